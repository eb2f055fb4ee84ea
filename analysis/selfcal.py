"""Multi-head self-calibration of an angle encoder (Hsieh, Watanabe, Hsu 2022, sec. 2.3, eqs. 8-9).

T.-H. Hsieh, T. Watanabe, P.-E. Hsu, Appl. Sci. 12 (2022) 5008; SelfA: Watanabe et al., Meas. Sci.
Technol. 25 (2014) 065002; general arrangements: Geckeler et al., Meas. Sci. Technol. 25 (2014)
055003; Probst, Meas. Sci. Technol. 19 (2008) 015101.

Data (docs/conventions.md, "Multi-head"): ``delta_arcsec[:, j−1]`` at θ is eq. 8's

    δ_{i,(1,j)} = a(θ) − a(θ − ψ_j)

head 1's reading error minus head j's, with ψ_j = ``heads_deg[j−1]`` the azimuth of head j from head 1
(so ``heads_deg[0] == 0`` and δ of head 1 is 0). Head j reads at θ the graduation that passed
head 1 when it read θ − ψ_j: heads sit counter-clockwise from head 1 and the disk turns
counter-clockwise (docs/conventions.md), so eq. 8's index i + (j−1)·NG/NH is θ − ψ_j in reading
coordinates. a(θ) is head 1's reading error, the encoder error
α(θ) of the shift-angle method (same sign: reading − true).

- eq. 9 (:func:`equal_spacing_selfcal_arcsec`): NH equally spaced heads, μ(θ) = (1/NH)·Σ_j δ_j(θ)
  = a(θ) − (1/NH)·Σ_j a(θ − ψ_j). The subtracted average contains exactly the harmonics of a whose
  order is a multiple of NH (and the mean), so μ is a without them.
- Fourier domain (:func:`transfer_function`, :func:`selfcal_fourier`): with a(θ) = Σ_k A_k e^{ikθ}, head j
  sees D_jk = G_jk·A_k, G_jk = 1 − e^{−ikψ_j}; the average over a set s of heads sees
  M_sk = H_sk·A_k with H_sk = 1 − (1/NH_s)·Σ_{j∈s} e^{−ikψ_j}. A set cannot see harmonics with H_sk = 0
  (for an equally spaced set: k ≡ 0 mod NH). Per set, Â_k = M_sk / H_sk where |H_sk| > tol. Across sets
  (or heads), the weighted least-squares estimate per harmonic
  Â_k = Σ_s w_s·conj(H_sk)·M_sk / Σ_s w_s·|H_sk|², w_s = 1/var(noise of M_s), recovers every harmonic
  that at least one set sees.

What remains unobservable (set to zero and listed in the result):

- k = 0, the mean of a: no arrangement of heads sees it; circle closure fixes it (Σa = 0, as eq. 2);
- every k with k·ψ_j ≡ 0 (mod 360°) for all heads j used — for the SelfA sets {3, 4, 7 heads} the
  common multiples of 3, 4 and 7, i.e. k = 84, 168, 252, …; for a single set of NH equally spaced
  heads, all multiples of NH;
- harmonics near the zeros of Σ_s w_s|H_sk|² are amplified noise; ``tol`` decides which are dropped;
- the Nyquist harmonic n/2 of the θ grid (not estimated), and anything above it (aliased by the
  sampling; the fractional head shifts are applied as trigonometric interpolation, exact for
  band-limited a).

Uncertainty: the estimator is linear and shift-invariant per head, â = Σ_j h_j ⊛ δ_j, so
u²(â(θ)) = Σ_j (h_j² ⊛ u_j²)(θ) for independent δ readings (white or per-θ ``u_delta_arcsec``).
Without ``u_delta_arcsec`` a pooled u(δ) is estimated from the residuals δ_j − (â(θ) − â(θ − ψ_j)) of the
heads used, with ν = n·(heads used) − (parameters) degrees of freedom (NaN if ν ≤ 0). Shared heads
between sets are accounted for in the propagation (the weights ignore the correlation).

Decisions where the paper is silent: SelfA averages heads 1 and 7 as the reference (sec. 3.2); here
the reference is head 1 as in the dataset's δ definition. θ must be an equally spaced full-circle grid.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "SELFA_HEADS_DEG",
    "SELFA_SETS",
    "equal_spacing_selfcal_arcsec",
    "transfer_function",
    "invisible_harmonics",
    "head_deltas_arcsec",
    "SelfCalResult",
    "selfcal_fourier",
    "tabulate_heads",
    "equally_spaced_sets",
]

#: SelfA head azimuths from head 1 (deg): the union of sets of 3, 4 and 7 equally spaced heads sharing
#: head 1, numbered around the circle (Hsieh 2022 fig. 10, sec. 3.2; heads 1 and 7 are opposite).
SELFA_HEADS_DEG: list[float] = [0.0, 360 / 7, 90.0, 2 * 360 / 7, 120.0, 3 * 360 / 7, 180.0, 4 * 360 / 7, 240.0,
                                5 * 360 / 7, 270.0, 6 * 360 / 7]
#: SelfA head sets (1-based head numbers): NH = 3 (120°), 4 (90°), 7 (≈51.43°).
SELFA_SETS: dict[str, list[int]] = {"NH3": [1, 5, 9], "NH4": [1, 3, 7, 11], "NH7": [1, 2, 4, 6, 8, 10, 12]}


def equal_spacing_selfcal_arcsec(delta_arcsec: np.ndarray, u_delta_arcsec: np.ndarray | float | None = None
                                 ) -> tuple[np.ndarray, np.ndarray]:
    """eq. 9: μ(θ) = (1/NH)·Σ_{j=1}^{NH} δ_{(1,j)}(θ) for NH equally spaced heads; ``delta_arcsec`` (n, NH).

    Returns ``(mu, u_mu)``; u from independent ``u_delta_arcsec`` (scalar or (n, NH)), NaN if not given.
    Head 1's column (δ ≡ 0) contributes nothing to u.
    """
    d = np.asarray(delta_arcsec, dtype=float)
    if d.ndim != 2:
        raise ValueError(f"delta_arcsec: expected shape (n, NH), got {d.shape}")
    nh = d.shape[1]
    mu = d.mean(axis=1)
    if u_delta_arcsec is None:
        return mu, np.full(mu.shape, np.nan)
    u = np.broadcast_to(np.asarray(u_delta_arcsec, dtype=float), d.shape).copy()
    u[:, 0] = 0.0
    return mu, np.sqrt(np.sum(u**2, axis=1)) / nh


def transfer_function(heads_deg: Sequence[float], harmonics: np.ndarray | Sequence[int],
                      weights: Sequence[float] | None = None) -> np.ndarray:
    """H_k = 1 − Σ_j w_j·e^{−ikψ_j} (w = 1/NH by default): what the head average μ sees of harmonic k of a."""
    psi = np.deg2rad(np.asarray(heads_deg, dtype=float))
    k = np.asarray(harmonics, dtype=float)
    w = np.full(psi.size, 1.0 / psi.size) if weights is None else np.asarray(weights, dtype=float)
    return 1.0 - np.exp(-1j * np.multiply.outer(k, psi)) @ w


def invisible_harmonics(heads_deg: Sequence[float] | np.ndarray, k_max: int, tol: float = 1e-9) -> np.ndarray:
    """Harmonic orders 1…k_max that the heads cannot see at all: k·ψ_j ≡ 0 (mod 360°) for every head.

    For a set of NH equally spaced heads these are the multiples of NH. (This is |H_k| = 0 with any
    positive weights, since every term of H_k's real part 1 − cos kψ_j is ≥ 0.)
    """
    k = np.arange(1, int(k_max) + 1)
    psi = np.deg2rad(np.asarray(heads_deg, dtype=float))
    G = 1.0 - np.exp(-1j * np.multiply.outer(k, psi))
    return k[np.all(np.abs(G) < tol, axis=1)]


def head_deltas_arcsec(a_fn: Callable[[np.ndarray], np.ndarray], theta_deg: np.ndarray,
                       heads_deg: Sequence[float]) -> np.ndarray:
    """eq. 8 from a known reading error a(θ): δ[:, j−1] = a(θ) − a(θ − ψ_j) (for tests and demos)."""
    th = np.asarray(theta_deg, dtype=float)
    return np.column_stack([a_fn(th) - a_fn(np.mod(th - p, 360.0)) for p in heads_deg])


@dataclass(frozen=True)
class SelfCalResult:
    """Result of :func:`selfcal_fourier`.

    ``theta_deg``, ``value_arcsec`` (â(θ), zero mean), ``u_arcsec`` per θ; ``per_set_arcsec`` each set's
    own estimate (harmonics it cannot see are zero); ``harmonics`` 0…n//2 and the transfer functions
    ``H`` per set over them; ``unobservable_harmonics`` (of the combination, 1…n//2−1),
    ``invisible_by_set``; ``sigma_delta_arcsec`` the pooled residual u(δ) (from the residuals of the set
    averages, scaled to one δ) and its ``dof``; ``residual_rms_arcsec`` the rms residual of the single
    heads' δ (larger than σ when a head sees an error that is not a property of the disk, e.g. the
    axis' radial error motion); ``set_residual_rms_arcsec`` per set; ``set_on_grid`` per set;
    ``u_model_arcsec`` the interpolation (aliasing) error of the harmonics only off-grid sets supply
    (``prefer_on_grid``), included in ``u``.
    """

    theta_deg: np.ndarray
    value_arcsec: np.ndarray
    u_arcsec: np.ndarray
    per_set_arcsec: dict[str, np.ndarray]
    harmonics: np.ndarray
    H: dict[str, np.ndarray]
    unobservable_harmonics: np.ndarray
    invisible_by_set: dict[str, np.ndarray]
    sigma_delta_arcsec: float
    dof: float
    residual_rms_arcsec: float
    notes: list[str] = field(default_factory=list)
    set_residual_rms_arcsec: dict[str, float] = field(default_factory=dict)
    set_on_grid: dict[str, bool] = field(default_factory=dict)
    u_model_arcsec: float = 0.0


def _check_grid(theta_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    th = np.asarray(theta_deg, dtype=float).ravel()
    if th.size < 4:
        raise ValueError(f"theta_deg: need at least 4 points on the circle, got {th.size}")
    if not np.all(np.isfinite(th)):
        raise ValueError(f"theta_deg: rows {np.flatnonzero(~np.isfinite(th))[:10].tolist()} not finite")
    order = np.argsort(np.mod(th, 360.0), kind="stable")
    ths = np.mod(th, 360.0)[order]
    n = ths.size
    step = 360.0 / n
    dev = np.abs((ths - ths[0]) - np.arange(n) * step)
    if dev.max() > 1e-6 * step + 1e-9:
        bad = order[np.flatnonzero(dev > 1e-6 * step + 1e-9)]
        raise ValueError(f"theta_deg: not an equally spaced full-circle grid of {n} points (step {step:g} deg); "
                         f"rows {bad[:10].tolist()} off the grid")
    return ths, order


def equally_spaced_sets(heads_deg: Sequence[float], tol_deg: float = 1e-4) -> dict[str, list[int]]:
    """The maximal sets of NH ≥ 2 equally spaced heads (360°/NH apart) among ``heads_deg``, 1-based.

    A set contained in a larger one is dropped (its blind harmonics, the multiples of its NH, include
    the larger set's). For the SelfA heads: {"NH3": [1, 5, 9], "NH4": [1, 3, 7, 11], "NH7": [1, 2, 4, …]}.
    Sets not containing head 1 are found too (named ``NH{n}@{head}``).
    """
    psi = np.mod(np.asarray(heads_deg, dtype=float).ravel(), 360.0)
    n = psi.size

    def find(a: float) -> int | None:
        d = np.abs(np.mod(psi - a + 180.0, 360.0) - 180.0)
        i = int(np.argmin(d))
        return i if d[i] <= tol_deg else None

    found: list[frozenset[int]] = []
    for nh in range(n, 1, -1):
        for base in range(n):
            found_idx = [find(psi[base] + m * 360.0 / nh) for m in range(nh)]
            idx = [i for i in found_idx if i is not None]
            if len(idx) != nh or len(set(idx)) != nh:
                continue
            st = frozenset(idx)
            if not any(st <= f for f in found):
                found.append(st)
    out: dict[str, list[int]] = {}
    for st in sorted(found, key=lambda f: (len(f), min(f))):
        h = sorted(i + 1 for i in st)
        name = f"NH{len(h)}" if 1 in h else f"NH{len(h)}@{h[0]}"
        while name in out:
            name += "'"
        out[name] = h
    return out


def _checked_deltas(theta_deg: np.ndarray, heads_deg: Sequence[float],
                    delta_arcsec: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(ψ of the heads in deg, the sorted θ grid, the order that sorts θ, δ sorted by θ (n × n_heads));
    ValueError naming the input otherwise."""
    psi_deg = np.asarray(heads_deg, dtype=float).ravel()
    nheads = psi_deg.size
    if nheads < 2:
        raise ValueError("need at least 2 heads")
    if abs(psi_deg[0]) > 1e-12:
        raise ValueError(f"heads_deg[0] must be 0 (azimuths are measured from head 1), got {psi_deg[0]}")
    d = np.asarray(delta_arcsec, dtype=float)
    ths, order = _check_grid(theta_deg)
    n = ths.size
    if d.shape != (n, nheads):
        raise ValueError(f"delta_arcsec: expected shape ({n}, {nheads}) (theta × heads), got {d.shape}")
    bad = np.argwhere(~np.isfinite(d))
    if bad.size:
        raise ValueError(f"delta_arcsec: not finite at (row, head) {[(int(r), int(c) + 1) for r, c in bad[:10]]}")
    return psi_deg, ths, order, d[order]


def _set_matrix(sets: Mapping[str, Sequence[int]] | None, nheads: int) -> tuple[list[str], np.ndarray]:
    """The sets' names and their averaging matrix over the heads (n_sets × n_heads, eq. 9); default:
    every head j ≥ 2 with head 1."""
    if sets is None:
        sets = {f"head{j}": [1, j] for j in range(2, nheads + 1)}
    for name, hs in sets.items():
        badh = [h for h in hs if not 1 <= int(h) <= nheads]
        if badh:
            raise ValueError(f"set {name!r}: heads {badh} outside 1…{nheads}")
    names = list(sets)
    P = np.zeros((len(names), nheads))  # set-averaging matrix over heads
    for s, name in enumerate(names):
        hs = sorted(set(int(h) for h in sets[name]))
        P[s, [h - 1 for h in hs]] = 1.0 / len(hs)
    return names, P


def _head_variances(u_delta_arcsec: np.ndarray | float | None, order: np.ndarray,
                    nheads: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Unit per-head noise variances for the weights (head 1: 0; all alike for exact data) and the
    given u(δ)² per reading sorted by θ (None when not given)."""
    n = order.size
    if u_delta_arcsec is None:
        var_head = np.ones(nheads)
        u2 = None
    else:
        u2 = np.broadcast_to(np.asarray(u_delta_arcsec, dtype=float), (n, nheads))[order].astype(float) ** 2
        var_head = u2.mean(axis=0)
    var_head = var_head.copy()
    var_head[0] = 0.0
    if not np.any(var_head[1:] > 0):  # exact data: weigh every head alike
        var_head[1:] = 1.0
    return var_head, u2


@dataclass(frozen=True)
class _System:
    """Eq. 9 in the Fourier domain: per FFT bin (signed harmonic ``kk``) the heads' transfer ``G``
    (n × heads) and the sets' ``Hs`` (n × sets), the sets' weights ``w`` and per harmonic ``W``,
    which sets sit on the θ grid, the normal-equation denominators ``den``, the harmonics ``seen``
    and the estimator ``Q`` (Â_k = Σ_j Q_jk D_jk)."""

    kk: np.ndarray
    nyq: np.ndarray
    G: np.ndarray
    P: np.ndarray
    Hs: np.ndarray
    w: np.ndarray
    W: np.ndarray
    set_on_grid: np.ndarray
    mixed: bool
    grid_sees: np.ndarray
    den: np.ndarray
    seen: np.ndarray
    Q: np.ndarray


def _system(n: int, psi_deg: np.ndarray, P: np.ndarray, var_head: np.ndarray, tol: float,
            prefer_on_grid: bool) -> _System:
    """Weighted least squares of the sets' eq. 9 per harmonic; with on-grid and off-grid sets mixed
    (``prefer_on_grid``), the off-grid sets only where no on-grid set sees the harmonic."""
    nsets, nheads = P.shape
    # signed harmonic index of each FFT bin
    kk = np.fft.fftfreq(n, d=1.0 / n).round().astype(int)
    psi = np.deg2rad(psi_deg)
    G = 1.0 - np.exp(-1j * np.outer(kk, psi))  # (n, nheads): head j sees a(θ − ψ_j)
    Hs = G @ P.T  # (n, nsets): H_sk = Σ_j P_sj G_jk = 1 − mean e^{ikψ}
    var_set = (P**2) @ var_head
    w = np.where(var_set > 0, 1.0 / np.where(var_set > 0, var_set, 1.0), 0.0)
    w = w / w.max() if w.max() > 0 else w
    step = 360.0 / n
    frac = np.abs(psi_deg / step - np.round(psi_deg / step))
    head_on_grid = frac < 1e-6
    set_on_grid = np.array([bool(np.all(head_on_grid[P[s] > 0])) for s in range(nsets)])
    nyq = (n % 2 == 0) & (np.abs(kk) == n // 2)
    W = np.broadcast_to(w, (n, nsets)).copy()  # weights per harmonic and set
    mixed = bool(prefer_on_grid and set_on_grid.any() and not set_on_grid.all())
    grid_sees = np.zeros(n, dtype=bool)
    if mixed:
        den_grid = (np.abs(Hs[:, set_on_grid]) ** 2) @ w[set_on_grid]
        grid_sees = den_grid > tol**2 * max(w[set_on_grid].sum(), 1e-300)
        W[np.ix_(grid_sees, ~set_on_grid)] = 0.0
    den = np.sum(np.abs(Hs) ** 2 * W, axis=1)  # (n,)
    seen = (den > tol**2 * max(w.sum(), 1e-300)) & (kk != 0) & ~nyq
    # Q_jk: Â_k = Σ_j Q_jk D_jk
    Q = np.zeros((n, nheads), dtype=complex)
    Q[seen] = ((np.conj(Hs[seen]) * W[seen]) @ P) / den[seen, None]
    return _System(kk, nyq, G, P, Hs, w, W, set_on_grid, mixed, grid_sees, den, seen, Q)


def _per_set_estimates(D: np.ndarray, sy: _System, names: list[str], tol: float) -> dict[str, np.ndarray]:
    """Each set's own estimate of a (eq. 9 alone; the harmonics it cannot see set to 0)."""
    n = D.shape[0]
    per_set = {}
    for s, name in enumerate(names):
        M = D @ sy.P[s]
        ok = (np.abs(sy.Hs[:, s]) > tol) & (sy.kk != 0) & ~sy.nyq
        As = np.zeros(n, dtype=complex)
        As[ok] = M[ok] / sy.Hs[ok, s]
        per_set[name] = np.real(np.fft.ifft(As))
    return per_set


@dataclass(frozen=True)
class _Residuals:
    """The fit's residuals: σ(δ) with its effective dof, RMS per set and over the heads used, and
    the per-harmonic pieces the interpolation error (:func:`_interpolation_u`) reuses."""

    sigma: float
    dof: float
    set_rms: dict[str, float]
    head_rms: float
    live: np.ndarray
    on_l: np.ndarray
    keep: np.ndarray
    Hl: np.ndarray
    qk: np.ndarray
    Rres: np.ndarray
    Rk: np.ndarray


def _residuals(d: np.ndarray, D: np.ndarray, A: np.ndarray, sy: _System, names: list[str], tol: float) -> _Residuals:
    """σ(δ) from the residuals of what the estimate is fitted to, the set averages (eq. 9).

    A set average of equally spaced heads cancels the axis' radial error motion, which a single
    head's δ does not (module docstring); for the default one-head sets this is the per-head residual.
    res_set (time domain, all harmonics) is reported per set as a diagnostic. In the Fourier domain,
    per harmonic k: residuals r_k = R_k·M_k, R_k = I − H_k q_kᵀ (q_k the set weights of Â_k); with
    unit noise per δ the set averages have covariance Σ = P Pᵀ (head 1: δ ≡ 0), so E[Σ_s |r_ks|²/c_s] ∝
    tr(R_k Σ R_kᴴ C⁻¹): summed over k, the effective residual dof (n·sets − parameters for plain
    weighted least squares; exact also where off-grid sets are set aside). k = 0 (the heads' constant
    offsets) and the Nyquist bin are not noise-only and are left out.
    """
    n = d.shape[0]
    P, Hs, W, den, seen = sy.P, sy.Hs, sy.W, sy.den, sy.seen
    # residuals of the heads used (per head: also shows errors that are not a property of the disk)
    used = np.flatnonzero(P.sum(axis=0) > 0)
    used = used[used > 0]
    pred = np.real(np.fft.ifft(A[:, None] * sy.G[:, used], axis=0))
    res = d[:, used] - pred
    res_set = d @ P.T - np.real(np.fft.ifft(A[:, None] * Hs, axis=0))
    c_set = np.sum(P[:, 1:] ** 2, axis=1)
    live = c_set > 0
    Msk = (D @ P.T)[:, live]
    Hl, Wl, cl = Hs[:, live], W[:, live], c_set[live]
    qk = np.zeros_like(Hl)
    qk[seen] = np.conj(Hl[seen]) * Wl[seen] / den[seen, None]
    Rres = Msk - Hl * np.sum(qk * Msk, axis=1, keepdims=True)
    # Only where a set sees the harmonic (|H_sk| > tol): where it does not, eq. 9 makes no claim about
    # its average — which there still carries what is not a property of the disk (head 1's share of
    # the axis motion, grid aliasing) without affecting the estimate.
    # With on-grid and off-grid sets mixed, σ comes from the on-grid sets (exact for samples); the
    # off-grid sets' excess scatter is their interpolation (aliasing) error, see _interpolation_u.
    keep = (sy.kk != 0) & ~sy.nyq
    on_l = sy.set_on_grid[live]
    vis = (np.abs(Hl) > tol) & keep[:, None]
    vis_sig = vis & (on_l[None, :] if sy.mixed else True)
    rss = float(np.sum(np.abs(Rres) ** 2 * vis_sig / cl) / n)
    Sig = P[live][:, 1:] @ P[live][:, 1:].T
    Rk = np.eye(int(live.sum()))[None] - Hl[:, :, None] * qk[:, None, :]
    e_ka = np.einsum("kab,bc,kac->ka", Rk, Sig, np.conj(Rk)).real / cl[None, :]
    dof = float(np.sum(e_ka * vis_sig))
    # no redundancy (e.g. one set of NH heads: eq. 9 fits its average exactly) leaves dof and rss at
    # rounding level (1e-31 on the twin's null_b), whose ratio is noise of the BLAS kernel, not a σ
    if dof <= 1e-6 * n:
        dof = 0.0
    sigma = float(np.sqrt(rss / dof)) if dof > 0 else float("nan")
    set_rms = {name: float(np.sqrt(np.mean(res_set[:, s_] ** 2))) for s_, name in enumerate(names)}
    head_rms = float(np.sqrt(np.mean(res**2))) if res.size else float("nan")
    return _Residuals(sigma, dof, set_rms, head_rms, live, on_l, keep, Hl, qk, Rres, Rk)


def _propagated_var(sy: _System, u2: np.ndarray | None, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """var(â(θ_m)) = Σ_j Σ_t h_j[m − t]² u2_j[t] (circular convolution of each head's impulse
    response with its reading variance; σ² where u(δ) was not given), and that variance (n × heads)."""
    n, nheads = sy.Q.shape
    h = np.real(np.fft.ifft(sy.Q, axis=0))  # (n, nheads)
    if u2 is None:
        u2 = np.full((n, nheads), sigma**2)
    u2 = u2.copy()
    u2[:, 0] = 0.0
    var = np.real(np.fft.ifft(np.fft.fft(h**2, axis=0) * np.fft.fft(u2, axis=0), axis=0)).sum(axis=1)
    return var, u2


def _interpolation_u(sy: _System, r: _Residuals, u2: np.ndarray, tol: float) -> float:
    """Interpolation error of off-grid sets (mixed case; 0 otherwise).

    Where on-grid sets carry a harmonic, an off-grid set's residual M_sk − H_sk·Â_k is its own error
    X_sk plus noise; the mean excess over the noise estimates E|X_s|² per harmonic, which enters Â
    wherever only off-grid sets see the harmonic. Treated as independent between harmonics (aliased
    content of different orders): a variance (1/n²)·Σ_k Σ_s |q_sk|²·E|X_s|², the same at every θ.
    """
    if not sy.mixed:
        return 0.0
    n = u2.shape[0]
    P, live = sy.P, r.live
    var_abs = u2.mean(axis=0)
    Sig_u = (P[live] * var_abs) @ P[live].T
    noise_ka = n * np.einsum("kab,bc,kac->ka", r.Rk, Sig_u, np.conj(r.Rk)).real
    X = np.zeros(int(live.sum()))
    for a in np.flatnonzero(~r.on_l):
        sel = sy.grid_sees & r.keep & (np.abs(r.Hl[:, a]) > tol)
        if sel.any():
            X[a] = max(0.0, float(np.mean(np.abs(r.Rres[sel, a]) ** 2 - noise_ka[sel, a])))
    only_off = sy.seen & ~sy.grid_sees
    return float(np.sqrt(np.sum(np.abs(r.qk[only_off]) ** 2 * X[None, :]) / n**2))


def selfcal_fourier(theta_deg: np.ndarray, heads_deg: Sequence[float], delta_arcsec: np.ndarray, *,
                    sets: Mapping[str, Sequence[int]] | None = None,
                    u_delta_arcsec: np.ndarray | float | None = None, tol: float = 1e-6,
                    prefer_on_grid: bool = True) -> SelfCalResult:
    """Self-calibration for any head arrangement in the Fourier domain; combine sets by weighted LS.

    ``theta_deg`` (n,) an equally spaced full-circle grid (any order, any start); ``heads_deg`` the
    azimuths from head 1 (``heads_deg[0] == 0``); ``delta_arcsec`` (n, n_heads) eq. 8's δ per head.
    ``sets``: name → 1-based head numbers averaged as in eq. 9 (e.g. :data:`SELFA_SETS`); default: every
    head j ≥ 2 on its own (head-level least squares, the most information). ``u_delta_arcsec``: standard
    uncertainty of each δ reading (scalar or (n, n_heads)); default: pooled from the residuals.
    ``tol``: a harmonic counts as seen by a set when |H_sk| > tol (combined: Σ_s w_s|H_sk|² > tol²·Σ_s w_s).

    ``prefer_on_grid``: a set whose heads all sit on the θ grid (ψ_j a multiple of the step) obeys
    eq. 8 exactly for the SAMPLES of a, whatever a contains above the grid's Nyquist harmonic: its
    shift is a whole number of samples. A set with a head between grid points relies on trigonometric
    interpolation, exact only for band-limited a; a graduation error with harmonics above n/2 folds
    into it (the twin's hsieh2022 encoder: 0.13″ rms above harmonic 180 on a 1° grid, which put up to
    0.1″ into the combined estimate). So, per harmonic, only on-grid sets are used where one of them
    sees it; off-grid sets fill in the rest (for SelfA on a 1° grid: the 7-head set supplies the
    multiples of 12). ``False``: all sets by weighted least squares at every harmonic.

    Zero noise (``u_delta_arcsec`` all 0, exact data): equal weights per head.

    Stages: :func:`_checked_deltas`, :func:`_set_matrix`, :func:`_head_variances`, :func:`_system`,
    the estimate Â = Σ_j Q_j D_j, :func:`_per_set_estimates`, :func:`_residuals`,
    :func:`_propagated_var`, :func:`_interpolation_u`.
    """
    psi_deg, ths, order, d = _checked_deltas(theta_deg, heads_deg, delta_arcsec)
    n, nheads = d.shape
    names, P = _set_matrix(sets, nheads)
    var_head, u2 = _head_variances(u_delta_arcsec, order, nheads)
    sy = _system(n, psi_deg, P, var_head, tol, prefer_on_grid)
    D = np.fft.fft(d, axis=0)
    A = np.sum(sy.Q * D, axis=1)
    value = np.real(np.fft.ifft(A))
    per_set = _per_set_estimates(D, sy, names, tol)
    r = _residuals(d, D, A, sy, names, tol)
    var, u2 = _propagated_var(sy, u2, r.sigma)
    u_model = _interpolation_u(sy, r, u2, tol)
    if sy.mixed:
        var = var + u_model**2
    u = np.sqrt(np.maximum(var, 0.0))
    kpos = np.arange(0, n // 2 + 1)
    H_out = {name: sy.Hs[kpos, s] for s, name in enumerate(names)}
    inv_k = kpos[1:][~sy.seen[1:n // 2 + 1]]
    if n % 2 == 0:
        inv_k = inv_k[inv_k < n // 2]  # the Nyquist bin is never estimated; not listed
    by_set = {name: invisible_harmonics(psi_deg[np.flatnonzero(P[s])], max(n // 2 - 1, 1)) for s, name in enumerate(names)}
    notes = []
    if inv_k.size:
        notes.append(f"harmonics not observable by the heads used (set to 0): {inv_k.tolist()}")
    return SelfCalResult(ths, value, u, per_set, kpos, H_out, inv_k, by_set, r.sigma, r.dof, r.head_rms, notes,
                         r.set_rms, {name: bool(sy.set_on_grid[s_]) for s_, name in enumerate(names)}, u_model)


def tabulate_heads(theta_deg: np.ndarray, head: np.ndarray, delta_arcsec: np.ndarray, n_heads: int, *,
                   rep: np.ndarray | None = None, direction: np.ndarray | None = None, decimals: int = 9
                   ) -> dict[str, np.ndarray]:
    """Arrange the heads table (θ, head, δ) into ``delta`` (n, n_heads); average repetitions.

    Head 1 may be absent (δ ≡ 0). Returns ``theta_deg``, ``delta_arcsec``, ``sd_arcsec`` (sample sd of
    repetitions, NaN with < 2), ``n_rep``. Raises ValueError naming rows (0-based) for NaN, a head outside
    1…n_heads, duplicates without ``rep``/``direction``, and missing (θ, head) cells.
    """
    th = np.asarray(theta_deg, dtype=float).ravel()
    hd = np.asarray(head).ravel()
    dl = np.asarray(delta_arcsec, dtype=float).ravel()
    if not (th.size == hd.size == dl.size):
        raise ValueError(f"columns of different lengths: theta_deg {th.size}, head {hd.size}, delta_arcsec {dl.size}")
    for name, v in (("theta_deg", th), ("head", hd.astype(float)), ("delta_arcsec", dl)):
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise ValueError(f"rows {bad[:10].tolist()}, column {name!r}: not a finite number")
    hf = hd.astype(float)
    bad = np.flatnonzero((hf != np.round(hf)) | (hf < 1) | (hf > n_heads))
    if bad.size:
        raise ValueError(f"rows {bad[:10].tolist()}, column 'head': expected an integer in 1…{n_heads}")
    hi = hf.astype(int)
    thk = np.round(np.mod(th, 360.0), decimals)
    extra = [np.asarray(c).ravel() for c in (rep, direction) if c is not None]
    seen: dict[tuple, int] = {}
    for r in range(th.size):
        key = (thk[r], hi[r]) + tuple(c[r] for c in extra)
        if key in seen:
            raise ValueError(f"rows {seen[key]} and {r}, columns theta_deg/head: duplicated reading "
                             f"(theta_deg={thk[r]:g}, head={hi[r]})" + ("" if extra else " without a 'rep' column"))
        seen[key] = r
    uth, inv = np.unique(thk, return_inverse=True)
    n = uth.size
    cnt = np.zeros((n, n_heads), dtype=int)
    sm = np.zeros((n, n_heads))
    np.add.at(cnt, (inv, hi - 1), 1)
    np.add.at(sm, (inv, hi - 1), dl)
    mean = np.where(cnt > 0, sm / np.maximum(cnt, 1), np.nan)
    ss = np.zeros((n, n_heads))
    np.add.at(ss, (inv, hi - 1), (dl - mean[inv, hi - 1]) ** 2)
    sd = np.where(cnt > 1, np.sqrt(ss / np.maximum(cnt - 1, 1)), np.nan)
    if not np.any(cnt[:, 0]):
        mean[:, 0] = 0.0
        cnt[:, 0] = 1
    miss = np.argwhere(cnt == 0)
    if miss.size:
        raise ValueError(f"missing readings (theta_deg, head): {[(float(uth[r]), int(c) + 1) for r, c in miss[:10]]}"
                         + (f" … ({len(miss) - 10} more)" if len(miss) > 10 else ""))
    return {"theta_deg": uth, "delta_arcsec": mean, "sd_arcsec": sd, "n_rep": cnt}
