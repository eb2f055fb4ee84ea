"""The tracing's weighted fits with the nuisance block factorised once per training set.

Every fit of :class:`~.problem._Problem` minimises

    ‖b − X·β − S·ν − E·μ‖² + ‖ν‖² + ‖μ‖²        (rows weighted by 1/u)

with S the model's nuisance columns (the same for every fit of one problem) and E the regressor
columns of one candidate (errors in variables; none for most fits), both under a unit Gaussian
prior. The reference solver (``_Problem._fit_reference``) stacks everything into one matrix and
solves it by SVD (``lstsq``) and a pseudo-inverse, ~5 ms a fit. Here:

- the S block is eliminated by its QR factorisation, computed once per training set: block
  elimination, the β block of the normal matrix's inverse is the inverse of its Schur complement,
  i.e. X projected on the orthogonal complement of [S; I] (Golub & Van Loan, *Matrix Computations*,
  4th ed. 2013, §5.2–5.3: QR and the full-rank least-squares problem; Björck, *Numerical Methods
  for Least Squares Problems*, SIAM 1996, on block elimination). The projection is repeated when a
  column lost more than half its norm (Kahan's "twice is enough", Parlett, *The Symmetric
  Eigenvalue Problem*, 1980; Giraud, Langou & Rozložník, Comput. Math. Appl. 50, 2005), and the
  projected columns are kept per training set (the candidates are made of the same columns);
- E enters only through E·Eᵀ (the prior marginalised: covariance I + S·Sᵀ + E·Eᵀ), so it is replaced
  by U·L with U an orthonormal basis of its range (:class:`RangeBasis`, shared by all the fits of a
  problem: the regressor perturbations are harmonics of θ, rank ≤ 18 whatever their number of
  columns) and L·Lᵀ = K·Kᵀ, K = Uᵀ·E: the same β, χ² and cov(β); μ = Eᵀ·r follows from the residual
  r (the stationarity condition of the prior term);
- what is left per fit is the QR of the few projected columns of X (and of U·L).

The reference truncates small singular values (``lstsq``: below ε·max(m, n)·σ₁; ``pinv``: λ below
1e-10·λ₁, i.e. σ below 1e-5·σ₁ of its column-scaled matrix; G&VL §5.5). Its answer is the exact
least-squares answer only when no σ is that small; :func:`block_fit` therefore bounds the condition
number of the reference's own column-scaled matrix (block upper-triangular R factor: ‖R⁻¹‖ ≤ a + d
+ a·c·d, a = ‖R_N⁻¹‖ of the nuisance block, d = ‖R_X⁻¹‖ of the projected X block, c ≥ ‖Q_Nᵀ·X‖;
σ₁ ≤ √columns) and, where that product of norms exceeds ``KAPPA_MAX``, a sharper bound from the
same factorisations (:func:`_kappa_blocks`: the norms of R⁻¹'s and A_s's block columns, not products
of their blocks' norms; a nuisance block with one column per stop and rep is nearly singular along
directions no candidate follows: on the seed-666 loop-validation graduation_error bench, 764 nuisance
columns, ‖R_S⁻¹‖ = 70–81, the product bound was 1.6·10⁴–10²⁰ (median 2·10⁷, the a·c·d term largest
in all 789 fits it declined) where 27 of 28 sampled reference matrices had κ = 170–2500 and one was
rank-deficient, κ 5·10¹⁶); it returns None when both exceed ``KAPPA_MAX``: the caller then uses the
reference. Within the bound both answer the same problem to ~κ·ε (measured on the default dataset:
χ² within 1e-15, β and cov(β) within ~1e-11 relative; tests/analysis/test_tracing_blockfit.py).
"""

from __future__ import annotations

import copy
import math
from typing import cast

import numpy as np

#: largest bound on the reference matrix's condition number for which the fast answer is used:
#: 10× below the reference's pseudo-inverse cut-off (σ < 1e-5·σ₁), 1e8× above its lstsq cut-off
KAPPA_MAX = 1e4
#: E is in the span of the range basis when ‖E − U·Uᵀ·E‖_F ≤ RANGE_TOL·‖E‖_F (the regressor
#: perturbations are exact harmonics; their rounding is ~1e-16)
RANGE_TOL = 1e-13
#: largest range basis kept (beyond it the reduction saves nothing: E is used as it is)
RANGE_MAX = 60


def _project(Q: np.ndarray, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(I − Q·Qᵀ)·Z and Qᵀ·Z; projected again when a column lost more than half its norm (Kahan's
    criterion: one more pass is then enough, Parlett, *The Symmetric Eigenvalue Problem*, 1980, §6.9)."""
    C = Q.T @ Z
    Zt = Z - Q @ C
    if Z.size and np.any(np.sum(Zt * Zt, axis=0) < 0.25 * np.sum(Z * Z, axis=0)):
        C2 = Q.T @ Zt
        Zt, C = Zt - Q @ C2, C + C2
    return Zt, C


def _surely_above(R: np.ndarray, floor: float) -> int:
    """How many singular values of R are certainly above ``floor``, from the eigenvalues of the small
    Gram matrix Rᵀ·R (one product, no SVD of the tall R): only those ≥ 1e-8 of the largest count (their
    error, ~ε·λ₁, is then below 1e-8 of them) and ≥ (10·floor)². A lower bound on the count the SVD
    finds above ``floor``; :meth:`RangeBasis.coefficients` declines an E that needs more new directions
    than the basis has room for, as it would after the SVD (a 12-head close-loop: 113 of its 354
    calls, ≈ 20 ms each)."""
    g = np.linalg.eigvalsh(R.T @ R)
    if not g.size or g[-1] <= 0:
        return 0
    return int(np.count_nonzero(g >= max(1e-8 * g[-1], (10.0 * floor) ** 2)))


class RangeBasis:
    """An orthonormal basis U (all rows of a problem) of the ranges of the E blocks seen so far."""

    def __init__(self, n_rows: int):
        self.U = np.zeros((n_rows, 0))
        self.version = 0

    def coefficients(self, E: np.ndarray) -> np.ndarray | None:
        """K with E = U·K to RANGE_TOL (the basis extended if needed); None if it would grow too big."""
        nE = float(np.linalg.norm(E))
        if nE == 0.0:
            return np.zeros((self.U.shape[1], E.shape[1]))
        K = self.U.T @ E
        R = E - self.U @ K      # one pass: U is orthonormal, only the size of R is asked
        if float(np.linalg.norm(R)) > RANGE_TOL * nE:
            R = _project(self.U, R)[0]
            room = RANGE_MAX - self.U.shape[1]
            if R.shape[1] > room and _surely_above(R, RANGE_TOL * nE) > room:
                return None     # what the SVD below would find too: more new directions than room
            u, s, _ = np.linalg.svd(R, full_matrices=False)
            new = u[:, s > RANGE_TOL * nE]
            new, _ = _project(self.U, new)
            new = np.linalg.qr(new)[0]
            if self.U.shape[1] + new.shape[1] > RANGE_MAX:
                return None
            self.U = np.hstack([self.U, new])
            self.version += 1
            K = self.U.T @ E
            if float(np.linalg.norm(E - self.U @ K)) > RANGE_TOL * nE:
                return None
        return K


class NuisanceFactor:
    """The S block of one training set factorised: scaled [S_w; I] = Q_S·R_S (the reference scales
    every column to unit norm), b projected onto the complement of its span."""

    def __init__(self, S: np.ndarray, w: np.ndarray, y: np.ndarray, rows: np.ndarray):
        self.rows = rows
        self.w = w[rows]
        self.m = int(self.w.size)
        q = S.shape[1]
        self.q = q
        self.Sw = S[rows] * self.w[:, None]
        b = np.concatenate([y[rows] * self.w, np.zeros(q)])
        if q:
            A = np.vstack([self.Sw, np.eye(q)])
            self.Q, self.R = np.linalg.qr(A / np.linalg.norm(A, axis=0))
            sv = np.linalg.svd(self.R, compute_uv=False)
            self.a = 1.0 / sv[-1] if sv[-1] > 0 else math.inf
            self.s1 = float(sv[0])      # ‖S_s‖₂ = ‖R_S‖₂ (the scaled nuisance block with its prior rows)
        else:
            self.Q, self.R, self.a, self.s1 = np.zeros((self.m, 0)), np.zeros((0, 0)), 0.0, 0.0
        self.bt = _project(self.Q, b[:, None])[0][:, 0]
        self._U: tuple[int, np.ndarray, np.ndarray, float] | None = None
        self._GU: tuple[int, np.ndarray] | None = None
        self._Rinv: np.ndarray | None = None
        self._cols: dict[bytes, tuple[float, np.ndarray, np.ndarray]] = {}
        self._g: dict[bytes, np.ndarray] = {}

    def retarget(self, y: np.ndarray) -> "NuisanceFactor":
        """The same factorisation for another target ``y`` (the errors-in-variables Gauss–Newton step
        of analysis/tracing/selection.py fits a shifted residual): only b's projection is new. The
        copy's column caches start as copies of this one's, so the step's adjusted regressors, used
        once, are not kept here."""
        G = copy.copy(self)
        b = np.concatenate([np.asarray(y, dtype=float)[self.rows] * self.w, np.zeros(self.q)])
        G.bt = _project(self.Q, b[:, None])[0][:, 0]
        G._cols, G._g = dict(self._cols), dict(self._g)
        return G

    def columns(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """X's columns weighted on these rows, their norms s_x, the scaled columns X_s and their
        projections (I − P_S)·[X_s; 0]: computed once per column (keyed on its exact bytes), since
        the candidates' designs are made of the same columns again (singles, pairs, z fits)."""
        keys = [X[:, j].tobytes() for j in range(X.shape[1])]
        new = [j for j, k in enumerate(keys) if k not in self._cols]
        if new:
            Xw = X[:, new][self.rows] * self.w[:, None]
            sx = np.linalg.norm(Xw, axis=0)
            Xs = Xw / np.where(sx > 0, sx, 1.0)
            Xt = _project(self.Q, self.pad(Xs))[0]
            for i, j in enumerate(new):
                self._cols[keys[j]] = (float(sx[i]), Xs[:, i], Xt[:, i])
        got = [self._cols[k] for k in keys]
        return (np.array([g[0] for g in got]), np.column_stack([g[1] for g in got]),
                np.column_stack([g[2] for g in got]))

    def pad(self, Z: np.ndarray) -> np.ndarray:
        """Data rows (weighted) and zero prior rows."""
        return np.vstack([Z, np.zeros((self.q, Z.shape[1]))])

    def basis(self, basis: RangeBasis) -> tuple[np.ndarray, np.ndarray, float]:
        """U_w (the basis on these rows, weighted), (I − P_S)·[U_w; 0] and ‖Q_Sᵀ·[U_w; 0]‖₂, cached
        per version of the basis."""
        if self._U is None or self._U[0] != basis.version:
            Uw = basis.U[self.rows] * self.w[:, None]
            Ut, C = _project(self.Q, self.pad(Uw))
            self._U = (basis.version, Uw, Ut, float(np.linalg.norm(C, 2)) if C.size else 0.0)
        return self._U[1], self._U[2], self._U[3]

    def _r_inv(self) -> np.ndarray:
        """R_S⁻¹ (q × q), formed once per training set, when a bound first needs it."""
        if self._Rinv is None:
            self._Rinv = np.linalg.inv(self.R) if self.q else np.zeros((0, 0))
        return self._Rinv

    def coupling(self, X: np.ndarray) -> np.ndarray:
        """R_S⁻¹·Q_Sᵀ·[X_s; 0] (q × p): the coefficients of X's scaled columns on the scaled nuisance
        block (the block R_S⁻¹·C of the reference's R⁻¹), computed once per column."""
        keys = [X[:, j].tobytes() for j in range(X.shape[1])]
        new = [k for k in dict.fromkeys(keys) if k not in self._g]
        if new:
            Xs = np.column_stack([self._cols[k][1] for k in new])
            G = self._r_inv() @ (self.Q.T @ self.pad(Xs)) if self.q else np.zeros((0, len(new)))
            for i, k in enumerate(new):
                self._g[k] = G[:, i]
        return np.column_stack([self._g[k] for k in keys]) if keys else np.zeros((self.q, 0))

    def basis_coupling(self, basis: RangeBasis) -> np.ndarray:
        """R_S⁻¹·Q_Sᵀ·[U_w; 0] (q × basis size), cached per version of the basis."""
        if self._GU is None or self._GU[0] != basis.version:
            Uw = basis.U[self.rows] * self.w[:, None]
            G = self._r_inv() @ (self.Q.T @ self.pad(Uw)) if self.q else np.zeros((0, Uw.shape[1]))
            self._GU = (basis.version, G)
        return self._GU[1]


def _kappa(ncols: int, p: int, a_S: float, a_E: float, c_E: float, d: float, c_X: float | None = None) -> float:
    """Upper bound on the condition number of the reference's column-scaled matrix [X, S, E] (with
    the prior rows): σ₁ ≤ √ncols (unit columns); ‖R⁻¹‖ of a block upper-triangular R ≤ a + d + a·c·d
    (the norms of its blocks' inverses a, d and of the coupling block c), applied to [S | E] (a_S,
    a_E, c_E) and then to [N | X] (c = ‖Q_Nᵀ·X_s‖₂ ≤ ‖X_s‖₂ = c_X ≤ √p)."""
    a_N = a_S + a_E + a_S * c_E * a_E
    c = math.sqrt(p) if c_X is None else c_X
    return math.sqrt(max(ncols, 1)) * (a_N + d + a_N * c * d)


def _kappa_blocks(F: NuisanceFactor, Bd: np.ndarray, prior_B: np.ndarray, RB: np.ndarray, G: np.ndarray) -> float:
    """A sharper upper bound on the condition number of the reference's column-scaled matrix
    A_s = [S_s, B_s] (with the prior rows; B = [E, X], the columns after the nuisance block S), for
    when :func:`_kappa`'s product of norms exceeds KAPPA_MAX. The singular values of A_s do not depend
    on the order of its columns; with A_s = [Q_S, Q_B]·R, R = [[R_S, C], [0, R_B]], C = Q_Sᵀ·B_s and
    Q_B·R_B = (I − Q_S·Q_Sᵀ)·B_s (the block solver's own factorisations, see the module's docstring):

    - σ₁(A_s) ≤ √(‖S_s‖₂² + ‖B_s‖₂²): for any partition into column blocks M = [M₁, M₂],
      ‖M·v‖ ≤ ‖M₁‖·‖v₁‖ + ‖M₂‖·‖v₂‖ ≤ √(‖M₁‖² + ‖M₂‖²)·‖v‖ (triangle and Cauchy–Schwarz inequalities);
      ‖S_s‖₂ = σ₁(R_S) (``F.s1``), ‖B_s‖₂² the largest eigenvalue of B_sᵀ·B_s (a small matrix);
    - 1/σ_min(A_s) = ‖R⁻¹‖₂ (A_s = Q·R, Q with orthonormal columns), and the inverse of a block upper
      triangular matrix is R⁻¹ = [[R_S⁻¹, −G·R_B⁻¹], [0, R_B⁻¹]] with G = R_S⁻¹·C (verified by
      multiplying out; e.g. "Inverse of partitioned matrices", math.techqa.club/inverse-of-partitioned-
      matrices-1377634, read 2026-12-06). The same partition into block columns gives
      ‖R⁻¹‖₂ ≤ √(‖R_S⁻¹‖₂² + ‖[G; I]·R_B⁻¹‖₂²), the second term's square the largest eigenvalue of
      R_B⁻ᵀ·(I + Gᵀ·G)·R_B⁻¹ (a matrix of B's size).

    :func:`_kappa` bounds the same ‖R⁻¹‖₂ by a + d + a·c·d (‖G·R_B⁻¹‖ ≤ a·c·d): this bound is never
    larger, and much smaller when X's share in the nuisance span avoids its ill-conditioned
    directions (the async motion's one column per stop and rep: S_s is nearly singular along sums
    of columns the closure centring cancels, which no candidate's harmonics follow).
    ``Bd``: B's scaled data rows; ``prior_B``: the diagonal of B's own prior rows (1/s_e per E
    column, 0 per X column); ``RB``: R_B; ``G``: R_S⁻¹·Q_Sᵀ·[Bd; 0]. inf when R_B is singular."""
    if not np.all(np.diag(RB) != 0):
        return math.inf
    gram = Bd.T @ Bd + np.diag(prior_B ** 2)
    b1 = float(np.linalg.eigvalsh(0.5 * (gram + gram.T))[-1])
    Gi = np.linalg.inv(RB)
    M = Gi.T @ ((G.T @ G + np.eye(G.shape[1])) @ Gi)
    r2 = float(np.linalg.eigvalsh(0.5 * (M + M.T))[-1])
    return math.sqrt(F.s1 ** 2 + max(b1, 0.0)) * math.sqrt(F.a ** 2 + max(r2, 0.0))


def _qr_r(a: np.ndarray) -> np.ndarray:
    """R of the QR factorisation of ``a`` (numpy's ``mode="r"``, which returns the array R; numpy's
    stubs type every mode as the (Q, R) result)."""
    return cast(np.ndarray, np.linalg.qr(a, mode="r"))


def _regressor_stack(K: np.ndarray, Ut: np.ndarray, Xt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Q_K, Z) for a regressor block E = U·K beside X: Kᵀ = Q_K·Lᵀ (so L·Lᵀ = K·Kᵀ and K = L·Q_Kᵀ), and
    the block solver's projected matrix Z = [U_t·L, X_t; I, 0] (E replaced by U·L: the same β, χ² and
    cov(β); the module's docstring)."""
    mE, p = K.shape[1], Xt.shape[1]
    QK, RK = np.linalg.qr(K.T) if K.size else (np.zeros((mE, 0)), np.zeros((0, K.shape[0])))
    Et = Ut @ RK.T
    r = Et.shape[1]
    return QK, np.vstack([np.hstack([Et, Xt]), np.hstack([np.eye(r), np.zeros((r, p))])])


def _sharper(F: NuisanceFactor, basis: RangeBasis, X: np.ndarray, Xs: np.ndarray, Rx: np.ndarray,
             K: np.ndarray | None, se: np.ndarray | None, RZ: np.ndarray | None, QK: np.ndarray | None) -> float:
    """:func:`_kappa_blocks` for a fit of X (scaled data rows Xs, R_X = Rx of the block solver's own
    factorisation) and, with a regressor block E = U·K (column norms se over data and prior rows), the
    reference's E columns [U_w·K/se; 0; diag(1/se)] as the first columns of B.

    ``RZ``, ``QK``: the block solver's R of Z = [U_t·L, X_t; I, 0] and the Q of Kᵀ = Q_K·Lᵀ
    (orthonormal columns; :func:`_regressor_stack`). B's projected matrix is Z_B = [U_t·K·D, X_t; D, 0]
    with D = diag(1/se) and K = L·Q_Kᵀ, and an R factor is fixed by the Gram matrix alone (up to the
    signs of its rows, which no singular value sees): with T = diag(Q_Kᵀ·D, I),
    Z_Bᵀ·Z_B = Tᵀ·RZᵀ·RZ·T + [D·P·D, 0; 0, 0], P = I − Q_K·Q_Kᵀ (the prior rows: D² where T gives
    D·Q_K·Q_Kᵀ·D), i.e. the Gram matrix of the small stack [RZ·T; P·D, 0]. Its QR replaces a QR of
    all the rows of Z_B (a 12-head bench: ≈ 16 ms a fit, 9 of its 65 s; the test compares the two)."""
    G_X = F.coupling(X)
    if K is None or se is None or RZ is None or QK is None:
        return _kappa_blocks(F, Xs, np.zeros(Xs.shape[1]), Rx, G_X)
    Ks = K / se
    mE, p = Ks.shape[1], Xs.shape[1]
    Uw = F.basis(basis)[0]
    Bd = np.hstack([Uw @ Ks, Xs])
    r = QK.shape[1]
    T = np.zeros((r + p, mE + p))
    T[:r, :mE] = QK.T / se[None, :]
    T[r:, mE:] = np.eye(p)
    PD = (np.eye(mE) - QK @ QK.T) / se[None, :]
    RB = _qr_r(np.vstack([RZ @ T, np.hstack([PD, np.zeros((mE, p))])]))
    G = np.hstack([F.basis_coupling(basis) @ Ks, G_X])
    return _kappa_blocks(F, Bd, np.concatenate([1.0 / se, np.zeros(p)]), RB, G)


def block_fit(F: NuisanceFactor, basis: RangeBasis, X: np.ndarray, extra: np.ndarray | None) -> dict | None:
    """The fit of X (and the regressor block ``extra``) on the training set of F, or None when the
    bound on the reference's condition number cannot rule out its truncations (use the reference)."""
    p = X.shape[1]
    mE = 0 if extra is None else extra.shape[1]
    if p:
        sx, Xs, Xt = F.columns(X)
        if not np.all(sx > 0):
            return None
    else:
        sx, Xs, Xt = np.zeros(0), np.zeros((F.m, 0)), np.zeros((F.m + F.q, 0))
    a_E, c_E, K, Ks, Uw, gain, QK = 0.0, 0.0, None, None, None, 0.0, None
    se: np.ndarray | None = None
    Ut: np.ndarray | None = None
    if extra is not None and mE:
        K = basis.coefficients(extra)
        if K is None:
            return None
        Uw, Ut, gain = F.basis(basis)
        # the reference's E columns are scaled to unit norm over data and prior rows (prior entries
        # 1/se_j, ‖E_w,j‖ = ‖U_w·K_j‖): projected on the complement of S their σ_min ≥ min 1/se_j
        # (the prior rows are S's zeros), and Q_Sᵀ·E_s = (Q_Sᵀ·U_w)·K·diag(1/se)
        UK = Uw @ K if K.size else np.zeros((F.m, mE))
        se = np.sqrt(np.sum(UK * UK, axis=0) + 1.0)
        a_E = float(se.max())
        Ks = K / se
        c_E = gain * float(np.linalg.norm(Ks))      # ‖·‖₂ ≤ ‖·‖_F
        QK, Z = _regressor_stack(K, Ut, Xt)
        r = QK.shape[1]
        bt = np.concatenate([F.bt, np.zeros(r)])
    else:
        r, Z, bt = 0, Xt, F.bt
    ncols = p + F.q + mE
    k = Z.shape[1]
    if k:
        # R of [Z, b̃]: R_Z and Q_Zᵀ·b̃ in one factorisation, no Q formed (numpy's LAPACK throughout:
        # scipy's has its own BLAS threads, outside trace's one-thread guard)
        Rb = _qr_r(np.hstack([Z, bt[:, None]]))
        R2 = Rb[:k, :k]
        if not np.all(np.diag(R2) != 0):
            return None
        gam = np.linalg.solve(R2, Rb[:k, k])
        res = bt - Z @ gam
    else:
        R2, gam, res = np.zeros((0, 0)), np.zeros(0), bt
    cov = np.zeros((0, 0))
    if p:
        Rx = R2[r:, r:]
        Gx = np.linalg.inv(Rx)     # R_X⁻¹: cov(β) = R_X⁻¹·R_X⁻ᵀ (scaled columns)
        d = float(np.linalg.norm(Gx))       # ‖R_X⁻¹‖₂ ≤ ‖R_X⁻¹‖_F
        if not _kappa(ncols, p, F.a, a_E, c_E, d) <= KAPPA_MAX:
            # the Frobenius norms may overstate by up to √(rank): the 2-norms (small SVDs) decide
            c_E = gain * float(np.linalg.norm(Ks, 2)) if Ks is not None else 0.0      # Ks: with E (mE > 0)
            c_X = math.sqrt(float(np.linalg.eigvalsh(Xs.T @ Xs)[-1]))      # ‖X_s‖₂ ≤ √p
            if not (_kappa(ncols, p, F.a, a_E, c_E, float(np.linalg.norm(Gx, 2)), c_X) <= KAPPA_MAX
                    or _sharper(F, basis, X, Xs, Rx, K, se, R2, QK) <= KAPPA_MAX):
                return None
        cov = (Gx @ Gx.T) / np.outer(sx, sx)
    elif not _kappa(ncols, 0, F.a, a_E, c_E, 0.0) <= KAPPA_MAX:
        return None
    rd = res[: F.m]     # the weighted data residual: ν = S_wᵀ·r, μ = E_wᵀ·r (prior stationarity)
    nuis = F.Sw.T @ rd if K is None or Uw is None else np.concatenate([F.Sw.T @ rd, K.T @ (Uw.T @ rd)])
    return {"beta": gam[r:] / sx if p else np.zeros(0), "cov": cov, "nuis": nuis, "chi2": float(res @ res), "k": p}
