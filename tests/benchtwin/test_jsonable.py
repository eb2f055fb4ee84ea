"""The one JSON converter (benchtwin/jsonable.py): its rules, and that no other module keeps a copy."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from benchtwin.jsonable import json_default, to_json


def test_numpy_tuples_keys_and_nonfinite():
    x = {1: (np.float64(1.5), np.int64(2)), "a": np.array([[1, 2], [3, 4]]), "n": float("nan"),
         "f": lambda t: t, "b": np.bool_(True)}
    kept = to_json(x)
    assert kept["1"] == [1.5, 2] and type(kept["1"][1]) is int
    assert kept["a"] == [[1, 2], [3, 4]] and kept["b"] is True
    assert math.isnan(kept["n"]) and callable(kept["f"])
    strict = to_json(x, nonfinite="null", drop_callables=True)
    assert strict["n"] is None and "f" not in strict
    assert to_json([np.float32(np.inf)], nonfinite="null") == [None]
    json.dumps(strict, allow_nan=False)
    with pytest.raises(ValueError, match="nonfinite"):
        to_json(1.0, nonfinite="drop")


def test_json_default_hook():
    assert json.dumps({"a": np.arange(3), "b": np.float64(0.25)}, default=json_default) == '{"a": [0, 1, 2], "b": 0.25}'
    with pytest.raises(TypeError, match="not JSON-serialisable: object"):
        json.dumps(object(), default=json_default)


def test_no_other_module_converts_numpy_for_json():
    """One converter: no module of the package defines its own numpy -> JSON conversion again."""
    root = Path(__file__).resolve().parents[2]
    pattern = re.compile(r"^def (_jsonable|_json_default|_json|_plain)\(", re.M)
    offenders = [f"{p.relative_to(root)}: {m.group(1)}" for folder in ("benchtwin", "twin", "analysis", "hw")
                 for p in (root / folder).rglob("*.py") for m in pattern.finditer(p.read_text())]
    assert not offenders, offenders
