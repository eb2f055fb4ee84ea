"""Load and validate scenario files (TOML with units in the values) into SI.

``load_scenario(path)`` reads a file, checks every key against ``scenario_schema.SCHEMA``
(unknown key, missing section or key, wrong unit dimension, out-of-range value, wrong type) and
returns a ``Scenario``: a mapping ``section -> {key: SI value}``. Every error is a
``ScenarioError`` whose message names the file, the key path (``bench.L1``) and what was
expected, so a metrologist can fix the file without reading code.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Any

from benchtwin.schema import SchemaError, check_version, load_toml_file
from benchtwin.jsonable import to_json
from benchtwin.units import UnitError, parse_quantity

from .scenario_schema import DEG as DEG_RAD
from .scenario_schema import HIDDEN_EFFECTS, OPTIONAL_SCHEMA, REQUIRED_SECTIONS, SCHEMA, Field

MAX_LIST = 100_000  # elements of a list-valued key (the longest: a motion table of one reading per stop)

DEFAULT_SCENARIO = "jia2019.toml"


class ScenarioError(ValueError):
    """A scenario file that cannot be used; the message names file, key path and expectation."""


class Scenario(Mapping):
    """A validated scenario: ``sc["bench"]["L1"]`` is in metres, ``sc.seed`` an int.

    Instrument sections are nested: ``sc["instruments"]["probe"]["repeatability"]``.
    ``raw`` keeps the file's own text values, for writing into a dataset's truth/; ``overrides``
    the ``{"bench.L1": "5 mm", ...}`` applied to the file by :meth:`with_overrides` (``--set``,
    ``--seed``), recorded in truth/scenario.json so the run can be repeated.
    """

    def __init__(self, data: dict[str, Any], raw: dict[str, Any], path: Path | None,
                 overrides: Mapping[str, Any] | None = None):
        self._data = data
        self.raw = raw
        self.path = path
        self.overrides: dict[str, Any] = dict(overrides or {})

    def __repr__(self) -> str:
        """The scenario at a glance (a notebook shows this): name, seed, file, the bench's main
        geometry and procedure, how many hidden effects, and the overrides applied."""
        b, pr = self._data["bench"], self._data["procedure"]
        e = self._data["errors"]["eccentricity"]
        where = self.path.name if self.path is not None else "<no file>"
        parts = [f"{self.name!r}", f"seed={self.seed}", f"file={where}",
                 f"r={b['optical_radius'] * 1e3:g} mm", f"L1={b['L1'] * 1e3:g} mm", f"L2={b['L2'] * 1e3:g} mm",
                 f"e={e * 1e6:g} µm", f"heads={len(b['heads'])}", f"polygon={b['polygon_faces']} faces",
                 f"shifts={len(pr['polygon_shifts'])}", f"radial={pr['radial_reps']}x{pr['radial_positions']}",
                 f"hidden effects={len(self.hidden)}"]
        if self.overrides:
            parts.append("overrides={" + ", ".join(f"{k}={v!r}" for k, v in self.overrides.items()) + "}")
        return "Scenario(" + ", ".join(parts) + ")"

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __iter__(self):
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    @property
    def seed(self) -> int:
        return self._data["scenario"]["seed"]

    @property
    def name(self) -> str:
        return self._data["scenario"]["name"]

    @property
    def hidden(self) -> dict[str, dict[str, Any]]:
        return self._data["hidden"]

    def to_dict(self) -> dict[str, Any]:
        """A plain nested dict (JSON-ready: SI floats, ints, strings, lists)."""
        return _plain(self._data)

    def with_overrides(self, overrides: Mapping[str, Any]) -> "Scenario":
        """A copy with ``{"bench.L1": "10 mm", ...}`` applied to the file's text values and
        re-validated (used by design studies: overrides are written with units too). The copy's
        ``overrides`` are this scenario's followed by these (a later value of a key wins)."""
        import copy

        raw = copy.deepcopy(self.raw)
        for dotted, value in overrides.items():
            parts = dotted.split(".")
            node = raw
            for p in parts[:-1]:
                node = node.setdefault(p, {})
            node[parts[-1]] = value
        sc = validate(raw, str(self.path or "<overrides>"))
        sc.overrides = {**self.overrides, **overrides}
        return sc


def parse_set_options(items: Sequence[str]) -> dict[str, Any]:
    """``--set KEY=VALUE`` options as overrides: KEY a dotted scenario key (``bench.L1``), VALUE a TOML
    value (``5``, ``true``, ``"5 mm"``, ``["0 deg", "5 deg"]``); a VALUE that is not TOML is taken as
    the string it is (``--set bench.L1="5 mm"`` reaches us as ``bench.L1=5 mm`` after the shell's
    quotes). The scenario's schema validates the result (:meth:`Scenario.with_overrides`).
    Raises ScenarioError naming the option."""
    from benchtwin.schema import loads_toml

    out: dict[str, Any] = {}
    for item in items:
        key, eq, text = item.partition("=")
        key = key.strip()
        parts = key.split(".")
        if not eq or len(parts) < 2 or not all(p and p.replace("_", "").isalnum() for p in parts):
            raise ScenarioError(f"--set {item!r}: expected KEY=VALUE with a dotted scenario key, e.g. "
                                "--set bench.L1=\"5 mm\" or --set procedure.polygon_reps=2")
        try:
            parsed = loads_toml(f"v = {text.strip()}", f"--set {key}")
        except (SchemaError, ValueError):
            parsed = {}
        out[key] = parsed["v"] if set(parsed) == {"v"} else text.strip()
    return out


_plain = to_json  # plain dicts and lists (benchtwin/jsonable.py)

def default_scenario_path() -> Path:
    """The embedded default scenario (Jia 2019), shipped inside the package."""
    return Path(str(resources.files("benchtwin.scenarios").joinpath(DEFAULT_SCENARIO)))


def load_scenario(path: str | Path | None = None) -> Scenario:
    """Read and validate a scenario file; ``None`` loads the embedded default (jia2019)."""
    p = Path(path) if path is not None else default_scenario_path()
    if not p.exists():
        raise ScenarioError(f"{p}: no such scenario file")
    try:
        # regular file, size and nesting limits, finite numbers (benchtwin.schema; issue #13)
        raw = load_toml_file(p, what="scenario file")
    except SchemaError as exc:
        raise ScenarioError(str(exc)) from None
    sc = validate(raw, str(p))
    sc.path = p
    return sc


def validate(raw: Mapping[str, Any], where: str = "<scenario>") -> Scenario:
    """Validate a parsed TOML mapping; raises ``ScenarioError`` on the first problem found."""
    if not isinstance(raw, Mapping):
        raise ScenarioError(f"{where}: expected a table at the top level")
    # the file format's optional version (missing = 1; an unknown one is refused, not guessed)
    check_version(raw, where, fail=ScenarioError)
    raw = {k: v for k, v in raw.items() if k != "version"}
    known_top = {s.split(".")[0] for s in SCHEMA} | {"hidden"} | set(OPTIONAL_SCHEMA)
    for key in raw:
        if key not in known_top:
            raise ScenarioError(
                f"{where}: unknown section [{key}]; expected one of "
                f"{', '.join('[' + s + ']' for s in sorted(known_top))}"
            )
    for section in REQUIRED_SECTIONS:
        if section not in raw:
            raise ScenarioError(f"{where}: missing section [{section}]")

    data: dict[str, Any] = {}
    for section, fields in SCHEMA.items():
        node = _get_section(raw, section, where)
        values = _validate_section(node, fields, section, where)
        if "." in section:
            outer, inner = section.split(".", 1)
            data.setdefault(outer, {})[inner] = values
        else:
            data[section] = values
    # Instrument sub-tables not in the schema are unknown keys too.
    for inner in raw.get("instruments", {}) or {}:
        if f"instruments.{inner}" not in SCHEMA:
            known = sorted(s.split(".", 1)[1] for s in SCHEMA if s.startswith("instruments."))
            raise ScenarioError(f"{where}: unknown section [instruments.{inner}]; expected one of {known}")
    for section, fields in OPTIONAL_SCHEMA.items():
        if section in raw:
            data[section] = _validate_section(_get_section(raw, section, where), fields, section, where)
    data["hidden"] = _validate_hidden(raw.get("hidden", {}), where)
    _cross_checks(data, where)
    return Scenario(data, dict(raw), None)


def _get_section(raw: Mapping[str, Any], section: str, where: str) -> Mapping[str, Any]:
    node: Any = raw
    for part in section.split("."):
        node = node.get(part, {}) if isinstance(node, Mapping) else None
        if not isinstance(node, Mapping):
            raise ScenarioError(f"{where}: [{section}] must be a table")
    return node


def _validate_section(node: Mapping[str, Any], fields: Mapping[str, Field], section: str, where: str) -> dict:
    out: dict[str, Any] = {}
    for key in node:
        if key not in fields:
            raise ScenarioError(
                f"{where}: unknown key {section}.{key}; expected one of {', '.join(sorted(fields))}"
            )
    for key, field in fields.items():
        path = f"{section}.{key}"
        if key not in node:
            if field.required:
                raise ScenarioError(f"{where}: missing key {path} ({_expect(field)})")
            if field.omit_default:
                continue
            out[key] = field.default
            continue
        out[key] = _convert(node[key], field, path, where)
    return out


def _expect(field: Field) -> str:
    if field.dim in ("int", "bool", "str"):
        what = {"int": "an integer", "bool": "true or false", "str": "a string"}[field.dim]
    elif field.dim == "lobes":
        what = "a list of {order, amplitude, phase} tables"
    elif field.dim.startswith("list["):
        what = f"a list of {field.dim[5:-1]} values with units"
    elif field.dim == "dimensionless":
        what = "a number"
    else:
        from benchtwin.units import units_of

        what = f"a {field.dim} with a unit ({', '.join(units_of(field.dim))})"
    if field.choices:
        what += f", one of {', '.join(field.choices)}"
    return "expected " + what


def _convert(value: Any, field: Field, path: str, where: str) -> Any:
    def fail(msg: str) -> ScenarioError:
        return ScenarioError(f"{where}: {path}: {msg}")

    dim = field.dim
    if dim == "str":
        if not isinstance(value, str):
            raise fail(f"{_expect(field)}, got {value!r}")
        if field.choices and value not in field.choices:
            raise fail(f"{value!r} is not one of {', '.join(field.choices)}")
        return value
    if dim == "bool":
        if not isinstance(value, bool):
            raise fail(f"expected true or false, got {value!r}")
        return value
    if dim == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise fail(f"expected an integer, got {value!r}")
        if field.choices and str(value) not in field.choices:
            raise fail(f"{value} is not one of {', '.join(field.choices)}")
        _check_range(value, field, fail)
        return value
    if dim == "lobes":
        if not isinstance(value, list):
            raise fail(f"{_expect(field)}, got {value!r}")
        lobes = []
        for i, item in enumerate(value):
            if not isinstance(item, Mapping) or set(item) != {"order", "amplitude", "phase"}:
                raise fail(f"item {i}: expected a table with exactly order, amplitude, phase; got {item!r}")
            if isinstance(item["order"], bool) or not isinstance(item["order"], int) or not 1 <= item["order"] <= 1000:
                raise fail(f"item {i}: order must be an integer 1…1000, got {item['order']!r}")
            try:
                amp = parse_quantity(item["amplitude"], "length")
                phase = parse_quantity(item["phase"], "angle")
            except UnitError as exc:
                raise fail(f"item {i}: {exc}") from None
            if not 0 <= amp <= 1e-3:
                raise fail(f"item {i}: amplitude {item['amplitude']!r} outside 0…1 mm")
            lobes.append({"order": item["order"], "amplitude": amp, "phase": phase})
        return lobes
    if dim.startswith("list["):
        inner = dim[5:-1]
        if not isinstance(value, list) or not value:
            raise fail(f"{_expect(field)}, got {value!r}")
        if inner == "str":
            for v in value:
                if not isinstance(v, str) or (field.choices and v not in field.choices):
                    raise fail(f"{v!r} is not one of {', '.join(field.choices or ())}")
            return list(value)
        if len(value) > MAX_LIST:
            raise fail(f"expected at most {MAX_LIST} values, got {len(value)}")
        out = []
        for i, v in enumerate(value):
            try:
                out.append(parse_quantity(v, inner))
            except UnitError as exc:
                raise fail(f"item {i}: {exc}") from None
            # every element has the field's range (issue #13: heads = 1e300° passed)
            _check_range(out[-1], field, lambda m, i=i: fail(f"item {i}: {m}"))
        return out
    try:
        x = parse_quantity(value, dim)
    except UnitError as exc:
        raise fail(str(exc)) from None
    _check_range(x, field, fail)
    return x


def _check_range(x: float, field: Field, fail) -> None:
    if field.lo is not None and x < field.lo:
        raise fail(f"value {x:g} (SI) is below the minimum {field.lo:g} (SI)")
    if field.hi is not None and x > field.hi:
        raise fail(f"value {x:g} (SI) is above the maximum {field.hi:g} (SI)")


def _validate_hidden(node: Any, where: str) -> dict[str, dict[str, Any]]:
    if not isinstance(node, Mapping):
        raise ScenarioError(f"{where}: [hidden] must be a table of effects")
    out: dict[str, dict[str, Any]] = {}
    for name, params in node.items():
        if name not in HIDDEN_EFFECTS:
            known = ", ".join(sorted(HIDDEN_EFFECTS)) or "(none registered yet)"
            raise ScenarioError(f"{where}: hidden.{name}: unknown effect; the twin simulates: {known}")
        if not isinstance(params, Mapping):
            raise ScenarioError(f"{where}: hidden.{name}: expected a table of parameters")
        out[name] = _validate_section(params, HIDDEN_EFFECTS[name], f"hidden.{name}", where)
    return out


def _cross_checks(data: dict[str, Any], where: str) -> None:
    """Relations between keys that single-key ranges cannot express."""
    b = data["bench"]
    if b["L1"] >= b["L2"]:
        raise ScenarioError(f"{where}: bench.L1 ({b['L1']:g} m) must be smaller than bench.L2 "
                            f"({b['L2']:g} m): the disk lies between the two spheres (Jia fig. 8)")
    if b["scale_edge_radius"] < b["optical_radius"]:
        raise ScenarioError(f"{where}: bench.scale_edge_radius must be at least bench.optical_radius")
    if b["grating_line_length"] >= b["scale_edge_radius"]:
        raise ScenarioError(f"{where}: bench.grating_line_length must be shorter than bench.scale_edge_radius")
    br = data["bearings"]
    if br.get("type") == "air":   # twin/air_bearing.py's geometry, named by key (exit 2, not a traceback)
        if br["air_clearance"] >= 0.01 * br["air_journal_diameter"]:
            raise ScenarioError(f"{where}: bearings.air_clearance must be < 1 % of bearings.air_journal_diameter")
        if br["thrust_outer_radius"] > 0 and not (
                0 < br["thrust_inner_radius"] < br["thrust_feed_radius"] < br["thrust_outer_radius"]):
            raise ScenarioError(f"{where}: bearings.thrust_*: expected 0 < thrust_inner_radius < "
                                "thrust_feed_radius < thrust_outer_radius (or thrust_outer_radius = 0: none)")
    if "vibration" in data:
        v = data["vibration"]
        if not v["floor_low_frequency"] <= v["floor_corner_frequency"] <= v["floor_high_frequency"]:
            raise ScenarioError(f"{where}: vibration: expected floor_low_frequency ≤ floor_corner_frequency ≤ "
                                f"floor_high_frequency, got {v['floor_low_frequency']:g}, "
                                f"{v['floor_corner_frequency']:g}, {v['floor_high_frequency']:g} Hz")
    if "motion_table" in data:
        mt = data["motion_table"]
        n = len(mt["theta"])
        for k, v in mt.items():
            if v is not None and len(v) != n:
                raise ScenarioError(f"{where}: motion_table.{k}: expected {n} values (as many as motion_table.theta), got {len(v)}")
        th = mt["theta"]
        bad = [i for i in range(1, n) if not th[i] > th[i - 1]]
        if n < 2 or bad:
            # the twin interpolates the table periodically (scipy): it needs θ increasing
            raise ScenarioError(f"{where}: motion_table.theta: expected at least 2 strictly increasing angles"
                                + (f"; item {bad[0]} is not above item {bad[0] - 1}" if bad else ""))
        if th[-1] - th[0] >= 2 * 3.141592653589793:
            raise ScenarioError(f"{where}: motion_table.theta: expected angles within one turn (< 360°)")
        data["motion_table"] = {k: v for k, v in mt.items() if v is not None}
    if "polygon" in data and data["polygon"]["pyramidal_error"] is not None:
        n_p, n_f = len(data["polygon"]["pyramidal_error"]), b["polygon_faces"]
        if n_p not in (1, n_f):
            raise ScenarioError(f"{where}: polygon.pyramidal_error: expected 1 value (every face) or "
                                f"{n_f} (one per face, bench.polygon_faces), got {n_p}")
    for key in ("heads",):
        v = b[key]
        if len(set(v)) != len(v):
            raise ScenarioError(f"{where}: bench.{key}: two heads at the same azimuth")
        if v and v[0] != 0.0:
            raise ScenarioError(f"{where}: bench.heads: item 0 is head 1, the reference, at 0 deg; got {v[0]:g} rad")
    pr = data["procedure"]
    shifts = pr["polygon_shifts"]
    if len(set(shifts)) != len(shifts):
        # simulate would write the same readings twice: a dataset its own validate rejects (issue #13)
        dup = next(s for s in shifts if shifts.count(s) > 1)
        raise ScenarioError(f"{where}: procedure.polygon_shifts: the shift {dup / DEG_RAD:g} deg is listed twice; "
                            "expected distinct shift angles")
    n_frames = round(2 * 3.141592653589793 / pr["ccd_step"]) * pr["ccd_reps"]
    if n_frames > 720:
        # the dataset's limit (analysis/dataset.py MAX_CCD_FRAMES: one frame every 0.5°)
        raise ScenarioError(f"{where}: procedure.ccd_reps × frames per sweep = {n_frames} CCD frames; at most 720 "
                            "are allowed in a dataset (fewer reps or a larger ccd_step)")
    if len(set(pr["directions"])) != len(pr["directions"]):
        raise ScenarioError(f"{where}: procedure.directions: a direction is listed twice")
    e = data["errors"]["eccentricity"]  # noqa: E501
    if e > 0.05 * b["optical_radius"]:
        raise ScenarioError(f"{where}: errors.eccentricity ({e:g} m) is over 5 % of bench.optical_radius")
    if data["procedure"]["traditional_start_face"] > b["polygon_faces"]:
        raise ScenarioError(f"{where}: procedure.traditional_start_face must be in 1…bench.polygon_faces "
                            f"({b['polygon_faces']})")
