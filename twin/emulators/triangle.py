"""TRIOPTICS TriAngle / OptiAngle electronic autocollimator, emulated (docs/protocols/triangle.md).

Request ``P 1`` (or the short form ``P``; commands are case sensitive), ended by CR LF (the
document's guess, kept) -> ``<Y>;<X>;<field 2>;<signal>`` CR LF: field 0 is Y, field 1 is X (in the
unit set by ``Unit``, arcsec here: ``Unit SEC``), field 2 is unknown to the document and sent as 0,
field 3 is the signal level (1.000 with a beam; 0.000 when the twin reports the face out of range,
which the driver reads as "no signal"). ``M`` (measure) answers like ``P 1``. Unknown requests get no
reply. ``Unit``/``Zero`` are not emulated (the driver never sends them).
"""

from __future__ import annotations

from ._base import ReadingEmulator

__all__ = ["TriAngleEmulator"]


class TriAngleEmulator(ReadingEmulator, protocol="triangle", instrument="autocollimator", decimals=3,
                       serial={"baudrate": 9600, "bytesize": 8, "parity": "N", "stopbits": 1}):

    def handle(self, request: bytes) -> bytes | None:
        cmd = request.strip()
        if cmd not in (b"P 1", b"P", b"M"):
            return None
        got = self.reading(self.instrument, "x_arcsec", "y_arcsec")
        x, y, signal = (*got, 1.0) if got is not None else (0.0, 0.0, 0.0)   # no beam: signal 0
        d = self.decimals
        return f"{y:.{d}f};{x:.{d}f};{0.0:.{d}f};{signal:.3f}\r\n".encode("ascii")
