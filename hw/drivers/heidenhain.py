"""Heidenhain ND-style position display / counter with one or more axes (hw.interfaces.AngleEncoder).

Protocol document: docs/protocols/heidenhain-nd.md (sources and uncertainty of every byte below).

Default: request ``ESC A0200 CR`` ("output of current value") answered ``STX`` followed, per axis,
by a sign and 9 digits without decimal point (leading zeros) and ``CR LF``. The decimal point is
not sent: ``decimals`` (from the bench file: the display resolution) scales the integer to degrees.
Each axis is one reading head; ``heads_deg`` (the heads' azimuths from head 1, conventions.md) says
how many there are. The display must be set to decimal degrees (not DMS); this driver never changes
display settings.
"""

from __future__ import annotations

import re
from dataclasses import replace
from typing import Any, cast

from benchtwin.hw.drivers.base import Command, SerialInstrument, parse_raw
from benchtwin.hw.interfaces import EncoderReading

__all__ = ["HeidenhainND", "format_heidenhain"]

_REPLY = rb"[\x11\x13]*\x02(?P<axes>(?:[-+ ]\d{9}\r\n)+)"
_AXIS = re.compile(rb"([-+ ])(\d{9})\r\n")


def parse_axes(inst: SerialInstrument, m: re.Match[bytes], cmd: Command) -> dict[str, Any]:
    counts = [(-1 if s == b"-" else 1) * int(d) for s, d in _AXIS.findall(m.group("axes"))]
    return {"counts": counts}


def format_heidenhain(counts: list[int]) -> bytes:
    """A reply as the display sends it (tests and emulators)."""
    return b"\x02" + b"".join(f"{'-' if c < 0 else '+'}{abs(c):09d}\r\n".encode("ascii") for c in counts)


class HeidenhainND(SerialInstrument):
    """Heidenhain ND display. Extra constructor arguments: ``heads_deg`` (azimuth of each head from
    head 1, one per display axis; default ``[0.0]``), ``decimals`` (digits after the decimal point on
    the display, default 4), ``sign`` (+1/-1 per head or one for all: counting direction relative to
    the bench's positive rotation). ``read()`` -> ``{"heads_deg", "angle_deg", "t_s", "status"}``."""

    KIND = "encoder"
    MODEL = "Heidenhain ND position display"
    UNITS = {"angle_deg": "deg", "heads_deg": "deg"}
    SERIAL_SETTINGS = {"baudrate": 9600, "bytesize": 7, "parity": "E", "stopbits": 2, "timeout": 0.5}
    PROTOCOL_DOC = "docs/protocols/heidenhain-nd.md"
    DEFAULT_COMMANDS = {"read": Command("read", b"\x1bA0200\r", _REPLY, "axes", b"\r\n", options={"nak": "\x15"})}
    PARSERS = {"axes": parse_axes, "raw": parse_raw}

    def __init__(self, name: str, transport, *, heads_deg: list[float] | None = None, decimals: int = 4,
                 sign: int | list[int] = 1, commands=None, **kw: Any) -> None:
        super().__init__(name, transport, commands=commands, **kw)
        self.heads_deg = [float(h) for h in (heads_deg if heads_deg is not None else [0.0])]
        if not self.heads_deg or self.heads_deg[0] != 0.0:
            raise ValueError(f"{name}: heads_deg lists azimuths from head 1, so it starts with 0; got {heads_deg}")
        self.decimals = int(decimals)
        signs = sign if isinstance(sign, (list, tuple)) else [sign] * len(self.heads_deg)
        if len(signs) != len(self.heads_deg) or any(s not in (1, -1) for s in signs):
            raise ValueError(f"{name}: sign must be +1/-1, one per head; got {sign!r}")
        self.signs = [int(s) for s in signs]
        if not (commands and "lines" in commands.get("read", {})):
            self.commands["read"] = replace(self.commands["read"], lines=len(self.heads_deg))

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "heads_deg": list(self.heads_deg), "decimals": self.decimals,
                "resolution_deg": 10.0 ** -self.decimals}

    def _to_deg(self, r: dict[str, Any]) -> dict[str, Any]:
        counts = r["counts"]
        if len(counts) < len(self.heads_deg):
            raise ValueError(f"{len(counts)} axis value(s) for {len(self.heads_deg)} head(s)")
        scale = 10.0 ** -self.decimals
        return {"angle_deg": [s * c * scale for s, c in zip(self.signs, counts)]}

    def read(self) -> EncoderReading:
        r = self.query("read", _post=self._to_deg)
        return cast(EncoderReading, self.reading(heads_deg=list(self.heads_deg), angle_deg=r["angle_deg"]))
