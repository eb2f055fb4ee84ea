"""TESA TT80/TT90 probe display, emulated (docs/protocols/tesa.md).

Request ``?`` CR ("request for displayed value") -> ``±xxxx.xx`` CR LF in µm (the TT80 metric
format; more decimals when the twin's probe resolution needs them, as the TT90's ``±xxx.xxx``).
The emulator's choices where the document is silent: a reading out of range is sent as the text
``OVER`` CR LF (the driver returns text as ``status = "instrument_message"``); ``UNI?`` answers
``UM`` (the emulated display is metric, in µm); any other request answers ``ERR23`` (the manual's
example of a rejected command).
"""

from __future__ import annotations

import math
from typing import Any

from ._base import ProtocolEmulator

__all__ = ["TesaEmulator"]


class TesaEmulator(ProtocolEmulator):
    PROTOCOL = "tesa"
    PROTOCOL_DOC = "docs/protocols/tesa.md"
    DRIVER = "tesa"
    SERIAL = {"baudrate": 4800, "bytesize": 7, "parity": "E", "stopbits": 2}

    def __init__(self, name: str, source: Any, instrument: str = "probe_top", decimals: int = 2):
        super().__init__(name, source)
        self.instrument = instrument
        self.decimals = int(decimals)

    def handle(self, request: bytes) -> bytes | None:
        cmd = request.strip()
        if cmd == b"?":
            r = self.source.read(self.instrument)
            v = float(r["value_um"])
            if r.get("status", "ok") != "ok" or not math.isfinite(v):
                return b"OVER\r\n"
            return f"{v:+.{self.decimals}f}\r\n".encode("ascii")
        if cmd == b"UNI?":
            return b"UM\r\n"
        return b"ERR23\r\n"
