"""Certificates that state only what happened (issue 34 item 3): methods and reference from what the
analysis ran, an imported table declared as such with its reference unknown, each U saying what it
includes and excludes, the DCC's basic_* refTypes, a distribution that matches k, and the page for
people (--html) with every string escaped. Validated offline against the shared DCC schemas.

Inputs: the session's certified runs (tests/conftest.py) and the imported Sensors table
(tests/app/conftest.py); no simulation of their own."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from benchtwin.app.certificate import validation_errors
from benchtwin.cli import main

ROOT = Path(__file__).resolve().parents[2]
SHARED_DCC = ROOT.parent / "shared" / "dcc"
LAB = ROOT / "docs" / "lab.example.toml"
NS = {"dcc": "https://ptb.de/dcc", "si": "https://ptb.de/si"}


def _shared_dcc() -> Path:
    if not (SHARED_DCC / "dcc.xsd").is_file():
        pytest.skip("../shared/dcc (the reference schemas) is not beside this checkout")
    return SHARED_DCC


def _certify(results: Path, out: Path, *extra: str) -> etree._ElementTree:
    assert main(["certificate", str(results), "-o", str(out), "--quiet", *extra]) == 0
    tree = etree.parse(str(out))
    assert validation_errors(tree, _shared_dcc()) == []
    return tree


def _by_reftype(tree: etree._ElementTree, ref: str) -> list[etree._Element]:
    return [q for q in tree.iterfind(".//dcc:quantity", NS) if ref in (q.get("refType") or "").split()]


def _floats(el: etree._Element, path: str) -> np.ndarray:
    return np.array([float(x) for x in el.find(path, NS).text.split()])


def test_imported_table_certificate_states_only_what_happened(imported_results, tmp_path):
    tree = _certify(imported_results, tmp_path / "rd.xml")
    text = (tmp_path / "rd.xml").read_text(encoding="utf-8")
    low = text.lower()
    for word in ("shift-angle", "shift angle", "polygon", "autocollimator"):
        assert word not in low, word
    assert "imported measured error curve" in text and "are unknown" in text
    assert "Jia error model" not in text and "mean over the angles is removed" not in text
    assert "0.971" in text and "not removed" in text       # the constant as it is: mean 0.97″, kept
    assert "harmonic order 8" in text                       # the ambiguity the analysis reported
    assert "does not include" in text and "reference instrument's own error" in text
    # U: k from the t-distribution at the type A u's 23 dof, and the distribution says so
    res = json.loads(imported_results.read_text(encoding="utf-8"))
    err = _by_reftype(tree, "basic_measurementError")[0].find("si:realListXMLList", NS)
    k = float(err.find("si:expandedUncXMLList/si:coverageFactorXMLList", NS).text)
    assert k == pytest.approx(2.07, abs=0.005)
    assert err.find("si:expandedUncXMLList/si:distributionXMLList", NS).text == "t"
    U = _floats(err, "si:expandedUncXMLList/si:uncertaintyXMLList")
    assert np.allclose(U, k * np.asarray(res["encoder_error_arcsec"]["u"]), rtol=0.05)


def test_imported_table_with_a_lab_file_claims_none_of_its_equipment(imported_results, tmp_path):
    tree = _certify(imported_results, tmp_path / "rd.xml", "--lab", str(LAB))
    text = (tmp_path / "rd.xml").read_text(encoding="utf-8")
    assert tree.find(".//dcc:measuringEquipments", NS) is None and "ELCOMAT" not in text
    assert tree.find(".//dcc:influenceConditions", NS) is None
    assert tree.find(".//dcc:statement[@refType='benchtwin_importedCurveEquipment']", NS) is not None


def test_close_loop_certificate_uses_the_dcc_basic_reftypes(jia_results, tmp_path):
    tree = _certify(jia_results, tmp_path / "jia.xml", "--lab", str(LAB))
    res = json.loads(jia_results.read_text(encoding="utf-8"))
    measured = _by_reftype(tree, "basic_measuredValue")
    errors = _by_reftype(tree, "basic_measurementError")
    reference = _by_reftype(tree, "basic_referenceValue")
    assert measured and errors and reference
    # the encoder error: one list of readings, reference angles and errors (each also benchtwin's refType)
    lst = errors[0].getparent()
    assert "benchtwin_encoderErrorValue" in errors[0].get("refType").split()
    th = _floats(measured[0], "si:realListXMLList/si:valueXMLList")
    err = errors[0].find("si:realListXMLList", NS)
    a = _floats(errors[0], "si:realListXMLList/si:valueXMLList")
    ref = _floats(reference[0], "si:realListXMLList/si:valueXMLList")
    assert measured[0].getparent() is lst and reference[0].getparent() is lst
    enc = res["encoder_error_arcsec"]
    np.testing.assert_allclose(th, enc["theta_deg"], atol=5e-7)
    np.testing.assert_allclose(a, enc["value"], atol=0.006)
    np.testing.assert_allclose(ref, th - np.asarray(enc["value"]) / 3600.0, atol=6e-6)
    # the distribution matches k: the budget's k is a t quantile at ν_eff
    k = float(err.find("si:expandedUncXMLList/si:coverageFactorXMLList", NS).text)
    assert k == pytest.approx(res["budget_summary"]["k"], abs=0.005)
    assert err.find("si:expandedUncXMLList/si:distributionXMLList", NS).text == "t"
    text = (tmp_path / "jia.xml").read_text(encoding="utf-8")
    assert f"ν_eff = {math.floor(res['budget_summary']['nu_eff'])}" in text
    # one shift angle ran: no "several shift angles"; the reference as the analysis used it
    assert "several shift angles" not in text and "at one shift angle (S = 0 deg)" in text
    assert "23-face optical polygon" in text and "declared in the dataset manifest" in text
    assert "No correction applied to the values." in text and "does not include" in text


def test_a_run_at_several_shifts_names_them(hsieh_results, tmp_path):
    _certify(hsieh_results, tmp_path / "h.xml")
    text = (tmp_path / "h.xml").read_text(encoding="utf-8")
    assert "shift-angle method" in text and "at 3 shift angles (S = 0, 5, 10 deg)" in text
    assert "multi-head self-calibration" in text


def test_certificate_html_is_self_contained_and_escapes_every_string(jia_results, tmp_path):
    evil = '<script>alert("x")</script> & "Co" <blink>'
    lab = tmp_path / "lab.toml"
    lab.write_text(LAB.read_text(encoding="utf-8").replace('name = "Example Angle Metrology Laboratory"',
                                                           f"name = '{evil}'"), encoding="utf-8")
    _certify(jia_results, tmp_path / "c.xml", "--lab", str(lab), "--html")
    page = (tmp_path / "c.html").read_text(encoding="utf-8")
    assert "<script" not in page and "<blink" not in page
    assert "&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt; &amp; &quot;Co&quot; &lt;blink&gt;" in page
    assert "src=" not in page and "href=" not in page and "http" not in page.split("<body>")[1]
    # it shows what the certificate states: the encoder error with U, k and its distribution
    res = json.loads(jia_results.read_text(encoding="utf-8"))
    assert f"k = {res['budget_summary']['k']:.2f}, p = 0.95, t distribution" in page
    assert "encoder error (″), ± U" in page and "Statements" in page
    # a path of one's own choosing
    _certify(jia_results, tmp_path / "d.xml", "--html", str(tmp_path / "people.html"))
    assert (tmp_path / "people.html").is_file()
