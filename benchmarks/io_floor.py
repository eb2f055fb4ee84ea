"""I/O floor of the CCD image analysis: the least any analysis of a dataset's frames must do.

Issue #17: the main job is measured against "decode, Otsu, label and PNG-encode each of the
dataset's frames once, in one process". This script does exactly that with bare OpenCV calls, once
per frame listed in ``ccd/index.csv`` (in its order, one process, no pool):

- decode: ``cv2.imdecode`` of the file's bytes (IMREAD_UNCHANGED, as the dataset reader does);
- Otsu: ``cv2.threshold(..., THRESH_OTSU)`` (16-bit frames are scaled to 8 bit first: OpenCV's Otsu
  takes 8-bit input; the scaling is counted);
- label: ``cv2.connectedComponentsWithStats`` (8-connectivity, as analysis/eccentricity.py);
- PNG-encode: ``cv2.imencode('.png', frame)`` at OpenCV's default level (the dataset writer's).

Prints one line per step (seconds, wall and CPU of this process) and, with ``--json``, one JSON
object on the last line (read by benchmarks/run_bench.py). ``process_*`` figures include the
interpreter start and the imports (measured from the process start time), ``ops_*`` only the work.

Usage: ``.venv/bin/python benchmarks/io_floor.py DATASET [--json]``
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import sys
import time
from pathlib import Path


def _process_start_wall() -> float:
    """Wall-clock time this process started (Linux /proc), for the whole-process figure."""
    try:
        ticks = os.sysconf("SC_CLK_TCK")
        start = int(Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[19])
        boot = next(float(line.split()[1]) for line in Path("/proc/stat").read_text().splitlines()
                    if line.startswith("btime"))
        return boot + start / ticks
    except (OSError, StopIteration, ValueError, IndexError):
        return time.time()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--json", action="store_true", help="print a JSON summary as the last line")
    args = ap.parse_args(argv)

    import cv2
    import numpy as np

    t_start = _process_start_wall()
    idx = args.dataset / "ccd" / "index.csv"
    with idx.open(newline="") as fh:
        files = [row["file"] for row in csv.DictReader(fh)]
    paths = [(args.dataset / "ccd" / f) if (args.dataset / "ccd" / f).is_file() else args.dataset / f for f in files]

    steps = ("decode", "otsu", "label", "encode")
    wall = dict.fromkeys(steps, 0.0)
    cpu = dict.fromkeys(steps, 0.0)
    c_ops0, w_ops0 = time.process_time(), time.perf_counter()
    for p in paths:
        data = np.fromfile(p, dtype=np.uint8)
        w, c = time.perf_counter(), time.process_time()
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        w1, c1 = time.perf_counter(), time.process_time()
        wall["decode"] += w1 - w
        cpu["decode"] += c1 - c
        img8 = img if img.dtype == np.uint8 else cv2.convertScaleAbs(img, alpha=255.0 / 65535.0)
        _, binary = cv2.threshold(img8, 0, 1, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
        w2, c2 = time.perf_counter(), time.process_time()
        wall["otsu"] += w2 - w1
        cpu["otsu"] += c2 - c1
        cv2.connectedComponentsWithStats(binary, connectivity=8)
        w3, c3 = time.perf_counter(), time.process_time()
        wall["label"] += w3 - w2
        cpu["label"] += c3 - c2
        ok, _png = cv2.imencode(".png", img)
        w4, c4 = time.perf_counter(), time.process_time()
        wall["encode"] += w4 - w3
        cpu["encode"] += c4 - c3
        if not ok:
            raise SystemExit(f"{p}: PNG encoding failed")
    ops_wall, ops_cpu = time.perf_counter() - w_ops0, time.process_time() - c_ops0
    ru = resource.getrusage(resource.RUSAGE_SELF)
    out = {
        "frames": len(paths), "threads": cv2.getNumThreads(),
        "wall_s": wall, "cpu_s": cpu, "ops_wall_s": ops_wall, "ops_cpu_s": ops_cpu,
        "process_wall_s": time.time() - t_start, "process_cpu_s": ru.ru_utime + ru.ru_stime,
    }
    for s in steps:
        print(f"{s:8s} {wall[s]:7.3f} s wall  {cpu[s]:7.3f} s CPU  ({wall[s] / max(len(paths), 1) * 1e3:6.1f} ms/frame)")
    print(f"{'all ops':8s} {ops_wall:7.3f} s wall  {ops_cpu:7.3f} s CPU  over {len(paths)} frames; whole process "
          f"{out['process_wall_s']:.3f} s wall, {out['process_cpu_s']:.3f} s CPU")
    if args.json:
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
