"""TESA TT80/TT90 probe display, emulated (docs/protocols/tesa.md).

Request ``?`` CR ("request for displayed value") -> ``±xxxx.xx`` CR LF in µm (the TT80 metric
format; more decimals when the twin's probe resolution needs them, as the TT90's ``±xxx.xxx``).
The emulator's choices where the document is silent: a reading out of range is sent as the text
``OVER`` CR LF (the driver returns text as ``status = "instrument_message"``); ``UNI?`` answers
``UM`` (the emulated display is metric, in µm); any other request answers ``ERR23`` (the manual's
example of a rejected command).
"""

from __future__ import annotations

from ._base import ReadingEmulator

__all__ = ["TesaEmulator"]


class TesaEmulator(ReadingEmulator, protocol="tesa", instrument="probe_top", decimals=2,
                   serial={"baudrate": 4800, "bytesize": 7, "parity": "E", "stopbits": 2}):

    def handle(self, request: bytes) -> bytes | None:
        cmd = request.strip()
        if cmd == b"?":
            got = self.reading(self.instrument, "value_um")
            if got is None:
                return b"OVER\r\n"
            return f"{got[0]:+.{self.decimals}f}\r\n".encode("ascii")
        if cmd == b"UNI?":
            return b"UM\r\n"
        return b"ERR23\r\n"
