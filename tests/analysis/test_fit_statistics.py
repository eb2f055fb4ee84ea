"""Issue 32: headline residuals that can fail (error_model.fit_statistics, sampling_advice) and the
refined eccentricity's u with its confounding with a first-order graduation term
(error_model.refine_eccentricity ``u_k1_arcsec``, pipeline.k1_prior)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.analysis.error_model import (EccentricityEstimate, eccentricity_term, fit_statistics, refine_eccentricity,
                                            sampling_advice)


def _brute_loo(J, y, u, prior=None):
    """Each point predicted by the weighted least-squares fit made without it (refit from scratch)."""
    out = []
    for i in range(y.size):
        m = np.arange(y.size) != i
        w = 1.0 / u[m] ** 2
        A = J[m].T @ (J[m] * w[:, None]) + (0.0 if prior is None else prior)
        x = np.linalg.solve(A, J[m].T @ (w * y[m]))
        out.append(y[i] - J[i] @ x)
    return np.array(out)


@pytest.mark.parametrize("with_prior", [False, True])
def test_loo_is_the_brute_force_refit(with_prior):
    rng = np.random.default_rng(32)
    n, p = 12, 4
    J = rng.normal(size=(n, p))
    u = rng.uniform(0.5, 2.0, n)
    y = J @ rng.normal(size=p) + rng.normal(0.0, u)
    prior = np.diag([4.0, 0.0, 0.25, 0.0]) if with_prior else None
    w = 1.0 / u ** 2
    x = np.linalg.solve(J.T @ (J * w[:, None]) + (0.0 if prior is None else prior), J.T @ (w * y))
    r = y - J @ x
    st = fit_statistics(J, r, u, prior)
    np.testing.assert_allclose(st["loo_residual_arcsec"], _brute_loo(J, y, u, prior), rtol=1e-9, atol=1e-12)
    assert st["loo_rms_arcsec"] == pytest.approx(float(np.sqrt(np.mean(_brute_loo(J, y, u, prior) ** 2))), rel=1e-9)
    assert st["n_params"] == p and st["dof"] == n - p
    assert st["chi2"] == pytest.approx(float(np.sum((r / u) ** 2)))
    assert 0.0 < st["p_value"] < 1.0


def test_interpolation_cannot_be_tested():
    # as many parameters as points: dof 0, no p, no prediction of a left-out point
    rng = np.random.default_rng(3)
    J = rng.normal(size=(6, 6))
    st = fit_statistics(J, np.zeros(6), 1.0)
    assert st["dof"] == 0 and st["p_value"] is None and st["loo_rms_arcsec"] is None
    # collinear columns count once (rank)
    st2 = fit_statistics(np.column_stack([J[:, 0], 2 * J[:, 0], J[:, 1]]), rng.normal(size=6), 1.0)
    assert st2["n_params"] == 2 and st2["dof"] == 4


def test_sampling_advice_below_three_dof():
    assert sampling_advice(69, 23) is None and sampling_advice(26, 23) is None
    msg = sampling_advice(23, 23)
    assert msg is not None and "cannot test the model" in msg and "23 parameters fitted to 23 stops" in msg
    assert "shift-angle" in msg and "26 distinct angles" in msg
    assert sampling_advice(24, 22) is not None and "2 degrees of freedom" in sampling_advice(24, 22)


def _graduated_bench(rng, u_pt=0.05, n=60, g1=(0.6, -0.4)):
    """α at n stops: eccentricity + a first-order graduation term g1 (″, sin/cos) + orders 2…6 of
    1″; the CCD's e, θ0 drawn with their u around the truth."""
    r, e, t0 = 22000.0, 7.1, 192.08
    th = np.arange(n) * 360.0 / n
    t = np.radians(th)
    amp = rng.uniform(0.5, 1.5, (5, 2))
    grad = sum(a * np.sin(k * t) + b * np.cos(k * t) for k, (a, b) in zip(range(2, 7), amp))
    alpha = eccentricity_term(e, t0, r)(t) + g1[0] * np.sin(t) + g1[1] * np.cos(t) + grad + rng.normal(0, u_pt, n)
    u_e, u_t = 0.2, 1.5
    e_ccd, t_ccd = e + rng.normal(0, u_e), t0 + rng.normal(0, u_t)
    res = alpha - eccentricity_term(e_ccd, t_ccd, r)(t)
    cols = np.column_stack([f(k * t) for k in range(2, 7) for f in (np.sin, np.cos)])
    sig = {"harmonics": [{"k": k, "a_arcsec": float(a), "b_arcsec": float(b)} for k, (a, b) in zip(range(2, 7), amp)]}
    return th, res, u_pt, e, e_ccd, t_ccd, u_e, u_t, r, cols, sig


def test_refined_e_covers_a_first_order_graduation_term():
    """α cannot tell a k = 1 graduation term from eccentricity: with the prior of pipeline.k1_prior
    the refined e is within 2u of the truth on every draw; without it (u_k1 = 0) the comparison
    reads the graduation term as e and states a u far too small (z of tens)."""
    from benchtwin.analysis.pipeline import k1_prior

    z_with, z_without = [], []
    for seed in range(20):
        th, res, u_pt, e, e_ccd, t_ccd, u_e, u_t, r, cols, sig = _graduated_bench(np.random.default_rng(seed))
        u_k1, source = k1_prior(sig)
        assert 0.5 < u_k1 < 1.5 and "orders 2…6" in source
        ref = refine_eccentricity(th, res, u_pt, EccentricityEstimate(e_ccd, t_ccd, u_e, u_t), r, u_k1_arcsec=u_k1,
                                  columns=cols)
        z_with.append((ref["e_um"] - e) / ref["u_e_um"])
        ref0 = refine_eccentricity(th, res, u_pt, EccentricityEstimate(e_ccd, t_ccd, u_e, u_t), r, columns=cols)
        z_without.append((ref0["e_um"] - e) / ref0["u_e_um"])
        assert ref["u_e_um"] > ref0["u_e_um"]
        # the joint fit: 1 constant + the first harmonic + 10 graduation columns fitted to 60 stops
        assert ref["fit"]["n_params"] == 13 and ref["fit"]["dof"] == 47
        assert ref["fit"]["loo_rms_arcsec"] == pytest.approx(u_pt, rel=0.5)
    assert max(abs(z) for z in z_with) < 2.0
    assert np.median(np.abs(z_without)) > 5.0


def test_k1_prior_without_harmonics():
    from benchtwin.analysis.pipeline import k1_prior

    assert k1_prior({})[0] == 0.0
    assert k1_prior({"harmonics": [{"k": 1, "a_arcsec": 5.0, "b_arcsec": 5.0}]})[0] == 0.0
    u, _ = k1_prior({"harmonics": [{"k": 2, "a_arcsec": 3.0, "b_arcsec": -4.0}]})
    assert u == pytest.approx(math.sqrt(12.5))
