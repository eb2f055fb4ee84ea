"""Issue 4 acceptance on twin images: the Jia 2019 sec. 4.2 image pipeline against the twin's truth.

Frames are rendered directly with the twin's own instruments (``sim_build``: the physics bench, the
servo stage that stops where head 1 reads θ, the CCD camera + sensor), 60 stops every 6° as in
``P.ccd_sweep``; the sensor noise is keyed per frame exactly as the runner keys it. The analytic
renderer (exact pixel coverage, no OpenGL; it agrees with the GL backend to ≤ 0.02 px, see
tests/twin/test_render.py) keeps a 60-frame sweep at ~9 s.

Truth per frame is what ``twin/simulate.py`` writes to ``truth/ccd.csv``: the disk's geometric
centre ``centre_px`` and the edge radius ``edge_radius_px`` in true pixels; d_ref_true =
|centre − R| − edge_radius. The reference for e and θ0 is the eq. 10–12 Fourier fit of d_ref_true
(µm, true pixel): the first harmonic of the disk centre under the camera, i.e. the installation
eccentricity PLUS the twin's once-per-revolution axis motion (≈ 0.06–0.1 µm, seed dependent), which
the CCD method cannot separate from e (neither can the encoder). The declared scenario values
(7.1 µm, 192.08°) are therefore not the reference.

The analysis never sees the truth: it gets the image, the manifest's reference point and the
grating period (at the edge radius, the twin's convention).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.analysis import eccentricity as ecc

BACKEND = "analytic"
STEP_DEG = 6.0
N_IMAGES = 60
PERIOD_UM = 20.0  # manifest bench.grating_period_um (jia2019)
NOISE_FREE = {"read_noise_e": 0.0, "dust_count": 0, "scratch_count": 0, "full_well_e": 1e12, "bit_depth": 16}


def _sweep(seed: int | None, ks, sensor_kw: dict | None = None):
    """(scenario, [(theta_deg, image, truth)]) for the stops k·6° of a jia2019 bench."""
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import sim_build

    sc = load_scenario()
    if seed is not None:
        sc = sc.with_overrides({"scenario.seed": seed})
    _, state, inst = sim_build(sc, BACKEND)
    stage, cam = inst["stage"], inst["ccd"]
    if sensor_kw:
        cam.sensor = cam.sensor.replace(**sensor_kw)
    state.apply_context({"rep": 0, "direction": "forward"})
    frames = []
    try:
        for k in ks:
            state.on_step(int(k), None, {}, False)  # noise stream keyed by the step, as in the runner
            stage.move_to(k * STEP_DEG)
            r = cam.capture()
            # the frame's centre without the microscope stand's vibration (twin/vibration.py: the
            # disk seen moved by −(δr, δt)), for the conventions check below
            vr, vt = cam.vibration_m()
            u = cam.camera.axes_lab()[0]
            t = np.array([-u[1], u[0], 0.0])
            still = cam.camera.lab_to_px(cam.disk_seen().pos + vr * u + vt * t, cam.grating.edge_radius_m)
            frames.append((k * STEP_DEG, r["image"], {**cam.last_truth, "centre_still_px": [float(v) for v in still]}))
    finally:
        cam.close()
    return sc, frames


def _dref_true(tr: dict) -> float:
    (cx, cy), (rx, ry) = tr["centre_px"], tr["reference_px"]
    return math.hypot(cx - rx, cy - ry) - tr["edge_radius_px"]


# --------------------------------------------------------------------------- noise-free: d_ref per image


def test_noise_free_frames_d_ref_within_0p02_px():
    # every 24° (15 frames round the circle): blur and vignetting kept (deterministic), no noise,
    # no dust, 16-bit
    sc, frames = _sweep(None, range(0, N_IMAGES, 4), NOISE_FREE)
    errs = []
    for th, img, tr in frames:
        assert img.dtype == np.uint16
        res = ecc.d_ref_px(img, tr["reference_px"], name=f"θ={th:g}°")
        assert res["n_lines"] >= 40 and len(res["rejected_points_px"]) == 0
        errs.append(res["d_ref_px"] - _dref_true(tr))
    errs = np.asarray(errs)
    print(f"noise-free d_ref − truth: max |err| {np.max(np.abs(errs)):.4f} px, mean {errs.mean():+.4f} px")
    assert np.max(np.abs(errs)) < 0.02
    # the pixel scale on the same frames: the period is at the edge radius (twin: N = round(2πR/p)
    # lines, true period at the edge 2πR/N = p·(1 − 5.9e-5)); a period taken at the optical radius
    # (22 mm) would be 2.2 % off
    # (each frame's scale scatters by ±5e-6 with the lines in view, i.e. with where the servo holds
    # the count: 1.0e-5 … 2.2e-5 low on jia2019's 15 frames; the mean over the sweep is the claim)
    n_lines = round(2 * math.pi * 22500.0 / PERIOD_UM)
    p_edge_true = 2 * math.pi * 22500.0 / n_lines
    rel = []
    for _, image, tr in frames:
        sc_ = ecc.pixel_scale_um(image, PERIOD_UM)
        assert len(sc_["rejected_spacing_px"]) == 0
        assert sc_["pixel_um"] == pytest.approx(tr["pixel_um"], rel=1e-4)
        rel.append(sc_["pixel_um"] / (tr["pixel_um"] * PERIOD_UM / p_edge_true) - 1.0)
    assert max(abs(r) for r in rel) < 3e-5
    assert abs(float(np.mean(rel))) < 2e-5


# --------------------------------------------------------------------------- realistic sensor: e, θ0


def _conftest_helper():
    from tests.support.grating import lab_to_image_centre

    return lab_to_image_centre


# None: the scenario's own seed (20190819). ~18 s per seed (render 9 s + analysis 9 s): the other
# two seeds run with -m slow, to keep the default run of this file under a minute
SEEDS = [None, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)]


@pytest.mark.parametrize("seed", SEEDS, ids=lambda s: f"seed={s if s is not None else 'jia2019'}")
def test_realistic_sweep_recovers_e_and_theta0(seed):
    sc, frames = _sweep(seed, range(N_IMAGES))
    th = np.array([f[0] for f in frames])
    ref = frames[0][2]["reference_px"]
    # analysis: d_ref per image (the manifest's reference point), the scale from the period at the
    # edge radius, median over every 12th image
    dref = np.array([ecc.d_ref_px(img, ref, name=f"img_{k:03d}.png")["d_ref_px"] for k, (_, img, _) in enumerate(frames)])
    scales = [ecc.pixel_scale_um(frames[k][1], PERIOD_UM, name=f"img_{k:03d}.png") for k in range(0, N_IMAGES, 12)]
    um = float(np.median([s["pixel_um"] for s in scales]))
    out = ecc.eccentricity_from_dref(th, dref * um, camera_azimuth_deg=180.0)
    # truth: the same fit on the true d_ref in true µm
    d_true = np.array([_dref_true(f[2]) for f in frames])
    pix_true = frames[0][2]["pixel_um"]
    ref_fit = ecc.eccentricity_from_dref(th, d_true * pix_true)
    err_px = dref - d_true
    de = out["e_um"] - ref_fit["e_um"]
    dth = (out["theta0_deg"] - ref_fit["theta0_deg"] + 180.0) % 360.0 - 180.0
    print(f"seed {sc.seed}: e {out['e_um']:.4f} µm (truth {ref_fit['e_um']:.4f}, declared 7.1), θ0 "
          f"{out['theta0_deg']:.3f}° (truth {ref_fit['theta0_deg']:.3f}°, declared 192.08°); d_ref − truth "
          f"mean {err_px.mean():+.4f} px, RMS {np.sqrt(np.mean(err_px**2)):.4f} px, max {np.max(np.abs(err_px)):.4f} px; "
          f"scale {um:.6f} µm/px")
    assert abs(de) < 0.05
    assert abs(dth) < 0.2
    # and per image: realistic noise, dust and scratches still within 0.05 px of the truth
    assert np.max(np.abs(err_px)) < 0.05
    assert um == pytest.approx(pix_true, rel=2e-4)
    # conventions: the analysis tests' lab → image helper (tests/analysis/conftest.py) agrees with
    # the twin's camera on where the disk centre is (image +y = lab +X at 180°), to the twin's axis
    # motion (bearing waviness, ~0.7 µm peak to peak ≈ 1 px); the opposite tangential sign is ~20 px off
    helper = _conftest_helper()
    true_c = np.array([f[2]["centre_still_px"] for f in frames])   # the vibration (±1.8 px per frame) removed
    for sign, lo, hi in ((+1.0, 0.0, 1.0), (-1.0, 10.0, np.inf)):
        hc = np.array([helper(t, ref_fit["e_um"], ref_fit["theta0_deg"], 22500.0, pix_true, tuple(ref),
                              tangential_sign=sign) for t in th])
        assert np.max(np.abs(hc[:, 0] - true_c[:, 0])) < 1.0
        assert lo <= np.max(np.abs(hc[:, 1] - true_c[:, 1])) < hi


# --------------------------------------------------------------------------- the dataset itself


@pytest.mark.slow
def test_simulated_jia2019_dataset_every_image_analysed(datasets):
    """The reported failure: ``simulate(jia2019)`` → img_010.png (a dust speck bridging two lines near
    their ends) was rejected ("line spacing is irregular"). Every image must now give d_ref within
    0.05 px of truth/ccd.csv and a pixel scale from the regular majority of line spacings (~35 s)."""
    import csv
    import json

    import cv2

    from benchtwin.twin.scenario import load_scenario

    ds = datasets.dataset(load_scenario(), backend=BACKEND)   # the run's default jia2019 (tests/twin/test_simulate.py's)
    man = json.loads((ds / "manifest.json").read_text())
    ref, period = man["ccd"]["reference_px"], man["bench"]["grating_period_um"]
    idx = list(csv.DictReader(open(ds / "ccd" / "index.csv")))
    truth = {int(r["k"]): r for r in csv.DictReader(open(ds / "truth" / "ccd.csv"))}
    th, dref, d_true, scales = [], [], [], []
    for row in idx:
        img = cv2.imread(str(ds / "ccd" / row["file"]), cv2.IMREAD_UNCHANGED)
        r = ecc.d_ref_px(img, ref, name=row["file"])
        scales.append(ecc.pixel_scale_um(img, period, name=row["file"])["pixel_um"])
        t = truth[int(row["k"])]
        th.append(float(row["theta_deg"]))
        dref.append(r["d_ref_px"])
        d_true.append(math.hypot(float(t["centre_x_px"]) - ref[0], float(t["centre_y_px"]) - ref[1])
                      - float(t["edge_radius_px"]))
    err = np.asarray(dref) - np.asarray(d_true)
    assert np.max(np.abs(err)) < 0.05
    assert np.ptp(scales) < 1e-4 and np.median(scales) == pytest.approx(0.667, rel=2e-4)
    out = ecc.eccentricity_from_dref(np.asarray(th), np.asarray(dref) * np.median(scales))
    ref_fit = ecc.eccentricity_from_dref(np.asarray(th), np.asarray(d_true) * 0.667)
    assert abs(out["e_um"] - ref_fit["e_um"]) < 0.05
    assert abs((out["theta0_deg"] - ref_fit["theta0_deg"] + 180.0) % 360.0 - 180.0) < 0.2
