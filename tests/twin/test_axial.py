"""The shaft's axial DOF (twin/axial.py, [axial]): the pair's axial stiffness against an independent
closed form, z under known loads, the order selection the ball sums make, the air thrust's supply
and form motion against its own non-linear law, face motion = axial + R × tilt on the posed
bench, the ISO 230-7 axial/face values against truth, and nothing changes without the section."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from benchtwin.analysis.iso230_7 import axial_error_motion, axial_face_error_motion
from benchtwin.twin.air_bearing import AerostaticThrust, SupplyPressure
from benchtwin.twin.axial import (AirThrustAxial, BallPairAxial, pair_axial_stiffness_N_m,
                                  palmgren_axial_stiffness_N_m)
from benchtwin.twin.bearing import BallBearingGeometry, BallSet
from benchtwin.twin.instruments.axial_probe import SimAxialProbe, face_truth_m
from benchtwin.twin.instruments.stage import SimBenchState
from benchtwin.twin.physics import Bench

from tests.support.scenarios import small_scenario

#: jia2019's pair (7004 C-size: 12 balls of 6.35 mm on 29 mm, 15°, 50 N)
GEOM = BallBearingGeometry(balls=12, ball_diameter_m=6.35e-3, pitch_diameter_m=29e-3,
                           contact_angle_rad=math.radians(15.0), preload_N=50.0)
NO_FACE = {s: ((np.zeros(0),) * 3, (np.zeros(0),) * 3) for s in ("top", "bottom")}


def ideal_pair(load_N: float = 0.0, face=NO_FACE, outer_top=None) -> BallPairAxial:
    top = BallSet(GEOM) if outer_top is None else BallSet(GEOM, outer=outer_top)
    return BallPairAxial(top, BallSet(GEOM), face, load_N)


def base(pair: BallPairAxial, theta: float = 0.0, cages=(0.0, 0.0)):
    return pair.base_approaches_m([0.0, 0.0, 0.0, 0.0], theta, cages)


def test_pair_axial_stiffness_against_palmgren_and_its_own_derivative():
    pair = ideal_pair()
    K = pair_axial_stiffness_N_m(*pair.sets)
    # Palmgren's empirical closed form (an independent source): within 15 % (measured 6.3 %)
    Kp = 2.0 * palmgren_axial_stiffness_N_m(pair.sets[0])
    assert abs(K / Kp - 1.0) < 0.15
    # the linearised formula is the derivative of the non-linear sums at the preload
    F0, dF = pair.axial_force_N(0.0, base(pair))
    assert abs(F0) < 1e-9 * GEOM.preload_N
    assert dF == pytest.approx(-K, rel=1e-12)
    h = 1e-10
    Fp, _ = pair.axial_force_N(h, base(pair))
    Fm, _ = pair.axial_force_N(-h, base(pair))
    assert -(Fp - Fm) / (2 * h) == pytest.approx(K, rel=1e-6)


def test_z_under_a_known_axial_load():
    """Below lift-off: the exact root of Z·K_n·sin a·((δ0 − s·z)^1.5 − (δ0 + s·z)^1.5) = −F (bisection
    written here), ≈ F/K; beyond lift-off (F > 2^1.5·F_a) one set carries all:
    z = ((F/(Z·K_n·sin a))^(2/3) − δ0)/sin a."""
    bs = BallSet(GEOM)
    sa, Z, Kn, d0 = math.sin(GEOM.contact_angle_rad), GEOM.balls, bs.Kn, bs.delta0_m
    K = pair_axial_stiffness_N_m(bs, bs)
    for F in (1.0, 10.0, -25.0):
        z = ideal_pair(F).solve_z_m(base(ideal_pair(F)))

        def net(zz, F=F):
            return Z * Kn * sa * (max(d0 - sa * zz, 0) ** 1.5 - max(d0 + sa * zz, 0) ** 1.5) + F
        lo, hi = -5e-6, 5e-6
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if net(mid) > 0 else (lo, mid)
        assert z == pytest.approx(0.5 * (lo + hi), rel=1e-9, abs=1e-17)
        assert z == pytest.approx(F / K, rel=0.05)
    F = 4.0 * GEOM.preload_N
    z = ideal_pair(F).solve_z_m(base(ideal_pair(F)))
    assert z > 0 and z == pytest.approx(((F / (Z * Kn * sa)) ** (2 / 3) - d0) / sa, rel=1e-10)


def test_only_race_orders_qZ_move_the_shaft_axially():
    """An outer-race lobe of order Z (= 12) moves z as the cage turns; orders Z ± 1 tilt (moment)
    but leave z still to second order: the sum over the balls selects, not the model."""
    amp = 0.05e-6
    ptp = {}
    for k in (11, 12, 13):
        pair = ideal_pair(outer_top=(np.array([float(k)]), np.array([amp]), np.array([0.3])))
        zs = [pair.solve_z_m(base(pair, 0.0, (c, c))) for c in np.linspace(0, 2 * np.pi / 12, 25)]
        ptp[k] = np.ptp(zs)
    # order 12: every ball's approach changes by cos(a)·amp·cos(...), z by ≈ that·/(2 sin a) each way
    expect = 2 * math.cos(GEOM.contact_angle_rad) * amp / (2 * math.sin(GEOM.contact_angle_rad))
    assert ptp[12] == pytest.approx(expect, rel=0.02)
    assert ptp[11] < 1e-3 * ptp[12] and ptp[13] < 1e-3 * ptp[12]


def _thrust():
    return AerostaticThrust(25e-3, 60e-3, 42e-3, 10e-6, 101325.0 + 5e5)


def test_thrust_two_gap_law_is_the_pad_law_and_z_follows_the_supply():
    t = _thrust()
    for h in (8e-6, 10e-6, 12e-6):
        assert t.pad_force_N(h, gap_film_m=h) == t.pad_force_N(h)
    W = -50.0
    sup = SupplyPressure(t.supply_pressure_Pa, 0.005, 300.0, 0.002, np.random.default_rng(3))
    no_form = {f: (np.array([8.0]), np.array([0.0]), np.array([0.0])) for f in ("lower", "upper")}
    ax = AirThrustAxial(t, sup, W, no_form)
    K0 = t.stiffness_N_m()
    for ts in (0.0, 77.0, 420.0, 1500.0):
        ps = float(sup(ts))
        exact = t.position_under_load_m(W, ps) - t.position_under_load_m(W, t.supply_pressure_Pa)
        assert ax.z_supply_m(ts) == pytest.approx(exact, rel=2e-3, abs=1e-14)
        # ≈ W·(1/K(t) − 1/K0) with the weight as a load along −z: z = W/K (W < 0)
        assert ax.z_supply_m(ts) == pytest.approx(W * (1 / t.stiffness_N_m(ps) - 1 / K0), rel=0.05, abs=2e-13)
    assert ax.z_form_m(0.3) == 0.0


def test_thrust_runner_form_passes_only_orders_qN_at_the_holes():
    t = _thrust()        # 8 feed holes
    sup = SupplyPressure(t.supply_pressure_Pa, 0.0, 300.0, 0.0, np.random.default_rng(0))
    amp = 0.1e-6
    out = {}
    for k in (7, 8, 9, 16):
        forms = {"lower": (np.array([float(k)]), np.array([amp]), np.array([0.0])),
                 "upper": (np.array([float(k)]), np.array([0.0]), np.array([0.0]))}
        ax = AirThrustAxial(t, sup, -50.0, forms)
        out[k] = np.ptp([ax.z_form_m(th) for th in np.linspace(0, 2 * np.pi, 97)])
        (Al, Bl), (Au, Bu) = ax.AB["lower"], ax.AB["upper"]
    assert out[7] < 1e-20 and out[9] < 1e-20
    # order 8: the holes see the lobe in phase; the boxcar's G(8) = 0: z = A_l·a·cos/(ΣA + ΣB)
    assert out[8] == pytest.approx(2 * amp * abs(Al / (Al + Bl + Au + Bu)), rel=1e-9)
    assert out[16] == pytest.approx(out[8], rel=1e-9)
    assert Al > 0 > Bl and Al + Bl < 0           # orifice: more curtain, more pressure; stiff overall


def scenario(**kw):
    return small_scenario(**{"bearings.type": "ball", "errors.disk_tilt": "0 arcsec", **kw})


def test_face_motion_is_axial_plus_R_times_tilt_on_the_posed_bench():
    b = Bench(scenario(**{"axial.face_probe_radius": "30 mm", "axial.face_probe_azimuth": "40 deg",
                          "bench.gravity_direction": "-z"}))
    st = SimBenchState(b)
    sc = b.sc
    pole = SimAxialProbe.axial_from_scenario(sc, st, b, "probe_axial")
    face = SimAxialProbe.axial_from_scenario(sc, st, b, "probe_face")
    tilt_seen = []
    for i, th in enumerate(np.linspace(0, 2 * np.pi, 13)[:-1]):
        p = b.pose_at(th, t_s=5.0 * i)
        z = p.extra["axial_m"]
        n = p.extra["spin_axis_lab"]
        R, beta = 0.03, math.radians(40.0)
        by_def = z - R * (n[0] * math.cos(beta) + n[1] * math.sin(beta))     # axial + R × tilt, first order
        assert face.sim_displacement_m(p) == pytest.approx(face_truth_m(p, R, beta), abs=1e-13)
        # the same to the axis point's offset in the disk plane (~µm) times the tilt (~µrad): < 1e-11 m
        assert face_truth_m(p, R, beta) == pytest.approx(by_def, abs=1e-11)
        # the pole reading: z less the centring's second-order e²/(2R) (e = 2.5 µm: 0.3 nm)
        assert pole.sim_displacement_m(p) == pytest.approx(z, abs=1e-9)
        tilt_seen.append(R * math.hypot(n[0], n[1]))
    assert max(tilt_seen) > 1e-8           # the test has a tilt to see (R × tilt > 10 nm)


def test_without_the_section_nothing_changes():
    plain = Bench(scenario())
    assert plain.axial is None and "axial" not in plain.truth()
    p = plain.pose_at(0.7, t_s=3.0)
    assert "axial_m" not in p.extra
    with_ax = Bench(scenario(**{"axial.sphere_probe": True}))
    q = with_ax.pose_at(0.7, t_s=3.0)
    # the radial solve is untouched (decoupled): the shaft's orientation bit for bit, its position
    # moved along the spin axis by z only
    assert np.array_equal(p.disk.R, q.disk.R)
    np.testing.assert_allclose(q.disk.pos - p.disk.pos, q.extra["axial_m"] * q.extra["spin_axis_lab"], atol=1e-18)


def test_iso230_7_axial_values_on_synthetic_revolutions():
    th = np.arange(0, 360, 10.0)
    sync = 0.2 * np.cos(np.deg2rad(th)) + 0.1 * np.cos(np.deg2rad(5 * th))
    revs = np.array([sync + d for d in (0.0, 0.03, -0.02)])
    em = axial_error_motion(th, revs, 0.01)
    assert em["synchronous_um"] == pytest.approx(np.ptp(sync), abs=1e-12)   # fundamental kept
    assert em["residual_synchronous_um"] == pytest.approx(np.ptp(0.1 * np.cos(np.deg2rad(5 * th))), abs=1e-12)
    assert em["fundamental_um"] == pytest.approx(0.2, abs=1e-12)
    assert em["asynchronous_um"] == pytest.approx(0.05, abs=1e-12)
    assert em["total_u_um"] == pytest.approx(math.sqrt(2) * 0.01)
    assert axial_face_error_motion(np.zeros(36), th, None, None, None) is None


@pytest.fixture(scope="module")
def axial_ds(datasets):
    sc = scenario(**{"axial.face_probe_radius": "30 mm", "procedure.radial_reps": 3,
                     "procedure.radial_positions": 36, "procedure.polygon_shifts": ["0 deg"],
                     "procedure.selfcal": False, "procedure.directions": ["forward"],
                     "instruments.probe.repeatability": "0.005 um", "instruments.probe.resolution": "0.001 um"})
    return datasets.dataset(sc)


def test_analysis_axial_and_face_against_truth(axial_ds):
    from benchtwin.analysis.dataset import Dataset
    from benchtwin.analysis.pipeline import step_radial_motion

    ds = Dataset(axial_ds)
    assert ds.bench["face_probe_radius_mm"] == pytest.approx(30.0)
    af = step_radial_motion(ds, 10).iso230_7["axial_face"]
    locs = {loc["name"]: loc for loc in af["locations"]}
    with (axial_ds / "truth" / "radial_motion.csv").open() as f:
        rows = list(csv.DictReader(f))
    for name, col in (("axial", "axial_um"), ("face", "face_um")):
        v = np.array([float(r[col]) for r in rows]).reshape(3, -1)
        truth = {"total_um": np.ptp(v), "synchronous_um": np.ptp(v.mean(0)), "asynchronous_um": np.ptp(v, axis=0).max()}
        loc = locs[name]
        assert truth["total_um"] > 0.1            # a motion to measure
        # the face probe reads the disk, whose wobble on the shaft is 0 here (errors.disk_tilt = 0):
        # readings = truth + linearity + 0.005 µm noise (+ the pole's e²/2R)
        for key, val in truth.items():
            assert abs(loc[key] - val) <= 3 * loc[key.replace("_um", "_u_um")] + 0.01, (name, key, loc[key], val)
