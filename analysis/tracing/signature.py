"""The residual's signature: harmonic spectrum, drift with time, repetition (synchronous or not),
start face and shift (polygon-related or not: Hsieh et al. 2022 eq. 3), direction (hysteresis),
the self-calibration (Hsieh eqs. 8–9: sees the encoder's own errors, not the reference chain's),
correlation with the radial motion and with each of the Jia et al. 2019 model's own terms.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..distributions import chi2_isf, chi2_sf, f_sf, norm_isf, t_sf
from ..fourier import evaluate_harmonics, fit_harmonics
from ._blas import _one_blas_thread
from .evidence import Evidence, column
from .problem import _Problem, _center, _rms, _z_from_chi2, chi2_scale
from .significance import _nested, _one_column, harmonic_test
from .thresholds import DBIC_GATE, P_SIG, SIZE_GATE, Z_GATE


# ----------------------------------------------------------------------------------------------
# 2. signature
# ----------------------------------------------------------------------------------------------

def _free_of_theta(pb: _Problem, col: np.ndarray) -> np.ndarray:
    """The closure-centred column with every function of the stop position θ removed (weighted)."""
    ev = pb.ev
    w2 = pb.w[: ev.n] ** 2
    x = _center(col, column(ev.closure_group), w2)
    D = _theta_dummies(pb)
    sw = np.sqrt(w2)
    beta, *_ = np.linalg.lstsq(D * sw[:, None], x * sw, rcond=None)
    out = x - D @ beta
    return np.where(np.abs(out) > 1e-9 * (np.max(np.abs(x)) + 1e-300), out, 0.0)


def _theta_dummies(pb: _Problem) -> np.ndarray:
    """One closure-centred indicator column per stop position (every function of θ), weighted."""
    ev = pb.ev
    return _center(_dummies(ev.theta_bin), column(ev.closure_group), pb.w[: ev.n] ** 2)


def _dummies(keys: np.ndarray) -> np.ndarray:
    inv = np.unique(keys, return_inverse=True)[1]
    X = np.zeros((keys.size, inv.max() + 1))
    X[np.arange(keys.size), inv] = 1.0
    return X


#: fewest closure groups (sweeps) whose own harmonic fits make the between-sweep test of
#: :func:`_time_pattern` (a regression of each coefficient on time with G − 2 dof; 5 → 3 dof)
MIN_TIME_GROUPS = 5


def _time_pattern(pb: _Problem, ks: list[int]) -> dict:
    """Is the θ pattern stationary? A significant change of amplitude or phase of harmonics ``ks``
    during the session (thermal growth, wear) is not an effect fixed to the disk, the motion or the
    reference.

    The unit of the test is the closure group (one sweep of the polygon, one mounting) whenever
    there are ≥ ``MIN_TIME_GROUPS`` of them, each with enough readings to fit ``ks`` itself: the
    asynchronous (non-repeating) motion of a ball-bearing shaft is not white from reading to
    reading. Its components at non-integer orders (outer-race lobes at q·Z·ρ cycles/rev, 4.81 for
    jia2019's bearings; inner-race lobes at q·Z·(1 − ρ) ± 1; the balls at ρ) look like harmonics
    of θ within one sweep, with a phase that jumps from sweep to sweep (docs/physics.md, "Why the
    default run's θ pattern looked non-stationary"). Tested reading by reading, a beat of that
    kind projects onto "harmonic × time" far beyond the per-reading noise (z ≈ 10 on the default
    jia2019 run, where the true α itself has it). So each sweep's own harmonic coefficients are
    regressed on its mean reading time and each slope is compared with the scatter of that
    coefficient between sweeps (t-test, G − 2 dof): the asynchronous motion enters as the noise
    it is, with the size the data show, and a real drift of the pattern (smooth in time,
    coherent over sweeps) still stands out. Designs with fewer sweeps (one start face, one rep)
    keep the reading-by-reading nested test (harmonics × (t − t̄)/T)."""
    ev = pb.ev
    ks = [int(k) for k in ks if 1 <= int(k) <= ev.kmax]
    if not ks:
        return {"available": False, "reason": "no harmonic to follow in time"}
    t = np.asarray(ev.t_s, dtype=float)
    T = float(np.ptp(t))
    if not np.all(np.isfinite(t)) or T <= 0:
        return {"available": False, "reason": "no reading times"}
    between = _time_pattern_between_groups(pb, ks, t, T)
    if between is not None:
        return between
    th = np.deg2rad(ev.theta_deg)
    tt = (t - t.mean()) / T
    H = np.column_stack([f(k * th) for k in ks for f in (np.sin, np.cos)])
    # nested over EVERY function of the stop position (one value per position, as the drift test):
    # a change with time is seen only where a position is read at different times. Nested over
    # the harmonics ``ks`` alone, a stationary order k' outside them reads, sweep by sweep, as order
    # k' − m·N with a phase that turns with the shift S, and the shifts are swept in time order: a
    # "change with time" of a pattern fixed to θ. On the twin's base benches (shifts 0…14°, one
    # start face per shift, 1 rep) the bearings' −δX/r above order 20 (0.1…0.3″ RMS, truth) did
    # exactly that, at z ≈ 9 for the noise-free true α (loop validation seeds 660-663).
    Xh = _center(H, column(ev.closure_group), pb.w ** 2)
    X0 = _theta_dummies(pb)
    X1 = _center(H * tt[:, None], column(ev.closure_group), pb.w ** 2)
    f0, f1 = pb.fit(X0), pb.fit(np.hstack([X0, X1]))
    d, k = f0["chi2"] - f1["chi2"], f1["k"] - f0["k"]
    if k <= 0:
        return {"available": False, "reason": "no stop position read at different times: a change of the pattern "
                                              "with time cannot be told from a θ pattern"}
    scale = chi2_scale(f1)
    z = _z_from_chi2(d / scale, k)
    beta = f1["beta"]
    n0 = X0.shape[1]
    slope = [float(math.hypot(beta[n0 + 2 * i], beta[n0 + 2 * i + 1])) for i in range(len(ks))]
    bh = pb.fit(Xh)["beta"]
    amp0 = [float(math.hypot(bh[2 * i], bh[2 * i + 1])) for i in range(len(ks))]
    # the size of the pattern's change: RMS over the readings of the fitted harmonics × (t − t̄)/T
    # part beyond every function of θ (what the revisits see). The removal of θ is a linear
    # projection, so the fitted combination is projected once (column by column, it was 21 of the
    # hsieh2022 default's 96 s of analysis: one SVD of the stop-position dummies per column)
    x1 = _free_of_theta(pb, X1 @ np.asarray(beta[n0:n0 + 2 * len(ks)]))
    rms = float(np.sqrt(np.mean(x1 ** 2)))
    return {"available": True, "test": "harmonics × (t − t̄)/T, nested over every function of θ", "harmonics": ks,
            "amplitude_arcsec": amp0, "change_over_session_arcsec": slope, "rms_arcsec": rms,
            "delta_chi2": float(d), "dof": int(k),
            "z": z, "p_value": float(chi2_sf(d / scale, k)), "significant": bool(z >= Z_GATE)}


def _time_pattern_between_groups(pb: _Problem, ks: list[int], t: np.ndarray, T: float) -> dict | None:
    """The between-sweep form of :func:`_time_pattern`, or None when the design has fewer than
    ``MIN_TIME_GROUPS`` closure groups able to fit ``ks`` (2·len(ks) + 1 parameters, ≥ 1 dof)."""
    ev = pb.ev
    n = ev.n
    y, w = pb.y[:n], pb.w[:n]
    th = np.deg2rad(ev.theta_deg)
    H = np.column_stack([f(k * th) for k in ks for f in (np.sin, np.cos)])
    coef, times = [], []
    for g in np.unique(column(ev.closure_group)):
        m = column(ev.closure_group) == g
        if int(m.sum()) < H.shape[1] + 2:
            continue
        A = np.column_stack([np.ones(int(m.sum())), H[m]]) * w[m, None]
        if np.linalg.matrix_rank(A) < A.shape[1]:
            continue
        beta, *_ = np.linalg.lstsq(A, y[m] * w[m], rcond=None)
        coef.append(beta[1:])
        times.append(float(np.average(t[m], weights=w[m] ** 2)))
    G = len(coef)
    if G < MIN_TIME_GROUPS:
        return None
    o = np.argsort(times, kind="stable")
    C = np.asarray(coef)[o]
    tg = (np.asarray(times)[o] - float(np.mean(times))) / T
    stt = float(tg @ tg)
    if stt <= 0:
        return None
    slope = (tg @ (C - C.mean(axis=0))) / stt
    res = C - C.mean(axis=0) - np.outer(tg, slope)
    nu = G - 2
    # serial correlation of the sweeps' deviations: the cage creeps (its slip accumulates over
    # the moves between sweeps), so consecutive sweeps see nearly the same ball configuration and
    # the asynchronous pattern wanders like a random walk. Lag-1 autocorrelation pooled over the
    # coefficients, ~N(0, 1/(G·2K)) for independent sweeps; flagged at P_SIG (one-sided). Flagged,
    # a curved drift is tested within a local-level model (:func:`_local_level_trend`): a random
    # walk plus each sweep's own scatter, their ratio estimated from all the coefficients together.
    den = float(np.sum(res ** 2))
    r1 = float(np.sum(res[1:] * res[:-1]) / den) if den > 0 else 0.0
    serial = bool(r1 * math.sqrt(res.size) > norm_isf(P_SIG))
    mean = C.mean(axis=0)
    amp0 = [float(math.hypot(mean[2 * i], mean[2 * i + 1])) for i in range(len(ks))]
    if serial:
        trend = _local_level_trend(C, tg)
        if trend is None:
            return None
        fitted, q, k2, s2, walk_share = trend
        nu = G - 3
        # the change over the session: the fitted curve from the first sweep to the last
        slope = fitted[-1] - fitted[0]
        # the size of the pattern's change: RMS over the sweeps of the fitted curve (centred), the
        # sin/cos pairs orthogonal on a sweep's grid (½ per coefficient²)
        rms = float(math.sqrt(float(np.mean(np.sum((fitted - fitted.mean(axis=0)) ** 2, axis=1))) / 2.0))
    else:
        s2 = np.sum(res ** 2, axis=0) / nu
        u = np.sqrt(np.where(s2 > 0, s2, np.inf) / stt)
        tstat = np.abs(slope) / u
        # each two-sided t-test as its χ²₁ equivalent; the coefficients of distinct harmonics are
        # orthogonal on the sweep's grid, so their sum is χ² with 2·len(ks) dof under stationarity
        p = np.clip(2.0 * t_sf(tstat, nu), 1e-300, 1.0)
        q = float(np.sum(chi2_isf(p, 1)))
        k2 = int(C.shape[1])
        # the size of the pattern's change: RMS over the sweeps of slope·(t − t̄)/T, the sin/cos pairs
        # orthogonal on a sweep's grid (½ per coefficient²)
        rms = float(math.sqrt(float(np.mean(tg ** 2)) * float(np.sum(np.asarray(slope) ** 2)) / 2.0))
    z = _z_from_chi2(q, k2)
    change = [float(math.hypot(slope[2 * i], slope[2 * i + 1])) for i in range(len(ks))]
    scatter = [float(math.sqrt((s2[2 * i] + s2[2 * i + 1]) / 2.0)) for i in range(len(ks))]
    out = {"available": True,
            "test": ("each sweep's harmonics: a curved drift (τ, τ²) within a random walk plus the sweeps' own scatter"
                     if serial else "each sweep's harmonics regressed on its time, against their scatter between sweeps"),
            "harmonics": ks, "n_sweeps": G, "dof_per_coefficient": nu,
            "serial_correlation": r1, "random_walk": serial,
            "amplitude_arcsec": amp0, "change_over_session_arcsec": change, "rms_arcsec": rms,
            "between_sweep_sd_arcsec": scatter, "chi2_equivalent": q, "dof": k2,
            "z": z, "p_value": float(chi2_sf(q, k2)), "significant": bool(z >= Z_GATE)}
    if serial:
        out["walk_share"] = walk_share
    return out


#: the walk's share ρ of the sweeps' noise tried by :func:`_local_level_trend` (0: independent
#: sweeps; 1: a pure random walk; between, walk variance ρ/(1 − ρ) × a sweep's own), a fixed grid
#: so that the choice cannot turn on rounding
_WALK_TO_SCATTER = np.logspace(-3.0, 3.0, 61)     # the walk's variance per step ÷ a sweep's own
WALK_SHARES = np.concatenate([[0.0], _WALK_TO_SCATTER / (1.0 + _WALK_TO_SCATTER), [1.0]])


def _local_level_trend(C: np.ndarray, tg: np.ndarray) -> tuple[np.ndarray, float, int, np.ndarray, float] | None:
    """A curved drift of each coefficient over the session, tested within a local-level model.

    Sweep g reads C_g = m(τ_g) + μ_g + ε_g: a drift m(τ) = b·τ + c·τ² (τ = (t − t̄)/T; a warm-up
    is curved), a level μ that walks (μ_g − μ_(g−1) = η_g, Var η_g ∝ Δτ_g: the cage's slip
    accumulates with the moves) and the sweep's own scatter ε_g: the "random walk plus noise" of
    Harvey 1989, *Forecasting, Structural Time Series Models and the Kalman Filter*, with a
    deterministic trend. On first differences, which remove the level: D = b·Δτ + c·Δ(τ²) + η + Δε,
    covariance σ²·[(1 − ρ)·K + ρ·diag(Δτ/mean Δτ)], K the tridiagonal (2, −1) of a differenced
    white noise; ρ = 0 is independent sweeps, ρ = 1 a pure random walk.

    Why this form (docs/loop-validation.md, "A warm-up read as a random walk"): a straight line
    leaves a warm-up's curvature in the sweeps' deviations, where it looks serial; tested as a pure
    random walk with drift (first differences) a smooth 1″ change was then only its mean increment
    (z 0.8, thermal_growth missed), and a curve tested against independent sweeps takes the slow
    part of a real walk for a drift (z 7.6 on the jia2019 default). Within this model a walk is
    noise of the size its increments show, and a curvature is a trend of the increments, which a
    walk's independent increments do not have. ρ comes from the restricted likelihood of all the
    coefficients together (each its own σ²): the walk is one process, the cage's, and a warm-up
    that bends one harmonic is not rough in the others. (Each coefficient's own ρ took a 0.5″ cage
    walk for a drift at z 3.6–3.8 in tests/analysis/test_time_pattern.py's synthetic sweeps; a
    cubic drift, at z 6.2.) ρ is taken at the upper end of its 95 % profile interval, the
    conservative side: the F-tests do not carry ρ's own uncertainty, and at the point estimate
    they were anti-conservative (Monte Carlo, below).

    Returns (the fitted drift per sweep and coefficient, G × m; Σ over the coefficients of each
    F-test of (b, c) as its χ²₂ equivalent; its dof 2m; each coefficient's sweep-to-sweep scatter,
    half an increment's variance; ρ), or None without time spread."""
    D, dt = np.diff(C, axis=0), np.diff(tg)
    n = D.shape[0]
    p = 2
    if n < p + 2 or np.any(dt <= 0):
        return None
    K = 2.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    W = np.diag(dt / float(np.mean(dt)))
    X = np.column_stack([dt, np.diff(tg ** 2)])

    def gls(rho: float):
        L = np.linalg.cholesky((1.0 - rho) * K + rho * W)
        Xw, Dw = np.linalg.solve(L, X), np.linalg.solve(L, D)
        A = Xw.T @ Xw
        B = np.linalg.solve(A, Xw.T @ Dw)
        s2 = np.sum((Dw - Xw @ B) ** 2, axis=0) / (n - p)
        # restricted log-likelihood summed over the coefficients (constants dropped)
        ll = float(-0.5 * np.sum((n - p) * np.log(np.where(s2 > 0, s2, 1e-300)) + 2.0 * np.sum(np.log(np.diag(L)))
                                 + np.linalg.slogdet(A)[1]))
        return ll, B, A, s2

    fits = [gls(float(rho)) for rho in WALK_SHARES]
    ll = np.array([f[0] for f in fits])
    # the largest ρ inside its 95 % profile interval (restricted log-likelihood within χ²₁(0.95)/2
    # of its maximum), not the maximum itself: with ρ at its point estimate, 1500 null series per
    # ρ = 0.3…1 (23 sweeps, 6 or 16 coefficients, serial ones only) went to z ≥ 4 in 0.1–1.5 % of
    # them, a slow stretch of the walk read as a drift; at the interval's upper end, in none
    best = int(np.nonzero(ll >= ll.max() - 0.5 * float(chi2_isf(0.05, 1)))[0].max())
    _, B, A, s2 = fits[best]
    rho = float(WALK_SHARES[best])
    F = np.einsum("ij,ik,kj->j", B, A, B) / p / np.where(s2 > 0, s2, np.inf)
    pv = np.clip(f_sf(F, p, n - p), 1e-300, 1.0)
    q = float(np.sum(chi2_isf(pv, p)))
    fitted = np.column_stack([tg, tg ** 2]) @ B
    return fitted, q, p * C.shape[1], s2 * (1.0 - rho / 2.0), rho


@_one_blas_thread
def signature(ev: Evidence, harmonics: list[dict] | None = None, time_ks: list[int] | None = None) -> dict:
    """The residual's signature (JSON-ready): see the module docstring, step 2. ``time_ks``: the
    harmonics whose stationarity is tested (default: this residual's significant harmonics)."""
    pb = _Problem(ev, use_selfcal=False)
    harmonics = harmonics if harmonics is not None else harmonic_test(ev, pb)
    sig: dict[str, Any] = {"harmonics": harmonics,
                           "significant_harmonics": [h["k"] for h in harmonics if h["significant"]]}
    sig["time_pattern"] = _time_pattern(pb, sig["significant_harmonics"] if time_ks is None else time_ks)
    # drift: only the part of the reading time that is not a function of θ can show it (a forward
    # sweep's time is a θ sawtooth that any encoder error of that shape fits as well)
    d = _one_column(pb, _free_of_theta(pb, np.asarray(ev.t_s, dtype=float)), "t_s (beyond any θ pattern)")
    sig["drift"] = {"slope_arcsec_per_s": d.get("gain"), "u": d.get("u"), "z": d.get("z"),
                    "rms_arcsec": d.get("rms_arcsec"),
                    "significant": d.get("significant", False), "available": d["available"],
                    "test": "reading time beyond any function of θ"}
    if not d["available"]:
        sig["drift"]["reason"] = "the reading order follows θ in every run: a drift cannot be told from a θ pattern"
    # repetition: synchronous (same at the same θ in every rep) or not
    if np.unique(column(ev.rep)).size >= 2:
        cell = ev.theta_bin * 10 + ev.approach
        inv = np.unique(cell, return_inverse=True)[1]
        w2 = pb.w ** 2
        m = np.bincount(inv, weights=w2 * pb.y) / np.bincount(inv, weights=w2)
        dev = pb.y - m[inv]
        chi2 = float(np.sum(w2 * dev ** 2))
        dof = max(ev.n - inv.max() - 1, 1)
        p = float(chi2_sf(chi2, dof))
        sig["repetition"] = {"available": True, "n_reps": int(np.unique(column(ev.rep)).size), "synchronous_rms_arcsec": _rms(m[inv]),
                             "asynchronous_rms_arcsec": _rms(dev), "chi2_async": chi2, "dof": int(dof), "p_value": p,
                             "synchronous": bool(p >= P_SIG)}
    else:
        sig["repetition"] = {"available": False, "reason": "one repetition"}
    # polygon-related: a pattern fixed to the face (moves with the start face)?
    base = _center(_dummies(ev.theta_bin * 10 + ev.approach), column(ev.closure_group), pb.w ** 2)
    if np.unique(column(ev.start_face)).size >= 2:
        fx = _center(_dummies(column(ev.face)), column(ev.closure_group), pb.w ** 2)
        sig["start_face"] = {"test": "face pattern beyond the θ pattern", **_nested(pb, base, fx)}
    else:
        sig["start_face"] = {"available": False, "reason": "one start face: face ≡ θ"}
    # shift: does the θ pattern depend on the shift angle (beyond a function of θ)?
    shifts = np.unique(np.round(column(ev.shift_deg), 6))
    if shifts.size >= 2:
        kk = range(1, max(1, (int(ev.n_faces) - 1) // 2) + 1)
        th = np.deg2rad(ev.theta_deg)
        H = np.column_stack([f(k * th) for k in kk for f in (np.sin, np.cos)])
        Hs = np.column_stack([H * (np.round(column(ev.shift_deg), 6) == s)[:, None] for s in shifts[1:]])
        sig["shift"] = {"test": "harmonics 1…(N−1)/2 differing between shifts",
                        **_nested(pb, _center(H, column(ev.closure_group), pb.w ** 2), _center(Hs, column(ev.closure_group), pb.w ** 2))}
    else:
        sig["shift"] = {"available": False, "reason": "one shift angle"}
    # direction of rotation: of the approach to each stop (a hysteresis follows the last move)
    dd = _one_column(pb, column(ev.approach).astype(float), "direction")
    sig["direction"] = {"half_difference_arcsec": dd.get("gain"), "u": dd.get("u"), "z": dd.get("z"),
                        "rms_arcsec": dd.get("rms_arcsec"),
                        "significant": dd.get("significant", False), "available": dd["available"]}
    # self-calibration
    sig["selfcal"] = _selfcal_signature(ev, pb)
    # correlation with the radial motion and with the model's own terms
    cor = {}
    for name, v in ev.model_terms.items():
        cor[f"term:{name}"] = _one_column(pb, v, name)
    ecc = ev.model_terms.get(ev.eccentricity_term)
    if ecc is not None and np.any(ecc != 0):
        c1 = fit_harmonics(ev.theta_deg, ecc, [1])
        cor["term:eccentricity_quadrature (θ0 error)"] = _one_column(pb, evaluate_harmonics(ev.theta_deg, {1: (c1[1][1], -c1[1][0])}), "q")
    if ev.radial is not None:
        for c in ev.radial.channels:
            cor[f"radial:{c}"] = _one_column(pb, ev.radial.at(ev.theta_deg, c), c)
            cor[f"radial:integral_{c}"] = _one_column(pb, ev.radial.integral_at(ev.theta_deg, c), c)
    sig["correlations"] = cor
    if ev.ccd is not None:
        cc = fit_harmonics(ev.ccd.theta_deg, ev.ccd.d_ref_um, range(1, 11))
        c1, d1 = cc[1]
        higher = evaluate_harmonics(ev.ccd.theta_deg, {k: v for k, v in cc.items() if k >= 2})
        sig["ccd"] = {"e_um": math.hypot(c1, d1), "theta0_deg": math.degrees(math.atan2(c1, d1)) % 360,
                      "rms_orders_2_10_um": _rms(higher)}
    return sig


def _selfcal_signature(ev: Evidence, pb: _Problem) -> dict:
    if ev.selfcal is None:
        return {"available": False, "reason": "no self-calibration curve"}
    full = _Problem(ev, use_selfcal=True)
    m = full.n_rows - ev.n
    r_s = full.y[ev.n:]
    th_s = np.asarray(ev.selfcal.theta_deg, dtype=float) % 360
    o = np.argsort(th_s)
    interp = np.interp(ev.theta_deg % 360, th_s[o], r_s[o], period=360.0)
    one = _one_column(pb, interp, "selfcal")
    return {"available": True, "rms_selfcal_residual_arcsec": _rms(r_s), "n_points": int(m),
            "gain_polygon_on_selfcal": one.get("gain"), "u": one.get("u"),
            "consistent": bool(one.get("available") and one["u"] > 0 and abs(one["gain"] - 1) < 3 * max(one["u"], 0.05)),
            "note": "a residual absent from the self-calibration belongs to the reference chain (polygon, autocollimator, drive)"}


def _significant_parts(sig: dict, n: int, u_rms: float = 0.0) -> list[str]:
    """The parts of a signature that would pass as an effect themselves: a harmonic whose χ²₂ clears
    both candidate gates (z ≥ Z_GATE and ΔBIC = χ² − 2 ln n ≥ DBIC_GATE), a drift or direction
    offset with z ≥ Z_GATE, a significant face pattern. (The Bonferroni flags of the signature are
    laxer: a harmonic can be flagged yet too small for any two-parameter effect to earn its BIC.)
    A harmonic, a drift, a direction offset or a change of the θ pattern with time must also be of
    practical size, as every candidate
    (``SIZE_GATE`` × the noise floor ``u_rms``, RMS over the readings): 1000 readings of a null resolve
    a 0.01″ direction offset at z = 5 (issue 16, hidden null_y_probes) that no calibration states."""
    out = []
    hk = [h["k"] for h in sig["harmonics"]
          if h["significant"] and h["z"] >= Z_GATE and h["chi2"] - 2 * math.log(n) >= DBIC_GATE
          and h["amplitude_arcsec"] / math.sqrt(2.0) >= SIZE_GATE * u_rms]
    if hk:
        out.append(f"harmonics {hk}")
    def big(part: dict) -> bool:
        return bool(part.get("significant")) and float(part.get("rms_arcsec") or math.inf) >= SIZE_GATE * u_rms

    if big(sig["drift"]):
        out.append("drift with time")
    if big(sig["direction"]):
        out.append("direction of rotation")
    if sig["start_face"].get("significant"):
        out.append("pattern fixed to the polygon face")
    tp = sig.get("time_pattern") or {}
    if big(tp):
        out.append(f"the θ pattern changes with time (harmonics {tp['harmonics']}, z = {tp['z']:.1f}): not stationary")
    return out


def _short_signature(sig: dict) -> dict:
    return {"significant_harmonics": sig["significant_harmonics"],
            "top_harmonics": sorted(({"k": h["k"], "amplitude_arcsec": h["amplitude_arcsec"], "z": h["z"]} for h in sig["harmonics"]),
                                    key=lambda h: -h["z"])[:5],
            "drift": sig["drift"], "direction": sig["direction"],
            "repetition_synchronous": sig["repetition"].get("synchronous"),
            "face_pattern": sig["start_face"].get("significant"), "shift_dependent": sig["shift"].get("significant"),
            "time_pattern": sig.get("time_pattern"),
            "selfcal_consistent": sig["selfcal"].get("consistent")}
