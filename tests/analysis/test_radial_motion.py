"""Tests of the radial error motion analysis (Jia 2019 sec. 4.1, eqs. 6-9, range method of sec. 5)."""

from __future__ import annotations

import numpy as np
import pytest

from benchtwin.analysis.radial_motion import (D_N, ProbeReadings, RadialOptions, SphereSpacing, disk_weights,
                                             error_motion_values, radial_motion, range_method_u)

L1, L2 = 6.81, 122.96  # mm, Jia sec. 5


def _harm(t, terms):
    return sum(a * np.cos(k * t - ph) for k, a, ph in terms)


def synthetic(reps=3, n=360, seed=0, async_sd=0.0, noise_sd=0.0, x=False):
    """Sphere readings = probe offset + sphere centring (1st harmonic) + shaft motion.

    Shaft motion of the disk δY (harmonics 2…7) and the tilt in the form of eq. 8 (ε = (δtop − δbot)/L2),
    so δtop = δY + L1·ε and δbot = δY − (L2 − L1)·ε. Asynchronous part: a random harmonic sum per rep.
    """
    rng = np.random.default_rng(seed)
    th = np.arange(n) * 360.0 / n
    t = np.radians(th)
    dY = _harm(t, [(2, 0.15, 0.5), (3, 0.10, 1.9), (5, 0.05, 3.5), (7, 0.02, 0.2)])  # µm
    eps = _harm(t, [(2, 0.8e-3, 2.0), (4, 0.5e-3, 0.1)])  # µm/mm (mrad)
    rows = {"rep": [], "theta_deg": [], "probe_top_um": [], "probe_bottom_um": []}
    if x:
        rows["probe_top_x_um"], rows["probe_bottom_x_um"] = [], []
    dX = _harm(t, [(2, 0.12, 2.5), (6, 0.04, 0.0)])
    asyncs = []
    for r in range(reps):
        a = sum(rng.normal(0, async_sd / 2) * np.cos(k * t - rng.uniform(0, 2 * np.pi)) for k in (2, 3, 4, 8)) \
            if async_sd > 0 else 0 * t
        a = a - 0  # harmonics ≥ 2: survive eq. 7
        asyncs.append(a)
        top = 12.0 + 3.0 * np.cos(t - np.radians(40)) + dY + a + L1 * eps
        bot = -7.0 + 4.5 * np.cos(t - np.radians(300)) + dY + a - (L2 - L1) * eps
        rows["rep"].append(np.full(n, r))
        rows["theta_deg"].append(th)
        rows["probe_top_um"].append(top + rng.normal(0, noise_sd, n))
        rows["probe_bottom_um"].append(bot + rng.normal(0, noise_sd, n))
        if x:
            rows["probe_top_x_um"].append(1.0 + 3.0 * np.sin(t - np.radians(40)) + dX)
            rows["probe_bottom_x_um"].append(2.0 + 4.5 * np.sin(t - np.radians(300)) + dX)
    cols = {k: np.concatenate(v) for k, v in rows.items()}
    return cols, {"theta_deg": th, "dY": dY, "eps": eps, "dX": dX, "async": np.array(asyncs)}


def test_disk_motion_recovered_noise_free():
    cols, truth = synthetic()
    res = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2))
    np.testing.assert_allclose(res["theta_deg"], truth["theta_deg"])
    rms = np.sqrt(np.mean((res["dY_um"] - truth["dY"]) ** 2))
    assert rms < 0.005  # 5 nm
    assert rms < 1e-9  # in fact exact: the truth is inside the order-10 series
    np.testing.assert_allclose(res["tilt_x_urad"], truth["eps"] * 1e3, atol=1e-6)
    # the sphere motions themselves: centring (1st) and probe offset (0th) removed
    np.testing.assert_allclose(res["delta_top_um"], truth["dY"] + L1 * truth["eps"], atol=1e-9)
    assert res["n_reps"] == 3 and res["dY_reps_um"].shape == (3, 360)


def test_eq9_weights():
    wt, wb = disk_weights(L1, L2)
    assert wt == pytest.approx((L2 - L1) / L2) and wb == pytest.approx(L1 / L2) and wt + wb == pytest.approx(1)
    with pytest.raises(ValueError):
        disk_weights(1.0, 0.0)


def test_callable_between_grid_points():
    cols, truth = synthetic(n=120)
    res = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2))
    q = np.array([0.5, 17.25, 181.0, 359.9])
    t = np.radians(q)
    expect = 0.15 * np.cos(2 * t - 0.5) + 0.10 * np.cos(3 * t - 1.9) + 0.05 * np.cos(5 * t - 3.5) + 0.02 * np.cos(7 * t - 0.2)
    np.testing.assert_allclose(res["dY_fn"](q), expect, atol=1e-9)
    np.testing.assert_allclose(res["dY_fn"](res["theta_deg"]), res["dY_um"], atol=1e-12)


def test_sync_async_and_summary_values():
    cols, truth = synthetic(async_sd=0.1, seed=3)
    res = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2))
    sync_true = truth["dY"] + truth["async"].mean(axis=0)
    np.testing.assert_allclose(res["dY_um"], sync_true, atol=1e-9)
    np.testing.assert_allclose(res["dY_async_um"], truth["async"] - truth["async"].mean(axis=0), atol=1e-9)
    s = res["summary"]["disk"]
    all_reps = truth["dY"] + truth["async"]
    assert s["total_um"] == pytest.approx(np.ptp(all_reps), abs=1e-9)
    assert s["synchronous_um"] == pytest.approx(np.ptp(sync_true), abs=1e-9)
    assert s["asynchronous_um"] == pytest.approx(np.max(np.ptp(all_reps, axis=0)), abs=1e-9)
    assert s["asynchronous_um"] > 0
    assert set(res["summary"]) == {"top", "bottom", "disk"}


def test_range_method_numbers_and_statistics():
    v = np.array([[0.0, 1.0], [0.3, 0.9], [0.1, 1.2]])
    np.testing.assert_allclose(range_method_u(v), np.array([0.3, 0.3]) / 1.693)
    np.testing.assert_allclose(range_method_u(v, d_n=1.69), np.array([0.3, 0.3]) / 1.69)  # Jia's rounding
    assert D_N[3] == pytest.approx(1.69, abs=0.005)
    # Jia: range 0.3 µm over 3 repetitions → σ = 0.18 µm
    assert 0.3 / D_N[3] == pytest.approx(0.18, abs=0.005)
    # statistically: mean(range)/d_n estimates σ
    rng = np.random.default_rng(8)
    samples = rng.normal(0, 0.1, (3, 20000))
    assert np.mean(range_method_u(samples)) == pytest.approx(0.1, rel=0.03)
    with pytest.raises(ValueError, match="d_n"):
        range_method_u(np.zeros((26, 3)))


@pytest.mark.parametrize("n", [11, 15, 20, 25])
def test_d_n_beyond_ten_is_the_mean_range_of_normal_samples(n):
    """d_n for 11…25 repetitions (issue #13: radial_reps ≥ 11 had none): the mean range of n
    standard normal samples, checked by Monte Carlo to 0.5 % (σ of the mean ≈ 0.1 %)."""
    rng = np.random.default_rng(n)
    x = rng.standard_normal((40000, n))
    assert np.mean(np.ptp(x, axis=1)) == pytest.approx(D_N[n], rel=0.005)


def test_range_method_on_disk_motion():
    cols, truth = synthetic(async_sd=0.1, seed=4)
    res = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2))
    reps = truth["dY"] + truth["async"]
    np.testing.assert_allclose(res["u_dY_range_theta_um"], np.ptp(reps, axis=0) / D_N[3], atol=1e-9)
    assert res["u_dY_range_um"] == pytest.approx(np.max(np.ptp(reps, axis=0)) / D_N[3], abs=1e-9)
    assert res["d_n"] == D_N[3]


def test_gum_uncertainty_matches_monte_carlo():
    sd = 0.05
    dYs, us = [], []
    for seed in range(60):
        cols, truth = synthetic(noise_sd=sd, seed=100 + seed, n=180)
        res = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2))
        dYs.append(res["dY_um"])
        us.append(res["u_dY_gum_theta_um"])
    sd_mc = np.std(dYs, axis=0, ddof=1).mean()
    assert np.mean(us) == pytest.approx(sd_mc, rel=0.2)
    # with the probe uncertainty given: absolute covariance, same size
    cols, _ = synthetic(noise_sd=sd, seed=1, n=180)
    res = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2), RadialOptions(u_probe_um=sd))
    assert res["u_dY_gum_um"] == pytest.approx(np.max(np.mean(us, axis=0)), rel=0.2)
    # the noise-free case has no fit uncertainty; u(L) adds a term ∝ |δtop − δbot|
    cols, truth = synthetic()
    res = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2, u_L1_mm=0.05))
    expect = np.abs(truth["eps"] * L2 / L2) * 0.05  # |∂δY/∂L1| = |δbot − δtop|/L2 = |ε|
    np.testing.assert_allclose(res["u_dY_gum_theta_um"], expect, atol=1e-9)


def test_x_probes():
    cols, truth = synthetic(x=True)
    res = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2))
    np.testing.assert_allclose(res["dX_um"], truth["dX"], atol=1e-9)
    np.testing.assert_allclose(res["tilt_y_urad"], 0.0, atol=1e-6)
    assert {"top_x", "bottom_x", "disk_x"} <= set(res["summary"])
    cols.pop("probe_bottom_x_um")
    with pytest.raises(ValueError, match="together"):
        radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2))


def test_nonuniform_and_different_grids_per_rep():
    cols, truth = synthetic(reps=2, n=200)
    rng = np.random.default_rng(2)
    # jitter the angles of rep 1 (and recompute its readings from the truth)
    th1 = np.sort(rng.uniform(0, 360, 200))
    t1 = np.radians(th1)
    dY = 0.15 * np.cos(2 * t1 - 0.5) + 0.10 * np.cos(3 * t1 - 1.9) + 0.05 * np.cos(5 * t1 - 3.5) + 0.02 * np.cos(7 * t1 - 0.2)
    eps = 0.8e-3 * np.cos(2 * t1 - 2.0) + 0.5e-3 * np.cos(4 * t1 - 0.1)
    m = cols["rep"] == 1
    cols["theta_deg"][m] = th1
    cols["probe_top_um"][m] = 1.0 + 2.0 * np.cos(t1) + dY + L1 * eps
    cols["probe_bottom_um"][m] = 5.0 + 1.0 * np.sin(t1) + dY - (L2 - L1) * eps
    res = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2))
    assert res["theta_deg"].size == 360  # default 1° grid when the reps' angles differ
    expect = res["dY_fn"](res["theta_deg"])
    t = np.radians(res["theta_deg"])
    truth_grid = 0.15 * np.cos(2 * t - 0.5) + 0.10 * np.cos(3 * t - 1.9) + 0.05 * np.cos(5 * t - 3.5) + 0.02 * np.cos(7 * t - 0.2)
    np.testing.assert_allclose(expect, truth_grid, atol=1e-9)


def test_errors_are_clear():
    cols, _ = synthetic(n=60)
    bad = dict(cols, probe_top_um=cols["probe_top_um"][:-1])
    with pytest.raises(ValueError, match="probe_top_um"):
        radial_motion(ProbeReadings(**bad), SphereSpacing(L1, L2))
    few = {k: v[:15] for k, v in cols.items()}  # rep 0 with 15 readings < 21 parameters
    with pytest.raises(ValueError, match="repetition 0"):
        radial_motion(ProbeReadings(**few), SphereSpacing(L1, L2))


def test_error_motion_values_single_rep():
    v = np.array([[0.0, 0.2, -0.1]])
    s = error_motion_values(v)
    assert s["total_um"] == pytest.approx(0.3) and s["asynchronous_um"] == 0.0


def test_keep_residual_keeps_content_above_the_order():
    cols, truth = synthetic(n=360)
    t = np.radians(cols["theta_deg"])
    hf = 0.03 * np.cos(15 * t)  # order 15: eq. 7 (order 10) filters it, keep_residual keeps it
    cols["probe_top_um"] = cols["probe_top_um"] + hf
    cols["probe_bottom_um"] = cols["probe_bottom_um"] + hf
    lit = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2))
    raw = radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2), RadialOptions(keep_residual=True))
    tg = np.radians(truth["theta_deg"])
    np.testing.assert_allclose(lit["dY_um"], truth["dY"], atol=1e-9)
    np.testing.assert_allclose(raw["dY_um"], truth["dY"] + 0.03 * np.cos(15 * tg), atol=1e-9)
    np.testing.assert_allclose(raw["dY_fn"](truth["theta_deg"]), raw["dY_um"], atol=1e-12)
    with pytest.raises(ValueError, match="same angles"):
        radial_motion(ProbeReadings(**cols), SphereSpacing(L1, L2),
                      RadialOptions(keep_residual=True, grid_deg=np.arange(0, 360, 2.0)))


def test_order1_model_error_is_the_backward_whirl_the_ccd_misreads():
    """RadialMotion.order1_model_error: a forward circle (centring, eccentricity) gives nothing; a
    backward one, B·e^{−iθ} at both spheres, gives 2·Re(B e^{−iθ}) with the CCD opposite the head
    and nothing with the CCD at 90°; its perturbation columns are the coefficients' type-A u."""
    from benchtwin.analysis.radial_motion import RadialMotion

    rng = np.random.default_rng(3)
    th = np.tile(np.arange(0.0, 360.0, 5.0), 3)
    t = np.deg2rad(th)
    lobes = 0.1 * np.sin(3 * t + 0.4)
    fwd_top, fwd_bot = 2.0 * np.exp(1j * (t + 0.7)), 3.0 * np.exp(1j * (t - 1.1))
    B = 0.12 - 0.05j
    bw = B * np.exp(-1j * t)
    noise = lambda: rng.normal(0, 0.002, th.size)  # noqa: E731
    top, bot = fwd_top + bw, fwd_bot + bw
    rm = RadialMotion(th, top.imag + lobes + noise(), bot.imag + noise(), 6.81, 122.96,
                      top_x_um=top.real + noise(), bottom_x_um=bot.real + lobes + noise(), rep=np.repeat([0, 1, 2], 72))
    a1, b1 = rm.order1_model_error(180.0)[1]
    # 2·Re(B e^{−iθ}) = 2·(Re B cos θ + Im B sin θ)
    assert a1 == pytest.approx(2 * B.imag, abs=2e-3) and b1 == pytest.approx(2 * B.real, abs=2e-3)
    a1, b1 = rm.order1_model_error(90.0)[1]
    assert abs(a1) < 1e-12 and abs(b1) < 1e-12
    P = rm.order1_model_error_perturbations(th, 180.0)
    assert P.shape == (th.size, 8) and 0 < np.abs(P).max() < 0.01
    fwd_only = RadialMotion(th, fwd_top.imag + noise(), fwd_bot.imag + noise(), 6.81, 122.96,
                            top_x_um=fwd_top.real + noise(), bottom_x_um=fwd_bot.real + noise())
    # no backward whirl: |B| below 3 u(|B|) (the probes' noise only): nothing enters
    assert fwd_only.backward_whirl_z() < 3.0 and fwd_only.order1_model_error(180.0) == {}
    assert fwd_only.order1_model_error_perturbations(th).shape == (th.size, 0)
    assert rm.backward_whirl_z() > 30.0
    assert RadialMotion(th, top.imag, bot.imag, 6.81, 122.96).order1_model_error() == {}
