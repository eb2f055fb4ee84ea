"""The periodic components a partial arc supports: period, amplitude and phase with u, false alarm.

A stage or a drive is often measured over part of a turn only (a dozen points over a sixth of a
turn). Such an arc carries no harmonics of the turn and no closure (analysis/error_curve.py), but
it can carry the periodic error of the drive: a worm repeats once per worm-wheel tooth (period
360°/z), a gear stage once per tooth of its wheel, a motor once per pole pitch. This module finds
such periods and says what they point to; it claims nothing about the turn.

- **Scan.** A generalised least-squares periodogram (Zechmeister & Kürster 2009, A&A 496, 577,
  with a polynomial trend of degree ``TREND_DEGREE`` fitted jointly instead of a constant):
  at each trial period P the model ``trend(θ) + a sin(2πθ/P) + b cos(2πθ/P)`` (the columns of
  analysis/fourier.py at the non-integer order k = 360°/P) is fitted by weighted least squares, and
  the power is ``z = (χ²_trend − χ²_P)/χ²_trend`` (the "standard" normalisation). Periods from
  the arc length down to 2 × the smallest spacing of the angles (a regular grid: its Nyquist
  period, 2 steps), frequencies oversampled ``OVERSAMPLE`` × the resolution 1/arc, the best peak
  refined by a bounded one-dimensional minimisation of χ².
- **False alarm.** The probability that noise alone gives a peak this high anywhere in the scanned
  band: Baluev 2008 (MNRAS 385, 1279), eq. 6, the alias-free approximation to the Davies upper
  bound, for the standard normalisation with N_H = n − (parameters of the null model) and
  N_K = N_H − 2 (Baluev's Table 1; ``astropy``'s ``fap_baluev`` in the same form): analytic, no
  random numbers. It is a bound from above (conservative) for a band [0, f_max]; the scanned band
  starts at 1/arc, which makes it more so.
- **Significant periods.** A peak with false alarm < ``P_SIG`` is kept, joins the null model, and
  the scan is repeated for the next one (at most ``MAX_PERIODS``, while ``MIN_DOF`` residual
  degrees of freedom remain, the period itself counted as a parameter).
- **Amplitude, phase and u.** The joint non-linear least-squares fit (trend, each period's a, b
  and period): the covariance ``(JᵀWJ)⁻¹`` from its Jacobian, absolute when u is given from outside
  the fit (a ``u_arcsec`` column or the scatter between two directions), else scaled by the
  residual variance χ²/(n − p) (type A, ν = n − p: with a dozen points 2u covers about 91 %, the
  t-distribution's, not 95 %). Amplitude and phase by Jia et al. 2019 eqs. 11-12
  (``A cos(2πθ/P − φ)``, θ from the table's 0°: analysis/fourier.amplitude_phase_ab); u(P) from
  the same covariance.
- **Aliases.** On a regular grid of step h the periods with frequency |m/h ± 1/P| fit the points
  exactly as well: they are listed (``alias_periods_deg``); only a measurement at other angles
  tells them apart.
- **Drive element.** The candidates the dataset's manifest declares (``drive_elements``: a list
  of {``name``, ``period_deg``} or {``name``, ``teeth``}, period 360°/teeth) whose period lies within
  2u(P) of the period found (k = 2); without a declaration the integer counts z with 360°/z within
  2u(P): a worm wheel of z teeth, a gear of z teeth, or z pole pitches of a direct drive per turn.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import gammaln

from .fourier import amplitude_phase_ab, harmonic_columns

__all__ = ["analyze_arc_periods", "fap_baluev", "drive_candidates", "ArcInputError", "P_SIG", "TREND_DEGREE",
           "OVERSAMPLE", "MAX_TRIALS", "MAX_PERIODS", "MIN_DOF"]

#: false alarm below which a period is kept (the significance of error_curve.P_SIG)
P_SIG = 1e-3
#: the trend fitted jointly with every period: a quadratic, as the arc's trend in error_curve (a
#: slope is a scale error, a curvature the start of a low harmonic of the turn)
TREND_DEGREE = 2
#: trial frequencies per resolution element 1/arc (a peak is not missed between grid points)
OVERSAMPLE = 10
#: at most this many trial periods: angles very close together (a repeated point 0.001° apart) would
#: otherwise ask for a band of millions; the shortest period scanned is then raised (and said so)
MAX_TRIALS = 20000
#: at most this many periods are extracted one after the other
MAX_PERIODS = 3
#: residual degrees of freedom left after the last period (its period counted as a parameter)
MIN_DOF = 3
#: matching window of a drive element: |P − P_candidate| ≤ MATCH_K · u(P)
MATCH_K = 2.0
#: integer counts listed at most (beyond, the range is given)
MAX_COUNTS = 12


class ArcInputError(ValueError):
    """A manifest's ``drive_elements`` that cannot be read; the message names the key."""


def _trend_columns(theta: np.ndarray, centre: float, half: float) -> np.ndarray:
    x = (theta - centre) / half
    return np.column_stack([x ** d for d in range(TREND_DEGREE + 1)])


def _wls(A: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, float]:
    beta, *_ = np.linalg.lstsq(A * w[:, None], y * w, rcond=None)
    r = (y - A @ beta) * w
    return beta, float(r @ r)


def _design(theta: np.ndarray, T: np.ndarray, ks: list[float]) -> np.ndarray:
    return np.column_stack([T, harmonic_columns(theta, ks)[0]]) if ks else T


def _chi2(theta, y, w, T, ks: list[float]) -> float:
    return _wls(_design(theta, T, ks), y, w)[1]


def _scan_chi2(theta, y, w, base: np.ndarray, ks: np.ndarray) -> np.ndarray:
    """χ² of ``base`` + one sine/cosine pair at each order in ``ks``, all at once: the pair is projected
    off the (weighted) base columns and the 2×2 normal equations are solved per order (the same least
    squares as :func:`_chi2`, vectorised)."""
    Q, _ = np.linalg.qr(base * w[:, None])
    yw = y * w
    r = yw - Q @ (Q.T @ yw)
    out = np.empty(ks.size)
    for i0 in range(0, ks.size, 2000):
        kk = ks[i0:i0 + 2000]
        X = harmonic_columns(theta, kk)[0] * w[:, None]   # [sin k₁θ, cos k₁θ, sin k₂θ, ...]
        X = X - Q @ (Q.T @ X)
        sn, cs = X[:, 0::2], X[:, 1::2]
        a11, a12, a22 = np.sum(sn * sn, 0), np.sum(sn * cs, 0), np.sum(cs * cs, 0)
        b1, b2 = sn.T @ r, cs.T @ r
        det = a11 * a22 - a12 ** 2
        with np.errstate(divide="ignore", invalid="ignore"):
            red = np.where(det > 1e-12 * np.maximum(a11 * a22, 1e-300),
                           (a22 * b1 ** 2 - 2 * a12 * b1 * b2 + a11 * b2 ** 2) / det, 0.0)
        out[i0:i0 + kk.size] = float(r @ r) - red
    return out


def _weighted_var(theta: np.ndarray, w: np.ndarray) -> float:
    p = w ** 2 / np.sum(w ** 2)
    m = float(p @ theta)
    return float(p @ (theta - m) ** 2)


def fap_baluev(z: float, f_max: float, theta_deg: np.ndarray, w: np.ndarray, n_h: int) -> float:
    """False-alarm probability of a peak of standard-normalised power ``z`` anywhere in the band
    [0, ``f_max``] (cycles per degree): Baluev 2008 eq. 6 (alias-free approximation of the Davies
    bound, eq. 5), Table 1's standard normalisation, ``n_h`` = N − parameters of the null model,
    N_K = n_h − 2; T_eff = √(4π·Var_w(θ)) with weights w² (``w`` = 1/u)."""
    z = float(min(max(z, 0.0), 1.0))
    n_k = n_h - 2
    fap_single = (1.0 - z) ** (0.5 * n_k)
    gamma = math.sqrt(2.0 / n_h) * math.exp(gammaln(n_h / 2.0) - gammaln((n_h - 1) / 2.0))
    W = f_max * math.sqrt(4.0 * math.pi * _weighted_var(np.asarray(theta_deg, float), np.asarray(w, float)))
    tau = gamma * W * (1.0 - z) ** (0.5 * (n_k - 1)) * math.sqrt(0.5 * n_h * z)
    return float(min(1.0, -math.expm1(-tau) + fap_single * math.exp(-tau)))


def _read_candidates(declared: Any) -> list[dict[str, Any]]:
    if declared is None:
        return []
    where = "manifest.json: key"
    if not isinstance(declared, list):
        raise ArcInputError(f"{where} 'drive_elements': expected a list of {{name, period_deg}} or {{name, teeth}} "
                            "objects")
    out = []
    for i, c in enumerate(declared):
        at = f"drive_elements[{i}]"
        if not isinstance(c, dict) or not isinstance(c.get("name"), str) or not c["name"]:
            raise ArcInputError(f"{where} '{at}': expected an object with a non-empty string 'name'")
        if ("period_deg" in c) == ("teeth" in c):
            raise ArcInputError(f"{where} '{at}': expected exactly one of 'period_deg' (a number > 0) or 'teeth' "
                                "(an integer > 0)")
        if "teeth" in c:
            t = c["teeth"]
            if isinstance(t, bool) or not isinstance(t, int) or t <= 0:
                raise ArcInputError(f"{where} '{at}.teeth': expected an integer > 0, got {t!r}")
            out.append({"name": c["name"], "period_deg": 360.0 / t, "teeth": t})
        else:
            p = c["period_deg"]
            if isinstance(p, bool) or not isinstance(p, (int, float)) or not math.isfinite(p) or p <= 0:
                raise ArcInputError(f"{where} '{at}.period_deg': expected a finite number > 0, got {p!r}")
            out.append({"name": c["name"], "period_deg": float(p)})
    return out


def drive_candidates(period_deg: float, u_period_deg: float, declared: list[dict[str, Any]] | None) -> dict[str, Any]:
    """What a period points to: the declared candidates within MATCH_K·u(P), else the integer counts
    z per turn with 360°/z within MATCH_K·u(P)."""
    lo, hi = period_deg - MATCH_K * u_period_deg, period_deg + MATCH_K * u_period_deg
    within = f"|P − P_candidate| ≤ {MATCH_K:g}·u(P) ({lo:.4g}° … {hi:.4g}°)"
    if declared:
        m = [{**c, "z": abs(period_deg - c["period_deg"]) / u_period_deg if u_period_deg > 0 else math.inf}
             for c in declared if lo <= c["period_deg"] <= hi]
        return {"source": "manifest (drive_elements)", "within": within, "matches": m,
                "note": ("matches the declared " + ", ".join(c["name"] for c in m)) if m else
                        "no declared drive element has this period"}
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= 0:
        return {"source": "integer counts per turn", "within": within, "matches": [], "counts": [],
                "note": "the period is not determined well enough to point to a count"}
    z_lo = max(1, math.ceil(360.0 / hi - 1e-9))
    z_hi = math.floor(360.0 / lo + 1e-9) if lo > 0 else None
    counts = list(range(z_lo, z_hi + 1)) if z_hi is not None and z_hi - z_lo < MAX_COUNTS else []
    if counts:
        note = (f"360°/z for z = {', '.join(map(str, counts))}: a worm wheel of z teeth (one worm turn per tooth), "
                "a gear of z teeth, or z pole pitches of a direct drive per turn")
    elif z_hi is None:
        note = f"any count z ≥ {z_lo}: the period is not determined well enough"
    else:
        note = f"any count z from {z_lo} to {z_hi}: the period is not determined well enough to single one out"
    return {"source": "integer counts per turn", "within": within, "matches": [
        {"name": f"z = {z} per turn", "period_deg": 360.0 / z, "teeth": z} for z in counts],
        "counts": counts, "note": note}


def _aliases(period_deg: float, step_deg: float, regular: bool) -> list[float]:
    if not regular:
        return []
    f, fs = 1.0 / period_deg, 1.0 / step_deg
    out = {abs(m * fs + s * f) for m in (1, 2) for s in (-1.0, 1.0)}
    return sorted((1.0 / a for a in out if a > 1e-12 and abs(a - f) > 1e-9 * f), reverse=True)


def _joint_fit(theta, y, w, T, ks: list[float], u_given: bool) -> dict[str, Any]:
    """Trend, a and b of each period, and each order k = 360°/P: the non-linear least squares at its
    optimum (linear parameters solved exactly at the given orders); covariance from the Jacobian."""
    A = _design(theta, T, ks)
    beta, chi2 = _wls(A, y, w)
    nt = T.shape[1]
    th_rad = np.deg2rad(theta)
    dcols = []
    for i, k in enumerate(ks):
        a, b = beta[nt + 2 * i], beta[nt + 2 * i + 1]
        s_, c_ = harmonic_columns(theta, [k])[0].T
        dcols.append(th_rad * (a * c_ - b * s_))   # ∂/∂k of a sin kθ + b cos kθ
    J = np.column_stack([A] + dcols) if dcols else A
    p = J.shape[1]
    dof = theta.size - p
    inv = np.linalg.pinv((J * w[:, None]).T @ (J * w[:, None]))
    scale = 1.0 if u_given else chi2 / dof
    return {"beta": beta, "cov": inv * scale, "chi2": chi2, "dof": dof, "n_trend": nt, "scale": scale}


def _scan_header(n: int, arc: float, u_given: bool) -> dict[str, Any]:
    """The scan's description (method, false-alarm method, trend degree, points, arc, u source)."""
    return {
        "method": (f"generalised least-squares periodogram (Zechmeister & Kürster 2009) with a degree-{TREND_DEGREE} "
                   "trend fitted jointly; power (χ²_null − χ²_P)/χ²_null"),
        "false_alarm_method": ("analytic: Baluev 2008 eq. 6 (alias-free approximation of the Davies upper bound), "
                               "standard normalisation, band [0, f_max]"),
        "trend_degree": TREND_DEGREE, "n_points": int(n), "arc_deg": arc, "significance": P_SIG,
        "u_source": "given (weights and absolute covariance)" if u_given else
                    "none: unit weights, covariance scaled by the residual (type A)",
        "periods_found": 0}


def _frequency_grid(steps: np.ndarray, arc: float, scan: dict[str, Any]) -> tuple[np.ndarray, float, float, bool]:
    """The trial frequencies (1/deg) from one period over the arc to the closest angles' Nyquist
    (at most MAX_TRIALS, OVERSAMPLE per 1/arc): (grid, spacing, f_max, regular θ grid); notes in ``scan``."""
    step_min = float(np.min(steps))
    regular = bool(np.ptp(steps) <= 1e-6 * float(np.median(steps)))
    f_min, f_max = 1.0 / arc, 1.0 / (2.0 * step_min)
    df = 1.0 / (OVERSAMPLE * arc)
    if (f_max - f_min) / df > MAX_TRIALS:
        f_max = f_min + MAX_TRIALS * df
        scan["band_limited"] = (f"the closest angles ({step_min:.3g}° apart) would allow periods down to "
                                f"{2 * step_min:.3g}°; the scan stops at {1.0 / f_max:.3g}° ({MAX_TRIALS} trial periods)")
    grid = np.arange(f_min, f_max + 0.5 * df, df)
    scan.update(period_min_deg=1.0 / f_max, period_max_deg=arc, regular_grid=regular, step_min_deg=step_min,
                n_trial_periods=int(grid.size))
    return grid, df, f_max, regular


def _refine_together(data: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], ks: list[float], df: float) -> None:
    """The orders found so far (cycles/turn, in place), refined together: each in turn, its neighbours held."""
    th, y, w, T = data
    for _ in range(2 if len(ks) > 1 else 0):
        for j in range(len(ks)):
            others = ks[:j] + ks[j + 1:]
            fj = ks[j] / 360.0
            r = minimize_scalar(lambda f, o=others: _chi2(th, y, w, T, o + [360.0 * f]),
                                bounds=(fj - df, fj + df), method="bounded", options={"xatol": 1e-6 * df})
            if r.fun < _chi2(th, y, w, T, ks):
                ks[j] = 360.0 * float(r.x)


def _find_periods(data: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], grid: np.ndarray, df: float,
                  f_max: float, scan: dict[str, Any]) -> tuple[list[float], list[tuple[float, float]], Any]:
    """Periods one at a time while the best one's false alarm (Baluev 2008) is below P_SIG and MIN_DOF
    residual dof remain: (orders in cycles/turn, (false alarm, power) each, the first periodogram's
    power or None); the reason the search stopped goes into ``scan``."""
    th, y, w, T = data
    n = th.size
    ks: list[float] = []
    fap_list: list[tuple[float, float]] = []
    chi2_null = _chi2(th, y, w, T, ks)
    power_first = None
    while len(ks) < MAX_PERIODS:
        p_null = T.shape[1] + 3 * len(ks)
        if n - p_null - 3 < MIN_DOF:
            scan["stopped"] = f"{n - p_null - 3} residual degrees of freedom would be left for another period"
            break
        chi2_f = _scan_chi2(th, y, w, _design(th, T, ks), 360.0 * grid)
        if power_first is None:
            power_first = 1.0 - chi2_f / chi2_null if chi2_null > 0 else np.zeros_like(chi2_f)
        i = int(np.argmin(chi2_f))
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
        best = minimize_scalar(lambda f: _chi2(th, y, w, T, ks + [360.0 * f]), bounds=(lo, hi), method="bounded",
                               options={"xatol": 1e-6 * df})
        f_best, chi2_best = (float(best.x), float(best.fun)) if best.fun < chi2_f[i] else (float(grid[i]), float(chi2_f[i]))
        z = (chi2_null - chi2_best) / chi2_null if chi2_null > 0 else 0.0
        fap = fap_baluev(z, f_max, th, w, n - p_null)
        if fap >= P_SIG:
            scan["best_rejected"] = {"period_deg": 1.0 / f_best, "power": z, "false_alarm": fap}
            break
        ks.append(360.0 * f_best)
        fap_list.append((fap, z))
        _refine_together(data, ks, df)
        chi2_null = _chi2(th, y, w, T, ks)
    return ks, fap_list, power_first


def _period_rows(fit: dict[str, Any], ks: list[float], fap_list: list[tuple[float, float]], arc: float,
                 grid_info: tuple[float, bool], u_given: bool, declared: Any) -> list[dict[str, Any]]:
    """One row per period found from the joint fit: period, amplitude and phase with u, false alarm,
    power, periods covered, dof, alias periods on a regular grid and the drive element it may be
    (``grid_info`` = (median step in deg, regular grid))."""
    nt, cov, beta = fit["n_trend"], fit["cov"], fit["beta"]
    median_step, regular = grid_info
    nk = len(ks)
    periods: list[dict[str, Any]] = []
    for i, k in enumerate(ks):
        ia, ib = nt + 2 * i, nt + 2 * i + 1
        ap = amplitude_phase_ab(beta[ia], beta[ib], cov[np.ix_([ia, ib], [ia, ib])])
        ik = nt + 2 * nk + i
        u_k = float(math.sqrt(max(cov[ik, ik], 0.0)))
        P = 360.0 / k
        u_P = 360.0 * u_k / k ** 2
        periods.append({
            "period_deg": P, "u_period_deg": u_P, "amplitude_arcsec": ap["amplitude"], "u": ap["u_amplitude"],
            "phase_deg": ap["phase_deg"], "u_phase_deg": ap["u_phase_deg"], "false_alarm": fap_list[i][0],
            "power": fap_list[i][1], "n_periods_covered": arc / P,
            "dof": None if u_given else int(fit["dof"]),
            "alias_periods_deg": _aliases(P, median_step, regular),
            "drive_element": drive_candidates(P, u_P, declared)})
        if periods[-1]["alias_periods_deg"]:
            periods[-1]["drive_element"]["note"] += (
                "; on this regular grid the alias periods " + ", ".join(
                    f"{a:.4g}°" for a in periods[-1]["alias_periods_deg"]) + " fit the points equally well")
    return periods


def analyze_arc_periods(theta_deg, value_arcsec, u_arcsec=None, *, drive_elements: Any = None) -> dict[str, Any]:
    """The periodic components of an arc (module docstring). ``u_arcsec``: per point standard
    uncertainties from outside the fit (None: unit weights, covariance scaled by the residual);
    ``drive_elements``: the manifest's declaration (or None). Returns ``{"periods": [...], "scan":
    {...}}``; each period: period_deg, u_period_deg, amplitude_arcsec, u (of the amplitude),
    phase_deg, u_phase_deg, false_alarm, power, n_periods_covered, dof (of the u's: residual degrees of
    freedom when u is scaled by the residual, None when given), alias_periods_deg, drive_element.

    Stages: :func:`_scan_header`, :func:`_frequency_grid`, :func:`_find_periods` (with
    :func:`_refine_together`), the joint fit, :func:`_period_rows`."""
    declared = _read_candidates(drive_elements)
    th = np.asarray(theta_deg, dtype=float).ravel()
    y = np.asarray(value_arcsec, dtype=float).ravel()
    o = np.argsort(th)
    th, y = th[o], y[o]
    u_given = u_arcsec is not None
    w = (1.0 / np.broadcast_to(np.asarray(u_arcsec, dtype=float), th.shape)[o]) if u_given else np.ones_like(th)
    n = th.size
    arc = float(th[-1] - th[0])
    steps = np.diff(th)
    scan = _scan_header(n, arc, u_given)
    if n < TREND_DEGREE + 1 + 3 + MIN_DOF or arc <= 0 or np.any(steps <= 0):
        scan["reason"] = (f"{n} distinct angles: a period with a degree-{TREND_DEGREE} trend needs at least "
                          f"{TREND_DEGREE + 1 + 3 + MIN_DOF}")
        return {"periods": [], "scan": scan}
    grid, df, f_max, regular = _frequency_grid(steps, arc, scan)
    T = _trend_columns(th, 0.5 * (th[0] + th[-1]), 0.5 * arc)
    ks, fap_list, power_first = _find_periods((th, y, w, T), grid, df, f_max, scan)
    if power_first is not None:
        scan["periodogram"] = {"period_deg": 1.0 / grid, "power": power_first}
    periods: list[dict[str, Any]] = []
    if ks:
        fit = _joint_fit(th, y, w, T, ks, u_given)
        periods = _period_rows(fit, ks, fap_list, arc, (float(np.median(steps)), regular), u_given, declared)
        beta, cov = fit["beta"], fit["cov"]
        r = y - _design(th, T, ks) @ beta
        scan.update(residual_rms_arcsec=float(np.sqrt(np.mean(r ** 2))), chi2=fit["chi2"], dof=int(fit["dof"]),
                    # the trend fitted with the periods (x = (θ − centre)/half-arc: slope = β₁/half-arc)
                    trend_slope_arcsec_per_deg=float(beta[1] / (0.5 * arc)),
                    u_trend_slope_arcsec_per_deg=float(math.sqrt(max(cov[1, 1], 0.0)) / (0.5 * arc)))
    scan["periods_found"] = len(periods)
    scan["phase_reference"] = "A cos(2π·θ/P − φ), θ in degrees from the table's 0°"
    return {"periods": periods, "scan": scan}
