"""The weighted least-squares problem every test and fit of the tracing solves.

Closure groups (Hsieh et al. 2022 eq. 2: Σα = 0 per run leaves α known up to one constant per
mounting): the weighted mean per group is removed from the residual and from every column; the
self-calibration rows (Hsieh eqs. 8–9) join the polygon's; the model's parameter uncertainties
(Jia et al. 2019 eq. 5: e, θ0, the probes' Fourier coefficients) enter as nuisance columns with a
unit Gaussian prior (covariance diag(u²) + S·Sᵀ); leave-one-group-out cross-validation folds; BIC
(Schwarz 1978) and AICc (Hurvich & Tsai 1989).
"""

from __future__ import annotations

import hashlib
import math

import numpy as np

from benchtwin.units import ARCSEC_PER_RAD
from ..distributions import chi2_logsf, norm_isf
from .blockfit import NuisanceFactor, RangeBasis, block_fit
from .evidence import Evidence, column
from .thresholds import MAX_CV_FOLDS


# ----------------------------------------------------------------------------------------------
# the weighted least-squares problem (closure groups, self-calibration rows, model nuisance)
# ----------------------------------------------------------------------------------------------

def _z_from_chi2(d: float, k: int) -> float:
    """Two-sided normal z equivalent of a χ²_k statistic d (Δχ² of k parameters)."""
    d = max(float(d), 0.0)
    k = max(int(k), 1)
    if k == 1:
        return math.sqrt(d)
    lp = float(chi2_logsf(d, k))
    if lp > -700:
        return float(norm_isf(math.exp(lp) / 2.0))
    return math.sqrt(-2.0 * lp)


def _digest(a: np.ndarray | None) -> tuple | None:
    """A key for the exact bytes of ``a`` (shape, dtype and a 256-bit BLAKE2b digest of its C-order
    bytes): equal keys for equal arrays, different keys for any other bytes (a collision is ~2⁻¹²⁸)."""
    if a is None:
        return None
    return a.shape, a.dtype.str, hashlib.blake2b(np.ascontiguousarray(a).tobytes(), digest_size=32).digest()


class _Fit(dict):
    """A fit's dict with some entries computed when first read (``lazy``: key → function returning
    the entries it computes): the cross-validation reads only beta, nuis and S, the rest reads
    everything; each entry is computed once, by the same expression as if it had been at once."""

    def __init__(self, d: dict, lazy: dict):
        super().__init__(d)
        self._lazy = lazy

    def __missing__(self, key):
        fn = self._lazy.get(key)
        if fn is None:
            raise KeyError(key)
        self.update(fn())
        for k in list(self._lazy):
            if k in self:
                del self._lazy[k]
        return self[key]


#: a column the closure keeps: its weighted norm after the per-group centring (:func:`_center`) above
#: this fraction of its norm before. Below it the per-run constants (Hsieh eq. 3's U_j) hold the
#: column and no reading constrains its coefficient: e.g. order N of an N-face polygon, whose kθ is
#: the same at every stop of a run at any shift.
CLOSURE_KEEP = 1e-6


def closure_kept(centred: np.ndarray, raw: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Which columns of a design survive the closure: ``centred`` (the columns after :func:`_center`,
    on the problem's rows) against ``raw`` (before, on the polygon's rows), both weighted by ``w``."""
    norms = np.linalg.norm(centred * w[: centred.shape[0], None], axis=0)
    before = np.linalg.norm(raw * w[: raw.shape[0], None], axis=0)
    return norms > CLOSURE_KEEP * np.maximum(before, 1e-300)


def _center(x: np.ndarray, groups: np.ndarray, w2: np.ndarray) -> np.ndarray:
    """Remove the w²-weighted mean of each group from each column of x."""
    x2 = x if x.ndim == 2 else x[:, None]
    ng = int(groups.max()) + 1
    sw = np.bincount(groups, weights=w2, minlength=ng)
    out = np.empty_like(x2, dtype=float)
    for c in range(x2.shape[1]):
        m = np.bincount(groups, weights=w2 * x2[:, c], minlength=ng) / np.where(sw > 0, sw, 1.0)
        out[:, c] = x2[:, c] - m[groups]
    return out if x.ndim == 2 else out[:, 0]


class _Problem:
    """Rows: the polygon readings (closure-centred) and, optionally, the self-calibration curve
    (centred, harmonics that are multiples of the head count projected out)."""

    #: the digest of ``y`` the memo and the factorisations are keyed on (set with y, __setattr__)
    _y_key: tuple | None
    #: −δX_async/r nuisance columns, computed once (:meth:`_async_nuisance`)
    _async_cache: np.ndarray | None = None

    def __init__(self, ev: Evidence, use_selfcal: bool = True):
        self.ev = ev
        n = ev.n
        self.view = ev.selfcal_view() if use_selfcal else None
        w_a = 1.0 / column(ev.u_arcsec)
        self.n_alpha = n
        y_a = _center(ev.residual_arcsec, column(ev.closure_group), w_a ** 2)
        self.n_groups = int(column(ev.closure_group).max()) + 1
        sens = ev.model_sensitivity or {}
        sens_keys = sorted(sens)
        S_a = (np.column_stack([sens[k] for k in sens_keys]) if sens_keys else np.zeros((n, 0)))
        S_a = np.hstack([S_a, self._radial_nuisance(ev)])
        S_a = _center(S_a, column(ev.closure_group), w_a ** 2) if S_a.shape[1] else S_a
        sc = ev.selfcal
        if self.view is not None and sc is not None:     # a view exists only with a self-calibration
            m = self.view.theta_deg.size
            w_s = np.broadcast_to(1.0 / np.asarray(sc.u_arcsec, dtype=float), (m,)).astype(float)
            th = np.deg2rad(self.view.theta_deg)
            blind = [np.ones(m)]
            k = int(sc.n_heads)
            while k > 0 and k <= (m - 1) // 2 and k <= 60:
                blind += [np.sin(k * th), np.cos(k * th)]
                k += int(sc.n_heads)
            self._Q = np.linalg.qr(np.column_stack(blind))[0]
            y_s = self._filt(self.view.alpha_arcsec - sum(self.view.model_terms.values()))
            if sens_keys:
                if not sc.model_sensitivity or set(sc.model_sensitivity) != set(sens_keys):
                    raise ValueError("selfcal.model_sensitivity must have the same keys as evidence.model_sensitivity")
                S_s = np.column_stack([sc.model_sensitivity[k] for k in sens_keys])
            else:
                S_s = np.zeros((m, 0))
            S_s = self._filt(np.hstack([S_s, self._radial_nuisance(self.view)]))
            self.y = np.concatenate([y_a, y_s])
            self.w = np.concatenate([w_a, w_s])
            self.S = np.vstack([S_a, S_s])
            self.n_groups += 1
        else:
            self.y, self.w, self.S = y_a, w_a, S_a
        self.n_rows = self.y.size
        # fits are memoised (keyed on the exact bytes of X, the training rows, E and y): S and w are
        # fixed for the problem's life, read-only so that nothing changes them under the memo
        self.S.flags.writeable = False
        self.w.flags.writeable = False
        # the block solver (analysis.tracing.blockfit) where its bound allows, else the reference:
        # trace's screening sets it (decisions, whose thresholds and ties are far above its ~1e-13
        # difference from the reference); the reported numbers are the reference's
        self.fast = False
        self._memo: dict = {}
        self._factors: dict = {}
        self._basis = RangeBasis(self.n_rows)
        self.alpha_rows = np.zeros(self.n_rows, bool)
        self.alpha_rows[:n] = True
        self.folds = self._folds()
        self.null = self.fit(np.zeros((self.n_rows, 0)))

    def _radial_nuisance(self, e) -> np.ndarray:
        ev = self.ev
        if ev.radial is None or not ev.radial_term or ev.radial_term not in ev.model_terms:
            return np.zeros((len(e.theta_deg), 0))
        k = ARCSEC_PER_RAD / (ev.optical_radius_mm * 1000.0)
        cols = [ev.radial.perturbations(e.theta_deg, "dY_um", "integral") * k]
        if ev.sphere_form_um:
            cols.append(ev.radial.form_perturbations(e.theta_deg, "dY_um", ev.sphere_form_um / math.sqrt(3.0)) * k)
        if e is ev:
            cols.append(self._async_nuisance(ev) * k)
        else:
            cols.append(np.zeros((len(e.theta_deg), self._async_nuisance(ev).shape[1])))
        return np.hstack(cols)

    def _async_nuisance(self, ev) -> np.ndarray:
        """−δX_async/r at the polygon readings (before the factor ARC/r): the non-repeating motion
        of the polygon's revolution is unmeasured along X; its size along Y (``RadialMotion.async_rms``,
        isotropic) sets one random offset per stop position and polygon rep (the stops sample it
        at their angles; its spectrum reaches far beyond the polygon's harmonics and aliases)."""
        cached = self._async_cache
        if cached is not None:
            return cached
        a = ev.radial.async_rms("dY_um") if ev.radial is not None else {}
        self.async_info = a
        sg = float(a.get("sigma_um", 0.0)) if a else 0.0
        cols = []
        if sg > 0:
            for r in np.unique(ev.rep):
                m = ev.rep == r
                for b in np.unique(ev.theta_bin[m]):
                    cols.append(sg * (m & (ev.theta_bin == b)).astype(float))
        self._async_cache = np.column_stack(cols) if cols else np.zeros((ev.n, 0))
        return self._async_cache

    def regressor_nuisance(self, modules, params_by_member, ctx) -> np.ndarray:
        """Nuisance columns for the uncertainty of measured regressors (radial motion), scaled by the
        fitted parameters: errors in variables, linearised."""
        cols = []
        for mod, P in zip(modules, params_by_member):
            fn = getattr(mod, "regressor_perturbations", None)
            if fn is None:
                continue
            R_a = np.asarray(fn(self.ev, P, ctx), dtype=float)
            if R_a.shape[1] == 0:
                continue
            R_a = self._center_screening(R_a) if self.fast else _center(R_a, column(self.ev.closure_group), self.w[: self.ev.n] ** 2)
            if self.view is not None:
                R_s = self._filt(np.asarray(fn(self.view, P, ctx), dtype=float)) if mod.SEEN_BY_SELFCAL else \
                    np.zeros((self.n_rows - self.ev.n, R_a.shape[1]))
                R_a = np.vstack([R_a, R_s])
            cols.append(R_a)
        return np.hstack(cols) if cols else np.zeros((self.n_rows, 0))

    def _center_screening(self, x: np.ndarray) -> np.ndarray:
        """:func:`_center` as one product with the (groups × readings) weighted-mean matrix: the
        same columns to rounding (not the same bits), for the screening's regressor blocks, which
        are centred per candidate; the reported fits centre them with :func:`_center`."""
        if getattr(self, "_mean_op", None) is None:
            g, w2 = column(self.ev.closure_group), self.w[: self.ev.n] ** 2
            M = np.zeros((int(g.max()) + 1, g.size))
            M[g, np.arange(g.size)] = w2
            sw = M.sum(axis=1)
            self._mean_op = M / np.where(sw > 0, sw, 1.0)[:, None]
        return x - (self._mean_op @ x)[column(self.ev.closure_group)]

    def _filt(self, x):
        x2 = x if x.ndim == 2 else x[:, None]
        out = x2 - self._Q @ (self._Q.T @ x2)
        return out if x.ndim == 2 else out[:, 0]

    def _folds(self):
        """Cross-validation folds over the polygon rows (self-calibration rows always train).

        Every training set must still identify what the candidates fit, whatever the design:
        - leave-one-repetition-out when there are ≥ 3 repetitions: a repetition is the same design
          again (all shifts, start faces and directions stay in every training set);
        - else leave-one-start-face-out with ≥ 3 start faces (the other faces keep the face pattern
          determined; a shift set with one face per shift loses one θ set per fold);
        - else leave-one-shift-out with ≥ 3 shifts (shift sets: SelfA-like 0…14° in 1° steps);
        - else interleaved stop positions: every MAX_CV_FOLDS-th position of θ held out (one rep,
          one start face, one shift, one or both directions; or keys whose largest group holds more
          than a third of the readings): the held-out stops are between trained ones, so the
          harmonics a candidate fits are still determined.
        Groups are merged cyclically into ≤ MAX_CV_FOLDS folds. None with fewer than 3 groups."""
        ev = self.ev
        f = np.full(self.n_rows, -1)
        for key in (ev.rep, ev.start_face, ev.shift_deg):
            u, inv = np.unique(np.round(np.asarray(key, dtype=float), 6), return_inverse=True)
            # balanced only: no group may hold more than a third of the readings (all start faces
            # at S = 0 but one face at the other shifts put every shifted reading into one fold)
            if u.size >= 3 and np.bincount(inv).max() <= ev.n / 3.0 + 1e-9:
                f[: ev.n] = inv % MAX_CV_FOLDS
                return f
        u, inv = np.unique(ev.theta_bin, return_inverse=True)
        k = min(MAX_CV_FOLDS, u.size // 4)   # ≥ 4 positions per fold's complement share
        if k >= 3:
            f[: ev.n] = inv % k
            return f
        return None

    # -- columns -----------------------------------------------------------------------------
    def columns(self, module, ctx) -> tuple[np.ndarray, list[str]]:
        ev = self.ev
        X_a, names = module.design(ev, ctx)
        X_a = np.asarray(X_a, dtype=float).reshape(ev.n, -1)
        X_a = _center(X_a, column(ev.closure_group), self.w[: ev.n] ** 2) if X_a.shape[1] else X_a
        if self.view is None:
            return X_a, list(names)
        m = self.view.theta_deg.size
        if module.SEEN_BY_SELFCAL and X_a.shape[1]:
            X_s, names_s = module.design(self.view, ctx)
            X_s = np.asarray(X_s, dtype=float).reshape(m, -1)
            if list(names_s) != list(names):
                raise RuntimeError(f"{module.NAME}: self-calibration design has other parameters")
            X_s = self._filt(X_s)
        else:
            X_s = np.zeros((m, X_a.shape[1]))
        return np.vstack([X_a, X_s]), list(names)

    # -- fits --------------------------------------------------------------------------------
    def fit(self, X: np.ndarray, train: np.ndarray | None = None, extra: np.ndarray | None = None,
            target: np.ndarray | None = None) -> dict:
        """The weighted fit of X (and E = ``extra``) with the model nuisance, on ``train`` rows (all
        rows by default): beta, cov, nuis, chi2, dof, k (rank of X), n, S. Memoised on the exact
        bytes of its inputs and y; the block solver when ``fast`` is set, else the reference.
        ``target``: fit that vector instead of y (the errors-in-variables Gauss–Newton step, used
        once: not memoised)."""
        if extra is not None and extra.shape[1] == 0:
            extra = None
        if target is not None:
            return (self._fit_block(X, train, extra, target) if self.fast else None) or \
                self._fit_reference(X, train, extra, target)
        if extra is not None:
            # a regressor block belongs to one candidate's parameters: such a fit is not asked for
            # twice (measured: 188 of 188 distinct on the default dataset); no memo, no hashing
            return (self._fit_block(X, train, extra) if self.fast else None) or self._fit_reference(X, train, extra)
        key = (self.fast, _digest(X), _digest(train), self._y_key)
        out = self._memo.get(key)
        if out is None:
            out = (self._fit_block(X, train, None) if self.fast else None) or self._fit_reference(X, train, None)
            self._memo[key] = out
        return out

    def __setattr__(self, name, value):
        # y (the residual; trace swaps it for the residual after) is kept as a read-only copy with
        # the digest the memo and the factorisations are keyed on; S and w are fixed at __init__
        if name == "y":
            value = np.array(value, dtype=float)
            value.flags.writeable = False
            super().__setattr__("_y_key", _digest(value))
        super().__setattr__(name, value)

    def _fit_block(self, X, train, extra, target=None) -> dict | None:
        rows = np.ones(self.n_rows, bool) if train is None else train
        fkey = (_digest(train), self._y_key)
        F = self._factors.get(fkey)
        if F is None:
            F = self._factors[fkey] = NuisanceFactor(self.S, self.w, self.y, rows)
        if target is not None:
            F = F.retarget(target)
        out = block_fit(F, self._basis, X, extra)
        if out is None:
            return None
        n_fit = int(rows.sum())
        out.update(dof=max(n_fit - self.n_groups - out["k"], 1), n=n_fit)
        if extra is None:
            out["S"] = self.S
            return out
        return _Fit(out, {"S": lambda: {"S": np.hstack([self.S, extra])}})

    def _fit_reference(self, X, train, extra, target=None) -> dict:
        """The reference solver: SVD least squares (lstsq) of the column-scaled stacked matrix,
        covariance from its pseudo-inverse, small singular values truncated."""
        w = self.w
        y = self.y if target is None else np.asarray(target, dtype=float)
        rows = np.ones(self.n_rows, bool) if train is None else train
        S = self.S if extra is None or extra.shape[1] == 0 else np.hstack([self.S, extra])
        p, q = X.shape[1], S.shape[1]
        A = np.hstack([X, S])[rows] * w[rows, None]
        b = y[rows] * w[rows]
        if q:
            prior = np.hstack([np.zeros((q, p)), np.eye(q)])
            A = np.vstack([A, prior])
            b = np.concatenate([b, np.zeros(q)])
        if A.shape[1]:
            scale = np.linalg.norm(A, axis=0)
            scale[scale == 0] = 1.0
            As = A / scale
            sol = np.linalg.lstsq(As, b, rcond=None)[0]
            beta_all = sol / scale
        else:
            beta_all = np.zeros(0)
        n_fit = int(rows.sum())

        def cov() -> dict:
            # the pseudo-inverse and the rank: not read by the cross-validation (only beta, nuis)
            if not A.shape[1]:
                return {"cov": np.zeros((0, 0))}
            covs = np.linalg.pinv(As.T @ As, rcond=1e-10, hermitian=True)
            return {"cov": (covs / np.outer(scale, scale))[:p, :p]}

        def rank() -> dict:
            rank_x = int(np.linalg.matrix_rank(X[rows] * w[rows, None] / np.where(scale[:p] > 0, scale[:p], 1), tol=1e-8)) if p else 0
            return {"k": rank_x, "dof": max(n_fit - self.n_groups - rank_x, 1)}

        chi2 = float(np.sum((b - A @ beta_all) ** 2)) if A.shape[1] else float(np.sum(b ** 2))
        return _Fit({"beta": beta_all[:p], "nuis": beta_all[p:], "chi2": chi2, "n": n_fit, "S": S},
                    {"cov": cov, "k": rank, "dof": rank})

    def predict_rows(self, X, fit, rows=None, nuisance=True):
        rows = np.ones(self.n_rows, bool) if rows is None else rows
        out = X[rows] @ fit["beta"] if X.shape[1] else np.zeros(int(rows.sum()))
        if nuisance and fit["S"].shape[1]:
            out = out + fit["S"][rows] @ fit["nuis"]
        return out

    def cv(self, X, extra=None) -> float | None:
        """Held-out weighted χ² summed over leave-one-group-out folds, plus the mean over the folds
        of the training fits' nuisance prior term Σ nuis² (None without folds).

        Why the prior term: every fit minimises the data's χ² plus the nuisance's unit Gaussian prior
        (the model's own uncertainty, e.g. u of the probes' Fourier coefficients). The prior is not
        data, so it is not held out; it enters once, as in each training fit. Without it a model can
        predict held-out readings through nuisance pushed far beyond its stated uncertainty (a 1″
        division error at k = 2 carried by the ∫δY term's 0.04″ type-A u, at 25 σ, on an air
        bearing's multi-head bench: the reference generator's hsieh_like, seed 41) and "no effect"
        cross-validates as well as the effect itself.

        None also when a fold's training rows do not determine X (rank below X's on every row): the
        held-out rows then ask the candidate for parameters no training set has seen — e.g. a value
        per stop position (graduation_error's every resolved order) when the only start face of the
        shifted runs is held out, or interleaved stop positions are — and the held-out χ² measures
        the folds, not the candidate. A test that cannot see the candidate decides nothing about it."""
        if self.folds is None:
            return None
        folds = np.unique(self.folds[self.folds >= 0])
        if X.shape[1] and not self._folds_determine(X, folds):
            return None
        tot, prior, nf = 0.0, 0.0, 0
        for f in folds:
            test = self.folds == f
            fit = self.fit(X, train=~test, extra=extra)
            r = (self.y[test] - self.predict_rows(X, fit, test)) * self.w[test]
            tot += float(np.sum(r ** 2))
            nu = np.asarray(fit["nuis"], dtype=float)
            prior += float(nu @ nu)
            nf += 1
        return tot + prior / max(nf, 1)

    def _folds_determine(self, X: np.ndarray, folds: np.ndarray) -> bool:
        """Does every fold's training set determine the columns of X as all rows do (the same rank,
        the reference fit's tolerance on the column-scaled weighted design)? Cached per design."""
        key = _digest(X)
        cache = self.__dict__.setdefault("_determined", {})
        if key not in cache:
            Xw = X * self.w[:, None]
            scale = np.linalg.norm(Xw, axis=0)
            Xs = Xw / np.where(scale > 0, scale, 1.0)
            full = int(np.linalg.matrix_rank(Xs, tol=1e-8))
            cache[key] = all(int(np.linalg.matrix_rank(Xs[self.folds != f], tol=1e-8)) >= full for f in folds)
        return bool(cache[key])

    def eiv_posterior(self, X: np.ndarray, fit: dict, extra: np.ndarray) -> tuple[np.ndarray, float]:
        """Errors in variables, checked: (ν̂, p) for the measured-regressor nuisance E (unit prior,
        ``extra``, at least one column) of a fit of X: ν̂ its posterior mean given the residual
        y − X·β (with the model nuisance S), per column of E in units of that column's u
        (selection._adjustment_by_order reads it order by order); p = Σ λ/(1 + λ) over the
        eigenvalues λ of Eᵀ Σ₀⁻¹ E (Σ₀ = W⁻¹ + S Sᵀ), the number of E's directions the readings
        determine: Σ ν̂² is ~χ²(p) when the regressor's uncertainty is what its u says."""
        w2 = self.w ** 2
        r = self.y - (X @ np.asarray(fit["beta"], dtype=float) if X.shape[1] else 0.0)
        A = np.hstack([self.S, extra])
        Aw = A * w2[:, None]
        nu = np.linalg.solve(np.eye(A.shape[1]) + A.T @ Aw, Aw.T @ r)[self.S.shape[1]:]
        We = extra * w2[:, None]
        S = self.S
        if S.shape[1]:
            Ws = S * w2[:, None]
            G = extra.T @ We - (We.T @ S) @ np.linalg.solve(np.eye(S.shape[1]) + S.T @ Ws, Ws.T @ extra)
        else:
            G = extra.T @ We
        lam = np.clip(np.linalg.eigvalsh(0.5 * (G + G.T)), 0.0, None)
        return nu, float(np.sum(lam / (1.0 + lam)))

    def ic(self, fit) -> tuple[float, float]:
        n, k, chi2 = fit["n"], fit["k"], fit["chi2"]
        bic = chi2 + k * math.log(n)
        aicc = chi2 + 2 * k + (2 * k * (k + 1) / (n - k - 1) if n - k - 1 > 0 else math.inf)
        return bic, aicc


def noise_floor(ev: Evidence) -> float:
    """The per-reading noise floor (arcsec): ``u_floor_arcsec`` if given (GUM u_c of one α, type A
    and B), else the RMS of the readings' u."""
    u = float(np.sqrt(np.mean(np.square(ev.u_arcsec))))
    return max(u, float(ev.u_floor_arcsec)) if ev.u_floor_arcsec else u


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else 0.0


def chi2_scale(fit: dict) -> float:
    """max(1, χ²/dof) of a fit (:meth:`_Problem.fit`): the factor by which its covariance, and a χ²
    difference judged against its scatter, are scaled when it leaves more scatter than the readings'
    u explain (GUM type A with an honest scatter); 1 when it does not."""
    return max(1.0, fit["chi2"] / fit["dof"])
