"""Lazy re-exports for the public packages' ``__init__`` (PEP 562 module ``__getattr__``).

Why lazy: ``import benchtwin.analysis.dataset`` (which the twin and hw do) runs
``benchtwin/analysis/__init__.py`` first; an eager ``from .pipeline import analyze`` there would
load the whole analysis (and matplotlib) into every simulation and driver process, and eager
imports in ``benchtwin/__init__.py`` would load MuJoCo for ``benchtwin validate``. A name is
imported from its module the first time it is used, then cached in the package's namespace.
Type checkers read the ``if TYPE_CHECKING:`` imports each ``__init__`` keeps beside its table.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def lazy_exports(package: str, namespace: dict[str, Any], table: Mapping[str, str]
                 ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package``: ``table`` maps an exported name to the
    module (absolute) that defines it."""

    def __getattr__(name: str) -> Any:
        mod = table.get(name)
        if mod is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(mod), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(table))

    return __getattr__, __dir__
