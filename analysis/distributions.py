"""The sampling distributions behind the analysis's tests and coverage factors, from SciPy's special
functions: χ² (goodness of fit, harmonic significance), Student's t (GUM coverage factor with
ν_eff, JCGM 100:2008 annex G), F (nested-model tests), normal.

Why not ``scipy.stats``: importing it costs ≈ 0.7 s of CPU (its hundred-odd distributions, with
SciPy's interpolate package), in every process that analyses a dataset (issue #17), for these
one-line functions. Each function is the special function ``scipy.stats`` itself evaluates for the
same arguments (SciPy 1.17: ``scipy/stats/_continuous_distns.py`` chi2_gen, t_gen, f_gen and the
normal's ``_norm_*``; ``scipy/stats/_distn_infrastructure.py`` rv_continuous._logsf and
rv_generic._isf for the ones a distribution inherits), so the values are the same bits;
tests/analysis/test_distributions.py holds them to ``scipy.stats`` on grids of arguments, the
edges of the support and invalid parameters included.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import special as sc

__all__ = ["chi2_sf", "chi2_isf", "chi2_logsf", "t_sf", "t_ppf", "norm_sf", "norm_ppf", "norm_isf", "f_sf",
           "f_isf"]


def _out(a: np.ndarray) -> Any:
    """A NumPy scalar for a 0-d result, as scipy.stats returns."""
    return a[()] if a.ndim == 0 else a


def _tail(inside: Any, x: Any, lower: float, at_lower: float, at_upper: float, valid: Any) -> Any:
    """``rv_continuous.sf``/``logsf``'s placement around the special function's values ``inside``:
    NaN for invalid parameters or x, ``at_lower`` at and below the support's lower end, ``at_upper``
    at +∞ (the support's open upper end for every distribution here)."""
    x = np.asarray(x, dtype=float)
    out = np.where(x <= lower, at_lower, np.where(x == np.inf, at_upper, inside))
    return _out(np.where(valid & ~np.isnan(x), out, np.nan))


def _quantile(inside: Any, q: Any, lower: float, upper: float, valid: Any, upper_tail: bool) -> Any:
    """``rv_generic.ppf``/``isf``'s placement: NaN outside [0, 1] and for invalid parameters, the
    support's ends at q = 0 and 1, and inside them ``value·scale + loc`` with scale 1 and loc 0 (as
    scipy.stats computes it: a −0 becomes +0)."""
    q = np.asarray(q, dtype=float)
    q_low, q_high = (1.0, 0.0) if upper_tail else (0.0, 1.0)      # the q of the lower, upper end
    out = np.where((q > 0) & (q < 1), np.asarray(inside, dtype=float) * 1.0 + 0.0, np.nan)
    out = np.where(q == q_low, lower, np.where(q == q_high, upper, out))
    return _out(np.where(valid, out, np.nan))


def _positive(*df: Any) -> Any:
    ok = np.asarray(True)
    for d in df:
        ok = ok & (np.asarray(d, dtype=float) > 0)
    return ok


def chi2_sf(x: Any, df: Any) -> Any:
    """P(χ²_df > x)."""
    return _tail(sc.chdtrc(df, x), x, 0.0, 1.0, 0.0, _positive(df))


def chi2_isf(q: Any, df: Any) -> Any:
    """x with P(χ²_df > x) = q."""
    return _quantile(sc.chdtri(df, q), q, 0.0, np.inf, _positive(df), upper_tail=True)


def chi2_logsf(x: Any, df: Any) -> Any:
    """log P(χ²_df > x), accurate far in the tail (where ``chi2_sf`` underflows): the log of the
    survival function above the median, log1p of minus the distribution function below it
    (``rv_continuous._logsf``)."""
    xa, dfa = np.asarray(x, dtype=float), np.asarray(df, dtype=float)
    median = 2.0 * sc.gammaincinv(dfa / 2, 0.5)
    with np.errstate(divide="ignore"):
        inside = np.where(xa > median, np.log(sc.chdtrc(dfa, xa)), np.log1p(-sc.chdtr(dfa, xa)))
    return _tail(inside, xa, 0.0, 0.0, -np.inf, _positive(df))


def t_sf(x: Any, df: Any) -> Any:
    """P(t_df > x)."""
    return _tail(sc.stdtr(df, -np.asarray(x, dtype=float)), x, -np.inf, 1.0, 0.0, _positive(df))


def t_ppf(q: Any, df: Any) -> Any:
    """x with P(t_df ≤ x) = q."""
    return _quantile(sc.stdtrit(df, q), q, -np.inf, np.inf, _positive(df), upper_tail=False)


def norm_sf(x: Any) -> Any:
    """P(Z > x), Z standard normal."""
    return _tail(sc.ndtr(-np.asarray(x, dtype=float)), x, -np.inf, 1.0, 0.0, np.asarray(True))


def norm_ppf(q: Any) -> Any:
    """x with P(Z ≤ x) = q."""
    return _quantile(sc.ndtri(q), q, -np.inf, np.inf, np.asarray(True), upper_tail=False)


def norm_isf(q: Any) -> Any:
    """x with P(Z > x) = q."""
    return _quantile(-sc.ndtri(q), q, -np.inf, np.inf, np.asarray(True), upper_tail=True)


def f_sf(x: Any, dfn: Any, dfd: Any) -> Any:
    """P(F_(dfn, dfd) > x)."""
    return _tail(sc.fdtrc(dfn, dfd, x), x, 0.0, 1.0, 0.0, _positive(dfn, dfd))


def f_isf(q: Any, dfn: Any, dfd: Any) -> Any:
    """x with P(F_(dfn, dfd) > x) = q (``rv_generic._isf``: the quantile of 1 − q)."""
    return _quantile(sc.fdtri(dfn, dfd, 1.0 - np.asarray(q, dtype=float)), q, 0.0, np.inf, _positive(dfn, dfd),
                     upper_tail=True)
