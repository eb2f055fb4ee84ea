"""Hsieh 2022 end to end (benchtwin.analysis.hsieh_pipeline.analyze_polygon): the data budget, the
comparison of the shift-angle method with self-calibration, and the twin's hsieh2022 dataset (issue 6).

Synthetic readings come from eq. 3 (tests.synthetic.polygon.synthesize_readings) and eq. 8; the twin tests
simulate the hsieh2022 scenario (small CCD images, few radial stops) and compare with its truth/.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from benchtwin.analysis import selfcal as sc
from benchtwin.analysis import shift_angle as sa
from benchtwin.analysis.hsieh_pipeline import HSIEH2022_TYPE_B, HeadsData, PolygonOptions, _drop_harmonics, analyze_polygon
from tests.synthetic.polygon import synthesize_readings

ROOT = Path(__file__).resolve().parents[2]


def series(harm):
    def a(th):
        t = np.deg2rad(np.asarray(th, dtype=float))
        return sum(A * np.sin(k * t + ph) for k, (A, ph) in harm.items())

    return a


def make_beta(N, seed):
    b = np.random.default_rng(seed).normal(0.0, 0.8, N)
    return b - b.mean()


def setup_fn(seed):
    rng = np.random.default_rng(seed)
    table = {}

    def U(S, j):
        return table.setdefault((round(float(S), 9), int(j)), float(rng.normal(0.0, 2.0)))

    return U


def fwd_bwd(cols, sigma, rng, h=0.0):
    """Both directions of every sweep (a constant hysteresis ±h), independent noise."""
    n = cols["ac_arcsec"].size
    out = {k: np.concatenate([v, v]) for k, v in cols.items()}
    out["direction"] = np.array(["forward"] * n + ["backward"] * n, dtype=object)
    out["ac_arcsec"] = out["ac_arcsec"] + np.r_[np.full(n, h), np.full(n, -h)] + rng.normal(0.0, sigma, 2 * n)
    return out


def heads_columns(alpha, theta, heads_deg, sigma, rng, n_rep=2):
    d0 = sc.head_deltas_arcsec(alpha, theta, heads_deg)
    th, hd, dl, rp = [], [], [], []
    for r in range(n_rep):
        dn = d0 + (rng.normal(0.0, sigma, d0.shape) if sigma else 0.0)
        for j in range(1, len(heads_deg)):
            th.append(theta)
            hd.append(np.full(theta.size, j + 1))
            dl.append(dn[:, j])
            rp.append(np.full(theta.size, r))
    return {"theta_deg": np.concatenate(th), "head": np.concatenate(hd), "delta_arcsec": np.concatenate(dl),
            "rep": np.concatenate(rp)}


ALPHA = series({1: (0.3, 0.2), 2: (1.0314, -2.4233), 3: (0.4, 1.0), 7: (0.2, 0.5), 11: (0.05, -1.0)})


# --------------------------------------------------------------------------- the budget from data


@pytest.fixture(scope="module")
def fb_result():
    """The twin's procedure with one run: all faces at S = 0, face 1 at 1…14°, forward and backward."""
    rng = np.random.default_rng(7)
    cols = synthesize_readings(ALPHA, make_beta(24, 8), setup_fn(9), np.arange(15.0))
    return analyze_polygon(fwd_bwd(cols, 0.05, rng, h=0.2), 24, type_b=replace(HSIEH2022_TYPE_B, encoder_resolution_arcsec=0.04))


def test_budget_dof_from_the_model_residuals_not_from_direction_pairs(fb_result):
    """Before: forward/backward pairs as repetitions, ν = 1, k = 12.7. Now ν of the repeatability is the
    model's residual dof (1035 here) and the budget's ν_eff and k are those of a well-determined u."""
    r = fb_result
    rep = r["repeatability"]
    assert rep["dof"] == 1035
    assert rep["s_reading_arcsec"] == pytest.approx(0.05, rel=0.1)  # ±h is not scatter
    rows = {row["name"]: row for row in r["budget"]}
    assert rows["Repeatability of angle error measurement"]["dof"] == 1035
    # one start face, both directions averaged: u(α) ≈ s/√2·√(1 − 1/N)
    assert rows["Repeatability of angle error measurement"]["u"] == pytest.approx(
        rep["s_reading_arcsec"] / math.sqrt(2) * math.sqrt(23 / 24), rel=0.02)
    assert "Direction difference (forward − backward)" in rows
    bs = r["budget_summary"]
    assert bs["nu_eff"] > 50 and 1.96 < bs["k"] < 2.01
    assert bs["U"] == pytest.approx(bs["k"] * bs["u_c"])
    assert r["direction_difference"]["offset_arcsec"] == pytest.approx(0.4, abs=0.02)
    # per-point expanded uncertainty: k·√(u_propagated² + type B²)
    e = r["encoder_error_arcsec"]
    np.testing.assert_allclose(e["U"], bs["k"] * np.sqrt(np.array(e["u_propagated"]) ** 2 + bs["u_type_b"] ** 2))


def test_monte_carlo_check_of_the_data_budget(fb_result):
    """GUM-S1: the budget's inputs drawn from their distributions (t for type A, rectangular for type B)
    give the GUM's u_c and, at one significant digit, its 95 % interval ±U."""
    mc = fb_result["budget_summary"]["monte_carlo"]
    bs = fb_result["budget_summary"]
    assert mc["n"] == 100_000
    assert mc["std"] == pytest.approx(bs["u_c"], rel=0.02)
    assert mc["validated_1_digit"]
    assert abs(mc["shortest"][1] - bs["U"]) < 0.05 * bs["U"] and abs(mc["shortest"][0] + bs["U"]) < 0.05 * bs["U"]


def test_results_keys_have_values_and_uncertainties():
    rng = np.random.default_rng(11)
    cols = synthesize_readings(ALPHA, make_beta(24, 12), setup_fn(13), np.arange(15.0), n_rep=2,
                                  noise_arcsec=0.02, rng=rng)
    heads = heads_columns(ALPHA, np.arange(360.0), sc.SELFA_HEADS_DEG, 0.01, rng)
    r = analyze_polygon(cols, 24, HeadsData(heads, sc.SELFA_HEADS_DEG),
                        type_b=replace(HSIEH2022_TYPE_B, encoder_resolution_arcsec=0.04))
    json.dumps(r, allow_nan=False)
    assert len(r["polygon_pitch_deviation_arcsec"]) == 24
    assert all(u > 0 for u in r["polygon_pitch_deviation_u_arcsec"])
    assert set(r["setup_error_arcsec"]) == {f"{s:g}" for s in range(15)}
    assert len(r["setup_error_arcsec"]["0"]) == 24 and len(r["setup_error_arcsec"]["7"]) == 1
    for key in ("encoder_error_arcsec", "selfcal_error_arcsec"):
        e = r[key]
        assert len(e["theta_deg"]) == len(e["value"]) == len(e["u"]) == 360
        assert min(e["u"]) > 0
    # the self-cal sets are found from the heads (SelfA: 3, 4 and 7), the 7-set is off the 1° grid
    assert r["selfcal"]["sets"] == sc.SELFA_SETS
    assert r["selfcal"]["set_on_grid"] == {"NH3": True, "NH4": True, "NH7": False}
    assert r["en_max"] < 1.0 and r["difference_arcsec"]["max_abs"] < 0.1


def test_comparison_on_the_harmonics_both_methods_see():
    """α with harmonics 24 (lost by the shift-angle method into U, eq. 2) and 84 (no SelfA set sees it):
    each method lacks one, so they differ by both unless the comparison drops both — which it does."""
    a = series({2: (1.0, 0.3), 5: (0.2, 0.1), 24: (0.3, 0.7), 84: (0.2, -0.4)})
    cols = synthesize_readings(a, make_beta(24, 14), setup_fn(15), np.arange(15.0))
    heads = heads_columns(a, np.arange(360.0), sc.SELFA_HEADS_DEG, 0.0, None, n_rep=1)
    r = analyze_polygon(cols, 24, HeadsData(heads, sc.SELFA_HEADS_DEG), options=PolygonOptions(u_eps_arcsec=0.01))
    d = r["difference_arcsec"]
    assert d["max_abs"] < 1e-9
    assert d["removed_from_shift_angle_rms"] == pytest.approx(0.2 / math.sqrt(2), rel=1e-6)  # the 84th
    assert r["selfcal"]["unobservable_harmonics"] == [84, 168]
    # and the disagreement shows when the harmonics the two see differ
    heads_other = heads_columns(series({2: (1.1, 0.3), 5: (0.2, 0.1)}), np.arange(360.0), sc.SELFA_HEADS_DEG, 0.0,
                                None, n_rep=1)
    r2 = analyze_polygon(cols, 24, HeadsData(heads_other, sc.SELFA_HEADS_DEG), options=PolygonOptions(u_eps_arcsec=0.01))
    assert r2["en_max"] > 1.0


def test_polygon_errors_name_the_rows():
    """Missing or duplicated readings, a wrong face count, a start face outside 1…N (analysis level)."""
    cols = synthesize_readings(ALPHA, make_beta(8, 16), setup_fn(17), [0.0, 10.0])
    with pytest.raises(sa.PolygonDataError, match=r"row 3, column 'start_face': expected an integer in 1…8"):
        bad = {k: v.copy() for k, v in cols.items()}
        bad["start_face"][3] = 9
        analyze_polygon(bad, 8)
    with pytest.raises(sa.PolygonDataError, match=r"rows 0 and 72.*duplicated reading"):
        analyze_polygon({k: np.concatenate([v, v[:1]]) for k, v in cols.items()}, 8)
    with pytest.raises(sa.PolygonDataError, match=r"missing readings \(start_face=1, step=2\)"):
        analyze_polygon({k: np.delete(v, 1) for k, v in cols.items()}, 8)
    with pytest.raises(sa.PolygonDataError, match="wrong face count"):
        analyze_polygon(cols, 9)


# --------------------------------------------------------------------------- the twin's hsieh2022 dataset
# Slow: simulate() writes the truth α of 12 heads on a 0.1° grid (3600 posings), ~25 s even for a small run.


def _truth_alpha(ds_path, theta):
    with open(ds_path / "truth" / "encoder_error.csv") as f:
        rows = list(csv.DictReader(f))
    tth = np.array([float(r["theta_deg"]) for r in rows])
    ta = np.array([float(r["alpha_arcsec"]) for r in rows])
    i = np.searchsorted(tth, np.round(np.mod(theta, 360.0), 9))
    assert np.allclose(tth[i], theta)
    return ta[i] - ta[i].mean()  # Σα = 0 (eq. 2): the mean of α is not measurable


def _truth_beta(ds_path):
    with open(ds_path / "truth" / "polygon_beta.csv") as f:
        return np.array([float(r["beta_arcsec"]) for r in csv.DictReader(f)])


def _analyze_twin(ds_path):
    from benchtwin.analysis.dataset import open_dataset

    ds = open_dataset(ds_path)
    b = ds.bench
    return analyze_polygon(ds.table("polygon"), b["polygon_faces"], HeadsData(ds.table("heads"), b["heads_deg"]),
                           type_b=replace(HSIEH2022_TYPE_B, encoder_resolution_arcsec=b["encoder_resolution_arcsec"]))


def _simulate(tmp_path_factory, name, **over):
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import simulate

    small = {"procedure.radial_positions": 8, "procedure.ccd_step": "90 deg", "instruments.ccd.width": "128 px",
             "instruments.ccd.height": "96 px"}
    sc_ = load_scenario(ROOT / "scenarios" / "hsieh2022.toml").with_overrides({**small, **over})
    return simulate(sc_, tmp_path_factory.mktemp(name) / "ds", progress=False, backend="analytic")


def _against_truth(ds_path, r):
    """RMS / max of β − truth and of each method − truth on the harmonics both see (truth on the 1° grid)."""
    N = r["n_faces"]
    e = r["encoder_error_arcsec"]
    th = np.array(e["theta_deg"])
    T = _truth_alpha(ds_path, th)
    d = r["difference_arcsec"]
    nyq = th.size // 2
    drop = sorted(set(range(N, nyq + 1, N)) | set(r["selfcal"]["unobservable_harmonics"]))
    Tc = _drop_harmonics(th, T, drop)
    T_sa = _drop_harmonics(th, T, range(N, nyq + 1, N))
    a_sa = _drop_harmonics(th, np.array(e["value"]), range(N, nyq + 1, N))
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
    return {"beta_rms": rms(np.array(r["polygon_pitch_deviation_arcsec"]) - _truth_beta(ds_path)),
            "alpha_rms": rms(a_sa - T_sa), "truth_lost_rms": rms(T - T_sa),
            "sa_err": np.array(d["shift_angle_compared"]) - Tc, "sc_err": np.array(d["selfcal_at_theta"]) - Tc}


@pytest.fixture(scope="module")
def twin_noise_off(tmp_path_factory):
    # shifts 0, 5, 10° and a 5° self-calibration step: 72 points on a 5° grid (cheaper than the 1° grid)
    ds = _simulate(tmp_path_factory, "h22_off", **{"instruments.encoder.noise": "0 arcsec",
                                                   "instruments.autocollimator.noise": "0 arcsec",
                                                   "procedure.polygon_reps": 1,
                                                   "procedure.polygon_shifts": ["0 deg", "5 deg", "10 deg"],
                                                   "procedure.selfcal_step": "5 deg"})
    return ds, _analyze_twin(ds)


@pytest.mark.slow
def test_twin_noise_off_beta_and_alpha_within_0p01_of_truth(twin_noise_off):
    """Issue 6: β and α within 0.01″ RMS of the twin's truth with the noise off (the AC still quantises
    to 0.001″ and has its accuracy curve; the encoder quantises δ to 0.04″). α is compared on what the
    method can see: its harmonics that are multiples of N = 24 go into the setup errors (eq. 2) — the
    twin's graduation error holds 0.03″ rms there, which no polygon of 24 faces can measure."""
    ds, r = twin_noise_off
    t = _against_truth(ds, r)
    assert t["beta_rms"] < 0.01
    assert t["alpha_rms"] < 0.01
    assert t["truth_lost_rms"] > 0.01  # the twin's α does hold what the method cannot see
    # self-calibration: the set averages cancel the axis' radial motion; left is the 7-set's folding
    assert np.sqrt(np.mean(t["sc_err"] ** 2)) < 0.015
    U_sc = np.array(r["selfcal_error_arcsec"]["U"])
    assert np.max(np.abs(t["sc_err"])) < np.min(U_sc)
    # the two methods agree far inside ±0.1″ and E_n < 1
    assert r["difference_arcsec"]["max_abs"] < 0.05 and r["en_max"] < 0.5


@pytest.mark.slow
def test_twin_paper_noise_agreement_and_budget(tmp_path_factory):
    """The hsieh2022 scenario as it stands (six runs, the paper's repeatability): issue 6's comparison.

    What holds at every seed tried (see docs/benchmarks.md): β and α agree with the truth within their
    u; the pooled budget has ν_eff of hundreds and k ≈ 1.97; with the paper's own repeatability (the
    largest sd over the six runs) the budget reproduces Table 3 (ν_eff ≈ 10, k ≈ 2.2, U ≈ 0.15″) and
    E_n < 1 everywhere, as the paper found (0.69). With the pooled u, the shift-angle α at a single
    start face has σ ≈ 0.03″ and its largest excursion over ~330 points is ≈ 3σ ≈ 0.1″: the largest
    per-point E_n is ≈ 1 (0.99…1.22 over four seeds) while at most a few points in a thousand exceed 1,
    which is what a per-point 95 % criterion predicts — the largest difference is noise, not a bias."""
    ds = _simulate(tmp_path_factory, "h22_paper")
    r = _analyze_twin(ds)
    t = _against_truth(ds, r)
    u_b = np.array(r["polygon_pitch_deviation_u_arcsec"])
    assert t["beta_rms"] < 2.0 * np.sqrt(np.mean(u_b**2))
    u_sa = np.array(r["encoder_error_arcsec"]["u_propagated"])
    # the truth is run 0's α; the mean of six runs differs from it by the axis' async motion too
    assert np.sqrt(np.mean(t["sa_err"] ** 2)) < 1.3 * np.sqrt(np.mean(u_sa**2))
    U_sc = np.array(r["selfcal_error_arcsec"]["U"])
    assert np.mean(np.abs(t["sc_err"]) < np.interp(np.array(r["difference_arcsec"]["theta_deg"]),
                                                    r["selfcal_error_arcsec"]["theta_deg"], U_sc)) > 0.95
    assert np.sqrt(np.mean(t["sc_err"] ** 2)) < 0.02
    bs = r["budget_summary"]
    assert bs["nu_eff"] > 100 and 1.96 < bs["k"] < 2.0 and bs["monte_carlo"]["validated_1_digit"]
    assert 0.12 < r["repeatability"]["alpha_sd_over_reps_max_arcsec"] < 0.16  # the paper: 0.13″
    bp = r["budget_paper_repeatability"]
    assert 7 < bp["nu_eff"] < 20 and 2.08 < bp["k"] < 2.4 and 0.12 < bp["U"] < 0.18
    assert r["en_max_paper_budget"] < 1.0
    d = r["difference_arcsec"]
    assert d["fraction_en_above_1"] < 0.02
    assert np.sqrt(np.mean(np.square(d["value"]))) < 0.05 and d["max_abs"] < 0.15
    assert r["direction_difference"]["p_value"] > 1e-3  # the hsieh2022 bench has no friction


def test_selfcal_type_a_from_the_runs_holds_what_the_heads_share():
    """An error all heads share at one instant — the axis' motion m_1 − m_j in every δ_j, different in
    each run — is correlated across heads; propagating s(δ) as independent readings misses it. The
    scatter of the runs' own eq. 9 estimates holds it: u_A ≈ σ_m/√R where σ_m is the per-run error
    of â (here head 1's share of the motion, white in θ), and the curve states the harmonics no set sees."""
    rng = np.random.default_rng(21)
    th = np.arange(0.0, 360.0, 2.0)
    heads_deg = [0.0, 120.0, 240.0]
    cols = synthesize_readings(ALPHA, make_beta(24, 22), setup_fn(23), np.arange(15.0), n_rep=2,
                               noise_arcsec=0.02, rng=rng)
    R, sig_m = 4, 0.05
    psi = np.deg2rad(heads_deg)
    thc, hd, dl, rp = [], [], [], []
    for r_ in range(R):
        dx, dy = rng.normal(0.0, sig_m, th.size), rng.normal(0.0, sig_m, th.size)  # translation / radius, ″
        a = np.column_stack([ALPHA(np.mod(th - p, 360.0)) - (dx * math.cos(q) + dy * math.sin(q))
                             for p, q in zip(heads_deg, psi)])
        d = a[:, :1] - a
        for j in (1, 2):
            thc.append(th), hd.append(np.full(th.size, j + 1)), dl.append(d[:, j]), rp.append(np.full(th.size, r_))
    heads = {"theta_deg": np.concatenate(thc), "head": np.concatenate(hd), "delta_arcsec": np.concatenate(dl),
             "rep": np.concatenate(rp)}
    r = analyze_polygon(cols, 24, HeadsData(heads, heads_deg), type_b=replace(HSIEH2022_TYPE_B, encoder_resolution_arcsec=0.0))
    parts = r["selfcal"]["u_parts"]
    assert parts["n_runs"] == R and "runs" in parts["type_a_source"]
    # â of one run errs by m_1 = −d_x (head 1 at ψ = 0) minus its multiples of 3: σ_m·√(2/3)
    assert parts["u_runs_arcsec"] == pytest.approx(sig_m * math.sqrt(2 / 3) / math.sqrt(R), rel=0.15)
    # the propagation of s(δ) as independent readings: var(δ_j) = 3σ_m², (δ_2 + δ_3)/3 → (2/3)σ_m², of
    # which 2/3 seen: σ_m·2/3 per run, short by √(2/3) (δ_2 and δ_3 share m_1: correlation +1/2)
    assert parts["u_propagated_max_arcsec"] == pytest.approx(sig_m * 2 / 3 / math.sqrt(R), rel=0.15)
    assert parts["u_propagated_max_arcsec"] < 0.9 * parts["u_runs_arcsec"]
    assert r["selfcal_error_arcsec"]["unobservable_harmonics"] == list(range(3, 90, 3)) + [90]  # + Nyquist
    np.testing.assert_allclose(r["selfcal_error_arcsec"]["u"], parts["u_runs_arcsec"], rtol=1e-12)


def test_comparison_off_a_grid_removes_the_heads_blind_orders_from_both_sides():
    """null_b's design: 23 faces at shifts 0/5/10° (θ not an equally spaced grid) and 3 heads at 120°
    (blind to the multiples of 3). α's 6th harmonic (a 12-ball bearing's axis motion at head 1) is in
    the shift-angle α and not in the self-calibration: before, the difference kept it (E_n 1.9 on the
    twin's null_b). Now the blind orders are fitted at the θ and removed from both sides; a real
    disagreement in an order both see still fails."""
    N, heads_deg = 23, [0.0, 120.0, 240.0]
    shifts = np.array([0.0, 5.0, 10.0])
    a = series({1: (0.5, 0.3), 2: (0.8, 0.1), 6: (0.6, 0.7), 9: (0.3, -0.2)})
    cols = synthesize_readings(a, make_beta(N, 31), setup_fn(32), shifts)
    th = np.arange(0.0, 360.0, 2.0)
    heads = heads_columns(a, th, heads_deg, 0.0, None, n_rep=1)
    opts = PolygonOptions(u_eps_arcsec=0.01)
    tb = replace(HSIEH2022_TYPE_B, encoder_resolution_arcsec=0.04)  # one run, one set: u(δ) from the quantization
    r = analyze_polygon(cols, N, HeadsData(heads, heads_deg), type_b=tb, options=opts)
    assert "orders [3, 6, 9" in r["difference_arcsec"]["note"]
    assert r["difference_arcsec"]["max_abs"] < 0.02 and r["en_max"] < 0.5
    heads_other = heads_columns(series({1: (0.5, 0.3), 2: (1.0, 0.1)}), th, heads_deg, 0.0, None, n_rep=1)
    r2 = analyze_polygon(cols, N, HeadsData(heads_other, heads_deg), type_b=tb, options=opts)
    assert r2["en_max"] > 1.0
