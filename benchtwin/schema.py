"""Strict reading of input files: one number grammar, bounded files, bounded nesting, and one small
declarative validator for the TOML input files (scenario, study, bench file, fault plan).

Every reader of the project goes through this module (issue #13, docs/reliability.md):

- **numbers** (``parse_float`` / ``parse_int``): ASCII decimal only, ``[+-]digits[.digits][e[+-]digits]``;
  no ``_`` separators (Python's ``float("1_000")`` is 1000.0), no ``nan``/``inf`` spelled out,
  no overflow (``1e400`` is not "inf", a 20-digit integer is not an int64), at most
  ``MAX_NUMBER_CHARS`` characters;
- **files** (``read_input_text``): a regular file (not a folder, FIFO or device), at most
  ``max_bytes``, UTF-8; optionally it must resolve inside a root folder (no ``..``, absolute
  path or symlink that leaves it). Errors name the file and never echo its content;
- **JSON / TOML** (``loads_json`` / ``loads_toml``): at most ``MAX_DEPTH`` levels of nesting
  (checked before parsing, so a hostile file cannot reach Python's recursion limit), JSON without
  ``NaN``/``Infinity`` constants;
- **declarative checks** (``Key`` / ``check_table``): a table's known keys with kind, range and
  choices, unknown keys rejected, one optional ``version`` key (missing = 1, unknown = error);
- **TOML out** (``toml_value`` / ``dumps_toml``): the one TOML writer (a calibrated scenario, the
  emulator's bench file and its ``[[procedure]]`` tables), so what is written reads back here.

The module imports nothing of the project, so every layer (analysis, twin, hw, app) can use it.
"""

from __future__ import annotations

import csv
import io
import json
import math
import numbers
import os
import re
import stat
import tomllib
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["SchemaError", "csv_rows", "MAX_DEPTH", "MAX_NUMBER_CHARS", "MAX_CELL_CHARS", "MAX_INPUT_BYTES",
           "parse_float", "parse_int", "is_number", "read_input_text", "resolve_inside", "check_relative_name", "loads_json",
           "loads_toml", "load_toml_file", "Key", "check_table", "check_version", "nesting_depth", "leaves", "toml_value",
           "dumps_toml"]

MAX_DEPTH = 32            # nesting of JSON/TOML inputs: the deepest real file (a study) has 4
MAX_NUMBER_CHARS = 64     # the longest float repr is 24 characters
MAX_CELL_CHARS = 4096     # a CSV cell (a file name is the longest real one)
MAX_INPUT_BYTES = 16 * 1024 * 1024   # a scenario/study/bench/model/manifest file (real ones: < 100 kB)
INT64_MAX = 2**63 - 1

_FLOAT = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")
_INT = re.compile(r"[+-]?[0-9]+\Z")


class SchemaError(ValueError):
    """Input that breaks the grammar or the limits; the message names the file and the key/row."""


# --------------------------------------------------------------------------- numbers


def parse_float(text: str) -> float:
    """The one number grammar: ASCII decimal, optional exponent, finite. Raises ValueError with
    the expectation (the caller adds file, row and column)."""
    if len(text) > MAX_NUMBER_CHARS:
        raise ValueError(f"expected a number of at most {MAX_NUMBER_CHARS} characters, got {len(text)}")
    if not _FLOAT.match(text):
        raise ValueError("expected a decimal number (digits, '.', exponent; no separators, no nan/inf)")
    x = float(text)
    if not math.isfinite(x):
        raise ValueError("expected a finite number (it overflows a double)")
    return x


def parse_int(text: str, lo: int = -INT64_MAX - 1, hi: int = INT64_MAX) -> int:
    """An integer in ASCII decimal digits (no separators, no exponent), within ``lo…hi``."""
    if len(text) > 20 or not _INT.match(text):
        raise ValueError("expected an integer (decimal digits)")
    n = int(text)
    if not lo <= n <= hi:
        raise ValueError(f"expected an integer in {lo}…{hi}")
    return n


def is_number(x: Any) -> bool:
    """A finite int or float (not a bool) of a parsed JSON/TOML value."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    if isinstance(x, int):
        return -INT64_MAX - 1 <= x <= INT64_MAX
    return math.isfinite(x)


# --------------------------------------------------------------------------- files


def check_relative_name(rel: str, where: str) -> Path:
    """A file name as written in a table: relative, without '..', NUL or backslashes."""
    if not rel or "\x00" in rel or len(rel) > MAX_CELL_CHARS:
        raise SchemaError(f"{where}: expected a relative file name, got an empty or over-long one")
    p = Path(rel)
    if p.is_absolute() or rel.startswith(("/", "\\")) or ".." in p.parts or "\\" in rel:
        raise SchemaError(f"{where}: file {_short(rel)}: expected a relative path inside the dataset, without '..'")
    return p


def resolve_inside(root: str | Path, rel: str, where: str) -> Path:
    """``root/rel`` if it names a file inside ``root``: a relative path without ``..`` whose
    resolved location (symlinks followed) stays inside ``root``. The error never shows the
    target's content, only the name as written."""
    root_r = Path(root).resolve()
    p = check_relative_name(rel, where)
    full = root_r / p
    _check_inside(root_r, full, f"{where}: file {rel!r}: cannot be resolved (symlink loop?)",
                  f"{where}: file {rel!r} leaves the dataset (a symlink pointing outside it)")
    return full


def _check_inside(root_r: Path, path: Path, unresolved: str, outside: str) -> None:
    """``path``, symlinks followed, is ``root_r`` (resolved) or lies inside it; else SchemaError
    with the message ``unresolved`` (a symlink loop) or ``outside``."""
    try:
        real = path.resolve()
    except (OSError, RuntimeError):
        raise SchemaError(unresolved) from None
    if real != root_r and root_r not in real.parents:
        raise SchemaError(outside)


def read_input_text(path: str | Path, *, max_bytes: int = MAX_INPUT_BYTES, what: str = "file",
                    root: str | Path | None = None) -> str:
    """The text of an input file: regular, at most ``max_bytes``, UTF-8. With ``root``, the file
    (symlinks resolved) must lie inside it. Errors name the file and never echo its content."""
    p = Path(path)
    if root is not None:
        _check_inside(Path(root).resolve(), p, f"{p}: cannot be resolved (symlink loop?)",
                      f"{p}: a symlink that leaves the dataset; expected a regular file inside it")
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise SchemaError(f"{p}: no such {what}") from None
    except OSError as exc:
        raise SchemaError(f"{p}: cannot read the {what}: {exc.strerror}") from None
    if stat.S_ISDIR(st.st_mode):
        raise SchemaError(f"{p}: is a folder; expected a {what} (a regular file)")
    if not stat.S_ISREG(st.st_mode):
        raise SchemaError(f"{p}: not a regular file (a device, FIFO or socket); expected a {what}")
    if st.st_size > max_bytes:
        raise SchemaError(f"{p}: {st.st_size} bytes; a {what} may have at most {max_bytes} bytes")
    try:
        with open(p, "rb") as f:
            data = f.read(max_bytes + 1)
    except OSError as exc:
        raise SchemaError(f"{p}: cannot read the {what}: {exc.strerror}") from None
    if len(data) > max_bytes:
        raise SchemaError(f"{p}: a {what} may have at most {max_bytes} bytes")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        # the position only: the bytes may be from a file the user did not mean to show
        raise SchemaError(f"{p}: not UTF-8 text (byte {exc.start}); expected a {what} in UTF-8") from None


# --------------------------------------------------------------------------- JSON / TOML


def csv_rows(text: str, where: str, error: Callable[[str], Exception] = ValueError) -> Iterator[tuple[int, list[str]]]:
    """The rows of CSV text as (row number, cells), numbered as in a text editor (the header is row
    1): the one CSV row reader of every table reader (the dataset's tables, an imported table, the
    minimal results CSV and truth tables of ``score``, a camera folder's index). Text with NUL bytes,
    and a row ``csv`` cannot parse (an unterminated quote, a cell over csv's field size limit), raise
    ``error`` naming ``where`` and the row; what the cells mean is the caller's to check."""
    if "\x00" in text:
        raise error(f"{where}: contains NUL bytes; expected CSV text")
    rows = csv.reader(io.StringIO(text))
    rowno = 0
    while True:
        try:
            row = next(rows)
        except StopIteration:
            return
        except csv.Error as exc:
            raise error(f"{where}: row {rowno + 1}: not valid CSV ({exc}); a cell may have at most "
                        f"{MAX_CELL_CHARS} characters") from None
        rowno += 1
        yield rowno, row


def nesting_depth(text: str, opens: str = "[{", closes: str = "]}") -> int:
    """Maximum bracket depth outside of strings (JSON and TOML quoting; a cheap pre-parse guard)."""
    depth = best = 0
    quote: str | None = None
    esc = False
    comment = False
    for ch in text:
        if comment:
            comment = ch != "\n"
            continue
        if quote is not None:
            if esc:
                esc = False
            elif ch == "\\" and quote == '"':
                esc = True
            elif ch == quote:
                quote = None
            continue
        if ch in "\"'":
            quote = ch
        elif ch == "#":
            comment = True
        elif ch in opens:
            depth += 1
            best = max(best, depth)
        elif ch in closes:
            depth -= 1
    return best


def _reject_constant(name: str):
    raise ValueError(f"{name} is not a number JSON allows")


def _json_int(text: str) -> int:
    """A JSON integer within int64 (Python's json gives any size: a 401-digit one overflowed later)."""
    try:
        return parse_int(text)
    except ValueError:
        raise ValueError(f"the integer {_short(text, 30)} is outside the 64-bit range") from None


def _json_float(text: str) -> float:
    """A JSON number that is a finite double (Python's json reads 1e400 as inf)."""
    x = float(text)
    if not math.isfinite(x):
        raise ValueError(f"the number {_short(text, 30)} overflows a double")
    return x


class _DuplicateKey(ValueError):
    pass


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object whose keys are distinct (Python's json lets the last of a repeated key win)."""
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise _DuplicateKey(f"key {_short(k)} appears twice in one object")
        out[k] = v
    return out


def loads_json(text: str, where: str, max_depth: int = MAX_DEPTH, allow_nan: bool = False) -> Any:
    """JSON with bounded nesting, no NaN/Infinity (unless ``allow_nan``: a cache the project wrote
    itself), integers within int64, numbers that fit a double and no key repeated in an object;
    errors name ``where``."""
    # '#' is not a comment in JSON: count brackets without the TOML comment rule
    d = nesting_depth(text.replace("#", " "))
    if d > max_depth:
        raise SchemaError(f"{where}: nested {d} levels deep; at most {max_depth} are allowed")
    try:
        return json.loads(text, parse_constant=float if allow_nan else _reject_constant, parse_int=_json_int,
                          parse_float=_json_float, object_pairs_hook=_unique_keys)
    except json.JSONDecodeError as exc:
        raise SchemaError(f"{where}: not valid JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})") from None
    except (ValueError, RecursionError) as exc:
        raise SchemaError(f"{where}: not valid JSON: {exc}") from None


def loads_toml(text: str, where: str, max_depth: int = MAX_DEPTH) -> dict[str, Any]:
    """TOML with bounded nesting (arrays, inline tables and dotted tables); errors name ``where``."""
    d = nesting_depth(text)
    if d > max_depth:
        raise SchemaError(f"{where}: nested {d} levels deep; at most {max_depth} are allowed")
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SchemaError(f"{where}: not valid TOML: {exc}") from None
    except RecursionError:
        raise SchemaError(f"{where}: nested too deeply; at most {max_depth} levels are allowed") from None
    if _depth(raw) > max_depth:
        raise SchemaError(f"{where}: nested more than {max_depth} levels deep")
    _check_toml_values(raw, where, "")
    return raw


def _depth(x: Any) -> int:
    """Nesting depth of parsed data, iteratively (no recursion limit)."""
    best, stack = 0, [(x, 1)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, Mapping):
            best = max(best, d)
            stack.extend((c, d + 1) for c in v.values())
        elif isinstance(v, (list, tuple)):
            best = max(best, d)
            stack.extend((c, d + 1) for c in v)
    return best


def leaves(x: Any, path: str = "") -> Iterator[tuple[Any, str]]:
    """The values of nested tables and lists that are neither, each with its key path
    (``a.b[2].c``), iteratively (no recursion limit): what a check of every value of a parsed
    input walks."""
    stack = [(x, path)]
    while stack:
        v, p = stack.pop()
        if isinstance(v, Mapping):
            stack.extend((c, f"{p}.{k}" if p else str(k)) for k, c in v.items())
        elif isinstance(v, list):
            stack.extend((c, f"{p}[{i}]") for i, c in enumerate(v))
        else:
            yield v, p


def _check_toml_values(x: Any, where: str, path: str) -> None:
    """TOML accepts nan, inf and arbitrarily large integers; no input of the project means them."""
    for v, p in leaves(x, path):
        if isinstance(v, float) and not math.isfinite(v):
            raise SchemaError(f"{where}: key {p}: expected a finite number, got {v}")
        elif isinstance(v, int) and not isinstance(v, bool) and not -INT64_MAX - 1 <= v <= INT64_MAX:
            raise SchemaError(f"{where}: key {p}: integer out of the 64-bit range")
        elif isinstance(v, str) and len(v) > MAX_INPUT_BYTES:
            raise SchemaError(f"{where}: key {p}: string too long")


def load_toml_file(path: str | Path, what: str = "TOML file", max_bytes: int = MAX_INPUT_BYTES) -> dict[str, Any]:
    """``read_input_text`` + ``loads_toml``: the one way a TOML input file is opened."""
    return loads_toml(read_input_text(path, max_bytes=max_bytes, what=what), str(path))


# --------------------------------------------------------------------------- TOML out

def toml_value(v: Any, unit: str | None = None) -> str:
    """``v`` as a TOML value: booleans, integers, floats (``repr``: read back to the bit), strings
    (JSON-escaped, which TOML's basic strings read alike), inline tables and arrays. With ``unit``,
    a number (or each number of a sequence) is a quantity string, ``"1.5 deg"`` (12 significant
    digits), as the scenario and bench formats write quantities."""
    if unit is not None:
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(toml_value(x, unit) for x in v) + "]"
        return json.dumps(f"{float(v):.12g} {unit}", ensure_ascii=False)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, numbers.Integral):
        return str(int(v))
    if isinstance(v, numbers.Real):
        return repr(float(v))
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as TOML")


def dumps_toml(raw: Mapping[str, Any], comments: Mapping[tuple[str, str], str] | None = None,
               header: Sequence[str] = ()) -> str:
    """A document as TOML: ``header`` as comment lines, top-level values after it, a ``[table]``
    (and ``[table.sub]``) for each table, and a comment beside each value that has one in
    ``comments`` (keyed by (table, key))."""
    comments = comments or {}
    lines = [f"# {h}" if h else "#" for h in header] + [""]

    def section(name: str, table: Mapping[str, Any]) -> None:
        plain = {k: v for k, v in table.items() if not isinstance(v, dict)}
        subs = {k: v for k, v in table.items() if isinstance(v, dict)}
        if plain or not subs:
            lines.append(f"[{name}]")
            for k, v in plain.items():
                text = f"{k} = {toml_value(v)}"
                c = comments.get((name, k))
                lines.append(f"{text}  # {c}" if c else text)
            lines.append("")
        for k, v in subs.items():
            section(f"{name}.{k}", v)

    for name, table in raw.items():
        if isinstance(table, dict):
            section(name, table)
        else:
            lines.insert(len(header) + 1, f"{name} = {toml_value(table)}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- declarative checks

KINDS = ("str", "int", "float", "bool", "table", "list", "list[str]", "list[float]", "list[int]", "list[table]", "any")


@dataclass(frozen=True)
class Key:
    """One key of a table: its kind, whether it is required, and its range or choices.

    ``lo``/``hi`` are inclusive bounds of a number (of every element of a list of numbers);
    ``choices`` an enumeration of strings (of every element of a list of strings); ``n_min``/
    ``n_max`` the length of a list or a string."""

    kind: str
    required: bool = False
    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] | None = None
    n_min: int | None = None
    n_max: int | None = None
    doc: str = ""

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"Key kind {self.kind!r} is not one of {KINDS}")


def _kind_ok(v: Any, kind: str) -> bool:
    if kind == "any":
        return True
    if kind == "str":
        return isinstance(v, str)
    if kind == "bool":
        return isinstance(v, bool)
    if kind == "int":
        return isinstance(v, int) and not isinstance(v, bool) and is_number(v)
    if kind == "float":
        return is_number(v)
    if kind == "table":
        return isinstance(v, Mapping)
    if kind.startswith("list"):
        if not isinstance(v, list):
            return False
        inner = kind[5:-1] if kind != "list" else "any"
        return all(_kind_ok(e, inner) for e in v)
    return False


_KIND_TEXT = {"str": "a string", "int": "an integer", "float": "a finite number", "bool": "true or false",
              "table": "a table", "list": "a list", "list[str]": "a list of strings",
              "list[float]": "a list of numbers", "list[int]": "a list of integers",
              "list[table]": "a list of tables", "any": "a value"}


def check_table(node: Any, keys: Mapping[str, Key], where: str, at: str = "",
                extra: bool = False, fail: Callable[[str], Exception] | None = None) -> dict[str, Any]:
    """Check a parsed table against ``keys``; returns it as a dict. Errors (``fail(msg)``, default
    ``SchemaError``) name ``where`` (the file), the key path and what was expected."""
    fail = fail or SchemaError
    head = f"{where}: {at}: " if at else f"{where}: "
    if not isinstance(node, Mapping):
        raise fail(f"{head}expected a table, got {_short(node)}")
    if not extra:
        unknown = [k for k in node if k not in keys]
        if unknown:
            raise fail(f"{head}unknown key {_short(unknown[0])}; expected one of {', '.join(sorted(keys))}")
    for name, k in keys.items():
        if name not in node:
            if k.required:
                raise fail(f"{head}missing key '{name}' ({_KIND_TEXT[k.kind]})")
            continue
        v = node[name]
        if not _kind_ok(v, k.kind):
            raise fail(f"{head}key '{name}': expected {_KIND_TEXT[k.kind]}, got {_short(v)}")
        if k.n_min is not None or k.n_max is not None:
            n = len(v) if isinstance(v, (list, str)) else None
            if n is not None and ((k.n_min is not None and n < k.n_min) or (k.n_max is not None and n > k.n_max)):
                raise fail(f"{head}key '{name}': expected {k.n_min or 0}…{k.n_max if k.n_max is not None else '∞'} "
                           f"{'characters' if isinstance(v, str) else 'items'}, got {n}")
        items: Sequence[Any] = v if isinstance(v, list) else [v]
        for i, e in enumerate(items):
            ix = f"[{i}]" if isinstance(v, list) else ""
            if is_number(e) and ((k.lo is not None and e < k.lo) or (k.hi is not None and e > k.hi)):
                rng = (f"{k.lo:g}…{k.hi:g}" if k.lo is not None and k.hi is not None
                       else f"≥ {k.lo:g}" if k.lo is not None else f"≤ {k.hi:g}")
                raise fail(f"{head}key '{name}'{ix}: expected {rng}, got {_short(e)}")
            if k.choices is not None and isinstance(e, str) and e not in k.choices:
                raise fail(f"{head}key '{name}'{ix}: expected one of {', '.join(k.choices)}, got {_short(e)}")
    return dict(node)


def check_version(node: Mapping[str, Any], where: str, known: Sequence[int] = (1,), at: str = "version",
                  fail: Callable[[str], Exception] | None = None) -> int:
    """The optional ``version`` key of an input file: missing = 1; any other than ``known`` is an
    error (a newer file is never read with an older meaning)."""
    fail = fail or SchemaError
    v = node.get("version", 1) if isinstance(node, Mapping) else 1
    if isinstance(v, bool) or not isinstance(v, int) or v not in known:
        raise fail(f"{where}: key {at}: expected one of {', '.join(map(str, known))} (the file format "
                   f"versions this benchtwin reads), got {_short(v)}")
    return v


def _short(v: Any, n: int = 60) -> str:
    s = repr(v)
    return s if len(s) <= n else s[: n - 1] + "…"
