"""What a lab's partial-arc table shows (issue 34 item 7; analysis/arc_periods.py): the periods an arc
supports, with u, their false alarm, the periods covered and the drive element; none on pure noise;
the aliases of a regular grid; a declared drive; and no change to a full turn."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchtwin.analysis.arc_periods import ArcInputError, _read_candidates, analyze_arc_periods, fap_baluev
from benchtwin.analysis.results import validate_results
from benchtwin.cli import main

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata" / "sensors2024_24_1400_table6_matrix_encoder_errors.csv"

PERIOD, AMP, NOISE, SLOPE = 6.0, 20.0, 0.5, 0.3   # deg, arcsec, arcsec, arcsec/deg


def _angles(rng):
    """12 angles over 60°: both ends and 10 drawn at random between (a regular grid of 12 points over 60°
    has a 5° step, and a 6° period is then an exact alias of 30°: see test_regular_grid_lists_the_aliases)."""
    return np.sort(np.concatenate([[0.0, 60.0], rng.uniform(0.0, 60.0, 10)]))


def _table(path: Path, th, err, u=None) -> Path:
    rows = [(a, e) if u is None else (a, e, u) for a, e in zip(np.asarray(th).tolist(), np.asarray(err).tolist())]
    head = "angle_deg,err_arcsec" + ("" if u is None else ",u_arcsec")
    path.write_text(head + "\n" + "".join(",".join(repr(float(v)) for v in r) + "\n" for r in rows))
    return path


def _import_and_close(tmp_path, th, err, u=None, manifest_extra=None, capsys=None):
    ds, out = tmp_path / "ds", tmp_path / "out"
    args = ["import", str(_table(tmp_path / "arc.csv", th, err, u)), "-o", str(ds), "--angle", "angle_deg",
            "--error", "err_arcsec", "--quiet"] + ([] if u is None else ["--u", "u_arcsec"])
    assert main(args) == 0
    if manifest_extra:
        m = json.loads((ds / "manifest.json").read_text())
        m.update(manifest_extra)
        (ds / "manifest.json").write_text(json.dumps(m))
    rc = main(["close-loop", str(ds), "-o", str(out), "--json"])
    return rc, out


def test_drive_period_on_a_sixth_of_a_turn(tmp_path, capsys):
    rng = np.random.default_rng(20261205)
    th = _angles(rng)
    err = AMP * np.sin(2 * np.pi * th / PERIOD + 0.7) + SLOPE * th + rng.normal(0.0, NOISE, th.size)
    rc, out = _import_and_close(tmp_path, th, err)
    assert rc == 0
    msg = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["message"]
    res = validate_results(json.loads((out / "results.json").read_text()))
    # still an arc: no turn harmonics, no closure
    assert not res["coverage"]["full_turn"] and res["harmonics"] == [] and res["closure"]["state"] == "not applicable"
    (p,) = res["arc_periods"]
    assert abs(p["period_deg"] - PERIOD) <= 2 * p["u_period_deg"] and 0 < p["u_period_deg"] < 0.05
    assert abs(p["amplitude_arcsec"] - AMP) <= 3 * p["u"] and 0 < p["u"] < 1.0   # u from the residual (no u given)
    assert p["false_alarm"] < 1e-3
    assert p["n_periods_covered"] == pytest.approx(60.0 / PERIOD, rel=0.01)
    # 60° / 6° = a 60-tooth worm wheel (or gear, or 60 pole pitches): the only integer within 2u
    assert p["drive_element"]["source"] == "integer counts per turn" and p["drive_element"]["counts"] == [60]
    assert p["alias_periods_deg"] == []   # irregular angles: no exact alias
    sc = res["arc_period_scan"]   # the trend fitted with the period: the slope put in
    assert abs(sc["trend_slope_arcsec_per_deg"] - SLOPE) <= 3 * sc["u_trend_slope_arcsec_per_deg"]
    assert p["dof"] == 12 - 3 - 3   # quadratic trend, a, b and the period
    # phase of A cos(2πθ/P − φ): sin(x + 0.7) = cos(x − (π/2 − 0.7))
    assert abs((p["phase_deg"] - np.degrees(np.pi / 2 - 0.7) + 180) % 360 - 180) <= 3 * p["u_phase_deg"]
    assert "period 6" in msg and "no closure" in msg
    html = (out / "report.html").read_text()
    assert "Periodic components over the arc" in html and "Baluev" in html


def test_given_u_is_used_absolutely(tmp_path, capsys):
    rng = np.random.default_rng(11)
    th = _angles(rng)
    err = AMP * np.sin(2 * np.pi * th / PERIOD) + rng.normal(0.0, NOISE, th.size)
    rc, out = _import_and_close(tmp_path, th, err, u=NOISE)
    assert rc == 0
    res = json.loads((out / "results.json").read_text())
    (p,) = res["arc_periods"]
    assert res["arc_period_scan"]["u_source"].startswith("given")
    # a stated u of 0.5″ per point over 12 points: u(A) ≈ 0.5·√(2/12) (the trend's columns cost a little)
    assert 0.15 < p["u"] < 0.4
    assert abs(p["period_deg"] - PERIOD) <= 2 * p["u_period_deg"]


def test_pure_noise_gets_no_period():
    """50 arcs of noise and a trend (seeds 1000…1049): a false alarm < 0.01 at most a few times (Baluev's
    bound is conservative), never a period kept (< 1e-3), and the bound not too loose either (its
    median below 0.9)."""
    faps, kept = [], 0
    for seed in range(1000, 1050):
        rng = np.random.default_rng(seed)
        th = _angles(rng)
        y = SLOPE * th + rng.normal(0.0, NOISE, th.size)
        r = analyze_arc_periods(th, y)
        kept += len(r["periods"])
        faps.append(r["scan"]["best_rejected"]["false_alarm"] if not r["periods"] else r["periods"][0]["false_alarm"])
    faps = np.array(faps)
    assert kept == 0
    assert np.sum(faps < 0.01) <= 3
    assert np.median(faps) < 0.9


def test_false_alarm_single_frequency_limit():
    """With a band too narrow to matter (f_max → 0) the bound is the single-frequency probability
    (1 − z)^(N_K/2) of the standard normalisation (a Beta(1, N_K/2) variable; Baluev 2008 Table 1)."""
    th = np.linspace(0.0, 60.0, 12)
    z, n_h = 0.4, 9
    assert fap_baluev(z, 1e-12, th, np.ones(12), n_h) == pytest.approx((1 - z) ** ((n_h - 2) / 2), rel=1e-9)
    assert fap_baluev(0.0, 1.0, th, np.ones(12), n_h) == pytest.approx(1.0)
    assert fap_baluev(0.9, 1.0, th, np.ones(12), n_h) < fap_baluev(0.5, 1.0, th, np.ones(12), n_h)


def test_regular_grid_lists_the_aliases():
    """12 points at a 5° step: the 6° period is an exact alias of 30° (1/5 − 1/6 = 1/30). The scan stops at
    2 steps (10°), finds 30°, and lists 6° among the periods that fit the points equally well."""
    rng = np.random.default_rng(3)
    th = np.arange(12) * 5.0
    y = AMP * np.sin(2 * np.pi * th / PERIOD + 0.7) + SLOPE * th + rng.normal(0.0, NOISE, th.size)
    r = analyze_arc_periods(th, y)
    (p,) = r["periods"]
    assert r["scan"]["regular_grid"] and r["scan"]["period_min_deg"] == pytest.approx(10.0)
    assert abs(p["period_deg"] - 30.0) <= 2 * p["u_period_deg"]
    assert any(abs(a - PERIOD) < 0.05 for a in p["alias_periods_deg"])
    assert "alias" in p["drive_element"]["note"]


def test_declared_drive_elements(tmp_path, capsys):
    rng = np.random.default_rng(5)
    th = _angles(rng)
    err = AMP * np.sin(2 * np.pi * th / PERIOD) + rng.normal(0.0, NOISE, th.size)
    decl = {"drive_elements": [{"name": "worm wheel", "teeth": 60}, {"name": "motor pole pitch", "period_deg": 15.0}]}
    rc, out = _import_and_close(tmp_path, th, err, manifest_extra=decl)
    assert rc == 0
    (p,) = json.loads((out / "results.json").read_text())["arc_periods"]
    de = p["drive_element"]
    assert de["source"].startswith("manifest") and [m["name"] for m in de["matches"]] == ["worm wheel"]
    capsys.readouterr()
    (tmp_path / "bad").mkdir()
    rc, _ = _import_and_close(tmp_path / "bad", th, err, manifest_extra={"drive_elements": [{"name": "worm",
                                                                                            "teeth": 0}]})
    assert rc == 2
    err = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["error"]   # --json: the error on stdout
    assert "manifest.json: key 'drive_elements[0].teeth': expected an integer > 0" in err


@pytest.mark.skipif(not REAL.is_file(), reason="../shared/realdata not beside the clone")
def test_the_shared_full_turn_gets_no_arc_periods(tmp_path):
    ds, out = tmp_path / "ds", tmp_path / "out"
    assert main(["import", str(REAL), "-o", str(ds), "--angle", "angle_deg", "--error", "error_prograde_arcsec",
                 "--reverse", "error_reversal_arcsec", "--quiet"]) == 0
    assert main(["close-loop", str(ds), "-o", str(out), "--quiet"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert "arc_periods" not in res and "arc_period_scan" not in res
    # its full-turn results as docs/real-data.md states them
    k8 = res["harmonics"][7]
    assert round(k8["amplitude_arcsec"], 2) == 2.19 and round(k8["u_arcsec"], 2) == 0.40
    assert [h["k"] for h in res["harmonics"] if h["significant"]] == [8]


_json = st.recursive(st.none() | st.booleans() | st.integers(-5, 400) | st.floats(allow_nan=True) | st.text(max_size=5),
                     lambda c: st.lists(c, max_size=3) | st.dictionaries(st.sampled_from(["name", "teeth", "period_deg",
                                                                                           "x"]), c, max_size=3),
                     max_leaves=8)


@settings(max_examples=100, deadline=None)
@given(decl=_json)
def test_drive_elements_reader_never_crashes(decl):
    """Any JSON value as the manifest's drive_elements: read, or an ArcInputError naming the key."""
    try:
        got = _read_candidates(decl)
    except ArcInputError as exc:
        assert "drive_elements" in str(exc)
        return
    assert all(c["period_deg"] > 0 and c["name"] for c in got)
