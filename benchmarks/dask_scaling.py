"""Throughput of a full-fidelity design study on a real Dask cluster: 1 worker vs 2 (issue 36, scale out).

Why: the points worth distributing are the heavy ones, full fidelity (every point-run simulates a
whole dataset with rendered CCD images and analyses it). The goal is ≥ 1.8× from 1 to 2 workers on
2 cores. This starts a real ``dask scheduler`` with 1, then 2, ``dask worker`` processes (1 thread
each) on loopback (``benchmarks/dask_cluster.py``), warms the workers up (imports), and runs the
same K point-runs on each with an empty cache: one point of jia2019 at full fidelity with K
repetitions (one task per repetition, each a new realisation), at the paper's procedure (360
positions × 3 repetitions, 60 CCD images of 2048 × 1536 px; ``--reduced``: the small procedure of
``benchmarks/study_bench.py``, seconds per point-run, a check that the script works, not the figure).

    .venv/bin/python benchmarks/dask_scaling.py [--k 4] [--reduced]

Prints points/s with 1 and 2 workers, their ratio, the mean time of a point-run on the workers
(if it grows from 1 to 2 workers, the two cores were not free) and the load average before and
after each run. Meaningful only on an otherwise idle 2-core machine: it says so when the load
average was ≥ 1 when it started.
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
name = "dask_scaling"
base = "jia2019"
seed = 11
repetitions = {k}
fidelity = "full"
order = {order}
outputs = ["eccentricity_um", "measured_angle_error_pv_arcsec", "predicted_angle_error_pv_arcsec",
           "residual_rms_arcsec"]
{fixed}
[[study.parameters]]
key = "errors.eccentricity"
values = ["7.1 um"]
"""

REDUCED = """[study.fixed]
"procedure.radial_positions" = 36
"procedure.radial_reps" = 2
"procedure.ccd_step" = "30 deg"
"instruments.ccd.width" = "512 px"
"instruments.ccd.height" = "384 px"
"bench.polygon_faces" = 8
"""


def _warm() -> None:
    """On every worker before the timing: import what a full point-run runs."""
    import benchtwin.app.run  # noqa: F401
    import benchtwin.app.study.points  # noqa: F401


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--k", type=int, default=4, help="point-runs per configuration (default 4; even)")
    ap.add_argument("--reduced", action="store_true", help="the small procedure: checks the script, not the figure")
    ns = ap.parse_args()

    import pyarrow.parquet as pq
    from distributed import Client

    from benchtwin.app.study import execution as st
    from benchtwin.app.study import run_study

    version = st.code_version()
    st.code_version = lambda: version  # other work may edit the code meanwhile: one key set
    tmp = Path(tempfile.mkdtemp(prefix="dask-scaling-"))
    study = tmp / "study.toml"
    study.write_text(STUDY.format(k=ns.k, order=3 if ns.reduced else 10, fixed=REDUCED if ns.reduced else ""),
                     encoding="utf-8")
    load_start = os.getloadavg()[0]
    rows = []
    try:
        for nw in (1, 2):
            with loopback_cluster(nw, tmp / f"cluster{nw}") as address:
                with Client(address, timeout="60s") as client:
                    client.run(_warm)
                load0 = os.getloadavg()[0]
                t0 = time.perf_counter()
                r = run_study(study, tmp / f"out{nw}", scheduler=address, progress=False)
                wall = time.perf_counter() - t0
                load1 = os.getloadavg()[0]
            assert r["computed"] == ns.k, r
            per_run = pq.read_table(r["table_parquet"])["elapsed_s"].to_pylist()
            rows.append((nw, wall, ns.k / wall, sum(per_run) / len(per_run), load0, load1))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    print(f"benchmarks/dask_scaling.py: jia2019 at full fidelity, {'reduced procedure' if ns.reduced else 'the paper procedure'}, "
          f"{ns.k} point-runs per configuration; {os.cpu_count()} cores, {platform.machine()}, Python "
          f"{platform.python_version()}\n")
    print("| dask workers | wall (s) | point-runs/s | mean point-run on its worker (s) | load before / after |")
    print("| ---: | ---: | ---: | ---: | --- |")
    for nw, wall, pps, mean_s, l0, l1 in rows:
        print(f"| {nw} | {wall:.1f} | {pps:.4f} | {mean_s:.1f} | {l0:.2f} / {l1:.2f} |")
    print(f"\nthroughput ratio, 2 workers / 1 worker: {rows[1][2] / rows[0][2]:.2f}")
    if load_start >= 1.0 or ns.reduced:
        print("NOT a measurement of the scaling: " + ("the reduced procedure; " if ns.reduced else "")
              + (f"the load average was {load_start:.2f} at the start (the machine was not idle)"
                 if load_start >= 1.0 else "").rstrip("; "))


if __name__ == "__main__":
    main()
