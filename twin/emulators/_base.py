"""Shared machinery of the protocol emulators: request framing and the reading source.

An emulator is a state machine: ``feed(bytes)`` accumulates what arrived on the port, cuts it into
requests (every protocol emulated here ends its requests with CR and/or LF: docs/protocols/*.md)
and returns, per complete request, the reply bytes (``None``: the instrument stays silent).
``handle(request)`` answers one request without its terminator. The numbers come from a *source*:
anything with ``read(name) -> reading dict`` and ``move(target_deg) -> deg`` (an
``EmulatedBench``, or a stub in tests), so the byte formats can be tested without the physics.

Written from docs/protocols/*.md only (import-linter forbids importing ``benchtwin.hw.drivers``).
"""

from __future__ import annotations

import math
import re
from typing import Any, Protocol

__all__ = ["ReadingSource", "ProtocolEmulator", "decimals_for"]

_TERM = re.compile(rb"[\r\n]")


class ReadingSource(Protocol):
    def read(self, name: str) -> dict[str, Any]: ...

    def move(self, target_deg: float) -> float: ...


def decimals_for(resolution: float, minimum: int = 2, maximum: int = 6) -> int:
    """Decimals that carry a value quantised to ``resolution`` exactly (0.005 -> 3, 0.01 -> 2)."""
    if not resolution or resolution <= 0 or not math.isfinite(resolution):
        return maximum
    d = max(0, math.ceil(-math.log10(resolution) - 1e-9))
    return int(min(max(d, minimum), maximum))


class ProtocolEmulator:
    """Base: framing on CR/LF, request counting, a ``describe()`` for logs and bench files."""

    PROTOCOL = "generic"
    PROTOCOL_DOC = "docs/protocols/README.md"
    DRIVER = ""            # the bench-file driver name that talks this protocol
    SERIAL: dict[str, Any] = {}

    def __init__(self, name: str, source: ReadingSource):
        self.name = str(name)
        self.source = source
        self._buf = b""
        self.requests = 0
        self.log: list[tuple[bytes, bytes | None]] = []
        self.keep_log = False

    def feed(self, data: bytes) -> list[tuple[bytes, bytes | None]]:
        """Bytes from the port -> [(request, reply or None)] for every complete request."""
        self._buf += bytes(data)
        out = []
        while True:
            m = _TERM.search(self._buf)
            if m is None:
                break
            req, self._buf = self._buf[:m.start()], self._buf[m.end():]
            if not req:
                continue  # the LF of a CR LF pair, or an empty line
            self.requests += 1
            reply = self.handle(req)
            if self.keep_log:
                self.log.append((req, reply))
            out.append((req, reply))
        return out

    def handle(self, request: bytes) -> bytes | None:  # pragma: no cover - abstract
        raise NotImplementedError

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "protocol": self.PROTOCOL, "protocol_doc": self.PROTOCOL_DOC,
                "driver": self.DRIVER, "serial": dict(self.SERIAL)}
