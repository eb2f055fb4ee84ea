"""The design-study file: its schema, the parameters, the target and the expanded points.

Why: metrologists ask the twin design questions before machining parts (how far may the grating
disk sit from the bearing, how good must the bearings be, how many heads, which polygon), and the
answer must come with its Monte Carlo uncertainty and be reproducible. A study file names a base
scenario, the parameters to vary (with units, like scenario files), the outputs and a target. This
module reads and validates it (errors name the file, the key and what was expected) and expands the
points; every point's resolved scenario is validated with the scenario validator. Running the points
(pool, Dask, cache, tables) is ``execution``; figures and the written summary are ``report``.

Study file (TOML; docs/studies.md has the full reference)::

    [study]
    name = "bearing_distance"
    base = "../jia2019.toml"          # relative to this file, or a packaged scenario name
    seed = 1                          # written into scenario.seed; reps use SeedSequence([seed, k])
    repetitions = 4
    outputs = ["angle_error_pv_arcsec"]
    fidelity = "auto"                 # auto | physics | full
    angles = 360                      # shaft positions per turn (physics outputs)
    [study.fixed]                     # overrides applied to every point
    "errors.eccentricity" = "0 um"
    [[study.parameters]]
    key = "bench.L1"
    values = ["2 mm", "5 mm"]         # or low/high/n with sampling = grid | random | lhs
    [study.target]
    output = "angle_error_pv_arcsec"
    below = "1 arcsec"
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.schema import SchemaError, check_version, load_toml_file
from benchtwin.twin.scenario import Scenario, ScenarioError, load_scenario
from benchtwin.twin.scenario_schema import HIDDEN_EFFECTS, SCHEMA, Field
from benchtwin.units import DIMENSIONS, UnitError, parse_quantity, units_of

from . import points as study_points

FIDELITIES = ("auto", "physics", "full")
SAMPLINGS = ("grid", "random", "lhs")
CRITERIA = ("mean", "individual")
_STUDY_KEYS = {"name", "description", "base", "seed", "repetitions", "outputs", "fidelity", "angles",
               "parameters", "target", "fixed", "order"}
_PARAM_KEYS = {"key", "name", "values", "labels", "low", "high", "n", "sampling", "set"}
_TARGET_KEYS = {"output", "below", "parameter", "coverage", "criterion"}
_SEED_MAX = 2**63 - 1
# A value level whose scenario overrides follow from its value once the parameter is parsed
# (``Parameter.overrides_for``); compared by identity, never mutated.
_UNRESOLVED: dict[str, Any] = {}


class StudyError(ValueError):
    """A study file that cannot be run; the message names the file, the key and what was expected."""


_Fail = Callable[[str], StudyError]  # message -> the error naming the study file


# ------------------------------------------------------------------------------------ spec


@dataclass
class Parameter:
    """One varied parameter. ``levels`` holds, per level, the value shown in the table (a number in
    ``unit``, an int, a label or a string) and the scenario overrides (text with units) it sets."""

    name: str
    kind: str  # "quantity" | "int" | "number" | "label" | "str" | "bool"
    unit: str  # display unit for quantities ("mm"), "" otherwise
    sampling: str
    levels: list[tuple[Any, dict[str, Any]]] = field(default_factory=list)
    # for random / lhs sampling:
    low: float | None = None
    high: float | None = None
    n: int | None = None
    sets: dict[str, tuple[float, float, str]] = field(default_factory=dict)  # key -> (scale, offset SI, unit)
    key: str | None = None
    dim: str = ""
    table_keys: list[str] = field(default_factory=list)  # keys set by labelled override tables

    @property
    def column(self) -> str:
        return _column(self.name, self.unit)

    def overrides_for(self, value: Any) -> dict[str, Any]:
        """Scenario overrides for a sampled value (number in ``unit`` or int)."""
        if self.key is not None:
            return {self.key: _text(value, self.unit) if self.kind == "quantity" else value}
        return _affine(self, value)


@dataclass
class Target:
    output: str
    below: float  # in the output's unit
    parameter: str  # parameter name along which the crossing is looked for
    coverage: float = 2.0
    criterion: str = "mean"


@dataclass
class Study:
    path: Path
    name: str
    description: str
    base: Scenario
    base_ref: str
    seed: int
    repetitions: int
    outputs: list[str]
    fidelity: str  # as written: auto | physics | full
    angles: int
    fixed: dict[str, Any]
    parameters: list[Parameter]
    target: Target | None
    order: int = 10  # Fourier order of the analysis (full fidelity)

    @property
    def run_fidelity(self) -> str:
        """What every point runs: "physics", or "full" (simulate → analyze, the close-the-loop step
        only if an output needs it: see ``close_loop``)."""
        needs_full = any(study_points.output_fidelity(o) != "physics" for o in self.outputs)
        return "full" if (self.fidelity == "full" or needs_full) else "physics"

    @property
    def close_loop(self) -> bool:
        return any(study_points.output_fidelity(o) == "full+close_loop" for o in self.outputs)

    def output_fidelity(self) -> dict[str, str]:
        """Per output, the fidelity that computed it (reported with the results). In a full study a
        physics output is computed on the realisation each repetition simulated (its rep seed)."""
        full = self.run_fidelity == "full"
        return {o: ("physics (rep-seed realisation of the full run)"
                    if full and study_points.output_fidelity(o) == "physics" else study_points.output_fidelity(o))
                for o in self.outputs}


def _column(name: str, unit: str) -> str:
    if not unit:
        return name
    u = unit.replace("µ", "u").replace("/", "_per_").replace("*", "").replace("^", "")
    return f"{name}_{u}"


def _text(value: float, unit: str) -> str:
    return f"{float(value):.12g} {unit}"


def _round(x: float) -> float:
    """Undo unit-conversion round-off ("7 arcsec" -> 6.999999999999999 -> 7.0)."""
    return float(f"{x:.12g}")


def _split_unit(text: str) -> str:
    m = re.match(r"^\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*(\S*)\s*$", text)
    return m.group(1) if m else ""


def _dim_of_unit(unit: str) -> str | None:
    if unit == "":
        return "dimensionless"
    for d in DIMENSIONS:
        if unit in units_of(d):
            return d
    return None


def _unit_dimension(unit: str, fail: Any, where: str, text: str) -> str:
    """The dimension of a free parameter's unit (no scenario key to take it from), or the spec
    error naming ``where`` and the value ``text`` the unit came from."""
    d = _dim_of_unit(unit)
    if d is None:
        raise fail(f"{where}: unknown unit in {text!r}")
    return d


def _factor(unit: str, dim: str) -> float:
    return parse_quantity(f"1 {unit}", dim) if unit else 1.0


def _affine(p: Parameter, value: float) -> dict[str, Any]:
    x_si = float(value) * _factor(p.unit, p.dim)
    return {k: _text((off + scale * x_si) / _factor(unit, p.dim), unit) for k, (scale, off, unit) in p.sets.items()}


def _field(key: str) -> Field | None:
    parts = key.split(".")
    for i in range(len(parts) - 1, 0, -1):
        section, rest = ".".join(parts[:i]), parts[i:]
        if section in SCHEMA and len(rest) == 1:
            return SCHEMA[section].get(rest[0])
    if parts[0] == "hidden" and len(parts) == 3 and parts[1] in HIDDEN_EFFECTS:
        return HIDDEN_EFFECTS[parts[1]].get(parts[2])
    return None


def _flatten(node: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in node.items():
        dotted = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(_flatten(v, dotted + "."))
        else:
            out[dotted] = v
    return out


def load_study(path: str | Path) -> Study:
    """Read and validate a study file; every point's resolved scenario is validated too.

    The checks name each key; a value of a type no check foresaw (found by the fuzz tests,
    tests/benchtwin/test_fuzz_readers.py) still ends as ``StudyError``, never as a TypeError (issue #13)."""
    try:
        return _load_study(path)
    except StudyError:
        raise
    except (TypeError, KeyError, AttributeError, IndexError, ValueError, OverflowError) as exc:
        raise StudyError(f"{path}: a value of the wrong type or shape ({type(exc).__name__}: {str(exc)[:120]}); "
                         "see docs/studies.md") from None


def _load_study(path: str | Path) -> Study:
    p = Path(path)
    where = str(p)

    def fail(msg: str) -> StudyError:
        return StudyError(f"{where}: {msg}")

    if not p.exists():
        raise fail("no such study file")
    try:  # bounded, regular, UTF-8, nesting-limited, finite numbers (benchtwin.schema; issue #13)
        raw = load_toml_file(p, what="study file")
    except SchemaError as exc:
        raise StudyError(str(exc)) from None
    check_version(raw, where, fail=StudyError)  # optional top-level version: missing = 1
    raw = {k: v for k, v in raw.items() if k != "version"}
    if set(raw) != {"study"}:
        extra = sorted(set(raw) - {"study"})
        raise fail(f"unknown section [{extra[0]}]; a study file holds only [study] and its sub-tables"
                   if extra else "missing section [study]")
    st = raw["study"]
    if not isinstance(st, Mapping):
        raise fail("[study] must be a table")
    for k in st:
        if k not in _STUDY_KEYS:
            raise fail(f"unknown key study.{k}; expected one of {', '.join(sorted(_STUDY_KEYS))}")
    for k in ("name", "base", "outputs", "parameters"):
        if k not in st:
            raise fail(f"missing key study.{k}")
    name = st["name"]
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise fail(f"study.name: expected a name of letters, digits, _ . -; got {name!r}")
    seed = st.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= _SEED_MAX:
        raise fail(f"study.seed: expected an integer 0…2^63−1, got {seed!r}")
    reps = st.get("repetitions", 1)
    if isinstance(reps, bool) or not isinstance(reps, int) or not 1 <= reps <= 100000:
        raise fail(f"study.repetitions: expected an integer ≥ 1, got {reps!r}")
    angles = st.get("angles", 360)
    if isinstance(angles, bool) or not isinstance(angles, int) or not 4 <= angles <= 100000:
        raise fail(f"study.angles: expected an integer 4…100000 (shaft positions per turn), got {angles!r}")
    fidelity = st.get("fidelity", "auto")
    if fidelity not in FIDELITIES:
        raise fail(f"study.fidelity: {fidelity!r} is not one of {', '.join(FIDELITIES)}")
    outputs, order = _parse_outputs(st, fidelity, fail)
    base, base_ref = _resolve_base(st["base"], p, fail)
    fixed_raw = st.get("fixed", {})
    if not isinstance(fixed_raw, Mapping):
        raise fail("study.fixed: expected a table of scenario overrides (\"bench.L1\" = \"10 mm\")")
    fixed = _flatten(fixed_raw)
    for k in fixed:
        if _field(k) is None:
            raise fail(f"study.fixed: unknown scenario key {k!r}")
    params_raw = st["parameters"]
    if not isinstance(params_raw, list) or not params_raw:
        raise fail("study.parameters: expected at least one [[study.parameters]] table")
    params = [_parse_parameter(i, pr, fail) for i, pr in enumerate(params_raw)]
    names = [q.name for q in params]
    if len(set(names)) != len(names):
        raise fail("study.parameters: two parameters have the same name/key")
    touched = [k for q in params for k in ([q.key] if q.key else list(q.sets) + q.table_keys)]
    if len(set(touched)) != len(touched):
        raise fail("study.parameters: a scenario key is set by two parameters")
    for k in touched:
        if k in fixed:
            raise fail(f"study.fixed: {k!r} is also a study parameter")
    target = _parse_target(st.get("target"), outputs, params, fail)
    study = Study(p, name, st.get("description", ""), base, base_ref, seed, reps, list(outputs), fidelity,
                  angles, fixed, params, target, order)
    return study


def study_with_overrides(study: Study, overrides: Mapping[str, Any]) -> Study:
    """The study with the command line's ``--set KEY=VALUE`` joined to ``[study.fixed]`` (applied to
    every point, recorded in its summary) and ``--seed`` / ``scenario.seed`` as the study's seed
    (which every point's scenario.seed comes from). A key the scenario does not have, or one a
    study parameter varies, is a StudyError naming it; every point's scenario is validated."""
    import dataclasses

    fixed = dict(study.fixed)
    seed = study.seed
    params = {k for q in study.parameters for k in ([q.key] if q.key else list(q.sets) + q.table_keys)}
    for k, v in overrides.items():
        if k == "scenario.seed":
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= _SEED_MAX:
                raise StudyError(f"{study.path}: --seed / --set scenario.seed: expected an integer 0…2^63−1, got {v!r}")
            seed = v
            continue
        if _field(k) is None:
            raise StudyError(f"{study.path}: --set {k}: unknown scenario key")
        if k in params:
            raise StudyError(f"{study.path}: --set {k}: a study parameter varies this key")
        fixed[k] = v
    out = dataclasses.replace(study, fixed=fixed, seed=seed)
    expand_points(out)  # every point's scenario validated now, before any output is touched
    return out


def _parse_outputs(st: Mapping[str, Any], fidelity: str, fail: _Fail) -> tuple[list[str], int]:
    """``study.outputs`` (each known, at a fidelity the study allows) and ``study.order``."""
    outputs = st["outputs"]
    if not isinstance(outputs, list) or not outputs or not all(isinstance(o, str) for o in outputs):
        raise fail("study.outputs: expected a non-empty list of output names")
    if len(set(outputs)) != len(outputs):
        raise fail("study.outputs: an output is listed twice")
    for o in outputs:
        try:
            fo = study_points.output_fidelity(o)
        except KeyError:
            raise fail(f"study.outputs: unknown output {o!r}; physics outputs: "
                       f"{', '.join(study_points.PHYSICS_OUTPUTS)}; full outputs: "
                       f"{', '.join(study_points._run.FULL_OUTPUTS)}, identified.<effect> (effect one of "
                       f"{', '.join(study_points._run.effect_names())}), and numbers of the pipeline's "
                       f"results.json written '{study_points.FULL_PREFIX}<key.in.results.json>'") from None
        if fidelity == "physics" and fo != "physics":
            raise fail(f"study.outputs: {o!r} needs fidelity 'full' (the simulate → analyze pipeline) "
                       "but study.fidelity is 'physics'")
    order = st.get("order", 10)
    if isinstance(order, bool) or not isinstance(order, int) or not 1 <= order <= 60:
        raise fail(f"study.order: expected an integer 1…60 (Fourier order of the analysis), got {order!r}")
    if "order" in st and fidelity != "full" and all(study_points.output_fidelity(o) == "physics" for o in outputs):
        raise fail("study.order: the analysis' Fourier order applies to full-fidelity studies only; every "
                   "output here is a physics output (no analysis runs)")
    return outputs, order


def _resolve_base(base: Any, study_path: Path, fail: _Fail) -> tuple[Scenario, str]:
    if not isinstance(base, str) or not base:
        raise fail("study.base: expected a scenario path (relative to the study file) or a packaged "
                   "scenario name such as 'jia2019'")
    cand = (study_path.parent / base)
    if cand.is_file():
        where = cand.resolve()
    else:
        pkg = resources.files("benchtwin.scenarios")
        fname = base if base.endswith(".toml") else base + ".toml"
        res = pkg.joinpath(fname)
        if not res.is_file():
            raise fail(f"study.base: {base!r} is neither a file next to the study file ({cand}) nor a "
                       "packaged scenario (jia2019, hsieh2022)")
        where = Path(str(res))
    try:
        return load_scenario(where), base
    except ScenarioError as exc:
        raise fail(f"study.base: the base scenario is invalid: {exc}") from None


def _parse_parameter(i: int, pr: Any, fail: _Fail) -> Parameter:
    at = f"study.parameters[{i}]"
    if not isinstance(pr, Mapping):
        raise fail(f"{at}: expected a table")
    for k in pr:
        if k not in _PARAM_KEYS:
            raise fail(f"{at}: unknown key {k!r}; expected one of {', '.join(sorted(_PARAM_KEYS))}")
    key, name, sets = pr.get("key"), pr.get("name"), pr.get("set")
    vals = pr.get("values")
    tables = isinstance(vals, list) and bool(vals) and all(isinstance(v, Mapping) for v in vals) and key is None
    if tables:
        return _parse_table_parameter(i, pr, fail)
    if (key is None) == (sets is None):
        raise fail(f"{at}: give either key = \"section.key\", or name = ... with set = {{ ... }}, or name = ... "
                   "with labels = [...] and values = [{ \"section.key\" = ..., ... }, ...]")
    if key is not None:
        if not isinstance(key, str) or _field(key) is None:
            raise fail(f"{at}.key: unknown scenario key {key!r} (see docs/scenario-format.md)")
        if key == "scenario.seed":
            raise fail(f"{at}.key: scenario.seed is set by study.seed and the repetitions")
        name = name or key
        fld = _field(key)
        assert fld is not None
        dim = fld.dim
    else:
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.]+", name):
            raise fail(f"{at}.name: expected a column name (letters, digits, _ .), got {name!r}")
        dim = ""  # from the values' unit
    has_values = "values" in pr
    has_range = any(k in pr for k in ("low", "high", "n"))
    if has_values == has_range:
        raise fail(f"{at} ({name}): give either values = [...] or low, high, n")
    sampling = pr.get("sampling", "grid")
    if sampling not in SAMPLINGS:
        raise fail(f"{at}.sampling ({name}): {sampling!r} is not one of {', '.join(SAMPLINGS)}")
    if has_values and "sampling" in pr and sampling != "grid":
        raise fail(f"{at}.sampling ({name}): random/lhs sampling needs low, high, n (values are a grid)")

    p = Parameter(name=name, kind="", unit="", sampling=sampling, key=key)
    ctx = _ParamContext(at, name, key, fail)
    dim = _parse_values(p, pr, dim, ctx) if has_values else _parse_range(p, pr, dim, ctx)
    p.dim = dim
    if sets is not None:
        _parse_sets(p, sets, dim, ctx)
    # resolve overrides of value levels
    p.levels = [(v, p.overrides_for(v) if ov is _UNRESOLVED else ov) for v, ov in p.levels]
    return p


@dataclass(frozen=True)
class _ParamContext:
    """Where a parameter stands in the study file, for its error messages."""

    at: str  # "study.parameters[i]"
    name: str  # the parameter's column name
    key: str | None  # its scenario key (None for set = {...} parameters)
    fail: _Fail


def _parse_values(p: Parameter, pr: Mapping[str, Any], dim: str, ctx: _ParamContext) -> str:
    """``values = [...]``: the levels of a grid parameter; returns the dimension (from the unit
    when the parameter has no key)."""
    at, name, key, fail = ctx.at, ctx.name, ctx.key, ctx.fail
    values = pr["values"]
    if not isinstance(values, list) or not values:
        raise fail(f"{at}.values ({name}): expected a non-empty list")
    first = values[0]
    labels = pr.get("labels")
    if all(isinstance(v, str) for v in values) and (dim in DIMENSIONS or (key is None)):
        p.kind = "quantity"
        p.unit = _split_unit(first)
        if key is None:
            dim = _unit_dimension(p.unit, fail, f"{at}.values ({name})", first)
        for j, v in enumerate(values):
            try:
                x_si = parse_quantity(v, dim)
            except UnitError as exc:
                raise fail(f"{at}.values[{j}] ({name}): {exc}") from None
            shown = _round(x_si / _factor(p.unit, dim)) if p.unit else x_si
            p.levels.append((shown, _UNRESOLVED))
    elif dim == "dimensionless" and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        p.kind = "number"
        p.levels = [(float(v), _UNRESOLVED) for v in values]
    elif dim == "int" and all(isinstance(v, int) and not isinstance(v, bool) for v in values):
        p.kind = "int"
        p.levels = [(int(v), _UNRESOLVED) for v in values]
    elif dim in ("str", "bool") and labels is None:
        p.kind = dim
        p.levels = [(v, _UNRESOLVED) for v in values]
    else:
        if labels is None or not isinstance(labels, list) or len(labels) != len(values) or \
                not all(isinstance(s, str) for s in labels):
            raise fail(f"{at} ({name}): values of kind {dim or 'unknown'} that are not plain quantities "
                       f"need labels = [...] of the same length (one name per value, for the table); "
                       f"got values {values!r}")
        if key is None:
            raise fail(f"{at} ({name}): labelled values need key = \"section.key\"")
        p.kind = "label"
        p.levels = [(lab, {key: v}) for lab, v in zip(labels, values)]
    if len({repr(v) for v, _ in p.levels}) != len(p.levels):
        raise fail(f"{at}.values ({name}): a value is listed twice")
    return dim


def _parse_range(p: Parameter, pr: Mapping[str, Any], dim: str, ctx: _ParamContext) -> str:
    """``low, high, n``: a linear grid or the bounds of random/LHS sampling; returns the dimension."""
    at, name, key, fail = ctx.at, ctx.name, ctx.key, ctx.fail
    sampling = p.sampling
    for k in ("low", "high", "n"):
        if k not in pr:
            raise fail(f"{at} ({name}): missing {k} (low, high and n go together)")
    n = pr["n"]
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise fail(f"{at}.n ({name}): expected an integer ≥ 1, got {n!r}")
    lo, hi = pr["low"], pr["high"]
    if dim == "int" or (isinstance(lo, int) and isinstance(hi, int) and not isinstance(lo, bool)
                        and dim in ("int", "")):
        if not (isinstance(lo, int) and isinstance(hi, int)) or isinstance(lo, bool):
            raise fail(f"{at} ({name}): low/high of an integer key must be integers")
        p.kind, p.dim, lo_v, hi_v = "int", "int", float(lo), float(hi)
    elif isinstance(lo, str):
        p.kind = "quantity"
        p.unit = _split_unit(lo)
        if key is None:
            dim = _unit_dimension(p.unit, fail, f"{at}.low ({name})", lo)
        if dim not in DIMENSIONS:
            raise fail(f"{at} ({name}): low/high/n needs a quantity or integer key; {key} is {dim}")
        try:
            f = _factor(p.unit, dim)
            lo_v = _round(parse_quantity(lo, dim) / f)
            hi_v = _round(parse_quantity(hi, dim) / f)
        except UnitError as exc:
            raise fail(f"{at}.low/high ({name}): {exc}") from None
    elif dim == "dimensionless" and isinstance(lo, (int, float)) and isinstance(hi, (int, float)):
        p.kind, lo_v, hi_v = "number", float(lo), float(hi)
    else:
        raise fail(f"{at} ({name}): low/high must be quantities with units (\"2 mm\") or integers")
    if not hi_v > lo_v:
        raise fail(f"{at} ({name}): high must be greater than low")
    p.low, p.high, p.n = lo_v, hi_v, n
    if sampling == "grid":
        grid = np.linspace(lo_v, hi_v, n)
        if p.kind == "int":
            p.levels = [(int(v), _UNRESOLVED) for v in np.unique(np.round(grid).astype(int))]
        else:
            p.levels = [(_round(float(v)), _UNRESOLVED) for v in grid]
    return dim


def _parse_sets(p: Parameter, sets: Any, dim: str, ctx: _ParamContext) -> None:
    """``set = { "section.key" = { scale, offset } }``: the keys one value sets, affinely."""
    at, name, fail = ctx.at, ctx.name, ctx.fail
    if not isinstance(sets, Mapping) or not sets:
        raise fail(f"{at}.set ({name}): expected a table {{ \"section.key\" = {{ scale = 1, offset = \"0 mm\" }} }}")
    if p.kind != "quantity":
        raise fail(f"{at}.set ({name}): set needs quantity values with units")
    for k, spec in _flatten_set(sets).items():
        fld = _field(k)
        if fld is None:
            raise fail(f"{at}.set ({name}): unknown scenario key {k!r}")
        if fld.dim != dim:
            raise fail(f"{at}.set ({name}): {k} is a {fld.dim}, the parameter's values are a {dim}")
        if not isinstance(spec, Mapping) or set(spec) - {"scale", "offset"}:
            raise fail(f"{at}.set.{k} ({name}): expected {{ scale = <number>, offset = \"<quantity>\" }}")
        scale = spec.get("scale", 1.0)
        if isinstance(scale, bool) or not isinstance(scale, (int, float)):
            raise fail(f"{at}.set.{k}.scale ({name}): expected a number, got {scale!r}")
        off_txt = spec.get("offset", f"0 {p.unit}")
        try:
            off = parse_quantity(off_txt, dim)
        except UnitError as exc:
            raise fail(f"{at}.set.{k}.offset ({name}): {exc}") from None
        p.sets[k] = (float(scale), off, p.unit)


def _parse_table_parameter(i: int, pr: Mapping[str, Any], fail: _Fail) -> Parameter:
    """A labelled parameter whose values are tables of overrides (e.g. a bearing grade that sets
    both races' waviness and the asynchronous motion)."""
    at = f"study.parameters[{i}]"
    name = pr.get("name")
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.]+", name):
        raise fail(f"{at}.name: a parameter whose values are tables needs name = \"...\" (a column name)")
    for k in ("set", "low", "high", "n", "sampling"):
        if k in pr:
            raise fail(f"{at}.{k} ({name}): not allowed with values that are tables of overrides")
    values, labels = pr["values"], pr.get("labels")
    if not isinstance(labels, list) or len(labels) != len(values) or not all(isinstance(s, str) for s in labels):
        raise fail(f"{at}.labels ({name}): values that are tables need labels = [...] of the same length")
    if len(set(labels)) != len(labels):
        raise fail(f"{at}.labels ({name}): a label is listed twice")
    p = Parameter(name=name, kind="label", unit="", sampling="grid")
    for j, (lab, v) in enumerate(zip(labels, values)):
        ov = _flatten_overrides(v)
        for k in ov:
            if _field(k) is None:
                raise fail(f"{at}.values[{j}] ({name}): unknown scenario key {k!r}")
        p.levels.append((lab, ov))
    p.table_keys = sorted({k for _, ov in p.levels for k in ov})
    return p


def _flatten_overrides(node: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Dotted keys from quoted ("bench.L1") or nested TOML tables; lobe lists stay values."""
    return _flatten(node, prefix)


def _flatten_set(sets: Mapping[str, Any]) -> dict[str, Any]:
    """``set`` entries may be written as quoted dotted keys or as nested TOML tables."""
    out: dict[str, Any] = {}

    def walk(node: Mapping[str, Any], prefix: str) -> None:
        for k, v in node.items():
            dotted = f"{prefix}{k}"
            if isinstance(v, Mapping) and not (set(v) <= {"scale", "offset"}):
                walk(v, dotted + ".")
            else:
                out[dotted] = v

    walk(sets, "")
    return out


def _output_dim(output: str) -> tuple[str, str]:
    for suffix, unit, dim in (("_arcsec", "arcsec", "angle"), ("_um", "um", "length"), ("_mm", "mm", "length"),
                              ("_deg", "deg", "angle"), ("_s", "s", "time")):
        if output.endswith(suffix):
            return unit, dim
    return "", "dimensionless"


def _parse_target(t: Any, outputs: list[str], params: list[Parameter], fail: _Fail) -> Target | None:
    if t is None:
        return None
    if not isinstance(t, Mapping):
        raise fail("study.target: expected a table")
    for k in t:
        if k not in _TARGET_KEYS:
            raise fail(f"unknown key study.target.{k}; expected one of {', '.join(sorted(_TARGET_KEYS))}")
    out = t.get("output")
    if out not in outputs:
        raise fail(f"study.target.output: {out!r} is not one of study.outputs ({', '.join(outputs)})")
    if "below" not in t:
        raise fail("study.target: missing key below (e.g. below = \"1 arcsec\")")
    unit, dim = _output_dim(out)
    try:
        below = _round(parse_quantity(t["below"], dim) / _factor(unit, dim))
    except UnitError as exc:
        raise fail(f"study.target.below: {exc} (the output {out} is in {unit or 'no unit'})") from None
    pname = t.get("parameter", params[0].name)
    names = [p.name for p in params]
    if pname not in names:
        raise fail(f"study.target.parameter: {pname!r} is not a study parameter ({', '.join(names)})")
    cov = t.get("coverage", 2.0)
    if isinstance(cov, bool) or not isinstance(cov, (int, float)) or cov < 0:
        raise fail(f"study.target.coverage: expected a number ≥ 0, got {cov!r}")
    crit = t.get("criterion", "mean")
    if crit not in CRITERIA:
        raise fail(f"study.target.criterion: {crit!r} is not one of {', '.join(CRITERIA)}")
    return Target(out, float(below), pname, float(cov), crit)


# ---------------------------------------------------------------------------------- points


@dataclass
class Point:
    index: int
    values: dict[str, Any]  # parameter name -> shown value
    overrides: dict[str, Any]  # dotted key -> text value
    scenario: Scenario
    scenario_key: str


def expand_points(study: Study) -> list[Point]:
    """The study's points: the product of the grid parameters × the sampled (random/lhs) rows.

    Random and LHS samples are drawn from ``np.random.default_rng`` seeded by the study seed, so
    the same file always gives the same points. Every point's scenario is validated."""
    grid = [p for p in study.parameters if p.sampling == "grid"]
    sampled = [p for p in study.parameters if p.sampling != "grid"]
    rows: list[list[tuple[Parameter, Any]]] = [[]]
    if sampled:
        kinds = {p.sampling for p in sampled}
        if len(kinds) > 1:
            raise StudyError(f"{study.path}: study.parameters: mix of random and lhs sampling; use one for all "
                             "sampled parameters (they are drawn jointly)")
        ns = {p.n for p in sampled}
        if len(ns) > 1:
            raise StudyError(f"{study.path}: study.parameters: sampled parameters ({', '.join(p.name for p in sampled)}) "
                             f"must share the same n (they are drawn jointly), got {sorted(n for n in ns if n is not None)}")
        n = ns.pop()
        assert n is not None
        seed_seq = np.random.SeedSequence([study.seed, 0x5A3])
        if kinds == {"lhs"}:
            from scipy.stats import qmc

            u = qmc.LatinHypercube(d=len(sampled), seed=np.random.default_rng(seed_seq)).random(n)
        else:
            u = np.random.default_rng(seed_seq).random((n, len(sampled)))
        rows = []
        for i in range(n):
            row = []
            for j, p in enumerate(sampled):
                assert p.low is not None and p.high is not None
                if p.kind == "int":
                    v: Any = int(min(math.floor(p.low + u[i, j] * (p.high - p.low + 1)), p.high))
                else:
                    v = float(p.low + u[i, j] * (p.high - p.low))
                row.append((p, v))
            rows.append(row)
    points: list[Point] = []
    for combo in itertools.product(*[p.levels for p in grid]):
        for row in rows:
            values: dict[str, Any] = {}
            overrides: dict[str, Any] = {}
            for p, (v, ov) in zip(grid, combo):
                values[p.name] = v
                overrides.update(ov)
            for p, v in row:
                values[p.name] = v
                overrides.update(p.overrides_for(v))
            idx = len(points)
            all_ov = {**study.fixed, **overrides, "scenario.seed": study.seed}
            try:
                sc = study.base.with_overrides(all_ov)
            except ScenarioError as exc:
                desc = ", ".join(f"{k} = {v!r}" for k, v in overrides.items())
                msg = str(exc).split(": ", 1)[-1]
                raise StudyError(f"{study.path}: point {idx} ({desc}) does not give a valid scenario: {msg}") from None
            sc.path = study.base.path
            points.append(Point(idx, values, overrides, sc, _hash(sc.to_dict())))
    return points


def _hash(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=repr).encode()).hexdigest()
