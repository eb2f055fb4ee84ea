"""Tests of the Hsieh 2022 shift-angle method (benchtwin.analysis.shift_angle) and its pipeline.

Synthetic readings come from eq. 3 with known α (a few harmonics, none a multiple of N unless the test
is about that), β (Σβ = 0) and U_j(S); every random draw uses an explicit seed.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from benchtwin.analysis import selfcal as sc
from benchtwin.analysis import shift_angle as sa
from benchtwin.analysis.hsieh_pipeline import HSIEH2022_TYPE_B, HeadsData, analyze_polygon, fourier_resample_arcsec
from tests.synthetic.polygon import synthesize_readings


def make_alpha(harm: dict[int, tuple[float, float]]):
    """α(θ) = Σ_k A_k sin(kθ + φ_k), arcsec."""

    def alpha(th):
        t = np.deg2rad(np.asarray(th, dtype=float))
        return sum(A * np.sin(k * t + ph) for k, (A, ph) in harm.items())

    return alpha


ALPHA = make_alpha({1: (0.3, 0.2), 2: (1.0314, -2.4233), 3: (0.4, 1.0), 7: (0.2, 0.5), 11: (0.05, -1.0)})


def make_beta(N: int, seed: int) -> np.ndarray:
    b = np.random.default_rng(seed).normal(0.0, 0.8, N)
    return b - b.mean()


def setup_fn(seed: int):
    rng = np.random.default_rng(seed)
    table = {}

    def U(S, j):
        key = (round(float(S), 9), int(j))
        if key not in table:
            table[key] = float(rng.normal(0.0, 2.0))
        return table[key]

    return U


def analyse(cols, N, **kw):
    tab = sa.tabulate_polygon({k: v for k, v in cols.items() if k != "direction"}, N)
    return tab, sa.shift_angle_analysis(tab, **kw)


# --------------------------------------------------------------------------- noise-free round trips


@pytest.mark.parametrize("N", [23, 24, 5])
def test_noise_free_roundtrip_beta_alpha_U(N):
    beta = make_beta(N, 10 + N)
    U = setup_fn(20 + N)
    shifts = [0.0, 5.0, 10.0]
    cols = synthesize_readings(ALPHA, beta, U, shifts, start_faces_at={5.0: [1], 10.0: [3, N]})
    tab, res = analyse(cols, N)
    assert res.beta_source == "closure"
    np.testing.assert_allclose(res.beta_arcsec, beta, atol=1e-9)
    assert abs(res.beta_arcsec.sum()) < 1e-12
    for s in res.shifts:
        ref = ALPHA(s.theta_deg)
        # closure (eq. 2) removes harmonics that are multiples of N: none in ALPHA for N > 11
        if N > 11:
            np.testing.assert_allclose(s.alpha_arcsec, ref, atol=1e-9)
            np.testing.assert_allclose(s.U_arcsec, [U(s.shift_deg, j) for j in s.start_faces], atol=1e-9)
    assert tab.n_rep[0.0].min() == 1


def test_table1_eq3_cells_and_table2_eq6_entries():
    N = 24
    beta = make_beta(N, 1)
    cols = synthesize_readings(ALPHA, beta, setup_fn(2), [0.0])
    tab, _ = analyse(cols, N)
    t = tab.eps_arcsec[0.0]
    B = sa.cumulative_pitch_sum_arcsec(beta)
    # eq. 3 sums: i terms from face j, wrapping; the full circle sums to 0
    assert B[0, 0] == pytest.approx(beta[0])
    assert B[1, N - 1] == pytest.approx(0.0, abs=1e-12)
    assert B[N - 1, 1] == pytest.approx(beta[N - 1] + beta[0])
    assert B[22, 22] == pytest.approx(beta[22:].sum() + beta[:21].sum())  # Table 1: Σ_{k=23}^{21}
    delta, n = sa.table2_arcsec(t)
    # first row of Table 2 (eq. 6): δ_{2,1,24}, δ_{3,2,23}, …, δ_{25,24,1}
    assert n[0].tolist() == [24] + list(range(23, 0, -1))
    assert delta[0, 0] == pytest.approx(t[23, 1] - t[23, 0])
    assert delta[0, N - 1] == pytest.approx(t[0, 0] - t[0, N - 1])  # ε_{25,1} ≡ ε_{1,1}
    th = np.arange(N) * 15.0
    assert delta[0, 0] == pytest.approx(ALPHA(15.0) - ALPHA(0.0) + beta[0])
    np.testing.assert_allclose(delta.mean(axis=1), beta, atol=1e-12)
    # the explicit linear operator is the same estimator
    np.testing.assert_allclose(sa.pitch_deviation_operator(N) @ t.ravel(), beta, atol=1e-12)
    del th


def test_shifts_0_to_14_combine_into_1_degree_curve():
    N = 24
    beta = make_beta(N, 3)
    U = setup_fn(4)
    cols = synthesize_readings(ALPHA, beta, U, np.arange(15.0))
    _, res = analyse(cols, N)
    th, a, u = sa.combined_curve(res)
    np.testing.assert_array_equal(th, np.arange(360.0))
    np.testing.assert_allclose(a, ALPHA(th), atol=1e-9)
    assert abs(a.sum()) < 1e-9  # closure holds per shift, hence overall


def test_any_N_23_faces_shifts_fill_the_pitch():
    N = 23
    beta = make_beta(N, 5)
    pitch = 360.0 / N
    shifts = np.arange(0, 4) * pitch / 4
    cols = synthesize_readings(ALPHA, beta, setup_fn(6), shifts)
    _, res = analyse(cols, N)
    th, a, _ = sa.combined_curve(res)
    assert th.size == 4 * N
    np.testing.assert_allclose(np.diff(th), pitch / 4, atol=1e-6)
    np.testing.assert_allclose(a, ALPHA(th), atol=1e-9)


def test_harmonics_multiple_of_N_are_lost_into_setup_error():
    N = 12
    beta = make_beta(N, 7)
    alpha = make_alpha({2: (1.0, 0.1), 12: (0.3, 0.4), 24: (0.1, 0.0)})
    visible = make_alpha({2: (1.0, 0.1)})
    cols = synthesize_readings(alpha, beta, setup_fn(8), [0.0, 7.5])
    _, res = analyse(cols, N)
    for s in res.shifts:
        np.testing.assert_allclose(s.alpha_arcsec, visible(s.theta_deg), atol=1e-9)


def test_curve_fit_setup_error_agrees_with_eq7():
    N = 24
    beta = make_beta(N, 9)
    alpha = make_alpha({2: (1.0314, -2.4233)})
    cols = synthesize_readings(alpha, beta, setup_fn(10), [0.0, 5.0, 10.0])
    _, res = analyse(cols, N)
    rows = sa.setup_error_by_curve_fit(res)
    assert len(rows) == N + 2
    assert max(abs(r["diff_arcsec"]) for r in rows) < 1e-9
    assert rows[0]["A_arcsec"] == pytest.approx(1.0314, abs=1e-9)
    assert rows[0]["B_rad"] == pytest.approx(-2.4233, abs=1e-9)
    # paper's form directly: fit at S=0 then only U with A, B fixed
    y5 = alpha(np.arange(N) * 15.0 + 5.0) + 1.234
    f = sa.fit_sine2_offset(np.arange(N) * 15.0 + 5.0, y5, A_arcsec=1.0314, B_rad=-2.4233)
    assert f["U_arcsec"] == pytest.approx(1.234, abs=1e-12)
    # general K-harmonic version on the richer α
    cols = synthesize_readings(ALPHA, beta, setup_fn(11), [0.0, 5.0])
    _, res = analyse(cols, N)
    rows = sa.setup_error_by_curve_fit(res, harmonics=(1, 2, 3, 7, 11))
    assert max(abs(r["diff_arcsec"]) for r in rows) < 1e-9
    ref = rows[0]
    assert ref["U_fit_arcsec"] == pytest.approx(res.shifts[0].U_arcsec[0], abs=1e-9)


def test_curve_fit_rejects_harmonic_aliasing_onto_offset():
    th = np.arange(12) * 30.0
    with pytest.raises(ValueError, match="not identifiable"):
        sa.fit_harmonic_offset(th, np.zeros(12), harmonics=(2, 12))


def test_fit_fails_to_match_when_shape_is_wrong():
    """The check is able to fail: with points not equally spaced the fixed-shape U differs from the mean."""
    th = np.array([0, 10, 50, 100, 200, 300.0])
    y = np.sin(2 * np.deg2rad(th)) + 0.5
    f = sa.fit_harmonic_offset(th, y, (2,), fixed_coef=np.array([0.0, 0.0]))
    assert abs(f["U"] - 0.5) > 1e-3


# --------------------------------------------------------------------------- traditional cross-calibration


def test_cross_calibration_with_certificate_one_start_face():
    N = 24
    beta = make_beta(N, 12)
    cols = synthesize_readings(ALPHA, beta, setup_fn(13), [0.0])
    tab, _ = analyse(cols, N)
    row = tab.eps_arcsec[0.0][4]  # start face 5 only
    r = sa.cross_calibrate_with_certificate(row, beta + 0.01, start_face=5, u_eps_arcsec=0.02,
                                            u_certificate_arcsec=0.03)
    np.testing.assert_allclose(r["alpha"], ALPHA(np.arange(N) * 15.0), atol=1e-9)  # mean 0.01 removed
    assert r["certificate_mean_arcsec"] == pytest.approx(0.01)
    assert np.all(r["u_alpha"] > 0.02 * np.sqrt(1 - 1 / N) - 1e-12)
    with pytest.raises(sa.PolygonDataError, match="expected N = 24"):
        sa.cross_calibrate_with_certificate(row, beta[:-1])


def test_certificate_used_when_S0_table_incomplete_and_closure_compared_when_full():
    N = 12
    beta = make_beta(N, 14)
    cols = synthesize_readings(ALPHA, beta, setup_fn(15), [0.0, 10.0])
    keep = (cols["shift_deg"] != 0.0) | (cols["start_face"] == 1)
    part = {k: v[keep] for k, v in cols.items()}
    _, res = analyse(part, N, beta_from=sa.BetaSource(certificate_arcsec=beta))
    assert res.beta_source == "certificate"
    for s in res.shifts:
        np.testing.assert_allclose(s.alpha_arcsec, ALPHA(s.theta_deg), atol=1e-9)
    with pytest.raises(sa.PolygonDataError, match=r"incomplete Table 1.*start_face=2, step=1"):
        analyse(part, N)
    _, full = analyse(cols, N, beta_from=sa.BetaSource("certificate", beta + 0.1))
    np.testing.assert_allclose(full.beta_closure_arcsec, beta, atol=1e-9)


def test_closure_cross_calibration_is_the_S0_part():
    N = 10
    beta = make_beta(N, 16)
    cols = synthesize_readings(ALPHA, beta, setup_fn(17), [0.0])
    tab, res = analyse(cols, N)
    r = sa.cross_calibrate_closure(tab.eps_arcsec[0.0])
    np.testing.assert_allclose(r["beta"], res.beta_arcsec, atol=1e-12)
    np.testing.assert_allclose(r["alpha"], res.shifts[0].alpha_arcsec, atol=1e-12)
    s, nu = sa.closure_residual_sd_arcsec(tab.eps_arcsec[0.0])
    assert s < 1e-12 and nu == 72


# --------------------------------------------------------------------------- noise and uncertainty


def test_noisy_recovery_within_propagated_uncertainty():
    N = 24
    rng = np.random.default_rng(2024)
    beta = make_beta(N, 18)
    sigma = 0.05
    cols = synthesize_readings(ALPHA, beta, setup_fn(19), np.arange(15.0), n_rep=3, noise_arcsec=sigma, rng=rng)
    tab, res = analyse(cols, N)
    # repetitions averaged, repeatability reported
    assert tab.n_rep[0.0].min() == 3 and tab.n_rep[5.0][0].min() == 3
    sd = np.concatenate([tab.sd_arcsec[s][np.isfinite(tab.sd_arcsec[s])] for s in tab.shifts_deg])
    assert np.sqrt(np.mean(sd**2)) == pytest.approx(sigma, rel=0.1)
    zb = (res.beta_arcsec - beta) / res.u_beta_arcsec
    assert np.max(np.abs(zb)) < 4.5
    # Mahalanobis distance with the propagated covariance (rank N−1: Σβ = 0) ~ χ²(N−1)
    d = res.beta_arcsec - beta
    m2 = d @ np.linalg.pinv(res.cov_beta_arcsec2, rcond=1e-10, hermitian=True) @ d
    assert stats.chi2.ppf(0.001, N - 1) < m2 < stats.chi2.ppf(0.999, N - 1)
    th, a, u = sa.combined_curve(res)
    za = (a - ALPHA(th)) / u
    assert np.max(np.abs(za)) < 5.0
    assert 0.7 < np.mean(za**2) < 1.4
    assert abs(res.beta_arcsec.sum()) < 1e-12


def test_propagated_u_matches_monte_carlo_scatter():
    """The linear propagation (incl. the α-β correlation at S=0) against 400 noisy repetitions, N = 8."""
    N, sigma, M = 8, 0.1, 400
    beta = make_beta(N, 21)
    U = setup_fn(22)
    clean = synthesize_readings(ALPHA, beta, U, [0.0, 20.0])
    rng = np.random.default_rng(23)
    b_hat, a0, a20 = [], [], []
    for _ in range(M):
        cols = dict(clean)
        cols["ac_arcsec"] = clean["ac_arcsec"] + rng.normal(0.0, sigma, clean["ac_arcsec"].size)
        _, res = analyse(cols, N, u_eps_arcsec=sigma)
        b_hat.append(res.beta_arcsec)
        a0.append(res.shifts[0].alpha_arcsec)
        a20.append(res.shifts[1].alpha_arcsec)
    for est, u in ((b_hat, res.u_beta_arcsec), (a0, res.shifts[0].u_alpha_arcsec), (a20, res.shifts[1].u_alpha_arcsec)):
        emp = np.std(np.array(est), axis=0, ddof=1)
        np.testing.assert_allclose(emp, u, rtol=0.15)
    # averaged over all N start faces, α at S = 0 does not depend on β at all: u = σ·√((1 − 1/N)/N)
    np.testing.assert_allclose(res.shifts[0].u_alpha_arcsec, sigma * np.sqrt((1 - 1 / N) / N), rtol=1e-12)


# --------------------------------------------------------------------------- clear errors


def full_cols(N=6, shifts=(0.0, 5.0)):
    return synthesize_readings(ALPHA, make_beta(N, 30), setup_fn(31), list(shifts))


def tab_of(cols, N=6, **kw):
    return sa.tabulate_polygon({**{k: v for k, v in cols.items() if k != "direction"}, **kw}, N)


def test_error_missing_reading_names_cell():
    cols = full_cols()
    drop = np.flatnonzero((cols["shift_deg"] == 0) & (cols["start_face"] == 3) & (cols["step"] == 4))[0]
    cols = {k: np.delete(v, drop) for k, v in cols.items()}
    with pytest.raises(sa.PolygonDataError, match=r"shift_deg=0.*missing readings \(start_face=3, step=4\)"):
        tab_of(cols)


def test_error_whole_start_face_missing_at_S0_is_incomplete_table():
    cols = full_cols()
    keep = ~((cols["shift_deg"] == 0) & (cols["start_face"] == 2))
    cols = {k: v[keep] for k, v in cols.items()}
    tab = tab_of(cols)
    with pytest.raises(sa.PolygonDataError, match=r"incomplete Table 1.*\(start_face=2, step=1\)"):
        sa.shift_angle_analysis(tab)


def test_error_duplicate_without_rep_names_both_rows():
    cols = full_cols()
    cols = {k: np.concatenate([v, v[7:8]]) for k, v in cols.items()}
    n = cols["ac_arcsec"].size
    with pytest.raises(sa.PolygonDataError, match=rf"rows 7 and {n - 1}.*duplicated reading.*no 'rep' column"):
        tab_of(cols)


def test_error_duplicate_with_same_rep():
    cols = full_cols()
    cols["rep"] = np.zeros(cols["ac_arcsec"].size, dtype=int)
    cols = {k: np.concatenate([v, v[3:4]]) for k, v in cols.items()}
    with pytest.raises(sa.PolygonDataError, match=r"rows 3 and \d+.*rep=0"):
        tab_of(cols)


@pytest.mark.parametrize("col,val", [("start_face", 7), ("start_face", 0), ("step", 0), ("step", 2.5)])
def test_error_face_or_step_out_of_range_names_row_and_column(col, val):
    cols = full_cols()
    cols[col] = cols[col].astype(float)
    cols[col][11] = val
    with pytest.raises(sa.PolygonDataError, match=rf"row 11, column '{col}': expected an integer in 1…6"):
        tab_of(cols)


@pytest.mark.parametrize("col", ["ac_arcsec", "shift_deg", "theta_deg"])
def test_error_nan_names_rows_and_column(col):
    cols = full_cols()
    cols[col] = cols[col].astype(float)
    cols[col][[4, 9]] = np.nan
    with pytest.raises(sa.PolygonDataError, match=rf"rows 4, 9, column '{col}': not a finite number"):
        tab_of(cols)


def test_error_wrong_face_count():
    cols = full_cols(N=5)
    with pytest.raises(sa.PolygonDataError, match="wrong face count"):
        tab_of({k: v for k, v in cols.items() if k != "theta_deg"}, N=6)
    with pytest.raises(sa.PolygonDataError, match=r"column 'theta_deg'.*wrong face count"):
        tab_of(cols, N=6)
    with pytest.raises(sa.PolygonDataError, match="n_faces"):
        tab_of(cols, N=2)


def test_error_columns_of_different_length():
    cols = full_cols()
    cols["step"] = cols["step"][:-1]
    with pytest.raises(sa.PolygonDataError, match="different lengths"):
        tab_of(cols)


def test_polygon_data_error_is_value_error():
    assert issubclass(sa.PolygonDataError, ValueError)


# --------------------------------------------------------------------------- properties


@settings(max_examples=30, deadline=None)
@given(N=st.integers(3, 30), seed=st.integers(0, 2**32 - 1))
def test_property_sum_beta_zero_for_any_table(N, seed):
    t = np.random.default_rng(seed).normal(0.0, 10.0, (N, N))
    beta, _, _ = sa.pitch_deviation_arcsec(t)
    assert abs(beta.sum()) < 1e-9 * N


@settings(max_examples=25, deadline=None)
@given(N=st.integers(3, 30), seed=st.integers(0, 2**32 - 1), shift=st.floats(0.01, 30.0))
def test_property_roundtrip_random_beta_alpha_U(N, seed, shift):
    rng = np.random.default_rng(seed)
    ks = [k for k in range(1, 4 * N) if k % N][:5]
    harm = {int(k): (float(rng.normal(0, 1)), float(rng.uniform(-np.pi, np.pi))) for k in rng.choice(ks, 3, replace=False)}
    alpha = make_alpha(harm)
    beta = rng.normal(0.0, 1.0, N)
    beta -= beta.mean()
    Us = rng.normal(0.0, 3.0, N + 1)
    cols = synthesize_readings(alpha, beta, lambda S, j: Us[j] if S == 0 else Us[0], [0.0, shift])
    _, res = analyse(cols, N)
    np.testing.assert_allclose(res.beta_arcsec, beta, atol=1e-9)
    for s in res.shifts:
        np.testing.assert_allclose(s.alpha_arcsec, alpha(s.theta_deg), atol=1e-8)


# --------------------------------------------------------------------------- pipeline


def _heads_columns(alpha, theta, heads_deg, noise, rng, n_rep=1):
    d = sc.head_deltas_arcsec(alpha, theta, heads_deg)
    th, hd, dl, rp = [], [], [], []
    for r in range(n_rep):
        dn = d + rng.normal(0.0, noise, d.shape)
        for j in range(1, len(heads_deg)):
            th.append(theta)
            hd.append(np.full(theta.size, j + 1))
            dl.append(dn[:, j])
            rp.append(np.full(theta.size, r))
    return {"theta_deg": np.concatenate(th), "head": np.concatenate(hd), "delta_arcsec": np.concatenate(dl),
            "rep": np.concatenate(rp)}


def test_analyze_polygon_end_to_end_json_ready():
    N = 24
    rng = np.random.default_rng(99)
    beta = make_beta(N, 40)
    alpha = make_alpha({2: (1.0314, -2.4233), 3: (0.3, 0.5), 5: (0.1, 0.1), 24: (0.02, 0.3)})
    cols = synthesize_readings(alpha, beta, setup_fn(41), np.arange(15.0), n_rep=3, noise_arcsec=0.02, rng=rng)
    heads = _heads_columns(alpha, np.arange(360.0), sc.SELFA_HEADS_DEG, 0.005, rng, n_rep=2)
    r = analyze_polygon(cols, N, HeadsData(heads, sc.SELFA_HEADS_DEG, sc.SELFA_SETS),
                        type_b=replace(HSIEH2022_TYPE_B, encoder_resolution_arcsec=0.04))
    json.dumps(r, allow_nan=False)
    for key in ("polygon_pitch_deviation_arcsec", "polygon_pitch_deviation_u_arcsec", "setup_error_arcsec",
                "encoder_error_arcsec", "selfcal_error_arcsec", "en_max", "budget"):
        assert key in r
    assert len(r["polygon_pitch_deviation_arcsec"]) == N
    assert sorted(r["setup_error_arcsec"], key=float) == [f"{s:g}" for s in range(15)]
    assert len(r["setup_error_arcsec"]["0"]) == N and len(r["setup_error_arcsec"]["5"]) == 1
    e = r["encoder_error_arcsec"]
    assert e["theta_deg"] == list(np.arange(360.0))
    assert all(u > 0 for u in e["u"])
    # shift-angle vs self-calibration agree (the harmonic 24 is removed from the self-cal side)
    assert r["en_max"] < 1.0
    assert max(abs(x) for x in r["difference_arcsec"]["value"]) < 0.1
    assert r["budget"][-1]["kind"] == "combined"
    assert r["budget_summary"]["k"] > 1.96
    # without heads
    r2 = analyze_polygon(cols, N, None)
    assert r2["en_max"] is None and r2["selfcal_error_arcsec"] is None


def test_analyze_polygon_detects_disagreement():
    """E_n can fail: a self-cal curve from a different encoder gives en_max > 1."""
    N = 24
    rng = np.random.default_rng(5)
    beta = make_beta(N, 42)
    alpha = make_alpha({2: (1.0, 0.0)})
    other = make_alpha({2: (1.5, 0.0)})
    cols = synthesize_readings(alpha, beta, setup_fn(43), [0.0, 5.0, 10.0], n_rep=3, noise_arcsec=0.01, rng=rng)
    heads = _heads_columns(other, np.arange(360.0), [0.0, 120.0, 240.0], 0.005, rng, n_rep=3)
    r = analyze_polygon(cols, N, HeadsData(heads, [0.0, 120.0, 240.0]))
    assert r["en_max"] > 1.0


def test_fourier_resample_drops_polygon_harmonics():
    th = np.arange(360.0)
    f = make_alpha({2: (1.0, 0.3), 24: (0.5, 0.0)})
    g = make_alpha({2: (1.0, 0.3)})
    x = np.array([0.5, 17.25, 200.0])
    np.testing.assert_allclose(fourier_resample_arcsec(th, f(th), x, drop_multiples_of=24), g(x), atol=1e-12)
    np.testing.assert_allclose(fourier_resample_arcsec(th, f(th), x), f(x), atol=1e-12)


def test_figures_render(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from benchtwin.analysis.report import figures_hsieh as fh

    N = 12
    rng = np.random.default_rng(7)
    alpha = make_alpha({2: (1.0, 0.2), 3: (0.2, 0.0)})
    cols = synthesize_readings(alpha, make_beta(N, 44), setup_fn(45), [0.0, 10.0, 20.0])
    heads = _heads_columns(alpha, np.arange(0, 360.0, 2.0), [0.0, 90.0, 180.0, 270.0], 0.005, rng)
    r = analyze_polygon(cols, N, HeadsData(heads, [0.0, 90.0, 180.0, 270.0]))
    for fn in (fh.figure_pitch_deviation, fh.figure_alpha_at_shifts, fh.figure_curve_fits,
               fh.figure_selfcal_vs_shift_angle, fh.figure_difference):
        fig = fn(r)
        fig.savefig(tmp_path / f"{fn.__name__}.png")
        assert (tmp_path / f"{fn.__name__}.png").stat().st_size > 1000


def test_closure_at_a_nonzero_reference_shift():
    N = 9
    beta = make_beta(N, 50)
    cols = synthesize_readings(ALPHA, beta, setup_fn(51), [0.0])
    cols["shift_deg"] = cols["shift_deg"] + 4.0  # the full table measured at S = 4°
    cols["theta_deg"] = np.mod(cols["theta_deg"] + 4.0, 360.0)
    cols["ac_arcsec"] = cols["ac_arcsec"] - ALPHA(cols["theta_deg"] - 4.0) + ALPHA(cols["theta_deg"])
    _, res = analyse(cols, N)
    assert res.reference_shift_deg == 4.0 and res.beta_source == "closure"
    np.testing.assert_allclose(res.beta_arcsec, beta, atol=1e-9)
    np.testing.assert_allclose(res.shifts[0].alpha_arcsec, ALPHA(res.shifts[0].theta_deg), atol=1e-9)
    assert sa.setup_error_by_curve_fit(res)[0]["shift_deg"] == 4.0


def test_pipeline_forward_backward_directions_and_theta_jitter():
    """Twin-like table: both directions (a hysteresis ±h cancels in the average), θ read with jitter."""
    N, h = 12, 0.3
    rng = np.random.default_rng(60)
    beta = make_beta(N, 61)
    base = synthesize_readings(ALPHA, beta, setup_fn(62), [0.0, 10.0])
    n = base["ac_arcsec"].size
    cols = {k: np.concatenate([v, v]) for k, v in base.items()}
    cols["direction"] = np.array(["forward"] * n + ["backward"] * n, dtype=object)
    cols["ac_arcsec"] = cols["ac_arcsec"] + np.r_[np.full(n, h), np.full(n, -h)] + rng.normal(0, 0.01, 2 * n)
    cols["theta_deg"] = np.mod(cols["theta_deg"] + rng.normal(0, 1e-4, 2 * n), 360.0)
    r = analyze_polygon(cols, N)
    e = r["encoder_error_arcsec"]
    np.testing.assert_allclose(e["value"], ALPHA(np.array(e["theta_deg"])), atol=0.03)
    assert r["repeatability"]["n_rep_min"] == 2
    assert r["repeatability"]["max_sd_eps_arcsec"] > h  # the two directions differ by 2h
    with pytest.raises(sa.PolygonDataError, match="direction"):
        analyze_polygon({k: np.concatenate([v, v[:1]]) for k, v in cols.items()}, N)


# --------------------------------------------------------------------------- repeatability and directions (issue 6)


def _runs(N, shifts, reps, sigma, h_fn, seed, alpha=ALPHA):
    """Readings of ``reps`` clampings (a new setup error per rep, shift and start face), each swept
    forward and backward; ``h_fn(theta_deg)`` is added forward and subtracted backward (hysteresis)."""
    rng = np.random.default_rng(seed)
    beta = make_beta(N, seed + 1)
    parts = []
    for r in range(reps):
        base = synthesize_readings(alpha, beta, setup_fn(seed + 10 + r), shifts)
        n = base["ac_arcsec"].size
        for d, sgn in (("forward", 1.0), ("backward", -1.0)):
            c = {k: v.copy() for k, v in base.items()}
            c["ac_arcsec"] = c["ac_arcsec"] + sgn * h_fn(c["theta_deg"]) + rng.normal(0.0, sigma, n)
            c["rep"] = np.full(n, r)
            c["direction"] = np.array([d] * n, dtype=object)
            parts.append(c)
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    tab = sa.tabulate_polygon(cols, N)
    return cols, tab, beta


def test_reading_repeatability_from_the_model_residuals_not_from_direction_pairs():
    """Forward/backward pairs and re-clampings are not repetitions of one value: a constant hysteresis
    ±h and the setup error of each clamping go into the row offsets, the scatter of one reading is
    what is left, with ν = readings − Σ(run-rows + N − 1) − (N − 1)."""
    N, R, sigma, h = 12, 3, 0.02, 0.3
    cols, tab, _ = _runs(N, [0.0, 5.0, 10.0], R, sigma, lambda th: np.full(th.shape, h), 100)
    rep = sa.reading_repeatability(tab)
    per_dir_s0 = R * N * N - (R * N + N - 1)
    per_dir_other = R * N - (R + N - 1)
    assert rep.dof == 2 * per_dir_s0 + 4 * per_dir_other - (N - 1) == 847
    assert rep.n_readings == cols["ac_arcsec"].size and not rep.dropped
    assert rep.s_arcsec == pytest.approx(sigma, rel=0.1)
    # the within-cell scatter of the old estimate is dominated by 2h and the clampings' setup errors
    assert tab.pooled_sd()[0] > 5 * sigma
    # one run, both directions, one start face at the other shifts (the twin's hsieh2022 with 1 rep)
    _, tab1, _ = _runs(24, [0.0] + list(np.arange(1.0, 15.0)), 1, sigma, lambda th: np.zeros(th.shape), 101)
    assert sa.reading_repeatability(tab1).dof == 1035
    # a missing reading drops that run-row (and says so)
    keep = ~((cols["shift_deg"] == 0.0) & (cols["start_face"] == 3) & (cols["step"] == 4) & (cols["rep"] == 1)
             & (cols["direction"] == "forward"))
    t2 = sa.tabulate_polygon({k: v[keep] for k, v in cols.items() if k != "theta_deg"}, N)
    r2 = sa.reading_repeatability(t2)
    assert r2.dropped == [(0.0, 1, "forward", 3)] and r2.dof == rep.dof - (N - 1)


def test_direction_difference_separates_theta_dependent_hysteresis_from_noise():
    N, sigma = 12, 0.02
    # constant hysteresis: no θ-dependent difference, the offset shows in U
    _, tab, beta = _runs(N, [0.0, 5.0, 10.0], 2, sigma, lambda th: np.full(th.shape, 0.3), 200)
    s = sa.reading_repeatability(tab).s_arcsec
    res = sa.shift_angle_analysis(tab, s_reading_arcsec=s)
    dd = sa.direction_difference(tab, res.beta_arcsec, s)
    assert dd["directions"] == ["forward", "backward"]
    assert dd["offset_arcsec"] == pytest.approx(0.6, abs=0.01)
    assert dd["p_value"] > 0.001 and dd["rms_systematic"] < 0.01
    np.testing.assert_allclose(res.shifts[0].alpha_arcsec, ALPHA(res.shifts[0].theta_deg), atol=4 * sigma)
    # θ-dependent hysteresis ±0.05·sin(3θ): detected, and its size estimated
    _, tab, beta = _runs(N, [0.0, 5.0, 10.0], 2, sigma, lambda th: 0.05 * np.sin(3 * np.deg2rad(th)), 201)
    s = sa.reading_repeatability(tab).s_arcsec
    assert s == pytest.approx(sigma, rel=0.15)  # α per direction: the hysteresis is not scatter
    res = sa.shift_angle_analysis(tab, s_reading_arcsec=s)
    dd = sa.direction_difference(tab, res.beta_arcsec, s)
    assert dd["p_value"] < 1e-6
    assert dd["rms_systematic"] == pytest.approx(0.1 / np.sqrt(2), rel=0.15)  # Δ = 2·0.05·sin(3θ)
    # one direction only: nothing to compare
    one = sa.tabulate_polygon(dict(zip(sa.POLYGON_COLUMNS, (np.zeros(9), np.repeat(np.arange(1, 4), 3),
                                                            np.tile(np.arange(1, 4), 3), np.arange(9.0)))), 3)
    assert sa.direction_difference(one, np.zeros(3), 0.01) is None


def test_alpha_scatter_over_reps_is_the_papers_repeatability():
    """Hsieh sec. 3.3 (1): sd over the repetitions of the whole method, per θ (here 3 reps)."""
    N, sigma = 12, 0.05
    _, tab, beta = _runs(N, [0.0, 10.0, 20.0], 3, sigma, lambda th: np.zeros(th.shape), 300)
    sc_ = sa.alpha_scatter_by_rep(tab, beta)
    assert sc_["n_reps"] == 3 and sc_["theta_deg"].size == 3 * N
    # one start face at S ≠ 0, both directions averaged: sd of α ≈ σ/√2·√(1 − 1/N)
    other = sc_["sd"][~np.isin(np.round(sc_["theta_deg"] % 30.0, 6), [0.0])]
    assert np.sqrt(np.mean(other**2)) == pytest.approx(sigma / np.sqrt(2) * np.sqrt(1 - 1 / N), rel=0.25)
