"""Imported error curves (issue 16, "real measured curves"): `benchtwin import` → an error-curve
dataset → `analyze` / `close-loop`: coverage, closure, hysteresis, harmonics with u, what a lone
curve cannot separate; the shared real two-direction table (../shared/realdata, Sensors 2024 Table 6)
and a partial arc."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from benchtwin.analysis.error_curve import analyze_error_curve, coverage
from benchtwin.cli import main

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata" / "sensors2024_24_1400_table6_matrix_encoder_errors.csv"


def _csv(path: Path, header: list[str], rows) -> Path:
    path.write_text(",".join(header) + "\n" + "".join(",".join(repr(float(v)) if not isinstance(v, str) else v
                                                               for v in r) + "\n" for r in rows))
    return path


@pytest.mark.skipif(not REAL.is_file(), reason="../shared/realdata not beside the clone")
def test_real_two_direction_table(tmp_path, capsys):
    ds, out = tmp_path / "ds", tmp_path / "out"
    assert main(["import", str(REAL), "-o", str(ds), "--angle", "angle_deg", "--error", "error_prograde_arcsec",
                 "--reverse", "error_reversal_arcsec", "--quiet"]) == 0
    m = json.loads((ds / "manifest.json").read_text())
    assert m["kind"] == "error-curve" and m["source"] == "external"
    assert main(["close-loop", str(ds), "-o", str(out), "--json"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["coverage_deg"] == 360.0 and res["coverage"]["full_turn"]
    # the table is zeroed at 0° in both directions (its README): relative to the start, not closed
    assert res["closure"]["state"].startswith("relative to the start")
    h = res["hysteresis"]
    assert h["available"] and h["n_angles"] == 24 and h["opposite_sign_angles"] == 8  # as the README counts
    assert h["u_mean_arcsec"] > 0 and math.isfinite(h["mean_arcsec"])
    # harmonics with u; 24 angles at 15°: orders 1…10 with 3 residual dof
    assert [x["k"] for x in res["harmonics"]] == list(range(1, 11))
    assert all(x["u_arcsec"] > 0 for x in res["harmonics"])
    # the dominant pattern repeats every 45° (0, 2.5, 3.1, −2.4, …): order 8, the one significant harmonic
    k8 = res["harmonics"][7]
    assert k8["significant"] and k8["amplitude_arcsec"] > 5 * k8["u_arcsec"]
    assert [x["k"] for x in res["harmonics"] if x["significant"]] == [8]
    # a lone curve identifies no cause: the division error is one of a set it cannot separate
    assert res["identified_effects"] == []
    assert any("graduation_error" in a["names"] and 8 in a["harmonics"] for a in res["ambiguous"])
    c = res["encoder_error_corrected_arcsec"]
    assert c["corrections_applied"] == [] and c["value"] == res["encoder_error_arcsec"]["value"]
    assert "<img" in (out / "report.html").read_text()


def test_partial_arc_claims_no_closure_and_no_turn_harmonics(tmp_path):
    th = np.arange(0.0, 121.0, 5.0)
    rng = np.random.default_rng(3)
    err = 0.02 * th + 0.5 * np.sin(np.deg2rad(3 * th)) + rng.normal(0, 0.05, th.size)
    table = _csv(tmp_path / "arc.csv", ["a", "e_urad", "u_urad"], [(a, e / 0.206264806, 0.05 / 0.206264806)
                                                                   for a, e in zip(th, err)])
    ds, out = tmp_path / "ds", tmp_path / "out"
    assert main(["import", str(table), "-o", str(ds), "--angle", "a", "--error", "e_urad", "--u", "u_urad",
                 "--error-unit", "urad", "--quiet"]) == 0
    assert main(["analyze", str(ds), "-o", str(out), "--quiet"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["coverage_deg"] == pytest.approx(120.0)
    assert not res["coverage"]["full_turn"]
    assert res["harmonics"] == [] and res["closure"]["state"] == "not applicable"
    assert res["error_curve"]["status"] == "arc"
    # the trend over the arc, in arcsec (converted from µrad)
    assert res["error_curve"]["trend"]["slope_arcsec_per_deg"] == pytest.approx(0.02, abs=0.01)


def test_full_turn_harmonic_and_constant_hysteresis_recovered():
    th = np.arange(0.0, 360.0, 10.0)
    rng = np.random.default_rng(11)
    g = 1.0 * np.sin(np.deg2rad(3 * th) + 0.4)
    fwd = g + 0.3 + rng.normal(0, 0.05, th.size)
    bwd = g - 0.3 + rng.normal(0, 0.05, th.size)
    r = analyze_error_curve(np.concatenate([th, th]), np.concatenate([fwd, bwd]),
                            ["forward"] * th.size + ["backward"] * th.size, 0.05)
    h3 = r["harmonics"][2]
    assert h3["significant"] and abs(h3["amplitude_arcsec"] - 1.0) < 4 * h3["u_arcsec"]
    assert [x["k"] for x in r["harmonics"] if x["significant"]] == [3]
    hy = r["hysteresis"]
    assert hy["significant"] and abs(hy["mean_arcsec"] - 0.3) < 4 * hy["u_mean_arcsec"]
    assert hy["p_constant"] > 1e-3  # a constant hysteresis: nothing direction-dependent left
    assert not r["unexplained"] and r["status"] == "ambiguous"
    assert {"torsion_hysteresis"} <= set(sum((a["names"] for a in r["ambiguous"]), []))
    # a null curve within its u: nothing to say
    n = analyze_error_curve(th, rng.normal(0, 0.05, th.size), None, 0.05)
    assert n["status"] == "no_significant_residual" and not n["ambiguous"]


def test_coverage_of_grids():
    assert coverage(np.arange(0, 360, 15))["full_turn"]
    assert coverage(np.delete(np.arange(0, 360, 15), 5))["full_turn"]  # one missing point: still a turn
    c = coverage(np.arange(30, 200, 10))
    assert not c["full_turn"] and c["coverage_deg"] == pytest.approx(160.0)
    assert c["start_deg"] == 30.0 and c["end_deg"] == 190.0


@pytest.mark.parametrize("rows, cols, needle", [
    ([(0, 1.0), (10, "x"), (20, 0.5)], ["a", "e"], "row 3, column 'e': expected a number"),
    ([(0, 1.0), (10, ""), (20, 0.5)], ["a", "e"], "row 3, column 'e': empty cell"),
    ([(0, 1.0), (360, 0.2), (20, 0.5)], ["a", "e"], "rows 2 and 3, column 'a': the same angle twice"),
    ([(0, 1.0), (10, 0.2), (20, 0.5)], ["a", "err"], "no column 'e'"),
])
def test_bad_tables_exit_2_naming_row_and_column(tmp_path, capsys, rows, cols, needle):
    p = tmp_path / "t.csv"
    p.write_text(",".join(cols) + "\n" + "".join(",".join(str(v) for v in r) + "\n" for r in rows))
    assert main(["import", str(p), "-o", str(tmp_path / "ds"), "--angle", "a", "--error", "e"]) == 2
    err = capsys.readouterr().err
    assert needle in err and str(p) in err
    assert not (tmp_path / "ds" / "manifest.json").exists()  # nothing half-written taken as complete
