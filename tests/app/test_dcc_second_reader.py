"""A second reader finds the numbers (issue 34 item 3): each certificate read back with
``dcc-json-toolkit`` (PTB's DCC ⇄ JSON converter, xmlschema-based; written independently of our
lxml writer and of pydcc) gives every calibrated angle, encoder error, U and k, found by the DCC's
own refTypes (``basic_measuredValue``, ``basic_measurementError``), equal to results.json's curve
(analysis/calibration.py) rounded as the certificate states it.

The reader validates against the packaged schemas (app/dcc/), offline: its cache is put in
a temporary folder holding the packaged D-SI schema, and the network is closed (a download fails the
test instead of passing it by luck). Inputs: the session's runs (tests/conftest.py) and the imported
shared table (tests/app/conftest.py); nothing simulated here.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchtwin.analysis.calibration import calibration_curve
from benchtwin.app.certificate import SCHEMA_DIR, SCHEMA_VERSION, _k_str, value_and_U, write_certificate


@pytest.fixture(scope="module")
def reader(tmp_path_factory):
    """dcc_json_toolkit's DccSchema for DCC 3.1.2 on the packaged schemas, no network."""
    import dcc_json_toolkit.cache as cache
    import requests

    mp = pytest.MonkeyPatch()

    def no_network(*args, **kwargs):
        raise AssertionError(f"the second reader tried the network: {args}")

    mp.setattr(requests, "get", no_network)
    mp.setattr(cache, "CACHE_DIR_PATH", tmp_path_factory.mktemp("dcc_cache"))
    from dcc_json_toolkit import DccSchema

    # dcc.xsd imports D-SI by URL: the cache finds the packaged copy under that file name first
    cache.CacheManager(SCHEMA_VERSION).cache_xsd_file(str(SCHEMA_DIR / "SI_Format.xsd"))
    schema = DccSchema(SCHEMA_VERSION, schema_url=str(SCHEMA_DIR / "dcc.xsd"))
    yield schema
    mp.undo()


def _walk(node, key):
    """Every value under ``key`` anywhere in the converted document."""
    if isinstance(node, dict):
        for k, v in node.items():
            if k == key:
                yield from (v if isinstance(v, list) else [v])
            yield from _walk(v, key)
    elif isinstance(node, list):
        for v in node:
            yield from _walk(v, key)


def _curve_read(doc: dict, result_ref: str) -> dict:
    """Angles, values, U and k of a result's list, by the DCC's refTypes only."""
    (result,) = [r for r in _walk(doc, "dcc:result") if result_ref in r.get("@refType", [])]
    qs = list(_walk(result, "dcc:quantity"))
    (angle,) = [q for q in qs if "basic_measuredValue" in q.get("@refType", [])]
    (error,) = [q for q in qs if "basic_measurementError" in q.get("@refType", [])]
    e = error["si:realListXMLList"]
    unc = e["si:expandedUncXMLList"]
    return {"theta_deg": angle["si:realListXMLList"]["si:valueXMLList"], "value": e["si:valueXMLList"],
            "unit": e["si:unitXMLList"], "U": unc["si:uncertaintyXMLList"], "k": unc["si:coverageFactorXMLList"],
            "distribution": unc["si:distributionXMLList"]}


@pytest.mark.parametrize("which", ["jia_results", "hsieh_results", "imported_results"])
def test_second_reader_gives_back_every_angle_value_U_and_k(which, reader, request, tmp_path):
    results: Path = request.getfixturevalue(which)
    cert = tmp_path / "cert.xml"
    write_certificate(results, cert, today="2026-12-05")
    xml = cert.read_text(encoding="utf-8")
    assert reader.is_valid(xml), reader.validate_dcc(xml)[:3]
    doc = reader.to_dict(xml)
    # the JSON the converter writes is plain JSON (what a user of dcc2json gets)
    doc = json.loads(json.dumps(doc))
    got = _curve_read(doc, "benchtwin_encoderError")

    cal = calibration_curve(json.loads(results.read_text(encoding="utf-8")))
    n = len(cal.theta_deg)
    assert len(got["theta_deg"]) == len(got["value"]) == len(got["U"]) == n >= 12
    assert got["unit"] == ["\\arcsecond"]
    assert got["k"] == [float(_k_str(cal.k))] and got["k"][0] >= 1.9
    assert got["distribution"] == [cal.distribution]
    for i, (th, a, U) in enumerate(zip(cal.theta_deg, cal.error_arcsec, cal.U_arcsec)):
        v_s, U_s = value_and_U(a, U)
        assert got["theta_deg"][i] == pytest.approx(th, abs=5e-7), i
        assert (got["value"][i], got["U"][i]) == (float(v_s), float(U_s)), i
        # and the numbers are the curve's: U to two significant digits, the value to U's last digit
        assert abs(got["U"][i] - U) <= 0.05 * U and abs(got["value"][i] - a) <= 0.05 * U, i
