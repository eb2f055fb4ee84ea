"""Shared fixtures of the scoring tests: one twin dataset of the suite, simulated once, and the
hand-made truth of known values (tests/support/known_truth.py)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def grad_dataset(tmp_path_factory):
    """The suite's graduation_error dataset at seed 11 (~20 s): the hidden division error with X probes."""
    from benchtwin.app.suite import ENTRIES, _simulate_one

    e = next(e for e in ENTRIES if e.name == "graduation_error")
    out = tmp_path_factory.mktemp("suite_one") / e.name
    _simulate_one((e, 11, str(out)))
    return out


@pytest.fixture(scope="session")
def grad_results(grad_dataset, tmp_path_factory):
    """The project's close-loop analysis of it, run on a copy without truth/ (~10 s): its results.json.
    Analysed in memory and written as the analysis writes results.json (``json.dumps(indent=1,
    sort_keys=True)``; tests/app/test_notebook_api.py checks the two are the same bytes): the scoring
    tests read results.json only, so no report is drawn (≈ 2 s of CPU, issue 35)."""
    import json
    import shutil

    from benchtwin.analysis.pipeline import analyze

    ds = tmp_path_factory.mktemp("blind") / "ds"
    shutil.copytree(grad_dataset, ds, ignore=shutil.ignore_patterns("truth", "journal.jsonl"))
    out = tmp_path_factory.mktemp("analysis") / "results.json"
    res = analyze(ds, progress=False, close_loop=True)
    out.write_text(json.dumps(res.to_json(), indent=1, sort_keys=True) + "\n", encoding="utf-8")
    return out


@pytest.fixture(scope="session")
def imported_results(datasets):
    """The shared Sensors 2024 table (docs/real-data.md) imported with both directions and closed-loop
    through the CLI, as a lab would (~2 s, no simulation): results.json of it."""
    from pathlib import Path

    from benchtwin.cli import main

    table = Path(__file__).resolve().parents[3] / "shared" / "realdata" / "sensors2024_24_1400_table6_matrix_encoder_errors.csv"
    if not table.is_file():
        pytest.skip(f"{table} (the shared real-data table) is not beside this checkout")

    def make(base: Path) -> None:
        assert main(["import", str(table), "-o", str(base / "rd"), "--angle", "angle_deg", "--error",
                     "error_prograde_arcsec", "--reverse", "error_reversal_arcsec", "--quiet"]) == 0
        assert main(["close-loop", str(base / "rd"), "-o", str(base / "out"), "--quiet"]) == 0

    # made once per run, by one xdist worker (the four modules reading it run on either): read-only
    return datasets.shared(f"imported_results: {table.name} import + close-loop", make) / "out" / "results.json"


@pytest.fixture()
def truth(tmp_path):
    """A dataset folder holding only the hand-made truth/ of known values (no simulation)."""
    from tests.support.known_truth import write_truth

    return write_truth(tmp_path)
