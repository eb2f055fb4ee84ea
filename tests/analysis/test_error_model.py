"""Tests of the Jia 2019 eq. 5 error model and the comparison with a measured encoder error."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.analysis.error_model import (
    EccentricityEstimate,
    ErrorModel,
    RadialCurve,
    compare_with_measured,
    jia_error_model,
    periodic_integral,
    radial_motion_term,
    radial_motion_term_fourier,
)
from benchtwin.units import ARCSEC

R_UM = 22000.0
E_UM, TH0 = 7.1, 192.08  # Jia sec. 5


def test_eccentricity_alone_is_eq3():
    th = np.linspace(0, 360, 721)
    m = jia_error_model(EccentricityEstimate(E_UM, TH0), R_UM)
    expect = (E_UM / R_UM) * np.sin(np.radians(th - TH0)) / ARCSEC
    np.testing.assert_allclose(m.predict(th), expect, rtol=1e-12, atol=1e-12)
    # 7.1 µm at r = 22 mm: 66.57″ amplitude; zero crossing rising at θ0
    assert np.max(m.predict(th)) == pytest.approx(E_UM / R_UM / ARCSEC, rel=1e-6)
    assert m.predict(np.array([TH0]))[0] == pytest.approx(0.0, abs=1e-9)
    assert m.predict(np.array([TH0 + 1.0]))[0] > 0


def _dY(th_deg):
    t = np.radians(th_deg)
    return 0.15 * np.sin(2 * t + 0.5) + 0.10 * np.cos(3 * t - 1.0) + 0.04 * np.sin(7 * t)


def _int_dY(th_deg):
    """Analytic ∫_0^θ of _dY (µm·rad)."""
    t = np.radians(th_deg)
    # sin(2t+.5) → (cos(.5) − cos(2t+.5))/2 ; cos(3t−1) → (sin(3t−1) − sin(−1))/3 ; sin 7t → (1 − cos 7t)/7
    return (0.15 * (math.cos(0.5) - np.cos(2 * t + 0.5)) / 2 + 0.10 * (np.sin(3 * t - 1.0) + math.sin(1.0)) / 3
            + 0.04 * (1 - np.cos(7 * t)) / 7)


def test_integral_term_against_analytic_uniform_grid():
    grid = np.arange(360.0)
    term = radial_motion_term(grid, _dY(grid), R_UM)
    q = np.linspace(-30, 400, 431)
    got = term(np.radians(q))
    expect = _int_dY(q) / R_UM / ARCSEC
    # trapezoid error ~ (k·h)²/12 relative for harmonic k: < 0.5 % of the amplitude here
    assert np.max(np.abs(got - expect)) < 5e-3 * np.max(np.abs(expect))
    assert np.max(np.abs(expect)) > 0.1  # arcsec: the test is not vacuous
    assert term(np.array(0.0)) == pytest.approx(0.0, abs=1e-15)
    assert abs(term.removed_mean_um) < 1e-12  # a series without 0th harmonic on a uniform grid


def test_integral_term_nonuniform_grid_and_mean_removal():
    rng = np.random.default_rng(4)
    grid = np.sort(rng.uniform(0, 360, 500))
    term = radial_motion_term(grid, _dY(grid) + 0.02, R_UM)  # offset: not periodic unless removed
    assert term.removed_mean_um == pytest.approx(0.02, abs=2e-4)
    q = np.linspace(0, 360, 200)
    expect = _int_dY(q) / R_UM / ARCSEC
    assert np.max(np.abs(term(np.radians(q)) - expect)) < 0.01 * np.max(np.abs(expect))
    # periodic after mean removal
    assert term(np.radians(np.array(360.0 + 17.0))) == pytest.approx(term(np.radians(np.array(17.0))), abs=1e-12)
    # without removal the integral drifts by 2π·mean per turn
    Y, mean = periodic_integral(grid, _dY(grid) + 0.02, remove_mean=False)
    assert Y(np.array(360.0)) - Y(np.array(0.0)) == pytest.approx(2 * math.pi * mean, rel=1e-9)


def test_fourier_term_is_exact():
    p = np.zeros(21)
    p[3], p[4] = 0.15 * math.cos(0.5), 0.15 * math.sin(0.5)  # 0.15 sin(2t+.5) = a sin2t + b cos2t
    p[5], p[6] = 0.10 * math.sin(-1.0) * -1, 0.10 * math.cos(1.0)  # 0.10 cos(3t−1)
    p[13] = 0.04
    q = np.linspace(0, 720, 97)
    got = radial_motion_term_fourier(p, R_UM)(np.radians(q))
    np.testing.assert_allclose(got, _int_dY(q) / R_UM / ARCSEC, atol=1e-12)


def test_terms_sum_and_add_term():
    grid = np.arange(0, 360, 2.0)
    m = jia_error_model(EccentricityEstimate(E_UM, TH0), R_UM, RadialCurve(grid, _dY(grid)))
    th = np.arange(0, 360, 15.0)
    parts = m.predict_terms(th)
    assert set(parts) == {"eccentricity", "radial_motion"}
    np.testing.assert_allclose(m.predict(th), parts["eccentricity"] + parts["radial_motion"])
    m.add_term("graduation", lambda t: 0.5 * np.sin(23 * t))
    np.testing.assert_allclose(m.predict(th) - parts["eccentricity"] - parts["radial_motion"],
                               0.5 * np.sin(23 * np.radians(th)), atol=1e-12)
    np.testing.assert_allclose(m.predict(th, terms=["graduation"]), 0.5 * np.sin(23 * np.radians(th)), atol=1e-12)
    with pytest.raises(KeyError):
        m.predict(th, terms=["nope"])
    with pytest.raises(ValueError):
        ErrorModel(0.0)


def test_uncertainty_propagation():
    th = np.array([TH0, TH0 + 90.0])
    m = jia_error_model(EccentricityEstimate(E_UM, TH0, u_e_um=0.24, u_theta0_deg=1.13), R_UM)
    u = m.uncertainty(th)
    # at θ = θ0: only the phase contributes, (e/r)·u(θ0); at θ0 + 90°: only e, u(e)/r
    assert u[0] == pytest.approx(E_UM / R_UM * math.radians(1.13) / ARCSEC, rel=1e-9)
    assert u[1] == pytest.approx(0.24 / R_UM / ARCSEC, rel=1e-9)
    # u(r): relative, on both 1/r terms together
    m2 = jia_error_model(EccentricityEstimate(E_UM, TH0), R_UM, u_r_um=22.0)
    assert m2.uncertainty(np.array([TH0 + 90.0]))[0] == pytest.approx(E_UM / R_UM / ARCSEC * 1e-3, rel=1e-9)
    # Monte Carlo of e, θ0, r
    rng = np.random.default_rng(9)
    q = np.array([30.0, 120.0, 250.0])
    m3 = jia_error_model(EccentricityEstimate(E_UM, TH0, u_e_um=0.24, u_theta0_deg=1.13), R_UM, u_r_um=50.0)
    e = rng.normal(E_UM, 0.24, 20000)
    t0 = rng.normal(TH0, 1.13, 20000)
    r = rng.normal(R_UM, 50.0, 20000)
    samples = (e[:, None] / r[:, None]) * np.sin(np.radians(q[None, :] - t0[:, None])) / ARCSEC
    np.testing.assert_allclose(m3.uncertainty(q), samples.std(axis=0), rtol=0.05)


def test_radial_uncertainty_independent_vs_correlated():
    grid = np.arange(360.0)
    ind = radial_motion_term(grid, _dY(grid), R_UM, u_dY_um=0.18)
    cor = radial_motion_term(grid, _dY(grid), R_UM, u_dY_um=0.18, correlated=True)
    t = np.radians(np.array([90.0, 360.0 - 1e-9]))
    # fully correlated: u·θ/r ; independent: sqrt(h·θ)·u/r
    np.testing.assert_allclose(cor.u_fn(t), 0.18 * t / R_UM / ARCSEC, rtol=1e-6)
    np.testing.assert_allclose(ind.u_fn(t), 0.18 * np.sqrt(np.radians(1.0) * t) / R_UM / ARCSEC, rtol=1e-6)


def test_compare_removes_means_and_reports_fraction():
    th = np.arange(23) * 360.0 / 23  # polygon positions
    m = jia_error_model(EccentricityEstimate(E_UM, TH0), R_UM)
    model = m.predict(th)
    rng = np.random.default_rng(12)
    extra = 0.09 * np.sqrt(np.mean((model - model.mean()) ** 2)) * rng.standard_normal(th.size)
    extra -= extra.mean()
    extra *= 0.09 * np.sqrt(np.mean((model - model.mean()) ** 2)) / np.sqrt(np.mean(extra**2))
    measured = model + extra + 123.4  # unknown constant of the polygon set-up
    c = compare_with_measured(th, measured, m)
    np.testing.assert_allclose(c["residual_arcsec"], extra, atol=1e-9)
    assert c["measured_mean_arcsec"] == pytest.approx(123.4 + model.mean())
    assert abs(np.mean(c["measured_arcsec"])) < 1e-9 and abs(np.mean(c["model_arcsec"])) < 1e-9
    # measured RMS includes the residual: RMS(res)/RMS(meas) = 0.09/sqrt(1 + 0.09²) (uncorrelated-ish)
    assert c["fraction_of_error"] == pytest.approx(0.09, rel=0.1)
    assert c["pv_ratio"] == pytest.approx(np.ptp(extra) / np.ptp(measured), rel=1e-9)
    assert "mean" in c["note"]
    # the model may also be passed as values
    c2 = compare_with_measured(th, measured, model)
    assert c2["residual_rms_arcsec"] == pytest.approx(c["residual_rms_arcsec"])
    with pytest.raises(ValueError):
        compare_with_measured(th, measured[:-1], m)


def test_duplicate_grid_angles_raise():
    with pytest.raises(ValueError, match="duplicate"):
        periodic_integral(np.array([0.0, 10.0, 10.0, 20.0]), np.zeros(4))


def test_figures_jia_smoke():
    from matplotlib.figure import Figure

    from benchtwin.analysis.eccentricity import eccentricity_from_dref
    from benchtwin.analysis.radial_motion import ProbeReadings, SphereSpacing, radial_motion
    from benchtwin.analysis.report.figures_jia import fig_comparison, fig_dref, fig_predicted_error, fig_radial_motion

    rng = np.random.default_rng(0)
    th = np.tile(np.arange(0, 360, 2.0), 3)
    rep = np.repeat([0, 1, 2], 180)
    t = np.radians(th)
    rm = radial_motion(ProbeReadings(rep, th, 3 * np.cos(t) + 0.2 * np.sin(2 * t) + rng.normal(0, 0.01, th.size),
                                     4 * np.sin(t) + 0.1 * np.cos(3 * t)), SphereSpacing(6.81, 122.96))
    fig = fig_radial_motion(rm)
    assert isinstance(fig, Figure) and len(fig.axes[0].lines) == 3 + 3 * 3
    thc = np.arange(60) * 6.0
    d = 3 + E_UM * np.cos(np.radians(thc - TH0)) + rng.normal(0, 0.05, 60)
    ecc = eccentricity_from_dref(thc, d)
    assert isinstance(fig_dref(ecc, thc, d), Figure)
    m = jia_error_model(EccentricityEstimate(ecc["e_um"], ecc["theta0_deg"], u_e_um=ecc["e_u_um"]), R_UM,
                        RadialCurve(rm["theta_deg"], rm["dY_um"]))
    f15 = fig_predicted_error(m)
    assert {ln.get_label() for ln in f15.axes[0].lines} >= {"eccentricity", "radial_motion", "Δθ (eq. 5)"}
    tp = np.arange(23) * 360 / 23
    f16 = fig_comparison(compare_with_measured(tp, m.predict(tp) + rng.normal(0, 2, 23), m))
    assert len(f16.axes) == 2
    f16.canvas.draw()  # renders without a display


def test_error_model_from_results_dicts():
    from benchtwin.analysis.error_model import error_model_from_results

    th = np.tile(np.arange(0, 360, 3.0), 3)
    rep = np.repeat([0, 1, 2], 120)
    rng = np.random.default_rng(3)
    t = np.radians(th)
    rm_in = dict(rep=rep, theta_deg=th, probe_top_um=2 * np.cos(t) + 0.2 * np.sin(2 * t) + rng.normal(0, 0.02, th.size),
                 probe_bottom_um=1 + 0.1 * np.cos(3 * t) + rng.normal(0, 0.02, th.size))
    from benchtwin.analysis.radial_motion import ProbeReadings, SphereSpacing, radial_motion

    rm = radial_motion(ProbeReadings(**rm_in), SphereSpacing(6.81, 122.96))
    ecc = {"e_um": E_UM, "theta0_deg": TH0, "e_u_um": 0.24, "theta0_u_deg": 1.13, "cov_e_theta0": 0.0}
    q = np.arange(0, 360, 10.0)
    models = {k: error_model_from_results(ecc, rm, R_UM, dY_uncertainty=k) for k in ("range", "range_mean", "gum", "none")}
    ref = jia_error_model(EccentricityEstimate(E_UM, TH0), R_UM, RadialCurve(rm["theta_deg"], rm["dY_um"]))
    for m in models.values():
        np.testing.assert_allclose(m.predict(q), ref.predict(q), atol=1e-12)
    u = {k: m.uncertainty(q) for k, m in models.items()}
    assert np.all(u["range"] >= u["none"]) and np.all(u["range"] >= u["range_mean"] - 1e-12)
    assert np.any(u["range"] > u["none"])
    with pytest.raises(ValueError):
        error_model_from_results(ecc, rm, R_UM, dY_uncertainty="bogus")


def test_integral_design_matrix_and_gum_u_of_the_integral():
    """b(θ)·p = ∫_0^θ δY for a Fourier δY (same as radial_motion_term_fourier), and the GUM u of the
    integral is √(bᵀCb): for one harmonic i with variance s² per coefficient, u = s·√(2 − 2cos iθ)/i."""
    from benchtwin.analysis.error_model import integral_design_matrix, radial_motion_u_gum

    rng = np.random.default_rng(5)
    p = np.concatenate([[0.0], rng.normal(0, 0.1, 20)])
    q = np.linspace(-20, 380, 41)
    np.testing.assert_allclose(integral_design_matrix(q, 10) @ p * 1.0 / R_UM / ARCSEC,
                               radial_motion_term_fourier(p, R_UM)(np.radians(q)), atol=1e-12)
    C = np.zeros((21, 21))
    C[5, 5] = C[6, 6] = 0.02**2  # harmonic 3
    u = radial_motion_u_gum({"order": 10, "dY_cov_sync": C}, R_UM)(np.radians(q))
    t = np.radians(q)
    np.testing.assert_allclose(u, 0.02 * np.sqrt(2 - 2 * np.cos(3 * t)) / 3 / R_UM / ARCSEC, atol=1e-15)


# --- refine_eccentricity: the CCD's (e, θ0) combined with the comparison's first harmonic ---------

def _refine_case(rng, de_um=0.3, dt_deg=2.0, u_pt=0.05, n=23, e=7.1, t0=192.0, r=22000.0):
    from benchtwin.analysis.error_model import eccentricity_term

    th = np.arange(n) * 360.0 / n
    true = eccentricity_term(e + de_um, t0 + dt_deg, r)(np.radians(th))
    model = eccentricity_term(e, t0, r)(np.radians(th))
    res = true - model + 5.0 + rng.normal(0.0, u_pt, n)     # α known up to a constant
    return th, res


def test_refine_eccentricity_recovers_a_known_error_and_weights_by_u():
    from benchtwin.analysis.error_model import EccentricityEstimate, refine_eccentricity

    th, res = _refine_case(np.random.default_rng(1), u_pt=1e-4)
    # a vague CCD prior: the comparison decides (the linearisation in δθ0 costs ~e·δθ0² ≈ 0.01 µm)
    ref = refine_eccentricity(th, res, 1e-4, EccentricityEstimate(7.1, 192.0, 10.0, 30.0), 22000.0)
    assert ref["e_um"] == pytest.approx(7.4, abs=0.01) and ref["theta0_deg"] == pytest.approx(194.0, abs=0.01)
    assert ref["comparison"]["e_um"] == pytest.approx(ref["e_um"], abs=1e-3)
    # a CCD far more precise than the comparison: the CCD's values stay
    ref2 = refine_eccentricity(th, res, 10.0, EccentricityEstimate(7.1, 192.0, 1e-4, 1e-4), 22000.0)
    assert ref2["e_um"] == pytest.approx(7.1, abs=1e-5) and ref2["theta0_deg"] == pytest.approx(192.0, abs=1e-5)
    assert ref2["u_e_um"] == pytest.approx(1e-4, rel=1e-3)
    # equal weights: halfway, with u/√2
    u_cmp = ref["comparison"]["u_e_um"]
    ref3 = refine_eccentricity(th, res, 1e-4, EccentricityEstimate(7.1, 192.0, u_cmp, ref["comparison"]["u_theta0_deg"]),
                               22000.0)
    assert ref3["u_e_um"] == pytest.approx(u_cmp / math.sqrt(2), rel=0.02)
    assert ref3["e_um"] == pytest.approx(7.1 + 0.5 * (ref["comparison"]["e_um"] - 7.1), abs=0.3 * u_cmp + 0.01)


def test_refine_eccentricity_consistency_chi2_against_monte_carlo():
    """GUM against Monte Carlo: CCD values drawn with their stated u around the truth, comparisons
    drawn with theirs: the χ² of the two is χ²(2) (mean 2, p uniform), and the combined e covers
    the truth at the stated u."""
    from benchtwin.analysis.error_model import EccentricityEstimate, refine_eccentricity

    rng = np.random.default_rng(20191)
    u_e, u_t = 0.24, 2.0
    chi2, z = [], []
    for _ in range(400):
        de, dt = rng.normal(0, u_e), rng.normal(0, u_t)     # the CCD's error
        th, res = _refine_case(rng, de_um=-de, dt_deg=-dt, u_pt=0.1, e=7.1 + de, t0=192.0 + dt)
        ref = refine_eccentricity(th, res, 0.1, EccentricityEstimate(7.1 + de, 192.0 + dt, u_e, u_t), 22000.0)
        chi2.append(ref["chi2"])
        z.append((ref["e_um"] - 7.1) / ref["u_e_um"])
    assert np.mean(chi2) == pytest.approx(2.0, rel=0.2)
    assert np.std(z) == pytest.approx(1.0, abs=0.15) and abs(np.mean(z)) < 0.2


def test_refine_eccentricity_rejects_bad_input():
    from benchtwin.analysis.error_model import EccentricityEstimate, refine_eccentricity

    with pytest.raises(ValueError, match="positive u"):
        refine_eccentricity([0, 90, 180, 270], [0, 1, 0, -1], 0.0, EccentricityEstimate(7.1, 0.0, 0.2, 1.0), 22000.0)
    with pytest.raises(ValueError, match="≥ 4 points"):
        refine_eccentricity([0, 180], [0, 1], 0.1, EccentricityEstimate(7.1, 0.0, 0.2, 1.0), 22000.0)
