"""Angle measurement error model of a rotary encoder (Jia 2019, eq. 5) and its comparison with a
measured encoder error.

Jia et al., Appl. Sci. 9 (2019) 3415, eq. 5:

    Δθ(θ) = [ e·sin(θ − θ0) + ∫_0^θ δY(θ') dθ' ] / r

with e, θ0 the disk eccentricity and its phase (eqs. 11-12, :mod:`benchtwin.analysis.eccentricity`),
δY the radial error motion of the disk along the reading head (eq. 9,
:mod:`benchtwin.analysis.radial_motion`) and r the optical radius. Sign: Δθ is "reading − true"
like the encoder error α of docs/conventions.md. Results in arcsec.

The model is a sum of named terms (:class:`ErrorModel`), so that further effects can be added as
terms of their own. Each term may carry a standard-uncertainty function; terms flagged
``inverse_r`` scale with 1/r and share the uncertainty of r (a correlated contribution, added
linearly over those terms before squaring).

Integration of δY (the paper is silent on the numerics): the samples are taken as one period of a
periodic function; the integral is that of the piecewise-linear interpolant (trapezoid rule), exact
between the grid points (piecewise quadratic). ∫δY over a full turn is 2π·mean(δY); a series without
0th harmonic (eq. 7) has zero mean, so the integral is periodic. On a grid where the trapezoid mean
is not exactly zero (non-uniform θ, or δY not from eq. 7) the mean is removed first by default and
reported (``radial_motion_term(...).removed_mean_um``), otherwise Δθ would not be periodic.

Comparison with a measured α(θ) (e.g. polygon + autocollimator, sec. 4.3, fig. 16): α is known only
up to a constant (polygon set-up / closure), so the mean of both curves is removed before
comparing; the residual is measured − model. Jia: residual within ±6″, 9 % of the angle error.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchtwin.units import ARCSEC

__all__ = [
    "ErrorModel",
    "Term",
    "eccentricity_term",
    "radial_motion_term",
    "radial_motion_term_fourier",
    "radial_motion_u_gum",
    "integral_design_matrix",
    "periodic_integral",
    "jia_error_model",
    "EccentricityEstimate",
    "RadialCurve",
    "error_model_from_results",
    "compare_with_measured",
    "refine_eccentricity",
    "fit_statistics",
    "sampling_advice",
]

TermFn = Callable[[np.ndarray], np.ndarray]  # θ [rad] → arcsec


@dataclass
class Term:
    """One named contribution: ``fn(θ_rad) → arcsec``; ``u_fn(θ_rad) → arcsec`` (standard
    uncertainty, independent of the other terms) or None; ``inverse_r``: the term is ∝ 1/r."""

    fn: TermFn
    u_fn: TermFn | None = None
    inverse_r: bool = False
    info: dict = field(default_factory=dict)

    def __call__(self, theta_rad: np.ndarray) -> np.ndarray:
        return self.fn(theta_rad)


class ErrorModel:
    """Δθ(θ) as a sum of named terms (Jia eq. 5 and whatever is added).

    ``terms``: dict name → :class:`Term` (a bare callable θ_rad → arcsec is accepted by
    :meth:`add_term`). ``r_um``, ``u_r_um``: optical radius and its uncertainty.
    """

    def __init__(self, r_um: float, u_r_um: float = 0.0, terms: dict[str, Term | TermFn] | None = None):
        if not (r_um > 0):
            raise ValueError(f"optical radius must be > 0, got {r_um} µm")
        self.r_um = float(r_um)
        self.u_r_um = float(u_r_um)
        self.terms: dict[str, Term] = {}
        for k, v in (terms or {}).items():
            self.add_term(k, v)

    def add_term(self, name: str, fn: Term | TermFn, u_fn: TermFn | None = None, inverse_r: bool = False) -> None:
        """Add (or replace) a named term; ``fn(θ_rad) → arcsec``."""
        if not isinstance(fn, Term):
            fn = Term(fn, u_fn, inverse_r)
        self.terms[name] = fn

    def predict_terms(self, theta_deg: np.ndarray) -> dict[str, np.ndarray]:
        th = np.deg2rad(np.asarray(theta_deg, dtype=float))
        return {k: np.asarray(t(th), dtype=float) * np.ones_like(th) for k, t in self.terms.items()}

    def predict(self, theta_deg: np.ndarray, terms: list[str] | None = None) -> np.ndarray:
        """Δθ in arcsec at the encoder angles ``theta_deg`` (sum of all or the listed terms)."""
        parts = self.predict_terms(theta_deg)
        names = list(parts) if terms is None else terms
        missing = [n for n in names if n not in parts]
        if missing:
            raise KeyError(f"unknown terms {missing}; have {list(parts)}")
        return sum((parts[n] for n in names), np.zeros(np.shape(theta_deg)))

    def uncertainty(self, theta_deg: np.ndarray) -> np.ndarray:
        """Standard uncertainty u(Δθ) in arcsec: per-term u in quadrature, plus u(r) acting on all
        ``inverse_r`` terms together (∂Δθ/∂r = −Δθ_{1/r}/r)."""
        th = np.deg2rad(np.asarray(theta_deg, dtype=float))
        var = np.zeros(th.shape)
        inv = np.zeros(th.shape)
        for t in self.terms.values():
            if t.u_fn is not None:
                var = var + np.asarray(t.u_fn(th), dtype=float) ** 2
            if t.inverse_r:
                inv = inv + np.asarray(t.fn(th), dtype=float)
        var = var + (inv * self.u_r_um / self.r_um) ** 2
        return np.sqrt(var)

    def __repr__(self) -> str:
        return f"ErrorModel(r_um={self.r_um}, terms={list(self.terms)})"


def eccentricity_sensitivities(theta_rad: np.ndarray, e_um: float, theta0_rad: float,
                                r_um: float) -> tuple[np.ndarray, np.ndarray]:
    """∂Δθ/∂e [rad/µm] and ∂Δθ/∂θ0 [rad/rad] of Jia eq. 3, Δθ = (e/r)·sin(θ − θ0)."""
    return np.sin(theta_rad - theta0_rad) / r_um, -e_um / r_um * np.cos(theta_rad - theta0_rad)


def eccentricity_term(e_um: float, theta0_deg: float, r_um: float, u_e_um: float = 0.0,
                      u_theta0_deg: float = 0.0, cov_e_theta0: float = 0.0) -> Term:
    """Jia eq. 3: (e/r)·sin(θ − θ0) in arcsec. ``cov_e_theta0`` in µm·deg (from the Fourier fit)."""
    e, th0, r = float(e_um), math.radians(theta0_deg), float(r_um)
    ut0 = math.radians(u_theta0_deg)
    c = math.radians(cov_e_theta0)

    def fn(theta_rad: np.ndarray) -> np.ndarray:
        return e / r * np.sin(theta_rad - th0) / ARCSEC

    def u_fn(theta_rad: np.ndarray) -> np.ndarray:
        de, dt = eccentricity_sensitivities(theta_rad, e, th0, r)
        var = (de * u_e_um) ** 2 + (dt * ut0) ** 2 + 2 * de * dt * c
        return np.sqrt(np.clip(var, 0, None)) / ARCSEC

    return Term(fn, u_fn, inverse_r=True, info={"e_um": e, "theta0_deg": theta0_deg, "u_e_um": u_e_um,
                                                 "u_theta0_deg": u_theta0_deg})


def periodic_integral(theta_deg: np.ndarray, y: np.ndarray, remove_mean: bool = True):
    """Antiderivative Y(θ) = ∫_0^θ y dθ' [y·rad] of periodic samples, as a callable of θ in degrees.

    Trapezoid rule on the periodic grid (the last interval wraps from the largest θ to the smallest
    + 360°); between grid points the exact integral of the linear interpolant. With ``remove_mean``
    the trapezoid mean ȳ = ∫y/2π is subtracted first so that Y is periodic. Returns (callable,
    removed mean).
    """
    th = np.asarray(theta_deg, dtype=float).ravel() % 360.0
    yy = np.asarray(y, dtype=float).ravel()
    if th.size != yy.size or th.size < 2:
        raise ValueError(f"need ≥ 2 samples of equal length, got {th.size} θ and {yy.size} values")
    order = np.argsort(th)
    th, yy = th[order], yy[order]
    if np.any(np.diff(th) <= 0):
        raise ValueError("duplicate angles in the δY grid (average repetitions first)")
    x = np.deg2rad(np.concatenate([th, [th[0] + 360.0]]))
    v = np.concatenate([yy, [yy[0]]])
    h = np.diff(x)
    seg = 0.5 * h * (v[:-1] + v[1:])
    mean = float(seg.sum() / (2 * math.pi))
    if remove_mean:
        v = v - mean
        seg = 0.5 * h * (v[:-1] + v[1:])
    cum = np.concatenate([[0.0], np.cumsum(seg)])  # ∫ from x[0] to x[k]
    total = cum[-1]  # 0 when the mean is removed

    def prim(theta_rad: np.ndarray) -> np.ndarray:
        """∫ from x[0] to θ (θ in rad, any real value)."""
        t = np.asarray(theta_rad, dtype=float)
        turns = np.floor((t - x[0]) / (2 * math.pi))
        tt = t - turns * 2 * math.pi  # in [x0, x0 + 2π)
        k = np.clip(np.searchsorted(x, tt, side="right") - 1, 0, x.size - 2)
        dt = tt - x[k]
        slope = (v[k + 1] - v[k]) / h[k]
        return cum[k] + v[k] * dt + 0.5 * slope * dt**2 + turns * total

    p0 = prim(np.array(0.0))

    def Y(theta_deg_q: np.ndarray) -> np.ndarray:
        return prim(np.deg2rad(np.asarray(theta_deg_q, dtype=float))) - p0

    return Y, mean


def radial_motion_term(theta_grid_deg: np.ndarray, dY_um: np.ndarray, r_um: float,
                       u_dY_um: float | np.ndarray = 0.0, correlated: bool = False,
                       remove_mean: bool = True) -> Term:
    """Jia eq. 5, second part: (1/r)·∫_0^θ δY dθ' in arcsec, δY sampled on ``theta_grid_deg``.

    ``u_dY_um``: standard uncertainty of δY (scalar or per grid point). ``correlated=False``: the
    grid values are independent, u(∫) is the trapezoid weights' root-sum-square up to θ;
    ``correlated=True``: fully correlated, u(∫) = ∫ u dθ' (an upper bound). The paper is silent; the
    default treats the per-point values as independent.
    """
    th = np.asarray(theta_grid_deg, dtype=float).ravel()
    Y, mean = periodic_integral(th, dY_um, remove_mean)
    uu = np.broadcast_to(np.asarray(u_dY_um, dtype=float), th.shape)
    r = float(r_um)

    def fn(theta_rad: np.ndarray) -> np.ndarray:
        return Y(np.rad2deg(theta_rad)) / r / ARCSEC

    if correlated:
        U, _ = periodic_integral(th, uu, remove_mean=False)

        def u_fn(theta_rad: np.ndarray) -> np.ndarray:
            return np.abs(U(np.rad2deg(theta_rad))) / r / ARCSEC
    else:
        U2, _ = periodic_integral(th, uu**2, remove_mean=False)
        # trapezoid weights ~ h: Var(Σ w_k y_k) = Σ w_k² u_k² ≈ h̄ · ∫ u² dθ (uniform grid)
        hbar = 2 * math.pi / th.size

        def u_fn(theta_rad: np.ndarray) -> np.ndarray:
            return np.sqrt(np.clip(hbar * np.abs(U2(np.rad2deg(theta_rad))), 0, None)) / r / ARCSEC

    t = Term(fn, u_fn, inverse_r=True, info={"removed_mean_um": mean, "correlated": correlated})
    t.removed_mean_um = mean  # type: ignore[attr-defined]
    return t


def radial_motion_term_fourier(params_um: np.ndarray, r_um: float) -> Term:
    """∫_0^θ δY dθ' / r for δY given as a Fourier series [a0, a1, b1, ...] (µm), analytically:
    ∫_0^θ (a_i sin iθ' + b_i cos iθ') dθ' = a_i (1 − cos iθ)/i + b_i sin(iθ)/i (a0 must be 0 for a
    periodic result; it is integrated as a0·θ)."""
    p = np.asarray(params_um, dtype=float)
    order = (p.size - 1) // 2
    r = float(r_um)

    def fn(theta_rad: np.ndarray) -> np.ndarray:
        t = np.asarray(theta_rad, dtype=float)
        s = p[0] * t
        for i in range(1, order + 1):
            s = s + p[2 * i - 1] * (1 - np.cos(i * t)) / i + p[2 * i] * np.sin(i * t) / i
        return s / r / ARCSEC

    return Term(fn, None, inverse_r=True)


def integral_design_matrix(theta_deg: np.ndarray, order: int) -> np.ndarray:
    """Rows b(θ) with ``b(θ)·p = ∫_0^θ δY dθ'`` [µm·rad] for δY = the Fourier series p = [a0, a1, b1, ...]
    (:mod:`benchtwin.analysis.fourier` order): θ, (1 − cos iθ)/i, sin(iθ)/i."""
    t = np.deg2rad(np.asarray(theta_deg, dtype=float)).ravel()
    B = np.empty((t.size, 2 * order + 1))
    B[:, 0] = t
    for i in range(1, order + 1):
        B[:, 2 * i - 1] = (1.0 - np.cos(i * t)) / i
        B[:, 2 * i] = np.sin(i * t) / i
    return B


def radial_motion_u_gum(rm: dict, r_um: float) -> TermFn:
    """GUM standard uncertainty of (1/r)·∫_0^θ δY dθ' [arcsec] for the δY of
    :func:`benchtwin.analysis.radial_motion.radial_motion` taken as the spindle's synchronous motion.

    The covariance of δY's Fourier coefficients (``dY_cov_sync``: from the repetitions' scatter,
    harmonic by harmonic — probe noise and the asynchronous motion in the mean of n revolutions;
    the fit covariance ``dY_cov`` for one revolution) is propagated exactly through the integral,
    ``u² = b(θ)ᵀ C b(θ)`` (:func:`integral_design_matrix`): δY's errors are smooth functions of θ,
    neither independent nor fully correlated from one grid angle to the next.
    """
    order = int(rm["order"])
    C = np.asarray(rm["dY_cov_sync"] if "dY_cov_sync" in rm else rm["dY_cov"], dtype=float)
    r = float(r_um)

    def u_fn(theta_rad: np.ndarray) -> np.ndarray:
        th = np.rad2deg(np.asarray(theta_rad, dtype=float))
        B = integral_design_matrix(th, order)
        var = np.nan_to_num(np.einsum("ij,jk,ik->i", B, C, B), nan=0.0)
        return (np.sqrt(np.clip(var, 0.0, None)) / r / ARCSEC).reshape(th.shape)

    return u_fn


@dataclass(frozen=True)
class EccentricityEstimate:
    """(e, θ0) of Jia eq. 3 (µm, deg) with their standard uncertainties and covariance (µm·deg, from
    the Fourier fit of eq. 11): the CCD's eccentricity as eq. 5 and :func:`refine_eccentricity` use it."""

    e_um: float
    theta0_deg: float
    u_e_um: float = 0.0
    u_theta0_deg: float = 0.0
    cov_e_theta0_um_deg: float = 0.0

    @classmethod
    def from_results(cls, ecc: Mapping[str, Any]) -> EccentricityEstimate:
        """From the dict of :func:`benchtwin.analysis.eccentricity.eccentricity_from_dref` (``e_um``,
        ``theta0_deg``, ``e_u_um``, ``theta0_u_deg``, ``cov_e_theta0``; the last three 0 when absent)."""
        return cls(ecc["e_um"], ecc["theta0_deg"], ecc.get("e_u_um", 0.0), ecc.get("theta0_u_deg", 0.0),
                   ecc.get("cov_e_theta0", 0.0))


@dataclass(frozen=True)
class RadialCurve:
    """The disk's radial motion δY (µm, eq. 9) on a θ grid (deg) for eq. 5's radial-motion term, with
    its standard uncertainty (µm, one number or per grid point) and whether that u is correlated over
    θ (:func:`radial_motion_term`)."""

    theta_grid_deg: np.ndarray
    dY_um: np.ndarray
    u_dY_um: float | np.ndarray = 0.0
    correlated: bool = False


def jia_error_model(ecc: EccentricityEstimate, r_um: float, radial: RadialCurve | None = None,
                    u_r_um: float = 0.0) -> ErrorModel:
    """Jia eq. 5 as an :class:`ErrorModel` with terms "eccentricity" and (if δY given) "radial_motion"."""
    m = ErrorModel(r_um, u_r_um)
    m.add_term("eccentricity", eccentricity_term(ecc.e_um, ecc.theta0_deg, r_um, ecc.u_e_um, ecc.u_theta0_deg,
                                                 ecc.cov_e_theta0_um_deg))
    if radial is not None:
        m.add_term("radial_motion", radial_motion_term(radial.theta_grid_deg, radial.dY_um, r_um, radial.u_dY_um,
                                                       radial.correlated))
    return m


def error_model_from_results(ecc: dict, rm: dict | None, r_um: float, u_r_um: float = 0.0,
                             dY_uncertainty: str = "range", dY_correlated: bool = False) -> ErrorModel:
    """Eq. 5 from the dicts of :func:`benchtwin.analysis.eccentricity.eccentricity_from_dref` (or
    ``eccentricity_from_images``) and :func:`benchtwin.analysis.radial_motion.radial_motion`.

    ``dY_uncertainty``: "range" (Jia sec. 5: one number, max range over the repetitions / d_n — the
    σ of one repetition, as the paper uses it — taken as independent from one grid angle to the
    next), "range_mean" (range / d_n per θ, divided by √n: the uncertainty of the synchronous mean
    actually used, same independence), "gum" (:func:`radial_motion_u_gum`: the covariance of the
    synchronous δY from the repetitions' scatter propagated through the integral with its
    correlation over θ), or "none".
    """
    grid = dY = None
    u_dY: float | np.ndarray = 0.0
    if rm is not None:
        grid, dY = np.asarray(rm["theta_deg"]), np.asarray(rm["dY_um"])
        if dY_uncertainty == "range":
            u_dY = float(np.nan_to_num(rm["u_dY_range_um"]))
        elif dY_uncertainty == "range_mean":
            u_dY = np.nan_to_num(np.asarray(rm["u_dY_range_theta_um"])) / math.sqrt(rm["n_reps"])
        elif dY_uncertainty == "gum":
            pass  # the covariance propagation replaces the per-point u below
        elif dY_uncertainty != "none":
            raise ValueError(f"dY_uncertainty must be 'range', 'range_mean', 'gum' or 'none', got {dY_uncertainty!r}")
    radial = None if grid is None or dY is None else RadialCurve(grid, dY, u_dY, dY_correlated)
    m = jia_error_model(EccentricityEstimate.from_results(ecc), r_um, radial, u_r_um)
    if rm is not None and dY_uncertainty == "gum":
        m.terms["radial_motion"].u_fn = radial_motion_u_gum(rm, r_um)
        m.terms["radial_motion"].info["u"] = "gum: covariance of the synchronous δY, through the integral"
    return m


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def compare_with_measured(theta_deg: np.ndarray, measured_arcsec: np.ndarray,
                          model: ErrorModel | np.ndarray) -> dict:
    """Residual = measured − model at the measured angles, both with their mean removed.

    The measured α (polygon + autocollimator) is only known up to a constant, hence the mean of
    each curve is removed (reported as ``measured_mean_arcsec``, ``model_mean_arcsec``).

    Keys: theta_deg, measured_arcsec, model_arcsec (both mean-free), residual_arcsec,
    residual_pv_arcsec, residual_rms_arcsec, residual_max_abs_arcsec, measured_pv_arcsec,
    measured_rms_arcsec, model_pv_arcsec, fraction_of_error (RMS(residual)/RMS(measured)),
    pv_ratio (P-V(residual)/P-V(measured)), measured_mean_arcsec, model_mean_arcsec, note.
    """
    th = np.asarray(theta_deg, dtype=float).ravel()
    meas = np.asarray(measured_arcsec, dtype=float).ravel()
    if th.size != meas.size or th.size == 0:
        raise ValueError(f"theta_deg ({th.size}) and measured_arcsec ({meas.size}) must have equal, non-zero length")
    pred = model.predict(th) if isinstance(model, ErrorModel) else np.asarray(model, dtype=float).ravel()
    if pred.size != th.size:
        raise ValueError(f"model has {pred.size} values for {th.size} angles")
    mm, pm = float(meas.mean()), float(pred.mean())
    meas0, pred0 = meas - mm, pred - pm
    res = meas0 - pred0
    rms_meas = _rms(meas0)
    return {
        "theta_deg": th,
        "measured_arcsec": meas0,
        "model_arcsec": pred0,
        "residual_arcsec": res,
        "residual_pv_arcsec": float(np.ptp(res)),
        "residual_rms_arcsec": _rms(res),
        "residual_max_abs_arcsec": float(np.max(np.abs(res))),
        "measured_pv_arcsec": float(np.ptp(meas0)),
        "measured_rms_arcsec": rms_meas,
        "model_pv_arcsec": float(np.ptp(pred0)),
        "fraction_of_error": _rms(res) / rms_meas if rms_meas > 0 else float("nan"),
        "pv_ratio": float(np.ptp(res) / np.ptp(meas0)) if np.ptp(meas0) > 0 else float("nan"),
        "measured_mean_arcsec": mm,
        "model_mean_arcsec": pm,
        "note": "mean of measured and model removed before comparison (α known up to a constant)",
    }


#: below this 1 − h_ii a stop determines a parameter by itself: no fit without it predicts it
LOO_LEVERAGE_TOL = 1e-8
#: a model is tested by its residual only with at least this many degrees of freedom left
MIN_TEST_DOF = 3


def fit_statistics(J: np.ndarray, residual_arcsec: np.ndarray, u_arcsec: np.ndarray | float,
                   prior_precision: np.ndarray | None = None) -> dict:
    """How far the residual of a weighted least-squares fit can test the fitted model.

    The fit: y ≈ J·x, weights w_i = 1/u_i², optionally a Gaussian prior of precision Λ on x (a
    parameter measured elsewhere, e.g. the CCD's e); ``residual_arcsec`` is r = y − J·x̂ at its
    solution (for a non-linear fit J is its Jacobian there: Gauss-Newton's last step).

    - ``n_params``: the rank of the weighted design W^½·J, i.e. the directions of x the data
      determine (a direction fixed only by its prior does not count); ``dof`` = n_points − n_params.
    - ``chi2`` = Σ (r_i/u_i)² with the u_i given (the caller states which yardstick), ``p_value`` =
      P(χ²_dof ≥ chi2); None when dof ≤ 0 (the residual cannot test anything).
    - leave-one-out: the PRESS residual (Allen 1974, Technometrics 16, 125) r_i/(1 − h_ii), h_ii the
      diagonal of the hat matrix H = W^½ J (JᵀWJ + Λ)⁻¹ Jᵀ W^½: point i predicted by the fit made
      without it, exactly for a linear fit (Sherman–Morrison: removing one row of a least-squares
      problem, the prior included), to first order at the solution for a non-linear one.
      ``loo_rms_arcsec`` is their RMS, None when a point alone determines a parameter
      (1 − h_ii < ``LOO_LEVERAGE_TOL``: no fit without it predicts it).
    """
    from benchtwin.analysis.distributions import chi2_sf

    r = np.asarray(residual_arcsec, dtype=float).ravel()
    J = np.asarray(J, dtype=float).reshape(r.size, -1)
    u = np.broadcast_to(np.asarray(u_arcsec, dtype=float), r.shape)
    sw = 1.0 / u
    Jw = J * sw[:, None]
    n, p = Jw.shape
    if p:
        norms = np.linalg.norm(Jw, axis=0)
        Jn = Jw[:, norms > 0] / norms[norms > 0]
        sv = np.linalg.svd(Jn, compute_uv=False) if Jn.size else np.zeros(0)
        rank = int(np.sum(sv > 1e-9 * sv[0])) if sv.size and sv[0] > 0 else 0
        A = Jw.T @ Jw + (np.zeros((p, p)) if prior_precision is None else np.asarray(prior_precision, dtype=float))
        h = np.einsum("ij,ij->i", Jw, np.linalg.lstsq(A, Jw.T, rcond=None)[0].T)
    else:
        rank, h = 0, np.zeros(n)
    dof = n - rank
    chi2 = float(np.sum((r * sw) ** 2))
    one_minus_h = 1.0 - h
    defined = one_minus_h > LOO_LEVERAGE_TOL
    loo = np.where(defined, r / np.where(defined, one_minus_h, 1.0), np.nan)
    return {"n_points": int(n), "n_params": rank, "dof": int(dof), "chi2": chi2,
            "p_value": float(chi2_sf(chi2, dof)) if dof > 0 else None,
            "loo_residual_arcsec": loo, "leverage": h,
            "loo_rms_arcsec": float(np.sqrt(np.mean(loo ** 2))) if bool(np.all(defined)) else None}


def sampling_advice(n_points: int, n_params: int) -> str | None:
    """None when the residual has ≥ ``MIN_TEST_DOF`` degrees of freedom; else the sentence the
    report, results.json and the certificate state: this sampling cannot test the model, and which
    would (Hsieh 2022's shift-angle method adds N stops per shift of an N-face polygon)."""
    dof = n_points - n_params
    if dof >= MIN_TEST_DOF:
        return None
    need = n_params + MIN_TEST_DOF
    return (f"this sampling cannot test the model: {n_params} parameters fitted to {n_points} stops leave {max(dof, 0)} "
            f"degrees of freedom, so the residual after is an interpolation, not a test. A sampling with at least "
            f"{need} distinct angles would test it: a shift-angle run (Hsieh 2022: the polygon re-mounted at "
            f"shifts S, e.g. 0, 5, 10°, N stops per shift) or a polygon with more faces; the leave-one-out "
            f"prediction then says how well the model predicts a stop it was not fitted to")


@dataclass(frozen=True)
class _Refit:
    """The joint fit of :func:`refine_eccentricity`: the stops (rad), residuals, weights, the linear
    columns, whether the k = 1 graduation term is fitted, r, the CCD's (e, θ0 rad) with covariance P,
    the CCD's eq. 3 term at the stops and the parameter count."""

    th: np.ndarray
    res: np.ndarray
    w: np.ndarray
    C: np.ndarray
    k1: bool
    u_k1_arcsec: float
    r_um: float
    m0: np.ndarray
    P: np.ndarray
    f0: np.ndarray
    n_par: int


def _refit_design(p: _Refit, x: np.ndarray) -> np.ndarray:
    """Arcsec per unit of each parameter at the stops: e [µm], θ0 [rad], (a1, b1) [″], c [″], δp."""
    de, dt = eccentricity_sensitivities(p.th, x[0], x[1], p.r_um)
    cols = [de / ARCSEC, dt / ARCSEC] + ([np.sin(p.th), np.cos(p.th)] if p.k1 else []) + [np.ones_like(p.th)]
    return np.column_stack(cols + [p.C])


def _refit_model(p: _Refit, x: np.ndarray) -> np.ndarray:
    """The modelled residual at the stops: ecc(e, θ0) − ecc(e_ccd, θ0_ccd) + the linear terms."""
    lin = _refit_design(p, x)[:, 2:] @ x[2:]
    return eccentricity_term(x[0], math.degrees(x[1]), p.r_um)(p.th) - p.f0 + lin


def _refit_precision(p: _Refit, prior_ccd: bool) -> np.ndarray:
    """The priors' precision matrix: the CCD's (e, θ0) (with ``prior_ccd``) and the k = 1 term's."""
    L = np.zeros((p.n_par, p.n_par))
    if prior_ccd:
        L[:2, :2] = np.linalg.inv(p.P)
    if p.k1:
        L[2, 2] = L[3, 3] = 1.0 / float(p.u_k1_arcsec) ** 2
    return L


def _gauss_newton(p: _Refit, prior_ccd: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Non-linear in θ0 (and e·θ0): Gauss-Newton from the CCD's values, to convergence (a δθ0 of
    degrees leaves e·δθ0² ≈ 0.01 µm in one linear step); the other parameters are linear.
    (x, covariance, Jacobian, prior precision)."""
    L = _refit_precision(p, prior_ccd)
    x0 = np.concatenate([p.m0, np.zeros(p.n_par - 2)])
    x = x0.copy()
    for _ in range(50):
        J = _refit_design(p, x)
        A = J.T @ (J * p.w[:, None]) + L
        g = J.T @ (p.w * (p.res - _refit_model(p, x))) - L @ (x - x0)
        step = np.linalg.lstsq(A, g, rcond=None)[0]
        x = x + step
        if abs(step[0]) <= 1e-12 * max(1.0, abs(x[0])) and abs(step[1]) <= 1e-14:
            break
    J = _refit_design(p, x)
    return x, np.linalg.pinv(J.T @ (J * p.w[:, None]) + L), J, L


def _refit_problem(theta_deg: np.ndarray, residual_arcsec: np.ndarray, u_arcsec: np.ndarray | float,
                   ccd: EccentricityEstimate, r_um: float, extra: tuple[float, np.ndarray | None]
                   ) -> tuple[_Refit, np.ndarray]:
    """The checked inputs as a :class:`_Refit` (``extra`` = (u_k1_arcsec, columns)) and u per stop."""
    u_k1_arcsec, columns = extra
    th = np.deg2rad(np.asarray(theta_deg, dtype=float).ravel())
    res = np.asarray(residual_arcsec, dtype=float).ravel()
    u_in = np.broadcast_to(np.asarray(u_arcsec, dtype=float), th.shape)
    if th.size < 4 or res.size != th.size or not np.all(np.isfinite(u_in)) or not np.all(u_in > 0):
        raise ValueError("refine_eccentricity: need ≥ 4 points with finite residuals and positive u")
    C = np.zeros((th.size, 0)) if columns is None else np.asarray(columns, dtype=float).reshape(th.size, -1)
    k1 = float(u_k1_arcsec) > 0.0
    r = float(r_um)
    m0 = np.array([float(ccd.e_um), math.radians(ccd.theta0_deg)])
    w = 1.0 / u_in ** 2
    f0 = eccentricity_term(m0[0], math.degrees(m0[1]), r)(th)
    n_par = 2 + (2 if k1 else 0) + 1 + C.shape[1]
    c = math.radians(ccd.cov_e_theta0_um_deg)
    P = np.array([[ccd.u_e_um ** 2, c], [c, math.radians(ccd.u_theta0_deg) ** 2]])
    return _Refit(th, res, w, C, k1, u_k1_arcsec, r, m0, P, f0, n_par), u_in


def refine_eccentricity(theta_deg: np.ndarray, residual_arcsec: np.ndarray, u_arcsec: np.ndarray | float,
                        ccd: EccentricityEstimate, r_um: float, *, u_k1_arcsec: float = 0.0,
                        columns: np.ndarray | None = None) -> dict:
    """(e, θ0) from the CCD (Jia eqs. 11-12; ``ccd``) combined with the first harmonic that a comparison
    with a measured α (polygon + autocollimator) still shows after the model, fitted jointly with the
    comparison's constant, a first-order graduation term and further linear ``columns``.

    The residual r_i = α_i − model_i at the stops is modelled as
    r = [ecc(e, θ0) − ecc(e_ccd, θ0_ccd)] + a1·sin θ + b1·cos θ + c + C·δp + noise:
    ecc the eq. 3 term, c the unknown constant of α, C the ``columns`` (each a unit change of a
    parameter of a traced effect at the stops: its correction δp is refitted here), noise
    independent with the points' standard uncertainties u_i. Priors: the CCD's (e, θ0) with its
    covariance P; the first-order graduation term (a1, b1) ~ N(0, u_k1²) per component — in α a
    k = 1 graduation term (the ruling's centre off the edge the CCD sees, and at N stops the orders
    N ± 1, 2N ± 1, ... that alias onto it) cannot be told from eccentricity, so the comparison
    measures e only as well as u_k1 allows (``u_k1_arcsec`` = 0: no such term, the former
    combination). The generalised least-squares estimate (minimum of Σ w_i r_i(x)² + the priors'
    quadratic forms; Gauss-Newton, non-linear in θ0) is the weighted combination of the CCD and
    the comparison (JCGM 102:2011 sec. 8; Cox 2002, Metrologia 39, 589, for the consistency check).
    The two are compared by χ² = dᵀ (P + C_c)⁻¹ d with 2 dof, d = x_c − x_ccd, x_c the comparison's
    own estimate (no CCD prior; its covariance C_c holds the k = 1 prior): p < 0.05 says the CCD's e
    disagrees with the comparison beyond both u. The u_i are taken as independent (the shift-angle
    α of neighbouring stops share parts of their budget, a constant that c absorbs).

    Returns e_um, theta0_deg, u_e_um, u_theta0_deg, cov_e_theta0 (µm·deg), the comparison's own
    e/θ0 estimate and u (``comparison``), ``ccd``, chi2, dof, p_value, n_points, ``k1_arcsec``
    ([a1, b1] and their u), ``column_params`` (δp), ``residual_arcsec`` (the residual at the
    solution) and ``fit`` (:func:`fit_statistics` of the joint fit, χ² against u_i).
    """
    from benchtwin.analysis.distributions import chi2_sf

    p, u_in = _refit_problem(theta_deg, residual_arcsec, u_arcsec, ccd, r_um, (u_k1_arcsec, columns))
    x, cov, J, L = _gauss_newton(p, True)
    xc, Cc, _, _ = _gauss_newton(p, False)
    d = xc[:2] - p.m0
    chi2 = float(d @ np.linalg.solve(p.P + Cc[:2, :2], d))
    resid = p.res - _refit_model(p, x)
    out = {"e_um": float(x[0]), "theta0_deg": float(math.degrees(x[1])),
           "u_e_um": float(math.sqrt(cov[0, 0])), "u_theta0_deg": float(math.degrees(math.sqrt(cov[1, 1]))),
           "cov_e_theta0": float(math.degrees(cov[0, 1])),
           "comparison": {"e_um": float(xc[0]), "theta0_deg": float(math.degrees(xc[1])),
                          "u_e_um": float(math.sqrt(Cc[0, 0])), "u_theta0_deg": float(math.degrees(math.sqrt(Cc[1, 1])))},
           "ccd": {"e_um": float(ccd.e_um), "theta0_deg": float(ccd.theta0_deg), "u_e_um": float(ccd.u_e_um),
                   "u_theta0_deg": float(ccd.u_theta0_deg)},
           "chi2": chi2, "dof": 2, "p_value": float(chi2_sf(chi2, 2)), "n_points": int(p.th.size),
           "column_params": x[p.n_par - p.C.shape[1]:].tolist(), "residual_arcsec": resid,
           "fit": fit_statistics(J, resid, u_in, L)}
    if p.k1:
        out["k1_arcsec"] = {"a1": float(x[2]), "b1": float(x[3]), "u_a1": float(math.sqrt(cov[2, 2])),
                            "u_b1": float(math.sqrt(cov[3, 3])), "u_prior": float(u_k1_arcsec)}
    return out
