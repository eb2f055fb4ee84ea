"""The Dask scheduler's overhead per point-run of a design study (issue 36, scale out).

Why: distributing a study pays only when a point-run costs much more than what the scheduler adds
to it. This measures what it adds, with point-runs that cost nothing: a point function that
returns at once (``instant_point``), so the wall time per point-run is the runner's and the
executor's own cost.

How: the same study of N trivial points (jia2019, one physics output, ``bench.L1`` on a grid of N
values, one repetition: one task per point) is run by ``run_study`` on

- the local process pool, 2 workers (``workers=2``; its start-up is inside the run), and
- a real ``dask scheduler`` with 2 ``dask worker`` processes (1 thread each) on loopback
  (``benchmarks/dask_cluster.py``, started once, outside the timing: a cluster outlives a study),

each at N = ``--n-small`` and ``--n-large`` points with a fresh output directory (empty cache).
The cost per point-run of an executor is the slope (T(N_large) − T(N_small)) / (N_large − N_small):
what does not grow with N (pool start-up, connecting the client, the figures' fixed part) cancels.
The scheduler's overhead per point-run = slope(Dask) − slope(local pool). The in-process runner
(``workers=0``) gives the slope that both share (validation of every point's scenario, cache
writes, tables). After one untimed warm-up round, every configuration is timed ``--repeat`` times,
round robin (bursts of other work on a shared machine hit all alike); the fastest is kept, and the difference is also given
round by round (median and range: the spread the machine's load puts on it).

    .venv/bin/python benchmarks/dask_overhead.py [--n-small 50] [--n-large 200] [--repeat 3]

Prints a markdown table; docs/studies.md ("Scaling out") quotes it.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dask_cluster import loopback_cluster  # noqa: E402

STUDY = """
[study]
name = "dask_overhead"
base = "jia2019"
seed = 1
repetitions = 1
outputs = ["angle_error_pv_arcsec"]
[[study.parameters]]
key = "bench.L1"
low = "2 mm"
high = "20 mm"
n = {n}
sampling = "grid"
"""


def instant_point(task: dict) -> list[dict]:
    """A point-run that costs nothing: the runner's and the executor's cost alone remain."""
    return [{"angle_error_pv_arcsec": 0.0} for _ in task["reps"]]


def timed(study: Path, out: Path, **kw) -> float:
    from benchtwin.app.study import run_study

    t0 = time.perf_counter()
    r = run_study(study, out, progress=False, point_fn=instant_point, **kw)
    wall = time.perf_counter() - t0
    assert r["computed"] == r["rows"], r   # a fresh cache: every point-run ran
    return wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n-small", type=int, default=50)
    ap.add_argument("--n-large", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3)
    ns = ap.parse_args()

    from benchtwin.app.study import execution as st

    version = st.code_version()
    st.code_version = lambda: version  # other work may edit the code meanwhile: one key set
    tmp = Path(tempfile.mkdtemp(prefix="dask-overhead-"))
    load0 = os.getloadavg()[0]
    sizes = (ns.n_small, ns.n_large)
    studies = {}
    for n in sizes:
        studies[n] = tmp / f"study_{n}.toml"
        studies[n].write_text(STUDY.format(n=n), encoding="utf-8")
    times: dict[tuple[str, int], list[float]] = {}
    try:
        with loopback_cluster(2, tmp / "cluster") as address:
            configs = {"in-process runner (workers=0)": {"workers": 0},
                       "local pool, 2 workers": {"workers": 2},
                       "dask scheduler + 2 dask workers (loopback)": {"scheduler": address}}
            run = 0
            for i in range(1 + ns.repeat):   # round 0 warms up (imports, first pickles): not kept
                for label, kw in configs.items():
                    for n in sizes:
                        run += 1
                        t = timed(studies[n], tmp / f"out{run}", **kw)
                        if i > 0:
                            times.setdefault((label, n), []).append(t)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    load1 = os.getloadavg()[0]

    dn = ns.n_large - ns.n_small
    slope = {label: (min(times[(label, ns.n_large)]) - min(times[(label, ns.n_small)])) / dn
             for label in configs}
    print(f"benchmarks/dask_overhead.py: {os.cpu_count()} cores, {platform.machine()}, Python "
          f"{platform.python_version()}; load average before/after {load0:.2f} / {load1:.2f}; "
          f"best of {ns.repeat}\n")
    print(f"| executor | wall, N = {ns.n_small} (s) | wall, N = {ns.n_large} (s) | per point-run (ms) |")
    print("| --- | ---: | ---: | ---: |")
    for label in configs:
        print(f"| {label} | {min(times[(label, ns.n_small)]):.2f} | {min(times[(label, ns.n_large)]):.2f} | "
              f"{1e3 * slope[label]:.1f} |")
    local = slope["local pool, 2 workers"]
    dask = slope["dask scheduler + 2 dask workers (loopback)"]
    # the same difference round by round (both executors timed in the same round): its spread is
    # what the shared machine's load does to the figure
    rounds = sorted(1e3 * ((times[(dk, ns.n_large)][i] - times[(dk, ns.n_small)][i])
                           - (times[(lp, ns.n_large)][i] - times[(lp, ns.n_small)][i])) / dn
                    for i in range(ns.repeat)
                    for dk, lp in [("dask scheduler + 2 dask workers (loopback)", "local pool, 2 workers")])
    print(f"\nscheduler overhead per point-run (Dask − local pool), from the fastest runs: "
          f"{1e3 * (dask - local):.1f} ms; round by round: median {rounds[len(rounds) // 2]:.1f} ms, "
          f"range {rounds[0]:.1f} … {rounds[-1]:.1f} ms ({ns.repeat} rounds)")
    print("all timings (s): " + "; ".join(f"{k[0]} N={k[1]}: " + ", ".join(f"{t:.2f}" for t in v)
                                         for k, v in times.items()))


if __name__ == "__main__":
    main()
