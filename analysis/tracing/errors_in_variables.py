"""The consistent estimate of a named effect whose regressor is measured: errors in variables.

tangential_motion's regressor is the X probes' δX (and eq. 5's ∫δY), tilt_abbe's the probes' tilt
motion: each is the true motion plus the probes' own noise, x + P·ν with ν ~ N(0, I) and P the
columns of the regressor's type-A u (``_Problem.regressor_nuisance``). The model of the readings is
then bilinear, y = X(x)·β + E(β)·ν + S·s + noise, with E(β) = Σ_j β_j·U_j linear in the parameters
(g·P_δX, h·P_∫δY, ΔL1·P_tilt).

The selection (analysis/tracing/selection.py ``_evaluate``) re-linearises only E(β) and keeps the
*measured* regressor as the column: its fixed point is the fit of the measured regressor, whose gain
the regressor's own noise attenuates by the reliability ratio (regression dilution: Fuller,
*Measurement Error Models*, Wiley 1987, §1.1). On the twin's X-probe benches that fit gives
g = 0.38–0.85 where the truth's gain is 1 (docs/loop-validation.md, "The measured motion's gain,
attenuated by the probes' own noise"). The selection's gates were derived on that fit and stay on
it; the estimate reported for the chosen candidate is this module's.

:func:`gauss_newton` minimises the joint least squares over (β, ν) with the variances known
(Deming regression; Fuller §1.3, §2.3): at (β₀, ν₀) a step fits y + E(β₀)·ν₀ with the columns
X + J(ν₀), J_j = U_j·ν₀, and the nuisance E(β₀) (its unit prior rows). E is linear in β, so J is
exact. A step is kept only where the objective profiled over ν at its β, φ(β) = min_ν ‖y − X·β −
E(β)·ν‖²_W + ‖ν‖² (with the model nuisance S), falls; else it is halved. φ never rises, so the
iteration cannot oscillate; it stops when β changes by less than ``RTOL`` or no halving of a step
lowers φ (both reported as converged), or after ``MAX_STEPS`` (reported as not converged, at the
lowest φ found). The covariance is the
Gauss–Newton one of the last linearisation: the regressor's uncertainty enters through J and E.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

#: at most MAX_STEPS Gauss–Newton steps, until the parameters change by < RTOL (relative)
MAX_STEPS = 30
RTOL = 1e-6
#: a step that does not lower the profiled objective is halved at most HALVINGS times
HALVINGS = 6


@dataclass(frozen=True)
class DemingFit:
    """The settled linearisation: ``fit`` (the ``_Problem.fit`` dict of the columns X + J at the
    settled ν, whose ``beta`` and ``cov`` are the estimate and its Gauss–Newton covariance, and whose
    ``chi2`` is the joint objective there), ``extra`` = E(β) at the settled β (the nuisance columns
    whose fitted values are the regressor's adjustment), the number of steps taken, whether β
    settled within RTOL, and the objective before (the selection's fit) and after."""

    fit: dict[str, Any]
    extra: np.ndarray
    steps: int
    converged: bool
    objective_start: float
    objective: float


def gauss_newton(fit_fn: Callable[..., dict[str, Any]], y: np.ndarray, X: np.ndarray,
                 units: list[np.ndarray], beta0: np.ndarray, nu0: np.ndarray, n_model_nuisance: int) -> DemingFit:
    """Deming's joint least squares for y = X·β + E(β)·ν, E(β) = Σ_j β_j·``units[j]``, from the
    selection's fit (β₀ = ``beta0``, ν₀ = ``nu0``, the regressor nuisance's fitted values).
    ``fit_fn(X, extra=E, target=t)`` is the weighted fit with the model nuisance (``_Problem.fit``):
    its ``nuis`` holds the model nuisance's ``n_model_nuisance`` values first, then E's."""
    q = int(n_model_nuisance)
    b0 = np.asarray(beta0, dtype=float)
    nu = np.asarray(nu0, dtype=float)

    def E_of(b: np.ndarray) -> np.ndarray:
        out = np.zeros_like(units[0])
        for bj, Uj in zip(b, units):
            out += bj * Uj
        return out

    def profile(b: np.ndarray) -> dict[str, Any]:
        return fit_fn(np.zeros((X.shape[0], 0)), extra=E_of(b), target=y - X @ b)

    phi_start = phi0 = float(profile(b0)["chi2"])
    steps, converged = 0, False
    for _ in range(MAX_STEPS):
        E0 = E_of(b0)
        J = np.column_stack([Uj @ nu for Uj in units])
        step = fit_fn(X + J, extra=E0, target=y + E0 @ nu)
        b1 = np.asarray(step["beta"], dtype=float)
        for _h in range(HALVINGS + 1):
            f1 = profile(b1)
            if f1["chi2"] <= phi0:
                break
            b1 = 0.5 * (b0 + b1)
        else:
            converged = True   # no lower objective along the step: β₀ is the minimum to within the halvings
            break
        steps += 1
        done = bool(np.allclose(b1, b0, rtol=RTOL, atol=0.0))
        b0, phi0, nu = b1, float(f1["chi2"]), np.asarray(f1["nuis"], dtype=float)[q:]
        if done:
            converged = True
            break
    E0 = E_of(b0)
    J = np.column_stack([Uj @ nu for Uj in units])
    fit = fit_fn(X + J, extra=E0, target=y + E0 @ nu)
    return DemingFit(fit=fit, extra=E0, steps=steps, converged=converged, objective_start=phi_start,
                     objective=phi0)
