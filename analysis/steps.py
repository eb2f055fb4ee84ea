"""The typed outputs of the analysis pipeline's steps (analysis/pipeline.py), one frozen dataclass each.

Each step of the pipeline returns one of these instead of the plain dict of the module that computes
it, so the pipeline, the report and the application read attributes that a type checker (mypy) sees,
with the unit in each name (principle 4: ``e_um``, ``u_e_um``, ``theta0_deg``), and each object is
serialised to its results.json section by one function, ``to_json()`` (the section types of
:mod:`benchtwin.analysis.results`, documented in docs/results-format.md):

- :class:`RadialMotionResult`: the two-sphere radial error motion (Jia et al. 2019 sec. 4.1,
  eqs. 6–9; :func:`benchtwin.analysis.radial_motion.radial_motion`) and its ISO 230-7:2015 values
  (:mod:`benchtwin.analysis.iso230_7`);
- :class:`EccentricityResult`: e and θ0 from the CCD sweep (Jia sec. 4.2, eqs. 10–13;
  :mod:`benchtwin.analysis.eccentricity`), with the frames used and rejected;
- :class:`PolygonAnalysis`: the shift-angle method, the multi-head self-calibration and the GUM
  budget (Hsieh et al. 2022; :func:`benchtwin.analysis.hsieh_pipeline.analyze_polygon`);
- :class:`TraceOutcome`: the tracing's verdict on the residual (analysis/tracing/, docs/effects.md).

The computing modules keep returning their documented dicts (their tests, benchmarks and the
functions of the same module that read them: the error model, the ISO 230-7 evaluation, the
report's figures); each object keeps that dict as ``detail`` for those functions only. The
``from_*`` constructors are the one place the dict's keys are read.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from benchtwin.analysis.results import (AutocollimatorDeclared, BudgetInput, BudgetRow, BudgetSummary, CCDSection,
                                        CloseLoop, EncoderErrorCurve, Floats, IdentifiedEffect, PolygonResults,
                                        RadialMotionSection, RejectedFrame, TraceResidual)

__all__ = ["RadialMotionResult", "EccentricityResult", "PolygonAnalysis", "TraceOutcome"]


@dataclass(frozen=True, eq=False)
class RadialMotionResult:
    """Radial error motion of the spheres and the disk (Jia eqs. 6–9) on the grid ``theta_deg``."""

    theta_deg: np.ndarray
    #: synchronous disk motion δY along the head direction (eq. 9), µm
    dY_um: np.ndarray
    #: synchronous tilt (eq. 8), µrad
    tilt_x_urad: np.ndarray
    #: u of δY as the spindle's synchronous motion at each θ, and its maximum
    u_dY_theta_um: np.ndarray
    u_dY_um: float
    #: range method (max range / d_n, Jia sec. 5) and the GUM u of the fits (max over θ)
    u_dY_range_um: float
    u_dY_gum_um: float
    d_n: float
    n_reps: int
    #: the asynchronous motion's share in the 1st harmonic of one revolution (per component) and its ν
    u_h1_async_um: float
    u_h1_async_dof: float
    #: per location (top, bottom, disk [, _x]): total_um, synchronous_um, asynchronous_um, asynchronous_pv_um
    summary: dict[str, dict[str, float]]
    #: the ISO 230-7:2015 evaluation of the same readings (analysis.iso230_7.radial_error_motion)
    iso230_7: dict[str, Any]
    #: radial_motion()'s whole dict (per-revolution curves, fits, the δY series) for the error model,
    #: the ISO 230-7 evaluation and the figures
    detail: dict[str, Any]

    @classmethod
    def from_radial_motion(cls, rm: dict[str, Any], iso230_7: dict[str, Any]) -> RadialMotionResult:
        return cls(theta_deg=rm["theta_deg"], dY_um=rm["dY_um"], tilt_x_urad=rm["tilt_x_urad"],
                   u_dY_theta_um=rm["u_dY_theta_um"], u_dY_um=rm["u_dY_um"], u_dY_range_um=rm["u_dY_range_um"],
                   u_dY_gum_um=rm["u_dY_gum_um"], d_n=rm["d_n"], n_reps=rm["n_reps"],
                   u_h1_async_um=rm["u_h1_async_um"], u_h1_async_dof=rm["u_h1_async_dof"], summary=rm["summary"],
                   iso230_7=iso230_7, detail=rm)

    @property
    def bandwidth(self) -> dict[str, Any]:
        """The orders per revolution the summary's values hold (radial_motion's series: 2…order)."""
        return cast(dict[str, Any], self.detail["bandwidth"])

    def to_json(self) -> RadialMotionSection:
        return RadialMotionSection(
            summary=self.summary, u_dY_range_um=self.u_dY_range_um, u_dY_gum_um=self.u_dY_gum_um, d_n=self.d_n,
            n_reps=self.n_reps, theta_deg=self.theta_deg, dY_um=self.dY_um, tilt_x_urad=self.tilt_x_urad,
            # δY as the spindle's synchronous motion (radial_motion: the revolutions' scatter per harmonic)
            u_dY_um=self.u_dY_um, u_dY_theta_um=self.u_dY_theta_um, u_h1_async_um=self.u_h1_async_um,
            bandwidth=self.bandwidth)


#: eccentricity_u_source of a one-sweep fit before the asynchronous motion is added
ONE_SWEEP_U_SOURCE = "the eq. 10 fit of one sweep (its residuals) alone"
#: the keys of results.json eccentricity_sweeps (analysis.eccentricity.eccentricity_from_sweeps)
SWEEP_KEYS = ("n_sweeps", "dof", "e_sweeps_um", "theta0_sweeps_deg", "e_sweep_sd_um", "theta0_sweep_sd_deg",
              "e_range_u_um", "theta0_range_u_deg")


@dataclass(frozen=True, eq=False)
class EccentricityResult:
    """Installation eccentricity e (Jia eq. 11) and its phase θ0 (eq. 12) from the CCD sweep."""

    e_um: float
    u_e_um: float
    theta0_deg: float
    u_theta0_deg: float
    #: the eq. 10 fit's part of u(e), u(θ0) alone (without the asynchronous motion)
    u_e_fit_um: float
    u_theta0_fit_deg: float
    #: the asynchronous motion's part of u(e) (radial motion's revolutions); None before it is added
    u_e_async_um: float | None
    #: image scale from the grating period (eq. 13), µm per pixel
    pixel_um: float
    #: the edge radius held fixed in the circle fits (from the manifest), px; None when fitted
    radius_fixed_px: float | None
    #: angles, files and d_ref (eqs. 10–12) of the frames used
    theta_deg: list[float]
    d_ref_um: np.ndarray
    files: list[str]
    n_frames: int
    rejected_frames: list[RejectedFrame]
    #: the fewest usable frames accepted (pipeline.ccd_frame_limits)
    min_frames: int
    residual_rms_um: float | None
    #: where u(e) comes from (results.json eccentricity_u_source)
    u_source: str
    #: repeated CCD sweeps (n_sweeps, dof, per-sweep e and θ0, their sd, Jia's range/d_n); None for one sweep
    sweeps: dict[str, Any] | None
    #: the step's whole dict (the d_ref Fourier fit, cov(e, θ0), ...) for the error model and the figures
    detail: dict[str, Any]

    @classmethod
    def from_eccentricity(cls, ecc: dict[str, Any]) -> EccentricityResult:
        return cls(e_um=ecc["e_um"], u_e_um=ecc["e_u_um"], theta0_deg=ecc["theta0_deg"],
                   u_theta0_deg=ecc["theta0_u_deg"], u_e_fit_um=ecc.get("e_u_fit_um", ecc["e_u_um"]),
                   u_theta0_fit_deg=ecc.get("theta0_u_fit_deg", ecc["theta0_u_deg"]),
                   u_e_async_um=ecc.get("u_async_h1_um"), pixel_um=ecc["pixel_um"],
                   radius_fixed_px=ecc["radius_fixed_px"], theta_deg=ecc["theta_deg"], d_ref_um=ecc["d_ref_um"],
                   files=ecc["files"], n_frames=ecc["n_frames"], rejected_frames=ecc["rejected_frames"],
                   min_frames=ecc["frame_limits"]["min_frames"], residual_rms_um=ecc.get("residual_rms_um"),
                   u_source=ecc.get("u_source", ONE_SWEEP_U_SOURCE),
                   sweeps={k: ecc[k] for k in SWEEP_KEYS} if "n_sweeps" in ecc else None,
                   detail=ecc)

    def with_async_motion(self, u_h1_um: float, dof: float | None) -> EccentricityResult:
        """The asynchronous motion's 1st harmonic added to u(e) and u(θ0) (eccentricity.with_async_motion)."""
        from benchtwin.analysis.eccentricity import with_async_motion

        return EccentricityResult.from_eccentricity(with_async_motion(dict(self.detail), u_h1_um, dof))

    def ccd_section(self) -> CCDSection:
        return CCDSection(pixel_um=self.pixel_um, n_images=len(self.files), n_frames=self.n_frames,
                          theta_deg=self.theta_deg, d_ref_um=self.d_ref_um, residual_rms_um=self.residual_rms_um,
                          min_frames=self.min_frames)

    def to_json(self) -> dict[str, Any]:
        """The eccentricity keys of results.json (BenchResults: eccentricity_*, ccd, ccd_rejected_frames)."""
        out: dict[str, Any] = {
            "eccentricity_um": self.e_um, "eccentricity_u_um": self.u_e_um,
            "eccentricity_phase_deg": self.theta0_deg, "eccentricity_phase_u_deg": self.u_theta0_deg,
            "eccentricity_u_fit_um": self.u_e_fit_um, "eccentricity_phase_u_fit_deg": self.u_theta0_fit_deg,
            "eccentricity_u_async_um": self.u_e_async_um, "eccentricity_u_source": self.u_source}
        if self.sweeps is not None:
            out["eccentricity_sweeps"] = self.sweeps
        out["ccd"] = self.ccd_section()
        out["ccd_rejected_frames"] = self.rejected_frames
        return out


@dataclass(frozen=True, eq=False)
class PolygonAnalysis:
    """The shift-angle method (Hsieh eqs. 2–7), the self-calibration (eqs. 8–9) and the budget (Table 3)."""

    #: pitch deviations β_k of the polygon (eqs. 5–6) and their u, arcsec
    pitch_deviation_arcsec: Floats
    pitch_deviation_u_arcsec: Floats
    #: "closure", "certificate", ...: where β came from
    beta_source: str
    #: setup errors U_j per shift (str(S) → one per start face measured, eq. 7) and those start faces
    setup_error_arcsec: dict[str, Floats]
    setup_error_start_faces: dict[str, list[int]]
    #: the encoder error α(θ), all shifts combined (eq. 3)
    encoder_error_arcsec: EncoderErrorCurve
    #: the multi-head self-calibration {theta_deg, value, u, U}; None with one head
    selfcal_error_arcsec: dict[str, Any] | None
    difference_arcsec: dict[str, Any] | None
    en_max: float | None
    budget: list[BudgetRow]
    budget_summary: BudgetSummary | None
    repeatability: dict[str, Any]
    autocollimator_declared: AutocollimatorDeclared
    budget_inputs: dict[str, BudgetInput]
    notes: list[str]
    #: analyze_polygon()'s whole dict (α per shift, curve fits, self-calibration details) for the figures
    detail: dict[str, Any]

    @classmethod
    def from_analysis(cls, pol: dict[str, Any], autocollimator: AutocollimatorDeclared,
                      budget_inputs: dict[str, BudgetInput], notes: list[str]) -> PolygonAnalysis:
        return cls(pitch_deviation_arcsec=pol["polygon_pitch_deviation_arcsec"],
                   pitch_deviation_u_arcsec=pol["polygon_pitch_deviation_u_arcsec"],
                   beta_source=pol.get("beta_source", "auto"), setup_error_arcsec=pol["setup_error_arcsec"],
                   setup_error_start_faces=pol["setup_error_start_faces"],
                   encoder_error_arcsec=pol["encoder_error_arcsec"], selfcal_error_arcsec=pol["selfcal_error_arcsec"],
                   difference_arcsec=pol["difference_arcsec"], en_max=pol["en_max"], budget=pol["budget"],
                   budget_summary=pol.get("budget_summary"), repeatability=pol.get("repeatability") or {},
                   autocollimator_declared=autocollimator, budget_inputs=budget_inputs,
                   notes=list(pol.get("notes", [])) + notes, detail=pol)

    def to_json(self) -> PolygonResults:
        out = PolygonResults(
            polygon_pitch_deviation_arcsec=self.pitch_deviation_arcsec,
            polygon_pitch_deviation_u_arcsec=self.pitch_deviation_u_arcsec,
            setup_error_arcsec=self.setup_error_arcsec, encoder_error_arcsec=self.encoder_error_arcsec,
            selfcal_error_arcsec=self.selfcal_error_arcsec, en_max=cast(float, self.en_max), budget=self.budget,
            difference_arcsec=self.difference_arcsec, repeatability=self.repeatability,
            autocollimator_declared=self.autocollimator_declared, budget_inputs=self.budget_inputs)
        if self.budget_summary is not None:
            out["budget_summary"] = self.budget_summary
        return out


#: the tracing's keys results.json's close_loop section carries when the trace has them
_CLOSE_LOOP_KEYS = ("signature", "selection", "skipped", "thresholds", "partial_effects", "unexplained_signature")


@dataclass(frozen=True, eq=False)
class TraceOutcome:
    """What the tracing found in the residual (analysis.tracing.trace; docs/effects.md, "Result of trace")."""

    #: explained / ambiguous / unexplained / no_significant_residual / ...
    status: str
    identified_effects: list[IdentifiedEffect]
    #: the best candidate when it was not accepted ([] when there is none)
    partial_effects: list[dict[str, Any]]
    ambiguous: list[dict[str, Any]]
    unexplained: bool
    #: the residual per polygon reading before and after the traced effects
    residual_before: TraceResidual
    residual_after: TraceResidual
    #: per identified artefact of the reference chain: value_arcsec, u_arcsec per reading, params
    reference_corrections: dict[str, dict[str, Any]]
    #: the model file's payload (analysis.tracing.save_model)
    model_file: dict[str, Any]
    #: trace()'s whole dict (signature, selection, candidates) for the report's figures
    detail: dict[str, Any]

    @classmethod
    def from_trace(cls, tr: dict[str, Any]) -> TraceOutcome:
        return cls(status=tr["status"], identified_effects=tr["identified_effects"],
                   partial_effects=tr.get("partial_effects") or [], ambiguous=tr["ambiguous"],
                   unexplained=tr["unexplained"], residual_before=tr["residual_before"],
                   residual_after=tr["residual_after"], reference_corrections=tr.get("reference_corrections") or {},
                   model_file=tr["model_file"], detail=tr)

    def to_json(self) -> CloseLoop:
        """results.json's close_loop section (the verdict, the signature, the selection)."""
        out = CloseLoop(status=self.status)
        for k in _CLOSE_LOOP_KEYS:
            if k in self.detail:
                out[k] = self.detail[k]  # type: ignore[literal-required]
        return out
