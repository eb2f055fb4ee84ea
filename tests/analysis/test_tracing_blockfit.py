"""The tracing's block solver (analysis/tracing/blockfit.py) against the reference solver, and the
fit memo (analysis/tracing/problem.py).

The block solver answers the screening's fits (trace's decisions); the reference answers every number
that is reported. So: (1) both answer the same least-squares problem to rounding wherever the block
solver answers; (2) where the reference truncates (rank-deficient designs), the block solver declines
and the reference answers; (3) the memo never answers for other bytes; (4) trace decides and reports
the same with the screening as with the reference alone.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchtwin.analysis.effects import ALL
from benchtwin.analysis.tracing import _Problem, trace
from benchtwin.analysis.tracing.problem import _center
from tests.synthetic.evidence import make_evidence


@pytest.fixture(scope="module")
def pb():
    ev = make_evidence(np.random.default_rng(5), start_faces=range(1, 24, 4), shifts=(0.0, 5.0, 10.0), x_probes=True,
                       inject={"graduation_error": {3: (0.5, 0.2)}, "tangential_motion": {"gain": 0.4}})[0]
    return _Problem(ev, use_selfcal=True)


def _harmonics(pb, ks):
    th = np.deg2rad(pb.ev.theta_deg)
    X = np.column_stack([f(k * th) for k in ks for f in (np.sin, np.cos)])
    X = _center(X, pb.ev.closure_group, pb.w[: pb.ev.n] ** 2)
    return np.vstack([X, np.zeros((pb.n_rows - pb.ev.n, X.shape[1]))])


def _extra(pb, gain):
    mod = ALL["tangential_motion"]
    return pb.regressor_nuisance([mod], [{"gain": gain}], {"harmonics": []})


def _close(a, b, rtol):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape
    scale = max(float(np.max(np.abs(b))) if b.size else 0.0, 1e-300)
    assert float(np.max(np.abs(a - b))) <= rtol * scale if a.size else True


@pytest.mark.parametrize("ks, gain, fold", [((2, 3), None, None), ((3,), 0.7, None), ((2, 4, 5, 7), None, 1),
                                            ((2, 3), 0.4, 2), ((), None, None), ((), 0.5, 0)])
def test_block_solver_answers_the_reference_problem(pb, ks, gain, fold):
    X = _harmonics(pb, ks) if ks else np.zeros((pb.n_rows, 0))
    extra = _extra(pb, gain) if gain is not None else None
    assert extra is None or extra.shape[1] > 0
    train = None if fold is None else pb.folds != fold
    fast = pb._fit_block(X, train, extra)
    ref = pb._fit_reference(X, train, extra)
    assert fast is not None, "a well-conditioned design must be answered by the block solver"
    assert fast["k"] == ref["k"] and fast["dof"] == ref["dof"] and fast["n"] == ref["n"]
    assert abs(fast["chi2"] - ref["chi2"]) <= 1e-11 * ref["chi2"]
    _close(fast["beta"], ref["beta"], 1e-9)
    _close(fast["cov"], ref["cov"], 1e-9)
    # the nuisance (S and the regressor block E): the same fitted contribution on every row
    _close(fast["S"] @ fast["nuis"], ref["S"] @ ref["nuis"], 1e-9)
    _close(fast["nuis"], ref["nuis"], 1e-8)


def test_block_solver_declines_where_the_reference_truncates(pb):
    X = _harmonics(pb, (2, 3))
    X = np.hstack([X, X[:, :1] * 2.0])        # a repeated column: rank 4 of 5, the reference truncates
    assert pb._fit_block(X, None, None) is None
    pb.fast = True
    try:
        f = pb.fit(X)
    finally:
        pb.fast = False
    ref = pb._fit_reference(X, None, None)
    assert f["k"] == ref["k"] == 4
    assert np.array_equal(f["beta"], ref["beta"]) and np.array_equal(f["cov"], ref["cov"]) and f["chi2"] == ref["chi2"]


def test_memo_answers_only_for_the_same_bytes(pb):
    X = _harmonics(pb, (2,))
    f1 = pb.fit(X)
    assert pb.fit(X.copy()) is f1                      # the same bytes: the memo's answer
    X2 = X.copy()
    X2[3, 0] = np.nextafter(X2[3, 0], np.inf)           # one ulp of one element
    f2 = pb.fit(X2)
    assert f2 is not f1
    ref2 = pb._fit_reference(X2, None, None)
    assert np.array_equal(f2["beta"], ref2["beta"]) and f2["chi2"] == ref2["chi2"]
    # another y (trace swaps in the residual after): not the memo's answer for the old y
    y0 = pb.y
    pb.y = y0 * 0.5
    try:
        f3 = pb.fit(X)
        assert f3 is not f1 and np.array_equal(f3["beta"], pb._fit_reference(X, None, None)["beta"])
        assert not pb.y.flags.writeable
    finally:
        pb.y = y0
    assert pb.fit(X) is f1
    # the block solver's answers are kept apart from the reference's
    pb.fast = True
    try:
        assert pb.fit(X) is not f1
    finally:
        pb.fast = False


def _without_candidates(res: dict) -> str:
    return json.dumps({k: v for k, v in res.items() if k != "candidates"}, sort_keys=True, default=str)


@pytest.mark.parametrize("seed, kw", [
    (12, dict(inject={"ac_scale": {"gain_pct": 0.3}})),
    (4, dict(start_faces=range(1, 24, 4), shifts=(0.0, 5.0), x_probes=True,
             inject={"tangential_motion": {"gain": 0.5}, "graduation_error": {4: (0.3, 1.0)}})),
])
def test_screening_changes_no_decision_and_no_reported_number(seed, kw, monkeypatch):
    """trace with the block solver's screening and with the reference alone: the same dict to the last
    bit, but for the report's list of candidates (screening numbers, ~1e-13 from the reference's)."""
    ev = make_evidence(np.random.default_rng(seed), **kw)[0]
    fast = trace(ev)
    monkeypatch.setattr(_Problem, "_fit_block", lambda self, X, train, extra: None)
    ref = trace(ev)
    assert _without_candidates(fast) == _without_candidates(ref)
    assert [c["names"] for c in fast["candidates"]] == [c["names"] for c in ref["candidates"]]


def _indicator_problem(rng, amp):
    """A nuisance block like the async motion's (one column per stop and rep, closure-centred): its
    scaled matrix is nearly singular along the sum of its columns (the centring cancels it in the data
    rows; only the prior rows keep it), a direction no harmonic design follows."""
    stops, reps = 40, 3
    theta = np.tile(np.repeat(np.arange(stops) * 360.0 / stops, 4), reps)
    stop = np.tile(np.repeat(np.arange(stops), 4), reps)
    rep = np.repeat(np.arange(reps), stops * 4)
    m = theta.size
    S = np.column_stack([amp * ((stop == b) & (rep == r)).astype(float) for r in range(reps) for b in range(stops)])
    S = S - S.mean(axis=0)          # one closure group: the column sums cancel in the data rows
    w = np.full(m, 2.0)
    th = np.deg2rad(theta)
    X = np.column_stack([f(k * th) for k in (2, 3, 5) for f in (np.sin, np.cos)])
    E = np.column_stack([f(k * th) for k in (1, 4) for f in (np.sin, np.cos)]) * 0.3
    y = X @ rng.normal(size=X.shape[1]) + rng.normal(size=m) * 0.5
    return S, w, y, X, E


def _dense(S, w, y, X, E):
    """The reference's problem, densely: [X, S, E] weighted with the unit prior rows, scaled columns,
    lstsq; its β, χ² and the scaled matrix's condition number."""
    N = S if E is None else np.hstack([S, E])
    p, q = X.shape[1], N.shape[1]
    A = np.vstack([np.hstack([X, N]) * w[:, None], np.hstack([np.zeros((q, p)), np.eye(q)])])
    b = np.concatenate([y * w, np.zeros(q)])
    scale = np.linalg.norm(A, axis=0)
    sol = np.linalg.lstsq(A / scale, b, rcond=None)[0] / scale
    sv = np.linalg.svd(A / scale, compute_uv=False)
    return sol[:p], float(np.sum((b - A @ sol) ** 2)), float(sv[0] / sv[-1])


@pytest.mark.parametrize("with_e", [False, True])
def test_sharper_bound_accepts_only_well_conditioned_problems(with_e):
    """The block bound of the nuisance-heavy problems (blockfit._kappa_blocks): never below the
    reference matrix's condition number; where the product of norms (_kappa) exceeds KAPPA_MAX and the
    matrix is well conditioned, the block solver answers, and answers the reference's problem."""
    from benchtwin.analysis.tracing import blockfit as bf
    rng = np.random.default_rng(3)
    for amp in (30.0, 300.0, 3e4):
        S, w, y, X, E = _indicator_problem(rng, amp)
        E = E if with_e else None
        F = bf.NuisanceFactor(S, w, y, np.ones(y.size, bool))
        basis = bf.RangeBasis(y.size)
        beta, chi2, kappa = _dense(S, w, y, X, E)
        sx, Xs, Xt = F.columns(X)
        K = se = RZ = QK = None
        if E is not None:
            K = basis.coefficients(E)
            Uw, Ut, _ = F.basis(basis)
            se = np.sqrt(np.sum((Uw @ K) ** 2, axis=0) + 1.0)
            QK, Z = bf._regressor_stack(K, Ut, Xt)      # as block_fit stacks them
            RZ = bf._qr_r(Z)
        bound = bf._sharper(F, basis, X, Xs, bf._qr_r(Xt), K, se, RZ, QK)
        assert bound >= kappa * (1.0 - 1e-9)
        product = bf._kappa(X.shape[1] + S.shape[1] + (0 if E is None else E.shape[1]), X.shape[1], F.a, 0.0, 0.0,
                            float(np.linalg.norm(np.linalg.inv(bf._qr_r(Xt)), 2)))
        fit = bf.block_fit(F, basis, X, E)
        if bound <= bf.KAPPA_MAX:
            assert fit is not None
            assert abs(fit["chi2"] - chi2) <= 1e-9 * chi2
            _close(fit["beta"], beta, 1e-8)
        else:
            assert fit is None
        if amp == 300.0:        # the case the sharper bound is for: the product declines, the matrix is fine
            assert product > bf.KAPPA_MAX and bound <= bf.KAPPA_MAX


@pytest.mark.parametrize("n_combos", [0, 4, 9])
def test_sharper_bound_from_the_solvers_own_r_equals_the_bound_from_all_the_rows(n_combos):
    """blockfit._sharper's R_B from the block solver's R of Z (a small QR) is the R of B's projected
    matrix over all the rows (the Gram matrices are equal): the same bound to rounding, whether E has
    as many columns as its range basis (Q_K square) or more (``n_combos`` extra combinations of them)."""
    from benchtwin.analysis.tracing import blockfit as bf
    rng = np.random.default_rng(11)
    for amp in (30.0, 300.0):
        S, w, y, X, E = _indicator_problem(rng, amp)
        E = np.hstack([E, E @ rng.normal(size=(E.shape[1], n_combos))])
        F = bf.NuisanceFactor(S, w, y, np.ones(y.size, bool))
        basis = bf.RangeBasis(y.size)
        sx, Xs, Xt = F.columns(X)
        K = basis.coefficients(E)
        Uw, Ut, _ = F.basis(basis)
        se = np.sqrt(np.sum((Uw @ K) ** 2, axis=0) + 1.0)
        QK, Z = bf._regressor_stack(K, Ut, Xt)      # as block_fit stacks them
        r, p, mE = QK.shape[1], X.shape[1], E.shape[1]
        RZ = bf._qr_r(Z)
        Rx = RZ[r:, r:]
        # the bound from all the rows: R of B's projected matrix [U_t·K/se, X_t; diag(1/se), 0] itself
        Ks = K / se
        ZB = np.vstack([np.hstack([Ut @ Ks, Xt]), np.hstack([np.diag(1.0 / se), np.zeros((mE, p))])])
        G = np.hstack([F.basis_coupling(basis) @ Ks, F.coupling(X)])
        rows = bf._kappa_blocks(F, np.hstack([Uw @ Ks, Xs]), np.concatenate([1.0 / se, np.zeros(p)]), bf._qr_r(ZB), G)
        small = bf._sharper(F, basis, X, Xs, Rx, K, se, RZ, QK)
        assert QK.shape == (E.shape[1], min(E.shape[1], 4))
        assert math.isfinite(rows) and abs(small - rows) <= 1e-12 * rows


def test_the_gram_count_never_exceeds_what_the_svd_finds():
    """blockfit._surely_above, the shortcut RangeBasis.coefficients takes before an SVD to decline an
    E with more new directions than room: never more singular values than the SVD finds above the
    floor (any spectrum, down to 1e-20 of the largest), and all of them where the spectrum has no
    value within 1e-4 of the largest's scale of the floor."""
    from benchtwin.analysis.tracing import blockfit as bf
    rng = np.random.default_rng(12)
    for trial in range(40):
        m, c = int(rng.integers(50, 400)), int(rng.integers(1, 40))
        r = min(m, c)
        sv = 10.0 ** rng.uniform(-20, 0, size=r) if trial % 2 else np.r_[np.ones(r // 2), np.full(r - r // 2, 1e-18)]
        U = np.linalg.qr(rng.normal(size=(m, r)))[0]
        V = np.linalg.qr(rng.normal(size=(c, r)))[0]
        R = (U * sv) @ V.T * float(10.0 ** rng.uniform(-3, 3))
        floor = 1e-13 * float(np.linalg.norm(R)) * float(10.0 ** rng.uniform(0, 2))
        by_svd = int(np.count_nonzero(np.linalg.svd(R, compute_uv=False) > floor))
        assert bf._surely_above(R, floor) <= by_svd
        if trial % 2 == 0:
            assert bf._surely_above(R, floor) == by_svd == r // 2
