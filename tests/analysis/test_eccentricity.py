"""Tests of the CCD eccentricity pipeline (Jia 2019 sec. 4.2, eqs. 10-13) on rendered grating images."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.analysis.eccentricity import (
    CcdSweep,
    ImageAnalysisError,
    ImageOptions,
    d_ref_px,
    eccentricity_from_dref,
    eccentricity_from_images,
    eccentricity_monte_carlo,
    edge_details,
    edge_points,
    fit_circle,
    pixel_scale_um,
)

UM_PER_PX = 0.667  # Jia eq. 13
R_UM = 22500.0  # scale edge radius (scenario jia2019)
R_PX = R_UM / UM_PER_PX
PERIOD_UM = 20.0
E_UM, TH0 = 7.1, 192.08


def _geom(W, H, dref_px, dy_px):
    ref = (W / 2.0, H / 2.0)
    centre = (ref[0] - (R_PX + dref_px), ref[1] + dy_px)
    exact = math.hypot(centre[0] - ref[0], centre[1] - ref[1]) - R_PX
    return ref, centre, exact


def test_full_size_image_d_ref(grating_renderer):
    W, H = 2048, 1536  # Jia's camera; reference point (1024, 768)
    ref, centre, exact = _geom(W, H, 4.37, -55.3)
    img = grating_renderer(W, H, centre, R_PX, PERIOD_UM / UM_PER_PX, phase_rad=2.1e-4)
    res = d_ref_px(img, ref)
    assert res["reference_px"] == (1024.0, 768.0)
    assert res["n_lines"] >= 45
    assert res["polarity"] == "dark"
    assert abs(res["d_ref_px"] - exact) < 0.02
    assert res["residual_rms_px"] < 0.01
    # known radius: the same
    res_r = d_ref_px(img, ref, radius_px=R_PX)
    assert abs(res_r["d_ref_px"] - exact) < 0.02
    # pixel scale: the paper's count (90 px over 3 periods) and the line-spacing estimate
    sc = pixel_scale_um(img, PERIOD_UM)
    assert sc["m_p_px"] == 90 and sc["um_per_px_count"] == pytest.approx(0.6667, abs=1e-4)
    assert sc["um_per_px"] == pytest.approx(UM_PER_PX, rel=5e-5)
    assert abs(sc["um_per_px"] - UM_PER_PX) < 5 * sc["u_um_per_px"] + 1e-6


@pytest.mark.parametrize("dref_px,dy_px,phase", [(3.3, 0.0, 0.0), (-5.71, 37.4, 3e-4), (12.25, -120.0, 7.7e-4)])
def test_crop_d_ref_exact(grating_renderer, dref_px, dy_px, phase):
    W, H = 400, 300
    ref, centre, exact = _geom(W, H, dref_px, dy_px)
    img = grating_renderer(W, H, centre, R_PX, PERIOD_UM / UM_PER_PX, phase_rad=phase)
    res = d_ref_px(img, ref)
    assert abs(res["d_ref_px"] - exact) < 0.02
    assert abs(d_ref_px(img, ref, radius_px=R_PX)["d_ref_px"] - exact) < 0.02
    pts = edge_points(img)
    assert pts.shape == (res["n_lines"], 2) and res["n_lines"] >= 8
    # every middle point lies on the edge circle
    r = np.hypot(res["points_px"][:, 0] - centre[0], res["points_px"][:, 1] - centre[1])
    assert np.max(np.abs(r - R_PX)) < 0.02


def test_bright_lines_colour_and_uint8(grating_renderer):
    W, H = 400, 300
    ref, centre, exact = _geom(W, H, 2.0, 10.0)
    dark = grating_renderer(W, H, centre, R_PX, PERIOD_UM / UM_PER_PX, to_uint8=True)
    bright = grating_renderer(W, H, centre, R_PX, PERIOD_UM / UM_PER_PX, glass=25.0, chrome=210.0, to_uint8=True)
    rd, rb = d_ref_px(dark, ref), d_ref_px(bright, ref)
    assert rd["polarity"] == "dark" and rb["polarity"] == "bright"
    assert abs(rd["d_ref_px"] - exact) < 0.02 and abs(rb["d_ref_px"] - exact) < 0.02
    colour = np.repeat(dark[:, :, None], 3, axis=2)
    assert d_ref_px(colour, ref)["d_ref_px"] == pytest.approx(rd["d_ref_px"], abs=1e-9)


def test_blur_noise_and_dust(grating_renderer):
    W, H = 400, 300
    ref, centre, exact = _geom(W, H, 1.5, -20.0)
    img = grating_renderer(W, H, centre, R_PX, PERIOD_UM / UM_PER_PX, blur_px=1.2, noise=1.0, seed=3, to_uint8=True)
    clean = d_ref_px(img, ref)
    assert abs(clean["d_ref_px"] - exact) < 0.05
    assert clean["u_d_ref_px"] < 0.05
    # dust: dark specks on the glass beyond the edge and on the lines (not on the line ends)
    dusty = img.copy()
    yy, xx = np.mgrid[0:H, 0:W]
    for (x, y, r) in [(300, 40, 4), (350, 200, 3), (250, 260, 5), (80, 150, 4), (330, 120, 2), (120, 30, 3)]:
        dusty[(xx - x) ** 2 + (yy - y) ** 2 <= r * r] = 35
    res = d_ref_px(dusty, ref)
    assert res["edges"].removed_dust >= 4
    assert res["n_lines"] == clean["n_lines"]
    assert res["d_ref_px"] == pytest.approx(clean["d_ref_px"], abs=0.01)
    # a speck on a line end spoils that line's edge: the line is rejected from the circle fit
    x, y = clean["points_px"][3]
    spoilt = img.copy()
    spoilt[(xx - (x + 2)) ** 2 + (yy - (y + 3)) ** 2 <= 9] = 35
    res = d_ref_px(spoilt, ref)
    assert len(res["rejected_points_px"]) == 1 and res["n_lines"] == clean["n_lines"] - 1
    assert abs(res["d_ref_px"] - exact) < 0.05
    assert abs(d_ref_px(spoilt, ref, options=ImageOptions(reject_outliers=False))["d_ref_px"] - exact) > 0.1  # the check has teeth


def test_edge_method_crossing_is_a_variant(grating_renderer):
    W, H = 400, 300
    ref, centre, exact = _geom(W, H, 3.0, 0.0)
    img = grating_renderer(W, H, centre, R_PX, PERIOD_UM / UM_PER_PX)
    a = d_ref_px(img, ref, options=ImageOptions(edge_method="area"))["d_ref_px"]
    c = d_ref_px(img, ref, options=ImageOptions(edge_method="crossing"))["d_ref_px"]
    assert abs(a - exact) < 0.02
    assert abs(c - exact) < 0.15  # linear interpolation of the 50 % crossing: biased on a sharp step


def test_fit_circle_exact_and_covariance():
    rng = np.random.default_rng(7)
    cx, cy = -32700.0, 768.0
    phi = np.linspace(-0.02, 0.02, 40)
    pts = np.column_stack([cx + R_PX * np.cos(phi), cy + R_PX * np.sin(phi)])
    fx, fy, fr, cov = fit_circle(pts)
    assert fx == pytest.approx(cx, abs=1e-4) and fy == pytest.approx(cy, abs=1e-4) and fr == pytest.approx(R_PX, abs=1e-4)
    fx, fy, fr, cov = fit_circle(pts, radius=R_PX)
    assert (fx, fy, fr) == pytest.approx((cx, cy, R_PX), abs=1e-5)
    assert cov[2, 2] == 0.0
    # covariance of d_ref (= l − r) vs Monte Carlo, σ = 0.02 px
    ref = np.array([1024.0, 768.0])
    d_true = math.hypot(cx - ref[0], cy - ref[1]) - R_PX
    D, U = [], []
    for _ in range(300):
        noisy = pts + rng.normal(0, 0.02, pts.shape)
        fx, fy, fr, cov = fit_circle(noisy)
        l = math.hypot(fx - ref[0], fy - ref[1])
        g = np.array([(fx - ref[0]) / l, (fy - ref[1]) / l, -1.0])
        D.append(l - fr)
        U.append(math.sqrt(g @ cov @ g))
    assert np.mean(D) == pytest.approx(d_true, abs=0.005)
    assert np.std(D, ddof=1) == pytest.approx(np.mean(U), rel=0.2)
    with pytest.raises(ValueError):
        fit_circle(pts[:3])


def test_eccentricity_from_dref_camera_azimuth(lab_centre):
    # d_ref from the exact geometry of docs/conventions.md, cameras at 180° and at 150°
    th = np.arange(60) * 6.0
    ref = (200.0, 150.0)
    for psi in (180.0, 150.0, 90.0):
        d = []
        for t in th:
            c = lab_centre(t, E_UM, TH0, R_UM + 2.0, UM_PER_PX, ref, camera_azimuth_deg=psi)
            d.append((math.hypot(c[0] - ref[0], c[1] - ref[1]) - R_PX) * UM_PER_PX)
        out = eccentricity_from_dref(th, np.array(d), camera_azimuth_deg=psi)
        assert out["e_um"] == pytest.approx(E_UM, abs=1e-3)
        assert out["theta0_deg"] == pytest.approx(TH0, abs=0.01)
        assert out["c0_um"] == pytest.approx(2.0, abs=1e-3)
    # d_ref = e cos(θ − θ0) for the camera at 180°: c1 = e sin θ0, d1 = e cos θ0
    out = eccentricity_from_dref(th, E_UM * np.cos(np.radians(th - TH0)))
    assert out["c1_um"] == pytest.approx(E_UM * math.sin(math.radians(TH0)))
    assert out["d1_um"] == pytest.approx(E_UM * math.cos(math.radians(TH0)))
    assert out["coefficients"].order == 10 and out["harmonics_um"].shape == (10,)


def test_monte_carlo_agrees_with_gum():
    rng = np.random.default_rng(17)
    th = np.arange(60) * 6.0
    d = 3.0 + E_UM * np.cos(np.radians(th - TH0)) + 0.3 * np.sin(np.radians(2 * th)) + rng.normal(0, 0.2, th.size)
    mc = eccentricity_monte_carlo(th, d, n=3000, seed=4)
    assert mc["e_std_um"] == pytest.approx(mc["e_u_gum_um"], rel=0.1)
    assert mc["theta0_std_deg"] == pytest.approx(mc["theta0_u_gum_deg"], rel=0.1)
    assert mc["e_mean_um"] == pytest.approx(E_UM, abs=4 * mc["e_u_gum_um"])
    assert mc["theta0_mean_deg"] == pytest.approx(TH0, abs=4 * mc["theta0_u_gum_deg"])


def test_sweep_of_60_images(grating_renderer, lab_centre):
    W, H = 400, 300
    ref = (W / 2.0, H / 2.0)
    th = np.arange(60) * 6.0
    pitch_rad = PERIOD_UM / R_UM
    images = []
    for t in th:
        c = lab_centre(t, E_UM, TH0, R_UM + 2.0, UM_PER_PX, ref)
        # the grating turns with the disk: the lines' phase in the image follows θ
        images.append(grating_renderer(W, H, c, R_PX, PERIOD_UM / UM_PER_PX,
                                       phase_rad=(0.1 + math.radians(t)) % pitch_rad))
    out = eccentricity_from_images(images, th, CcdSweep(period_um=PERIOD_UM, reference_px=ref),
                                   names=[f"ccd/img_{k:03d}.png" for k in range(60)])
    assert out["e_um"] == pytest.approx(E_UM, abs=0.01)
    assert out["theta0_deg"] == pytest.approx(TH0, abs=0.1)
    assert out["e_u_um"] < 0.01 and out["theta0_u_deg"] < 0.1
    assert out["um_per_px"] == pytest.approx(UM_PER_PX, rel=3e-4)
    assert out["um_per_px_count"] == pytest.approx(0.6667, abs=1e-4)
    assert out["c0_um"] == pytest.approx(2.0, abs=0.01)
    assert out["dref_um"].shape == (60,)
    # the paper's fixed scale gives the same answer
    out2 = eccentricity_from_images(images[::2], th[::2], CcdSweep(um_per_px=UM_PER_PX, reference_px=ref, order=5))
    assert out2["e_um"] == pytest.approx(E_UM, abs=0.01)


# --------------------------------------------------------------------------- errors


def test_blank_saturated_black_frames_raise():
    rng = np.random.default_rng(1)
    blank = np.clip(180 + rng.normal(0, 1.0, (300, 400)), 0, 255).astype(np.uint8)
    with pytest.raises(ImageAnalysisError, match=r"img_003\.png.*blank"):
        d_ref_px(blank, name="ccd/img_003.png")
    sat = np.full((300, 400), 255, np.uint8)
    sat[100:115, :150] = 30
    with pytest.raises(ImageAnalysisError, match="saturated"):
        edge_points(sat, name=7)
    with pytest.raises(ImageAnalysisError, match="image #7"):
        edge_points(sat, name=7)
    with pytest.raises(ImageAnalysisError, match="black"):
        edge_points(np.zeros((300, 400), np.uint16))
    assert issubclass(ImageAnalysisError, ValueError)


def test_no_grating_raises():
    # bright glass with dust only
    rng = np.random.default_rng(2)
    img = np.full((300, 400), 200.0)
    yy, xx = np.mgrid[0:300, 0:400]
    for x, y, r in zip(rng.uniform(10, 390, 60), rng.uniform(10, 290, 60), rng.uniform(2, 7, 60)):
        img[(xx - x) ** 2 + (yy - y) ** 2 <= r * r] = 30.0
    with pytest.raises(ImageAnalysisError, match=r"frame_9.*(no grating found|too few edge points)"):
        d_ref_px(img, name="frame_9")
    few = np.full((300, 400), 200.0)
    few[(xx - 200) ** 2 + (yy - 150) ** 2 <= 36] = 30.0
    with pytest.raises(ImageAnalysisError, match=r"frame_9.*no grating"):
        d_ref_px(few, name="frame_9")


def test_too_few_lines_raise(grating_renderer):
    W, H = 400, 110  # about three lines in view
    ref, centre, _ = _geom(W, H, 3.0, 0.0)
    img = grating_renderer(W, H, centre, R_PX, PERIOD_UM / UM_PER_PX)
    with pytest.raises(ImageAnalysisError, match=r"too few edge points: \d usable line ends \(need ≥ 5\)"):
        d_ref_px(img, ref, name="narrow.png")
    # mirrored image: the line ends leave the field on the right → no usable ends
    W, H = 400, 300
    ref, centre, _ = _geom(W, H, 3.0, 0.0)
    img = grating_renderer(W, H, centre, R_PX, PERIOD_UM / UM_PER_PX)
    with pytest.raises(ImageAnalysisError, match="too few edge points"):
        edge_details(np.ascontiguousarray(img[:, ::-1]))


def test_bad_shape_raises():
    with pytest.raises(ImageAnalysisError, match="2-D"):
        edge_points(np.zeros((10, 10, 10, 2)))


def test_range_method_for_repeated_sweeps():
    from benchtwin.analysis.eccentricity import eccentricity_range_method

    # Jia sec. 5: range of e 0.4 µm, of θ0 1.91°, n = 3 → 0.24 µm, 1.13°
    r = eccentricity_range_method([7.0, 7.4, 7.1], [191.0, 192.91, 192.3], d_n=1.69)
    assert r["e_u_um"] == pytest.approx(0.24, abs=0.005)
    assert r["theta0_u_deg"] == pytest.approx(1.13, abs=0.005)
    # θ0 across 0°: the range is taken on the circle
    r = eccentricity_range_method([1.0, 1.0, 1.0], [359.0, 0.5, 1.0])
    assert r["theta0_range_deg"] == pytest.approx(2.0)
    with pytest.raises(ValueError):
        eccentricity_range_method([1.0], [2.0])


# --------------------------------------------------------------------------- robustness (contaminated line ends)


def _noisy(grating_renderer, W=400, H=300, dref=1.5, dy=-20.0):
    ref, centre, exact = _geom(W, H, dref, dy)
    img = grating_renderer(W, H, centre, R_PX, PERIOD_UM / UM_PER_PX, blur_px=1.2, noise=1.0, seed=3, to_uint8=True)
    return img, ref, exact


def _bridge(img, x0, x1, y0, y1, level=35):
    out = img.copy()
    out[int(round(y0)):int(round(y1)) + 1, int(round(x0)):int(round(x1)) + 1] = level
    return out


def test_dust_bridging_two_lines_inside_keeps_both_ends(grating_renderer):
    # twin img_010 of jia2019: a speck bridges two neighbouring lines ~35 px inside their ends; the
    # part then holds two line ends, each still clean
    img, ref, exact = _noisy(grating_renderer)
    clean = d_ref_px(img, ref)
    sc_clean = pixel_scale_um(img, PERIOD_UM)
    (xa, ya), (_, yb) = clean["points_px"][4], clean["points_px"][5]
    dusty = _bridge(img, xa - 40, xa - 33, ya, yb)
    res = d_ref_px(dusty, ref)
    assert res["n_lines"] == clean["n_lines"] and len(res["rejected_points_px"]) == 0
    assert res["d_ref_px"] == pytest.approx(clean["d_ref_px"], abs=0.01)
    sc = pixel_scale_um(dusty, PERIOD_UM)
    assert sc["n_lines"] == sc_clean["n_lines"] and len(sc["rejected_spacing_px"]) == 0
    assert sc["um_per_px"] == pytest.approx(sc_clean["um_per_px"], rel=2e-4)


def test_dust_merging_two_line_ends_is_rejected_not_fatal(grating_renderer):
    # a speck across the gap AT the line ends: the two ends are one blob, rejected as an outlier;
    # the image is still measured, the scale from the regular majority (a missing index is allowed)
    img, ref, exact = _noisy(grating_renderer)
    clean = d_ref_px(img, ref)
    sc_clean = pixel_scale_um(img, PERIOD_UM)
    (xa, ya), (_, yb) = clean["points_px"][4], clean["points_px"][5]
    dusty = _bridge(img, xa - 8, xa - 3, ya, yb)
    res = d_ref_px(dusty, ref)
    assert res["n_lines"] == clean["n_lines"] - 2 and len(res["rejected_points_px"]) == 1
    assert abs(res["d_ref_px"] - exact) < 0.05
    sc = pixel_scale_um(dusty, PERIOD_UM)
    assert sc["n_lines"] == sc_clean["n_lines"] - 2
    assert sc["um_per_px"] == pytest.approx(UM_PER_PX, rel=5e-4)
    # without outlier rejection the merged end is one point between two lines: the old hard failure
    with pytest.raises(ImageAnalysisError, match="line spacing is irregular"):
        pixel_scale_um(dusty, PERIOD_UM, name="dusty.png", options=ImageOptions(reject_outliers=False))


def test_scale_rejects_a_line_centre_shifted_along_the_edge(grating_renderer):
    # a speck in the gap just beside one line end pulls that line's centre row along the edge
    # (invisible to the circle fit, which is radial): the spacing fit rejects that end
    img, ref, exact = _noisy(grating_renderer)
    sc_clean = pixel_scale_um(img, PERIOD_UM)
    clean = d_ref_px(img, ref)
    x, y = clean["points_px"][4]
    dusty = _bridge(img, x - 11, x - 6, y + 7, y + 11)
    sc = pixel_scale_um(dusty, PERIOD_UM)
    assert len(sc["rejected_spacing_px"]) == 1
    assert abs(sc["rejected_spacing_px"][0][1] - y) < 3.0
    assert sc["um_per_px"] == pytest.approx(sc_clean["um_per_px"], rel=2e-4)


def _irregular_grating(W, H, centre, radius_px, ys_px, half_px=6.0, ss=4, glass=200.0, chrome=30.0):
    """Radial lines ending on the edge circle at the given image rows (any spacing), ss² supersampled."""
    cx, cy = centre
    yy, xx = (np.mgrid[0:H * ss, 0:W * ss] + 0.5) / ss - 0.5
    r = np.hypot(xx - cx, yy - cy)
    ang = np.arctan2(yy - cy, xx - cx)
    cover = np.zeros_like(r, dtype=bool)
    for y in ys_px:
        a = math.atan2(y - cy, math.sqrt(radius_px**2 - (y - cy) ** 2))
        cover |= np.abs(ang - a) * radius_px < half_px
    cover &= (r <= radius_px) & (r >= radius_px - 300)
    c = cover.reshape(H, ss, W, ss).mean(axis=(1, 3))
    return glass + (chrome - glass) * c


def test_irregular_spacing_is_never_a_scale():
    # lines ending on a circle but at random spacings: d_ref is measurable (it needs no pitch),
    # the pixel scale is not, and must raise rather than return garbage
    W, H = 400, 300
    ref, centre, exact = _geom(W, H, 2.0, 0.0)
    rng = np.random.default_rng(11)
    ys = 12.0 + np.cumsum(rng.uniform(20.0, 48.0, 12))
    ys = ys[ys < H - 12]
    img = _irregular_grating(W, H, centre, R_PX, ys)
    res = d_ref_px(img, ref)
    assert res["n_lines"] == ys.size and abs(res["d_ref_px"] - exact) < 0.05
    with pytest.raises(ImageAnalysisError, match=r"irr\.png.*line spacing is irregular"):
        pixel_scale_um(img, PERIOD_UM, name="irr.png")
    # the same renderer with regular spacing gives the scale (the check has teeth)
    ys_reg = 12.0 + 30.0 * np.arange(9)
    sc = pixel_scale_um(_irregular_grating(W, H, centre, R_PX, ys_reg), PERIOD_UM)
    assert sc["n_lines"] == 9 and sc["pitch_px"] == pytest.approx(30.0, abs=0.05)


def test_lab_centre_helper_follows_conventions(lab_centre):
    # docs/conventions.md: at ψ = 180° image +y is lab +X for tangential "+x" (−X for "-x"); a disk
    # centre on lab +X (polar 0° = 90° − θ0 + t with θ0 = 90°, t = 0) is below the reference row
    ref = (200.0, 150.0)
    x, y = lab_centre(0.0, 6.67, 90.0, R_UM, UM_PER_PX, ref)
    assert x == pytest.approx(ref[0] - R_PX) and y == pytest.approx(ref[1] + 10.0)
    x, y = lab_centre(0.0, 6.67, 90.0, R_UM, UM_PER_PX, ref, tangential_sign=-1.0)
    assert y == pytest.approx(ref[1] - 10.0)
    # camera at 90° (on −X): u = −X, image +y = ẑ × u = −Y; a centre on lab +Y (θ0 = 0) is above
    x, y = lab_centre(0.0, 6.67, 0.0, R_UM, UM_PER_PX, ref, camera_azimuth_deg=90.0)
    assert x == pytest.approx(ref[0] - R_PX) and y == pytest.approx(ref[1] - 10.0)


def _sweep_fits(e_um: float, theta0_deg: float, noise_um: float, n_sweeps: int, whirl_um: float, seed: int):
    """n sweeps of 60 frames: d_ref = e·cos(θ − θ0') + a whirl of the sweep's own (the asynchronous
    first harmonic, different per sweep) + per-frame noise, fitted by eccentricity_from_dref."""
    from benchtwin.analysis.eccentricity import eccentricity_from_dref

    rng = np.random.default_rng(seed)
    th = np.arange(60) * 6.0
    fits = []
    for _ in range(n_sweeps):
        a, b = rng.normal(0.0, whirl_um, 2)
        d = (e_um * np.cos(np.radians(th - theta0_deg)) + a * np.sin(np.radians(th)) + b * np.cos(np.radians(th))
             + rng.normal(0.0, noise_um, th.size) + 3.0)
        fits.append(eccentricity_from_dref(th, d, camera_azimuth_deg=180.0))
    return fits


def test_repeated_sweeps_type_a_u_of_the_mean():
    """eccentricity_from_sweeps: e is the mean first-harmonic vector; u(e) = s/√n of the mean; s is
    σ of one sweep (Jia's σ_e), and it carries the asynchronous whirl that each sweep's own fit
    cannot see (the fit's u stays the noise's)."""
    from benchtwin.analysis.eccentricity import eccentricity_from_sweeps

    whirl = 0.2
    s_all, e_all, u_all, ufit = [], [], [], []
    for seed in range(400):
        r = eccentricity_from_sweeps(_sweep_fits(7.1, 192.08, 0.02, 3, whirl, seed))
        s_all.append(r["e_sweep_sd_um"])
        e_all.append(r["e_um"])
        u_all.append(r["e_u_um"])
        ufit.append(r["e_u_fit_um"])
        assert r["n_sweeps"] == 3 and r["dof"] == 2 and len(r["e_sweeps_um"]) == 3
        assert r["e_u_um"] >= r["e_u_fit_um"]
    # σ of one sweep: s² is unbiased for the whirl's variance along e (+ the fit noise)
    sig1 = math.hypot(whirl, 0.02 * math.sqrt(2 / 60))
    assert np.sqrt(np.mean(np.square(s_all))) == pytest.approx(sig1, rel=0.06)
    # the mean of 3 sweeps scatters by σ/√3, which u(e) states on average (floored s: slightly above)
    assert np.std(e_all) == pytest.approx(sig1 / math.sqrt(3), rel=0.1)
    assert np.sqrt(np.mean(np.square(u_all))) == pytest.approx(sig1 / math.sqrt(3), rel=0.1)
    assert np.mean(ufit) < 0.05 * sig1       # the per-sweep fit alone would miss the whirl
    assert np.mean(e_all) == pytest.approx(7.1, abs=0.01)


def test_repeated_sweeps_phase_floor_and_errors():
    from benchtwin.analysis.eccentricity import eccentricity_from_sweeps

    # no whirl: the scatter of 3 sweeps is the noise's; u never falls below the fits' pooled u
    fits = _sweep_fits(7.1, 359.9, 0.05, 3, 0.0, 1)
    r = eccentricity_from_sweeps(fits)
    assert r["e_u_um"] >= r["e_u_fit_um"] and r["theta0_u_deg"] >= r["theta0_u_fit_deg"]
    assert min(abs(r["theta0_deg"] - 359.9), abs(r["theta0_deg"] + 0.1)) < 0.1   # θ0 across 0°: circular
    assert r["theta0_sweep_sd_deg"] < 0.2
    assert r["e_range_u_um"] == pytest.approx(np.ptp(r["e_sweeps_um"]) / 1.693)
    assert "type A" in r["u_source"]
    with pytest.raises(ValueError, match="≥ 2 sweeps"):
        eccentricity_from_sweeps(fits[:1])
    bad = [dict(fits[0]), dict(fits[1], camera_azimuth_deg=90.0)]
    with pytest.raises(ValueError, match="camera azimuths"):
        eccentricity_from_sweeps(bad)


def test_a_thin_scratch_end_is_not_a_line_end():
    # Seed 660 of issue 32's validation, img_008: a thin scratch joined to the grating was segmented
    # as a line end (its pixels beyond the frame's threshold), but the level measured lev pixels
    # inside it was glass, a few grey levels either side of it: the line level's median equalled the
    # glass level (177.25), the chrome fraction divided by zero and the end became a NaN point that
    # cost the frame. A line end's measured line level must lie beyond the frame's threshold.
    from benchtwin.analysis.eccentricity import _measure_end

    hw, lev, xb0 = ImageOptions().half_window_px, 6, 40
    grey = np.full((32, 80), 177.0)
    ys = np.arange(10, 22)
    xb = np.full(ys.size, xb0)
    grey[ys, xb0 - 1:xb0 + 1] = 30.0  # the scratch: 2 px of "line", then glass again inside it
    c_cols = xb0 - hw - 1 - np.arange(lev)
    for i, y in enumerate(ys):
        grey[y, c_cols] = 175.0 if i % 2 else 179.0  # glass either side of 177: median 177 = G
    with np.errstate(all="raise"):
        assert _measure_end(grey, ys, xb, int(hw), lev, "area", threshold=103.5) is None
    # a real line end (line level 30 inside, beyond the threshold) is still measured
    grey_line = np.full((32, 80), 177.0)
    grey_line[ys, : xb0 + 1] = 30.0
    m = _measure_end(grey_line, ys, xb, int(hw), lev, "area", threshold=103.5)
    assert m is not None and np.all(np.isfinite(m[:2])) and m[0] == pytest.approx(xb0 + 0.5, abs=0.01)
