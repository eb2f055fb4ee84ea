"""The corrected calibration result (issue 16): the encoder's error after removing the identified
artefacts of the reference chain, with the uncertainty of each correction; the raw curve when
nothing is identified."""

from __future__ import annotations

import numpy as np

from benchtwin.analysis.effects.synthetic import make_evidence
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
