"""analysis/tracing/errors_in_variables.py against Deming regression's closed form (Fuller,
*Measurement Error Models*, 1987, §1.3): a straight line through the origin, y = g·x*, with both
the readings y (σ_y) and the regressor x = x* + σ_x·ν measured, the variances known."""

import math

import numpy as np
import pytest

from benchtwin.analysis.tracing.errors_in_variables import gauss_newton


def _fit_fn(sigma_y: float):
    """The weighted fit with a unit-prior nuisance (``_Problem.fit``'s contract, no model nuisance):
    beta, nuis, chi2 (residuals in units of σ_y, plus ‖ν‖²)."""
    def fit(X, extra=None, target=None):
        n, p = X.shape
        E = np.zeros((n, 0)) if extra is None else extra
        q = E.shape[1]
        A = np.vstack([np.hstack([X, E]) / sigma_y, np.hstack([np.zeros((q, p)), np.eye(q)])])
        b = np.concatenate([np.asarray(target, float) / sigma_y, np.zeros(q)])
        sol, *_ = np.linalg.lstsq(A, b, rcond=None)
        r = b - A @ sol
        cov = np.linalg.pinv(A.T @ A)[:p, :p]
        return {"beta": sol[:p], "nuis": sol[p:], "chi2": float(r @ r), "cov": cov}
    return fit


def _deming_through_origin(x, y, sigma_x, sigma_y):
    """The closed form: g minimising Σ (y − g·x)² / (σ_y² + g²·σ_x²)."""
    d = sigma_y ** 2 / sigma_x ** 2
    sxx, syy, sxy = x @ x, y @ y, x @ y
    return ((syy - d * sxx) + math.sqrt((syy - d * sxx) ** 2 + 4 * d * sxy ** 2)) / (2 * sxy)


def test_gauss_newton_is_demings_estimate_and_undoes_the_attenuation():
    rng = np.random.default_rng(20261207)
    n, g_true, sigma_x, sigma_y = 60, 1.0, 0.5, 0.1
    n_attenuated = 0
    for _ in range(5):
        x_true = rng.normal(0.0, 1.0, n)
        y = g_true * x_true + rng.normal(0.0, sigma_y, n)
        x = x_true + rng.normal(0.0, sigma_x, n)
        fit_fn = _fit_fn(sigma_y)
        ols = fit_fn(x[:, None], target=y)
        g_ols = float(ols["beta"][0])
        # the regressor's nuisance at the OLS gain: the selection's fixed point starts there
        units = [sigma_x * np.eye(n)]
        start = fit_fn(x[:, None], extra=g_ols * units[0], target=y)
        d = gauss_newton(fit_fn, y, x[:, None], units, start["beta"], start["nuis"], 0)
        g = float(d.fit["beta"][0])
        u = math.sqrt(d.fit["cov"][0, 0])
        assert d.converged and d.objective <= d.objective_start
        # the closed form, to the iteration's tolerance
        assert g == pytest.approx(_deming_through_origin(x, y, sigma_x, sigma_y), rel=1e-5)
        assert abs(g - g_true) < 3 * u, (g, u)
        # the fit of the measured regressor is attenuated by the reliability ratio 1/(1 + σ_x²) = 0.8
        n_attenuated += g_ols < g_true - 0.1
    assert n_attenuated >= 4, n_attenuated
