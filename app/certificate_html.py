"""The certificate for people: one self-contained HTML page rendered from the DCC itself.

``benchtwin certificate RESULTS.json -o CERT.xml --html [CERT.html]`` writes it beside the XML. It
is rendered from the validated XML tree (app/certificate.py), not from results.json, so
the page shows what the certificate states and nothing else: the administrative data, the
statements, the methods, the equipment, the influence conditions and every result (lists as tables,
each value with its expanded uncertainty, k, p and distribution). Every string from the
certificate is escaped (``html.escape``); the page has no script and loads nothing (inline CSS).
"""

from __future__ import annotations

import html
from typing import Any

from lxml import etree

DCC_NS = "https://ptb.de/dcc"
SI_NS = "https://ptb.de/si"
NS = {"dcc": DCC_NS, "si": SI_NS}

#: D-SI unit strings as people write them (anything else is shown as written)
UNIT_TEXT = {r"\degree": "°", r"\arcsecond": "″", r"\micro\metre": "µm", r"\milli\metre": "mm", r"\metre": "m",
             r"\micro\radian": "µrad", r"\radian": "rad", r"\degreecelsius": "°C", r"\kelvin": "K",
             r"\percent": "%", r"\hecto\pascal": "hPa", r"\pascal": "Pa", r"\one": "", r"\second": "s",
             r"\hour": "h"}

_CSS = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222;line-height:1.4}
h1{border-bottom:2px solid #335;padding-bottom:.2em} h2{margin-top:2em;color:#335} h3{color:#335}
table{border-collapse:collapse;margin:.5em 0} td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left;
vertical-align:top} th{background:#eef} td.num{text-align:right;font-variant-numeric:tabular-nums}
.small{font-size:.9em;color:#555}
"""


def _e(s: Any) -> str:
    return html.escape("" if s is None else str(s), quote=True)


def _t(el: Any, path: str) -> str:
    """The text of the first element at ``path`` (a dcc text element's content, or a plain element)."""
    if el is None:
        return ""
    found = el.find(path, NS)
    if found is None:
        return ""
    contents = found.findall("dcc:content", NS)
    if contents:
        return " ".join((c.text or "").strip() for c in contents)
    return (found.text or "").strip()


def _unit(u: str) -> str:
    return UNIT_TEXT.get(u.strip(), u.strip())


def _coverage(eu: Any, list_: bool) -> str:
    sfx = "XMLList" if list_ else ""
    k = _t(eu, f"si:coverageFactor{sfx}")
    p = _t(eu, f"si:coverageProbability{sfx}")
    d = _t(eu, f"si:distribution{sfx}")
    return f"k = {k}, p = {p}" + (f", {d} distribution" if d else "")


def _quantity_columns(q: Any) -> tuple[str, list[str], str]:
    """(header, cells, note) of a quantity holding a si:realListXMLList."""
    name = _t(q, "dcc:name")
    rl = q.find("si:realListXMLList", NS)
    unit = _unit(_t(rl, "si:unitXMLList"))
    values = _t(rl, "si:valueXMLList").split()
    eu = rl.find("si:expandedUncXMLList", NS)
    head = f"{name} ({unit})" if unit else name
    if eu is None:
        return head, values, ""
    U = _t(eu, "si:uncertaintyXMLList").split()
    if len(U) == 1:
        U = U * len(values)
    cells = [f"{v} ± {u}" for v, u in zip(values, U)]
    return f"{head}, ± U", cells, f"{name}: U with {_coverage(eu, True)}"


def _real(q: Any) -> tuple[str, str, str]:
    """(name, value ± U unit, coverage) of a quantity holding a si:real."""
    r = q.find("si:real", NS)
    unit = _unit(_t(r, "si:unit"))
    v = _t(r, "si:value")
    eu = r.find("si:expandedUnc", NS)
    if eu is None:
        return _t(q, "dcc:name"), f"{v} {unit}".strip(), ""
    return _t(q, "dcc:name"), f"{v} ± {_t(eu, 'si:uncertainty')} {unit}".strip(), _coverage(eu, False)


def _list_html(lst: Any) -> list[str]:
    out = []
    name = _t(lst, "dcc:name")
    if name:
        out.append(f"<h4>{_e(name)}</h4>")
    desc = _t(lst, "dcc:description")
    if desc:
        out.append(f'<p class="small">{_e(desc)}</p>')
    cols, reals, notes = [], [], []
    for q in lst.findall("dcc:quantity", NS):
        if q.find("si:realListXMLList", NS) is not None:
            head, cells, note = _quantity_columns(q)
            cols.append((head, cells))
            if note:
                notes.append(note)
        elif q.find("si:real", NS) is not None:
            reals.append(_real(q))
        elif q.find("dcc:noQuantity", NS) is not None:   # a statement in place of a value ("not computed: ...")
            reals.append((_t(q, "dcc:name"), _t(q, "dcc:noQuantity"), ""))
    if cols:
        n = max(len(c) for _, c in cols)
        out.append("<table><tr>" + "".join(f"<th>{_e(h)}</th>" for h, _ in cols) + "</tr>")
        for i in range(n):
            out.append("<tr>" + "".join(f'<td class="num">{_e(c[i]) if i < len(c) else ""}</td>' for _, c in cols)
                       + "</tr>")
        out.append("</table>")
        out += [f'<p class="small">{_e(x)}</p>' for x in notes]
    if reals:
        out.append("<table><tr><th>quantity</th><th>value ± U</th><th>coverage</th></tr>")
        out += [f'<tr><td>{_e(a)}</td><td class="num">{_e(b)}</td><td>{_e(c)}</td></tr>' for a, b, c in reals]
        out.append("</table>")
    for sub in lst.findall("dcc:list", NS):
        out += _list_html(sub)
    return out


def render_html(tree: etree._ElementTree | etree._Element) -> str:
    """The certificate as a self-contained HTML page (every string escaped)."""
    root = tree.getroot() if isinstance(tree, etree._ElementTree) else tree
    adm = root.find("dcc:administrativeData", NS)
    core = adm.find("dcc:coreData", NS)
    uid = _t(core, "dcc:uniqueIdentifier")
    title = f"Calibration certificate {uid}"
    b = [f"<h1>{_e(title)}</h1>"]
    item = adm.find("dcc:items/dcc:item", NS)
    serials = "; ".join(f"{_t(i, 'dcc:name') or _t(i, 'dcc:issuer')}: {_t(i, 'dcc:value')}"
                        for i in item.findall("dcc:identifications/dcc:identification", NS))
    lab = adm.find("dcc:calibrationLaboratory/dcc:contact", NS)
    cust = adm.find("dcc:customer", NS)
    persons = "; ".join(
        _t(p, "dcc:person/dcc:name") + (f" ({_t(p, 'dcc:role')})" if _t(p, "dcc:role") else "")
        + (", main signer" if _t(p, "dcc:mainSigner") == "true" else "")
        for p in adm.findall("dcc:respPersons/dcc:respPerson", NS))
    rows = [("certificate", uid),
            ("performed", f"{_t(core, 'dcc:beginPerformanceDate')} to {_t(core, 'dcc:endPerformanceDate')} "
                          f"({_t(core, 'dcc:performanceLocation')}, {_t(core, 'dcc:countryCodeISO3166_1')})"),
            ("item", " ".join(x for x in (_t(item, "dcc:name"), _t(item, "dcc:manufacturer/dcc:name"),
                                          _t(item, "dcc:model")) if x) + (f"; {serials}" if serials else "")),
            ("calibration laboratory", ", ".join(x for x in (_t(lab, "dcc:name"), _t(lab, "dcc:location/dcc:city"),
                                                             _t(lab, "dcc:location/dcc:countryCode")) if x)),
            ("customer", ", ".join(x for x in (_t(cust, "dcc:name"), _t(cust, "dcc:location/dcc:city")) if x)),
            ("responsible persons", persons),
            ("software", " ".join(x for x in (_t(adm, "dcc:dccSoftware/dcc:software/dcc:name"),
                                              _t(adm, "dcc:dccSoftware/dcc:software/dcc:release")) if x))]
    b.append("<table>" + "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in rows) + "</table>")
    b.append("<h2>Statements</h2><ul>")
    for s in adm.findall("dcc:statements/dcc:statement", NS):
        ref = " ".join(x for x in (_t(s, "dcc:norm"), _t(s, "dcc:reference")) if x)
        b.append(f"<li>{_e(_t(s, 'dcc:declaration'))}" + (f' <span class="small">({_e(ref)})</span>' if ref else "")
                 + "</li>")
    b.append("</ul>")
    for mr in root.findall("dcc:measurementResults/dcc:measurementResult", NS):
        b.append(f"<h2>{_e(_t(mr, 'dcc:name'))}</h2>")
        methods = mr.findall("dcc:usedMethods/dcc:usedMethod", NS)
        if methods:
            b.append("<h3>Methods</h3><ul>")
            for m in methods:
                ref = " ".join(x for x in (_t(m, "dcc:norm"), _t(m, "dcc:reference")) if x)
                b.append(f"<li><b>{_e(_t(m, 'dcc:name'))}</b>: {_e(_t(m, 'dcc:description'))}"
                         + (f' <span class="small">({_e(ref)})</span>' if ref else "") + "</li>")
            b.append("</ul>")
        eqs = mr.findall("dcc:measuringEquipments/dcc:measuringEquipment", NS)
        if eqs:
            b.append("<h3>Measuring equipment</h3><table><tr><th>equipment</th><th>manufacturer</th><th>model</th>"
                     "<th>serial</th><th>its certificate</th></tr>")
            for q in eqs:
                b.append("<tr>" + "".join(f"<td>{_e(x)}</td>" for x in (
                    _t(q, "dcc:name"), _t(q, "dcc:manufacturer/dcc:name"), _t(q, "dcc:model"),
                    _t(q, "dcc:identifications/dcc:identification/dcc:value"),
                    _t(q, "dcc:certificate/dcc:referralID"))) + "</tr>")
            b.append("</table>")
        conds = mr.findall("dcc:influenceConditions/dcc:influenceCondition", NS)
        if conds:
            b.append("<h3>Influence conditions</h3><table><tr><th>condition</th><th>value ± U</th><th>coverage</th>"
                     "<th>source</th></tr>")
            for c in conds:
                for q in c.findall("dcc:data/dcc:quantity", NS):
                    _n, v, cov = _real(q)
                    b.append(f"<tr><td>{_e(_t(c, 'dcc:name'))}</td><td class=\"num\">{_e(v)}</td><td>{_e(cov)}</td>"
                             f"<td>{_e(_t(c, 'dcc:description'))}</td></tr>")
            b.append("</table>")
        b.append("<h3>Results</h3>")
        for r in mr.findall("dcc:results/dcc:result", NS):
            b.append(f"<h3>{_e(_t(r, 'dcc:name'))}</h3>")
            desc = _t(r, "dcc:description")
            if desc:
                b.append(f"<p>{_e(desc)}</p>")
            data = r.find("dcc:data", NS)
            if data is None:
                continue
            b += _list_html(data)
    body = "\n".join(b)
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{_e(title)}</title><style>{_CSS}</style>"
            f"</head><body>\n{body}\n</body></html>\n")
