"""Hsieh 2022 analysis end to end on the dataset's columns: shift-angle method, self-calibration, budget.

Hsieh, Watanabe, Hsu, "Calibration of Rotary Encoders Using a Shift-Angle Method", Appl. Sci. 12
(2022) 5008: sec. 2.1-2.2 and 3.1 (:mod:`.shift_angle`), sec. 2.3 and 3.2 (:mod:`.selfcal`), sec. 3.3
(:mod:`.uncertainty`: eq. 10-12, Table 3, eq. 13 with the standard E_n).

:func:`analyze_polygon` is pure (arrays in, a JSON-ready dict out; NaN becomes ``None``). Result keys:

- ``polygon_pitch_deviation_arcsec`` (N), ``polygon_pitch_deviation_u_arcsec`` (N), ``beta_source``;
- ``setup_error_arcsec`` {str(S): [U_j for the start faces measured]}, ``setup_error_start_faces``
  {str(S): [j…]}, ``setup_error_u_arcsec`` {str(S): [...]};
- ``encoder_error_arcsec`` {theta_deg, value, u, u_propagated, U}: all shifts combined, sorted by θ;
  u = √(u_propagated² + Σ type-B²) where u_propagated is the linear propagation of the repeatability
  of ε (s/√n per cell) and u(β), and the type-B terms are items (2)-(6), (8) of the budget and the
  direction difference (9); U = k·u with the budget's k;
- ``alpha_by_shift_arcsec`` {str(S): {theta_deg, value, u}}; ``curve_fit`` rows (sec. 3.1 check);
- ``selfcal_error_arcsec`` {theta_deg, value, u, U} (only with heads data), ``selfcal`` details,
  ``difference_arcsec`` {theta_deg, value, en, shift_angle_compared, selfcal_at_theta, max_abs, …}
  (shift-angle − self-calibration on the harmonics both see), ``en_max`` (None without heads);
- ``budget`` (rows of :meth:`UncertaintyBudget.table`), ``budget_summary`` {u_c, nu_eff, k, U,
  monte_carlo (GUM-S1 check)}; ``direction_difference`` (forward − backward α, see
  :func:`.shift_angle.direction_difference`);
- ``repeatability`` {s_reading_arcsec, dof, alpha_sd_over_reps_max_arcsec (the paper's sec. 3.3 (1)), …},
  ``notes``.

Repeatability of ε (sec. 3.3 (1)). Forward and backward sweeps are not repetitions of one value when
the bench has hysteresis, and re-clamped runs differ by their setup errors; so neither is used as a
"repetition". The readings of each cell are averaged (directions and runs, as the paper averages its
six results) and the standard deviation s of ONE reading comes from the residuals of eq. 3 fitted to
every single reading — α per shift and direction, common β, one offset per run-row
(:func:`.shift_angle.reading_repeatability`). Its degrees of freedom are the readings minus the
parameters: with the twin's procedure (all N start faces at S = 0, face 1 at the other shifts, both
directions) 1035 for one run, ≈ 9800 for six. u(ε) of a cell is s/√n, propagated exactly through the
estimators. The budget row (1) is the worst θ of that propagation (a single start face at S ≠ 0);
row (7) is u(β) with the sensitivity of this estimator (from its Jacobian; Estler's eq. 11 holds for
α averaged over all start faces). The θ-dependent part of the direction difference that the
repeatability does not explain is its own row (9); a constant one only changes U_j.

Self-calibration: eq. 9 per set of equally spaced heads (found from ``heads_deg`` unless given). A set
average cancels the axis' radial error motion (Σ of the heads' tangents is 0), a single head's δ does
not: on the twin's hsieh2022 bench (0.025 µm order-3 bearing waviness) head-level least squares put
0.15″ of that motion into α. Sets whose heads sit on the θ grid are preferred per harmonic (exact for
samples); the off-grid set (7 heads at 51.43° on a 1° grid) only supplies what the others cannot see,
with an interpolation-error term (:func:`.selfcal.selfcal_fourier`). The self-cal reference is head 1.
Its u (:func:`_selfcal`): type A from the scatter of the runs' own estimates where the heads table has
two runs or more (the axis' motion is shared by all heads at one instant, so the δ are correlated and
the independent-δ propagation of s(δ) is short: hsieh2022 0.0059″ propagated, 0.0087″ between the
forward and backward runs), else propagated; the interpolation term; the encoder resolution. The
curve states the harmonics no set sees (``unobservable_harmonics``, set to 0): the measurand is α
without them, as the shift-angle α is without the multiples of N (on the ball-bearing benches with
3 heads they hold 0.34″ of head 1's error, the bearing's axis motion at orders 6, 9, 15, …).

Comparison (eq. 13, standard E_n with √(U₁² + U₂²)): on the harmonics both methods see — without the
multiples of N (lost by the shift-angle method into U_j, eq. 2), those the heads cannot see (84, 168
for SelfA) and the Nyquist term — when the shift-angle θ form a full equally spaced grid; otherwise
the lowest blind orders of the heads that a least-squares fit at those θ separates are removed from
both sides and the rest named in the note (:func:`_compared_curves`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchtwin.jsonable import to_json

from . import selfcal as sc
from . import shift_angle as sa
from . import uncertainty as un
from .fourier import harmonic_columns
from .uncertainty import HSIEH2022_TYPE_B

__all__ = ["analyze_polygon", "fourier_resample_arcsec", "HeadsData", "PolygonOptions", "HSIEH2022_TYPE_B"]


# plain JSON types, non-finite floats -> null (benchtwin/jsonable.py)
_json = functools.partial(to_json, nonfinite="null")


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


def _full_grid(theta_deg: np.ndarray) -> bool:
    """True if θ is an equally spaced full-circle grid (sorted, any start)."""
    th = np.sort(np.mod(np.asarray(theta_deg, dtype=float), 360.0))
    n = th.size
    if n < 4:
        return False
    return bool(np.max(np.abs((th - th[0]) - np.arange(n) * 360.0 / n)) < 1e-6)


def _drop_harmonics(theta_deg: np.ndarray, values: np.ndarray, drop: Sequence[int]) -> np.ndarray:
    """Values on an equally spaced full-circle grid without the listed harmonics (and without the
    Nyquist term, which a real grid cannot split into sine and cosine)."""
    th = np.asarray(theta_deg, dtype=float)
    order = np.argsort(np.mod(th, 360.0), kind="stable")
    v = np.asarray(values, dtype=float)[order]
    n = v.size
    C = np.fft.rfft(v)
    k = np.arange(C.size)
    kill = np.isin(k, np.asarray(list(drop), dtype=int))
    if n % 2 == 0:
        kill[-1] = True
    C[kill] = 0.0
    out = np.empty(n)
    out[order] = np.fft.irfft(C, n)
    return out


def _heads_repeatability(ht: Mapping[str, np.ndarray]) -> tuple[np.ndarray | None, float, float]:
    """Pooled repeatability of δ over θ and heads 2…: (u per cell = s/√n, s, ν = Σ(n − 1))."""
    nr, sdv = ht["n_rep"][:, 1:], ht["sd_arcsec"][:, 1:]
    ok = nr >= 2
    dof = float(np.sum(nr[ok] - 1))
    if dof <= 0:
        return None, float("nan"), 0.0
    sp = math.sqrt(float(np.sum((nr[ok] - 1) * sdv[ok] ** 2)) / dof)
    return sp / np.sqrt(np.maximum(ht["n_rep"], 1).astype(float)), sp, dof


@dataclass(frozen=True)
class HeadsData:
    """The self-calibration input of :func:`analyze_polygon`: the heads table (``theta_deg, head,
    delta_arcsec`` + ``rep``, ``direction``), the heads' azimuths from head 1 (deg) and the head sets
    of eq. 9 (None: the maximal equally spaced sets, :func:`.selfcal.equally_spaced_sets`)."""

    table: Mapping[str, np.ndarray]
    heads_deg: Sequence[float] | None
    sets: Mapping[str, Sequence[int]] | None = None


@dataclass(frozen=True)
class PolygonOptions:
    """How :func:`analyze_polygon` estimates β and u(ε), and its budget's coverage and GUM-S1 check.

    ``beta``: where β comes from, a calibrated polygon's pitch deviations among them
    (:class:`.shift_angle.BetaSource`); ``u_eps_arcsec``: the standard
    deviation of ONE reading if known from elsewhere (ν = ∞; None: from the data); ``fit_harmonics``:
    the sec. 3.1 curve-fit check's harmonics; ``p``: coverage probability; ``mc_samples`` draws (0:
    none) seeded by ``mc_seed`` for the GUM-S1 check."""

    beta: sa.BetaSource = sa.BetaSource()
    u_eps_arcsec: float | None = None
    fit_harmonics: Sequence[int] = (2,)
    p: float = 0.95
    mc_samples: int = 100_000
    mc_seed: int = 20220516


@dataclass(frozen=True)
class _Repeatability:
    """u(ε) of one reading (arcsec) with its dof and source, and the table's scatter figures."""

    s_read_arcsec: float | None
    dof: float
    source: str
    fit: Any                  # sa.reading_repeatability's result
    n_rep_min: int
    sd_all_arcsec: np.ndarray
    closure_s_arcsec: float
    closure_dof: int


def _repeatability(table: Any, u_eps_arcsec: float | None, notes: list[str]) -> _Repeatability:
    """The repeatability of one reading (sec. 3.3 (1)): given, or from the residuals of eq. 3 fitted
    to every reading (:func:`.shift_angle.reading_repeatability`); notes appended to ``notes``."""
    n_rep_min = int(min(int(table.n_rep[s][table.n_rep[s] > 0].min()) for s in table.shifts_deg))
    sd_all = np.concatenate([table.sd_arcsec[s][np.isfinite(table.sd_arcsec[s])] for s in table.shifts_deg])
    closure_s, closure_nu = (float("nan"), 0)
    complete = [float(s) for s in table.shifts_deg if table.is_complete(float(s))]
    if complete:
        ref = 0.0 if 0.0 in complete else complete[0]
        closure_s, closure_nu = sa.closure_residual_sd_arcsec(table.eps_arcsec[ref])
    rep = sa.reading_repeatability(table)
    if rep.dropped:
        notes.append(f"repeatability: {len(rep.dropped)} run-rows with a missing reading left out "
                     f"(shift, rep, direction, start face): {rep.dropped[:5]}")
    s_read: float | None
    if u_eps_arcsec is not None:
        s_read, dof_rep, u_src = float(u_eps_arcsec), math.inf, "given u_eps_arcsec (one reading)"
    elif rep.dof > 0 and math.isfinite(rep.s_arcsec):
        s_read, dof_rep = rep.s_arcsec, float(rep.dof)
        u_src = ("residuals of eq. 3 fitted to every reading: α per shift and direction, common β, one offset "
                 "per run-row (clamping, constant hysteresis)")
    else:
        s_read, dof_rep, u_src = None, math.inf, "none (no residual degrees of freedom)"
        notes.append("no residual degrees of freedom for the repeatability of ε (one run, no full table) and no "
                     "u_eps_arcsec: statistical u unavailable")
    return _Repeatability(s_read, dof_rep, u_src, rep, n_rep_min, sd_all, closure_s, closure_nu)


def _curve_fit_check(res: Any, fit_harmonics: Sequence[int], notes: list[str]) -> tuple[list[dict[str, Any]], float]:
    """Sec. 3.1's curve-fit check of the setup errors: its rows and the largest |difference| (arcsec)."""
    try:
        fit_rows = sa.setup_error_by_curve_fit(res, fit_harmonics)
        return fit_rows, max(abs(r["diff_arcsec"]) for r in fit_rows)
    except ValueError as exc:  # e.g. a harmonic aliasing onto the offset
        notes.append(f"curve-fit check skipped: {exc}")
        return [], 0.0


def _data_budget(res: Any, r: _Repeatability, n_faces: int, setup_residual: float, dd: dict[str, Any] | None,
                 type_b: un.TypeBInputs) -> un.UncertaintyBudget:
    """The budget (sec. 3.3) with the pooled repeatability: the worst case over θ of the statistical
    parts, β's sensitivity from the estimator's Jacobian, the direction difference as row (9)."""
    u_e = np.concatenate([s.u_alpha_eps_arcsec for s in res.shifts])
    u_b = np.concatenate([s.u_alpha_beta_arcsec for s in res.shifts])
    u_rep_alpha = float(np.nanmax(u_e)) if np.any(np.isfinite(u_e)) else 0.0
    u_rep_beta = float(np.nanmax(res.u_beta_arcsec)) if np.any(np.isfinite(res.u_beta_arcsec)) else 0.0
    c_beta = None
    if u_rep_beta > 0 and np.any(np.isfinite(u_b)) and np.nanmax(u_b) > 0:
        c_beta = float(np.nanmax(u_b)) / u_rep_beta
    dof_beta = r.dof if res.beta_source == "closure" else math.inf
    inputs = un.ShiftAngleBudgetInputs(
        u_repeat_alpha_arcsec=u_rep_alpha, dof_repeat_alpha=r.dof, n_faces=n_faces, u_repeat_beta_arcsec=u_rep_beta,
        dof_repeat_beta=dof_beta, setup_residual_arcsec=setup_residual, sensitivity_beta=c_beta,
        direction_difference_arcsec=dd["rms_systematic"] if dd is not None else None)
    return un.shift_angle_budget(inputs, type_b)


def _paper_budget(by_rep: dict[str, Any] | None, n_faces: int, setup_residual: float,
                  type_b: un.TypeBInputs) -> un.UncertaintyBudget | None:
    """The paper's own way (sec. 3.3 (1), (7)): the largest sd over the repetitions of the whole method,
    /√n, with n − 1 dof — a worst case over θ (biased high: the maximum of many sample sds), shown
    beside the pooled budget; with it E_n is also given as the paper computes U (one U for all θ).
    None with one repetition."""
    if by_rep is None:
        return None
    nr = by_rep["n_reps"]
    nb = by_rep["n_reps_beta"]
    inputs = un.ShiftAngleBudgetInputs(
        u_repeat_alpha_arcsec=by_rep["max_sd"] / math.sqrt(nr), dof_repeat_alpha=nr - 1, n_faces=n_faces,
        u_repeat_beta_arcsec=by_rep["max_sd_beta"] / math.sqrt(nb) if nb >= 2 else 0.0,
        dof_repeat_beta=max(nb - 1, 1), setup_residual_arcsec=setup_residual)
    return un.shift_angle_budget(inputs, type_b, title="Combined uncertainty, the paper's repeatability (max sd)")


def _monte_carlo_check(budget: un.UncertaintyBudget, mc_samples: int, mc_seed: int) -> dict[str, Any] | None:
    """GUM-S1 check of the budget's interval with ``mc_samples`` draws (None when 0 or u_c = 0)."""
    if not (mc_samples and budget.u_c > 0):
        return None
    mc = budget.monte_carlo(int(mc_samples), rng=np.random.default_rng(mc_seed))
    v = un.validate_gum_with_mc(0.0, budget.U, mc, budget.u_c, ndig=1)
    return {"n": mc.n, "std": mc.std, "shortest": list(mc.shortest), "symmetric": list(mc.symmetric),
            "gum_interval": [-budget.U, budget.U], "delta": v["delta"], "validated_1_digit": v["ok"]}


def _repeatability_out(table: Any, r: _Repeatability, by_rep: dict[str, Any] | None) -> dict[str, Any]:
    """The ``repeatability`` key of :func:`analyze_polygon`'s result."""
    return {"s_reading_arcsec": r.s_read_arcsec, "dof": r.dof if math.isfinite(r.dof) else None,
            "pooled_sd_eps_arcsec": r.s_read_arcsec,  # the same s (pipeline.py's tracing reads this key)
            "u_eps_source": r.source, "n_readings": r.fit.n_readings, "n_run_rows": r.fit.n_rows,
            "max_sd_eps_arcsec": float(np.max(r.sd_all_arcsec)) if r.sd_all_arcsec.size else None,
            "n_rep_min": r.n_rep_min,
            "closure_residual_sd_arcsec": r.closure_s_arcsec, "closure_dof": r.closure_dof,
            "alpha_sd_over_reps_max_arcsec": by_rep["max_sd"] if by_rep else None,
            "n_reps": by_rep["n_reps"] if by_rep else 1,
            "theta_offset_max_deg": table.theta_offset_max_deg}


def _budget_out(budget: un.UncertaintyBudget, budget_paper: un.UncertaintyBudget | None, u_typeb: float, p: float,
                mc_out: dict[str, Any] | None) -> dict[str, Any]:
    """The ``budget``, ``budget_summary`` and ``budget_paper_repeatability`` keys."""
    return {
        "budget": budget.table(),
        "budget_summary": {"u_c": budget.u_c, "nu_eff": budget.nu_eff, "k": budget.k, "U": budget.U, "p": p,
                           "u_type_b": u_typeb, "sensitivity_beta": budget.contributions[6].sensitivity,
                           "monte_carlo": mc_out},
        "budget_paper_repeatability": None if budget_paper is None else
        {"rows": budget_paper.table(), "u_c": budget_paper.u_c, "nu_eff": budget_paper.nu_eff, "k": budget_paper.k,
         "U": budget_paper.U},
    }


def _shift_angle_out(table: Any, res: Any, curve: tuple[np.ndarray, ...]) -> dict[str, Any]:
    """The shift-angle keys of :func:`analyze_polygon`'s result: β, U_j, α per shift and the combined
    curve ``curve`` = (θ, α, u, u_propagated, U)."""
    th, alpha, u_tot, u_prop, U = curve
    return {
        "method": "Hsieh 2022 shift-angle",
        "n_faces": table.n_faces,
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
        "encoder_error_arcsec": {"theta_deg": th, "value": alpha, "u": u_tot, "u_propagated": u_prop, "U": U},
    }


def _direction_out(dd: dict[str, Any] | None) -> dict[str, Any] | None:
    """The ``direction_difference`` key (:func:`.shift_angle.direction_difference`; None without u(ε))."""
    if dd is None:
        return None
    return {k_: dd[k_] for k_ in ("directions", "theta_deg", "value", "u", "chi2", "dof", "p_value", "rms",
                                  "rms_systematic", "max_abs", "offset_arcsec")}


def _runs_scatter(tab: Mapping[str, np.ndarray], heads_deg: Sequence[float], sets: Mapping[str, Sequence[int]] | None,
                  n_seen: int) -> tuple[float, int, float] | None:
    """Type A of the self-calibration from its own repetitions: eq. 9 on each run (one ``rep`` and
    ``direction``) alone, the pooled standard deviation s of the runs' estimates over θ and the runs,
    (s/√R, R, ν = (R − 1)·``n_seen``); None with fewer than two complete runs.

    Unlike the propagation of s(δ) (:func:`_heads_repeatability`, independent δ per head), this holds
    what the heads share at one instant: the axis' motion between runs reads into all of them at once
    (m₁ − m_j in every δ_j), so its errors are correlated across heads and its effect on â is not the
    independent-reading one. ``n_seen``: the real Fourier parameters eq. 9 estimates (the dof per run)."""
    cols = [np.asarray(tab[c]).ravel() for c in ("rep", "direction") if tab.get(c) is not None]
    if not cols:
        return None
    keys = list(zip(*cols))
    runs = sorted(set(keys), key=str)
    if len(runs) < 2:
        return None
    th_all = np.asarray(tab["theta_deg"], dtype=float).ravel()
    hd_all = np.asarray(tab["head"]).ravel()
    dl_all = np.asarray(tab["delta_arcsec"], dtype=float).ravel()
    vals = []
    for run in runs:
        sel = np.array([k_ == run for k_ in keys])
        try:
            t = sc.tabulate_heads(th_all[sel], hd_all[sel], dl_all[sel], len(heads_deg))
            vals.append(sc.selfcal_fourier(t["theta_deg"], heads_deg, t["delta_arcsec"], sets=sets,
                                           u_delta_arcsec=1.0).value_arcsec)
        except ValueError:  # an incomplete run (missing cells, another θ grid): no run-level scatter
            return None
    V = np.array(vals)
    if len({v.size for v in vals}) != 1:
        return None
    R = V.shape[0]
    s = math.sqrt(float(np.mean(np.var(V, axis=0, ddof=1))))
    return s / math.sqrt(R), R, float((R - 1) * n_seen)


def _selfcal(heads: HeadsData, encoder_resolution_arcsec: float, p: float, notes: list[str]) -> tuple[Any, ...]:
    """Eq. 9 on the heads table: (the self-calibration result, its u per θ, k, dof, s(δ), the sets, the
    parts of u).

    u(θ) = √(u_A² + u_interp² + u_res²): u_A the type A of â — from the scatter of the runs' own
    estimates (:func:`_runs_scatter`) where the table has two runs or more, else the propagation of
    s(δ) (between repetitions of a cell, or the residuals of eq. 9 where the sets are redundant);
    u_interp the off-grid sets' interpolation error (:func:`.selfcal.selfcal_fourier`); u_res the
    encoder resolution (rectangular). With one run and no redundancy (one set of NH heads) eq. 9 has
    no residual: u(δ) is then the quantization of its two readings, √2·res/√12 (type B, ν = ∞)."""
    if heads.heads_deg is None:
        raise ValueError("heads table given without heads_deg (head azimuths from head 1)")
    heads_deg = heads.heads_deg
    tab = heads.table
    ht = sc.tabulate_heads(tab["theta_deg"], tab["head"], tab["delta_arcsec"], len(heads_deg), rep=tab.get("rep"),
                           direction=tab.get("direction"))
    sets: dict[str, Sequence[int]] | None = dict(heads.sets if heads.sets else sc.equally_spaced_sets(heads_deg))
    if not sets:
        sets = None
        notes.append("self-calibration: no equally spaced head sets; every head on its own (its δ also carries "
                     "the axis' radial error motion, which set averages would cancel)")
    u_d, s_d, dof_d = _heads_repeatability(ht)
    scr = sc.selfcal_fourier(ht["theta_deg"], heads_deg, ht["delta_arcsec"], sets=sets, u_delta_arcsec=u_d)
    u_res = encoder_resolution_arcsec / (2 * math.sqrt(3.0))
    dof_self = dof_d if u_d is not None else scr.dof
    a_source = "propagated s(δ) between repetitions" if u_d is not None else "propagated residuals of eq. 9"
    if u_d is None and not math.isfinite(scr.sigma_delta_arcsec):
        if u_res > 0:
            u_fb, a_source = math.sqrt(2.0) * u_res, "quantization of δ's two readings √2·res/√12 (type B; no residual dof)"
            notes.append("self-calibration: one run and no redundant head set (eq. 9 has no residual): u(δ) is the "
                         "quantization of its two readings only; nothing in the data shows the heads' noise")
        else:
            # no resolution either: the single heads' residuals from the set estimate, an upper bound
            # (they also hold what the set average cancels, e.g. the axis' radial error motion)
            u_fb, a_source = scr.residual_rms_arcsec, "single heads' residual RMS (upper bound; no residual dof)"
            notes.append("self-calibration: one run, no redundant head set and no encoder resolution: u(δ) is the "
                         "single heads' residual RMS, an upper bound")
        # a residual at rounding level (exact data, or 2 heads: eq. 9 fits head 2's δ exactly) shows nothing
        if math.isfinite(u_fb) and u_fb > 1e-9 * float(np.sqrt(np.mean(ht["delta_arcsec"] ** 2))):
            scr = sc.selfcal_fourier(ht["theta_deg"], heads_deg, ht["delta_arcsec"], sets=sets, u_delta_arcsec=u_fb)
            dof_self = math.inf
    n = scr.theta_deg.size
    n_seen = n - 1 - 2 * int(scr.unobservable_harmonics.size) - (1 if n % 2 == 0 else 0)
    runs = _runs_scatter(tab, heads_deg, sets, n_seen)
    u_interp = float(scr.u_model_arcsec)
    u_prop = np.sqrt(np.maximum(scr.u_arcsec**2 - u_interp**2, 0.0))
    if runs is not None:
        u_a: np.ndarray = np.full(n, runs[0])
        dof_self, a_source = runs[2], f"scatter of the {runs[1]} runs' own estimates (s/√R)"
    else:
        u_a = u_prop
    u_self = np.sqrt(u_a**2 + u_interp**2 + u_res**2)
    k_self = un.coverage_factor(dof_self if dof_self >= 1 else math.inf, p)
    notes += scr.notes
    parts = {"u_type_a_arcsec": float(np.max(u_a)), "type_a_source": a_source,
             "u_propagated_max_arcsec": float(np.nanmax(u_prop)) if np.any(np.isfinite(u_prop)) else None,
             "u_runs_arcsec": runs[0] if runs else None, "n_runs": runs[1] if runs else 1,
             "u_interpolation_arcsec": u_interp, "u_resolution_arcsec": u_res}
    return scr, u_self, k_self, dof_self, s_d, sets, parts


def _compared_curves(th: np.ndarray, alpha: np.ndarray, scr: Any, N: int,
                     notes: list[str]) -> tuple[np.ndarray, np.ndarray, str]:
    """Both methods on the harmonics both see: not the multiples of N (shift-angle, eq. 2), not those
    the heads cannot see (self-calibration), not the Nyquist term. (shift-angle α, self-cal at θ, note)."""
    blind_sa = [m for m in range(N, 100_000, N)]
    drop = sorted(set(blind_sa) | {int(x) for x in scr.unobservable_harmonics})
    if _full_grid(th):
        n_sa = th.size
        alpha_cmp = _drop_harmonics(th, alpha, [m for m in drop if m <= n_sa // 2])
        mu_at = _drop_harmonics(th, fourier_resample_arcsec(scr.theta_deg, scr.value_arcsec, th),
                                [m for m in drop if m <= n_sa // 2])
        cmp_note = (f"compared without the harmonics multiples of N = {N} (shift-angle) and "
                    f"{[int(x) for x in scr.unobservable_harmonics]} (self-calibration), and the Nyquist term")
    else:
        mu_at = fourier_resample_arcsec(scr.theta_deg, scr.value_arcsec, th, drop_multiples_of=N)
        ks = _fit_orders(th, [int(x) for x in scr.unobservable_harmonics if int(x) % N])
        if ks:
            A = np.column_stack([np.ones(th.size), harmonic_columns(th, ks)[0]])
            alpha_cmp = alpha - A @ np.linalg.lstsq(A, alpha, rcond=None)[0]
            mu_at = mu_at - A @ np.linalg.lstsq(A, mu_at, rcond=None)[0]
        else:
            alpha_cmp = alpha
        unob = [int(x) for x in scr.unobservable_harmonics]
        rest = [k for k in unob if k % N and k not in ks]
        cmp_note = (f"shift-angle θ not a full equally spaced grid: self-calibration evaluated at its θ without "
                    f"the multiples of N = {N}; of the harmonics the heads cannot see, orders {ks} fitted (least "
                    f"squares at the {th.size} θ, with the mean) and removed from both sides"
                    + (f"; orders {rest[:5]}{'…' if len(rest) > 5 else ''} not (too many for the θ), their part of "
                       f"the shift-angle α stays in the difference" if rest else ""))
        notes.append(cmp_note)
    return alpha_cmp, mu_at, cmp_note


def _fit_orders(theta_deg: np.ndarray, orders: Sequence[int], max_cond: float = 10.0) -> list[int]:
    """The lowest of ``orders`` that a least-squares fit at ``theta_deg`` (not a full grid) separates:
    with the mean at most a third as many parameters as points, and a well-conditioned design
    (condition number ≤ ``max_cond``: the orders nearly orthogonal on these θ, so the fit takes little
    of the other orders with them)."""
    th = np.asarray(theta_deg, dtype=float)
    ks: list[int] = []
    for k in sorted(orders):
        if 1 + 2 * (len(ks) + 1) > th.size / 3:
            break
        A = np.column_stack([np.ones(th.size), harmonic_columns(th, ks + [k])[0]])
        if np.linalg.cond(A) > max_cond:
            break
        ks.append(k)
    return ks


def _curve_blind(scr: Any) -> list[int]:
    """The harmonics the self-calibration curve holds at 0: those no set sees and, on an even grid, the
    Nyquist term n/2, which eq. 9 does not estimate (on the suite's 5° hsieh2022 grid the graduation's
    content above it folds into that term: 0.034″ of α at seed 22, all of the error against truth
    beyond the 0.009″ of the rest)."""
    n = int(scr.theta_deg.size)
    return [int(x) for x in scr.unobservable_harmonics] + ([n // 2] if n % 2 == 0 else [])


def _selfcal_out(heads: HeadsData, curve: tuple[np.ndarray, ...], N: int, budgets: tuple[Any, ...],
                 encoder_resolution_arcsec: float, notes: list[str]) -> dict[str, Any]:
    """Self-calibration and the comparison (sec. 3.2, eq. 13): the keys ``selfcal_error_arcsec``,
    ``selfcal``, ``difference_arcsec``, ``en_max`` (and ``en_max_paper_budget``). ``curve`` = (θ, α,
    U of α); ``budgets`` = (p, the paper's budget or None)."""
    th, alpha, U_alpha = curve
    p, budget_paper = budgets
    scr, u_self, k_self, dof_self, s_d, sets, parts = _selfcal(heads, encoder_resolution_arcsec, p, notes)
    alpha_cmp, mu_at, cmp_note = _compared_curves(th, alpha, scr, N, notes)
    u_self_at = np.interp(th, scr.theta_deg, u_self, period=360.0)
    diff = alpha_cmp - mu_at
    en = un.en_number(alpha_cmp, U_alpha, mu_at, k_self * u_self_at)
    out: dict[str, Any] = {}
    # the curve states its measurand: α without the harmonics no head set sees (set to 0 here; the
    # scorer and any comparison leave them out, as α of the shift-angle method without the k·N)
    out["selfcal_error_arcsec"] = {"theta_deg": scr.theta_deg, "value": scr.value_arcsec, "u": u_self,
                                   "U": k_self * u_self, "unobservable_harmonics": _curve_blind(scr)}
    out["selfcal"] = {"k": k_self, "dof": dof_self, "s_delta_arcsec": s_d, "u_parts": parts,
                      "sigma_delta_residual_arcsec": scr.sigma_delta_arcsec, "residual_dof": scr.dof,
                      "head_residual_rms_arcsec": scr.residual_rms_arcsec,
                      "set_residual_rms_arcsec": scr.set_residual_rms_arcsec, "set_on_grid": scr.set_on_grid,
                      "unobservable_harmonics": scr.unobservable_harmonics,
                      "sets": sets, "per_set_arcsec": scr.per_set_arcsec}
    out["difference_arcsec"] = {"theta_deg": th, "value": diff, "shift_angle_compared": alpha_cmp,
                                "selfcal_at_theta": mu_at, "en": en, "note": cmp_note,
                                "removed_from_shift_angle_rms": float(np.sqrt(np.mean((alpha - alpha_cmp) ** 2))),
                                "max_abs": float(np.max(np.abs(diff)))}
    out["en_max"] = float(np.max(en))
    out["difference_arcsec"]["fraction_en_above_1"] = float(np.mean(en > 1.0))
    if budget_paper is not None:
        en_p = un.en_number(alpha_cmp, budget_paper.U, mu_at, k_self * u_self_at)
        out["en_max_paper_budget"] = float(np.max(en_p))
    return out


def analyze_polygon(columns: Mapping[str, np.ndarray], n_faces: int, heads: HeadsData | None = None, *,
                    type_b: un.TypeBInputs = HSIEH2022_TYPE_B, options: PolygonOptions | None = None) -> dict[str, Any]:
    """Analyse a polygon table (and optionally a heads table) with the Hsieh 2022 methods.

    ``columns``: ``shift_deg, start_face, step, ac_arcsec`` (+ ``theta_deg``, ``t_s``, ``rep``,
    ``direction``; ``t_s`` is not used). ``heads``: the heads table with the heads' azimuths and sets
    (:class:`HeadsData`). ``type_b``: the budget's declared inputs in arcsec (defaults
    :data:`HSIEH2022_TYPE_B`, Hsieh sec. 3.3: ELCOMAT 3000 resolution 0.001″, traceability U = 0.01″
    (k = 2), maximum error 0.05″, setup misalignment 0.05″; the encoder resolution comes from the
    bench, 0 if unknown). ``options``: the certificate of the polygon, u of one reading if known, the
    curve-fit harmonics, coverage and the GUM-S1 check (:class:`PolygonOptions`).

    Raises :class:`.shift_angle.PolygonDataError` for unusable polygon readings.
    """
    opt = options if options is not None else PolygonOptions()
    need = [c for c in ("shift_deg", "start_face", "step", "ac_arcsec") if c not in columns]
    if need:
        raise sa.PolygonDataError(f"polygon columns missing: {need} (has {sorted(columns)})")
    table = sa.tabulate_polygon(columns, n_faces)
    N = table.n_faces
    notes: list[str] = []
    r = _repeatability(table, opt.u_eps_arcsec, notes)
    res = sa.shift_angle_analysis(table, beta_from=opt.beta, s_reading_arcsec=r.s_read_arcsec)
    notes += res.notes
    th, alpha, u_prop = sa.combined_curve(res)
    fit_rows, setup_residual = _curve_fit_check(res, opt.fit_harmonics, notes)
    # direction difference and the paper's scatter of α over the repetitions
    dd = sa.direction_difference(table, res.beta_arcsec, r.s_read_arcsec) if r.s_read_arcsec is not None else None
    by_rep = sa.alpha_scatter_by_rep(table, res.beta_arcsec)
    budget = _data_budget(res, r, N, setup_residual, dd, type_b)
    budget.p = opt.p
    stat_names = {"Repeatability of angle error measurement", "Repeatability of the pitch angle deviation measurement"}
    u_typeb = math.sqrt(sum(c.contribution**2 for c in budget.contributions if c.name not in stat_names))
    u_prop0 = np.where(np.isfinite(u_prop), u_prop, 0.0)
    u_tot = np.sqrt(u_prop0**2 + u_typeb**2)
    k = budget.k
    budget_paper = _paper_budget(by_rep, N, setup_residual, type_b)
    if budget_paper is not None:
        budget_paper.p = opt.p
    mc_out = _monte_carlo_check(budget, opt.mc_samples, opt.mc_seed)
    out: dict[str, Any] = _shift_angle_out(table, res, (th, alpha, u_tot, u_prop, k * u_tot))
    out["curve_fit"] = fit_rows
    out["repeatability"] = _repeatability_out(table, r, by_rep)
    out["direction_difference"] = _direction_out(dd)
    out.update(_budget_out(budget, budget_paper, u_typeb, opt.p, mc_out))
    out.update(selfcal_error_arcsec=None, difference_arcsec=None, en_max=None, en_max_paper_budget=None)
    if res.beta_closure_arcsec is not None:
        out["certificate_minus_closure_arcsec"] = res.beta_arcsec - res.beta_closure_arcsec
    if heads is not None:  # self-calibration and comparison (sec. 3.2, eq. 13)
        out.update(_selfcal_out(heads, (th, alpha, k * u_tot), N, (opt.p, budget_paper),
                                type_b.encoder_resolution_arcsec, notes))
    out["notes"] = notes
    return _json(out)
