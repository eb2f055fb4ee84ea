"""A PTB Digital Calibration Certificate (DCC 3.1.2, D-SI 2.1.0) for a rotary-encoder calibration.

What a calibration lab hands on (issue 20): the analysis's ``results.json`` becomes an XML
certificate in the PTB DCC format (https://ptb.de/dcc/, schema v3.1.2; quantities in D-SI v2.1.0,
https://ptb.de/si/), validated against the schemas before it is written. The schemas ship with the
package (``app/dcc/``, LGPL-3.0, unchanged copies of ``../shared/dcc/``) so a certificate
is checked offline: ``dcc.xsd`` imports D-SI by its URL, which :func:`load_schema` resolves to the
local ``SI_Format.xsd``.

Contents (one ``measurementResult``):

- the encoder error at every calibrated angle (analysis/calibration.py, the numbers of
  calibration.csv: the loop's corrected curve when a correction was applied, else the measured
  curve of Hsieh et al. 2022 eq. 3 or of an imported table), as the encoder reading
  (``basic_measuredValue``), the reference angle (``basic_referenceValue``) and the error
  (``basic_measurementError``), each with ``si:expandedUncXMLList`` (U, k, p and the distribution
  k belongs to: t at the budget's ν_eff, Hsieh Table 3 / JCGM 100:2008 G.4, or at an imported
  table's type A ν), and what U includes and excludes;
- the self-calibration curve (Hsieh sec. 2.3) when it was measured;
- the polygon pitch deviations β (Hsieh eq. 1) and the eccentricity e, θ0 (Jia et al. 2019
  eqs. 10–12), each with U = k·u, k = 2 (p ≈ 95 %, normal distribution, GUM 6.3.3: these are
  least-squares results with many degrees of freedom);
- the radial error motion values of ISO 230-7:2015 (total / synchronous / asynchronous) at each
  test sphere and at the disk plane, when the analysis computed them;
- the methods (``usedMethods``), the effects the loop identified (a statement plus each effect's
  parameters with U), the measuring equipment (dataset manifest + lab file) and the environment
  (manifest ``environment`` or the lab file's ``[environment]``) as ``influenceConditions``;
- the administrative data (laboratory, customer, item, responsible persons, dates) from a lab file
  (TOML, example in ``docs/lab.example.toml``); without one, every field says "not stated" and a
  statement says so.

Rounding (EA-4/02 M:2022 sec. 5): U to two significant digits, the value to the same decimal
place as its U.

It states only what happened (issue 34): the methods and the reference chain are those the analysis
ran (read from results.json), a dataset from the twin is declared as such (the values then describe
the simulated bench, not a physical item), an imported table as an imported measured curve whose
reference is unknown, and each ambiguity the analysis reported is stated.
"""

from __future__ import annotations

import datetime as _dt
import math
import re
import unicodedata
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from lxml import etree

from benchtwin import __version__
from benchtwin.analysis.results import ResultsError, read_results_text
from benchtwin.analysis.results_api import Results
from benchtwin.schema import Key, SchemaError, check_table, leaves, load_toml_file, loads_json, read_input_text

DCC_NS = "https://ptb.de/dcc"
SI_NS = "https://ptb.de/si"
SI_SCHEMA_URL = "https://ptb.de/si/v2.1.0/SI_Format.xsd"
SCHEMA_VERSION = "3.1.2"
SCHEMA_DIR = Path(__file__).with_name("dcc")
NSMAP = {"dcc": DCC_NS, "si": SI_NS}

#: D-SI unit strings (D-SI 2.1.0 unit syntax) for the unit suffixes of our names (docs/conventions.md)
DSI_UNITS = {"arcsec": r"\arcsecond", "deg": r"\degree", "um": r"\micro\metre", "mm": r"\milli\metre",
             "urad": r"\micro\radian", "rad": r"\radian", "degC": r"\degreecelsius", "K": r"\kelvin",
             "percent": r"\percent", "hPa": r"\hecto\pascal", "Pa": r"\pascal", "one": r"\one",
             "s": r"\second", "h": r"\hour", "per_h": r"\hour\tothe{-1}", "arcsec_per_h": r"\arcsecond\hour\tothe{-1}"}

NOT_STATED = "not stated"
K_DEFAULT = 2.0  # coverage factor where no budget gives one (GUM 6.3.3; p ≈ 95 % for a normal distribution)
P_DEFAULT = 0.95


@dataclass(frozen=True)
class Coverage:
    """How a stated expanded uncertainty U covers the value: coverage factor k, coverage
    probability p and the distribution k was taken from (GUM 6.2-6.3, G.4; D-SI expandedUnc)."""

    k: float = K_DEFAULT
    p: float = P_DEFAULT
    distribution: str = "normal"


DEFAULT_COVERAGE = Coverage()


class CertificateInputError(ValueError):
    """Bad results.json or lab file (the CLI turns it into exit 2); the message names file and key."""


# ----------------------------------------------------------------------------- schema


class _LocalSchemas(etree.Resolver):
    """Resolve the D-SI import of dcc.xsd (by URL) to the packaged copy: validation stays offline."""

    def resolve(self, url: str, pubid: str | None, context: Any) -> Any:  # noqa: D401 - lxml API
        if url in (SI_SCHEMA_URL, "SI_Format.xsd") or url.endswith("/SI_Format.xsd"):
            return self.resolve_filename(str(self.directory / "SI_Format.xsd"), context)
        return None

    def __init__(self, directory: Path):
        super().__init__()
        self.directory = directory


@lru_cache(maxsize=4)
def load_schema(directory: str | Path = SCHEMA_DIR) -> etree.XMLSchema:
    """dcc.xsd 3.1.2 with D-SI 2.1.0 from ``directory`` (no network: the import URL is resolved locally)."""
    d = Path(directory)
    parser = etree.XMLParser(no_network=True)
    parser.resolvers.add(_LocalSchemas(d))
    doc = etree.parse(str(d / "dcc.xsd"), parser)
    return etree.XMLSchema(doc)


def validation_errors(xml: etree._Element | etree._ElementTree | bytes, schema_dir: str | Path = SCHEMA_DIR) -> list[str]:
    """The schema's complaints about a certificate ([] when it validates)."""
    if isinstance(xml, bytes):
        xml = etree.fromstring(xml, etree.XMLParser(no_network=True))
    schema = load_schema(str(schema_dir))
    if schema.validate(xml):
        return []
    return [f"line {e.line}: {e.message}" for e in schema.error_log]


# ----------------------------------------------------------------------------- numbers


def round_expanded(U: float) -> tuple[float, int]:
    """U to two significant digits (EA-4/02 M:2022 sec. 5, GUM 7.2.6) and the number of decimals
    it has then. Rounded to nearest: at two digits that lowers U by at most 0.5/10.5 = 4.8 %,
    inside the 5 % beyond which EA-4/02 asks to round up."""
    if not (math.isfinite(U) and U > 0):
        raise ValueError(f"expanded uncertainty must be finite and > 0, got {U!r}")
    decimals = 1 - int(math.floor(math.log10(U)))
    r = round(U, decimals)
    if r >= 10.0 ** (2 - decimals):  # 9.96 -> 10: the second digit moved one place left
        decimals -= 1
    return r, decimals


def _dec(x: float, decimals: int) -> str:
    """A D-SI decimal: fixed notation with ``decimals`` places (negative: rounded to tens, hundreds...)."""
    if decimals >= 0:
        s = f"{x:.{decimals}f}"
    else:
        s = f"{round(x, decimals):.0f}"
    return s[1:] if s.startswith("-") and float(s) == 0.0 else s  # no "-0.00"


def value_and_U(x: float, U: float) -> tuple[str, str]:
    """(value, U) as D-SI decimal strings, value rounded to U's last digit."""
    r, d = round_expanded(U)
    return _dec(x, d), _dec(r, d)


def _k_str(k: float) -> str:
    # si:kValueType is ≥ 1 written as [1-9]\d*(\.\d*)?
    if not (math.isfinite(k) and k >= 1.0):
        raise ValueError(f"coverage factor must be ≥ 1, got {k!r}")
    return f"{k:.2f}"


def _p_str(p: float) -> str:
    if not (math.isfinite(p) and 0.0 < p <= 1.0):
        raise ValueError(f"coverage probability must be in (0, 1], got {p!r}")
    return f"{p:.2f}" if p < 1 else "1.0"


def _unit_of(name: str) -> tuple[str, str]:
    """('gain', r'\\one') from a name whose suffix is a unit (``amplitude_arcsec`` -> \\arcsecond)."""
    for suffix in sorted(DSI_UNITS, key=len, reverse=True):
        if name.endswith("_" + suffix):
            return name[: -len(suffix) - 1], DSI_UNITS[suffix]
    return name, DSI_UNITS["one"]


# ----------------------------------------------------------------------------- the lab file


@dataclass(frozen=True)
class Contact:
    name: str
    email: str
    street: str = ""
    street_no: str = ""
    post_code: str = ""
    city: str = ""
    country: str = ""
    phone: str = ""


@dataclass
class LabFile:
    """The administrative data of a certificate (docs/lab.example.toml)."""

    certificate_id: str
    language: str
    country: str
    begin_date: str
    end_date: str
    receipt_date: str | None
    location: str
    laboratory: Contact
    laboratory_code: str
    customer: Contact
    item: dict[str, str]
    persons: list[dict[str, Any]]
    equipment: list[dict[str, str]]
    environment: dict[str, float]
    stated: bool  # False: no lab file was given, every field is a placeholder
    source: str = "(no lab file)"


_CONTACT_KEYS = {"name", "email", "street", "street_no", "post_code", "city", "country", "phone"}
_LOCATIONS = ("laboratory", "customer", "laboratoryBranch", "customerBranch", "other")

# The lab file's keys, declared (benchtwin.schema.Key / check_table; issue 31): kinds, lengths and
# choices; every string of the file is also free of control characters (_check_text). A value of
# another type (a street given as a table, role = 5) is an error naming the key, never a dict or
# a number printed into the certificate.
MAX_LAB_BYTES = 1024 * 1024   # a real lab file is about 2 kB
_NAME = 200                   # a name, an address line, an identifier
_LONG = 2000                  # a description


def _str(required: bool = False, n_max: int = _NAME) -> Key:
    return Key("str", required=required, n_min=1 if required else 0, n_max=n_max)


LAB_KEYS: dict[str, Key] = {
    "certificate": Key("table", required=True), "laboratory": Key("table", required=True),
    "customer": Key("table", required=True), "item": Key("table", required=True),
    "person": Key("list[table]", n_max=100), "equipment": Key("list[table]", n_max=1000),
    "environment": Key("table")}
CERTIFICATE_KEYS: dict[str, Key] = {
    "id": _str(True), "language": _str(), "country": _str(), "begin_date": Key("any"), "end_date": Key("any"),
    "receipt_date": Key("any"), "location": Key("str", choices=_LOCATIONS)}
CONTACT_KEYS: dict[str, Key] = {"name": _str(True), "email": _str(True),
                                **{k: _str() for k in sorted(_CONTACT_KEYS - {"name", "email"})}}
ITEM_KEYS: dict[str, Key] = {"name": _str(True), "manufacturer": _str(True), "serial": _str(True), "model": _str(),
                             "customer_id": _str(), "description": _str(n_max=_LONG)}
PERSON_KEYS: dict[str, Key] = {"name": _str(True), "role": _str(), "main_signer": Key("bool")}
EQUIPMENT_KEYS: dict[str, Key] = {k: _str(k == "name") for k in
                                  ("name", "manufacturer", "model", "serial", "certificate", "instrument")}
#: the range of an environment value by its unit suffix (value, and its standard uncertainty
#: ``*_u_<unit>``): the conditions a calibration lab works in, generously; any other unit ±1e6
ENV_RANGES: dict[str, tuple[tuple[float, float], tuple[float, float]]] = {
    "degC": ((-50.0, 100.0), (0.0, 50.0)), "K": ((223.15, 373.15), (0.0, 50.0)),
    "percent": ((0.0, 100.0), (0.0, 100.0)), "hPa": ((0.0, 2000.0), (0.0, 2000.0)),
    "Pa": ((0.0, 200000.0), (0.0, 200000.0))}
ENV_OTHER = ((-1e6, 1e6), (0.0, 1e6))
_ENV_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}\Z")


def _fail(msg: str) -> Exception:
    return CertificateInputError(msg)


def _check_text(where: str, data: Any) -> None:
    """No control character (a NUL, an escape sequence, a line break) in any string of the lab
    file: they are not XML characters, or would be written into the certificate as they are."""
    for v, at in leaves(data):
        if isinstance(v, str) and any(unicodedata.category(c) in ("Cc", "Cs") for c in v):
            raise CertificateInputError(f"{where}: key {at}: expected text without control characters "
                                        "(tab, line break, NUL, escape)")


def _s(where: str, table: Mapping[str, Any], key: str, default: str | None = None) -> str:
    v = table.get(key, default)
    if v is None:
        raise CertificateInputError(f"{where}: key {key!r} is required (a string)")
    if not isinstance(v, str) or not v.strip():
        raise CertificateInputError(f"{where}: key {key!r} must be a non-empty string, got {v!r}")
    return v


def _date(where: str, table: Mapping[str, Any], key: str, default: str | None) -> str | None:
    v = table.get(key, default)
    if v is None:
        return None
    if isinstance(v, _dt.date) and not isinstance(v, _dt.datetime):
        return v.isoformat()
    if isinstance(v, str):
        try:
            return _dt.date.fromisoformat(v).isoformat()
        except ValueError:
            pass
    raise CertificateInputError(f"{where}: key {key!r} must be a date YYYY-MM-DD, got {v!r}")


def _contact(where: str, t: Any) -> Contact:
    if not isinstance(t, Mapping):
        raise CertificateInputError(f"{where}: expected a table with name, email, city, country, ...")
    c = Contact(name=_s(where, t, "name"), email=_s(where, t, "email"),
                **{k: str(t[k]) for k in ("street", "street_no", "post_code", "city", "country", "phone") if k in t})
    if c.country and not (len(c.country) == 2 and c.country.isalpha() and c.country.isupper()):
        raise CertificateInputError(f"{where}: key 'country' must be an ISO 3166-1 code like 'DE', got {c.country!r}")
    return c


def parse_lab(data: Mapping[str, Any], source: str, today: str) -> LabFile:
    """Check a lab file's tables (docs/lab.example.toml; the keys declared in ``LAB_KEYS`` and
    the tables below it); errors name the file and the key."""
    for key in ("certificate", "laboratory", "customer", "item"):
        if isinstance(data, Mapping) and key not in data:
            raise CertificateInputError(f"{source}: table [{key}] is required")
    check_table(data, LAB_KEYS, source, fail=_fail)
    _check_text(source, data)
    check_table(data["certificate"], CERTIFICATE_KEYS, source, "[certificate]", fail=_fail)
    lab_keys = {**CONTACT_KEYS, "code": _str()}
    check_table(data["laboratory"], lab_keys, source, "[laboratory]", fail=_fail)
    check_table(data["customer"], CONTACT_KEYS, source, "[customer]", fail=_fail)
    check_table(data["item"], ITEM_KEYS, source, "[item]", fail=_fail)
    for i, p in enumerate(data.get("person", [])):
        check_table(p, PERSON_KEYS, source, f"[[person]] #{i + 1}", fail=_fail)
    for i, e in enumerate(data.get("equipment", [])):
        check_table(e, EQUIPMENT_KEYS, source, f"[[equipment]] #{i + 1}", fail=_fail)
    cert = data["certificate"]
    w = f"{source} [certificate]"
    lang = _s(w, cert, "language", "en")
    if not (len(lang) == 2 and lang.isalpha() and lang.islower()):
        raise CertificateInputError(f"{w}: key 'language' must be an ISO 639-1 code like 'en', got {lang!r}")
    country = _s(w, cert, "country")
    if not (len(country) == 2 and country.isalpha() and country.isupper()):
        raise CertificateInputError(f"{w}: key 'country' must be an ISO 3166-1 code like 'DE', got {country!r}")
    loc = _s(w, cert, "location", "laboratory")
    if loc not in _LOCATIONS:
        raise CertificateInputError(f"{w}: key 'location' must be one of {', '.join(_LOCATIONS)}, got {loc!r}")
    end = _date(w, cert, "end_date", today) or today
    begin = _date(w, cert, "begin_date", end) or end
    if begin > end:
        raise CertificateInputError(f"{w}: begin_date {begin} is after end_date {end}")
    lab = data["laboratory"]
    lab_code = str(lab.get("code", "")) if isinstance(lab, Mapping) else ""
    lab_t = {k: v for k, v in lab.items() if k != "code"} if isinstance(lab, Mapping) else lab
    item = data["item"]
    wi = f"{source} [item]"
    item_d = {"name": _s(wi, item, "name"), "manufacturer": _s(wi, item, "manufacturer"),
              "serial": _s(wi, item, "serial")}
    for k in ("model", "customer_id", "description"):
        if k in item:
            item_d[k] = _s(wi, item, k)
    persons = []
    for i, p in enumerate(data.get("person", [])):
        wp = f"{source} [[person]] #{i + 1}"
        if not isinstance(p, Mapping):
            raise CertificateInputError(f"{wp}: expected a table with name, role, main_signer")
        ms = p.get("main_signer", False)
        if not isinstance(ms, bool):
            raise CertificateInputError(f"{wp}: key 'main_signer' must be true or false, got {ms!r}")
        persons.append({"name": _s(wp, p, "name"), "role": p.get("role", ""), "main_signer": ms})
    if not persons:
        raise CertificateInputError(f"{source}: at least one [[person]] (the responsible person) is required")
    equipment = []
    for i, e in enumerate(data.get("equipment", [])):
        we = f"{source} [[equipment]] #{i + 1}"
        if not isinstance(e, Mapping):
            raise CertificateInputError(f"{we}: expected a table with name, manufacturer, model, serial, certificate")
        equipment.append({k: _s(we, e, k) for k in e})
        if "name" not in e:
            raise CertificateInputError(f"{we}: key 'name' is required")
    env = _environment(f"{source} [environment]", data.get("environment", {}))
    return LabFile(certificate_id=_s(w, cert, "id"), language=lang, country=country, begin_date=begin, end_date=end,
                   receipt_date=_date(w, cert, "receipt_date", None), location=loc,
                   laboratory=_contact(f"{source} [laboratory]", lab_t), laboratory_code=lab_code,
                   customer=_contact(f"{source} [customer]", data["customer"]), item=item_d, persons=persons,
                   equipment=equipment, environment=env, stated=True, source=source)


def _environment(where: str, env: Any) -> dict[str, float]:
    """The environment: names with a unit suffix, each a finite number within its unit's range
    (``ENV_RANGES``: temperature −50…100 °C, humidity 0…100 %, ...; an uncertainty ``*_u_<unit>``
    ≥ 0). Used for the lab file's [environment] and the manifest's ``environment`` alike."""
    if not isinstance(env, Mapping):
        raise CertificateInputError(f"{where}: expected a table of numbers such as temperature_degC = 20.1")
    if len(env) > 100:
        raise CertificateInputError(f"{where}: {len(env)} entries; at most 100 are allowed")
    out: dict[str, float] = {}
    for k, v in env.items():
        if not isinstance(k, str) or not _ENV_NAME.match(k):
            raise CertificateInputError(f"{where}: key {str(k)[:40]!r}: expected a name of ASCII letters, digits "
                                        "and '_' (at most 64), such as temperature_degC")
        base, unit = _unit_of(k)
        if unit == DSI_UNITS["one"] and not k.endswith("_one"):
            raise CertificateInputError(
                f"{where}: key {k!r} needs a unit suffix (_degC, _K, _percent, _hPa, _Pa), e.g. temperature_degC")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
            raise CertificateInputError(f"{where}: key {k!r} must be a finite number, got {str(v)[:40]!r}")
        suffix = k[len(base) + 1:]
        value_rng, u_rng = ENV_RANGES.get(suffix, ENV_OTHER)
        lo, hi = u_rng if base.endswith("_u") else value_rng
        if not lo <= v <= hi:
            raise CertificateInputError(f"{where}: key {k!r}: expected {lo:g}…{hi:g} {suffix}, got {str(v)[:40]}")
        out[k] = float(v)
    return out


def load_lab(path: str | Path | None, today: str) -> LabFile:
    """The lab file at ``path``, or placeholders ("not stated") when there is none (country "ZZ": the
    ISO 3166 user-assigned code commonly used for "unknown")."""
    if path is None:
        nc = Contact(name=NOT_STATED, email=NOT_STATED, city=NOT_STATED)
        return LabFile(certificate_id=f"benchtwin-{today}", language="en", country="ZZ", begin_date=today,
                       end_date=today, receipt_date=None, location="laboratory", laboratory=nc, laboratory_code="",
                       customer=nc, item={"name": "rotary encoder", "manufacturer": NOT_STATED, "serial": NOT_STATED},
                       persons=[{"name": NOT_STATED, "role": "", "main_signer": False}], equipment=[],
                       environment={}, stated=False)
    p = Path(path)
    if not p.exists() and not p.is_symlink():
        raise CertificateInputError(f"{p}: lab file not found")
    try:  # the one TOML reader: a regular file (a FIFO is refused, not opened), bounded size, depth, numbers
        data = load_toml_file(p, what="lab file", max_bytes=MAX_LAB_BYTES)
    except SchemaError as exc:
        raise CertificateInputError(str(exc)) from None
    return parse_lab(data, str(p), today)


# ----------------------------------------------------------------------------- results.json


def load_results(path: str | Path) -> Results:
    """results.json by the format's one reader (analysis.results: ``read_results_text``, a regular
    file of bounded size; strict JSON; ``Results.checked``, the type of every key), then what a
    certificate needs: the encoder error curve, and every number within its unit's range."""
    p = Path(path)
    if not p.exists() and not p.is_symlink():
        raise CertificateInputError(f"{p}: results file not found")
    try:
        text = read_results_text(p)
    except ResultsError as exc:
        raise CertificateInputError(str(exc)) from None
    try:
        obj = loads_json(text, str(p))
    except SchemaError as exc:
        raise CertificateInputError(f"{p}: not a JSON file ({str(exc).removeprefix(str(p) + ': ')})") from None
    try:
        res = Results.checked(obj, str(p))
    except ResultsError as exc:
        raise CertificateInputError(str(exc)) from None
    if not isinstance(res.get("encoder_error_arcsec"), Mapping):
        raise CertificateInputError(
            f"{p}: key 'encoder_error_arcsec' is required: a certificate states the encoder error, which needs the "
            "polygon measurement (polygon.csv) in the dataset")
    _check_ranges(res, str(p))
    return res


#: the ranges of what a certificate states (as the dataset reader's unit ranges: angles of a turn,
#: errors within ±10°), and of the coverage factor and probability it states them with
_CURVE_RANGES = {"theta_deg": (-360.0, 720.0), "value": (-36000.0, 36000.0), "u": (0.0, 36000.0),
                 "U": (0.0, 36000.0)}


def _check_ranges(res: Mapping[str, Any], where: str) -> None:
    """Numbers the certificate states within their ranges (a k below 1 was an internal error)."""
    bs = res.get("budget_summary")
    if isinstance(bs, Mapping):
        for key, lo, hi in (("k", 1.0, 100.0), ("p", 1e-9, 1.0)):
            v = bs.get(key)
            if isinstance(v, (int, float)) and not isinstance(v, bool) and not lo <= v <= hi:
                raise CertificateInputError(f"{where}: key 'budget_summary.{key}': expected {lo:g}…{hi:g}, got {v!r}")
    for curve in ("encoder_error_arcsec", "encoder_error_corrected_arcsec", "selfcal_error_arcsec"):
        d = res.get(curve)
        if not isinstance(d, Mapping):
            continue
        for key, (lo, hi) in _CURVE_RANGES.items():
            vals = d.get(key)
            if not isinstance(vals, list):
                continue
            for i, v in enumerate(vals):
                if isinstance(v, (int, float)) and not isinstance(v, bool) and not lo <= v <= hi:
                    raise CertificateInputError(f"{where}: {curve}.{key}[{i}]: expected {lo:g}…{hi:g}, got {v!r}")


def _series(where: str, d: Mapping[str, Any], key: str, n: int | None = None, positive: bool = False) -> list[float]:
    v = d.get(key)
    if not isinstance(v, Sequence) or isinstance(v, str) or not v:
        raise CertificateInputError(f"{where}: key {key!r} must be a non-empty list of numbers")
    out = []
    for i, x in enumerate(v):
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or (positive and x <= 0):
            raise CertificateInputError(f"{where}: {key}[{i}] must be a finite{' positive' if positive else ''} number, got {x!r}")
        out.append(float(x))
    if n is not None and len(out) != n:
        raise CertificateInputError(f"{where}: key {key!r} has {len(out)} values, expected {n} (one per angle)")
    return out


def _number(where: str, d: Mapping[str, Any], key: str, positive: bool = False) -> float:
    x = d.get(key)
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or (positive and x <= 0):
        raise CertificateInputError(f"{where}: key {key!r} must be a finite{' positive' if positive else ''} number, got {x!r}")
    return float(x)


def encoder_curve(res: Mapping[str, Any], src: str) -> dict[str, Any]:
    """The curve the certificate states (analysis/calibration.py, the same as calibration.csv): the
    loop's corrected curve when a correction of the reference chain was applied, else the measured
    encoder error; values, U and the k, p, ν and distribution they were expanded with, and what u
    includes and excludes (``cal``: the :class:`CalibrationCurve`). Each list is checked first, so
    bad input names its key and index (exit 2)."""
    from benchtwin.analysis.calibration import calibration_curve

    # results.json's encoder_error_corrected_arcsec (analysis/pipeline.py corrected_curve) equals the
    # measured curve when nothing was identified; it is stated as corrected only when a correction
    # of the reference chain was applied (calibration_curve names the corrections)
    key = "encoder_error_arcsec"
    corrected = res.get("encoder_error_corrected_arcsec")
    if isinstance(corrected, Mapping) and corrected.get("value") and corrected.get("corrections_applied"):
        key = "encoder_error_corrected_arcsec"
    d = res[key]
    w = f"{src}: {key}"
    theta = _series(w, d, "theta_deg")
    _series(w, d, "value", len(theta))
    _series(w, d, "u", len(theta), positive=True)
    if d.get("U") and key == "encoder_error_arcsec":
        _series(w, d, "U", len(theta), positive=True)
    try:
        cal = calibration_curve(res)
    except (ValueError, TypeError, KeyError) as exc:
        raise CertificateInputError(f"{src}: {exc}") from None
    if cal is None:
        raise CertificateInputError(f"{w}: no encoder error curve")
    return {"key": cal.key, "label": cal.label, "theta_deg": list(cal.theta_deg), "value": list(cal.error_arcsec),
            "U": list(cal.U_arcsec), "k": cal.k, "p": cal.p, "nu": cal.nu, "distribution": cal.distribution,
            "cal": cal}


# ----------------------------------------------------------------------------- XML building


def _el(parent: etree._Element, tag: str, text: str | None = None, ns: str = DCC_NS, **attrib: str) -> etree._Element:
    e = etree.SubElement(parent, f"{{{ns}}}{tag}", {k: v for k, v in attrib.items() if v})
    if text is not None:
        e.text = text
    return e


def _text(parent: etree._Element, tag: str, text: str, lang: str) -> etree._Element:
    t = _el(parent, tag)
    _el(t, "content", text, lang=lang)
    return t


def _contact_xml(parent: etree._Element, tag: str, c: Contact, lang: str, strict: bool = True) -> etree._Element:
    e = _el(parent, tag)
    _text(e, "name", c.name, lang)
    if strict or c.email:
        _el(e, "eMail", c.email or NOT_STATED)
    if c.phone:
        _el(e, "phone", c.phone)
    loc_fields = [("city", c.city), ("countryCode", c.country), ("postCode", c.post_code), ("street", c.street),
                  ("streetNo", c.street_no)]
    if strict or any(v for _, v in loc_fields):
        loc = _el(e, "location")
        wrote = False
        for tag_, v in loc_fields:
            if v:
                _el(loc, tag_, v)
                wrote = True
        if not wrote:
            _el(loc, "city", NOT_STATED)
    return e


def _real(parent: etree._Element, label: str, x: float, unit: str, U: float | None = None,
          cov: Coverage = DEFAULT_COVERAGE) -> etree._Element:
    """si:real: the value rounded to its U (with U's coverage), or the plain value without U."""
    r = _el(parent, "real", ns=SI_NS)
    _el(r, "label", label, ns=SI_NS)
    if U is None:
        _el(r, "value", repr(float(x)), ns=SI_NS)
        _el(r, "unit", unit, ns=SI_NS)
        return r
    v, Us = value_and_U(x, U)
    _el(r, "value", v, ns=SI_NS)
    _el(r, "unit", unit, ns=SI_NS)
    eu = _el(r, "expandedUnc", ns=SI_NS)
    _el(eu, "uncertainty", Us, ns=SI_NS)
    _el(eu, "coverageFactor", _k_str(cov.k), ns=SI_NS)
    _el(eu, "coverageProbability", _p_str(cov.p), ns=SI_NS)
    _el(eu, "distribution", cov.distribution, ns=SI_NS)
    return r


def _real_list(parent: etree._Element, labels: Sequence[str] | None, values: Sequence[float], unit: str,
               U: Sequence[float] | None = None, cov: Coverage = DEFAULT_COVERAGE,
               decimals: int | None = None) -> etree._Element:
    """si:realListXMLList: one unit for all, each value rounded to its own U (or to ``decimals``)."""
    r = _el(parent, "realListXMLList", ns=SI_NS)
    if labels is not None:
        _el(r, "labelXMLList", " ".join(labels), ns=SI_NS)
    if U is not None:
        pairs = [value_and_U(x, u) for x, u in zip(values, U)]
        _el(r, "valueXMLList", " ".join(a for a, _ in pairs), ns=SI_NS)
    else:
        _el(r, "valueXMLList", " ".join(_dec(x, decimals) if decimals is not None else repr(float(x)) for x in values),
            ns=SI_NS)
    _el(r, "unitXMLList", unit, ns=SI_NS)
    if U is not None:
        eu = _el(r, "expandedUncXMLList", ns=SI_NS)
        _el(eu, "uncertaintyXMLList", " ".join(b for _, b in pairs), ns=SI_NS)
        _el(eu, "coverageFactorXMLList", _k_str(cov.k), ns=SI_NS)
        _el(eu, "coverageProbabilityXMLList", _p_str(cov.p), ns=SI_NS)
        _el(eu, "distributionXMLList", cov.distribution, ns=SI_NS)
    return r


def _quantity(parent: etree._Element, name: str, lang: str, ref: str = "") -> etree._Element:
    q = _el(parent, "quantity", refType=ref)
    _text(q, "name", name, lang)
    return q


def _result(results: etree._Element, name: str, lang: str, ref: str, description: str = "") -> etree._Element:
    r = _el(results, "result", refType=ref)
    _text(r, "name", name, lang)
    if description:
        _text(r, "description", description, lang)
    return _el(r, "data")


def _statement(parent: etree._Element, text: str, lang: str, ref: str, norm: str = "", reference: str = "") -> None:
    s = _el(parent, "statement", refType=ref)
    if norm:
        _el(s, "norm", norm)
    if reference:
        _el(s, "reference", reference)
    _text(s, "declaration", text, lang)


def _shifts(res: Mapping[str, Any]) -> list[float]:
    """The shift angles the polygon was measured at (the keys of results.json's setup errors)."""
    out = []
    for key in res.get("setup_error_arcsec") or {}:
        try:
            out.append(float(key))
        except ValueError:
            continue
    return sorted(out)


def _reference_chain(res: Mapping[str, Any]) -> str:
    """The reference of a bench dataset in words: the polygon and the autocollimator as the analysis
    used them (declared in the dataset manifest, or assumed and said so)."""
    b = res.get("bench") or {}
    faces = b.get("polygon_faces")
    beta = ("its pitch deviations taken from its certificate" if b.get("polygon_certificate_arcsec") is not None
            else "its pitch deviations determined with the encoder by the closure condition")
    s = f"a {faces}-face optical polygon ({beta})" if faces else f"an optical polygon ({beta})"
    ac = res.get("autocollimator_declared") or {}
    if ac:
        decl = ("declared in the dataset manifest" if ac.get("source") == "manifest"
                else "not declared by the dataset: the values of Hsieh 2022's ELCOMAT 3000 assumed in the budget")
        s += (f", read by an autocollimator (resolution {float(ac['resolution_arcsec']):g} arcsec, maximum error "
              f"{float(ac['accuracy_arcsec']):g} arcsec; {decl})")
    else:
        s += ", read by an autocollimator"
    return s


def _methods_used(res: Mapping[str, Any]) -> list[tuple[str, str, str, str, str]]:
    """(name, refType, description, norm, reference) of each method the analysis ran on this dataset."""
    used: list[tuple[str, str, str, str, str]] = []
    if res.get("kind") == "error-curve":
        imp = res.get("imported_from") or {}
        cols = ", ".join(f"{k.removesuffix('_column')} = {imp[k]}" for k in ("angle_column", "error_column",
                                                                              "reverse_column", "u_column")
                         if imp.get(k))
        up = res.get("u_point") or {}
        used.append(("imported measured error curve", "benchtwin_importedCurve",
                     f"The encoder error as listed in an imported table ({Path(str(imp.get('table'))).name if imp.get('table') else NOT_STATED}"
                     + (f"; {cols}" if cols else "") + "), read with benchtwin import; the mean of the directions "
                     "at each angle is stated. How the table was measured and against which reference instrument "
                     "are not known.", "", ""))
        used.append(("error-curve analysis", "benchtwin_errorCurve",
                     "Coverage, closure, hysteresis between the directions and harmonics with their standard "
                     "uncertainties (benchtwin analysis/error_curve.py); a lone curve identifies no cause.", "", ""))
        used.append(("type A evaluation of the uncertainty", "basic_GUM",
                     f"Standard uncertainty of each point: {up.get('source', NOT_STATED)}.", "JCGM 100:2008", ""))
        return used + _methods_used_curve(res)
    if res.get("encoder_error_arcsec") is not None:
        shifts = _shifts(res)
        starts = {k: len(v) for k, v in (res.get("setup_error_arcsec") or {}).items() if isinstance(v, Sequence)}
        ref = _reference_chain(res)
        if len(shifts) > 1:
            used.append(("shift-angle method", "benchtwin_shiftAngle",
                         f"Cross-calibration of the encoder against {ref}, at {len(shifts)} shift angles "
                         f"(S = {', '.join(f'{x:g}' for x in shifts)} deg); the polygon's pitch deviations and the "
                         "encoder error separate by the closure condition (Hsieh eqs. 1-3).",
                         "", "Hsieh, Watanabe, Hsu 2022, Appl. Sci. 12, 5008, sec. 2.2"))
        else:
            n0 = next(iter(starts.values()), None)
            used.append(("polygon cross-calibration", "benchtwin_polygonCrossCalibration",
                         f"Cross-calibration of the encoder against {ref}, at one shift angle"
                         + (f" (S = {shifts[0]:g} deg)" if shifts else "")
                         + (f" from {n0} start faces" if n0 else "") + "; the polygon's pitch deviations and the "
                         "encoder error separate by the closure condition (Hsieh eqs. 1-3).",
                         "", "Hsieh, Watanabe, Hsu 2022, Appl. Sci. 12, 5008, sec. 2.1"))
    if res.get("selfcal_error_arcsec"):
        used.append(("multi-head self-calibration", "benchtwin_selfCalibration",
                     "Equal-division-averaged self-calibration from several reading heads of the encoder (Hsieh "
                     "sec. 2.3).", "", "Hsieh, Watanabe, Hsu 2022, Appl. Sci. 12, 5008, sec. 2.3"))
    if res.get("model_prediction_arcsec") is not None:
        used.append(("Jia error model", "benchtwin_jiaModel",
                     "Angle error from installation eccentricity (CCD images of the grating edge)"
                     + (" and radial error motion (two test spheres)" if res.get("radial_motion") is not None else "")
                     + ": Δθ = [e·sin(θ−θ0) + ∫δY dθ]/r, compared with the measured encoder error.",
                     "", "Jia et al. 2019, Appl. Sci. 9, 3415, eqs. 5-13"))
    if "identified_effects" in res and res.get("residual_before") is not None:
        used.append(("residual tracing", "benchtwin_closeLoop",
                     "The residual of the error model tested for significance and traced to effects of the benchtwin "
                     "library (docs/effects.md); a correction of the reference chain is applied to the stated curve "
                     "only when such an effect is identified.", "", ""))
    bs = res.get("budget_summary") or {}
    if bs:
        mc = bs.get("monte_carlo") or {}
        check = ""
        if mc:
            check = (", validated to one significant digit by a Monte Carlo method (JCGM 101)"
                     if mc.get("validated_1_digit") else
                     "; a Monte Carlo method (JCGM 101) did not validate it to one significant digit")
        used.append(("GUM uncertainty evaluation", "basic_GUM",
                     "Standard uncertainties by the GUM law of propagation with Welch-Satterthwaite effective degrees "
                     f"of freedom (Hsieh 2022 sec. 3.3, Table 3){check}.", "JCGM 100:2008", ""))
    if res.get("radial_error_motion"):
        used.append(("ISO 230-7 radial error motion", "benchtwin_iso230_7",
                     "Total, synchronous and asynchronous radial error motion, fixed sensitive direction, fundamental "
                     f"removed, about the least-squares centre. {_iso230_7_conditions(res['radial_error_motion'])}",
                     "ISO 230-7:2015", ""))
    return used + _methods_used_curve(res)


def _methods_used_curve(res: Mapping[str, Any]) -> list[tuple[str, str, str, str, str]]:
    """The ISO 230-2 statistics and the period scan of an arc, when the analysis made them."""
    used: list[tuple[str, str, str, str, str]] = []
    iso = res.get("iso230_2")
    if isinstance(iso, Mapping) and iso.get("figures"):
        used.append(("ISO 230-2 positioning statistics", "benchtwin_iso230_2",
                     f"Accuracy, systematic deviation, repeatability and reversal of the rotary axis from runs in both "
                     f"directions ({iso.get('source', NOT_STATED)}); {iso.get('convention', '')}.",
                     "ISO 230-2:2014", ""))
    scan = res.get("arc_period_scan")
    if res.get("arc_periods") is not None and isinstance(scan, Mapping):
        used.append(("period scan over an arc", "benchtwin_arcPeriods",
                     f"Periodic components the measured arc supports: {scan.get('method', NOT_STATED)}; false-alarm "
                     f"probability {scan.get('false_alarm_method', NOT_STATED)}. No turn harmonics and no closure are "
                     "claimed for an arc.", "", "Zechmeister & Kürster 2009, A&A 496, 577; Baluev 2008, MNRAS 385, 1279"))
    return used


def _iso230_7_conditions(rem: Mapping[str, Any]) -> str:
    """Speed and bandwidth of the ISO 230-7 values in words (analysis/iso230_7.py bandwidth, acquisition)."""
    acq, bw = rem.get("acquisition"), rem.get("bandwidth")
    speed = (f"Speed: {acq['text']}." if isinstance(acq, Mapping) and acq.get("text") else
             "Speed: not stated by the results (an older results.json).")
    band = (f"Bandwidth: {bw['text']}." if isinstance(bw, Mapping) and bw.get("text") else
            "Bandwidth: not stated by the results (an older results.json).")
    return f"{speed} {band}"


def _ambiguity(res: Mapping[str, Any]) -> str:
    """The ambiguity sets the analysis reported, with what would separate them."""
    from benchtwin.analysis.calibration import LONE_CURVE_SEPARATION, ambiguities

    words = ambiguities(res)
    if not words:
        return ""
    if res.get("kind") == "error-curve":
        return f" The data cannot tell apart: {'; '.join(words)} ({LONE_CURVE_SEPARATION} would separate them)."
    seps = [str(a.get("separating_measurement") or "") for a in res.get("ambiguous") or []]
    return " The data cannot tell apart: " + "; ".join(
        w + (f" (separating measurement: {sep})" if sep else "") for w, sep in zip(words, seps)) + "."


def _residual_test(r: Mapping[str, Any]) -> str:
    """What a residual can test, in brackets (results.json residual_before / residual_after: the
    stops, the parameters fitted, dof, χ², leave-one-out); empty for results without these keys."""
    if r.get("dof") is None:
        return ""
    p, loo = r.get("p_value"), r.get("loo_rms_arcsec")
    return (f"({r['n_points']} stops, {r['n_params']} parameter{'' if r['n_params'] == 1 else 's'} fitted, "
            f"{r['dof']} degrees of freedom, chi2 "
            f"{r['chi2']:.3g}" + ("" if p is None else f", p = {p:.2g}") + "; each stop predicted by the fit made "
            "without it: " + ("no such fit" if loo is None else f"{loo:.3g} arcsec RMS") + ")")


def _estimator_clause(e: Mapping[str, Any]) -> str:
    """How an identified effect whose regressor is measured was estimated (its results'
    ``estimator``, analysis/tracing/errors_in_variables.py), as the analysis did it: "" for the
    others."""
    est = e.get("estimator")
    if not isinstance(est, Mapping):
        return ""
    if est.get("adopted"):
        return ("; estimated with its measured regressor's own uncertainty (errors in variables, Deming's "
                "joint least squares)")
    return ("; the selection's fit of the measured regressor: the errors-in-variables estimate was not adopted ("
            f"{est.get('why_not', 'implausible')})")


def effects_statement(res: Mapping[str, Any]) -> str:
    """What the analysis concluded about the causes of the error, in sentences a reader can check:
    only the models it ran, the effects it identified and the ambiguities it reported."""
    amb = _ambiguity(res)
    if "identified_effects" not in res:
        return "The causes of the error were not traced (the loop was not closed)." + amb
    eff = res.get("identified_effects") or []
    rb, ra = res.get("residual_before") or {}, res.get("residual_after") or {}
    if res.get("kind") == "error-curve":
        return ("No effect was identified: a lone error curve cannot tell causes apart (no error model was "
                "compared with it)." + amb)
    if not eff:
        model = "the Jia error model" if res.get("model_prediction_arcsec") is not None else "the error model"
        extra = " It is significant but no effect of the library explains it." if res.get("unexplained") else ""
        return f"No effect beyond {model} was identified in the residual.{extra}{amb}"
    parts = []
    for e in eff:
        ps = ", ".join(f"{k} = {v:.4g} ± {e.get('u', {}).get(k, float('nan')):.2g}" for k, v in e.get("params", {}).items())
        parts.append(f"{e['name']} ({ps}; standard uncertainties{_estimator_clause(e)})")
    s = "The loop identified: " + "; ".join(parts) + "."
    if rb.get("rms_arcsec") is not None and ra.get("rms_arcsec") is not None:
        s += (f" With it the residual of the error model went from {rb['rms_arcsec']:.3f} arcsec RMS "
              f"{_residual_test(rb)} to {ra['rms_arcsec']:.3f} arcsec RMS {_residual_test(ra)}.")
        if ra.get("sampling_note"):
            s += f" The residual after: {ra['sampling_note']}."
        ref = res.get("eccentricity_refined")
        if isinstance(ref, Mapping) and ref.get("e_um") is not None:
            k1 = ref.get("k1_prior") or {}
            s += (f" The model after the loop takes the eccentricity from the CCD combined with the first harmonic "
                  f"of the comparison: e = {ref['e_um']:.3f} ± {ref['u_e_um']:.2g} µm (CCD alone "
                  f"{ref['ccd']['e_um']:.3f} ± {ref['ccd']['u_e_um']:.2g} µm; consistency p = {ref['p_value']:.2g}"
                  + (f"; its u includes a first-order graduation term, which the comparison cannot tell from "
                     f"eccentricity, of {k1['u_arcsec']:.2g} arcsec per component" if k1.get("u_arcsec") else "")
                  + ").")
    return s + amb


def build_certificate(res: Mapping[str, Any], lab: LabFile, manifest: Mapping[str, Any] | None = None,
                      src: str = "results.json") -> etree._ElementTree:
    """The DCC as an lxml tree (pure: no I/O). ``res``: results.json; ``manifest``: the dataset's.
    In the DCC's order: the administrative data (software, core data, item, laboratory and persons,
    statements), then the measurement result (methods, software, equipment, influence conditions,
    and one result per quantity)."""
    lang = lab.language
    man = manifest or {}
    root = etree.Element(f"{{{DCC_NS}}}digitalCalibrationCertificate", nsmap=NSMAP, schemaVersion=SCHEMA_VERSION)
    adm = _el(root, "administrativeData")
    _software(_el(adm, "dccSoftware"), lang)
    _core_data(adm, lab, lang)
    _items(adm, lab, lang)
    _laboratory_and_persons(adm, lab, lang)
    curve = encoder_curve(res, src)
    _statements(adm, res, lab, man, curve["cal"])

    # ----------------------------------------------------------------- measurement results
    mr = _el(_el(root, "measurementResults"), "measurementResult")
    _text(mr, "name", "Angle calibration of a rotary encoder", lang)
    _used_methods(mr, res, lang)
    _software(_el(mr, "usedSoftware"), lang)
    # an imported table names no instrument and no environment: the lab file's (its bench's) are not
    # claimed for it (said in a statement)
    imported = res.get("kind") == "error-curve"
    _measuring_equipment(mr, man, lab, imported)
    _influence_conditions(mr, man, lab, imported)
    results = _el(mr, "results")
    _encoder_error_result(results, res, curve, lang)
    _selfcal_result(results, res, src, lang)
    _pitch_result(results, res, src, lang)
    _eccentricity_result(results, res, src, lang)
    _radial_motion_result(results, res, src, lang)
    _iso230_2_result(results, res, src, lang)
    _arc_periods_result(results, res, src, lang)
    _effects_result(results, res, lang)
    return etree.ElementTree(root)


def _software(parent: etree._Element, lang: str) -> None:
    sw = _el(parent, "software")
    _text(sw, "name", "benchtwin", lang)
    _el(sw, "release", __version__)
    _el(sw, "type", "application")


def _core_data(adm: etree._Element, lab: LabFile, lang: str) -> None:
    core = _el(adm, "coreData")
    _el(core, "countryCodeISO3166_1", lab.country)
    _el(core, "usedLangCodeISO639_1", lang)
    _el(core, "mandatoryLangCodeISO639_1", lang)
    _el(core, "uniqueIdentifier", lab.certificate_id)
    if lab.receipt_date:
        _el(core, "receiptDate", lab.receipt_date)
    _el(core, "beginPerformanceDate", lab.begin_date)
    _el(core, "endPerformanceDate", lab.end_date)
    _el(core, "performanceLocation", lab.location)


def _items(adm: etree._Element, lab: LabFile, lang: str) -> None:
    items = _el(adm, "items")
    item = _el(items, "item")
    _text(item, "name", lab.item["name"], lang)
    if lab.item.get("description"):
        _text(item, "description", lab.item["description"], lang)
    man_el = _el(item, "manufacturer")
    _text(man_el, "name", lab.item["manufacturer"], lang)
    if lab.item.get("model"):
        _el(item, "model", lab.item["model"])
    ids = _el(item, "identifications")
    ident = _el(ids, "identification")
    _el(ident, "issuer", "manufacturer")
    _el(ident, "value", lab.item["serial"])
    _text(ident, "name", "serial number", lang)
    if lab.item.get("customer_id"):
        ident = _el(ids, "identification")
        _el(ident, "issuer", "customer")
        _el(ident, "value", lab.item["customer_id"])
        _text(ident, "name", "customer's inventory number", lang)


def _laboratory_and_persons(adm: etree._Element, lab: LabFile, lang: str) -> None:
    cl = _el(adm, "calibrationLaboratory")
    if lab.laboratory_code:
        _el(cl, "calibrationLaboratoryCode", lab.laboratory_code)
    _contact_xml(cl, "contact", lab.laboratory, lang)
    rps = _el(adm, "respPersons")
    for p in lab.persons:
        rp = _el(rps, "respPerson")
        _text(_el(rp, "person"), "name", p["name"], lang)
        if p.get("role"):
            _el(rp, "role", p["role"])
        if p.get("main_signer"):
            _el(rp, "mainSigner", "true")
    _contact_xml(adm, "customer", lab.customer, lang)


def _statements(adm: etree._Element, res: Mapping[str, Any], lab: LabFile, man: Mapping[str, Any],
                cal: Any) -> None:
    """Where the values come from (imported, simulated, measured), what is not stated, the
    uncertainty's convention, the identified effects and the analysis's notes."""
    lang = lab.language
    st = _el(adm, "statements")
    source = str(res.get("source", man.get("source", "unknown")))
    if res.get("kind") == "error-curve":
        imp = res.get("imported_from") or {}
        _statement(st, "The values are an imported measured error curve, not a measurement made with benchtwin: table "
                       f"{imp.get('table', NOT_STATED)!s}, read with benchtwin import (data source: {source}; "
                       f"{imp.get('convention', 'convention not stated')!s}). The reference instrument, its "
                       "traceability, the method and the conditions of the original measurement are unknown.",
                   lang, "benchtwin_importedCurve")
    elif source == "twin":
        _statement(st, f"The values were obtained on the benchtwin digital twin (scenario "
                       f"{man.get('scenario', NOT_STATED)!s}, seed {man.get('seed', NOT_STATED)!s}), not on a physical "
                       "item: they describe the simulated bench.", lang, "benchtwin_simulated")
    else:
        _statement(st, f"Measured data source: {source}.", lang, "benchtwin_dataSource")
    if res.get("kind") == "error-curve" and (lab.equipment or lab.environment):
        _statement(st, f"The measuring equipment and environment of the lab file ({lab.source}) are not stated for "
                       "this imported curve: the table does not say with which instruments and under which "
                       "conditions it was measured.", lang, "benchtwin_importedCurveEquipment")
    if not lab.stated:
        _statement(st, "No lab file was given: laboratory, customer, item and responsible person are not stated.",
                   lang, "benchtwin_adminNotStated")
    _statement(st, "The expanded uncertainties are the standard uncertainties multiplied by the coverage factor k "
                   f"stated with them. Encoder error: k = {cal.k:.2f}, {cal.k_source}; its u includes {cal.u_includes}; it does not include {cal.u_excludes}. "
                   "Elsewhere k = 2 (normal distribution, about 95 %), and each result says what its U includes.",
               lang, "basic_uncertainty", norm="JCGM 100:2008", reference="EA-4/02 M:2022")
    _statement(st, effects_statement(res), lang, "benchtwin_identifiedEffects")
    for n in res.get("notes") or []:
        _statement(st, str(n), lang, "benchtwin_note")


def _used_methods(mr: etree._Element, res: Mapping[str, Any], lang: str) -> None:
    um = _el(mr, "usedMethods")
    for name, ref, desc, norm, reference in _methods_used(res):
        m = _el(um, "usedMethod", refType=ref)
        _text(m, "name", name, lang)
        _text(m, "description", desc, lang)
        if norm:
            _el(m, "norm", norm)
        if reference:
            _el(m, "reference", reference)


def _measuring_equipment(mr: etree._Element, man: Mapping[str, Any], lab: LabFile, imported: bool) -> None:
    lang = lab.language
    equipment = _equipment(man, lab) if not imported else []
    if equipment:
        me = _el(mr, "measuringEquipments")
        for e in equipment:
            eq = _el(me, "measuringEquipment", refType=f"benchtwin_{e.get('instrument', 'instrument')}")
            _text(eq, "name", e["name"], lang)
            if e.get("certificate"):
                c = _el(eq, "certificate")
                _text(c, "referral", "calibration certificate", lang)
                _el(c, "referralID", e["certificate"])
                _el(c, "procedure", NOT_STATED)
                _el(c, "value", NOT_STATED)
            if e.get("manufacturer"):
                _text(_el(eq, "manufacturer"), "name", e["manufacturer"], lang)
            if e.get("model"):
                _el(eq, "model", e["model"])
            if e.get("serial"):
                i = _el(_el(eq, "identifications"), "identification")
                _el(i, "issuer", "manufacturer")
                _el(i, "value", e["serial"])


def _influence_conditions(mr: etree._Element, man: Mapping[str, Any], lab: LabFile, imported: bool) -> None:
    """The environment of the manifest, else of the lab file (not for an imported table)."""
    lang = lab.language
    env = dict(man.get("environment") or {}) if isinstance(man.get("environment"), Mapping) else {}
    env_src = "the dataset manifest"
    if not env and lab.environment and not imported:
        env, env_src = lab.environment, lab.source
    env = {k: v for k, v in env.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    if env:
        ic = _el(mr, "influenceConditions")
        for k in sorted(env):
            base, unit = _unit_of(k)
            if base.endswith("_u"):
                continue  # a standard uncertainty of another entry
            c = _el(ic, "influenceCondition", refType=f"basic_{base}")
            _text(c, "name", base.replace("_", " "), lang)
            _text(c, "description", f"from {env_src}", lang)
            u_key = f"{base}_u_{k[len(base) + 1:]}"
            u = env.get(u_key)
            q = _quantity(_el(c, "data"), base.replace("_", " "), lang)
            _real(q, base, float(env[k]), unit, K_DEFAULT * float(u) if u else None)


def _encoder_error_result(results: etree._Element, res: Mapping[str, Any], curve: Mapping[str, Any],
                          lang: str) -> None:
    """The encoder error at every calibrated angle, the reference angle and the corrections applied."""
    cal = curve["cal"]
    corr = [c for c in (res.get(cal.key) or {}).get("corrections_applied") or [] if isinstance(c, Mapping)]
    corr_s = ("Corrections applied: " + "; ".join(
        f"{c.get('effect')} ({float(c['rms_arcsec']):.3f} arcsec RMS)" if isinstance(c.get("rms_arcsec"), (int, float))
        else str(c.get("effect")) for c in corr) + ".") if corr else "No correction applied to the values."
    d = _result(results, "Encoder error", lang, "benchtwin_encoderError",
                f"Encoder error α = encoder reading − reference angle at every calibrated angle: {cal.label}. "
                f"Constant: {cal.constant}. {corr_s} U = k·u, k = {cal.k:.2f}, {cal.k_source}. "
                f"u includes {cal.u_includes}. It does not include {cal.u_excludes}.")
    lst = _el(d, "list")
    # the DCC's own refTypes first (readers look for them), benchtwin's as the additional one
    q = _quantity(lst, "encoder reading (calibrated angle)", lang, "basic_measuredValue benchtwin_angle")
    _real_list(q, None, curve["theta_deg"], DSI_UNITS["deg"], decimals=6)
    q = _quantity(lst, "reference angle (encoder reading − encoder error)", lang,
                  "basic_referenceValue benchtwin_referenceAngle")
    _real_list(q, None, [t - a / 3600.0 for t, a in zip(curve["theta_deg"], curve["value"])], DSI_UNITS["deg"],
               [U / 3600.0 for U in curve["U"]], Coverage(curve["k"], curve["p"], curve["distribution"]))
    q = _quantity(lst, "encoder error", lang, "basic_measurementError benchtwin_encoderErrorValue")
    _real_list(q, None, curve["value"], DSI_UNITS["arcsec"], curve["U"],
               Coverage(curve["k"], curve["p"], curve["distribution"]))


def _selfcal_result(results: etree._Element, res: Mapping[str, Any], src: str, lang: str) -> None:
    sc = res.get("selfcal_error_arcsec")
    if isinstance(sc, Mapping) and sc.get("value"):
        w = f"{src}: selfcal_error_arcsec"
        th = _series(w, sc, "theta_deg")
        d = _result(results, "Encoder error by self-calibration", lang, "benchtwin_selfCalibrationError",
                    "Encoder error from the multi-head self-calibration (Hsieh sec. 2.3), mean removed. U = 2·u "
                    "(normal distribution): u is the repeatability of the heads' readings propagated through Hsieh "
                    "eq. 9 with the encoder's resolution; the harmonics the head sets cannot see are absent from "
                    "the values and not included in U.")
        lst = _el(d, "list")
        _real_list(_quantity(lst, "encoder reading (calibrated angle)", lang, "basic_measuredValue benchtwin_angle"),
                   None, th, DSI_UNITS["deg"], decimals=6)
        _real_list(_quantity(lst, "encoder error", lang, "basic_measurementError benchtwin_encoderErrorValue"), None,
                   _series(w, sc, "value", len(th)), DSI_UNITS["arcsec"],
                   [K_DEFAULT * u for u in _series(w, sc, "u", len(th), positive=True)])


def _pitch_result(results: etree._Element, res: Mapping[str, Any], src: str, lang: str) -> None:
    if res.get("polygon_pitch_deviation_arcsec"):
        beta = _series(src, res, "polygon_pitch_deviation_arcsec")
        u_beta = _series(src, res, "polygon_pitch_deviation_u_arcsec", len(beta), positive=True)
        d = _result(results, "Polygon pitch deviations", lang, "benchtwin_polygonPitchDeviation",
                    "Pitch deviation β of each polygon face (Hsieh eq. 1, sum zero), determined with the encoder. "
                    "U = 2·u (normal distribution): u is the repeatability of the autocollimator readings propagated "
                    "to β (type A); it does not include the autocollimator's own error or its traceability.")
        lst = _el(d, "list")
        _real_list(_quantity(lst, "face", lang, "benchtwin_face"), None, list(range(1, len(beta) + 1)),
                   DSI_UNITS["one"], decimals=0)
        _real_list(_quantity(lst, "pitch deviation", lang, "benchtwin_pitchDeviationValue"), None, beta,
                   DSI_UNITS["arcsec"], [K_DEFAULT * u for u in u_beta])


def _eccentricity_result(results: etree._Element, res: Mapping[str, Any], src: str, lang: str) -> None:
    if res.get("eccentricity_um") is not None:
        d = _result(results, "Installation eccentricity", lang, "benchtwin_eccentricity",
                    "Eccentricity of the grating relative to the axis from the CCD images of its edge (Jia eqs. 10-12). "
                    f"U = 2·u (normal distribution); u: {res.get('eccentricity_u_source', NOT_STATED)!s}. It does not "
                    "include a change of the mounting after the calibration.")
        q = _quantity(d, "eccentricity e", lang, "benchtwin_eccentricityValue")
        _real(q, "e", _number(src, res, "eccentricity_um"), DSI_UNITS["um"],
              K_DEFAULT * _number(src, res, "eccentricity_u_um", positive=True))
        q = _quantity(d, "eccentricity phase θ0", lang, "benchtwin_eccentricityPhase")
        _real(q, "theta0", _number(src, res, "eccentricity_phase_deg"), DSI_UNITS["deg"],
              K_DEFAULT * _number(src, res, "eccentricity_phase_u_deg", positive=True))


def _radial_motion_result(results: etree._Element, res: Mapping[str, Any], src: str, lang: str) -> None:
    rem = res.get("radial_error_motion")
    if isinstance(rem, Mapping) and rem.get("locations"):
        cond = _iso230_7_conditions(rem)
        d = _result(results, "Radial error motion (ISO 230-7)", lang, "benchtwin_radialErrorMotion",
                    "Error motion values, fixed sensitive direction, fundamental removed, about the least-squares "
                    f"centre; {rem.get('n_revolutions', NOT_STATED)} revolutions. {cond} U = 2·u (normal "
                    "distribution): u from the probes' reading noise; it does not include the probes' calibration, "
                    "the test spheres' form error or motion of the orders outside the bandwidth.")
        bw, acq = rem.get("bandwidth"), rem.get("acquisition")
        band = (f" (orders {bw['lowest_order']}–{bw['highest_order']} per revolution)"
                if isinstance(bw, Mapping) and bw.get("highest_order") is not None else "")
        for loc in rem["locations"]:
            w = f"{src}: radial_error_motion.locations[{loc.get('name')!r}]"
            lst = _el(d, "list", refType=f"benchtwin_{loc['name']}")
            _text(lst, "name", loc.get("label", loc["name"]), lang)
            for kind in ("total", "synchronous", "asynchronous"):
                if kind == "asynchronous" and loc.get("asynchronous_um") is None:
                    continue  # one revolution: no asynchronous error motion value
                x = _number(w, loc, f"{kind}_um")
                u = loc.get(f"{kind}_u_um")
                q = _quantity(lst, f"{kind} error motion value{band}", lang, f"benchtwin_{kind}ErrorMotion")
                _text(q, "description", cond, lang)
                _real(q, kind, x, DSI_UNITS["um"],
                      K_DEFAULT * float(u) if isinstance(u, (int, float)) and u > 0 else None)
            if isinstance(bw, Mapping) and isinstance(acq, Mapping):
                _iso230_7_influence(lst, bw, acq, lang)


def _effects_result(results: etree._Element, res: Mapping[str, Any], lang: str) -> None:
    eff = res.get("identified_effects") or []
    if eff:
        d = _result(results, "Identified effects", lang, "benchtwin_identifiedEffects", effects_statement(res))
        for e in eff:
            lst = _el(d, "list", refType=f"benchtwin_effect_{e['name']}")
            _text(lst, "name", str(e["name"]), lang)
            for pk, pv in (e.get("params") or {}).items():
                base, unit = _unit_of(pk)
                u = (e.get("u") or {}).get(pk)
                q = _quantity(lst, base, lang)
                _real(q, pk, float(pv), unit, K_DEFAULT * float(u) if isinstance(u, (int, float)) and u > 0 else None)


def _iso230_7_influence(lst: etree._Element, bw: Mapping[str, Any], acq: Mapping[str, Any], lang: str) -> None:
    """The bandwidth (lowest and highest order per revolution) and the speed (step-and-settle at N
    positions per turn) of an ISO 230-7 list as influence conditions a reader can take numbers from."""
    ic = _el(lst, "influenceConditions")
    c = _el(ic, "influenceCondition", refType="benchtwin_bandwidth")
    _text(c, "name", "bandwidth", lang)
    _text(c, "description", str(bw.get("text", "")), lang)
    data = _el(c, "data")
    for key in ("lowest_order", "highest_order"):
        if bw.get(key) is not None:
            _real(_quantity(data, f"{key.replace('_', ' ')} per revolution", lang, f"benchtwin_{key}"), key,
                  float(bw[key]), DSI_UNITS["one"], None)
    c = _el(ic, "influenceCondition", refType="benchtwin_stepAndSettle")
    _text(c, "name", "speed: step-and-settle", lang)
    _text(c, "description", str(acq.get("text", "")), lang)
    _real(_quantity(_el(c, "data"), "positions per turn", lang, "benchtwin_positionsPerTurn"), "positions_per_turn",
          float(acq["positions_per_turn"]), DSI_UNITS["one"], None)


def _iso230_2_result(results: etree._Element, res: Mapping[str, Any], src: str, lang: str) -> None:
    """ISO 230-2 figures (arcsec, without U: statistics of the measured deviations, the reference's
    uncertainty not in them, as results.json's ``excludes`` says), the runs per direction, whether
    they meet the standard's count, and its flags."""
    iso = res.get("iso230_2")
    if not (isinstance(iso, Mapping) and isinstance(iso.get("figures"), Mapping) and iso["figures"]):
        return
    runs = iso.get("n_runs") or {}
    meets = iso.get("meets_run_count")
    flags = [str(f) for f in iso.get("flags") or []]
    d = _result(results, "Positioning statistics (ISO 230-2)", lang, "benchtwin_iso230_2",
                f"{iso.get('standard', 'ISO 230-2')}. {iso.get('convention', '')}. Runs: {iso.get('source', NOT_STATED)}"
                f"; {runs.get('forward', NOT_STATED)} forward, {runs.get('backward', NOT_STATED)} backward; "
                f"{'meets' if meets else 'does not meet'} the {iso.get('runs_required_per_direction', 5)} runs per "
                f"direction ISO 230-2 asks for. No uncertainty is stated for the figures; not included in them: "
                f"{iso.get('excludes', NOT_STATED)}."
                + (" Flags: " + "; ".join(flags) + "." if flags else ""))
    lst = _el(d, "list", refType="benchtwin_iso230_2Figures")
    _text(lst, "name", "figures of the axis", lang)
    for key, f in iso["figures"].items():
        if not isinstance(f, Mapping):
            continue
        q = _quantity(lst, f"{f.get('symbol', key)}: {f.get('what', '')}", lang, f"benchtwin_iso230_2_{key}")
        v = f.get("value")
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
            _real(q, key, float(v), DSI_UNITS.get(str(f.get("unit", "arcsec")), DSI_UNITS["arcsec"]), None)
        else:
            _text(q, "noQuantity", "not computed: the runs cannot give it (see the flags)", lang)
    lst = _el(d, "list", refType="benchtwin_iso230_2Runs")
    _text(lst, "name", "runs", lang)
    for direction in ("forward", "backward"):
        n = runs.get(direction)
        if isinstance(n, int) and not isinstance(n, bool):
            _real(_quantity(lst, f"runs, {direction}", lang, f"benchtwin_runs_{direction}"), f"n_runs_{direction}",
                  float(n), DSI_UNITS["one"], None)
    _text(_quantity(lst, "meets the run count of ISO 230-2", lang, "benchtwin_meetsRunCount"), "noQuantity",
          "true" if meets else "false", lang)


def _arc_periods_result(results: etree._Element, res: Mapping[str, Any], src: str, lang: str) -> None:
    """The periodic components of an arc (analysis/arc_periods.py): period, amplitude and phase with
    U = k·u, k = t_0.975(ν) at the fit's residual degrees of freedom (normal, k = 2, when the table
    gave u), the false-alarm probability, the periods the arc covers and the drive element it points to."""
    periods = res.get("arc_periods")
    if not isinstance(periods, Sequence) or isinstance(periods, str):
        return
    from benchtwin.analysis.distributions import t_ppf

    scan = res.get("arc_period_scan") or {}
    d = _result(results, "Periodic components over the arc", lang, "benchtwin_arcPeriods",
                f"{len(periods)} significant component(s) A·cos(2π·θ/P − φ) over an arc of "
                f"{scan.get('arc_deg', NOT_STATED)} deg ({scan.get('phase_reference', 'θ from the table')}). "
                f"u: from the joint least-squares fit of period, amplitude, phase and trend ({scan.get('u_source', NOT_STATED)}); "
                "it does not include the reference instrument's error (unknown for an imported table) or components "
                "outside the scanned band. The false-alarm probability is that of noise giving such a peak in the band.")
    for i, p in enumerate(periods):
        w = f"{src}: arc_periods[{i}]"
        if not isinstance(p, Mapping):
            raise CertificateInputError(f"{w}: expected an object with period_deg, amplitude_arcsec, u, ...")
        dof = p.get("dof")
        if isinstance(dof, (int, float)) and not isinstance(dof, bool) and dof >= 1:
            k, dist = float(t_ppf(0.975, math.floor(dof))), "t"
            k_s = f"k = {k:.2f} = t_0.975(ν = {int(dof)}), the fit's residual degrees of freedom"
        else:
            k, dist, k_s = K_DEFAULT, "normal", "k = 2 (normal distribution: u from the table's own u)"
        note = str((p.get("drive_element") or {}).get("note") or "no drive element matches")
        lst = _el(d, "list", refType="benchtwin_arcPeriod")
        _text(lst, "name", f"component {i + 1}", lang)
        _text(lst, "description", f"U = k·u, {k_s}. Drive element: {note}.", lang)
        for key, ukey, name, ref in (("period_deg", "u_period_deg", "period P", "benchtwin_period"),
                                     ("amplitude_arcsec", "u", "amplitude A", "benchtwin_amplitude"),
                                     ("phase_deg", "u_phase_deg", "phase φ", "benchtwin_phase")):
            _real(_quantity(lst, name, lang, ref), key.rsplit("_", 1)[0], _number(w, p, key), _unit_of(key)[1],
                  k * _number(w, p, ukey, positive=True), Coverage(k, P_DEFAULT, dist))
        for key, name, ref in (("false_alarm", "false-alarm probability", "benchtwin_falseAlarm"),
                               ("n_periods_covered", "periods covered by the arc", "benchtwin_periodsCovered")):
            _real(_quantity(lst, name, lang, ref), key, _number(w, p, key), DSI_UNITS["one"], None)


def _equipment(man: Mapping[str, Any], lab: LabFile) -> list[dict[str, str]]:
    """The manifest's instruments (kind, model, serial) merged with the lab file's entries (which add
    manufacturer and the instrument's own calibration certificate); joined on ``instrument``."""
    out: dict[str, dict[str, str]] = {}
    for name, d in (man.get("instruments") or {}).items():
        if isinstance(d, Mapping):
            out[name] = {"instrument": name, "name": f"{name} ({d.get('kind', 'instrument')})",
                         **{k: str(d[k]) for k in ("model", "serial") if d.get(k)}}
    for e in lab.equipment:
        key = e.get("instrument", e["name"])
        out.setdefault(key, {"instrument": key})
        out[key].update(e)
    return list(out.values())


# ----------------------------------------------------------------------------- command


def dataset_manifest(res: Mapping[str, Any]) -> dict[str, Any] | None:
    """The manifest of the dataset the results came from, when it is still there."""
    ds = res.get("dataset")
    if not ds:
        return None
    p = Path(str(ds)) / "manifest.json"
    if not p.is_file():
        return None  # moved or deleted since the analysis: the certificate says what it knows
    try:  # present: read as every manifest is (benchtwin.schema); a bad one is an error, not ignored
        m = loads_json(read_input_text(p, max_bytes=1024 * 1024, what="manifest"), str(p))
    except SchemaError as exc:
        raise CertificateInputError(f"{exc} (the dataset of the results, key 'dataset')") from None
    if not isinstance(m, dict):
        raise CertificateInputError(f"{p}: expected a JSON object (the dataset's manifest)")
    if m.get("environment") is not None:
        _environment(f"{p}: environment", m["environment"])
    for k in ("instruments",):
        if m.get(k) is not None and not isinstance(m[k], Mapping):
            raise CertificateInputError(f"{p}: key {k!r}: expected an object")
    _check_text(str(p), {k: m.get(k) for k in ("instruments", "source", "scenario", "seed")})
    return m


def write_certificate(results_path: str | Path, out_path: str | Path, lab_path: str | Path | None = None,
                      today: str | None = None, html_path: str | Path | None = None, *,
                      force: bool = False) -> dict[str, Any]:
    """results.json (+ lab file) -> a validated DCC at ``out_path`` (written atomically); with
    ``html_path`` also the page for people rendered from it (app/certificate_html.py). The
    writing rule (``benchtwin.fsio.check_output_target``) holds for both: an existing file is replaced
    only with ``force``, and never when it is the results or the lab file."""
    from benchtwin.fsio import atomic_write_bytes, atomic_write_text, check_output_target

    out = check_output_target(out_path, force=force, inputs=[results_path, lab_path], what="certificate")
    html_out = (None if html_path is None else
                check_output_target(html_path, force=force, inputs=[results_path, lab_path, out],
                                    what="certificate page"))
    today = today or _dt.datetime.now(_dt.UTC).date().isoformat()
    res = load_results(results_path)
    lab = load_lab(lab_path, today)
    man = dataset_manifest(res)
    tree = build_certificate(res, lab, man, src=str(results_path))
    errors = validation_errors(tree)
    if errors:  # a bug in the writer, not bad input: never hand on a certificate that does not validate
        raise RuntimeError("the certificate does not validate against dcc.xsd 3.1.2: " + "; ".join(errors[:5]))
    atomic_write_bytes(out, etree.tostring(tree, xml_declaration=True, encoding="UTF-8", pretty_print=True))
    extra: dict[str, Any] = {}
    if html_out is not None:
        from benchtwin.app.certificate_html import render_html

        extra["html"] = str(atomic_write_text(html_out, render_html(tree)))
    curve = encoder_curve(res, str(results_path))
    return {"certificate": str(out), **extra, "unique_identifier": lab.certificate_id, "schema": f"DCC {SCHEMA_VERSION} / D-SI 2.1.0",
            "valid": True, "n_angles": len(curve["theta_deg"]), "curve": curve["key"],
            "max_U_arcsec": max(curve["U"]), "administrative_data": "lab file" if lab.stated else "not stated",
            "identified_effects": [e["name"] for e in res.get("identified_effects") or []]}
