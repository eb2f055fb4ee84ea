"""The measuring loop's thermal drift (issue 33 item 3): the read-head mount and the autocollimator
stand as first-order lags of the room air ([measuring_loop], twin/thermal.py), moving the heads'
lines of sight and the autocollimator's optical axis in the exact geometry.

- the nodes' closed form against an integration of τ·T' + T = T_air(t) (1e-6 K);
- the drift formula: with the cage's slip off and no other time-varying motion (no axis drift), the
  true α at a fixed stop drifts as −(growth·ΔT_h(t))/r, within 5 % (the head's tangential
  displacement over the radius), through the stage, the bench and the encoder, keyed by bench time;
- the autocollimator's reading turns with its stand's yaw, growth·ΔT/base;
- a scenario without the section is unchanged; the keys are validated with units and ranges.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from benchtwin.twin.instruments.autocollimator import SimAutocollimator
from benchtwin.twin.instruments.stage import SimRotaryStage
from benchtwin.twin.scenario import ScenarioError, load_scenario
from benchtwin.twin.simulate import sim_build
from benchtwin.units import ARCSEC

ROOT = Path(__file__).resolve().parents[2]

#: slip off, no axis drift: the head's mount is the only time-varying motion of the loop
STILL = {"bearings.cage_slip": 0.0, "thermal.axis_drift": "0 um/K"}
LOOP = {"measuring_loop.head_mount_growth": "0.46 um/K",          # aluminium 23e-6/K × 20 mm arm
        "measuring_loop.head_mount_time_constant": "16 min",
        "measuring_loop.autocollimator_stand_growth": "0.115 um/K",  # aluminium × 5 mm asymmetry
        "measuring_loop.autocollimator_stand_base": "100 mm",
        "measuring_loop.autocollimator_stand_time_constant": "1 h"}


def scenario(**kw):
    return load_scenario(ROOT / "scenarios" / "jia2019.toml").with_overrides(kw)


def test_loop_nodes_closed_form_matches_integration():
    sc = scenario(**STILL, **LOOP)
    bench, _state, _inst = sim_build(sc, camera=False)
    th = bench.thermal
    assert th.loop_active and th.Ac == pytest.approx(0.5)
    air = lambda t: th.state(t).ambient_degC  # noqa: E731

    def rhs(t, y):
        return [(air(t) - y[0]) / th.tau_h, (air(t) - y[1]) / th.tau_acs]

    ts = np.linspace(0.0, 3 * 3600.0, 25)
    sol = solve_ivp(rhs, (0.0, ts[-1]), [th.head_mount_degC(0.0), th.autocollimator_stand_degC(0.0)], t_eval=ts,
                    rtol=1e-10, atol=1e-12, max_step=20.0)
    for i, t in enumerate(ts):
        np.testing.assert_allclose([th.head_mount_degC(t), th.autocollimator_stand_degC(t)], sol.y[:, i], atol=1e-6)
        dT = th.head_mount_degC(t) - th.head_mount_degC(0.0)
        assert th.head_mount_drift_m(t) == pytest.approx((0.46e-6 * dT, 0.0), abs=1e-18)
    # with the daily cycle off, the mount (16 min) follows the 15-min cycling at 1/√(1 + (ωτ)²) of its ±0.5 K
    th2 = sim_build(scenario(**STILL, **LOOP, **{"thermal.ambient_amplitude": "0 K"}), camera=False)[0].thermal
    w = 2 * math.pi / 900.0
    swing = np.ptp([th2.head_mount_degC(t) for t in np.linspace(7200.0, 7200.0 + 900.0, 600)])
    assert swing == pytest.approx(2 * 0.5 / math.sqrt(1 + (w * 960.0) ** 2), rel=1e-4)


@pytest.mark.parametrize("target_deg", [30.0, 200.0])
def test_alpha_drifts_as_head_displacement_over_radius(target_deg):
    """α = reading − true angle at a stop revisited over an hour: its change follows
    −(µm/K · ΔT_h(t))/r within 5 % of its range (the head moves counter-clockwise by growth·ΔT_h,
    the graduation under it by that arc, and the counter, which adds the head's nominal azimuth,
    reads that much less)."""
    sc = scenario(**STILL, **LOOP)
    bench, state, inst = sim_build(sc, camera=False)
    enc = inst["encoder"]
    stage = SimRotaryStage("ideal", state, enc)     # lands the exact reading on the target (1e-6″)
    th = bench.thermal
    r = enc.radius_m
    ts = np.linspace(0.0, 3600.0, 25)
    alpha, pred = [], []
    for t in ts:
        state.clock.set(float(t))
        stage.move_to(target_deg)
        p = state.pose
        alpha.append((enc.sim_exact_readings(p)[0] - p.shaft_angle_rad) / ARCSEC)
        pred.append(-0.46e-6 * (th.head_mount_degC(p.t_s) - th.head_mount_degC(ts[0])) / r / ARCSEC)
    drift = np.asarray(alpha) - alpha[0]
    pred = np.asarray(pred) - pred[0]
    assert np.ptp(pred) > 0.1                       # the loop drifts by tenths of an arcsecond
    assert np.max(np.abs(drift - pred)) <= 0.05 * np.max(np.abs(pred))


def test_alpha_is_still_without_the_mount():
    """The same stops without [measuring_loop]: α does not move (so the drift above is the mount's)."""
    sc = scenario(**STILL)
    bench, state, inst = sim_build(sc, camera=False)
    assert not bench.thermal.loop_active
    enc = inst["encoder"]
    stage = SimRotaryStage("ideal", state, enc)
    alpha = []
    for t in (0.0, 900.0, 1800.0, 3600.0):
        state.clock.set(t)
        stage.move_to(30.0)
        p = state.pose
        alpha.append((enc.sim_exact_readings(p)[0] - p.shaft_angle_rad) / ARCSEC)
    assert np.ptp(alpha) < 1e-3


def test_autocollimator_turns_with_its_stand():
    """The autocollimator's exact x reading of a still polygon changes by the stand's yaw,
    growth·ΔT/base (the line of sight turned counter-clockwise reads + that angle); y is unchanged."""
    sc = scenario(**STILL, **LOOP)
    bench, state, _inst = sim_build(sc, camera=False)
    ac = SimAutocollimator.sim_from_scenario(sc, state)
    th = bench.thermal
    pose0 = bench.pose_at(0.0, t_s=0.0)
    x0, y0, f0 = ac.sim_exact_angles(pose0)
    for t in (600.0, 1800.0, 3600.0):
        p = bench.pose_at(0.0, t_s=t)
        x, y, f = ac.sim_exact_angles(p)
        yaw = 0.115e-6 * (th.autocollimator_stand_degC(t) - th.autocollimator_stand_degC(0.0)) / 0.1
        assert f == f0
        # the polygon itself stands still (no axis drift, no slip): the same pose to < 1e-12 rad
        assert np.max(np.abs(p.polygon.R - pose0.polygon.R)) < 1e-12
        assert x - x0 == pytest.approx(yaw, abs=1e-12)
        assert y == pytest.approx(y0, abs=1e-12)
    assert abs(th.autocollimator_stand_yaw_rad(3600.0)) > 1e-8


def test_keys_are_validated():
    with pytest.raises(ScenarioError, match="measuring_loop.head_mount_growth"):
        scenario(**{"measuring_loop.head_mount_growth": "0.46 um"})          # a length, not per K
    with pytest.raises(ScenarioError, match="measuring_loop.autocollimator_stand_base"):
        scenario(**{"measuring_loop.autocollimator_stand_base": "0 mm"})     # below 1 mm
    with pytest.raises(ScenarioError, match="measuring_loop"):
        scenario(**{"measuring_loop.head_mount_lag": "1 min"})               # unknown key
