"""report.html of a bench dataset (analysis/pipeline.py analyze_into), in named stages.

Written from the pipeline's typed stages (:class:`benchtwin.analysis.steps.BenchAnalysis`) and the
results.json dict built from them (the calibration section and the notes read it as calibration.csv
does): the summary table, the radial motion, the CCD, the Jia model and its comparison, the polygon
(Hsieh 2022) and the loop, in that order.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.analysis.dataset import Dataset
from benchtwin.analysis.results import BenchResults, ResidualSummary
from benchtwin.analysis.steps import BenchAnalysis, LoopOutcome
from benchtwin.units import ARCSEC

__all__ = ["write_bench_report", "residual_test_text", "add_iso230_2_table"]


def residual_test_text(r: Mapping[str, Any]) -> str:
    """One line on what a residual can test (results.json residual_before / residual_after): stops,
    parameters fitted, dof, χ² and p against u of each α, and the leave-one-out RMS."""
    p = r.get("p_value")
    loo = r.get("loo_rms_arcsec")
    return (f"{r['n_points']} stops, {r['n_params']} parameter{'' if r['n_params'] == 1 else 's'} fitted, {r['dof']} dof; χ² = {r['chi2']:.3g} "
            f"against u of each α (p = {'–' if p is None else f'{p:.2g}'}); each stop predicted by the fit made "
            f"without it: {'no such fit (a stop alone fixes a parameter)' if loo is None else f'{loo:.3g}″ RMS'}")


def add_iso230_2_table(rep: Any, iso: Mapping[str, Any]) -> None:
    """The ISO 230-2 figures as a small table (analysis.iso230_2)."""
    n = iso["n_runs"]
    rep.heading("Positioning statistics of the rotary axis (ISO 230-2:2014)", level=3)
    rep.paragraph(f"{iso['n_positions']} target positions, {n['forward']} forward and {n['backward']} backward "
                  f"runs ({iso['source']}). {iso['convention']}. Not included: {iso['excludes']}.")
    rep.table([[f["symbol"], "–" if not math.isfinite(f["value"]) else f"{f['value']:.3f}″", f["what"]]
               for f in iso["figures"].values()], ["figure", "value", "what it is"])
    for fl in iso["flags"]:
        rep.paragraph(fl, note=True)


def write_bench_report(out: Path, ds: Dataset, a: BenchAnalysis, results: BenchResults,
                       preface: list | None = None) -> None:
    """``out/report.html``: the calibration result first (issue 34), the ``preface`` figures (the app
    layer's view of the bench), the summary, then one section per step."""
    import matplotlib

    matplotlib.use("Agg")
    from benchtwin.analysis.calibration import calibration_curve
    from benchtwin.analysis.report.figures_calibration import add_calibration_section
    from benchtwin.analysis.report.html import Report

    rep = Report(f"Encoder calibration bench — {ds.manifest.get('scenario', ds.path.name)}")
    rep.paragraph(f"Dataset {ds.path} (source: {ds.manifest['source']}). Analysis: Jia et al. 2019 "
                  "(radial motion, eccentricity from CCD images, error model eq. 5) and Hsieh et al. 2022 "
                  "(shift-angle method, self-calibration, GUM budget). Standard uncertainties unless stated.")
    add_calibration_section(rep, calibration_curve(results))  # the calibration result first (issue 34)
    for fig, caption in preface or []:
        rep.figure(fig, caption)
    _add_summary(rep, a, results)
    _add_radial_section(rep, ds, a)
    _add_ccd_section(rep, ds, a)
    _add_model_sections(rep, a)
    _add_polygon_section(rep, a)
    if a.loop is not None:
        _add_loop_section(rep, ds, a.loop, a.residual_before)
    rep.write(out / "report.html")


# ----------------------------------------------------------------------------- the summary


def _summary_rows(a: BenchAnalysis) -> tuple[list[list[Any]], list[str]]:
    """The summary table's rows (quantity, value) and the notes under it."""
    from benchtwin.analysis.report.html import value_with_u

    rows: list[list[Any]] = []
    ecc, rm, pol = a.ecc, a.rm, a.pol
    if ecc is not None:
        rows.append(["eccentricity e (Jia eq. 11)", value_with_u(ecc.e_um, ecc.u_e_um, "µm")])
        rows.append(["eccentricity phase θ0 (eq. 12)", value_with_u(ecc.theta0_deg, ecc.u_theta0_deg, "°")])
        rows.append(["pixel scale (from the grating)", f"{ecc.frames.pixel_um:.5f} µm/px"])
    if rm is not None:
        rows += _radial_rows(a)
    if pol is not None and pol.budget_summary:
        bs = pol.budget_summary
        rows.append(["shift-angle α: u_c, ν_eff, k, U", f"{bs['u_c']:.3f}″, {bs['nu_eff']:.0f}, {bs['k']:.2f}, {bs['U']:.3f}″"])
        if pol.en_max is not None:
            rows.append(["E_n max (shift-angle vs self-calibration)", f"{pol.en_max:.2f}"])
    test_notes = []
    if a.residual_before is not None:
        rb = a.residual_before
        rows.append(["residual after the Jia model: RMS / P-V / share", f"{rb['rms_arcsec']:.3f}″ / {rb['pv_arcsec']:.3f}″ / {100 * rb['fraction_of_error']:.1f} %"])
        if "dof" in rb:
            rows.append(["… what it tests", residual_test_text(rb)])
    if a.loop is not None and a.loop.trace.identified_effects:
        ra = a.loop.residual_after
        rows.append(["residual after adding the traced effect(s): RMS / P-V / share",
                     f"{ra['rms_arcsec']:.3f}″ / {ra['pv_arcsec']:.3f}″ / {100 * ra['fraction_of_error']:.1f} %"])
        if "dof" in ra:
            rows.append(["… what it tests", residual_test_text(ra)])
            if ra.get("sampling_note"):
                test_notes.append("Residual after: " + ra["sampling_note"] + ".")
    return rows, test_notes


def _radial_rows(a: BenchAnalysis) -> list[list[Any]]:
    """Two quantities, each under its own name with its bandwidth (issue 34): the P-V of Jia's
    order-2…10 series (what the error model integrates) and the ISO 230-7 value of the readings."""
    from benchtwin.analysis.report.figures_iso import iso_band_label
    from benchtwin.analysis.report.html import value_with_u

    rm = a.rm
    assert rm is not None
    s = rm.summary["disk"]
    rows = [[f"disk radial motion δY, synchronous P-V of the order-2–10 series (Jia eqs. 7, 9; "
             f"{iso_band_label(rm.bandwidth)})",
             value_with_u(s["synchronous_um"], s.get("synchronous_u_um", float("nan")), "µm")]]
    disk = next((loc for loc in rm.iso230_7["locations"] if loc["name"] == "disk"), None)
    if disk is not None and math.isfinite(disk["asynchronous_um"]):
        bw, acq = rm.iso230_7["bandwidth"], rm.iso230_7["acquisition"]
        rows.append([f"δY asynchronous error motion, ISO 230-7, disk plane ({iso_band_label(bw)}; step-and-settle, "
                     f"{acq['positions_per_turn']} positions per turn)",
                     value_with_u(disk["asynchronous_um"], disk["asynchronous_u_um"], "µm")])
    rows.append(["u(δY), range method (d_n)", f"{rm.u_dY_range_um:.3f} µm"])
    return rows


def _add_summary(rep: Any, a: BenchAnalysis, results: BenchResults) -> None:
    from benchtwin.analysis.report.html import U_CONVENTION

    rows, test_notes = _summary_rows(a)
    rep.heading("Summary")
    rep.paragraph(U_CONVENTION, note=True)
    rep.table(rows, ["quantity", "value"])
    for n in test_notes:
        rep.paragraph(n, note=True)
    for n in results["notes"]:
        rep.paragraph(str(n), note=True)


# ----------------------------------------------------------------------------- the steps


def _add_radial_section(rep: Any, ds: Dataset, a: BenchAnalysis) -> None:
    from benchtwin.analysis.report import figures_jia as fj

    if a.rm is None:
        return
    rep.heading("Radial error motion (Jia sec. 4.1, fig. 13)")
    rep.figure(fj.fig_radial_motion(a.rm.detail), "Radial error motion of the test spheres and of the grating disk along the head direction")
    pd_ = a.rm.probe_drift
    if pd_:
        ch = pd_["channels"]
        parts = "; ".join(f"{name.removeprefix('probe_').removesuffix('_um')}: {c['pv_um']:.3f} µm P-V, u {c['u_um']:.3f} µm "
                          f"(Legendre orders {', '.join(map(str, c['legendre_orders']))})"
                          for name, c in ch.items() if c["order"] > 0)
        dy = pd_.get("disk_y")
        rep.paragraph(
            f"The probes' readings drift in time over the {pd_['duration_s'] / 60:.1f}-minute run ({parts}; "
            f"F test against no drift at p = {pd_['test_p']:g}, order by BIC)"
            + (f"; at the disk along Y {dy['pv_um']:.3f} ± {dy['u_um']:.3f} µm P-V" if dy else "")
            + ". It is taken as the probes' stand's, not axis motion: removed before the revolutions' scatter (the "
            "asynchronous motion) is formed; the synchronous δY is the readings' own (a drift's part common to "
            "the revolutions cannot be told from it)"
            + (f". Were it the axis's along X, α would move by {pd_['as_axis_alpha_pv_arcsec']:.2f}″ over the run; "
               "a drift in time during the polygon run is the loop's ac_drift effect to find" if "as_axis_alpha_pv_arcsec" in pd_
               else "") + ".", note=True)
    from benchtwin.analysis.report.figures_iso import add_iso230_7_section

    add_iso230_7_section(rep, a.rm.iso230_7, ds, filtered=a.rm.summary)


def _add_ccd_section(rep: Any, ds: Dataset, a: BenchAnalysis) -> None:
    from benchtwin.analysis.report import figures_jia as fj

    ecc = a.ecc
    if ecc is None:
        return
    rep.heading("Eccentricity from CCD images (Jia sec. 4.2, fig. 14)")
    from benchtwin.analysis.report.figures_ccd import add_ccd_pictures

    add_ccd_pictures(rep, ds, ecc.detail)  # the pictures of the image analysis (issue 20)
    fr = ecc.frames
    rep.figure(fj.fig_dref(ecc.detail, np.asarray(fr.theta_deg), np.asarray(fr.d_ref_um)), "d_ref over the sweep and its first harmonic")
    if fr.rejected_frames:
        rep.paragraph(f"{len(fr.rejected_frames)} of {fr.n_frames} frames rejected by the image analysis "
                      f"and dropped; e and θ0 are fitted on the {len(fr.files)} remaining angles (the "
                      f"least-squares fit of eq. 10 does not need equal spacing; ≥ {fr.min_frames} "
                      "frames are required).", note=True)
        rep.table([[r["file"], f"{r['theta_deg']:.1f}°", r["stage"], r["reason"]] for r in fr.rejected_frames],
                  ["rejected frame", "θ", "step", "reason"])


def _add_model_sections(rep: Any, a: BenchAnalysis) -> None:
    from benchtwin.analysis.report import figures_jia as fj

    if a.model is not None:
        rep.heading("Predicted angle error (Jia eq. 5, fig. 15)")
        rep.figure(fj.fig_predicted_error(a.model), "Angle error predicted from eccentricity and radial motion")
    if a.cmp is not None:
        rep.heading("Comparison with the polygon (Jia sec. 4.3, fig. 16)")
        rep.figure(fj.fig_comparison(a.cmp.detail), "Measured encoder error (polygon + autocollimator) vs model, and the residual")


def _add_polygon_section(rep: Any, a: BenchAnalysis) -> None:
    pol = a.pol
    if pol is None:
        return
    from benchtwin.analysis.report import figures_hsieh as fh

    rep.heading("Polygon cross-calibration and shift-angle method (Hsieh 2022)")
    rep.figure(fh.figure_pitch_deviation(pol.detail), "Pitch deviations β of the polygon (Hsieh fig. 6)")
    rep.figure(fh.figure_alpha_at_shifts(pol.detail), "Encoder error at the shift angles (Hsieh fig. 7)")
    if pol.selfcal_error_arcsec:
        rep.figure(fh.figure_selfcal_vs_shift_angle(pol.detail), "Self-calibration vs shift-angle method (Hsieh fig. 11)"
                   + _blind_caption(pol.detail.get("selfcal_error_arcsec")))
        rep.figure(fh.figure_difference(pol.detail), "Difference between the two methods (Hsieh fig. 12)")
    if a.iso230_2:
        add_iso230_2_table(rep, a.iso230_2)
    if pol.budget:
        rep.heading("Uncertainty budget (GUM, Hsieh Table 3)", level=3)
        rep.table(_budget_rows(pol.budget), ["contribution", "u(xᵢ) ″", "∂α/∂xᵢ", "|c|·u ″", "ν"])


def _budget_rows(budget: Sequence[Mapping[str, Any]]) -> list[list[Any]]:
    """The GUM table's rows as a reader expects them: ν of a type B input with no stated
    reliability is ∞ (results.json writes it as null), the combined row has no sensitivity (–), and a
    u that is zero to the arithmetic's precision (below 1e-9 of the combined u, e.g. the setup-error
    calculation's 1.7e-15″) is shown as 0, not as a 1e-15 that reads like a measured size."""
    combined = max((abs(float(r["u"])) for r in budget if isinstance(r.get("u"), (int, float))), default=0.0)

    def num(v: Any) -> Any:
        if isinstance(v, float) and abs(v) < 1e-9 * combined:
            return 0
        return v

    return [[r.get("name"), num(r.get("u")), "–" if r.get("sensitivity") is None else r["sensitivity"],
             num(r.get("contribution")), "∞" if r.get("dof") is None else r["dof"]] for r in budget]


# ----------------------------------------------------------------------------- the loop


def _add_loop_section(rep: Any, ds: Dataset, loop: LoopOutcome, residual_before: ResidualSummary | None) -> None:
    from benchtwin.analysis.report import figures_loop as fl

    tr = loop.trace
    rep.heading("Closing the loop: what the model lacks")
    names = ", ".join(e["name"] for e in tr.identified_effects) or "none"
    rep.paragraph(f"Status: {tr.status}. Identified: {names}.")
    if tr.identified_effects:
        _add_loop_identified(rep, ds, loop, names)
    elif tr.partial_effects:
        rep.paragraph("Best candidate (not accepted, the residual after it is still significant): "
                      + ", ".join(e["name"] for e in tr.partial_effects)
                      + f"; left: {', '.join(tr.residual_after.get('signature_left') or [])}.", note=True)
    _add_loop_tables(rep, loop, residual_before)
    rep.figure(fl.plot_residual_before_after(loop.evidence, tr.detail), "Residual before and after adding the traced effect")
    rep.figure(fl.plot_harmonic_spectrum(tr.detail), "Harmonic spectrum of the residual with uncertainties")
    rep.figure(fl.plot_signature(loop.evidence, tr.detail), "Signature of the residual: time, start face, direction")


def _add_loop_identified(rep: Any, ds: Dataset, loop: LoopOutcome, names: str) -> None:
    """What the identified effects bring: per reading, per stop with the refined (e, θ0), and the
    axis's non-repeating motion that remains."""
    from benchtwin.analysis.report.html import value_with_u

    tr = loop.trace
    rb_t, ra_t = tr.residual_before, tr.residual_after
    pars = "; ".join(f"{e['name']}: " + ", ".join(f"{k} = {value_with_u(v, e['u'].get(k, float('nan')), '')}"
                                                 for k, v in e["params"].items()) for e in tr.identified_effects)
    rep.paragraph(
        f"The model lacked {names} ({pars}). Adding it brings the residual per polygon reading from "
        f"{rb_t['rms_arcsec']:.3f}″ RMS ({rb_t['pv_arcsec']:.2f}″ P-V, {100 * rb_t['fraction_of_error']:.1f} % "
        f"of the error) to {ra_t['rms_arcsec']:.3f}″ RMS ({ra_t['pv_arcsec']:.2f}″ P-V, "
        f"{100 * ra_t['fraction_of_error']:.1f} %); noise floor {rb_t.get('noise_floor_arcsec', float('nan')):.3f}″ "
        f"(u of one reading), χ² after {ra_t['chi2']:.0f} for {ra_t['dof']} dof (p = {ra_t['p_value']:.2g}).")
    ra_s = loop.residual_after
    ref = loop.refined
    if ra_s.get("per_reading_rms_arcsec") is not None and ref is not None:
        rep.paragraph(
            f"That residual per reading keeps the Jia model's eccentricity term with the CCD's (e, θ0): its first "
            f"harmonic is the CCD's e within its u (u(e) = {ref.ccd_u_e_um:.3f} µm, "
            f"{ref.ccd_u_e_um / (float(ds.bench['optical_radius_mm']) * 1000.0) / ARCSEC:.2f}″ at the optical radius). The model after the loop "
            f"takes the first harmonic from the comparison (e = {ref.e_um:.3f} ± {ref.u_e_um:.3f} µm, its u "
            f"including a first-order graduation term of u = {ref.k1_prior_u_arcsec:.2f}″ per component that "
            f"α cannot tell from e) and refits the traced parameters on the stops: per reading it leaves "
            f"{ra_s['per_reading_rms_arcsec']:.3f}″ RMS, at the stops {ra_s['rms_arcsec']:.3f}″ "
            f"({residual_test_text(ra_s)}).")
    am = rb_t.get("async_motion") or {}
    if am.get("sigma_um"):
        rep.paragraph(
            f"What remains includes the axis's non-repeating motion: the probes' revolutions scatter by "
            f"{am['sigma_um']:.3f} µm RMS (orders 1…{am.get('band_orders', 10)}), i.e. about "
            f"{am['per_stop_arcsec']:.2f}″ per polygon stop along X, unmeasured at the polygon's revolution; it "
            "is part of the model's uncertainty, not an effect (more polygon reps would average it).", note=True)


def _add_loop_tables(rep: Any, loop: LoopOutcome, residual_before: ResidualSummary | None) -> None:
    """The identified parameters, the corrected curve's corrections, the ambiguities and the
    residual before / after."""
    from benchtwin.analysis.report.html import value_with_u

    tr = loop.trace
    for e in tr.identified_effects:
        rep.table([[k, value_with_u(v, e["u"].get(k, float('nan')), "")] for k, v in e["params"].items()],
                  [f"{e['name']}: parameter", "value"])
    cc = loop.corrected
    if cc.get("corrections_applied"):
        rep.paragraph("Corrected calibration curve (encoder_error_corrected_arcsec, the curve a certificate states): "
                      "the measured encoder error minus " + "; ".join(
                          f"{c['effect']} ({c['rms_arcsec']:.3f}″ RMS, u {c['u_rms_arcsec']:.3f}″)"
                          for c in cc["corrections_applied"]) + ".")
    else:
        rep.paragraph("Corrected calibration curve: no artefact of the reference chain identified; the "
                      "measured encoder error is stated unchanged.", note=True)
    for amb in tr.ambiguous:
        rep.paragraph(f"Ambiguous: {', '.join(amb['names'])}. Separating measurement: {amb.get('separating_measurement', '')}", note=True)
    if tr.unexplained:
        rep.paragraph("Unexplained: the residual is significant but no effect of the library explains it; see the signature.", note=True)
    res_b = residual_before
    res_a = loop.residual_after
    if res_b and res_a:
        rep.table([["before", res_b["rms_arcsec"], res_b["pv_arcsec"], res_b["fraction_of_error"]],
                   ["after", res_a["rms_arcsec"], res_a["pv_arcsec"], res_a["fraction_of_error"]]],
                  ["residual", "RMS ″", "P-V ″", "share of the error"])


def _blind_caption(curve: Any) -> str:
    """What the self-calibration curve leaves out (principle 5): the harmonics no head set sees and
    the Nyquist term, held at 0 (analysis/hsieh_pipeline.py ``_curve_blind``); the comparison and
    E_n leave them out of both curves."""
    blind = list((curve or {}).get("unobservable_harmonics") or []) if isinstance(curve, Mapping) else []
    if not blind:
        return ""
    shown = ", ".join(str(int(k)) for k in blind[:12]) + (", …" if len(blind) > 12 else "")
    return (f". The self-calibration curve holds the harmonics k = {shown} at 0 (no head set sees them, or"
            " the Nyquist term, which it does not estimate); its u does not include them, and the comparison"
            " and E_n leave them out of both curves")
