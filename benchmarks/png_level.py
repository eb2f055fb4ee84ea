"""PNG compression of the CCD frames: file size against encode and decode time, per zlib level.

Issue #17 asks for "a PNG compression level chosen by measuring size against time" for the
dataset writer (analysis/dataset.py ``write_image``: ``cv2.imencode('.png', frame)``, OpenCV's
default parameters). PNG is lossless: every level decodes to the same pixels, so the level changes
a dataset's bytes and speed, never its analysis.

Prints, for OpenCV's default and for ``IMWRITE_PNG_COMPRESSION`` 0…9, the mean file size and the
mean encode and decode time per frame (CPU and wall), over every ``--every``-th frame of a dataset.

Usage: ``.venv/bin/python benchmarks/png_level.py DATASET [--every 5]``
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--every", type=int, default=5)
    args = ap.parse_args(argv)

    import cv2
    import numpy as np

    with (args.dataset / "ccd" / "index.csv").open(newline="") as fh:
        files = [row["file"] for row in csv.DictReader(fh)][:: max(args.every, 1)]
    imgs = [cv2.imread(str(args.dataset / "ccd" / f), cv2.IMREAD_UNCHANGED) for f in files]
    print(f"{len(imgs)} frames {imgs[0].shape[1]}×{imgs[0].shape[0]} {imgs[0].dtype}, OpenCV {cv2.__version__}")
    print(f"{'level':>8s} {'kB/frame':>9s} {'encode ms CPU':>14s} {'wall':>7s} {'decode ms CPU':>14s} {'wall':>7s}")
    for lvl in (None, *range(10)):
        par = [] if lvl is None else [cv2.IMWRITE_PNG_COMPRESSION, lvl]
        c0, w0 = time.process_time(), time.perf_counter()
        pngs = [cv2.imencode(".png", im, par)[1] for im in imgs]
        ce, we = time.process_time() - c0, time.perf_counter() - w0
        c0, w0 = time.process_time(), time.perf_counter()
        back = [cv2.imdecode(p, cv2.IMREAD_UNCHANGED) for p in pngs]
        cd, wd = time.process_time() - c0, time.perf_counter() - w0
        assert all(np.array_equal(a, b) for a, b in zip(imgs, back)), "PNG must be lossless"
        n = len(imgs)
        print(f"{'default' if lvl is None else lvl:>8} {np.mean([p.size for p in pngs]) / 1e3:9.1f} "
              f"{ce / n * 1e3:14.1f} {we / n * 1e3:7.1f} {cd / n * 1e3:14.1f} {wd / n * 1e3:7.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
