"""Before/after of the main job's commands, two checkouts interleaved (issue 36: docs/benchmarks.md's table).

    .venv/bin/python benchmarks/before_after.py --before /tmp/speed-base --after . --ref-case DIR \
        [--rounds 1] [--stages physics,run,simulate_jia2019,analyze,close_loop_ref,simulate_hsieh2022] \
        [--log results.jsonl]

Each stage is a fresh process of the checkout's own ``.venv`` (``benchtwin …`` with ``--quiet``, or a benchmark
script of that checkout), before and after alternately (who goes first alternates with the round), so a burst of
other people's work on the shared machine hits both alike. Per command: wall time, CPU time (user + system of the
process and all its descendants, ``resource.getrusage(RUSAGE_CHILDREN)``; a subreaper collects the frame
workers' forkserver, as run_bench.py does) and the 1-minute load average (``os.getloadavg``, i.e. ``uptime``)
before and after it. One JSON line per command in ``--log`` (so a long session keeps what it measured), and a
markdown table at the end.

Stages: ``physics`` (benchmarks/physics_floor.py on jia2019: the twin's µs per pose against the closed form, in
CPU time of one process); ``run`` (``benchtwin run``, the embedded jia2019); ``simulate_jia2019`` /
``simulate_hsieh2022``; ``analyze`` (the dataset of this round's ``simulate_jia2019`` of the same checkout, its
truth/ moved out); ``close_loop_ref`` (``benchtwin close-loop`` of one reference-generator case, ``--ref-case``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from run_bench import timed_run  # noqa: E402  (the subreaper is set on import)

STAGES = ("physics", "run", "simulate_jia2019", "analyze", "close_loop_ref", "simulate_hsieh2022")


def timed(cmd: list[str], cwd: Path) -> dict:
    """run_bench's timing of one command (its whole process tree's CPU), with the load around it."""
    load0 = os.getloadavg()[0]
    wall, cpu, out = timed_run(cmd, capture=True, cwd=cwd)
    return {"wall_s": wall, "cpu_s": cpu, "load": [load0, os.getloadavg()[0]], "stdout": out[-2000:]}


def command(stage: str, tree: Path, work: Path, ref_case: Path | None) -> list[str] | None:
    bt, py = str(tree / ".venv" / "bin" / "benchtwin"), str(tree / ".venv" / "bin" / "python")
    if stage == "physics":
        return [py, str(tree / "benchmarks" / "physics_floor.py"), str(tree / "scenarios" / "jia2019.toml"), "--json"]
    if stage == "run":
        return [bt, "run", "-o", str(work / "run"), "--quiet"]
    if stage.startswith("simulate_"):
        name = stage.split("_", 1)[1]
        return [bt, "simulate", str(tree / "scenarios" / f"{name}.toml"), "-o", str(work / name), "--quiet"]
    if stage == "analyze":
        ds = work / "jia2019"
        if not ds.is_dir():
            return None
        if (ds / "truth").is_dir():
            shutil.move(str(ds / "truth"), str(work / "jia2019_truth"))
        return [bt, "analyze", str(ds), "-o", str(work / "an"), "--quiet"]
    if stage == "close_loop_ref":
        return None if ref_case is None else [bt, "close-loop", str(ref_case), "-o", str(work / "cl_ref"), "--quiet"]
    raise ValueError(stage)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, required=True)
    ap.add_argument("--after", type=Path, required=True)
    ap.add_argument("--ref-case", type=Path, default=None, help="a reference-generator case folder (close-loop)")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--stages", default=",".join(STAGES))
    ap.add_argument("--log", type=Path, default=None, help="append one JSON line per command")
    a = ap.parse_args(argv)
    trees = {"before": a.before.resolve(), "after": a.after.resolve()}
    stages = [s for s in a.stages.split(",") if s]
    rows: list[dict] = []
    base = Path(tempfile.mkdtemp(prefix="benchtwin-before-after-"))
    try:
        for rnd in range(a.rounds):
            order = ["before", "after"] if rnd % 2 == 0 else ["after", "before"]
            for stage in stages:
                for side in order:
                    work = base / f"{side}{rnd}"
                    work.mkdir(exist_ok=True)
                    cmd = command(stage, trees[side], work, a.ref_case)
                    if cmd is None:
                        continue
                    r = timed(cmd, trees[side])
                    r.update(stage=stage, side=side, round=rnd, utc=time.strftime("%H:%M:%S", time.gmtime()))
                    if stage == "physics":
                        r["physics"] = json.loads(r["stdout"].strip().splitlines()[-1])
                    r.pop("stdout")
                    rows.append(r)
                    print(json.dumps(r), flush=True)
                    if a.log:
                        with open(a.log, "a", encoding="utf-8") as fh:
                            fh.write(json.dumps(r) + "\n")
    finally:
        shutil.rmtree(base, ignore_errors=True)
    print("\n| stage | round | side | UTC | wall s | CPU s | load 1 min before → after | |")
    print("| --- | ---: | --- | --- | ---: | ---: | --- | --- |")
    for r in rows:
        extra = (f"{r['physics']['twin_us_per_pose']:.1f} / {r['physics']['floor_us_per_pose']:.1f} µs per pose = "
                 f"{r['physics']['ratio']:.2f}×") if "physics" in r else ""
        print(f"| {r['stage']} | {r['round']} | {r['side']} | {r['utc']} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | "
              f"{r['load'][0]:.1f} → {r['load'][1]:.1f} | {extra} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
