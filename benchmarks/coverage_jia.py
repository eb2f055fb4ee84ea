"""Coverage of the Jia 2019 pipeline's uncertainties over many twin seeds (issue 5).

For each seed the jia2019 scenario (realistic noise: probe repeatability, linearity, sphere form,
asynchronous motion; CCD read noise, dust, scratches) is simulated on the twin (analytic renderer:
exact pixel coverage, no OpenGL, ~2× cheaper than pyrender and equal to it within 0.02 px), its
``truth/`` is moved OUT of the dataset before the analysis opens it, and the analysis runs on the
dataset exactly as the pipeline does:

- radial motion: :func:`benchtwin.analysis.pipeline.step_radial_motion` (Jia eqs. 6-9);
- CCD: the two passes of :func:`benchtwin.analysis.pipeline.step_eccentricity` (pixel scale per
  frame from the grating, Jia eq. 13, median; then d_ref per frame with the edge radius fixed),
  keeping the per-frame numbers, then :func:`benchtwin.analysis.eccentricity.eccentricity_from_sweep`
  (eqs. 10-12; it adds the pixel scale's u, ~3e-6 relative, which the pipeline leaves out) and
  :func:`benchtwin.analysis.eccentricity.with_async_motion` with the radial motion's
  ``u_h1_async_um``, as the pipeline does;
- Δθ: :func:`benchtwin.analysis.error_model.error_model_from_results` (eq. 5), as the pipeline
  calls it (its ``u`` is ``model_prediction_arcsec.u`` of results.json), and with
  ``dY_uncertainty="gum"`` (the fit covariance of δY, propagated through the integral).

The polygon procedure is simulated too (simulate runs every procedure of the scenario; it costs
~1 s of the ~14 s) but not analysed. Per seed: ~14 s simulation + ~12 s image analysis on one core.

Truth (never seen by the analysis):

- synchronous (:func:`sync_truth`: the same bench and seed with ``bearings.async_rms = 0``): e, θ0
  of eq. 10-12 on the disk's geometric centre at the CCD stops — the installation eccentricity
  PLUS the axis's synchronous once-per-revolution motion, which neither the CCD method nor the
  encoder can separate from e; δY the harmonics 2…10 of the axis's synchronous motion; these are
  the paper's measurands;
- this sweep / these revolutions (from the moved-aside truth/): the eq. 10-12 fit of the TRUE d_ref
  of each frame (truth/ccd.csv: disk centre and edge radius in true pixels × the true pixel size),
  and per repetition the harmonics 2…10 of the true axis motion along Y (truth/radial_motion.csv
  ``axis_dy_um``) averaged over the repetitions — asynchronous motion of the run included;
- Δθ (a): eq. 5 evaluated on the synchronous truth (r from the manifest, the twin's r) — tests
  the propagation through the model; (b) the true encoder error α(θ) of truth/encoder_error.csv
  (rep 0), both means removed — tests the model itself (the Jia model lacks (1 − 1/k) of each
  k-lobed whirl of the axis, docs/hidden-suite.md; not an uncertainty matter).

Reported for each quantity: the fraction of seeds (seeds × angles for δY, Δθ) with
|estimate − truth| ≤ k·u, k = 1, 2 (a normal error with the right u: 68.3 %, 95.4 %), with its
binomial standard uncertainty sqrt(p(1−p)/n) (n = seeds, the conservative count for the pooled
angles, which are correlated within a seed), and the normalised error z = (estimate − truth)/u:
mean, standard deviation, 68th and 95th percentile of |z|.

    .venv/bin/python benchmarks/coverage_jia.py [--seeds 50] [--first 1000] [--work /tmp/coverage_jia]
                                                [--doc docs/benchmarks.md] [--fig docs/img/coverage_jia.png]

Resumable: each seed's record is cached as ``<work>/records/seed_NNNNNN.json``; the datasets are
deleted after use (70 MB each). ``--summary-only`` recomputes the tables from the cache.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ANGLES_DEG = np.arange(0.0, 360.0, 45.0)  # where δY and Δθ are scored (on the analysis' 1° grid)
KS = (1.0, 2.0)
SCALE_EVERY = 6  # pixel scale from every 6th frame (10 of 60) in the benchmark; see analyse_dataset
NORMAL_P = {1.0: math.erf(1 / math.sqrt(2)), 2.0: math.erf(2 / math.sqrt(2))}


# --------------------------------------------------------------------------- one seed


def _csv(path: Path) -> dict[str, np.ndarray]:
    import csv

    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    out = {}
    for k in rows[0]:
        vals = [r[k] for r in rows]
        try:
            out[k] = np.array([float(v) for v in vals])
        except ValueError:
            out[k] = np.array(vals)
    return out


def analyse_dataset(ds_path: Path, order: int = 10, scale_every: int = 1) -> dict[str, Any]:
    """The pipeline's Jia steps on one dataset (truth/ must not be inside). ``scale_every``: the
    pixel scale from every n-th frame only (the pipeline uses every frame; the scale's frame-to-frame
    spread is ~5e-6 relative, so a median of 10 frames changes e by ~1e-5 µm, 0.4 % of u(e))."""
    from benchtwin.analysis import eccentricity as ecc
    from benchtwin.analysis.dataset import open_dataset

    ds = open_dataset(ds_path)
    if (Path(ds_path) / "truth").exists():
        raise RuntimeError(f"{ds_path}: truth/ must be moved out before the analysis")
    b, ccd = ds.bench, ds.manifest["ccd"]
    t = ds.table("radial_motion")  # the columns step_radial_motion passes to radial_motion
    radial = {"rep": t["rep"].tolist(), "theta_deg": t["theta_deg"].tolist(),
              "probe_top_um": t["probe_top_um"].tolist(), "probe_bottom_um": t["probe_bottom_um"].tolist(),
              "L1_mm": b["L1_mm"], "L2_mm": b["L2_mm"]}
    # CCD, pass 1 (as step_eccentricity): pixel scale per frame from the grating
    scales, u_scales, bad = [], [], set()
    for i, (k, theta, image, f) in enumerate(ds.ccd_frames()):
        if i % scale_every:
            continue
        try:
            s = ecc.pixel_scale_um(image, b["grating_period_um"], name=f)
        except ecc.ImageAnalysisError:
            bad.add(f)
            continue
        scales.append(s["pixel_um"])
        u_scales.append(s["u_um_per_px"])
    scale = float(np.median(scales))
    radius_px = b["scale_edge_radius_mm"] * 1000.0 / scale
    ks, th, dpx = [], [], []
    for k, theta, image, f in ds.ccd_frames():  # pass 2: d_ref with the edge radius fixed
        if f in bad:
            continue
        try:
            r = ecc.d_ref_px(image, tuple(ccd["reference_px"]), radius_px=radius_px, name=f)
        except ecc.ImageAnalysisError:
            continue
        ks.append(int(k))
        th.append(float(theta))
        dpx.append(r["d_ref_px"])
    return {"radial": radial, "ccd_k": ks, "ccd_theta_deg": th, "d_ref_px": dpx, "scales_um_per_px": scales,
            "u_scales_um_per_px": u_scales, "camera_azimuth_deg": float(ccd["position_deg"]),
            "r_um": b["optical_radius_mm"] * 1000.0, "reference_px": list(ccd["reference_px"])}


def eccentricity_estimate(a: dict[str, Any], order: int = 10) -> dict[str, Any]:
    """e, θ0 and their u from the per-frame numbers, as the pipeline computes them."""
    from benchtwin.analysis.eccentricity import eccentricity_from_sweep

    return eccentricity_from_sweep(np.asarray(a["ccd_theta_deg"]), np.asarray(a["d_ref_px"]),
                                   np.asarray(a["scales_um_per_px"]), camera_azimuth_deg=a["camera_azimuth_deg"],
                                   order=order)


def truth_of(truth_dir: Path, a: dict[str, Any], order: int = 10) -> dict[str, Any]:
    """e, θ0 (eq. 10-12 on the true d_ref), δY (synchronous harmonics 2…order) and α on the 1° grid."""
    from benchtwin.analysis.eccentricity import eccentricity_from_dref
    from benchtwin.analysis.fourier import design_matrix, fit_fourier

    tc = _csv(truth_dir / "ccd.csv")
    ref = a["reference_px"]
    by_k = {int(k): i for i, k in enumerate(tc["k"])}
    idx = [by_k[k] for k in a["ccd_k"]]
    d_true_um = (np.hypot(tc["centre_x_px"][idx] - ref[0], tc["centre_y_px"][idx] - ref[1])
                 - tc["edge_radius_px"][idx]) * tc["pixel_um"][idx]
    et = eccentricity_from_dref(np.asarray(a["ccd_theta_deg"]), d_true_um, a["camera_azimuth_deg"], order)
    tr = _csv(truth_dir / "radial_motion.csv")
    grid = np.unique(np.round(tr["theta_deg"][tr["rep"] == tr["rep"][0]] % 360.0, 9))
    G = design_matrix(grid, order, harmonics=range(2, order + 1))
    reps = np.unique(tr["rep"])
    dy = np.mean([G @ fit_fourier(tr["theta_deg"][tr["rep"] == r], tr["axis_dy_um"][tr["rep"] == r], order).params
                  for r in reps], axis=0)
    te = _csv(truth_dir / "encoder_error.csv")
    sel = np.isin(np.round(te["theta_deg"], 6), np.round(np.arange(360.0), 6))
    return {"e_um": et["e_um"], "theta0_deg": et["theta0_deg"], "dY_theta_deg": grid.tolist(), "dY_um": dy.tolist(),
            "alpha_theta_deg": te["theta_deg"][sel].tolist(), "alpha_arcsec": te["alpha_arcsec"][sel].tolist()}


def sync_truth(sc: Any, ccd_theta_deg: list[float], grid_deg: np.ndarray, order: int = 10) -> dict[str, Any]:
    """The synchronous truth: the same bench (same seed) with the non-repeating motion switched off
    (``bearings.async_rms = 0``: the cage lobes and the random part scale to zero; every other random
    draw comes from its own stream and is unchanged). Posed at the stops the stage reaches at the
    commanded readings, as in the run:

    - e, θ0: eq. 10-12 on the disk's geometric centre along lab Y (d_ref = const + c_y for the camera
      at 180°, docs/conventions.md) at the CCD angles;
    - δY: harmonics 2…order of the axis's disk-plane motion along Y at the radial stops.
    The per-sweep truths (truth/ccd.csv, truth/radial_motion.csv) include the realisation of the
    non-repeating motion during the run, which the estimate contains too."""
    from benchtwin.analysis.eccentricity import eccentricity_from_dref
    from benchtwin.analysis.fourier import design_matrix, fit_fourier
    from benchtwin.twin.simulate import sim_build

    _, state, inst = sim_build(sc.with_overrides({"bearings.async_rms": "0 um"}), camera=False)
    stage = inst["stage"]
    state.apply_context({"rep": 0, "direction": "forward"})

    def poses(ths):
        cy, ay = [], []
        for th in ths:
            stage.move_to(float(th))
            p = state.pose
            cy.append(p.disk.pos[1] * 1e6)
            ay.append(p.extra["axis_disk_plane_m"][1] * 1e6)
        return np.array(cy), np.array(ay)

    cy, _ = poses(ccd_theta_deg)
    et = eccentricity_from_dref(np.asarray(ccd_theta_deg), cy, 180.0, order)
    _, ay = poses(grid_deg)
    G = design_matrix(grid_deg, order, harmonics=range(2, order + 1))
    dy = G @ fit_fourier(grid_deg, ay, order).params
    return {"e_um": et["e_um"], "theta0_deg": et["theta0_deg"], "dY_um": dy.tolist()}


class _without_polygon:
    """simulate() with the scenario's procedure cut before the polygon (and self-calibration)
    steps. The radial-motion and CCD steps come first in ``sim_procedure``, and the twin keys every
    random stream by the step's index, so the radial and CCD data are the same as those of the
    full simulation of that seed (checked by ``tests/analysis/test_coverage_jia.py``)."""

    def __enter__(self):
        import benchtwin.twin.simulate as S
        from benchtwin.hw.acquisition import procedures as P

        self._S, self._orig = S, S.sim_procedure
        orig = self._orig

        def jia_only(sc):
            steps = orig(sc)
            for i, st in enumerate(steps):
                if isinstance(st, P.Mark) and st.context.get("procedure") not in ("radial_motion", "ccd"):
                    return steps[:i]
            return steps

        S.sim_procedure = jia_only
        return self

    def __exit__(self, *exc):
        self._S.sim_procedure = self._orig
        return False


def run_seed(seed: int, work: Path, order: int = 10, scale_every: int = SCALE_EVERY,
             overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """Simulate jia2019 with ``seed`` (and scenario ``overrides``), run the image analysis without
    truth, read the truth: the raw record (JSON-able; :func:`score` turns it into estimates,
    uncertainties and truth)."""
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import simulate

    t0 = time.perf_counter()
    sc = load_scenario().with_overrides({**(overrides or {}), "scenario.seed": int(seed)})
    ds = work / f"ds_{seed}"
    truth = work / f"truth_{seed}"
    for p in (ds, truth):
        shutil.rmtree(p, ignore_errors=True)
    with _without_polygon():
        simulate(sc, ds, progress=False, backend="analytic")
    (ds / "truth").rename(truth)  # the analysis never sees it
    t_sim = time.perf_counter() - t0
    try:
        a = analyse_dataset(ds, order, scale_every)
        t_ana = time.perf_counter() - t0 - t_sim
        tt = truth_of(truth, a, order)
        if a["camera_azimuth_deg"] != 180.0:
            raise RuntimeError("sync_truth assumes the camera at 180°")
        tt["sync"] = sync_truth(sc, a["ccd_theta_deg"], np.asarray(tt["dY_theta_deg"]), order)
    finally:
        shutil.rmtree(ds, ignore_errors=True)
        shutil.rmtree(truth, ignore_errors=True)
    return {"seed": int(seed), "order": order, "measured": a, "truth": tt, "t_sim_s": t_sim, "t_analysis_s": t_ana}


def score(raw: dict[str, Any]) -> dict[str, Any]:
    """Estimates, uncertainties and truths at the scored angles (plain lists) from a raw record,
    with the analysis code as it is now (the raw record holds only measurements and truth)."""
    from benchtwin.analysis.eccentricity import with_async_motion
    from benchtwin.analysis.error_model import error_model_from_results as efr
    from benchtwin.analysis.error_model import EccentricityEstimate, RadialCurve, jia_error_model
    from benchtwin.analysis.radial_motion import ProbeReadings, RadialOptions, SphereSpacing, radial_motion

    a, t, order = raw["measured"], raw["truth"], raw["order"]
    ts = t["sync"]
    rad = a["radial"]
    # as pipeline.step_radial_motion calls it
    rm = radial_motion(ProbeReadings(np.asarray(rad["rep"]), np.asarray(rad["theta_deg"]), np.asarray(rad["probe_top_um"]),
                                     np.asarray(rad["probe_bottom_um"])),
                       SphereSpacing(rad["L1_mm"], rad["L2_mm"]), RadialOptions(order=order))
    ec_fit = eccentricity_estimate(a, order)
    ec = with_async_motion(ec_fit, rm["u_h1_async_um"], rm["u_h1_async_dof"])  # as the pipeline does
    grid = np.asarray(rm["theta_deg"], dtype=float)
    if not np.allclose(grid, t["dY_theta_deg"]):
        raise RuntimeError("analysis grid and truth grid differ")
    at = np.isin(np.round(grid, 6), ANGLES_DEG)
    if np.count_nonzero(at) != ANGLES_DEG.size:
        raise RuntimeError("the radial-motion grid does not contain the scored angles")
    r_um = a["r_um"]
    q = np.arange(360.0)
    qa = ANGLES_DEG.astype(int)
    m_pipe = efr(ec, rm, r_um)  # the pipeline's call (results.json model_prediction_arcsec)
    m_gum = efr(ec, rm, r_um, dY_uncertainty="gum")
    m_true = jia_error_model(EccentricityEstimate(ts["e_um"], ts["theta0_deg"]), r_um, RadialCurve(grid, np.asarray(ts["dY_um"])))
    pred, ptrue = m_pipe.predict(q), m_true.predict(q)
    alpha = np.interp(q, t["alpha_theta_deg"], t["alpha_arcsec"], period=360.0)
    dY, u_gum = np.asarray(rm["dY_um"]), np.asarray(rm["u_dY_gum_theta_um"])
    u_sync = np.asarray(rm["u_dY_theta_um"])  # as the spindle's synchronous motion
    sc_ = np.asarray(a["scales_um_per_px"])
    L = lambda x: np.asarray(x)[at].tolist()  # noqa: E731
    return {
        "seed": raw["seed"], "t_sim_s": raw.get("t_sim_s"), "t_analysis_s": raw.get("t_analysis_s"),
        "e_um": ec["e_um"], "e_u_um": ec["e_u_um"], "e_u_fit_um": ec["e_u_fit_um"],
        "e_sync_um": ts["e_um"], "e_sweep_um": t["e_um"],
        "theta0_deg": ec["theta0_deg"], "theta0_u_deg": ec["theta0_u_deg"], "theta0_u_fit_deg": ec["theta0_u_fit_deg"],
        "theta0_sync_deg": ts["theta0_deg"], "theta0_sweep_deg": t["theta0_deg"],
        "u_h1_async_um": rm["u_h1_async_um"],
        "pixel_um": ec["pixel_um"], "u_pixel_um": ec["u_pixel_um"], "n_frames": len(a["ccd_k"]),
        "scale_spread_um": float(np.std(sc_, ddof=1)),
        "dY_theta_deg": L(grid), "dY_um": L(dY),
        "dY_reps_true_um": L(t["dY_um"]), "dY_sync_true_um": L(ts["dY_um"]),
        "dY_u_gum_um": L(u_gum), "dY_u_sync_um": L(u_sync),
        "dY_u_range_um": L(rm["u_dY_range_theta_um"]),
        "dY_rms_err_reps_um": float(np.sqrt(np.mean((dY - np.asarray(t["dY_um"])) ** 2))),
        "dY_rms_err_sync_um": float(np.sqrt(np.mean((dY - np.asarray(ts["dY_um"])) ** 2))),
        "dY_rms_u_gum_um": float(np.sqrt(np.mean(u_gum**2))),
        "dY_rms_u_sync_um": float(np.sqrt(np.mean(u_sync**2))),
        "dtheta_theta_deg": ANGLES_DEG.tolist(),
        "dtheta_arcsec": pred[qa].tolist(),
        "dtheta_true_inputs_arcsec": ptrue[qa].tolist(),
        "dtheta_u_pipeline_arcsec": m_pipe.uncertainty(ANGLES_DEG).tolist(),
        "dtheta_u_gum_arcsec": m_gum.uncertainty(ANGLES_DEG).tolist(),
        # model vs the true encoder error, both means removed (α is known up to a constant)
        "dtheta_vs_alpha_arcsec": ((pred - pred.mean()) - (alpha - alpha.mean()))[qa].tolist(),
        "dtheta_vs_alpha_rms_arcsec": float(np.sqrt(np.mean(((pred - pred.mean()) - (alpha - alpha.mean())) ** 2))),
    }


# --------------------------------------------------------------------------- statistics


def coverage(z: np.ndarray, n_units: int | None = None) -> dict[str, Any]:
    """Fractions |z| ≤ k with binomial u (n_units: the independent count; default z.size)."""
    z = np.asarray(z, dtype=float).ravel()
    n = int(n_units if n_units is not None else z.size)
    out: dict[str, Any] = {"n": int(z.size), "n_units": n, "z_mean": float(np.mean(z)),
                           "z_sd": float(np.std(z, ddof=1)) if z.size > 1 else float("nan"),
                           "abs_z_p68": float(np.quantile(np.abs(z), 0.6827)),
                           "abs_z_p95": float(np.quantile(np.abs(z), 0.9545))}
    for k in KS:
        p = float(np.mean(np.abs(z) <= k))
        out[f"p{k:g}"] = p
        # binomial u of the fraction; at p = 0 or 1 use the expected p (not 0)
        pe = p if 0 < p < 1 else NORMAL_P[k]
        out[f"u_p{k:g}"] = math.sqrt(pe * (1 - pe) / n)
    return out


def _wrap(d: np.ndarray) -> np.ndarray:
    return (np.asarray(d) + 180.0) % 360.0 - 180.0


def normalised_errors(recs: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    R = {k: np.array([r[k] for r in recs], dtype=float) for k in recs[0]
         if isinstance(recs[0][k], (int, float, list)) and recs[0][k] is not None}
    de_s, de_w = R["e_um"] - R["e_sync_um"], R["e_um"] - R["e_sweep_um"]
    dt_s, dt_w = _wrap(R["theta0_deg"] - R["theta0_sync_deg"]), _wrap(R["theta0_deg"] - R["theta0_sweep_deg"])
    dY = R["dY_um"]
    ddt = R["dtheta_arcsec"] - R["dtheta_true_inputs_arcsec"]
    return {
        "e (synchronous truth; u incl. async 1st harmonic)": de_s / R["e_u_um"],
        "e (synchronous truth; u from the d_ref fit only)": de_s / R["e_u_fit_um"],
        "e (this sweep's truth; u from the fit only)": de_w / R["e_u_fit_um"],
        "θ0 (synchronous truth; u incl. async 1st harmonic)": dt_s / R["theta0_u_deg"],
        "θ0 (synchronous truth; u from the d_ref fit only)": dt_s / R["theta0_u_fit_deg"],
        "θ0 (this sweep's truth; u from the fit only)": dt_w / R["theta0_u_fit_deg"],
        "δY (synchronous truth; u from the revolutions' scatter, per harmonic)": (dY - R["dY_sync_true_um"]) / R["dY_u_sync_um"],
        "δY (synchronous truth; u = GUM fit only)": (dY - R["dY_sync_true_um"]) / R["dY_u_gum_um"],
        "δY (these revolutions' truth; u = GUM fit)": (dY - R["dY_reps_true_um"]) / R["dY_u_gum_um"],
        "δY (synchronous truth; u = range/d_n, Jia)": (dY - R["dY_sync_true_um"]) / R["dY_u_range_um"],
        "Δθ (eq. 5 on the synchronous truth; u = GUM)": ddt / R["dtheta_u_gum_arcsec"],
        "Δθ (eq. 5 on the synchronous truth; u = pipeline default, range)": ddt / R["dtheta_u_pipeline_arcsec"],
        "Δθ (true encoder error α; u = GUM)": R["dtheta_vs_alpha_arcsec"] / R["dtheta_u_gum_arcsec"],
    }


def summarise(recs: list[dict[str, Any]]) -> dict[str, Any]:
    z = normalised_errors(recs)
    n = len(recs)

    def m(k):
        return float(np.mean([np.mean(r[k]) for r in recs]))

    def rms(x):
        return float(np.sqrt(np.mean(np.square(x))))

    return {"n_seeds": n, "coverage": {k: coverage(v, n) for k, v in z.items()},
            "scalars": {
                "e_err_sync_um_rms": rms([r["e_um"] - r["e_sync_um"] for r in recs]),
                "e_err_sweep_um_rms": rms([r["e_um"] - r["e_sweep_um"] for r in recs]),
                "e_u_um_mean": m("e_u_um"), "e_u_fit_um_mean": m("e_u_fit_um"),
                "theta0_err_sync_deg_rms": rms([_wrap(r["theta0_deg"] - r["theta0_sync_deg"]) for r in recs]),
                "theta0_u_deg_mean": m("theta0_u_deg"), "theta0_u_fit_deg_mean": m("theta0_u_fit_deg"),
                "dY_rms_err_sync_um_mean": m("dY_rms_err_sync_um"), "dY_rms_err_reps_um_mean": m("dY_rms_err_reps_um"),
                "dY_rms_u_gum_um_mean": m("dY_rms_u_gum_um"), "dY_rms_u_sync_um_mean": m("dY_rms_u_sync_um"),
                "dY_u_range_um_mean": m("dY_u_range_um"),
                "dtheta_err_arcsec_rms": rms([np.subtract(r["dtheta_arcsec"], r["dtheta_true_inputs_arcsec"])
                                              for r in recs]),
                "dtheta_vs_alpha_rms_arcsec_mean": m("dtheta_vs_alpha_rms_arcsec"),
                "dtheta_u_pipeline_arcsec_mean": m("dtheta_u_pipeline_arcsec"),
                "dtheta_u_gum_arcsec_mean": m("dtheta_u_gum_arcsec"),
                "t_sim_s_mean": m("t_sim_s"), "t_analysis_s_mean": m("t_analysis_s"),
                "t_total_min": float(sum(r["t_sim_s"] + r["t_analysis_s"] for r in recs) / 60.0),
            }}


PREAMBLE = """\
`benchmarks/coverage_jia.py --seeds 50` — do the Jia 2019 pipeline's standard uncertainties cover the
twin's truth? jia2019 (realistic noise: probe repeatability 0.1 µm, linearity, sphere form 14 nm,
asynchronous spindle motion 0.06 µm RMS, CCD read noise, dust, scratches) simulated for each seed
(analytic renderer; the polygon steps skipped — the radial and CCD data are byte-identical to the
full run's, `tests/analysis/test_coverage_jia.py`), truth/ moved out, the pipeline's Jia steps run
(the pixel scale from every 6th frame: its spread is ~5e-6 relative, irrelevant to e), estimate −
truth divided by the reported u.

Truths: **synchronous** — the same bench and seed with the non-repeating motion switched off
(`bearings.async_rms = 0`): e, θ0 of eq. 10-12 on the disk centre at the CCD stops (= the declared
7.1 µm, 192.08° to < 1 nm: the axis's own once-per-revolution motion is negligible here), δY the
harmonics 2…10 of the axis's synchronous motion, Δθ eq. 5 on those. **This sweep / these
revolutions** — the same quantities as they were during the run (truth/ccd.csv, truth/radial_motion.csv),
asynchronous motion included. The measurands of the paper (the eccentricity of the disk, the
synchronous radial motion of the spindle) are the synchronous ones.

Finding (fixed in `analysis/`): the eccentricity's u from the d_ref fit residual (2-3 nm) was right
for *this sweep* but 20× too small for e: one CCD sweep sees the disk during one revolution, and the
once-per-revolution part of the asynchronous motion during it (~0.05 µm) adds to the first harmonic,
inseparable from e; the fit residual shows only the other frequencies. It is now estimated from
the two-sphere data — the scatter of the disk-plane combination's 1st-harmonic coefficients over
the revolutions (eq. 7 removes them as sphere centring, but their rep-to-rep scatter is
asynchronous motion; `radial_motion(...)["u_h1_async_um"]`, ν = 4 for 3 revolutions) — and added
in quadrature to u(e) and, divided by e, to u(θ0) (`eccentricity.with_async_motion`, called by the
pipeline). Likewise δY as the spindle's synchronous motion carries 1/n of the asynchronous variance:
`u_dY_theta_um` takes the covariance of the mean from the revolutions' scatter, harmonic by
harmonic (ν = 4 each), and the GUM u of Δθ propagates that covariance through ∫δY exactly
(`error_model_from_results(..., dY_uncertainty="gum")`). A u with ν = 4 is itself uncertain: a
normal error divided by it follows a t-distribution with 4 dof (68 % → 63 %, 95 % → 88 % within 1 and
2 u; the GUM's k for 95 % is 2.78).
"""


POSTSCRIPT = """\
What the numbers say:

- e, θ0, δY and Δθ, with the u the pipeline now reports, cover the synchronous truth at about the
  stated level (within the binomial ± and the t-distribution's 63 % / 88 % for ν = 4); θ0's tails
  are the heaviest (its u divides a ν = 4 estimate by e).
- The d_ref fit's u alone (what the pipeline reported before) covers *this sweep's* truth
  generously (sd z 0.1: the residual is real disk motion at other frequencies, which the truth
  contains too) and the eccentricity of the disk not at all (8 %, 6 % within 1 u).
- δY: the fit covariance alone is right for *these revolutions* (62 % / 94 %) and too small for the
  spindle's synchronous motion (44 % / 72 %); Jia's range method (σ of ONE revolution, not of the
  mean of 3) is too large for the mean at 1 u (79 %) and, estimated from 3 values per angle, has
  heavy tails (|z| 95th percentile 2.4).
- Δθ: GUM (covariance through the integral) and the pipeline's default (Jia's single range-method
  number treated as independent per 1° grid angle) give similar coverage here; the default keeps
  the paper's method.
- Against the twin's TRUE encoder error α the model is off by 1.0″ RMS (28 % within 1 u): the Jia
  model lacks (1 − 1/k) of each k-lobed whirl (docs/hidden-suite.md) — a model error, which the
  comparison with the polygon (residual_before) exposes, not an uncertainty to be inflated.
- Twin caveat: the twin draws the asynchronous motion per repetition label as a function of the
  shaft angle, so the CCD sweep and the polygon sweep (both rep 0) see the same realisation as
  radial-motion revolution 0; on a real bench they would not.
"""


def markdown(summ: dict[str, Any], seeds: list[int]) -> str:
    c, s = summ["coverage"], summ["scalars"]
    lines = [PREAMBLE,
        "| quantity (truth) | n | within 1·u | within 2·u | mean z | sd z | \\|z\\| 68 % / 95 % |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for k, v in c.items():
        lines.append(f"| {k} | {v['n']} | {100 * v['p1']:.0f} ± {100 * v['u_p1']:.0f} % | "
                     f"{100 * v['p2']:.0f} ± {100 * v['u_p2']:.0f} % | {v['z_mean']:+.2f} | {v['z_sd']:.2f} | "
                     f"{v['abs_z_p68']:.2f} / {v['abs_z_p95']:.2f} |")
    lines += [
        "",
        f"Seeds {min(seeds)}…{max(seeds)} ({summ['n_seeds']}); n = seeds × scored angles (δY, Δθ: 8 angles, "
        "0°, 45°, …, 315°; the binomial ± counts seeds only, the angles of one seed being correlated). "
        "A normal error with the right u: 68.3 % and 95.4 %, sd z = 1.",
        "",
        f"Means over the seeds: e − e_sync RMS {s['e_err_sync_um_rms'] * 1e3:.1f} nm (e − this sweep's truth "
        f"{s['e_err_sweep_um_rms'] * 1e3:.2f} nm), u(e) {s['e_u_um_mean'] * 1e3:.1f} nm (fit only "
        f"{s['e_u_fit_um_mean'] * 1e3:.1f} nm); θ0 − θ0_sync RMS {s['theta0_err_sync_deg_rms']:.3f}°, u(θ0) "
        f"{s['theta0_u_deg_mean']:.3f}° (fit only {s['theta0_u_fit_deg_mean']:.3f}°); δY − synchronous truth RMS "
        f"{s['dY_rms_err_sync_um_mean'] * 1e3:.1f} nm (− these revolutions' {s['dY_rms_err_reps_um_mean'] * 1e3:.1f} nm), "
        f"u(δY) {s['dY_rms_u_sync_um_mean'] * 1e3:.1f} nm (GUM fit only {s['dY_rms_u_gum_um_mean'] * 1e3:.1f} nm; "
        f"range method, σ of one revolution {s['dY_u_range_um_mean'] * 1e3:.1f} nm); Δθ − eq. 5 on the synchronous "
        f"truth RMS {s['dtheta_err_arcsec_rms']:.3f}″, u(Δθ) GUM {s['dtheta_u_gum_arcsec_mean']:.3f}″, pipeline "
        f"default {s['dtheta_u_pipeline_arcsec_mean']:.3f}″; model − true α RMS "
        f"{s['dtheta_vs_alpha_rms_arcsec_mean']:.2f}″. Time per seed (one core, shared machine): simulation "
        f"{s['t_sim_s_mean']:.0f} s + image analysis {s['t_analysis_s_mean']:.0f} s, {s['t_total_min']:.0f} min for "
        f"the {summ['n_seeds']} seeds in one process (load average 7-11 on the 2 cores during the run; "
        "~28 s per seed on an idle core).",
        "",
        "![normalised errors](img/coverage_jia.png)",
        "",
        POSTSCRIPT,
    ]
    return "\n".join(lines)


def figure(recs: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    z = normalised_errors(recs)
    keys = [k for k in z if "incl. async" in k or "per harmonic" in k or k.startswith("Δθ (eq. 5 on the synchronous truth; u = GUM")]
    fig, axs = plt.subplots(1, len(keys), figsize=(3.3 * len(keys), 3.2), sharey=False)
    xs = np.linspace(-4, 4, 200)
    for ax, k in zip(axs, keys):
        v = np.clip(np.ravel(z[k]), -4.5, 4.5)
        ax.hist(v, bins=np.linspace(-4.5, 4.5, 19), density=True, color="0.7", edgecolor="0.3")
        ax.plot(xs, np.exp(-xs**2 / 2) / math.sqrt(2 * math.pi), "k-", lw=1)
        name, rest = k.split(" (", 1)
        ax.set_title(name + "\n" + rest.rstrip(")").replace("; ", "\n"), fontsize=7)
        ax.set_xlabel("(estimate − truth) / u")
    axs[0].set_ylabel("density")
    fig.suptitle(f"jia2019, {len(recs)} seeds: normalised errors vs N(0, 1)", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)


# --------------------------------------------------------------------------- CLI

SECTION = "## Jia uncertainty coverage"


def write_section(doc: Path, body: str) -> None:
    text = doc.read_text(encoding="utf-8")
    if SECTION in text:
        head, rest = text.split(SECTION, 1)
        nxt = rest.find("\n## ")
        tail = rest[nxt:] if nxt >= 0 else "\n"
        text = head + SECTION + "\n\n" + body.strip() + "\n" + tail
    else:
        text = text.rstrip("\n") + "\n\n" + SECTION + "\n\n" + body.strip() + "\n"
    doc.write_text(text, encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--first", type=int, default=1000, help="first seed (seeds first … first + n − 1)")
    ap.add_argument("--work", type=Path, default=Path("/tmp/coverage_jia"))
    ap.add_argument("--doc", type=Path, default=None, help="write the table into this markdown file's section")
    ap.add_argument("--fig", type=Path, default=None)
    ap.add_argument("--summary-only", action="store_true")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    recdir = args.work / "records"
    recdir.mkdir(parents=True, exist_ok=True)
    seeds = list(range(args.first, args.first + args.seeds))
    recs = []
    for i, s in enumerate(seeds):
        f = recdir / f"seed_{s:06d}.json"
        if f.exists():
            recs.append(score(json.loads(f.read_text())))
            continue
        if args.summary_only:
            continue
        raw = run_seed(s, args.work)
        f.write_text(json.dumps(raw))
        rec = score(raw)
        recs.append(rec)
        print(f"[{i + 1}/{len(seeds)}] seed {s}: e {rec['e_um']:.4f}±{rec['e_u_um']:.4f} (true {rec['e_true_um']:.4f}) "
              f"θ0 {rec['theta0_deg']:.3f}±{rec['theta0_u_deg']:.3f} (true {rec['theta0_true_deg']:.3f}) "
              f"δY rms err {rec['dY_rms_err_um'] * 1e3:.2f} nm (u {rec['dY_rms_u_gum_um'] * 1e3:.2f}) "
              f"[{rec['t_sim_s']:.0f}+{rec['t_analysis_s']:.0f} s]", flush=True)
    if not recs:
        print("no records", file=sys.stderr)
        return 1
    summ = summarise(recs)
    md = markdown(summ, [r["seed"] for r in recs])
    print(json.dumps(summ, indent=1) if args.json else md)
    if args.fig:
        figure(recs, args.fig)
    if args.doc:
        write_section(args.doc, md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
