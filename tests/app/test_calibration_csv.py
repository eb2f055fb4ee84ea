"""calibration.csv and compensation.csv beside results.json, and the report that opens with them
(issue 34 item 1): U ≥ k·u on every row as written, the numbers those of results.json, what u
includes and excludes in the header; an imported table's k from its type A degrees of freedom.

The runs are the session's certified runs (tests/conftest.py: jia_results, a close-loop of a small
jia2019 simulation) and the imported Sensors table (tests/app/conftest.py: imported_results)."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from benchtwin.analysis.calibration import (CALIBRATION_COLUMNS, COMPENSATION_COLUMNS, calibration_csv,
                                            calibration_curve, compensation_csv)
from benchtwin.analysis.distributions import t_ppf


def _read(path: Path) -> tuple[str, list[str], list[list[str]]]:
    """(the '#' header as one text, the column names, the rows as strings)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    head = "\n".join(ln[2:] for ln in lines if ln.startswith("#"))
    body = [ln for ln in lines if ln and not ln.startswith("#")]
    return head, body[0].split(","), [ln.split(",") for ln in body[1:]]


def _check_U_at_least_k_u(rows: list[list[str]]) -> None:
    for r in rows:
        u, U, k = float(r[2]), float(r[3]), float(r[4])
        assert u > 0 and k >= 1
        assert U >= k * u, f"row {r}: U = {U} < k·u = {k * u}"


def test_close_loop_calibration_csv_states_U_at_least_k_u(jia_results):
    res = json.loads(jia_results.read_text(encoding="utf-8"))
    head, cols, rows = _read(jia_results.parent / "calibration.csv")
    assert tuple(cols) == CALIBRATION_COLUMNS
    _check_U_at_least_k_u(rows)
    key = re.search(r"results\.json: (\w+)\)", head).group(1)
    curve = res[key]
    assert len(rows) == len(curve["theta_deg"]) > 0
    k_budget = res["budget_summary"]["k"]
    for r, th, v, u, U in zip(rows, curve["theta_deg"], curve["value"], curve["u"], curve.get("U") or curve["u"]):
        assert abs(float(r[0]) - th) <= 5e-7 and abs(float(r[1]) - v) <= 5e-5
        assert 0 <= float(r[2]) - u <= 1e-4 + 1e-12          # u rounded up, never down
        assert 0 <= float(r[4]) - k_budget <= 1e-3 + 1e-12   # the budget's k, rounded up
        if key == "encoder_error_arcsec":
            assert float(r[3]) >= U                           # never below results.json's U
    # what u includes: the budget's own rows; what it excludes; where k comes from
    for row in res["budget"]:
        if row["kind"] == "member" and row["contribution"] >= 5e-4 and not row["name"].startswith("Repeatability"):
            assert row["name"].lower() in head
    assert "It does not include:" in head and "between the calibrated angles" in head
    assert f"ν_eff = {math.floor(res['budget_summary']['nu_eff'])}" in head and "t distribution" in head


def test_compensation_is_minus_the_error_with_sign_and_interpolation_stated(jia_results):
    _, _, cal = _read(jia_results.parent / "calibration.csv")
    head, cols, comp = _read(jia_results.parent / "compensation.csv")
    assert tuple(cols) == COMPENSATION_COLUMNS
    assert [r[0] for r in comp] == [r[0] for r in cal]
    for c, r in zip(comp, cal):
        assert float(c[1]) == -float(r[1]) and c[2] == r[3]
    assert "reference angle = reading + correction_arcsec / 3600" in head
    assert "interpolate linearly" in head and "periodic over 360 deg" in head


def test_report_opens_with_the_calibration_result(jia_results):
    html = (jia_results.parent / "report.html").read_text(encoding="utf-8")
    h2 = re.findall(r"<h2>(.*?)</h2>", html)
    assert h2[0].startswith("Calibration result")
    _, _, rows = _read(jia_results.parent / "calibration.csv")
    section = html[html.index(h2[0]):html.index(f"<h2>{h2[1]}</h2>")]
    assert "± U" in section and "<th>ν</th>" in section and "do not include" in section
    for r in rows:  # the table shows the numbers of calibration.csv
        assert f"<td>{r[0]}</td><td>{r[1]}</td><td>{r[2]}</td><td>{r[3]}</td><td>{r[4]}</td>" in section


def test_imported_table_calibration_csv_says_what_its_U_includes(imported_results):
    res = json.loads(imported_results.read_text(encoding="utf-8"))
    head, cols, rows = _read(imported_results.parent / "calibration.csv")
    assert tuple(cols) == CALIBRATION_COLUMNS and len(rows) == 24
    _check_U_at_least_k_u(rows)
    # k from the t-distribution at the type A u's 23 degrees of freedom, not k = 2
    nu = res["u_point"]["dof"]
    assert nu == 23
    k = float(t_ppf(0.975, nu))
    assert all(0 <= float(r[4]) - k <= 1e-3 for r in rows)
    assert "imported measured error curve" in head and "reference" in head and "unknown" in head
    assert "both directions share" in head
    # the values as imported (not re-centred), and the constant said so
    assert [float(r[1]) for r in rows] == pytest.approx(res["encoder_error_arcsec"]["value"], abs=5e-5)
    assert "not removed" in head and "0.971" in head
    # the k = 8 ambiguity the analysis reported is among what U does not cover
    assert "harmonic order 8" in head
    assert (imported_results.parent / "compensation.csv").is_file()


def test_imported_table_analyze_writes_the_files_too(imported_results, tmp_path):
    """analyze (the loop not closed) writes them as well, through the command's output folder."""
    from benchtwin.cli import main

    ds = Path(json.loads(imported_results.read_text(encoding="utf-8"))["dataset"])
    assert main(["analyze", str(ds), "-o", str(tmp_path / "a"), "--quiet"]) == 0
    _, cols, rows = _read(tmp_path / "a" / "calibration.csv")
    assert tuple(cols) == CALIBRATION_COLUMNS and len(rows) == 24
    assert (tmp_path / "a" / "compensation.csv").is_file()
    assert not list(tmp_path.glob(".*"))  # nothing half-written beside it


@pytest.mark.parametrize("k", [1.5, 1.9693105698498752, 2.0, 2.0686576104190406])
def test_rounding_never_breaks_U_at_least_k_u(k, tmp_path):
    """u and k rounded up, U from them rounded up: the written numbers keep U ≥ k·u even where the
    exact product lands on a rounding boundary; a results.json U below k·u is lifted to k·u."""
    us = [0.2, 0.24075832401658637, 1 / 3, 0.1, 0.30000000000000004, 1.3722337127176407, 1e-4]
    n = len(us)
    res = {"encoder_error_arcsec": {"theta_deg": [360.0 * i / n for i in range(n)], "value": [0.5] * n, "u": us,
                                    "U": [0.9 * k * u for u in us]},
           "budget_summary": {"k": k, "nu_eff": 40.0, "p": 0.95}}
    c = calibration_curve(res)
    assert all(U >= k * u for U, u in zip(c.U_arcsec, c.u_arcsec))
    p = tmp_path / "calibration.csv"
    p.write_text(calibration_csv(c), encoding="utf-8")
    _, _, rows = _read(p)
    _check_U_at_least_k_u(rows)
    comp = tmp_path / "compensation.csv"
    comp.write_text(compensation_csv(c), encoding="utf-8")
    assert [r[1] for r in _read(comp)[2]] == ["-0.5000"] * n
