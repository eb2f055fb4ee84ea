"""The corrected calibration result (issue 16): the encoder's error after removing the identified
artefacts of the reference chain, with the uncertainty of each correction; the raw curve when
nothing is identified."""

from __future__ import annotations

import numpy as np

from tests.synthetic.evidence import make_evidence
from benchtwin.analysis.pipeline import corrected_curve
from benchtwin.analysis.tracing import _center, trace


def _curve(ev, values):
    """A measured curve on the stop positions: the closure-centred readings averaged per θ."""
    ub, inv = np.unique(ev.theta_bin, return_inverse=True)   # stop positions (tracing.THETA_BIN_DEG)
    v = np.bincount(inv, values) / np.bincount(inv)
    th = ub * 0.05                                             # the bin's centre (0.05°)
    return {"theta_deg": th, "value": v, "u": np.full(ub.size, 0.05)}


def test_drift_of_the_autocollimator_is_removed_from_the_curve():
    ev, truth = make_evidence(np.random.default_rng(5), directions=(1, -1), start_faces=range(1, 24, 2),
                              inject={"ac_drift": {"drift_arcsec_per_s": 1e-3}})
    res = trace(ev)
    assert [e["name"] for e in res["identified_effects"]] == ["ac_drift"]
    corr = res["reference_corrections"]
    assert set(corr) == {"ac_drift"} and np.all(np.asarray(corr["ac_drift"]["u_arcsec"]) > 0)
    w2 = 1.0 / ev.u_arcsec ** 2
    meas = _center(ev.residual_arcsec, ev.closure_group, w2)
    true = _center(ev.residual_arcsec - 1e-3 * ev.t_s, ev.closure_group, w2)  # the drift the twin of it added
    # per reading: the correction takes the drift out (the readings' own noise stays)
    v = np.asarray(corr["ac_drift"]["value_arcsec"])
    err_raw = np.sqrt(np.mean((meas - true) ** 2))
    err_cor = np.sqrt(np.mean((meas - v - true) ** 2))
    assert err_cor < 0.1 * err_raw, (err_raw, err_cor)
    # on the curve: the mean correction of the readings at each stop, its u added
    raw = _curve(ev, meas)
    c = corrected_curve(raw, ev.theta_deg, corr)
    assert [a["effect"] for a in c["corrections_applied"]] == ["ac_drift"]
    near = np.abs(((ev.theta_deg[None, :] - raw["theta_deg"][:, None]) + 180.0) % 360.0 - 180.0) <= 0.025
    expect = np.array([v[m].mean() for m in near])
    np.testing.assert_allclose(c["value"], raw["value"] - expect, atol=1e-12)
    assert np.all(c["u"] > raw["u"])  # the correction's own u is added
    t = _curve(ev, true)["value"]
    assert np.all(np.abs(c["value"] - t) < 2 * c["u"] + 3 * 0.07 / np.sqrt(2)), np.max(np.abs(c["value"] - t))


def test_nothing_identified_leaves_the_raw_curve():
    ev, _ = make_evidence(np.random.default_rng(6))
    res = trace(ev)
    assert not res["identified_effects"] and not res.get("reference_corrections")
    raw = _curve(ev, ev.residual_arcsec)
    c = corrected_curve(raw, ev.theta_deg, res.get("reference_corrections") or {})
    assert c["corrections_applied"] == []
    np.testing.assert_array_equal(c["value"], raw["value"])
    np.testing.assert_array_equal(c["u"], raw["u"])


def test_reading_response_is_the_shift_angle_analysis_of_the_perturbation():
    """α is linear in the readings ε (Hsieh eqs. 5-7): adding q·ε² to every reading changes each α
    by exactly q × reading_response(ε²), the column ac_scale fits for a quadratic non-linearity."""
    from benchtwin.analysis.hsieh_pipeline import PolygonOptions, analyze_polygon
    from benchtwin.analysis.pipeline import _setup_error_lookup, reading_response
    from benchtwin.analysis.results import AutocollimatorDeclared
    from benchtwin.analysis.steps import PolygonAnalysis
    from benchtwin.analysis.tracing import BenchContext, evidence_from_polygon

    rng = np.random.default_rng(2)
    N = 7
    rows = [(0.0, j, i) for j in range(1, N + 1) for i in range(1, N + 1)] + [(20.0, 1, i) for i in range(1, N + 1)]
    S, j, i = (np.array(c) for c in zip(*rows))
    th = (i - 1) * 360.0 / N + S
    beta = rng.normal(0, 2.0, N)
    beta -= beta.mean()
    cum = np.concatenate([[0.0], np.cumsum(np.concatenate([beta, beta]))])
    eps = 3.0 * np.sin(np.deg2rad(2 * th)) + cum[j - 1 + i] - cum[j - 1] + rng.normal(0, 20.0, N + 1)[np.where(S > 0, N, j - 1)]
    eps = eps + rng.normal(0, 0.05, eps.size)
    q = 3e-4

    def alpha(e):
        cols = {"shift_deg": S, "start_face": j, "step": i, "theta_deg": th, "ac_arcsec": e, "t_s": np.arange(e.size)}
        pol = PolygonAnalysis.from_analysis(analyze_polygon(cols, N, options=PolygonOptions(mc_samples=0, u_eps_arcsec=0.05)),
                                            AutocollimatorDeclared(resolution_arcsec=0.001, accuracy_arcsec=0.05,
                                                                   source="test"), {}, [])
        ev = evidence_from_polygon(cols, pol.pitch_deviation_arcsec, _setup_error_lookup(pol),
                                   lambda t: {}, BenchContext(n_faces=N))
        return ev.alpha_arcsec, cols, pol

    a1, cols, pol = alpha(eps)
    a2, _, _ = alpha(eps + q * eps ** 2)
    resp = reading_response(cols, pol, eps ** 2, N)
    np.testing.assert_allclose(a2 - a1, q * resp, atol=1e-9)
    # ε² itself is not that column: the closure moves its face-fixed part into β, its run means into U
    assert np.sqrt(np.mean((q * eps ** 2 - (a2 - a1)) ** 2)) > 10 * np.sqrt(np.mean((q * resp - (a2 - a1)) ** 2)) + 1e-3
