"""Shared helpers for the effect modules (numpy and the analysis's Fourier series, :mod:`benchtwin.analysis.fourier`).

Every effect module in this package follows one protocol, stated with types in
:mod:`benchtwin.analysis.effects.protocol` (:class:`~benchtwin.analysis.effects.protocol.Effect`;
``docs/effects.md``). The parts of it that are the same for many effects live here once, and the
modules take them from here:

- ``linear_predictor(design)``: the ``predict`` of a linear effect, ``X @ params`` (all of them);
- ``no_aux`` / ``no_term``: the ``aux`` and ``term`` of an effect with no θ-function (an error of
  the reference chain, not of the encoder: it gives no ErrorModel term);
- ``channels(...)``: a module's ``CHANNELS``, every channel named, "none" where not stated;
- ``disk_fixed_heads_of(term, aux)``: the ``heads`` of an error fixed to the disk (Hsieh eq. 8);
- ``within`` / ``amplitudes_within``: the usual ``plausible`` bounds (one parameter; sin/cos pairs).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np

from benchtwin.analysis.fourier import evaluate_harmonics, fit_harmonics, integrate_harmonics
from benchtwin.analysis.fourier import perturbation_columns as perturbation_columns  # re-exported
from benchtwin.analysis.fourier import harmonic_columns as harmonic_columns  # re-exported to the effect modules
from benchtwin.analysis.radial_motion import RADIAL_ORDERS as RADIAL_ORDERS  # re-exported (Jia eq. 7)
from benchtwin.units import ARCSEC_PER_RAD as ARCSEC_PER_RAD  # re-exported to the effect modules

from .protocol import CHANNEL_NAMES, Context, Evidence, ThetaFunction

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


def linear_predict(design, ev, params: Mapping[str, float], ctx: Context = None) -> np.ndarray:
    """Generic ``predict`` for a linear effect: X @ params (missing names count as 0)."""
    X, names = design(ev, ctx)
    p = np.array([float(params.get(n, 0.0)) for n in names])
    return X @ p if names else np.zeros(len(ev.theta_deg))


def linear_predictor(design: Callable[[Evidence, Context], tuple[np.ndarray, list[str]]]) -> Callable[..., np.ndarray]:
    """The ``predict(ev, params, ctx=None)`` of a linear effect whose columns are ``design``: X @ params."""
    def predict(ev: Evidence, params: Mapping[str, float], ctx: Context = None) -> np.ndarray:
        """The effect's residual at the readings: X @ params (missing names count as 0)."""
        return linear_predict(design, ev, params, ctx)
    return predict


def no_aux(ev: Evidence, ctx: Context = None) -> dict[str, Any]:
    """``aux`` of an effect whose θ-function needs no data from the evidence (or that has none)."""
    return {}


def no_term(params: Mapping[str, float], aux: Mapping[str, Any], base_terms: Any = None) -> None:
    """``term`` of an effect of the reference chain (SEEN_BY_SELFCAL false): not an encoder error, so
    no ErrorModel term."""
    return None


def channels(*, alpha: str, selfcal: str, radial: str = "none", ccd: str = "none", heads: str = "none") -> dict[str, str]:
    """A module's ``CHANNELS``: how the effect shows up in each measured channel (protocol.CHANNEL_NAMES,
    in that order); a channel not stated is "none"."""
    return dict(zip(CHANNEL_NAMES, (alpha, selfcal, radial, ccd, heads)))


def within(params: Mapping[str, float], name: str, limit: float, what: str, unit: str) -> tuple[bool, str]:
    """``plausible`` for one parameter: (ok, reason) with ok = |params[name]| ≤ limit (missing: 0);
    ``unit`` follows the numbers in the reason (e.g. "″", " %")."""
    v = float(params.get(name, 0.0))
    ok = abs(v) <= limit
    return ok, "" if ok else f"{what} {v:.3g}{unit} is beyond ±{limit:g}{unit}"


def amplitudes_within(params: Mapping[str, float], pairs: Iterable[tuple[str, str, str]], limit: float) -> tuple[bool, str]:
    """``plausible`` for sin/cos pairs: (ok, reason), ok when every pair's amplitude √(s² + c²) (arcsec)
    is ≤ limit; ``pairs`` are (label, sin name, cos name), missing names count as 0."""
    for label, s, c in pairs:
        a = float(abs(complex(params.get(s, 0.0), params.get(c, 0.0))))
        if a > limit:
            return False, f"{label}: {a:.3g}″ is beyond {limit:g}″"
    return True, ""


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


def disk_fixed_heads_of(term: Callable[..., ThetaFunction | None],
                        aux: Callable[[Evidence, Context], dict[str, Any]]) -> Callable[..., np.ndarray]:
    """The ``heads(ev, params, heads_deg, ctx=None)`` of an error fixed to the disk whose θ-function
    is ``term(params, aux(ev, ctx))``: δ_(1,j)(θ) = g(θ) − g(θ − ψ_j) (Hsieh eq. 8)."""
    def heads(ev: Evidence, params: Mapping[str, float], heads_deg: Any, ctx: Context = None) -> np.ndarray:
        """δ_(1,j)(θ) = g(θ) − g(θ − ψ_j) (Hsieh eq. 8): the error is fixed to the disk."""
        return disk_fixed_heads(term(params, aux(ev, ctx)), ev.theta_deg, heads_deg)
    return heads


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


#: a reference-chain effect whose column is (almost) a function of θ inside every run (closure group)
#: is an encoder error at those stops to the data: below this share of the run-centred column's
#: variance left after removing every function of θ it is declared unobservable (ac_drift: the
#: reading time of forward sweeps from one start angle; torsion_hysteresis: the approach of
#: forward-only runs, backward only at each run's first stop)
MIN_FREE_FRACTION = 0.2


def theta_free_fraction(ev, values) -> float:
    """Share of the run-centred (per ``closure_group``) variance of the per-reading ``values`` that is
    not explained by a function of θ (the stop position ``theta_bin``): what can tell an effect that
    follows ``values`` from an encoder error. 0 when the centred values vanish."""
    t = np.asarray(values, dtype=float)
    g = np.asarray(ev.closure_group)
    tc = t - (np.bincount(g, weights=t) / np.bincount(g))[g]
    tot = float(np.sum(tc ** 2))
    if tot <= 0:
        return 0.0
    cells = np.unique(np.asarray(ev.theta_bin), return_inverse=True)[1]
    X = np.zeros((t.size, int(cells.max()) + 1))
    X[np.arange(t.size), cells] = 1.0
    Xc = X - np.vstack([np.bincount(g, weights=X[:, j]) / np.bincount(g) for j in range(X.shape[1])]).T[g]
    beta, *_ = np.linalg.lstsq(Xc, tc, rcond=None)
    return float(np.sum((tc - Xc @ beta) ** 2) / tot)
