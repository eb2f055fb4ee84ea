"""The scorer against hand-made truth and hand-made results of known error (issue 19).

A truth folder is written by hand (no simulation; tests/support/known_truth.py, the ``truth``
fixture of tests/app/conftest.py): e, θ0, β of a 4-face polygon, α at its stops
and on a 16-point grid. Each test gives results whose error is known in advance and checks the
score to rounding, so a scorer that passed a wrong result (or failed a right one) fails here.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchtwin.app.score import (canonical_results, read_results, read_truth, results_from_csv, score_results)
from benchtwin.cli import InputError
from tests.support.known_truth import BETA, E_UM, GRID, STOPS, THETA0_DEG, alpha_true


def _score(ds, res):
    return score_results(canonical_results(res), read_truth(ds / "truth", ds))


def _min(**kw):
    return {"format": "benchtwin-min-results", **kw}


def test_perfect_results_score_zero(truth):
    s = _score(truth, _min(e_um=E_UM, e_u_um=0.01, theta0_deg=THETA0_DEG, theta0_u_deg=0.1,
                           alpha={"theta_deg": STOPS.tolist(), "value_arcsec": (alpha_true(STOPS) + 3.0).tolist()},
                           beta={"face": [1, 2, 3, 4], "value_arcsec": list(BETA.values())},
                           named=[], ambiguous=[], unexplained=False))
    assert s["e_error_um"] == pytest.approx(0, abs=1e-12) and s["theta0_error_deg"] == pytest.approx(0, abs=1e-9)
    assert s["alpha_rms_error_arcsec"] == pytest.approx(0, abs=1e-9)  # a constant offset is not an error
    assert s["beta_rms_error_arcsec"] == pytest.approx(0, abs=1e-12)
    assert s["identification_correct"] is True and s["spurious"] == []


def test_e_and_theta0_errors_and_z(truth):
    s = _score(truth, _min(e_um=E_UM + 0.15, e_u_um=0.1, theta0_deg=0.1, theta0_u_deg=0.4))
    assert s["e_error_um"] == pytest.approx(0.15) and s["e_z"] == pytest.approx(1.5)
    assert s["theta0_error_deg"] == pytest.approx(0.2)  # 0.1° − 359.9°: wrapped, not −359.8°
    assert s["theta0_z"] == pytest.approx(0.5)
    # e: |z| = 1.5 is within 2u, not within 1u; θ0: within both → pooled 1/2 within 1u, 2/2 within 2u
    assert s["coverage_1u"] == pytest.approx(0.5) and s["coverage_2u"] == pytest.approx(1.0)
    # nothing else was given: nothing else is scored
    for k in ("alpha_rms_error_arcsec", "beta_rms_error_arcsec", "selfcal_rms_error_arcsec", "named", "spurious"):
        assert s[k] is None, k


def test_alpha_and_beta_rms_and_coverage(truth):
    d_alpha = np.array([0.1, -0.1, 0.1, -0.1])  # zero mean: all of it is error
    d_beta = np.array([0.3, -0.3, 0.0, 0.0])
    s = _score(truth, _min(alpha={"theta_deg": STOPS.tolist(), "value_arcsec": (alpha_true(STOPS) + d_alpha).tolist(),
                                  "u_arcsec": [0.05] * 4},
                           beta={"face": [1, 2, 3, 4], "value_arcsec": (np.array(list(BETA.values())) + d_beta).tolist(),
                                 "u_arcsec": [0.2] * 4}))
    assert s["alpha_rms_error_arcsec"] == pytest.approx(0.1)
    assert s["beta_rms_error_arcsec"] == pytest.approx(math.sqrt(0.045))
    assert s["coverage"]["alpha"]["within_1u"] == 0 and s["coverage"]["alpha"]["within_2u"] == 4
    assert s["coverage"]["beta"]["within_1u"] == 2 and s["coverage"]["beta"]["within_2u"] == 4
    assert s["coverage_1u"] == pytest.approx(2 / 8) and s["coverage_2u"] == pytest.approx(1.0)


def test_alpha_on_a_uniform_grid_drops_only_what_the_polygon_cannot_see(truth):
    """16 points, N = 4 faces: an error at harmonic 4 (or 8) is invisible to the polygon (Hsieh
    eq. 2) and not counted; the same error at harmonic 3 is counted in full."""
    th = np.radians(GRID)
    blind = _score(truth, _min(alpha={"theta_deg": GRID.tolist(),
                                      "value_arcsec": (alpha_true(GRID) + 0.3 * np.cos(4 * th)).tolist()}))
    assert blind["alpha_rms_error_arcsec"] == pytest.approx(0, abs=1e-9)
    assert blind["alpha_dropped_harmonics"] == [4, 8]  # 8 = 4·2 is also the grid's Nyquist term (its cosine)
    seen = _score(truth, _min(alpha={"theta_deg": GRID.tolist(),
                                     "value_arcsec": (alpha_true(GRID) + 0.3 * np.cos(3 * th)).tolist()}))
    assert seen["alpha_rms_error_arcsec"] == pytest.approx(0.3 / math.sqrt(2))


def test_selfcal_curve_scored_against_the_grid(truth):
    th = np.radians(GRID)
    s = _score(truth, _min(selfcal={"theta_deg": GRID.tolist(),
                                    "value_arcsec": (alpha_true(GRID) + 0.2 * np.sin(5 * th)).tolist(),
                                    "u_arcsec": [0.1] * GRID.size}))
    assert s["selfcal_rms_error_arcsec"] == pytest.approx(0.2 / math.sqrt(2))
    assert s["alpha_rms_error_arcsec"] is None


@pytest.mark.parametrize("hidden,res,outcome,correct,spurious", [
    ({}, dict(named=[], ambiguous=[], unexplained=False), "nothing", True, []),
    ({}, dict(named=["graduation_error"], ambiguous=[], unexplained=False), "spurious", False, ["graduation_error"]),
    ({}, dict(named=[], ambiguous=[], unexplained=True), "unexplained", False, []),
    ({"graduation_error": {}}, dict(named=["graduation_error"], unexplained=False), "named", True, []),
    ({"graduation_error": {}}, dict(named=[], ambiguous=[["tangential_motion", "graduation_error"]],
                                    unexplained=False), "ambiguous", True, []),
    ({"graduation_error": {}}, dict(named=["ac_scale"], unexplained=False), "missed", False, ["ac_scale"]),
    ({"graduation_error": {}}, dict(named=["graduation_error", "ac_drift"], unexplained=False), "named", False,
     ["ac_drift"]),
    ({"thermal_growth": {}}, dict(named=[], unexplained=True), "unexplained", True, []),
    ({"thermal_growth": {}}, dict(named=["graduation_error"], unexplained=False), "spurious", False,
     ["graduation_error"]),
])
def test_identification(truth, hidden, res, outcome, correct, spurious):
    (truth / "truth" / "hidden.json").write_text(json.dumps({"effects": hidden}))
    s = _score(truth, _min(**res))
    assert s["identification"]["outcome"] == outcome
    assert s["identification_correct"] is correct
    assert s["spurious"] == spurious


def test_suite_expectation_overrides_hidden_json(truth):
    """An absorbed effect (truth/expected.json: nothing to name) makes naming it spurious."""
    (truth / "truth" / "hidden.json").write_text(json.dumps({"effects": {"polygon_pitch_ignored": {}}}))
    (truth / "truth" / "expected.json").write_text(json.dumps({"expect": [], "accept": ["nothing"]}))
    s = _score(truth, _min(named=["polygon_pitch_ignored"], unexplained=False))
    assert s["identification_correct"] is False and s["spurious"] == ["polygon_pitch_ignored"]


def test_residual_against_floor(truth):
    s = _score(truth, _min(residual_before_arcsec=0.9, residual_after_arcsec=0.05))
    assert s["residual_before_arcsec"] == 0.9 and s["floor_arcsec"] is None  # no readings: no floor
    (truth / "truth" / "polygon.csv").write_text("theta_deg,alpha_arcsec,ac_exact_arcsec,start_face,step\n"
                                                 "0,0,10,1,1\n0,0,-5,2,2\n90,0,3,1,2\n90,0,1,2,1\n")
    (truth / "polygon.csv").write_text("theta_deg,ac_arcsec,start_face,step\n0,10.2,1,1\n0,-4.8,2,2\n90,2.8,1,2\n"
                                       "90,0.8,2,1\n")
    s = _score(truth, _min(residual_before_arcsec=0.9, residual_after_arcsec=0.1))
    # the AC's error per stop: +0.2 at 0°, −0.2 at 90° → mean removed RMS 0.2
    assert s["floor_parts"]["alpha_measurement_arcsec"] == pytest.approx(0.2)
    assert s["residual_after_over_floor"] == pytest.approx(0.5)


def test_floor_holds_the_servo_twist_scatter_not_its_mean_per_run(truth):
    """truth/polygon.csv's twist (the servo's stick-slip) joins the floor with its mean per run-row
    removed: a constant or a direction offset is no floor (U; torsion_hysteresis), the scatter is."""
    head = "theta_deg,alpha_arcsec,ac_exact_arcsec,start_face,step,direction,twist_arcsec\n"
    rows = ["0,0,10,1,1,1,{}", "90,0,3,1,2,1,{}", "0,0,10,1,1,-1,{}", "90,0,3,1,2,-1,{}"]
    (truth / "polygon.csv").write_text("theta_deg,ac_arcsec,start_face,step,direction\n0,10,1,1,1\n90,3,1,2,1\n"
                                       "0,10,1,1,-1\n90,3,1,2,-1\n")
    # a direction offset only (±0.4″): no floor part
    (truth / "truth" / "polygon.csv").write_text(head + "\n".join(r.format(v) for r, v in zip(rows, (.4, .4, -.4, -.4))))
    s = _score(truth, _min(residual_before_arcsec=0.9, residual_after_arcsec=0.1))
    assert "servo_twist_arcsec" not in s["floor_parts"]
    # stop-to-stop scatter ±0.3″ within each direction's run: per stop ±0.3 → RMS 0.3
    (truth / "truth" / "polygon.csv").write_text(head + "\n".join(r.format(v) for r, v in zip(rows, (.7, .1, -.1, -.7))))
    s = _score(truth, _min(residual_before_arcsec=0.9, residual_after_arcsec=0.1))
    assert s["floor_parts"]["servo_twist_arcsec"] == pytest.approx(0.3)
    assert s["floor_parts"]["servo_twist_reading_arcsec"] == pytest.approx(0.3)
    assert s["floor_arcsec"] == pytest.approx(0.3)  # the AC reads the exact faces here


def test_csv_results_score_like_json(truth, tmp_path):
    j = _min(e_um=E_UM + 0.05, e_u_um=0.02, alpha={"theta_deg": STOPS.tolist(),
                                                   "value_arcsec": (alpha_true(STOPS) + [0.1, 0, 0, -0.1]).tolist(),
                                                   "u_arcsec": [0.1] * 4},
             named=["graduation_error"], ambiguous=[["a", "b"]], unexplained=False)
    rows = ["quantity,key,value,u", f"e_um,,{E_UM + 0.05!r},0.02"]
    rows += [f"alpha_arcsec,{t!r},{v!r},0.1" for t, v in zip(j["alpha"]["theta_deg"], j["alpha"]["value_arcsec"])]
    rows += ["named,,graduation_error,", "ambiguous,1,a,", "ambiguous,1,b,", "unexplained,,false,"]
    p = tmp_path / "r.csv"
    p.write_text("\n".join(rows) + "\n")
    a = score_results(read_results(p), read_truth(truth / "truth", truth))
    b = _score(truth, j)
    for k in ("e_error_um", "e_z", "alpha_rms_error_arcsec", "coverage_1u", "spurious", "named"):
        assert a[k] == b[k], k


def test_project_results_json_keys(truth):
    """The project's results.json names (analysis/pipeline.py) map onto the same criteria."""
    r = {"format": "bench-results", "eccentricity_um": E_UM - 0.1, "eccentricity_u_um": 0.05,
         "eccentricity_phase_deg": THETA0_DEG, "eccentricity_phase_u_deg": 0.1,
         "encoder_error_arcsec": {"theta_deg": STOPS.tolist(), "value": alpha_true(STOPS).tolist(), "u": [0.1] * 4},
         "polygon_pitch_deviation_arcsec": list(BETA.values()), "polygon_pitch_deviation_u_arcsec": [0.1] * 4,
         "identified_effects": [{"name": "graduation_error", "evidence": {}}], "ambiguous": [], "unexplained": False,
         "residual_before": {"rms_arcsec": 0.7}, "residual_after": {"rms_arcsec": 0.06}}
    s = _score(truth, r)
    assert s["e_error_um"] == pytest.approx(-0.1) and s["e_z"] == pytest.approx(-2.0)
    assert s["beta_rms_error_arcsec"] == pytest.approx(0, abs=1e-12)
    assert s["spurious"] == ["graduation_error"] and s["identification_correct"] is False  # a null: nothing hidden
    assert s["residual_after_arcsec"] == 0.06


@pytest.mark.parametrize("bad,msg", [
    ({"format": "benchtwin-min-results", "e_um": "7.1"}, "e_um: expected a finite number"),
    ({"format": "benchtwin-min-results", "eccentricity": 7.1}, "unknown key(s) 'eccentricity'"),
    ({"format": "benchtwin-min-results", "alpha": {"theta_deg": [0, 90], "value_arcsec": [1.0]}}, "expected 2 values"),
    ({"format": "benchtwin-min-results", "e_um": 7.0, "e_u_um": 0}, "e_u_um: expected a number > 0"),
    ({"format": "benchtwin-min-results", "named": "graduation_error"}, "named: expected a list"),
    ({"format": "something"}, "format 'something'"),
])
def test_bad_results_are_named(bad, msg):
    with pytest.raises(InputError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        canonical_results(bad, "r.json")


def test_bad_csv_names_the_row():
    with pytest.raises(InputError, match="row 1: expected the header"):
        results_from_csv("q,k,v\n", "r.csv")
    with pytest.raises(InputError, match=r"r.csv: row 3: column 'value': expected a number, got 'x'"):
        results_from_csv("quantity,key,value,u\ne_um,,7.1,\nalpha_arcsec,0,x,\n", "r.csv")
    with pytest.raises(InputError, match="row 2: unknown quantity 'ecc'"):
        results_from_csv("quantity,key,value,u\necc,,7.1,\n", "r.csv")


def test_beta_face_outside_polygon(truth):
    with pytest.raises(InputError, match=r"face\(s\) \[5\]"):
        _score(truth, _min(beta={"face": [1, 2, 3, 5], "value_arcsec": [0.0] * 4}))


def test_floor_leaves_out_a_hidden_autocollimator_scale(truth):
    """An AC gain the truth hid is the effect, not the floor: its form is fitted out of the AC error."""
    ex = np.array([10.0, -5.0, 3.0, 1.0, 40.0, -30.0])
    th = [0, 0, 90, 90, 180, 180]
    noise = np.array([0.02, -0.02, 0.01, -0.01, 0.0, 0.0])
    lines_t = ["theta_deg,alpha_arcsec,ac_exact_arcsec,start_face,step"]
    lines_d = ["theta_deg,ac_arcsec,start_face,step"]
    for i in range(6):
        lines_t.append(f"{th[i]},0,{float(ex[i])!r},{i % 2 + 1},{i // 2 + 1}")
        lines_d.append(f"{th[i]},{float(ex[i] * 1.01 + 1e-4 * ex[i] ** 2 + noise[i])!r},{i % 2 + 1},{i // 2 + 1}")
    (truth / "truth" / "polygon.csv").write_text("\n".join(lines_t) + "\n")
    (truth / "polygon.csv").write_text("\n".join(lines_d) + "\n")
    with_gain = read_truth(truth / "truth", truth)["floor"]["parts"]["alpha_measurement_arcsec"]
    assert with_gain > 0.05  # nothing hidden: the gain (0.07″ per stop here) counts as the instrument's error
    (truth / "truth" / "hidden.json").write_text(json.dumps({"effects": {"ac_scale": {"gain": 0.01}}}))
    without = read_truth(truth / "truth", truth)["floor"]["parts"]["alpha_measurement_arcsec"]
    assert without < 0.02


def test_selfcal_declared_nyquist_term_is_dropped(truth):
    """A self-calibration on an even grid does not estimate the Nyquist term n/2 (its curve holds 0
    there); declared, the scorer leaves it out (its cosine: the sine is 0 on the grid)."""
    th = np.radians(GRID)
    curve = {"theta_deg": GRID.tolist(), "value_arcsec": (alpha_true(GRID) + 0.2 * np.cos(8 * th)).tolist(),
             "u_arcsec": [0.1] * GRID.size}
    assert _score(truth, _min(selfcal=curve))["selfcal_rms_error_arcsec"] == pytest.approx(0.2)
    s = _score(truth, _min(selfcal={**curve, "unobservable_harmonics": [8]}))
    assert s["selfcal_rms_error_arcsec"] == pytest.approx(0, abs=1e-9) and s["selfcal_dropped_harmonics"] == [8]
