"""ISO 230-2:2014 positioning statistics of the rotary axis (issue 34 item 2; analysis/iso230_2.py):
the figures on a small table computed by hand, the flags with too few runs, and the pipeline on an
imported two-direction table and on a polygon table swept in both directions."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchtwin.analysis.dataset import DatasetWriter
from benchtwin.analysis.iso230_2 import positioning_statistics
from benchtwin.analysis.pipeline import analyze
from benchtwin.analysis.results import validate_results
from benchtwin.cli import main

R3 = math.sqrt(3.0)


def test_figures_of_a_hand_computed_table():
    """3 targets, 3 runs per direction. By hand (ISO 230-2:2014 clause 3):
    forward  x: (1, 3, 2) (2, 2, 5) (0, 2, 1) → x̄↑ = 2, 3, 1;  s↑ = 1, √3, 1
    backward x: (0, 2, 1) (1, 1, 1) (−1, −1, 2) → x̄↓ = 1, 1, 0;  s↓ = 1, 0, √3
    B_i = 1, 2, 1 → B = 2, B̄ = 4/3;  x̄ = 1.5, 2, 0.5 → M = 1.5;  E↑ = 2, E↓ = 1, E = 3 − 0 = 3;
    R↑ = R↓ = 4√3;  R_i = max(5, 4, 4), max(2√3 + 2, 4√3, 0), max(2 + 2√3 + 1, 4, 4√3) → R = 4√3;
    A↑ = (3 + 2√3) − (1 − 2) = 4 + 2√3;  A↓ = 2√3 − (−2√3) = 4√3;  A = (3 + 2√3) − (−2√3) = 3 + 4√3."""
    fwd = np.array([[1, 2, 0], [3, 2, 2], [2, 5, 1]], dtype=float)
    bwd = np.array([[0, 1, -1], [2, 1, -1], [1, 1, 2]], dtype=float)
    iso = positioning_statistics([0.0, 120.0, 240.0], fwd, bwd, source="hand")
    f = {k: v["value"] for k, v in iso["figures"].items()}
    want = {"B": 2.0, "B_mean": 4.0 / 3.0, "M": 1.5, "E_forward": 2.0, "E_backward": 1.0, "E": 3.0,
            "R_forward": 4 * R3, "R_backward": 4 * R3, "R": 4 * R3, "A_forward": 4 + 2 * R3, "A_backward": 4 * R3,
            "A": 3 + 4 * R3}
    assert set(f) == set(want)
    for k, v in want.items():
        assert f[k] == pytest.approx(v, abs=1e-12), k
    assert all(v["unit"] == "arcsec" and v["what"] for v in iso["figures"].values())
    assert iso["figures"]["B_mean"]["symbol"] == "B̄"
    np.testing.assert_allclose(iso["per_position"]["reversal_arcsec"], [1, 2, 1])
    np.testing.assert_allclose(iso["per_position"]["R_bidirectional_arcsec"], [5, 4 * R3, 4 * R3])
    # 3 runs per direction: computed, and flagged (ISO asks for 5)
    assert iso["n_runs"] == {"forward": 3, "backward": 3} and not iso["meets_run_count"]
    assert any("asks for 5" in s for s in iso["flags"])


def test_one_run_per_direction_has_no_repeatability():
    iso = positioning_statistics([0.0, 90.0, 180.0, 270.0], [[0.0, 1.0, 2.0, -1.0]], [[0.5, 1.0, 1.0, -2.0]],
                                 source="one run")
    f = {k: v["value"] for k, v in iso["figures"].items()}
    for k in ("R", "R_forward", "R_backward", "A", "A_forward", "A_backward"):
        assert math.isnan(f[k]), k
    assert f["E"] == pytest.approx(4.0) and f["B"] == pytest.approx(1.0) and f["B_mean"] == pytest.approx(1.5 / 4)  # B_i = −0.5, 0, 1, 1
    assert any("no repeatability estimate" in s for s in iso["flags"])
    with pytest.raises(ValueError, match="target positions"):
        positioning_statistics([0.0, 90.0], [[0.0, 1.0, 2.0]], [[0.0, 1.0, 2.0]], source="bad")


def test_imported_two_direction_table(tmp_path):
    th = np.arange(0.0, 360.0, 30.0)
    fwd = np.sin(np.deg2rad(2 * th))
    bwd = fwd - 0.4   # a constant reversal: the backward error 0.4″ lower
    table = tmp_path / "t.csv"
    table.write_text("a,f,b\n" + "".join(f"{a!r},{x!r},{y!r}\n" for a, x, y in
                                        zip(th.tolist(), fwd.tolist(), bwd.tolist())))
    ds, out = tmp_path / "ds", tmp_path / "out"
    assert main(["import", str(table), "-o", str(ds), "--angle", "a", "--error", "f", "--reverse", "b", "--quiet"]) == 0
    assert main(["close-loop", str(ds), "-o", str(out), "--quiet"]) == 0
    res = validate_results(json.loads((out / "results.json").read_text()))
    iso = res["iso230_2"]
    f = {k: v["value"] for k, v in iso["figures"].items()}
    # x = −α: x̄↑ − x̄↓ = −(fwd − bwd) = −0.4 at every target
    assert f["B_mean"] == pytest.approx(-0.4) and f["B"] == pytest.approx(0.4)
    assert f["E_forward"] == pytest.approx(np.ptp(fwd)) and f["E"] == pytest.approx(np.ptp(fwd) + 0.4)
    assert f["R"] is None and f["A"] is None   # one run per direction: null in the file
    assert iso["n_runs"] == {"forward": 1, "backward": 1}
    assert "ISO 230-2" in (out / "report.html").read_text()


N = 8
HYST = 0.3   # the backward encoder error is 0.3″ above the forward one (a constant reversal)


def _alpha(th):
    return 1.2 * np.sin(np.deg2rad(2 * th) + 0.3) + 0.5 * np.cos(np.deg2rad(3 * th))


def _polygon_dataset(root, directions, reps, rng):
    beta = rng.normal(0.0, 1.0, N)
    beta -= beta.mean()
    cum = np.concatenate([[0.0], np.cumsum(np.concatenate([beta, beta]))])
    cols = {k: [] for k in ("shift_deg", "start_face", "step", "theta_deg", "ac_arcsec", "t_s", "rep", "direction")}
    t = 0.0
    for rep in range(reps):
        for j in range(1, N + 1):
            U = rng.normal(0.0, 5.0)   # the clamping's setup constant, common to both directions
            for d in directions:
                for i in (range(1, N + 1) if d == "forward" else range(N, 0, -1)):
                    th = (i - 1) * 360.0 / N
                    a = _alpha(th) + (HYST if d == "backward" else 0.0)
                    eps = a + cum[j - 1 + i] - cum[j - 1] + U + rng.normal(0.0, 0.05)
                    for k, v in zip(cols, (0.0, j, i, th, float(eps), t, rep, d)):
                        cols[k].append(v)
                    t += 1.0
    m = {"format": "bench-dataset", "version": 1, "source": "external",
         "bench": {"optical_radius_mm": 22.0, "L1_mm": 6.81, "L2_mm": 122.96, "grating_period_um": 20.0,
                   "polygon_faces": N}}
    with DatasetWriter(root, m) as w:
        w.write_table("polygon", cols)
    return root


def test_polygon_swept_both_ways(tmp_path):
    """8 faces, 5 repetitions of every start face, each clamping swept forward and backward: 40 runs
    per direction; the deviations are −α (common β and setup constants removed), the reversal the
    constant put in."""
    ds = _polygon_dataset(tmp_path / "ds", ("forward", "backward"), 5, np.random.default_rng(7))
    res = analyze(ds, tmp_path / "out", progress=False, close_loop=False)["results"]
    validate_results(json.loads((tmp_path / "out" / "results.json").read_text()))
    iso = res["iso230_2"]
    assert iso["n_runs"] == {"forward": 40, "backward": 40} and iso["meets_run_count"] and iso["flags"] == []
    th = np.arange(N) * 360.0 / N
    x_true = -(_alpha(th) - _alpha(th).mean() - HYST / 2)   # the circle closes on the mean of both directions
    np.testing.assert_allclose(iso["per_position"]["mean_forward_arcsec"], x_true, atol=0.05)
    f = {k: v["value"] for k, v in iso["figures"].items()}
    # u of a mean of 40 runs ≈ 0.05/√40 per reading (+ β's): well inside these tolerances
    # B_i = x̄↑ − x̄↓ = −α↑ + α↓ = +HYST (the backward encoder error is HYST higher)
    assert f["B_mean"] == pytest.approx(HYST, abs=0.03) and f["B"] == pytest.approx(HYST, abs=0.05)
    assert f["E_forward"] == pytest.approx(np.ptp(_alpha(th)), abs=0.05)
    assert f["E"] == pytest.approx(np.ptp(_alpha(th)) + HYST, abs=0.06)
    # repeatability: 4 s with s ≈ the readings' 0.05″ scatter (a run's deviation carries one reading and 1/16 of
    # its clamping's mean), so R↑ is about 0.2″; R ≥ max(R↑, R↓)
    assert 0.12 < f["R_forward"] < 0.32 and f["R"] >= max(f["R_forward"], f["R_backward"])
    assert f["A"] >= f["E"]
    html = (tmp_path / "out" / "report.html").read_text()
    assert "Positioning statistics of the rotary axis (ISO 230-2:2014)" in html and "40 forward and 40 backward" in html


def test_one_direction_polygon_has_no_iso_section(tmp_path):
    ds = _polygon_dataset(tmp_path / "ds", ("forward",), 2, np.random.default_rng(8))
    res = analyze(ds, tmp_path / "out", progress=False, close_loop=False)["results"]
    assert "iso230_2" not in res
