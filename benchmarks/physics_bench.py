"""Speed of the twin's physics: poses per second and Newton iterations per pose.

Run: .venv/bin/python benchmarks/physics_bench.py [scenario.toml]
Prints one line per case; the numbers in docs/benchmarks.md ("Twin physics") come from here.
A pose = drive command -> static equilibrium of the 6 compliant DOFs (Newton, one mj_forward per
iteration) -> posed bodies (twin/physics.py).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from benchtwin.twin.physics import Bench
from benchtwin.twin.scenario import load_scenario


def main() -> None:
    sc = load_scenario(sys.argv[1] if len(sys.argv) > 1 else None)
    t0 = time.perf_counter()
    bench = Bench(sc)
    t_build = time.perf_counter() - t0
    print(f"scenario {sc.name}: build + axis-average centring {t_build * 1e3:.1f} ms")

    cases = [
        ("sweep 1 rev, 360 stops, +dir", np.linspace(0, 2 * np.pi, 360, endpoint=False), 1),
        ("sweep 3 reps x 360 stops", np.tile(np.linspace(0, 2 * np.pi, 360, endpoint=False), 3), 1),
        ("random angles (cold warm-start)", np.random.default_rng(0).uniform(0, 2 * np.pi, 2000), 1),
        ("alternating direction", np.linspace(0, 2 * np.pi, 1000), 0),
    ]
    for name, angles, direction in cases:
        bench.total_iterations = bench.n_poses = 0
        t0 = time.perf_counter()
        for i, th in enumerate(angles):
            d = direction if direction else (1 if i % 2 == 0 else -1)
            bench.pose_at(th, rep=i // 360, direction=d)
        dt = time.perf_counter() - t0
        it = bench.total_iterations / bench.n_poses
        print(f"{name:36s} {angles.size:5d} poses  {angles.size / dt:8.0f} poses/s  "
              f"{dt / angles.size * 1e6:6.1f} us/pose  {it:.2f} Newton iterations/pose")


if __name__ == "__main__":
    main()
