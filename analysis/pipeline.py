"""The analysis pipeline: dataset → results.json + report.html.

One pipeline for every source (twin, emulated instruments, real bench, external data): it reads
only the dataset format (``analysis.dataset``) and never the twin's ground truth.

Steps, each from its paper:

1. Radial error motion from the two test spheres (Jia 2019 sec. 4.1, eqs. 6–9).
2. Installation eccentricity from the CCD images (Jia sec. 4.2, eqs. 10–13).
3. Polygon cross-calibration / shift-angle method and multi-head self-calibration (Hsieh 2022).
4. The error model Δθ = [e·sin(θ−θ0) + ∫δY dθ]/r (Jia eq. 5) compared with the measured encoder
   error (Jia sec. 4.3): residual, P-V, RMS and share of the error.
5. Closing the loop (optional): is the residual significant, what is its signature, which effect
   of the library explains it; the effect joins the model and the residual is re-computed.
"""

from __future__ import annotations

import functools
import itertools
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, cast, overload

import numpy as np

from benchtwin.analysis.calibration import CalibrationCurve, calibration_curve, write_calibration_files
from benchtwin.analysis.dataset import Dataset, DatasetError, open_dataset
from benchtwin.analysis.results import (ArcPeriod, AutocollimatorDeclared, BenchResults, Bench, BudgetInput, CloseLoop,
                                        Comparison, CorrectedCurve, CorrectionApplied, Curve, ErrorCurveResults,
                                        Iso230_2, ModelPrediction, RadialErrorMotion, ResidualSummary)
from benchtwin.analysis.results_api import Results
from benchtwin.analysis.steps import EccentricityResult, PolygonAnalysis, RadialMotionResult, TraceOutcome
from benchtwin.jsonable import to_json
from benchtwin.units import ARCSEC
from benchtwin.fsio import atomic_write_text


# results.json: strict JSON (non-finite -> null), model-term functions left out (benchtwin/jsonable.py)
_jsonable = functools.partial(to_json, nonfinite="null", drop_callables=True)

def _progress(enabled: bool, total: int, desc: str):
    from tqdm.auto import tqdm  # a notebook widget in Jupyter, the text bar elsewhere (issue 34)

    return tqdm(total=total, desc=desc, disable=not enabled, unit="step", leave=False)


# ----------------------------------------------------------------------------- steps


def step_radial_motion(ds: Dataset, order: int) -> RadialMotionResult:
    """Radial error motion from the two test spheres (Jia eqs. 6-9), with its ISO 230-7 values."""
    from benchtwin.analysis.radial_motion import ProbeReadings, RadialOptions, SphereSpacing, radial_motion

    t = ds.table("radial_motion")
    b = ds.bench
    rm = radial_motion(ProbeReadings.from_table(t), SphereSpacing(b["L1_mm"], b["L2_mm"]), RadialOptions(order=order))
    # with the ISO 230-7 values and polar plots (issue 20)
    return RadialMotionResult.from_radial_motion(rm, step_iso230_7(ds, rm, order))


def step_iso230_7(ds: Dataset, rm: dict[str, Any], order: int) -> dict[str, Any]:
    """ISO 230-7 total / synchronous / asynchronous radial error motion (analysis.iso230_7)."""
    from benchtwin.analysis.iso230_7 import radial_error_motion

    t = ds.table("radial_motion")
    probes = {k: t.get(k) for k in ("probe_top_um", "probe_bottom_um", "probe_top_x_um", "probe_bottom_x_um")}
    return radial_error_motion(t["rep"], t["theta_deg"], probes, ds.bench["L1_mm"], ds.bench["L2_mm"], rm=rm,
                               order=order)


def _iso_summary(iso: Mapping[str, Any]) -> RadialErrorMotion:
    from benchtwin.analysis.iso230_7 import summary

    return cast(RadialErrorMotion, summary(iso))  # the section iso230_7.summary builds (analysis/results.py)


#: CCD frames: a frame whose line ends cannot be found (a scratch across the edge, dust on every
#: end, a blank frame) is dropped, recorded (``ccd_rejected_frames``) and the sweep fitted on the
#: remaining angles — eq. 10 is a least-squares fit and does not need equal spacing. The analysis
#: aborts only when the remaining frames cannot carry the fit:
#: - fewer than 2·order + 1 + ``CCD_MIN_DOF`` frames: eq. 10 has 2·order + 1 coefficients and the
#:   type-A covariance of e and θ0 (from the fit residuals) needs a few residual degrees of freedom;
#: - more than ``CCD_MAX_REJECTED_FRACTION`` of the frames rejected: then the failure is systematic
#:   (focus, illumination, orientation, wrong period), not a contaminated frame, and dropping frames
#:   would hide it.
CCD_MIN_DOF = 3
CCD_MAX_REJECTED_FRACTION = 0.25


def ccd_frame_limits(n_frames: int, order: int) -> dict[str, int]:
    """The smallest number of usable CCD frames the eccentricity fit accepts (see above)."""
    by_fit = 2 * order + 1 + CCD_MIN_DOF
    by_fraction = int(math.ceil((1.0 - CCD_MAX_REJECTED_FRACTION) * n_frames - 1e-9))
    return {"min_frames": max(by_fit, by_fraction), "by_fit": by_fit, "by_fraction": by_fraction}


def step_eccentricity(ds: Dataset, order: int, progress: bool, workers: int | None = None) -> EccentricityResult:
    from benchtwin.analysis import eccentricity as ecc
    from collections.abc import Iterator

    from benchtwin.analysis.parallel import ordered_map

    ccd = ds.manifest.get("ccd")
    if ccd is None:
        raise DatasetError(f"{ds.path}/manifest.json: key 'ccd' is required when ccd/index.csv is present")
    period_um = ds.bench["grating_period_um"]
    ref = tuple(ccd["reference_px"])
    # Two stages: the pixel scale first (from the grating period, Jia eq. 13), then d_ref with the
    # edge radius fixed where the manifest knows it (Jia: "r_fitting is already known") — a short arc
    # of a 22 mm circle does not determine its radius well.
    # Each frame is decoded once and its line edges found once (ecc.frame_edges_and_scale), frames in
    # worker threads (analysis/parallel.py: in order, bit-identical to the serial loop, at most a
    # few frames in flight; frames are read and checked in this thread); only the edges (a few
    # hundred numbers per frame) are kept for the d_ref stage, so memory stays flat for long sweeps of
    # large frames. ``workers``: threads (default: BENCHTWIN_WORKERS, else the cores that help, as
    # measured, see analysis/parallel.py; 1 = serial, in this thread).
    # A frame the image analysis rejects is dropped from that stage on and recorded (module constants).
    n_frames = len(ds.table("ccd/index")["k"])
    limits = ccd_frame_limits(n_frames, order)
    rejected: dict[str, dict[str, Any]] = {}

    def reject(f: str, theta: float, stage: str, exc: Exception) -> None:
        msg = str(exc)
        prefix = f"image {f!r}: "
        rejected.setdefault(f, {"file": f, "theta_deg": float(theta), "stage": stage,
                                "reason": msg[len(prefix):] if msg.startswith(prefix) else msg})

    def check(n_used: int, what: str) -> None:
        if n_used < limits["min_frames"]:
            lst = "; ".join(f"{r['file']} ({r['stage']}): {r['reason']}" for r in list(rejected.values())[:5])
            more = f" (and {len(rejected) - 5} more)" if len(rejected) > 5 else ""
            raise DatasetError(
                f"{ds.path / 'ccd'}: only {n_used} of {n_frames} CCD frames usable for the {what}; need ≥ "
                f"{limits['min_frames']} (the order-{order} series of Jia eq. 10 has {2 * order + 1} coefficients "
                f"+ {CCD_MIN_DOF} residual dof for u(e), and at most {CCD_MAX_REJECTED_FRACTION:.0%} of the frames "
                f"may be rejected before the failure counts as systematic). Rejected: {lst}{more}")

    meta: list[tuple[float, str]] = []  # (theta, file) per frame, in index order

    def frames() -> Iterator[tuple[np.ndarray, float, str]]:
        for _k, theta, image, f in ds.ccd_frames():
            meta.append((float(theta), f))
            yield image, period_um, f

    scales: list[float] = []
    edges: list[Any] = []  # per frame: its LineEdges, or None if rejected
    bar = _progress(progress, n_frames, "CCD images")
    # The first frame that can be analysed is done here (before any pool starts): its lines' polarity
    # is the one the other frames are expected to have, which orders their labelling work only
    # (ecc.segment_lines: each frame decides its own polarity, the same whatever is expected)
    sweep = frames()
    head: list[Any] = []
    polarity = None
    for args in sweep:
        head.append(ecc.frame_edges_and_scale(*args))
        if head[-1][0] is not None:
            polarity = head[-1][0].polarity
            break
    rest = ordered_map(ecc.frame_edges_and_scale, ((*args, polarity) for args in sweep), workers)
    for i, (ed, scale_i, exc) in enumerate(itertools.chain(head, rest)):
        bar.update()
        theta, f = meta[i]
        if exc is not None or scale_i is None:
            reject(f, theta, "pixel scale (eq. 13)", exc or ecc.ImageAnalysisError("no pixel scale"))
            edges.append(None)
            continue
        scales.append(scale_i)
        edges.append(ed)
    bar.close()
    check(len(scales), "pixel scale (Jia eq. 13)")
    scale = float(np.median(scales))
    edge_mm = ds.bench.get("scale_edge_radius_mm")
    radius_px = edge_mm * 1000.0 / scale if edge_mm else None
    thetas, drefs_px, files = [], [], []
    first_fit: dict[str, Any] | None = None
    for (theta, f), ed in zip(meta, edges):
        if ed is None:
            continue  # its line ends were not found for the pixel scale: not trusted for d_ref either
        try:
            fit = ecc.d_ref_px(None, ref, radius_px=radius_px, name=f, edges=ed)
        except ecc.ImageAnalysisError as exc:
            reject(f, theta, "d_ref (eqs. 10-12)", exc)
            continue
        drefs_px.append(fit["d_ref_px"])
        if first_fit is None:  # the report draws the first used frame's fit (figures_ccd.add_ccd_pictures)
            first_fit = {"file": f, "fit": fit}
        thetas.append(theta)
        files.append(f)
    check(len(thetas), "eccentricity fit (Jia eqs. 10-12)")
    dref_um = np.asarray(drefs_px) * scale
    res = _fit_sweeps(ds, ecc, np.asarray(thetas), dref_um, files, ccd["position_deg"], order)
    res["pixel_um"] = scale
    res["radius_fixed_px"] = radius_px
    res["theta_deg"] = thetas
    res["d_ref_um"] = dref_um
    res["files"] = files
    res["n_frames"] = n_frames
    res["rejected_frames"] = list(rejected.values())
    res["frame_limits"] = limits
    res["first_frame_fit"] = first_fit
    return EccentricityResult.from_eccentricity(res)


def _fit_sweeps(ds: Dataset, ecc: Any, thetas: np.ndarray, dref_um: np.ndarray, files: list[str], camera_deg: float,
                order: int) -> dict[str, Any]:
    """Jia eqs. 10-12 on the frames of each sweep (``ccd/index.csv`` column ``sweep``; one sweep
    without it) and, with ≥ 2 sweeps, e ± u(e) type A from their scatter
    (:func:`benchtwin.analysis.eccentricity.eccentricity_from_sweeps`). One sweep: the fit's result
    (its u is the fit's; ``run`` adds the probes' asynchronous part, ``with_async_motion``)."""
    idx = ds.table("ccd/index")
    if "sweep" not in idx or len(np.unique(idx["sweep"])) < 2:
        return ecc.eccentricity_from_dref(thetas, dref_um, camera_azimuth_deg=camera_deg, order=order)
    sweep_of = {str(f).strip(): int(sw) for f, sw in zip(idx["file"], idx["sweep"])}
    sw = np.array([sweep_of[f] for f in files])
    fits = []
    for k in np.unique(np.asarray(idx["sweep"], dtype=int)):
        m = sw == k
        # each sweep is a fit of its own: the frame limits hold per sweep
        lim = ccd_frame_limits(int(np.sum(np.asarray(idx["sweep"]) == k)), order)
        if int(m.sum()) < lim["min_frames"]:
            raise DatasetError(f"{ds.path / 'ccd'}: sweep {int(k)}: only {int(m.sum())} usable CCD frames for its "
                               f"eccentricity fit (Jia eqs. 10-12); need ≥ {lim['min_frames']} (see ccd_frame_limits)")
        fits.append(ecc.eccentricity_from_dref(thetas[m], dref_um[m], camera_azimuth_deg=camera_deg, order=order))
    comb = ecc.eccentricity_from_sweeps(fits)
    # the figures and the CCD section show sweep 0's fit with every sweep's points; the numbers are the sweeps'
    res = dict(fits[0])
    res.update(comb)
    n = len(fits)
    e_i, t_i = np.asarray(comb["e_sweeps_um"]), np.asarray(comb["theta0_sweeps_deg"])
    dt = (t_i - comb["theta0_deg"] + 180.0) % 360.0 - 180.0
    res["cov_e_theta0"] = float(np.cov(e_i, dt, ddof=1)[0, 1] / n)   # µm·deg, of the means
    res["residual_rms_um"] = float(np.sqrt(np.mean([f["residual_rms_um"] ** 2 for f in fits])))
    res["sweep_of_frame"] = sw.tolist()
    return res


#: The autocollimator Hsieh et al. 2022 used (MÖLLER-WEDEL ELCOMAT 3000, sec. 3.3 (2) and (4)):
#: resolution 0.001″, maximum error 0.05″. Assumed only when the manifest does not declare the
#: instrument (bench.autocollimator_resolution_arcsec / _accuracy_arcsec), and said so in the notes.
HSIEH_AC_RESOLUTION_ARCSEC = 0.001
HSIEH_AC_ACCURACY_ARCSEC = 0.05


def autocollimator_declared(bench: dict[str, Any]) -> tuple[float, float, str | None]:
    """(resolution, accuracy, note): the manifest's declared autocollimator, else Hsieh's with a note."""
    res = bench.get("autocollimator_resolution_arcsec")
    acc = bench.get("autocollimator_accuracy_arcsec")
    note = None
    if res is None or acc is None:
        note = ("autocollimator resolution/accuracy not declared in the manifest (bench.autocollimator_resolution_arcsec, "
                f"bench.autocollimator_accuracy_arcsec): Hsieh's ELCOMAT 3000 values assumed "
                f"({HSIEH_AC_RESOLUTION_ARCSEC}″ / {HSIEH_AC_ACCURACY_ARCSEC}″)")
    return (float(HSIEH_AC_RESOLUTION_ARCSEC if res is None else res),
            float(HSIEH_AC_ACCURACY_ARCSEC if acc is None else acc), note)


#: decimals of a degree an encoder display transmits (Heidenhain ND: 6, i.e. 3.6 mas)
DISPLAY_DECIMALS_DEG = 6


def polygon_table(ds: Dataset) -> dict[str, Any]:
    """polygon.csv with each autocollimator reading referred to its commanded stop.

    Hsieh eq. 3 takes the encoder to display the nominal angle (i−1)·360°/N + S at every stop. A
    servo holds the encoder's count nearest to it instead: the display ``theta_read_deg`` differs
    from the stop ``theta_deg`` by q (up to half the encoder's resolution, 0.2″ for 0.39″), and the
    polygon then stands at θ_read − α, so ε = α + Σβ + U − q. Where the reading is recorded, q is
    added back (ε + q: the reading the autocollimator would show at the nominal display; α changes by
    < 1e-4″ over q). q is fixed to θ (the same stop → the same count in every run), so left in, it is
    a θ pattern of resolution/√12 ≈ 0.11″ RMS at the stops, read as a division error (issue 16:
    a 0.12″ 9th harmonic on the hidden nulls, 23 faces)."""
    t = dict(ds.table("polygon"))
    if "theta_read_deg" in t:
        th = np.asarray(t["theta_deg"], dtype=float)
        # the display is known to what a display transmits: 6 decimals of a degree (Heidenhain ND,
        # hw/drivers/heidenhain.py), so the twin's exact reading and an emulated one give one q
        shown = np.round(np.asarray(t["theta_read_deg"], dtype=float), DISPLAY_DECIMALS_DEG)
        q_arcsec = ((shown - th + 180.0) % 360.0 - 180.0) * 3600.0
        t["ac_arcsec"] = np.asarray(t["ac_arcsec"], dtype=float) + q_arcsec
    return t


#: The other type B inputs of Hsieh's budget (sec. 3.3), each read from the manifest's bench block
#: when declared, else these, named in results.json (``budget_inputs``) with their source:
#: - (3) the autocollimator's calibration (traceability): expanded uncertainty U = 0.01″ with k = 2,
#:   Hsieh sec. 3.3 (3) (ELCOMAT 3000 calibration certificate);
#: - (8) the polygon's setup (misalignment of the polygon axis to the encoder axis): 0.05″, rectangular,
#:   Hsieh sec. 3.3 (8);
#: - (5) the encoder's resolution: the manifest's ``encoder_resolution_arcsec``; undeclared, no term
#:   (0″) and a note, since no paper value applies to an unknown encoder.
HSIEH_AC_TRACEABILITY_U_ARCSEC = 0.01
HSIEH_AC_TRACEABILITY_K = 2.0
HSIEH_SETUP_MISALIGNMENT_ARCSEC = 0.05
ENCODER_RESOLUTION_UNDECLARED_ARCSEC = 0.0

#: (key in results.json's budget_inputs, manifest bench key, default, source of the default)
_BUDGET_INPUTS: tuple[tuple[str, str, float, str], ...] = (
    ("ac_traceability_U_arcsec", "autocollimator_traceability_U_arcsec", HSIEH_AC_TRACEABILITY_U_ARCSEC,
     "assumed (Hsieh 2022 sec. 3.3 (3), ELCOMAT 3000 calibration)"),
    ("ac_traceability_k", "autocollimator_traceability_k", HSIEH_AC_TRACEABILITY_K,
     "assumed (Hsieh 2022 sec. 3.3 (3))"),
    ("setup_misalignment_arcsec", "polygon_setup_misalignment_arcsec", HSIEH_SETUP_MISALIGNMENT_ARCSEC,
     "assumed (Hsieh 2022 sec. 3.3 (8))"),
    ("encoder_resolution_arcsec", "encoder_resolution_arcsec", ENCODER_RESOLUTION_UNDECLARED_ARCSEC,
     "not declared: no resolution term"),
)


def budget_inputs(bench: dict[str, Any]) -> tuple[dict[str, BudgetInput], list[str]]:
    """The type B inputs of Hsieh's budget besides the autocollimator's resolution and accuracy
    (:func:`autocollimator_declared`): {name: {value, source}} and a note for each one not declared."""
    out: dict[str, BudgetInput] = {}
    assumed = []
    for name, key, default, source in _BUDGET_INPUTS:
        v = bench.get(key)
        if v is None:
            out[name] = BudgetInput(value=float(default), source=source)
            assumed.append(f"bench.{key} = {default:g} ({source.removeprefix('assumed (').removesuffix(')')})")
        else:
            out[name] = BudgetInput(value=float(v), source="manifest")
    notes = [f"budget inputs not declared in the manifest, assumed: {'; '.join(assumed)}"] if assumed else []
    return out, notes


def step_polygon(ds: Dataset, table: Mapping[str, Any] | None = None) -> PolygonAnalysis:
    """The shift-angle analysis of ``polygon_table(ds)``, or of ``table`` (the same rows with corrected
    autocollimator readings: :func:`reading_corrections`)."""
    from dataclasses import replace

    from benchtwin.analysis.hsieh_pipeline import HeadsData, PolygonOptions, analyze_polygon
    from benchtwin.analysis.shift_angle import BetaSource, PolygonDataError
    from benchtwin.analysis.uncertainty import HSIEH2022_TYPE_B

    b = ds.bench
    heads = ds.table("heads") if ds.has("heads") else None
    cert = b.get("polygon_certificate_arcsec")
    ac_res, ac_acc, note = autocollimator_declared(b)
    inputs, input_notes = budget_inputs(b)
    try:
        out = analyze_polygon(
            dict(table) if table is not None else polygon_table(ds), b["polygon_faces"],
            HeadsData(heads, b.get("heads_deg")) if heads is not None else None,
            type_b=replace(
                HSIEH2022_TYPE_B, encoder_resolution_arcsec=inputs["encoder_resolution_arcsec"]["value"],
                ac_resolution_arcsec=ac_res, ac_error_half_width_arcsec=ac_acc,
                ac_traceability_U_arcsec=inputs["ac_traceability_U_arcsec"]["value"],
                ac_traceability_k=inputs["ac_traceability_k"]["value"],
                setup_misalignment_arcsec=inputs["setup_misalignment_arcsec"]["value"]),
            options=PolygonOptions(beta=BetaSource(certificate_arcsec=np.asarray(cert, dtype=float) if cert is not None else None)),
        )
        declared = AutocollimatorDeclared(resolution_arcsec=ac_res, accuracy_arcsec=ac_acc,
                                          source="manifest" if note is None else "assumed (Hsieh 2022 ELCOMAT 3000)")
        return PolygonAnalysis.from_analysis(out, declared, inputs, ([note] if note else []) + input_notes)
    except PolygonDataError as exc:
        # The Hsieh analysis names rows by array index; the file counts the header as row 1.
        raise DatasetError(f"{ds.path / 'polygon.csv'}: {exc} (array index i is file row i + 2)") from None


def step_iso230_2_polygon(ds: Dataset, pol: PolygonAnalysis) -> dict[str, Any] | None:
    """ISO 230-2 positioning statistics from the polygon's clampings swept in both directions
    (analysis.iso230_2); None when no clamping was measured in both directions."""
    from benchtwin.analysis import shift_angle as sa
    from benchtwin.analysis.iso230_2 import positioning_statistics, runs_from_polygon

    t = polygon_table(ds)
    if "direction" not in t or len(set(np.asarray(t["direction"]).astype(str))) < 2:
        return None
    table = sa.tabulate_polygon({**t, "direction": np.asarray(t["direction"]).astype(str)}, ds.bench["polygon_faces"])
    got = runs_from_polygon(table, np.asarray(pol.pitch_deviation_arcsec, dtype=float))
    if got is None:
        return None
    target, up, dn, how = got
    out = positioning_statistics(target, up, dn, source="polygon.csv: " + how["note"])
    out["shift_deg"] = how["shift_deg"]
    return out


def _setup_error_lookup(pol: PolygonAnalysis):
    table = {}
    for s, values in pol.setup_error_arcsec.items():
        faces = pol.setup_error_start_faces[s]
        for f, u in zip(faces, values):
            table[(float(s), int(f))] = float(u)

    def lookup(shift: float, face: int) -> float:
        key = (float(round(shift, 9)), int(face))
        if key not in table:  # shifts are stored with their string key; match numerically
            for (s, f), u in table.items():
                if f == face and abs(s - shift) < 1e-6:
                    return u
            raise KeyError(f"no setup error for shift {shift} deg, start face {face}")
        return table[key]

    return lookup


#: the yardstick of the residuals' χ² (results.json ``residual_before`` / ``residual_after``: ``chi2_u``)
CHI2_YARDSTICK = ("u of each α (encoder_error_arcsec.u: the GUM budget of the shift-angle curve, Hsieh 2022 "
                  "Table 3); the model's own parameters (e, θ0 from the CCD, δY from the probes) are not in it")


def _residual_summary(cmp: dict[str, Any], u_arcsec: float | None = None,
                      stats: Mapping[str, Any] | None = None) -> ResidualSummary:
    """The comparison's RMS, P-V, ... and, with ``stats`` (error_model.fit_statistics of the fit
    behind the residual), what it can test: n_params, dof, chi2, p_value, loo_rms_arcsec and, where
    dof < 3, the sentence saying this sampling cannot test the model and which would."""
    from benchtwin.analysis.error_model import sampling_advice

    out = ResidualSummary(rms_arcsec=cmp["residual_rms_arcsec"], pv_arcsec=cmp["residual_pv_arcsec"],
                          max_abs_arcsec=cmp["residual_max_abs_arcsec"], fraction_of_error=cmp["fraction_of_error"],
                          pv_ratio=cmp["pv_ratio"], measured_pv_arcsec=cmp["measured_pv_arcsec"],
                          measured_rms_arcsec=cmp["measured_rms_arcsec"], n_points=int(len(cmp["theta_deg"])),
                          note=cmp["note"])
    if u_arcsec is not None:
        out["u_rms_arcsec"] = u_arcsec
    if stats is not None:
        out["n_params"] = int(stats["n_params"])
        out["dof"] = int(stats["dof"])
        out["chi2"] = float(stats["chi2"])
        out["p_value"] = stats["p_value"]
        out["loo_rms_arcsec"] = stats["loo_rms_arcsec"]
        out["chi2_u"] = CHI2_YARDSTICK
        advice = sampling_advice(out["n_points"], out["n_params"])
        if advice is not None:
            out["sampling_note"] = advice
    return out


def _constant_fit(cmp: dict[str, Any], u: np.ndarray) -> dict[str, Any]:
    """fit_statistics of measured − model with only α's constant fitted (the Jia model takes e, θ0
    and δY from the CCD and the probes, not from α): the weighted mean removed, one parameter."""
    from benchtwin.analysis.error_model import fit_statistics

    y = np.asarray(cmp["residual_arcsec"], dtype=float)
    w = 1.0 / u ** 2
    return fit_statistics(np.ones((y.size, 1)), y - float(np.sum(w * y) / np.sum(w)), u)


def _alpha_u(enc: Curve | Mapping[str, Any], fallback: float) -> np.ndarray:
    """u of each α (the χ² yardstick, CHI2_YARDSTICK); a point without a positive u takes ``fallback``."""
    th = np.asarray(enc["theta_deg"], dtype=float)
    u = np.asarray(enc.get("u") if enc.get("u") is not None else np.full(th.shape, fallback), dtype=float)
    return np.where(np.isfinite(u) & (u > 0), u, fallback)


def k1_prior(signature: Mapping[str, Any]) -> tuple[float, str]:
    """The prior u (per Fourier component, arcsec) of a first-order graduation term, and its source.

    In α a k = 1 graduation term (the ruling's centre off the edge the CCD measures, and at N stops
    the orders N ± 1, 2N ± 1, ... aliasing onto order 1) cannot be told from eccentricity. No
    encoder class states it (a maker centres the disk's edge on its ruling: the outer edge of the
    pattern is taken as concentric with it, Celera Motion, "Rotary scales alignment", MicroE
    technical paper; no tolerance given), so the prior is this encoder's own division error: the
    order 1 taken as one more low order of the same disk, of the size the residual shows at the
    orders 2…kmax the data resolve (the RMS of their Fourier components a_k, b_k; the orders that
    alias onto them included). Conservative where the residual holds other effects too (their
    content only widens the prior, i.e. leans e on the CCD)."""
    comps = [c for h in (signature.get("harmonics") or []) if int(h.get("k", 0)) >= 2
             for c in (h.get("a_arcsec"), h.get("b_arcsec")) if c is not None and math.isfinite(float(c))]
    if not comps:
        return 0.0, "no harmonic of order ≥ 2 in the residual's signature: no first-order graduation term"
    u = float(np.sqrt(np.mean(np.square(comps))))
    ks = [int(h["k"]) for h in signature["harmonics"] if int(h.get("k", 0)) >= 2]
    return u, (f"this encoder's division error at the orders the data resolve: RMS of the residual's Fourier "
               f"components at orders {min(ks)}…{max(ks)} (before the loop), the order 1 taken as one more low "
               "order of the same disk; no encoder class states a first-order term (the maker centres the edge "
               "the CCD sees on the ruling)")


def traced_columns(payload: Mapping[str, Any], base_terms: Mapping[str, Any], theta_deg: np.ndarray
                   ) -> tuple[np.ndarray, list[tuple[int, str]]]:
    """∂(traced terms)/∂p at ``theta_deg`` [arcsec per unit of each parameter] for every parameter
    of the traced encoder effects in the model file ``payload`` (tracing.model_terms_from_payload:
    reference-chain effects give no term), and their (effect index, parameter name). Central
    differences with a step of the parameter's u (1e-3 where it has none): exact for effects linear
    in their parameters (graduation_error, interpolation_error, tangential_motion, …), the
    linearisation at the traced values otherwise."""
    import copy

    from benchtwin.analysis.tracing import model_terms_from_payload

    th = np.deg2rad(np.asarray(theta_deg, dtype=float))
    cols, names = [], []
    for i, e in enumerate(payload.get("effects", [])):
        one = {**payload, "effects": [e]}
        if not model_terms_from_payload(one, dict(base_terms)):
            continue
        for name, v in e["params"].items():
            uu = (e.get("u") or {}).get(name)
            h = float(uu) if uu is not None and math.isfinite(float(uu)) and float(uu) > 0 else 1e-3 * max(1.0, abs(float(v)))
            vals = []
            for sgn in (1.0, -1.0):
                q = copy.deepcopy(one)
                q["effects"][0]["params"][name] = float(v) + sgn * h
                terms = model_terms_from_payload(q, dict(base_terms))
                vals.append(sum(np.asarray(fn(th), dtype=float) for fn in terms.values()))
            cols.append((vals[0] - vals[1]) / (2.0 * h))
            names.append((i, name))
    return (np.column_stack(cols) if cols else np.zeros((th.size, 0))), names


def _refitted_payload(payload: Mapping[str, Any], names: list[tuple[int, str]], dp: list[float]) -> dict[str, Any]:
    """The model file with each refitted parameter moved by its correction δp (refine_eccentricity)."""
    import copy

    out = copy.deepcopy(dict(payload))
    for (i, name), d in zip(names, dp):
        out["effects"][i]["params"][name] = float(out["effects"][i]["params"][name]) + float(d)
    return out


def _bench(bench: dict[str, Any]) -> Bench:
    """The manifest's bench block as read (validated by analysis.dataset, docs/dataset-format.md)."""
    return cast(Bench, dict(bench))


def _step(ds: Dataset, table: str, fn, *args):
    """One analysis step; data it cannot analyse (a ValueError of the analysis: too few positions
    for the Fourier order, a singular design, …) is the dataset's error, named by its table (issue
    #13: what validate accepts either runs or gets a clear exit 2, never a traceback)."""
    try:
        return fn(*args)
    except DatasetError:
        raise
    except ValueError as exc:
        raise DatasetError(f"{ds.path / table}: cannot be analysed: {exc}") from None


@overload
def analyze(dataset: str | Path | Dataset, out: None = None, *, force: bool = False, order: int = 10,
            model_file: str | Path | None = None, progress: bool = True, close_loop: bool = True,
            preface: list | None = None) -> Results: ...


@overload
def analyze(dataset: str | Path | Dataset, out: str | Path, *, force: bool = False, order: int = 10,
            model_file: str | Path | None = None, progress: bool = True, close_loop: bool = True,
            preface: list | None = None) -> dict[str, Any]: ...


def analyze(dataset: str | Path | Dataset, out: str | Path | None = None, *, force: bool = False, order: int = 10,
            model_file: str | Path | None = None,
            progress: bool = True, close_loop: bool = True, preface: list | None = None) -> Results | dict[str, Any]:
    """Analyse a dataset directory (or an open :class:`Dataset`).

    ``out`` None (a notebook): in memory; nothing is written anywhere (no report, no results.json,
    no calibration files, no model file); returns the :class:`~benchtwin.analysis.results_api.Results`
    (a read-only mapping of results.json's keys with typed properties). ``force`` needs ``out``.

    ``out`` a folder: ``results.json``, ``report.html``, the calibration files and ``model.json``
    when the loop identifies effects, by the writing rule of ``benchtwin analyze``
    (issue 31, ``benchtwin.fsio``): a non-empty ``out`` is refused unless ``force``; a folder
    another live run holds, and an ``out`` that is, contains or lies inside the dataset or the
    model file, are refused whatever ``force`` says; the folder is built beside ``out`` and
    renamed onto it when complete (a failed run keeps the previous output).

    ``preface``: [(matplotlib figure, caption)] the report opens with (the app layer's rendered
    view of the bench; the analysis itself never builds the twin).

    With ``out``, returns ``{"results": Results, "paths": {"results": ..., "report": ..., "model": ...?}}``
    (as before the in-memory form: ``res["results"]["eccentricity_um"]`` still works).
    Raises :class:`DatasetError` for invalid input (naming file, row, column), and
    ``benchtwin.fsio.OutputError`` for an output folder the rule refuses.
    """
    from benchtwin.fsio import AtomicDir

    if isinstance(dataset, Dataset):
        dataset = dataset.path
    if out is None:
        if force:
            raise ValueError("analyze: force=True needs an output folder (out=None writes nothing)")
        return Results(analyze_into(dataset, None, order=order, model_file=model_file, progress=progress,
                                    close_loop=close_loop)["results"])
    if model_file is not None:  # a bad model file is named as such before any output rule applies
        from benchtwin.analysis.model_file import read_model_file

        read_model_file(model_file)
    out = Path(out)
    with AtomicDir(out, force=force, what="analysis output folder", owner="analyze",
                   inputs=[dataset, model_file]) as tmp:
        res = analyze_into(dataset, tmp, order=order, model_file=model_file, progress=progress,
                           close_loop=close_loop, preface=preface)
        res["paths"] = retarget(res["paths"], tmp, out)
    res["results"] = Results(res["results"])
    return res


def retarget(paths: dict[str, str], tmp: Path, out: Path) -> dict[str, str]:
    """Paths built under an ``AtomicDir``'s temporary folder ``tmp``, as they are once it is renamed
    to ``out``. The texts written there (report, results, model file) that name ``tmp`` are
    rewritten (atomically) to name ``out``, so no report points at a folder that no longer exists."""
    for name in ("report.html", "results.json", "model.json"):
        f = tmp / name
        if f.is_file():
            text = f.read_text(encoding="utf-8")
            if str(tmp) in text:
                atomic_write_text(f, text.replace(str(tmp), str(out)))
    return {k: str(out / Path(v).relative_to(tmp)) if Path(v).is_relative_to(tmp) else v for k, v in paths.items()}


def analyze_into(dataset: str | Path, out_dir: str | Path | None, *, order: int = 10,
                 model_file: str | Path | None = None,
                 progress: bool = True, close_loop: bool = True, preface: list | None = None) -> dict[str, Any]:
    """``analyze`` writing in place into ``out_dir``, a folder the caller has prepared and holds
    (``benchtwin run`` analyses into its own partial folder, beside the dataset it simulated);
    the files it writes there are replaced. ``out_dir`` None: nothing is written (``paths`` is
    empty). Everyone else calls ``analyze``."""
    from benchtwin.analysis.error_model import compare_with_measured, error_model_from_results

    ds = open_dataset(dataset, order)
    # every table read and checked (cells, and the structure each step assumes at this order:
    # analysis/structure.py) before any analysis step runs; the same check as validate's
    ds.check_tables()
    model_payload: dict[str, Any] | None = None
    if model_file is not None:
        from benchtwin.analysis.model_file import read_model_file

        model_payload = read_model_file(model_file)  # checked before any analysis runs (issue #13)
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    if ds.kind == "error-curve":
        return analyze_error_curve_dataset(ds, out, close_loop=close_loop)
    b = ds.bench
    r_um = b["optical_radius_mm"] * 1000.0
    results: BenchResults = {
        "format": "bench-results", "version": 1, "dataset": str(ds.path), "source": ds.manifest["source"],
        "bench": _bench(b), "notes": [],
    }

    rm: RadialMotionResult | None = None
    ecc: EccentricityResult | None = None
    pol: PolygonAnalysis | None = None
    if ds.has("radial_motion"):
        rm = _step(ds, "radial_motion.csv", step_radial_motion, ds, order)
        results["radial_motion"] = rm.to_json()
        results["radial_error_motion"] = _iso_summary(rm.iso230_7)
    if ds.has("ccd/index"):
        ecc = _step(ds, "ccd/index.csv", step_eccentricity, ds, order, progress)
        if rm is not None and ecc.sweeps is None:
            # one sweep also carries the async motion's 1st harmonic (Jia eqs. 11-12): a type B
            # term from the radial run's repetitions; repeated sweeps hold it in their own scatter
            ecc = ecc.with_async_motion(rm.u_h1_async_um, rm.u_h1_async_dof)
        results.update(cast(BenchResults, ecc.to_json()))
        if ecc.rejected_frames:
            results["notes"].append(
                f"CCD: {len(ecc.rejected_frames)} of {ecc.n_frames} frames rejected and dropped "
                f"({', '.join(r['file'] for r in ecc.rejected_frames)}); e and θ0 fitted on the "
                f"{len(ecc.files)} remaining angles (≥ {ecc.min_frames} required)")
    if ds.has("polygon"):
        pol = _step(ds, "polygon.csv", step_polygon, ds)
        results.update(pol.to_json())
        results["notes"] += pol.notes
        iso2 = _step(ds, "polygon.csv", step_iso230_2_polygon, ds, pol)
        if iso2 is not None:
            results["iso230_2"] = iso2

    # Jia eq. 5: the error model from the measured eccentricity and radial motion.
    model = None
    if ecc is not None:
        model = error_model_from_results(ecc.detail, rm.detail if rm is not None else None, r_um)
        if model_payload is not None:
            from benchtwin.analysis.tracing import add_to_error_model

            added = add_to_error_model(model, model_payload)
            results["model_file_terms"] = added
        grid = np.arange(0.0, 360.0, 1.0)
        results["model_prediction_arcsec"] = ModelPrediction(theta_deg=grid, value=model.predict(grid),
                                                             u=model.uncertainty(grid),
                                                             terms=dict(model.predict_terms(grid).items()))
    else:
        results["notes"].append("no CCD images: the Jia error model (eq. 5) needs the eccentricity; no prediction")

    cmp = None
    if model is not None and pol is not None:
        enc = pol.encoder_error_arcsec
        cmp = compare_with_measured(np.asarray(enc["theta_deg"]), np.asarray(enc["value"]), model)
        u_meas = float(np.sqrt(np.mean(np.square(np.asarray(enc["u"], dtype=float)))))
        u_pts = _alpha_u(enc, u_meas if u_meas > 0 else 1.0)
        results["residual_before"] = _residual_summary(cmp, u_meas, _constant_fit(cmp, u_pts))
        results["comparison"] = Comparison(theta_deg=cmp["theta_deg"], measured_arcsec=cmp["measured_arcsec"],
                                           model_arcsec=cmp["model_arcsec"], residual_arcsec=cmp["residual_arcsec"])

    paths = {"results": str(out / "results.json"), "report": str(out / "report.html")} if out is not None else {}
    ev = tr = None
    if pol is not None:  # the raw curve until the loop identifies an artefact of the reference chain
        results["encoder_error_corrected_arcsec"] = corrected_curve(pol.encoder_error_arcsec, None, {})
    if close_loop and cmp is not None and ecc is not None and pol is not None and model is not None:
        ev, tr = _close_loop(ds, results, rm, ecc, pol, model, paths, out)

    if out is None:  # in memory (analyze(dataset) in a notebook): nothing written
        return {"results": results, "paths": paths}
    _write_report(out, ds, results, rm, ecc, pol, model, cmp, ev, tr, preface)
    # the calibration result a lab uses, beside results.json (analysis/calibration.py)
    paths.update(write_calibration_files(out, results))
    # written last (atomically, benchtwin.fsio): results.json is the completion marker of an analysis
    atomic_write_text(out / "results.json", json.dumps(_jsonable(results), indent=1, sort_keys=True) + "\n")
    return {"results": results, "paths": paths}


def corrected_curve(enc: Curve | Mapping[str, Any], theta_read_deg,
                    corrections: Mapping[str, Mapping[str, Any]],
                    in_readings: frozenset[str] = frozenset()) -> CorrectedCurve:
    """The encoder's error after removing the identified artefacts of the reference chain.

    ``enc``: the measured curve {theta_deg, value, u} (Hsieh's combined α); ``corrections``: per
    reading (at ``theta_read_deg``) the contribution and u of each identified reference-chain effect
    (tracing ``reference_corrections``). At each θ of the curve the correction is the mean of the
    readings' contributions at that stop (±``THETA_BIN_DEG``/2; the curve averages the same readings)
    and its u the mean of theirs (fully correlated: one set of parameters); u of the corrected value =
    √(u_curve² + Σ u_correction²). Effects named in ``in_readings`` were already removed from the
    autocollimator readings before the shift-angle solution that gave ``enc``
    (:func:`reading_corrections`): only their u is added. Unchanged (and ``corrections_applied``
    empty) without corrections."""
    from benchtwin.analysis.tracing import THETA_BIN_DEG

    th = np.asarray(enc["theta_deg"], dtype=float)
    val = np.asarray(enc["value"], dtype=float).copy()
    u2 = np.asarray(enc["u"], dtype=float) ** 2
    applied: list[CorrectionApplied] = []
    if corrections and theta_read_deg is not None:
        tr_ = np.mod(np.asarray(theta_read_deg, dtype=float), 360.0)
        d = np.abs(((tr_[None, :] - np.mod(th, 360.0)[:, None]) + 180.0) % 360.0 - 180.0)
        near = d <= THETA_BIN_DEG / 2.0
        cnt = near.sum(axis=1)
        for name, c in sorted(corrections.items()):
            v = np.asarray(c["value_arcsec"], dtype=float)
            uc = np.asarray(c["u_arcsec"], dtype=float)
            corr = np.where(cnt > 0, (near @ v) / np.maximum(cnt, 1), 0.0)
            ucorr = np.where(cnt > 0, (near @ uc) / np.maximum(cnt, 1), 0.0)
            if name not in in_readings:
                val = val - corr
            u2 = u2 + ucorr ** 2
            applied.append(CorrectionApplied(effect=name, rms_arcsec=float(np.sqrt(np.mean(corr ** 2))),
                                             u_rms_arcsec=float(np.sqrt(np.mean(ucorr ** 2))), params=c.get("params"),
                                             angles_without_readings=int(np.sum(cnt == 0))))
    return CorrectedCurve(theta_deg=th, value=val, u=np.sqrt(u2), corrections_applied=applied,
                          note="the measured encoder error minus the identified artefacts of the reference chain "
                               "(autocollimator scale, non-linearity and drift, polygon pitch, disk-to-polygon "
                               "twist); the raw curve when none is identified. Stated at the calibration points "
                               "(theta_deg) only: no value between them (periods shorter than twice the step, "
                               "e.g. the sub-division error, are not sampled)")


def reading_corrections(tr: TraceOutcome, ev: Any) -> dict[str, np.ndarray]:
    """{effect: what it added to each raw autocollimator reading (arcsec)} for the identified
    reference-chain effects that act on the reading itself (an effect module's ``reading_correction``:
    ac_scale's (k/100)·ε + q·ε²). The pipeline subtracts them from the readings and repeats the
    shift-angle solution: the corrected curve and the residual after the loop then come out of the
    same analysis as the measured curve. Empty when nothing of the kind is identified."""
    from benchtwin.analysis.effects import ALL

    out: dict[str, np.ndarray] = {}
    for eff in tr.identified_effects:
        fn = getattr(ALL.get(eff["name"]), "reading_correction", None)
        if fn is not None and eff["name"] in tr.reference_corrections:
            out[eff["name"]] = np.asarray(fn(ev, eff["params"]), dtype=float)
    return out


def corrected_polygon(ds: Dataset, poly: Mapping[str, Any], pol: PolygonAnalysis, tr: TraceOutcome,
                      ev: Any) -> CorrectedCurve:
    """The corrected calibration curve from the same pipeline as the measured one: an identified
    artefact of the autocollimator acts on the reading it measures (ε = α + Σβ + U, Hsieh eq. 3), so
    it is removed from every reading of ``poly`` (the table ``ev`` was built from) and the shift-angle
    solution is repeated (β, U, α); the other artefacts of the reference chain are then subtracted per
    stop (:func:`corrected_curve`). ``pol``'s curve when nothing acts on the readings."""
    in_readings = reading_corrections(tr, ev)
    pol_c = pol
    if in_readings:
        poly_c = dict(poly)
        poly_c["ac_arcsec"] = np.asarray(poly["ac_arcsec"], dtype=float) - sum(in_readings.values())
        pol_c = step_polygon(ds, poly_c)
    return corrected_curve(pol_c.encoder_error_arcsec, ev.theta_deg, tr.reference_corrections, frozenset(in_readings))


def reading_response(poly: dict[str, Any], pol: PolygonAnalysis, d: np.ndarray, n_faces: int) -> np.ndarray | None:
    """The α per reading that a perturbation ``d`` of every autocollimator reading produces after the
    shift-angle analysis (Hsieh eqs. 5-7: β from the closure of the reference shift's full table, or
    the certificate, which does not move; U_j per start face; α = ε − Σβ − U, eq. 3). The analysis is
    linear in ε, so this is the exact first-order column of an effect that adds ``d`` to the readings:
    e.g. an autocollimator non-linearity q·ε² (ac_scale), whose face-fixed part the closure puts into
    β and whose per-run mean goes into U. None if the analysis cannot be repeated on ``d``."""
    from benchtwin.analysis import shift_angle as sa

    N = int(n_faces)
    try:
        t = sa.tabulate_polygon({**poly, "ac_arcsec": d}, N)
        src = pol.beta_source
        res = sa.shift_angle_analysis(t, beta_from=sa.BetaSource(src, np.zeros(N) if src == "certificate" else None))
    except (sa.PolygonDataError, ValueError):
        return None
    U = {}
    for sr in res.shifts:
        for f, u in zip(sr.start_faces, sr.U_arcsec):
            U[(round(float(sr.shift_deg), 6), int(f))] = float(u)
    beta = np.asarray(res.beta_arcsec, dtype=float)
    cum = np.concatenate([[0.0], np.cumsum(np.concatenate([beta, beta]))])
    j = np.asarray(poly["start_face"]).astype(int)
    i = np.asarray(poly["step"]).astype(int)
    S = np.asarray(poly["shift_deg"], dtype=float)
    try:
        Uj = np.array([U[(round(float(s_), 6), int(f))] for s_, f in zip(S, j)])
    except KeyError:
        return None
    return np.asarray(d, dtype=float) - (cum[j - 1 + i] - cum[j - 1]) - Uj


def _per_reading_after(ev: Any, tr: TraceOutcome, model2: Any, ccd: Mapping[str, Any], r_um: float,
                       payload: Mapping[str, Any], col_names: list[tuple[int, str]], ref: Mapping[str, Any]
                       ) -> float | None:
    """RMS per polygon reading of the residual after the model of ``residual_after``: the tracing's
    residual after its effects (closure-centred, residual_after_trace) with the eq. 3 term moved from
    the CCD's (e, θ0) to the refined one, the first-order graduation term and the refitted parameters'
    corrections, all evaluated at the readings' θ — the same model as the stops' residual, per reading
    (what ``benchtwin score`` compares with its per-reading floor)."""
    from benchtwin.analysis.error_model import eccentricity_term
    from benchtwin.analysis.report.figures_loop import effect_contribution
    from benchtwin.analysis.tracing import _center

    if not tr.identified_effects:
        return None
    th = np.deg2rad(np.asarray(ev.theta_deg, dtype=float))
    r1 = _center(ev.residual_arcsec, ev.closure_group, 1.0 / ev.u_arcsec ** 2) - effect_contribution(ev, tr.detail)
    delta = (eccentricity_term(ref["e_um"], ref["theta0_deg"], r_um)(th)
             - eccentricity_term(ccd["e_um"], ccd["theta0_deg"], r_um)(th))
    if "graduation_k1" in model2.terms:
        delta = delta + model2.terms["graduation_k1"](th)
    if col_names:
        cols, _ = traced_columns(payload, dict(model2.terms), np.asarray(ev.theta_deg, dtype=float))
        delta = delta + cols @ np.asarray(ref["column_params"], dtype=float)
    r2 = r1 - _center(delta, ev.closure_group, 1.0 / ev.u_arcsec ** 2)
    return float(np.sqrt(np.mean(r2 ** 2)))


def _close_loop(ds: Dataset, results: BenchResults, rm: RadialMotionResult | None, ecc: EccentricityResult,
                pol: PolygonAnalysis, model: Any, paths: dict[str, str], out: Path | None) -> tuple[Any, TraceOutcome]:
    """Jia's residual → significance, signature, effect selection (analysis.tracing), then the
    chosen effect joins the model and the comparison is redone (before/after)."""
    from benchtwin.analysis.error_model import (EccentricityEstimate, compare_with_measured, eccentricity_term,
                                                error_model_from_results, refine_eccentricity)
    from benchtwin.analysis.tracing import RadialMotion, add_to_error_model, evidence_from_polygon, save_model, trace

    b = ds.bench
    radial = None
    if rm is not None:
        t = ds.table("radial_motion")
        radial = RadialMotion(t["theta_deg"], t["probe_top_um"], t["probe_bottom_um"], b["L1_mm"], b["L2_mm"],
                              top_x_um=t.get("probe_top_x_um"), bottom_x_um=t.get("probe_bottom_x_um"), rep=t["rep"])
    sc_cal = pol.selfcal_error_arcsec
    if sc_cal and not np.all(np.isfinite(np.asarray(sc_cal["u"], dtype=float))):
        # 2 heads: δ = α(θ) − α(θ+180°) fixes every odd harmonic with no redundancy, so no u; evidence
        # without an uncertainty cannot be weighted (issue #13: the close loop's SVD did not converge)
        results["notes"].append("close loop: the self-calibration has no uncertainty (no redundancy between the "
                                "heads), so it is not used as evidence")
        sc_cal = None
    rep = pol.repeatability
    if pol.budget_summary:
        u_eps = float(pol.budget_summary["u_c"])
    else:
        # no budget: the declared autocollimator's type B parts (resolution r/(2√3), max error a/√3,
        # Hsieh sec. 3.3 (2), (4)) with the readings' repeatability where the data give one
        ac = pol.autocollimator_declared
        res_, acc_ = ac["resolution_arcsec"], ac["accuracy_arcsec"]
        s_rep = rep.get("pooled_sd_eps_arcsec") or 0.0
        u_eps = math.sqrt((res_ / (2 * math.sqrt(3.0))) ** 2 + (acc_ / math.sqrt(3.0)) ** 2 + float(s_rep) ** 2)
    u_read = rep.get("pooled_sd_eps_arcsec") or rep.get("closure_sd_arcsec") or u_eps
    poly = {k: (v.astype(str) if v.dtype == object else v) for k, v in polygon_table(ds).items()}
    ev = evidence_from_polygon(
        poly, pol.pitch_deviation_arcsec, _setup_error_lookup(pol), model,
        n_faces=b["polygon_faces"], u_arcsec=float(u_read), radial=radial,
        selfcal_theta_deg=sc_cal["theta_deg"] if sc_cal else None,
        selfcal_value_arcsec=sc_cal["value"] if sc_cal else None,
        selfcal_u_arcsec=np.asarray(sc_cal["u"]) if sc_cal else None,
        n_heads=len(b.get("heads_deg", [0])),
        optical_radius_mm=b["optical_radius_mm"], L1_mm=b["L1_mm"], L2_mm=b["L2_mm"],
        grating_period_um=b["grating_period_um"], encoder_lines=b.get("encoder_lines"),
        radial_term="radial_motion" if rm is not None else None,
        u_floor_arcsec=max(float(u_read), u_eps),
    )
    ev.ac_quadratic_response = reading_response(poly, pol, np.asarray(poly["ac_arcsec"], dtype=float) ** 2,
                                                b["polygon_faces"])
    ev.add_eccentricity_uncertainty(ecc.e_um, ecc.theta0_deg, ecc.u_e_um, ecc.u_theta0_deg)
    tr = TraceOutcome.from_trace(trace(ev))
    results["close_loop"] = tr.to_json()
    results["identified_effects"] = tr.identified_effects
    results["ambiguous"] = tr.ambiguous
    results["unexplained"] = tr.unexplained
    results["residual_test"] = tr.residual_before
    results["residual_after_trace"] = tr.residual_after
    corrected = corrected_polygon(ds, poly, pol, tr, ev)
    results["encoder_error_corrected_arcsec"] = corrected
    if tr.identified_effects:
        if out is not None:
            mpath = out / "model.json"
            save_model(mpath, tr.model_file)
            paths["model"] = str(mpath)
        r_um = b["optical_radius_mm"] * 1000.0
        rm_detail = rm.detail if rm is not None else None
        model2 = error_model_from_results(ecc.detail, rm_detail, r_um)
        added = add_to_error_model(model2, tr.model_file)
        # the model after is compared with the curve the reference chain would have given: the
        # measured one less the identified artefacts of the reference chain (the raw curve when none)
        enc = corrected
        th_c, a_c = np.asarray(enc["theta_deg"]), np.asarray(enc["value"])
        cmp2 = compare_with_measured(th_c, a_c, model2)
        # The model after the loop takes (e, θ0) from the CCD combined with the first harmonic the
        # comparison still shows (error_model.refine_eccentricity): one CCD sweep states e to u(e)
        # of tenths of a µm (Jia: 0.24 µm, ≈ 2.3″ of first harmonic at r = 22 mm), the comparison
        # measures that harmonic to hundredths of an arcsecond — but in α a first-order graduation
        # term reads exactly as eccentricity, so the comparison measures e only within the prior on
        # that term (k1_prior). The traced effects' parameters are refitted with it on the stops
        # (traced_columns): one weighted least-squares fit, whose residual is ``residual_after`` and
        # whose statistics (n_params, dof, χ², leave-one-out) say what that residual can test. The
        # tracing's decisions are made before, on the CCD's values with their u
        # (ev.add_eccentricity_uncertainty); this changes no decision.
        u_c = _alpha_u(enc, u_eps)
        d = ecc.detail
        if th_c.size >= 4:
            base = dict(model2.terms)
            cols, col_names = traced_columns(tr.model_file, base, th_c)
            u_k1, k1_source = k1_prior(tr.detail.get("signature") or {})
            ref = refine_eccentricity(th_c, cmp2["residual_arcsec"], u_c, EccentricityEstimate.from_results(d), r_um,
                                      u_k1_arcsec=u_k1, columns=cols)
            fit = ref.pop("fit")
            ref.pop("residual_arcsec")
            ref["k1_prior"] = {"u_arcsec": u_k1, "u_um": u_k1 * ARCSEC * r_um, "source": k1_source}
            ref["refitted_params"] = [f"{tr.model_file['effects'][i]['name']}.{n}" for i, n in col_names]
            ref["residual_after_ccd_e_pv_arcsec"] = float(cmp2["residual_pv_arcsec"])   # with the CCD's (e, θ0)
            results["eccentricity_refined"] = ref
            # the model after: the refitted traced terms, the eq. 3 term replaced (add_term replaces by
            # name) and the first-order graduation term the fit gave
            model2 = error_model_from_results(ecc.detail, rm_detail, r_um)
            added = add_to_error_model(model2, _refitted_payload(tr.model_file, col_names, ref["column_params"]))
            model2.add_term("eccentricity", eccentricity_term(ref["e_um"], ref["theta0_deg"], r_um, ref["u_e_um"],
                                                              ref["u_theta0_deg"], ref["cov_e_theta0"]))
            if "k1_arcsec" in ref:
                a1, b1 = float(ref["k1_arcsec"]["a1"]), float(ref["k1_arcsec"]["b1"])

                def graduation_k1(t: np.ndarray, a1: float = a1, b1: float = b1) -> np.ndarray:
                    return a1 * np.sin(t) + b1 * np.cos(t)

                model2.add_term("graduation_k1", graduation_k1)
            added = added + ["refined:eccentricity (CCD ⊕ comparison, first-order graduation prior)",
                             "refitted on the stops: " + ", ".join(ref["refitted_params"]) if col_names else
                             "refitted on the stops: none"]
            cmp2 = compare_with_measured(th_c, a_c, model2)
            results["residual_after"] = _residual_summary(cmp2, stats=fit)
            per_reading = _per_reading_after(ev, tr, model2, d, r_um, tr.model_file, col_names, ref)
            if per_reading is not None:
                results["residual_after"]["per_reading_rms_arcsec"] = per_reading
        else:   # a 3-face polygon: (e, θ0) and α's constant leave no degree of freedom
            results["notes"].append(f"(e, θ0) not refined by the comparison: {th_c.size} points, at least 4 needed")
            results["residual_after"] = _residual_summary(cmp2)
        results["residual_after"]["added_terms"] = added
        results["comparison_after"] = Comparison(theta_deg=cmp2["theta_deg"], model_arcsec=cmp2["model_arcsec"],
                                                 residual_arcsec=cmp2["residual_arcsec"])
    else:
        results["residual_after"] = results["residual_before"].copy()
        results["residual_after"]["added_terms"] = []
    return ev, tr


def r_um_of(ds: Dataset) -> float:
    """The optical radius r of the dataset's bench in µm (Jia eq. 5)."""
    return float(ds.bench["optical_radius_mm"]) * 1000.0


def residual_test_text(r: Mapping[str, Any]) -> str:
    """One line on what a residual can test (results.json residual_before / residual_after): stops,
    parameters fitted, dof, χ² and p against u of each α, and the leave-one-out RMS."""
    p = r.get("p_value")
    loo = r.get("loo_rms_arcsec")
    return (f"{r['n_points']} stops, {r['n_params']} parameter{'' if r['n_params'] == 1 else 's'} fitted, {r['dof']} dof; χ² = {r['chi2']:.3g} "
            f"against u of each α (p = {'–' if p is None else f'{p:.2g}'}); each stop predicted by the fit made "
            f"without it: {'no such fit (a stop alone fixes a parameter)' if loo is None else f'{loo:.3g}″ RMS'}")


def _write_report(out: Path, ds: Dataset, results: BenchResults, rm: RadialMotionResult | None,
                  ecc: EccentricityResult | None, pol: PolygonAnalysis | None, model: Any, cmp: Any, ev: Any,
                  tr: TraceOutcome | None, preface: list | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from benchtwin.analysis.report.html import Report, value_with_u

    rep = Report(f"Encoder calibration bench — {ds.manifest.get('scenario', ds.path.name)}")
    rep.paragraph(f"Dataset {ds.path} (source: {ds.manifest['source']}). Analysis: Jia et al. 2019 "
                  "(radial motion, eccentricity from CCD images, error model eq. 5) and Hsieh et al. 2022 "
                  "(shift-angle method, self-calibration, GUM budget). Standard uncertainties unless stated.")
    from benchtwin.analysis.report.figures_calibration import add_calibration_section

    add_calibration_section(rep, calibration_curve(results))  # the calibration result first (issue 34)
    for fig, caption in preface or []:
        rep.figure(fig, caption)
    rows = []
    if ecc is not None:
        rows.append(["eccentricity e (Jia eq. 11)", value_with_u(ecc.e_um, ecc.u_e_um, "µm")])
        rows.append(["eccentricity phase θ0 (eq. 12)", value_with_u(ecc.theta0_deg, ecc.u_theta0_deg, "°")])
        rows.append(["pixel scale (from the grating)", f"{ecc.pixel_um:.5f} µm/px"])
    if rm is not None:
        from benchtwin.analysis.report.figures_iso import iso_band_label

        # two quantities, each under its own name with its bandwidth (issue 34): the P-V of Jia's
        # order-2…10 series (what the error model integrates) and the ISO 230-7 value of the readings
        s = rm.summary["disk"]
        rows.append([f"disk radial motion δY, synchronous P-V of the order-2–10 series (Jia eqs. 7, 9; "
                     f"{iso_band_label(rm.bandwidth)})",
                     value_with_u(s["synchronous_um"], s.get("synchronous_u_um", float("nan")), "µm")])
        disk = next((loc for loc in rm.iso230_7["locations"] if loc["name"] == "disk"), None)
        if disk is not None and math.isfinite(disk["asynchronous_um"]):
            bw, acq = rm.iso230_7["bandwidth"], rm.iso230_7["acquisition"]
            rows.append([f"δY asynchronous error motion, ISO 230-7, disk plane ({iso_band_label(bw)}; step-and-settle, "
                         f"{acq['positions_per_turn']} positions per turn)",
                         value_with_u(disk["asynchronous_um"], disk["asynchronous_u_um"], "µm")])
        rows.append(["u(δY), range method (d_n)", f"{rm.u_dY_range_um:.3f} µm"])
    if pol is not None and pol.budget_summary:
        bs = pol.budget_summary
        rows.append(["shift-angle α: u_c, ν_eff, k, U", f"{bs['u_c']:.3f}″, {bs['nu_eff']:.0f}, {bs['k']:.2f}, {bs['U']:.3f}″"])
        if pol.en_max is not None:
            rows.append(["E_n max (shift-angle vs self-calibration)", f"{pol.en_max:.2f}"])
    test_notes = []
    if "residual_before" in results:
        rb = results["residual_before"]
        rows.append(["residual after the Jia model: RMS / P-V / share", f"{rb['rms_arcsec']:.3f}″ / {rb['pv_arcsec']:.3f}″ / {100 * rb['fraction_of_error']:.1f} %"])
        if "dof" in rb:
            rows.append(["… what it tests", residual_test_text(rb)])
    if "residual_after" in results and results.get("identified_effects"):
        ra = results["residual_after"]
        rows.append(["residual after adding the traced effect(s): RMS / P-V / share",
                     f"{ra['rms_arcsec']:.3f}″ / {ra['pv_arcsec']:.3f}″ / {100 * ra['fraction_of_error']:.1f} %"])
        if "dof" in ra:
            rows.append(["… what it tests", residual_test_text(ra)])
            if ra.get("sampling_note"):
                test_notes.append("Residual after: " + ra["sampling_note"] + ".")
    rep.heading("Summary")
    rep.table(rows, ["quantity", "value"])
    for n in test_notes:
        rep.paragraph(n, note=True)
    for n in results["notes"]:
        rep.paragraph(str(n), note=True)

    from benchtwin.analysis.report import figures_jia as fj

    if rm is not None:
        rep.heading("Radial error motion (Jia sec. 4.1, fig. 13)")
        rep.figure(fj.fig_radial_motion(rm.detail), "Radial error motion of the test spheres and of the grating disk along the head direction")
        from benchtwin.analysis.report.figures_iso import add_iso230_7_section

        add_iso230_7_section(rep, rm.iso230_7, ds, filtered=rm.summary)
    if ecc is not None:
        rep.heading("Eccentricity from CCD images (Jia sec. 4.2, fig. 14)")
        from benchtwin.analysis.report.figures_ccd import add_ccd_pictures

        add_ccd_pictures(rep, ds, ecc.detail)  # the pictures of the image analysis (issue 20)
        rep.figure(fj.fig_dref(ecc.detail, np.asarray(ecc.theta_deg), np.asarray(ecc.d_ref_um)), "d_ref over the sweep and its first harmonic")
        if ecc.rejected_frames:
            rep.paragraph(f"{len(ecc.rejected_frames)} of {ecc.n_frames} frames rejected by the image analysis "
                          f"and dropped; e and θ0 are fitted on the {len(ecc.files)} remaining angles (the "
                          f"least-squares fit of eq. 10 does not need equal spacing; ≥ {ecc.min_frames} "
                          "frames are required).", note=True)
            rep.table([[r["file"], f"{r['theta_deg']:.1f}°", r["stage"], r["reason"]] for r in ecc.rejected_frames],
                      ["rejected frame", "θ", "step", "reason"])
    if model is not None:
        rep.heading("Predicted angle error (Jia eq. 5, fig. 15)")
        rep.figure(fj.fig_predicted_error(model), "Angle error predicted from eccentricity and radial motion")
    if cmp is not None:
        rep.heading("Comparison with the polygon (Jia sec. 4.3, fig. 16)")
        rep.figure(fj.fig_comparison(cmp), "Measured encoder error (polygon + autocollimator) vs model, and the residual")
    if pol is not None:
        from benchtwin.analysis.report import figures_hsieh as fh

        rep.heading("Polygon cross-calibration and shift-angle method (Hsieh 2022)")
        rep.figure(fh.figure_pitch_deviation(pol.detail), "Pitch deviations β of the polygon (Hsieh fig. 6)")
        rep.figure(fh.figure_alpha_at_shifts(pol.detail), "Encoder error at the shift angles (Hsieh fig. 7)")
        if pol.selfcal_error_arcsec:
            rep.figure(fh.figure_selfcal_vs_shift_angle(pol.detail), "Self-calibration vs shift-angle method (Hsieh fig. 11)")
            rep.figure(fh.figure_difference(pol.detail), "Difference between the two methods (Hsieh fig. 12)")
        if results.get("iso230_2"):
            _add_iso230_2_table(rep, results["iso230_2"])
        if pol.budget:
            rep.heading("Uncertainty budget (GUM, Hsieh Table 3)", level=3)
            rep.table([[r.get("name"), r.get("u"), r.get("sensitivity"), r.get("contribution"), r.get("dof")]
                       for r in pol.budget], ["contribution", "u(xᵢ) ″", "∂α/∂xᵢ", "|c|·u ″", "ν"])
    if tr is not None:
        from benchtwin.analysis.report import figures_loop as fl

        rep.heading("Closing the loop: what the model lacks")
        status = tr.status
        names = ", ".join(e["name"] for e in tr.identified_effects) or "none"
        rep.paragraph(f"Status: {status}. Identified: {names}.")
        rb_t, ra_t = tr.residual_before, tr.residual_after
        if tr.identified_effects:
            pars = "; ".join(f"{e['name']}: " + ", ".join(f"{k} = {value_with_u(v, e['u'].get(k, float('nan')), '')}"
                                                         for k, v in e["params"].items()) for e in tr.identified_effects)
            rep.paragraph(
                f"The model lacked {names} ({pars}). Adding it brings the residual per polygon reading from "
                f"{rb_t['rms_arcsec']:.3f}″ RMS ({rb_t['pv_arcsec']:.2f}″ P-V, {100 * rb_t['fraction_of_error']:.1f} % "
                f"of the error) to {ra_t['rms_arcsec']:.3f}″ RMS ({ra_t['pv_arcsec']:.2f}″ P-V, "
                f"{100 * ra_t['fraction_of_error']:.1f} %); noise floor {rb_t.get('noise_floor_arcsec', float('nan')):.3f}″ "
                f"(u of one reading), χ² after {ra_t['chi2']:.0f} for {ra_t['dof']} dof (p = {ra_t['p_value']:.2g}).")
            ra_s: Mapping[str, Any] = results.get("residual_after") or {}
            ref: Mapping[str, Any] = results.get("eccentricity_refined") or {}
            if ra_s.get("per_reading_rms_arcsec") is not None and ref:
                rep.paragraph(
                    f"That residual per reading keeps the Jia model's eccentricity term with the CCD's (e, θ0): its first "
                    f"harmonic is the CCD's e within its u (u(e) = {ref['ccd']['u_e_um']:.3f} µm, "
                    f"{ref['ccd']['u_e_um'] / (r_um_of(ds)) / ARCSEC:.2f}″ at the optical radius). The model after the loop "
                    f"takes the first harmonic from the comparison (e = {ref['e_um']:.3f} ± {ref['u_e_um']:.3f} µm, its u "
                    f"including a first-order graduation term of u = {ref['k1_prior']['u_arcsec']:.2f}″ per component that "
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
        elif tr.partial_effects:
            rep.paragraph("Best candidate (not accepted, the residual after it is still significant): "
                          + ", ".join(e["name"] for e in tr.partial_effects)
                          + f"; left: {', '.join(ra_t.get('signature_left') or [])}.", note=True)
        for e in tr.identified_effects:
            rep.table([[k, value_with_u(v, e["u"].get(k, float('nan')), "")] for k, v in e["params"].items()],
                      [f"{e['name']}: parameter", "value"])
        cc: CorrectedCurve | dict[str, Any] = results.get("encoder_error_corrected_arcsec") or {}
        if cc.get("corrections_applied"):
            rep.paragraph("Corrected calibration curve (encoder_error_corrected_arcsec, the curve a certificate states): "
                          "the measured encoder error minus " + "; ".join(
                              f"{a['effect']} ({a['rms_arcsec']:.3f}″ RMS, u {a['u_rms_arcsec']:.3f}″)"
                              for a in cc["corrections_applied"]) + ".")
        else:
            rep.paragraph("Corrected calibration curve: no artefact of the reference chain identified; the "
                          "measured encoder error is stated unchanged.", note=True)
        for a in tr.ambiguous:
            rep.paragraph(f"Ambiguous: {', '.join(a['names'])}. Separating measurement: {a.get('separating_measurement', '')}", note=True)
        if tr.unexplained:
            rep.paragraph("Unexplained: the residual is significant but no effect of the library explains it; see the signature.", note=True)
        res_b = results.get("residual_before")
        res_a = results.get("residual_after")
        if res_b and res_a:
            rep.table([["before", res_b["rms_arcsec"], res_b["pv_arcsec"], res_b["fraction_of_error"]],
                       ["after", res_a["rms_arcsec"], res_a["pv_arcsec"], res_a["fraction_of_error"]]],
                      ["residual", "RMS ″", "P-V ″", "share of the error"])
        rep.figure(fl.plot_residual_before_after(ev, tr.detail), "Residual before and after adding the traced effect")
        rep.figure(fl.plot_harmonic_spectrum(tr.detail), "Harmonic spectrum of the residual with uncertainties")
        rep.figure(fl.plot_signature(ev, tr.detail), "Signature of the residual: time, start face, direction")
    rep.write(out / "report.html")


# ----------------------------------------------------------------------------- error curves


def _write_results(out: Path, results: ErrorCurveResults) -> None:
    atomic_write_text(out / "results.json", json.dumps(_jsonable(results), indent=1, sort_keys=True) + "\n")


def analyze_error_curve_dataset(ds: Dataset, out: Path | None, *, close_loop: bool = True) -> dict[str, Any]:
    """An "error curve" dataset (an imported α(θ) table): coverage, closure, hysteresis, harmonics with
    u, what a lone curve cannot separate (analysis.error_curve) → results.json + report.html.
    ``close_loop`` adds the verdict keys (status, ambiguous, unexplained) that close-loop reports;
    a lone curve identifies no effect and changes no curve."""
    from benchtwin.analysis.error_curve import analyze_error_curve

    t = ds.table("error_curve")
    try:
        ec = analyze_error_curve(t["theta_deg"], t["error_arcsec"], t.get("direction"), t.get("u_arcsec"))
    except ValueError as exc:
        raise DatasetError(f"{ds.path / 'error_curve.csv'}: {exc}") from None
    mc = ec["mean_curve"]
    arc = None
    if not ec["coverage"]["full_turn"]:
        from benchtwin.analysis.arc_periods import ArcInputError, analyze_arc_periods

        # u from outside the fit (a u column, the two directions) weighs the points; else none
        u_ext = None if ec["u_point"]["source"].startswith("type A from the residual") else mc["u_arcsec"]
        try:
            arc = analyze_arc_periods(mc["theta_deg"], mc["value_arcsec"], u_ext,
                                      drive_elements=ds.manifest.get("drive_elements"))
        except ArcInputError as exc:
            raise DatasetError(f"{ds.path}/{exc}") from None
    iso2 = None
    from benchtwin.analysis.iso230_2 import positioning_statistics, runs_from_error_curve

    runs = runs_from_error_curve(t["theta_deg"], t["error_arcsec"], t.get("direction"))
    if runs is not None:
        iso2 = positioning_statistics(*runs, source="error_curve.csv: one run per direction at the angles measured "
                                                    "in both")
    results = ErrorCurveResults(
        format="bench-results", version=1, dataset=str(ds.path), source=ds.manifest["source"],
        kind="error-curve", bench=_bench(ds.bench), notes=list(ec["notes"]),
        imported_from=ds.manifest.get("import"),
        coverage_deg=ec["coverage_deg"], coverage=ec["coverage"], closure=ec["closure"],
        hysteresis=ec["hysteresis"], u_point=ec["u_point"], harmonics=ec["harmonics"],
        error_curve={k: v for k, v in ec.items() if k not in ("notes",)},
        encoder_error_arcsec=Curve(theta_deg=mc["theta_deg"], value=mc["value_arcsec"], u=mc["u_arcsec"]),
        # nothing of the reference chain is identified on a lone curve: the corrected curve is the raw one
        encoder_error_corrected_arcsec=CorrectedCurve(theta_deg=mc["theta_deg"], value=mc["value_arcsec"],
                                                      u=mc["u_arcsec"], corrections_applied=[]),
    )
    if arc is not None:
        results["arc_periods"] = cast(list[ArcPeriod], arc["periods"])
        results["arc_period_scan"] = arc["scan"]
    if iso2 is not None:
        results["iso230_2"] = cast(Iso230_2, iso2)
    if close_loop:
        results["identified_effects"] = []
        results["ambiguous"] = ec["ambiguous"]
        results["unexplained"] = ec["unexplained"]
        results["close_loop"] = CloseLoop(status=ec["status"], left=ec.get("left", []))
    if out is None:  # in memory: nothing written
        return {"results": results, "paths": {}}
    paths = {"results": str(out / "results.json"), "report": str(out / "report.html")}
    _write_error_curve_report(out, ds, ec, close_loop, calibration_curve(results), arc, iso2)
    paths.update(write_calibration_files(out, results))
    _write_results(out, results)
    return {"results": results, "paths": paths}


def _add_iso230_2_table(rep: Any, iso: Mapping[str, Any]) -> None:
    """The ISO 230-2 figures as a small table (analysis.iso230_2)."""
    n = iso["n_runs"]
    rep.heading("Positioning statistics of the rotary axis (ISO 230-2:2014)", level=3)
    rep.paragraph(f"{iso['n_positions']} target positions, {n['forward']} forward and {n['backward']} backward "
                  f"runs ({iso['source']}). {iso['convention']}. Not included: {iso['excludes']}.")
    rep.table([[f["symbol"], "–" if not math.isfinite(f["value"]) else f"{f['value']:.3f}″", f["what"]]
               for f in iso["figures"].values()], ["figure", "value", "what it is"])
    for fl in iso["flags"]:
        rep.paragraph(fl, note=True)


def _add_arc_periods(rep: Any, arc: Mapping[str, Any]) -> None:
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


def _write_error_curve_report(out: Path, ds: Dataset, ec: dict[str, Any], close_loop: bool,
                              cal: CalibrationCurve | None = None, arc: Mapping[str, Any] | None = None,
                              iso: Mapping[str, Any] | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from benchtwin.analysis.report.html import Report, value_with_u

    rep = Report(f"Encoder error curve — {ds.path.name}")
    imp = ds.manifest.get("import") or {}
    rep.paragraph(f"Dataset {ds.path} (source: {ds.manifest['source']}, an imported error curve"
                  + (f" from {imp.get('table')}" if imp.get("table") else "") + "). A lone curve: no radial probes, "
                  "no CCD, no polygon start faces; what it cannot separate is stated below.")
    from benchtwin.analysis.report.figures_calibration import add_calibration_section

    add_calibration_section(rep, cal)  # the calibration result first (issue 34)
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
    rep.heading("Summary")
    rep.table(rows, ["quantity", "value"])
    for n in ec["notes"]:
        rep.paragraph(str(n), note=True)
    if ec["harmonics"]:
        rep.heading("Harmonics (Jia 2019 eqs. 6, 11, 12), direction mean", level=3)
        rep.table([[x["k"], value_with_u(x["amplitude_arcsec"], x["u_arcsec"], "″"), f"{x['phase_deg']:.1f}°",
                    f"{x['p_value']:.2g}", "yes" if x["significant"] else ""] for x in ec["harmonics"]],
                  ["k", "amplitude", "phase", "p", "significant"])
    for a in ec.get("ambiguous", []):
        rep.paragraph(f"Cannot be separated on this curve: {', '.join(a['names'])}"
                      + (f" (harmonics {a['harmonics']})" if a["harmonics"] else "")
                      + f". Separating measurement: {a['separating_measurement']}", note=True)
    if ec.get("unexplained"):
        rep.paragraph("Unexplained: " + "; ".join(ec.get("left", [])), note=True)
    if arc is not None:
        _add_arc_periods(rep, arc)
    if iso is not None:
        _add_iso230_2_table(rep, iso)
    fig, ax = plt.subplots(figsize=(7, 3.2))
    t = ds.table("error_curve")
    d = t.get("direction")
    for name in ("forward", "backward"):
        m = np.ones(len(t["theta_deg"]), bool) if d is None else (d == name)
        if m.any():
            o = np.argsort(t["theta_deg"][m])
            ax.plot(t["theta_deg"][m][o], t["error_arcsec"][m][o], "o-", ms=3, label=name if d is not None else "error")
    mc = ec["mean_curve"]
    ax.errorbar(mc["theta_deg"], mc["value_arcsec"], yerr=mc["u_arcsec"], fmt="k.", ms=2, lw=0.6, label="mean ± u")
    ax.set_xlabel("θ (°)")
    ax.set_ylabel("error (″)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    rep.figure(fig, "The imported error curve")
    plt.close(fig)
    rep.write(out / "report.html")
