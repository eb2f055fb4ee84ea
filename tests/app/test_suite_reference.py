"""The project's own analysis on the small benchmark suite, seed 11, against stored expectations
(issue 19: its score must not get worse unnoticed). Slow (~6 min on one core: six datasets
simulated and analysed); the default suite has the one-dataset version in test_score_twin.py.

The expectations (tests/app/data/suite_small_seed11.json) are written by
benchmarks/suite_scores.py from its seed-11 run of the full suite (the small suite's datasets are
the same datasets). Tolerances, stated per criterion: an error may grow by 25 % of itself plus a
fixed margin of about the seed-to-seed spread in docs/suite-scores.md (e 0.005 µm, θ0 0.01°,
α/β/self-cal 0.01″, after/floor 0.3); a coverage may fall by at most 0.1; a correct naming must stay
correct and no spurious name may appear where there was none.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import pytest

import benchtwin

DATA = Path(__file__).parent / "data" / "suite_small_seed11.json"
MARGIN = {"e_error_um": 0.005, "theta0_error_deg": 0.01, "beta_rms_error_arcsec": 0.01,
          "alpha_rms_error_arcsec": 0.01, "selfcal_rms_error_arcsec": 0.01, "residual_after_over_floor": 0.3}
COVERAGE_DROP = 0.1


def check_against(stored: dict, got: dict) -> list[str]:
    """Every way ``got`` (label → score) is worse than ``stored`` beyond the tolerances."""
    worse = []
    for label, exp in stored.items():
        s = got.get(label)
        if s is None:
            worse.append(f"{label}: no score")
            continue
        for k, m in MARGIN.items():
            if exp.get(k) is not None and (s.get(k) is None or abs(s[k]) > 1.25 * abs(exp[k]) + m):
                worse.append(f"{label}: {k} {s.get(k)} vs stored {exp[k]}")
        for k in ("coverage_1u", "coverage_2u"):
            if exp.get(k) is not None and (s.get(k) is None or s[k] < exp[k] - COVERAGE_DROP):
                worse.append(f"{label}: {k} {s.get(k)} vs stored {exp[k]}")
        if exp.get("identification_correct") and not s.get("identification_correct"):
            worse.append(f"{label}: naming was correct, now {s.get('identification')}")
        if exp.get("spurious") == [] and s.get("spurious"):
            worse.append(f"{label}: spurious {s['spurious']}")
    return worse


def test_check_against_catches_a_worse_score():
    """The comparison itself cannot pass a worse score (hand-made)."""
    stored = {"x": {"e_error_um": 0.01, "coverage_2u": 0.95, "identification_correct": True, "spurious": []}}
    assert check_against(stored, {"x": {"e_error_um": -0.0124, "coverage_2u": 0.9, "identification_correct": True,
                                        "spurious": []}}) == []
    bad = check_against(stored, {"x": {"e_error_um": 0.02, "coverage_2u": 0.8, "identification_correct": False,
                                       "spurious": ["ac_scale"]}})
    assert len(bad) == 4
    assert check_against(stored, {}) == ["x: no score"]


@pytest.mark.slow
def test_project_score_on_the_small_suite_does_not_get_worse(tmp_path):
    from benchtwin.analysis.pipeline import analyze
    from benchtwin.app.suite import write_suite

    stored = json.loads(DATA.read_text())
    suite = tmp_path / "s"
    write_suite(suite, seed=stored["seed"], blind=True, size="small")

    def project(ds):
        return analyze(Path(ds), Path(tempfile.mkdtemp(dir=tmp_path)), progress=False, close_loop=True)["results"]

    out = benchtwin.score(project, suite=suite)
    assert out["errors"] == {}
    got = {out["labels"][n]["label"]: s for n, s in out["scores"].items()}
    worse = check_against(stored["datasets"], got)
    assert not worse, "\n".join(worse)
    assert out["overall"]["identification_correct"] >= stored["overall"]["identification_correct"]
