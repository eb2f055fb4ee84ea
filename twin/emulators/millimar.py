"""Mahr Millimar C1202 compact amplifier, emulated (docs/protocols/millimar.md).

Every command and reply ends with CR. ``M1?``/``M2?``/``M3?`` -> ``n ±XXX.XX um`` (the number with
leading zeros, decimals from the twin's probe resolution), ``n ERR6`` for a feature with no probe
(deactivated); ``?`` -> all three features separated by ``;``; ``ID?`` -> an identification text.
The emulator's choices where the document is silent: a reading out of range is sent as
``n ERR1`` (the driver reports ``status = "error_ERR1"``); no tolerance symbols (tolerances off);
an unknown command gets no reply.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ._base import ProtocolEmulator

__all__ = ["MillimarEmulator"]


class MillimarEmulator(ProtocolEmulator, protocol="millimar",
                       serial={"baudrate": 9600, "bytesize": 7, "parity": "E", "stopbits": 2}):

    def __init__(self, name: str, source: Any, channels: Mapping[int, str] | None = None, decimals: int = 2):
        super().__init__(name, source)
        self.channels = {int(k): str(v) for k, v in (channels or {1: "probe_top", 2: "probe_bottom"}).items()}
        bad = [k for k in self.channels if k not in (1, 2, 3)]
        if bad:
            raise ValueError(f"{name}: Millimar features are 1, 2, 3; got {bad}")
        self.decimals = int(decimals)

    def _feature(self, n: int) -> str:
        inst = self.channels.get(n)
        if inst is None:
            return f"{n} ERR6"
        got = self.reading(inst, "value_um")
        if got is None:
            return f"{n} ERR1"
        d = self.decimals
        return f"{n} {got[0]:+0{d + 5}.{d}f} um"

    def handle(self, request: bytes) -> bytes | None:
        cmd = request.strip()
        if len(cmd) == 3 and cmd[:1] == b"M" and cmd[2:] == b"?" and cmd[1:2] in (b"1", b"2", b"3"):
            return (self._feature(int(cmd[1:2])) + "\r").encode("latin-1")
        if cmd == b"?":
            return (";".join(self._feature(n) for n in (1, 2, 3)) + "\r").encode("latin-1")
        if cmd == b"ID?":
            return b"C1202 benchtwin emulator\r"
        return None
