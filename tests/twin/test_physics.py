"""Tests of the bench physics (twin/physics.py, twin/build.py, models/bench.xml).

Tolerances, and why:
- geometry that must hold exactly up to float64 rounding (rigid bodies, pure translations,
  determinism): 1e-12 m / 1e-12 rad — three orders below the 1 nm / 0.001″ (4.8e-9 rad) budget;
- the precision requirement itself: pose noise < 1 nm and < 0.001″ (we expect ~1e-15);
- physical comparisons (lever rule with a finite tilt stiffness, dynamic vs static friction):
  relative tolerances stated at each test, derived from the neglected term.
"""

from __future__ import annotations

import copy
import json
import math

import mujoco
import numpy as np
import pytest

from benchtwin.twin.build import build_model
from benchtwin.twin.physics import ARCSEC, Bench, disk_shift_overrides, shift_disk
from benchtwin.twin.scenario import load_scenario

NM = 1e-9
EXACT_M = 1e-12
EXACT_RAD = 1e-12


#: the rolling-path bearings these tests exercise (``bearings.type = "path"``: an air bearing or a
#: replayed spindle), with the race waviness and non-repeating motion jia2019.toml had before its
#: bearings became ball sets (those are tested in tests/twin/test_bearing.py)
PATH_BEARINGS = {
    "type": "path",
    "waviness_top": [{"order": 2, "amplitude": 0.15e-6, "phase": math.radians(30)},
                     {"order": 3, "amplitude": 0.10e-6, "phase": math.radians(110)},
                     {"order": 5, "amplitude": 0.05e-6, "phase": math.radians(200)}],
    "waviness_bottom": [{"order": 2, "amplitude": 0.10e-6, "phase": math.radians(250)},
                        {"order": 4, "amplitude": 0.06e-6, "phase": math.radians(80)}],
    "async_rms": 0.06e-6,
}


@pytest.fixture(scope="module")
def jia() -> dict:
    s = load_scenario().to_dict()
    s["bearings"].update(copy.deepcopy(PATH_BEARINGS))
    return s


def quiet(sc: dict, **bearings) -> dict:
    """A copy with no waviness, no non-repeating motion, no gravity: only what a test adds."""
    s = copy.deepcopy(sc)
    s["bearings"].update(waviness_top=[], waviness_bottom=[], async_rms=0.0, unbalance=0.0)
    s["bench"]["gravity_direction"] = "none"
    s["bearings"].update(bearings)
    return s


@pytest.fixture(scope="module")
def bench(jia) -> Bench:
    return Bench(jia)


def harmonics(y: np.ndarray) -> np.ndarray:
    """Amplitude of harmonics 0…n/2 of a signal sampled uniformly over one revolution."""
    return np.abs(np.fft.rfft(y)) * 2 / y.size


ANGLES = 2 * np.pi * np.arange(64) / 64


# ------------------------------------------------------------------------- API and basics ----
def test_pose_api_and_lab_frame(bench, jia):
    p = bench.pose_at(0.3, rep=0, t_s=1.5, direction=+1)
    assert p.t_s == 1.5
    for bp in (p.disk, p.polygon, p.sphere_top, p.sphere_bottom):
        assert bp.pos.shape == (3,) and bp.R.shape == (3, 3)
        np.testing.assert_allclose(bp.R @ bp.R.T, np.eye(3), atol=1e-14)
    # Disk plane at z = 0, spheres at z = L1 and L1 - L2 (conventions), to within the µm
    # centring/tilt effects.
    L1, L2 = jia["bench"]["L1"], jia["bench"]["L2"]
    assert abs(p.disk.pos[2]) < 1e-8
    assert abs(p.sphere_top.pos[2] - L1) < 1e-8
    assert abs(p.sphere_bottom.pos[2] - (L1 - L2)) < 1e-8
    # True angle = command minus the torsional lag (≈ 6″ for the jia2019 drive).
    lag = jia["bearings"]["friction_torque"] * (1 / jia["bearings"]["drive_torsional_stiffness"]
                                                + 1 / jia["bearings"]["shaft_torsional_stiffness"])
    assert abs((0.3 - p.shaft_angle_rad) - lag) < 0.02 * lag
    # Eccentricity: disk centre at e from the shaft axis, at body angle 90° − θ0 (conventions).
    shaft = p.extra["shaft"]
    c = shaft.to_body(p.disk.pos)
    e, th0 = jia["errors"]["eccentricity"], jia["errors"]["theta0"]
    np.testing.assert_allclose(c[:2], e * np.array([math.cos(math.pi / 2 - th0), math.sin(math.pi / 2 - th0)]),
                               atol=EXACT_M)


@pytest.mark.parametrize("name", [None, "hsieh2022.toml"])
def test_builds_from_loaded_scenario_objects(name):
    """Bench takes the loader's Scenario (sc.seed, SI values) as well as plain dicts."""
    from benchtwin.twin.scenario import default_scenario_path

    path = None if name is None else default_scenario_path().with_name(name)
    sc = load_scenario(path)
    b = Bench(sc)
    p = b.pose_at(1.0, rep=1, direction=-1)
    assert p.shaft_angle_rad > 1.0 - 1e-9          # backward approach: disk ahead of the drive
    assert b.truth()["seed"] == sc.seed
    assert b.truth()["polygon_faces"] == sc["bench"]["polygon_faces"]
    with pytest.raises(ValueError):
        p.extra["polygon_face_normal_angle_rad"][0] = 1.0   # shared arrays are read-only


def test_truth_is_json_ready_and_complete(bench, jia):
    t = bench.truth()
    s = json.dumps(t)
    assert json.loads(s)["seed"] == jia["scenario"]["seed"]
    beta = np.array(t["polygon_pitch_deviation_rad"])
    assert beta.size == jia["bench"]["polygon_faces"]
    assert abs(beta.sum()) < 1e-18                       # Σβ = 0 (Hsieh eq. 1)
    assert 0.3 < np.std(beta) / jia["errors"]["polygon_pitch_rms"] < 1.7
    # Face normals: consecutive normals 2π/N + β_k apart, closing the circle.
    g = np.array(t["polygon_face_normal_angle_body_rad"])
    steps = np.diff(np.concatenate([g, [g[0] + 2 * np.pi]]))
    np.testing.assert_allclose(steps - 2 * np.pi / beta.size, beta, atol=1e-15)
    for key in ("waviness_top", "cage_lobes_top", "unbalance_kgm", "housing_offsets_m", "sphere_top_form"):
        assert key in t
    # Sphere form: peak deviation = errors.sphere_form.
    dev = bench.sphere_form_deviation_m("top", np.linspace(0, 2 * np.pi, 4096))
    assert abs(np.abs(dev).max() - jia["errors"]["sphere_form"]) < 0.01 * jia["errors"]["sphere_form"]


# ------------------------------------------------------------------------ rigid-body checks ----
def test_spheres_disk_polygon_on_one_rigid_shaft_line(bench):
    """Each body's centre minus its own (constant, body-frame) offset lies on the shaft axis:
    the whole rotor moves as one rigid line (plus the polygon's twist about it)."""
    t = bench.truth()
    for th in np.linspace(0, 2 * np.pi, 13):
        for rep, direction in ((0, 1), (2, -1)):
            p = bench.pose_at(th, rep=rep, direction=direction)
            sh, ps = p.extra["shaft"], p.extra["polygon_section"]
            a = sh.R[:, 2]
            pts = [
                p.disk.pos - sh.R @ np.array(t["disk_centre_body_m"]),
                p.sphere_top.pos - sh.R @ (np.array(t["sphere_top_centre_body_m"]) * [1, 1, 0]),
                p.sphere_bottom.pos - sh.R @ (np.array(t["sphere_bottom_centre_body_m"]) * [1, 1, 0]),
                p.polygon.pos - ps.R @ np.array(t["polygon_centre_body_m"]),
            ]
            for q in pts:
                r = q - sh.pos
                off_axis = r - a * (r @ a)
                assert np.linalg.norm(off_axis) < EXACT_M
            # axial positions are the design ones
            np.testing.assert_allclose([(q - sh.pos) @ a for q in pts],
                                       [0.0, t["geometry"]["sphere_top_z_m"], t["geometry"]["sphere_bottom_z_m"],
                                        t["geometry"]["polygon_z_m"]], atol=EXACT_M)
            # polygon frame = shaft frame turned by the twist about the axis
            tw = p.extra["twist_disk_to_polygon_rad"]
            Rz = np.array([[math.cos(tw), -math.sin(tw), 0], [math.sin(tw), math.cos(tw), 0], [0, 0, 1]])
            np.testing.assert_allclose(ps.R, sh.R @ Rz, atol=EXACT_RAD)


def _table_bench(jia, dx=None, dy=None, tilt_x=None, tilt_y=None) -> Bench:
    s = quiet(jia)
    th = 2 * np.pi * np.arange(360) / 360
    z = np.zeros_like(th)
    s["motion_table"] = {"theta": th, "dx": dx(th) if dx else z, "dy": dy(th) if dy else z,
                         "tilt_x": tilt_x(th) if tilt_x else z, "tilt_y": tilt_y(th) if tilt_y else z}
    return Bench(s)


@pytest.mark.parametrize("axis", ["x", "y"])
def test_pure_translation_comes_out_where_expected(jia, axis):
    """A measured pure translation (motion table, no tilt): every body moves by the same δ(θ)
    along the same axis, and disk_plane_motion returns it."""
    A = 0.2e-6
    f = lambda th: A * np.cos(2 * th + 0.3)  # noqa: E731
    b = _table_bench(jia, **{f"d{axis}": f})
    i, j = (0, 1) if axis == "x" else (1, 0)
    for th in np.linspace(0.1, 6.2, 9):
        p = b.pose_at(th)
        true_th = p.shaft_angle_rad
        for body in ("disk", "sphere_top", "sphere_bottom"):
            # body centre = rotated body offset + δ; remove the rotation of the offset
            bp = getattr(p, body)
            off = p.extra["shaft"].to_body(bp.pos)
            moved = bp.pos - p.extra["shaft"].R @ off
            assert abs(moved[i] - f(true_th)) < EXACT_M
            assert abs(moved[j]) < EXACT_M
        dx, dy = b.disk_plane_motion([th])
        assert abs((dx if axis == "x" else dy)[0] - f(b.data.qpos[4])) < EXACT_M


def test_tilt_table_moves_spheres_by_lever_arm(jia):
    """A pure tilt ε_X about the disk-plane origin moves a point at height z by −z·ε_X along y."""
    E = 2e-6
    b = _table_bench(jia, tilt_x=lambda th: E * np.sin(3 * th))
    for th in (0.2, 1.1, 2.9):
        p = b.pose_at(th)
        eps = E * math.sin(3 * p.shaft_angle_rad)
        for body in ("sphere_top", "sphere_bottom"):
            bp = getattr(p, body)
            moved = bp.pos - p.extra["shaft"].R @ (p.extra["shaft"].to_body(bp.pos) * [1, 1, 0])
            # relative tolerance 1e-4: the bearings' moment stiffness resists the tilt slightly
            assert abs(moved[1] - (-bp.pos[2] * eps)) < 1e-4 * abs(bp.pos[2] * E) + EXACT_M
        assert abs(p.extra["axis_disk_plane_m"][1]) < 1e-4 * 0.1 * E


# ------------------------------------------------------------------------ error motions -------
@pytest.mark.parametrize("k", [2, 3, 5, 7])
def test_lobing_order_k_shows_at_harmonic_k(jia, k):
    a = 0.1e-6
    s = quiet(jia, waviness_top=[{"order": k, "amplitude": a, "phase": 0.4}])
    b = Bench(s)
    dx, dy = b.disk_plane_motion(ANGLES)
    for sig in (dx, dy):
        h = harmonics(sig)
        assert np.argmax(h) == k
        others = np.delete(h, k)
        assert others.max() < 1e-6 * h[k]
        # Lever rule: top bearing at z_t, bottom at z_b, disk at 0: the disk sees z_b/(z_b − z_t)
        # of the top race offset, up to the bearings' moment stiffness, which resists the tilt by
        # 2·k_tilt / (k_radial·(z_t − z_b)²) ≈ 1e-5 here.
        zt, zb = jia["bench"]["bearing_top_z"], jia["bench"]["bearing_bottom_z"]
        br = jia["bearings"]
        rel = 2 * br["tilt_stiffness"] / (br["radial_stiffness"] * (zt - zb) ** 2)
        assert h[k] == pytest.approx(a * zb / (zb - zt), rel=2 * rel + 1e-9)


def test_async_differs_between_reps_sync_repeats(jia):
    b = Bench(jia)
    runs = [np.array(b.disk_plane_motion(ANGLES, rep=r)) for r in range(3)]
    diff = runs[1] - runs[0]
    rms_diff = np.sqrt(np.mean(diff**2))
    assert rms_diff > 0.2 * jia["bearings"]["async_rms"]          # non-repeating part present
    # The synchronous part (waviness orders) repeats: its harmonics stay within the async level.
    for r in runs[1:]:
        for c in range(2):
            h0, h1 = harmonics(runs[0][c]), harmonics(r[c])
            assert abs(h1[2] - h0[2]) < 3 * jia["bearings"]["async_rms"]
    # Without the non-repeating motion, reps are identical.
    s = copy.deepcopy(jia)
    s["bearings"]["async_rms"] = 0.0
    b2 = Bench(s)
    r0, r1 = np.array(b2.disk_plane_motion(ANGLES, rep=0)), np.array(b2.disk_plane_motion(ANGLES, rep=1))
    assert np.abs(r1 - r0).max() < EXACT_M
    # The cage turns at ~0.4 × shaft speed: its lobing is not a harmonic of the rotation, so
    # the same rep over two consecutive revolutions does not repeat either.
    dx1, _ = b.disk_plane_motion(ANGLES, rep=0)
    dx2, _ = b.disk_plane_motion(ANGLES + 2 * np.pi, rep=0)
    assert np.sqrt(np.mean((dx2 - dx1) ** 2)) > 0.1 * jia["bearings"]["async_rms"]


def test_axis_average_line_is_the_lab_z_axis(bench):
    """Housings are placed so the least-squares axis of the synchronous motion is lab z."""
    assert np.abs(bench.axis_average_residual).max() < 1e-13


def test_gravity_sag_is_physical(jia):
    """Gravity along −y: bearing spring rest positions are raised by the static sag, which the
    bearings' stiffness predicts: total housing force = weight."""
    b = Bench(quiet(jia))
    s = quiet(jia)
    s["bench"]["gravity_direction"] = "-y"
    bg = Bench(s)
    k = jia["bearings"]["radial_stiffness"]
    h = bg.truth()["housing_offsets_m"]
    # all moving mass (the rotor, plus the carrier's 1e-6 kg placeholder mass)
    weight = bg.model.body_subtreemass[bg.model.body("shaft_carrier").id] * 9.80665
    assert weight == pytest.approx(jia["bench"]["shaft_mass"] * 9.80665, rel=1e-5)
    assert (h["bearing_top_y"] + h["bearing_bottom_y"]) * k == pytest.approx(weight, rel=1e-6)
    assert abs(b.truth()["housing_offsets_m"]["bearing_top_y"]) < 1e-15


# ------------------------------------------------------------------------- torsion -----------
def test_twist_changes_sign_with_direction(bench, jia):
    tf, ks = jia["bearings"]["friction_torque"], jia["bearings"]["shaft_torsional_stiffness"]
    for th in (0.5, 2.0, 4.0):
        fw = bench.pose_at(th, direction=+1)
        bw = bench.pose_at(th, direction=-1)
        tw_f, tw_b = fw.extra["twist_disk_to_polygon_rad"], bw.extra["twist_disk_to_polygon_rad"]
        assert tw_f > 0 > tw_b
        # |twist| = (T_f ± unbalance gravity torque)/k_s; U·g/T_f = 1 % for jia2019
        assert tw_f == pytest.approx(tf / ks, rel=0.02) and -tw_b == pytest.approx(tf / ks, rel=0.02)
        # disk vs polygon angle in the lab: polygon leads forward, lags backward
        ang = lambda bp: math.atan2(bp.R[1, 0], bp.R[0, 0])  # noqa: E731
        d_f = (ang(fw.polygon) - ang(fw.disk) + np.pi) % (2 * np.pi) - np.pi
        d_b = (ang(bw.polygon) - ang(bw.disk) + np.pi) % (2 * np.pi) - np.pi
        assert d_f > 0 > d_b
        assert fw.shaft_angle_rad < th < bw.shaft_angle_rad


def test_static_twist_matches_dynamic_run_with_frictionloss(jia):
    """The static state (friction at its sliding value) is what MuJoCo's own dynamics give while
    the drive turns slowly with joint frictionloss: twist = T_f/k_s, sign by direction.
    (At rest MuJoCo's regularised friction creeps; a real bearing sticks, holding this state.)"""
    s = quiet(jia)
    b = Bench(s)
    m, _ = build_model(s, b.placement)
    m.tendon_lengthspring[b._ten, 0] = b._housing_m
    m.tendon_lengthspring[b._ten, 1] = b._housing_m
    d = mujoco.MjData(m)
    n = int(0.03 / m.opt.timestep)
    for target, direction in ((0.1, +1), (-0.05, -1)):
        start = d.ctrl[0]
        for i in range(n):
            d.ctrl[0] = start + (target - start) * (i + 1) / n
            mujoco.mj_step(m, d)
        assert not np.any(d.warning.number)
        st = b.pose_at(target, direction=direction)
        assert d.qpos[5] == pytest.approx(st.extra["twist_disk_to_polygon_rad"], rel=0.01)


# ---------------------------------------------------------------- precision, determinism ----
def test_pose_noise_below_1nm_and_1e_3_arcsec(jia):
    """Re-settling the same state from different initial conditions gives the same pose within
    1 nm / 0.001″ (in fact within ~1e-15); MuJoCo reports no warnings."""
    b = Bench(jia)
    rng = np.random.default_rng(1)
    worst_m, worst_rad = 0.0, 0.0
    for th in (0.0, 1.234, 3.5, 5.9):
        ref = b.pose_at(th, rep=1)
        for _ in range(5):
            # perturb the starting state: µm radial, µrad tilt, arcmin of twist/spin
            b._q_last = b._q_last + rng.normal(0, [1e-6, 1e-6, 1e-5, 1e-5, 3e-4, 3e-4])
            b._cmd_last = th + rng.normal(0, 0.1)
            p = b.pose_at(th, rep=1)
            assert not np.any(b.data.warning.number)
            for f in ("disk", "polygon", "sphere_top", "sphere_bottom"):
                worst_m = max(worst_m, np.abs(getattr(p, f).pos - getattr(ref, f).pos).max())
                worst_rad = max(worst_rad, np.abs(getattr(p, f).R - getattr(ref, f).R).max())
            worst_rad = max(worst_rad, abs(p.shaft_angle_rad - ref.shaft_angle_rad))
    assert worst_m < 1 * NM and worst_rad < 0.001 * ARCSEC
    assert worst_m < 1e-13 and worst_rad < 1e-13   # what the solver actually achieves


def test_determinism_by_seed(jia):
    a, b = Bench(jia), Bench(jia)
    assert json.dumps(a.truth()) == json.dumps(b.truth())
    pa, pb = a.pose_at(2.0, rep=3), b.pose_at(2.0, rep=3)
    assert np.array_equal(pa.disk.pos, pb.disk.pos) and pa.shaft_angle_rad == pb.shaft_angle_rad
    s = copy.deepcopy(jia)
    s["scenario"]["seed"] += 1
    c = Bench(s)
    assert c.truth()["polygon_pitch_deviation_rad"] != a.truth()["polygon_pitch_deviation_rad"]
    assert not np.array_equal(c.pose_at(2.0, rep=3).disk.pos, pa.disk.pos)


def test_pose_cost_is_a_few_newton_iterations(bench):
    """A pose costs its Newton iterations, one ``mj_forward`` each (requirement: a few ms a pose;
    typical 0.1–0.3 ms). Counted, not timed: the time is a benchmark (benchmarks/physics_bench.py,
    docs/benchmarks.md "Twin physics"), which a busy machine cannot fail. Measured: 2.62 on this
    sweep (0.72° moves), 2.99 at random angles."""
    th = np.linspace(0, 2 * np.pi, 500)
    bench.total_iterations = bench.n_poses = 0
    for x in th:
        bench.pose_at(x)
    assert bench.n_poses == th.size
    assert bench.total_iterations / bench.n_poses <= 3.5


# ---------------------------------------------------------------------- design study -------
@pytest.mark.parametrize("delta_mm", [-5.0, 4.0, 6.0])
def test_l1_design_study_follows_shaft_tilt(jia, delta_mm):
    """Moving the disk along the shaft (changing L1 and the bearing-to-disk distance) changes the
    disk-plane motion exactly as the rigid shaft's tilt implies: δ(Δ) = δ(0) + Δ·(tilt)."""
    s = copy.deepcopy(jia)
    s["bench"]["gravity_direction"] = "none"   # the sag differs with the shaft's extent
    delta = delta_mm * 1e-3
    a, b = Bench(s), Bench(shift_disk(s, delta))
    for th in ANGLES[::8]:
        a.pose_at(th, rep=1)
        p, ax = a._axis_line()
        expect = p[:2] + ax[:2] * delta               # axis of bench a at height delta
        dx, dy = b.disk_plane_motion([th], rep=1)
        np.testing.assert_allclose([dx[0], dy[0]], expect, atol=1e-12)


def test_unbalance_at_speed_gives_once_per_rev_motion(jia):
    """bench.speed > 0: the centrifugal force U·ω² turns with the shaft -> a 1×/rev whirl whose
    size is U·ω² over the bearings' stiffness (lever rule for the unbalance's axial position)."""
    s = quiet(jia, unbalance=20e-6)
    b0 = Bench(s)
    s["bench"]["speed"] = 2 * np.pi * 20.0          # 20 rev/s
    b1 = Bench(s)
    dx0, dy0 = b0.disk_plane_motion(ANGLES)
    dx1, dy1 = b1.disk_plane_motion(ANGLES)
    h = harmonics(dy1 - dy0)
    F = 20e-6 * (2 * np.pi * 20.0) ** 2
    zt, zb, zu = jia["bench"]["bearing_top_z"], jia["bench"]["bearing_bottom_z"], b1.placement.unbalance_z_m
    # rigid shaft on two springs k: force F at zu -> bearing loads, disk-plane displacement
    k = jia["bearings"]["radial_stiffness"]
    Ft, Fb = F * (zu - zb) / (zt - zb), F * (zt - zu) / (zt - zb)
    expect = (Ft / k) * (0 - zb) / (zt - zb) + (Fb / k) * (zt - 0) / (zt - zb)
    assert np.argmax(h) == 1 and h[1] == pytest.approx(abs(expect), rel=1e-3)


def test_disk_shift_overrides_on_a_scenario_file():
    """The hook as a design study uses it: overrides with units on the loaded Scenario give the
    same bench as the plain-dict shift; changing L1 alone leaves the disk-plane motion alone."""
    sc = load_scenario()
    delta = -4e-3
    b1 = Bench(sc.with_overrides(disk_shift_overrides(sc, delta)))
    b2 = Bench(shift_disk(sc.to_dict(), delta))
    np.testing.assert_allclose(b1.disk_plane_motion(ANGLES[::4]), b2.disk_plane_motion(ANGLES[::4]), atol=1e-15)
    # L1 alone: the top sphere moves, disk and bearings stay. With ball bearings (jia2019.toml) the
    # shaft's longer top end changes the bearing loads a little, and Hertzian contact is not linear:
    # the disk-plane motion changes by ~1e-10 m (0.1 nm); with linear path bearings not at all.
    b3 = Bench(sc.with_overrides({"bench.L1": "10 mm"}))
    np.testing.assert_allclose(b3.disk_plane_motion(ANGLES[::4]), Bench(sc).disk_plane_motion(ANGLES[::4]),
                               atol=1e-9)
    sp = sc.with_overrides({"bearings.type": "path"})
    np.testing.assert_allclose(Bench(sp.with_overrides({"bench.L1": "10 mm"})).disk_plane_motion(ANGLES[::4]),
                               Bench(sp).disk_plane_motion(ANGLES[::4]), atol=1e-15)


def test_template_loads_on_its_own_with_named_elements():
    """models/bench.xml is a complete model (Menagerie style): it compiles without build.py."""
    from benchtwin.twin.build import template_path

    m = mujoco.MjModel.from_xml_path(str(template_path()))
    for body in ("base", "shaft_carrier", "shaft", "disk", "sphere_top", "sphere_bottom", "polygon_section", "polygon"):
        m.body(body)
    for j in ("radial_x", "radial_y", "tilt_x", "tilt_y", "spin", "shaft_twist"):
        m.joint(j)
    for t in ("bearing_top_x", "bearing_top_y", "bearing_bottom_x", "bearing_bottom_y", "drive_angle"):
        m.tendon(t)
    m.actuator("drive")


def test_coincident_bearings_are_rejected(jia):
    s = copy.deepcopy(jia)
    s["bench"]["bearing_bottom_z"] = s["bench"]["bearing_top_z"]
    with pytest.raises(ValueError, match="bearing"):
        Bench(s)


def test_motion_table_replay_with_gravity(jia):
    """Replaying a measured spindle ([motion_table]): with gravity and unbalance on, the disk-plane
    motion is the table's (the static sag is constant and belongs to the axis average line); the
    spline interpolates between table rows. Tolerance: the bearings' moment stiffness resists the
    table's tilt by ~1e-5 of it."""
    s = copy.deepcopy(jia)
    s["bearings"]["async_rms"] = 0.0
    th = 2 * np.pi * np.arange(720) / 720
    fx = lambda t: 0.15e-6 * np.cos(3 * t) + 0.05e-6 * np.sin(5 * t + 1)  # noqa: E731
    fy = lambda t: 0.10e-6 * np.sin(2 * t + 0.2)  # noqa: E731
    s["motion_table"] = {"theta_rad": th, "dx_m": fx(th), "dy_m": fy(th),
                         "tilt_x_rad": 1e-6 * np.cos(2 * th), "tilt_y_rad": np.zeros_like(th)}
    b = Bench(s)
    dx, dy = b.disk_plane_motion(ANGLES + 0.003)
    t_true = ANGLES + 0.003 - b.truth()["lag_disk_behind_drive_nominal_rad"]
    # tilt resisted by 2 k_t/(k_r Δz²) ≈ 1e-5 of 1 µrad, times lever arms of ~0.1 m: ~1e-12 m
    np.testing.assert_allclose(dx, fx(t_true), atol=2e-12)
    np.testing.assert_allclose(dy, fy(t_true), atol=2e-12)
