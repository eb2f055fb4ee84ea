"""The pipeline's typed step outputs (analysis/steps.py, issue 16 item 5): attributes, not string keys.

The steps return frozen dataclasses; pipeline.py reads their attributes (mypy checks them) and each
object writes its results.json section with one ``to_json()``. A string-key read of a step output in
pipeline.py (``ecc["e_um"]``) would fail at run time on these objects, and this test names it before.
"""

from __future__ import annotations

import ast
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from benchtwin.analysis.eccentricity import eccentricity_from_dref
from benchtwin.analysis.radial_motion import ProbeReadings, RadialOptions, SphereSpacing, radial_motion
from benchtwin.analysis.results import _check, CCDSection, RadialMotionSection
from benchtwin.analysis.steps import EccentricityResult, PolygonAnalysis, RadialMotionResult, TraceOutcome

ROOT = Path(__file__).resolve().parents[2]
#: the names pipeline.py gives the step outputs (analyze, _close_loop, _write_report)
STEP_NAMES = {"rm", "ecc", "pol", "tr"}


def test_pipeline_reads_no_step_output_by_string_key():
    tree = ast.parse((ROOT / "analysis" / "pipeline.py").read_text(encoding="utf-8"))
    hits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id in STEP_NAMES \
                and isinstance(node.slice, ast.Constant) and isinstance(node.slice.value, str):
            hits.append(f"line {node.lineno}: {ast.unparse(node)}")
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get" \
                and isinstance(node.func.value, ast.Name) and node.func.value.id in STEP_NAMES:
            hits.append(f"line {node.lineno}: {ast.unparse(node)}")
    # the error-curve report's local `tr` is its trend dict (analysis/error_curve.py), not a step output
    hits = [h for h in hits if "slope_arcsec_per_deg" not in h and "u_slope" not in h]
    assert not hits, hits


@pytest.mark.parametrize("cls", [RadialMotionResult, EccentricityResult, PolygonAnalysis, TraceOutcome])
def test_step_outputs_are_frozen_and_name_their_units(cls):
    assert dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen
    # a value with a unit carries it in its name (principle 4); counts, flags, texts and the nested
    # sections (typed by analysis/results.py) do not have one
    unitless = {"n_reps", "frames", "summary", "detail", "iso230_7",
                "beta_source", "budget", "budget_summary", "repeatability", "autocollimator_declared",
                "budget_inputs", "notes", "en_max", "status", "identified_effects", "partial_effects", "ambiguous",
                "unexplained", "residual_before", "residual_after", "reference_corrections", "model_file",
                "selfcal_error_arcsec", "difference_arcsec", "setup_error_start_faces", "d_n", "u_h1_async_dof",
                "u_source", "sweeps", "probe_drift", "readings"}
    units = ("_um", "_deg", "_arcsec", "_urad", "_px")
    bad = [f.name for f in dataclasses.fields(cls) if f.name not in unitless and not f.name.endswith(units)]
    assert not bad, bad


def _sweep(rng):
    th = np.arange(0.0, 360.0, 12.0)
    d = 100.0 + 7.0 * np.sin(np.deg2rad(th - 30.0)) + rng.normal(0, 0.02, th.size)
    return th, d


def test_eccentricity_result_reads_the_step_dict_and_adds_the_async_motion():
    rng = np.random.default_rng(3)
    th, d = _sweep(rng)
    raw = eccentricity_from_dref(th, d, order=3)
    raw.update(pixel_um=0.5, radius_fixed_px=None, theta_deg=list(th), d_ref_um=d, files=[f"f{i}" for i in th],
               n_frames=th.size, rejected_frames=[], frame_limits={"min_frames": 10, "by_fit": 10, "by_fraction": 23})
    e = EccentricityResult.from_eccentricity(raw)
    assert e.e_um == raw["e_um"] and e.u_e_um == raw["e_u_um"] and e.theta0_deg == raw["theta0_deg"]
    assert e.u_e_fit_um == e.u_e_um and e.u_e_async_um is None and e.frames.min_frames == 10
    with pytest.raises(dataclasses.FrozenInstanceError):
        e.e_um = 0.0  # type: ignore[misc]
    a = e.with_async_motion(0.04, 4)
    assert a.u_e_fit_um == e.u_e_um and a.u_e_async_um == 0.04
    assert math.isclose(a.u_e_um, math.hypot(e.u_e_um, 0.04))
    j = a.to_json()
    assert j["eccentricity_u_um"] == a.u_e_um and j["eccentricity_u_async_um"] == 0.04
    _check(j["ccd"], CCDSection, "ccd", "test")  # the section results.py documents
    assert j["ccd"]["n_images"] == th.size


def test_radial_motion_result_section_is_the_documented_one():
    rng = np.random.default_rng(4)
    th = np.tile(np.arange(0.0, 360.0, 10.0), 3)
    rep = np.repeat([1, 2, 3], 36)
    top = 0.1 * np.sin(np.deg2rad(3 * th)) + rng.normal(0, 0.005, th.size)
    bot = 0.05 * np.cos(np.deg2rad(2 * th)) + rng.normal(0, 0.005, th.size)
    raw = radial_motion(ProbeReadings(rep, th, top, bot), SphereSpacing(50.0, 150.0), RadialOptions(order=5))
    r = RadialMotionResult.from_radial_motion(raw, {"locations": []})
    assert r.n_reps == 3 and r.dY_um is raw["dY_um"] and r.u_h1_async_um == raw["u_h1_async_um"]
    sec = r.to_json()
    _check({k: (list(v) if isinstance(v, np.ndarray) else v) for k, v in sec.items()}, RadialMotionSection,
           "radial_motion", "test")
