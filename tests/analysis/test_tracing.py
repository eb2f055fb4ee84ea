"""trace(): is there anything to explain, the signature, nulls, the unexplained case, the model
file, the figures. Synthetic evidence from ``tests.synthetic.evidence`` with explicit
seeds."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchtwin.analysis.effects import ALL
from tests.synthetic.evidence import make_evidence
from benchtwin.analysis.tracing import (Evidence, add_to_error_model, harmonic_test, load_model,
                                        model_terms_from_payload, residual_test, save_model, signature, trace)

NULL_CONFIGS = {
    "all_start_faces": dict(),
    "rich": dict(start_faces=range(1, 24, 4), reps=2, directions=(1, -1), x_probes=True, selfcal=True),
    "shifts": dict(start_faces=range(1, 24, 5), shifts=(0.0, 5.0, 10.0)),
}


def _h7(th, t):
    """Outside the library: a 7th harmonic whose amplitude grows during the session."""
    return 0.6 * (t / t.max()) * np.sin(7 * np.deg2rad(th) + 0.3)


# ---------------------------------------------------------------------------------------------
# evidence
# ---------------------------------------------------------------------------------------------

def test_evidence_validates_and_derives_faces():
    with pytest.raises(ValueError):
        Evidence(theta_deg=[0, 1, 2], alpha_arcsec=[0, 1], u_arcsec=0.1, model_terms={})
    with pytest.raises(ValueError):
        Evidence(theta_deg=[0, 1], alpha_arcsec=[0, 1], u_arcsec=0.0, model_terms={})
    N = 23
    th = np.arange(N) * 360 / N
    ev = Evidence(theta_deg=np.tile(th, 2), alpha_arcsec=np.zeros(2 * N), u_arcsec=0.1, model_terms={},
                  start_face=np.repeat([1, 5], N), n_faces=N)
    np.testing.assert_array_equal(ev.step[:N], np.arange(1, N + 1))
    np.testing.assert_array_equal(ev.face[N:], (5 + np.arange(1, N + 1) - 2) % N + 1)  # face = (j + i − 2) mod N + 1
    assert ev.closure_group.max() == 1
    assert ev.kmax == 11  # 23 stop positions: harmonics up to 11


# ---------------------------------------------------------------------------------------------
# 1. anything to explain?
# ---------------------------------------------------------------------------------------------

def test_residual_test_is_calibrated_on_nulls():
    p = [residual_test(make_evidence(np.random.default_rng(s))[0])["p_value"] for s in range(30, 40)]
    assert min(p) > 1e-3 and 0.2 < float(np.mean(p)) < 0.8


def test_harmonic_test_finds_an_injected_harmonic():
    ev, _ = make_evidence(np.random.default_rng(8), inject={"graduation_error": {4: (0.15, 2.0)}})
    h = {x["k"]: x for x in harmonic_test(ev)}
    assert [k for k, x in h.items() if x["significant"]] == [4]
    assert abs(h[4]["amplitude_arcsec"] - 0.15) < 3 * h[4]["u_arcsec"]
    assert abs(h[4]["a_arcsec"] - 0.15 * math.cos(2.0)) < 3 * h[4]["u_arcsec"]


def test_an_order_the_closure_removes_is_not_tested():
    """Shifts 0…14° (345 positions: kmax 40) reach order 23 of the 23-face polygon, whose kθ is the
    same at every stop of a run: the per-run constants hold it and no reading constrains it. It is
    not listed; every order listed has a finite amplitude and u, and the injected one is found. θ
    is the commanded stop, as in a dataset's polygon table (no jitter)."""
    ev, _ = make_evidence(np.random.default_rng(8), start_faces=range(1, 24, 6), shifts=tuple(float(s) for s in range(15)),
                          jitter_arcsec=0.0, inject={"graduation_error": {4: (0.15, 2.0)}})
    assert ev.kmax >= 23
    h = {x["k"]: x for x in harmonic_test(ev)}
    assert 23 not in h and set(h) == set(range(1, ev.kmax + 1)) - {23}
    assert all(x["amplitude_arcsec"] < 1.0 and x["u_arcsec"] < 1.0 for x in h.values())
    assert [k for k, x in h.items() if x["significant"]] == [4]
    # the first-order graduation prior is the RMS of these components (it was 10¹⁰–10¹²″ with order N in)
    from benchtwin.analysis.pipeline import k1_prior
    assert 0.0 < k1_prior({"harmonics": list(h.values())})[0] < 0.1


def test_residual_within_model_uncertainty_is_nothing_to_explain():
    """A 1 % error of e is inside u(e) = 0.24 µm (3.4 %, Jia sec. 5): with the model's uncertainty
    in the evidence, nothing is significant; without it, it is."""
    ev, _ = make_evidence(np.random.default_rng(4), inject={"ccd_pixel_scale": {"scale_error_pct": 1.0}})
    assert trace(ev)["residual_before"]["significant"]
    ev.model_sensitivity = {"u_e": ev.model_terms["eccentricity"] * 0.24 / 7.1}
    res = trace(ev)
    assert res["status"] == "no_significant_residual", res["status"]
    assert not res["identified_effects"]


# ---------------------------------------------------------------------------------------------
# 2. signature
# ---------------------------------------------------------------------------------------------

def test_signature_drift_direction_face_and_terms():
    ev, _ = make_evidence(np.random.default_rng(12), start_faces=range(1, 24, 2), directions=(1, -1),
                          inject={"ac_drift": {"drift_arcsec_per_s": 5e-4}})
    s = signature(ev)
    assert s["drift"]["significant"] and abs(s["drift"]["slope_arcsec_per_s"] - 5e-4) < 3 * s["drift"]["u"]
    assert not s["start_face"]["significant"]
    json.dumps(s)
    # forward sweeps only, every run from the same angle: the reading time is a θ sawtooth, and a
    # drift cannot be told from an encoder error of that shape — not tested, said so
    ev0, _ = make_evidence(np.random.default_rng(12), start_faces=range(1, 24, 2), dwell_s=10.0,
                           inject={"ac_drift": {"drift_arcsec_per_s": 5e-4}})
    s0 = signature(ev0)
    assert not s0["direction"]["available"]
    assert not s0["drift"]["significant"] and s0["drift"]["u"] > 5 * s["drift"]["u"]  # the θ-free part is tiny
    ok, why = ALL["ac_drift"].available(ev0)
    assert not ok and "backward" in why
    assert "ac_drift" in trace(ev0)["skipped"]
    ev1, _ = make_evidence(np.random.default_rng(12), directions=(1, -1), start_faces=range(1, 24, 2),
                           inject={"torsion_hysteresis": {"half_hysteresis_arcsec": 0.2}})
    s1 = signature(ev1)
    assert s1["direction"]["significant"]
    assert abs(s1["direction"]["half_difference_arcsec"] - 0.2) < 3 * s1["direction"]["u"]
    ev2, _ = make_evidence(np.random.default_rng(12), inject={"polygon_pitch_ignored": {"rms_arcsec": 0.3}})
    s2 = signature(ev2)
    assert s2["start_face"]["significant"]
    ev3, _ = make_evidence(np.random.default_rng(12), inject={"optical_radius": {"delta_r_mm": 0.1}})
    s3 = signature(ev3)
    g = s3["correlations"]["term:eccentricity"]
    assert g["significant"] and abs(g["gain"] + 0.1 / 22.1) < 3 * g["u"]  # gain −Δr/(r+Δr)


def test_signature_repetition_and_selfcal():
    ev, _ = make_evidence(np.random.default_rng(13), reps=3, start_faces=range(1, 24, 4), extra=_h7)
    assert not signature(ev)["repetition"]["synchronous"]
    ev2, _ = make_evidence(np.random.default_rng(13), reps=3, start_faces=range(1, 24, 4), selfcal=True,
                           inject={"graduation_error": {2: (0.4, 0.3)}})
    s2 = signature(ev2)
    assert s2["repetition"]["synchronous"]
    assert s2["selfcal"]["consistent"]  # an encoder error: the self-calibration sees the same
    ev3, _ = make_evidence(np.random.default_rng(13), selfcal=True, inject={"ac_drift": {"drift_arcsec_per_s": 1e-3}})
    s3 = signature(ev3)
    assert s3["selfcal"]["rms_selfcal_residual_arcsec"] < 0.03  # the reference chain's drift is not there


# ---------------------------------------------------------------------------------------------
# 3. selection: nulls, unexplained, result format
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("config", sorted(NULL_CONFIGS))
@pytest.mark.parametrize("seed", [101, 102, 103, 104, 105])
def test_nulls_give_no_effect(config, seed):
    ev, _ = make_evidence(np.random.default_rng(seed), **NULL_CONFIGS[config])
    res = trace(ev)
    assert res["status"] == "no_significant_residual", (res["status"], [c["names"] for c in res["candidates"] if c["passed"]])
    assert not res["identified_effects"] and not res["ambiguous"] and not res["unexplained"]
    assert res["model_file"]["effects"] == []


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_effect_outside_the_library_is_unexplained(seed):
    ev, _ = make_evidence(np.random.default_rng(seed), extra=_h7)
    res = trace(ev)
    assert res["unexplained"] and res["status"] == "unexplained"
    assert res["identified_effects"] == []
    assert 7 in res["unexplained_signature"]["significant_harmonics"]  # the residual's signature
    assert res["unexplained_signature"]["left"]  # and what the best candidate leaves
    assert res["residual_after"]["p_value"] < 1e-3
    assert res["model_file"]["effects"] == []  # never force a fit into the model file


def test_result_is_json_ready_and_complete():
    ev, _ = make_evidence(np.random.default_rng(21), directions=(1, -1), start_faces=range(1, 24, 2),
                          inject={"ac_drift": {"drift_arcsec_per_s": 1e-3}})
    res = trace(ev)
    text = json.dumps(res, allow_nan=False)
    assert json.loads(text)["status"] == "explained"
    for k in ("rms_arcsec", "pv_arcsec", "fraction_of_error", "chi2", "dof", "p_value", "significant"):
        assert k in res["residual_before"]
    for k in ("rms_arcsec", "pv_arcsec", "fraction_of_error"):
        assert k in res["residual_after"]
    e = res["identified_effects"][0]
    assert e["name"] == "ac_drift"
    for k in ("delta_bic", "delta_aicc", "cv_gain", "z"):
        assert e["evidence"][k] is not None
    assert e["evidence"]["delta_bic"] > 10 and e["evidence"]["cv_gain"] > 0 and e["evidence"]["z"] > 4
    assert res["residual_after"]["fraction_of_error"] < res["residual_before"]["fraction_of_error"]


def test_candidates_subset():
    # forward and backward sweeps: the drift is not a θ pattern, so no encoder error can stand in for it
    ev, _ = make_evidence(np.random.default_rng(22), directions=(1, -1), start_faces=range(1, 24, 2),
                          inject={"ac_drift": {"drift_arcsec_per_s": 1e-3}})
    res = trace(ev, candidates=["graduation_error", "optical_radius"])
    assert res["status"] == "unexplained"  # the true effect is not among the candidates: no forced fit
    assert not res["identified_effects"]


# ---------------------------------------------------------------------------------------------
# model file
# ---------------------------------------------------------------------------------------------

class _Model:
    def __init__(self, terms):
        self.terms = dict(terms)

    def add_term(self, name, fn):
        self.terms[name] = fn

    def predict(self, theta_deg):
        th = np.deg2rad(np.asarray(theta_deg, dtype=float))
        return sum(np.asarray(f(th), dtype=float) for f in self.terms.values())


def test_model_file_round_trip(tmp_path):
    ev, _ = make_evidence(np.random.default_rng(31), inject={"graduation_error": {2: (0.4, 0.3), 5: (0.2, 1.0)}})
    res = trace(ev)
    payload = res["model_file"]
    assert payload["effects"] and payload["effects"][0]["name"] == "graduation_error"
    path = tmp_path / "traced.json"
    save_model(path, payload)
    loaded = load_model(path)
    assert loaded == [(e["name"], e["params"]) for e in payload["effects"]]
    terms = model_terms_from_payload(path)
    fn = terms["traced:graduation_error"]
    th = np.linspace(0, 2 * np.pi, 50)
    p = payload["effects"][0]["params"]
    expect = p["a2_arcsec"] * np.sin(2 * th) + p["b2_arcsec"] * np.cos(2 * th) + p["a5_arcsec"] * np.sin(5 * th) + p["b5_arcsec"] * np.cos(5 * th)
    np.testing.assert_allclose(fn(th), expect, atol=1e-12)
    # the correction closes the loop: model + traced term reproduces α at the readings
    m = _Model({})
    assert add_to_error_model(m, path) == ["traced:graduation_error"]
    r_after = ev.residual_arcsec - m.predict(ev.theta_deg)
    r_after -= np.bincount(ev.closure_group, r_after)[ev.closure_group] / np.bincount(ev.closure_group)[ev.closure_group]
    assert float(np.sqrt(np.mean(r_after ** 2))) < 1.5 * 0.07
    with pytest.raises(ValueError):
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps({"format": "x", "version": 1, "effects": []}))
        load_model(bad)


def test_model_file_gain_effect_uses_the_model_terms(tmp_path):
    ev, _ = make_evidence(np.random.default_rng(32), selfcal=True, inject={"optical_radius": {"delta_r_mm": 0.1}})
    res = trace(ev)
    names = [e["name"] for e in res["identified_effects"]]
    assert names and names[0] in ("optical_radius", "ccd_pixel_scale")
    save_model(tmp_path / "m.json", res["model_file"])
    assert model_terms_from_payload(tmp_path / "m.json") == {}  # scaling effects need the base terms
    ecc = lambda th: 66.57 * np.sin(th - math.radians(192.08))  # noqa: E731
    m = _Model({"eccentricity": ecc})
    added = add_to_error_model(m, tmp_path / "m.json")
    assert added == [f"traced:{names[0]}"]
    th = np.linspace(0, 2 * np.pi, 7)
    g = m.terms[added[0]](th) / ecc(th)
    assert np.allclose(g, g[0]) and -0.006 < g[0] < -0.003  # −Δr/r ≈ −0.45 %


def test_with_the_project_error_model(tmp_path):
    em = pytest.importorskip("benchtwin.analysis.error_model")
    ev, _ = make_evidence(np.random.default_rng(33), inject={"graduation_error": {3: (0.3, 0.5)}})
    res = trace(ev)
    save_model(tmp_path / "m.json", res["model_file"])
    model = em.ErrorModel(r_um=22000.0)
    add_to_error_model(model, tmp_path / "m.json")
    y = model.predict(np.array([0.0, 30.0]))
    assert y.shape == (2,) and np.all(np.isfinite(y))


# ---------------------------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------------------------

def test_figures(tmp_path):
    from benchtwin.analysis.report.figures_loop import figures_loop

    ev, _ = make_evidence(np.random.default_rng(41), directions=(1, -1), start_faces=range(1, 24, 3),
                          inject={"graduation_error": {2: (0.4, 0.3)}})
    res = trace(ev)
    paths = figures_loop(ev, res, tmp_path)
    for p in paths:
        assert p.exists() and p.stat().st_size > 10_000


def test_docs_list_every_effect_and_threshold():
    from pathlib import Path

    from benchtwin.analysis import tracing
    from benchtwin.analysis.effects import ALL

    text = (Path(__file__).resolve().parents[2] / "docs" / "effects.md").read_text(encoding="utf-8")
    for name in ALL:
        assert f"`{name}`" in text, name
    for const in ("P_SIG", "Z_GATE", "DBIC_GATE", "AMBIG_DBIC", "COLLINEAR", "TIE_REL"):
        v = getattr(tracing, const)
        assert f"`{const}` = {v:g}" in text or f"`{const}` = {v:.0e}".replace("e-0", "e-") in text, (const, v)


def test_evidence_from_polygon_table():
    """Adapter from polygon.csv columns + β + U (Hsieh eqs. 3, 7) to Evidence: α = ε − Σβ − U."""
    from benchtwin.analysis.tracing import BenchContext, RadialMotion, evidence_from_polygon

    ev, truth = make_evidence(np.random.default_rng(51), start_faces=[1, 7, 20], directions=(1, -1))
    cols = {"shift_deg": ev.shift_deg, "start_face": ev.start_face, "step": ev.step, "theta_deg": ev.theta_deg,
            "ac_arcsec": ev.ac_arcsec, "t_s": ev.t_s, "direction": np.where(ev.direction > 0, "forward", "backward")}
    U = {(float(s), int(j)): float(u) for s, j, u in zip(ev.shift_deg, ev.start_face, truth["U"])}
    radial = RadialMotion(truth["grid_deg"], truth["top_um"], truth["bottom_um"], 6.81, 122.96)
    ev2 = evidence_from_polygon(cols, truth["beta"], U, truth["model_terms"],
                                BenchContext(n_faces=23, radial=radial, encoder_lines=36000))
    np.testing.assert_allclose(ev2.alpha_arcsec, truth["alpha_true"], atol=1e-9)
    np.testing.assert_array_equal(ev2.direction, ev.direction)
    np.testing.assert_array_equal(ev2.face, ev.face)
    assert set(ev2.model_terms) == {"eccentricity", "radial_motion_integral"}
    assert trace(ev2)["status"] == "no_significant_residual"  # α exact: the model explains it (to the probe noise)


def test_signature_ccd_eccentricity():
    """CCD d_ref (Jia eqs. 10–12): first harmonic → e, θ0 of eq. 3 (camera at 180°)."""
    from benchtwin.analysis.tracing import CCDData

    ev, _ = make_evidence(np.random.default_rng(61))
    th = np.arange(0.0, 360.0, 6.0)
    d = 3.0 + 7.1 * np.cos(np.deg2rad(th - 192.08)) + 0.05 * np.sin(np.deg2rad(4 * th))
    ev.ccd = CCDData(th, d + np.random.default_rng(62).normal(0, 0.02, th.size))
    s = signature(ev)["ccd"]
    assert abs(s["e_um"] - 7.1) < 0.02 and abs(s["theta0_deg"] - 192.08) < 0.3
    assert 0.02 < s["rms_orders_2_10_um"] < 0.06


def test_jia_eccentricity_uncertainty_hides_a_gain_on_the_eccentricity():
    """With Jia's u(e) = 0.24 µm and u(θ0) = 1.13° (sec. 5), a 1 % pixel-scale error is within the
    model's own uncertainty; with a self-calibration too (the same nuisance acts on its rows)."""
    for selfcal in (False, True):
        ev, _ = make_evidence(np.random.default_rng(71), selfcal=selfcal,
                              inject={"ccd_pixel_scale": {"scale_error_pct": 1.0}})
        ev.add_eccentricity_uncertainty(7.1, 192.08, 0.24, 1.13)
        assert set(ev.model_sensitivity) == {"u_e", "u_theta0"}
        res = trace(ev)
        assert res["status"] == "no_significant_residual", res["status"]


# ---------------------------------------------------------------------------------------------
# gates (issue 7 follow-up): plausibility, degenerate pairs, practical size, stationarity,
# tangential motion without X probes, asynchronous motion
# ---------------------------------------------------------------------------------------------

def _cands(res, names):
    return [c for c in res["candidates"] if sorted(c["names"]) == sorted(names)]


def test_degenerate_cancelling_pair_is_rejected():
    """Half of the ∫δY term missing from the data and a 0.3 % eccentricity gain: +gain on the whole
    model and −gain on the eccentricity term cancel to leave −0.5·∫δY, with gains of ~50 %
    (Δr = 11 mm): implausible and a degenerate pair — never an identification."""
    ev, _ = make_evidence(np.random.default_rng(81), noise_arcsec=0.03)
    ev.alpha_arcsec = (ev.alpha_arcsec - 0.5 * ev.model_terms["radial_motion_integral"]
                       + 0.003 * ev.model_terms["eccentricity"])
    res = trace(ev, candidates=["optical_radius", "ccd_pixel_scale"])
    (pair,) = _cands(res, ["optical_radius", "ccd_pixel_scale"])
    why = " ".join(pair["rejected_because"])
    assert "degenerate pair" in why and "implausible" in why
    assert abs(pair["params"]["optical_radius"]["delta_r_mm"]) > 5  # the fit itself is absurd
    assert {e["name"] for e in res["identified_effects"]} != {"optical_radius", "ccd_pixel_scale"}
    assert res["status"] == "unexplained"  # the single gain leaves the ∫δY part: not forced


def test_physically_implausible_size_is_rejected():
    """A head radius 11 % off the datasheet (2.5 mm at 22 mm) is beyond what any gain of the library
    can plausibly be (radius 5 %, pixel scale 10 %, autocollimator 5 %): unexplained, not forced."""
    ev, _ = make_evidence(np.random.default_rng(82), inject={"optical_radius": {"delta_r_mm": 2.5}})
    res = trace(ev)
    assert res["status"] == "unexplained" and not res["identified_effects"]
    (c,) = _cands(res, ["optical_radius"])
    assert any("implausible" in r and "5%" in r for r in c["rejected_because"])


def test_small_effect_below_the_noise_floor_is_not_a_finding():
    """A 0.1 % gain on the eccentricity term (0.047″ RMS) is resolved statistically by 529 readings
    of 0.02″ noise, but it is below a quarter of a 0.25″ noise floor (u_c of one α): not a finding."""
    kw = dict(noise_arcsec=0.02, inject={"ccd_pixel_scale": {"scale_error_pct": 0.1}})
    ev, _ = make_evidence(np.random.default_rng(83), **kw)
    res = trace(ev)
    names = {e["name"] for e in res["identified_effects"]} | {n for a in res["ambiguous"] for n in a["names"]}
    assert "ccd_pixel_scale" in names  # without a floor: statistically and practically significant
    ev2, _ = make_evidence(np.random.default_rng(83), **kw)
    ev2.u_floor_arcsec = 0.25
    res2 = trace(ev2)
    assert not res2["identified_effects"] and res2["residual_before"]["noise_floor_arcsec"] == 0.25
    (c,) = _cands(res2, ["ccd_pixel_scale"])
    assert any("noise floor" in r for r in c["rejected_because"])
    assert c["f_test_p"] < 1e-3  # the F-test alone would have passed it


def test_chi2_after_is_held_to_the_practical_size_gate():
    """The χ² after the chosen effect is read by the same rule as the χ² before ("anything to
    explain?": p < P_SIG AND an excess RMS ≥ SIZE_GATE × the noise floor). A 1″ division error with
    a reading scatter 0.06″ beyond the stated u (529 readings: χ²/dof ≈ 1.7 after, p ≪ 1e-3): against
    a 0.25″ floor (u_c of one α) the excess, ≈ 0.05″ RMS, is below a calibration's resolution and
    the division error is identified; with the floor at the readings' u (0.07″) the same excess is
    of practical size and the verdict is "unexplained" (loop validation seed 71, ac_drift #0)."""
    def scatter(th, t):
        return np.random.default_rng(5).normal(0.0, 0.06, np.size(th))

    kw = dict(inject={"graduation_error": {4: (1.0, 0.3)}}, extra=scatter, x_probes=True)
    ev, _ = make_evidence(np.random.default_rng(84), **kw)
    ev.u_floor_arcsec = 0.25
    res = trace(ev)
    assert res["residual_after"]["p_value"] < 1e-3  # resolved statistically
    # identified, not "unexplained": in the set with sphere_form, since both X and Y readings of the
    # top sphere hold order 4 (0.1 µm lobes) and a 0.11 µm form read by the X probe gives the same
    # harmonic (sphere_form.ambiguous_with; a reversal of the sphere separates them)
    assert res["status"] == "ambiguous", (res["status"], res["residual_after"].get("signature_left"))
    assert [e["name"] for e in res["identified_effects"]] == ["graduation_error"]
    assert [a["names"] for a in res["ambiguous"]] == [["graduation_error", "sphere_form"]]
    ev2, _ = make_evidence(np.random.default_rng(84), **kw)
    res2 = trace(ev2)
    assert res2["status"] == "unexplained" and res2["residual_after"]["signature_left"][0].startswith("χ² after")


def test_tangential_motion_without_x_probes_is_ambiguous_with_graduation():
    """An X motion the Y probes do not see (independent X lobes) reads like a division error: the
    answer is the set {graduation_error, tangential_motion} and the separating measurement names
    the X probes; with the X probes the same data give tangential_motion alone."""
    kw = dict(noise_arcsec=0.05, inject={"tangential_motion": {"gain": 1.0}})
    ev, _ = make_evidence(np.random.default_rng(84), **kw)
    res = trace(ev)
    (amb,) = res["ambiguous"]
    assert {"graduation_error", "tangential_motion"} <= set(amb["names"])
    assert "X probes" in amb["separating_measurement"]
    ev2, _ = make_evidence(np.random.default_rng(84), x_probes=True, **kw)
    res2 = trace(ev2)
    assert [e["name"] for e in res2["identified_effects"]] == ["tangential_motion"] and not res2["ambiguous"]
    # and a division error with the X probes present is named without tangential_motion in its set
    # (they exclude an X motion); a 0.045 µm form of the top sphere, which both its probes' 0.1 µm
    # lobes at order 4 can hold, gives the same harmonic: the set with sphere_form (a reversal
    # separates them)
    ev3, _ = make_evidence(np.random.default_rng(84), x_probes=True, inject={"graduation_error": {4: (0.4, 1.0)}})
    res3 = trace(ev3)
    assert [e["name"] for e in res3["identified_effects"]] == ["graduation_error"]
    assert [a["names"] for a in res3["ambiguous"]] == [["graduation_error", "sphere_form"]], res3["ambiguous"]


def test_growing_pattern_is_not_stationary():
    """A harmonic whose amplitude grows during the session is refused as a stationary effect: the
    after-residual keeps 'the θ pattern changes with time'."""
    ev, _ = make_evidence(np.random.default_rng(85), extra=_h7)
    res = trace(ev)
    assert res["status"] == "unexplained" and not res["identified_effects"]
    tp = res["signature"]["time_pattern"]
    assert tp["significant"] and 7 in tp["harmonics"]
    assert any("changes with time" in x for x in res["unexplained_signature"]["left"])


def test_async_motion_from_the_rep_to_rep_scatter():
    """Non-repeating motion: smooth harmonics 1–3 drawn anew per rep (σ = 0.05 µm per coefficient,
    0.087 µm RMS), probe noise 0.01 µm: its RMS is found, the noise subtracted; without it nothing is
    claimed; in the fits it is one random offset per stop position."""
    from benchtwin.analysis.tracing import RadialMotion, _Problem

    rng = np.random.default_rng(86)
    th = np.tile(np.arange(0.0, 360.0, 3.0), 5)
    rep = np.repeat(np.arange(5), 120)
    t = np.deg2rad(th)
    base = 0.2 * np.sin(3 * t)
    top, top0 = base + rng.normal(0, 0.01, th.size), base + rng.normal(0, 0.01, th.size)
    for r in range(5):
        m = rep == r
        for k in (1, 2, 3):
            top[m] += rng.normal(0, 0.05) * np.sin(k * t[m]) + rng.normal(0, 0.05) * np.cos(k * t[m])
    bottom = 0.1 * np.sin(3 * t) + rng.normal(0, 0.01, th.size)
    a = RadialMotion(th, top, bottom, 6.81, 122.96, rep=rep).async_rms("top_um")
    assert a["significant"] and 0.05 < a["sigma_um"] < 0.13 and abs(a["noise_um"] - 0.01) < 0.0025
    a0 = RadialMotion(th, top0, bottom, 6.81, 122.96, rep=rep).async_rms("top_um")
    assert not a0["significant"] and a0["sigma_um"] == 0.0
    assert RadialMotion(th, top, bottom, 6.81, 122.96).async_rms() == {}  # no reps: nothing claimed
    ev, _ = make_evidence(np.random.default_rng(87))
    ev.radial = RadialMotion(th, top, bottom, 6.81, 122.96, rep=rep)
    ev.model_terms["radial_motion_integral"] = ev.radial.integral_at(ev.theta_deg, "dY_um") / 22000.0 * 206264.8
    pb = _Problem(ev, use_selfcal=False)
    assert pb.async_info["sigma_um"] > 0 and pb._async_cache.shape[1] == np.unique(ev.theta_bin).size  # one per stop


def test_backward_whirl_of_order_1_is_taken_by_the_tangential_motion():
    """An order-1 motion of the axis against the rotation (B·e^{−iθ}: no centring makes it; the
    ball-bearing benches of issue 32, e.g. 0.13 µm at seed 581 tilt_abbe #0) is read by head 1 as
    −B_x/r, and the CCD opposite the head, which reads c_y's order 1 as one forward circle, puts
    another −B_x/r into the model's eccentricity: −2B_x/r left, 1.6″ RMS there. The X and Y probes
    together measure B, so tangential_motion's regressor carries it; without it the loop said
    "unexplained" (χ² ≈ 85 000 for 500 dof on this evidence)."""
    ev, _ = make_evidence(np.random.default_rng(5), start_faces=range(1, 24, 2), x_probes=True,
                          inject={"tangential_motion": {"gain": 1.0}}, backward_whirl_um=0.08 - 0.05j)
    res = trace(ev)
    assert res["status"] == "explained" and not res["unexplained"], res["status"]
    assert [e["name"] for e in res["identified_effects"]] == ["tangential_motion"]
    g = res["identified_effects"][0]["params"]["gain"]
    assert abs(g - 1.0) < 0.1, g
    ra = res["residual_after"]
    assert ra["chi2"] < 1.3 * ra["dof"], (ra["chi2"], ra["dof"])


def test_reported_effect_with_its_regressor_adjustment_reproduces_the_residual_after():
    """The identified effect as reported (its parameters and ``regressor_adjustment_coefs``, what
    the model file and the report's figure use) gives back the residual after that the fit left,
    at the polygon's stops: the adjustment is stored as the function of θ it is (every order of the
    X probes' δX series), not as a 10-order fit of its samples at the stops."""
    from benchtwin.analysis.report.figures_loop import _centred_residual, effect_contribution

    ev, _ = make_evidence(np.random.default_rng(5), start_faces=range(1, 24, 2), x_probes=True,
                          inject={"tangential_motion": {"gain": 1.0}}, backward_whirl_um=0.08 - 0.05j)
    K = ev.radial.highest_order
    assert K > 10, K  # δX beyond eq. 7's orders: what a 10-order fit dropped
    res = trace(ev)
    (eff,) = res["identified_effects"]
    coefs = eff["regressor_adjustment_coefs"]
    assert sorted(int(k) for k in coefs) == list(range(1, K + 1))
    left = _centred_residual(ev) - effect_contribution(ev, res)
    rms = float(np.sqrt(np.mean(left ** 2)))
    assert rms == pytest.approx(res["residual_after"]["rms_arcsec"], rel=1e-9, abs=1e-12)
