"""GUM vs Monte Carlo (GUM Supplement 1) for the Jia 2019 outputs e, θ0, δY and Δθ (issue 5).

Each test draws the inputs of the analysis from their distributions (synthetic, pure numpy), runs
the analysis functions themselves on every draw and compares the spread of the results with the
GUM standard uncertainty the same functions report. Where the GUM u is a type-A estimate from the
data of one draw (fit residuals, repetitions), it varies between draws; the comparison is then
with its root-mean-square over the draws (E[u²] = σ² for an unbiased variance).

Tolerances: with M draws the relative standard error of an MC standard deviation is ≈ 1/√(2M)
(M = 2000: 1.6 %; M = 300: 4 %); the GUM is first order. Stated per test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.analysis.eccentricity import eccentricity_from_dref, eccentricity_from_sweep, with_async_motion
from benchtwin.analysis.error_model import error_model_from_results
from benchtwin.analysis.radial_motion import ProbeReadings, SphereSpacing, radial_motion
from benchtwin.analysis.uncertainty import MCResult, coverage_interval_shortest

E_UM, TH0_DEG, R_UM = 7.1, 192.08, 22000.0  # Jia sec. 5; r: scenarios/jia2019.toml
L1, L2 = 6.81, 122.96
PX_UM = 0.667
TH_CCD = np.arange(60) * 6.0  # Jia: 60 images every 6°


def _dref_true_px(th_deg: np.ndarray) -> np.ndarray:
    t = np.radians(th_deg)
    return (3.0 + E_UM * np.cos(t - math.radians(TH0_DEG)) + 0.05 * np.cos(2 * t - 1.0)) / PX_UM


def _wrap(d):
    return (np.asarray(d) + 180.0) % 360.0 - 180.0


def _mc_ratio(samples: np.ndarray, u_gum: np.ndarray) -> float:
    """MC standard deviation / RMS of the GUM u over the draws."""
    return float(np.std(samples, ddof=1) / np.sqrt(np.mean(np.square(u_gum))))


# --------------------------------------------------------------------------- e, θ0


def test_e_theta0_gum_matches_mc_with_pixel_scale_and_async_whirl():
    """d_ref noise (0.02 px), per-frame pixel-scale noise (3e-4 relative: exaggerated so that it
    matters) and a once-per-revolution asynchronous whirl (u = 0.03 µm per component, the share
    eccentricity_from_sweep cannot see) → e, θ0: the MC spread within 7 % of the GUM u."""
    rng = np.random.default_rng(51)
    M, sd_px, rel_s, u_h1 = 2000, 0.02, 3e-4, 0.03
    d0 = _dref_true_px(TH_CCD)
    t = np.radians(TH_CCD)
    e, th0, ue, ut = [], [], [], []
    for _ in range(M):
        c1, d1 = rng.normal(0.0, u_h1, 2)  # the async whirl's 1st harmonic during this sweep
        d = d0 + rng.normal(0.0, sd_px, TH_CCD.size) + (c1 * np.sin(t) + d1 * np.cos(t)) / PX_UM
        scales = PX_UM * (1 + rel_s * rng.standard_normal(TH_CCD.size))
        r = with_async_motion(eccentricity_from_sweep(TH_CCD, d, scales), u_h1)
        e.append(r["e_um"]), th0.append(r["theta0_deg"]), ue.append(r["e_u_um"]), ut.append(r["theta0_u_deg"])
    e, th0 = np.array(e), np.array(th0)
    assert np.mean(e) == pytest.approx(E_UM, abs=3 * np.std(e) / math.sqrt(M) + 1e-3)
    assert _mc_ratio(e, np.array(ue)) == pytest.approx(1.0, abs=0.07)
    assert _mc_ratio(_wrap(th0 - TH0_DEG), np.array(ut)) == pytest.approx(1.0, abs=0.07)
    # GUM-S1 style: the MC 95 % shortest interval's half-width vs 1.96·u (normal output)
    lo, hi = coverage_interval_shortest(e, 0.95)
    assert (hi - lo) / 2 == pytest.approx(1.96 * np.sqrt(np.mean(np.square(ue))), rel=0.08)
    # without the async term the GUM u would be far too small: the test can fail
    r0 = eccentricity_from_sweep(TH_CCD, d0 + rng.normal(0.0, sd_px, TH_CCD.size), np.full(TH_CCD.size, PX_UM))
    assert np.std(e) > 3 * r0["e_u_um"]


def test_pixel_scale_uncertainty_enters_e_not_theta0():
    rng = np.random.default_rng(3)
    d = _dref_true_px(TH_CCD) + rng.normal(0, 0.01, TH_CCD.size)
    scales = PX_UM * (1 + 1e-3 * rng.standard_normal(TH_CCD.size))
    r = eccentricity_from_sweep(TH_CCD, d, scales)
    base = eccentricity_from_dref(TH_CCD, d * float(np.median(scales)))
    assert r["e_um"] == pytest.approx(base["e_um"], rel=1e-12)
    assert r["theta0_u_deg"] == pytest.approx(base["theta0_u_deg"], rel=1e-12)
    us = r["u_pixel_um"]
    assert us == pytest.approx(math.sqrt(math.pi / 2) * 1e-3 * PX_UM / math.sqrt(60), rel=0.35)
    assert r["e_u_um"] == pytest.approx(math.hypot(base["e_u_um"], r["e_um"] * us / r["pixel_um"]), rel=1e-12)
    assert r["e_u_um"] > 1.2 * base["e_u_um"]  # the scale term is not negligible here
    with pytest.raises(ValueError, match="scale"):
        eccentricity_from_sweep(TH_CCD, d, [])


def test_with_async_motion_adds_in_quadrature_and_flags_one_revolution():
    ecc = {"e_um": 7.0, "e_u_um": 0.003, "theta0_deg": 192.0, "theta0_u_deg": 0.02}
    r = with_async_motion(ecc, 0.04, 4)
    assert r["e_u_um"] == pytest.approx(math.hypot(0.003, 0.04))
    assert r["theta0_u_deg"] == pytest.approx(math.hypot(0.02, math.degrees(0.04 / 7.0)))
    assert r["e_u_fit_um"] == 0.003 and r["u_async_h1_dof"] == 4
    one = with_async_motion(ecc, float("nan"))
    assert one["e_u_um"] == 0.003 and "no repeated revolutions" in one["async_note"]
    assert "alone" in one["u_source"] and "not in u" in one["u_source"]  # says what u leaves out
    with pytest.raises(ValueError):
        with_async_motion(ecc, -1.0)


# --------------------------------------------------------------------------- δY


def _sphere_readings(rng, n=180, reps=3, noise_sd=0.05, async_sd=0.04):
    """Probe readings of two spheres: offsets + centring (1st harmonic) + synchronous disk motion
    + a per-revolution asynchronous whirl (harmonics 1…6, the same rigid-axis motion at both
    spheres, random amplitudes) + probe noise. Returns the columns and the synchronous δY."""
    th = np.arange(n) * 360.0 / n
    t = np.radians(th)
    dY = 0.15 * np.cos(2 * t - 0.5) + 0.10 * np.cos(3 * t - 1.9) + 0.05 * np.cos(5 * t - 3.5)
    cols = {k: [] for k in ("rep", "theta_deg", "probe_top_um", "probe_bottom_um")}
    for r in range(reps):
        a = sum(rng.normal(0, async_sd) * np.cos(k * t) + rng.normal(0, async_sd) * np.sin(k * t) for k in range(1, 7))
        cols["rep"].append(np.full(n, r))
        cols["theta_deg"].append(th)
        cols["probe_top_um"].append(12 + 3 * np.cos(t - 0.7) + dY + a + rng.normal(0, noise_sd, n))
        cols["probe_bottom_um"].append(-7 + 4.5 * np.cos(t - 5.2) + dY + a + rng.normal(0, noise_sd, n))
    return {k: np.concatenate(v) for k, v in cols.items()}, dY


@pytest.mark.parametrize("async_sd", [0.0, 0.04])
def test_dY_gum_matches_mc(async_sd):
    """δY (eq. 9 of the eq. 7 series, mean of 3 revolutions) vs the synchronous δY: MC spread over
    300 draws within 15 % of the RMS of ``u_dY_theta_um`` (a type-A u with few dof per draw); with
    no asynchronous motion ``u_dY_gum_theta_um`` (fit covariance) too. The 1st-harmonic scatter
    (``u_h1_async_um``) estimates the whirl's per-revolution σ."""
    rng = np.random.default_rng(7 + int(async_sd * 1000))
    M = 300
    at = np.arange(0, 180, 15)  # every 30°
    err, u, ug, h1 = [], [], [], []
    for _ in range(M):
        cols, dY = _sphere_readings(rng, async_sd=async_sd)
        rm = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2))
        err.append((rm["dY_um"] - dY)[at])
        u.append(rm["u_dY_theta_um"][at])
        ug.append(rm["u_dY_gum_theta_um"][at])
        h1.append(rm["u_h1_async_um"])
    err, u, ug = np.array(err), np.array(u), np.array(ug)
    ratio = np.std(err, axis=0, ddof=1) / np.sqrt(np.mean(u**2, axis=0))
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
    if async_sd == 0:
        assert np.all(np.abs(np.std(err, axis=0, ddof=1) / np.sqrt(np.mean(ug**2, axis=0)) - 1) < 0.15)
    else:
        # the fit covariance alone misses the asynchronous motion (the test can fail)
        assert np.mean(np.std(err, axis=0) / np.sqrt(np.mean(ug**2, axis=0))) > 2.0
        # σ of one revolution's 1st-harmonic coefficient: the whirl's σ (+ a little probe noise)
        assert np.sqrt(np.mean(np.square(h1))) == pytest.approx(async_sd, rel=0.15)


# --------------------------------------------------------------------------- Δθ


def test_dtheta_gum_matches_mc_through_the_whole_chain():
    """Probe readings and one CCD sweep → radial_motion, eccentricity_from_dref + with_async_motion
    → error_model_from_results(dY_uncertainty="gum") → Δθ at 8 angles (Jia eq. 5), 250 draws: the
    spread of Δθ − eq. 5 on the synchronous truth within 20 % of the RMS GUM u (type-A inputs
    with 2-4 dof per draw; first order). The CCD sweep sees the 1st harmonic of the same kind of
    whirl as the probes (its own draw)."""
    rng = np.random.default_rng(2019)
    M, async_sd, sd_dref_um = 250, 0.04, 0.015
    q = np.arange(0.0, 360.0, 45.0)
    t = np.radians(TH_CCD)
    d0 = _dref_true_px(TH_CCD) * PX_UM
    truth = None
    vals, us = [], []
    for _ in range(M):
        cols, dY = _sphere_readings(rng, async_sd=async_sd)
        rm = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2))
        c1, d1 = rng.normal(0, async_sd, 2)
        d = d0 + c1 * np.sin(t) + d1 * np.cos(t) + rng.normal(0, sd_dref_um, TH_CCD.size)
        ecc = with_async_motion(eccentricity_from_dref(TH_CCD, d), rm["u_h1_async_um"])
        m = error_model_from_results(ecc, rm, R_UM, dY_uncertainty="gum")
        vals.append(m.predict(q))
        us.append(m.uncertainty(q))
        if truth is None:
            truth = error_model_from_results({"e_um": E_UM, "theta0_deg": TH0_DEG}, dict(rm, dY_um=dY), R_UM,
                                             dY_uncertainty="none").predict(q)
    vals, us = np.array(vals), np.array(us)
    err = vals - truth
    assert np.all(np.abs(err.mean(axis=0)) < 4 * err.std(axis=0) / math.sqrt(M))  # unbiased
    ratio = err.std(axis=0, ddof=1) / np.sqrt(np.mean(us**2, axis=0))
    assert np.all(np.abs(ratio - 1) < 0.2), ratio
    mc = MCResult(float(err[:, 2].mean()), float(err[:, 2].std(ddof=1)), coverage_interval_shortest(err[:, 2]),
                  coverage_interval_shortest(err[:, 2]), M, 0.95)
    assert mc.std > 0.01  # arcsec: not a vacuous comparison


def test_range_method_d3_is_jia_1p69():
    """Jia sec. 5: u = range / d_n with d_3 = 1.69 (0.3 µm over 3 revolutions → 0.18 µm); over many
    draws mean(range)/d_3 estimates σ (the d_n constant's definition)."""
    from benchtwin.analysis.radial_motion import D_N, range_method_u

    assert round(D_N[3], 2) == 1.69
    rng = np.random.default_rng(1)
    x = rng.normal(0, 0.18, (3, 40000))
    assert np.mean(range_method_u(x)) == pytest.approx(0.18, rel=0.01)
