"""One number per quantity (issue 34 item 4): each radial error motion quantity is computed once, in
results.json, with its bandwidth; the report's summary, its ISO 230-7 table and the certificate quote
that number with the same u, and a quantity of another bandwidth has another name (item 3: the
certificate's ISO 230-7 values state the speed and the bandwidth).

Input: the session's simulated jia2019 run (tests/conftest.py ``jia_results``); nothing simulated here.
"""

from __future__ import annotations

import html
import json
import re

import pytest
from lxml import etree

from benchtwin.analysis.report.html import value_with_u
from benchtwin.app.certificate import K_DEFAULT, value_and_U, write_certificate

NS = {"dcc": "https://ptb.de/dcc", "si": "https://ptb.de/si"}
KINDS = ("total", "synchronous", "asynchronous")


def _tables(page: str) -> list[list[list[str]]]:
    """Every table of the report as rows of cell texts."""
    out = []
    for t in re.findall(r"<table>(.*?)</table>", page, re.S):
        out.append([[html.unescape(re.sub(r"<[^>]+>", "", c)).strip() for c in re.findall(r"<t[hd][^>]*>(.*?)</t[hd]>", r, re.S)]
                    for r in re.findall(r"<tr>(.*?)</tr>", t, re.S)])
    return out


def _shown(x: float, u: float) -> str:
    """How the report shows a value with its standard uncertainty."""
    return value_with_u(x, u, "µm")


@pytest.fixture(scope="module")
def quoted(jia_results, tmp_path_factory):
    res = json.loads(jia_results.read_text(encoding="utf-8"))
    page = (jia_results.parent / "report.html").read_text(encoding="utf-8")
    cert = tmp_path_factory.mktemp("one_number") / "cert.xml"
    write_certificate(jia_results, cert, today="2026-12-05")
    return res, page, etree.parse(str(cert))


def test_iso230_7_values_are_the_same_in_results_table_summary_and_certificate(quoted):
    res, page, cert = quoted
    rem = res["radial_error_motion"]
    bw, acq = rem["bandwidth"], rem["acquisition"]
    # the bandwidth is the sampling's: orders 2 … N/2 of the N step-and-settle positions of a turn
    n = acq["positions_per_turn"]
    assert acq["mode"] == "step-and-settle" and n == len(rem["locations"][0]["theta_deg"])
    assert (bw["lowest_order"], bw["highest_order"]) == (2, n // 2) and not rem["filtered"]
    band = f"orders 2–{n // 2}/rev"
    (iso_table,) = [t for t in _tables(page) if t[0][0] == "location"]
    assert iso_table[0][1:] == [f"{k}, {band}" for k in KINDS]   # the table's columns name the bandwidth
    rows = {r[0]: r[1:] for r in iso_table[1:]}
    res_el = cert.find(".//dcc:result[@refType='benchtwin_radialErrorMotion']", NS)
    assert "step-and-settle" in res_el.findtext("dcc:description/dcc:content", namespaces=NS)
    checked = 0
    for loc in rem["locations"]:
        lst = res_el.find(f".//dcc:list[@refType='benchtwin_{loc['name']}']", NS)
        for i, kind in enumerate(KINDS):
            x, u = loc[f"{kind}_um"], loc[f"{kind}_u_um"]
            assert rows[loc["label"]][i] == _shown(x, u), (loc["name"], kind)          # table = results
            q = lst.find(f"dcc:quantity[@refType='benchtwin_{kind}ErrorMotion']", NS)
            assert f"orders 2–{n // 2} per revolution" in q.findtext("dcc:name/dcc:content", namespaces=NS)
            real = q.find("si:real", NS)
            U = float(real.findtext("si:expandedUnc/si:uncertainty", namespaces=NS))
            k = float(real.findtext("si:expandedUnc/si:coverageFactor", namespaces=NS))
            # certificate = results: the same value, U = k·u (each rounded to U's two digits)
            assert (real.findtext("si:value", namespaces=NS), real.findtext("si:expandedUnc/si:uncertainty",
                                                                            namespaces=NS)) == value_and_U(x, k * u)
            assert k == K_DEFAULT and abs(U / k - u) <= 0.05 * u
            # the table's number and the certificate's agree to the coarser rounding of the two
            shown, cv = rows[loc["label"]][i].split(" ± ")[0], real.findtext("si:value", namespaces=NS)
            tol = sum(0.5 * 10.0 ** -len(s.partition(".")[2]) for s in (shown, cv))
            assert abs(float(shown) - float(cv)) <= tol + 1e-12
            checked += 1
        # speed and bandwidth as numbers a reader can take (item 3)
        cond = {c.get("refType"): c for c in lst.findall("dcc:influenceConditions/dcc:influenceCondition", NS)}
        hi = cond["benchtwin_bandwidth"].find(".//dcc:quantity[@refType='benchtwin_highest_order']/si:real/si:value",
                                               NS)
        assert float(hi.text) == n // 2
        pos = cond["benchtwin_stepAndSettle"].find(".//si:real/si:value", NS)
        assert float(pos.text) == n
    assert checked == 3 * len(rem["locations"]) >= 9

    # the summary quotes the disk plane's ISO 230-7 asynchronous value of the table, under a name that says
    # it is ISO 230-7 and gives its bandwidth and speed
    (summary,) = [t for t in _tables(page) if t[0] == ["quantity", "value"] and any("δY" in r[0] for r in t)]
    iso_rows = [r for r in summary if "ISO 230-7" in r[0]]
    assert len(iso_rows) == 1, iso_rows
    name, value = iso_rows[0]
    disk = next(loc for loc in rem["locations"] if loc["name"] == "disk")
    assert band in name and "step-and-settle" in name and f"{n} positions per turn" in name
    assert value == _shown(disk["asynchronous_um"], disk["asynchronous_u_um"])
    assert value == rows[disk["label"]][2]


def test_the_order_2_10_series_is_another_quantity_with_its_own_name_and_u(quoted):
    res, page, _ = quoted
    rm = res["radial_motion"]
    assert (rm["bandwidth"]["lowest_order"], rm["bandwidth"]["highest_order"]) == (2, 10)
    (summary,) = [t for t in _tables(page) if t[0] == ["quantity", "value"] and any("δY" in r[0] for r in t)]
    disk = rm["summary"]["disk"]
    series = [r for r in summary if "order-2–10 series" in r[0]]
    assert len(series) == 1 and "ISO 230-7" not in series[0][0] and "orders 2–10/rev" in series[0][0]
    assert series[0][1] == _shown(disk["synchronous_um"], disk["synchronous_u_um"])
    # the report's comparison states the series' values with the same u, named as a different quantity
    text = html.unescape(re.sub(r"<[^>]+>", "", page))
    i = text.index("A different quantity, for comparison")
    para = text[i:text.index("(total / synchronous / asynchronous)", i)]
    assert "orders 2–10 of the revolution" in para
    for name in ("top", "bottom", "disk"):
        v = rm["summary"][name]
        assert " / ".join(_shown(v[f"{k}_um"], v[f"{k}_u_um"]) for k in KINDS) in para, name
    # u of the series is the probe noise left in an order-10 series: smaller than the unfiltered value's u
    iso_disk = next(loc for loc in res["radial_error_motion"]["locations"] if loc["name"] == "disk")
    assert 0 < disk["asynchronous_u_um"] < iso_disk["asynchronous_u_um"]
