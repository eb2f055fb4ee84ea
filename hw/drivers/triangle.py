"""TRIOPTICS TriAngle / OptiAngle family electronic autocollimator (hw.interfaces.Autocollimator).

Protocol document: docs/protocols/triangle.md (sources and uncertainty of every byte below).

Default: request ``P 1\\r\\n`` ("Poll", short form, measurement 1) answered by ``;``-separated
numbers ``<f0>;<f1>;<f2>;<f3>...\\r\\n``. Public third-party code reads field 0 as the instrument's Y
angle, field 1 as X, and field 3 as the signal level, treating a level <= 0.01 as "no signal". Which
field is which, the no-signal threshold and the scale to arcsec (the unit is whatever the
instrument's ``Unit`` setting is; this driver never changes it) are constructor arguments taken from
the bench file.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from typing import Any, cast

from benchtwin.hw.drivers.base import Command, FormatError, SerialInstrument, parse_float, parse_raw
from benchtwin.hw.interfaces import AutocollimatorReading

__all__ = ["TriAngle", "TriAngleSettings", "format_triangle"]

_NUM = rb"\s*[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?\s*"
_REPLY = rb"(?P<values>" + _NUM + rb"(?:;" + _NUM + rb")*);?\r\n"


def parse_fields(inst: SerialInstrument, m: re.Match[bytes], cmd: Command) -> dict[str, Any]:
    parts = [p for p in m.group("values").split(b";")]
    return {"fields": [parse_float(p, f"field {i}") for i, p in enumerate(parts)]}


def format_triangle(fields: list[float], decimals: int = 3) -> bytes:
    """A reply line as the instrument sends it (tests and emulators)."""
    return (";".join(f"{v:.{decimals}f}" for v in fields) + "\r\n").encode("ascii")


@dataclass(frozen=True)
class TriAngleSettings:
    """Which fields of the reply are x, y and the signal level (None: no signal field), the signal
    level at or below which there is no signal, and arcsec per reply unit (1: the instrument set to
    ``Unit SEC``)."""

    x_field: int = 1
    y_field: int = 0
    signal_field: int | None = 3
    no_signal_below: float = 0.01
    arcsec_per_unit: float = 1.0


_TRIANGLE_FIELDS = tuple(f.name for f in dataclasses.fields(TriAngleSettings))


class TriAngle(SerialInstrument):
    """TRIOPTICS TriAngle. Extra constructor arguments: ``x_field`` (1), ``y_field`` (0),
    ``signal_field`` (3), ``no_signal_below`` (0.01: a signal level <= this is "no_signal"),
    ``arcsec_per_unit`` (1.0: the instrument set to ``Unit SEC``). ``read()`` ->
    ``{"x_arcsec", "y_arcsec", "signal", "t_s", "status"}``; with no signal, x/y are NaN."""

    KIND = "autocollimator"
    MODEL = "TRIOPTICS TriAngle family"
    UNITS = {"x_arcsec": "arcsec", "y_arcsec": "arcsec"}
    SERIAL_SETTINGS = {"baudrate": 9600, "bytesize": 8, "parity": "N", "stopbits": 1, "timeout": 0.5}
    PROTOCOL_DOC = "docs/protocols/triangle.md"
    DEFAULT_COMMANDS = {"poll": Command("poll", b"P 1\r\n", _REPLY, "fields", b"\r\n")}
    PARSERS = {"fields": parse_fields, "raw": parse_raw}

    def __init__(self, name: str, transport, fields: TriAngleSettings | None = None, **kw: Any) -> None:
        """``fields`` (a ``TriAngleSettings``), or its fields as keywords beside the common ones
        (``SerialInstrument``'s ``LinkSettings``)."""
        if fields is None:
            fields = TriAngleSettings(**{k: kw.pop(k) for k in _TRIANGLE_FIELDS if k in kw})
        super().__init__(name, transport, **kw)
        self.x_field, self.y_field, self.signal_field = int(fields.x_field), int(fields.y_field), fields.signal_field
        self.no_signal_below = float(fields.no_signal_below)
        self.arcsec_per_unit = float(fields.arcsec_per_unit)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "x_field": self.x_field, "y_field": self.y_field,
                "signal_field": self.signal_field, "no_signal_below": self.no_signal_below,
                "arcsec_per_unit": self.arcsec_per_unit, "rotation_plane_axis": "x"}

    def _interpret(self, fields: list[float]) -> dict[str, Any]:
        need = max(self.x_field, self.y_field, self.signal_field if self.signal_field is not None else 0) + 1
        if len(fields) < need:
            raise FormatError(f"expected at least {need} ';'-separated fields, got {len(fields)}")
        out: dict[str, Any] = {"x_arcsec": fields[self.x_field] * self.arcsec_per_unit,
                               "y_arcsec": fields[self.y_field] * self.arcsec_per_unit, "status": "ok"}
        if self.signal_field is not None:
            out["signal"] = fields[self.signal_field]
            if out["signal"] <= self.no_signal_below:
                out.update(x_arcsec=math.nan, y_arcsec=math.nan, status="no_signal")
        return out

    def read(self) -> AutocollimatorReading:
        return cast(AutocollimatorReading,
                    self.reading(**self.query("poll", _post=lambda r: self._interpret(r["fields"]))))
