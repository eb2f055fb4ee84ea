"""Step rate of the drive servo (twin/instruments/drive.py) against raw ``mj_step`` on the same model.

    .venv/bin/python benchmarks/servo_bench.py [scenario ...]

For each scenario: the drive train of its bench (models/drive.xml with the bench's inertia and
friction), then
- raw: ``mj_step(m, d, nstep=N)`` with a constant motor torque (no Python in the loop);
- servo: ``DriveServo.settle`` over a sequence of 1° stops (the count PID, Stribeck friction update
  and settle detection in Python once per servo sample, ``substeps`` physics steps per sample);
and prints physics steps per second of both and their ratio (raw / servo: the servo's overhead;
the target is ≤ 2, docs/benchmarks.md). Best of 3 repetitions each, in CPU time of this process (the
machine may be shared: wall time would count the other jobs).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def bench_one(path: Path, n_stops: int = 100, raw_steps: int = 100_000, reps: int = 3) -> dict:
    from benchtwin.twin.instruments.drive import DriveServo
    from benchtwin.twin.physics import Bench
    from benchtwin.twin.scenario import load_scenario

    sc = load_scenario(path)
    bench = Bench(sc)
    best_raw, best_servo, steps_per_stop = 0.0, 0.0, 0.0
    for _ in range(reps):
        s = DriveServo.sim_from_bench(sc, bench)
        m, d = s.model, s.data
        d.ctrl[0] = 1e-3
        t0 = time.process_time()
        mujoco.mj_step(m, d, nstep=raw_steps)
        best_raw = max(best_raw, raw_steps / (time.process_time() - t0))

        s = DriveServo.sim_from_bench(sc, bench)
        rng = np.random.default_rng(0)
        t0 = time.process_time()
        for _ in range(n_stops):
            s.settle(math.radians(1.0), math.radians(20.0), math.radians(40.0), rng.uniform(0.0, s.Ts), rng)
        wall = time.process_time() - t0
        best_servo = max(best_servo, s.total_steps / wall)
        steps_per_stop = s.total_steps / n_stops
    return {"scenario": sc.name, "raw_steps_s": best_raw, "servo_steps_s": best_servo,
            "ratio": best_raw / best_servo, "steps_per_stop": steps_per_stop,
            "ms_per_stop": steps_per_stop / best_servo * 1e3, "substeps": s.substeps,
            "timestep_s": m.opt.timestep}


def main(argv: list[str]) -> None:
    paths = [Path(a) for a in argv] or [ROOT / "scenarios" / "jia2019.toml", ROOT / "scenarios" / "hsieh2022.toml"]
    print(f"MuJoCo {mujoco.__version__}, numpy {np.__version__}")
    print("| scenario | raw mj_step (steps/s) | servo (steps/s) | ratio raw/servo | steps/stop | ms/stop |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for p in paths:
        r = bench_one(p)
        print(f"| {r['scenario']} | {r['raw_steps_s']:,.0f} | {r['servo_steps_s']:,.0f} | {r['ratio']:.2f} | "
              f"{r['steps_per_stop']:.0f} | {r['ms_per_stop']:.2f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
