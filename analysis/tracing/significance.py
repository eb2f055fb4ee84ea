"""Is there anything to explain? χ² of the residual (α − Jia et al. 2019 eq. 5 model) against the
combined uncertainty of measurement and model, and a harmonic-by-harmonic test (Bonferroni-corrected
at ``P_SIG``); the nested-model tests the signature uses.
"""

from __future__ import annotations

import math

import numpy as np

from ..distributions import chi2_sf
from ..fourier import harmonic_columns
from ._blas import _one_blas_thread
from .evidence import Evidence, column
from .problem import _Problem, _center, _rms, _z_from_chi2, chi2_scale, closure_kept
from .thresholds import P_SIG, Z_GATE


# ----------------------------------------------------------------------------------------------
# 1. anything to explain?
# ----------------------------------------------------------------------------------------------

@_one_blas_thread
def residual_test(ev: Evidence) -> dict:
    """χ² of the (closure-centred) residual against the combined uncertainty, and its summary."""
    pb = _Problem(ev, use_selfcal=False)
    r = pb.y[: ev.n]
    chi2, dof = pb.null["chi2"], pb.null["dof"]
    return {"rms_arcsec": _rms(r), "pv_arcsec": float(np.ptp(r)) if r.size else 0.0,
            "fraction_of_error": _rms(r) / max(_rms(_center(ev.alpha_arcsec, column(ev.closure_group), 1 / column(ev.u_arcsec) ** 2)), 1e-300),
            "chi2": chi2, "dof": dof, "p_value": float(chi2_sf(chi2, dof))}


def resolved_harmonics(ev: Evidence, pb: _Problem) -> tuple[list[int], np.ndarray]:
    """The orders 1…kmax of θ the closure leaves and their closure-centred columns
    (``fourier.harmonic_columns``, [sin kθ, cos kθ] per order): the design of :func:`harmonic_test`
    and of every scale taken "after harmonics 1…kmax". An order whose columns the closure removes
    (:func:`closure_kept`: order N of an N-face polygon, which the shift-angle designs reach with
    kmax up to 40) is left out: no reading constrains it, and fitted beside the others its
    coefficient was the solver's round-off (10¹⁰–10¹³″ ± as much on the 0…14° benches of loop
    validation seeds 804–806), and so was its χ² (the hsieh2022 default flagged order 24)."""
    raw = harmonic_columns(ev.theta_deg, range(1, ev.kmax + 1))[0]
    X = _center(raw, column(ev.closure_group), pb.w ** 2)
    keep: np.ndarray = np.asarray(closure_kept(X, raw, pb.w).reshape(-1, 2).all(axis=1), dtype=bool)
    ks = [k for k, kept in zip(range(1, ev.kmax + 1), keep) if kept]
    return ks, (X if keep.all() else X[:, np.repeat(keep, 2)])


@_one_blas_thread
def harmonic_test(ev: Evidence, pb: _Problem | None = None) -> list[dict]:
    """Each harmonic of :func:`resolved_harmonics` fitted jointly; amplitude, its u and a χ²_2 test
    (Bonferroni over the harmonics tested; u scaled by √(χ²/dof) when that exceeds 1). The orders
    the closure removes are not tested and not listed."""
    pb = pb or _Problem(ev, use_selfcal=False)
    ks, X = resolved_harmonics(ev, pb)
    fit = pb.fit(X)
    scale = chi2_scale(fit)
    out = []
    for i, k in enumerate(ks):
        a, b = fit["beta"][2 * i], fit["beta"][2 * i + 1]
        C = fit["cov"][2 * i:2 * i + 2, 2 * i:2 * i + 2] * scale
        amp = math.hypot(a, b)
        try:
            q = float(np.array([a, b]) @ np.linalg.solve(C, np.array([a, b])))
        except np.linalg.LinAlgError:
            q = 0.0
        g = np.array([a, b]) / amp if amp > 0 else np.array([1.0, 0.0])
        u_amp = float(math.sqrt(max(g @ C @ g, 0.0)))
        p = float(chi2_sf(q, 2))
        out.append({"k": k, "amplitude_arcsec": amp, "u_arcsec": u_amp, "phase_deg": math.degrees(math.atan2(a, b)),
                    "a_arcsec": float(a), "b_arcsec": float(b), "chi2": q, "z": _z_from_chi2(q, 2), "p_value": p,
                    "significant": bool(p * len(ks) < P_SIG)})
    return out


def _one_column(pb: _Problem, col: np.ndarray, name: str) -> dict:
    ev = pb.ev
    X = _center(np.asarray(col, dtype=float)[:, None], column(ev.closure_group), pb.w ** 2)
    if not np.any(np.abs(X) > 1e-12 * (np.max(np.abs(col)) + 1e-300)):
        return {"available": False, "reason": f"{name}: no variation inside the closure groups"}
    fit = pb.fit(X)
    scale = chi2_scale(fit)
    g = float(fit["beta"][0])
    u = float(math.sqrt(fit["cov"][0, 0] * scale))
    xw, yw = X[:, 0] * pb.w, pb.y * pb.w
    corr = float(xw @ yw / math.sqrt((xw @ xw) * (yw @ yw))) if (xw @ xw) > 0 and (yw @ yw) > 0 else 0.0
    # its size: the RMS the column changes the (closure-centred) readings by, for the size gate
    size = abs(g) * float(np.sqrt(np.mean(X[:, 0] ** 2)))
    return {"available": True, "gain": g, "u": u, "z": abs(g) / u if u > 0 else math.inf, "corr": corr,
            "rms_arcsec": size, "significant": bool(u > 0 and abs(g) / u > Z_GATE)}


def _nested(pb: _Problem, X0: np.ndarray, X1: np.ndarray) -> dict:
    f0, f1 = pb.fit(X0), pb.fit(np.hstack([X0, X1]))
    d, k = f0["chi2"] - f1["chi2"], f1["k"] - f0["k"]
    if k <= 0:
        return {"available": False}
    p = float(chi2_sf(d, k))
    return {"available": True, "delta_chi2": float(d), "dof": int(k), "p_value": p, "significant": bool(p < P_SIG)}
