"""Aerostatic journals (twin/air_bearing.py, issue 33 item 1): the restrictor and film laws, the
sector model's stiffness, the form's transfer through the film (which orders move the journal, in
which direction: emerging from the sector sums), and the supply pressure's motion in time."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.air_bearing import (
    P_AMBIENT_PA,
    AerostaticJournal,
    AerostaticThrust,
    SupplyPressure,
    generate_form,
    land_mean_pressure,
    orifice_mass_flow,
    slot_mass_flow,
)

P_S = P_AMBIENT_PA + 5e5


def journal(**kw) -> AerostaticJournal:
    args = dict(diameter_m=0.05, length_m=0.05, clearance_m=8e-6, supply_pressure_Pa=P_S, orifice_diameter_m=0.15e-3)
    args.update(kw)
    return AerostaticJournal(**args)


def test_orifice_flow_chokes_at_the_critical_ratio():
    rc = (2 / 2.4) ** (1.4 / 0.4)
    assert rc == pytest.approx(0.5283, abs=1e-4)
    a = 1e-7
    # below the critical ratio the flow no longer grows
    assert orifice_mass_flow(a, P_S, 0.3 * P_S) == pytest.approx(orifice_mass_flow(a, P_S, 0.5 * P_S), rel=0)
    # choked flow: C_d·A·p_s·sqrt(κ/(RT))·(2/(κ+1))^((κ+1)/(2(κ−1))) (the textbook closed form)
    RT = 287.05 * 293.15
    choked = 0.8 * a * P_S * math.sqrt(1.4 / RT) * (2 / 2.4) ** (2.4 / 0.8)
    assert orifice_mass_flow(a, P_S, 0.4 * P_S) == pytest.approx(choked, rel=1e-12)
    assert orifice_mass_flow(a, P_S, P_S) == 0.0


def test_land_mean_pressure_is_the_mean_of_the_square_root_profile():
    p_d, pa = 4e5, P_AMBIENT_PA
    x = np.linspace(0, 1, 200001)
    p = np.sqrt(p_d**2 - (p_d**2 - pa**2) * x)
    assert float(land_mean_pressure(p_d)) == pytest.approx(np.trapezoid(p, x), rel=1e-9)


def test_feed_pressure_balances_the_flows():
    j = journal()
    h = np.array([6e-6, 8e-6, 10e-6])
    p_d = j.feed_pressure_Pa(h)
    inflow = 2 * orifice_mass_flow(math.pi * j.orifice_diameter_m * h, P_S, p_d)
    outflow = 2 * slot_mass_flow(j.sector_width_m, h, j.land_m, p_d)
    assert np.allclose(inflow, outflow, rtol=1e-9)
    assert np.all(np.diff(p_d) < 0)            # a wider gap drains the pocket


def test_stiffness_is_positive_and_follows_the_supply():
    j = journal()
    k = j.stiffness_N_m()
    assert 50e6 < k < 200e6                    # a 50 mm air journal: tens to a few hundred N/µm
    assert 0.5 < j.pressure_ratio() < 0.8      # the designed restrictor: near the stiffness optimum
    assert j.stiffness_N_m(1.02 * P_S) > k > j.stiffness_N_m(0.98 * P_S)
    # the non-linear law: at half the gap the film no longer follows the linear stiffness
    f1 = -j.force_N(np.array([1e-6, 0.0]))[0]
    f4 = -j.force_N(np.array([4e-6, 0.0]))[0]
    assert f1 == pytest.approx(k * 1e-6, rel=0.02)
    assert abs(f4 / (4 * f1) - 1) > 0.01
    # near rotational symmetry: the force on a displacement is along it (N discrete sectors leave
    # an N-fold anisotropy of the non-linear law: 3e-8 of the force at 1 µm)
    u = 1e-6 * np.array([math.cos(0.3), math.sin(0.3)])
    f = j.force_N(u)
    assert abs(f[0] * u[1] - f[1] * u[0]) < 1e-6 * np.linalg.norm(f) * np.linalg.norm(u)


@pytest.mark.parametrize("n", [6, 8, 9])
def test_form_transfer_emerges_from_the_sector_sums(n):
    """A journal lobe moves the unloaded journal only at k ≡ ±1 (mod N), forward at +1, backward at
    −1, by G(k)/G(1); checked against a direct equilibrium of the non-linear sector law."""
    j = journal(feed_holes=n)
    ks = np.arange(1, 3 * n + 2)
    P, Q = j.form_transfer(ks)
    g1 = float(j.G(1))
    for k, p, q in zip(ks, P, Q):
        gain = float(j.G(k)) / g1
        if k % n == 1:
            # forward: u = −gain·(cos X, sin X)
            assert p == pytest.approx([-gain, 0.0], abs=1e-12) and q == pytest.approx([0.0, -gain], abs=1e-12)
        elif k % n == n - 1:
            # backward: u = −gain·(cos X, −sin X)
            assert p == pytest.approx([-gain, 0.0], abs=1e-12) and q == pytest.approx([0.0, gain], abs=1e-12)
        else:
            assert np.abs(p).max() < 1e-14 and np.abs(q).max() < 1e-14
    # the averaging: order N ± 1 passes ≈ 1/(N ± 1) of its amplitude
    assert float(j.G(n + 1)) / g1 == pytest.approx(-1.0 / (n + 1), rel=1e-12)
    assert float(j.G(n - 1)) / g1 == pytest.approx(1.0 / (n - 1), rel=1e-12)

    # direct check: solve F(u) = 0 with the sectors' mean form of an (N+1)-lobed journal
    a, k, theta, psi = 0.05e-6, n + 1, 0.7, 0.4
    phi = 2 * math.pi * np.arange(n) / n
    mean_form = a * float(j.G(k)) * np.cos(k * (phi - theta) - psi)
    u = np.zeros(2)
    K = j.stiffness_N_m()
    for _ in range(20):
        u = u + j.force_N(u, form_m=mean_form) / K
    X = k * theta + psi
    gain = float(j.G(k)) / g1
    expect = -a * gain * np.array([math.cos(X), math.sin(X)])
    assert np.allclose(u, expect, atol=1e-3 * a * abs(gain) + 1e-13)


def test_form_generator_roundness_and_spectrum():
    k, a, p = generate_form(0.1e-6, np.random.default_rng(3))
    grid = np.linspace(0, 2 * math.pi, 4096, endpoint=False)
    prof = (a[:, None] * np.cos(k[:, None] * grid - p[:, None])).sum(0)
    assert prof.max() - prof.min() == pytest.approx(0.1e-6, rel=1e-12)
    assert k[0] == 2 and np.all(a > 0)
    assert np.mean(a[:5]) > 3 * np.mean(a[-5:])     # falling with the order


def test_supply_pressure_is_a_function_of_time():
    s = SupplyPressure(P_S, 0.005, 300.0, 0.001, np.random.default_rng(1))
    t = np.linspace(0, 3600, 7201)
    r = s.relative(t)
    assert np.std(r) == pytest.approx(math.sqrt(0.005**2 / 2 + 0.001**2), rel=0.15)
    assert s(100.0) == s(100.0) and s(100.0) != s(250.0)
    still = SupplyPressure(P_S, 0.0, 300.0, 0.0, np.random.default_rng(1))
    assert not still.active and np.all(still.relative(t) == 0)


def test_thrust_bearing_carries_a_load_and_is_stiff():
    t = AerostaticThrust(0.025, 0.06, 0.042, 10e-6, P_S)
    k = t.stiffness_N_m()
    assert k > 0
    z = t.position_under_load_m(-50.0)
    assert t.force_N(z) == pytest.approx(50.0, rel=1e-6)
    assert z == pytest.approx(-50.0 / k, rel=0.05)


def test_air_bench_moves_in_time_under_a_radial_load():
    """On a horizontal air-bearing bench the supply's fluctuation moves the loaded journals with
    TIME at a fixed shaft angle; the form's motion repeats with the angle."""
    from twin.physics import Bench
    from twin.scenario import load_scenario

    sc = load_scenario("scenarios/hsieh2022.toml").with_overrides({
        "bench.gravity_direction": "-y", "bearings.supply_ripple": 0.01, "bearings.supply_noise": 0.0,
        "thermal.axis_drift": "0 um/K"})
    b = Bench(sc)
    ab = b.air_bearings
    assert ab is not None
    assert b.model.tendon_stiffness[b.model.tendon("bearing_top_x").id] == pytest.approx(ab.K0)
    y = []
    for t in (0.0, 75.0, 150.0, 225.0):
        b.pose_at(0.5, t_s=t)
        y.append(b.data.qpos[1])
    y = np.array(y)
    u_load = -b._housing_m
    k = ab.stiffness_at(ab.supply(np.array([0.0, 75.0, 150.0, 225.0])))
    # the journals' sag scales by K0/K(t): W/K(t) − W/K0 along the load
    expect_top = u_load[1] * (k / ab.K0 - 1.0)
    assert np.ptp(y) > 0.5 * np.ptp(expect_top) > 0
    # with a still supply the same angle gives the same pose at any time
    sc0 = sc.with_overrides({"bearings.supply_ripple": 0.0})
    b0 = Bench(sc0)
    p = [b0.pose_at(0.5, t_s=t).shaft_angle_rad for t in (0.0, 500.0)]
    q = []
    for t in (0.0, 500.0):
        b0.pose_at(0.5, t_s=t)
        q.append(b0.data.qpos[:2].copy())
    assert np.allclose(q[0], q[1], rtol=0, atol=1e-14) and p[0] == pytest.approx(p[1], abs=1e-14)


def test_bad_air_geometry_names_the_key():
    from twin.scenario import ScenarioError, load_scenario

    sc = load_scenario("scenarios/hsieh2022.toml")
    with pytest.raises(ScenarioError, match="bearings.thrust_"):
        sc.with_overrides({"bearings.thrust_feed_radius": "70 mm"})
    with pytest.raises(ScenarioError, match="bearings.air_clearance"):
        sc.with_overrides({"bearings.air_clearance": "90 um", "bearings.air_journal_diameter": "5 mm"})
