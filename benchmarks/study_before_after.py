"""The README's design study, before against after, interleaved (issue 36's before/after table, "Dask study").

Runs ``benchtwin study scenarios/studies/bearing_distance.toml`` of two checkouts (each with its own
``.venv``) with an empty output folder, alternating before/after, on the local pool (2 workers) and
on a real ``dask scheduler`` with 2 ``dask worker``s on loopback (``benchmarks/dask_cluster.py``,
started with that checkout's venv). Prints one JSON line per run: wall time, CPU time of the whole
process tree (``RUSAGE_CHILDREN`` with this process a subreaper, so the pool's forkserver children
count; on Dask the scheduler and both workers, their start-up included) and the load average
before/after.

    .venv/bin/python benchmarks/study_before_after.py --before /path/to/old/checkout [--after .] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import dask_cluster  # noqa: E402
from run_bench import SUBREAPER, _reap_descendants  # noqa: E402  (the subreaper is set on import)

ORDER = [("before", "local"), ("after", "local"), ("after", "dask"), ("before", "dask"),
         ("after", "local"), ("before", "local")]


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_once(root: Path, mode: str, out: Path) -> dict:
    shutil.rmtree(out, ignore_errors=True)
    cmd = [str(root / ".venv/bin/benchtwin"), "study", str(root / "scenarios/studies/bearing_distance.toml"),
           "-o", str(out), "--quiet"]
    load0 = os.getloadavg()[0]
    c0 = _cpu_s()
    if mode == "dask":
        dask_cluster.DASK = root / ".venv/bin/dask"   # that checkout's scheduler and workers
        dask_cluster.ROOT = root
        with dask_cluster.loopback_cluster(2, out.with_name(out.name + "_cluster")) as address:
            t0 = time.perf_counter()
            subprocess.run(cmd + ["--scheduler", address], check=True, cwd=root, stdout=subprocess.DEVNULL)
            wall = time.perf_counter() - t0
    else:
        t0 = time.perf_counter()
        subprocess.run(cmd + ["--workers", "2"], check=True, cwd=root, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - t0
    _reap_descendants()
    return {"mode": mode, "wall_s": round(wall, 1), "cpu_s": round(_cpu_s() - c0, 1),
            "load": [round(load0, 1), round(os.getloadavg()[0], 1)], "utc": time.strftime("%H:%M", time.gmtime()),
            "subreaper": SUBREAPER}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--before", required=True, help="the older checkout (with its .venv)")
    ap.add_argument("--after", default=str(Path(__file__).resolve().parents[1]))
    ap.add_argument("--out", default="/tmp/study_before_after")
    a = ap.parse_args(argv)
    trees = {"before": Path(a.before).resolve(), "after": Path(a.after).resolve()}
    for i, (tree, mode) in enumerate(ORDER):
        rec = run_once(trees[tree], mode, Path(a.out) / f"{i}_{tree}_{mode}")
        print(json.dumps({"tree": tree, **rec}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
