"""Tests of multi-head self-calibration (Hsieh 2022 sec. 2.3, eqs. 8-9; SelfA head sets)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchtwin.analysis import selfcal as sc

TH = np.arange(360.0)


def series(harm: dict[int, tuple[float, float]]):
    def a(th):
        t = np.deg2rad(np.asarray(th, dtype=float))
        return sum(A * np.sin(k * t + ph) for k, (A, ph) in harm.items())

    return a


# harmonics chosen to hit the blind spots of each SelfA set: 3, 6 (NH3), 4, 8, 12 (NH3 and NH4),
# 7, 14, 21 (NH7), 28 (NH4 and NH7), 84 (all three)
HARM = {1: (0.1, 0.0), 2: (1.0, 0.3), 3: (0.4, 1.1), 4: (0.3, -0.5), 5: (0.1, 0.2), 6: (0.08, 0.0), 7: (0.2, 0.4),
        8: (0.05, 1.0), 12: (0.06, 0.3), 14: (0.04, 0.0), 21: (0.03, 2.0), 28: (0.02, -1.0), 84: (0.05, 0.7)}
A_TRUE = series(HARM)


def without(harm, pred):
    return series({k: v for k, v in harm.items() if not pred(k)})


@pytest.mark.parametrize("nh", [3, 4, 7])
def test_eq9_equal_spacing_loses_exactly_the_multiples_of_NH(nh):
    heads = [360.0 * j / nh for j in range(nh)]
    d = sc.head_deltas_arcsec(A_TRUE, TH, heads)
    assert np.all(d[:, 0] == 0.0)
    mu, u = sc.equal_spacing_selfcal_arcsec(d)
    np.testing.assert_allclose(mu, without(HARM, lambda k: k % nh == 0)(TH), atol=1e-12)
    assert np.all(np.isnan(u))
    # the Fourier version of the same set is eq. 9
    r = sc.selfcal_fourier(TH, heads, d, sets={f"NH{nh}": list(range(1, nh + 1))})
    np.testing.assert_allclose(r.value_arcsec, mu, atol=1e-12)
    np.testing.assert_array_equal(r.invisible_by_set[f"NH{nh}"], np.arange(nh, 180, nh))


def test_transfer_function_of_equally_spaced_set():
    k = np.arange(0, 30)
    for nh in (3, 4, 7):
        H = sc.transfer_function([360.0 * j / nh for j in range(nh)], k)
        np.testing.assert_allclose(np.abs(H), np.where(k % nh == 0, 0.0, 1.0), atol=1e-12)
    # head 1 alone sees nothing; two opposite heads miss the even harmonics and see odd ones doubled/2
    H2 = sc.transfer_function([0.0, 180.0], k)
    np.testing.assert_allclose(H2, np.where(k % 2 == 0, 0.0, 1.0), atol=1e-12)
    np.testing.assert_array_equal(sc.invisible_harmonics([0.0, 120.0, 240.0], 10), [3, 6, 9])


def test_selfa_heads_form_the_three_sets():
    psi = np.array(sc.SELFA_HEADS_DEG)
    assert np.all(np.diff(psi) > 0) and psi[0] == 0.0
    for name, nh in (("NH3", 3), ("NH4", 4), ("NH7", 7)):
        got = np.sort(psi[np.array(sc.SELFA_SETS[name]) - 1])
        np.testing.assert_allclose(got, np.arange(nh) * 360.0 / nh, atol=1e-12)
    assert psi[6] - psi[0] == 180.0  # heads 1 and 7 opposite (sec. 3.2)


def test_selfa_sets_blind_spots_and_recovery_by_combining():
    d = sc.head_deltas_arcsec(A_TRUE, TH, sc.SELFA_HEADS_DEG)
    r = sc.selfcal_fourier(TH, sc.SELFA_HEADS_DEG, d, sets=sc.SELFA_SETS)
    for name, nh in (("NH3", 3), ("NH4", 4), ("NH7", 7)):
        # each set alone misses its multiples of NH …
        np.testing.assert_allclose(r.per_set_arcsec[name], without(HARM, lambda k, nh=nh: k % nh == 0)(TH), atol=1e-12)
        assert np.max(np.abs(r.per_set_arcsec[name] - A_TRUE(TH))) > 0.05
        H = r.H[name]
        assert np.all(np.abs(H[np.arange(nh, 181, nh)]) < 1e-12)
    # … the combination recovers everything but the common multiples of 3, 4 and 7
    np.testing.assert_array_equal(r.unobservable_harmonics, [84, 168])
    np.testing.assert_allclose(r.value_arcsec, without(HARM, lambda k: k % 84 == 0)(TH), atol=1e-12)
    # head-level least squares: the same
    r2 = sc.selfcal_fourier(TH, sc.SELFA_HEADS_DEG, d)
    np.testing.assert_allclose(r2.value_arcsec, r.value_arcsec, atol=1e-12)


def test_irregular_heads_off_the_theta_grid():
    heads = [0.0, 37.3, 113.9, 250.1]
    a = series({1: (0.2, 0.1), 2: (1.0, 0.0), 5: (0.3, 1.0), 17: (0.05, 0.5)})
    th = np.arange(0.0, 360.0, 2.5)  # 144 points, band limit 71
    d = sc.head_deltas_arcsec(a, th, heads)
    r = sc.selfcal_fourier(th, heads, d)
    assert r.unobservable_harmonics.size == 0
    np.testing.assert_allclose(r.value_arcsec, a(th), atol=1e-10)


def test_grid_start_and_order_do_not_matter():
    heads = [0.0, 90.0, 180.0, 270.0]
    th = np.mod(np.arange(72) * 5.0 + 2.5, 360.0)
    rng = np.random.default_rng(11)
    perm = rng.permutation(th.size)
    d = sc.head_deltas_arcsec(A_TRUE, th[perm], heads)
    r = sc.selfcal_fourier(th[perm], heads, d)
    np.testing.assert_allclose(r.theta_deg, np.sort(th))
    np.testing.assert_allclose(r.value_arcsec, without(HARM, lambda k: k % 4 == 0 or k >= 36)(r.theta_deg), atol=1e-10)


def test_noise_uncertainty_matches_scatter_and_residual_sigma():
    sigma = 0.01
    th = np.arange(0.0, 360.0, 5.0)
    d0 = sc.head_deltas_arcsec(series({2: (1.0, 0.3), 3: (0.2, 0.0)}), th, sc.SELFA_HEADS_DEG)
    truth = series({2: (1.0, 0.3), 3: (0.2, 0.0)})(th)
    rng = np.random.default_rng(12345)
    for sets in (sc.SELFA_SETS, None):
        est, sig = [], []
        for _ in range(300):
            d = d0 + rng.normal(0.0, sigma, d0.shape)
            d[:, 0] = 0.0
            r = sc.selfcal_fourier(th, sc.SELFA_HEADS_DEG, d, sets=sets)
            est.append(r.value_arcsec)
            sig.append(r.sigma_delta_arcsec)
        emp = np.std(np.array(est) - truth, axis=0, ddof=1)
        r_known = sc.selfcal_fourier(th, sc.SELFA_HEADS_DEG, d, sets=sets, u_delta_arcsec=sigma)
        assert np.mean(emp) == pytest.approx(np.mean(r_known.u_arcsec), rel=0.03)
        assert np.median(sig) == pytest.approx(sigma, rel=0.05)
        assert np.mean(r.u_arcsec) == pytest.approx(np.mean(r_known.u_arcsec), rel=0.15)
    # eq. 9 u for equally spaced heads
    mu, u = sc.equal_spacing_selfcal_arcsec(np.zeros((5, 4)), 0.02)
    np.testing.assert_allclose(u, 0.02 * np.sqrt(3) / 4)


def test_head_level_ls_beats_single_set_noise():
    """Combining all heads gives a smaller u than the best single set (more information)."""
    d = sc.head_deltas_arcsec(A_TRUE, TH, sc.SELFA_HEADS_DEG)
    all_heads = sc.selfcal_fourier(TH, sc.SELFA_HEADS_DEG, d, u_delta_arcsec=0.01)
    nh7 = sc.selfcal_fourier(TH, sc.SELFA_HEADS_DEG, d, sets={"NH7": sc.SELFA_SETS["NH7"]}, u_delta_arcsec=0.01)
    assert np.mean(all_heads.u_arcsec) < np.mean(nh7.u_arcsec)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), nheads=st.integers(2, 6))
def test_property_random_heads_roundtrip_visible_part(seed, nheads):
    rng = np.random.default_rng(seed)
    heads = [0.0] + sorted(rng.uniform(5.0, 355.0, nheads - 1).round(3).tolist())
    harm = {int(k): (float(rng.normal(0, 1)), float(rng.uniform(-3, 3))) for k in rng.choice(np.arange(1, 20), 4, False)}
    a = series(harm)
    th = np.arange(0.0, 360.0, 4.0)
    d = sc.head_deltas_arcsec(a, th, heads)
    r = sc.selfcal_fourier(th, heads, d, tol=1e-3)
    lost = set(int(k) for k in r.unobservable_harmonics)
    np.testing.assert_allclose(r.value_arcsec, without(harm, lambda k: k in lost)(th), atol=1e-6)


# --------------------------------------------------------------------------- input errors


def test_errors_grid_heads_shape():
    d = sc.head_deltas_arcsec(A_TRUE, TH, [0.0, 120.0, 240.0])
    with pytest.raises(ValueError, match="equally spaced"):
        sc.selfcal_fourier(np.r_[TH[:-1], 359.5], [0.0, 120.0, 240.0], d)
    with pytest.raises(ValueError, match=r"heads_deg\[0\] must be 0"):
        sc.selfcal_fourier(TH, [10.0, 120.0, 240.0], d)
    with pytest.raises(ValueError, match="expected shape"):
        sc.selfcal_fourier(TH, [0.0, 120.0], d)
    with pytest.raises(ValueError, match="outside 1…3"):
        sc.selfcal_fourier(TH, [0.0, 120.0, 240.0], d, sets={"x": [1, 4]})
    d[3, 1] = np.nan
    with pytest.raises(ValueError, match=r"not finite at \(row, head\) \[\(3, 2\)\]"):
        sc.selfcal_fourier(TH, [0.0, 120.0, 240.0], d)


def test_tabulate_heads_averages_reps_and_names_bad_rows():
    th = np.repeat(np.arange(0.0, 360.0, 90.0), 2)
    head = np.tile([2, 3], 4)
    vals = np.arange(8.0)
    cols = {"theta_deg": np.r_[th, th], "head": np.r_[head, head], "delta_arcsec": np.r_[vals, vals + 1.0],
            "rep": np.r_[np.zeros(8), np.ones(8)]}
    t = sc.tabulate_heads(cols["theta_deg"], cols["head"], cols["delta_arcsec"], 3, rep=cols["rep"])
    np.testing.assert_allclose(t["delta_arcsec"][:, 0], 0.0)
    np.testing.assert_allclose(t["delta_arcsec"][:, 1], vals[::2] + 0.5)
    np.testing.assert_allclose(t["sd_arcsec"][:, 1:], np.sqrt(0.5))
    with pytest.raises(ValueError, match=r"rows 0 and 8, columns theta_deg/head: duplicated"):
        sc.tabulate_heads(cols["theta_deg"], cols["head"], cols["delta_arcsec"], 3)
    with pytest.raises(ValueError, match=r"rows \[5\], column 'head'"):
        h = head.copy()
        h[5] = 4
        sc.tabulate_heads(th, h, vals, 3)
    with pytest.raises(ValueError, match=r"missing readings \(theta_deg, head\): \[\(270.0, 3\)\]"):
        sc.tabulate_heads(th[:-1], head[:-1], vals[:-1], 3)
    with pytest.raises(ValueError, match=r"rows \[2\], column 'delta_arcsec'"):
        v = vals.copy()
        v[2] = np.nan
        sc.tabulate_heads(th, head, v, 3)


# --------------------------------------------------------------------------- what the twin showed (issue 6)


def _radial_motion_heads(g, theta, heads_deg, dx, dy):
    """Head j's reading error a_j(θ) = g(θ − ψ_j) + m_j(θ): g a property of the disk, m_j(θ) =
    −(d_x(θ)·cos ψ_j + d_y(θ)·sin ψ_j) the axis' lab-fixed radial error motion seen at head j (already
    divided by the radius, arcsec). Returns (α = a_1, δ = a_1 − a_j per head)."""
    psi = np.deg2rad(np.asarray(heads_deg))
    a = np.column_stack([g(np.mod(theta - p, 360.0)) - (dx(theta) * np.cos(q) + dy(theta) * np.sin(q))
                         for p, q in zip(heads_deg, psi)])
    return a[:, 0], a[:, :1] - a


def test_equally_spaced_sets_found_among_heads():
    assert sc.equally_spaced_sets(sc.SELFA_HEADS_DEG) == sc.SELFA_SETS
    assert sc.equally_spaced_sets([0.0, 90.0, 180.0, 270.0]) == {"NH4": [1, 2, 3, 4]}
    assert sc.equally_spaced_sets([0.0, 180.0, 100.0]) == {"NH2": [1, 2]}
    assert sc.equally_spaced_sets([0.0, 100.0, 220.0]) == {}
    # a set that does not contain head 1
    assert sc.equally_spaced_sets([0.0, 30.0, 210.0]) == {"NH2@2": [2, 3]}


def test_set_averages_cancel_the_axis_radial_error_motion_single_heads_do_not():
    """The twin's hsieh2022 axis has an order-3 radial error motion (bearing waviness): head j sees
    −(d·t_j)/r, which is not head 1's error shifted by ψ_j. Averaging equally spaced heads cancels it
    (Σ_j t_j = 0), so eq. 9 per set recovers α = g + m_1; the head-level least squares does not."""
    th = np.arange(360.0)
    g = series({2: (1.0, 0.3), 3: (0.4, 1.1), 5: (0.1, 0.2), 7: (0.2, 0.4)})
    dx = lambda x: 0.09 * np.cos(3 * np.deg2rad(x) + 0.4)  # noqa: E731 (0.025 µm / 60 mm ≈ 0.09″)
    dy = lambda x: 0.09 * np.sin(3 * np.deg2rad(x) + 0.4)  # noqa: E731
    alpha, d = _radial_motion_heads(g, th, sc.SELFA_HEADS_DEG, dx, dy)
    assert np.ptp(alpha - g(th)) > 0.15  # the motion is part of head 1's error α
    sets = sc.selfcal_fourier(th, sc.SELFA_HEADS_DEG, d, sets=sc.SELFA_SETS)
    np.testing.assert_allclose(sets.value_arcsec, alpha - alpha.mean(), atol=1e-9)
    heads = sc.selfcal_fourier(th, sc.SELFA_HEADS_DEG, d)  # every head on its own
    assert np.max(np.abs(heads.value_arcsec - (alpha - alpha.mean()))) > 0.03
    assert heads.residual_rms_arcsec > 0.05  # the single heads' δ do not fit a disk-only model


def test_off_grid_set_folds_harmonics_above_nyquist_grid_sets_do_not():
    """On a 1° grid, heads at multiples of 1° (sets of 3 and 4) obey eq. 8 exactly for the samples of a,
    whatever a holds above harmonic 180; the set of 7 (51.43°) needs interpolation and folds such
    content. Preferring on-grid sets leaves only the multiples of 12 to the 7-set, whose error is then
    covered by u_model."""
    th = np.arange(360.0)
    rng = np.random.default_rng(2022)
    harm = {int(k): (0.025, float(rng.uniform(0, 6.28))) for k in rng.choice(np.arange(181, 900), 150, replace=False)}
    harm.update({2: (1.0, 0.3), 3: (0.4, 1.1), 12: (0.05, 0.2), 36: (0.03, 1.0)})
    a = series(harm)
    d = sc.head_deltas_arcsec(a, th, sc.SELFA_HEADS_DEG)
    truth = a(th)
    # the samples' own spectrum, without what the sets cannot see (84, 168) and the Nyquist term
    C = np.fft.rfft(truth)
    C[[0, 84, 168, 180]] = 0.0
    ref = np.fft.irfft(C, 360)
    grid = sc.selfcal_fourier(th, sc.SELFA_HEADS_DEG, d, sets=sc.SELFA_SETS, u_delta_arcsec=0.0)
    mixed = sc.selfcal_fourier(th, sc.SELFA_HEADS_DEG, d, sets=sc.SELFA_SETS, u_delta_arcsec=0.0,
                               prefer_on_grid=False)
    err_grid, err_mixed = grid.value_arcsec - ref, mixed.value_arcsec - ref
    assert grid.set_on_grid == {"NH3": True, "NH4": True, "NH7": False}
    assert np.sqrt(np.mean(err_grid**2)) < 0.5 * np.sqrt(np.mean(err_mixed**2))
    # what is left is in the multiples of 12 (only the 7-set sees them)
    E = np.abs(np.fft.rfft(err_grid))
    k = np.arange(E.size)
    assert np.all(E[k % 12 != 0] < 1e-9)
    assert grid.u_model_arcsec > 0.0
    assert np.sqrt(np.mean(err_grid**2)) < 2.0 * grid.u_model_arcsec
    assert np.max(np.abs(err_grid)) < 4.0 * grid.u_model_arcsec
    assert mixed.u_model_arcsec == 0.0


def test_exact_data_zero_u_delta_still_weighs_the_heads():
    """u_delta = 0 (exact data: repetitions that agree) used to zero every weight and return α = 0."""
    d = sc.head_deltas_arcsec(A_TRUE, TH, sc.SELFA_HEADS_DEG)
    r = sc.selfcal_fourier(TH, sc.SELFA_HEADS_DEG, d, sets=sc.SELFA_SETS, u_delta_arcsec=0.0)
    np.testing.assert_allclose(r.value_arcsec, without(HARM, lambda k: k % 84 == 0)(TH), atol=1e-9)
    assert np.max(r.u_arcsec) < 1e-9


def test_one_set_without_redundancy_has_no_residual_sigma():
    """One set of NH equally spaced heads: eq. 9 fits its average exactly, so there are no residual
    degrees of freedom. Before, dof and the residual sum of squares were both at rounding level
    (≈ 1e-31 on the twin's null_b) and their ratio was reported as σ(δ) ≈ 0.1″: a figure of the BLAS
    kernel, not of the data. Now dof = 0 and σ is NaN, whatever the noise."""
    th = np.arange(0.0, 360.0, 2.0)
    heads = [0.0, 120.0, 240.0]
    d = sc.head_deltas_arcsec(series({1: (1.0, 0.2), 2: (0.5, 0.1)}), th, heads)
    d = d + np.random.default_rng(3).normal(0.0, 0.1, d.shape) * (np.arange(3) > 0)
    r = sc.selfcal_fourier(th, heads, d, sets={"NH3": [1, 2, 3]})
    assert r.dof == 0.0 and np.isnan(r.sigma_delta_arcsec)
