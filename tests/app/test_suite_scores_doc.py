"""docs/suite-scores.md is generated, not edited (issue 34 item 8).

benchmarks/suite_scores.py stores the scores of its run in docs/data/suite-scores.json and renders
the doc from that file alone (render_doc: the JSON, the prose NOTES of the script and the suite's
table format, app/suite.py format_suite_table). Here the doc is rendered again from the stored JSON
and must equal docs/suite-scores.md byte for byte: a hand edit of the doc, or a change of the
renderer, of the table format or of the prose without ``suite_scores.py --render``, fails. The
numbers themselves are re-measured by the full run (``suite_scores.py``, ≈ 1.5 h), and seed 11's
small-suite part by tests/app/test_suite_reference.py (slow), whose expectations must be derived
from the same JSON (checked here), so that the doc's seed-11 figures are what that test defends.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "suite-scores.md"
DATA = ROOT / "docs" / "data" / "suite-scores.json"
EXPECTATIONS = ROOT / "tests" / "app" / "data" / "suite_small_seed11.json"
RENDER = ".venv/bin/python benchmarks/suite_scores.py --render (after a prose or format change), or the full run"


@pytest.fixture(scope="module")
def ss():
    spec = importlib.util.spec_from_file_location("suite_scores", ROOT / "benchmarks" / "suite_scores.py")
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def data():
    return json.loads(DATA.read_text(encoding="utf-8"))


def test_the_doc_is_what_the_stored_scores_render_to(ss):
    diff = ss.drift(DATA, DOC)
    assert diff == "", f"docs/suite-scores.md has drifted from its JSON; {RENDER}\n{diff}"
    assert ss.main(["--check", "--data", str(DATA), "--doc", str(DOC)]) == 0


def test_the_json_is_as_the_script_writes_it(ss, data):
    """Sorted keys and the script's layout: a re-run that changes nothing changes no byte."""
    assert DATA.read_text(encoding="utf-8") == ss.data_text(data)


def test_a_changed_number_or_a_hand_edit_is_drift(ss, data, tmp_path):
    seed = ss._seeds(data)[0]
    changed = json.loads(json.dumps(data))
    changed["seeds"][seed]["overall"]["e_error_um"] += 0.001  # a number of the overall table (4 decimals)
    p = tmp_path / "changed.json"
    p.write_text(ss.data_text(changed), encoding="utf-8")
    assert "e error RMS" in ss.drift(p, DOC)
    assert ss.main(["--check", "--data", str(p), "--doc", str(DOC)]) == 1
    name = sorted(changed["seeds"][seed]["scores"])[0]  # a dataset's row of a seed's table
    changed = json.loads(json.dumps(data))
    changed["seeds"][seed]["scores"][name]["floor_arcsec"] = 9.999
    p.write_text(ss.data_text(changed), encoding="utf-8")
    assert ss.drift(p, DOC) != ""
    edited = tmp_path / "edited.md"  # a hand edit of the doc's prose
    edited.write_text(DOC.read_text(encoding="utf-8").replace("## Reading the figures\n",
                                                              "## Reading the figures\n\nA note.\n", 1),
                      encoding="utf-8")
    assert "A note." in ss.drift(DATA, edited)


def test_the_overall_figures_are_those_of_the_stored_dataset_scores(data):
    """The doc's overall rows come from the per-dataset scores it tabulates (benchtwin.app.suite.overall)."""
    from benchtwin.app.score import public
    from benchtwin.app.suite import overall

    def same(a, b):  # the quadratic means summed in another order: equal to the last bits
        if isinstance(a, float) and isinstance(b, float):
            return abs(a - b) <= 1e-12 * max(abs(a), abs(b))
        return a == b

    for seed, run in data["seeds"].items():
        got = public(overall(run["scores"]))
        assert got.keys() == run["overall"].keys(), seed
        bad = {k: (got[k], v) for k, v in run["overall"].items() if not same(got[k], v)}
        assert not bad, f"seed {seed}: {bad}"


def test_the_reference_test_defends_the_docs_seed_11(ss, data):
    """tests/app/data/suite_small_seed11.json is the small suite's part of the doc's seed-11 run."""
    assert "11" in data["seeds"] and data["size"] == "full"
    assert EXPECTATIONS.read_text(encoding="utf-8") == ss.expectations(data["seeds"]["11"], 11), (
        "the slow reference test's expectations are not from the run the doc shows: regenerate both with "
        "benchmarks/suite_scores.py")
