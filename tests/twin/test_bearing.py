"""Tests of the rolling-element bearing model (twin/bearing.py) and its use by the bench.

The selection rule is NOT coded anywhere: these tests solve the journal's equilibrium under the
summed Hertzian ball forces and check that only the waviness orders Wardle (1988) names move the
centre, at the frequencies he gives. Tolerances: a lobe that moves the centre does so by about
its own amplitude a (linear theory: exactly a for equal balls); one that does not leaves only the
second-order Hertz terms, ~ a²/delta_0 ≈ 1e-2·a for a = 0.1 µm, delta_0 = 1.6 µm, and those
fall on orders 2k, which never satisfy 2k = qZ ± 1 for even Z: we demand < 1e-6·a.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from benchtwin.twin.bearing import (BallBearingGeometry, BallSet, generate_ball_set, load_deflection_constant,
                                    preload_approach_m, radial_stiffness_N_m)
from benchtwin.twin.physics import Bench
from benchtwin.twin.scenario import load_scenario

Z = 12
GEOM = BallBearingGeometry(balls=Z, ball_diameter_m=6.35e-3, pitch_diameter_m=31e-3,
                           contact_angle_rad=math.radians(15), preload_N=50.0)
A = 0.1e-6


def equilibrium(bs: BallSet, theta: float, cage: float, load=(0.0, 0.0)) -> np.ndarray:
    """Journal displacement u where the ball forces balance ``load`` (Newton, 2×2)."""
    u = np.zeros(2)
    for _ in range(50):
        f = bs.force_on_shaft_N(u, theta, cage) + load
        J = np.zeros((2, 2))
        for i in range(2):
            du = np.zeros(2)
            du[i] = 1e-10
            J[:, i] = (bs.force_on_shaft_N(u + du, theta, cage) - bs.force_on_shaft_N(u - du, theta, cage)) / 2e-10
        step = -np.linalg.solve(J, f)
        u += step
        if np.abs(step).max() < 1e-16:
            break
    return u


def centre_path(bs: BallSet, n: int = 720, revs: int = 5) -> tuple[np.ndarray, np.ndarray]:
    th = 2 * np.pi * revs * np.arange(n * revs) / (n * revs)
    u = np.array([equilibrium(bs, t, bs.rho * t) for t in th])
    return th, u[:, 0] + 1j * u[:, 1]


def one_lobe(race: str, k: int) -> BallSet:
    lobe = (np.array([float(k)]), np.array([A]), np.array([0.7]))
    return BallSet(GEOM, **{race: lobe})


def test_hertz_constants_are_those_of_a_quarter_inch_steel_ball():
    """K_n of a 6.35 mm ball in 52 %/53 % grooves: Harris' tables give ~8e9 N/m^1.5 (same order for
    every 1/4" ball bearing); the preload approach and radial stiffness follow from it."""
    Kn = load_deflection_constant(GEOM)
    assert 5e9 < Kn < 1.2e10
    d0 = preload_approach_m(GEOM)
    assert Kn * d0**1.5 == pytest.approx(50.0 / (Z * math.sin(math.radians(15))), rel=1e-12)
    assert 40e6 < radial_stiffness_N_m(GEOM) < 200e6
    assert GEOM.cage_ratio == pytest.approx(0.5 * (1 - 6.35 * math.cos(math.radians(15)) / 31), rel=1e-15)


@pytest.mark.parametrize("race", ["inner", "outer"])
def test_waviness_selection_rule_emerges_from_summed_ball_forces(race):
    """Wardle 1988: race waviness of order k moves the centre only for k = qZ ± 1 (and the inner
    race's order 1, its eccentricity, which turns with the shaft); every other order loads all
    balls symmetrically and the centre stays put."""
    moving = {Z - 1, Z + 1, 2 * Z - 1, 2 * Z + 1} | ({1} if race == "inner" else set())
    for k in range(1, 2 * Z + 3):
        _, u = centre_path(one_lobe(race, k), n=48, revs=3)
        spread = np.abs(u - u.mean()).max()
        if k in moving:
            assert spread == pytest.approx(A, rel=0.05), (race, k)
        else:
            assert spread < 1e-6 * A, (race, k, spread / A)


@pytest.mark.parametrize("race,k", [("inner", Z - 1), ("inner", Z + 1), ("outer", Z - 1), ("outer", Z + 1)])
def test_waviness_moves_the_centre_at_wardles_frequencies(race, k):
    """The centre whirls at qZ·(1 − rho) ± 1 (inner race, orders qZ ± 1) or qZ·rho (outer race)
    cycles per revolution: the ball pass frequencies, NOT harmonics of the rotation."""
    bs = one_lobe(race, k)
    revs, n = 10, 64
    th, u = centre_path(bs, n=n, revs=revs)
    spec = np.abs(np.fft.fft(u - u.mean())) / u.size
    f = np.fft.fftfreq(u.size, d=1.0 / n)          # cycles per revolution, signed (whirl sense)
    peak = f[np.argmax(spec)]
    rho = bs.rho
    if race == "inner":
        expect = Z * (1 - rho) + 1 if k == Z + 1 else -(Z * (1 - rho) - 1)
    else:
        expect = -Z * rho if k == Z + 1 else Z * rho
    assert abs(abs(peak) - abs(expect)) <= 1.0 / revs + 1e-9
    assert not np.isclose(abs(expect), round(abs(expect)), atol=0.05)   # asynchronous


def test_ball_diameter_variation_moves_the_centre_at_cage_frequency():
    dd = np.zeros(Z)
    dd[0] = 0.2e-6                     # one big ball
    bs = BallSet(GEOM, ball_dd_m=dd)
    th, u = centre_path(bs, n=32, revs=5)
    spec = np.abs(np.fft.fft(u - u.mean()))
    f = np.fft.fftfreq(u.size, d=1.0 / 32)
    assert abs(abs(f[np.argmax(spec)]) - bs.rho) <= 0.2 + 1e-9
    assert np.abs(u - u.mean()).max() > 0.1 * 0.2e-6


def test_generated_set_follows_grade_and_is_seeded():
    a = generate_ball_set(GEOM, "P4", "G5", np.random.default_rng(1))
    b = generate_ball_set(GEOM, "P4", "G5", np.random.default_rng(1))
    c = generate_ball_set(GEOM, "P2", "G5", np.random.default_rng(1))
    assert np.array_equal(a.inner[1], b.inner[1]) and np.array_equal(a.ball_dd_m, b.ball_dd_m)
    assert np.all(c.inner[1][1:] < a.inner[1][1:])      # a better grade: smaller waviness
    assert np.ptp(a.ball_dd_m) <= 0.25e-6                # G5: lot diameter variation 0.25 µm
    with pytest.raises(ValueError, match="ISO 492"):
        generate_ball_set(GEOM, "P9", "G5", np.random.default_rng(1))


# ------------------------------------------------------------------ the bench with ball sets --
def ball_scenario(**bearings) -> dict:
    sc = load_scenario().to_dict()
    sc["bearings"].update(type="ball", balls=Z, ball_diameter=6.35e-3, pitch_diameter=31e-3,
                          contact_angle=math.radians(15), preload=50.0, groove_inner=0.52, groove_outer=0.53,
                          grade="P4", ball_grade="G5", cage_slip=0.02)
    sc["bearings"].update(bearings)
    return sc


@pytest.mark.parametrize("gravity", ["none", "-y"])
def test_bench_selection_rule_through_mujoco(gravity):
    """The same rule through the whole bench (MuJoCo statics, two bearings): a lobe of order Z+1 on
    the top inner race moves the disk-plane axis by about its amplitude; order Z+2 does not.
    Under gravity the load zone is no longer uniform (each ball's contact stiffness varies once
    around the set by ~ u_g/delta_0, u_g ≈ 0.05 µm the sag), so the neighbouring orders leak at
    that ratio — physics beyond Wardle's symmetric case, which the model keeps."""
    out = {}
    for k in (Z + 1, Z + 2):
        sc = ball_scenario(friction_torque=0.0, unbalance=0.0)
        sc["bench"]["gravity_direction"] = gravity
        b = Bench(sc)
        for s in ("top", "bottom"):
            b.ball_sets[s] = BallSet(b.ball_sets[s].geometry)
        b.ball_sets["top"] = BallSet(b.ball_sets["top"].geometry,
                                     inner=(np.array([float(k)]), np.array([A]), np.array([0.3])))
        b._center_axis_average_line()
        th = np.linspace(0, 2 * np.pi, 90, endpoint=False)
        dx, dy = b.disk_plane_motion(th)
        out[k] = max(np.ptp(dx), np.ptp(dy))
    assert out[Z + 1] > 0.5 * A
    assert out[Z + 2] < (1e-4 if gravity == "none" else 0.05) * A


def test_cage_path_makes_revisits_differ():
    """Revisiting a stop after a different path gives another ball configuration: the cage angle
    integrates the shaft's rotation (times rho) and slips a little at every start/stop."""
    b = Bench(ball_scenario())
    p0 = b.pose_at(0.5, t_s=1.0)
    c0 = b.cage_angles_rad(b.data.qpos[4])
    # the same stop within one time (the servo's iterations): the same configuration
    p0b = b.pose_at(0.5, t_s=1.0)
    np.testing.assert_allclose(p0.disk.pos, p0b.disk.pos, rtol=0, atol=1e-15)
    # a full revolution and back: the cage rolled out and back with slip -> another configuration
    for i, th in enumerate(np.linspace(0.5, 0.5 + 2 * np.pi, 24)[1:]):
        b.pose_at(th, t_s=2.0 + i)
    p1 = b.pose_at(0.5, t_s=100.0)
    c1 = b.cage_angles_rad(b.data.qpos[4])
    assert np.all(np.abs(c1 - c0) > 1e-4)
    assert np.abs(p1.disk.pos - p0.disk.pos).max() > 1e-9
    # same seed, same calls: bit-identical
    b2 = Bench(ball_scenario())
    b2.pose_at(0.5, t_s=1.0)
    b2.pose_at(0.5, t_s=1.0)
    for i, th in enumerate(np.linspace(0.5, 0.5 + 2 * np.pi, 24)[1:]):
        b2.pose_at(th, t_s=2.0 + i)
    assert np.array_equal(b2.pose_at(0.5, t_s=100.0).disk.pos, p1.disk.pos)


def test_quasi_static_pose_is_where_mujoco_dynamics_settle():
    """The bearings' radial modes are at ~1.6 kHz (k ≈ 84 N/µm per bearing, 0.8 kg): the static
    solve is the state a MuJoCo mj_step integration of the same model (ball forces applied as
    generalized forces each step, tendon damping, drive damping) settles to."""
    sc = ball_scenario(friction_torque=0.0)
    b = Bench(sc)
    cmd = 0.8
    st = b.pose_at(cmd, t_s=0.0)
    q_static = b.data.qpos.copy()
    m = b.model
    d = mujoco.MjData(m)
    d.ctrl[b._act] = cmd
    d.qpos[:] = 0.0
    d.qpos[4] = cmd                          # start at the angle, off the radial equilibrium
    for _ in range(int(0.03 / m.opt.timestep)):
        mujoco.mj_kinematics(m, d)
        d.qfrc_applied[:] = b._T.T @ b._ball_forces(d.qpos.copy())
        mujoco.mj_step(m, d)
    assert not np.any(d.warning.number)
    np.testing.assert_allclose(d.qpos[:2], q_static[:2], atol=1e-11)     # m: 1e-11 m = 0.01 nm
    np.testing.assert_allclose(d.qpos[2:4], q_static[2:4], atol=1e-10)   # rad
    assert d.qpos[4] == pytest.approx(q_static[4], abs=1e-9)
    assert st.shaft_angle_rad == pytest.approx(q_static[4], abs=0)


def test_ball_bench_pose_noise_below_floors():
    """The numerical floors hold with the nonlinear ball forces: re-settling one stop from
    perturbed starting states gives the same pose within 1 nm and 0.001″ (in fact ~1e-13)."""
    b = Bench(ball_scenario())
    rng = np.random.default_rng(3)
    worst_m = worst_rad = 0.0
    for th in (0.0, 1.234, 3.5):
        ref = b.pose_at(th, t_s=7.0)
        for _ in range(4):
            b._q_last = b._q_last + rng.normal(0, [1e-6, 1e-6, 1e-5, 1e-5, 3e-4, 3e-4])
            b._cmd_last = th + rng.normal(0, 0.1)
            p = b.pose_at(th, t_s=7.0)
            for f in ("disk", "polygon", "sphere_top", "sphere_bottom"):
                worst_m = max(worst_m, np.abs(getattr(p, f).pos - getattr(ref, f).pos).max())
                worst_rad = max(worst_rad, np.abs(getattr(p, f).R - getattr(ref, f).R).max())
    assert worst_m < 1e-9 and worst_rad < 0.001 * math.pi / 648000
    assert worst_m < 1e-12 and worst_rad < 1e-12


def test_jia2019_alpha_scatters_over_the_23_visits_of_a_stop():
    """Issue 15's done-when: on jia2019 the true α at a polygon stop, visited once per start face
    (23 sweeps of 23 stops, each with its moves and dwells on the bench clock), scatters by the
    asynchronous motion of the ball sets: std over the 23 visits >= 0.1″ at every stop."""
    from benchtwin.twin.instruments.encoder_head import SimEncoder
    from benchtwin.twin.instruments.stage import SimBenchState, SimRotaryStage

    sc = load_scenario()
    b = Bench(sc)
    st = SimBenchState(b)
    enc = SimEncoder.sim_from_scenario(sc, st)
    stage = SimRotaryStage("stage", st, enc)
    N = 23
    alpha = np.zeros((N, N))
    for j in range(N):                     # start face j: a full forward sweep
        for i in range(N):
            stage.move_to(360.0 * i / N)
            st.clock.advance(0.5)          # dwell
            alpha[j, i] = (enc.sim_exact_readings(st.pose)[0] - st.pose.shaft_angle_rad) / (math.pi / 648000)
    sd = alpha.std(axis=0, ddof=1)
    assert sd.min() >= 0.1, sd
    assert 0.1 < sd.mean() < 2.0


# ----------------------------------------------- the time-keyed cage slip (issue 33 item 2) --
def _walk(b: Bench, path) -> np.ndarray:
    """The cage path alone (no solve): every (shaft angle, bench time) a stop; the cages at the end."""
    for th, t in path:
        b._advance_path(t)
        b._end_stop(th)
    return b.cage_angles_rad(path[-1][0])


def _sweeps(n: int, dt: float, step_deg: float = 15.0, stops: int = 24):
    """n polygon-like sweeps: `stops` forward stops of `step_deg`, a return move to the start; one
    stop every `dt` seconds. Returns the path and the indices of the stops at the start angle."""
    path, at_start, t = [], [], 0.0
    for _ in range(n):
        for k in range(stops):
            t += dt
            if k == 0:
                at_start.append(len(path))
            path.append((math.radians(step_deg * k), t))
    return path, at_start


def _start_visits(b: Bench, path, at_start) -> np.ndarray:
    """The cage angles (top, bottom) at every visit of the start stop."""
    out = []
    for i, (th, t) in enumerate(path):
        b._advance_path(t)
        b._end_stop(th)
        if i in at_start:
            out.append(b.cage_angles_rad(th))
    return np.array(out)


def test_time_keyed_slip_is_zero_without_slip_and_linear_in_its_spread():
    """cage_slip = 0 (any correlation time): every visit of a stop after out-and-back sweeps sees the
    same cages. With slip, the visits' cage offsets are the integral of the slip over the moves,
    so they scale exactly with cage_slip (one realisation of ξ(t), the same seed)."""
    path, at = _sweeps(6, dt=1.5)
    off = _start_visits(Bench(ball_scenario(cage_slip=0.0, cage_slip_time=60.0)), path, at)
    np.testing.assert_allclose(off - off[0], 0.0, atol=1e-12)
    d = {}
    for s in (0.01, 0.02):
        c = _start_visits(Bench(ball_scenario(cage_slip=s, cage_slip_time=60.0)), path, at)
        d[s] = c - c[0]
    assert np.abs(d[0.02]).max() > 1e-4
    np.testing.assert_allclose(d[0.02], 2.0 * d[0.01], rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("tau", [0.0, 3.0, 60.0])
def test_revisit_spread_follows_the_slip_process(tau):
    """The cage's change over one sweep (23 forward moves of 15°, one return of −345°) is
    −rho·Σ_k Δθ_k·s(t_k): its variance over independent runs is rho²σ²·Σ_kl Δθ_kΔθ_l·C(t_k − t_l),
    C = exp(−|Δt|/τ) for the time-keyed process and δ_kl for the per-stop draws (tau = 0). A
    slowly varying slip (τ ≫ the sweep) nearly cancels between the way out and back: the spread
    of the visits shrinks with τ as the model says."""
    sigma, dt = 0.02, 1.5
    path, at = _sweeps(2, dt=dt)
    b = Bench(ball_scenario(cage_slip=sigma, cage_slip_time=tau))
    rho = b.ball_sets["top"].rho
    th = np.array([p[0] for p in path[at[0]:at[1] + 1]])
    tt = np.array([p[1] for p in path[at[0]:at[1] + 1]])
    dth, tk = np.diff(th), tt[1:]
    C = np.exp(-np.abs(tk[:, None] - tk[None, :]) / tau) if tau > 0 else np.eye(len(tk))
    predicted = rho * sigma * math.sqrt(dth @ C @ dth)
    runs = 600
    dc = np.empty((runs, 2))
    for r in range(runs):
        b.reset_path(run=r)
        c = _start_visits(b, path, at)
        dc[r] = c[1] - c[0]
    measured = dc.std(axis=0)
    np.testing.assert_allclose(measured, predicted, rtol=0.15)
    if tau == 60.0:   # against the per-stop model's spread: a 36 s sweep at τ = 60 s cancels ~half of it
        assert predicted < 0.7 * rho * sigma * math.sqrt(dth @ dth)


def test_time_keyed_slip_depends_on_elapsed_time_not_on_call_order():
    """The same angular path run faster or slower reaches a revisited stop with other cages (the
    slip is a function of bench time); the slip at a time is the same whatever was asked before."""
    b = Bench(ball_scenario(cage_slip=0.02, cage_slip_time=60.0))
    fast, _ = _sweeps(3, dt=1.5)
    slow, _ = _sweeps(3, dt=15.0)
    c_fast = _walk(b, fast)
    b.reset_path()
    c_slow = _walk(b, slow)
    assert np.all(np.abs(c_fast - c_slow) > 1e-6)
    s1 = b.cage_slip_at(123.4)
    b.reset_path()
    _walk(b, fast)
    np.testing.assert_array_equal(b.cage_slip_at(123.4), s1)
    assert b.cage_slip_at(123.4)[0] != b.cage_slip_at(123.4)[1]   # the two bearings slip independently
    assert np.all(b.cage_slip_at(5.0) != 0.0)
    assert not np.any(Bench(ball_scenario(cage_slip=0.02)).cage_slip_at(5.0))
