"""Design studies: sweep scenario parameters, run the twin at every point, tabulate and summarise.

Why: metrologists ask the twin design questions before machining parts (how far may the grating
disk sit from the bearing, how good must the bearings be, how many heads, which polygon), and the
answer must come with its Monte Carlo uncertainty and be reproducible. A study file names a base
scenario, the parameters to vary (with units, like scenario files), the outputs and a target; the
runner expands the points, validates every resolved scenario with the scenario validator, runs the
points on a local process pool or a Dask cluster, caches every (point, repetition) on disk so an
interrupted study resumes and a re-run recomputes nothing, and writes a tidy table (CSV + Parquet),
a per-point summary (mean, standard deviation, standard uncertainty of the mean), figures and a
short written summary naming the parameter value that keeps the output under the target.

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

Entry point for the command line: ``run_study(study_path, out_dir, scheduler=None, workers=None,
progress=True) -> dict``.
"""

from __future__ import annotations

import concurrent.futures as cf
import hashlib
import itertools
import json
import math
import multiprocessing as mp
import os
import re
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

import benchtwin
from benchtwin.fsio import atomic_write_text
from benchtwin.schema import SchemaError, check_version, load_toml_file
from benchtwin.units import DIMENSIONS, UnitError, parse_quantity, units_of

from . import study_points
from .scenario import Scenario, ScenarioError, load_scenario
from .scenario_schema import HIDDEN_EFFECTS, SCHEMA, Field

FIDELITIES = ("auto", "physics", "full")
SAMPLINGS = ("grid", "random", "lhs")
CRITERIA = ("mean", "individual")
_STUDY_KEYS = {"name", "description", "base", "seed", "repetitions", "outputs", "fidelity", "angles",
               "parameters", "target", "fixed", "order"}
_PARAM_KEYS = {"key", "name", "values", "labels", "low", "high", "n", "sampling", "set"}
_TARGET_KEYS = {"output", "below", "parameter", "coverage", "criterion"}
_SEED_MAX = 2**63 - 1


class StudyError(ValueError):
    """A study file that cannot be run; the message names the file, the key and what was expected."""


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
    tests/test_fuzz_readers.py) still ends as ``StudyError``, never as a TypeError (issue #13)."""
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


def _resolve_base(base: Any, study_path: Path, fail) -> tuple[Scenario, str]:
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


def _parse_parameter(i: int, pr: Any, fail) -> Parameter:
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
    if has_values:
        values = pr["values"]
        if not isinstance(values, list) or not values:
            raise fail(f"{at}.values ({name}): expected a non-empty list")
        first = values[0]
        labels = pr.get("labels")
        if all(isinstance(v, str) for v in values) and (dim in DIMENSIONS or (key is None)):
            p.kind = "quantity"
            p.unit = _split_unit(first)
            if key is None:
                d = _dim_of_unit(p.unit)
                if d is None:
                    raise fail(f"{at}.values ({name}): unknown unit in {first!r}")
                dim = d
            for j, v in enumerate(values):
                try:
                    x_si = parse_quantity(v, dim)
                except UnitError as exc:
                    raise fail(f"{at}.values[{j}] ({name}): {exc}") from None
                shown = _round(x_si / _factor(p.unit, dim)) if p.unit else x_si
                p.levels.append((shown, None))
        elif dim == "dimensionless" and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
            p.kind = "number"
            p.levels = [(float(v), None) for v in values]
        elif dim == "int" and all(isinstance(v, int) and not isinstance(v, bool) for v in values):
            p.kind = "int"
            p.levels = [(int(v), None) for v in values]
        elif dim in ("str", "bool") and labels is None:
            p.kind = dim
            p.levels = [(v, None) for v in values]
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
    else:
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
                d = _dim_of_unit(p.unit)
                if d is None:
                    raise fail(f"{at}.low ({name}): unknown unit in {lo!r}")
                dim = d
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
                p.levels = [(int(v), None) for v in np.unique(np.round(grid).astype(int))]
            else:
                p.levels = [(_round(float(v)), None) for v in grid]
    p.dim = dim
    if sets is not None:
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
    # resolve overrides of value levels
    p.levels = [(v, ov if ov is not None else p.overrides_for(v)) for v, ov in p.levels]
    return p


def _parse_table_parameter(i: int, pr: Mapping[str, Any], fail) -> Parameter:
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


def _parse_target(t: Any, outputs: list[str], params: list[Parameter], fail) -> Target | None:
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
                             f"must share the same n (they are drawn jointly), got {sorted(ns)}")
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


def rep_seed(study_seed: int, rep: int) -> int:
    """Seed of repetition ``rep``: the same for every point (common random numbers)."""
    return int(np.random.SeedSequence([study_seed, rep]).generate_state(1, np.uint64)[0]) & _SEED_MAX


def code_version() -> str:
    """benchtwin.__version__ plus a hash of every source a point can run (cache invalidation): the
    ``.py`` files of twin/, analysis/, hw/ (the acquisition runner and procedures the simulation
    uses), benchtwin/ (units), and every file of models/ (the MuJoCo model).

    Computed afresh by every ``run_study`` (a few ms): pool workers import the code as it is on
    disk now, so a version remembered from an earlier run could be stale."""
    import benchtwin.analysis
    import benchtwin.hw
    import benchtwin.models
    import benchtwin.twin

    h = hashlib.sha256()
    for pkg, pattern in ((benchtwin.twin, "*.py"), (benchtwin.analysis, "*.py"), (benchtwin.hw, "*.py"),
                         (benchtwin, "*.py"), (benchtwin.models, "*")):
        root = Path(list(pkg.__path__)[0])
        for f in sorted(root.rglob(pattern)):
            if not f.is_file() or "__pycache__" in f.parts:
                continue
            h.update(f"{pkg.__name__}/{f.relative_to(root).as_posix()}".encode())
            h.update(f.read_bytes())
    return f"{benchtwin.__version__}+{h.hexdigest()[:16]}"


# --------------------------------------------------------------------------------- execution


def _fn_id(fn: Callable) -> str:
    base = getattr(fn, "func", fn)  # functools.partial: identity of the wrapped function
    return f"{base.__module__}.{base.__qualname__}"


def _run_task(task: dict) -> dict:
    """Worker side: compute the missing repetitions of one point (module-level: picklable)."""
    t0 = time.perf_counter()
    results: list[dict[str, float]] = [{} for _ in task["reps"]]
    for fn in task["point_fns"]:
        for r, part in zip(results, fn(task)):
            r.update(part)
    return {"point": task["point"], "reps": task["reps"], "results": results,
            "elapsed_s": time.perf_counter() - t0}


def _mp_context():
    methods = mp.get_all_start_methods()
    return mp.get_context("forkserver" if "forkserver" in methods else "spawn")


class _Cache:
    """One JSON file per (point, repetition) under ``<out_dir>/cache``, written atomically."""

    def __init__(self, root: Path):
        self.root = root

    def path(self, key: str) -> Path:
        return self.root / key[:2] / f"{key}.json"

    def get(self, key: str) -> dict | None:
        p = self.path(key)
        try:
            return json.loads(p.read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            return None

    def put(self, key: str, entry: dict) -> None:
        atomic_write_text(self.path(key), json.dumps(entry), fsync=False)


def run_study(study_path: str | Path, out_dir: str | Path, scheduler: Any = None, workers: int | None = None,
              progress: bool = True, point_fn: Callable | None = None) -> dict[str, Any]:
    """Run a study file; write table, summary, figures under ``out_dir``; return a JSON-ready dict.

    - ``scheduler``: ``None`` for a local process pool, or a Dask scheduler address
      ``"tcp://HOST:PORT"`` (or an object with ``scheduler_address``, e.g. a ``LocalCluster``).
    - ``workers``: local pool size (default: all cores); ``0`` runs the points in this process.
    - ``point_fn``: replaces the fidelity's point function (a module-level callable or a
      ``functools.partial`` of one; used by tests and benchmarks); its name enters the cache key.
    """
    study = load_study(study_path)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # study.json is written last (the completion marker): an earlier run's must not outlive a new
    # run that is killed (benchtwin.fsio; issue #13)
    (out / "study.json").unlink(missing_ok=True)
    points = expand_points(study)
    fidelity = study.run_fidelity
    if point_fn is not None:
        fns: list[Callable] = [point_fn]
        fid_map = {o: f"custom:{_fn_id(point_fn)}" for o in study.outputs}
    else:
        # full: one pipeline run per repetition gives every output (physics ones on its realisation)
        fns = [study_points.full_point] if fidelity == "full" else [study_points.physics_point]
        fid_map = study.output_fidelity()
    version = code_version()
    fn_ids = [_fn_id(f) for f in fns]
    seeds = [rep_seed(study.seed, k) for k in range(study.repetitions)]
    cache = _Cache(out / "cache")

    keys: dict[tuple[int, int], str] = {}
    done: dict[tuple[int, int], dict] = {}
    tasks: list[dict] = []
    pipeline = {"order": study.order, "close_loop": study.close_loop} if fidelity == "full" else None
    for pt in points:
        missing = []
        for k in range(study.repetitions):
            spec = {"scenario": pt.scenario_key, "rep": k, "rep_seed": seeds[k], "angles": study.angles,
                    "point_fns": fn_ids, "code": version}
            if pipeline is not None:
                spec["pipeline"] = pipeline
            key = _hash(spec)
            keys[(pt.index, k)] = key
            entry = cache.get(key)
            if entry is not None and all(o in entry["outputs"] for o in study.outputs):
                done[(pt.index, k)] = entry
            else:
                missing.append(k)
        # physics: one task per point (its repetitions share one Bench); full: one task per
        # repetition (each is a separate simulation of tens of seconds: both workers share a point,
        # and the progress bar moves per run)
        for reps in ([missing] if fidelity != "full" else [[k] for k in missing]) if missing else []:
            tasks.append({"point": pt.index, "scenario": pt.scenario, "scenario_key": pt.scenario_key,
                          "reps": reps, "rep_seeds": [seeds[k] for k in reps], "angles": study.angles,
                          "outputs": study.outputs, "point_fns": fns, "order": study.order,
                          "close_loop": study.close_loop})
    n_total = len(points) * study.repetitions
    n_cached = len(done)
    t0 = time.perf_counter()

    def store(res: dict) -> None:
        per_rep = res["elapsed_s"] / max(1, len(res["reps"]))
        for k, outs in zip(res["reps"], res["results"]):
            missing = [o for o in study.outputs if o not in outs]
            if missing:
                raise StudyError(f"{study.path}: point {res['point']} rep {k}: the point function "
                                 f"({', '.join(fn_ids)}) returned no {', '.join(missing)}")
            entry = {"outputs": outs, "elapsed_s": per_rep, "code": version}
            cache.put(keys[(res["point"], k)], entry)
            done[(res["point"], k)] = entry

    bar = _progress_bar(progress, n_total, n_cached, study.name)
    try:
        if not tasks:
            pass
        elif scheduler is not None:
            _run_dask(scheduler, tasks, store, bar)
        elif workers == 0:
            for task in tasks:
                res = _run_task(task)
                store(res)
                bar.update(len(res["reps"]))
        else:
            n_workers = workers or _cpu_count()
            pool = cf.ProcessPoolExecutor(max_workers=min(n_workers, len(tasks)), mp_context=_mp_context())
            try:
                futs = [pool.submit(_run_task, t) for t in tasks]
                for fut in cf.as_completed(futs):
                    res = fut.result()
                    store(res)
                    bar.update(len(res["reps"]))
            except cf.process.BrokenProcessPool as exc:
                pool.shutdown(wait=False, cancel_futures=True)
                raise RuntimeError(
                    "a worker process of the study pool died (killed, out of memory, or — when run_study "
                    "is called from a script — the script lacks the `if __name__ == \"__main__\":` guard "
                    "that spawned worker processes need); finished points are cached: re-run to resume"
                ) from exc
            except BaseException:
                # interrupted or a point failed: what is stored stays cached; a re-run resumes
                pool.shutdown(wait=False, cancel_futures=True)
                raise
            else:
                pool.shutdown(wait=True)
    finally:
        bar.close()
    wall_s = time.perf_counter() - t0
    return _write_results(study, points, done, keys, seeds, out, fid_map, fidelity, version,
                          computed=n_total - n_cached, cached=n_cached, wall_s=wall_s,
                          where="dask " + str(getattr(scheduler, "scheduler_address", scheduler))
                          if scheduler is not None else ("in-process" if workers == 0 else
                                                         f"local pool, {workers or _cpu_count()} workers"))


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def _progress_bar(enabled: bool, total: int, initial: int, name: str):
    if enabled:
        from tqdm import tqdm

        return tqdm(total=total, initial=initial, desc=f"study {name}", unit="pt", smoothing=0.1)

    class _Null:
        def update(self, n: int) -> None: ...

        def close(self) -> None: ...

    return _Null()


def _run_dask(scheduler: Any, tasks: list[dict], store: Callable[[dict], None], bar) -> None:
    from distributed import Client, as_completed

    address = getattr(scheduler, "scheduler_address", scheduler)
    with Client(address, timeout="30s") as client:
        futs = client.map(_run_task, tasks, pure=False)
        try:
            for fut in as_completed(futs):
                res = fut.result()
                store(res)
                bar.update(len(res["reps"]))
        except BaseException:
            client.cancel(futs)
            raise


# ----------------------------------------------------------------------------------- results


def _write_results(study: Study, points: list[Point], done: dict, keys: dict, seeds: list[int], out: Path,
                   fid_map: dict[str, str], fidelity: str, version: str, computed: int, cached: int,
                   wall_s: float, where: str) -> dict[str, Any]:
    import pyarrow as pa
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    params = study.parameters
    # what every row ran: physics, full (simulate → analyze) or full+close_loop; per output in fid_map
    run_label = ("full+close_loop" if study.close_loop else "full") if fidelity == "full" else fidelity
    if any(v.startswith("custom:") for v in fid_map.values()):
        run_label = next(iter(fid_map.values()))
    cols: dict[str, list] = {"point": [], "rep": [], "rep_seed": []}
    for p in params:
        cols[p.column] = []
        for k in p.sets:
            cols[_column(k, p.unit)] = []
    for o in study.outputs:
        cols[o] = []
    cols["fidelity"] = []
    cols["elapsed_s"] = []
    cols["cache_key"] = []
    for pt in points:
        for k in range(study.repetitions):
            e = done[(pt.index, k)]
            cols["point"].append(pt.index)
            cols["rep"].append(k)
            cols["rep_seed"].append(seeds[k])
            for p in params:
                cols[p.column].append(pt.values[p.name])
                for key in p.sets:
                    cols[_column(key, p.unit)].append(float(_split_num(pt.overrides[key])))
            for o in study.outputs:
                cols[o].append(float(e["outputs"][o]))
            cols["fidelity"].append(run_label)
            cols["elapsed_s"].append(float(e.get("elapsed_s", float("nan"))))
            cols["cache_key"].append(keys[(pt.index, k)][:16])
    meta = {"study": study.name, "base": study.base_ref, "seed": str(study.seed),
            "code_version": version, "fidelity": json.dumps(fid_map)}
    table = pa.table(cols).replace_schema_metadata(meta)
    pq.write_table(table, out / "table.parquet")
    pacsv.write_csv(table, out / "table.csv")

    # per-point summary
    scols: dict[str, list] = {"point": [], "n": [], "fidelity": []}
    for p in params:
        scols[p.column] = []
    for o in study.outputs:
        for s in ("mean", "std", "u"):
            scols[f"{o}_{s}"] = []
    summary_rows = []
    for pt in points:
        scols["point"].append(pt.index)
        scols["n"].append(study.repetitions)
        scols["fidelity"].append(run_label)
        for p in params:
            scols[p.column].append(pt.values[p.name])
        row = {"point": pt.index, "values": pt.values}
        for o in study.outputs:
            x = np.array([done[(pt.index, k)]["outputs"][o] for k in range(study.repetitions)], float)
            mean = float(x.mean())
            std = float(x.std(ddof=1)) if len(x) > 1 else float("nan")
            u = std / math.sqrt(len(x)) if len(x) > 1 else float("nan")
            scols[f"{o}_mean"].append(mean)
            scols[f"{o}_std"].append(std)
            scols[f"{o}_u"].append(u)
            row[o] = (mean, std, u)
        summary_rows.append(row)
    stable = pa.table(scols).replace_schema_metadata(meta)
    pq.write_table(stable, out / "summary.parquet")
    pacsv.write_csv(stable, out / "summary.csv")

    verdict = _target_verdict(study, summary_rows) if study.target else None
    figures = _figures(study, summary_rows, done, out, verdict)
    md = _markdown(study, summary_rows, verdict, fid_map, fidelity, computed, cached, wall_s, where, version)
    atomic_write_text(out / "summary.md", md)
    atomic_write_text(out / "summary.html", _html(md))
    report = _report(study, _html(md), figures, out / "report.html")
    result = {
        "ok": True, "study": study.name, "out_dir": str(out), "points": len(points),
        "repetitions": study.repetitions, "rows": len(points) * study.repetitions,
        "computed": computed, "cached": cached, "wall_s": wall_s, "executor": where,
        "fidelity": fidelity, "output_fidelity": fid_map, "code_version": version,
        "table_csv": str(out / "table.csv"), "table_parquet": str(out / "table.parquet"),
        "summary_csv": str(out / "summary.csv"), "summary_parquet": str(out / "summary.parquet"),
        "summary_md": str(out / "summary.md"),
        "summary_html": str(out / "summary.html"), "report_html": str(report),
        "figures": [str(f) for f in figures],
        "target": verdict,
        "message": (verdict or {}).get("sentence") or
        f"study {study.name}: {len(points)} points × {study.repetitions} reps ({computed} computed, "
        f"{cached} from cache) -> {out}",
    }
    atomic_write_text(out / "study.json", json.dumps(result, indent=2, default=str))  # last: the completion marker
    return result


def _split_num(text: str) -> float:
    return float(str(text).split()[0])


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _target_verdict(study: Study, rows: list[dict]) -> dict[str, Any]:
    """Along the target parameter (for each combination of the other parameters): which values keep
    ``mean + k·u`` (criterion "mean") or ``mean + k·s`` ("individual") below the target, and where the
    upper bound crosses the target (linear interpolation between neighbouring points)."""
    t = study.target
    assert t is not None
    param = next(p for p in study.parameters if p.name == t.parameter)
    unit, _ = _output_dim(t.output)
    # group by the other grid parameters; sampled (random/lhs) ones vary within a group
    others = [p.name for p in study.parameters if p.name != t.parameter and p.sampling == "grid"]
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault(tuple(repr(r["values"][o]) for o in others), []).append(r)
    result_groups = []
    for gkey, grs in groups.items():
        numeric = param.kind in ("quantity", "int", "number")
        if numeric:
            grs = sorted(grs, key=lambda r: r["values"][t.parameter])
        xs, ups, oks = [], [], []
        for r in grs:
            mean, std, u = r[t.output]
            spread = std if t.criterion == "individual" else u
            upper = mean + t.coverage * (spread if math.isfinite(spread) else 0.0)
            xs.append(r["values"][t.parameter])
            ups.append(upper)
            oks.append(upper < t.below)
        crossing = None
        if numeric:
            for i in range(len(xs) - 1):
                if oks[i] != oks[i + 1]:
                    x0, x1, y0, y1 = float(xs[i]), float(xs[i + 1]), ups[i], ups[i + 1]
                    crossing = x0 + (t.below - y0) * (x1 - x0) / (y1 - y0) if y1 != y0 else x0
                    break
        good = [x for x, ok in zip(xs, oks) if ok]
        label = ", ".join(f"{o} = {_fmt(grs[0]['values'][o])}" for o in others)
        result_groups.append({"others": {o: grs[0]["values"][o] for o in others}, "values_ok": good,
                              "upper": ups, "values": xs, "crossing": crossing, "label": label})
    pu = f" {param.unit}" if param.unit else ""
    bound = f"mean + {t.coverage:g}·{'s' if t.criterion == 'individual' else 'u'}"
    sentences = []
    for g in result_groups:
        where = f" ({g['label']})" if g["label"] else ""
        if not g["values_ok"]:
            s = f"no swept value of {param.name} keeps {t.output} ({bound}) below {t.below:g} {unit}{where}"
        elif len(g["values_ok"]) == len(g["values"]):
            s = f"every swept value of {param.name} keeps {t.output} ({bound}) below {t.below:g} {unit}{where}"
        else:
            ok = ", ".join(_fmt(v) for v in g["values_ok"])
            s = f"{t.output} ({bound}) stays below {t.below:g} {unit} for {param.name} = {ok}{pu}{where}"
            if g["crossing"] is not None:
                s += f"; the bound crosses the target at {param.name} ≈ {g['crossing']:.3g}{pu}"
        sentences.append(s)
    return {"output": t.output, "below": t.below, "unit": unit, "parameter": param.name,
            "parameter_unit": param.unit, "criterion": t.criterion, "coverage": t.coverage,
            "groups": result_groups, "sentence": "; ".join(sentences) + "."}


def _figures(study: Study, rows: list[dict], done: dict, out: Path, verdict: dict | None) -> list[Path]:
    """Each output against the first numeric parameter: mean with a k·u band, individual reps as dots,
    one line per combination of the other parameters, and the target as a dashed line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    numeric = [p for p in study.parameters if p.kind in ("quantity", "int", "number")]
    if not numeric:
        return []
    xp = next((p for p in numeric if study.target and p.name == study.target.parameter), numeric[0])
    others = [p.name for p in study.parameters if p.name != xp.name and p.sampling == "grid"]
    scattered = any(p.sampling != "grid" for p in study.parameters)  # no lines through sampled points
    k = study.target.coverage if study.target else 2.0
    figdir = out / "figures"
    figdir.mkdir(exist_ok=True)
    paths = []
    for o in study.outputs:
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        groups: dict[tuple, list[dict]] = {}
        for r in rows:
            groups.setdefault(tuple(repr(r["values"][n]) for n in others), []).append(r)
        for gi, grs in enumerate(groups.values()):
            grs = sorted(grs, key=lambda r: r["values"][xp.name])
            x = np.array([r["values"][xp.name] for r in grs], float)
            m = np.array([r[o][0] for r in grs])
            u = np.nan_to_num(np.array([r[o][2] for r in grs]))
            s = np.nan_to_num(np.array([r[o][1] for r in grs]))
            label = ", ".join(f"{n} = {_fmt(grs[0]['values'][n])}" for n in others) or "mean"
            if scattered:
                line = ax.errorbar(x, m, yerr=k * u, fmt="o", ms=4, capsize=2, label=label).lines[0]
            else:
                line, = ax.plot(x, m, "o-", ms=4, label=label)
                ax.fill_between(x, m - k * s, m + k * s, color=line.get_color(), alpha=0.12, lw=0)
                ax.fill_between(x, m - k * u, m + k * u, color=line.get_color(), alpha=0.35, lw=0)
            for r in grs:
                reps = [done[(r["point"], j)]["outputs"][o] for j in range(study.repetitions)]
                ax.plot([r["values"][xp.name]] * len(reps), reps, ".", color=line.get_color(), ms=2, alpha=0.5)
        if study.target and study.target.output == o:
            unit, _ = _output_dim(o)
            ax.axhline(study.target.below, ls="--", color="k", lw=1, label=f"target {study.target.below:g} {unit}")
            if verdict and study.target.parameter == xp.name:
                for g in verdict["groups"]:
                    if g["crossing"] is not None:
                        ax.axvline(g["crossing"], ls=":", color="0.3", lw=1)
                        ax.annotate(f"{g['crossing']:.3g} {xp.unit}", (g["crossing"], study.target.below),
                                    textcoords="offset points", xytext=(4, 6), fontsize=8)
        ax.set_xlabel(xp.column)
        ax.set_ylabel(o)
        bands = (f"error bars ± {k:g}·u(mean); other sampled parameters vary between points" if scattered else
                 f"dark band ± {k:g}·u(mean), light band ± {k:g}·s (single run)")
        ax.set_title(f"{study.name}: {o}\nmean over {study.repetitions} reps; {bands}; dots: single runs",
                     fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        path = figdir / f"{o}_vs_{xp.column}.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        paths.append(path)
    return paths


def _markdown(study: Study, rows: list[dict], verdict: dict | None, fid_map: dict[str, str], fidelity: str,
              computed: int, cached: int, wall_s: float, where: str, version: str) -> str:
    lines = [f"### Study `{study.name}`", ""]
    if study.description:
        lines += [study.description, ""]
    lines += [f"Base scenario `{study.base_ref}`, seed {study.seed}, {len(rows)} points × "
              f"{study.repetitions} repetitions ({computed} computed, {cached} from cache, "
              f"{wall_s:.1f} s, {where}); code {version}.", ""]
    if study.fixed:
        lines += ["Fixed for every point: " + ", ".join(f"`{k} = {v}`" for k, v in study.fixed.items()) + ".", ""]
    lines += ["Fidelity per output: " + ", ".join(f"`{o}`: {f}" for o, f in fid_map.items()) + ".", ""]
    used = set(fid_map.values())
    legend = {"physics": "physics = the twin's MuJoCo statics and the exact reading of the posed disk (no images, "
                         "no instruments, no analysis)",
              "full": "full = simulate the whole dataset (rendered CCD images, every instrument) and analyse it "
                      f"with the one pipeline (Fourier order {study.order}), one simulated bench per repetition",
              "full+close_loop": "full+close_loop = the same plus the close-the-loop step"}
    notes = [text for key, text in legend.items() if key in used or
             (key == "full" and any(v.startswith("physics (") or v == "full+close_loop" for v in used))]
    if notes:
        lines += ["; ".join(notes) + ".", ""]
    if verdict:
        lines += [f"**Target**: {verdict['sentence']}", ""]
    head = [p.column for p in study.parameters] + [f"{o} [{fid_map[o]}] (mean ± u, s)" for o in study.outputs]
    lines += ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for r in rows:
        cells = [_fmt(r["values"][p.name]) for p in study.parameters]
        cells += [f"{r[o][0]:.4g} ± {r[o][2]:.2g}, {r[o][1]:.2g}" for o in study.outputs]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    return "\n".join(lines)


def _report(study: Study, summary_html: str, figures: list[Path], path: Path) -> Path:
    """The study's self-contained report: the written summary, then every figure embedded (PNG data
    URIs, the analysis report's format), so it can be mailed or archived alone."""
    import base64
    import html as _h

    from benchtwin.analysis.report.html import Report

    rep = Report(f"Design study {study.name}")
    rep.blocks.append(summary_html)
    rep.heading("Figures")
    for f in figures:
        data = base64.b64encode(Path(f).read_bytes()).decode()
        cap = f"{Path(f).stem.replace('_vs_', ' vs ')}: mean over the repetitions with its bands (see the summary)"
        rep.blocks.append(f'<figure><img alt="{_h.escape(cap)}" src="data:image/png;base64,{data}">'
                          f"<figcaption>{_h.escape(cap)}</figcaption></figure>")
    return rep.write(path)


def _html(md: str) -> str:
    """A small HTML snippet of the markdown summary (headings, paragraphs, one table)."""
    import html as _h

    out, in_table = ["<section class=\"study-summary\">"], False
    for line in md.splitlines():
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            if all(set(c) <= {"-", " "} for c in cells):
                continue
            if not in_table:
                out.append("<table>")
                in_table = True
                out.append("<tr>" + "".join(f"<th>{_h.escape(c)}</th>" for c in cells) + "</tr>")
            else:
                out.append("<tr>" + "".join(f"<td>{_h.escape(c)}</td>" for c in cells) + "</tr>")
            continue
        if in_table:
            out.append("</table>")
            in_table = False
        if line.startswith("### "):
            out.append(f"<h3>{_h.escape(line[4:].replace('`', ''))}</h3>")
        elif line.strip():
            text = _h.escape(line).replace("**", "")
            text = re.sub(r"`([^`]*)`", r"<code>\1</code>", text)
            out.append(f"<p>{text}</p>")
    if in_table:
        out.append("</table>")
    out.append("</section>")
    return "\n".join(out) + "\n"
