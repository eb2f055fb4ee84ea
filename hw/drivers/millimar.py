"""Mahr Millimar C1202 compact amplifier (hw.interfaces.DisplacementProbe), one object per channel.

Protocol document: docs/protocols/millimar.md (sources and uncertainty of every byte below).

Default: request ``M<n>?\\r`` (current value of feature n = 1, 2, 3) answered
``<n> ±XXX.XX <unit>[ <tol>][ <warn>]\\r`` where unit is mm/um/inch (deg/rad/dms also exist and are
refused here: not a displacement), ``<tol>``/``<warn>`` are ``<``, ``=`` or ``>`` when tolerance or
warning limits are active, and ``<n> ERR6`` means the feature is deactivated (returned as
``status = "feature_off"``). 9600 baud, 7 data bits, even parity, 2 stop bits; every command and
reply ends with CR. Channels share one port: pass the same ``SharedPort`` to each object
(``MillimarC1202.channels(...)`` does that).
"""

from __future__ import annotations

import math
import re
from typing import Any, cast

from benchtwin.hw.drivers.base import (Command, FormatError, InstrumentError, ProbeDisplay, SerialInstrument,
                                       SharedPort, parse_float, parse_raw)
from benchtwin.hw.interfaces import ProbeReading

__all__ = ["MillimarC1202", "format_millimar"]

_REPLY = (rb"(?P<ch>\d) (?:(?P<value>[-+]?\s*\d+(?:\.\d+)?) (?P<unit>[A-Za-z\xb5]+)"
          rb"(?: (?P<tol>[<=>]))?(?: (?P<warn>[<=>]))?|(?P<err>ERR\d+)) *\r")

UM_PER = {"mm": 1000.0, "um": 1.0, "\xb5m": 1.0, "inch": 25400.0, "in": 25400.0}
_TOL = {"<": "below", "=": "within", ">": "above"}


def parse_channel(inst: SerialInstrument, m: re.Match[bytes], cmd: Command) -> dict[str, Any]:
    ch = int(m.group("ch"))
    expected = getattr(inst, "channel", ch)
    if ch != expected:
        raise FormatError(f"reply is for feature {ch}, asked for {expected}")
    if m.group("err") is not None:
        err = m.group("err").decode()
        return {"value_um": math.nan, "status": "feature_off" if err == "ERR6" else f"error_{err}", "error": err}
    unit = m.group("unit").decode("latin-1")
    if unit not in UM_PER:
        raise InstrumentError(inst.name, cmd.name, f"feature {ch} displays in {unit!r}, not a length "
                              f"(set mm/um/inch on the instrument)", m.group(0))
    out: dict[str, Any] = {"value_um": parse_float(m.group("value")) * UM_PER[unit], "status": "ok", "unit": unit}
    if m.group("tol"):
        out["tolerance"] = _TOL[m.group("tol").decode()]
    if m.group("warn"):
        out["warning"] = _TOL[m.group("warn").decode()]
    return out


def format_millimar(channel: int, value: float, unit: str = "um", decimals: int = 2, tol: str | None = None) -> bytes:
    """A reply as the C1202 sends it (tests and emulators)."""
    s = f"{channel} {value:+0{decimals + 5}.{decimals}f} {unit}"
    if tol:
        s += f" {tol}"
    return (s + "\r").encode("latin-1")


class MillimarC1202(ProbeDisplay):
    """One feature (channel) of a Millimar C1202. Extra constructor argument: ``channel`` (1..3).
    ``read()`` also gives ``tolerance``/``warning`` when they are active."""

    MODEL = "Mahr Millimar C1202"
    SERIAL_SETTINGS = {"baudrate": 9600, "bytesize": 7, "parity": "E", "stopbits": 2, "timeout": 0.5}
    PROTOCOL_DOC = "docs/protocols/millimar.md"
    DEFAULT_COMMANDS = {"read": Command("read", b"M{channel}?\r", _REPLY, "channel", b"\r")}
    PARSERS = {"channel": parse_channel, "raw": parse_raw}

    def __init__(self, name: str, transport, *, channel: int = 1, **kw: Any) -> None:
        if int(channel) not in (1, 2, 3):
            raise ValueError(f"{name}: channel (feature) must be 1, 2 or 3, got {channel!r}")
        super().__init__(name, transport, **kw)
        self.channel = int(channel)

    @classmethod
    def channels(cls, transport, names: dict[int, str], **kw: Any) -> dict[int, "MillimarC1202"]:
        """One object per channel sharing one port: ``{channel: driver}``."""
        port = transport if isinstance(transport, SharedPort) else SharedPort(transport)
        return {ch: cls(name, port, channel=ch, **kw) for ch, name in names.items()}

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "channel": self.channel}

    def read(self) -> ProbeReading:
        return cast(ProbeReading, self.reading(**self.query("read", channel=self.channel)))
