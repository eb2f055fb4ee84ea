"""A study on a real Dask cluster (issue 36, scale out): the ``dask scheduler`` and two ``dask worker``
programs of this venv, started as subprocesses on loopback (``benchmarks/dask_cluster.py``), give
the same table as the local process pool, row for row, in every result column.

The study is the smallest real one: the jia2019 bench at physics fidelity (MuJoCo statics and the
exact reading of the posed disk), 4 values of L1 × 2 repetitions — seconds of work, every output
computed by the workers' own import of benchtwin. ``test_study.py`` keeps the same property with an
in-process ``LocalCluster`` and a stand-in point function; this one keeps it with the programs a
user starts on a cluster. No timing here: the scheduler's overhead is measured by
``benchmarks/dask_overhead.py`` (docs/studies.md)."""

from __future__ import annotations

import importlib.util
import textwrap
from pathlib import Path

import pyarrow.parquet as pq

from benchtwin.app.study import run_study

ROOT = Path(__file__).resolve().parents[2]

STUDY = """
[study]
name = "basic"
base = "jia2019"
seed = 7
repetitions = 2
outputs = ["angle_error_pv_arcsec", "angle_error_rms_arcsec", "disk_radial_motion_pv_um",
           "disk_motion_x_pv_um", "disk_motion_y_pv_um", "disk_tilt_max_arcsec"]
[[study.parameters]]
key = "bench.L1"
values = ["2 mm", "5 mm", "10 mm", "20 mm"]
[study.target]
output = "angle_error_pv_arcsec"
below = "1.2 arcsec"
"""


def _loopback_cluster():
    spec = importlib.util.spec_from_file_location("dask_cluster", ROOT / "benchmarks" / "dask_cluster.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.loopback_cluster


def _benchtwin_file() -> str:
    """Run on every worker: where its benchtwin comes from."""
    import benchtwin

    return str(Path(benchtwin.__file__).resolve())


def test_real_dask_scheduler_gives_the_local_pools_table_row_for_row(tmp_path):
    from distributed import Client

    study = tmp_path / "basic.toml"
    study.write_text(textwrap.dedent(STUDY), encoding="utf-8")
    local = run_study(study, tmp_path / "local", workers=2, progress=False)
    with _loopback_cluster()(2, tmp_path / "cluster") as address:
        assert address.startswith("tcp://127.0.0.1:")
        with Client(address, timeout="60s") as client:
            where = client.run(_benchtwin_file)
        remote = run_study(study, tmp_path / "dask", scheduler=address, progress=False)
    # two worker processes, each importing this worktree's benchtwin
    assert len(where) == 2 and all(Path(f).is_relative_to(ROOT / "benchtwin") for f in where.values()), where
    assert remote["executor"] == f"dask {address}"
    assert (local["computed"], remote["computed"], remote["rows"]) == (8, 8, 8)

    a = pq.read_table(local["table_parquet"])
    b = pq.read_table(remote["table_parquet"])
    assert a.column_names == b.column_names
    # every column but the point-runs' own durations: point, rep, rep_seed, the parameter, all six
    # outputs, fidelity, cache_key; compared row by row (exact: same code, same inputs)
    cols = [c for c in a.column_names if c != "elapsed_s"]
    rows_a = a.select(cols).to_pylist()
    rows_b = b.select(cols).to_pylist()
    assert len(rows_a) == len(rows_b) == 8
    for i, (ra, rb) in enumerate(zip(rows_a, rows_b)):
        assert ra == rb, f"row {i}: local {ra} != dask {rb}"
    # the outputs are the bench's, not a constant: every (point, repetition) gives its own value
    assert len({r["angle_error_pv_arcsec"] for r in rows_a}) == 8
    assert pq.read_table(local["summary_parquet"]).equals(pq.read_table(remote["summary_parquet"]))
