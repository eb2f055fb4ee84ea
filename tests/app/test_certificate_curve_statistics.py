"""The certificate quotes what results.json has of the ISO 230-2 positioning statistics and of an
arc's periodic components (issue 34 items 2, 3, 7), each with its unit and what its u includes.

Inputs: the imported shared table closed-loop as a lab would (tests/app/conftest.py
``imported_results``: one run per direction, so R and A are not computed) and a lab's partial-arc
table of 12 angles over 60° with a drive's 6° period, imported through the CLI (a table, no twin
simulation; as tests/analysis/test_arc_periods.py).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from lxml import etree

from benchtwin.analysis.distributions import t_ppf
from benchtwin.app.certificate import _k_str, validation_errors, value_and_U, write_certificate
from benchtwin.cli import main

NS = {"dcc": "https://ptb.de/dcc", "si": "https://ptb.de/si"}


def _cert(results, tmp_path) -> etree._ElementTree:
    out = tmp_path / "cert.xml"
    write_certificate(results, out, today="2026-12-05")
    tree = etree.parse(str(out))
    assert validation_errors(tree) == []
    return tree


def _text(el) -> str:
    return " ".join(el.itertext())


def test_iso230_2_figures_runs_flags_and_what_they_exclude(imported_results, tmp_path):
    iso = json.loads(imported_results.read_text(encoding="utf-8"))["iso230_2"]
    cert = _cert(imported_results, tmp_path)
    (r,) = cert.findall(".//dcc:result[@refType='benchtwin_iso230_2']", NS)
    desc = r.findtext("dcc:description/dcc:content", namespaces=NS)
    assert iso["excludes"] in desc and "No uncertainty is stated" in desc
    assert all(f in desc for f in iso["flags"]) and iso["flags"]
    assert "does not meet" in desc and not iso["meets_run_count"]
    computed = 0
    for key, f in iso["figures"].items():
        (q,) = r.findall(f".//dcc:quantity[@refType='benchtwin_iso230_2_{key}']", NS)
        assert q.findtext("dcc:name/dcc:content", namespaces=NS).startswith(f["symbol"] + ": " + f["what"][:20])
        if f["value"] is None:   # one run per direction: R and A have no s to be made of
            assert q.find("dcc:noQuantity", NS) is not None and q.find("si:real", NS) is None
            continue
        assert float(q.findtext("si:real/si:value", namespaces=NS)) == f["value"]
        assert q.findtext("si:real/si:unit", namespaces=NS) == "\\arcsecond"
        assert q.find("si:real/si:expandedUnc", NS) is None   # a statistic, no U claimed
        computed += 1
    assert computed == sum(f["value"] is not None for f in iso["figures"].values()) >= 6
    for d in ("forward", "backward"):
        (q,) = r.findall(f".//dcc:quantity[@refType='benchtwin_runs_{d}']", NS)
        assert float(q.findtext("si:real/si:value", namespaces=NS)) == iso["n_runs"][d]
    (q,) = r.findall(".//dcc:quantity[@refType='benchtwin_meetsRunCount']", NS)
    assert _text(q.find("dcc:noQuantity", NS)).strip() == "false"
    assert cert.find(".//dcc:usedMethod[@refType='benchtwin_iso230_2']", NS) is not None


@pytest.fixture(scope="module")
def arc_results(tmp_path_factory):
    """12 angles over a sixth of a turn with a 6° drive period of 20″, a trend and 0.5″ noise (seed fixed)."""
    base = tmp_path_factory.mktemp("arc_cert")
    rng = np.random.default_rng(20261205)
    th = np.sort(np.concatenate([[0.0, 60.0], rng.uniform(0.0, 60.0, 10)]))
    err = 20.0 * np.sin(2 * np.pi * th / 6.0 + 0.7) + 0.3 * th + rng.normal(0.0, 0.5, th.size)
    table = base / "arc.csv"
    table.write_text("angle_deg,err_arcsec\n" + "".join(f"{a!r},{e!r}\n" for a, e in zip(th.tolist(), err.tolist())))
    assert main(["import", str(table), "-o", str(base / "ds"), "--angle", "angle_deg", "--error", "err_arcsec",
                 "--quiet"]) == 0
    assert main(["close-loop", str(base / "ds"), "-o", str(base / "out"), "--quiet"]) == 0
    return base / "out" / "results.json"


def test_arc_periods_with_u_k_false_alarm_coverage_and_drive_element(arc_results, tmp_path):
    res = json.loads(arc_results.read_text(encoding="utf-8"))
    (p,) = res["arc_periods"]
    cert = _cert(arc_results, tmp_path)
    (r,) = cert.findall(".//dcc:result[@refType='benchtwin_arcPeriods']", NS)
    assert res["arc_period_scan"]["u_source"] in r.findtext("dcc:description/dcc:content", namespaces=NS)
    (lst,) = r.findall("dcc:data/dcc:list[@refType='benchtwin_arcPeriod']", NS)
    assert p["drive_element"]["note"] in lst.findtext("dcc:description/dcc:content", namespaces=NS)
    # u from a fit with ν residual degrees of freedom: k = t_0.975(ν), stated as a t distribution
    k = float(t_ppf(0.975, p["dof"]))
    assert k > 2.2
    for ref, key, ukey, unit in (("benchtwin_period", "period_deg", "u_period_deg", "\\degree"),
                                 ("benchtwin_amplitude", "amplitude_arcsec", "u", "\\arcsecond"),
                                 ("benchtwin_phase", "phase_deg", "u_phase_deg", "\\degree")):
        real = lst.find(f"dcc:quantity[@refType='{ref}']/si:real", NS)
        got = (real.findtext("si:value", namespaces=NS), real.findtext("si:expandedUnc/si:uncertainty", namespaces=NS))
        assert got == value_and_U(p[key], k * p[ukey]), ref
        assert real.findtext("si:unit", namespaces=NS) == unit
        assert real.findtext("si:expandedUnc/si:coverageFactor", namespaces=NS) == _k_str(k)
        assert real.findtext("si:expandedUnc/si:distribution", namespaces=NS) == "t"
    for ref, key in (("benchtwin_falseAlarm", "false_alarm"), ("benchtwin_periodsCovered", "n_periods_covered")):
        v = float(lst.findtext(f"dcc:quantity[@refType='{ref}']/si:real/si:value", namespaces=NS))
        assert math.isclose(v, p[key], rel_tol=1e-12), ref
    assert cert.find(".//dcc:usedMethod[@refType='benchtwin_arcPeriods']", NS) is not None
