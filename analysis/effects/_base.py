"""Shared helpers for the effect modules (plain numpy; no dependency on the rest of the analysis).

Every effect module in this package follows one protocol (see ``docs/effects.md``):

- ``NAME`` (str), ``MEANING`` (one paragraph), ``PARAMS`` (name → unit; ``{k}`` marks a family),
  ``CHANNELS`` (measured channel → how the effect shows up there), ``SEEN_BY_SELFCAL`` (bool: is
  it an error of the encoder/model, hence present identically in the multi-head self-calibration
  residual, or an error of the polygon/autocollimator reference chain, hence absent there),
  ``SEPARATED_BY`` (which data tell it apart), ``SEPARATES_FROM`` (other effect → the measurement
  that would separate the two).
- ``available(ev, ctx) -> (bool, reason)``; ``design(ev, ctx) -> (X, names)`` with X of shape
  (n_readings, n_params), the residual being ``X @ params`` (all effects here are linear in their
  parameters); ``predict(ev, params, ctx)``; ``aux(ev, ctx) -> dict`` (JSON-ready data the
  θ-function needs); ``term(params, aux, base_terms) -> callable(theta_rad) -> arcsec | None``
  (None: the effect is not an encoder error and gives no ErrorModel term).

``ev`` is a :class:`benchtwin.analysis.tracing.Evidence` (or its self-calibration view, which has
the same θ-related attributes); the modules use its attributes only (duck typing), so they do not
import ``tracing``.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from benchtwin.units import ARCSEC_PER_RAD as ARCSEC_PER_RAD  # re-exported to the effect modules

#: Harmonic order set of the radial-motion series (Jia eq. 7: orders 2…10; 0 = probe position and
#: 1 = sphere centring are removed).
RADIAL_ORDERS = tuple(range(2, 11))


def harmonic_columns(theta_deg: np.ndarray, ks: Iterable[int], prefix: str = "", unit: str = "arcsec"):
    """Columns sin kθ, cos kθ for each k (θ in degrees) and their names ``a{k}_<unit>``/``b{k}_<unit>``."""
    th = np.deg2rad(np.asarray(theta_deg, dtype=float))
    cols, names = [], []
    for k in ks:
        cols += [np.sin(k * th), np.cos(k * th)]
        names += [f"{prefix}a{k}_{unit}", f"{prefix}b{k}_{unit}"]
    X = np.column_stack(cols) if cols else np.zeros((th.size, 0))
    return X, names


def fourier_fit(theta_deg: np.ndarray, y: np.ndarray, ks: Iterable[int] = RADIAL_ORDERS,
                with_mean: bool = True, nuisance_ks: Iterable[int] = (), return_u: bool = False):
    """Least-squares coefficients {k: (a_k, b_k)} of Σ a_k sin kθ + b_k cos kθ (+ a free mean and
    free harmonics ``nuisance_ks``, fitted but not returned — e.g. order 1 = sphere centring, eq. 7).
    With ``return_u`` also {k: (u(a_k), u(b_k))} from the residual scatter (type A)."""
    ks = list(ks)
    nk = [k for k in nuisance_ks if k not in ks]
    X, _ = harmonic_columns(theta_deg, ks + nk)
    if with_mean:
        X = np.column_stack([X, np.ones(X.shape[0])])
    yy = np.asarray(y, dtype=float)
    beta, *_ = np.linalg.lstsq(X, yy, rcond=None)
    coefs = {k: (float(beta[2 * i]), float(beta[2 * i + 1])) for i, k in enumerate(ks)}
    if not return_u:
        return coefs
    dof = max(yy.size - X.shape[1], 1)
    s2 = float(np.sum((yy - X @ beta) ** 2)) / dof
    cov = s2 * np.linalg.pinv(X.T @ X)
    u = {k: (float(np.sqrt(cov[2 * i, 2 * i])), float(np.sqrt(cov[2 * i + 1, 2 * i + 1]))) for i, k in enumerate(ks)}
    return coefs, u


def fourier_eval(theta_deg: np.ndarray, coefs: dict[int, tuple[float, float]]) -> np.ndarray:
    th = np.deg2rad(np.asarray(theta_deg, dtype=float))
    out = np.zeros_like(th)
    for k, (a, b) in coefs.items():
        out += a * np.sin(int(k) * th) + b * np.cos(int(k) * th)
    return out


def fourier_integral(theta_deg: np.ndarray, coefs: dict[int, tuple[float, float]]) -> np.ndarray:
    """Antiderivative in θ (radians) of the series, without constant: ∫ a sin kθ + b cos kθ dθ =
    (−a cos kθ + b sin kθ)/k. The constant of Jia eq. 5's ∫_0^θ is a per-run offset, which the
    polygon closure removes anyway."""
    th = np.deg2rad(np.asarray(theta_deg, dtype=float))
    out = np.zeros_like(th)
    for k, (a, b) in coefs.items():
        k = int(k)
        out += (-a * np.cos(k * th) + b * np.sin(k * th)) / k
    return out


def perturbation_columns(theta_deg, u: dict[int, tuple[float, float]], weight: float = 1.0, kind: str = "value"):
    """Columns: the change of a series (``kind`` = "value", "integral" or "quadrature") at θ for a
    one-standard-uncertainty change of each of its coefficients (u from :func:`fourier_fit`)."""
    th = np.deg2rad(np.asarray(theta_deg, dtype=float))
    cols = []
    for k, (ua, ub) in u.items():
        k = int(k)
        s_, c_ = np.sin(k * th), np.cos(k * th)
        if kind == "value":
            cols += [ua * s_, ub * c_]
        elif kind == "integral":
            cols += [-ua * c_ / k, ub * s_ / k]
        elif kind == "quadrature":
            cols += [-ua * c_, ub * s_]
        else:
            raise ValueError(kind)
    return weight * (np.column_stack(cols) if cols else np.zeros((th.size, 0)))


def quadrature(coefs: dict[int, tuple[float, float]]) -> dict[int, tuple[float, float]]:
    """The series shifted by a quarter period in each harmonic: a sin + b cos → b sin − a cos."""
    return {k: (b, -a) for k, (a, b) in coefs.items()}


def coefs_to_json(coefs: dict[int, tuple[float, float]]) -> dict[str, list[float]]:
    return {str(int(k)): [float(a), float(b)] for k, (a, b) in coefs.items()}


def coefs_from_json(d: dict) -> dict[int, tuple[float, float]]:
    return {int(k): (float(v[0]), float(v[1])) for k, v in d.items()}


def linear_predict(design, ev, params: dict[str, float], ctx=None) -> np.ndarray:
    """Generic ``predict`` for a linear effect: X @ params (missing names count as 0)."""
    X, names = design(ev, ctx)
    p = np.array([float(params.get(n, 0.0)) for n in names])
    return X @ p if names else np.zeros(len(ev.theta_deg))


def radius_um(ev) -> float:
    return float(ev.optical_radius_mm) * 1000.0


def alias_harmonic(k_true: int, n_faces: int) -> int:
    """Harmonic k_true seen on an N-point equally spaced grid: folded into 0…N/2."""
    k = int(k_true) % int(n_faces)
    return min(k, int(n_faces) - k)


def disk_fixed_heads(fn, theta_deg, heads_deg) -> np.ndarray:
    """Multi-head channel (Hsieh eq. 8) of an error g fixed to the disk: head j at azimuth ψ_j reads
    the disk where head 1 was at θ − ψ_j (docs/conventions.md), so δ_(1,j)(θ) = g(θ) − g(θ − ψ_j). Returns (n, n_heads), head 1 = 0."""
    th = np.deg2rad(np.asarray(theta_deg, dtype=float))
    g1 = np.asarray(fn(th), dtype=float) + 0.0 * th
    return np.column_stack([g1 - (np.asarray(fn(th - np.deg2rad(p)), dtype=float) + 0.0 * th) for p in heads_deg])


def forward(module, ev, params: dict, ctx=None, heads_deg=None) -> dict:
    """The effect's contribution to every channel the library models numerically:

    - ``alpha``: per polygon reading (arcsec);
    - ``selfcal``: on the self-calibration grid (arcsec), zero for reference-chain effects, None
      without a self-calibration curve (before removing the blind harmonics);
    - ``heads``: δ_(1,j) at the readings for ``heads_deg`` (arcsec, (n, n_heads)) where the module
      has a ``heads`` forward model, zeros for reference-chain effects, else None (see CHANNELS).
    The other channels (radial, CCD) are described in ``module.CHANNELS``.
    """
    out = {"alpha": module.predict(ev, params, ctx)}
    view = ev.selfcal_view() if hasattr(ev, "selfcal_view") else None
    if view is None:
        out["selfcal"] = None
    elif module.SEEN_BY_SELFCAL:
        out["selfcal"] = module.predict(view, params, ctx)
    else:
        out["selfcal"] = np.zeros(len(view.theta_deg))
    if heads_deg is not None:
        if not module.SEEN_BY_SELFCAL:
            out["heads"] = np.zeros((len(ev.theta_deg), len(heads_deg)))
        elif hasattr(module, "heads"):
            out["heads"] = module.heads(ev, params, heads_deg, ctx)
        else:
            out["heads"] = None
    return out
