"""The model file of ``close-loop`` (``benchtwin-traced-effects`` v1): the traced effects with
their fitted parameters, written (:func:`save_model`), read back (:func:`load_model`) and added to
the Jia et al. 2019 error model (:func:`add_to_error_model`). The strict reader that checks a file
before any analysis runs is :mod:`benchtwin.analysis.model_file`.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np

from benchtwin.jsonable import to_json

from ..effects import ALL
from ..fourier import evaluate_harmonics
from .evidence import Evidence


def _payload(ev: Evidence, effects: list[dict], ambiguous: list[dict], status: str, ctx: dict) -> dict:
    out = []
    for e in effects:
        mod = ALL[e["name"]]
        aux = _jsonable(mod.aux(ev, ctx))
        if e.get("regressor_adjustment_coefs"):
            aux["regressor_adjustment_coefs"] = e["regressor_adjustment_coefs"]
        out.append({"name": e["name"], "params": e["params"], "u": e["u"], "aux": aux,
                    "encoder_error": bool(mod.SEEN_BY_SELFCAL)})
    return {"format": "benchtwin-traced-effects", "version": 1, "status": status, "effects": out,
            "ambiguous": [{"names": a["names"], "separating_measurement": a["separating_measurement"]} for a in ambiguous],
            "created_by": "benchtwin.analysis.tracing.trace"}


# plain JSON types, non-finite floats -> null (benchtwin/jsonable.py)
_jsonable = functools.partial(to_json, nonfinite="null")

def save_model(path, payload: dict) -> None:
    """Write the ``model_file`` payload as JSON, atomically (temporary file, fsync, rename)."""
    from benchtwin.fsio import atomic_write_text

    atomic_write_text(path, json.dumps(_jsonable(payload), indent=2, allow_nan=False))


def _read(path_or_payload) -> dict:
    if isinstance(path_or_payload, dict):
        return path_or_payload
    d = json.loads(Path(path_or_payload).read_text(encoding="utf-8"))
    if d.get("format") != "benchtwin-traced-effects" or d.get("version") != 1:
        raise ValueError(f"{path_or_payload}: not a benchtwin-traced-effects v1 file")
    for e in d["effects"]:
        if e["name"] not in ALL:
            raise ValueError(f"{path_or_payload}: unknown effect {e['name']!r}")
    return d


def load_model(path) -> list[tuple[str, dict[str, float]]]:
    """[(effect_name, params)] from a file written by :func:`save_model`."""
    return [(e["name"], {k: float(v) for k, v in e["params"].items()}) for e in _read(path)["effects"]]


def model_terms_from_payload(path_or_payload, base_terms: dict | None = None) -> dict:
    """Named terms {name: callable(theta_rad) -> arcsec} for ``ErrorModel.add_term``.

    Only encoder errors give terms (reference-chain effects — drift, autocollimator scale,
    hysteresis, polygon pitch — correct the reference data, not the encoder). Effects that scale
    the model's own terms (optical_radius, ccd_pixel_scale) need ``base_terms`` (the ErrorModel's
    ``terms``); without them they are left out.
    """
    d = _read(path_or_payload)
    out = {}
    for e in d["effects"]:
        fn = ALL[e["name"]].term(e["params"], e["aux"], base_terms)
        if fn is not None:
            adj = e["aux"].get("regressor_adjustment_coefs") if isinstance(e.get("aux"), dict) else None
            if adj:
                coefs = {int(k): (float(v[0]), float(v[1])) for k, v in adj.items()}
                fn = (lambda f, cc: (lambda th: np.asarray(f(th), dtype=float)
                                     + evaluate_harmonics(np.rad2deg(np.asarray(th, dtype=float)), cc)))(fn, coefs)
            out[f"traced:{e['name']}"] = fn
    return out


def add_to_error_model(model, path_or_payload) -> list[str]:
    """Add the traced effects to an ``ErrorModel`` (anything with ``terms`` and ``add_term``)."""
    base = dict(getattr(model, "terms", {}) or {})
    terms = model_terms_from_payload(path_or_payload, base)
    for name, fn in terms.items():
        model.add_term(name, fn)
    return list(terms)
