"""Positioning statistics of the rotary axis, ISO 230-2:2014 (the figures CARTO reports; VDI/DGQ 3441's
own P, Pa, U, Ps are not computed here): accuracy A, systematic deviation E, mean bidirectional range M, repeatability R,
reversal value B and the mean reversal value, unidirectional (↑ forward, ↓ backward) and
bidirectional, from runs in both directions over the same target positions.

Definitions (ISO 230-2:2014 clause 3; i = target position 1…m, j = run 1…n, ↑/↓ = direction):

- positional deviation x_ij = actual position reached − target position P_i. On this bench the
  axis is positioned by the encoder (its display shows P_i) and the reference measures the actual
  angle, so **x = −α** (α = encoder reading − reference angle, docs/conventions.md);
- mean unidirectional positional deviation x̄_i↑ = (1/n) Σ_j x_ij↑ (x̄_i↓ alike);
- mean bidirectional positional deviation x̄_i = (x̄_i↑ + x̄_i↓)/2;
- reversal value B_i = x̄_i↑ − x̄_i↓; of the axis B = max |B_i|; mean reversal value B̄ = (1/m) Σ B_i;
- estimator of the unidirectional repeatability s_i↑ = √(Σ_j (x_ij↑ − x̄_i↑)² / (n − 1));
- unidirectional repeatability R_i↑ = 4 s_i↑; bidirectional R_i = max(2 s_i↑ + 2 s_i↓ + |B_i|, R_i↑, R_i↓);
  of the axis R↑ = max R_i↑, R↓ = max R_i↓, R = max R_i;
- unidirectional systematic positional deviation E↑ = max x̄_i↑ − min x̄_i↑ (E↓ alike);
  bidirectional E = max(x̄_i↑, x̄_i↓) − min(x̄_i↑, x̄_i↓);
- mean bidirectional positional deviation range M = max x̄_i − min x̄_i;
- unidirectional accuracy A↑ = max(x̄_i↑ + 2 s_i↑) − min(x̄_i↑ − 2 s_i↑) (A↓ alike);
  bidirectional A = max(x̄_i↑ + 2 s_i↑, x̄_i↓ + 2 s_i↓) − min(x̄_i↑ − 2 s_i↑, x̄_i↓ − 2 s_i↓).

ISO 230-2 asks for 5 runs in each direction (clause 4.3.2 / 5.3.2 for rotary axes). With fewer the
figures are computed and flagged; with one run in a direction there is no s, so R and A (which
contain ±2s) are null and say why. The figures are statistics of the measured deviations: the
measurement uncertainty of the reference (ISO 230-9) is not in them.

Runs from the data:

- an error-curve dataset (``error_curve.csv`` with ``direction``): one run per direction at the
  angles measured in both;
- a polygon table (``polygon.csv`` with ``direction`` [and ``rep``]): each clamping (shift S,
  repetition, start face j) swept in both directions (hw/acquisition/procedures.polygon_traditional:
  "backward: i = N…1, same mounting") is one run per direction: x_i = −(ε_ij − B_ji − U) with the
  common pitch deviations β (Hsieh 2022 eq. 3, B_ji their cumulative sums) and one setup constant U
  per clamping, the mean of ε − B over both directions (eq. 7 on the bidirectional mean: the
  circle closes on the average of the two directions, and a constant reversal between them, a
  backlash, stays in B). The shift with the most such clampings is used; target positions are
  (i − 1)·360°/N + S. A harmonic of order k·N of α is absorbed by U (Hsieh's method cannot see it)
  and is missing from these deviations as well.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["positioning_statistics", "runs_from_polygon", "runs_from_error_curve", "RUNS_REQUIRED", "FIGURES"]

#: runs per direction ISO 230-2 prescribes
RUNS_REQUIRED = 5

#: each figure: (key, symbol, what it is)
FIGURES: tuple[tuple[str, str, str], ...] = (
    ("A", "A", "bidirectional accuracy of positioning: max(x̄↑ + 2s↑, x̄↓ + 2s↓) − min(x̄↑ − 2s↑, x̄↓ − 2s↓)"),
    ("A_forward", "A↑", "unidirectional accuracy of positioning, forward: max(x̄↑ + 2s↑) − min(x̄↑ − 2s↑)"),
    ("A_backward", "A↓", "unidirectional accuracy of positioning, backward: max(x̄↓ + 2s↓) − min(x̄↓ − 2s↓)"),
    ("E", "E", "bidirectional systematic positional deviation: max(x̄↑, x̄↓) − min(x̄↑, x̄↓)"),
    ("E_forward", "E↑", "unidirectional systematic positional deviation, forward: max x̄↑ − min x̄↑"),
    ("E_backward", "E↓", "unidirectional systematic positional deviation, backward: max x̄↓ − min x̄↓"),
    ("M", "M", "mean bidirectional positional deviation range: max x̄ − min x̄, x̄ = (x̄↑ + x̄↓)/2"),
    ("R", "R", "bidirectional repeatability of positioning: max over positions of "
               "max(2s↑ + 2s↓ + |B_i|, 4s↑, 4s↓)"),
    ("R_forward", "R↑", "unidirectional repeatability of positioning, forward: max 4s↑"),
    ("R_backward", "R↓", "unidirectional repeatability of positioning, backward: max 4s↓"),
    ("B", "B", "reversal value of the axis: max |B_i|, B_i = x̄↑ − x̄↓"),
    ("B_mean", "B̄", "mean reversal value: the mean of B_i over the positions"),
)


def positioning_statistics(target_deg, forward_arcsec, backward_arcsec, *, source: str) -> dict[str, Any]:
    """ISO 230-2 figures from positional deviations x (arcsec; module docstring): ``forward_arcsec``
    and ``backward_arcsec`` are (runs × positions) arrays at the targets ``target_deg``. Returns the
    JSON-ready section ``iso230_2``: figures {key: {symbol, value, unit, what}}, per-position values,
    runs per direction, flags."""
    P = np.asarray(target_deg, dtype=float).ravel()
    up = np.atleast_2d(np.asarray(forward_arcsec, dtype=float))
    dn = np.atleast_2d(np.asarray(backward_arcsec, dtype=float))
    m = P.size
    if up.shape[1] != m or dn.shape[1] != m:
        raise ValueError(f"{m} target positions, runs of {up.shape[1]} (forward) and {dn.shape[1]} (backward) points")
    if m < 2 or up.shape[0] < 1 or dn.shape[0] < 1:
        raise ValueError("ISO 230-2 needs at least 2 target positions and a run in each direction")
    if not (np.all(np.isfinite(up)) and np.all(np.isfinite(dn))):
        raise ValueError("positional deviations must be finite")
    n_up, n_dn = up.shape[0], dn.shape[0]
    xu, xd = up.mean(axis=0), dn.mean(axis=0)
    su = up.std(axis=0, ddof=1) if n_up >= 2 else np.full(m, np.nan)
    sd = dn.std(axis=0, ddof=1) if n_dn >= 2 else np.full(m, np.nan)
    Bi = xu - xd
    xm = 0.5 * (xu + xd)
    hi_ud, lo_ud = np.maximum(xu, xd), np.minimum(xu, xd)
    val: dict[str, float] = {
        "E_forward": float(np.ptp(xu)), "E_backward": float(np.ptp(xd)),
        "E": float(hi_ud.max() - lo_ud.min()), "M": float(np.ptp(xm)),
        "B": float(np.max(np.abs(Bi))), "B_mean": float(np.mean(Bi)),
        "R_forward": float(np.max(4 * su)) if n_up >= 2 else math.nan,
        "R_backward": float(np.max(4 * sd)) if n_dn >= 2 else math.nan,
        "A_forward": float(np.max(xu + 2 * su) - np.min(xu - 2 * su)) if n_up >= 2 else math.nan,
        "A_backward": float(np.max(xd + 2 * sd) - np.min(xd - 2 * sd)) if n_dn >= 2 else math.nan,
    }
    if n_up >= 2 and n_dn >= 2:
        Ri = np.maximum(2 * su + 2 * sd + np.abs(Bi), np.maximum(4 * su, 4 * sd))
        val["R"] = float(np.max(Ri))
        val["A"] = float(max(np.max(xu + 2 * su), np.max(xd + 2 * sd)) - min(np.min(xu - 2 * su), np.min(xd - 2 * sd)))
    else:
        Ri = np.full(m, np.nan)
        val["R"] = val["A"] = math.nan
    flags = []
    if min(n_up, n_dn) < RUNS_REQUIRED:
        flags.append(f"{n_up} forward and {n_dn} backward runs: ISO 230-2 asks for {RUNS_REQUIRED} in each direction; "
                     "the figures are computed from the runs there are")
    if min(n_up, n_dn) < 2:
        flags.append("a direction with one run has no repeatability estimate s: R and A (which contain ±2s) are not "
                     "computed (null)" + ("" if max(n_up, n_dn) < 2 else "; R and A of the direction with "
                                          "repetitions are"))
    figures = {k: {"symbol": sym, "value": val[k], "unit": "arcsec", "what": what} for k, sym, what in FIGURES}
    return {
        "standard": "ISO 230-2:2014 (accuracy and repeatability of positioning of numerically controlled axes; "
                    "rotary axis); VDI/DGQ 3441's own figures (P, Pa, U, Ps) are not computed",
        "convention": "positional deviation x = actual position − target position = −α (the axis positioned by the "
                      "encoder, the actual angle from the reference); arcsec",
        "source": source, "target_deg": P, "n_positions": int(m),
        "n_runs": {"forward": int(n_up), "backward": int(n_dn)}, "runs_required_per_direction": RUNS_REQUIRED,
        "meets_run_count": bool(min(n_up, n_dn) >= RUNS_REQUIRED),
        "figures": figures,
        "per_position": {"mean_forward_arcsec": xu, "mean_backward_arcsec": xd, "mean_bidirectional_arcsec": xm,
                         "s_forward_arcsec": su, "s_backward_arcsec": sd, "reversal_arcsec": Bi,
                         "R_bidirectional_arcsec": Ri},
        "flags": flags,
        "excludes": "the measurement uncertainty of the reference (ISO 230-9): these are statistics of the measured "
                    "deviations only",
    }


def runs_from_error_curve(theta_deg, error_arcsec, direction) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(targets, forward runs, backward runs) of an error-curve table: one run per direction at the
    angles measured in both, x = −α; None without two directions or fewer than 2 common angles."""
    if direction is None:
        return None
    th = np.round(np.mod(np.asarray(theta_deg, dtype=float), 360.0), 9)
    err = np.asarray(error_arcsec, dtype=float)
    d = np.asarray(direction, dtype=object)
    f, b = d == "forward", d == "backward"
    common, i_f, i_b = np.intersect1d(th[f], th[b], return_indices=True)
    if common.size < 2:
        return None
    return common, -err[f][i_f][None, :], -err[b][i_b][None, :]


def runs_from_polygon(table: Any, beta_arcsec) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, Any]] | None:
    """(targets, forward runs, backward runs, how) of a polygon table (analysis.shift_angle.PolygonTable)
    with the common pitch deviations β (module docstring); None without a clamping measured completely
    in both directions."""
    from .shift_angle import cumulative_pitch_sum_arcsec, nominal_theta_deg

    N = table.n_faces
    B = cumulative_pitch_sum_arcsec(np.asarray(beta_arcsec, dtype=float))
    best: tuple[int, float] | None = None
    for S in table.shifts_deg:
        runs = table.runs.get(float(S), {})
        reps = sorted({k[0] for k in runs})
        n = sum(1 for r in reps for j in range(N)
                if all((r, d) in runs and np.all(np.isfinite(runs[(r, d)][j])) for d in ("forward", "backward")))
        if n and (best is None or n > best[0]):
            best = (n, float(S))
    if best is None:
        return None
    S = best[1]
    runs = table.runs[S]
    up, dn, setups = [], [], []
    for r in sorted({k[0] for k in runs}):
        for j in range(N):
            rows = {d: runs.get((r, d)) for d in ("forward", "backward")}
            if any(t is None or not np.all(np.isfinite(t[j])) for t in rows.values()):
                continue
            rf, rb = rows["forward"][j] - B[j], rows["backward"][j] - B[j]
            U = 0.5 * (rf.mean() + rb.mean())  # one setup constant for the clamping, both directions
            up.append(-(rf - U))
            dn.append(-(rb - U))
            setups.append((r, j + 1))
    how = {"shift_deg": S, "clampings": len(setups),
           "note": f"each clamping (repetition, start face) at S = {S:g}° swept in both directions is one run per "
                   "direction; x = −(ε − Σβ − U), U per clamping from both directions"}
    return nominal_theta_deg(N, S), np.asarray(up), np.asarray(dn), how
