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
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, TypedDict, cast, overload

import numpy as np

from benchtwin.analysis.calibration import calibration_curve, write_calibration_files
from benchtwin.analysis.dataset import Dataset, DatasetError, open_dataset
from benchtwin.analysis.results import (AutocollimatorDeclared, Bench, BudgetInput, CorrectedCurve, CorrectionApplied,
                                        Curve, ModelPrediction, RejectedFrame, ResidualSummary)
from benchtwin.analysis.results_api import Results
from benchtwin.analysis.steps import (CurveArrays, ModelFileEffect, ReferenceCorrection, SignatureHarmonic,
                                      combined_sweeps, payload_with_params,
                                      BenchAnalysis, BenchGeometry, CcdFrames, CcdSweepSetup, EccentricityResult,
                                      ErrorCurveAnalysis, ErrorCurveTable, FitStatistics, LoopOutcome, ModelComparison,
                                      PolygonAnalysis, PolygonReadings, RadialMotionResult, RadialMotionTable, RefinedEccentricity,
                                      TraceOutcome)
from benchtwin.jsonable import to_json
from benchtwin.units import ARCSEC
from benchtwin.fsio import atomic_write_text

if TYPE_CHECKING:
    from typing_extensions import Unpack


# results.json: strict JSON (non-finite -> null), model-term functions left out (benchtwin/jsonable.py)
_jsonable = functools.partial(to_json, nonfinite="null", drop_callables=True)

def _progress(enabled: bool, total: int, desc: str):
    from tqdm.auto import tqdm  # a notebook widget in Jupyter, the text bar elsewhere (issue 34)

    return tqdm(total=total, desc=desc, disable=not enabled, unit="step", leave=False)


# ----------------------------------------------------------------------------- steps


def step_radial_motion(ds: Dataset, order: int) -> RadialMotionResult:
    """Radial error motion from the two test spheres (Jia eqs. 6-9), with its ISO 230-7 values."""
    from benchtwin.analysis.radial_motion import ProbeReadings, RadialOptions, SphereSpacing, radial_motion

    t, drift = radial_table(ds)
    b = BenchGeometry.from_manifest(ds.bench)
    L1_mm, L2_mm = b.sphere_distances_mm

    def reduce(tt: RadialMotionTable) -> dict[str, Any]:
        return radial_motion(ProbeReadings(tt.rep, tt.theta_deg, tt.probe_top_um, tt.probe_bottom_um,
                                           probe_top_x_um=tt.probe_top_x_um, probe_bottom_x_um=tt.probe_bottom_x_um),
                             SphereSpacing(L1_mm, L2_mm), RadialOptions(order=order))

    rm = reduce(t)
    if drift is not None:
        # Jia sec. 5's range method on the readings as taken (Jia removed no drift): the number to
        # compare with the paper's 0.18 µm; u_dY_range_um is the drift-corrected one
        drift["u_dY_range_as_read_um"] = float(reduce(RadialMotionTable.from_table(ds.table("radial_motion")))
                                               ["u_dY_range_um"])
    # with the ISO 230-7 values and polar plots (issue 20)
    return RadialMotionResult.from_radial_motion(rm, step_iso230_7(ds, rm, order, table=t), probe_drift=drift,
                                                 readings=t)


def radial_table(ds: Dataset) -> tuple[RadialMotionTable, dict[str, Any] | None]:
    """radial_motion.csv less the probes' time-smooth drift where one is significant
    (:meth:`RadialMotionTable.drift_corrected`, analysis/probe_drift.py), and the drift's summary
    (None: the readings as they are). Every reduction of the probes (Jia eqs. 6-9, ISO 230-7, the
    loop's radial evidence and its asynchronous term) reads this table."""
    t = RadialMotionTable.from_table(ds.table("radial_motion"))
    b = BenchGeometry.from_manifest(ds.bench)
    L1_mm, L2_mm = b.sphere_distances_mm
    return t.drift_corrected(L1_mm, L2_mm, b.optical_radius_mm)


def step_iso230_7(ds: Dataset, rm: dict[str, Any], order: int,
                  table: RadialMotionTable | None = None) -> dict[str, Any]:
    """ISO 230-7 total / synchronous / asynchronous radial error motion (analysis.iso230_7), of
    ``table`` (default: :func:`radial_table`)."""
    from benchtwin.analysis.iso230_7 import radial_error_motion

    from benchtwin.analysis.iso230_7 import axial_face_error_motion

    t = table if table is not None else radial_table(ds)[0]
    b = BenchGeometry.from_manifest(ds.bench)
    L1_mm, L2_mm = b.sphere_distances_mm
    out = radial_error_motion(t.rep, t.theta_deg, t.probes(), L1_mm, L2_mm, rm=rm, order=order)
    raw = ds.table("radial_motion")
    if "probe_axial_um" in raw or "probe_face_um" in raw:   # probes parallel to the axis (optional)
        out["axial_face"] = axial_face_error_motion(raw["rep"], raw["theta_deg"], raw.get("probe_axial_um"),
                                                    raw.get("probe_face_um"), ds.bench.get("face_probe_radius_mm"),
                                                    order)
    return out


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


def _min_frames(n_frames: int, order: int) -> int:
    """The fewest usable frames of ``n_frames`` the eccentricity fit accepts (ccd_frame_limits)."""
    return ccd_frame_limits(n_frames, order)["min_frames"]


def ccd_frame_limits(n_frames: int, order: int) -> dict[str, int]:
    """The smallest number of usable CCD frames the eccentricity fit accepts (see above)."""
    by_fit = 2 * order + 1 + CCD_MIN_DOF
    by_fraction = int(math.ceil((1.0 - CCD_MAX_REJECTED_FRACTION) * n_frames - 1e-9))
    return {"min_frames": max(by_fit, by_fraction), "by_fit": by_fit, "by_fraction": by_fraction}


@dataclass(frozen=True)
class _Rejection:
    """A CCD frame the image analysis could not use, and at which stage."""

    file: str
    theta_deg: float
    stage: str
    reason: str


class _FrameCheck:
    """The CCD frames rejected so far and the limit on them (ccd_frame_limits): ``check`` raises the
    DatasetError naming them when too few frames are left for a stage."""

    def __init__(self, ds: Dataset, n_frames: int, order: int) -> None:
        self.ds, self.n_frames, self.order = ds, n_frames, order
        self.limits = ccd_frame_limits(n_frames, order)
        self.min_frames = _min_frames(n_frames, order)
        self.rejected: dict[str, _Rejection] = {}

    def reject(self, f: str, theta: float, stage: str, exc: Exception) -> None:
        msg = str(exc)
        prefix = f"image {f!r}: "
        self.rejected.setdefault(f, _Rejection(file=f, theta_deg=float(theta), stage=stage,
                                               reason=msg[len(prefix):] if msg.startswith(prefix) else msg))

    def check(self, n_used: int, what: str) -> None:
        if n_used < self.min_frames:
            rej = list(self.rejected.values())
            lst = "; ".join(f"{r.file} ({r.stage}): {r.reason}" for r in rej[:5])
            more = f" (and {len(rej) - 5} more)" if len(rej) > 5 else ""
            order = self.order
            raise DatasetError(
                f"{self.ds.path / 'ccd'}: only {n_used} of {self.n_frames} CCD frames usable for the {what}; need ≥ "
                f"{self.min_frames} (the order-{order} series of Jia eq. 10 has {2 * order + 1} coefficients "
                f"+ {CCD_MIN_DOF} residual dof for u(e), and at most {CCD_MAX_REJECTED_FRACTION:.0%} of the frames "
                f"may be rejected before the failure counts as systematic). Rejected: {lst}{more}")

    def rejected_frames(self) -> list[RejectedFrame]:
        return [RejectedFrame(file=r.file, theta_deg=r.theta_deg, stage=r.stage, reason=r.reason)
                for r in self.rejected.values()]


def step_eccentricity(ds: Dataset, order: int, progress: bool, workers: int | None = None) -> EccentricityResult:
    """e and θ0 from the CCD sweep (Jia eqs. 10-13), in two stages: the pixel scale first (from the
    grating period, Jia eq. 13), then d_ref with the edge radius fixed where the manifest knows it
    (Jia: "r_fitting is already known") — a short arc of a 22 mm circle does not determine its radius
    well. A frame the image analysis rejects is dropped from that stage on and recorded (module
    constants above); ``workers``: threads for the frames (_ccd_edges)."""
    ccd = ds.manifest.get("ccd")
    if ccd is None:
        raise DatasetError(f"{ds.path}/manifest.json: key 'ccd' is required when ccd/index.csv is present")
    geo = BenchGeometry.from_manifest(ds.bench)
    setup = CcdSweepSetup.from_dataset(ccd, ds.table("ccd/index"))
    frames = _FrameCheck(ds, setup.n_frames, order)
    meta, edges, scales = _ccd_edges(ds, geo, frames, progress, workers)
    frames.check(len(scales), "pixel scale (Jia eq. 13)")
    scale = float(np.median(scales))
    edge_mm = geo.scale_edge_radius_mm
    radius_px = edge_mm * 1000.0 / scale if edge_mm else None
    thetas, drefs_px, files, first_fit = _d_ref_stage(meta, edges, setup.reference_px, radius_px, frames)
    frames.check(len(thetas), "eccentricity fit (Jia eqs. 10-12)")
    dref_um = np.asarray(drefs_px) * scale
    fit = _fit_sweeps(ds, setup, np.asarray(thetas), dref_um, files, order)
    return EccentricityResult.from_frames(fit, CcdFrames(
        pixel_um=scale, radius_fixed_px=radius_px, theta_deg=thetas, d_ref_um=dref_um, files=files,
        n_frames=frames.n_frames, rejected_frames=frames.rejected_frames(), frame_limits=frames.limits,
        first_frame_fit=first_fit))


def _ccd_edges(ds: Dataset, geo: BenchGeometry, frames: _FrameCheck, progress: bool, workers: int | None
               ) -> tuple[list[tuple[float, str]], list[Any], list[float]]:
    """The pixel-scale stage: each frame decoded once and its line edges found once
    (ecc.frame_edges_and_scale), frames in worker threads (analysis/parallel.py: in order,
    bit-identical to the serial loop, at most a few frames in flight; frames are read and checked in
    this thread); only the edges (a few hundred numbers per frame) are kept for the d_ref stage, so
    memory stays flat for long sweeps of large frames. ``workers``: threads (default:
    BENCHTWIN_WORKERS, else the cores that help, as measured, see analysis/parallel.py; 1 = serial,
    in this thread). Returns (θ, file) per frame in index order, its edges (None if rejected) and
    the scales of the frames kept."""
    from collections.abc import Iterator

    from benchtwin.analysis import eccentricity as ecc
    from benchtwin.analysis.parallel import ordered_map

    period_um = geo.grating_period
    meta: list[tuple[float, str]] = []  # (theta, file) per frame, in index order

    def sweep_frames() -> Iterator[tuple[np.ndarray, float, str]]:
        for _k, theta, image, f in ds.ccd_frames():
            meta.append((float(theta), f))
            yield image, period_um, f

    scales: list[float] = []
    edges: list[Any] = []  # per frame: its LineEdges, or None if rejected
    bar = _progress(progress, frames.n_frames, "CCD images")
    # The first frame that can be analysed is done here (before any pool starts): its lines' polarity
    # is the one the other frames are expected to have, which orders their labelling work only
    # (ecc.segment_lines: each frame decides its own polarity, the same whatever is expected)
    sweep = sweep_frames()
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
            frames.reject(f, theta, "pixel scale (eq. 13)", exc or ecc.ImageAnalysisError("no pixel scale"))
            edges.append(None)
            continue
        scales.append(scale_i)
        edges.append(ed)
    bar.close()
    return meta, edges, scales


def _d_ref_stage(meta: list[tuple[float, str]], edges: list[Any], ref: tuple, radius_px: float | None,
                 frames: _FrameCheck) -> tuple[list[float], list[float], list[str], dict[str, Any] | None]:
    """d_ref per frame (Jia eqs. 10-12) from the edges of the pixel-scale stage: (θ, d_ref in px, file)
    of the frames used and the first one's fit, which the report draws (figures_ccd.add_ccd_pictures)."""
    from benchtwin.analysis import eccentricity as ecc

    thetas: list[float] = []
    drefs_px: list[float] = []
    files: list[str] = []
    first_fit: dict[str, Any] | None = None
    for (theta, f), ed in zip(meta, edges):
        if ed is None:
            continue  # its line ends were not found for the pixel scale: not trusted for d_ref either
        try:
            fit = ecc.d_ref_px(None, ref, radius_px=radius_px, name=f, edges=ed)
        except ecc.ImageAnalysisError as exc:
            frames.reject(f, theta, "d_ref (eqs. 10-12)", exc)
            continue
        drefs_px.append(fit["d_ref_px"])
        if first_fit is None:
            first_fit = {"file": f, "fit": fit}
        thetas.append(theta)
        files.append(f)
    return thetas, drefs_px, files, first_fit


def _fit_sweeps(ds: Dataset, setup: CcdSweepSetup, thetas: np.ndarray, dref_um: np.ndarray, files: list[str],
                order: int) -> dict[str, Any]:
    """Jia eqs. 10-12 on the frames of each sweep (``ccd/index.csv`` column ``sweep``; one sweep
    without it) and, with ≥ 2 sweeps, e ± u(e) type A from their scatter
    (:func:`benchtwin.analysis.eccentricity.eccentricity_from_sweeps`). One sweep: the fit's result
    (its u is the fit's; ``run`` adds the probes' asynchronous part, ``with_async_motion``)."""
    from benchtwin.analysis import eccentricity as ecc

    camera_deg = setup.position_deg
    if setup.sweep is None or len(np.unique(setup.sweep)) < 2:
        return ecc.eccentricity_from_dref(thetas, dref_um, camera_azimuth_deg=camera_deg, order=order)
    sweep_of = {f: int(sw) for f, sw in zip(setup.files, setup.sweep)}
    sw = np.array([sweep_of[f] for f in files])
    fits = []
    for k in np.unique(np.asarray(setup.sweep, dtype=int)):
        m = sw == k
        # each sweep is a fit of its own: the frame limits hold per sweep
        need = _min_frames(int(np.sum(np.asarray(setup.sweep) == k)), order)
        if int(m.sum()) < need:
            raise DatasetError(f"{ds.path / 'ccd'}: sweep {int(k)}: only {int(m.sum())} usable CCD frames for its "
                               f"eccentricity fit (Jia eqs. 10-12); need ≥ {need} (see ccd_frame_limits)")
        fits.append(ecc.eccentricity_from_dref(thetas[m], dref_um[m], camera_azimuth_deg=camera_deg, order=order))
    # the figures and the CCD section show sweep 0's fit with every sweep's points; the numbers are the sweeps'
    return combined_sweeps(fits, ecc.eccentricity_from_sweeps(fits), sw)


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
    p = PolygonReadings.from_table(t)
    if p.theta_read_deg is not None:
        th = np.asarray(p.theta_deg, dtype=float)
        # the display is known to what a display transmits: 6 decimals of a degree (Heidenhain ND,
        # hw/drivers/heidenhain.py), so the twin's exact reading and an emulated one give one q
        shown = np.round(np.asarray(p.theta_read_deg, dtype=float), DISPLAY_DECIMALS_DEG)
        q_arcsec = ((shown - th + 180.0) % 360.0 - 180.0) * 3600.0
        t.update(ac_arcsec=np.asarray(p.ac_arcsec, dtype=float) + q_arcsec)
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

    from benchtwin.analysis.hsieh_pipeline import HeadsData, PolygonOptions, analyze_polygon
    from benchtwin.analysis.shift_angle import BetaSource, PolygonDataError
    from benchtwin.analysis.uncertainty import HSIEH2022_TYPE_B

    b = BenchGeometry.from_manifest(ds.bench)
    heads = ds.table("heads") if ds.has("heads") else None
    cert = b.polygon_certificate_arcsec
    ac_res, ac_acc, note = autocollimator_declared(b.block)
    inputs, input_notes = budget_inputs(b.block)
    try:
        # the budget's other type B inputs go by their results.json names, which are analyze_polygon's
        out = analyze_polygon(
            dict(table) if table is not None else polygon_table(ds), b.faces,
            HeadsData(heads, b.heads_deg) if heads is not None else None,
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

    t = PolygonReadings.from_table(polygon_table(ds))
    direction = t.directions()
    if direction is None or len(set(direction)) < 2:
        return None
    table = sa.tabulate_polygon({"shift_deg": t.shift_deg, "start_face": t.start_face, "step": t.step,
                                 "ac_arcsec": t.ac_arcsec, "theta_deg": t.theta_deg, "rep": t.rep,
                                 "direction": direction}, BenchGeometry.from_manifest(ds.bench).faces)
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


def _constant_fit(cmp: ModelComparison, u: np.ndarray) -> FitStatistics:
    """fit_statistics of measured − model with only α's constant fitted (the Jia model takes e, θ0
    and δY from the CCD and the probes, not from α): the weighted mean removed, one parameter."""
    from benchtwin.analysis.error_model import fit_statistics

    y = np.asarray(cmp.residual_arcsec, dtype=float)
    w = 1.0 / u ** 2
    return FitStatistics.from_fit(fit_statistics(np.ones((y.size, 1)), y - float(np.sum(w * y) / np.sum(w)), u))


def _alpha_u(enc: Curve | Mapping[str, Any], fallback: float) -> np.ndarray:
    """u of each α (the χ² yardstick, CHI2_YARDSTICK); a point without a positive u takes ``fallback``."""
    c = CurveArrays.from_curve(enc)
    th = np.asarray(c.theta_deg, dtype=float)
    u = np.asarray(c.u if c.u is not None else np.full(th.shape, fallback), dtype=float)
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
    above = [h for h in SignatureHarmonic.from_signature(signature) if h.k >= 2]
    comps = [c for h in above for c in (h.a_arcsec, h.b_arcsec) if c is not None and math.isfinite(float(c))]
    if not comps:
        return 0.0, "no harmonic of order ≥ 2 in the residual's signature: no first-order graduation term"
    u = float(np.sqrt(np.mean(np.square(comps))))
    ks = [h.k for h in above]
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
    from benchtwin.analysis.tracing import model_terms_from_payload

    th = np.deg2rad(np.asarray(theta_deg, dtype=float))
    cols, names = [], []
    for i, eff in enumerate(ModelFileEffect.effects_of(payload)):
        alone = payload_with_params(payload, {}, only=i)     # one deep copy per effect, read only below
        if not model_terms_from_payload(alone, dict(base_terms)):
            continue
        e0 = alone["effects"][0]
        for name, v in eff.params.items():
            uu = eff.u.get(name)
            h = float(uu) if uu is not None and math.isfinite(float(uu)) and float(uu) > 0 else 1e-3 * max(1.0, abs(float(v)))
            vals = []
            for sgn in (1.0, -1.0):
                # the effect with this one parameter moved: a new params dict, the rest shared (the
                # terms only read it; a deep copy per evaluation was 2.7 s of a 35 s close-loop)
                q = {**alone, "effects": [{**e0, "params": {**e0["params"], name: float(v) + sgn * h}}]}
                terms = model_terms_from_payload(q, dict(base_terms))
                vals.append(sum(np.asarray(fn(th), dtype=float) for fn in terms.values()))
            cols.append((vals[0] - vals[1]) / (2.0 * h))
            names.append((i, name))
    return (np.column_stack(cols) if cols else np.zeros((th.size, 0))), names


def _refitted_payload(payload: Mapping[str, Any], names: list[tuple[int, str]], dp: list[float]) -> dict[str, Any]:
    """The model file with each refitted parameter moved by its correction δp (refine_eccentricity)."""
    effects = ModelFileEffect.effects_of(payload)
    return payload_with_params(payload, {(i, name): float(effects[i].params[name]) + float(d)
                                         for (i, name), d in zip(names, dp)})


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


@dataclass(frozen=True)
class AnalysisOptions:
    """How ``analyze`` runs (its keywords, as one object): the Fourier ``order`` of the fits, a
    ``model_file`` whose effects join the Jia model (benchtwin close-loop's model.json), the progress
    bars, whether to close the loop, and the ``preface`` figures [(matplotlib figure, caption)] the
    report opens with (the app layer's rendered view of the bench)."""

    order: int = 10
    model_file: str | Path | None = None
    progress: bool = True
    close_loop: bool = True
    preface: list | None = None


class AnalysisSettings(TypedDict, total=False):
    """``analyze``'s keywords one by one (the fields of :class:`AnalysisOptions`)."""

    order: int
    model_file: str | Path | None
    progress: bool
    close_loop: bool
    preface: list | None


@overload
def analyze(dataset: str | Path | Dataset, out: None = None, *, force: bool = False,
            options: AnalysisOptions | None = None, **settings: Unpack[AnalysisSettings]) -> Results: ...


@overload
def analyze(dataset: str | Path | Dataset, out: str | Path, *, force: bool = False,
            options: AnalysisOptions | None = None, **settings: Unpack[AnalysisSettings]) -> dict[str, Any]: ...


def analyze(dataset: str | Path | Dataset, out: str | Path | None = None, *, force: bool = False,
            options: AnalysisOptions | None = None, **settings: Unpack[AnalysisSettings]) -> Results | dict[str, Any]:
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

    ``options`` (:class:`AnalysisOptions`) or its fields as keywords (``order=10``,
    ``model_file=None``, ``progress=True``, ``close_loop=True``, ``preface=None``; a keyword
    overrides the same field of ``options``). ``preface``: [(matplotlib figure, caption)] the
    report opens with (the app layer's rendered view of the bench; the analysis itself never
    builds the twin).

    With ``out``, returns ``{"results": Results, "paths": {"results": ..., "report": ..., "model": ...?}}``
    (as before the in-memory form: ``res["results"]["eccentricity_um"]`` still works).
    Raises :class:`DatasetError` for invalid input (naming file, row, column), and
    ``benchtwin.fsio.OutputError`` for an output folder the rule refuses.
    """
    from benchtwin.fsio import AtomicDir

    opts = replace(options or AnalysisOptions(), **settings)
    if isinstance(dataset, Dataset):
        dataset = dataset.path
    if out is None:
        if force:
            raise ValueError("analyze: force=True needs an output folder (out=None writes nothing)")
        got = analyze_into(dataset, None, order=opts.order, model_file=opts.model_file, progress=opts.progress,
                           close_loop=opts.close_loop)
        return Results(got["results"])
    if opts.model_file is not None:  # a bad model file is named as such before any output rule applies
        from benchtwin.analysis.model_file import read_model_file

        read_model_file(opts.model_file)
    out = Path(out)
    with AtomicDir(out, force=force, what="analysis output folder", owner="analyze",
                   inputs=[dataset, opts.model_file]) as tmp:
        got = analyze_into(dataset, tmp, order=opts.order, model_file=opts.model_file, progress=opts.progress,
                           close_loop=opts.close_loop, preface=opts.preface)
        paths = retarget(got["paths"], tmp, out)
    return {"results": Results(got["results"]), "paths": paths}


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
    a = _jia_model(_measure(ds, order, progress), model_payload)
    if close_loop and a.cmp is not None and a.ecc is not None and a.pol is not None and a.model is not None:
        a = replace(a, loop=_close_loop(ds, a, out))
    results = a.to_json()
    if out is None:  # in memory (analyze(dataset) in a notebook): nothing written
        return {"results": results, "paths": {}}
    paths = {"results": str(out / "results.json"), "report": str(out / "report.html")}
    if a.loop is not None and a.loop.model_path is not None:
        paths["model"] = a.loop.model_path
    _write_report(out, ds, a, results, preface)
    # the calibration result a lab uses, beside results.json (analysis/calibration.py)
    paths.update(write_calibration_files(out, results))
    # written last (atomically, benchtwin.fsio): results.json is the completion marker of an analysis
    _write_results(out, results)
    return {"results": results, "paths": paths}


def _measure(ds: Dataset, order: int, progress: bool) -> BenchAnalysis:
    """Steps 1-3: the radial motion (Jia eqs. 6-9), the eccentricity (eqs. 10-13) and the polygon
    (Hsieh 2022), each where the dataset has its table."""
    rm: RadialMotionResult | None = None
    ecc: EccentricityResult | None = None
    pol: PolygonAnalysis | None = None
    iso2 = None
    notes: list[str] = []
    if ds.has("radial_motion"):
        rm = _step(ds, "radial_motion.csv", step_radial_motion, ds, order)
    if ds.has("ccd/index"):
        ecc = _step(ds, "ccd/index.csv", step_eccentricity, ds, order, progress)
        if rm is not None and ecc.sweeps is None:
            # one sweep also carries the async motion's 1st harmonic (Jia eqs. 11-12): a type B
            # term from the radial run's repetitions; repeated sweeps hold it in their own scatter
            ecc = ecc.with_async_motion(rm.u_h1_async_um, rm.u_h1_async_dof)
        if ecc.frames.rejected_frames:
            notes.append(
                f"CCD: {len(ecc.frames.rejected_frames)} of {ecc.frames.n_frames} frames rejected and dropped "
                f"({', '.join(ecc.rejected_files)}); e and θ0 fitted on the "
                f"{len(ecc.frames.files)} remaining angles (≥ {ecc.frames.min_frames} required)")
    if ds.has("polygon"):
        pol = _step(ds, "polygon.csv", step_polygon, ds)
        notes += pol.notes
        iso2 = _step(ds, "polygon.csv", step_iso230_2_polygon, ds, pol)
    return BenchAnalysis(dataset=str(ds.path), source=ds.manifest["source"], bench=BenchGeometry.from_manifest(ds.bench),
                         rm=rm, ecc=ecc, pol=pol, iso230_2=iso2, notes=tuple(notes))


def _jia_model(a: BenchAnalysis, model_payload: Mapping[str, Any] | None) -> BenchAnalysis:
    """Step 4, Jia eq. 5: the error model from the measured eccentricity and radial motion (with the
    terms of a model file), its prediction, and its comparison with the polygon's α (sec. 4.3)."""
    from benchtwin.analysis.error_model import compare_with_measured, error_model_from_results

    pol = a.pol
    # the raw curve until the loop identifies an artefact of the reference chain
    corrected = corrected_curve(pol.encoder_error_arcsec, None, {}) if pol is not None else None
    if a.ecc is None:
        return replace(a, corrected=corrected, notes=a.notes + (
            "no CCD images: the Jia error model (eq. 5) needs the eccentricity; no prediction",))
    model = error_model_from_results(a.ecc.detail, a.rm.detail if a.rm is not None else None, a.bench.r_um)
    terms = None
    if model_payload is not None:
        from benchtwin.analysis.tracing import add_to_error_model

        terms = add_to_error_model(model, model_payload)
    grid = np.arange(0.0, 360.0, 1.0)
    prediction = ModelPrediction(theta_deg=grid, value=model.predict(grid), u=model.uncertainty(grid),
                                 terms=dict(model.predict_terms(grid).items()))
    cmp = before = None
    if pol is not None:
        cmp = ModelComparison.from_compare(compare_with_measured(pol.alpha_theta_deg, pol.alpha_arcsec, model))
        u_meas = float(np.sqrt(np.mean(np.square(pol.alpha_u_arcsec))))
        u_pts = _alpha_u(pol.encoder_error_arcsec, u_meas if u_meas > 0 else 1.0)
        before = cmp.residual_summary(u_meas, _constant_fit(cmp, u_pts))
    return replace(a, model=model, model_file_terms=terms, prediction=prediction, cmp=cmp, residual_before=before,
                   corrected=corrected)


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

    curve = CurveArrays.from_curve(enc)
    th = np.asarray(curve.theta_deg, dtype=float)
    val = np.asarray(curve.value, dtype=float).copy()
    u2 = np.asarray(curve.u, dtype=float) ** 2
    applied: list[CorrectionApplied] = []
    if corrections and theta_read_deg is not None:
        tr_ = np.mod(np.asarray(theta_read_deg, dtype=float), 360.0)
        d = np.abs(((tr_[None, :] - np.mod(th, 360.0)[:, None]) + 180.0) % 360.0 - 180.0)
        near = d <= THETA_BIN_DEG / 2.0
        cnt = near.sum(axis=1)
        for name, c in sorted(corrections.items()):
            rc = ReferenceCorrection.from_trace(c)
            v, uc = rc.value_arcsec, rc.u_arcsec
            corr = np.where(cnt > 0, (near @ v) / np.maximum(cnt, 1), 0.0)
            ucorr = np.where(cnt > 0, (near @ uc) / np.maximum(cnt, 1), 0.0)
            if name not in in_readings:
                val = val - corr
            u2 = u2 + ucorr ** 2
            applied.append(CorrectionApplied(effect=name, rms_arcsec=float(np.sqrt(np.mean(corr ** 2))),
                                             u_rms_arcsec=float(np.sqrt(np.mean(ucorr ** 2))), params=rc.params,
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
    for name, params in tr.identified():
        fn = getattr(ALL.get(name), "reading_correction", None)
        if fn is not None and name in tr.reference_corrections:
            out[name] = np.asarray(fn(ev, params), dtype=float)
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
        ac = np.asarray(PolygonReadings.from_table(poly).ac_arcsec, dtype=float) - sum(in_readings.values())
        pol_c = step_polygon(ds, {**poly, "ac_arcsec": ac})
    return corrected_curve(pol_c.encoder_error_arcsec, ev.theta_deg, tr.reference_corrections, frozenset(in_readings))


def reading_response(poly: Mapping[str, Any], pol: PolygonAnalysis, d: np.ndarray, n_faces: int) -> np.ndarray | None:
    """The α per reading that a perturbation ``d`` of every autocollimator reading produces after the
    shift-angle analysis (Hsieh eqs. 5-7: β from the closure of the reference shift's full table, or
    the certificate, which does not move; U_j per start face; α = ε − Σβ − U, eq. 3). The analysis is
    linear in ε, so this is the exact first-order column of an effect that adds ``d`` to the readings:
    e.g. an autocollimator non-linearity q·ε² (ac_scale), whose face-fixed part the closure puts into
    β and whose per-run mean goes into U. None if the analysis cannot be repeated on ``d``."""
    from benchtwin.analysis import shift_angle as sa

    N = int(n_faces)
    p = PolygonReadings.from_table(poly)
    try:
        t = sa.tabulate_polygon({"shift_deg": p.shift_deg, "start_face": p.start_face, "step": p.step,
                                 "ac_arcsec": d, "theta_deg": p.theta_deg, "rep": p.rep, "direction": p.direction}, N)
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
    j = np.asarray(p.start_face).astype(int)
    i = np.asarray(p.step).astype(int)
    S = np.asarray(p.shift_deg, dtype=float)
    try:
        Uj = np.array([U[(round(float(s_), 6), int(f))] for s_, f in zip(S, j)])
    except KeyError:
        return None
    return np.asarray(d, dtype=float) - (cum[j - 1 + i] - cum[j - 1]) - Uj


@dataclass(frozen=True, eq=False)
class _LoopFit:
    """What the model after the loop is built from: the analysis so far, the tracing's evidence and
    verdict, the corrected curve the model is compared with and the u of one reading."""

    a: BenchAnalysis
    ev: Any
    tr: TraceOutcome
    corrected: CorrectedCurve
    u_eps: float

    @property
    def ecc(self) -> EccentricityResult:
        return cast(EccentricityResult, self.a.ecc)

    @property
    def r_um(self) -> float:
        return self.a.bench.r_um

    def jia_model(self) -> Any:
        """The Jia model (eq. 5) of the CCD's (e, θ0) and the probes' δY, before any traced term."""
        from benchtwin.analysis.error_model import error_model_from_results

        return error_model_from_results(self.ecc.detail, self.a.rm.detail if self.a.rm is not None else None,
                                        self.r_um)


def _per_reading_after(f: _LoopFit, model2: Any, col_names: list[tuple[int, str]], ref: RefinedEccentricity
                       ) -> float | None:
    """RMS per polygon reading of the residual after the model of ``residual_after``: the tracing's
    residual after its effects (closure-centred, residual_after_trace) with the eq. 3 term moved from
    the CCD's (e, θ0) to the refined one, the first-order graduation term and the refitted parameters'
    corrections, all evaluated at the readings' θ — the same model as the stops' residual, per reading
    (what ``benchtwin score`` compares with its per-reading floor)."""
    from benchtwin.analysis.error_model import eccentricity_term
    from benchtwin.analysis.report.figures_loop import effect_contribution
    from benchtwin.analysis.tracing import _center

    ev, tr, r_um = f.ev, f.tr, f.r_um
    if not tr.identified_effects:
        return None
    th = np.deg2rad(np.asarray(ev.theta_deg, dtype=float))
    r1 = _center(ev.residual_arcsec, ev.closure_group, 1.0 / ev.u_arcsec ** 2) - effect_contribution(ev, tr.detail)
    delta = (eccentricity_term(ref.e_um, ref.theta0_deg, r_um)(th)
             - eccentricity_term(f.ecc.e_um, f.ecc.theta0_deg, r_um)(th))
    if "graduation_k1" in model2.terms:
        delta = delta + model2.terms["graduation_k1"](th)
    if col_names:
        cols, _ = traced_columns(tr.model_file, dict(model2.terms), np.asarray(ev.theta_deg, dtype=float))
        delta = delta + cols @ np.asarray(ref.column_params, dtype=float)
    r2 = r1 - _center(delta, ev.closure_group, 1.0 / ev.u_arcsec ** 2)
    return float(np.sqrt(np.mean(r2 ** 2)))


def _close_loop(ds: Dataset, a: BenchAnalysis, out: Path | None) -> LoopOutcome:
    """Step 5: Jia's residual → significance, signature, effect selection (analysis.tracing), then the
    chosen effect joins the model and the comparison is redone (before/after). With ``out``, the
    model file of the identified effects is written there (model.json)."""
    from benchtwin.analysis.tracing import save_model, trace

    pol = cast(PolygonAnalysis, a.pol)
    ev, poly, u_eps, notes = _loop_evidence(ds, a)
    tr = TraceOutcome.from_trace(trace(ev))
    corrected = corrected_polygon(ds, poly, pol, tr, ev)
    if not tr.identified_effects:
        before = cast(ResidualSummary, a.residual_before)
        return LoopOutcome(evidence=ev, trace=tr, corrected=corrected,
                           residual_after=ResidualSummary(**before, added_terms=[]), comparison_after=None,
                           refined=None, notes=notes, model_path=None)
    model_path = None
    if out is not None:
        save_model(out / "model.json", tr.model_file)
        model_path = str(out / "model.json")
    residual_after, cmp2, refined, more_notes = _model_after(_LoopFit(a=a, ev=ev, tr=tr, corrected=corrected,
                                                                      u_eps=u_eps))
    return LoopOutcome(evidence=ev, trace=tr, corrected=corrected, residual_after=residual_after,
                       comparison_after=cmp2, refined=refined, notes=notes + more_notes, model_path=model_path)


def _reading_u(pol: PolygonAnalysis) -> tuple[float, float]:
    """(u of α's readings ε for the evidence's floor, u of one reading): the budget's u_c, else the
    declared autocollimator's type B parts (resolution r/(2√3), max error a/√3, Hsieh sec. 3.3 (2),
    (4)) with the readings' repeatability where the data give one; one reading's u is the
    repeatability (pooled, else the closure's sd), else that u."""
    u_c = pol.u_c_arcsec
    if u_c is not None:
        u_eps = u_c
    else:
        res_, acc_ = pol.ac_resolution_arcsec, pol.ac_accuracy_arcsec
        s_rep = pol.pooled_sd_eps_arcsec or 0.0
        u_eps = math.sqrt((res_ / (2 * math.sqrt(3.0))) ** 2 + (acc_ / math.sqrt(3.0)) ** 2 + float(s_rep) ** 2)
    return u_eps, pol.pooled_sd_eps_arcsec or pol.closure_sd_arcsec or u_eps


def _loop_evidence(ds: Dataset, a: BenchAnalysis) -> tuple[Any, dict[str, Any], float, list[str]]:
    """The tracing's evidence (analysis.tracing.evidence_from_polygon): the polygon's readings less
    the Jia model, the radial probes, the self-calibration where it has a u, and the CCD's (e, θ0)
    with their u. Returns (evidence, the polygon table it was built from, u of α's readings, notes)."""
    from benchtwin.analysis.tracing import BenchContext, RadialMotion, SelfCalCurve, evidence_from_polygon

    geo, ecc, pol = a.bench, cast(EccentricityResult, a.ecc), cast(PolygonAnalysis, a.pol)
    radial = None
    if a.rm is not None:
        t = a.rm.readings if a.rm.readings is not None else radial_table(ds)[0]
        radial = RadialMotion(t.theta_deg, t.probe_top_um, t.probe_bottom_um, *geo.sphere_distances_mm,
                              top_x_um=t.probe_top_x_um, bottom_x_um=t.probe_bottom_x_um, rep=t.rep)
    notes = []
    sc_cal = pol.selfcal
    if sc_cal is not None and not np.all(np.isfinite(np.asarray(sc_cal.u, dtype=float))):
        # 2 heads: δ = α(θ) − α(θ+180°) fixes every odd harmonic with no redundancy, so no u; evidence
        # without an uncertainty cannot be weighted (issue #13: the close loop's SVD did not converge)
        notes.append("close loop: the self-calibration has no uncertainty (no redundancy between the "
                     "heads), so it is not used as evidence")
        sc_cal = None
    u_eps, u_read = _reading_u(pol)
    poly = {k: (v.astype(str) if v.dtype == object else v) for k, v in polygon_table(ds).items()}
    selfcal = (SelfCalCurve(theta_deg=sc_cal.theta_deg, value_arcsec=sc_cal.value, u_arcsec=np.asarray(sc_cal.u),
                            n_heads=geo.n_heads) if sc_cal else None)
    ev = evidence_from_polygon(
        poly, pol.pitch_deviation_arcsec, _setup_error_lookup(pol), a.model,
        BenchContext(n_faces=geo.faces, u_arcsec=float(u_read), radial=radial, selfcal=selfcal,
                     optical_radius_mm=geo.optical_radius_mm, L1_mm=geo.L1_mm, L2_mm=geo.L2_mm,
                     grating_period_um=geo.grating_period_um, encoder_lines=geo.encoder_lines,
                     radial_term="radial_motion" if a.rm is not None else None,
                     u_floor_arcsec=max(float(u_read), u_eps),
                     ccd_azimuth_deg=float((ds.manifest.get("ccd") or {}).get("position_deg", 180.0))),
    )
    ev.ac_quadratic_response = reading_response(poly, pol, np.asarray(PolygonReadings.from_table(poly).ac_arcsec,
                                                                      dtype=float) ** 2,
                                                geo.faces)
    ev.add_eccentricity_uncertainty(ecc.e_um, ecc.theta0_deg, ecc.u_e_um, ecc.u_theta0_deg)
    return ev, poly, u_eps, notes


def _model_after(f: _LoopFit) -> tuple[ResidualSummary, ModelComparison, RefinedEccentricity | None, list[str]]:
    """The model after the loop: the traced effects added to the Jia model and compared with the
    curve the reference chain would have given (the measured one less the identified artefacts of
    the reference chain; the raw curve when none).

    The model after the loop takes (e, θ0) from the CCD combined with the first harmonic the
    comparison still shows (error_model.refine_eccentricity): one CCD sweep states e to u(e) of
    tenths of a µm (Jia: 0.24 µm, ≈ 2.3″ of first harmonic at r = 22 mm), the comparison measures
    that harmonic to hundredths of an arcsecond — but in α a first-order graduation term reads
    exactly as eccentricity, so the comparison measures e only within the prior on that term
    (k1_prior). The traced effects' parameters are refitted with it on the stops (traced_columns):
    one weighted least-squares fit, whose residual is ``residual_after`` and whose statistics
    (n_params, dof, χ², leave-one-out) say what that residual can test. The tracing's decisions are
    made before, on the CCD's values with their u (ev.add_eccentricity_uncertainty); this changes no
    decision. Returns (residual_after, the comparison after, the refined (e, θ0) or None, notes)."""
    from benchtwin.analysis.error_model import compare_with_measured
    from benchtwin.analysis.tracing import add_to_error_model

    model2 = f.jia_model()
    added = add_to_error_model(model2, f.tr.model_file)
    corrected = CurveArrays.from_curve(f.corrected)
    th_c, a_c = np.asarray(corrected.theta_deg), np.asarray(corrected.value)
    cmp2 = ModelComparison.from_compare(compare_with_measured(th_c, a_c, model2))
    if th_c.size < 4:   # a 3-face polygon: (e, θ0) and α's constant leave no degree of freedom
        return (cmp2.residual_summary(added_terms=added), cmp2, None,
                [f"(e, θ0) not refined by the comparison: {th_c.size} points, at least 4 needed"])
    ref, col_names = _refine_eccentricity(f, model2, th_c, cmp2)
    model2, added = _refined_model(f, ref, col_names)
    cmp2 = ModelComparison.from_compare(compare_with_measured(th_c, a_c, model2))
    return (cmp2.residual_summary(stats=ref.fit, per_reading_rms_arcsec=_per_reading_after(f, model2, col_names, ref),
                                  added_terms=added), cmp2, ref, [])


def _refine_eccentricity(f: _LoopFit, model2: Any, th_c: np.ndarray, cmp2: ModelComparison
                         ) -> tuple[RefinedEccentricity, list[tuple[int, str]]]:
    """(e, θ0) and the traced parameters refitted on the stops, with the prior on a first-order
    graduation term (error_model.refine_eccentricity, k1_prior, traced_columns)."""
    from benchtwin.analysis.error_model import EccentricityEstimate, refine_eccentricity

    ecc, tr, r_um = f.ecc, f.tr, f.r_um
    u_c = _alpha_u(f.corrected, f.u_eps)
    cols, col_names = traced_columns(tr.model_file, dict(model2.terms), th_c)
    u_k1, k1_source = k1_prior(tr.signature)
    raw = refine_eccentricity(th_c, cmp2.residual_arcsec, u_c,
                              EccentricityEstimate(ecc.e_um, ecc.theta0_deg, ecc.u_e_um, ecc.u_theta0_deg,
                                                   ecc.cov_e_theta0),
                              r_um, u_k1_arcsec=u_k1, columns=cols)
    ref = RefinedEccentricity.from_refine(
        raw, {"u_arcsec": u_k1, "u_um": u_k1 * ARCSEC * r_um, "source": k1_source},
        [f"{tr.effect_name(i)}.{n}" for i, n in col_names],
        float(cmp2.residual_pv_arcsec))   # the residual with the CCD's (e, θ0)
    return ref, col_names


def _refined_model(f: _LoopFit, ref: RefinedEccentricity, col_names: list[tuple[int, str]]) -> tuple[Any, list[str]]:
    """The model after: the refitted traced terms, the eq. 3 term replaced (add_term replaces by
    name) and the first-order graduation term the fit gave; and the terms it added."""
    from benchtwin.analysis.error_model import eccentricity_term
    from benchtwin.analysis.tracing import add_to_error_model

    r_um = f.r_um
    model2 = f.jia_model()
    added = add_to_error_model(model2, _refitted_payload(f.tr.model_file, col_names, ref.column_params))
    model2.add_term("eccentricity", eccentricity_term(ref.e_um, ref.theta0_deg, r_um, ref.u_e_um,
                                                      ref.u_theta0_deg, ref.cov_e_theta0))
    if ref.k1_a1_arcsec is not None and ref.k1_b1_arcsec is not None:
        a1, b1 = ref.k1_a1_arcsec, ref.k1_b1_arcsec

        def graduation_k1(t: np.ndarray, a1: float = a1, b1: float = b1) -> np.ndarray:
            return a1 * np.sin(t) + b1 * np.cos(t)

        model2.add_term("graduation_k1", graduation_k1)
    added = added + ["refined:eccentricity (CCD ⊕ comparison, first-order graduation prior)",
                     "refitted on the stops: " + ", ".join(ref.refitted_params) if col_names else
                     "refitted on the stops: none"]
    return model2, added


def _write_report(out: Path, ds: Dataset, a: BenchAnalysis, results: Mapping[str, Any],
                  preface: list | None = None) -> None:
    """report.html (analysis/report/bench_report.py)."""
    from benchtwin.analysis.report.bench_report import write_bench_report

    write_bench_report(out, ds, a, cast(Any, results), preface)


# ----------------------------------------------------------------------------- error curves


def _write_results(out: Path, results: Mapping[str, Any]) -> None:
    """results.json (strict JSON, sorted keys): the one place it is written."""
    atomic_write_text(out / "results.json", json.dumps(_jsonable(results), indent=1, sort_keys=True) + "\n")


def analyze_error_curve_dataset(ds: Dataset, out: Path | None, *, close_loop: bool = True) -> dict[str, Any]:
    """An "error curve" dataset (an imported α(θ) table): coverage, closure, hysteresis, harmonics with
    u, what a lone curve cannot separate (analysis.error_curve) → results.json + report.html.
    ``close_loop`` adds the verdict keys (status, ambiguous, unexplained) that close-loop reports;
    a lone curve identifies no effect and changes no curve."""
    from benchtwin.analysis.error_curve import analyze_error_curve
    from benchtwin.analysis.iso230_2 import positioning_statistics, runs_from_error_curve

    t = ErrorCurveTable.from_table(ds.table("error_curve"))
    try:
        a = ErrorCurveAnalysis.from_analysis(analyze_error_curve(t.theta_deg, t.error_arcsec, t.direction, t.u_arcsec))
    except ValueError as exc:
        raise DatasetError(f"{ds.path / 'error_curve.csv'}: {exc}") from None
    if not a.full_turn:
        a = replace(a, arc=_arc_periods(ds, a))
    runs = runs_from_error_curve(t.theta_deg, t.error_arcsec, t.direction)
    if runs is not None:
        a = replace(a, iso230_2=positioning_statistics(
            *runs, source="error_curve.csv: one run per direction at the angles measured in both"))
    results = a.to_json(str(ds.path), ds.manifest, _bench(ds.bench), close_loop)
    if out is None:  # in memory: nothing written
        return {"results": results, "paths": {}}
    from benchtwin.analysis.report.error_curve_report import write_error_curve_report

    paths = {"results": str(out / "results.json"), "report": str(out / "report.html")}
    write_error_curve_report(out, ds, a, close_loop, calibration_curve(results))
    paths.update(write_calibration_files(out, results))
    _write_results(out, results)
    return {"results": results, "paths": paths}


def _arc_periods(ds: Dataset, a: ErrorCurveAnalysis) -> dict[str, Any]:
    """The periods over an arc (analysis.arc_periods): u from outside the fit (a u column, the two
    directions) weighs the points; else none."""
    from benchtwin.analysis.arc_periods import ArcInputError, analyze_arc_periods

    u_ext = None if a.u_from_residual else a.u_arcsec
    try:
        return analyze_arc_periods(a.theta_deg, a.value_arcsec, u_ext, drive_elements=ds.manifest.get("drive_elements"))
    except ArcInputError as exc:
        raise DatasetError(f"{ds.path}/{exc}") from None
