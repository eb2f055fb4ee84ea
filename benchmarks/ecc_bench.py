"""The eccentricity step (Jia 2019 sec. 4.2) on a dataset: serial and in N threads, against the floor.

Issue #17: the CCD image analysis should cost ≤ 2× "decode + label each frame once". Cases, each
timed ``--repeat`` times in turn (interleaved, so a shared machine's load hits them alike; medians
printed), wall and CPU (this process + its reaped children):

- ``step, serial``: ``step_eccentricity(..., workers=1)`` (every frame decoded once, its edges found
  once, analysed in its integer levels; the calling thread only);
- ``step, N threads``: ``step_eccentricity(..., workers=N)`` (default N = 2; analysis/parallel.py:
  frames analysed in N threads while this thread reads them);
- ``floor``: decode + Otsu + label of each frame once (bare OpenCV, as benchmarks/io_floor.py).
- ``two-pass`` (``--two-pass``): every frame read and its edges found twice (``pixel_scale_um`` per
  frame, then ``d_ref_px`` with the fixed radius), the step before decode-once / edges-once; a slow
  independent path whose d_ref is checked too.

The d_ref values of all cases (and so the frames they keep) are checked equal (bit for bit) before
anything is printed. The load average (1 min) before and after is printed: on a shared machine
wall times mean little above a load of ~1 per core; compare CPU.

The step before this code (another checkout, e.g. main) is measured by running its own
``ecc_bench.py`` from its own virtualenv, alternating with this one.

Usage: ``.venv/bin/python benchmarks/ecc_bench.py DATASET [--repeat 3] [--workers 2] [--two-pass] [--json]``
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from benchtwin.analysis import eccentricity as ecc
from benchtwin.analysis.dataset import open_dataset
from benchtwin.analysis.pipeline import step_eccentricity


def two_pass(ds) -> np.ndarray:
    """The former step_eccentricity's image work (commit 2fd56d6), without its bookkeeping."""
    period = ds.bench["grating_period_um"]
    ref = tuple(ds.manifest["ccd"]["reference_px"])
    scales, bad = [], set()
    for _k, _t, image, f in ds.ccd_frames():
        try:
            scales.append(ecc.pixel_scale_um(image, period, name=f)["pixel_um"])
        except ecc.ImageAnalysisError:
            bad.add(f)
    scale = float(np.median(scales))
    radius_px = ds.bench["scale_edge_radius_mm"] * 1000.0 / scale
    d = []
    for _k, _t, image, f in ds.ccd_frames():
        if f in bad:
            continue
        try:
            d.append(ecc.d_ref_px(image, ref, radius_px=radius_px, name=f)["d_ref_px"])
        except ecc.ImageAnalysisError:
            pass
    return np.asarray(d) * scale


def floor(ds) -> None:
    import cv2

    for _k, _t, image, _f in ds.ccd_frames():
        _, b = cv2.threshold(image if image.dtype == np.uint8 else cv2.convertScaleAbs(image, alpha=255 / 65535),
                             0, 1, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
        cv2.connectedComponentsWithStats(b, connectivity=8)


def cpu_all() -> float:
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--two-pass", action="store_true", help="also time (and check d_ref against) the two-pass path")
    ap.add_argument("--json", action="store_true", help="print a JSON summary as the last line")
    args = ap.parse_args(argv)
    ds = open_dataset(args.dataset)

    cases = {
        "step, serial": lambda: np.asarray(step_eccentricity(ds, 10, False, workers=1).frames.d_ref_um),
        f"step, {args.workers} threads": lambda: np.asarray(
            step_eccentricity(ds, 10, False, workers=args.workers).frames.d_ref_um),
        "floor: decode+Otsu+label once": lambda: floor(ds),
    }
    if args.two_pass:
        cases["two-pass (edges found twice)"] = lambda: two_pass(ds)
    load0 = os.getloadavg()[0]
    times: dict[str, list[tuple[float, float]]] = {k: [] for k in cases}
    results: dict[str, np.ndarray] = {}
    for _ in range(args.repeat):
        for name, fn in cases.items():
            w, c = time.perf_counter(), cpu_all()
            out = fn()
            times[name].append((time.perf_counter() - w, cpu_all() - c))
            if out is not None:
                results[name] = out
    load1 = os.getloadavg()[0]
    ref = results["step, serial"]
    for name, r in results.items():
        if not np.array_equal(r, ref):
            raise SystemExit(f"{name}: d_ref differs from the serial step's")
    fl = statistics.median(c for _, c in times["floor: decode+Otsu+label once"])
    flw = statistics.median(w for w, _ in times["floor: decode+Otsu+label once"])
    print(f"{args.dataset}: {len(ref)} frames used; median of {args.repeat}, interleaved; d_ref bit-identical "
          f"in all cases; load average {load0:.1f} → {load1:.1f}")
    print(f"{'case':34s} {'wall s':>8s} {'CPU s':>8s} {'×floor wall':>12s} {'×floor CPU':>11s}")
    summary = {}
    for name, ts in times.items():
        w = statistics.median(t for t, _ in ts)
        c = statistics.median(t for _, t in ts)
        summary[name] = {"wall_s": w, "cpu_s": c, "runs": ts}
        print(f"{name:34s} {w:8.2f} {c:8.2f} {w / flw:12.2f} {c / fl:11.2f}")
    if args.json:
        print(json.dumps({"load": [load0, load1], "cases": summary}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
