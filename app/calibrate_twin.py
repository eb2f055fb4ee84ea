"""The twin learns the bench (issue 16, item 3): a measured dataset -> a scenario whose twin
reproduces it.

This is the digital twin's own loop (Jia et al. 2019 sec. 5-6; ISO 230-7:2015 sec. 3; GUM JCGM
100:2008 for the uncertainties written beside each value): the analysis measures the bench
(eccentricity from the CCD, Jia eqs. 10-13; radial error motion from the two test spheres, eqs.
6-9; the residual traced to effects by close-loop, docs/effects.md), and every measured quantity
is written back into the twin's scenario as the PHYSICAL cause the twin simulates — never as the
analysis's template (principle 1):

- ``errors.eccentricity`` / ``errors.theta0``: the CCD result (results.json ``eccentricity_um``,
  ``eccentricity_phase_deg`` and their u). It contains the bearings' once-per-turn run-out at the
  disk plane (the CCD and the head see both alike), which is why the motion table below carries
  harmonics 2...order only.
- ``[motion_table]``: the synchronous radial error motion of the disk plane, replayed by the twin
  (twin/physics.py converts it to the rolling-path offsets of both bearings, so gravity and the
  drive still act physically): δY and the tilt ε_X from the Y probes (Jia eqs. 8-9), δX and ε_Y
  from the X probes when present (otherwise δX is not observable and is 0, unless the traced
  ``tangential_motion`` says how the axis whirls). ``bearings.type`` becomes "path" (the table
  replaces the ball sets' motion) and ``bearings.async_rms`` the measured asynchronous motion
  (the repetitions' scatter, per bearing and axis, ISO 230-7 sec. 3.3).
- each identified effect of close-loop becomes the twin's cause (see ``_EFFECTS``): disk
  graduation harmonics ([hidden.graduation_error], α = +E(g) with g = 90° − θ for head 1 on +Y,
  twin/instruments/encoder_head.py), the autocollimator's scale and non-linearity
  ([hidden.ac_scale]) and zero drift ([hidden.ac_drift]), the bearing friction torque that twists
  the shaft (``bearings.friction_torque`` = half-hysteresis × shaft torsional stiffness), the
  heads' true radius ([hidden.optical_radius]), the spheres' true height ([hidden.tilt_abbe]),
  the grating period at the scale edge ([hidden.ccd_pixel_scale]), the head's interpolation error
  ([hidden.interpolation_error]). ``[hidden]`` here means what the twin simulates without
  declaring it in the dataset: the analysis of the calibrated twin has to find it again.

Every fitted value is written with a TOML comment giving its standard uncertainty and the data it
came from. What one dataset cannot teach (the disk's per-line division error between the polygon's
faces, δX without X probes, the polygon's and the ball sets' seeded details) is listed in the
file's header and in docs/calibrate-twin.md; those values stay the base scenario's.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.analysis.radial_motion import disk_weights
from benchtwin.analysis.results import ResultsError
from benchtwin.analysis.results_api import Results
from benchtwin.schema import dumps_toml as dump_toml  # the one TOML writer
from benchtwin.units import ARCSEC_PER_RAD

__all__ = ["CalibrationInputError", "calibrate_twin", "learn", "dump_toml"]


class CalibrationInputError(ValueError):
    """A dataset, results file or base scenario calibrate-twin cannot use (exit 2)."""


# ----------------------------------------------------------------------------- inputs

def _read_results(path: Path) -> Results:
    """results.json read and checked by the format's one reader (``Results.read``,
    analysis.results.read_results): its error names the file and the key (exit 2)."""
    try:
        return Results.read(path)
    except ResultsError as exc:
        raise CalibrationInputError(str(exc)) from None


def _need(res: Mapping[str, Any], key: str, where: Path) -> Any:
    v = res.get(key)
    if v is None:
        raise CalibrationInputError(f"{where}: key {key!r} missing; calibrate-twin needs a bench dataset "
                                    "analysed with its CCD images (analyze / close-loop)")
    return v


def locate(path: Path, results: Path | None = None) -> tuple[Path, Path | None]:
    """(dataset folder, results.json or None). PATH is a dataset folder (with manifest.json) or
    the output folder of analyze / close-loop / run (with results.json naming its dataset). A
    results.json beside the dataset (a `run` folder: OUT/dataset and OUT/results.json) is used."""
    path = Path(path)
    if not path.is_dir():
        raise CalibrationInputError(f"{path}: no such dataset or results folder")
    if results is not None:
        return path, Path(results)
    if (path / "manifest.json").is_file():
        for cand in (path / "results.json", path.parent / "results.json"):
            if cand.is_file():
                try:
                    ds = Results.read(cand).get("dataset")
                except ResultsError:
                    continue  # not a results file of this dataset's: look further, or analyse it afresh
                if ds and Path(ds).resolve() == path.resolve():
                    return path, cand
        return path, None
    if (path / "results.json").is_file():
        res = _read_results(path / "results.json")
        ds = res.get("dataset")
        if not ds or not (Path(ds) / "manifest.json").is_file():
            raise CalibrationInputError(f"{path / 'results.json'}: key 'dataset' = {ds!r} is not a dataset folder")
        return Path(ds), path / "results.json"
    raise CalibrationInputError(f"{path}: neither a dataset (manifest.json) nor a results folder (results.json)")


def analysed(dataset: Path, results: Path | None, workdir: Path, progress: bool = False) -> Results:
    """results.json of the dataset: the given one, or close-loop run into ``workdir``."""
    if results is not None:
        return _read_results(results)
    from benchtwin.analysis.pipeline import analyze

    return analyze(dataset, workdir / "analysis", progress=progress, close_loop=True)["results"]


def _q(v: float, unit: str, sig: int = 6) -> str:
    """A quantity string with a unit, as the scenario format wants it (docs/scenario-format.md)."""
    return f"{float(v):.{sig}g} {unit}"


# ----------------------------------------------------------------------------- base scenario

def _manifest_overrides(raw: dict[str, Any], manifest: dict[str, Any], comments: dict) -> None:
    """Without --base: the embedded default with the dataset's declared bench (manifest.json)."""
    b = manifest.get("bench", {})
    src = "from the dataset's manifest.json"
    bench = raw.setdefault("bench", {})
    for key, mkey, unit in (("optical_radius", "optical_radius_mm", "mm"), ("scale_edge_radius", "scale_edge_radius_mm", "mm"),
                            ("grating_period", "grating_period_um", "um"), ("encoder_resolution", "encoder_resolution_arcsec", "arcsec"),
                            ("L1", "L1_mm", "mm"), ("L2", "L2_mm", "mm")):
        if mkey in b:
            bench[key] = _q(b[mkey], unit, 9)
            comments[("bench", key)] = src
    for key, mkey in (("encoder_lines", "encoder_lines"), ("polygon_faces", "polygon_faces")):
        if mkey in b:
            bench[key] = int(b[mkey])
            comments[("bench", key)] = src
    if "heads_deg" in b:
        bench["heads"] = [_q(h, "deg", 9) for h in b["heads_deg"]]
        comments[("bench", "heads")] = src
    ccd = manifest.get("ccd", {})
    if "position_deg" in ccd:
        bench["ccd_position"] = _q(ccd["position_deg"], "deg", 9)
        comments[("bench", "ccd_position")] = src
    ac = raw.setdefault("instruments", {}).setdefault("autocollimator", {})
    for key, mkey in (("resolution", "autocollimator_resolution_arcsec"), ("accuracy", "autocollimator_accuracy_arcsec")):
        if mkey in b:
            ac[key] = _q(b[mkey], "arcsec")
            comments[("instruments.autocollimator", key)] = src


def _procedure_from_dataset(raw: dict[str, Any], ds: Any, comments: dict) -> None:
    """The measured procedure (positions, repetitions, CCD step, shifts, X probes), so that the
    calibrated twin runs what the bench ran."""
    proc = raw.setdefault("procedure", {})
    src = "as measured (dataset tables)"
    if ds.has("radial_motion"):
        t = ds.table("radial_motion")
        reps = np.unique(t["rep"])
        proc["radial_reps"] = int(reps.size)
        proc["radial_positions"] = int(np.unique(np.round(np.asarray(t["theta_deg"])[t["rep"] == reps[0]] % 360, 6)).size)
        comments[("procedure", "radial_reps")] = comments[("procedure", "radial_positions")] = src
        x = t.get("probe_top_x_um") is not None
        raw.setdefault("instruments", {}).setdefault("probe", {})["x_probes"] = bool(x)
        comments[("instruments.probe", "x_probes")] = src
    if ds.has("polygon"):
        t = ds.table("polygon")
        shifts = sorted({round(float(s), 9) for s in t["shift_deg"]})
        proc["polygon_shifts"] = [_q(s, "deg", 9) for s in shifts]
        comments[("procedure", "polygon_shifts")] = src


# ----------------------------------------------------------------------------- the learning

def _radial(ds: Any, order: int) -> dict[str, Any] | None:
    if not ds.has("radial_motion"):
        return None
    from benchtwin.analysis.radial_motion import ProbeReadings, RadialOptions, SphereSpacing, radial_motion

    t = ds.table("radial_motion")
    b = ds.bench
    return radial_motion(ProbeReadings.from_table(t), SphereSpacing(b["L1_mm"], b["L2_mm"]), RadialOptions(order=order))


def _quadrature_on_grid(theta_deg: np.ndarray, y: np.ndarray, order: int) -> np.ndarray:
    """H[y]: each harmonic a sin kθ + b cos kθ shifted a quarter period (b sin kθ − a cos kθ), the
    convention of analysis/effects/_base.quadrature, which the tangential-motion basis uses."""
    from benchtwin.analysis.fourier import design_matrix

    A = design_matrix(theta_deg, order)
    p = np.linalg.lstsq(A, y, rcond=None)[0]
    q = np.zeros_like(p)
    for k in range(1, order + 1):
        a, b = p[2 * k - 1], p[2 * k]
        q[2 * k - 1], q[2 * k] = b, -a
    return A @ q


#: a harmonic of the measured motion is replayed when its (a, b) differ from 0 at this level
#: (χ² with 2 dof against the fit covariance: the probes' noise), so noise is not written into the
#: twin. 0.999: about 36 harmonics are tested (9 orders × up to 4 channels), so the family-wise
#: false-positive rate stays ≈ 4 % (Bonferroni); at 0.99 a null bench got a 0.03 µm δX lobe (0.26″)
SIGNIFICANCE_P = 0.999


def _significant_series(fa: list, fb: list, wa: float, wb: float, order: int) -> tuple[np.ndarray, list[int]]:
    """Fourier parameters (design_matrix order) of wa·a + wb·b, mean over the revolutions, with
    only the significant harmonics 2…order kept; and the kept orders."""
    from benchtwin.analysis.distributions import chi2_isf

    n = len(fa)
    p = sum(wa * x.params + wb * y.params for x, y in zip(fa, fb)) / n
    cov = sum(wa ** 2 * x.cov + wb ** 2 * y.cov for x, y in zip(fa, fb)) / n ** 2
    crit = float(chi2_isf(1.0 - SIGNIFICANCE_P, 2))
    keep = np.zeros_like(p)
    kept: list[int] = []
    for k in range(2, order + 1):
        i = [2 * k - 1, 2 * k]
        c = cov[np.ix_(i, i)]
        v = p[i]
        try:
            z2 = float(v @ np.linalg.solve(c, v))
        except np.linalg.LinAlgError:
            z2 = float("inf")
        if not np.all(np.isfinite(c)) or z2 > crit:
            keep[i] = 1.0
            kept.append(k)
    return p * keep, kept


def _significant_curve(theta_deg: np.ndarray, fa: list, fb: list, wa: float, wb: float, order: int) -> tuple[
        np.ndarray, list[int]]:
    """wa·(series a) + wb·(series b), mean over the revolutions, harmonics 2…order kept only where
    significant; returns (curve on theta_deg, kept orders)."""
    from benchtwin.analysis.fourier import design_matrix

    p, kept = _significant_series(fa, fb, wa, wb, order)
    return design_matrix(theta_deg, order) @ p, kept


def _form_lobes(eff: dict[str, Any], sphere: str, fits: list | None = None) -> dict[int, tuple[float, float]]:
    """{k: (sin, cos) µm} of a traced sphere form in that sphere's Y reading (analysis/effects/
    sphere_form.py: explicit lobes, or ``form_fraction`` × the reading's own lobes 2…10, or the
    lobes as the X probe reads them, a quarter turn before the Y probe: Y(θ) = X(θ − 90°))."""
    p = eff["params"]
    out: dict[int, tuple[float, float]] = {}
    for name in p:
        if name.startswith(f"{sphere}_h") and name.endswith("_sin_um"):
            k = int(name[len(sphere) + 2:-len("_sin_um")])
            out[k] = (float(p[name]), float(p.get(f"{sphere}_h{k}_cos_um", 0.0)))
    for name in p:
        if name.startswith(f"{sphere}_x_h") and name.endswith("_sin_um"):
            k = int(name[len(sphere) + 4:-len("_sin_um")])
            ax, bx = float(p[name]), float(p.get(f"{sphere}_x_h{k}_cos_um", 0.0))
            c, s = math.cos(math.radians(90.0 * k)), math.sin(math.radians(90.0 * k))
            a0, b0 = out.get(k, (0.0, 0.0))
            out[k] = (a0 + ax * c + bx * s, b0 - ax * s + bx * c)
    fr = float(p.get("form_fraction", 0.0))
    if fr and fits:
        m = sum(x.params for x in fits) / len(fits)
        for k in range(2, (m.size - 1) // 2 + 1):
            a, b = out.get(k, (0.0, 0.0))
            out[k] = (a + fr * float(m[2 * k - 1]), b + fr * float(m[2 * k]))
    return out


def _form_curve(theta_deg: np.ndarray, eff: dict[str, Any], sphere: str, fits: list) -> np.ndarray:
    th = np.radians(theta_deg)
    return sum((a * np.sin(k * th) + b * np.cos(k * th) for k, (a, b) in _form_lobes(eff, sphere, fits).items()),
               np.zeros_like(th))


def _eff_u(e: dict[str, Any], name: str) -> float:
    return float((e.get("u") or {}).get(name, float("nan")))


@dataclass
class _Learning:
    """What ``learn``'s stages share: the comments written beside the keys, the notes, the effects
    close-loop identified (by name), the radial-motion fits (None without radial_motion.csv) and the
    replayed δX's Fourier parameters (design_matrix order; None: no δX replayed)."""

    comments: dict[tuple[str, str], str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    identified: dict[str, Any] = field(default_factory=dict)
    rm: dict[str, Any] | None = None
    dx_params: np.ndarray | None = None


@dataclass(frozen=True)
class _TwinMotion:
    """What the calibrated twin will itself produce on the encoder: the fitted eccentricity (µm) and
    its phase (deg), on the optical radius (mm), and the replayed δX (Fourier parameters in µm, at
    harmonics up to ``order``; None: no δX)."""

    eccentricity_um: float
    theta0_deg: float
    optical_radius_mm: float
    dx_params_um: np.ndarray | None
    order: int


def learn(ds: Any, res: Mapping[str, Any], raw: dict[str, Any], where: Path, order: int = 10) -> tuple[
        dict[str, Any], dict[tuple[str, str], str], list[str]]:
    """The measured bench into the scenario ``raw`` (edited in place): returns (raw, comments
    {(section, key): text}, notes). ``res`` is the results.json of the dataset ``ds``."""
    lr = _Learning(identified={x["name"]: x for x in res.get("identified_effects") or []})
    e_true, ph = _learn_eccentricity(res, raw, where, lr)
    _learn_radial(ds, res, raw, order, lr)
    # --- identified effects as physical causes
    if "graduation_error" in lr.identified:
        motion = _TwinMotion(e_true, ph, float(ds.bench["optical_radius_mm"]), lr.dx_params, order)
        lr.identified["graduation_error"] = _division_error_for_twin(lr.identified["graduation_error"], res, motion,
                                                                     lr.notes)
    _learn_effects(res, raw, lr)
    return raw, lr.comments, lr.notes


def _learn_eccentricity(res: Mapping[str, Any], raw: dict[str, Any], where: Path, lr: _Learning) -> tuple[float, float]:
    """Eccentricity (Jia eqs. 10-13, CCD) into [errors]: returns (e in µm, × (1 + s) of a traced
    ccd_pixel_scale; its phase in deg as results.json gives it)."""
    rj = "results.json"
    e = float(_need(res, "eccentricity_um", where))
    ue = float(res.get("eccentricity_u_um", float("nan")))
    ph = float(_need(res, "eccentricity_phase_deg", where))
    uph = float(res.get("eccentricity_phase_u_deg", float("nan")))
    n_img = int((res.get("ccd") or {}).get("n_images", 0))
    err = raw.setdefault("errors", {})
    if "ccd_pixel_scale" in lr.identified:
        # the period at the scale edge differs from the datasheet by s: the measured e is e_true/(1 + s)
        s = float(lr.identified["ccd_pixel_scale"]["params"]["scale_error_pct"]) / 100.0
        e_true = e * (1.0 + s)
        lr.notes.append(f"ccd_pixel_scale: e corrected by (1 + s) = {1 + s:.6f} (grating period error at the scale edge)")
    else:
        e_true = e
    err["eccentricity"] = _q(e_true, "um")
    lr.comments[("errors", "eccentricity")] = (f"u = {ue:.2g} um, from {n_img} CCD frames ({rj} eccentricity_um"
                                               f"{', × (1 + s) of ccd_pixel_scale' if e_true != e else ''})")
    err["theta0"] = _q(ph % 360.0, "deg")
    lr.comments[("errors", "theta0")] = f"u = {uph:.2g} deg, from {n_img} CCD frames ({rj} eccentricity_phase_deg)"
    return e_true, ph


def _learn_radial(ds: Any, res: Mapping[str, Any], raw: dict[str, Any], order: int, lr: _Learning) -> None:
    """Radial error motion (Jia eqs. 6-9), replayed as [motion_table] (the bearings' own motion
    replaced), and the bearings' asynchronous motion."""
    rj = "results.json"
    br = raw.setdefault("bearings", {})
    rm = lr.rm = _radial(ds, order)
    if rm is None:
        lr.notes.append("no radial_motion.csv: the bearings are kept from the base scenario")
        return
    th = np.asarray(rm["theta_deg"], dtype=float)
    w_top, w_bot = disk_weights(float(ds.bench["L1_mm"]), float(ds.bench["L2_mm"]))
    L2 = float(ds.bench["L2_mm"])
    f = rm["fits"]
    # only the harmonics measured above the probes' noise are replayed (a null bench stays null)
    dY, kY = _significant_curve(th, f["top"], f["bottom"], w_top, w_bot, order)
    # ε_X = −(δ_top − δ_bot)/L2: eq. 8 (radial_motion.py) is a rotation about −X; µm/mm = mrad → µrad
    tilt_x, kTx = _significant_curve(th, f["top"], f["bottom"], -1e3 / L2, 1e3 / L2, order)
    form = lr.identified.get("sphere_form")
    if form is not None:
        # a traced form error is part of the sphere's reading, not motion: out of the table, into
        # the sphere ([hidden.sphere_form], _sphere_form)
        ft, fb = (_form_curve(th, form, s_, f[s_]) for s_ in ("top", "bottom"))
        dY = dY - (w_top * ft + w_bot * fb)
        tilt_x = tilt_x + (ft - fb) / L2 * 1e3
        lr.notes.append("sphere_form: the traced form removed from the motion table (it is the sphere's, not the axis's)")
    has_x = "top_x" in f
    u_dy = float(np.nanmax(rm["u_dY_theta_um"]))
    reps = int(rm["n_reps"])
    src = f"{reps} revolution{'s' if reps > 1 else ''} × {th.size} positions of radial_motion.csv"
    dX, tilt_y, kTy, dx_src = _learn_x_motion(th, f, dY, (w_top, w_bot, L2), order, lr)
    if form is not None and has_x:
        # the X probes read the same form a quarter turn before the Y probes: out of δX and ε_Y too
        fxt, fxb = (_form_curve(th + 90.0, form, s_, f[s_]) for s_ in ("top", "bottom"))
        dX = dX - (w_top * fxt + w_bot * fxb)
        tilt_y = tilt_y - (fxt - fxb) / L2 * 1e3
    raw["motion_table"] = {
        "theta": [_q(t, "deg", 9) for t in th],
        "dx": [_q(v, "um", 5) for v in dX],
        "dy": [_q(v, "um", 5) for v in dY],
        "tilt_x": [_q(v, "urad", 5) for v in tilt_x],
        "tilt_y": [_q(v, "urad", 5) for v in tilt_y],
    }
    comments = lr.comments
    comments[("motion_table", "theta")] = f"synchronous radial error motion of the disk plane, harmonics 2…{order}, from {src}"
    comments[("motion_table", "dy")] = (f"harmonics {kY or 'none'} significant (χ²₂, p = {1 - SIGNIFICANCE_P:g}); "
                                        f"u ≤ {u_dy:.2g} um ({rj} radial_motion.u_dY_um), Jia eq. 9")
    comments[("motion_table", "dx")] = dx_src
    comments[("motion_table", "tilt_x")] = f"ε_X = −(δ_top − δ_bot)/L2 (Jia eq. 8 is about −X), harmonics {kTx or 'none'}"
    comments[("motion_table", "tilt_y")] = (f"(δX_top − δX_bot)/L2 from the X probes, harmonics {kTy or 'none'}" if has_x else
                                            "0: not observable without X probes")
    br["type"] = "path"
    comments[("bearings", "type")] = "the measured motion table replaces the bearings' own motion (twin/physics.py)"
    # a path bearing states where its replayed motion was measured (docs/physics.md, "Path bearings")
    br["path_provenance"] = f"radial_motion.csv of the dataset {Path(str(ds.path)).name} ({src}), by benchtwin calibrate-twin"
    for k in ("waviness_top", "waviness_bottom"):
        br[k] = []
        comments[("bearings", k)] = "replaced by [motion_table]"
    _learn_async(res, raw, reps, lr)


def _learn_x_motion(th: np.ndarray, f: dict[str, Any], dY: np.ndarray, lever: tuple[float, float, float],
                    order: int, lr: _Learning) -> tuple[np.ndarray, np.ndarray, list, str]:
    """The X motion of the disk plane: measured by the X probes, else the traced tangential motion's
    whirl, else 0. ``lever``: (w_top, w_bot, L2 in mm). Returns (δX µm, tilt_y µrad, tilt_y's
    significant harmonics, the comment on δX); sets ``lr.dx_params``."""
    w_top, w_bot, L2 = lever
    tang = lr.identified.get("tangential_motion")
    if "top_x" in f:
        dX, kX = _significant_curve(th, f["top_x"], f["bottom_x"], w_top, w_bot, order)
        lr.dx_params = _significant_series(f["top_x"], f["bottom_x"], w_top, w_bot, order)[0]
        tilt_y, kTy = _significant_curve(th, f["top_x"], f["bottom_x"], 1e3 / L2, -1e3 / L2, order)
        u_dx = float(np.nanmax(lr.rm.get("u_dX_range_theta_um", [np.nan]))) if lr.rm is not None else float("nan")
        dx_src = f"δX from the X probes (eq. 9 on X), harmonics {kX or 'none'} significant, u ≤ {u_dx:.2g} um"
        if tang is not None:
            lr.notes.append("tangential_motion: identified; with X probes it is the measured δX, already in "
                            "motion_table.dx (the twin's head reads −δX/r from the posed disk)")
        return dX, tilt_y, kTy, dx_src
    if tang is not None:
        # the traced whirl: δX = p·δY + q·H[δY] (analysis/effects/tangential_motion.py, no X probes)
        p = float(tang["params"].get("inphase_gain", 0.0))
        q = float(tang["params"].get("quadrature_gain", 0.0))
        dX = p * dY + q * _quadrature_on_grid(th, dY, order)
        from benchtwin.analysis.fourier import design_matrix

        lr.dx_params = np.linalg.lstsq(design_matrix(th, order), dX, rcond=None)[0]
        dx_src = (f"δX = p·δY + q·H[δY] of the traced tangential_motion, p = {p:.3g} (u {_eff_u(tang, 'inphase_gain'):.2g}),"
                  f" q = {q:.3g} (u {_eff_u(tang, 'quadrature_gain'):.2g})")
        return dX, np.zeros_like(th), [], dx_src
    lr.notes.append("no X probes: the X motion of the axis is not measured and is set to 0")
    return np.zeros_like(th), np.zeros_like(th), [], "δX = 0: not observable without X probes (docs/calibrate-twin.md)"


def _learn_async(res: Mapping[str, Any], raw: dict[str, Any], reps: int, lr: _Learning) -> None:
    """The bearings' asynchronous motion (bearings.async_rms) from the residual test's band 1…10,
    carried from the disk plane to the two seats; kept from the base after one revolution."""
    am = (res.get("residual_test") or {}).get("async_motion") or {}
    if am.get("sigma_um") is None:
        lr.notes.append("one revolution: the asynchronous motion is not measured; bearings.async_rms kept from the base")
        return
    s_disk = float(am["sigma_um"])   # band 1…10, the probes' noise removed (F test; analysis/tracing/)
    bench = raw.get("bench", {})
    from benchtwin.units import parse_quantity

    zt = parse_quantity(bench["bearing_top_z"], "length")
    zb = parse_quantity(bench["bearing_bottom_z"], "length")
    # the rigid shaft carries the bearings' independent motions to the disk plane (z = 0)
    # with the lever weights of the two seats: w_top = −z_b/(z_t − z_b), w_bot = z_t/(z_t − z_b)
    w_t, w_b = -zb / (zt - zb), zt / (zt - zb)
    s_b = s_disk / math.hypot(w_t, w_b)
    raw["bearings"]["async_rms"] = _q(s_b, "um", 4)
    how = ("above the probes' noise" if am.get("significant") else
           f"scatter {float(am.get('scatter_um', 0)):.2g} um not above the probes' noise "
           f"{float(am.get('noise_in_band_um', 0)):.2g} um (F test): 0")
    lr.comments[("bearings", "async_rms")] = (
        f"from results.json residual_test.async_motion.sigma_um = {s_disk:.2g} um at the disk plane ({how}; "
        f"{int(am.get('n_reps', reps))} revolutions), per bearing and axis")


def _learn_effects(res: Mapping[str, Any], raw: dict[str, Any], lr: _Learning) -> None:
    """The identified effects as physical causes ([hidden.*] and the keys they set); the ambiguous
    and unexplained ones noted."""
    hidden = raw.setdefault("hidden", {})
    for name, eff in lr.identified.items():
        fn = _EFFECTS.get(name)
        if fn is None:
            lr.notes.append(f"{name}: identified, but has no physical counterpart calibrate-twin can set; not transferred")
            continue
        if name == "sphere_form":
            _sphere_form(eff, raw, hidden, lr.comments, lr.notes, fits=lr.rm["fits"] if lr.rm is not None else None)
        else:
            fn(eff, raw, hidden, lr.comments, lr.notes)
    for x in res.get("ambiguous") or []:
        lr.notes.append(f"ambiguous (not transferred): {x}")
    if res.get("unexplained"):
        lr.notes.append("the close-loop residual stayed unexplained: the twin does not reproduce that part")
    if not hidden:
        raw.pop("hidden")


def _division_error_for_twin(eff: dict[str, Any], res: Mapping[str, Any], motion: _TwinMotion,
                             notes: list[str]) -> dict[str, Any]:
    """The disk's division harmonics as the calibrated twin needs them: the measured encoder curve
    (the corrected one, docs/effects.md) minus what the twin itself will produce from the fitted
    eccentricity (sin α = (e/r)·sin(θ − θ0), exact for the head on +Y, encoder_head.py) and from the
    replayed motion (−δX/r), fitted (weighted least squares, u of the curve) at the orders close-loop
    identified. The close-loop's own a_k, b_k are fitted to the residual of Jia's model, whose ∫δY dθ/r
    holds only 1/k of a k-lobed whirl's −δX/r: taken as they are, the twin would play the missing
    (1 − 1/k) twice, once as motion and once as division error."""
    e_um, theta0_deg, dx_params = motion.eccentricity_um, motion.theta0_deg, motion.dx_params_um
    c = res.get("encoder_error_corrected_arcsec") or res.get("encoder_error_arcsec")
    orders = sorted({int(k[1:].split("_")[0]) for k in eff["params"] if k.startswith(("a", "b")) and k.endswith("_arcsec")})
    if not isinstance(c, dict) or not orders:
        return eff
    from benchtwin.analysis.fourier import design_matrix, harmonic_columns

    th = np.asarray(c["theta_deg"], dtype=float)
    y = np.asarray(c["value"], dtype=float)
    u = np.ones_like(y) if c.get("u") is None else np.asarray(c["u"], dtype=float)
    r_um = motion.optical_radius_mm * 1e3
    y = y - np.degrees(np.arcsin(e_um / r_um * np.sin(np.radians(th - theta0_deg)))) * 3600.0
    if dx_params is not None:
        y = y + (design_matrix(th, motion.order) @ dx_params) / r_um * ARCSEC_PER_RAD
    cols = [np.ones_like(th), harmonic_columns(th, orders)[0]]   # [1, sin kθ, cos kθ, …] (fourier.py)
    X = np.column_stack(cols) / u[:, None]
    if X.shape[0] <= X.shape[1]:
        return eff
    beta, *_ = np.linalg.lstsq(X, y / u, rcond=None)
    cov = np.linalg.inv(X.T @ X)
    params, uu = {}, {}
    for i, k in enumerate(orders):
        params[f"a{k}_arcsec"], params[f"b{k}_arcsec"] = float(beta[1 + 2 * i]), float(beta[2 + 2 * i])
        uu[f"a{k}_arcsec"] = float(math.sqrt(cov[1 + 2 * i, 1 + 2 * i]))
        uu[f"b{k}_arcsec"] = float(math.sqrt(cov[2 + 2 * i, 2 + 2 * i]))
    shift = max(math.hypot(params[f"a{k}_arcsec"] - float(eff["params"].get(f"a{k}_arcsec", 0.0)),
                           params[f"b{k}_arcsec"] - float(eff["params"].get(f"b{k}_arcsec", 0.0))) for k in orders)
    notes.append(f"graduation_error: harmonics {orders} refitted to the measured curve minus the twin's own e and "
                 f"−δX/r terms (largest change from close-loop's values {shift:.2g}″)")
    return {**eff, "params": params, "u": uu, "refit": True}


def _graduation(
        eff: dict[str, Any], raw: dict[str, Any], hidden: dict[str, Any], comments: dict[tuple[str, str], str],
        notes: list[str]) -> None:
    p, u = eff["params"], eff.get("u") or {}
    orders = sorted({int(k[1:].split("_")[0]) for k in p if k.startswith(("a", "b")) and k.endswith("_arcsec")})
    amps, phases, us = [], [], []
    for k in orders:
        a, b = float(p.get(f"a{k}_arcsec", 0.0)), float(p.get(f"b{k}_arcsec", 0.0))
        # α_k(θ) = a sin kθ + b cos kθ = R cos(kθ − ψ); the twin's α = +E(g) with g = 90° − θ
        # (head 1 on +Y reads 90° − g; encoder_head.py), E_k = R cos(k·g − φ) ⇒ φ = k·90° − ψ
        R, psi = math.hypot(a, b), math.degrees(math.atan2(a, b))
        amps.append(_q(R, "arcsec", 5))
        phases.append(_q((k * 90.0 - psi) % 360.0, "deg", 6))
        us.append(f"k={k}: u(a) = {float(u.get(f'a{k}_arcsec', float('nan'))):.2g}″, u(b) = {float(u.get(f'b{k}_arcsec', float('nan'))):.2g}″")
    hidden["graduation_error"] = {"orders": orders, "amplitudes": amps, "phases": phases}
    comments[("hidden.graduation_error", "orders")] = (
        "the orders close-loop identified (results.json identified_effects graduation_error)"
        + ("; a_k, b_k refitted to encoder_error_corrected_arcsec minus the twin's e and −δX/r terms" if eff.get("refit") else ""))
    comments[("hidden.graduation_error", "amplitudes")] = "; ".join(us)
    comments[("hidden.graduation_error", "phases")] = "φ_k = k·90° − atan2(a_k, b_k): the head on +Y sees the line g = 90° − θ"
    raw.setdefault("errors", {})["graduation_error_rms"] = "0 arcsec"
    comments[("errors", "graduation_error_rms")] = ("the base's statistical disk is replaced by the measured harmonics "
                                                     "([hidden.graduation_error]); kept, it would count them twice")


def _ac_scale(
        eff: dict[str, Any], raw: dict[str, Any], hidden: dict[str, Any], comments: dict[tuple[str, str], str],
        notes: list[str]) -> None:
    p = eff["params"]
    d: dict[str, Any] = {}
    if "gain_pct" in p:
        d["gain"] = float(p["gain_pct"]) / 100.0
        comments[("hidden.ac_scale", "gain")] = f"u = {_eff_u(eff, 'gain_pct') / 100:.2g}, results.json ac_scale gain_pct / 100"
    if "quad_per_arcsec" in p:
        d["quadratic_per_arcsec"] = float(p["quad_per_arcsec"])
        comments[("hidden.ac_scale", "quadratic_per_arcsec")] = f"u = {_eff_u(eff, 'quad_per_arcsec'):.2g} per arcsec, results.json ac_scale"
    hidden["ac_scale"] = d


def _ac_drift(
        eff: dict[str, Any], raw: dict[str, Any], hidden: dict[str, Any], comments: dict[tuple[str, str], str],
        notes: list[str]) -> None:
    r = float(eff["params"]["drift_arcsec_per_s"])
    hidden["ac_drift"] = {"rate": _q(r, "arcsec/s", 5)}
    comments[("hidden.ac_drift", "rate")] = f"u = {_eff_u(eff, 'drift_arcsec_per_s'):.2g} arcsec/s, autocollimator zero drift (results.json ac_drift)"


def _torsion(
        eff: dict[str, Any], raw: dict[str, Any], hidden: dict[str, Any], comments: dict[tuple[str, str], str],
        notes: list[str]) -> None:
    from benchtwin.units import parse_quantity

    h = float(eff["params"]["half_hysteresis_arcsec"]) / ARCSEC_PER_RAD
    k = parse_quantity(raw.get("bearings", {}).get("shaft_torsional_stiffness", "100000 N*m/rad"), "torsional_stiffness")
    T = abs(h) * k   # the twin's static friction twist is ±T/k_shaft with the approach direction
    raw["bearings"]["friction_torque"] = _q(T, "N*m", 4)
    comments[("bearings", "friction_torque")] = (
        f"u = {_eff_u(eff, 'half_hysteresis_arcsec') / ARCSEC_PER_RAD * k:.2g} N*m: half-hysteresis "
        f"{h * ARCSEC_PER_RAD:.3g}″ (results.json torsion_hysteresis) × shaft_torsional_stiffness")


def _optical_radius(
        eff: dict[str, Any], raw: dict[str, Any], hidden: dict[str, Any], comments: dict[tuple[str, str], str],
        notes: list[str]) -> None:
    from benchtwin.units import parse_quantity

    r_mm = parse_quantity(raw["bench"]["optical_radius"], "length") * 1e3
    rel = float(eff["params"]["delta_r_mm"]) / r_mm
    hidden["optical_radius"] = {"relative": rel}
    comments[("hidden.optical_radius", "relative")] = f"u = {_eff_u(eff, 'delta_r_mm') / r_mm:.2g}: Δr/r of results.json optical_radius"


def _tilt_abbe(
        eff: dict[str, Any], raw: dict[str, Any], hidden: dict[str, Any], comments: dict[tuple[str, str], str],
        notes: list[str]) -> None:
    d = float(eff["params"].get("dL1_mm", eff["params"].get("dL1_tangential_mm", 0.0)))
    hidden["tilt_abbe"] = {"delta_L1": _q(d, "mm", 5)}
    comments[("hidden.tilt_abbe", "delta_L1")] = f"u = {_eff_u(eff, 'dL1_mm'):.2g} mm: the spheres' true height (results.json tilt_abbe)"


def _ccd_scale(
        eff: dict[str, Any], raw: dict[str, Any], hidden: dict[str, Any], comments: dict[tuple[str, str], str],
        notes: list[str]) -> None:
    s = float(eff["params"]["scale_error_pct"]) / 100.0
    hidden["ccd_pixel_scale"] = {"grating_period_relative": s}
    comments[("hidden.ccd_pixel_scale", "grating_period_relative")] = (
        f"u = {_eff_u(eff, 'scale_error_pct') / 100:.2g}: the grating period at the scale edge (results.json ccd_pixel_scale)")


def _interpolation(
        eff: dict[str, Any], raw: dict[str, Any], hidden: dict[str, Any], comments: dict[tuple[str, str], str],
        notes: list[str]) -> None:
    p = eff["params"]
    d: dict[str, Any] = {}
    for m in (1, 2):
        s, c = float(p.get(f"c{m}_sin_arcsec", 0.0)), float(p.get(f"c{m}_cos_arcsec", 0.0))
        if f"c{m}_sin_arcsec" not in p and f"c{m}_cos_arcsec" not in p:
            continue
        # s·sin x + c·cos x = R·sin(x + φ), φ = atan2(c, s) (x the grating phase, twin/hidden.py)
        d[f"c{m}"] = _q(math.hypot(s, c), "arcsec", 5)
        d[f"c{m}_phase"] = _q(math.degrees(math.atan2(c, s)), "deg", 6)
        comments[("hidden.interpolation_error", f"c{m}")] = (
            f"u ≈ {max(_eff_u(eff, f'c{m}_sin_arcsec'), _eff_u(eff, f'c{m}_cos_arcsec')):.2g}″ (results.json interpolation_error)")
    hidden["interpolation_error"] = d
    notes.append("interpolation_error: transferred with the phase convention of the head's grating phase; "
                 "not checked in a round trip")


def _sphere_form(
        eff: dict[str, Any], raw: dict[str, Any], hidden: dict[str, Any], comments: dict[tuple[str, str], str],
        notes: list[str], fits: dict[str, list] | None = None) -> None:
    d: dict[str, Any] = {}
    for s_ in ("top", "bottom"):
        lobes = []
        for k, (a, b) in sorted(_form_lobes(eff, s_, (fits or {}).get(s_)).items()):
            # the probe on +Y touches the body polar angle 90° − θ and reads +f there (twin/instruments/
            # probe.py): f_k(g) = R cos(k·g − p) reads R cos(kθ − (k·90° − p)) ⇒ p = k·90° − atan2(a, b)
            R = math.hypot(a, b)
            if R > 0:
                lobes.append({"order": int(k), "amplitude": _q(R, "um", 5),
                              "phase": _q((k * 90.0 - math.degrees(math.atan2(a, b))) % 360.0, "deg", 6)})
        if lobes:
            d[s_] = lobes
            us = [f"{n}: {v:.2g} um" for n, v in (eff.get("u") or {}).items() if n.startswith(s_)]
            comments[("hidden.sphere_form", s_)] = (f"traced sphere_form (results.json identified_effects); u {', '.join(us)}"
                                                   if us else "traced sphere_form (results.json identified_effects)")
    if d:
        hidden["sphere_form"] = d


_EFFECTS = {"graduation_error": _graduation, "ac_scale": _ac_scale, "ac_drift": _ac_drift,
            "torsion_hysteresis": _torsion, "optical_radius": _optical_radius, "tilt_abbe": _tilt_abbe,
            "ccd_pixel_scale": _ccd_scale, "interpolation_error": _interpolation,
            "sphere_form": _sphere_form}


# ----------------------------------------------------------------------------- the command

def calibrate_twin(dataset: Path, out: Path, base: Path | None = None, results: Path | None = None,
                   order: int = 10, progress: bool = False, *, force: bool = False) -> dict[str, Any]:
    """Write OUT (a scenario TOML) whose twin reproduces the measured DATASET; returns a summary.
    The writing rule (``benchtwin.fsio.check_output_target``): an existing OUT is replaced only with
    ``force``, and never when it is (or lies in) one of the inputs: the dataset, the results, the base."""
    import copy

    from benchtwin.analysis.dataset import open_dataset
    from benchtwin.fsio import atomic_write_text, check_output_target
    from benchtwin.schema import load_toml_file
    from benchtwin.twin.scenario import ScenarioError, default_scenario_path, load_scenario, validate

    ds_path, res_path = locate(Path(dataset), results)
    check_output_target(out, force=force, inputs=[dataset, ds_path, res_path, base], what="scenario file")
    ds = open_dataset(ds_path)
    if ds.kind == "error-curve":
        raise CalibrationInputError(f"{ds_path}: an error-curve dataset (imported table) has no bench to learn: "
                                    "calibrate-twin needs a bench dataset (radial_motion.csv, ccd/, polygon.csv)")
    base_path = Path(base) if base is not None else default_scenario_path()
    try:
        load_scenario(base_path)
    except ScenarioError as exc:
        raise CalibrationInputError(f"--base: {exc}") from None
    raw = copy.deepcopy(load_toml_file(base_path, what="scenario file"))
    comments: dict[tuple[str, str], str] = {}
    if base is None:
        _manifest_overrides(raw, ds.manifest, comments)
    _procedure_from_dataset(raw, ds, comments)
    with tempfile.TemporaryDirectory(prefix="calibrate-twin-") as tmp:
        res = analysed(ds_path, res_path, Path(tmp), progress=progress)
    where = res_path or ds_path
    raw, fitted, notes = learn(ds, res, raw, where, order=order)
    comments.update(fitted)
    sc = raw.setdefault("scenario", {})
    base_name = str(sc.get("name", "bench"))
    sc["name"] = f"{ds.manifest.get('scenario') or base_name}_calibrated"
    sc["description"] = f"twin calibrated on {ds_path.name} (benchtwin calibrate-twin; base {base_path.name})"
    header = [f"Calibrated twin of the bench measured in {ds_path} (benchtwin calibrate-twin).",
              f"Base scenario: {base_path}{' (embedded default + the manifest)' if base is None else ''};",
              "every value without a comment is the base's (not fitted). Fitted values carry their u and source.",
              f"Results: {res_path or 'close-loop run on the dataset'}.",
              "Not learned from one dataset (docs/calibrate-twin.md): the disk's division error between the",
              "polygon's stops and above the significant harmonics, δX without X probes, the polygon's pitch,",
              "the seeded details of the base (sphere form, ball sets, noise streams)."]
    header += [f"note: {n}" for n in notes]
    text = dump_toml(raw, comments, header)
    try:
        validate(load_toml_text(text, out), str(out))
    except ScenarioError as exc:   # a bug here, never the user's input
        raise RuntimeError(f"calibrate-twin wrote an invalid scenario: {exc}") from None
    out = check_output_target(out, force=force, inputs=[dataset, ds_path, res_path, base], what="scenario file")
    atomic_write_text(out, text)
    fitted_keys = sorted({f"{s}.{k}" for s, k in fitted})
    return {"scenario": str(out), "dataset": str(ds_path), "results": str(res_path) if res_path else None,
            "base": str(base_path), "eccentricity_um": float(res["eccentricity_um"]),
            "identified_effects": [e["name"] for e in res.get("identified_effects") or []],
            "fitted": fitted_keys, "notes": notes}


def load_toml_text(text: str, where: Path) -> dict[str, Any]:
    from benchtwin.schema import loads_toml

    return loads_toml(text, str(where))
