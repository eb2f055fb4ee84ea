"""The twin's instruments read the EXACT geometry of hand-built poses (no physics needed), then
apply their own imperfections. Geometry facts used below:

- Eccentricity (disk centre at body polar angle 90° − θ0, distance e; conventions.md): in the
  triangle axis–disk centre–head the law of sines gives, exactly, sin α = (e/r)·sin(θ − θ0) with
  θ the READING. Hence α(θ) = (e/r)·sin(θ − θ0) + (e/r)³·sin³(θ − θ0)/6 + …: as a function of the
  reading the first-order model is exact up to third order (relative deviation ≤ (e/r)²/6, far
  below 1e-3). As a function of the TRUE angle φ (u = φ − θ0):
  α = atan(e·sin u / (r − e·cos u)) = (e/r)·sin u + ½(e/r)²·sin 2u + O((e/r)³),
  i.e. the second-order term is ½(e/r)²·sin 2u; the test uses e/r = 1/40 so that this term
  (3.1e-4 rad) is 20× the third-order remainder bound (e/r)³ = 1.6e-5 rad.
- A centre displacement (c_x, c_y) gives α = −atan(c_x/(r − c_y)) for a head on +Y: X moves the
  reading at first order (−c_x/r), Y only through the product c_x·c_y/r² (second order).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.hw.acquisition.runner import SimClock
from benchtwin.hw.interfaces import INSTRUMENT_KINDS, check_image
from benchtwin.twin.instruments.autocollimator import AutocollimatorSpec, SimAutocollimator
from benchtwin.twin.instruments.encoder_head import GRADUATION_FIXED_POINT_TOL_RAD, EncoderSpec, SimEncoder
from benchtwin.twin.instruments.probe import ProbeSpec, SimProbe
from benchtwin.twin.instruments.stage import (ARCSEC, SimBenchState, SimRotaryStage, sim_hsieh_to_physics_face,
                                              sim_rz)

from tests.support.poses import Z_BOT, Z_TOP, eccentric_pose, make_pose

R_OPT = 22e-3
SPHERE_R = 6e-3


def rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def ideal_encoder(state, heads=(0.0,), seed=0, **kw):
    return SimEncoder("encoder", state, EncoderSpec(heads_rad=heads, radius_m=R_OPT, n_lines=7069, resolution_rad=0.0, **kw),
                      seed=seed)


# --------------------------------------------------------------------------- encoder

def test_centred_disk_reads_the_true_angle_on_every_head():
    st = SimBenchState(seed=1)
    enc = ideal_encoder(st, heads=np.radians([0, 90, 137.5, 270]))
    for phi in np.radians([0, 0.3, 45, 179.9, 359.99, 725.0, -30.0]):
        x = enc.sim_exact_readings(make_pose(phi))
        np.testing.assert_allclose(x, phi, rtol=0, atol=1e-15 * max(1, abs(phi)) * 8)


@pytest.mark.parametrize("theta0_deg", [0.0, 192.08, -75.0])
def test_eccentricity_exact_error_law_of_sines(theta0_deg):
    e, th0 = R_OPT / 40, math.radians(theta0_deg)
    st = SimBenchState(seed=1)
    enc = ideal_encoder(st)
    phi = np.radians(np.arange(0, 360, 2.5))
    x = np.array([enc.sim_exact_readings(eccentric_pose(p, e, th0))[0] for p in phi])
    alpha = x - phi
    # exact: sin α = (e/r) sin(θ − θ0), θ the reading
    np.testing.assert_allclose(np.sin(alpha), (e / R_OPT) * np.sin(x - th0), rtol=0, atol=1e-15)
    # as a function of the reading the first-order model holds to (e/r)^2/6 relative (< 1e-3)
    first = (e / R_OPT) * np.sin(x - th0)
    assert np.max(np.abs(alpha - first)) <= 1e-3 * e / R_OPT
    # as a function of the true angle: first order + ½(e/r)² sin 2u, remainder O((e/r)^3)
    u = phi - th0
    second = (e / R_OPT) * np.sin(u) + 0.5 * (e / R_OPT) ** 2 * np.sin(2 * u)
    assert np.max(np.abs(alpha - second)) <= (e / R_OPT) ** 3
    assert np.max(np.abs(alpha - (e / R_OPT) * np.sin(u))) > 10 * (e / R_OPT) ** 3  # 2nd order is real


def test_eccentricity_jia_magnitude_and_heads():
    """Jia: e = 7.1 µm, r = 22 mm -> 66.6″ peak; head j at h_j sees sin α_j = (e/r) sin(θ − θ0 − h_j)."""
    e, th0 = 7.1e-6, math.radians(192.08)
    heads = np.radians([0.0, 120.0, 240.0])
    enc = ideal_encoder(SimBenchState(seed=1), heads=heads)
    phi = np.radians(np.arange(0, 360, 5.0))
    X = np.array([enc.sim_exact_readings(eccentric_pose(p, e, th0)) for p in phi])
    alpha = X - phi[:, None]
    assert abs(np.max(np.abs(alpha[:, 0])) / ARCSEC - 66.57) < 0.05
    for j, h in enumerate(heads):
        np.testing.assert_allclose(np.sin(alpha[:, j]), (e / R_OPT) * np.sin(X[:, j] - th0 - h), atol=1e-16)


def test_translation_along_y_is_second_order_along_x_first_order():
    e, th0, d = 7.1e-6, math.radians(30.0), 2e-6
    enc = ideal_encoder(SimBenchState(seed=1))
    phi = np.radians(np.arange(0, 360, 10.0))
    base = np.array([enc.sim_exact_readings(eccentric_pose(p, e, th0))[0] for p in phi])
    dy = np.array([enc.sim_exact_readings(eccentric_pose(p, e, th0, (0.0, d)))[0] for p in phi]) - base
    dx = np.array([enc.sim_exact_readings(eccentric_pose(p, e, th0, (d, 0.0)))[0] for p in phi]) - base
    bound2 = 2 * (e + d) * d / R_OPT**2
    assert np.max(np.abs(dy)) <= bound2                   # second order: ~1e-8 rad
    np.testing.assert_allclose(dx, -d / R_OPT, atol=bound2)  # first order: −d/r = −19″
    # pure translation of a centred disk along Y: no reading change at all
    assert enc.sim_exact_readings(make_pose(0.4, (0.0, 5e-6, 0.0)))[0] == pytest.approx(0.4, abs=1e-15)


def test_tilted_disk_line_of_sight_projection():
    """Disk tilted by τ about lab x (centred): the head's vertical line meets the plane at the
    same (x, y): body polar angle atan2(r/cos τ, 0) = 90° exactly at φ = 0; about lab y the
    foreshortening changes the polar angle only where x ≠ 0 (exact value checked)."""
    enc = ideal_encoder(SimBenchState(seed=1))
    tau = math.radians(0.05)
    assert enc.sim_exact_readings(make_pose(0.0, disk_R=rx(tau)))[0] == pytest.approx(0.0, abs=1e-15)
    # rotated disk tilted about the lab y axis: exact projection
    phi = math.radians(30)
    ry = np.array([[math.cos(tau), 0, math.sin(tau)], [0, 1, 0], [-math.sin(tau), 0, math.cos(tau)]])
    R = ry @ sim_rz(phi)
    x = enc.sim_exact_readings(make_pose(phi, disk_R=R))[0]
    q = np.array([0.0, R_OPT, 0.0]) @ R  # the plane passes through the origin: (0, r, 0) lies on it
    expected = math.pi / 2 - math.atan2(q[1], q[0])
    assert x == pytest.approx(expected, abs=1e-15)
    assert abs(x - phi) < 1e-12  # tilt about y: error of order τ²·(...) only


def test_graduation_error_is_fixed_to_the_disk():
    st = SimBenchState(seed=7)
    rms = 0.6 * ARCSEC
    enc = ideal_encoder(st, graduation_error_rms_rad=rms, seed=7)
    g = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
    E = enc.sim_graduation_error(g)
    assert np.sqrt(np.mean(E**2)) == pytest.approx(rms, rel=0.05)
    phi = np.radians(np.arange(0, 360, 7.0))
    alpha = np.array([enc.sim_exact_readings(make_pose(p))[0] - p for p in phi])
    gval = enc.sim_graduation_value(np.pi / 2 - phi)
    np.testing.assert_allclose(alpha, enc.sim_graduation_error(gval), atol=1e-16)
    # same seed -> same disk; another seed -> another disk
    assert np.array_equal(ideal_encoder(st, graduation_error_rms_rad=rms, seed=7).sim_graduation_error(g), E)
    assert not np.allclose(ideal_encoder(st, graduation_error_rms_rad=rms, seed=8).sim_graduation_error(g), E)


def reference_exact_readings(enc, pose):
    """``sim_exact_readings`` as written on arrays (before its float path): the fixed point with
    ``error_rad``, the interpolation error from ``enc.interpolation``, the wrap."""
    gamma = enc.sim_head_body_angles(pose)
    g = gamma
    if enc.graduation_error_rms_rad:
        g = gamma - enc.sim_graduation_error(gamma)
        for _ in range(8):
            g_new = gamma - enc.sim_graduation_error(g)
            done = np.max(np.abs(g_new - g)) <= GRADUATION_FIXED_POINT_TOL_RAD
            g = g_new
            if done:
                break
    ip = np.zeros_like(g)
    for m, (a, p) in enumerate(zip(enc.interpolation["amplitude_rad"], enc.interpolation["phase_rad"]), start=1):
        if a:
            ip = ip + a * np.sin(m * enc.n_lines * g + p)
    raw = 0.5 * math.pi + enc.heads_rad - g + ip
    phi = pose.shaft_angle_rad
    return phi + ((raw - phi + math.pi) % (2 * math.pi) - math.pi)


@pytest.mark.parametrize("heads_deg", [(0.0,), (0.0, 180.0), (0.0, 120.0, 240.0), tuple(range(0, 360, 30))])
def test_exact_readings_equal_the_array_expression_bit_for_bit(heads_deg):
    """The float path of ``sim_exact_readings`` (no hidden effects) gives the array expression's
    doubles on random eccentric, shifted, tilted poses over several turns, both signs."""
    rng = np.random.default_rng(len(heads_deg))
    for grad, interp in ((0.6 * ARCSEC, 0.1 * ARCSEC), (0.0, 0.1 * ARCSEC), (0.6 * ARCSEC, 0.0), (0.0, 0.0)):
        enc = ideal_encoder(SimBenchState(seed=2), heads=np.radians(heads_deg), graduation_error_rms_rad=grad,
                            interpolation_error_rad=interp, seed=2)
        for _ in range(300):
            phi = rng.uniform(-15.0, 15.0)
            R = sim_rz(phi) @ rx(rng.normal(0.0, 1e-4)) @ sim_rz(rng.uniform(0, 2 * np.pi))
            pose = make_pose(phi, rng.normal(0.0, 5e-6, 3), disk_R=R)
            x, ref = enc.sim_exact_readings(pose), reference_exact_readings(enc, pose)
            assert np.array_equal(x.view(np.int64), ref.view(np.int64)), (grad, interp, phi)


def test_interpolation_error_periodic_in_the_grating_pitch():
    st = SimBenchState(seed=3)
    a = 0.1 * ARCSEC
    enc = ideal_encoder(st, interpolation_error_rad=a, seed=3)
    p = enc.pitch_rad
    phi = 0.3 + np.linspace(0, p, 50, endpoint=False)
    alpha = np.array([enc.sim_exact_readings(make_pose(f))[0] - f for f in phi])
    alpha2 = np.array([enc.sim_exact_readings(make_pose(f + 5 * p))[0] - f - 5 * p for f in phi])
    np.testing.assert_allclose(alpha, alpha2, atol=1e-14)
    assert 0.7 * a < np.max(np.abs(alpha)) <= (1 + 1 / 3) * a + 1e-15


def test_encoder_noise_resolution_and_protocol():
    st = SimBenchState(seed=5, pose=make_pose(math.radians(10.0)))
    res, noise = 0.39 * ARCSEC, 0.05 * ARCSEC
    enc = SimEncoder("encoder", st, EncoderSpec(heads_rad=[0.0, math.pi], radius_m=R_OPT, resolution_rad=res, noise_rad=noise),
                     seed=5)
    assert isinstance(enc, INSTRUMENT_KINDS["encoder"])
    r = enc.read()
    assert set(r) >= {"heads_deg", "angle_deg", "t_s", "status"} and r["status"] == "ok"
    assert r["heads_deg"] == [0.0, 180.0]
    vals = []
    for i in range(400):
        st.on_step(i, None, {}, False)
        a = np.radians(enc.read()["angle_deg"])
        k = a / res
        np.testing.assert_allclose(k, np.round(k), atol=1e-6)
        vals.append(a[0])
    d = (np.array(vals) - math.radians(10.0)) / ARCSEC
    assert np.all(np.abs(d) <= 0.39 / 2 + 4 * 0.05)
    # keyed by step: the same step index gives the same draw
    st.on_step(17, None, {}, False)
    assert enc.read()["angle_deg"][0] == pytest.approx(math.degrees(vals[17]), abs=0)


# --------------------------------------------------------------------------- probes

def probe(st, sphere="top", axis="y", side=1, seed=0, **kw):
    z = Z_TOP if sphere == "top" else Z_BOT
    spec = ProbeSpec(sphere, axis, side, sphere_radius_m=SPHERE_R, nominal_z_m=z, **kw)
    return SimProbe(f"p_{sphere}_{axis}", st, spec, seed=seed)


@pytest.mark.parametrize("side", [1, -1])
def test_probe_reads_surface_displacement_exactly(side):
    st = SimBenchState(seed=1)
    py, px = probe(st, side=side), probe(st, axis="x", side=side)
    # along the axis: exact displacement, positive towards +Y whatever the side
    for d in (-20e-6, 0.0, 3e-6, 250e-6):
        st.pose = make_pose(0.7, top=(0.0, d))
        assert py.sim_displacement_m() == pytest.approx(d, abs=1e-18)
        assert px.sim_displacement_m() == pytest.approx(0.0, abs=1e-18 + (d**2) / SPHERE_R)
    # across the axis: the sphere's curvature, exactly ±(sqrt(R² − dx²) − R) (not 0, not −dx²/2R):
    # the touched surface point recedes towards the centre, i.e. along −side·u
    dx = 50e-6
    st.pose = make_pose(0.0, top=(dx, 0.0))
    assert py.sim_displacement_m() == pytest.approx(side * (math.sqrt(SPHERE_R**2 - dx**2) - SPHERE_R), abs=1e-18)
    assert px.sim_displacement_m() == pytest.approx(dx, abs=1e-18)


def test_probes_follow_the_rigid_shaft_between_the_spheres():
    """A rigid shaft (axis through (x0, y0) at the disk plane, tilts ax, ay): the probes read the
    sphere centres' lab Y (to the curvature term); Jia eq. 9 recovers the disk-plane motion y0."""
    st = SimBenchState(seed=1)
    top, bot = probe(st, "top"), probe(st, "bottom")
    x0, y0, ax, ay = 0.3e-6, -0.8e-6, 2e-6, -3e-6  # rad tilts
    c_top = (x0 + ax * Z_TOP, y0 + ay * Z_TOP)
    c_bot = (x0 + ax * Z_BOT, y0 + ay * Z_BOT)
    st.pose = make_pose(1.0, top=c_top, bottom=c_bot)
    t, b = top.sim_displacement_m(), bot.sim_displacement_m()
    curv = lambda c: math.sqrt(SPHERE_R**2 - c[0] ** 2) - SPHERE_R
    assert t == pytest.approx(c_top[1] + curv(c_top), abs=1e-18)
    assert b == pytest.approx(c_bot[1] + curv(c_bot), abs=1e-18)
    L1, L2 = Z_TOP, Z_TOP - Z_BOT
    dY = (L2 - L1) / L2 * t + L1 / L2 * b
    # eq. 9 gives the disk-plane motion y0, plus the (weighted) curvature terms of the X offsets
    assert dY == pytest.approx(y0 + (L2 - L1) / L2 * curv(c_top) + L1 / L2 * curv(c_bot), abs=1e-18)
    assert abs(dY - y0) < 1e-11


def test_probe_form_error_follows_the_sphere_body():
    st = SimBenchState(seed=1)
    lobes = [{"order": 3, "amplitude": 10e-9, "phase": 0.4}, {"order": 5, "amplitude": 4e-9, "phase": 2.0}]
    p = probe(st, form_lobes=lobes)
    for phi in np.radians([0.0, 33.0, 200.0]):
        st.pose = make_pose(phi)
        g = math.pi / 2 - phi  # body angle of the contact direction (+Y)
        f = sum(l["amplitude"] * math.cos(l["order"] * g - l["phase"]) for l in lobes)
        assert p.sim_displacement_m() == pytest.approx(f, abs=1e-18)


def test_probe_imperfections_linearity_noise_resolution_range():
    st = SimBenchState(seed=2)
    p = probe(st, repeatability_m=0.1e-6, linearity_a_m=0.2e-6, linearity_b_m=50e-6, range_m=0.3e-3,
              resolution_m=0.01e-6, seed=2)
    assert isinstance(p, INSTRUMENT_KINDS["probe"])
    L = np.linspace(-0.3e-3, 0.3e-3, 601)
    lin = p.sim_linearity_error_m(L)
    env = 0.2e-6 + 50e-6 * (L / 1e-3) ** 2
    assert np.all(np.abs(lin) <= env) and np.max(np.abs(lin) / env) > 0.3
    assert p.sim_linearity_error_m(0.0) == 0.0
    st.pose = make_pose(0.0, top=(0.0, 5e-6))
    vals = []
    for i in range(300):
        st.on_step(i, None, {}, False)
        r = p.read()
        assert r["status"] == "ok"
        vals.append(r["value_um"])
        assert abs(r["value_um"] * 100 - round(r["value_um"] * 100)) < 1e-9
    vals = np.array(vals) - 5.0 - p.sim_linearity_error_m(5e-6) / 1e-6
    assert abs(np.mean(vals)) < 0.03 and 0.08 < np.std(vals) < 0.12
    st.pose = make_pose(0.0, top=(0.0, 0.31e-3))
    r = p.read()
    assert r["status"] == "out_of_range" and math.isnan(r["value_um"])


# --------------------------------------------------------------------------- autocollimator

def test_autocollimator_exact_reflection_sign_and_tilt():
    N = 8
    beta = np.array([1.0, -2.0, 0.5, 0.0, 3.0, -1.5, -0.5, -0.5]) * ARCSEC
    assert abs(beta.sum()) < 1e-18
    faces = 2 * np.pi * np.arange(N) / N + np.concatenate([[0.0], np.cumsum(beta[:-1])])
    st = SimBenchState(seed=1, n_faces=N, polygon_setup_rms_rad=0.0)
    ac = SimAutocollimator("ac", st, AutocollimatorSpec(range_rad=1000 * ARCSEC))
    assert isinstance(ac, INSTRUMENT_KINDS["autocollimator"])
    # polygon turned by +d (CCW): reading −d
    for d in np.array([-300.0, -1.0, 0.0, 2.5, 400.0]) * ARCSEC:
        st.pose = make_pose(d, face_angles=faces)
        x, y, k = ac.sim_exact_angles()
        assert k == 1 and x == pytest.approx(-d, abs=1e-15) and y == pytest.approx(0.0, abs=1e-15)
    # face normals tilted towards +z: Y positive, equal to the tilt
    tau = 20 * ARCSEC
    st.pose = make_pose(0.0, poly_R=np.array([[math.cos(tau), 0, -math.sin(tau)], [0, 1, 0],
                                              [math.sin(tau), 0, math.cos(tau)]]), face_angles=faces)
    x, y, _ = ac.sim_exact_angles()
    assert y == pytest.approx(tau, abs=1e-15) and x == pytest.approx(0.0, abs=1e-15)
    # a CCW step of 360/N brings Hsieh's next face (physics face N) with −β_N in the reading
    st.pose = make_pose(2 * np.pi / N, face_angles=faces)
    x, _, k = ac.sim_exact_angles()
    assert k == sim_hsieh_to_physics_face(2, N) == N
    assert x == pytest.approx(beta[N - 1], abs=1e-14)


def test_autocollimator_drift_range_resolution():
    st = SimBenchState(seed=1, n_faces=12, polygon_setup_rms_rad=0.0, clock=SimClock())
    ac = SimAutocollimator("ac", st, AutocollimatorSpec(resolution_rad=0.005 * ARCSEC, range_rad=100 * ARCSEC,
                                                  drift_rate_rad_s=1.0 * ARCSEC / 3600.0))
    st.pose = make_pose(-10 * ARCSEC)
    r0 = ac.read()
    st.clock.advance(1800.0)
    r1 = ac.read()
    assert r0["x_arcsec"] == pytest.approx(10.0, abs=0.0025)
    assert r1["x_arcsec"] - r0["x_arcsec"] == pytest.approx(0.5, abs=0.006)
    assert abs(r1["x_arcsec"] * 200 - round(r1["x_arcsec"] * 200)) < 1e-9
    st.pose = make_pose(-150 * ARCSEC)
    assert ac.read()["status"] == "out_of_range"


class FakeBench:
    """Rigid bench without physics: command = true angle, eccentric disk, polygon with β."""

    def __init__(self, N, e, theta0, beta, seed=11):
        self.n_faces, self.seed, self.e, self.th0 = N, seed, e, theta0
        self.faces = 2 * np.pi * np.arange(N) / N + np.concatenate([[0.0], np.cumsum(beta[:-1])])

    def pose_at(self, cmd, rep=0, t_s=0.0, direction=1):
        a = math.pi / 2 - self.th0 + cmd
        p = make_pose(cmd, (self.e * math.cos(a), self.e * math.sin(a), 0.0), face_angles=self.faces, t_s=t_s)
        return p


def test_polygon_readings_obey_hsieh_eq3_on_a_rigid_bench():
    """ε_ij = α((i−1)·360/N + S) + Σ_{k=j}^{j+i−1} β_k + U_j with α = reading − true (exact)."""
    from benchtwin.hw.acquisition.procedures import PolygonSetup, polygon_shift_angle
    from benchtwin.hw.acquisition.runner import Runner

    N = 12
    rng = np.random.default_rng(0)
    beta_p = rng.normal(0, 1.0, N) * ARCSEC
    beta_p -= beta_p.mean()
    fb = FakeBench(N, 7.1e-6, math.radians(192.08), beta_p)
    st = SimBenchState(fb, SimClock(), polygon_setup_rms_rad=1.0 * ARCSEC)
    enc = ideal_encoder(st)
    stage = SimRotaryStage("stage", st, enc)
    ac = SimAutocollimator("autocollimator", st, AutocollimatorSpec(range_rad=1000 * ARCSEC))
    rows = Runner({"stage": stage, "encoder": enc, "autocollimator": ac}, st.clock, on_step=st.on_step).run(
        polygon_shift_angle(PolygonSetup(N, ("forward", "backward")), [0.0, 5.0]))
    assert len(rows) == 2 * (N * N + N)
    beta_h = np.array([beta_p[sim_hsieh_to_physics_face(h, N) - 1] for h in range(1, N + 1)])
    U = {}
    for r in rows:
        t = r["tag"]
        i, j, S = t["step"], t["start_face"], t["shift_deg"]
        th = math.radians((i - 1) * 360.0 / N + S)
        e_over_r = fb.e / R_OPT
        alpha = math.asin(e_over_r * math.sin(th - fb.th0))  # exact, from the geometry of the truth
        bsum = sum(beta_h[(j - 1 + m) % N] for m in range(i))
        u = r["readings"]["autocollimator"]["x_arcsec"] * ARCSEC - alpha - bsum
        U.setdefault((S, j), []).append(u)
    for key, us in U.items():
        assert np.ptp(us) < 1e-5 * ARCSEC, key  # U_j constant (stage tolerance 1e-6″)
    assert np.std([np.mean(v) for v in U.values()]) > 0.3 * ARCSEC  # and differs between mountings


# --------------------------------------------------------------------------- camera

def test_camera_capture_shape_and_truth():
    from benchtwin.twin.instruments.camera import CcdOptics, SimCamera
    from benchtwin.twin.render import GratingSpec, SensorParams

    st = SimBenchState(seed=4, pose=eccentric_pose(0.2, 7.1e-6, math.radians(192.08)))
    sensor = SensorParams(width_px=256, height_px=192, dust_count=0, scratch_count=0)
    cam = sensor.camera(math.pi)
    grating = GratingSpec(period_m=20e-6, duty=0.5, line_length_m=1.2e-3, edge_radius_m=22.5e-3)
    with SimCamera("ccd", st, CcdOptics(grating, cam, sensor), backend="analytic") as c:
        assert isinstance(c, INSTRUMENT_KINDS["camera"])
        r = c.capture()
        geo = c.sim_frame_truth()
    img = check_image(r["image"])
    assert img.shape == (192, 256) and r["status"] == "ok"
    assert "truth" not in r                      # no true value in a reading (it is journaled)
    cx, cy = c.last_truth["centre_px"]
    expect = cam.lab_to_px(st.pose.disk.pos, grating.edge_radius_m)
    assert (cx, cy) == pytest.approx(tuple(expect), abs=1e-6)
    assert c.last_truth["edge_radius_px"] == pytest.approx(22.5e-3 / 0.667e-6, rel=1e-12)
    # the geometry-only truth (simulate's, also for frames replayed on resume) is the renderer's
    assert {k: geo[k] for k in ("centre_px", "edge_radius_px", "pixel_um")} == \
        {k: c.last_truth[k] for k in ("centre_px", "edge_radius_px", "pixel_um")}


def test_head_j_sees_what_head_1_saw_psi_earlier():
    """Heads counter-clockwise from head 1, rotation counter-clockwise: a line passes head 1 first
    and reaches head j after the disk turned by ψ_j, so head j's error at θ is head 1's error at
    θ − ψ_j (graduation error fixed to the disk; centred disk). Hsieh eq. 8 in graduation indices,
    δ = a_i − a_{i+(j−1)NG/NH}, counts graduation indices against the reading here: the line under
    head 1 at reading θ has body angle 90° − θ (the reading grows while the index under the head
    falls), so a_{i+Δ} is the error at the reading θ − Δ."""
    psi = np.radians([0.0, 51.428571, 120.0, 257.142857])
    enc = ideal_encoder(SimBenchState(seed=9), heads=psi, graduation_error_rms_rad=0.6 * ARCSEC, seed=9)
    for th in np.radians([3.0, 100.0, 271.5]):
        a_j = enc.sim_exact_readings(make_pose(th)) - th
        for j, p in enumerate(psi):
            a1_earlier = enc.sim_exact_readings(make_pose(th - p))[0] - (th - p)
            assert a_j[j] == pytest.approx(a1_earlier, abs=1e-14)  # float64 of angles ~6 rad
    # and not θ + ψ_j (the harmonics make the two differ by arcsec)
    a_j = enc.sim_exact_readings(make_pose(0.5)) - 0.5
    a1_later = enc.sim_exact_readings(make_pose(0.5 + psi[2]))[0] - (0.5 + psi[2])
    assert abs(a_j[2] - a1_later) > 0.01 * ARCSEC


def test_stage_warm_start_memory_is_bounded(monkeypatch):
    """A long acquisition of ever-new stops keeps the sim stage's warm-start offsets bounded (LRU,
    issue 8's flat memory), and a stop it still remembers is reached in one pose."""
    from benchtwin.hw.acquisition.runner import SimClock
    from benchtwin.twin.instruments import stage as stage_mod

    monkeypatch.setattr(stage_mod, "SIM_OFFSET_CACHE_SIZE", 16)
    fb = FakeBench(12, 7.1e-6, math.radians(192.08), np.zeros(12))
    st = SimBenchState(fb, SimClock())
    stage = SimRotaryStage("stage", st, ideal_encoder(st))
    for k in range(200):                                  # 200 distinct targets
        stage.move_to(0.37 * k)
        assert len(stage._offsets) <= 16
    stage.move_to(0.37 * 198)                             # still remembered: the first pose holds
    assert stage.last_iterations == 1
