"""TESA TT-series (TT80/TT90 family) inductive-probe display (hw.interfaces.DisplacementProbe).

Protocol document: docs/protocols/tesa.md (sources and uncertainty of every byte below).

Default: request ``?\\r`` ("request for displayed value") answered ``±xxxx.xx\\r\\n``; 4800 baud,
7 data bits, even parity, 2 stop bits. The reply carries no unit: the display's unit (µm by default
here, ``um_per_unit`` from the bench file otherwise) must match the instrument's setting, which this
driver never changes. A reply that is text instead of a number is returned as
``status = "instrument_message"`` with the text in ``message`` (not retried).
"""

from __future__ import annotations

import math
import re
from typing import Any, cast

from benchtwin.hw.drivers.base import Command, ProbeDisplay, SerialInstrument, parse_float, parse_raw
from benchtwin.hw.interfaces import ProbeReading

__all__ = ["TesaTT", "format_tesa"]

_REPLY = rb"(?:(?P<value>[-+]\s*\d*\.?\d+|[-+]?\s*\d+\.\d*)|(?P<msg>[A-Za-z][ -~]*?))\s*\r\n"


def parse_value(inst: SerialInstrument, m: re.Match[bytes], cmd: Command) -> dict[str, Any]:
    if m.group("msg") is not None:
        return {"value": math.nan, "status": "instrument_message", "message": m.group("msg").decode("ascii")}
    return {"value": parse_float(m.group("value")), "status": "ok"}


def format_tesa(value: float, decimals: int = 2) -> bytes:
    """A reply as the TT80 sends it: explicit sign, fixed decimals, CR LF."""
    return f"{value:+.{decimals}f}\r\n".encode("ascii")


class TesaTT(ProbeDisplay):
    """TESA TT80/TT90. Extra constructor argument: ``um_per_unit`` (1.0: display in µm; 1000.0 for mm)."""

    MODEL = "TESA TT-series display"
    SERIAL_SETTINGS = {"baudrate": 4800, "bytesize": 7, "parity": "E", "stopbits": 2, "timeout": 0.5}
    PROTOCOL_DOC = "docs/protocols/tesa.md"
    DEFAULT_COMMANDS = {"read": Command("read", b"?\r", _REPLY, "value", b"\r\n")}
    PARSERS = {"value": parse_value, "raw": parse_raw}

    def __init__(self, name: str, transport, *, um_per_unit: float = 1.0, **kw: Any) -> None:
        super().__init__(name, transport, **kw)
        self.um_per_unit = float(um_per_unit)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "um_per_unit": self.um_per_unit}

    def read(self) -> ProbeReading:
        r = self.query("read")
        out = {"value_um": r["value"] * self.um_per_unit, "status": r["status"]}
        if "message" in r:
            out["message"] = r["message"]
        return cast(ProbeReading, self.reading(**out))
