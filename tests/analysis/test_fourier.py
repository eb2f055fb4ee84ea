"""Tests of the least-squares Fourier series (Jia 2019 eqs. 6, 7, 10, 11, 12)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchtwin.analysis.fourier import (
    amplitude_phase,
    design_matrix,
    evaluate,
    fit_fourier,
    param_index,
    remove_harmonics,
)


def _series(theta_deg, params):
    return design_matrix(theta_deg, (len(params) - 1) // 2) @ np.asarray(params)


def test_exact_recovery_on_nonuniform_grid():
    rng = np.random.default_rng(11)
    th = np.sort(rng.uniform(0, 360, 90))
    p = rng.normal(0, 1, 21)
    fit = fit_fourier(th, _series(th, p), order=10)
    np.testing.assert_allclose(fit.params, p, atol=1e-10)
    assert fit.a0 == pytest.approx(p[0])
    np.testing.assert_allclose(fit.a, p[1::2], atol=1e-10)  # sine
    np.testing.assert_allclose(fit.b, p[2::2], atol=1e-10)  # cosine
    assert fit.dof == 90 - 21


def test_sine_and_cosine_columns_are_the_right_way_round():
    th = np.arange(0, 360, 6.0)
    y = 2.0 * np.sin(np.radians(th)) + 0.5 * np.cos(np.radians(3 * th))
    fit = fit_fourier(th, y, order=4)
    assert fit.a[0] == pytest.approx(2.0) and fit.b[0] == pytest.approx(0.0, abs=1e-12)
    assert fit.b[2] == pytest.approx(0.5) and fit.a[2] == pytest.approx(0.0, abs=1e-12)
    assert param_index(0) == (0,) and param_index(3) == (5, 6)


def test_covariance_from_residuals_matches_monte_carlo():
    rng = np.random.default_rng(5)
    th = np.sort(rng.uniform(0, 360, 60))
    p = rng.normal(0, 1, 21)
    sigma = 0.05
    fits = [fit_fourier(th, _series(th, p) + rng.normal(0, sigma, th.size), 10) for _ in range(600)]
    P = np.array([f.params for f in fits])
    sd_mc = P.std(axis=0, ddof=1)
    sd_gum = np.sqrt(np.mean([np.diag(f.cov) for f in fits], axis=0))
    np.testing.assert_allclose(sd_gum, sd_mc, rtol=0.12)
    assert np.mean([f.sigma for f in fits]) == pytest.approx(sigma, rel=0.05)


def test_covariance_with_given_u_is_absolute():
    th = np.arange(0, 360, 10.0)
    A = design_matrix(th, 3)
    y = np.zeros(th.size)  # zero residual: the given u must still give a covariance
    fit = fit_fourier(th, y, order=3, u=0.2)
    np.testing.assert_allclose(fit.cov, 0.04 * np.linalg.inv(A.T @ A), rtol=1e-10, atol=1e-14)
    assert fit.u_given


def test_evaluate_subset_and_callable():
    th = np.linspace(0, 360, 37)[:-1]
    p = np.arange(1.0, 8.0)  # order 3
    fit = fit_fourier(th, _series(th, p), order=3)
    q = np.array([12.5, 200.0])
    np.testing.assert_allclose(fit(q), _series(q, p), atol=1e-10)
    only2 = p * 0
    only2[3:5] = p[3:5]
    np.testing.assert_allclose(evaluate(fit, q, harmonics=[2]), _series(q, only2), atol=1e-10)
    assert fit.u_evaluate(q).shape == q.shape


def test_remove_harmonics_eq7():
    th = np.arange(360.0)
    t = np.radians(th)
    y = 4.0 + 3.0 * np.cos(t - 0.4) + 0.2 * np.sin(2 * t) + 0.1 * np.cos(5 * t) + 0.05 * np.sin(15 * t)
    d, fit = remove_harmonics(th, y)  # eq. 7 literally: harmonics 2…10
    np.testing.assert_allclose(d, 0.2 * np.sin(2 * t) + 0.1 * np.cos(5 * t), atol=1e-12)
    d2, _ = remove_harmonics(th, y, keep_residual=True)  # y − (0th + 1st)
    np.testing.assert_allclose(d2, 0.2 * np.sin(2 * t) + 0.1 * np.cos(5 * t) + 0.05 * np.sin(15 * t), atol=1e-12)


@pytest.mark.parametrize("theta0_deg", [0.0, 35.0, 90.0, 135.0, 180.0, 192.08, 270.0, 315.0])
def test_amplitude_phase_all_quadrants(theta0_deg):
    # d_ref = e·cos(θ − θ0) = e sinθ0 · sinθ + e cosθ0 · cosθ  → c1 = e sinθ0, d1 = e cosθ0
    th = np.arange(0, 360, 6.0)
    e = 7.1
    y = 3.0 + e * np.cos(np.radians(th - theta0_deg))
    ap = amplitude_phase(fit_fourier(th, y, 10), 1)
    assert ap["amplitude"] == pytest.approx(e, abs=1e-10)
    assert (ap["phase_deg"] - theta0_deg + 180) % 360 - 180 == pytest.approx(0.0, abs=1e-9)
    assert 0.0 <= ap["phase_deg"] < 360.0


def test_amplitude_phase_uncertainty_matches_monte_carlo():
    rng = np.random.default_rng(21)
    th = np.arange(0, 360, 6.0)
    truth = 7.1 * np.cos(np.radians(th - 192.08))
    sigma = 0.3
    A, PH, UA, UP = [], [], [], []
    for _ in range(800):
        ap = amplitude_phase(fit_fourier(th, truth + rng.normal(0, sigma, th.size), 10), 1)
        A.append(ap["amplitude"])
        PH.append(ap["phase_deg"])
        UA.append(ap["u_amplitude"])
        UP.append(ap["u_phase_deg"])
    assert np.std(A, ddof=1) == pytest.approx(np.mean(UA), rel=0.12)
    assert np.std(PH, ddof=1) == pytest.approx(np.mean(UP), rel=0.12)
    # analytic check for uniform θ: u(c1) = σ·sqrt(2/N)
    assert np.mean(UA) == pytest.approx(sigma * math.sqrt(2 / th.size), rel=0.1)


def test_bad_input_raises():
    with pytest.raises(ValueError, match="parameters"):
        fit_fourier(np.arange(10.0), np.zeros(10), order=10)
    with pytest.raises(ValueError, match="rank deficient"):
        fit_fourier(np.r_[np.zeros(20), np.full(20, 180.0)], np.zeros(40), order=3)
    with pytest.raises(ValueError, match="samples"):
        fit_fourier(np.arange(30.0), np.zeros(29), order=2)
    with pytest.raises(ValueError, match="finite"):
        fit_fourier(np.arange(30.0), np.r_[np.zeros(29), np.nan], order=2)
    with pytest.raises(ValueError, match="harmonic"):
        amplitude_phase(fit_fourier(np.arange(0, 360, 10.0), np.zeros(36), 2), 3)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-100, 100, allow_nan=False), min_size=11, max_size=11),
       st.integers(min_value=11, max_value=200))
def test_recovery_property(params, n):
    p = np.asarray(params)
    th = (np.arange(n) + 0.37) * 360.0 / n
    fit = fit_fourier(th, _series(th, p), order=5)
    np.testing.assert_allclose(fit.params, p, atol=1e-8 * (1 + np.abs(p).max()))


def test_series_over_chosen_harmonics_is_the_same_least_squares():
    """fit_harmonics (the tracing's and the effects' series over chosen orders) on orders 2…10 with a free
    mean and a free order 1 is eq. 7's fit: the same coefficients and type-A u as fit_fourier of order 10;
    evaluate_harmonics / integrate_harmonics are the series and its antiderivative."""
    from benchtwin.analysis.fourier import evaluate_harmonics, fit_harmonics, integrate_harmonics

    rng = np.random.default_rng(12)
    th = np.sort(rng.uniform(0, 360, 150))
    y = _series(th, rng.normal(0, 1, 21)) + rng.normal(0, 0.1, th.size)
    full = fit_fourier(th, y, order=10)
    coefs, u = fit_harmonics(th, y, range(2, 11), nuisance_ks=(1,), return_u=True)
    for k in range(2, 11):
        ia, ib = param_index(k)
        assert coefs[k] == pytest.approx((full.params[ia], full.params[ib]), rel=1e-10, abs=1e-12)
        assert u[k] == pytest.approx((math.sqrt(full.cov[ia, ia]), math.sqrt(full.cov[ib, ib])), rel=1e-8)
    np.testing.assert_allclose(evaluate_harmonics(th, coefs), evaluate(full, th, range(2, 11)), atol=1e-10)
    # d/dθ of the antiderivative is the series (θ in radians)
    h = 1e-6
    d = (integrate_harmonics(th + np.rad2deg(h), coefs) - integrate_harmonics(th - np.rad2deg(h), coefs)) / (2 * h)
    np.testing.assert_allclose(d, evaluate_harmonics(th, coefs), atol=1e-6)


def test_series_over_chosen_harmonics_is_minimum_norm_where_undetermined():
    """Eight equally spaced angles cannot tell order 3 from order 5 (aliases): no error, the minimum-norm
    split, which reproduces the data."""
    from benchtwin.analysis.fourier import evaluate_harmonics, fit_harmonics

    th = np.arange(8) * 45.0
    y = np.sin(np.deg2rad(3 * th))
    coefs = fit_harmonics(th, y, [3, 5], with_mean=False)
    np.testing.assert_allclose(evaluate_harmonics(th, coefs), y, atol=1e-12)
    assert all(np.isfinite(v).all() for v in map(np.asarray, coefs.values()))


def test_harmonic_rows_are_the_bits_of_each_orders_own_sine():
    """fourier.harmonic_rows (kept for the last few θ): each row the bits np.sin(k·θ) / np.cos(k·θ)
    gives for that order alone, read-only, and the same arrays when asked again."""
    from benchtwin.analysis.fourier import harmonic_rows
    th = np.random.default_rng(5).uniform(0, 2 * np.pi, size=(3, 37))
    ks = [2, 3, 17, 40]
    S, C = harmonic_rows(th, ks)
    assert S.shape == C.shape == (4, 3, 37)
    for i, k in enumerate(ks):
        assert np.array_equal(S[i], np.sin(k * th)) and np.array_equal(C[i], np.cos(k * th))
    assert not S.flags.writeable and harmonic_rows(th.copy(), ks)[0] is S
    assert harmonic_rows(th + 1e-12, ks)[0] is not S


def test_graduation_term_is_the_order_by_order_sum():
    """The graduation error's model term (analysis/effects/graduation_error.py), evaluated from the
    kept rows, equals the sum of a_k sin kθ + b_k cos kθ taken order by order, bit for bit."""
    from benchtwin.analysis.effects import graduation_error as g
    rng = np.random.default_rng(6)
    ks = list(range(2, 30))
    params = {f"{c}{k}_arcsec": float(v) for k in ks for c, v in zip("ab", rng.normal(size=2))}
    th = rng.uniform(0, 2 * np.pi, size=200)
    want = sum(params[f"a{k}_arcsec"] * np.sin(k * th) + params[f"b{k}_arcsec"] * np.cos(k * th) for k in ks) + 0.0 * th
    fn = g.term(params, {"orders": ks})
    assert np.array_equal(fn(th), want) and np.array_equal(fn(th), want)


def test_harmonic_rows_keep_a_bounded_number_of_bytes():
    """The kept rows stay within ``_ROWS_KEPT`` entries and ``_ROWS_BYTES`` beside the newest entry
    (a long-lived process keeps them)."""
    from benchtwin.analysis import fourier as fo
    big = int(fo._ROWS_BYTES / (2 * 8 * 40)) // 2 + 1      # an entry of 40 orders: a little over half the cap
    for j in range(3):
        fo.harmonic_rows(np.linspace(0.0, 1.0 + j, big), range(1, 41))
    assert len(fo._ROWS) <= fo._ROWS_KEPT
    assert sum(a.nbytes + b.nbytes for a, b in fo._ROWS.values()) <= fo._ROWS_BYTES
    for j in range(6):
        fo.harmonic_rows(np.linspace(0.0, 1.0 + j, 7), [2, 3])
    assert len(fo._ROWS) == fo._ROWS_KEPT
