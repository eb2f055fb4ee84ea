"""The structure issue's measurable limits, kept (issue 35, "Done when").

Measured as the issue measured them: an ``ast`` walk over the package's folders (twin/, analysis/,
hw/, benchtwin/ and app/, the application layer's own folder since the layering round). Each limit
is checked against the tree and, so the check can fail, against a small source that breaks it.
"""

from __future__ import annotations

import ast
import tomllib
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_DIRS = ("twin", "analysis", "hw", "benchtwin", "app")
MAX_FUNCTION_LINES = 100
MANY_PARAMETERS = 8
MAX_FUNCTIONS_WITH_MANY_PARAMETERS = 10
MAX_PIPELINE_STRING_KEYS = 39  # "fewer than 40"


def _functions(tree: ast.AST) -> Iterator[ast.FunctionDef | ast.AsyncFunctionDef]:
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield node


def _parameters(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    a = fn.args
    names = [*a.posonlyargs, *a.args, *a.kwonlyargs]
    n = len(names) + (a.vararg is not None) + (a.kwarg is not None)
    return n - (1 if names and names[0].arg in ("self", "cls") else 0)


def _string_key_lookups(tree: ast.AST) -> int:
    """``x["key"]`` and ``x.get("key", ...)`` with a literal string key."""
    n = 0
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant) \
                and isinstance(node.slice.value, str):
            n += 1
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get" \
                and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str):
            n += 1
    return n


def _package_trees() -> Iterator[tuple[Path, ast.AST]]:
    for d in PACKAGE_DIRS:
        for path in sorted((ROOT / d).rglob("*.py")):
            yield path, ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def test_the_counters_count() -> None:
    src = ast.parse("def f(self, a, b, *c, d, **e):\n    x = {}\n    return x['k'], x.get('j'), x[0]\n")
    (fn,) = _functions(src)
    assert _parameters(fn) == 5
    assert fn.end_lineno is not None and fn.end_lineno - fn.lineno + 1 == 3
    assert _string_key_lookups(src) == 2


def test_no_function_is_over_100_lines() -> None:
    long = [f"{p.relative_to(ROOT)}:{fn.lineno} {fn.name} ({fn.end_lineno - fn.lineno + 1} lines)"
            for p, tree in _package_trees() for fn in _functions(tree)
            if fn.end_lineno is not None and fn.end_lineno - fn.lineno + 1 > MAX_FUNCTION_LINES]
    assert not long, long


def test_at_most_ten_functions_have_eight_or_more_parameters() -> None:
    many = [f"{p.relative_to(ROOT)}:{fn.lineno} {fn.name} ({_parameters(fn)})"
            for p, tree in _package_trees() for fn in _functions(tree) if _parameters(fn) >= MANY_PARAMETERS]
    assert len(many) <= MAX_FUNCTIONS_WITH_MANY_PARAMETERS, many


def test_the_pipeline_has_fewer_than_40_string_key_lookups() -> None:
    tree = ast.parse((ROOT / "analysis" / "pipeline.py").read_text(encoding="utf-8"))
    assert _string_key_lookups(tree) <= MAX_PIPELINE_STRING_KEYS


def test_no_module_is_exempt_from_mypy_errors() -> None:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    exempt = [o.get("module") for o in cfg.get("tool", {}).get("mypy", {}).get("overrides", [])
              if o.get("ignore_errors")]
    assert not exempt, exempt
