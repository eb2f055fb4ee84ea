"""Shared helpers for the effect modules (numpy and the analysis's Fourier series, :mod:`benchtwin.analysis.fourier`).

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


import numpy as np

from benchtwin.analysis.fourier import evaluate_harmonics, fit_harmonics, integrate_harmonics
from benchtwin.analysis.fourier import perturbation_columns as perturbation_columns  # re-exported
from benchtwin.analysis.fourier import harmonic_columns as harmonic_columns  # re-exported to the effect modules
from benchtwin.analysis.radial_motion import RADIAL_ORDERS as RADIAL_ORDERS  # re-exported (Jia eq. 7)
from benchtwin.units import ARCSEC_PER_RAD as ARCSEC_PER_RAD  # re-exported to the effect modules

# The series over a set of harmonics ({k: (a_k, b_k)}) are the analysis's one Fourier engine
# (analysis/fourier.py, Jia eqs. 6-7); the effect modules know them by these names.
fourier_fit = fit_harmonics
fourier_eval = evaluate_harmonics
fourier_integral = integrate_harmonics



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
