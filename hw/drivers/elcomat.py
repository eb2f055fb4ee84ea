"""Möller-Wedel ELCOMAT 3000-family autocollimator (hw.interfaces.Autocollimator).

Protocol document: docs/protocols/elcomat.md (sources and uncertainty of every byte below).

Defaults: request ``a\\r\\n`` (absolute reading) answered ``4 003 <X> <Y>\\r``; request ``r\\r\\n``
(relative reading) answered ``2 103 <X> <Y>\\r``; X and Y in arcsec; 8N1. Which (first, second) code
pairs mean a valid reading is an option of each command (``options.ok_codes``); any other well-formed
code pair is returned with ``status = "code_<a>_<b>"`` and NaN values, never retried, because we do
not know what the instrument meant. The baud rate default (19200) is a guess: set it in the bench file.
"""

from __future__ import annotations

import math
import re
from typing import Any, cast

from benchtwin.hw.drivers.base import Command, SerialInstrument, parse_float, parse_raw
from benchtwin.hw.interfaces import AutocollimatorReading

__all__ = ["Elcomat", "format_elcomat"]

_NUM = rb"[-+]?\s*\d+(?:\.\d*)?"
_REPLY = rb"(?P<a>\d) (?P<b>\d{3}) +(?P<x>" + _NUM + rb") +(?P<y>" + _NUM + rb")\r"


def parse_xy(inst: SerialInstrument, m: re.Match[bytes], cmd: Command) -> dict[str, Any]:
    code = f"{m.group('a').decode()} {m.group('b').decode()}"
    x = parse_float(m.group("x"), "X")
    y = parse_float(m.group("y"), "Y")
    ok_codes = list(cmd.options.get("ok_codes", []))
    if code in ok_codes:
        return {"x_arcsec": x, "y_arcsec": y, "status": "ok", "code": code}
    return {"x_arcsec": math.nan, "y_arcsec": math.nan, "status": f"code_{code.replace(' ', '_')}", "code": code,
            "x_raw_arcsec": x, "y_raw_arcsec": y}


def format_elcomat(x_arcsec: float, y_arcsec: float, code: str = "4 003", decimals: int = 2) -> bytes:
    """A reply line as the instrument sends it (used by tests and emulators)."""
    return f"{code} {x_arcsec:.{decimals}f} {y_arcsec:.{decimals}f}\r".encode("ascii")


class Elcomat(SerialInstrument):
    """ELCOMAT 3000 family. Extra constructor argument: ``mode`` = "absolute" (``a``, default) or
    "relative" (``r``). ``read()`` -> ``{"x_arcsec", "y_arcsec", "t_s", "status", "code"}``."""

    KIND = "autocollimator"
    MODEL = "Möller-Wedel ELCOMAT 3000 family"
    UNITS = {"x_arcsec": "arcsec", "y_arcsec": "arcsec", "x_raw_arcsec": "arcsec", "y_raw_arcsec": "arcsec"}
    SERIAL_SETTINGS = {"baudrate": 19200, "bytesize": 8, "parity": "N", "stopbits": 1, "timeout": 0.5}
    PROTOCOL_DOC = "docs/protocols/elcomat.md"
    DEFAULT_COMMANDS = {
        "read_absolute": Command("read_absolute", b"a\r\n", _REPLY, "xy", b"\r", options={"ok_codes": ["4 003"]}),
        "read_relative": Command("read_relative", b"r\r\n", _REPLY, "xy", b"\r", options={"ok_codes": ["2 103"]}),
    }
    PARSERS = {"xy": parse_xy, "raw": parse_raw}

    def __init__(self, name: str, transport, *, mode: str = "absolute", **kw: Any) -> None:
        if mode not in ("absolute", "relative"):
            raise ValueError(f"{name}: mode must be 'absolute' or 'relative', got {mode!r}")
        super().__init__(name, transport, **kw)
        self.mode = mode

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "mode": self.mode, "rotation_plane_axis": "x"}

    def read(self) -> AutocollimatorReading:
        r = self.query(f"read_{self.mode}")
        return cast(AutocollimatorReading, self.reading(**r))
