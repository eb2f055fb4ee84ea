"""The DCC certificate (issue 20): a small simulated jia2019 run and an hsieh-type run (12 heads,
self-calibration) analysed, certified, validated OFFLINE against dcc.xsd 3.1.2 + D-SI 2.1.0 (the
copies in ../shared/dcc, as CI has them, and the packaged ones), and read back with an independent
DCC reader from PyPI (pydcc, Siemens/PTB) whose values must agree with results.json.

pydcc is used as a reader only: its module imports ``certvalidator`` for XAdES signature checks
(our certificates are unsigned, and certvalidator's oscrypto 1.3.0 cannot parse this machine's
OpenSSL 3 version string), so a stand-in module takes its name; and its ``DCC`` object builds a
schema validator that downloads the PTB schema list, which we replace: validation is ours, offline.
"""

from __future__ import annotations

import json
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from benchtwin.app.certificate import (SCHEMA_DIR, load_results, round_expanded, validation_errors, value_and_U,
                                       write_certificate)
from benchtwin.cli import main

ROOT = Path(__file__).resolve().parents[2]
SHARED_DCC = ROOT.parent / "shared" / "dcc"
LAB = ROOT / "docs" / "lab.example.toml"


def _shared_dcc() -> Path:
    if not (SHARED_DCC / "dcc.xsd").is_file():
        pytest.skip("../shared/dcc (the reference schemas) is not beside this checkout")
    return SHARED_DCC


# the fixtures jia_results and hsieh_results (a small simulated jia2019 run and a reduced hsieh2022
# run, analysed with the loop closed, truth deleted) are in tests/conftest.py: session-scoped, shared
# with tests/app/test_certificate_honest.py and tests/app/test_calibration_csv.py


# ----------------------------------------------------------------------------- the reader


def _pydcc():
    """pydcc's DCC class, importable offline (see the module docstring)."""
    if "certvalidator" not in sys.modules:
        stub = types.ModuleType("certvalidator")
        stub.CertificateValidator = stub.ValidationContext = object
        stub.errors = types.SimpleNamespace()
        sys.modules["certvalidator"] = stub
    import dcc.dcc as pydcc

    pydcc.DCCXMLValidator = lambda *a, **k: None  # no schema download; we validate offline ourselves
    return pydcc.DCC


def _by_ref(dcc_obj) -> dict[str, dict]:
    """pydcc's results keyed by the quantity's path of refTypes (as pydcc writes them)."""
    out = {}
    for path, si in dcc_obj.get_calibration_results("xpath"):
        # each element's last refType: benchtwin's own (a quantity also carries the DCC's basic_* first)
        refs = [p.split("'")[1].split()[-1] for p in path.split("refType =")[1:]]
        out["/".join(refs)] = si
    return out


def _floats(s: str) -> np.ndarray:
    return np.array([float(x) for x in s.split()])


# ----------------------------------------------------------------------------- tests


def test_packaged_schemas_are_the_reference_copies():
    shared = _shared_dcc()
    for name in ("dcc.xsd", "SI_Format.xsd"):
        assert (SCHEMA_DIR / name).read_bytes() == (shared / name).read_bytes(), name


def test_jia_certificate_validates_and_reads_back(jia_results, tmp_path):
    out = tmp_path / "cert.xml"
    rc = main(["certificate", str(jia_results), "-o", str(out), "--lab", str(LAB), "--json"])
    assert rc == 0 and out.is_file()
    tree = etree.parse(str(out))
    assert validation_errors(tree, _shared_dcc()) == []

    res = json.loads(jia_results.read_text())
    DCC = _pydcc()
    cert = DCC(xml_file_name=str(out))
    assert cert.is_loaded() and cert.version() == "3.1.2"
    assert cert.uid() == "BT-2026-0042"
    assert cert.calibration_laboratory_name() == "Example Angle Metrology Laboratory"
    assert cert.calibration_date().date().isoformat() == "2026-12-01"
    assert cert.mandatory_language() == "en"
    ids = cert.item_id()["identifications"]["identification"]
    assert {i["value"] for i in ids} == {"SN 0000-1234", "INV-88"}

    q = _by_ref(cert)
    enc = res["encoder_error_arcsec"]
    ang = q["benchtwin_encoderError/benchtwin_angle"]["realListXMLList"]
    err = q["benchtwin_encoderError/benchtwin_encoderErrorValue"]["realListXMLList"]
    assert ang["unitXMLList"] == r"\degree" and err["unitXMLList"] == r"\arcsecond"
    np.testing.assert_allclose(_floats(ang["valueXMLList"]), enc["theta_deg"], atol=5e-7)
    U_read = _floats(err["expandedUncXMLList"]["uncertaintyXMLList"])
    np.testing.assert_allclose(U_read, enc["U"], rtol=0.05)  # two significant digits
    # each value rounded to its U's last digit: within half that digit of results.json
    half_digit = 0.5 * 10.0 ** -np.array([round_expanded(u)[1] for u in enc["U"]])
    assert np.all(np.abs(_floats(err["valueXMLList"]) - enc["value"]) <= half_digit + 1e-12)
    k = float(err["expandedUncXMLList"]["coverageFactorXMLList"])
    assert k == pytest.approx(res["budget_summary"]["k"], abs=0.005)
    assert float(err["expandedUncXMLList"]["coverageProbabilityXMLList"]) == pytest.approx(0.95)

    beta = q["benchtwin_polygonPitchDeviation/benchtwin_pitchDeviationValue"]["realListXMLList"]
    np.testing.assert_allclose(_floats(beta["valueXMLList"]), res["polygon_pitch_deviation_arcsec"], atol=0.0051)
    np.testing.assert_allclose(_floats(beta["expandedUncXMLList"]["uncertaintyXMLList"]),
                               2 * np.asarray(res["polygon_pitch_deviation_u_arcsec"]), rtol=0.05)
    e = q["benchtwin_eccentricity/benchtwin_eccentricityValue"]["real"]
    assert e["unit"] == r"\micro\metre"
    assert float(e["value"]) == pytest.approx(res["eccentricity_um"], abs=0.01)
    assert float(e["expandedUnc"]["uncertainty"]) == pytest.approx(2 * res["eccentricity_u_um"], rel=0.05)
    t0 = q["benchtwin_eccentricity/benchtwin_eccentricityPhase"]["real"]
    assert float(t0["value"]) == pytest.approx(res["eccentricity_phase_deg"], abs=0.05)

    # the effects the loop identified: a statement and each parameter with U
    text = out.read_text(encoding="utf-8")
    for eff in res["identified_effects"]:
        assert f"benchtwin_effect_{eff['name']}" in text and eff["name"] in text
    assert "benchtwin_simulated" in text  # a twin dataset is declared as such
    # the methods the run used: one shift angle (S = 0, all start faces) is a polygon cross-calibration,
    # not the shift-angle method "at several shift angles"
    assert "Jia" in text and "polygon cross-calibration" in text and "several shift angles" not in text
    assert "\\degreecelsius" in text  # the environment from the lab file
    assert "ELCOMAT 3000" in text  # the equipment

    # the report of the same run: ISO 230-7 values and polar plots, the CCD pictures
    html = (jia_results.parent / "report.html").read_text(encoding="utf-8")
    assert "Radial error motion values (ISO 230-7:2015)" in html and "ISO 230-7 polar plots along Y" in html
    assert "raw CCD frame with the detected line ends" in html
    rem = res["radial_error_motion"]
    assert [loc["name"] for loc in rem["locations"]] == ["top", "bottom", "disk", "top_x", "bottom_x", "disk_x"]
    tot = q["benchtwin_radialErrorMotion/benchtwin_disk/benchtwin_totalErrorMotion"]["real"]
    assert float(tot["value"]) == pytest.approx(rem["locations"][2]["total_um"], abs=0.006)


def test_hsieh_certificate_validates_and_states_selfcal(hsieh_results, tmp_path):
    out = tmp_path / "hsieh.xml"
    info = write_certificate(hsieh_results, out)  # no lab file: placeholders, still a valid DCC
    assert info["valid"] and info["administrative_data"] == "not stated"
    assert validation_errors(etree.parse(str(out)), _shared_dcc()) == []
    res = json.loads(hsieh_results.read_text())
    q = _by_ref(_pydcc()(xml_file_name=str(out)))
    sc = q["benchtwin_selfCalibrationError/benchtwin_encoderErrorValue"]["realListXMLList"]
    assert len(sc["valueXMLList"].split()) == len(res["selfcal_error_arcsec"]["value"])
    err = q["benchtwin_encoderError/benchtwin_encoderErrorValue"]["realListXMLList"]
    assert len(err["valueXMLList"].split()) == len(res["encoder_error_arcsec"]["theta_deg"]) == info["n_angles"]
    assert "benchtwin_adminNotStated" in out.read_text(encoding="utf-8")


def test_invalid_certificate_is_detected(jia_results, tmp_path):
    """The validator is not a formality: a certificate without coreData fails dcc.xsd."""
    out = tmp_path / "c.xml"
    write_certificate(jia_results, out)
    tree = etree.parse(str(out))
    adm = tree.getroot()[0]
    adm.remove(adm.find("{https://ptb.de/dcc}coreData"))
    errs = validation_errors(tree, _shared_dcc())
    assert errs and "coreData" in errs[0]


def test_rounding_of_expanded_uncertainty():
    assert round_expanded(0.2349) == (0.23, 2)
    assert round_expanded(9.96) == (10.0, 0)
    assert round_expanded(0.0996) == (0.1, 2)
    assert value_and_U(13.34411, 0.2349) == ("13.34", "0.23")
    assert value_and_U(-0.0001, 0.2349) == ("0.00", "0.23")  # no "-0.00"
    assert value_and_U(1234.5, 123.4) == ("1230", "120")


@pytest.mark.parametrize("case", ["missing", "not_json", "wrong_format", "no_encoder_error", "nan_value",
                                  "lab_missing", "lab_country", "lab_unknown_key", "lab_date", "lab_env_unit"])
def test_bad_input_exit_2(case, jia_results, tmp_path, capsys):
    res = json.loads(jia_results.read_text())
    rpath, lab = tmp_path / "results.json", None
    if case == "missing":
        rpath = tmp_path / "nope.json"
    elif case == "not_json":
        rpath.write_text("{", encoding="utf-8")
    elif case == "wrong_format":
        rpath.write_text(json.dumps({**res, "format": "bench-dataset"}), encoding="utf-8")
    elif case == "no_encoder_error":
        rpath.write_text(json.dumps({k: v for k, v in res.items() if k != "encoder_error_arcsec"}), encoding="utf-8")
    elif case == "nan_value":
        res["encoder_error_arcsec"]["value"][3] = None
        rpath.write_text(json.dumps(res), encoding="utf-8")
    else:
        rpath.write_text(json.dumps(res), encoding="utf-8")
        text = LAB.read_text(encoding="utf-8")
        text = {"lab_missing": None,
                "lab_country": text.replace('country = "DE"                 # ISO', 'country = "Germany"  # ISO'),
                "lab_unknown_key": text.replace("[item]", "[item]\ncolour = \"red\""),
                "lab_date": text.replace("end_date = 2026-12-01", 'end_date = "1 Dec 2026"'),
                "lab_env_unit": text.replace("temperature_degC = 20.1", "temperature = 20.1")}[case]
        lab = tmp_path / "lab.toml"
        if text is not None:
            lab.write_text(text, encoding="utf-8")
    out = tmp_path / "cert.xml"
    args = ["certificate", str(rpath), "-o", str(out), "--json"] + (["--lab", str(lab)] if lab else [])
    assert main(args) == 2
    cap = capsys.readouterr()
    err = json.loads(cap.err or cap.out)  # --json: the error object (stream as the CLI chooses)
    expect = {"missing": "not found", "not_json": "not a JSON", "wrong_format": "'format'",
              "no_encoder_error": "encoder_error_arcsec", "nan_value": "value[3]", "lab_missing": "lab file not found",
              "lab_country": "ISO 3166", "lab_unknown_key": "colour", "lab_date": "end_date",
              "lab_env_unit": "unit suffix"}[case]
    assert expect in err["error"]
    assert not out.exists()  # nothing half-written


def test_load_results_names_the_file(tmp_path):
    p = tmp_path / "r.json"
    p.write_text("[]", encoding="utf-8")
    with pytest.raises(ValueError, match=str(p)):
        load_results(p)


def test_equipment_and_environment_from_an_acquisition_manifest(jia_results):
    """An acquired dataset's manifest names its instruments (kind, model, serial) and may carry the
    environment; the lab file adds the traceability of the same instrument (joined on its name)."""
    from benchtwin.app.certificate import build_certificate, load_lab

    res = json.loads(jia_results.read_text())
    res["source"] = "hardware"
    man = {"source": "hardware", "instruments": {
        "autocollimator": {"kind": "autocollimator", "model": "ELCOMAT 3000", "serial": "AC-0001"},
        "encoder": {"kind": "encoder", "model": "ND 287", "serial": "E-77"}},
        "environment": {"temperature_degC": 20.3, "temperature_u_degC": 0.05}}
    tree = build_certificate(res, load_lab(LAB, "2026-12-01"), man)
    assert validation_errors(tree, _shared_dcc()) == []
    ns = {"dcc": "https://ptb.de/dcc", "si": "https://ptb.de/si"}
    eq = tree.findall(".//dcc:measuringEquipment", ns)
    ac = next(e for e in eq if e.get("refType") == "benchtwin_autocollimator")
    assert ac.find("dcc:certificate/dcc:referralID", ns).text == "DKD-K-00000 2026-05"  # from the lab file
    assert ac.find("dcc:model", ns).text == "ELCOMAT 3000"
    assert any(e.get("refType") == "benchtwin_encoder" for e in eq)  # only in the manifest
    t = tree.find(".//dcc:influenceCondition[@refType='basic_temperature']//si:real", ns)
    assert t.find("si:value", ns).text == "20.30" and t.find("si:expandedUnc/si:uncertainty", ns).text == "0.10"
    assert tree.find(".//dcc:statement[@refType='benchtwin_dataSource']", ns) is not None


def test_certificate_states_the_corrected_curve_only_when_a_correction_was_applied():
    """The loop's ``encoder_error_corrected_arcsec`` (issue 16) is the curve a certificate states when a
    correction of the reference chain was applied; with none applied it equals the measured curve and
    the certificate says "measured"."""
    from benchtwin.app.certificate import encoder_curve

    measured = {"theta_deg": [0.0, 180.0], "value": [1.0, -1.0], "u": [0.1, 0.1]}
    corrected = {"theta_deg": [0.0, 180.0], "value": [0.4, -0.4], "u": [0.12, 0.12],
                 "corrections_applied": [{"effect": "ac_scale", "rms_arcsec": 0.6}]}
    res = {"encoder_error_arcsec": measured, "encoder_error_corrected_arcsec": corrected,
           "budget_summary": {"k": 2.0, "p": 0.95}}
    c = encoder_curve(res, "results.json")
    assert c["key"] == "encoder_error_corrected_arcsec" and "ac_scale" in c["label"]
    assert c["value"] == [0.4, -0.4] and c["U"] == pytest.approx([0.24, 0.24])
    res["encoder_error_corrected_arcsec"] = {**measured, "corrections_applied": []}
    c = encoder_curve(res, "results.json")
    assert c["key"] == "encoder_error_arcsec" and c["label"].startswith("measured")
