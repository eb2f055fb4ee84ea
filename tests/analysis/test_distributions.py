"""analysis/distributions.py gives scipy.stats' values bit for bit (it evaluates the same special
functions without importing scipy.stats): on grids of arguments spanning the bulk and both tails,
the edges of the support, and invalid parameters (where both give NaN)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from benchtwin.analysis import distributions as D

X = np.concatenate([[-1.0, 0.0, 1e-300, 1e-12], np.geomspace(1e-6, 1e4, 157), [np.inf, np.nan]])
T = np.concatenate([-X[::-1], X])
Q = np.concatenate([[0.0, 1e-300, 1e-16], np.geomspace(1e-12, 0.5, 61), 1 - np.geomspace(1e-12, 0.5, 61),
                    [1.0, -0.1, 1.1, np.nan]])
DF = [0, -1, 0.5, 1, 2, 3, 7.5, 23, 74, 1000, 1e6]


def bits(a, b) -> list:
    """indices where a and b differ (NaN equals NaN; otherwise the same bits, so +0 ≠ −0)"""
    a, b = np.asarray(a, dtype=float).ravel(), np.asarray(b, dtype=float).ravel()
    ok = (a.view(np.int64) == b.view(np.int64)) | (np.isnan(a) & np.isnan(b))
    return np.flatnonzero(~ok).tolist()


@pytest.mark.parametrize("df", DF)
def test_chi2(df):
    assert bits(D.chi2_sf(X, df), stats.chi2.sf(X, df)) == []
    assert bits(D.chi2_isf(Q, df), stats.chi2.isf(Q, df)) == []
    assert bits(D.chi2_logsf(X, df), stats.chi2.logsf(X, df)) == []


@pytest.mark.parametrize("df", DF + [np.inf])
def test_t(df):
    assert bits(D.t_sf(T, df), stats.t.sf(T, df)) == []
    assert bits(D.t_ppf(Q, df), stats.t.ppf(Q, df)) == []


def test_norm():
    assert bits(D.norm_sf(T), stats.norm.sf(T)) == []
    assert bits(D.norm_ppf(Q), stats.norm.ppf(Q)) == []
    assert bits(D.norm_isf(Q), stats.norm.isf(Q)) == []


@pytest.mark.parametrize("dfn, dfd", [(1, 1), (2, 5), (3, 40), (10, 1000), (0.5, 7), (0, 5), (4, -1)])
def test_f(dfn, dfd):
    assert bits(D.f_sf(X, dfn, dfd), stats.f.sf(X, dfn, dfd)) == []
    assert bits(D.f_isf(Q, dfn, dfd), stats.f.isf(Q, dfn, dfd)) == []


def test_scalars_are_scalars():
    """A scalar argument gives a NumPy scalar, as scipy.stats does (callers wrap it in float())."""
    for got, ref in ((D.chi2_sf(3.0, 2), stats.chi2.sf(3.0, 2)), (D.chi2_logsf(3.0, 2), stats.chi2.logsf(3.0, 2)),
                     (D.t_ppf(0.975, 9), stats.t.ppf(0.975, 9)), (D.norm_isf(1e-3), stats.norm.isf(1e-3)),
                     (D.f_isf(0.01, 2, 30), stats.f.isf(0.01, 2, 30))):
        assert np.ndim(got) == 0 and bits(got, ref) == []
