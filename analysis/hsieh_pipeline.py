"""Hsieh 2022 analysis end to end on the dataset's columns: shift-angle method, self-calibration, budget.

Hsieh, Watanabe, Hsu, "Calibration of Rotary Encoders Using a Shift-Angle Method", Appl. Sci. 12
(2022) 5008: sec. 2.1-2.2 and 3.1 (:mod:`.shift_angle`), sec. 2.3 and 3.2 (:mod:`.selfcal`), sec. 3.3
(:mod:`.uncertainty`: eq. 10-12, Table 3, eq. 13 with the standard E_n).

:func:`analyze_polygon` is pure (arrays in, a JSON-ready dict out; NaN becomes ``None``). Result keys:

- ``polygon_pitch_deviation_arcsec`` (N), ``polygon_pitch_deviation_u_arcsec`` (N), ``beta_source``;
- ``setup_error_arcsec`` {str(S): [U_j for the start faces measured]}, ``setup_error_start_faces``
  {str(S): [j…]}, ``setup_error_u_arcsec`` {str(S): [...]};
- ``encoder_error_arcsec`` {theta_deg, value, u, u_propagated, U}: all shifts combined, sorted by θ;
  u = √(u_propagated² + Σ type-B²) where u_propagated is the linear propagation of u(ε) (repetitions,
  or the closure residual) and u(β), and the type-B terms are items (2)-(6), (8) of the budget; U = k·u
  with the budget's k;
- ``alpha_by_shift_arcsec`` {str(S): {theta_deg, value, u}}; ``curve_fit`` rows (sec. 3.1 check);
- ``selfcal_error_arcsec`` {theta_deg, value, u, U} (only with heads data), ``selfcal`` details,
  ``difference_arcsec`` {theta_deg, value, en} (shift-angle − self-calibration at the shift-angle θ),
  ``en_max`` (None without heads);
- ``budget`` (rows of :meth:`UncertaintyBudget.table`), ``budget_summary`` {u_c, nu_eff, k, U};
- ``repeatability`` {max_sd_eps_arcsec, n_rep_min, u_eps_source, ...}, ``notes``.

Decisions where the paper is silent: the comparison with self-calibration evaluates the self-cal
curve at the shift-angle θ by its Fourier series with the harmonics that are multiples of N removed
(the shift-angle method cannot see them, see :mod:`.shift_angle`); the self-cal reference is head 1.
The budget's repeatability rows follow the paper (worst case over the readings: max sd/√n); with one
reading per cell, u(ε) is the pooled residual s of the S = 0 closure with ν = (N−1)(N−2).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from . import selfcal as sc
from . import shift_angle as sa
from . import uncertainty as un

__all__ = ["analyze_polygon", "fourier_resample_arcsec"]


def _json(x: Any) -> Any:
    if isinstance(x, Mapping):
        return {str(k): _json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json(v) for v in x]
    if isinstance(x, np.ndarray):
        return _json(x.tolist())
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def _skey(s: float) -> str:
    return f"{s:g}"


def fourier_resample_arcsec(theta_grid_deg: np.ndarray, values_arcsec: np.ndarray, theta_eval_deg: np.ndarray, *,
                            drop_multiples_of: int | None = None) -> np.ndarray:
    """Evaluate the trigonometric interpolant of values on an equally spaced full-circle grid at other θ,
    optionally without the harmonics that are multiples of ``drop_multiples_of`` (and without the
    Nyquist term)."""
    th = np.asarray(theta_grid_deg, dtype=float)
    v = np.asarray(values_arcsec, dtype=float)
    n = th.size
    C = np.fft.rfft(v) / n
    k = np.arange(C.size)
    keep = np.ones(C.size, dtype=bool)
    if n % 2 == 0:
        keep[-1] = False
    if drop_multiples_of:
        keep &= ~((k % int(drop_multiples_of) == 0) & (k > 0))
    ph = np.deg2rad(np.asarray(theta_eval_deg, dtype=float) - th[0])
    out = np.full(ph.shape, C[0].real if keep[0] else 0.0)
    for kk in k[1:][keep[1:]]:
        out = out + 2.0 * np.real(C[kk] * np.exp(1j * kk * ph))
    return out


def analyze_polygon(columns: Mapping[str, np.ndarray], n_faces: int, heads: Mapping[str, np.ndarray] | None = None,
                    heads_deg: Sequence[float] | None = None, certificate_beta_arcsec: np.ndarray | None = None, *,
                    u_certificate_arcsec: np.ndarray | float | None = None, beta_source: str = "auto",
                    u_eps_arcsec: float | None = None, fit_harmonics: Sequence[int] = (2,),
                    selfcal_sets: Mapping[str, Sequence[int]] | None = None,
                    ac_resolution_arcsec: float = 0.001, ac_traceability_U_arcsec: float = 0.01,
                    ac_traceability_k: float = 2.0, ac_error_half_width_arcsec: float = 0.05,
                    encoder_resolution_arcsec: float = 0.0, setup_misalignment_arcsec: float = 0.05,
                    type_b_relative: float = 0.10, p: float = 0.95) -> dict[str, Any]:
    """Analyse a polygon table (and optionally a heads table) with the Hsieh 2022 methods.

    ``columns``: ``shift_deg, start_face, step, ac_arcsec`` (+ ``theta_deg``, ``t_s``, ``rep``,
    ``direction``; ``t_s`` is not used). ``heads``: ``theta_deg, head, delta_arcsec`` (+ ``rep``,
    ``direction``) with ``heads_deg`` the azimuths of the heads from head 1. ``certificate_beta_arcsec``:
    pitch deviations of a calibrated polygon (used per ``beta_source``; see
    :func:`.shift_angle.shift_angle_analysis`). Budget parameters in arcsec (defaults from Hsieh sec. 3.3:
    ELCOMAT 3000 resolution 0.001″, traceability U = 0.01″ (k = 2), maximum error 0.05″, setup
    misalignment 0.05″; the encoder resolution comes from the bench, 0 if unknown).

    Raises :class:`.shift_angle.PolygonDataError` for unusable polygon readings.
    """
    need = [c for c in ("shift_deg", "start_face", "step", "ac_arcsec") if c not in columns]
    if need:
        raise sa.PolygonDataError(f"polygon columns missing: {need} (has {sorted(columns)})")
    table = sa.tabulate_polygon(columns["shift_deg"], columns["start_face"], columns["step"], columns["ac_arcsec"],
                                n_faces, theta_deg=columns.get("theta_deg"), rep=columns.get("rep"),
                                direction=columns.get("direction"))
    N = table.n_faces
    notes: list[str] = []
    # ---- u(ε): repetitions, else given, else the closure residual at S = 0
    n_rep_min = int(min(int(table.n_rep[s][table.n_rep[s] > 0].min()) for s in table.shifts_deg))
    sd_all = np.concatenate([table.sd_arcsec[s][np.isfinite(table.sd_arcsec[s])] for s in table.shifts_deg])
    closure_s, closure_nu = (float("nan"), 0)
    complete = [float(s) for s in table.shifts_deg if table.is_complete(float(s))]
    if complete:
        ref = 0.0 if 0.0 in complete else complete[0]
        closure_s, closure_nu = sa.closure_residual_sd_arcsec(table.eps_arcsec[ref])
    if n_rep_min >= 2:
        u_fill, u_src, dof_rep = u_eps_arcsec, "pooled repeatability s_p/sqrt(n)", n_rep_min - 1
    elif u_eps_arcsec is not None:
        u_fill, u_src, dof_rep = float(u_eps_arcsec), "given u_eps_arcsec", math.inf
    elif math.isfinite(closure_s):
        u_fill, u_src, dof_rep = closure_s, "pooled residual of the S=0 closure", closure_nu
        notes.append(f"no repetitions: u(ε) = {closure_s:.3g} arcsec from the S=0 closure residual (ν = {closure_nu})")
    else:
        u_fill, u_src, dof_rep = None, "none (u not available)", math.inf
        notes.append("no repetitions, no u_eps_arcsec and no full S=0 table: statistical u unavailable")
    res = sa.shift_angle_analysis(table, certificate_beta_arcsec=certificate_beta_arcsec,
                                  u_certificate_arcsec=u_certificate_arcsec, u_eps_arcsec=u_fill,
                                  beta_source=beta_source)
    notes += res.notes
    th, alpha, u_prop = sa.combined_curve(res)
    # ---- sec. 3.1 curve-fit check
    try:
        fit_rows = sa.setup_error_by_curve_fit(res, fit_harmonics)
        setup_residual = max(abs(r["diff_arcsec"]) for r in fit_rows)
    except ValueError as exc:  # e.g. a harmonic aliasing onto the offset
        fit_rows, setup_residual = [], 0.0
        notes.append(f"curve-fit check skipped: {exc}")
    # ---- budget (sec. 3.3)
    if n_rep_min >= 2:
        u_rep_alpha = float(np.max(sd_all)) / math.sqrt(n_rep_min) if sd_all.size else 0.0
    else:
        u_rep_alpha = float(u_fill) if u_fill is not None else 0.0
    u_rep_beta = float(np.nanmax(res.u_beta_arcsec)) if np.any(np.isfinite(res.u_beta_arcsec)) else 0.0
    dof_beta = dof_rep if res.beta_source == "closure" else math.inf
    budget = un.shift_angle_budget(u_repeat_alpha=u_rep_alpha, dof_repeat_alpha=dof_rep, n_faces=N,
                                   u_repeat_beta=u_rep_beta, dof_repeat_beta=dof_beta,
                                   ac_resolution=ac_resolution_arcsec, ac_traceability_U=ac_traceability_U_arcsec,
                                   ac_traceability_k=ac_traceability_k, ac_error_half_width=ac_error_half_width_arcsec,
                                   encoder_resolution=encoder_resolution_arcsec, setup_residual=setup_residual,
                                   setup_misalignment=setup_misalignment_arcsec, type_b_relative=type_b_relative)
    budget.p = p
    stat_names = {"Repeatability of angle error measurement", "Repeatability of the pitch angle deviation measurement"}
    u_typeb = math.sqrt(sum(c.contribution**2 for c in budget.contributions if c.name not in stat_names))
    u_prop0 = np.where(np.isfinite(u_prop), u_prop, 0.0)
    u_tot = np.sqrt(u_prop0**2 + u_typeb**2)
    k = budget.k
    out: dict[str, Any] = {
        "method": "Hsieh 2022 shift-angle",
        "n_faces": N,
        "shifts_deg": table.shifts_deg,
        "beta_source": res.beta_source,
        "reference_shift_deg": res.reference_shift_deg,
        "polygon_pitch_deviation_arcsec": res.beta_arcsec,
        "polygon_pitch_deviation_u_arcsec": res.u_beta_arcsec,
        "setup_error_arcsec": {_skey(s.shift_deg): s.U_arcsec for s in res.shifts},
        "setup_error_u_arcsec": {_skey(s.shift_deg): s.u_U_arcsec for s in res.shifts},
        "setup_error_start_faces": {_skey(s.shift_deg): s.start_faces for s in res.shifts},
        "alpha_by_shift_arcsec": {_skey(s.shift_deg): {"theta_deg": s.theta_deg, "value": s.alpha_arcsec,
                                                         "u": s.u_alpha_arcsec} for s in res.shifts},
        "encoder_error_arcsec": {"theta_deg": th, "value": alpha, "u": u_tot, "u_propagated": u_prop, "U": k * u_tot},
        "curve_fit": fit_rows,
        "repeatability": {"max_sd_eps_arcsec": float(np.max(sd_all)) if sd_all.size else None,
                          "pooled_sd_eps_arcsec": table.pooled_sd()[0], "pooled_dof": table.pooled_sd()[1],
                          "n_rep_min": n_rep_min, "u_eps_source": u_src,
                          "closure_residual_sd_arcsec": closure_s, "closure_dof": closure_nu,
                          "theta_offset_max_deg": table.theta_offset_max_deg},
        "budget": budget.table(),
        "budget_summary": {"u_c": budget.u_c, "nu_eff": budget.nu_eff, "k": k, "U": budget.U, "p": p,
                           "u_type_b": u_typeb},
        "selfcal_error_arcsec": None,
        "difference_arcsec": None,
        "en_max": None,
    }
    if res.beta_closure_arcsec is not None:
        out["certificate_minus_closure_arcsec"] = res.beta_arcsec - res.beta_closure_arcsec
    # ---- self-calibration and comparison (sec. 3.2, eq. 13)
    if heads is not None:
        if heads_deg is None:
            raise ValueError("heads table given without heads_deg (head azimuths from head 1)")
        nh = len(heads_deg)
        ht = sc.tabulate_heads(heads["theta_deg"], heads["head"], heads["delta_arcsec"], nh, rep=heads.get("rep"),
                               direction=heads.get("direction"))
        u_d = None
        if np.all(ht["n_rep"][:, 1:] >= 2):  # pooled repeatability of δ over θ and heads 2…, / √n per cell
            nr, sdv = ht["n_rep"][:, 1:], ht["sd_arcsec"][:, 1:]
            sp = math.sqrt(float(np.sum((nr - 1) * sdv**2)) / float(np.sum(nr - 1)))
            u_d = sp / np.sqrt(ht["n_rep"].astype(float))
        scr = sc.selfcal_fourier(ht["theta_deg"], heads_deg, ht["delta_arcsec"], sets=selfcal_sets, u_delta_arcsec=u_d)
        u_res = encoder_resolution_arcsec / (2 * math.sqrt(3.0))
        u_self = np.sqrt(scr.u_arcsec**2 + u_res**2)
        dof_self = float(np.min(ht["n_rep"][:, 1:]) - 1) if u_d is not None else scr.dof
        k_self = un.coverage_factor(dof_self if dof_self > 0 else math.inf, p)
        notes += scr.notes
        mu_at = fourier_resample_arcsec(scr.theta_deg, scr.value_arcsec, th, drop_multiples_of=N)
        u_self_at = np.interp(th, scr.theta_deg, u_self, period=360.0)
        diff = alpha - mu_at
        en = un.en_number(alpha, k * u_tot, mu_at, k_self * u_self_at)
        out["selfcal_error_arcsec"] = {"theta_deg": scr.theta_deg, "value": scr.value_arcsec, "u": u_self,
                                       "U": k_self * u_self}
        out["selfcal"] = {"k": k_self, "dof": dof_self, "sigma_delta_arcsec": scr.sigma_delta_arcsec,
                          "unobservable_harmonics": scr.unobservable_harmonics,
                          "sets": list(selfcal_sets) if selfcal_sets else None,
                          "per_set_arcsec": scr.per_set_arcsec}
        out["difference_arcsec"] = {"theta_deg": th, "value": diff, "selfcal_at_theta": mu_at, "en": en}
        out["en_max"] = float(np.max(en))
    out["notes"] = notes
    return _json(out)
