"""Issue 32: `benchtwin score` expects what a scenario DECLARES beyond Jia's model (a disk graduation
error: jia2019's 3″), reads the residual after the model results.json states, and the certificate
quotes what the headline residual can test."""

from __future__ import annotations

import json

from benchtwin.app.certificate import effects_statement
from benchtwin.app.score import _from_project, declared_beyond_jia, expected_from_hidden, read_truth


def _scenario(grad_rad):
    return {"name": "x", "seed": 1, "si": {"errors": {"graduation_error_rms": grad_rad, "eccentricity": 7e-6}}}


def test_declared_graduation_error_is_expected():
    assert declared_beyond_jia(_scenario(1.45e-5)) == ["graduation_error"]
    assert declared_beyond_jia(_scenario(0.0)) == [] and declared_beyond_jia(None) == []
    e = expected_from_hidden({"effects": {}}, ["graduation_error"])
    assert e["expect"] == ["graduation_error"] and e["accept"] == ["named", "ambiguous"]
    assert expected_from_hidden({"effects": {}})["accept"] == ["nothing"]
    both = expected_from_hidden({"effects": {"tangential_motion": {}}}, ["graduation_error"])
    assert both["expect"] == ["tangential_motion", "graduation_error"]


def test_read_truth_takes_the_scenarios_declared_errors(tmp_path):
    td = tmp_path / "truth"
    td.mkdir()
    (td / "scenario.json").write_text(json.dumps(_scenario(1.45e-5)))
    assert read_truth(td, tmp_path)["expected"]["expect"] == ["graduation_error"]
    (td / "scenario.json").write_text(json.dumps(_scenario(0.0)))
    assert read_truth(td, tmp_path)["expected"]["accept"] == ["nothing"]


def test_score_reads_the_residual_after_the_stated_model():
    r = {"identified_effects": [{"name": "graduation_error"}], "residual_test": {"rms_arcsec": 4.0},
         "residual_after_trace": {"rms_arcsec": 2.8}, "residual_after": {"rms_arcsec": 0.003, "per_reading_rms_arcsec": 0.7}}
    assert _from_project(r, "r")["residual_after_arcsec"] == 0.7
    del r["residual_after"]["per_reading_rms_arcsec"]
    assert _from_project(r, "r")["residual_after_arcsec"] == 2.8


def test_certificate_quotes_what_the_residual_tests():
    note = "this sampling cannot test the model: 23 parameters fitted to 23 stops leave 0 degrees of freedom"
    res = {"identified_effects": [{"name": "graduation_error", "params": {"a2_arcsec": 1.0}, "u": {"a2_arcsec": 0.1}}],
           "residual_before": {"rms_arcsec": 4.004, "n_points": 23, "n_params": 1, "dof": 22, "chi2": 6444.0,
                               "p_value": 0.0, "loo_rms_arcsec": 4.19},
           "residual_after": {"rms_arcsec": 0.002, "n_points": 23, "n_params": 23, "dof": 0, "chi2": 0.002,
                              "p_value": None, "loo_rms_arcsec": 31.5, "sampling_note": note}}
    s = effects_statement(res)
    assert "23 stops, 23 parameters fitted, 0 degrees of freedom" in s and "31.5 arcsec RMS" in s
    assert note in s and "4.19 arcsec RMS" in s


def test_certificate_says_how_a_measured_regressors_effect_was_estimated():
    """A certificate states only what happened: where the analysis estimated an effect by errors in
    variables (results' ``estimator``), the statement says so, and where it reported the selection's
    fit instead (``adopted`` false), it says that and why."""
    est = {"method": "errors in variables", "steps": 6, "converged": True, "adopted": True,
           "params_selection": {"gain": 0.62}}
    res = {"identified_effects": [{"name": "tangential_motion", "params": {"gain": 1.025}, "u": {"gain": 0.171},
                                   "estimator": est},
                                  {"name": "graduation_error", "params": {"a2_arcsec": 1.0}, "u": {"a2_arcsec": 0.1}}]}
    s = effects_statement(res)
    assert "gain = 1.025 ± 0.17; standard uncertainties; estimated with its measured regressor's own uncertainty" in s
    assert "a2_arcsec = 1 ± 0.1; standard uncertainties)" in s
    res["identified_effects"][0]["estimator"] = {**est, "adopted": False, "why_not": "tangential_motion: implausible"}
    s = effects_statement(res)
    assert "not adopted (tangential_motion: implausible)" in s and "estimated with its" not in s
