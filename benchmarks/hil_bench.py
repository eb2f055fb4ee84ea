"""Hardware-in-the-loop benchmark: an emulated acquisition of N readings (radial-motion stops of
the jia2019 bench, encoder + two probes per reading, Zaber stage moves) through the real drivers
on pseudo-terminals (emulators and acquisition in this one process: both are traced). Prints
throughput and memory per block of readings, and the flatness figures: traced-memory growth per
reading from the first block to the last, and the ratio of the last block's rate to the second's
(the first includes start-up), and the process CPU time per reading (emulator threads included:
what the rate would be on an idle machine). Both should stay flat: the runner streams rows to
the tables.

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
            ru = resource.getrusage(resource.RUSAGE_SELF)
            marks.append((n[0], time.perf_counter(), cur, ru.ru_maxrss, ru.ru_utime + ru.ru_stime))

    with EmulationSession(sc) as s:
        bench = s.start(d / "emu")
        bench_text = bench.read_text()
        # radial motion only: drop the polygon procedure from the generated bench file
        bench.write_text(bench_text.split("[[procedure]]\ntype = \"polygon_shift_angle\"")[0])
        acquire(bench, d / "ds", progress=False, on_row=on_row)
    prev_n, prev_t = 0, t0
    rates = []
    prev_cpu = marks[0][4] if marks else 0.0
    print(f"{'readings':>9} {'rows/s':>8} {'CPU ms/row':>10} {'traced MiB':>11} {'maxrss MiB':>11}")
    for k, t, cur, rss, cpu in marks:
        rates.append((k - prev_n) / (t - prev_t))
        cpu_ms = "" if k == marks[0][0] else f"{1e3 * (cpu - prev_cpu) / (k - prev_n):.2f}"
        print(f"{k:9d} {rates[-1]:8.1f} {cpu_ms:>10} {cur / 2**20:11.2f} {rss / 1024:11.1f}")
        prev_n, prev_t, prev_cpu = k, t, cpu
    (k0, _, c0, r0, _), (k1, _, c1, r1, _) = marks[0], marks[-1]
    print(f"traced growth {(c1 - c0) / (k1 - k0):.1f} B/reading ({(c1 - c0) / 2**20:+.2f} MiB over {k1 - k0} "
          f"readings); max RSS {r0 / 1024:.1f} -> {r1 / 1024:.1f} MiB")
    if len(rates) > 2:
        print(f"rate last/second block {rates[-1] / rates[1]:.2f}; min/max over blocks 2.. "
              f"{min(rates[1:]):.1f}/{max(rates[1:]):.1f} rows/s")
    print(f"total {n[0]} readings in {time.perf_counter() - t0:.1f} s; dataset {d / 'ds'}")


if __name__ == "__main__":
    main()
