"""hsieh2022's own default through the loop (issue 16), slow: the graduation error is the chosen
candidate and no drift is flagged on a twin without drift (before: graduation_error skipped as
'no significant harmonic', 'drift with time' z = 4.6). The twin's declared division error has 0.18″
RMS above order 20 (docs/effects.md): with every order the 360 stops resolve (issue 32 item 5,
graduation_error's broadband variant, 6 repetitions × 2 directions revisit every stop) the loop
closes: 0.625″ → 0.102″, χ² 10 671 / 10 364 dof, nothing left (docs/loop-validation.md)."""

from __future__ import annotations

import shutil

import pytest

from benchtwin.analysis.pipeline import analyze
from benchtwin.twin.scenario import load_scenario
from benchtwin.twin.simulate import simulate


@pytest.mark.slow
def test_hsieh2022_default_names_the_graduation_error_and_no_drift(tmp_path):
    from pathlib import Path

    sc = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "hsieh2022.toml")
    ds = simulate(sc, tmp_path / "ds", progress=False, backend="analytic")
    shutil.rmtree(ds / "truth")
    res = analyze(ds, tmp_path / "out", progress=False, close_loop=True)["results"]
    chosen = [e["name"] for e in res["identified_effects"]] or [e["name"] for e in res["close_loop"]["partial_effects"]]
    assert chosen == ["graduation_error"], chosen
    assert not res["close_loop"]["signature"]["drift"]["significant"]
    assert res["residual_after_trace"]["rms_arcsec"] < 0.4 * res["residual_test"]["rms_arcsec"]
    assert res["unexplained"] is False, res["close_loop"].get("unexplained_signature")
