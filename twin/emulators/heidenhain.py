"""Heidenhain ND position display, emulated (docs/protocols/heidenhain-nd.md).

Requests are ``ESC`` + a letter + 4 digits (``ESC A0200``: "output of current value"); the manuals
give them as fixed-length sequences, so the display acts on the 6th character after ``ESC`` and
needs no terminator: a CR or LF after the sequence (pymeasure's ND287 driver sends CR when it opens
the port through VISA, nothing when it is handed a serial adapter) is ignored, and so is anything
before an ``ESC`` (line noise, or a previous client's half-sent request).

- ``ESC A0200`` -> ``STX``, then per axis (one per reading head of the twin's encoder) a sign and a
  9-digit value without decimal point, with leading zeros, and CR LF. ``decimals`` is the display's
  resolution setting (digits after the decimal point it would show; 6 by default so 0…360° fits 9
  digits at 1e-6°): the value sent is the twin's reading rounded to it.
- ``ESC A0000`` (identification) -> ``STX`` + the display's model and software id + CR LF, 37 bytes
  in all (the length pymeasure's ND287 driver reads).
- ``ESC A0301`` (error message) -> ``STX`` + a 33-character text + CR LF (36 bytes, as pymeasure
  reads it): ``NO ERROR`` padded with spaces, or the current error (``OVERFLOW`` when a value does
  not fit 9 digits).
- ``ESC A0800`` (status bar) -> ``STX`` + a 13-character status text + CR LF: ``REF OK DEG``
  (reference marks traversed, display in degrees) padded.
- anything else -> ``NAK`` (0x15), as the manuals say for commands that cannot be identified.

Where the content of the identification, error and status texts is our choice and where only
their framing is documented: docs/protocols/heidenhain-nd.md.
"""

from __future__ import annotations

import re
from typing import Any

from ._base import ProtocolEmulator

__all__ = ["HeidenhainEmulator", "STX", "NAK"]

STX, NAK, ESC = b"\x02", b"\x15", b"\x1b"
_SEQ = re.compile(rb"\x1b([A-Z])(\d{4})")
ID_LEN, ERROR_LEN, STATUS_TEXT_LEN = 37, 36, 13


class HeidenhainEmulator(ProtocolEmulator):
    PROTOCOL = "heidenhain-nd"
    PROTOCOL_DOC = "docs/protocols/heidenhain-nd.md"
    DRIVER = "heidenhain"
    SERIAL = {"baudrate": 9600, "bytesize": 7, "parity": "E", "stopbits": 2}
    TCP_PORT = 0

    def __init__(self, name: str, source: Any, instrument: str = "encoder", decimals: int = 6,
                 model: str = "ND 287", software: str = "benchtwin-emulated"):
        super().__init__(name, source)
        self.instrument = instrument
        self.decimals = int(decimals)
        self.model, self.software = str(model), str(software)
        self.error = ""

    def split(self, buf: bytes) -> tuple[list[bytes], bytes]:
        """Complete ``ESC`` sequences; bytes before an ``ESC`` are noise, a line without one is an
        unidentifiable command (NAK); a half sequence waits for its last characters."""
        out: list[bytes] = []
        while buf:
            esc = buf.find(ESC)
            if esc < 0:
                # no sequence started: a terminated line is an unknown command, the rest waits
                m = re.search(rb"[\r\n]", buf)
                if m is None:
                    return out, buf[-64:]   # bounded: noise without a terminator is dropped
                line, buf = buf[:m.start()].strip(b"\x11\x13 "), buf[m.end():]
                if line:
                    out.append(line)
                continue
            buf = buf[esc:]
            if len(buf) < 6:
                return out, buf
            m = _SEQ.match(buf)
            out.append(buf[:6] if m else buf[:2])
            buf = buf[6:] if m else buf[1:]
            while buf[:1] in (b"\r", b"\n"):
                buf = buf[1:]
        return out, buf

    @staticmethod
    def _text(text: str, n: int) -> bytes:
        return STX + text[:n].ljust(n).encode("ascii") + b"\r\n"

    def handle(self, request: bytes) -> bytes | None:
        m = _SEQ.fullmatch(request)
        code = (m.group(1) + m.group(2)).decode() if m else ""
        if code == "A0200":
            return self._value()
        if code == "A0000":
            return self._text(f"{self.model} {self.software}", ID_LEN - 3)
        if code == "A0301":
            return self._text(self.error or "NO ERROR", ERROR_LEN - 3)
        if code == "A0800":
            return self._text("REF OK DEG", STATUS_TEXT_LEN)
        return NAK

    def _value(self) -> bytes:
        r = self.source.read(self.instrument)
        out = STX
        for a in r["angle_deg"]:
            c = int(round(float(a) * 10 ** self.decimals))
            if abs(c) > 999_999_999:
                self.error = "OVERFLOW"
                return STX + b"OVERFLOW     \r\n"  # error text: STX + 13 characters + CR LF
            out += f"{'-' if c < 0 else '+'}{abs(c):09d}\r\n".encode("ascii")
        self.error = ""
        return out
