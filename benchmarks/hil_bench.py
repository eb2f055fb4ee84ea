"""Hardware-in-the-loop benchmark: an emulated acquisition of N readings (radial-motion stops of
the jia2019 bench, encoder + two probes per reading, Zaber stage moves) through the real drivers
on pseudo-terminals. Prints throughput and memory per block of readings: both should stay flat.

    .venv/bin/python benchmarks/hil_bench.py [--readings 10000] [--block 1000]
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
import tracemalloc
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--readings", type=int, default=10000)
    ap.add_argument("--block", type=int, default=1000)
    a = ap.parse_args()
    from benchtwin.hw.acquisition.acquire import acquire
    from benchtwin.twin.emulators.serve import EmulationSession
    from benchtwin.twin.scenario import load_scenario

    sc = load_scenario().with_overrides({"procedure.radial_positions": a.readings, "procedure.radial_reps": 1,
                                         "procedure.polygon_shifts": ["0 deg"], "procedure.ccd_step": "180 deg"})
    d = Path(tempfile.mkdtemp(prefix="hil-bench-"))
    bench_text = None
    tracemalloc.start()
    marks: list[tuple[int, float, int, int]] = []
    n = [0]
    t0 = time.perf_counter()

    def on_row(row, _):
        if row["tag"].get("procedure") != "radial_motion":
            return
        n[0] += 1
        if n[0] % a.block == 0:
            cur, _peak = tracemalloc.get_traced_memory()
            marks.append((n[0], time.perf_counter(), cur, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss))

    with EmulationSession(sc) as s:
        bench = s.start(d / "emu")
        bench_text = bench.read_text()
        # radial motion only: drop the polygon procedure from the generated bench file
        bench.write_text(bench_text.split("[[procedure]]\ntype = \"polygon_shift_angle\"")[0])
        acquire(bench, d / "ds", progress=False, on_row=on_row)
    prev_n, prev_t = 0, t0
    print(f"{'readings':>9} {'rows/s':>8} {'traced MiB':>11} {'maxrss MiB':>11}")
    for k, t, cur, rss in marks:
        print(f"{k:9d} {(k - prev_n) / (t - prev_t):8.1f} {cur / 2**20:11.2f} {rss / 1024:11.1f}")
        prev_n, prev_t = k, t
    print(f"total {n[0]} readings in {time.perf_counter() - t0:.1f} s; dataset {d / 'ds'}")


if __name__ == "__main__":
    main()
