"""The one conversion of results to JSON-ready Python values (numpy included).

Why one place: the dataset writer, the pipeline's results.json, the tracing's model file, the
twin's truth files, the scenario's plain copy and the runner's journal each had their own copy of
"numpy scalars to Python, arrays to lists, tuples to lists" (issue 14), and they differed in two
decisions that are now explicit arguments:

- ``nonfinite="keep"`` (default) leaves NaN/inf floats for ``json.dumps`` to write as ``NaN``;
  ``nonfinite="null"`` turns them into ``None`` (strict JSON, as results.json and model files are);
- ``drop_callables=True`` leaves out mapping entries whose value is callable (the pipeline's
  results carry model terms as functions beside their numbers).

Mapping keys become ``str``; mappings become dicts, lists and tuples lists, numpy arrays lists and
numpy scalars Python scalars; anything else is returned as it is. ``json_default`` is the same
conversion as a ``json.dumps(default=...)`` hook for values json cannot encode itself.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["to_json", "json_default"]


def to_json(x: Any, *, nonfinite: str = "keep", drop_callables: bool = False) -> Any:
    """A JSON-ready copy of ``x`` (see the module docstring for the rules)."""
    if nonfinite not in ("keep", "null"):
        raise ValueError(f"nonfinite: expected 'keep' or 'null', got {nonfinite!r}")
    return _convert(x, nonfinite == "null", drop_callables)


def _convert(x: Any, null: bool, drop: bool) -> Any:
    if isinstance(x, Mapping):
        return {str(k): _convert(v, null, drop) for k, v in x.items() if not (drop and callable(v))}
    if isinstance(x, (list, tuple)):
        return [_convert(v, null, drop) for v in x]
    if isinstance(x, np.ndarray):
        return _convert(x.tolist(), null, drop)
    if isinstance(x, np.generic):
        x = x.item()
    if null and isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def json_default(o: Any) -> Any:
    """``json.dumps(..., default=json_default)``: numpy arrays and scalars; anything else a TypeError."""
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON-serialisable: {type(o).__name__}")
