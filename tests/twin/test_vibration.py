"""twin/vibration.py and the camera's use of it: the CCD microscope stand's floor-borne vibration.

Checked against closed forms and an independent time-domain integration:

- the transmissibility integral under a white base acceleration is Miles' equation (1e-7);
- the one-third-octave conversion: a band's integral of the PSD is the band's mean square (0.5 %);
- jia2019's model (a VC-A floor through a 59 Hz, ζ = 0.03 stand) against Miles at the mode (3 %:
  the criterion's acceleration PSD grows ∝ f across the mode) and, at ζ = 0.005, 1 %;
- the exposure's mean of a sinusoid is sinc(f·T) (numerical quadrature, 1e-9), and the model's
  frame RMS is the instantaneous one times |sinc(f_n·T)| (2 %);
- a time-domain integration of the oscillator (scipy's exact ZOH discretisation, white base
  acceleration, 400 s): its RMS, with and without the exposure's box average, matches the spectral
  integral (3 %, the record's statistical precision is ~1 %), and frames 1.37 s apart are
  uncorrelated;
- the frames' independence: the model's autocorrelation at jia2019's frame spacing (1.37 s, 15
  correlation times) is < 1e-3;
- the camera: a frame's displacement is drawn per step (the same for the truth and the render,
  reproducible, another seed another draw), radial and tangential, with the model's RMS; it moves
  the rendered image's centre; without ``[vibration]`` nothing changes.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate, signal, stats

from benchtwin.twin import vibration as V
from benchtwin.twin.scenario import load_scenario
from tests.support.poses import eccentric_pose   # the instrument tests' posed disk

ROOT = Path(__file__).resolve().parents[2]
JIA = load_scenario(ROOT / "scenarios" / "jia2019.toml")
#: jia2019's frame spacing: 6° steps, each a move, the settle and the dwell (ccd/index.csv t_s)
JIA_FRAME_SPACING_S = 1.3746


def jia_model(**kw) -> V.StandVibration:
    m = V.StandVibration.from_section(JIA["vibration"])
    assert m is not None
    return V.StandVibration(**{**{k: getattr(m, k) for k in (
        "floor_velocity", "stand_frequency", "stand_damping", "exposure_time", "floor_corner_frequency",
        "floor_low_frequency", "floor_high_frequency")}, **kw})


def _quad(fn, edges):
    return sum(integrate.quad(fn, a, b, limit=400, epsabs=0.0, epsrel=1e-11)[0] for a, b in zip(edges[:-1], edges[1:]))


@pytest.mark.parametrize("fn, zeta", [(59.0, 0.03), (20.0, 0.005), (300.0, 0.1)])
def test_transmissibility_integral_under_white_input_is_miles(fn, zeta):
    s0 = 3e-7   # (m/s²)²/Hz
    var = _quad(lambda f: s0 * float(V.relative_receptance_sq(f, fn, zeta)), [0.0, 0.5 * fn, fn, 2 * fn, 50 * fn])
    var += integrate.quad(lambda f: s0 * float(V.relative_receptance_sq(f, fn, zeta)), 50 * fn, np.inf)[0]
    assert math.sqrt(var) == pytest.approx(V.miles_relative_rms(s0, fn, zeta), rel=1e-7)


def test_third_octave_band_integral_is_the_band_mean_square():
    """S_v = v_b²/(0.2316 f): over one band (f_c·2^(±1/6)) the integral is v_b²·(ln 2/3)/0.2316."""
    v, fc = 50e-6, 31.5
    band = integrate.quad(lambda f: float(V.acceleration_psd(f, v, 8.0, 4.0, 80.0)) / (2 * math.pi * f) ** 2,
                          fc * 2 ** (-1 / 6), fc * 2 ** (1 / 6))[0]
    assert math.sqrt(band) == pytest.approx(v, rel=5e-3)
    # below the corner the criterion is constant acceleration: v_b·f constant; outside the band 0
    f = np.array([4.0, 5.0, 6.3, 8.0])
    assert np.ptp(V.criterion_velocity(f, v, 8.0, 4.0, 80.0) * f) == pytest.approx(0.0, abs=1e-15)
    assert float(V.criterion_velocity(100.0, v, 8.0, 4.0, 80.0)) == 0.0 == float(V.criterion_velocity(3.0, v, 8.0, 4.0, 80.0))


def test_jia_model_against_miles_at_the_mode():
    m = jia_model(exposure_time=0.0)
    assert m.rms() == pytest.approx(m.miles_frame_rms(), rel=0.03)
    light = jia_model(exposure_time=0.0, stand_damping=0.005)
    assert light.rms() == pytest.approx(light.miles_frame_rms(), rel=0.01)
    # the stand's size for jia2019 (docs/physics.md): about 1.4 µm per axis before the exposure
    assert 1.2e-6 < m.rms() < 1.6e-6
    # stated from geometry: a Ø 25 mm aluminium column 300 mm high, 1.0 kg at its top
    assert V.cantilever_frequency(70e9, 0.025, 0.300, 1.0, 2700.0) == pytest.approx(JIA["vibration"]["microscope_stand_frequency"], abs=0.5)


def test_exposure_mean_of_a_sinusoid_is_sinc_and_the_model_applies_it():
    for f, T in ((59.0, 5e-3), (59.0, 12e-3), (210.0, 3e-3)):
        w = 2 * math.pi * f
        c = integrate.quad(math.cos, 0.0, w * T, epsabs=1e-14)[0] / (w * T)      # mean of cos(ωt) over T
        s = integrate.quad(math.sin, 0.0, w * T, epsabs=1e-14)[0] / (w * T)
        assert math.hypot(c, s) == pytest.approx(math.sqrt(float(V.exposure_gain_sq(f, T))), abs=1e-9)
    m = jia_model()
    assert m.exposure_time == pytest.approx(5e-3)
    assert m.frame_rms / m.rms(0.0) == pytest.approx(abs(np.sinc(m.stand_frequency * m.exposure_time)), rel=0.02)
    assert m.frame_rms**2 + m.blur_rms**2 == pytest.approx(m.rms(0.0) ** 2, rel=1e-12)
    assert jia_model(exposure_time=0.0).frame_rms == jia_model(exposure_time=0.0).rms(0.0)


def test_time_domain_oscillator_matches_the_spectral_integral():
    """Integrate z'' + 2ζω_n z' + ω_n² z = −a(t) in time (exact ZOH discretisation of the base-excited
    oscillator, white a(t) of one-sided PSD S0 to Nyquist) for 400 s; compare RMS with and without
    the exposure's box average with the spectral integral, and the frames' correlation."""
    fn, zeta, T, s0 = 59.0, 0.03, 5e-3, 1e-6
    fs = 5000.0
    n = int(400 * fs)
    a = np.random.default_rng(11).normal(0.0, math.sqrt(s0 * fs / 2.0), n)
    w = 2 * math.pi * fn
    num, den, _ = signal.cont2discrete(([-1.0], [1.0, 2 * zeta * w, w * w]), 1 / fs, method="zoh")
    z = signal.lfilter(np.ravel(num), den, a)[int(5 * fs):]          # after 5 s (≫ 0.09 s) of start-up
    edges = [0.0, 0.5 * fn, 0.9 * fn, fn, 1.1 * fn, 2 * fn, fs / 2]
    var0 = _quad(lambda f: s0 * float(V.relative_receptance_sq(f, fn, zeta)), edges)
    varT = _quad(lambda f: s0 * float(V.relative_receptance_sq(f, fn, zeta) * V.exposure_gain_sq(f, T)), edges)
    assert math.sqrt(var0) == pytest.approx(V.miles_relative_rms(s0, fn, zeta), rel=2e-3)
    assert float(np.std(z)) == pytest.approx(math.sqrt(var0), rel=0.03)
    k = int(round(T * fs))
    zbar = np.convolve(z, np.ones(k) / k, mode="valid")              # the mean over each exposure
    assert float(np.std(zbar)) == pytest.approx(math.sqrt(varT), rel=0.03)
    frames = zbar[:: int(round(JIA_FRAME_SPACING_S * fs))]
    r = float(np.corrcoef(frames[:-1], frames[1:])[0, 1])
    assert abs(r) < 3.5 / math.sqrt(frames.size), r                  # uncorrelated (≈ 290 frames)


def test_frames_are_independent_at_jias_spacing():
    m = jia_model()
    assert m.correlation_time == pytest.approx(1 / (0.03 * 2 * math.pi * 59.0))
    assert JIA_FRAME_SPACING_S > 10 * m.correlation_time
    assert m.autocorrelation(0.0) == pytest.approx(1.0, rel=1e-6)
    # the mode's envelope e^(−τ/τc) bounds it while the mode dominates
    for tau in (0.02, 0.05, 0.1):
        assert abs(m.autocorrelation(tau)) <= math.exp(-tau / m.correlation_time) + 0.02
    assert abs(m.autocorrelation(JIA_FRAME_SPACING_S)) < 1e-3


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="damping"):
        jia_model(stand_damping=0.0)
    with pytest.raises(ValueError, match="floor_low_frequency"):
        jia_model(floor_low_frequency=10.0)
    from benchtwin.twin.scenario import ScenarioError

    with pytest.raises(ScenarioError, match="floor_low_frequency ≤ floor_corner_frequency"):
        JIA.with_overrides({"vibration.floor_corner_frequency": "100 Hz"})
    assert V.StandVibration.from_section(None) is None
    assert V.StandVibration.from_section({**JIA["vibration"], "floor_velocity": 0.0}) is None


# --------------------------------------------------------------------------- the camera

def _camera(sc, seed: int = 4):
    from benchtwin.twin.instruments.camera import SimCamera
    from benchtwin.twin.instruments.stage import SimBenchState

    st = SimBenchState(seed=seed, pose=eccentric_pose(0.3, 7.1e-6, math.radians(192.08)))
    return st, SimCamera.sim_from_scenario(sc, st, backend="analytic")


SMALL_CCD = {"instruments.ccd.width": "160 px", "instruments.ccd.height": "120 px",
             "instruments.ccd.dust_count": 0, "instruments.ccd.scratch_count": 0}


def test_camera_draws_a_displacement_per_frame_with_the_models_rms():
    sc = JIA.with_overrides(SMALL_CCD)
    st, cam = _camera(sc)
    u = cam.camera.axes_lab()[0]
    t = np.array([-u[1], u[0], 0.0])
    d = []
    for i in range(600):
        st.on_step(i, None, {}, False)
        a, b = cam.disk_seen(), cam.disk_seen()
        assert np.array_equal(a.pos, b.pos)                         # one draw per step, not per call
        dp = a.pos - st.pose.disk.pos
        d.append((float(dp @ u), float(dp @ t)))
        assert abs(float(dp[2])) == 0.0                             # in the disk plane
    d = np.array(d)
    sig = cam.vibration.frame_rms
    lo, hi = (math.sqrt(stats.chi2.ppf(q, d.shape[0]) / d.shape[0]) for q in (0.0005, 0.9995))
    for col in (0, 1):                                              # radial and tangential
        assert lo * sig < float(np.sqrt(np.mean(d[:, col] ** 2))) < hi * sig
    assert abs(float(np.corrcoef(d[:, 0], d[:, 1])[0, 1])) < 0.15
    assert abs(float(np.corrcoef(d[:-1, 0], d[1:, 0])[0, 1])) < 0.15

    # reproducible: the same seed and step give the same draw, another seed another one
    st2, cam2 = _camera(sc)
    st2.on_step(599, None, {}, False)
    assert np.array_equal(cam2.disk_seen().pos, cam.disk_seen().pos)
    st3, cam3 = _camera(sc, seed=5)
    st3.on_step(599, None, {}, False)
    assert not np.array_equal(cam3.disk_seen().pos, cam.disk_seen().pos)


def test_the_rendered_frame_and_its_truth_carry_the_displacement():
    sc = JIA.with_overrides(SMALL_CCD)
    st, cam = _camera(sc)
    st.on_step(7, None, {}, False)
    geo = cam.sim_frame_truth()
    r = cam.capture()
    assert r["image"] is not None
    assert geo["centre_px"] == pytest.approx(cam.last_truth["centre_px"], abs=1e-9)   # truth = what is drawn
    px = cam.camera.true_pixel_m
    still = cam.camera.lab_to_px(st.pose.disk.pos, cam.grating.edge_radius_m)
    vr, vt = cam.vibration_m()
    assert max(abs(vr), abs(vt)) > 0.1e-6
    # image +x radially outward, +y along ±tangential (camera rotation 0): the disk moves by −(δr, δt)
    assert cam.last_truth["centre_px"][0] - still[0] == pytest.approx(-vr / px, abs=1e-6)
    assert abs(cam.last_truth["centre_px"][1] - still[1]) == pytest.approx(abs(vt) / px, abs=1e-6)
    cam.close()


def test_without_a_vibration_section_nothing_moves():
    raw = (ROOT / "scenarios" / "jia2019.toml").read_text()
    start = raw.index("[vibration]")
    end = raw.index("[procedure]")
    sc = _load_text(raw[:start] + raw[end:])
    assert "vibration" not in sc.to_dict()                    # truth/scenario.json keeps its bytes
    st, cam = _camera(sc.with_overrides(SMALL_CCD))
    assert cam.vibration is None and cam.vibration_m() == (0.0, 0.0)
    st.on_step(3, None, {}, False)
    assert cam.disk_seen() is st.pose.disk


def _load_text(text: str):
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s.toml"
        p.write_text(text)
        return load_scenario(p)
