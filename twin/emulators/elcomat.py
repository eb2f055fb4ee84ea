"""Möller-Wedel ELCOMAT 3000 family autocollimator, emulated (docs/protocols/elcomat.md).

Requests (each ends with CR LF): ``a`` absolute reading -> ``4 003 <X> <Y>`` CR; ``r`` relative
reading -> ``2 103 <X> <Y>`` CR (X, Y in arcsec, one space between fields, fixed decimals). The
emulator's choices where the document is silent: the relative reading is taken against the
absolute reading at the first ``r`` after start (the instrument's zero at that moment); a reading
the twin reports as out of range is sent as the code pair ``4 000`` with zero values (the real
codes for that state are unknown; the driver reports any other pair as ``status = code_a_b``);
an unknown request gets no reply.
"""

from __future__ import annotations

from typing import Any

from ._base import ReadingEmulator

__all__ = ["ElcomatEmulator"]


class ElcomatEmulator(ReadingEmulator, protocol="elcomat", instrument="autocollimator", decimals=3,
                      serial={"baudrate": 19200, "bytesize": 8, "parity": "N", "stopbits": 1}):
    NOT_OK_CODE = "4 000"

    def __init__(self, name: str, source: Any, instrument: str | None = None, decimals: int | None = None):
        super().__init__(name, source, instrument, decimals)
        self.zero: tuple[float, float] | None = None

    def _line(self, code: str, x: float, y: float) -> bytes:
        d = self.decimals
        return f"{code} {x:.{d}f} {y:.{d}f}\r".encode("ascii")

    def handle(self, request: bytes) -> bytes | None:
        cmd = request.strip()
        if cmd not in (b"a", b"r"):
            return None
        got = self.reading(self.instrument, "x_arcsec", "y_arcsec")
        if got is None:
            return self._line(self.NOT_OK_CODE, 0.0, 0.0)
        x, y = got
        if cmd == b"a":
            return self._line("4 003", x, y)
        if self.zero is None:
            self.zero = (x, y)
        return self._line("2 103", x - self.zero[0], y - self.zero[1])
