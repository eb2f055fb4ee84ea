"""How much physics one ``simulate`` (hence one ``benchtwin run``) computes: its static poses and its servo's
physics steps, counted (issue 36: each part of ``run`` against its own floor, run_bench.py).

    .venv/bin/python benchmarks/run_parts.py [scenario.toml] [--json]

The scenario is simulated once in THIS process (``BENCHTWIN_FORK=0``: the settles, the truth's α grid
and the frames here, not in forked workers, so every call is counted; the dataset's bytes do not depend
on where they run, twin/simulate.py), with the analytic renderer (the frames' count, not their cost,
matters here) into a temporary folder. Counted, by wrapping the classes' methods:

- ``Bench.pose_at`` calls (static poses) and their Newton iterations, split into the run's and the
  truth's α grid's (``twin.simulate._alpha_grid``);
- ``DriveServo.settle`` calls and their ``mj_step`` calls (``Rest.steps``);
- the CCD frames (``ccd/img_*.png`` written).

No timing: run_bench.py multiplies these counts by the floors it measures in the same run (the closed
form's µs per pose, benchmarks/physics_floor.py; raw ``mj_step``'s steps per second,
benchmarks/servo_bench.py).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

os.environ["BENCHTWIN_FORK"] = "0"
os.environ["BENCHTWIN_SIM_FRAMES"] = "serial"


def count(scenario: str | None) -> dict:
    from benchtwin.twin import simulate as sim
    from benchtwin.twin.instruments.drive import DriveServo
    from benchtwin.twin.physics import Bench
    from benchtwin.twin.scenario import load_scenario

    n = {"poses_run": 0, "poses_grid": 0, "newton_run": 0, "newton_grid": 0, "settles": 0, "servo_steps": 0}
    in_grid = [False]
    pose_at, settle, alpha_grid = Bench.pose_at, DriveServo.settle, sim._alpha_grid

    def counted_pose_at(self, *a, **kw):
        p = pose_at(self, *a, **kw)
        where = "grid" if in_grid[0] else "run"
        n[f"poses_{where}"] += 1
        n[f"newton_{where}"] += self.last_iterations
        return p

    def counted_settle(self, *a, **kw):
        r = settle(self, *a, **kw)
        n["settles"] += 1
        n["servo_steps"] += r.steps
        return r

    def counted_grid(*a, **kw):
        in_grid[0] = True
        try:
            return alpha_grid(*a, **kw)
        finally:
            in_grid[0] = False

    Bench.pose_at, DriveServo.settle, sim._alpha_grid = counted_pose_at, counted_settle, counted_grid
    out = Path(tempfile.mkdtemp(prefix="benchtwin-run-parts-"))
    try:
        sc = load_scenario(scenario)
        sim.simulate(sc, out / "ds", progress=False, backend="analytic")
        n["frames"] = len(list((out / "ds" / "ccd").glob("img_*.png"))) if (out / "ds" / "ccd").is_dir() else 0
        n["scenario"] = sc.name
    finally:
        Bench.pose_at, DriveServo.settle, sim._alpha_grid = pose_at, settle, alpha_grid
        shutil.rmtree(out, ignore_errors=True)
    return n


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario", nargs="?", default=None, help="scenario TOML (default: the embedded jia2019)")
    ap.add_argument("--json", action="store_true", help="print a JSON summary as the last line")
    a = ap.parse_args(argv)
    n = count(a.scenario)
    print(f"scenario {n['scenario']}: static poses {n['poses_run']} in the run (Newton "
          f"{n['newton_run'] / max(n['poses_run'], 1):.2f}/pose) + {n['poses_grid']} in the truth's α grid "
          f"(Newton {n['newton_grid'] / max(n['poses_grid'], 1):.2f}/pose); servo: {n['settles']} settles, "
          f"{n['servo_steps']:,} mj_step calls; {n['frames']} CCD frames")
    if a.json:
        print(json.dumps(n))
    return 0


if __name__ == "__main__":
    sys.exit(main())
