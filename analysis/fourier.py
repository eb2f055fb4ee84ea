"""Least-squares Fourier series over one turn (Jia et al. 2019, eqs. 6, 7, 10, 11, 12).

Jia et al., "A New Method of Angle Measurement Error Analysis of Rotary Encoders",
Appl. Sci. 9 (2019) 3415:

- eq. 6 / eq. 10: ``y(θ) = a0 + Σ_{i=1}^{order} (a_i sin iθ + b_i cos iθ)``, order 10 in the paper,
  coefficients by least squares. The samples may be non-uniform in θ (the fit is a plain linear
  least-squares problem, not an FFT).
- eq. 7: the radial error motion is the series without the 0th (probe position) and 1st (sphere
  centring) harmonics.
- eqs. 11-12: amplitude and phase of a harmonic, ``c sin iθ + d cos iθ = A cos(iθ − φ)`` with
  ``A = sqrt(c² + d²)`` and ``φ = atan2(c, d)``. ``atan2`` covers all four quadrants, which is what
  the case analysis of eq. 12 spells out (d > 0: arctan(c/d); d < 0: arctan(c/d) + π; ...).

Parameter order everywhere in this module: ``[a0, a1, b1, a2, b2, ..., a_order, b_order]``
(``a`` multiplies sin, ``b`` multiplies cos). Angles in, degrees (``theta_deg``); the series is
in radians internally.

Covariance of the coefficients (GUM, linear least squares):

- no ``u`` given: ``s² (AᵀA)⁻¹`` with ``s² = RSS / (n − p)`` (type A, from the residual scatter);
- ``u`` given (standard uncertainty per point, same unit as ``y``): weighted least squares and the
  absolute covariance ``(Aᵀ W A)⁻¹`` with ``W = diag(1/u²)`` (the residual scatter is reported,
  not used).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from benchtwin.units import wrap_deg

__all__ = [
    "FourierFit",
    "design_matrix",
    "fit_fourier",
    "evaluate",
    "remove_harmonics",
    "amplitude_phase",
    "amplitude_phase_ab",
    "param_index",
    "harmonic_columns",
    "harmonic_rows",
    "fit_harmonics",
    "evaluate_harmonics",
    "integrate_harmonics",
    "perturbation_columns",
]

#: {k: (a_k, b_k)}: the coefficients of a series over a chosen set of harmonics (a: sin, b: cos)
Coefs = dict[int, tuple[float, float]]


def param_index(harmonic: int) -> tuple[int, ...]:
    """Indices of the parameters of one harmonic: (0,) for the mean, (2i−1, 2i) for (a_i, b_i)."""
    if harmonic < 0:
        raise ValueError(f"harmonic must be >= 0, got {harmonic}")
    return (0,) if harmonic == 0 else (2 * harmonic - 1, 2 * harmonic)


def harmonic_columns(theta_deg: np.ndarray, ks: Iterable[float], prefix: str = "",
                     unit: str = "arcsec", cos_first: bool = False) -> tuple[np.ndarray, list[str]]:
    """Columns ``[sin k₁θ, cos k₁θ, sin k₂θ, cos k₂θ, ...]`` for the harmonics ``ks`` (θ in degrees;
    n × 2·len(ks)) and their names ``{prefix}a{k}_{unit}`` / ``{prefix}b{k}_{unit}``: the terms of
    eq. 6 of the orders listed, the one place the package builds them. An order need not be an
    integer: k = 360°/P is a period P over an arc (analysis/arc_periods.py). ``cos_first``: each
    pair as ``[cos kθ, sin kθ]`` (ISO 230-7's a cos θ + b sin θ), names likewise."""
    th = np.deg2rad(np.asarray(theta_deg, dtype=float)).ravel()
    cols, names = [], []
    for k in ks:
        pair = [np.sin(k * th), np.cos(k * th)]
        pair_names = [f"{prefix}a{k}_{unit}", f"{prefix}b{k}_{unit}"]
        cols += pair[::-1] if cos_first else pair
        names += pair_names[::-1] if cos_first else pair_names
    X = np.column_stack(cols) if cols else np.zeros((th.size, 0))
    return X, names


#: the last few (θ, orders) of :func:`harmonic_rows`: a model term is evaluated again and again at
#: the same stops (the central differences of pipeline.traced_columns: two evaluations of every
#: order per parameter; the residual's signature), and the sines were most of the close-loop's time
#: (a 12-head shift-angle bench, 172 orders: 16 of 90 s)
_ROWS: OrderedDict[tuple, tuple[np.ndarray, np.ndarray]] = OrderedDict()
_ROWS_KEPT = 4
#: and no more than this many bytes beside the newest entry (a long-lived process, e.g. a study's
#: worker, keeps them: the hsieh2022 default's readings × 178 orders are 31 MB)
_ROWS_BYTES = 64 * 2 ** 20


def harmonic_rows(theta_rad: np.ndarray, ks: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """(sin kθ, cos kθ) at ``theta_rad`` (radians, any shape), one row per order of ``ks``
    (len(ks) × θ.shape), each row computed as ``np.sin(k * θ)`` is, so the same bits as the
    one-order expression. Read-only arrays, kept for the last few θ and orders asked for."""
    th = np.asarray(theta_rad, dtype=float)
    key = (tuple(int(k) for k in ks), th.shape, th.tobytes())
    hit = _ROWS.get(key)
    if hit is not None:
        _ROWS.move_to_end(key)
        return hit
    S = np.empty((len(key[0]),) + th.shape)
    C = np.empty_like(S)
    for i, k in enumerate(key[0]):
        S[i] = np.sin(k * th)
        C[i] = np.cos(k * th)
    S.flags.writeable = False
    C.flags.writeable = False
    _ROWS[key] = (S, C)
    while len(_ROWS) > 1 and (len(_ROWS) > _ROWS_KEPT or sum(a.nbytes + b.nbytes for a, b in _ROWS.values()) > _ROWS_BYTES):
        _ROWS.popitem(last=False)
    return S, C


def _solve(U: np.ndarray, s: np.ndarray, Vt: np.ndarray, yw: np.ndarray,
           rcond: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Weighted linear least squares from the SVD ``U·diag(s)·Vt`` of the weighted design (rows
    divided by u) and the weighted data ``yw``: (parameters, (AᵀWA)⁻¹). ``rcond``: singular values
    ≤ rcond·s_max are dropped (the minimum-norm solution and the pseudo-inverse, as
    ``numpy.linalg.lstsq``); None keeps all (the caller has checked the rank)."""
    if rcond is not None and s.size and s[-1] <= rcond * s[0]:
        keep = s > rcond * s[0]
        U, s, Vt = U[:, keep], s[keep], Vt[keep]
    params = Vt.T @ ((U.T @ yw) / s)
    inv = (Vt.T / s**2) @ Vt
    return params, inv


def design_matrix(theta_deg: np.ndarray, order: int, harmonics: Iterable[int] | None = None) -> np.ndarray:
    """Columns ``[1, sin θ, cos θ, sin 2θ, cos 2θ, ...]`` (n × (2·order+1)).

    With ``harmonics`` the columns of the harmonics not listed are zero (the shape stays the same,
    so the matrix can be applied to the full parameter vector).
    """
    th = np.asarray(theta_deg, dtype=float).ravel()
    A = np.empty((th.size, 2 * order + 1))
    A[:, 0] = 1.0
    A[:, 1:] = harmonic_columns(th, range(1, order + 1))[0]
    if harmonics is not None:
        keep = set(int(h) for h in harmonics)
        bad = [h for h in keep if h < 0 or h > order]
        if bad:
            raise ValueError(f"harmonics {sorted(bad)} outside 0…{order}")
        mask = np.zeros(2 * order + 1, dtype=bool)
        for h in keep:
            mask[list(param_index(h))] = True
        A[:, ~mask] = 0.0
    return A


@dataclass(frozen=True)
class FourierFit:
    """Result of :func:`fit_fourier`.

    ``params`` = [a0, a1, b1, ...]; ``a`` (sin) and ``b`` (cos) are views by harmonic 1…order;
    ``cov`` the parameter covariance; ``sigma`` the residual standard deviation ``sqrt(RSS/dof)``
    (NaN when dof = 0); ``u_given`` whether the covariance came from per-point uncertainties.
    """

    order: int
    params: np.ndarray
    cov: np.ndarray
    residual: np.ndarray
    sigma: float
    dof: int
    u_given: bool

    @property
    def a0(self) -> float:
        return float(self.params[0])

    @property
    def a(self) -> np.ndarray:
        """Sine coefficients a_1…a_order (eq. 6; c_i of eq. 10)."""
        return self.params[1::2]

    @property
    def b(self) -> np.ndarray:
        """Cosine coefficients b_1…b_order (eq. 6; d_i of eq. 10)."""
        return self.params[2::2]

    def __call__(self, theta_deg: np.ndarray, harmonics: Iterable[int] | None = None) -> np.ndarray:
        return evaluate(self, theta_deg, harmonics)

    def u_evaluate(self, theta_deg: np.ndarray, harmonics: Iterable[int] | None = None) -> np.ndarray:
        """Standard uncertainty of the evaluated series at ``theta_deg`` (from ``cov``)."""
        A = design_matrix(np.asarray(theta_deg, dtype=float), self.order, harmonics)
        var = np.einsum("ij,jk,ik->i", A, self.cov, A)
        return np.sqrt(np.clip(var, 0.0, None)).reshape(np.shape(theta_deg))

    def as_dict(self) -> dict:
        return {"order": self.order, "a0": self.a0, "a": self.a.copy(), "b": self.b.copy(),
                "params": self.params.copy(), "cov": self.cov.copy(), "sigma": self.sigma, "dof": self.dof}


def fit_fourier(theta_deg: np.ndarray, y: np.ndarray, order: int = 10, u: np.ndarray | float | None = None) -> FourierFit:
    """Least-squares Fourier series of ``order`` to samples ``y(θ)`` (eq. 6 / eq. 10).

    ``u``: optional standard uncertainty of each ``y`` (scalar or per point). Raises ValueError for
    mismatched/non-finite input or fewer samples than parameters (2·order+1), or when the
    θ samples do not determine the series (rank deficient, e.g. too few distinct angles).
    """
    th = np.asarray(theta_deg, dtype=float).ravel()
    yy = np.asarray(y, dtype=float).ravel()
    if order < 0:
        raise ValueError(f"order must be >= 0, got {order}")
    if th.size != yy.size:
        raise ValueError(f"theta_deg has {th.size} samples, y has {yy.size}")
    if not (np.all(np.isfinite(th)) and np.all(np.isfinite(yy))):
        raise ValueError("theta_deg and y must be finite")
    p = 2 * order + 1
    if th.size < p:
        raise ValueError(f"a Fourier series of order {order} has {p} parameters; got only {th.size} samples")
    A = design_matrix(th, order)
    if u is not None:
        uu = np.broadcast_to(np.asarray(u, dtype=float), yy.shape)
        if np.any(~np.isfinite(uu)) or np.any(uu <= 0):
            raise ValueError("u must be finite and > 0")
        w = 1.0 / uu
    else:
        w = np.ones_like(yy)
    Aw = A * w[:, None]
    # Orthogonal factorisation; rank check on the singular values.
    U, s, Vt = np.linalg.svd(Aw, full_matrices=False)
    if s[-1] <= s[0] * 1e-10:
        raise ValueError(f"the θ samples do not determine a Fourier series of order {order} "
                         f"(rank deficient; {np.unique(np.round(th % 360, 9)).size} distinct angles)")
    params, inv = _solve(U, s, Vt, yy * w)  # inv = (Aᵀ W A)⁻¹
    resid = yy - A @ params
    dof = th.size - p
    sigma = float(math.sqrt(np.sum(resid**2) / dof)) if dof > 0 else float("nan")
    if u is not None:
        cov = inv
    else:
        cov = inv * (sigma**2 if dof > 0 else np.nan)
    return FourierFit(order, params, cov, resid, sigma, dof, u is not None)


def evaluate(fit: FourierFit | np.ndarray, theta_deg: np.ndarray, harmonics: Iterable[int] | None = None,
             order: int | None = None) -> np.ndarray:
    """Evaluate the series (all harmonics, or only those listed) at ``theta_deg``.

    ``fit`` may be a :class:`FourierFit` or a parameter vector [a0, a1, b1, ...].
    """
    params = fit.params if isinstance(fit, FourierFit) else np.asarray(fit, dtype=float)
    n_ord = (params.size - 1) // 2 if order is None else order
    th = np.asarray(theta_deg, dtype=float)
    A = design_matrix(th.ravel(), n_ord, harmonics)
    return (A @ params).reshape(th.shape)


# ----------------------------------------------------------------------------------------------
# Series over a chosen set of harmonics, as {k: (a_k, b_k)}. The tracing and the effect library
# (analysis/tracing/, analysis/effects/) describe a residual, a motion or a division error by a
# few orders (eq. 7: 2…10; a division error at orders 4 and 6; a polygon's aliases), not by a full
# series 0…order: the same least squares (:func:`_solve`) on the columns of those orders.
# ----------------------------------------------------------------------------------------------


def fit_harmonics(theta_deg: np.ndarray, y: np.ndarray, ks: Iterable[int], with_mean: bool = True,
                  nuisance_ks: Iterable[int] = (), return_u: bool = False):
    """Least-squares coefficients {k: (a_k, b_k)} of Σ a_k sin kθ + b_k cos kθ over the orders ``ks``
    (+ a free mean and free orders ``nuisance_ks``, fitted but not returned: e.g. order 1, the
    sphere centring of eq. 7). With ``return_u`` also {k: (u(a_k), u(b_k))}, type A from the
    residual scatter: ``s² (AᵀA)⁻¹``, s² = RSS / (n − p) (as :func:`fit_fourier` without ``u``).
    Where the samples do not determine every column the minimum-norm solution is returned (no
    error: the tracing tries orders a design may not resolve, and tests them itself)."""
    ks = list(ks)
    nk = [k for k in nuisance_ks if k not in ks]
    X, _ = harmonic_columns(theta_deg, ks + nk)
    if with_mean:
        X = np.column_stack([X, np.ones(X.shape[0])])
    yy = np.asarray(y, dtype=float).ravel()
    if X.size == 0:  # no samples or no columns: nothing determined
        beta, inv = np.zeros(X.shape[1]), np.zeros((X.shape[1], X.shape[1]))
    else:
        U, s, Vt = np.linalg.svd(X, full_matrices=False)
        # numpy.linalg.lstsq's default cut-off: machine ε × the larger dimension
        beta, inv = _solve(U, s, Vt, yy, rcond=float(np.finfo(float).eps) * max(X.shape))
    coefs = {k: (float(beta[2 * i]), float(beta[2 * i + 1])) for i, k in enumerate(ks)}
    if not return_u:
        return coefs
    dof = max(yy.size - X.shape[1], 1)
    s2 = float(np.sum((yy - X @ beta) ** 2)) / dof
    cov = s2 * inv
    u = {k: (float(np.sqrt(cov[2 * i, 2 * i])), float(np.sqrt(cov[2 * i + 1, 2 * i + 1]))) for i, k in enumerate(ks)}
    return coefs, u


def _vector(coefs: Coefs) -> tuple[list[int], np.ndarray]:
    ks = [int(k) for k in coefs]
    return ks, np.array([float(c) for k in coefs for c in coefs[k]], dtype=float)


def evaluate_harmonics(theta_deg: np.ndarray, coefs: Coefs) -> np.ndarray:
    """Σ a_k sin kθ + b_k cos kθ at ``theta_deg`` (degrees; eq. 6 without the mean), same shape."""
    th = np.asarray(theta_deg, dtype=float)
    ks, p = _vector(coefs)
    return (harmonic_columns(th, ks)[0] @ p).reshape(th.shape)


def integrate_harmonics(theta_deg: np.ndarray, coefs: Coefs) -> np.ndarray:
    """Antiderivative in θ (radians) of the series, without constant: ∫ a sin kθ + b cos kθ dθ =
    (b/k) sin kθ − (a/k) cos kθ (eq. 5's ∫δY dθ; the constant of its ∫_0^θ is a per-run offset,
    which the polygon closure removes)."""
    return evaluate_harmonics(theta_deg, {int(k): (b / int(k), -a / int(k)) for k, (a, b) in coefs.items()})


def perturbation_columns(theta_deg: np.ndarray, u: Coefs, weight: float = 1.0, kind: str = "value") -> np.ndarray:
    """Columns: the change of a series (``kind`` = "value", "integral" or "quadrature") at θ for a
    one-standard-uncertainty change of each of its coefficients (u from :func:`fit_harmonics`)."""
    th = np.asarray(theta_deg, dtype=float)
    cols = []
    for k, (ua, ub) in u.items():
        k = int(k)
        s_, c_ = harmonic_columns(th, [k])[0].T
        if kind == "value":
            cols += [ua * s_, ub * c_]
        elif kind == "integral":
            cols += [-ua * c_ / k, ub * s_ / k]
        elif kind == "quadrature":
            cols += [-ua * c_, ub * s_]
        else:
            raise ValueError(kind)
    return weight * (np.column_stack(cols) if cols else np.zeros((np.size(th), 0)))


def remove_harmonics(theta_deg: np.ndarray, y: np.ndarray, order: int = 10, remove: Iterable[int] = (0, 1),
                     keep_residual: bool = False, u: np.ndarray | float | None = None) -> tuple[np.ndarray, FourierFit]:
    """Eq. 7: the series of ``order`` fitted to ``y`` without the harmonics in ``remove``.

    Default (``keep_residual=False``) is eq. 7 literally: ``Σ_{i=2}^{order} (a_i sin iθ + b_i cos iθ)``
    evaluated at the samples (content above ``order`` and noise are dropped). With
    ``keep_residual=True`` the result is ``y`` minus the removed harmonics (all other content kept).
    Returns (values at ``theta_deg``, the fit).
    """
    fit = fit_fourier(theta_deg, y, order, u)
    rem = set(int(h) for h in remove)
    if keep_residual:
        out = np.asarray(y, dtype=float) - evaluate(fit, theta_deg, rem)
    else:
        out = evaluate(fit, theta_deg, [h for h in range(order + 1) if h not in rem])
    return out, fit


def amplitude_phase(fit: FourierFit, harmonic: int = 1) -> dict:
    """Amplitude and phase of one harmonic with GUM uncertainties (eqs. 11 and 12).

    ``a_i sin iθ + b_i cos iθ = A cos(iθ − φ)``: ``A = sqrt(a_i² + b_i²)`` (eq. 11),
    ``φ = atan2(a_i, b_i)`` in [0°, 360°) (eq. 12, all quadrants). Uncertainties by first-order
    propagation of the 2×2 coefficient covariance (``J = [[a/A, b/A], [b/A², −a/A²]]``); they are
    meaningless when ``A`` is comparable to ``u(A)`` (the phase is then undefined), which is flagged
    by ``phase_defined = A > 3 u(A)``.

    Keys: amplitude, u_amplitude, phase_deg, u_phase_deg, cov_amp_phase (A [unit], φ [rad]),
    a (sin coefficient), b (cos coefficient), cov_ab, phase_defined.
    """
    if not 1 <= harmonic <= fit.order:
        raise ValueError(f"harmonic must be in 1…{fit.order}, got {harmonic}")
    ia, ib = param_index(harmonic)
    return amplitude_phase_ab(float(fit.params[ia]), float(fit.params[ib]), fit.cov[np.ix_([ia, ib], [ia, ib])])


def amplitude_phase_ab(a: float, b: float, cov_ab: np.ndarray) -> dict:
    """Eqs. 11-12 for one sine/cosine pair ``a sin x + b cos x = A cos(x − φ)`` with the 2×2 covariance
    of (a, b): the keys of :func:`amplitude_phase`. Also for a pair of a non-integer order (a period
    over an arc, analysis/arc_periods.py)."""
    a, b = float(a), float(b)
    cov_ab = np.asarray(cov_ab, dtype=float)
    A = math.hypot(a, b)
    phi = math.atan2(a, b)
    if A > 0:
        J = np.array([[a / A, b / A], [b / A**2, -a / A**2]])
        cov_ap = J @ cov_ab @ J.T
    else:
        cov_ap = np.full((2, 2), np.nan)
    uA = float(math.sqrt(max(cov_ap[0, 0], 0.0))) if np.isfinite(cov_ap[0, 0]) else float("nan")
    uphi = float(math.sqrt(max(cov_ap[1, 1], 0.0))) if np.isfinite(cov_ap[1, 1]) else float("nan")
    return {
        "amplitude": A,
        "u_amplitude": uA,
        "phase_deg": wrap_deg(math.degrees(phi)),
        "u_phase_deg": math.degrees(uphi),
        "cov_amp_phase": cov_ap,
        "a": a,
        "b": b,
        "cov_ab": cov_ab,
        "phase_defined": bool(np.isfinite(uA) and A > 3 * uA) if uA > 0 else A > 0,
    }
