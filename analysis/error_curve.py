"""A lone measured error curve α(θ): what it shows and what it cannot separate.

The commonest thing a lab has is a table from an earlier calibration: the encoder error at a set of
angles, perhaps in both directions of rotation, without the bench's other channels (no radial
probes, no CCD, no polygon start faces). This module analyses such a curve (the "error curve"
dataset kind, docs/dataset-format.md):

- **Coverage.** The arc the angles span. A full turn is sampled when the largest circular gap
  between neighbouring angles is at most ``FULL_TURN_GAP`` × the median step; otherwise the curve
  is an arc (a stage or a gear over part of a revolution): ``coverage_deg`` = 360° − the largest gap,
  and neither a closure nor harmonics of the turn are claimed (on an arc the functions sin kθ are
  not orthogonal and the lowest orders are confounded with a polynomial); a linear and a quadratic
  trend over the arc are reported instead.
- **Closure** (full turn only). An encoder's error over a full turn is defined up to a constant:
  a circle closes (the circle closure principle, Hsieh et al. 2022 eq. 2, Σα = 0). The table's own
  reference is stated (zero at the start = relative to the starting position; zero mean = closed;
  otherwise an offset) and the constant is removed before anything else.
- **Hysteresis** (both directions). The half difference (forward − backward)/2 at the common
  angles: its mean (a constant hysteresis, torsion or backlash), its RMS and its non-constant part.
- **Uncertainty of one point.** Given per point (``u_arcsec`` column), else type A from the two
  directions: the scatter of the direction difference about its mean, /√2 per point (the
  differences contain each point's non-repeatability twice; a non-constant hysteresis counts as
  non-repeatability — conservative); else from the residual of a Fourier series of order
  ⌊(n−1)/4⌋ (content above that order counts as noise). The source is stated.
- **Harmonics** (full turn). Least-squares Fourier series (analysis/fourier.py, Jia et al. 2019
  eqs. 6, 11, 12) of the direction mean, orders 1…K with K = min(10, ⌊(n−1)/2⌋ − 1) (at least a
  few residual degrees of freedom), each with its standard uncertainty and a χ²₂ test at
  Bonferroni-corrected ``P_SIG``; then χ² of what is left against u.
- **What a lone curve can and cannot separate.** Order 1 is the scale's eccentricity on the axis or
  a first-order division error (Jia eq. 3: a CCD measurement of e separates them); orders ≥ 2 are a
  division error of the scale (``graduation_error``), a synchronous radial motion of the axis
  tangential at the head (``tangential_motion``) or the reference's own error (a polygon's pitch or
  the autocollimator: ``polygon_pitch_ignored``) — X probes, re-mounting the scale rotated on the
  shaft, or a shift-angle / self-calibration measurement tell them apart. These are reported as
  ambiguity sets, never as identified effects. A residual still significant after the harmonics
  and the constant hysteresis is "unexplained".
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .distributions import chi2_isf, chi2_sf, norm_sf
from .fourier import amplitude_phase, fit_fourier

__all__ = ["analyze_error_curve", "coverage", "P_SIG", "FULL_TURN_GAP", "ZERO_TOL_ARCSEC"]

#: significance of every test here (as tracing.P_SIG: many tests per curve, false alarms rare)
P_SIG = 1e-3
#: a full turn is sampled when no circular gap exceeds 1.5 median steps: a regular grid of n points
#: has all gaps equal to the step, a missing point makes a gap of 2 steps (then the grid is still a
#: turn, but with a hole: see ``missing``), a partial arc leaves one gap of many steps
FULL_TURN_GAP = 2.0
#: a value within this of 0 is "zero" for the closure state (a printed table: 0.01″ is its last digit)
ZERO_TOL_ARCSEC = 1e-9
#: the harmonics fitted leave at least this many residual degrees of freedom
MIN_DOF = 3


def coverage(theta_deg) -> dict[str, Any]:
    """The arc spanned by the angles: ``full_turn``, ``coverage_deg``, ``step_deg``, ``max_gap_deg``,
    ``start_deg``, ``end_deg`` (of the arc: the points after and before the largest gap)."""
    th = np.unique(np.round(np.mod(np.asarray(theta_deg, dtype=float), 360.0), 9))
    th = th[th < 360.0]
    if th.size < 3:
        return {"full_turn": False, "coverage_deg": float(np.ptp(th)) if th.size else 0.0, "n_angles": int(th.size),
                "step_deg": None, "max_gap_deg": None, "start_deg": float(th[0]) if th.size else None,
                "end_deg": float(th[-1]) if th.size else None}
    gaps = np.diff(np.concatenate([th, [th[0] + 360.0]]))
    step = float(np.median(gaps))
    i = int(np.argmax(gaps))
    gmax = float(gaps[i])
    full = gmax <= FULL_TURN_GAP * step + 1e-9
    # a turn starts at its smallest angle; an arc at the point after its largest gap
    start, end = (float(th[0]), float(th[-1])) if full else (float(th[(i + 1) % th.size]), float(th[i]))
    return {"full_turn": bool(full), "coverage_deg": 360.0 if full else 360.0 - gmax, "n_angles": int(th.size),
            "step_deg": step, "max_gap_deg": gmax, "start_deg": start, "end_deg": end}


def _by_direction(theta, err, direction, u):
    dirs = {}
    for d in (["forward", "backward"] if direction is not None else ["forward"]):
        m = np.ones(theta.size, bool) if direction is None else (direction == d)
        if m.any():
            o = np.argsort(theta[m])
            dirs[d] = {"theta_deg": theta[m][o], "error_arcsec": err[m][o], "u": None if u is None else u[m][o]}
    return dirs


def _hysteresis(dirs: dict) -> dict[str, Any] | None:
    if set(dirs) != {"forward", "backward"}:
        return None
    f, b = dirs["forward"], dirs["backward"]
    common, i_f, i_b = np.intersect1d(np.round(f["theta_deg"], 9), np.round(b["theta_deg"], 9), return_indices=True)
    if common.size < 2:
        return {"available": False, "reason": "fewer than 2 angles measured in both directions"}
    half = (f["error_arcsec"][i_f] - b["error_arcsec"][i_b]) / 2.0
    n = half.size
    sd = float(np.std(half, ddof=1))
    out = {"available": True, "theta_deg": common, "half_difference_arcsec": half,
           "mean_arcsec": float(np.mean(half)), "u_mean_arcsec": sd / math.sqrt(n),
           "rms_arcsec": float(np.sqrt(np.mean(half ** 2))), "max_abs_arcsec": float(np.max(np.abs(half))),
           "sd_about_mean_arcsec": sd, "n_angles": int(n),
           "opposite_sign_angles": int(np.sum(np.sign(f["error_arcsec"][i_f]) * np.sign(b["error_arcsec"][i_b]) < 0)),
           "note": "half difference (forward − backward)/2 at the common angles; its mean is a constant hysteresis "
                   "(torsion, backlash), its scatter about the mean is non-repeatability or a direction-dependent "
                   "pattern (a lone pair of curves cannot tell which)"}
    if f["u"] is not None and b["u"] is not None:
        uh = 0.5 * np.sqrt(f["u"][i_f] ** 2 + b["u"][i_b] ** 2)
        out["u_point_arcsec"] = uh
        w = 1.0 / uh ** 2
        mean_w = float(np.sum(w * half) / np.sum(w))
        chi2 = float(np.sum(w * (half - mean_w) ** 2))
        out.update(mean_arcsec=mean_w, u_mean_arcsec=float(1.0 / math.sqrt(np.sum(w))),
                   chi2_about_mean=chi2, dof=n - 1, p_constant=float(chi2_sf(chi2, n - 1)))
    z = abs(out["mean_arcsec"]) / out["u_mean_arcsec"] if out["u_mean_arcsec"] > 0 else math.inf
    out["z_mean"] = z
    out["significant"] = bool(2 * norm_sf(z) < P_SIG)
    return out


def _checked_curve(theta_deg: Any, error_arcsec: Any, direction: Any,
                   u_arcsec: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(θ, error, direction or None when one direction, u per point or None) as flat arrays;
    ValueError on mismatched lengths or fewer than 3 points."""
    th = np.asarray(theta_deg, dtype=float).ravel()
    err = np.asarray(error_arcsec, dtype=float).ravel()
    if th.size != err.size:
        raise ValueError(f"theta_deg has {th.size} values, error_arcsec {err.size}")
    if th.size < 3:
        raise ValueError(f"an error curve needs at least 3 points, got {th.size}")
    dirn = None if direction is None else np.asarray(direction, dtype=object).ravel()
    if dirn is not None and set(dirn) <= {"forward"}:
        dirn = None
    u = None if u_arcsec is None else np.broadcast_to(np.asarray(u_arcsec, dtype=float), th.shape).copy()
    return th, err, dirn, u


def _point_u(u: np.ndarray | None, inv: np.ndarray, cnt: np.ndarray, mean: np.ndarray, theta_u: np.ndarray,
             hyst: dict[str, Any] | None, cov: dict[str, Any]) -> tuple[np.ndarray, str, float]:
    """u of one point of the direction-mean curve (arcsec): given, else type A from the two directions,
    else from the residual of a low-order series (full turn) or a quadratic (arc). (u, source, dof)."""
    if u is not None:
        u_mean = np.sqrt(np.bincount(inv, weights=u ** 2)) / cnt
        return u_mean, "given per point (u_arcsec)", math.inf
    if hyst and hyst.get("available") and hyst["n_angles"] >= 3:
        s_pt = hyst["sd_about_mean_arcsec"] * math.sqrt(2.0)  # sd of (f − b) is √2·s_point; half-diff sd = s_point/√2
        u_src = ("type A from the two directions: the scatter of (forward − backward) about its mean, /√2 per point "
                 "(a non-constant hysteresis counts as non-repeatability: conservative)")
        return s_pt / np.sqrt(cnt), u_src, hyst["n_angles"] - 1
    n_u = theta_u.size
    K0 = max(1, (n_u - 1) // 4)
    u_dof: float
    if cov["full_turn"] and n_u >= 2 * K0 + 1 + MIN_DOF:
        f0 = fit_fourier(theta_u, mean, K0)
        s_pt = f0.sigma
        u_src = f"type A from the residual of a Fourier series of order {K0} (content above it counted as noise)"
        u_dof = f0.dof
    else:
        c = np.polyfit(theta_u, mean, 2)
        r = mean - np.polyval(c, theta_u)
        u_dof = max(n_u - 3, 1)
        s_pt = float(math.sqrt(np.sum(r ** 2) / u_dof))
        u_src = "type A from the residual of a quadratic over the arc (content beyond it counted as noise)"
    return np.full(n_u, max(s_pt, 1e-12)), u_src, u_dof


def _arc_outputs(cov: dict[str, Any], theta_u: np.ndarray, mean: np.ndarray, u_mean: np.ndarray,
                 u_src: str) -> dict[str, Any]:
    """An arc: no closure, no harmonics of the turn; the trend over the arc (weighted quadratic) and
    χ² of what is left (meaningful only against a u from outside the fit)."""
    out: dict[str, Any] = {}
    out["closure"] = {"state": "not applicable", "reason": f"an arc of {cov['coverage_deg']:.1f}° is not a turn: "
                      "it does not close and carries no harmonics of the turn"}
    out["harmonics"] = []
    x = (theta_u - theta_u.mean())
    A = np.column_stack([np.ones_like(x), x, x ** 2])
    w = 1.0 / u_mean
    beta, *_ = np.linalg.lstsq(A * w[:, None], mean * w, rcond=None)
    C = np.linalg.inv((A * w[:, None]).T @ (A * w[:, None]))
    r = mean - A @ beta
    chi2 = float(np.sum((r / u_mean) ** 2))
    dof = max(theta_u.size - 3, 1)
    out["trend"] = {"slope_arcsec_per_deg": float(beta[1]), "u_slope": float(math.sqrt(C[1, 1])),
                    "curvature_arcsec_per_deg2": float(beta[2]), "u_curvature": float(math.sqrt(C[2, 2])),
                    "about_deg": float(theta_u.mean()),
                    "note": "a slope over an arc is a scale error of the encoder or of the reference, or the "
                            "start of a low harmonic: an arc cannot tell them apart"}
    out["residual"] = {"rms_arcsec": float(np.sqrt(np.mean(r ** 2))), "pv_arcsec": float(np.ptp(mean)),
                       "chi2": chi2, "dof": dof, "p_value": float(chi2_sf(chi2, dof))}
    # only against a u from outside the fit (given, or from the two directions) can χ² tell anything
    sig_left = not u_src.startswith("type A from the residual") and out["residual"]["p_value"] < P_SIG
    out["unexplained"] = bool(sig_left)
    out["status"] = "arc"
    return out


def _closure(cov: dict[str, Any], theta_u: np.ndarray, mean: np.ndarray, u_mean: np.ndarray,
             dirs: dict[str, Any]) -> dict[str, Any]:
    """The closure state of a full turn: zero at the start, zero mean, or offset; the weighted mean
    (arcsec) that is removed."""
    first = float(mean[np.argmin(np.abs(((theta_u - cov["start_deg"]) + 180.0) % 360.0 - 180.0))])
    zero_start = all(abs(float(d["error_arcsec"][0])) <= ZERO_TOL_ARCSEC for d in dirs.values())
    m0 = float(np.sum(mean / u_mean ** 2) / np.sum(1.0 / u_mean ** 2))
    u_m0 = float(1.0 / math.sqrt(np.sum(1.0 / u_mean ** 2)))
    state = ("relative to the start (zero at the first angle)" if zero_start
             else "closed (zero mean)" if abs(m0) <= 2 * u_m0 else "offset (neither zero at the start nor zero mean)")
    return {"state": state, "mean_arcsec": m0, "u_mean_arcsec": u_m0, "first_value_arcsec": first,
            "closed": bool(abs(m0) <= 2 * u_m0), "applied": "the mean over the turn is removed: a full "
            "turn determines the error only up to a constant (circle closure, Hsieh 2022 eq. 2)"}


def _harmonics(theta_u: np.ndarray, y: np.ndarray, u_mean: np.ndarray,
               notes: list[str]) -> tuple[list[dict[str, Any]], np.ndarray, dict[str, Any] | None]:
    """Harmonics 1…K (K ≤ 10, with MIN_DOF residual dof) of the closed curve, each tested at P_SIG/K
    (Bonferroni): (rows, the curve minus its significant harmonics, the fit's χ² row or None)."""
    n_u = theta_u.size
    K = int(min(10, (n_u - 1) // 2 - 1))
    while K >= 1 and n_u < 2 * K + 1 + MIN_DOF:
        K -= 1
    harm: list[dict[str, Any]] = []
    resid = y
    if K < 1:
        notes.append("too few angles for any harmonic with residual degrees of freedom")
        return harm, resid, None
    fit = fit_fourier(theta_u, y, K, u=u_mean)
    crit = float(chi2_isf(P_SIG / K, 2))
    for k in range(1, K + 1):
        ap = amplitude_phase(fit, k)
        try:
            q = float(np.array([ap["a"], ap["b"]]) @ np.linalg.solve(ap["cov_ab"], np.array([ap["a"], ap["b"]])))
        except np.linalg.LinAlgError:
            q = 0.0
        harm.append({"k": k, "amplitude_arcsec": ap["amplitude"], "u_arcsec": ap["u_amplitude"],
                     "phase_deg": ap["phase_deg"], "u_phase_deg": ap["u_phase_deg"], "a_arcsec": ap["a"],
                     "b_arcsec": ap["b"], "chi2": q, "p_value": float(chi2_sf(q, 2)),
                     "significant": bool(q > crit)})
    sig_k = [h["k"] for h in harm if h["significant"]]
    if sig_k:
        resid = y - fit(theta_u, sig_k)
    chi2_all = float(np.sum((fit.residual / u_mean) ** 2))
    fit_row = {"order": K, "chi2": chi2_all, "dof": int(fit.dof), "p_value": float(chi2_sf(chi2_all, max(fit.dof, 1)))}
    return harm, resid, fit_row


def _ambiguities(sig_k: list[int], hyst: dict[str, Any] | None) -> list[dict[str, Any]]:
    """What a lone curve cannot separate, with the measurement that would."""
    amb: list[dict[str, Any]] = []
    if 1 in sig_k:
        amb.append({"names": ["eccentricity", "graduation_error (order 1)"], "harmonics": [1],
                    "separating_measurement": "measure the scale's eccentricity on the axis (CCD, Jia sec. 4.2, eq. 3) "
                                              "or re-mount the scale rotated: a first-order division error stays with "
                                              "the scale's lines, the eccentricity changes with the mounting"})
    higher = [k for k in sig_k if k >= 2]
    if higher:
        amb.append({"names": ["graduation_error", "polygon_pitch_ignored", "tangential_motion"], "harmonics": higher,
                    "separating_measurement": "X probes on two spheres (the axis' tangential motion), re-mounting the "
                                              "scale rotated on the shaft (a division error moves with it), and a "
                                              "shift-angle or multi-head self-calibration (the reference's own error "
                                              "is absent from it, Hsieh 2022 eqs. 3, 8-9)"})
    if hyst and hyst.get("available") and hyst.get("significant"):
        amb.append({"names": ["torsion_hysteresis", "backlash of the drive or the reference"], "harmonics": [],
                    "separating_measurement": "measure both directions with a reference coupled directly to the "
                                              "encoder's shaft, at two drive torques"})
    return amb


def _what_is_left(resid: np.ndarray, u_mean: np.ndarray, n_sig: int,
                  hyst: dict[str, Any] | None) -> tuple[dict[str, Any], list[str]]:
    """The residual after the significant harmonics (and the constant hysteresis, which the direction
    mean already cancels) against u: its row and the reasons it is unexplained (empty: none)."""
    chi2 = float(np.sum((resid / u_mean) ** 2))
    dof = int(max(resid.size - 1 - 2 * n_sig, 1))
    p = float(chi2_sf(chi2, dof))
    row = {"rms_arcsec": float(np.sqrt(np.mean(resid ** 2))), "pv_arcsec": float(np.ptp(resid)),
           "chi2": chi2, "dof": dof, "p_value": p,
           "note": "direction mean minus its constant and its significant harmonics, against u"}
    left = []
    if p < P_SIG:
        left.append(f"χ² of what is left: {chi2:.1f} for {dof} dof (p = {p:.2g})")
    if hyst and hyst.get("available") and hyst.get("p_constant") is not None and hyst["p_constant"] < P_SIG:
        left.append("a direction difference that is not constant")
    return row, left


def analyze_error_curve(theta_deg, error_arcsec, direction=None, u_arcsec=None) -> dict[str, Any]:
    """Analyse a lone error curve (see the module docstring). ``direction``: per point "forward" /
    "backward" (or None: one direction); ``u_arcsec``: per point standard uncertainty (or None).
    Returns a JSON-ready dict (arrays as numpy arrays): coverage, closure, hysteresis, u, harmonics,
    residual, ambiguous, identified_effects (always empty: a lone curve identifies no cause),
    unexplained, status, notes.

    Stages: :func:`_checked_curve`, the direction mean, :func:`_point_u`; an arc: :func:`_arc_outputs`;
    a full turn: :func:`_closure`, :func:`_harmonics`, :func:`_ambiguities`, :func:`_what_is_left`."""
    th, err, dirn, u = _checked_curve(theta_deg, error_arcsec, direction, u_arcsec)
    thm = np.mod(th, 360.0)
    cov = coverage(thm)
    dirs = _by_direction(thm, err, dirn, u)
    notes: list[str] = []
    out: dict[str, Any] = {"kind": "error-curve", "n_points": int(th.size), "directions": sorted(dirs),
                           "coverage": cov, "coverage_deg": cov["coverage_deg"], "identified_effects": [],
                           "notes": notes}
    hyst = _hysteresis(dirs)
    out["hysteresis"] = hyst
    # the direction mean at every angle (a point measured in one direction only stands for itself)
    keys = np.round(thm, 9)
    uniq, inv = np.unique(keys, return_inverse=True)
    cnt = np.bincount(inv)
    mean = np.bincount(inv, weights=err) / cnt
    theta_u = uniq
    u_mean, u_src, u_dof = _point_u(u, inv, cnt, mean, theta_u, hyst, cov)
    out["u_point"] = {"u_arcsec": float(np.sqrt(np.mean(u_mean ** 2))), "source": u_src,
                      "dof": None if not math.isfinite(u_dof) else int(u_dof)}
    out["mean_curve"] = {"theta_deg": theta_u, "value_arcsec": mean, "u_arcsec": u_mean, "n_directions": cnt}
    if not cov["full_turn"]:
        out.update(_arc_outputs(cov, theta_u, mean, u_mean, u_src))
        notes.append(out["closure"]["reason"])
        out["ambiguous"] = []
        return out
    out["closure"] = _closure(cov, theta_u, mean, u_mean, dirs)
    y = mean - out["closure"]["mean_arcsec"]
    harm, resid, fit_row = _harmonics(theta_u, y, u_mean, notes)
    if fit_row is not None:
        out["fit"] = fit_row
    out["harmonics"] = harm
    sig_k = [h["k"] for h in harm if h["significant"]]
    out["significant_harmonics"] = sig_k
    amb = _ambiguities(sig_k, hyst)
    out["ambiguous"] = amb
    out["residual"], left = _what_is_left(resid, u_mean, len(sig_k), hyst)
    out["left"] = left
    out["unexplained"] = bool(left)
    out["status"] = ("unexplained" if left else "ambiguous" if amb else "no_significant_residual")
    if u is None and not (hyst and hyst.get("available")):
        notes.append("no u given and one direction: u comes from the curve's own scatter about a low-order series; "
                     "what the curve holds above that order cannot be told from noise")
    return out
