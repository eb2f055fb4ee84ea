"""No test module imports another test module (issue 35): what tests share lives in tests/support/
(plain helpers) or in a conftest.py (fixtures). A test module imported by another is collected
twice over, runs its fixtures' and helpers' side effects in a foreign module, and ties two files
that should move independently; this test keeps the rule from now on."""

from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def _is_test_module(dotted: str) -> bool:
    """A module path whose last part is a test module's name (``tests.app.test_study``, ``test_x``)."""
    return dotted.rsplit(".", 1)[-1].startswith("test_")


def imports_of_test_modules(source: str) -> list[tuple[int, str]]:
    """(line, module) of every import of a test module in ``source``: ``import``/``from`` statements
    anywhere (also inside functions), relative or absolute, and ``importlib.import_module("...")``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if any(map(_is_test_module, _prefixes(a.name)))]
        elif isinstance(node, ast.ImportFrom):
            base = "." * node.level + (node.module or "")
            if node.module and any(map(_is_test_module, _prefixes(node.module))):
                found.append((node.lineno, base))
            elif not node.module or not _is_test_module(node.module):
                found += [(node.lineno, base + ("" if base.endswith(".") else ".") + a.name) for a in node.names
                          if _is_test_module(a.name)]
        elif (isinstance(node, ast.Call) and isinstance(node.func, (ast.Attribute, ast.Name))
              and (node.func.attr if isinstance(node.func, ast.Attribute) else node.func.id) == "import_module"
              and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)
              and any(map(_is_test_module, _prefixes(node.args[0].value)))):
            found.append((node.lineno, node.args[0].value))
    return found


def _prefixes(dotted: str) -> list[str]:
    parts = dotted.split(".")
    return [".".join(parts[: i + 1]) for i in range(len(parts))]


def test_no_test_module_imports_another():
    bad = [f"{p.relative_to(TESTS.parent)}:{line}: imports {mod}"
           for p in sorted(TESTS.rglob("test_*.py")) if ".venv" not in p.parts
           for line, mod in imports_of_test_modules(p.read_text(encoding="utf-8"))]
    assert not bad, "a test module imports another (move what they share to tests/support/ or a conftest.py):\n" + \
        "\n".join(bad)


def test_the_rule_sees_every_form_of_import():
    """The check can fail: each way a test module has imported another is caught, and the imports
    of tests/support/ and of ordinary packages are not."""
    caught = {
        "from tests.app.test_study import BASIC": "tests.app.test_study",
        "from .test_emulators import Stub": ".test_emulators",
        "from . import test_emulators": ".test_emulators",
        "import tests.hw.test_tcp": "tests.hw.test_tcp",
        "import test_study": "test_study",
        "def f():\n    from tests.app.test_score_known_error import truth as t\n": "tests.app.test_score_known_error",
        "import importlib\nm = importlib.import_module('test_study').counting_point": "test_study",
    }
    for source, module in caught.items():
        assert [m for _, m in imports_of_test_modules(source)] == [module], source
    for source in ("from tests.support.study import BASIC", "import tests.support.resume",
                   "from benchtwin.app.study import execution", "import pytest", "from . import conftest",
                   "importlib.import_module('tests.support.study')"):
        assert imports_of_test_modules(source) == [], source
