"""report.html of an error-curve dataset (an imported α(θ) table; analysis/pipeline.py
analyze_error_curve_dataset): the summary, the harmonics, what a lone curve cannot separate, the
periods over an arc, the ISO 230-2 statistics and the curve itself."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.analysis.calibration import CalibrationCurve
from benchtwin.analysis.dataset import Dataset
from benchtwin.analysis.report.bench_report import add_iso230_2_table
from benchtwin.analysis.steps import ErrorCurveAnalysis

__all__ = ["write_error_curve_report"]


def add_arc_periods(rep: Any, arc: Mapping[str, Any]) -> None:
    """The periods over an arc: a table and the periodogram (analysis.arc_periods)."""
    import matplotlib.pyplot as plt

    from benchtwin.analysis.report.html import value_with_u

    sc = arc["scan"]
    rep.heading("Periodic components over the arc", level=3)
    if "period_min_deg" not in sc:
        rep.paragraph(f"No period scan: {sc.get('reason', '')}", note=True)
        return
    rep.paragraph(f"{sc['method']}; periods {sc['period_min_deg']:.3g}°…{sc['period_max_deg']:.3g}° "
                  f"({sc['n_trial_periods']} trial periods); false alarm: {sc['false_alarm_method']}; kept below "
                  f"{sc['significance']:g}. u: {sc['u_source']}. No harmonic of the turn and no closure is claimed.")
    if sc.get("band_limited"):
        rep.paragraph(f"Band limited: {sc['band_limited']}.", note=True)
    if arc["periods"]:
        rep.table([[value_with_u(p["period_deg"], p["u_period_deg"], "°"),
                    value_with_u(p["amplitude_arcsec"], p["u"], "″"),
                    value_with_u(p["phase_deg"], p["u_phase_deg"], "°"), f"{p['false_alarm']:.2g}",
                    f"{p['n_periods_covered']:.1f}", p["drive_element"]["note"]] for p in arc["periods"]],
                  ["period", "amplitude", "phase", "false alarm", "periods covered", "drive element"])
        rep.paragraph(f"With the periods and the trend fitted together: residual {sc['residual_rms_arcsec']:.3g}″ RMS "
                      f"(χ² {sc['chi2']:.3g} for {sc['dof']} dof), slope "
                      f"{value_with_u(sc['trend_slope_arcsec_per_deg'], sc['u_trend_slope_arcsec_per_deg'], '″/°')}. "
                      "The arc's u of one point and slope in the summary come from a quadratic alone, which counts "
                      "these periods as noise.", note=True)
    else:
        b = sc.get("best_rejected") or {}
        rep.paragraph("No period: the highest peak" + (f" ({b['period_deg']:.4g}°, false alarm {b['false_alarm']:.2g})"
                                                      if b else "") + " is what noise gives.", note=True)
    pg = sc.get("periodogram")
    if pg is not None:
        fig, ax = plt.subplots(figsize=(7, 2.6))
        ax.semilogx(pg["period_deg"], pg["power"], "k-", lw=0.8)
        for p in arc["periods"]:
            ax.axvline(p["period_deg"], color="C3", lw=0.8, ls="--")
        ax.set_xlabel("period (°)")
        ax.set_ylabel("power (1 − χ²/χ²_trend)")
        fig.tight_layout()
        rep.figure(fig, "Least-squares periodogram of the arc (trend fitted jointly); dashed: the periods kept")
        plt.close(fig)


def write_error_curve_report(out: Path, ds: Dataset, a: ErrorCurveAnalysis, close_loop: bool,
                             cal: CalibrationCurve | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from benchtwin.analysis.report.html import U_CONVENTION, Report

    rep = Report(f"Encoder error curve — {ds.path.name}")
    imp = ds.manifest.get("import") or {}
    rep.paragraph(f"Dataset {ds.path} (source: {ds.manifest['source']}, an imported error curve"
                  + (f" from {imp.get('table')}" if imp.get("table") else "") + "). A lone curve: no radial probes, "
                  "no CCD, no polygon start faces; what it cannot separate is stated below.")
    from benchtwin.analysis.report.figures_calibration import add_calibration_section

    add_calibration_section(rep, cal)  # the calibration result first (issue 34)
    rep.heading("Summary")
    rep.paragraph(U_CONVENTION, note=True)
    rep.table(_summary_rows(a, close_loop), ["quantity", "value"])
    _add_findings(rep, a)
    if a.arc is not None:
        add_arc_periods(rep, a.arc)
    if a.iso230_2 is not None:
        add_iso230_2_table(rep, a.iso230_2)
    _add_curve_figure(rep, ds, a)
    rep.write(out / "report.html")


def _summary_rows(a: ErrorCurveAnalysis, close_loop: bool) -> list[list[Any]]:
    from benchtwin.analysis.report.html import value_with_u

    ec, arc = a.detail, a.arc
    cov = ec["coverage"]
    rows = [["coverage", f"{ec['coverage_deg']:.1f}° ({'full turn' if cov['full_turn'] else 'arc'}, "
                         f"{cov['n_angles']} angles, step {cov['step_deg'] or float('nan'):.3g}°)"],
            ["closure", ec["closure"]["state"]],
            ["u of one point", f"{ec['u_point']['u_arcsec']:.3f}″ ({ec['u_point']['source']})"]]
    h = ec.get("hysteresis")
    if h and h.get("available"):
        rows.append(["hysteresis: mean half difference", value_with_u(h["mean_arcsec"], h["u_mean_arcsec"], "″")])
        rows.append(["hysteresis: RMS / max |half difference|", f"{h['rms_arcsec']:.3f}″ / {h['max_abs_arcsec']:.3f}″"])
        rows.append(["angles where the directions differ in sign", str(h["opposite_sign_angles"])])
    if "trend" in ec:
        tr = ec["trend"]
        rows.append(["slope over the arc", value_with_u(tr["slope_arcsec_per_deg"], tr["u_slope"], "″/°")])
    rows.append(["residual: RMS / P-V", f"{ec['residual']['rms_arcsec']:.3f}″ / {ec['residual']['pv_arcsec']:.3f}″"])
    if arc is not None:
        rows.append(["periods over the arc (false alarm < " f"{arc['scan']['significance']:g})",
                     "; ".join(f"{value_with_u(p['period_deg'], p['u_period_deg'], '°', k=1)}: "
                               f"{value_with_u(p['amplitude_arcsec'], p['u'], '″', k=1)}"
                               for p in arc["periods"]) or "none"])
    if close_loop:
        rows.append(["status", ec["status"]])
    return rows


def _add_findings(rep: Any, a: ErrorCurveAnalysis) -> None:
    """The notes, the harmonics, what the curve cannot separate and what it leaves unexplained."""
    from benchtwin.analysis.report.html import value_with_u

    ec = a.detail
    for n in ec["notes"]:
        rep.paragraph(str(n), note=True)
    if ec["harmonics"]:
        rep.heading("Harmonics (Jia 2019 eqs. 6, 11, 12), direction mean", level=3)
        rep.table([[x["k"], value_with_u(x["amplitude_arcsec"], x["u_arcsec"], "″"), f"{x['phase_deg']:.1f}°",
                    f"{x['p_value']:.2g}", "yes" if x["significant"] else ""] for x in ec["harmonics"]],
                  ["k", "amplitude", "phase", "p", "significant"])
    for amb in ec.get("ambiguous", []):
        rep.paragraph(f"Cannot be separated on this curve: {', '.join(amb['names'])}"
                      + (f" (harmonics {amb['harmonics']})" if amb["harmonics"] else "")
                      + f". Separating measurement: {amb['separating_measurement']}", note=True)
    if ec.get("unexplained"):
        rep.paragraph("Unexplained: " + "; ".join(ec.get("left", [])), note=True)


def _add_curve_figure(rep: Any, ds: Dataset, a: ErrorCurveAnalysis) -> None:
    """The imported curve per direction and its mean ± u."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.2))
    t = ds.table("error_curve")
    d = t.get("direction")
    for name in ("forward", "backward"):
        m = np.ones(len(t["theta_deg"]), bool) if d is None else (d == name)
        if m.any():
            o = np.argsort(t["theta_deg"][m])
            ax.plot(t["theta_deg"][m][o], t["error_arcsec"][m][o], "o-", ms=3, label=name if d is not None else "error")
    ax.errorbar(a.theta_deg, a.value_arcsec, yerr=a.u_arcsec, fmt="k.", ms=2, lw=0.6, label="mean ± u")
    ax.set_xlabel("θ (°)")
    ax.set_ylabel("error (″)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    rep.figure(fig, "The imported error curve")
    plt.close(fig)
