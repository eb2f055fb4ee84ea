"""CCD microscope renderer (Jia 2019 sec. 4.2): geometry truth, GL vs exact coverage, sensor model.

Edges are measured here by methods independent of the renderer: the 50 % crossing of row profiles
across each line end (linear interpolation), and for truth checks the area method (the edge of a
box-integrated step is where the summed coverage says it is). Frames are 512×384 px except one
full-size 2048×1536 frame, to keep the file well under a minute.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.twin.pose import BodyPose
from benchtwin.twin.render import CcdCamera, GratingSpec, Renderer, SensorParams, render_ccd
from benchtwin.twin.render.analytic import coverage_image, polygon_pixel_area
from benchtwin.twin.render.grating import build_scene
from benchtwin.twin.render.gl import gl_status
from benchtwin.twin.render.sensor import apply_sensor

from tests.support.gl import GL, needs_gl

GRATING = GratingSpec(period_m=20e-6, duty=0.5, line_length_m=1.2e-3, edge_radius_m=22.5e-3)
SMALL = dict(width_px=512, height_px=384)


def rot(axis: str, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    if axis == "z":
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    if axis == "x":
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    raise ValueError(axis)


def pose(t_rad: float, pos_um=(0.0, 0.0, 0.0), tilt_rad: float = 0.0) -> BodyPose:
    return BodyPose(pos=np.asarray(pos_um, float) * 1e-6, R=rot("x", tilt_rad) @ rot("z", t_rad))


def crossing_ends(cov: np.ndarray, ends_px: np.ndarray, half_rows: int = 4) -> np.ndarray:
    """Mean 50 % crossing x over the rows around each line end's midpoint (nan if not in view)."""
    h, w = cov.shape
    out = np.full(len(ends_px), np.nan)
    for i, (xm, ym) in enumerate(ends_px):
        yc, x0 = int(round(ym)), int(math.floor(xm)) - 6
        if not (half_rows + 2 <= yc < h - half_rows - 2 and 0 <= x0 and x0 + 13 < w):
            continue
        xs = []
        for y in range(yc - half_rows, yc + half_rows + 1):
            seg = cov[y, x0:x0 + 13]
            j = np.flatnonzero((seg[:-1] >= 0.5) & (seg[1:] < 0.5))
            if len(j) != 1:
                break
            j = j[0]
            xs.append(x0 + j + (seg[j] - 0.5) / (seg[j] - seg[j + 1]))
        else:
            out[i] = np.mean(xs)
    return out


def area_end(cov: np.ndarray, x_in: int, y: int, x_out: int) -> float:
    """Area-method edge along row y: the chrome runs from x_in (fully covered) to the edge."""
    return x_in - 0.5 + float(cov[y, x_in:x_out].sum())


def area_ends(cov: np.ndarray, ends_px: np.ndarray, half_rows: int = 4) -> np.ndarray:
    """Mean area-method end position over the rows around each line end (nan if not in view).
    Unlike the 50 % crossing, exact (slope 1) for a box-integrated step."""
    h, w = cov.shape
    out = np.full(len(ends_px), np.nan)
    for i, (xm, ym) in enumerate(ends_px):
        yc, x0 = int(round(ym)), int(math.floor(xm)) - 8
        if half_rows <= yc < h - half_rows and 0 <= x0 and x0 + 17 < w:
            out[i] = np.mean([area_end(cov, x0, y, x0 + 17) for y in range(yc - half_rows, yc + half_rows + 1)])
    return out


@pytest.fixture(scope="module")
def gl_renderer():
    if not GL:
        pytest.skip(f"no OpenGL context: {gl_status()}")
    r = Renderer(backend="pyrender")
    yield r
    r.close()


# ------------------------------------------------------------------ geometry / analytic (no GL)


def test_pixel_area_is_exact():
    rng = np.random.default_rng(3)
    from scipy.spatial import ConvexHull

    pts = rng.uniform(0.0, 5.0, (9, 2))
    poly = pts[ConvexHull(pts).vertices]
    px, py = np.meshgrid(np.arange(6.0), np.arange(6.0))
    area = polygon_pixel_area(poly, px.ravel(), py.ravel())
    shoelace = 0.5 * abs(np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1]))
    assert area.sum() == pytest.approx(shoelace, abs=1e-12)
    # a half-plane cut of one pixel: x ≤ 0.3 inside the pixel centred at 0 → 0.8
    sq = np.array([[-5.0, -5.0], [0.3, -5.0], [0.3, 5.0], [-5.0, 5.0]])
    assert polygon_pixel_area(sq, np.array([0.0]), np.array([0.0]))[0] == pytest.approx(0.8, abs=1e-15)


def test_truth_centre_follows_pose_and_conventions():
    cam = CcdCamera(azimuth_rad=math.pi, **SMALL)
    ex, ey = 5.0, -3.0  # µm
    scene = build_scene(pose(0.2, (ex, ey, 0.0)), GRATING, cam)
    a = cam.true_pixel_m
    # camera at 180°: image +x = −Y (outward), image +y = +X (tangential "+x")
    x_expect = 256.0 + (-ey * 1e-6 - GRATING.edge_radius_m) / a
    y_expect = 192.0 + ex * 1e-6 / a
    assert scene.centre_px == pytest.approx((x_expect, y_expect), abs=1e-9)
    # "-x" mirrors y; a pixel-scale error scales distances
    cam2 = CcdCamera(azimuth_rad=math.pi, tangential="-x", pixel_scale_error=1e-3, **SMALL)
    sc2 = build_scene(pose(0.2, (ex, ey, 0.0)), GRATING, cam2)
    assert sc2.centre_px[1] - 192.0 == pytest.approx(-(y_expect - 192.0) / 1.001, rel=1e-12)
    assert sc2.edge_radius_px == pytest.approx(GRATING.edge_radius_m / (a * 1.001), rel=1e-12)


@pytest.mark.parametrize("psi_deg", [0.0, 90.0, 180.0, 250.0])
def test_camera_axes_any_azimuth(psi_deg):
    """Image +x radially outward at the camera, image +y along ẑ × u ("+x" tangential)."""
    cam = CcdCamera(azimuth_rad=math.radians(psi_deg), **SMALL)
    a = cam.true_pixel_m
    sc = build_scene(pose(0.0), GRATING, cam)
    assert sc.centre_px == pytest.approx((256.0 - GRATING.edge_radius_m / a, 192.0), abs=1e-6)
    u = np.array([math.cos(math.radians(90 + psi_deg)), math.sin(math.radians(90 + psi_deg)), 0.0])
    tang = np.cross([0.0, 0.0, 1.0], u)
    moved = build_scene(pose(0.0, tuple(1.0 * u + 2.0 * tang)), GRATING, cam)  # µm
    assert moved.centre_px[0] - sc.centre_px[0] == pytest.approx(1e-6 / a, rel=1e-9)
    assert moved.centre_px[1] - sc.centre_px[1] == pytest.approx(2e-6 / a, rel=1e-9)


def test_analytic_edges_lie_on_truth_circle():
    cam = CcdCamera(azimuth_rad=math.pi, **SMALL)
    p = pose(1.234, (6.0, -4.0, 0.0))
    scene = build_scene(p, GRATING, cam)
    cov = coverage_image(scene.polygons, 512, 384, cam.reference_px)
    cx, cy = scene.centre_px
    R = scene.edge_radius_px
    n = 0
    for xm, ym in scene.end_mid_px:
        y = int(round(ym))
        if not (3 <= y < 381):
            continue
        xe = area_end(cov, int(xm) - 8, y, int(xm) + 8)
        assert math.hypot(xe - cx, y - cy) == pytest.approx(R, abs=2e-3)
        n += 1
    assert n >= 10


# ------------------------------------------------------------------ GL backend


@pytest.mark.render
@needs_gl
@pytest.mark.parametrize("t_rad, pos_um, tilt_rad, cam_rot", [
    (0.0, (0.0, 0.0, 0.0), 0.0, 0.0),
    (0.777, (7.1, -3.0, 0.2), 0.0, 0.003),
    (2.5, (-4.0, 6.0, 0.0), 2e-4, -0.01),
])
def test_gl_and_analytic_agree_on_line_ends(gl_renderer, t_rad, pos_um, tilt_rad, cam_rot):
    cam = CcdCamera(azimuth_rad=math.pi, rotation_rad=cam_rot, **SMALL)
    p = pose(t_rad, pos_um, tilt_rad)
    cov_gl, scene, used = gl_renderer.coverage(p, GRATING, cam)
    assert used == "pyrender"
    cov_an = coverage_image(scene.polygons, 512, 384, cam.reference_px)
    e_gl = crossing_ends(cov_gl, scene.end_mid_px)
    e_an = crossing_ends(cov_an, scene.end_mid_px)
    ok = ~np.isnan(e_gl) & ~np.isnan(e_an)
    assert ok.sum() >= 10
    assert np.max(np.abs(e_gl[ok] - e_an[ok])) <= 0.02
    # the whole image: only edge pixels differ, by the body's quarter-pixel MSAA quantisation
    # improved by the jitter passes (≤ 1/16 px of a side)
    assert np.mean(np.abs(cov_gl - cov_an)) < 2e-3


@pytest.mark.render
@needs_gl
def test_gl_resolves_a_005px_shift(gl_renderer):
    cam = CcdCamera(azimuth_rad=math.pi, **SMALL)
    a = cam.true_pixel_m
    base = pose(0.4, (0.0, 0.0, 0.0))
    # 0.05 px outward (image +x = lab −Y at 180°)
    moved = pose(0.4, (0.0, -0.05 * a * 1e6, 0.0))
    c0, s0, _ = gl_renderer.coverage(base, GRATING, cam)
    c1, s1, _ = gl_renderer.coverage(moved, GRATING, cam)
    e0, e1 = area_ends(c0, s0.end_mid_px), area_ends(c1, s1.end_mid_px)
    ok = ~np.isnan(e0) & ~np.isnan(e1)
    d = e1[ok] - e0[ok]
    assert np.mean(d) == pytest.approx(0.05, abs=0.002)
    assert np.max(np.abs(d - 0.05)) < 0.005


@pytest.mark.render
@needs_gl
def test_full_size_frame_matches_truth(gl_renderer):
    ccd = {"width": 2048.0, "height": 1536.0, "pixel_pitch": 0.667e-6, "bit_depth": 8, "numerical_aperture": 0.1,
           "defocus": 0.0, "vignetting": 0.15, "full_well": 20000.0, "read_noise": 12.0, "exposure": 0.7,
           "dust_count": 6, "scratch_count": 1, "rotation": 0.0, "pixel_scale_error": 0.0}
    sensor = SensorParams.from_section(ccd)
    cam = sensor.camera(math.pi)
    p = pose(math.radians(192.0), (7.1, 0.0, 0.0))
    frame = gl_renderer.render(p, GRATING, cam, sensor, np.random.default_rng(5))
    img = frame.image
    assert img.shape == (1536, 2048) and img.dtype == np.uint8
    t = frame.truth
    assert t["reference_px"] == (1024.0, 768.0)
    assert t["pixel_um"] == pytest.approx(0.667)
    assert t["edge_radius_px"] == pytest.approx(22.5e3 / 0.667)
    assert t["centre_px"] == pytest.approx((1024.0 - 22.5e3 / 0.667, 768.0 + 7.1 / 0.667))
    # the image shows the edge where the truth circle says: columns left of the edge alternate
    # dark/bright (lines), right of it they are bright glass
    grey = img.astype(float)
    xe = t["centre_px"][0] + t["edge_radius_px"]
    left = grey[100:1400, int(xe) - 40]
    right = grey[100:1400, int(xe) + 40]
    assert left.min() < 0.3 * right.mean() and np.percentile(right, 5) > 0.7 * right.mean()
    # period at the edge: 20 µm / 0.667 µm ≈ 30 px (Jia: 3 periods = 90 px)
    spec = np.abs(np.fft.rfft(left - left.mean()))
    f = np.argmax(spec[5:]) + 5
    assert len(left) / f == pytest.approx(20 / 0.667, rel=0.03)


# ------------------------------------------------------------------ sensor model


def _flat_sensor(**kw) -> SensorParams:
    base = dict(width_px=256, height_px=256, bit_depth=16, numerical_aperture=0.0, vignetting=0.0,
                full_well_e=20000.0, read_noise_e=12.0, exposure=1.0, dust_count=0, scratch_count=0)
    base.update(kw)
    return SensorParams(**base)


@pytest.mark.parametrize("signal, read_e", [(0.5, 12.0), (0.002, 3.0), (0.3, 0.0)])
def test_noise_statistics(signal, read_e):
    s = _flat_sensor(read_noise_e=read_e)
    img = apply_sensor(np.full((256, 256), signal), s, np.random.default_rng(11)).astype(float)
    g = s.max_dn / s.full_well_e
    lam = signal * s.exposure * s.full_well_e
    assert img.mean() == pytest.approx(g * lam, rel=0.01, abs=0.5)
    var_expect = g * g * (lam + read_e ** 2) + 1.0 / 12.0
    assert img.var() == pytest.approx(var_expect, rel=0.03)  # 65536 samples: σ_rel(var) ≈ 0.6 %


def test_saturation_and_bit_depth():
    irr = np.full((64, 64), 1.0)
    for bits, dtype in ((8, np.uint8), (12, np.uint16), (16, np.uint16)):
        s = _flat_sensor(width_px=64, height_px=64, bit_depth=bits, exposure=1.5)
        img = apply_sensor(irr, s, np.random.default_rng(1))
        assert img.dtype == dtype
        assert np.all(img == 2 ** bits - 1)  # 30 000 e⁻ on a 20 000 e⁻ well: clipped
    s = _flat_sensor(width_px=64, height_px=64, bit_depth=12, exposure=0.5)
    img = apply_sensor(np.linspace(0, 1, 64 * 64).reshape(64, 64), s, np.random.default_rng(1))
    assert img.max() <= 4095 and img.max() > 1800


def test_dust_and_scratches_present():
    s = _flat_sensor(width_px=512, height_px=512, bit_depth=8, read_noise_e=5.0, exposure=0.7,
                     dust_count=20, scratch_count=2)
    img = apply_sensor(np.ones((512, 512)), s, np.random.default_rng(2)).astype(float)
    clean = apply_sensor(np.ones((512, 512)), s.replace(dust_count=0, scratch_count=0),
                         np.random.default_rng(2)).astype(float)
    thr = clean.mean() - 8 * clean.std()
    assert np.sum(clean < thr) == 0
    import cv2

    n, _, stats, _ = cv2.connectedComponentsWithStats((img < thr).astype(np.uint8))
    sizes = stats[1:, cv2.CC_STAT_AREA]
    assert n - 1 >= 5  # specks (some may merge or be too faint/small to pass 8σ)
    assert sizes.max() > 10 * max(1, np.median(sizes))  # several sizes: a scratch or lint among specks


def test_same_seed_same_image_and_from_section():
    ccd = {"width": 512.0, "height": 384.0, "pixel_pitch": 0.667e-6, "bit_depth": 12, "numerical_aperture": 0.1,
           "defocus": 2e-6, "vignetting": 0.15, "full_well": 20000.0, "read_noise": 12.0, "exposure": 0.7,
           "dust_count": 6, "scratch_count": 1, "rotation": 0.001, "pixel_scale_error": 1e-4}
    s = SensorParams.from_section(ccd)
    assert (s.width_px, s.bit_depth, s.dust_count) == (512, 12, 6) and s.defocus_m == 2e-6
    with pytest.raises(ValueError):
        SensorParams.from_section({**ccd, "bogus": 1})
    cam = s.camera(math.pi)
    assert cam.rotation_rad == 0.001 and cam.true_pixel_m == pytest.approx(0.667e-6 * 1.0001)
    p = pose(0.3, (2.0, 1.0, 0.0))
    a = render_ccd(p, GRATING, cam, s, np.random.default_rng(7), backend="analytic")
    b = render_ccd(p, GRATING, cam, s, np.random.default_rng(7), backend="analytic")
    c = render_ccd(p, GRATING, cam, s, np.random.default_rng(8), backend="analytic")
    assert a.image.dtype == np.uint16 and np.array_equal(a.image, b.image)
    assert not np.array_equal(a.image, c.image)
    assert a.truth["backend"] == "analytic"
