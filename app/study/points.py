"""Point functions of a design study: one resolved scenario (+ repetition) -> a dict of outputs.

Why a separate module: the runner (``execution.py``) only schedules, caches and tabulates; what a
point *costs* is decided here, by fidelity, so that a study whose outputs need no images and no
dynamics never pays for them:

- ``physics``: build the twin's ``Bench`` (MuJoCo, quasi-static poses) and read the posed disk
  with exact trigonometry. Outputs: ``PHYSICS_OUTPUTS``. Milliseconds to a second per point.
- ``full``: the whole simulate → analyze pipeline (``app/run.py``: rendered CCD images, every
  instrument, the analysis of the dataset it wrote). Outputs: ``run.FULL_OUTPUTS`` by name (measured,
  predicted, residual, uncertainty, eccentricity, true α from the twin's truth),
  ``identified.<effect>`` and any number in the pipeline's ``results.json`` written
  ``results.<dotted.path>``. The close-the-loop step runs only when an output needs it
  (``full+close_loop``). Seconds to tens of seconds per repetition. Repetition k simulates the
  scenario with ``scenario.seed = rep_seed[k]`` (a new realisation of everything seeded: the same
  across points, common random numbers); physics outputs of a full study are computed on that same
  realisation (run 0), so every row describes one simulated bench.

Point functions are module-level (picklable by reference) and build every MuJoCo object inside
the worker process: MuJoCo models and data cannot be pickled. A small per-process cache keeps the
last benches so that the repetitions of one point share one model.

A point function has the signature ``fn(task: dict) -> list[dict]``: ``task`` holds
``scenario`` (a validated ``Scenario``), ``reps`` (repetition indices), ``rep_seeds``
(``numpy.random.SeedSequence([study seed, rep])`` states), ``angles`` (shaft positions per turn),
``outputs`` (the study's output names) and, for ``full``, ``order`` and ``close_loop``; it returns
one dict of outputs per repetition, in order.
"""

from __future__ import annotations

import importlib
import math
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np

from benchtwin.units import ARCSEC, UM

from benchtwin.app import run as _run

# name -> what it is (units in the name; docs/studies.md lists them too).
PHYSICS_OUTPUTS: dict[str, str] = {
    "angle_error_pv_arcsec": "peak-to-valley over one turn of the encoder error α = reading − true "
                             "angle (mean of the heads' readings), exact reading of the posed disk",
    "angle_error_rms_arcsec": "RMS about the mean of the same α over one turn (the index offset is "
                              "arbitrary, so the mean is removed)",
    "disk_radial_motion_pv_um": "largest peak-to-valley, over all fixed sensitive directions in the "
                                "disk plane, of the disk's radial motion over one turn",
    "disk_motion_x_pv_um": "peak-to-valley of the disk's motion along lab X (the direction that "
                           "changes head 1's reading: α ≈ −δx/r)",
    "disk_motion_y_pv_um": "peak-to-valley of the disk's motion along lab Y (towards head 1)",
    "disk_tilt_max_arcsec": "largest angle between the disk normal and the lab z axis over one turn",
}

FULL_PREFIX = "results."
# The simulate -> analyze entry point (module, function), app/run.py:
#   simulate_and_analyze(scenario: Scenario, out_dir: pathlib.Path, rep_seed: int,
#                        progress: bool = False, *, order=10, close_loop=True) -> dict  # results.json
FULL_ENTRY_POINT = ("benchtwin.app.run", "simulate_and_analyze")
FIDELITY_ORDER = ("physics", "full", "full+close_loop")  # cheapest first

_BENCHES: OrderedDict[str, Any] = OrderedDict()
_BENCH_CACHE_SIZE = 4


def output_fidelity(output: str) -> str:
    """The cheapest fidelity that can compute ``output`` (one of ``FIDELITY_ORDER``); ``KeyError``
    for an unknown name."""
    if output in PHYSICS_OUTPUTS:
        return "physics"
    if _run.is_full_output(output) or (output.startswith(FULL_PREFIX) and len(output) > len(FULL_PREFIX)):
        return "full+close_loop" if _run.needs_close_loop(output) else "full"
    raise KeyError(output)


def full_entry_point() -> Callable[..., dict[str, Any]]:
    """The simulate → analyze function (``FULL_ENTRY_POINT``)."""
    mod, fn = FULL_ENTRY_POINT
    return getattr(importlib.import_module(mod), fn)


# ----------------------------------------------------------------------------------- physics


def _bench_for(task: dict) -> Any:
    """One ``Bench`` per resolved scenario per worker process (reps of a point share it)."""
    key = task["scenario_key"]
    if key in _BENCHES:
        _BENCHES.move_to_end(key)
        return _BENCHES[key]
    from benchtwin.twin.physics import Bench  # MuJoCo is built here, inside the worker

    bench = Bench(task["scenario"])
    _BENCHES[key] = bench
    while len(_BENCHES) > _BENCH_CACHE_SIZE:
        _BENCHES.popitem(last=False)
    return bench


def physics_point(task: dict) -> list[dict[str, float]]:
    """Exact encoder error and disk motion from the twin's posed disk, one dict per repetition."""
    sc = task["scenario"]
    bench = _bench_for(task)
    n = int(task["angles"])
    angles = 2.0 * math.pi * np.arange(n) / n
    r = float(sc["bench"]["optical_radius"])
    heads = np.asarray(sc["bench"]["heads"], dtype=float)
    dwell = float(sc["procedure"]["dwell"])
    out = []
    for rep in task["reps"]:
        if hasattr(bench, "reset_path"):   # each repetition its own run of the bench's path
            bench.reset_path(run=int(rep))
        err = np.empty(n)
        tilt = np.empty(n)
        axis = np.full((n, 2), np.nan)
        for i, a in enumerate(angles):
            pose = bench.pose_at(float(a), rep=int(rep), t_s=i * dwell, direction=+1)
            err[i] = _exact_reading_error_rad(pose, r, heads).mean()
            nz = float(np.clip(pose.disk.R[2, 2], -1.0, 1.0))
            tilt[i] = math.acos(nz)
            if "axis_disk_plane_m" in pose.extra:  # same solve: no second pass over the turn
                axis[i] = pose.extra["axis_disk_plane_m"]
        if np.isnan(axis).any():
            dx, dy = (np.asarray(v, float) for v in bench.disk_plane_motion(angles, int(rep)))
        else:
            dx, dy = axis[:, 0], axis[:, 1]
        out.append({
            "angle_error_pv_arcsec": float(np.ptp(err)) / ARCSEC,
            "angle_error_rms_arcsec": float(np.sqrt(np.mean((err - err.mean()) ** 2))) / ARCSEC,
            "disk_radial_motion_pv_um": _worst_direction_pv(dx, dy) / UM,
            "disk_motion_x_pv_um": float(np.ptp(dx)) / UM,
            "disk_motion_y_pv_um": float(np.ptp(dy)) / UM,
            "disk_tilt_max_arcsec": float(tilt.max()) / ARCSEC,
        })
    return out


def _exact_reading_error_rad(pose: Any, r: float, heads_rad: np.ndarray) -> np.ndarray:
    """Exact reading error of each head (rad) for one posed disk.

    Head j sits at lab azimuth a_j = 90° + ψ_j (head 1 on +Y, docs/conventions.md) at radius r and
    looks along lab z. Its line of sight meets the disk plane at q; the graduation under it is the
    polar angle g of q in the disk body frame, about the disk's geometric centre. At the ideal pose
    g = a_j − t, so the head reads a_j − g, and its error is (a_j − g) − t with t the true shaft
    angle. No small-angle approximation: the intersection and atan2 are exact.
    """
    c = np.asarray(pose.disk.pos, float)
    R = np.asarray(pose.disk.R, float)
    n = R[:, 2]
    a = 0.5 * math.pi + np.asarray(heads_rad, float)
    p0 = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)], axis=1)  # (H, 3)
    s = ((c - p0) @ n) / n[2]  # distance along +z to the disk plane
    q = p0 + s[:, None] * np.array([0.0, 0.0, 1.0])
    b = (q - c) @ R  # body frame
    g = np.arctan2(b[:, 1], b[:, 0])
    err = (a - g) - float(pose.shaft_angle_rad)
    return (err + math.pi) % (2.0 * math.pi) - math.pi


def _worst_direction_pv(dx: np.ndarray, dy: np.ndarray, n_dir: int = 180) -> float:
    """Largest peak-to-valley of u·(dx, dy) over fixed unit directions u (radial error motion)."""
    phi = np.pi * np.arange(n_dir) / n_dir
    proj = np.outer(np.cos(phi), dx) + np.outer(np.sin(phi), dy)
    return float(np.max(np.ptp(proj, axis=1)))


# -------------------------------------------------------------------------------------- full


def full_point(task: dict) -> list[dict[str, float]]:
    """The whole simulate → analyze pipeline, one run per repetition (``scenario.seed`` = its
    rep seed), in a temporary directory; outputs by name (``run.FULL_OUTPUTS``,
    ``identified.<effect>``), ``results.<path>`` keys, and physics outputs of the same realisation.

    ``task`` also holds ``order`` (the analysis' Fourier order) and ``close_loop`` (run the
    close-the-loop step: only when an output needs it)."""
    import tempfile
    from pathlib import Path

    fn = full_entry_point()
    outputs = list(task["outputs"])
    generic = [o for o in outputs if o.startswith(FULL_PREFIX)]
    named = [o for o in outputs if _run.is_full_output(o)]
    phys = [o for o in outputs if o in PHYSICS_OUTPUTS]
    out = []
    for rep, seed in zip(task["reps"], task["rep_seeds"]):
        with tempfile.TemporaryDirectory(prefix="benchtwin-study-") as tmp:
            results = fn(task["scenario"], Path(tmp), rep_seed=int(seed), progress=False,
                         order=int(task.get("order", 10)), close_loop=bool(task.get("close_loop", True)))
            row = _run.study_outputs(results, Path(tmp), named)
        for o in generic:
            node: Any = results
            for part in o[len(FULL_PREFIX):].split("."):
                if isinstance(node, list) and part.isdigit() and int(part) < len(node):
                    node = node[int(part)]
                elif isinstance(node, dict) and part in node:
                    node = node[part]
                else:
                    raise _run.RunOutputError(f"output {o!r}: the pipeline's results have no key {part!r}")
            if isinstance(node, bool) or not isinstance(node, (int, float)):
                raise _run.RunOutputError(f"output {o!r}: results.json holds {type(node).__name__} there, "
                                          "expected a number")
            row[o] = float(node)
        if phys:
            sc = task["scenario"]
            sc_k = sc.with_overrides({"scenario.seed": int(seed)}) if int(sc.seed) != int(seed) else sc
            ptask = {**task, "scenario": sc_k, "scenario_key": f"{task['scenario_key']}/seed{int(seed)}",
                     "reps": [0], "rep_seeds": [int(seed)]}
            row.update({o: v for o, v in physics_point(ptask)[0].items() if o in phys})
        out.append(row)
    return out
