"""Figures like Hsieh, Watanabe, Hsu 2022 (Appl. Sci. 12, 5008) figs. 6, 7, 9, 11, 12.

Each function takes the results dict of :func:`benchtwin.analysis.hsieh_pipeline.analyze_polygon` and
returns a matplotlib ``Figure`` (Agg canvas, nothing shown, nothing written).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure

__all__ = [
    "figure_pitch_deviation",
    "figure_alpha_at_shifts",
    "figure_curve_fits",
    "figure_selfcal_vs_shift_angle",
    "figure_difference",
]


def _arr(x: Any) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in (x or [])], dtype=float)


def _pick_shifts(results: Mapping[str, Any], shifts: Sequence[float] | None, n: int = 3) -> list[str]:
    keys = sorted(results["alpha_by_shift_arcsec"], key=float)
    if shifts is None:
        want = [k for k in keys if float(k) in (0.0, 5.0, 10.0)]
        return want if len(want) >= 2 else keys[:n]
    return [k for k in keys if float(k) in {float(s) for s in shifts}]


def figure_pitch_deviation(results: Mapping[str, Any]) -> Figure:
    """Fig. 6: pitch deviation β per face (with standard uncertainty where known)."""
    b = _arr(results["polygon_pitch_deviation_arcsec"])
    u = _arr(results.get("polygon_pitch_deviation_u_arcsec"))
    faces = np.arange(1, b.size + 1)
    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot()
    ax.errorbar(faces, b, yerr=u if u.size == b.size and np.any(np.isfinite(u)) else None, fmt="o-", capsize=3)
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_xlabel("face")
    ax.set_ylabel("pitch angle deviation β (arcsec)")
    ax.set_title(f"Polygon pitch deviations ({results.get('beta_source', '')})")
    ax.set_xticks(faces if b.size <= 36 else faces[:: max(1, b.size // 24)])
    return fig


def figure_alpha_at_shifts(results: Mapping[str, Any], shifts: Sequence[float] | None = None) -> Figure:
    """Fig. 7: encoder error α at a few shift angles (default S = 0, 5, 10 if present)."""
    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot()
    for key, m in zip(_pick_shifts(results, shifts), "o*s^vD"):
        d = results["alpha_by_shift_arcsec"][key]
        th, a = _arr(d["theta_deg"]), _arr(d["value"])
        o = np.argsort(th)
        ax.plot(th[o], a[o], marker=m, label=f"S = {key}°")
    ax.set_xlabel("θ (deg)")
    ax.set_ylabel("angle error α (arcsec)")
    ax.set_xlim(0, 360)
    ax.legend()
    ax.set_title("Shift-angle method: α at the shift angles")
    return fig


def figure_curve_fits(results: Mapping[str, Any], shifts: Sequence[float] | None = None) -> Figure:
    """Fig. 9: measured values α + U_j at a few shifts and the sec. 3.1 fit A·sin(2θ + B) + U(fitting)."""
    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot()
    rows = results.get("curve_fit") or []
    fine = np.linspace(0, 360, 721)
    for key, m in zip(_pick_shifts(results, shifts), "o*s^vD"):
        d = results["alpha_by_shift_arcsec"][key]
        th, a = _arr(d["theta_deg"]), _arr(d["value"])
        U0 = _arr(results["setup_error_arcsec"][key])[0]
        o = np.argsort(th)
        pts = ax.plot(th[o], a[o] + U0, ls="none", marker=m, label=f"S = {key}° measured")[0]
        row = next((r for r in rows if float(r["shift_deg"]) == float(key)), None)
        if row is not None and row.get("A_arcsec") is not None:
            y = row["A_arcsec"] * np.sin(2 * np.deg2rad(fine) + row["B_rad"]) + row["U_fit_arcsec"]
            ax.plot(fine, y, color=pts.get_color(), label=f"S = {key}° fit, U = {row['U_fit_arcsec']:.4f}″")
    ax.set_xlabel("θ (deg)")
    ax.set_ylabel("α + U (arcsec)")
    ax.set_xlim(0, 360)
    ax.legend(fontsize="small")
    ax.set_title("Curve fitting check of the setup error")
    return fig


def figure_selfcal_vs_shift_angle(results: Mapping[str, Any]) -> Figure:
    """Fig. 11: self-calibration (red dashed) and shift-angle method (blue solid)."""
    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot()
    e = results["encoder_error_arcsec"]
    ax.plot(_arr(e["theta_deg"]), _arr(e["value"]), "b-", label="shift-angle method")
    s = results.get("selfcal_error_arcsec")
    if s:
        ax.plot(_arr(s["theta_deg"]), _arr(s["value"]), "r--", label="self-calibration")
    ax.set_xlabel("θ (deg)")
    ax.set_ylabel("angle error (arcsec)")
    ax.set_xlim(0, 360)
    ax.legend()
    ax.set_title("Self-calibration and shift-angle method")
    return fig


def figure_difference(results: Mapping[str, Any]) -> Figure:
    """Fig. 12: shift-angle − self-calibration, with the combined expanded uncertainty band and E_n."""
    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot()
    d = results.get("difference_arcsec")
    if d:
        th, v = _arr(d["theta_deg"]), _arr(d["value"])
        ax.plot(th, v, "k-", lw=1, label="shift-angle − self-calibration")
        U1 = _arr(results["encoder_error_arcsec"]["U"])
        s = results["selfcal_error_arcsec"]
        U2 = np.interp(th, _arr(s["theta_deg"]), _arr(s["U"]), period=360.0)
        band = np.sqrt(U1**2 + U2**2)
        ax.fill_between(th, -band, band, color="0.85", label="±√(U₁² + U₂²)")
        en_max = results.get("en_max")  # None when E_n is undefined (2 heads: no u of the self-calibration)
        ax.set_title(f"Difference (max E_n = {en_max:.2f})" if en_max is not None else
                     "Difference (E_n undefined: the self-calibration has no uncertainty)")
        ax.legend(fontsize="small")
    else:
        ax.text(0.5, 0.5, "no self-calibration data", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("θ (deg)")
    ax.set_ylabel("difference (arcsec)")
    ax.set_xlim(0, 360)
    return fig
