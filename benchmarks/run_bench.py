"""Whole-process timings of the main job's stages, each against its floor measured in the same run.

Issue #17. Stages (each a fresh ``benchtwin`` process, as a user runs them, ``--quiet``):

- ``simulate``: the scenario (default: the embedded jia2019) → a dataset with its CCD frames;
- ``analyze``: that dataset (its ``truth/`` moved aside first, as ``benchtwin run`` does);
- ``close-loop``: the same analysis + tracing the residual to an effect; "tracing" = close-loop − analyze;
- ``run``: simulate → analyze → close the loop in one process (the README's command).

Floors, measured in the same run by the scripts beside this one:

- I/O floor (benchmarks/io_floor.py): decode, Otsu, label and PNG-encode each of the dataset's
  frames once, in one process (the work, without interpreter start and imports);
- render floor (benchmarks/render_floor.py): a bare NumPy rasteriser of the exact coverage (the
  twin's line-end quality or better: benchmarks/area_floor.py) and bare OpenCV sensor operations on
  one frame of the same scenario, next to the twin's renderer and sensor model on the same frame;
- physics floor (benchmarks/physics_floor.py): the twin's static poses (``Bench.pose_at``, as the
  truth's α grid calls it) against the closed-form solve of the same poses, all at once in NumPy;
- servo floor (benchmarks/servo_bench.py): the drive servo's physics steps against raw ``mj_step``
  on the same model (the servo's dynamics have no closed form: raw MuJoCo is their floor).

The parts of ``run`` (issue #36), each against its own floor, all measured in this run; the amounts of
work are one simulate's own, counted by benchmarks/run_parts.py (its static poses, run and α grid; its
servo's ``mj_step`` calls; its frames):

- I/O: the I/O floor above (decode, Otsu, label, encode of the frames);
- render + sensor: frames × (the twin's render + sensor model of a frame), floor frames × (bare NumPy
  render + bare OpenCV sensor);
- statics: poses × the twin's µs per pose (``Bench.pose_at``), floor poses × the closed form's µs per
  pose (both from physics_floor.py's α grid, the per-pose cost applied to the run's poses too);
- servo: its ``mj_step`` calls at the servo's steps/s, floor at raw ``mj_step``'s (servo_bench.py);
- tracing: close-loop − analyze (two processes), floor the tracing's own CPU inside one close-loop
  process (report_bench.py: it has no closed form; the floor is the step without process overhead).

Then run's CPU / the sum of the floors (goal ≤ 1.5, stretch 1.2) and run's wall / its CPU (≤ 0.6 on 2
cores), with the load average before and after (``uptime``): CPU time and these ratios are what a
loaded machine changes least.

Ratios also printed: run / I/O floor (target ≤ 3, stretch 2), analyze / (decode + Otsu + label), the
eccentricity step alone (serial and in threads; benchmarks/ecc_bench.py) / decode + Otsu + label in
the same process (target ≤ 2), the twin's poses / their closed-form solve (target ≤ 2), the servo /
raw mj_step, the twin's render and sensor per frame / the floor's, simulate / (frames × floor render + sensor +
encode), tracing against its 1 s target (as close-loop − analyze of two processes, and measured
inside one close-loop process by benchmarks/report_bench.py, which also gives the report's and the
bench picture's own times in that process). Wall AND CPU time (user + system of the process and all its
descendants: a process pool, the frame workers' forkserver, which outlives the command by a moment
and is reaped here) are printed for every stage: the machine is shared, so wall figures
are taken under load (the load average is printed) and CPU time is the steadier figure.

Where the time goes inside one ``run`` (its critical path: the run's steps, the CCD frames'
backlog, each analysis step): ``benchmarks/run_timeline.py``.

Usage: ``.venv/bin/python benchmarks/run_bench.py [scenario.toml] [--repeat 1] [--keep DIR] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
BIN = Path(sys.executable).parent
ENV = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
       "PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM", "egl")}


def _become_subreaper() -> bool:
    """Linux: orphaned descendants of the commands are re-parented to this process
    (``prctl(PR_SET_CHILD_SUBREAPER)``), so their CPU can be counted: ``simulate``'s frame workers
    are children of multiprocessing's forkserver (twin/render/pipeline.py), which outlives the
    command by a moment and is not waited for by it."""
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0) == 0   # 36 = PR_SET_CHILD_SUBREAPER
    except (OSError, AttributeError):
        return False


SUBREAPER = _become_subreaper()


def _reap_descendants(timeout_s: float = 30.0) -> None:
    """Wait for every descendant left behind by the last command (see ``_become_subreaper``)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            time.sleep(0.01)


def timed_run(cmd: list[str], capture: bool = False, cwd: Path | None = None) -> tuple[float, float, str]:
    """(wall s, CPU s of the process and all its descendants, stdout) of one command. Wall: until
    the command exits; CPU: also of descendants that outlive it (the forkserver of the frame
    workers), reaped here (Linux; elsewhere only the children the command itself waited for)."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=cwd, env=ENV, stdout=subprocess.PIPE if capture else subprocess.DEVNULL,
                       stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    if SUBREAPER:
        _reap_descendants()
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: exit {p.returncode}\n{p.stderr[-3000:]}")
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return wall, cpu, p.stdout or ""


def _servo(sc: list[str]) -> dict:
    """The servo's steps/s against raw mj_step (benchmarks/servo_bench.py, in this process: CPU time)."""
    sys.path.insert(0, str(HERE))
    from servo_bench import bench_one

    return bench_one(Path(sc[0]) if sc else None)


def last_json(text: str) -> dict:
    return json.loads(text.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario", nargs="?", default=None, help="scenario TOML (default: the embedded jia2019)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per stage; the median is printed")
    ap.add_argument("--keep", type=Path, default=None, help="keep the outputs in this folder")
    ap.add_argument("--json", action="store_true", help="print a JSON summary as the last line")
    args = ap.parse_args(argv)

    bt = str(BIN / "benchtwin")
    py = sys.executable
    sc = [args.scenario] if args.scenario else []
    work = Path(tempfile.mkdtemp(prefix="benchtwin-run-bench-")) if args.keep is None else args.keep
    work.mkdir(parents=True, exist_ok=True)
    load0 = os.getloadavg()
    stages: dict[str, list[tuple[float, float]]] = {k: [] for k in ("simulate", "analyze", "close-loop", "run")}
    io: list[dict] = []
    ecc: list[dict] = []
    parts: list[dict] = []
    try:
        for i in range(args.repeat):
            ds, truth = work / f"ds{i}", work / f"truth{i}"
            for p in (ds, truth, work / f"an{i}", work / f"cl{i}", work / f"run{i}"):
                shutil.rmtree(p, ignore_errors=True)
            stages["simulate"].append(timed_run([bt, "simulate", *sc, "-o", str(ds), "--quiet"])[:2])
            shutil.move(str(ds / "truth"), str(truth))  # the analysis runs with truth/ out of the dataset
            stages["analyze"].append(timed_run([bt, "analyze", str(ds), "-o", str(work / f"an{i}"), "--quiet"])[:2])
            stages["close-loop"].append(timed_run([bt, "close-loop", str(ds), "-o", str(work / f"cl{i}"),
                                                   "--quiet"])[:2])
            stages["run"].append(timed_run([bt, "run", *sc, "-o", str(work / f"run{i}"), "--quiet"])[:2])
            io.append(last_json(timed_run([py, str(HERE / "io_floor.py"), str(ds), "--json"], capture=True)[2]))
            # the eccentricity step alone (serial and in threads) against decode + Otsu + label, one process
            ecc.append(last_json(timed_run([py, str(HERE / "ecc_bench.py"), str(ds), "--repeat", "2", "--json"],
                                           capture=True)[2])["cases"])
            # inside one close-loop process: the tracing, the report and the bench picture on their own
            parts.append(last_json(timed_run([py, str(HERE / "report_bench.py"), str(ds), "-o", str(work / f"rb{i}"),
                                              "--close-loop", "--json"], capture=True)[2])["parts"])
        # the amounts of work of one simulate (hence of run's): poses, servo steps, frames
        counts = last_json(timed_run([py, str(HERE / "run_parts.py"), *sc, "--json"], capture=True)[2])
        rf = last_json(timed_run([py, str(HERE / "render_floor.py"), "--json"], capture=True)[2])
        pf = last_json(timed_run([py, str(HERE / "physics_floor.py"), *sc, "--json"], capture=True)[2])
        sv = _servo(sc)
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)
    load1 = os.getloadavg()

    def med(xs: list[float]) -> float:
        return float(statistics.median(xs))

    wall = {k: med([w for w, _ in v]) for k, v in stages.items()}
    cpu = {k: med([c for _, c in v]) for k, v in stages.items()}
    n = int(io[0]["frames"])
    io_w = {k: med([d["wall_s"][k] for d in io]) for k in ("decode", "otsu", "label", "encode")}
    io_c = {k: med([d["cpu_s"][k] for d in io]) for k in ("decode", "otsu", "label", "encode")}
    floor_io_w, floor_io_c = sum(io_w.values()), sum(io_c.values())
    floor_an_w = io_w["decode"] + io_w["otsu"] + io_w["label"]
    floor_an_c = io_c["decode"] + io_c["otsu"] + io_c["label"]
    floor_sim_w = n * (rf["floor_render_s"] + rf["floor_sensor_s"]) + io_w["encode"]
    floor_sim_c = n * (rf["floor_render_cpu_s"] + rf["floor_sensor_cpu_s"]) + io_c["encode"]
    tr_w, tr_c = wall["close-loop"] - wall["analyze"], cpu["close-loop"] - cpu["analyze"]

    def part(name: str) -> tuple[float, float]:
        got = [d[name] for d in parts if name in d]
        return (med([g["wall_s"] for g in got]), med([g["cpu_s"] for g in got])) if got else (float("nan"),) * 2

    tin_w, tin_c = part("close the loop (tracing + model after)")
    rep_w, rep_c = part("report (all figures + HTML)")
    pic_w, pic_c = part("bench picture (figure built)")

    def ecc_case(pick) -> tuple[float, float]:
        got = [next(v for k, v in d.items() if pick(k)) for d in ecc]
        return med([g["wall_s"] for g in got]), med([g["cpu_s"] for g in got])

    es_w, es_c = ecc_case(lambda k: k == "step, serial")
    et_w, et_c = ecc_case(lambda k: k.startswith("step, ") and k != "step, serial")
    ef_w, ef_c = ecc_case(lambda k: k.startswith("floor"))

    rows = [
        ("simulate", wall["simulate"], cpu["simulate"], "frames×(render+sensor)+encode", floor_sim_w, floor_sim_c),
        ("analyze", wall["analyze"], cpu["analyze"], "decode+Otsu+label", floor_an_w, floor_an_c),
        ("  eccentricity step, serial", es_w, es_c, "decode+Otsu+label (same process)", ef_w, ef_c),
        ("  eccentricity step, threads", et_w, et_c, "decode+Otsu+label (same process)", ef_w, ef_c),
        ("close-loop", wall["close-loop"], cpu["close-loop"], "decode+Otsu+label", floor_an_w, floor_an_c),
        ("  tracing (close-loop − analyze)", tr_w, tr_c, "target 1 s", 1.0, 1.0),
        ("  tracing, inside one process", tin_w, tin_c, "target 1 s", 1.0, 1.0),
        ("  report (figures + HTML), same", rep_w, rep_c, "decode+Otsu+label", floor_an_w, floor_an_c),
        ("  bench picture, same", pic_w, pic_c, "decode+Otsu+label", floor_an_w, floor_an_c),
        ("run", wall["run"], cpu["run"], "I/O floor", floor_io_w, floor_io_c),
        ("render of a frame", rf["twin_render_s"], rf["twin_render_cpu_s"], "exact-area numpy (same quality)",
         rf["floor_render_s"], rf["floor_render_cpu_s"]),
        ("sensor model of a frame", rf["twin_sensor_s"], rf["twin_sensor_cpu_s"], "cv2 blur+noise+vignetting",
         rf["floor_sensor_s"], rf["floor_sensor_cpu_s"]),
    ]
    print(f"scenario {args.scenario or 'jia2019 (embedded default)'}, {n} CCD frames, median of {args.repeat}; "
          f"{os.cpu_count()} cores; load average {load0[0]:.1f} before, {load1[0]:.1f} after: wall figures "
          "were taken under load (shared machine), CPU = user + system of the process and its children")
    print(f"{'stage':34s} {'wall s':>8s} {'CPU s':>8s}   {'floor':31s} {'wall s':>7s} {'CPU s':>7s} "
          f"{'×wall':>6s} {'×CPU':>6s}")
    for name, w, c, fname, fw, fc in rows:
        print(f"{name:34s} {w:8.3f} {c:8.3f}   {fname:31s} {fw:7.3f} {fc:7.3f} {w / fw:6.2f} {c / fc:6.2f}")
    print(f"I/O floor over {n} frames (one process, work only): "
          + ", ".join(f"{k} {io_w[k]:.3f} s" for k in io_w)
          + f"; whole process incl. start and imports {med([d['process_wall_s'] for d in io]):.2f} s wall")
    print(f"render: twin backend {rf['twin_backend']}, line-end error ≤ {rf['twin_end_error_px']:.4f} px; "
          f"floor ≤ {rf['floor_end_error_px']:.4f} px (against the exact analytic coverage)")
    print(f"physics: {pf['poses']} poses of the α grid ({pf['stops']} stops), twin {pf['twin_us_per_pose']:.1f} µs/pose "
          f"(Newton {pf['newton_twin']:.2f} iterations), closed form {pf['floor_us_per_pose']:.1f} µs/pose: "
          f"{pf['ratio']:.2f}× (target ≤ 2), CPU; servo: {sv['servo_steps_s']:,.0f} steps/s against raw mj_step "
          f"{sv['raw_steps_s']:,.0f}: {sv['ratio']:.2f}× (target ≤ 2)")
    print(f"Goal (issue #17): run ≤ 3× I/O floor: {wall['run'] / floor_io_w:.2f}× wall, "
          f"{cpu['run'] / floor_io_c:.2f}× CPU")

    # issue #36: every part of run against its own floor (CPU s), with the amounts of run's own work
    poses = counts["poses_run"] + counts["poses_grid"]
    steps = counts["servo_steps"]
    run_parts = [
        # run's own I/O is spread over its steps (no separate figure): its floor stands for it
        ("I/O (decode+Otsu+label+encode)*", f"{n} frames", floor_io_c, floor_io_c),
        ("render + sensor", f"{n} frames", n * (rf["twin_render_cpu_s"] + rf["twin_sensor_cpu_s"]),
         n * (rf["floor_render_cpu_s"] + rf["floor_sensor_cpu_s"])),
        ("statics (run + α grid)", f"{counts['poses_run']}+{counts['poses_grid']} poses",
         poses * pf["twin_us_per_pose"] * 1e-6, poses * pf["floor_us_per_pose"] * 1e-6),
        ("servo (mj_step)", f"{steps:,} steps", steps / sv["servo_steps_s"], steps / sv["raw_steps_s"]),
        ("tracing", "close-loop − analyze", tr_c, tin_c),
    ]
    print(f"\nParts of run (issue #36), CPU s: the part at the twin's measured rate and at its floor's, both "
          f"measured in this run; load average {load0[0]:.1f} before, {load1[0]:.1f} after")
    print(f"{'part':32s} {'amount':22s} {'twin CPU s':>10s} {'floor CPU s':>11s} {'×':>6s}")
    for name, amount, tw, fl in run_parts:
        print(f"{name:32s} {amount:22s} {tw:10.2f} {fl:11.2f} {tw / fl:6.2f}")
    sum_floor = sum(fl for *_, fl in run_parts)
    sum_twin = sum(tw for _, _, tw, _ in run_parts)
    print(f"{'sum':55s} {sum_twin:10.2f} {sum_floor:11.2f}   (* run's own I/O is not separable: its floor)")
    print(f"run: {cpu['run']:.2f} s CPU, {wall['run']:.2f} s wall. CPU / sum of floors {cpu['run'] / sum_floor:.2f} "
          f"(goal ≤ 1.5, stretch 1.2); CPU / sum of the parts at the twin's rates {cpu['run'] / sum_twin:.2f} "
          f"(the rest: imports, process starts, analysis beyond decode+label, tables, report); wall / CPU "
          f"{wall['run'] / cpu['run']:.2f} (goal ≤ 0.6 on 2 cores); statics {pf['ratio']:.2f}× their closed form "
          f"(goal ≤ 2)")
    if args.json:
        print(json.dumps({"wall_s": wall, "cpu_s": cpu, "in_process": parts, "io_floor": {"wall_s": io_w, "cpu_s": io_c},
                          "render_floor": rf, "physics_floor": pf, "servo": sv, "eccentricity_step": ecc,
                          "load_average": [load0[0], load1[0]], "frames": n, "counts": counts,
                          "run_parts": {name: {"twin_cpu_s": tw, "floor_cpu_s": fl} for name, _, tw, fl in run_parts},
                          "run_cpu_over_floors": cpu["run"] / sum_floor, "run_wall_over_cpu": wall["run"] / cpu["run"]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
