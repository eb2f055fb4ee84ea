"""results.json (format ``bench-results``, version 1): its typed sections, their documentation and a validator.

The results of ``benchtwin analyze`` / ``close-loop`` (analysis/pipeline.py) are built as the
TypedDicts below; each key is annotated with its unit and meaning (``Annotated[type, Key(unit,
doc)]``), and the same annotations give

- :func:`validate_results`: the check of a results file or object, like the dataset's
  (``benchtwin validate RESULTS.json``): a :class:`ResultsError` (exit 2) naming the file, the key
  (dotted path, list index in brackets) and what was expected;
- :func:`results_format_markdown`: docs/results-format.md, every key with its unit (generated:
  tests/analysis/test_results_format.py checks the page against it).

Values follow the JSON writer of the pipeline (benchtwin/jsonable.py): numbers are JSON numbers,
a non-finite number is written as null, arrays are lists. Units are those of the key's name
(principle 4: ``e_um``, ``theta_deg``); ″ = arcsec. Where a section is the output of a module with
its own documentation (the tracing's signature and selection, docs/effects.md; the GUM budget,
analysis/uncertainty.py), its inner keys are listed to the depth given here and the rest is
described, not typed ("object").

Sources: Jia et al. 2019 (Appl. Sci. 9, 3415): radial motion eqs. 6–9, eccentricity eqs. 10–13,
error model eq. 5; Hsieh et al. 2022 (Appl. Sci. 12, 5008): shift-angle eqs. 2–7, self-calibration
eqs. 8–9, budget Table 3; ISO 230-7:2015 (error motion); JCGM 100:2008 (GUM) and 101:2008 (MC).
"""

# no `from __future__ import annotations`: TypedDict reads NotRequired from evaluated annotations (3.11)
import functools
import math
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, NotRequired, TypedDict, Union

import numpy as np

__all__ = ["ResultsError", "validate_results", "read_results", "read_results_text", "parse_results", "results_format_markdown", "BenchResults",
           "ErrorCurveResults", "PolygonResults", "FORMAT", "VERSION", "MAX_RESULTS_BYTES"]

FORMAT = "bench-results"
VERSION = 1
#: results of a long sweep: the CCD's d_ref per frame and curves of a few thousand points, ~1 MB;
#: the limit keeps a wrong file from being read whole
MAX_RESULTS_BYTES = 256 * 1024 * 1024


class ResultsError(ValueError):
    """A results file or object that does not follow this format; the message names the file, the key
    and what was expected."""


@dataclass(frozen=True)
class Key:
    """A key's unit ("" for none) and meaning."""

    unit: str
    doc: str


class _Nullable:
    """Marks a number the writer may write as null (a non-finite value, benchtwin/jsonable.py)."""

    def __repr__(self) -> str:
        return "NULLABLE"


NULLABLE = _Nullable()
#: a number: a float in memory (possibly NaN), a JSON number or null in the file
Num = Annotated[float, NULLABLE]
#: a list of numbers in the file; in memory (the object analyze() returns) also a numpy array
Floats = list[Num] | np.ndarray


# ----------------------------------------------------------------------------------------------
# curves and small tables
# ----------------------------------------------------------------------------------------------

class Curve(TypedDict):
    """A curve with its standard uncertainty at each angle."""

    theta_deg: Annotated[Floats, Key("deg", "encoder angle θ of each point")]
    value: Annotated[Floats, Key("arcsec", "the value at θ")]
    u: Annotated[Floats, Key("arcsec", "its standard uncertainty (GUM, k = 1)")]


class EncoderErrorCurve(Curve):
    """The shift-angle method's encoder error α(θ) (Hsieh eq. 3, combined over shifts)."""

    U: NotRequired[Annotated[Floats, Key("arcsec", "expanded uncertainty (k of budget_summary)")]]
    u_propagated: NotRequired[Annotated[Floats, Key("arcsec", "u propagated through eqs. 5–7 alone")]]


class CorrectionApplied(TypedDict):
    effect: Annotated[str, Key("", "effect of the reference chain removed (analysis/effects)")]
    rms_arcsec: Annotated[Num, Key("arcsec", "RMS of the correction over the curve")]
    u_rms_arcsec: Annotated[Num, Key("arcsec", "RMS of the correction's standard uncertainty")]
    params: Annotated[Any, Key("", "the effect's parameter names (or values) the correction used")]
    angles_without_readings: Annotated[int, Key("", "angles of the curve with no polygon reading at that stop")]


class CorrectedCurve(Curve):
    """The encoder's error after removing the identified artefacts of the reference chain; the raw
    curve when none is identified (docs/effects.md, "The corrected calibration curve")."""

    corrections_applied: Annotated[list[CorrectionApplied], Key("", "one entry per correction, [] for none")]
    note: NotRequired[Annotated[str, Key("", "what the curve is")]]


class Comparison(TypedDict):
    """Measured encoder error against the Jia model (Jia sec. 4.3, fig. 16), at the polygon angles."""

    theta_deg: Annotated[Floats, Key("deg", "polygon angles")]
    measured_arcsec: NotRequired[Annotated[Floats, Key("arcsec", "measured encoder error (mean removed)")]]
    model_arcsec: Annotated[Floats, Key("arcsec", "model Δθ (Jia eq. 5; mean removed)")]
    residual_arcsec: Annotated[Floats, Key("arcsec", "measured − model")]


class ModelPrediction(Curve):
    """The error model Δθ = [e·sin(θ−θ0) + ∫δY dθ]/r (Jia eq. 5) on a 1° grid, with its u."""

    terms: Annotated[dict[str, Floats], Key("arcsec", "each term of the model on the grid, by name")]


class ResidualSummary(TypedDict):
    """Residual of the measured encoder error after the model (Jia sec. 4.3)."""

    rms_arcsec: Annotated[Num, Key("arcsec", "RMS of the residual")]
    pv_arcsec: Annotated[Num, Key("arcsec", "peak-to-valley of the residual")]
    max_abs_arcsec: Annotated[Num, Key("arcsec", "largest |residual|")]
    fraction_of_error: Annotated[Num, Key("1", "residual RMS / measured RMS")]
    pv_ratio: Annotated[Num, Key("1", "residual P-V / measured P-V")]
    measured_pv_arcsec: Annotated[Num, Key("arcsec", "P-V of the measured encoder error")]
    measured_rms_arcsec: Annotated[Num, Key("arcsec", "RMS of the measured encoder error")]
    n_points: Annotated[int, Key("", "number of angles compared")]
    note: Annotated[str, Key("", "how the comparison is made")]
    u_rms_arcsec: NotRequired[Annotated[Num, Key("arcsec", "RMS of the measured curve's u")]]
    added_terms: NotRequired[Annotated[list[str], Key("", "terms the traced effects added to the model")]]
    # what the residual can test (error_model.fit_statistics of the fit behind it)
    n_params: NotRequired[Annotated[int, Key("", "parameters fitted to these angles (rank of the weighted design: "
                                                 "α's constant; after the loop also the first harmonic and the "
                                                 "traced effects' parameters)")]]
    dof: NotRequired[Annotated[int, Key("", "degrees of freedom left: n_points − n_params")]]
    chi2: NotRequired[Annotated[Num, Key("1", "Σ (residual/u)², u of each α (chi2_u)")]]
    p_value: NotRequired[Annotated[Num, Key("1", "P(χ²_dof ≥ chi2); null when dof = 0")]]
    loo_rms_arcsec: NotRequired[Annotated[Num, Key("arcsec", "leave-one-out: RMS of each angle predicted by the fit "
                                                            "made without it (PRESS residual r/(1 − h), hat "
                                                            "matrix); null when an angle alone fixes a parameter")]]
    chi2_u: NotRequired[Annotated[str, Key("", "the u the χ² is taken against")]]
    sampling_note: NotRequired[Annotated[str, Key("", "only when dof < 3: this sampling cannot test the model, "
                                                      "and which sampling would")]]
    per_reading_rms_arcsec: NotRequired[Annotated[Num, Key("arcsec", "after the loop: RMS per polygon reading of "
                                                                     "the residual after this same model "
                                                                     "(closure-centred)")]]


class TraceResidual(TypedDict, total=False):
    """The tracing's residual per polygon reading (α − model, closure-centred; docs/effects.md)."""

    rms_arcsec: Annotated[Num, Key("arcsec", "RMS per polygon reading")]
    pv_arcsec: Annotated[Num, Key("arcsec", "peak-to-valley")]
    fraction_of_error: Annotated[Num, Key("1", "RMS / RMS of the measured α")]
    chi2: Annotated[Num, Key("1", "χ² against the combined uncertainty of measurement and model")]
    dof: Annotated[int, Key("", "its degrees of freedom")]
    p_value: Annotated[Num, Key("1", "P(χ² ≥ observed)")]
    significant: Annotated[bool, Key("", "p < P_SIG and excess ≥ SIZE_GATE of the noise floor")]
    noise_floor_arcsec: Annotated[Num, Key("arcsec", "u_c of one α (GUM type A and B)")]
    excess_rms_arcsec: Annotated[Num, Key("arcsec", "RMS beyond the uncertainties, u·√(χ²/ν − 1)")]
    async_motion: Annotated[dict[str, Any], Key("", "the axis's non-repeating motion (RadialMotion.async_rms): "
                                                    "sigma_um, scatter_um, noise_um (µm), per_stop_arcsec (″), ...")]
    signature_left: Annotated[list[str], Key("", "signature parts left after the traced effects")]


# ----------------------------------------------------------------------------------------------
# measurement sections
# ----------------------------------------------------------------------------------------------

class Bench(TypedDict, total=False):
    """The manifest's bench block as read (docs/dataset-format.md); keys as there."""

    optical_radius_mm: Annotated[float, Key("mm", "optical radius r of the reading head (Jia eq. 5)")]
    L1_mm: Annotated[float, Key("mm", "top sphere → disk (Jia eq. 9)")]
    L2_mm: Annotated[float, Key("mm", "top sphere → bottom sphere")]
    grating_period_um: Annotated[float, Key("µm", "grating period (Jia eq. 13)")]
    scale_edge_radius_mm: Annotated[float, Key("mm", "radius of the graduation's outer edge the CCD sees")]
    encoder_lines: Annotated[int, Key("", "graduation lines per turn")]
    encoder_resolution_arcsec: Annotated[float, Key("arcsec", "encoder resolution (GUM type B)")]
    heads_deg: Annotated[Floats, Key("deg", "azimuths of the reading heads")]
    polygon_faces: Annotated[int, Key("", "faces N of the polygon")]
    autocollimator_resolution_arcsec: Annotated[float, Key("arcsec", "declared autocollimator resolution")]
    autocollimator_accuracy_arcsec: Annotated[float, Key("arcsec", "declared autocollimator maximum error")]


class RadialMotionSection(TypedDict):
    """Radial error motion from the two test spheres (Jia sec. 4.1, eqs. 6–9; analysis/radial_motion.py)."""

    summary: Annotated[dict[str, dict[str, Num]], Key("µm", "per location (top, bottom, disk [, _x]): total_um, "
                                                             "synchronous_um, asynchronous_um, asynchronous_pv_um of "
                                                             "the order-2…10 series (Jia eq. 7), their _u_um")]
    u_dY_range_um: Annotated[Num, Key("µm", "range method (max range / d_n, Jia sec. 5)")]
    u_dY_gum_um: Annotated[Num, Key("µm", "GUM u of the synchronous δY from the fits (max over θ)")]
    d_n: Annotated[Num, Key("1", "d_n of the range method")]
    n_reps: Annotated[int, Key("", "repetitions (revolutions) of the probes")]
    theta_deg: Annotated[Floats, Key("deg", "grid of the motion")]
    dY_um: Annotated[Floats, Key("µm", "disk motion δY along the head (eq. 9), synchronous")]
    tilt_x_urad: Annotated[Floats, Key("µrad", "tilt (eq. 8)")]
    u_dY_um: Annotated[Num, Key("µm", "u of δY as the spindle's synchronous motion (max over θ)")]
    u_dY_theta_um: Annotated[Floats, Key("µm", "the same at each θ")]
    u_h1_async_um: Annotated[Num, Key("µm", "asynchronous motion's share in the 1st harmonic of one revolution")]
    bandwidth: NotRequired[Annotated[dict[str, Any], Key("", "orders per revolution of the summary's values: "
                                                             "lowest_order, highest_order, filter, text")]]
    probe_drift: NotRequired[Annotated[dict[str, Any], Key("", "the probes' time-smooth drift removed before the "
                                                               "reduction (analysis/probe_drift.py), present when a "
                                                               "probe's passed the F test: channels (order, pv_um, "
                                                               "rms_um, u_um, p_value_none, ...), disk_y, disk_x, "
                                                               "duration_s, as_axis_alpha_pv_arcsec, "
                                                               "u_dY_range_as_read_um (Jia sec. 5's range "
                                                               "method on the readings as taken)")]]


class RadialErrorMotion(TypedDict, total=False):
    """ISO 230-7:2015 radial error motion values (analysis/iso230_7.py)."""

    standard: Annotated[str, Key("", "\"ISO 230-7:2015\"")]
    centre: Annotated[str, Key("", "reference centre (least-squares circle)")]
    sensitive_direction: Annotated[str, Key("", "\"fixed\"")]
    filtered: Annotated[bool, Key("", "whether a filter was applied")]
    fundamental_removed: Annotated[bool, Key("", "1st harmonic (centring) removed")]
    n_revolutions: Annotated[int, Key("", "revolutions")]
    order: Annotated[int | None, Key("", "Fourier order of the filter, null unfiltered")]
    bandwidth: Annotated[dict[str, Any], Key("", "orders per revolution the values hold: lowest_order, "
                                                 "highest_order (the positions' Nyquist unfiltered), filter, text")]
    acquisition: Annotated[dict[str, Any], Key("", "how the readings were taken: mode (step-and-settle), "
                                                   "positions_per_turn, text")]
    locations: Annotated[list[dict[str, Any]], Key("µm", "per location: name, label, total_um, synchronous_um, "
                                                         "asynchronous_um and their _u_um, n_revolutions, theta_deg, "
                                                         "synchronous_plot_um")]
    axial_face: NotRequired[Annotated[dict[str, Any], Key("µm", "ISO 230-7 axial and face error motion (present "
                                                                "when radial_motion.csv has probe_axial_um / "
                                                                "probe_face_um): locations axial, face with "
                                                                "total_um, synchronous_um, asynchronous_um and "
                                                                "their _u_um (fundamental included, about the PC), "
                                                                "residual_total_um, residual_synchronous_um, "
                                                                "fundamental_um, radius_mm (face)")]]


class CCDSection(TypedDict):
    """The CCD sweep (Jia sec. 4.2, eqs. 10–13)."""

    pixel_um: Annotated[Num, Key("µm/px", "image scale from the grating period (eq. 13)")]
    n_images: Annotated[int, Key("", "frames used")]
    n_frames: Annotated[int, Key("", "frames in the dataset")]
    theta_deg: Annotated[Floats, Key("deg", "angles of the frames used")]
    d_ref_um: Annotated[Floats, Key("µm", "distance of the edge to the reference point (eqs. 10–12)")]
    residual_rms_um: Annotated[float | None, Key("µm", "RMS residual of the eq. 10 fit")]
    min_frames: Annotated[int, Key("", "fewest usable frames accepted")]


class RejectedFrame(TypedDict):
    file: Annotated[str, Key("", "image file")]
    theta_deg: Annotated[float, Key("deg", "its angle")]
    stage: Annotated[str, Key("", "the step that rejected it")]
    reason: Annotated[str, Key("", "why")]


class AutocollimatorDeclared(TypedDict):
    """The autocollimator's GUM type B inputs (Hsieh sec. 3.3 (2), (4))."""

    resolution_arcsec: Annotated[float, Key("arcsec", "resolution (rectangular, r/(2√3))")]
    accuracy_arcsec: Annotated[float, Key("arcsec", "maximum error (rectangular, a/√3)")]
    source: Annotated[str, Key("", "\"manifest\" or the assumed instrument")]


class BudgetInput(TypedDict):
    value: Annotated[float, Key("", "the input (arcsec; the coverage factor k: 1), unit in its name")]
    source: Annotated[str, Key("", "\"manifest\" or the assumption and its reference")]


class BudgetRow(TypedDict, total=False):
    """One line of the GUM budget (Hsieh Table 3; analysis/uncertainty.py)."""

    name: Annotated[str, Key("", "contribution")]
    kind: Annotated[str, Key("", "\"group\" or \"member\"")]
    group: Annotated[str | None, Key("", "the group a member belongs to")]
    u: Annotated[Num, Key("arcsec", "standard uncertainty u(xᵢ)")]
    sensitivity: Annotated[Num, Key("1", "∂α/∂xᵢ")]
    contribution: Annotated[Num, Key("arcsec", "|c|·u")]
    dof: Annotated[Num, Key("1", "degrees of freedom ν")]
    distribution: Annotated[str, Key("", "\"t\", \"rectangular\", ... (empty for a group)")]


class BudgetSummary(TypedDict, total=False):
    """The budget's result (GUM; Monte Carlo check, JCGM 101)."""

    u_c: Annotated[Num, Key("arcsec", "combined standard uncertainty of one α")]
    u_type_b: Annotated[Num, Key("arcsec", "its type B part")]
    nu_eff: Annotated[Num, Key("1", "Welch–Satterthwaite degrees of freedom")]
    k: Annotated[Num, Key("1", "coverage factor")]
    U: Annotated[Num, Key("arcsec", "expanded uncertainty k·u_c")]
    p: Annotated[Num, Key("1", "coverage probability")]
    sensitivity_beta: Annotated[Num, Key("1", "sensitivity of α to the pitch deviations β")]
    monte_carlo: Annotated[dict[str, Any], Key("arcsec", "JCGM 101 check: n, std, gum_interval, shortest, "
                                                         "symmetric, delta, validated_1_digit")]


class IsoFigure(TypedDict):
    """One ISO 230-2 figure of the rotary axis."""

    symbol: Annotated[str, Key("", "its symbol in ISO 230-2 (A, A↑, E, M, R, B, B̄, ...)")]
    value: Annotated[Num, Key("arcsec", "its value; null where the runs cannot give it (R, A with one run)")]
    unit: Annotated[str, Key("", "\"arcsec\"")]
    what: Annotated[str, Key("", "what it is, with its formula")]


class Iso230_2(TypedDict):
    """Positioning statistics of the rotary axis, ISO 230-2:2014 (analysis/iso230_2.py), from runs in
    both directions."""

    standard: Annotated[str, Key("", "the standard")]
    convention: Annotated[str, Key("", "positional deviation x = actual − target = −α")]
    source: Annotated[str, Key("", "the runs used (table, how a run is formed)")]
    target_deg: Annotated[Floats, Key("deg", "the target positions P_i")]
    n_positions: Annotated[int, Key("", "number of target positions m")]
    n_runs: Annotated[dict[str, int], Key("", "runs per direction (forward, backward)")]
    runs_required_per_direction: Annotated[int, Key("", "what ISO 230-2 asks for (5)")]
    meets_run_count: Annotated[bool, Key("", "both directions have at least that many runs")]
    figures: Annotated[dict[str, IsoFigure], Key("", "A, A_forward, A_backward, E, E_forward, E_backward, M, R, "
                                                     "R_forward, R_backward, B, B_mean")]
    per_position: Annotated[dict[str, Floats], Key("arcsec", "per target: mean_forward_arcsec, mean_backward_arcsec, "
                                                             "mean_bidirectional_arcsec, s_forward_arcsec, "
                                                             "s_backward_arcsec, reversal_arcsec, "
                                                             "R_bidirectional_arcsec")]
    flags: Annotated[list[str], Key("", "what falls short of ISO 230-2 (fewer runs, no s)")]
    excludes: Annotated[str, Key("", "what the figures do not include")]
    shift_deg: NotRequired[Annotated[float, Key("deg", "polygon: the shift whose clampings are the runs")]]


class ArcPeriod(TypedDict):
    """A periodic component of a partial arc (analysis/arc_periods.py)."""

    period_deg: Annotated[Num, Key("deg", "the period P")]
    u_period_deg: Annotated[Num, Key("deg", "its standard uncertainty (joint least squares)")]
    amplitude_arcsec: Annotated[Num, Key("arcsec", "amplitude A of A cos(2πθ/P − φ)")]
    u: Annotated[Num, Key("arcsec", "standard uncertainty of the amplitude")]
    phase_deg: Annotated[Num, Key("deg", "phase φ, θ from the table's 0°")]
    u_phase_deg: Annotated[Num, Key("deg", "its standard uncertainty")]
    false_alarm: Annotated[Num, Key("1", "probability that noise gives such a peak in the band (Baluev 2008)")]
    power: Annotated[Num, Key("1", "periodogram power (χ²_null − χ²_P)/χ²_null")]
    n_periods_covered: Annotated[Num, Key("1", "arc / P")]
    dof: Annotated[int | None, Key("", "degrees of freedom of the u's (residual; null when u is given)")]
    alias_periods_deg: Annotated[Floats, Key("deg", "periods that fit a regular grid equally well ([] otherwise)")]
    drive_element: Annotated[dict[str, Any], Key("", "source, within, matches [{name, period_deg, teeth?}], note: "
                                                     "the drive element the period points to")]


# ----------------------------------------------------------------------------------------------
# closing the loop
# ----------------------------------------------------------------------------------------------

class IdentifiedEffect(TypedDict, total=False):
    """An effect of the library the tracing identified (docs/effects.md, "Result of trace")."""

    name: Annotated[str, Key("", "effect name (analysis/effects)")]
    params: Annotated[dict[str, Num], Key("", "fitted parameters, unit in each name")]
    u: Annotated[dict[str, Num], Key("", "their standard uncertainties")]
    evidence: Annotated[dict[str, Any], Key("", "z, delta_bic, delta_aicc, cv_gain, chi2, dof, with, notes")]
    estimator: Annotated[dict[str, Any], Key("", "where its regressor is measured (δX, ∫δY, the tilt motion): the "
                                                 "consistent estimate's method, steps, converged, "
                                                 "objective_chi2 (and _selection), params_selection: the "
                                                 "selection's fit, attenuated by the regressor's noise; "
                                                 "adopted (false: implausible, why_not, "
                                                 "params_consistent; the selection's fit reported)")]


class Ambiguity(TypedDict, total=False):
    names: Annotated[list[str], Key("", "effects the data cannot tell apart")]
    separating_measurement: Annotated[str, Key("", "what would tell them apart")]


class CloseLoop(TypedDict, total=False):
    """The tracing's verdict (analysis/tracing/, docs/effects.md)."""

    status: Annotated[str, Key("", "identified / ambiguous / unexplained / no_significant_residual / ...")]
    signature: Annotated[dict[str, Any], Key("", "harmonics, drift, repetition, start face, shift, direction, "
                                                 "self-calibration, correlations (docs/effects.md)")]
    selection: Annotated[dict[str, Any], Key("", "by_bic, by_aicc, by_cv, agree, n_passed, cv_folds")]
    skipped: Annotated[dict[str, str], Key("", "candidate → why it was not tried")]
    thresholds: Annotated[dict[str, Num], Key("", "the thresholds used (analysis/tracing/thresholds.py)")]
    partial_effects: Annotated[list[dict[str, Any]], Key("", "the best candidate when not accepted")]
    unexplained_signature: Annotated[dict[str, Any] | None, Key("", "what is left when nothing explains it")]
    left: Annotated[list[str], Key("", "error curves: what a lone curve leaves")]


# ----------------------------------------------------------------------------------------------
# the files
# ----------------------------------------------------------------------------------------------

class _Common(TypedDict):
    format: Annotated[Literal["bench-results"], Key("", "file format")]
    version: Annotated[Literal[1], Key("", "format version")]
    dataset: Annotated[str, Key("", "the dataset analysed (path)")]
    source: Annotated[str, Key("", "the dataset's source: twin, emulator, bench, external, import")]
    bench: Annotated[Bench, Key("", "the manifest's bench block")]
    notes: Annotated[list[str], Key("", "assumptions and warnings of the analysis")]
    encoder_error_corrected_arcsec: NotRequired[Annotated[CorrectedCurve, Key("arcsec", "the curve a "
                                                                               "certificate states")]]
    identified_effects: NotRequired[Annotated[list[IdentifiedEffect], Key("", "close-loop: effects identified")]]
    ambiguous: NotRequired[Annotated[list[dict[str, Any]], Key("", "close-loop: ambiguity sets (names, "
                                                                   "separating_measurement, ...)")]]
    unexplained: NotRequired[Annotated[bool, Key("", "close-loop: a significant residual nothing explains")]]
    close_loop: NotRequired[Annotated[CloseLoop, Key("", "close-loop: the tracing's verdict")]]


class PolygonResults(TypedDict, total=False):
    """The shift-angle method and the multi-head self-calibration (Hsieh 2022; analysis/hsieh_pipeline.py)."""

    polygon_pitch_deviation_arcsec: Annotated[Floats, Key("arcsec", "pitch deviations β_k (Hsieh eqs. 5–6)")]
    polygon_pitch_deviation_u_arcsec: Annotated[Floats, Key("arcsec", "their u")]
    setup_error_arcsec: Annotated[dict[str, Floats], Key("arcsec", "setup errors U_j per shift (eq. 7)")]
    encoder_error_arcsec: Annotated[EncoderErrorCurve, Key("arcsec", "encoder error α(θ) (eq. 3)")]
    selfcal_error_arcsec: Annotated[dict[str, Any] | None, Key("arcsec", "multi-head self-calibration (eqs. 8–9): "
                                                                         "theta_deg (deg), value, u, ...; null "
                                                                         "with one head")]
    en_max: Annotated[Num, Key("1", "largest E_n of shift-angle vs self-calibration")]
    budget: Annotated[list[BudgetRow], Key("", "GUM budget (Hsieh Table 3)")]
    budget_summary: Annotated[BudgetSummary, Key("", "u_c, ν_eff, k, U")]
    difference_arcsec: Annotated[dict[str, Any] | None, Key("arcsec", "shift-angle − self-calibration (Hsieh "
                                                                      "fig. 12), null with one head")]
    repeatability: Annotated[dict[str, Any], Key("arcsec", "the readings' scatter: pooled_sd_eps_arcsec, "
                                                           "closure_residual_sd_arcsec (″), dof, n_reps, ...")]
    autocollimator_declared: Annotated[AutocollimatorDeclared, Key("", "the budget's autocollimator inputs")]
    budget_inputs: Annotated[dict[str, BudgetInput], Key("", "the budget's other type B inputs (Hsieh sec. 3.3 "
                                                             "(3), (5), (8)): ac_traceability_U_arcsec, "
                                                             "ac_traceability_k, setup_misalignment_arcsec, "
                                                             "encoder_resolution_arcsec")]


class BenchResults(_Common, PolygonResults, total=False):
    """results.json of a bench dataset (twin, emulator, bench): the Jia and Hsieh analyses and the loop."""

    radial_motion: Annotated[RadialMotionSection, Key("", "Jia sec. 4.1 (radial_motion.csv)")]
    radial_error_motion: Annotated[RadialErrorMotion, Key("", "ISO 230-7 values")]
    eccentricity_um: Annotated[Num, Key("µm", "installation eccentricity e (Jia eq. 11)")]
    eccentricity_u_um: Annotated[Num, Key("µm", "its standard uncertainty (fit and async motion)")]
    eccentricity_phase_deg: Annotated[Num, Key("deg", "its phase θ0 (Jia eq. 12)")]
    eccentricity_phase_u_deg: Annotated[Num, Key("deg", "u(θ0)")]
    eccentricity_u_fit_um: Annotated[Num, Key("µm", "u(e) from the eq. 10 fit alone")]
    eccentricity_phase_u_fit_deg: Annotated[Num, Key("deg", "u(θ0) from the fit alone")]
    eccentricity_u_async_um: Annotated[float | None, Key("µm", "the async motion's part of u(e), null without probes")]
    eccentricity_u_source: Annotated[str, Key("", "where u(e) comes from and what it includes: one sweep's fit ⊕ "
                                                 "the probes' async part (type B); the fit alone, saying the async "
                                                 "part is not in u, when the radial run has one revolution; or type "
                                                 "A from repeated sweeps. e is about the axis of rotation: a "
                                                 "synchronous first harmonic of the axis is part of e, not of u "
                                                 "(docs/scoring.md)")]
    eccentricity_sweeps: Annotated[dict[str, Any], Key("µm", "repeated CCD sweeps: n_sweeps, dof, e_sweeps_um, "
                                                             "theta0_sweeps_deg, e_sweep_sd_um (s of one sweep), "
                                                             "e_range_u_um (Jia's range/d_n), ...")]
    ccd: Annotated[CCDSection, Key("", "the CCD sweep")]
    ccd_rejected_frames: Annotated[list[RejectedFrame], Key("", "frames the image analysis dropped")]
    model_file_terms: Annotated[list[str], Key("", "analyze --model: terms added from the model file")]
    model_prediction_arcsec: Annotated[ModelPrediction, Key("arcsec", "the Jia model (eq. 5) on a 1° grid")]
    residual_before: Annotated[ResidualSummary, Key("", "measured − Jia model")]
    comparison: Annotated[Comparison, Key("", "measured and model at the polygon angles")]
    residual_test: Annotated[TraceResidual, Key("", "close-loop: is there anything to explain?")]
    residual_after_trace: Annotated[TraceResidual, Key("", "close-loop: after the traced effects")]
    eccentricity_refined: Annotated[dict[str, Any], Key("µm", "close-loop: (e, θ0) of the model after the loop, "
                                                              "the CCD's combined with the comparison's first "
                                                              "harmonic (GLS), its u including the confounding "
                                                              "with a first-order graduation term (k1_prior: "
                                                              "u_arcsec, u_um, source; k1_arcsec: a1, b1 and u): "
                                                              "e_um, u_e_um, theta0_deg (deg), u_theta0_deg, "
                                                              "cov_e_theta0 (µm·deg), comparison, ccd, chi2, dof, "
                                                              "p_value (their consistency), refitted_params, "
                                                              "column_params, residual_after_ccd_e_pv_arcsec (the "
                                                              "P-V after with the CCD's own e, θ0 and the traced "
                                                              "parameters)")]
    residual_after: Annotated[ResidualSummary, Key("", "close-loop: measured − (model + traced effects), (e, θ0) "
                                                       "refined (eccentricity_refined)")]
    comparison_after: Annotated[Comparison, Key("", "close-loop: the same after the traced effects")]
    iso230_2: Annotated[Iso230_2, Key("", "ISO 230-2 positioning statistics (polygon runs in both directions)")]


class ErrorCurveResults(_Common):
    """results.json of an "error curve" dataset (an imported table; analysis/error_curve.py)."""

    kind: Annotated[Literal["error-curve"], Key("", "the dataset kind")]
    imported_from: Annotated[dict[str, Any] | None, Key("", "the manifest's import block (table, columns, unit)")]
    coverage_deg: Annotated[Num, Key("deg", "360 for a full turn, else the arc")]
    coverage: Annotated[dict[str, Any], Key("deg", "full_turn, n_angles, step_deg, max_gap_deg, start_deg, end_deg")]
    closure: Annotated[dict[str, Any], Key("arcsec", "state, mean_arcsec, u_mean_arcsec, closed, applied; "
                                                     "state and reason on an arc")]
    hysteresis: Annotated[dict[str, Any] | None, Key("arcsec", "both directions: half differences, mean, u, RMS, "
                                                               "significance; null with one")]
    u_point: Annotated[dict[str, Any], Key("arcsec", "u_arcsec, source, dof")]
    harmonics: Annotated[list[dict[str, Any]], Key("arcsec", "k, amplitude_arcsec, u_arcsec, phase_deg, "
                                                             "u_phase_deg, a_arcsec, b_arcsec, chi2, p_value, "
                                                             "significant; [] on an arc")]
    error_curve: Annotated[dict[str, Any], Key("", "everything of analysis/error_curve.py")]
    encoder_error_arcsec: Annotated[Curve, Key("arcsec", "the mean curve")]
    arc_periods: NotRequired[Annotated[list[ArcPeriod], Key("", "an arc: the significant periodic components "
                                                                "([] for none)")]]
    arc_period_scan: NotRequired[Annotated[dict[str, Any], Key("", "an arc: the period scan (method, false-alarm "
                                                                   "method, band, best rejected peak, periodogram)")]]
    iso230_2: NotRequired[Annotated[Iso230_2, Key("", "ISO 230-2 positioning statistics (both directions)")]]


# ----------------------------------------------------------------------------------------------
# validation
# ----------------------------------------------------------------------------------------------

@functools.cache
def _hints(td: Any) -> dict[str, Any]:
    return typing.get_type_hints(td, include_extras=True)


def _strip(tp: Any) -> tuple[Any, Key | None]:
    """(type without Annotated / NotRequired, its Key); a nullable number is ``float | None``."""
    key = None
    nullable = False
    while True:
        origin = typing.get_origin(tp)
        if origin is Annotated:
            key = next((m for m in tp.__metadata__ if isinstance(m, Key)), key)
            nullable = nullable or any(m is NULLABLE for m in tp.__metadata__)
            tp = tp.__origin__
        elif origin in (NotRequired, typing.Required):
            tp = typing.get_args(tp)[0]
        else:
            return (float | None if nullable and tp is float else tp), key


def _is_typeddict(tp: Any) -> bool:
    return isinstance(tp, type) and issubclass(tp, dict) and hasattr(tp, "__required_keys__")


def _describe(tp: Any) -> str:
    tp, _ = _strip(tp)
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is Any:
        return "any value"
    if tp is np.ndarray:
        return "a list of numbers"
    if tp is type(None):
        return "null"
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is str:
        return "a string"
    if tp is bool:
        return "true or false"
    if origin is Literal:
        return " or ".join(repr(a) for a in args)
    if origin in (Union, types.UnionType):
        return " or ".join(_describe(a) for a in args if a is not np.ndarray)  # an array is the list in memory
    if origin is list:
        return f"a list of {_plural(args[0])}" if args else "a list"
    if origin is dict or tp is dict:
        return f"an object of {_plural(args[1])}" if args else "an object"
    if _is_typeddict(tp):
        return f"an object ({tp.__name__})"
    return str(tp)


def _plural(tp: Any) -> str:
    """The elements' type in the plural: "numbers (or null)", "BudgetRow objects", "lists of strings"."""
    t_, _ = _strip(tp)
    origin, args = typing.get_origin(t_), typing.get_args(t_)
    if _is_typeddict(t_):
        return f"{t_.__name__} objects"
    if origin in (Union, types.UnionType):
        parts = [a for a in args if a is not type(None) and a is not np.ndarray]
        base = " or ".join(_plural(a) for a in parts)
        return base + " (or null)" if type(None) in args else base
    simple = {Any: "values", float: "numbers", int: "integers", str: "strings", bool: "booleans"}
    if t_ in simple:
        return simple[t_]
    if origin is list:
        return f"lists of {_plural(args[0])}" if args else "lists"
    if origin is dict or t_ is dict:
        return f"objects of {_plural(args[1])}" if args else "objects"
    return _describe(t_)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _check(v: Any, tp: Any, at: str, where: str) -> None:
    tp, key = _strip(tp)
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    unit = f" ({key.unit})" if key is not None and key.unit not in ("", "1") else ""

    def fail() -> typing.NoReturn:
        got = repr(v)
        got = got if len(got) <= 60 else got[:59] + "…"
        raise ResultsError(f"{where}: key {at!r}: expected {_describe(tp)}{unit}, got {got}")

    if tp is Any:
        return
    if tp is np.ndarray:  # in memory only (analyze()'s object): a 1-D array of numbers
        if not (isinstance(v, np.ndarray) and v.ndim == 1 and v.dtype.kind in "fiu"):
            fail()
        return
    if tp is type(None):
        if v is not None:
            fail()
        return
    if origin in (Union, types.UnionType):
        for a in args:
            try:
                _check(v, a, at, where)
                return
            except ResultsError:
                continue
        fail()
    if tp is float:
        if not _is_number(v):
            fail()
        return
    if tp is int:
        if not (isinstance(v, int) and not isinstance(v, bool)):
            fail()
        return
    if tp is str or tp is bool:
        if not isinstance(v, tp):
            fail()
        return
    if origin is Literal:
        if v not in args or isinstance(v, bool) != any(isinstance(a, bool) for a in args):
            fail()
        return
    if origin is list:
        if not isinstance(v, list):
            fail()
        for i, x in enumerate(v):
            _check(x, args[0], f"{at}[{i}]", where)
        return
    if origin is dict or tp is dict:
        if not isinstance(v, dict):
            fail()
        for k, x in v.items():
            if not isinstance(k, str):
                fail()
            if args:
                _check(x, args[1], f"{at}.{k}", where)
        return
    if _is_typeddict(tp):
        if not isinstance(v, dict):
            fail()
        hints = _hints(tp)
        for k in sorted(tp.__required_keys__):
            if k not in v:
                t_, key_ = _strip(hints[k])
                u_ = f" ({key_.unit})" if key_ is not None and key_.unit not in ("", "1") else ""
                raise ResultsError(f"{where}: key {_join(at, k)!r} is missing: expected {_describe(t_)}{u_}")
        for k, x in v.items():
            if k in hints:
                _check(x, hints[k], _join(at, k), where)
        return
    raise TypeError(f"results schema: unsupported type {tp!r} at {at}")  # pragma: no cover - schema bug


def _join(at: str, k: str) -> str:
    return f"{at}.{k}" if at else k


def validate_results(obj: Any, where: str = "results.json") -> dict[str, Any]:
    """Check a parsed results.json against this format; returns it (raises :class:`ResultsError`,
    naming ``where``, the key and what was expected). Keys not described here are allowed (a newer
    writer may add some); every described key present must have its type."""
    if not isinstance(obj, dict):
        raise ResultsError(f"{where}: expected a JSON object (results.json of analyze / close-loop)")
    if obj.get("format") != FORMAT:
        raise ResultsError(f"{where}: key 'format': expected {FORMAT!r}, got {obj.get('format')!r}")
    if obj.get("version") != VERSION or isinstance(obj.get("version"), bool):
        raise ResultsError(f"{where}: key 'version': expected {VERSION}, got {obj.get('version')!r}")
    if "kind" in obj and obj["kind"] != "error-curve":
        raise ResultsError(f"{where}: key 'kind': expected 'error-curve' (an imported curve) or no kind (a bench "
                           f"dataset), got {obj['kind']!r}")
    _check(obj, ErrorCurveResults if obj.get("kind") == "error-curve" else BenchResults, "", where)
    return obj


def read_results_text(path: str | Path) -> str:
    """A results file's text, read as every input is (benchtwin.schema: a regular file, bounded
    size, UTF-8); a ResultsError names the file."""
    from benchtwin.schema import SchemaError, read_input_text

    try:
        return read_input_text(Path(path), max_bytes=MAX_RESULTS_BYTES, what="results file")
    except SchemaError as exc:
        raise ResultsError(str(exc)) from None


def parse_results(text: str, where: str = "results.json") -> dict[str, Any]:
    """A results.json's text parsed (strict JSON: no NaN/Infinity, no key twice, bounded depth) and
    checked by this format (:func:`validate_results`); a ResultsError names ``where`` and the key."""
    from benchtwin.schema import SchemaError, loads_json

    try:
        obj = loads_json(text, where)
    except SchemaError as exc:
        raise ResultsError(str(exc)) from None
    return validate_results(obj, where)


def read_results(path: str | Path) -> dict[str, Any]:
    """Read and check a results.json (strict JSON: no NaN/Infinity, bounded size and depth): the one
    reader of the format (``Results.read`` gives it typed; score, certificate, compare and
    calibrate-twin read results.json through it)."""
    return parse_results(read_results_text(path), str(Path(path)))


# ----------------------------------------------------------------------------------------------
# documentation
# ----------------------------------------------------------------------------------------------

def _rows(td: Any, prefix: str, out: list[str], seen: set[str]) -> None:
    hints = _hints(td)
    for k, tp in hints.items():
        t_, key = _strip(tp)
        req = "yes" if k in td.__required_keys__ else "no"
        name = f"{prefix}{k}"
        unit = key.unit if key is not None and key.unit else "–"
        doc = key.doc if key is not None else ""
        out.append(f"| `{name}` | {_describe(t_)} | {unit} | {req} | {doc} |")
        inner = t_
        if typing.get_origin(inner) is list and _is_typeddict(typing.get_args(inner)[0]):
            inner, name = typing.get_args(inner)[0], name + "[]"
        elif typing.get_origin(inner) is dict and _is_typeddict(typing.get_args(inner)[1]):
            inner, name = typing.get_args(inner)[1], name + ".<name>"
        if _is_typeddict(inner) and name not in seen:
            seen.add(name)
            _rows(inner, name + ".", out, seen)


def results_format_markdown() -> str:
    """docs/results-format.md, generated from the annotations above (the page and the validator
    cannot drift apart)."""
    head = __doc__.split("\n\nSources:")[0].split("\n", 1)[1].strip()
    out = ["# results.json (format \"bench-results\", version 1)", "",
           "Generated from `analysis/results.py` (`results_format_markdown()`); do not edit by hand. "
           "Check a file with `benchtwin validate RESULTS.json` (exit 2 names the key and what was expected).",
           "", head, "",
           "Columns: the key (dotted below its section; `[]` = each element of a list, `<name>` = each entry of "
           "an object), the JSON type, the unit "
           "(– none; 1 = dimensionless; ″ = arcsec), whether the key is always present, and its meaning.", ""]
    for title, td in (("Bench datasets (twin, emulator, bench)", BenchResults),
                      ("Error-curve datasets (`benchtwin import`)", ErrorCurveResults)):
        out += [f"## {title}", "", "| key | type | unit | required | meaning |", "| --- | --- | --- | --- | --- |"]
        _rows(td, "", out, set())
        out.append("")
    return "\n".join(out)
