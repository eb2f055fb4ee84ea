"""The digest of a set of packages' source files: the part of a cache key that says "this code".

A cached result of the twin (the α grid, ``twin/alpha_grid_memo.py``; the report's bench picture,
``app/bench_view.py``) is valid only for the code that computed it. Both key it by the bytes of the
source files it can depend on, each under its path relative to its package's folder, so any edit is
a new key and a stale result is never read. The packages are found by name
(``importlib.util.find_spec``), not imported: a caller lower in the layers (the twin) may name a
package it must not import.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Iterable
from pathlib import Path
from typing import Any


def update_with_sources(h: Any, packages: Iterable[tuple[str, str]]) -> None:
    """Feed ``h`` (a ``hashlib`` object) every file matching ``pattern`` under each ``(package,
    pattern)``'s folder(s), in sorted order: its relative POSIX path, then its bytes (``__pycache__``
    left out)."""
    for name, pattern in packages:
        spec = importlib.util.find_spec(name)
        for folder in (spec.submodule_search_locations or []) if spec is not None else []:
            root = Path(folder)
            for f in sorted(root.rglob(pattern)):
                if f.is_file() and "__pycache__" not in f.parts:
                    h.update(f.relative_to(root).as_posix().encode())
                    h.update(f.read_bytes())
