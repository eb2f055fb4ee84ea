"""Heidenhain ND position display, emulated (docs/protocols/heidenhain-nd.md).

``ESC A0200`` CR ("output of current value") -> ``STX``, then per axis (one per reading head of
the twin's encoder) a sign and a 9-digit value without decimal point, with leading zeros, and
CR LF. The display's resolution setting is ``decimals`` (digits after the decimal point the
display would show; 6 by default so 0…360° fits 9 digits at 1e-6°): the value sent is the twin's
reading rounded to it. Any other request is answered ``NAK`` (0x15), as the manuals say for
commands that cannot be identified.
"""

from __future__ import annotations

from typing import Any

from ._base import ProtocolEmulator

__all__ = ["HeidenhainEmulator", "STX", "NAK"]

STX, NAK, ESC = b"\x02", b"\x15", b"\x1b"


class HeidenhainEmulator(ProtocolEmulator):
    PROTOCOL = "heidenhain-nd"
    PROTOCOL_DOC = "docs/protocols/heidenhain-nd.md"
    DRIVER = "heidenhain"
    SERIAL = {"baudrate": 9600, "bytesize": 7, "parity": "E", "stopbits": 2}

    def __init__(self, name: str, source: Any, instrument: str = "encoder", decimals: int = 6):
        super().__init__(name, source)
        self.instrument = instrument
        self.decimals = int(decimals)

    def handle(self, request: bytes) -> bytes | None:
        cmd = request.lstrip(b"\x11\x13")
        if cmd != ESC + b"A0200":
            return NAK
        r = self.source.read(self.instrument)
        out = STX
        for a in r["angle_deg"]:
            c = int(round(float(a) * 10 ** self.decimals))
            if abs(c) > 999_999_999:
                return STX + b"OVERFLOW     \r\n"  # error text: STX + 13 characters + CR LF
            out += f"{'-' if c < 0 else '+'}{abs(c):09d}\r\n".encode("ascii")
        return out
