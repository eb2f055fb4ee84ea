"""The model file of ``close-loop`` (``analyze --model``), read strictly before any analysis runs.

A model file (``benchtwin-traced-effects`` v1, written by ``analysis.tracing.save_model``) lists
traced effects of the library (``analysis.effects``: Jia 2019 / Hsieh 2022 error sources) with
their fitted parameters. Issue #13: a bad ``--model`` file failed with a traceback after ~10 s of
analysis. ``read_model_file`` checks it completely first, in milliseconds:

- the file: regular, at most 4 MiB, UTF-8, JSON of at most ``benchtwin.schema.MAX_DEPTH`` levels,
  no NaN/Infinity (``benchtwin.schema``);
- the structure: ``format``/``version``, ``effects`` a list of at most 64 tables with a known
  ``name``, ``params`` (and ``u``) tables of finite numbers, ``aux`` a table;
- the content: every effect's term is built and evaluated on a 10° grid against stand-in model
  terms; it must give finite values (a missing ``aux`` key or a wrong type is found here, named).

Errors name the file, the effect (index and name) and the key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.schema import SchemaError, is_number, loads_json, read_input_text

__all__ = ["ModelFileError", "read_model_file", "MAX_MODEL_BYTES", "MAX_EFFECTS"]

MAX_MODEL_BYTES = 4 * 1024 * 1024
MAX_EFFECTS = 64
FORMAT = "benchtwin-traced-effects"


class ModelFileError(ValueError):
    """A model file that cannot be used; the message names the file, the effect and the key."""


class _StandInTerms(dict):
    """Model terms for a trial evaluation: every name is present, each a smooth unit function
    (effects that scale the model's own terms, e.g. optical_radius, need some)."""

    def __contains__(self, key: object) -> bool:
        return True

    def __getitem__(self, key: Any):
        return lambda th: np.sin(np.asarray(th, dtype=float)) + 0.5

    def get(self, key: Any, default: Any = None):
        return self[key]


def read_model_file(path: str | Path) -> dict[str, Any]:
    """The parsed, checked payload of a model file; raises ``ModelFileError``."""
    from benchtwin.analysis.effects import ALL

    p = Path(path)
    try:
        d = loads_json(read_input_text(p, max_bytes=MAX_MODEL_BYTES, what="model file"), str(p))
    except SchemaError as exc:
        raise ModelFileError(str(exc)) from None
    if not isinstance(d, dict):
        raise ModelFileError(f"{p}: expected a JSON object (a model file written by close-loop)")
    if d.get("format") != FORMAT:
        raise ModelFileError(f"{p}: key 'format': expected {FORMAT!r} (a model file written by close-loop), "
                             f"got {_short(d.get('format'))}")
    if d.get("version") != 1 or isinstance(d.get("version"), bool):
        raise ModelFileError(f"{p}: key 'version': expected 1, got {_short(d.get('version'))}")
    effects = d.get("effects")
    if not isinstance(effects, list) or len(effects) > MAX_EFFECTS:
        raise ModelFileError(f"{p}: key 'effects': expected a list of at most {MAX_EFFECTS} effects")
    for i, e in enumerate(effects):
        at = f"{p}: effects[{i}]"
        if not isinstance(e, dict):
            raise ModelFileError(f"{at}: expected an object with name, params, aux")
        name = e.get("name")
        if not isinstance(name, str) or name not in ALL:
            raise ModelFileError(f"{at}.name: expected one of {', '.join(sorted(ALL))}, got {_short(name)}")
        at = f"{at} ({name})"
        for key in ("params", "u"):
            v = e.get(key, {} if key == "u" else None)
            if not isinstance(v, dict) or not all(isinstance(k, str) and is_number(x) for k, x in v.items()):
                raise ModelFileError(f"{at}.{key}: expected an object of finite numbers")
        aux = e.get("aux", {})
        if not isinstance(aux, dict):
            raise ModelFileError(f"{at}.aux: expected an object")
        _trial(ALL[name], e["params"], aux, at)
    return d


def _trial(mod: Any, params: dict, aux: dict, at: str) -> None:
    th = np.deg2rad(np.arange(0.0, 360.0, 10.0))
    try:
        fn = mod.term(params, aux, _StandInTerms())
        if fn is None:
            return
        y = np.asarray(fn(th), dtype=float)
    except KeyError as exc:
        raise ModelFileError(f"{at}: missing key {exc.args[0]!r} (in params or aux)") from None
    except (TypeError, ValueError, AttributeError, IndexError, ZeroDivisionError, OverflowError) as exc:
        raise ModelFileError(f"{at}: params/aux do not give a usable term ({type(exc).__name__}: {exc})") from None
    if y.shape not in (th.shape, ()) or not np.all(np.isfinite(y)):
        raise ModelFileError(f"{at}: params/aux give non-finite values of the term")


def _short(v: Any, n: int = 60) -> str:
    s = repr(v)
    return s if len(s) <= n else s[: n - 1] + "…"
