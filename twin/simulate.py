"""Scenario -> twin bench -> procedures on the simulated clock -> dataset (format v1) + truth/.

    simulate(sc, out_dir, progress=True, backend="auto", resume=False) -> Path

What runs (``[procedure]`` of the scenario), through ``hw.acquisition.runner`` exactly as on the
real bench (the same procedures and runner; only the instruments and the clock are simulated):

1. radial motion (Jia sec. 4.1): ``radial_reps`` revolutions × ``radial_positions`` stops, encoder +
   probes (+ X probes if ``instruments.probe.x_probes``) -> ``radial_motion.csv``;
2. CCD sweep (Jia sec. 4.2): one image every ``ccd_step`` -> ``ccd/img_KKK.png`` + ``ccd/index.csv``;
3. polygon shift-angle (Hsieh sec. 2.2): all N start faces at the first shift, start face 1 at
   the others, ``polygon_reps`` × ``directions`` -> ``polygon.csv``;
4. self-calibration sweep (Hsieh sec. 2.3) if ``selfcal`` and several heads -> ``heads.csv``.

Every table's ``theta_deg`` is the stop's encoder position: the commanded reading at which the
servo holds head 1's interpolated signal (the bench stops at commanded encoder readings); the
displayed, noisy and quantised reading of head 1 is the extra column ``theta_read_deg``.
``t_s`` is the simulated time. The run's journal is kept as ``journal.jsonl`` (``resume=True`` continues an interrupted
simulation). truth/ holds: ``scenario.json`` (SI values and the file's text), ``bench.json``
(``Bench.truth()`` + the instruments' generated parameters), ``encoder_error.csv`` (α(θ) of every
head and the disk-plane motion δX, δY of the axis on a 0.1° grid of readings, rep 0, forward; α
without the encoder's noise and quantisation), ``radial_motion.csv`` (per stop: true angle,
axis and disk centre motion in the disk plane δX/δY, sphere centres, α), ``polygon.csv`` (per
reading: true angle, α, exact face angle, Σβ in Hsieh's numbering, U), ``polygon_beta.csv``,
``polygon_setup.csv`` (U_j per mounting and direction), ``ccd.csv`` (per image disk centre and
edge radius in px), ``seeds.json``. Per-reading truth is taken during the run from the very pose
the instruments read (``_reading_truth``, O(1) per reading: the stop's pose at its own time, head
1's exact reading from the servo's last evaluation); a resumed run re-does the journaled moves and
waits (not the readings) so its state and truth are bit for bit those of an uninterrupted run.

Same scenario and seed -> byte-identical dataset (no wall time, no host names are written).

Both cores: the drive servo's settles are computed ahead by a forked worker from the procedure's
plan (``instruments/settle_ahead.py``: the same rests, bit for bit); the CCD frames (render,
sensor model, PNG encode, atomic write) are made by worker processes, forked from a forkserver
that has imported the render stack, while the physics goes on here (``twin/render/pipeline.py``;
``BENCHTWIN_SIM_FRAMES`` = serial | pipeline | auto; auto pipelines large sweeps, e.g. jia2019's
60 frames of 3 Mpx). The dataset is byte-identical
either way; a capture's journal line, and the lines after it, are written once its frame is on
disk (``_FrameGatedRunner``), so a killed run journals no incomplete frame.
"""

from __future__ import annotations

import contextlib
import copy
import math
import shutil
import tempfile
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, overload

import numpy as np

from benchtwin.analysis.dataset import JOURNAL, Dataset, DatasetError, DatasetWriter
from benchtwin.forkcall import ForkCall
from benchtwin.fsio import OutputError, OutputFolder, locked_output_dir
from benchtwin.hw.acquisition import procedures as P
from benchtwin.hw.acquisition.tables import TableSink
from benchtwin.hw.acquisition.runner import Runner, RunnerSettings, SimClock

from .instruments.autocollimator import SimAutocollimator
from .instruments.axial_probe import SimAxialProbe, face_truth_m
from .instruments.drive import DriveServo
from .instruments.encoder_head import SimEncoder
from .instruments.probe import SimProbe
from .instruments.settle_ahead import SettleAhead
from .instruments.stage import ARCSEC, SIM_STREAMS, SimBenchState, SimRotaryStage, sim_hsieh_to_physics_face
from .alpha_grid_memo import memoised
from .physics import Bench
from .render.pipeline import FramePipeline, frame_mode

ALPHA_GRID_STEP_DEG = 0.1
#: niceness of the α grid's child: it is wanted at the run's end, while the run's own steps (the
#: servo, the statics) are its critical path and keep their core (issue #17)
GRID_NICE = 10
#: niceness of ``simulate_apart``'s truth child (with its α grid): nothing waits for it before the
#: caller's analysis has ended, so it takes only the CPU the frames and the analysis leave (issue #17)
TRUTH_APART_NICE = 19
#: the dataset folder a simulation writes in place (``benchtwin.fsio.locked_output_dir``): resumable
#: by its journal, complete once its manifest is written
_DATASET_FOLDER = OutputFolder("dataset folder", "simulate", resume_marker=JOURNAL, complete_marker="manifest.json")


def scenario_procedures(sc: Any, probes: list[str] | None = None, ccd: bool = True) -> list[dict[str, Any]]:
    """The scenario's ``[procedure]`` in the procedure language (``hw.acquisition.procedures``:
    specs in degrees and seconds), in the order the simulation runs them: radial motion, CCD sweep,
    polygon shift-angle, self-calibration (with more than one head). The same specs are the
    emulated bench file's ``[[procedure]]`` tables (``twin.emulators.serve``). ``probes``: the
    radial-motion probes (default: the top and bottom probes, plus the X probes when the
    scenario has them); ``ccd``: include the CCD sweep."""
    b, pr = sc["bench"], sc["procedure"]
    dwell = float(pr["dwell"])
    if probes is None:
        probes = ["probe_top", "probe_bottom"]
        if sc["instruments"]["probe"]["x_probes"]:
            probes += ["probe_top_x", "probe_bottom_x"]
        probes += axial_probe_names(sc)
    dirs = list(pr["directions"])
    specs: list[dict[str, Any]] = [{"type": "radial_motion", "reps": int(pr["radial_reps"]),
                                    "positions": int(pr["radial_positions"]), "dwell": dwell,
                                    "probes": list(probes)}]
    if ccd:
        ccd_spec: dict[str, Any] = {"type": "ccd_sweep", "step": _deg(pr["ccd_step"]), "dwell": dwell, "camera": "ccd"}
        if int(pr["ccd_reps"]) > 1:   # one sweep: the spec (and the emulated bench file) as before
            ccd_spec["reps"] = int(pr["ccd_reps"])
        specs.append(ccd_spec)
    specs.append({"type": "polygon_shift_angle", "shifts": [_deg(s) for s in pr["polygon_shifts"]],
                  "reps": int(pr["polygon_reps"]), "directions": dirs, "dwell": dwell,
                  "faces": int(b["polygon_faces"])})
    if pr["selfcal"] and len(b["heads"]) > 1:
        specs.append({"type": "selfcal", "step": _deg(pr["selfcal_step"]), "directions": dirs, "dwell": dwell,
                      "heads": [_deg(h) for h in b["heads"]]})
    return specs


def axial_probe_names(sc: Any) -> list[str]:
    """The ISO 230-7 axial / face probes a scenario's optional ``[axial]`` section asks for (none
    without it)."""
    ax = sc.get("axial") if hasattr(sc, "get") else None
    if not ax:
        return []
    # the schema fills the section's defaults (twin/scenario_schema.py "axial"): none re-applied here
    out = ["probe_axial"] if ax["sphere_probe"] else []
    if float(ax["face_probe_radius"]) > 0:
        out.append("probe_face")
    return out


def sim_procedure(sc: Any) -> list:
    """The scenario's procedures as one list of steps (a dry run of the simulation)."""
    return list(P.steps_from_specs(scenario_procedures(sc)))


def sim_build(sc: Any, backend: str = "auto", bench: Bench | None = None, camera: bool = True):
    """Bench, state and instruments of a scenario: (bench, state, instruments dict)."""
    bench = Bench(sc) if bench is None else bench
    state = SimBenchState(bench, SimClock())
    # One Hidden per bench (twin/hidden.py): the physics built it; every instrument gets that one.
    hidden = bench.hidden
    enc = SimEncoder.sim_from_scenario(sc, state, hidden=hidden)
    servo = DriveServo.sim_from_bench(sc, bench)   # the drive servo on the encoder's count
    inst: dict[str, Any] = {"encoder": enc, "stage": SimRotaryStage("stage", state, enc, servo=servo)}
    key = 0
    axes = ("y", "x") if sc["instruments"]["probe"]["x_probes"] else ("y",)
    for ax in axes:
        for s in ("top", "bottom"):
            p = SimProbe.sim_from_scenario(sc, state, bench, s, ax, key=key)
            inst[p.name] = p
            key += 1
    for name in axial_probe_names(sc):   # [axial] (optional): probes parallel to the axis
        inst[name] = SimAxialProbe.axial_from_scenario(sc, state, bench, name)
    inst["autocollimator"] = SimAutocollimator.sim_from_scenario(sc, state, hidden=hidden)
    if camera:
        from .instruments.camera import SimCamera

        inst["ccd"] = SimCamera.sim_from_scenario(sc, state, backend=backend, hidden=hidden)
    return bench, state, inst


def _deg(rad: float) -> float:
    """Degrees from a parsed angle, rounded to 12 significant digits ("120 deg" -> 120.0, not
    119.99999999999999: the scenario's text value, not the float round trip)."""
    return float(f"{math.degrees(float(rad)):.12g}")


def _manifest(sc: Any, enc: SimEncoder, cam: Any, bench: Bench | None = None) -> dict:
    """The dataset's declarations: from the NOMINAL scenario only ([hidden] never shows here)."""
    b = sc["bench"]
    m = {
        "format": "bench-dataset", "version": 1, "source": "twin",
        "scenario": sc.name, "seed": int(sc.seed), "created_by": "benchtwin.twin.simulate",
        "bench": {
            "optical_radius_mm": float(b["optical_radius"]) * 1e3,
            "L1_mm": float(b["L1"]) * 1e3,
            "L2_mm": float(b["L2"]) * 1e3,
            "grating_period_um": float(b["grating_period"]) * 1e6,
            "scale_edge_radius_mm": float(b["scale_edge_radius"]) * 1e3,
            "encoder_lines": int(enc.n_lines),
            "polygon_faces": int(b["polygon_faces"]),
            "heads_deg": [_deg(h) for h in b["heads"]],
            "encoder_resolution_arcsec": float(b["encoder_resolution"]) / ARCSEC,
        },
    }
    if "probe_face" in axial_probe_names(sc):   # [axial]: where the face probe stands (ISO 230-7 face motion)
        m["bench"]["face_probe_radius_mm"] = float(sc["axial"]["face_probe_radius"]) * 1e3
        m["bench"]["face_probe_azimuth_deg"] = _deg(sc["axial"]["face_probe_azimuth"])
    ac = sc.get("instruments", {}).get("autocollimator") if hasattr(sc, "get") else None
    if ac:  # the declared instrument (its data sheet), the budget's type B inputs (Hsieh sec. 3.3)
        m["bench"]["autocollimator_resolution_arcsec"] = float(ac["resolution"]) / ARCSEC
        m["bench"]["autocollimator_accuracy_arcsec"] = float(ac["accuracy"]) / ARCSEC
    ball_sets = getattr(bench, "ball_sets", None) if bench is not None else None
    if ball_sets and int(sc["procedure"].get("continuous_revolutions") or 0) > 0:
        # the bearings' nominal kinematic orders (catalogue geometry: Z, Dw, Dpw, contact angle;
        # Harris ch. 7), declared for the continuous run's spectrum (report: ISO 230-7 section)
        m["bench"]["bearing_kinematic_orders"] = {
            f"{k} ({s_})": float(v) for s_, set_ in sorted(ball_sets.items())
            for k, v in set_.kinematic_orders().items()}
    if bench is not None and bench.hidden.writes_certificate:
        # a calibrated polygon's certificate: the declared polygon's β (Hsieh numbering); the true
        # polygon differs from it by the hidden pattern (twin/hidden.py, polygon_pitch_ignored)
        N = bench.n_faces
        cert = np.asarray(bench.polygon_pitch_declared_rad) / ARCSEC
        m["bench"]["polygon_certificate_arcsec"] = [float(cert[sim_hsieh_to_physics_face(h, N) - 1])
                                                    for h in range(1, N + 1)]
    if cam is not None:
        c = cam.camera
        m["ccd"] = {"position_deg": _deg(c.azimuth_rad), "outward": "+x", "tangential": c.tangential,
                    "reference_px": [float(v) for v in c.reference_px], "pixel_um": c.pixel_pitch_m * 1e6}
    return m


class SimulatedDataset(Dataset):
    """A dataset ``simulate(scenario)`` made in a temporary folder (``out_dir`` None, a notebook):
    an open :class:`~benchtwin.analysis.dataset.Dataset` (``analyze`` takes it, and it is a path:
    ``os.fspath``) whose folder, truth/ included, is removed by :meth:`cleanup`, at the end of a
    ``with`` block, or when the object is garbage-collected or the interpreter exits; ``keep=True``
    leaves it for you (``.path`` says where)."""

    def __init__(self, path: str | Path, *, keep: bool = False):
        super().__init__(path)
        self.keep = keep
        root = self.path.parent
        self._finalizer = None if keep else weakref.finalize(self, shutil.rmtree, root, ignore_errors=True)

    def __fspath__(self) -> str:
        return str(self.path)

    def cleanup(self) -> None:
        """Remove the temporary folder now (nothing with ``keep=True``)."""
        if self._finalizer is not None:
            self._finalizer()

    def __enter__(self) -> "SimulatedDataset":
        return self

    def __exit__(self, *exc: object) -> None:
        self.cleanup()

    def __repr__(self) -> str:
        return (f"SimulatedDataset({str(self.path)!r}, scenario={self.manifest.get('scenario')!r}, "
                f"seed={self.manifest.get('seed')}, tables={self.tables()}, "
                f"{'kept' if self.keep else 'temporary'})")


@overload
def simulate(sc: Any, out_dir: None = None, progress: bool = True, backend: str = "auto", resume: bool = False,
             force: bool = False, live: Any | None = None, *, keep: bool = False) -> SimulatedDataset: ...


@overload
def simulate(sc: Any, out_dir: str | Path, progress: bool = True, backend: str = "auto", resume: bool = False,
             force: bool = False, live: Any | None = None, *, keep: bool = False) -> Path: ...


def simulate(sc: Any, out_dir: str | Path | None = None, progress: bool = True, backend: str = "auto",
             resume: bool = False, force: bool = False, live: Any | None = None, *,
             keep: bool = False) -> Path | SimulatedDataset:
    """Run the scenario on the twin and write the dataset directory ``out_dir``; returns it.

    ``out_dir`` None (a notebook): the dataset is made in a new temporary folder and returned as a
    :class:`SimulatedDataset` (an open dataset that ``analyze`` accepts), removed when it is no
    longer used (``keep=True``: kept; ``resume`` and ``force`` need an ``out_dir``).

    ``out_dir`` must be new or empty, or hold an unfinished run's journal with ``resume``;
    ``force`` clears it first, once this run holds the folder's lock (``benchtwin.fsio.
    locked_output_dir``: a live run's folder is refused, whatever the flags); the scenario's own file
    may not be in it; the manifest is written last (a killed run leaves no dataset).
    ``live``: an observer with ``start(n_steps)``, ``on_step(...)``, ``on_row(...)`` (the live view
    of ``simulate --live``); it only watches the run."""
    if out_dir is None:
        if resume or force:
            raise ValueError("simulate: resume and force need an out_dir (out_dir=None simulates into a new "
                             "temporary folder)")
        root = Path(tempfile.mkdtemp(prefix=f"benchtwin-{sc.name}-"))
        try:
            path = simulate(sc, root / "dataset", progress=progress, backend=backend, live=live)
        except BaseException:
            shutil.rmtree(root, ignore_errors=True)
            raise
        return SimulatedDataset(path, keep=keep)
    out = Path(out_dir)
    try:
        # the lock first, then the check (and --force's clearing): never a live run's folder
        with locked_output_dir(out, _DATASET_FOLDER, force=force, resume=resume, inputs=[getattr(sc, "path", None)]):
            return _simulate(sc, _RunOptions(out, progress, backend, resume, live))[0]
    except OutputError as exc:
        raise DatasetError(str(exc)) from None


def simulate_apart(sc: Any, out_dir: str | Path, truth_dir: str | Path, progress: bool = True,
                   backend: str = "auto") -> tuple[Path, ForkCall]:
    """``simulate`` with the truth written to ``truth_dir``, never into the dataset, by a forked
    child (``benchtwin.forkcall``) that starts when the run's last step is done: the call returns
    once the *measured* dataset is complete (manifest written), and the caller analyses it while
    the truth is computed on the other core. ``job.wait()`` returns when ``truth_dir`` is complete
    (or raises the child's error); ``job.cancel()`` when the caller gives up. The truth's bytes
    are those ``simulate`` writes to ``truth/``: the child is the bench as the run left it, and it
    computes the α grid from a copy of the bench as built (``_alpha_grid``), at nice
    ``TRUTH_APART_NICE``: the frames and the caller's analysis go first.

    Why (issue #17): the truth (then with its α grid: 3600 stops, ≈ 9 s of CPU before the round's
    physics work, ≈ 4 s after, docs/benchmarks.md) came after the run, on the critical path of
    ``benchtwin run``; the analysis never needs it (principle 3), so the two can overlap."""
    out = Path(out_dir)
    try:
        with locked_output_dir(out, OutputFolder("dataset folder", "simulate"), inputs=[getattr(sc, "path", None)]):
            _, job = _simulate(sc, _RunOptions(out, progress, backend, False, truth_dir=Path(truth_dir)))
    except OutputError as exc:
        raise DatasetError(str(exc)) from None
    assert job is not None
    return out, job


@dataclass(frozen=True)
class _RunOptions:
    """How ``_simulate`` runs: the dataset folder, the progress bar, the CCD renderer, a resumed run,
    the live observer (``simulate --live``) and ``simulate_apart``'s truth folder (None: truth/)."""

    out: Path
    progress: bool
    backend: str
    resume: bool
    live: Any | None = None
    truth_dir: Path | None = None


@dataclass(frozen=True)
class _BuiltRun:
    """The bench ``_simulate`` built for the run: its steps, bench, state and instruments, and the
    truth's α grid (a call: from its own child, or computed here)."""

    steps: list
    bench: Bench
    state: SimBenchState
    inst: dict
    alpha_grid: Callable[[], dict[str, list]]


@dataclass
class _RunTruth:
    """The truth taken during the run, per step index: the readings' (``_reading_truth``), the count
    the servo holds at each reading (deg) and each frame's, from the posed geometry (never journaled)."""

    rows: dict[int, tuple] = field(default_factory=dict)
    held_deg: dict[int, float] = field(default_factory=dict)
    ccd: dict[int, dict] = field(default_factory=dict)
    #: [axial] only: per reading (axial z, its bearing / supply / thermal parts, face motion at the
    #: face probe by the definition axial + R × tilt), m
    axial: dict[int, tuple] = field(default_factory=dict)


def _simulate(sc: Any, opts: _RunOptions) -> tuple[Path, ForkCall | None]:
    """The run; ``opts.truth_dir`` (``simulate_apart``): the truth goes there, from a forked child."""
    steps = sim_procedure(sc)
    has_ccd = any(isinstance(s, P.Capture) for s in steps)
    bench, state, inst = sim_build(sc, opts.backend, camera=has_ccd)
    stage: SimRotaryStage = inst["stage"]
    # The servo's settles of the whole procedure are known from its steps (settle_ahead.py): a
    # worker forked now computes them ahead while the run poses and reads; the same rests either way.
    ahead = SettleAhead.start(stage, steps)
    # The truth's α grid is a property of the bench as built (``_alpha_grid``), computed from a
    # copy. ``simulate``: by a child forked now, while the run steps (forked before any thread of
    # this run starts: the progress bar, the frame pool). ``simulate_apart``: by the truth's own
    # child, after the run (nothing waits for it before the caller's analysis has ended; a grid
    # child here would share the cores with the frames the analysis waits for, issue #17). Its
    # bytes do not depend on where it runs (BENCHTWIN_FORK=0: here, on the copy).
    # (``alpha_grid_memo``: read back instead when $BENCHTWIN_ALPHA_GRID_CACHE holds this bench's grid)
    alpha_grid: Callable[[], dict[str, list]] = partial(memoised, sc, partial(_grid_of, sc, copy.deepcopy(bench)))
    with contextlib.ExitStack() as stack:
        if ahead is not None:
            stack.enter_context(ahead)      # the settles' worker stopped when the run ends
            stack.callback(setattr, stage, "sim_ahead", None)    # (and the stage settles itself again)
        if opts.truth_dir is None:          # cancelled if the run fails before it is waited for
            alpha_grid = stack.enter_context(ForkCall(alpha_grid, what=f"the truth's α grid of {sc.name}",
                                                      nice=GRID_NICE)).wait
        stage.sim_ahead = ahead
        return _run_and_write(sc, opts, _BuiltRun(steps, bench, state, inst, alpha_grid))


def _frame_pipeline(run: _BuiltRun, opts: _RunOptions) -> FramePipeline | None:
    """The frame workers when the sweep is worth pipelining (``frame_mode``), attached to the camera."""
    cam = run.inst.get("ccd")
    if cam is None:
        return None
    n_frames = sum(isinstance(s, P.Capture) for s in run.steps)
    if frame_mode(n_frames, cam.camera.width_px, cam.camera.height_px, live=opts.live is not None) != "pipeline":
        return None
    pipe = FramePipeline.start(opts.backend, cam.grating, cam.camera, cam.sensor)
    cam.pipeline = pipe
    return pipe


class _RunObserver:
    """The runner's ``on_step`` and ``on_row`` for the twin: the bench's state follows the steps
    (replayed ones re-done), the truth is taken from the pose the instruments read, the frames are
    written (by the pipeline when there is one), and the progress bar and the live view watch."""

    def __init__(self, run: _BuiltRun, opts: _RunOptions, writer: DatasetWriter, bar: Any,
                 pipe: FramePipeline | None) -> None:
        self.state, self.live, self.writer, self.bar, self.pipe = run.state, opts.live, writer, bar, pipe
        self.stage: SimRotaryStage = run.inst["stage"]
        self.enc: SimEncoder = run.inst["encoder"]
        self.ac: SimAutocollimator = run.inst["autocollimator"]
        self.cam = run.inst.get("ccd")
        self.face = run.inst.get("probe_face")
        self.truth = _RunTruth()

    def on_step(self, i: int, step: Any, context: dict, replay: bool) -> None:
        state, stage = self.state, self.stage
        state.on_step(i, step, context, replay)
        if replay:
            # Resume: re-do the journaled step's effect on the bench (moves and waits; readings and
            # images come from the journal), so the state — poses, clock, servo — is bit for bit
            # that of an uninterrupted run; the runner's re-issued last move then holds.
            if isinstance(step, P.Move):
                stage.move_to(step.target_deg)
            elif isinstance(step, P.Wait):
                state.clock.advance(step.seconds)
            stage.sim_hold = True
        else:
            stage.sim_hold = False
        if isinstance(step, P.Read) and {**context, **step.tag}.get("procedure") in TRUTH_PROCEDURES:
            self.truth.rows[i] = _reading_truth(state, stage, self.enc,
                                                self.ac if "autocollimator" in step.names else None)
            self.truth.held_deg[i] = float(stage.held_deg)
            pose = state.posed()
            if "axial_m" in pose.extra:   # [axial]: the shaft's axial DOF (twin/axial.py)
                parts = pose.extra["axial_parts_m"]
                face = (face_truth_m(pose, self.face.radius_m, self.face.azimuth_rad)
                        if self.face is not None else float("nan"))
                self.truth.axial[i] = (float(pose.extra["axial_m"]), float(parts["bearing"]),
                                       float(parts["supply"]), float(parts["thermal"]), face)
        if isinstance(step, P.Capture) and self.cam is not None:
            self.truth.ccd[i] = self.cam.sim_frame_truth()
        self.bar.update(1)
        if self.live is not None:
            self.live.on_step(i, step, context, replay)

    def on_row(self, row: dict, result: dict) -> None:
        cam = self.cam
        if row["type"] == "capture":
            rel = f"ccd/img_{int(row['tag']['k']):03d}.png"
            if result.get("image") is None and cam is not None and cam.pending_job is not None:
                assert self.pipe is not None      # a pending job is the pipeline's
                self.pipe.submit(self.writer.path / rel, *cam.take_job())   # journaled once it is written
            else:
                self.writer.write_image(rel, result["image"])
        if self.live is not None:
            self.live.on_row(row, result)


def _continuous(sc: Any, writer: DatasetWriter, run: _BuiltRun) -> None:
    """The ISO 230-7 continuous run, after the stop-and-go procedures (twin/continuous.py), when the
    scenario asks for one."""
    pr = sc["procedure"]
    n_rev = int(pr.get("continuous_revolutions", 0) or 0) if hasattr(pr, "get") else 0
    if n_rev > 0:
        from .continuous import continuous_run

        writer.write_table("radial_continuous", continuous_run(
            run.bench, run.state, run.inst, float(pr["continuous_speed"]), n_rev,
            int(pr["continuous_samples_per_rev"])))


def _truth_after_run(sc: Any, writer: DatasetWriter, rows: list[dict], run: _BuiltRun, truth: _RunTruth,
                     truth_dir: Path | None) -> ForkCall | None:
    """The truth (its α grid from its own child, started with the run) while the frame workers
    finish their backlog; apart (simulate_apart): in a forked child that also computes the grid,
    while the caller goes on to its analysis (the child's job is returned)."""
    def write() -> None:
        _write_truth(sc, writer, rows, run.bench, run.inst, truth, run.alpha_grid())

    if truth_dir is None:
        write()
        return None
    return ForkCall(write, what=f"the truth of {sc.name} (written to {truth_dir})", nice=TRUTH_APART_NICE)


def _run_and_write(sc: Any, opts: _RunOptions, run: _BuiltRun) -> tuple[Path, ForkCall | None]:
    """``_simulate``'s run of the built bench: the steps, the frames, the tables, the truth."""
    from tqdm.auto import tqdm  # a notebook widget in Jupyter, the text bar elsewhere (issue 34)

    enc: SimEncoder = run.inst["encoder"]
    cam = run.inst.get("ccd")
    writer = DatasetWriter(opts.out, _manifest(sc, enc, cam, run.bench), prepared=True, resume=opts.resume,
                           truth_to=opts.truth_dir)
    bar = tqdm(total=len(run.steps), desc=f"simulate {sc.name}", unit="step", disable=not opts.progress,
               leave=False)
    pipe = _frame_pipeline(run, opts)
    obs = _RunObserver(run, opts, writer, bar, pipe)
    if opts.live is not None:
        opts.live.start(len(run.steps))
    job: ForkCall | None = None
    settings = RunnerSettings(on_step=obs.on_step, on_row=obs.on_row, fsync=False)
    gated: _FrameGatedRunner | None = None
    if pipe is None:
        runner = Runner(run.inst, run.state.clock, opts.out / JOURNAL, settings)
    else:
        runner = gated = _FrameGatedRunner(run.inst, run.state.clock, opts.out / JOURNAL, settings)
        gated.frames = pipe
    ok = False
    try:
        try:
            rows = runner.run(run.steps, resume=opts.resume)
        finally:
            bar.close()
            if cam is not None:
                cam.close()
        _continuous(sc, writer, run)
        job = _truth_after_run(sc, writer, rows, run, obs.truth, opts.truth_dir)
        if gated is not None:
            gated.drain()     # the last frames written, then the journal lines held behind them
        ok = True
    finally:
        if pipe is not None:
            pipe.close(wait=ok)
        if not ok and job is not None:
            job.cancel()
    try:
        _write_tables(writer, rows, enc)    # checks every capture's image is there
        writer.close()
    except BaseException:
        if job is not None:
            job.cancel()
        raise
    return opts.out, job


class _FrameGatedRunner(Runner):
    """The runner with frames written by ``FramePipeline``: a capture's journal line, and every
    line after it, is held until its frame is on disk (the journal keeps its order and never names
    a frame that is not complete; a run killed meanwhile loses the held steps, which a resume
    re-does bit for bit: the noise is keyed by step). ``drain()`` after the run: wait for the
    remaining frames and append the held lines."""

    frames: FramePipeline

    def __init__(self, *args: Any, **kw: Any):
        super().__init__(*args, **kw)
        self._held: list[tuple[dict, int]] = []

    def _append(self, fh, *recs: dict) -> None:
        if fh is None:
            return
        self._held.extend((rec, self.frames.submitted) for rec in recs)
        self._release(fh, self.frames.completed())

    def _release(self, fh, done: int) -> None:
        n = 0
        for rec, need in self._held:
            if need > done:
                break
            Runner._append(self, fh, rec)
            n += 1
        if n:
            del self._held[:n]

    def drain(self) -> None:
        done = self.frames.completed(wait=True)
        if self._held and self.journal is not None:
            with open(self.journal, "a", encoding="utf-8") as fh:
                self._release(fh, done)


# --------------------------------------------------------------------------- tables

def _theta(row) -> float:
    """The stop's encoder position: the commanded reading at which the servo holds head 1's
    interpolated signal (to 1e-6″); what the displayed reading scatters around."""
    return float(row["tag"]["target_deg"])


#: the radial-motion probes in the tables' column order (X probes only where the scenario has them)
PROBES = ("probe_top", "probe_bottom", "probe_top_x", "probe_bottom_x", "probe_axial", "probe_face")


def _write_tables(w: DatasetWriter, rows: list[dict], enc: SimEncoder) -> None:
    """The dataset tables from the run's rows through acquire's ``TableSink``: the twin and the bench
    write their tables with one mapping (theta_deg = the stop's commanded encoder position)."""
    radial = next((r for r in rows if r["type"] == "read" and r["tag"].get("procedure") == "radial_motion"), None)
    probes = [p for p in PROBES if radial is not None and p in radial["readings"]]
    sink = TableSink(w, probes=probes, resolution_arcsec=enc.resolution_rad / ARCSEC, theta="target")
    try:
        for r in rows:
            sink(r)
    except BaseException:
        sink.abort()
        raise
    sink.close()


# --------------------------------------------------------------------------- truth

def _graduation_map_truth(enc: SimEncoder) -> dict:
    """The disk's static line-position map as the heads read it (twin/instruments/graduation.py):
    model, field, rms and its first harmonics (the full map: truth/graduation_map.csv)."""
    m = enc.sim_graduation_map()
    out: dict = {"model": "line-position map: closed ruling walk + clamping harmonics, head field average",
                 "scanning_field_lines": enc.scanning_field_lines}
    if m is None:
        return {**out, "head_rms_rad": 0.0, "line_rms_rad": 0.0}
    c = np.fft.rfft(m.head) * (2.0 / m.n_lines)
    k = np.arange(1, min(21, c.size))
    return {**out, "head_rms_rad": m.rms_rad, "line_rms_rad": float(np.sqrt(np.mean(m.lines**2))),
            "head_harmonics": {"order": k.tolist(), "amplitude_rad": np.abs(c[k]).tolist(),
                               "phase_rad": np.angle(c[k]).tolist(),
                               "form": "a_k·cos(k·g + phase_k), g the nominal graduation value"}}


def _instrument_truth(inst: dict) -> dict:
    enc: SimEncoder = inst["encoder"]
    ac: SimAutocollimator = inst["autocollimator"]
    out = {
        "encoder": {"lines": enc.n_lines, "heads_rad": enc.heads_rad.tolist(), "optical_radius_m": enc.radius_m,
                    "index_line_body_angle_rad": math.pi / 2,
                    "graduation_error_rms_rad": enc.graduation_error_rms_rad,
                    "graduation_map": _graduation_map_truth(enc),
                    "interpolation": {k: np.asarray(v).tolist() for k, v in enc.interpolation.items()},
                    "resolution_rad": enc.resolution_rad, "noise_rad": enc.noise_rad},
        "autocollimator": {"azimuth_rad": ac.azimuth_rad, "accuracy_curve": {k: v.tolist() for k, v in ac._acc.items()},
                           "accuracy_rad": ac.accuracy_rad, "range_rad": ac.range_rad,
                           "drift_rate_rad_s": ac.drift_rate_rad_s, "noise_rad": ac.noise_rad,
                           "resolution_rad": ac.resolution_rad},
        "probes": {n: {"sphere": p.sphere, "axis": p.axis, "side": p.side, "sphere_radius_m": p.R,
                       "nominal_z_m": p.nominal_z_m, "linearity_coeffs": p._lin_c.tolist(),
                       "linearity_phases": p._lin_p.tolist(), "linearity_scale": p._lin_scale}
                   for n, p in inst.items() if isinstance(p, SimProbe)},
        "stage": inst["stage"].describe(),
    }
    servo = getattr(inst["stage"], "servo", None)
    if servo is not None:   # truth only: its friction is the TRUE one (hidden extra friction included)
        out["drive_servo"] = servo.describe()
    return out


TRUTH_PROCEDURES = ("radial_motion", "polygon")


def _reading_truth(st: SimBenchState, stage: SimRotaryStage, enc: SimEncoder,
                   ac: SimAutocollimator | None) -> tuple:
    """The truth of the reading about to be taken: from the pose the instruments read (the stop's
    pose, at its own time), O(1). (shaft angle, head 1's exact reading, axis δX/δY in the disk
    plane, disk centre x/y, top and bottom sphere centres x/y, twist[, AC exact x, y, face seen,
    polygon setup error]) — rad and m."""
    p = st.posed()
    last = stage.last_exact
    x0 = float(last[0] if last is not None and stage.last_pose is p else enc.sim_exact_readings(p)[0])
    ax = p.extra["axis_disk_plane_m"]
    out: tuple = (float(p.shaft_angle_rad), x0, float(ax[0]), float(ax[1]), float(p.disk.pos[0]), float(p.disk.pos[1]),
           float(p.sphere_top.pos[0]), float(p.sphere_top.pos[1]), float(p.sphere_bottom.pos[0]),
           float(p.sphere_bottom.pos[1]), float(p.extra.get("twist_disk_to_polygon_rad", 0.0)))
    if ac is not None:
        ex, ey, face = ac.sim_exact_angles(p)
        out += (float(ex), float(ey), int(face), float(st.polygon_setup_error_rad))
    return out


def _grid_of(sc: Any, bench: Bench) -> dict[str, list]:
    """``_alpha_grid``, looked up when called (benchmarks/run_parts.py counts it by replacing it)."""
    return _alpha_grid(sc, bench)


def _alpha_grid(sc: Any, bench: Bench) -> dict[str, list]:
    """The truth's α grid: every head's error α = reading − true angle at readings 0.1° apart (rep 0,
    forward), ``encoder_error.csv``'s columns. ``bench``: a bench as built, before the run (this
    function resets its path and leaves warm starts on it: pass a copy).

    The grid is a property of the bench, not of the run: a fresh state and clock (t = 0), a fresh
    encoder and an ideal stage, and the bench's path started afresh. So it is computed from a copy
    of the bench as built, ≈ 4 s of CPU (jia2019), off the run's critical path (``_simulate``:
    ``simulate``'s own child while the run steps, ``simulate_apart``'s truth child while the
    caller analyses; issue #17)."""
    # An independent state + stage for the α grid (the run's clock is not touched). The grid is
    # one continuous sweep of a bench whose path starts afresh (ball bearings: cages at their
    # initial angles, rolling with the shaft along the grid, no start/stop slip: one time).
    bench.reset_path()
    st = SimBenchState(bench, SimClock())
    enc = SimEncoder.sim_from_scenario(sc, st, hidden=bench.hidden)
    # the secant on head 1's reading: the same stops to the same tolerance in fewer poses
    stage = SimRotaryStage("truth_stage", st, enc, secant=True)

    def stop(tag, t_s: float = 0.0) -> tuple:
        # the clock at the reading's time (time-dependent hidden physics); the move adds its own
        # duration (seconds, against hours of thermal time constant)
        st.clock.set(float(t_s))
        st.apply_context(tag)
        stage.move_to(float(tag["target_deg"]))
        return st.pose, stage.last_exact

    # α on a fine grid of readings, every head (rep 0, forward).
    st.apply_context({"rep": 0, "direction": "forward"})
    grid = np.round(np.arange(0.0, 360.0, ALPHA_GRID_STEP_DEG), 10)
    cols: dict[str, list] = {"theta_deg": [], "true_deg": [], "axis_dx_um": [], "axis_dy_um": []}
    nh = enc.heads_rad.size
    for j in range(nh):
        cols[f"alpha_h{j + 1}_arcsec"] = []
    for th in grid:
        p, x = stop({"target_deg": th})
        cols["theta_deg"].append(float(th))
        cols["true_deg"].append(math.degrees(p.shaft_angle_rad))
        cols["axis_dx_um"].append(float(p.extra["axis_disk_plane_m"][0]) * 1e6)
        cols["axis_dy_um"].append(float(p.extra["axis_disk_plane_m"][1]) * 1e6)
        for j in range(nh):
            cols[f"alpha_h{j + 1}_arcsec"].append((x[j] - p.shaft_angle_rad) / ARCSEC)
    cols["alpha_arcsec"] = cols["alpha_h1_arcsec"]
    return cols


def _write_radial_truth(w: DatasetWriter, rows: list[dict], truth: _RunTruth) -> None:
    """truth/radial_motion.csv: per radial-motion stop, the true angle, α, the axis and disk centre
    motion in the disk plane and the sphere centres (µm)."""
    radial = [r for r in rows if r["type"] == "read" and r["tag"].get("procedure") == "radial_motion"]
    if not radial:
        return
    t: dict[str, list] = {k: [] for k in ("rep", "k", "theta_deg", "target_deg", "true_deg", "alpha_arcsec", "axis_dx_um",
                                          "axis_dy_um", "disk_centre_x_um", "disk_centre_y_um",
                                          "sphere_top_x_um", "sphere_top_y_um", "sphere_bottom_x_um",
                                          "sphere_bottom_y_um")}
    for r in radial:
        phi, x0, *pos_m = truth.rows[r["i"]][:10]
        vals = (r["tag"]["rep"], r["tag"]["k"], truth.held_deg.get(r["i"], _theta(r)), _theta(r), math.degrees(phi),
                (x0 - phi) / ARCSEC,
                *(v * 1e6 for v in pos_m))
        for k, v in zip(t, vals):
            t[k].append(v)
    if truth.axial:   # [axial] only: the columns are absent otherwise (the table's bytes as before)
        names = ("axial_um", "axial_bearing_um", "axial_supply_um", "axial_thermal_um", "face_um")
        for k in names:
            t[k] = []
        for r in radial:
            for k, v in zip(names, truth.axial[r["i"]]):
                t[k].append(v * 1e6)
    w.write_truth_table("radial_motion", t)


def _write_polygon_truth(w: DatasetWriter, rows: list[dict], truth: _RunTruth,
                         beta_h: np.ndarray) -> dict[tuple, list]:
    """truth/polygon.csv and polygon_setup.csv: per polygon reading, the true angle, α, the exact
    face angle, Σβ (Hsieh numbering, ``beta_h`` in arcsec) and U; per mounting, U and its spread.
    Returns the mountings' (U, setup error) per (rep, shift, start face, direction)."""
    N = beta_h.size
    poly = [r for r in rows if r["type"] == "read" and r["tag"].get("procedure") == "polygon"]
    setup: dict[tuple, list] = {}
    if not poly:
        return setup
    t: dict[str, list] = {k: [] for k in (
        "shift_deg", "start_face", "step", "rep", "direction", "theta_deg", "target_deg", "true_deg", "alpha_arcsec",
        "ac_exact_arcsec", "ac_exact_y_arcsec", "physics_face", "beta_sum_arcsec", "U_arcsec", "setup_error_arcsec",
        "twist_arcsec")}
    for r in poly:
        tag = r["tag"]
        phi, x0, *_, twist, ex, ey, face, setup_err = truth.rows[r["i"]]
        j, i = int(tag["start_face"]), int(tag["step"])
        bsum = float(sum(beta_h[(j - 1 + m) % N] for m in range(i)))
        alpha = (x0 - phi) / ARCSEC
        # Hsieh eq. 3 at the commanded stop θ: ε = U + Σβ + (θ − θ_true) − twist. The servo rests
        # anywhere in the held count and the friction it holds twists the shaft per stop, so U,
        # the mounting's constant, is what remains after both (twin/instruments/drive.py).
        U = ex / ARCSEC - (math.radians(_theta(r)) - phi) / ARCSEC - bsum + twist / ARCSEC
        vals = (tag["shift_deg"], j, i, tag["rep"], tag["direction"], truth.held_deg.get(r["i"], _theta(r)), _theta(r),
                math.degrees(phi),
                alpha, ex / ARCSEC, ey / ARCSEC, face, bsum, U, setup_err / ARCSEC, twist / ARCSEC)
        for k, v in zip(t, vals):
            t[k].append(v)
        setup.setdefault((tag["rep"], tag["shift_deg"], j, tag["direction"]), []).append(
            (U, setup_err / ARCSEC))
    w.write_truth_table("polygon", t)
    keys = list(setup)
    w.write_truth_table("polygon_setup", {
        "rep": [k[0] for k in keys], "shift_deg": [k[1] for k in keys], "start_face": [k[2] for k in keys],
        "direction": [k[3] for k in keys],
        "U_arcsec": [float(np.mean([u for u, _ in setup[k]])) for k in keys],
        "U_spread_arcsec": [float(np.ptp([u for u, _ in setup[k]])) for k in keys],
        "setup_error_arcsec": [setup[k][0][1] for k in keys]})
    return setup


def _write_truth(sc: Any, w: DatasetWriter, rows: list[dict], bench: Bench, inst: dict, truth: _RunTruth,
                 alpha: dict[str, list]) -> None:
    """The run's truth into ``w``'s truth folder; ``truth``: what the run took per step
    (``_RunObserver``); ``alpha``: the α grid's columns (``_alpha_grid``)."""
    N = bench.n_faces
    # the overrides applied to the file (--set, --seed, with_overrides): only when there are some, so
    # a run of the file as it is keeps its bytes; "file" holds the values with them applied
    overrides = dict(getattr(sc, "overrides", None) or {})
    w.write_truth_json("scenario.json", {"name": sc.name, "seed": int(sc.seed), "si": sc.to_dict(),
                                         "file": getattr(sc, "raw", None),
                                         "path": str(sc.path) if getattr(sc, "path", None) else None,
                                         **({"overrides": overrides} if overrides else {})})
    w.write_truth_table("encoder_error", alpha)

    _write_radial_truth(w, rows, truth)

    beta_p = np.asarray(bench.polygon_pitch_deviation_rad) / ARCSEC
    kmap = [sim_hsieh_to_physics_face(h, N) for h in range(1, N + 1)]
    beta_h = np.array([beta_p[k - 1] for k in kmap])
    w.write_truth_table("polygon_beta", {"face": list(range(1, N + 1)), "physics_face": kmap,
                                         "beta_arcsec": beta_h.tolist()})
    setup = _write_polygon_truth(w, rows, truth, beta_h)

    caps = [r for r in rows if r["type"] == "capture"]
    if caps:
        ct = [truth.ccd[r["i"]] for r in caps]
        w.write_truth_table("ccd", {
            "k": [r["tag"]["k"] for r in caps],
            "centre_x_px": [c["centre_px"][0] for c in ct],
            "centre_y_px": [c["centre_px"][1] for c in ct],
            "edge_radius_px": [c["edge_radius_px"] for c in ct],
            "pixel_um": [c["pixel_um"] for c in ct],
            "backend": [r["reading"].get("backend", "") for r in caps]})

    bt = bench.truth()
    bt["polygon_pitch_deviation_hsieh_arcsec"] = beta_h.tolist()
    bt["polygon_face_numbering"] = ("polygon.csv uses Hsieh's numbering: face h is physics face "
                                    "((1 - h) mod N) + 1 (physics faces run counter-clockwise in the body)")
    bt["instruments"] = _instrument_truth(inst)
    bt["polygon_mountings"] = [{"rep": k[0], "shift_deg": k[1], "start_face": k[2], "direction": k[3],
                                "U_arcsec": float(np.mean([u for u, _ in v])), "setup_error_arcsec": v[0][1]}
                               for k, v in setup.items()]
    w.write_truth_json("bench.json", bt)
    gm = inst["encoder"].sim_graduation_map()
    if gm is not None:   # the disk's static line map: per line, and as the heads read it
        w.write_truth_table("graduation_map", {
            "line": list(range(gm.n_lines)), "nominal_deg": (np.arange(gm.n_lines) * math.degrees(gm.pitch_rad)).tolist(),
            "line_error_arcsec": (gm.lines / ARCSEC).tolist(), "head_error_arcsec": (gm.head / ARCSEC).tolist()})
    if bench.hidden:
        t_end = max((float(r["t_s"]) for r in rows if "t_s" in r), default=0.0)
        w.write_truth_json("hidden.json", bench.hidden.truth(N, thermal=bench.thermal,
                                                              radius_m=inst["encoder"].radius_m, t_end_s=t_end))
    w.write_truth_json("seeds.json", {"scenario_seed": int(sc.seed), "instrument_streams": SIM_STREAMS,
                                      "note": "every random quantity is drawn from SeedSequence([seed, stream, keys…])"})


__all__ = ["simulate", "simulate_apart", "sim_procedure", "sim_build"]
