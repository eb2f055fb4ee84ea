"""Conformance check of an instrument against the return shapes in ``hw/interfaces.py``.

``check_conformance(instrument, kind)`` calls ``describe()`` and the kind's reading methods once each
and returns a list of problems (empty = conforms). It is used on the serial drivers (replayed, see
tests/hw/test_conformance_drivers.py) and on the twin's simulated instruments alike, so it only
relies on the protocols: it imports nothing from the twin. For a stage, ``move_to`` is called only
when ``move_to_deg`` is given (it moves the stage).

Checks: the ``typing.Protocol`` of the kind (``isinstance``); ``describe()`` has ``name`` (= the
``name`` attribute), ``kind`` (= ``kind``), ``model`` (str) and ``units`` (dict str -> str) and every
unit-suffixed key a reading returns (``value_um``, ``x_arcsec``, ``angle_deg``, ...) is in ``units``
with the unit its suffix names; every reading has ``t_s`` (finite float) and ``status`` (non-empty
str); the kind's keys and types: probe ``value_um`` float; encoder ``heads_deg`` and ``angle_deg``
equal-length non-empty lists of floats with ``heads_deg[0] == 0``; autocollimator ``x_arcsec``,
``y_arcsec`` floats; stage ``position()`` ``angle_deg`` float and ``move_to`` ``target_deg`` float
and ``duration_s`` float >= 0; camera ``image`` 2-D uint8/uint16. Values may be NaN only when
``status`` is not "ok".

Stage soft limits (the ``RotaryStage`` contract, the same for the twin's stage and the drivers):
``describe()["soft_limits_deg"]`` is ``[low, high]`` (low < high) or None; with
``check_soft_limits`` (default) ``move_to`` is called with a target above ``high`` and with NaN,
and each must raise ``SoftLimitError`` (not return a status, not raise anything else), leaving
``position()["angle_deg"]`` unchanged. A conforming stage sends nothing for these calls (a
replayed driver proves it: its transcript has no such exchange); against a live stage whose
driver has not been proven on a transcript, pass ``check_soft_limits=False``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from benchtwin.hw.interfaces import INSTRUMENT_KINDS, SoftLimitError

__all__ = ["check_conformance", "SUFFIX_UNITS"]

SUFFIX_UNITS = {"_um": "um", "_mm": "mm", "_deg": "deg", "_arcsec": "arcsec", "_s": "s", "_px": "px"}

_REQUIRED = {
    "probe": {"value_um": "float"},
    "encoder": {"heads_deg": "list", "angle_deg": "list"},
    "autocollimator": {"x_arcsec": "float", "y_arcsec": "float"},
    "stage": {"angle_deg": "float"},
    "camera": {"image": "image"},
}


def _is_float(v: Any) -> bool:
    return isinstance(v, (float, int, np.floating, np.integer)) and not isinstance(v, bool)


def _unit_of(key: str) -> str | None:
    if key == "t_s":
        return None
    for suffix, unit in SUFFIX_UNITS.items():
        if key.endswith(suffix):
            return unit
    return None


def _check_reading(label: str, r: Any, required: dict[str, str], units: dict[str, str], problems: list[str]) -> None:
    if not isinstance(r, dict):
        problems.append(f"{label} returned {type(r).__name__}, expected dict")
        return
    status = r.get("status")
    if not isinstance(status, str) or not status:
        problems.append(f"{label}: 'status' must be a non-empty str, got {status!r}")
    t: Any = r.get("t_s")
    if not _is_float(t) or not math.isfinite(float(t)):
        problems.append(f"{label}: 't_s' must be a finite float, got {t!r}")
    ok = status == "ok"
    for key, typ in required.items():
        if key not in r:
            problems.append(f"{label}: missing key {key!r} (has {sorted(r)})")
            continue
        v = r[key]
        if typ == "float":
            if not _is_float(v):
                problems.append(f"{label}: {key!r} must be a float, got {type(v).__name__}")
            elif ok and not math.isfinite(float(v)):
                problems.append(f"{label}: {key!r} is {v} with status 'ok'")
        elif typ == "list":
            if not isinstance(v, (list, tuple)) or not v or not all(_is_float(x) for x in v):
                problems.append(f"{label}: {key!r} must be a non-empty list of floats, got {v!r}")
            elif ok and not all(math.isfinite(float(x)) for x in v):
                problems.append(f"{label}: {key!r} has non-finite values with status 'ok'")
        elif typ == "image":
            a = np.asarray(v) if v is not None else None
            if a is None or a.ndim != 2 or a.dtype not in (np.uint8, np.uint16):
                problems.append(f"{label}: 'image' must be a 2-D uint8/uint16 array, got "
                                f"{None if a is None else (a.shape, str(a.dtype))}")
    for key in r:
        unit = _unit_of(key)
        if unit is None or (key == "duration_s" and key not in units):
            continue  # t_s is universal; duration_s (move_to) is seconds by the protocol
        if key not in units:
            problems.append(f"{label}: key {key!r} is not in describe()['units']")
        elif units[key] != unit:
            problems.append(f"{label}: describe()['units'][{key!r}] = {units[key]!r}, but the key says {unit!r}")


def _check_soft_limits(instrument: Any, d: dict, first_position: Any, problems: list[str]) -> None:
    if "soft_limits_deg" not in d:
        problems.append("describe() lacks 'soft_limits_deg' ([low, high] in deg, or None)")
        return
    lim = d["soft_limits_deg"]
    if lim is not None:
        if (not isinstance(lim, (list, tuple)) or len(lim) != 2 or not all(_is_float(v) for v in lim)
                or not all(math.isfinite(float(v)) for v in lim) or not float(lim[0]) < float(lim[1])):
            problems.append(f"describe()['soft_limits_deg'] must be [low, high] with low < high or None, got {lim!r}")
            return
    before = first_position.get("angle_deg") if isinstance(first_position, dict) else None
    targets = ([float(lim[1]) + max(1.0, 0.01 * (float(lim[1]) - float(lim[0])))] if lim is not None else [])
    for target in targets + [math.nan]:
        label = f"move_to({target}) outside the soft limits {lim}"
        try:
            r = instrument.move_to(target)
        except SoftLimitError:
            pass
        except Exception as exc:  # noqa: BLE001 - reported, not raised
            problems.append(f"{label} raised {type(exc).__name__} ({exc}), expected SoftLimitError")
            continue
        else:
            problems.append(f"{label} returned {r!r} instead of raising SoftLimitError")
            continue
        try:
            after = instrument.position().get("angle_deg")
        except Exception as exc:  # noqa: BLE001
            problems.append(f"position() after a refused move raised {type(exc).__name__}: {exc}")
            continue
        if before is not None and after != before:
            problems.append(f"{label}: the stage moved from {before} to {after} deg")


def check_conformance(instrument: Any, kind: str, *, move_to_deg: float | None = None,
                      check_soft_limits: bool = True) -> list[str]:
    """Problems found (empty list: the instrument conforms to ``kind``'s protocol and shapes)."""
    problems: list[str] = []
    if kind not in INSTRUMENT_KINDS:
        return [f"unknown kind {kind!r}; known: {sorted(INSTRUMENT_KINDS)}"]
    proto = INSTRUMENT_KINDS[kind]
    if not isinstance(instrument, proto):
        problems.append(f"{type(instrument).__name__} does not implement {proto.__name__}")
    name = getattr(instrument, "name", None)
    if not isinstance(name, str) or not name:
        problems.append(f"'name' attribute must be a non-empty str, got {name!r}")
    try:
        d = instrument.describe()
    except Exception as exc:  # noqa: BLE001 - reported, not raised
        return problems + [f"describe() raised {type(exc).__name__}: {exc}"]
    units: dict[str, str] = {}
    if not isinstance(d, dict):
        return problems + [f"describe() returned {type(d).__name__}, expected dict"]
    for key in ("name", "kind", "model", "units"):
        if key not in d:
            problems.append(f"describe() lacks {key!r}")
    if d.get("name") != name:
        problems.append(f"describe()['name'] = {d.get('name')!r} differs from .name = {name!r}")
    if "kind" in d and d["kind"] != kind:
        problems.append(f"describe()['kind'] = {d['kind']!r}, expected {kind!r}")
    if "model" in d and not isinstance(d["model"], str):
        problems.append("describe()['model'] must be a str")
    if isinstance(d.get("units"), dict) and all(isinstance(k, str) and isinstance(v, str) for k, v in d["units"].items()):
        units = d["units"]
    elif "units" in d:
        problems.append(f"describe()['units'] must be a dict of str -> str, got {d['units']!r}")

    calls: list[tuple[str, Any, dict[str, str]]] = []
    if kind in ("probe", "encoder", "autocollimator"):
        calls.append(("read()", lambda: instrument.read(), _REQUIRED[kind]))
    elif kind == "camera":
        calls.append(("capture()", lambda: instrument.capture(), _REQUIRED[kind]))
    elif kind == "stage":
        calls.append(("position()", lambda: instrument.position(), _REQUIRED[kind]))
        if move_to_deg is not None:
            calls.append((f"move_to({move_to_deg})", lambda: instrument.move_to(move_to_deg),
                          {"target_deg": "float", "duration_s": "float"}))
    for label, call, required in calls:
        try:
            r = call()
        except Exception as exc:  # noqa: BLE001 - reported, not raised
            problems.append(f"{label} raised {type(exc).__name__}: {exc}")
            continue
        _check_reading(label, r, required, units, problems)
        if label == "position()" and check_soft_limits:
            _check_soft_limits(instrument, d, r, problems)
        if kind == "encoder" and isinstance(r, dict):
            h, a = r.get("heads_deg"), r.get("angle_deg")
            if isinstance(h, (list, tuple)) and isinstance(a, (list, tuple)):
                if len(h) != len(a):
                    problems.append(f"{label}: heads_deg has {len(h)} entries, angle_deg {len(a)}")
                if h and h[0] != 0:
                    problems.append(f"{label}: heads_deg[0] must be 0 (azimuths from head 1), got {h[0]}")
        if label.startswith("move_to") and isinstance(r, dict):
            dur: Any = r.get("duration_s")
            if _is_float(dur) and float(dur) < 0:
                problems.append(f"{label}: duration_s is negative ({dur})")
    return problems
