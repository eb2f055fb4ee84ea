"""The autocollimator's optics (twin/instruments/ac_optics.py): the exact detector law against its
small-angle series, the legacy coefficient mapping, the symmetry of each cause, and the simulated
instrument reading through them (hidden ac_scale with physical keys)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.twin.hidden import Hidden
from benchtwin.twin.instruments.ac_optics import FOCAL_LENGTH_M, AutocollimatorOptics
from benchtwin.units import ARCSEC

V = np.linspace(-300.0, 300.0, 121) * ARCSEC    # face angles, rad


def _x(o: AutocollimatorOptics, v=V) -> np.ndarray:
    return np.array([o.reading_rad(float(x))[0] for x in v])


def test_ideal_instrument_reads_the_face_angle_exactly():
    o = AutocollimatorOptics()
    assert o.ideal
    for v in (0.0, 1e-5, -3.3e-3):
        assert o.reading_rad(v, -v) == (v, -v)                    # bit-exact: no tan/atan round trip
        sx, sy = o.detector_position_m(v, -v)
        assert sx == pytest.approx(FOCAL_LENGTH_M * math.tan(2 * v), rel=1e-15, abs=1e-18)
        assert sy == pytest.approx(-FOCAL_LENGTH_M * math.tan(2 * v), rel=1e-15, abs=1e-18)


@pytest.mark.parametrize("df,tau_deg,k1", [(2e-3, 0.0, 0.0), (0.0, 0.5, 0.0), (0.0, 0.0, 50.0), (-1e-3, 2.0, -20.0)])
def test_small_angle_coefficients_match_the_exact_law(df, tau_deg, k1):
    """A degree-5 fit of the exact reading over ±300″ gives c1, c2, c3 of the series (relative
    1e-6 on c1; c2, c3 within 1 % of their value or of the scale of the other terms)."""
    o = AutocollimatorOptics(focal_length_error=df, detector_tilt_rad=math.radians(tau_deg), distortion_k1=k1)
    c = np.polynomial.polynomial.polyfit(V, _x(o), 5)
    c1, c2, c3 = o.small_angle_coefficients()
    assert c[1] == pytest.approx(c1, rel=1e-9)
    assert c[2] == pytest.approx(c2, rel=1e-3, abs=1e-6)
    assert c[3] == pytest.approx(c3, rel=1e-2, abs=1e-2)
    assert abs(c[0]) < 1e-15


def test_causes_have_their_symmetry():
    """Focal length and distortion are odd in v (a turned-over face reads the opposite); the
    detector tilt adds the even part; nothing but the tilt changes the x reading's v² term."""
    odd = AutocollimatorOptics(focal_length_error=1e-3, distortion_k1=30.0)
    x = _x(odd)
    np.testing.assert_allclose(x + x[::-1], 0.0, atol=1e-18)
    tilt = AutocollimatorOptics(detector_tilt_rad=math.radians(1.0))
    x = _x(tilt)
    even = 0.5 * (x + x[::-1])
    np.testing.assert_allclose(even, 2 * math.tan(math.radians(1.0)) * V**2, rtol=1e-3, atol=1e-16)
    # linear f·θ firmware against the f·tan law: the classical odd cubic (4/3)·v³ (0.03″ at 1000″)
    v = 1000 * ARCSEC
    assert (0.5 * math.tan(2 * v) - v) / ARCSEC == pytest.approx(4 / 3 * v**3 / ARCSEC, rel=1e-4)
    assert 0.030 < 4 / 3 * v**3 / ARCSEC < 0.032


@pytest.mark.parametrize("gain,q", [(0.01, 1e-4), (0.0, 3e-4), (-2e-3, -5e-5), (0.0, 1e-7)])
def test_legacy_coefficients_map_to_optics_with_those_terms(gain, q):
    o = AutocollimatorOptics.from_coefficients(gain, q)
    c1, c2, _ = o.small_angle_coefficients()
    assert c1 == pytest.approx(1 + gain, rel=1e-12)
    assert c2 * ARCSEC == pytest.approx(q, rel=1e-12, abs=1e-20)
    # and the exact reading at 10″ is the legacy reading to its third-order remainder
    v = 10 * ARCSEC
    legacy = v * (1 + gain) + q * (v / ARCSEC) * v
    assert abs(o.reading_rad(v)[0] - legacy) / ARCSEC < 2e-3


def test_q_of_a_real_instrument_needs_a_tiny_tilt():
    """|q| ≲ 1e-7/″ (0.05–0.25″ instruments: 0.1″ at 1000″) is a tilt of about 0.6° (q/1″ = 2·tanτ)."""
    o = AutocollimatorOptics.from_coefficients(0.0, 1e-7)
    assert abs(math.degrees(o.detector_tilt_rad)) == pytest.approx(math.degrees(math.atan(1e-7 / ARCSEC / 2)), rel=1e-12)
    assert 0.55 < abs(math.degrees(o.detector_tilt_rad)) < 0.6
    big = AutocollimatorOptics.from_coefficients(0.01, 1e-4)
    assert 84.0 < math.degrees(big.detector_tilt_rad) < 85.0
    assert big.x_only and big.reading_rad(1e-4, 3e-5)[1] == 3e-5     # legacy: X reading only


def test_hidden_ac_scale_physical_keys_build_the_optics_and_forbid_mixing():
    h = Hidden({"ac_scale": {"focal_length_error": 1e-3, "detector_tilt": math.radians(0.2), "distortion_k1": 5.0,
                             "focal_length": 0.3}})
    o = h.ac_optics()
    assert o is not None and o.focal_length_error == 1e-3 and o.distortion_k1 == 5.0
    assert Hidden({}).ac_optics() is None
    with pytest.raises(ValueError, match="not both"):
        Hidden({"ac_scale": {"gain": 0.01, "detector_tilt": 0.1}}).ac_optics()
    t = h.truth()["autocollimator_optics"]
    assert t["x_reading_coefficients"]["c1"] == pytest.approx(1e-3 + 1 / math.cos(math.radians(0.2)) + 1e-3 *
                                                              (1 / math.cos(math.radians(0.2)) - 1), rel=1e-12)


def test_simulated_autocollimator_reads_through_the_optics():
    """The twin's instrument applies the optics to the exact face angles (both axes)."""
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import sim_build

    from tests.support.scenarios import HIDDEN_DIR, without_hidden

    sc = load_scenario(HIDDEN_DIR / "ac_scale.toml").with_overrides(
        {"hidden.ac_scale.gain": 0.0, "hidden.ac_scale.quadratic_per_arcsec": 0.0,
         "hidden.ac_scale.focal_length_error": 2e-3, "hidden.ac_scale.distortion_k1": 100.0,
         "instruments.autocollimator.noise": "0 arcsec", "instruments.autocollimator.resolution": "0 arcsec",
         "instruments.autocollimator.accuracy": "0 arcsec"})
    readings = []
    for s in (sc, without_hidden(sc)):
        _, st, inst = sim_build(s, camera=False)
        st.apply_context({"rep": 0, "direction": "forward", "polygon_start_face": 1, "shift_deg": 0.0})
        inst["stage"].move_to(2 * 360 / 23 + 0.02)   # a face 72″ off the instrument axis
        ac = inst["autocollimator"]
        readings.append((ac.read(), ac.sim_exact_angles(st.pose)[:2], ac.optics))
    (r_h, (vx, vy), o), (r_0, _, o0) = readings
    assert o0 is None and o is not None
    ex, ey = o.reading_rad(vx, vy)
    assert r_h["x_arcsec"] == pytest.approx(ex / ARCSEC, abs=1e-9)
    assert r_h["y_arcsec"] == pytest.approx(ey / ARCSEC, abs=1e-9)
    assert abs(r_h["x_arcsec"] - r_0["x_arcsec"]) > 1e-3 * abs(r_0["x_arcsec"]) * 0.9
