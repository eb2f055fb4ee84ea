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
``from_*`` constructors are the one place the dict's keys are read (``_StepDetail.from_detail``:
each field from the key of its name).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, Self, cast

import numpy as np

from benchtwin.analysis.results import (ArcPeriod, AutocollimatorDeclared, Bench, BenchResults, BudgetInput, BudgetRow,
                                        BudgetSummary, CCDSection, CloseLoop, Comparison, CorrectedCurve, Curve,
                                        EncoderErrorCurve, ErrorCurveResults, Floats, IdentifiedEffect, Iso230_2, ModelPrediction, PolygonResults,
                                        RadialErrorMotion, RadialMotionSection, RejectedFrame, ResidualSummary,
                                        TraceResidual)

__all__ = ["RadialMotionResult", "EccentricityResult", "PolygonAnalysis", "TraceOutcome", "BenchGeometry",
           "RadialMotionTable", "CcdFrames", "FitStatistics", "ModelComparison", "RefinedEccentricity", "LoopOutcome",
           "BenchAnalysis", "ErrorCurveTable", "ErrorCurveAnalysis", "PolygonReadings", "CcdSweepSetup", "CurveArrays",
           "ReferenceCorrection", "SignatureHarmonic", "ModelFileEffect", "payload_with_params", "combined_sweeps"]


@dataclass(frozen=True, eq=False)
class _StepDetail:
    """A step's output read from the documented dict of the module that computes it, kept whole as
    ``detail`` for that module's own functions (the error model, the ISO 230-7 evaluation, the
    report's figures)."""

    detail: dict[str, Any]

    @classmethod
    def from_detail(cls, d: dict[str, Any], **given: Any) -> Self:
        """Each field from the key of its name in ``d``, those ``given`` excepted."""
        names = [f.name for f in fields(cls) if f.name != "detail" and f.name not in given]
        return cls(detail=d, **{n: d[n] for n in names}, **given)


@dataclass(frozen=True, eq=False)
class RadialMotionResult(_StepDetail):
    """Radial error motion of the spheres and the disk (Jia eqs. 6–9) on the grid ``theta_deg``;
    ``detail``: radial_motion()'s whole dict (per-revolution curves, fits, the δY series) for the
    error model, the ISO 230-7 evaluation and the figures."""

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
    #: the probes' time-smooth drift removed before the reduction (analysis.probe_drift;
    #: :meth:`RadialMotionTable.drift_corrected`), None when no probe's drift passed the test
    probe_drift: dict[str, Any] | None = None
    #: the readings the reduction used (drift-corrected where a drift was found), so that later
    #: steps (the loop's radial evidence) read the same table without fitting the drift again
    readings: RadialMotionTable | None = None

    @classmethod
    def from_radial_motion(cls, rm: dict[str, Any], iso230_7: dict[str, Any],
                           probe_drift: dict[str, Any] | None = None,
                           readings: RadialMotionTable | None = None) -> RadialMotionResult:
        return cls.from_detail(rm, iso230_7=iso230_7, probe_drift=probe_drift, readings=readings)

    @property
    def bandwidth(self) -> dict[str, Any]:
        """The orders per revolution the summary's values hold (radial_motion's series: 2…order)."""
        return cast(dict[str, Any], self.detail["bandwidth"])

    def to_json(self) -> RadialMotionSection:
        out = RadialMotionSection(
            summary=self.summary, u_dY_range_um=self.u_dY_range_um, u_dY_gum_um=self.u_dY_gum_um, d_n=self.d_n,
            n_reps=self.n_reps, theta_deg=self.theta_deg, dY_um=self.dY_um, tilt_x_urad=self.tilt_x_urad,
            # δY as the spindle's synchronous motion (radial_motion: the revolutions' scatter per harmonic)
            u_dY_um=self.u_dY_um, u_dY_theta_um=self.u_dY_theta_um, u_h1_async_um=self.u_h1_async_um,
            bandwidth=self.bandwidth)
        if self.probe_drift:
            out["probe_drift"] = self.probe_drift
        return out

    def iso_summary(self) -> RadialErrorMotion:
        """results.json's radial_error_motion: the ISO 230-7 section (iso230_7.summary)."""
        from benchtwin.analysis.iso230_7 import summary

        return cast(RadialErrorMotion, summary(self.iso230_7))


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
    #: the sweep's frames: the pixel scale (eq. 13), the angles and d_ref of those used, those rejected
    frames: CcdFrames
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
                   u_e_async_um=ecc.get("u_async_h1_um"), frames=CcdFrames.from_detail(ecc),
                   residual_rms_um=ecc.get("residual_rms_um"),
                   u_source=ecc.get("u_source", ONE_SWEEP_U_SOURCE),
                   sweeps={k: ecc[k] for k in SWEEP_KEYS} if "n_sweeps" in ecc else None,
                   detail=ecc)

    @classmethod
    def from_frames(cls, fit: dict[str, Any], frames: CcdFrames) -> EccentricityResult:
        """The fit of the sweep(s) (eccentricity.eccentricity_from_dref / _from_sweeps) with its frames."""
        return cls.from_eccentricity({**fit, **frames.detail()})

    @property
    def cov_e_theta0(self) -> float:
        """cov(e, θ0) of the fit (µm·deg); 0 where the fit states none."""
        return cast(float, self.detail.get("cov_e_theta0", 0.0))

    @property
    def rejected_files(self) -> list[str]:
        return [r["file"] for r in self.frames.rejected_frames]

    def with_async_motion(self, u_h1_um: float, dof: float | None) -> EccentricityResult:
        """The asynchronous motion's 1st harmonic added to u(e) and u(θ0) (eccentricity.with_async_motion)."""
        from benchtwin.analysis.eccentricity import with_async_motion

        return EccentricityResult.from_eccentricity(with_async_motion(dict(self.detail), u_h1_um, dof))

    def ccd_section(self) -> CCDSection:
        f = self.frames
        return CCDSection(pixel_um=f.pixel_um, n_images=len(f.files), n_frames=f.n_frames, theta_deg=f.theta_deg,
                          d_ref_um=f.d_ref_um, residual_rms_um=self.residual_rms_um, min_frames=f.min_frames)

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
        out["ccd_rejected_frames"] = self.frames.rejected_frames
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

    @property
    def alpha_theta_deg(self) -> np.ndarray:
        """θ of the combined α (eq. 3), degrees."""
        return np.asarray(self.encoder_error_arcsec["theta_deg"])

    @property
    def alpha_arcsec(self) -> np.ndarray:
        return np.asarray(self.encoder_error_arcsec["value"])

    @property
    def alpha_u_arcsec(self) -> np.ndarray:
        """u of each α (the GUM budget of the curve, Hsieh Table 3), arcsec."""
        return np.asarray(self.encoder_error_arcsec["u"], dtype=float)

    @property
    def selfcal(self) -> CurveArrays | None:
        """The self-calibration's curve (Hsieh eqs. 8–9); None with one head."""
        return CurveArrays.from_curve(self.selfcal_error_arcsec) if self.selfcal_error_arcsec else None

    @property
    def u_c_arcsec(self) -> float | None:
        """The budget's combined standard uncertainty u_c of α (Table 3); None without a budget."""
        return float(self.budget_summary["u_c"]) if self.budget_summary else None

    @property
    def pooled_sd_eps_arcsec(self) -> float | None:
        """The readings' repeatability (pooled sd of ε over repeated runs); None (or 0) without."""
        return self.repeatability.get("pooled_sd_eps_arcsec")

    @property
    def closure_sd_arcsec(self) -> float | None:
        return self.repeatability.get("closure_sd_arcsec")

    @property
    def ac_resolution_arcsec(self) -> float:
        return self.autocollimator_declared["resolution_arcsec"]

    @property
    def ac_accuracy_arcsec(self) -> float:
        return self.autocollimator_declared["accuracy_arcsec"]

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
class TraceOutcome(_StepDetail):
    """What the tracing found in the residual (analysis.tracing.trace; docs/effects.md, "Result of trace");
    ``detail``: trace()'s whole dict (signature, selection, candidates) for the report's figures."""

    #: explained / ambiguous / unexplained / no_significant_residual / ..., and whether a significant
    #: residual is left unexplained
    status: str
    unexplained: bool
    identified_effects: list[IdentifiedEffect]
    #: the best candidate when it was not accepted ([] when there is none)
    partial_effects: list[dict[str, Any]]
    ambiguous: list[dict[str, Any]]
    #: the residual per polygon reading before and after the traced effects
    residual_before: TraceResidual
    residual_after: TraceResidual
    #: per identified artefact of the reference chain: value_arcsec, u_arcsec per reading, params
    reference_corrections: dict[str, dict[str, Any]]
    #: the model file's payload (analysis.tracing.save_model)
    model_file: dict[str, Any]

    @classmethod
    def from_trace(cls, tr: dict[str, Any]) -> TraceOutcome:
        return cls.from_detail(tr, partial_effects=tr.get("partial_effects") or [],
                               reference_corrections=tr.get("reference_corrections") or {})

    @property
    def signature(self) -> dict[str, Any]:
        """The residual's signature (harmonics, time, start face, direction); {} when the trace has none."""
        return self.detail.get("signature") or {}

    def identified(self) -> list[tuple[str, dict[str, Any]]]:
        """(name, params) of each identified effect."""
        return [(e["name"], e["params"]) for e in self.identified_effects]

    def effect_name(self, i: int) -> str:
        """The name of the model file's i-th effect."""
        return str(self.model_file["effects"][i]["name"])

    def to_json(self) -> CloseLoop:
        """results.json's close_loop section (the verdict, the signature, the selection)."""
        out = CloseLoop(status=self.status)
        for k in _CLOSE_LOOP_KEYS:
            if k in self.detail:
                out[k] = self.detail[k]  # type: ignore[literal-required]
        return out


# ----------------------------------------------------------------------------- the pipeline's inputs and stages
# (issue 35 item 1: the pipeline passes these frozen objects between its stages; the dataset's dicts
# and the equation modules' dicts are read here, in one constructor each, and results.json's dict is
# built from them by one ``to_json()`` each: BenchAnalysis.to_json is the edge where it is written)


@dataclass(frozen=True, eq=False)
class BenchGeometry:
    """The manifest's bench quantities the pipeline reads (docs/dataset-format.md), as declared."""

    optical_radius_mm: float
    L1_mm: float | None
    L2_mm: float | None
    grating_period_um: float | None
    polygon_faces: int | None
    heads_deg: list[float] | None
    #: heads the polygon's evidence counts (1 when the manifest names none)
    n_heads: int
    encoder_lines: int | None
    scale_edge_radius_mm: float | None
    polygon_certificate_arcsec: list[float] | None
    #: the whole bench block as read (validated by analysis.dataset)
    block: dict[str, Any]

    @classmethod
    def from_manifest(cls, b: dict[str, Any]) -> BenchGeometry:
        return cls(optical_radius_mm=b.get("optical_radius_mm"), L1_mm=b.get("L1_mm"),  # type: ignore[arg-type]
                   L2_mm=b.get("L2_mm"), grating_period_um=b.get("grating_period_um"),
                   polygon_faces=b.get("polygon_faces"), heads_deg=b.get("heads_deg"),
                   n_heads=len(b.get("heads_deg", [0])), encoder_lines=b.get("encoder_lines"),
                   scale_edge_radius_mm=b.get("scale_edge_radius_mm"),
                   polygon_certificate_arcsec=b.get("polygon_certificate_arcsec"), block=b)

    @property
    def r_um(self) -> float:
        """The optical radius r in µm (Jia eq. 5)."""
        return self.optical_radius_mm * 1000.0

    @property
    def sphere_distances_mm(self) -> tuple[float, float]:
        """(L1, L2): the test spheres' distances the radial motion needs (Jia eqs. 6–8)."""
        if self.L1_mm is None or self.L2_mm is None:
            raise ValueError("the manifest's bench block needs L1_mm and L2_mm for the radial motion (Jia eqs. 6-8)")
        return self.L1_mm, self.L2_mm

    @property
    def grating_period(self) -> float:
        """The grating's period in µm, the CCD images' scale (Jia eq. 13)."""
        if self.grating_period_um is None:
            raise ValueError("the manifest's bench block needs grating_period_um for the CCD images (Jia eq. 13)")
        return self.grating_period_um

    @property
    def faces(self) -> int:
        """The polygon's number of faces N (Hsieh eqs. 1–7)."""
        if self.polygon_faces is None:
            raise ValueError("the manifest's bench block needs polygon_faces for polygon.csv (Hsieh eqs. 1-7)")
        return self.polygon_faces


@dataclass(frozen=True, eq=False)
class RadialMotionTable:
    """radial_motion.csv: the two probes per revolution (docs/dataset-format.md), X probes optional."""

    rep: np.ndarray
    theta_deg: np.ndarray
    probe_top_um: np.ndarray
    probe_bottom_um: np.ndarray
    probe_top_x_um: np.ndarray | None
    probe_bottom_x_um: np.ndarray | None
    #: the time of each reading (optional column), s
    t_s: np.ndarray | None = None

    @classmethod
    def from_table(cls, t: Mapping[str, Any]) -> RadialMotionTable:
        return cls(rep=t["rep"], theta_deg=t["theta_deg"], probe_top_um=t["probe_top_um"],
                   probe_bottom_um=t["probe_bottom_um"], probe_top_x_um=t.get("probe_top_x_um"),
                   probe_bottom_x_um=t.get("probe_bottom_x_um"), t_s=t.get("t_s"))

    def drift_corrected(self, L1_mm: float, L2_mm: float,
                        optical_radius_mm: float | None = None) -> tuple[RadialMotionTable, dict[str, Any] | None]:
        """The readings less each probe's time-smooth drift (analysis.probe_drift: a Legendre series
        in the reading time fitted jointly with the θ-synchronous series, its order by a nested F
        test), and the drift's summary for results.json. Probes whose drift is not significant keep
        their readings bit for bit; (self, None) when none is (or there are no reading times)."""
        from benchtwin.analysis.probe_drift import drift_summary, fit_probe_drift
        from benchtwin.analysis.radial_motion import disk_weights

        cols = self.probes()
        fits = fit_probe_drift(self.rep, self.theta_deg, self.t_s, cols)
        if self.t_s is None or not any(f.order > 0 for f in fits.values()):
            return self, None
        new = {c: (np.asarray(v, dtype=float) - fits[c].removed_um if c in fits and fits[c].order > 0 else v)
               for c, v in cols.items()}
        out = drift_summary(fits, self.t_s, disk_weights(L1_mm, L2_mm), optical_radius_mm)
        table = RadialMotionTable(rep=self.rep, theta_deg=self.theta_deg,
                                  probe_top_um=cast(np.ndarray, new["probe_top_um"]),
                                  probe_bottom_um=cast(np.ndarray, new["probe_bottom_um"]),
                                  probe_top_x_um=new["probe_top_x_um"], probe_bottom_x_um=new["probe_bottom_x_um"],
                                  t_s=self.t_s)
        return table, out

    def probes(self) -> dict[str, np.ndarray | None]:
        """{column: values} of the four probes (analysis.iso230_7.radial_error_motion)."""
        return {"probe_top_um": self.probe_top_um, "probe_bottom_um": self.probe_bottom_um,
                "probe_top_x_um": self.probe_top_x_um, "probe_bottom_x_um": self.probe_bottom_x_um}


@dataclass(frozen=True, eq=False)
class FitStatistics:
    """What a fit's residual can test (analysis.error_model.fit_statistics)."""

    n_params: int
    dof: int
    chi2: float
    p_value: float | None
    loo_rms_arcsec: float | None

    @classmethod
    def from_fit(cls, st: Mapping[str, Any]) -> FitStatistics:
        return cls(n_params=int(st["n_params"]), dof=int(st["dof"]), chi2=float(st["chi2"]), p_value=st["p_value"],
                   loo_rms_arcsec=st["loo_rms_arcsec"])


#: the yardstick of the residuals' χ² (results.json ``residual_before`` / ``residual_after``: ``chi2_u``)
CHI2_YARDSTICK = ("u of each α (encoder_error_arcsec.u: the GUM budget of the shift-angle curve, Hsieh 2022 "
                  "Table 3); the model's own parameters (e, θ0 from the CCD, δY from the probes) are not in it")


@dataclass(frozen=True, eq=False)
class ModelComparison(_StepDetail):
    """Measured encoder error − Jia model (eq. 5) at the curve's angles (error_model.compare_with_measured);
    ``detail``: compare_with_measured()'s whole dict for the report's figure (figures_jia.fig_comparison)."""

    theta_deg: np.ndarray
    measured_arcsec: np.ndarray
    model_arcsec: np.ndarray
    residual_arcsec: np.ndarray
    residual_rms_arcsec: float
    residual_pv_arcsec: float
    residual_max_abs_arcsec: float
    fraction_of_error: float
    pv_ratio: float
    measured_pv_arcsec: float
    measured_rms_arcsec: float
    note: str

    @classmethod
    def from_compare(cls, cmp: dict[str, Any]) -> ModelComparison:
        return cls.from_detail(cmp)

    def residual_summary(self, u_arcsec: float | None = None, stats: FitStatistics | None = None, *,
                         per_reading_rms_arcsec: float | None = None,
                         added_terms: list[str] | None = None) -> ResidualSummary:
        """The comparison's RMS, P-V, ... and, with ``stats`` (the fit behind the residual), what it
        can test: n_params, dof, chi2, p_value, loo_rms_arcsec and, where dof < 3, the sentence saying
        this sampling cannot test the model and which would (error_model.sampling_advice); then the
        residual per polygon reading and the terms the model after the loop added, where given."""
        from benchtwin.analysis.error_model import sampling_advice

        out = ResidualSummary(rms_arcsec=self.residual_rms_arcsec, pv_arcsec=self.residual_pv_arcsec,
                              max_abs_arcsec=self.residual_max_abs_arcsec, fraction_of_error=self.fraction_of_error,
                              pv_ratio=self.pv_ratio, measured_pv_arcsec=self.measured_pv_arcsec,
                              measured_rms_arcsec=self.measured_rms_arcsec, n_points=int(len(self.theta_deg)),
                              note=self.note)
        if u_arcsec is not None:
            out["u_rms_arcsec"] = u_arcsec
        if stats is not None:
            out["n_params"] = stats.n_params
            out["dof"] = stats.dof
            out["chi2"] = stats.chi2
            # None (null in results.json) where the fit leaves no dof / no leave-one-out fit (ResidualSummary)
            out["p_value"] = cast(float, stats.p_value)
            out["loo_rms_arcsec"] = cast(float, stats.loo_rms_arcsec)
            out["chi2_u"] = CHI2_YARDSTICK
            advice = sampling_advice(out["n_points"], out["n_params"])
            if advice is not None:
                out["sampling_note"] = advice
        if per_reading_rms_arcsec is not None:
            out["per_reading_rms_arcsec"] = per_reading_rms_arcsec
        if added_terms is not None:
            out["added_terms"] = added_terms
        return out

    def section(self, with_measured: bool = True) -> Comparison:
        """results.json's comparison (with the measured curve) or comparison_after (without)."""
        if with_measured:
            return Comparison(theta_deg=self.theta_deg, measured_arcsec=self.measured_arcsec,
                              model_arcsec=self.model_arcsec, residual_arcsec=self.residual_arcsec)
        return Comparison(theta_deg=self.theta_deg, model_arcsec=self.model_arcsec, residual_arcsec=self.residual_arcsec)


@dataclass(frozen=True, eq=False)
class RefinedEccentricity:
    """(e, θ0) from the CCD combined with the comparison's first harmonic, and the traced parameters
    refitted on the stops (error_model.refine_eccentricity; results.json ``eccentricity_refined``)."""

    e_um: float
    u_e_um: float
    theta0_deg: float
    u_theta0_deg: float
    cov_e_theta0: float
    #: the refitted parameters' corrections δp, in the order of ``refitted_params``
    column_params: list[float]
    refitted_params: list[str]
    #: the first-order graduation term's Fourier components (a1, b1), arcsec; None when not fitted
    k1_a1_arcsec: float | None
    k1_b1_arcsec: float | None
    #: the prior u of that term per component (pipeline.k1_prior), arcsec
    k1_prior_u_arcsec: float
    #: u(e) of the CCD alone, µm
    ccd_u_e_um: float
    #: the fit's statistics (the residual after the loop)
    fit: FitStatistics
    #: the results.json section as refine_eccentricity gave it, with k1_prior, refitted_params and
    #: residual_after_ccd_e_pv_arcsec
    section: dict[str, Any]

    @classmethod
    def from_refine(cls, ref: dict[str, Any], k1_prior: dict[str, Any], refitted_params: list[str],
                    residual_after_ccd_e_pv_arcsec: float) -> RefinedEccentricity:
        sec = dict(ref)
        fit = sec.pop("fit")
        sec.pop("residual_arcsec")
        sec.update(k1_prior=k1_prior, refitted_params=refitted_params,
                   residual_after_ccd_e_pv_arcsec=residual_after_ccd_e_pv_arcsec)
        k1 = sec.get("k1_arcsec")
        return cls(e_um=sec["e_um"], u_e_um=sec["u_e_um"], theta0_deg=sec["theta0_deg"],
                   u_theta0_deg=sec["u_theta0_deg"], cov_e_theta0=sec["cov_e_theta0"],
                   column_params=sec["column_params"], refitted_params=refitted_params,
                   k1_a1_arcsec=float(k1["a1"]) if k1 is not None else None,
                   k1_b1_arcsec=float(k1["b1"]) if k1 is not None else None,
                   k1_prior_u_arcsec=k1_prior["u_arcsec"], ccd_u_e_um=sec["ccd"]["u_e_um"],
                   fit=FitStatistics.from_fit(fit), section=sec)

    def to_json(self) -> dict[str, Any]:
        return self.section


@dataclass(frozen=True, eq=False)
class LoopOutcome:
    """Closing the loop (pipeline._close_loop): the tracing's verdict, the corrected curve, the model
    after the traced effects and its residual."""

    #: the tracing's evidence (analysis.tracing.Evidence) and its verdict
    evidence: Any
    trace: TraceOutcome
    #: the encoder error less the identified artefacts of the reference chain
    corrected: CorrectedCurve
    residual_after: ResidualSummary
    #: the comparison with the model after the loop; None when nothing was identified
    comparison_after: ModelComparison | None
    refined: RefinedEccentricity | None
    notes: list[str]
    #: the model file written (out/model.json); None when none
    model_path: str | None

    def to_json(self) -> dict[str, Any]:
        """The keys of results.json the loop writes (close_loop, identified_effects, ..., residual_after)."""
        tr = self.trace
        out: dict[str, Any] = {
            "close_loop": tr.to_json(), "identified_effects": tr.identified_effects, "ambiguous": tr.ambiguous,
            "unexplained": tr.unexplained, "residual_test": tr.residual_before,
            "residual_after_trace": tr.residual_after, "encoder_error_corrected_arcsec": self.corrected}
        if self.refined is not None:
            out["eccentricity_refined"] = self.refined.to_json()
        out["residual_after"] = self.residual_after
        if self.comparison_after is not None:
            out["comparison_after"] = self.comparison_after.section(with_measured=False)
        return out


@dataclass(frozen=True, eq=False)
class BenchAnalysis:
    """A bench dataset's analysis, stage by stage (pipeline.analyze_into): what results.json,
    the report and the calibration files are written from."""

    #: format, version, dataset, source: results.json's header
    dataset: str
    source: str
    bench: BenchGeometry
    rm: RadialMotionResult | None = None
    ecc: EccentricityResult | None = None
    pol: PolygonAnalysis | None = None
    #: ISO 230-2 statistics of the polygon's clampings (analysis.iso230_2); None without both directions
    iso230_2: dict[str, Any] | None = None
    #: the Jia error model (eq. 5; analysis.error_model.ErrorModel) and the terms a model file added
    model: Any = None
    model_file_terms: list[str] | None = None
    prediction: ModelPrediction | None = None
    cmp: ModelComparison | None = None
    residual_before: ResidualSummary | None = None
    #: the raw curve as the corrected one, until the loop identifies an artefact of the reference chain
    corrected: CorrectedCurve | None = None
    loop: LoopOutcome | None = None
    notes: tuple[str, ...] = ()

    def to_json(self) -> BenchResults:
        """results.json's dict (the one place it is built for a bench dataset)."""
        out: dict[str, Any] = {"format": "bench-results", "version": 1, "dataset": self.dataset,
                               "source": self.source, "bench": cast(Bench, dict(self.bench.block)),
                               "notes": list(self.notes) + (self.loop.notes if self.loop is not None else [])}
        if self.rm is not None:
            out["radial_motion"] = self.rm.to_json()
            out["radial_error_motion"] = self.rm.iso_summary()
        if self.ecc is not None:
            out.update(self.ecc.to_json())
        if self.pol is not None:
            out.update(self.pol.to_json())
            if self.iso230_2 is not None:
                out["iso230_2"] = self.iso230_2
        if self.model_file_terms is not None:
            out["model_file_terms"] = self.model_file_terms
        if self.prediction is not None:
            out["model_prediction_arcsec"] = self.prediction
        if self.cmp is not None:
            out["residual_before"] = self.residual_before
            out["comparison"] = self.cmp.section()
        if self.corrected is not None:
            out["encoder_error_corrected_arcsec"] = self.corrected
        if self.loop is not None:
            out.update(self.loop.to_json())
        return cast(BenchResults, out)


@dataclass(frozen=True, eq=False)
class CcdFrames:
    """The CCD sweep's frames as the image analysis left them (pipeline.step_eccentricity): the pixel
    scale (Jia eq. 13), d_ref per frame used (eqs. 10–12) and the frames rejected."""

    pixel_um: float
    radius_fixed_px: float | None
    theta_deg: list[float]
    d_ref_um: np.ndarray
    files: list[str]
    n_frames: int
    rejected_frames: list[RejectedFrame]
    frame_limits: dict[str, int]
    #: the first used frame's fit {file, fit}, which the report draws (figures_ccd.add_ccd_pictures)
    first_frame_fit: dict[str, Any] | None

    @classmethod
    def from_detail(cls, d: Mapping[str, Any]) -> CcdFrames:
        """The frames from the eccentricity fit's dict they were merged into (``detail()``)."""
        return cls(pixel_um=d["pixel_um"], radius_fixed_px=d["radius_fixed_px"], theta_deg=d["theta_deg"],
                   d_ref_um=d["d_ref_um"], files=d["files"], n_frames=d["n_frames"],
                   rejected_frames=d["rejected_frames"], frame_limits=d["frame_limits"],
                   first_frame_fit=d.get("first_frame_fit"))

    @property
    def min_frames(self) -> int:
        """The fewest usable frames accepted (pipeline.ccd_frame_limits)."""
        return self.frame_limits["min_frames"]

    def detail(self) -> dict[str, Any]:
        """The keys the step adds to the eccentricity fit's dict (EccentricityResult.detail)."""
        return {"pixel_um": self.pixel_um, "radius_fixed_px": self.radius_fixed_px, "theta_deg": self.theta_deg,
                "d_ref_um": self.d_ref_um, "files": self.files, "n_frames": self.n_frames,
                "rejected_frames": self.rejected_frames, "frame_limits": self.frame_limits,
                "first_frame_fit": self.first_frame_fit}


@dataclass(frozen=True, eq=False)
class ErrorCurveTable:
    """error_curve.csv: an imported α(θ) table (docs/dataset-format.md); direction and u optional."""

    theta_deg: np.ndarray
    error_arcsec: np.ndarray
    direction: np.ndarray | None
    u_arcsec: np.ndarray | None

    @classmethod
    def from_table(cls, t: Mapping[str, Any]) -> ErrorCurveTable:
        return cls(theta_deg=t["theta_deg"], error_arcsec=t["error_arcsec"], direction=t.get("direction"),
                   u_arcsec=t.get("u_arcsec"))


@dataclass(frozen=True, eq=False)
class ErrorCurveAnalysis:
    """A lone error curve's analysis (analysis.error_curve.analyze_error_curve), with what the pipeline
    adds: the periods over an arc (analysis.arc_periods) and ISO 230-2 statistics (analysis.iso230_2)."""

    #: the direction mean {theta_deg, value_arcsec, u_arcsec}
    theta_deg: np.ndarray
    value_arcsec: np.ndarray
    u_arcsec: np.ndarray
    full_turn: bool
    #: u of one point is type A from the fit's residual (then it does not weigh the arc's periods)
    u_from_residual: bool
    status: str
    ambiguous: list[dict[str, Any]]
    unexplained: bool
    left: list[str]
    notes: list[str]
    #: analyze_error_curve()'s whole dict (results.json error_curve; the report's tables)
    detail: dict[str, Any]
    arc: dict[str, Any] | None = None
    iso230_2: dict[str, Any] | None = None

    @classmethod
    def from_analysis(cls, ec: dict[str, Any]) -> ErrorCurveAnalysis:
        mc = ec["mean_curve"]
        return cls(theta_deg=mc["theta_deg"], value_arcsec=mc["value_arcsec"], u_arcsec=mc["u_arcsec"],
                   full_turn=ec["coverage"]["full_turn"],
                   u_from_residual=ec["u_point"]["source"].startswith("type A from the residual"),
                   status=ec["status"], ambiguous=ec["ambiguous"], unexplained=ec["unexplained"],
                   left=ec.get("left", []), notes=ec["notes"], detail=ec)

    def to_json(self, dataset: str, manifest: Mapping[str, Any], bench: Bench, close_loop: bool) -> ErrorCurveResults:
        """results.json's dict of an error-curve dataset (the one place it is built)."""
        ec = self.detail
        results = ErrorCurveResults(
            format="bench-results", version=1, dataset=dataset, source=manifest["source"],
            kind="error-curve", bench=bench, notes=list(self.notes), imported_from=manifest.get("import"),
            coverage_deg=ec["coverage_deg"], coverage=ec["coverage"], closure=ec["closure"],
            hysteresis=ec["hysteresis"], u_point=ec["u_point"], harmonics=ec["harmonics"],
            error_curve={k: v for k, v in ec.items() if k not in ("notes",)},
            encoder_error_arcsec=Curve(theta_deg=self.theta_deg, value=self.value_arcsec, u=self.u_arcsec),
            # nothing of the reference chain is identified on a lone curve: the corrected curve is the raw one
            encoder_error_corrected_arcsec=CorrectedCurve(theta_deg=self.theta_deg, value=self.value_arcsec,
                                                          u=self.u_arcsec, corrections_applied=[]),
        )
        if self.arc is not None:
            results["arc_periods"] = cast(list[ArcPeriod], self.arc["periods"])
            results["arc_period_scan"] = self.arc["scan"]
        if self.iso230_2 is not None:
            results["iso230_2"] = cast(Iso230_2, self.iso230_2)
        if close_loop:
            results["identified_effects"] = []
            results["ambiguous"] = self.ambiguous
            results["unexplained"] = self.unexplained
            results["close_loop"] = CloseLoop(status=self.status, left=self.left)
        return results


@dataclass(frozen=True, eq=False)
class PolygonReadings:
    """polygon.csv's columns the shift-angle method reads (Hsieh eqs. 2–7; docs/dataset-format.md):
    one autocollimator reading per (shift, start face, step); θ, repetition and direction optional."""

    shift_deg: np.ndarray
    start_face: np.ndarray
    step: np.ndarray
    ac_arcsec: np.ndarray
    theta_deg: np.ndarray | None
    rep: np.ndarray | None
    direction: np.ndarray | None
    #: the encoder's display at each stop (pipeline.polygon_table), where recorded
    theta_read_deg: np.ndarray | None

    @classmethod
    def from_table(cls, t: Mapping[str, Any]) -> PolygonReadings:
        return cls(shift_deg=t["shift_deg"], start_face=t["start_face"], step=t["step"], ac_arcsec=t["ac_arcsec"],
                   theta_deg=t.get("theta_deg"), rep=t.get("rep"), direction=t.get("direction"),
                   theta_read_deg=t.get("theta_read_deg"))

    def directions(self) -> np.ndarray | None:
        """The direction column as text; None without one."""
        return None if self.direction is None else np.asarray(self.direction).astype(str)


@dataclass(frozen=True, eq=False)
class CcdSweepSetup:
    """The CCD sweep as the manifest and ccd/index.csv state it (Jia sec. 4.2)."""

    #: the reference point d_ref is measured from (px) and the camera's azimuth (deg)
    reference_px: tuple[float, ...]
    position_deg: float
    #: per frame of the index: its file and sweep (None: one sweep)
    n_frames: int
    files: list[str]
    sweep: np.ndarray | None

    @classmethod
    def from_dataset(cls, ccd: Mapping[str, Any], index: Mapping[str, Any]) -> CcdSweepSetup:
        return cls(reference_px=tuple(ccd["reference_px"]), position_deg=ccd["position_deg"],
                   n_frames=len(index["k"]), files=[str(f).strip() for f in index["file"]], sweep=index.get("sweep"))


@dataclass(frozen=True, eq=False)
class CurveArrays:
    """A curve section of results.json ({theta_deg, value, u}: encoder_error_arcsec, the corrected
    curve, the self-calibration) as its arrays, as stored (u None where the section has none)."""

    theta_deg: Any
    value: Any
    u: Any

    @classmethod
    def from_curve(cls, c: Mapping[str, Any]) -> CurveArrays:
        return cls(theta_deg=c["theta_deg"], value=c["value"], u=c.get("u"))


@dataclass(frozen=True, eq=False)
class ReferenceCorrection:
    """One identified artefact of the reference chain per polygon reading (tracing
    ``reference_corrections``): its contribution and u per reading (arcsec) and its parameters."""

    value_arcsec: np.ndarray
    u_arcsec: np.ndarray
    params: dict[str, Any] | None

    @classmethod
    def from_trace(cls, c: Mapping[str, Any]) -> ReferenceCorrection:
        return cls(value_arcsec=np.asarray(c["value_arcsec"], dtype=float),
                   u_arcsec=np.asarray(c["u_arcsec"], dtype=float), params=c.get("params"))


@dataclass(frozen=True, eq=False)
class SignatureHarmonic:
    """One harmonic of the residual's signature (analysis.tracing): order k and its Fourier
    components a (sin), b (cos), arcsec (None where not stated)."""

    k: int
    a_arcsec: float | None
    b_arcsec: float | None

    @classmethod
    def from_signature(cls, signature: Mapping[str, Any]) -> list[SignatureHarmonic]:
        return [cls(k=int(h.get("k", 0)), a_arcsec=h.get("a_arcsec"), b_arcsec=h.get("b_arcsec"))
                for h in (signature.get("harmonics") or [])]


@dataclass(frozen=True, eq=False)
class ModelFileEffect:
    """One effect of a model file (analysis.tracing.save_model): its name, parameters and their u."""

    name: str
    params: dict[str, Any]
    u: dict[str, Any]

    @classmethod
    def effects_of(cls, payload: Mapping[str, Any]) -> list[ModelFileEffect]:
        return [cls(name=e.get("name", ""), params=e["params"], u=e.get("u") or {})
                for e in payload.get("effects", [])]


def payload_with_params(payload: Mapping[str, Any], params: Mapping[tuple[int, str], float],
                        only: int | None = None) -> dict[str, Any]:
    """A deep copy of the model file ``payload`` with parameter ``name`` of effect ``i`` set to
    ``params[(i, name)]``; with ``only``, the copy holds that effect alone (index 0)."""
    import copy

    out = copy.deepcopy(dict(payload))
    if only is not None:
        out["effects"] = [out["effects"][only]]
    for (i, name), v in params.items():
        out["effects"][0 if only is not None else i]["params"][name] = v
    return out


def combined_sweeps(fits: list[dict[str, Any]], comb: Mapping[str, Any], sweep_of_frame: np.ndarray) -> dict[str, Any]:
    """The eccentricity step's dict for repeated CCD sweeps: sweep 0's fit (the figures and the CCD
    section show it with every sweep's points), the sweeps' combination (eccentricity_from_sweeps),
    cov(e, θ0) of the means (µm·deg), the RMS of the fits' residuals and the sweep of each frame."""
    n = len(fits)
    e_i, t_i = np.asarray(comb["e_sweeps_um"]), np.asarray(comb["theta0_sweeps_deg"])
    dt = (t_i - comb["theta0_deg"] + 180.0) % 360.0 - 180.0
    res = dict(fits[0])
    res.update(comb)
    res["cov_e_theta0"] = float(np.cov(e_i, dt, ddof=1)[0, 1] / n)   # µm·deg, of the means
    res["residual_rms_um"] = float(np.sqrt(np.mean([f["residual_rms_um"] ** 2 for f in fits])))
    res["sweep_of_frame"] = sweep_of_frame.tolist()
    return res
