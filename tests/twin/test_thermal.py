"""Tests of the bench's thermal state (twin/thermal.py) and its effects on the instruments.

The closed forms are checked against a numerical integration of the node equations (scipy's
solve_ivp, rtol 1e-10): agreement to 1e-6 K. The drift over the hsieh2022 run is checked against
the coefficients and temperature changes the scenario states (docs/physics.md).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from benchtwin.twin.instruments.autocollimator import AutocollimatorSpec, SimAutocollimator
from benchtwin.twin.instruments.stage import SimBenchState
from benchtwin.twin.physics import ARCSEC, Bench
from benchtwin.twin.scenario import default_scenario_path, load_scenario
from benchtwin.twin.scenario_schema import SCHEMA
from benchtwin.twin.thermal import Thermal

SCEN = default_scenario_path().parent


def params(**kw) -> dict:
    th = {k: f.default for k, f in SCHEMA["thermal"].items()}
    th.update(ambient_amplitude=1.0, ambient_period=6 * 3600.0, motor_rise=2.0, axis_drift=0.1e-6,
              axis_drift_azimuth=0.3, probe_stand_growth=0.2e-6, ac_drift=0.05 * ARCSEC)
    th.update(kw)
    return th


def test_closed_form_matches_integrated_node_equations():
    th = params()
    m = Thermal(th, phase_rad=0.7)
    A, w, phi, T0 = m.A, m.w, 0.7, m.T0
    amb = lambda t: T0 + A * math.sin(w * t + phi)  # noqa: E731
    # periodic initial state of each lag: the closed form's value at t = 0
    s0 = m.state(0.0)

    def rhs(t, y):
        Tm, Ts, Tp, Tac = y
        Tm_eq = amb(t) + m.dTm
        lag_amb_m = T0 + A / math.sqrt(1 + (w * m.tau_m) ** 2) * math.sin(w * t + phi - math.atan(w * m.tau_m))
        return [(Tm_eq - Tm) / m.tau_m,
                (amb(t) + m.share * (Tm - lag_amb_m) - Ts) / m.tau_s,
                (amb(t) - Tp) / m.tau_p,
                (amb(t) - Tac) / m.tau_ac]

    t_end = 8 * 3600.0
    ts = np.linspace(0, t_end, 17)
    sol = solve_ivp(rhs, (0, t_end), [s0.motor_degC, s0.structure_degC, s0.probe_stand_degC,
                                      s0.autocollimator_degC], t_eval=ts, rtol=1e-10, atol=1e-12)
    for i, t in enumerate(ts):
        s = m.state(t)
        np.testing.assert_allclose([s.motor_degC, s.structure_degC, s.probe_stand_degC, s.autocollimator_degC],
                                   sol.y[:, i], atol=1e-6)
    # the motor warms by its stated rise after many time constants
    assert m.state(20 * m.tau_m).motor_degC - m.state(20 * m.tau_m).ambient_degC == pytest.approx(
        m.dTm, abs=1.1 * A)


def test_inert_by_default():
    th = {k: f.default for k, f in SCHEMA["thermal"].items()}
    th["axis_drift_azimuth"] = 0.0
    m = Thermal(th, 0.0)
    assert not m.active
    assert m.ac_drift_rad(1e5) == 0.0 and m.probe_stand_drift_m(1e5) == 0.0


def test_hsieh2022_thermal_drift_over_the_run():
    """hsieh2022.toml states its environment (20 ± 1 °C, Hsieh sec. 3) and the coefficients of the
    drifts; over the 6.8 h of its run the autocollimator's zero drifts by ac_drift·ΔT_ac and the
    axis by axis_drift·ΔT_s, both read through the twin's own instruments and physics."""
    sc = load_scenario(SCEN / "hsieh2022.toml")
    b = Bench(sc)
    th = b.thermal
    assert th.active
    assert th.T0 == 20.0 and th.A == 1.0
    t_end = 6.8 * 3600.0
    dT_ac = th.state(t_end).autocollimator_degC - th.state(0).autocollimator_degC
    dT_s = th.state(t_end).structure_degC - th.state(0).structure_degC
    assert 0.05 < abs(dT_s) < 2.0                       # the run is long enough to see the bench warm
    # the autocollimator, read at one pose at t = 0 and at t_end (noise off)
    st = SimBenchState(b)
    ac = SimAutocollimator("ac", st, AutocollimatorSpec(noise_rad=0.0, resolution_rad=0.0, accuracy_rad=0.0))
    st.pose = b.pose_at(0.0, t_s=0.0)
    r0 = ac.read()["x_arcsec"]
    st.clock.set(t_end)
    r1 = ac.read()["x_arcsec"]
    assert r1 - r0 == pytest.approx(th.ac_rad_K * dT_ac / ARCSEC, rel=1e-9, abs=1e-12)
    # the axis: its disk-plane position moves with the housings by axis_drift·ΔT_s
    p0 = b.pose_at(0.1, t_s=1.0).extra["axis_disk_plane_m"].copy()
    p1 = b.pose_at(0.1, t_s=t_end).extra["axis_disk_plane_m"].copy()
    drift = np.hypot(*(p1 - p0))
    assert drift == pytest.approx(abs(th.axis_drift_m_K * (th.state(t_end).structure_degC
                                                           - th.state(1.0).structure_degC)), rel=0.02)


def test_room_control_cycling_and_microscope_stand_closed_form():
    """The room control's cycling (hvac_*) is a second sinusoid of the air that every node lags
    with its own τ; the closed form matches an integration of the probe- and microscope-stand
    nodes to 1e-6 K, and their drifts are growth × ΔT of their node since t = 0."""
    th = params(hvac_amplitude=0.5, hvac_period=900.0, hvac_phase=0.4, probe_stand_time_constant=730.0,
                probe_stand_growth=1.8e-6, microscope_stand_growth=2.3e-6, microscope_stand_time_constant=1520.0)
    m = Thermal(th, phase_rad=0.7)
    assert m.active
    T0, A, w, Ac, wc = m.T0, m.A, m.w, 0.5, 2 * math.pi / 900.0
    amb = lambda t: T0 + A * math.sin(w * t + 0.7) + Ac * math.sin(wc * t + 0.4)  # noqa: E731
    s0 = m.state(0.0)
    assert s0.ambient_degC == pytest.approx(amb(0.0), abs=1e-12)

    def rhs(t, y):
        return [(amb(t) - y[0]) / m.tau_p, (amb(t) - y[1]) / m.tau_c]

    ts = np.linspace(0, 3 * 3600.0, 25)
    sol = solve_ivp(rhs, (0, ts[-1]), [s0.probe_stand_degC, s0.microscope_stand_degC], t_eval=ts, rtol=1e-10,
                    atol=1e-12, max_step=30.0)
    for i, t in enumerate(ts):
        s = m.state(t)
        np.testing.assert_allclose([s.probe_stand_degC, s.microscope_stand_degC], sol.y[:, i], atol=1e-6)
        assert m.microscope_stand_drift_m(t) == pytest.approx(2.3e-6 * (s.microscope_stand_degC - s0.microscope_stand_degC))
        assert m.probe_stand_drift_m(t) == pytest.approx(1.8e-6 * (s.probe_stand_degC - s0.probe_stand_degC))
    # the arm (τ = 730 s) follows the 15-min cycling at 1/√(1 + (ωτ)²) of its amplitude
    m2 = Thermal(dict(th, ambient_amplitude=0.0, motor_rise=0.0), phase_rad=0.7)
    assert np.ptp([m2.state(t).probe_stand_degC for t in np.linspace(7200, 7200 + 900, 400)]) == pytest.approx(
        2 * Ac / math.sqrt(1 + (wc * 730.0) ** 2), rel=1e-3)


def test_cycling_off_changes_nothing():
    """hvac_amplitude = 0 (the default) and no microscope stand: the state is bit-identical to the
    model without them (datasets of scenarios that do not state them are unchanged)."""
    base = Thermal(params(), 0.7)
    off = Thermal(params(hvac_amplitude=0.0, hvac_period=600.0, hvac_phase=1.0), 0.7)
    for t in (0.0, 100.0, 5000.0, 1e5):
        assert base.state(t) == off.state(t)
    assert off.microscope_stand_drift_m(5000.0) == 0.0
    assert "hvac_amplitude_K" not in off.truth()
