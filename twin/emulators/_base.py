"""Shared machinery of the protocol emulators: request framing, the client's line settings, and
the reading source.

An emulator is a state machine: ``feed(bytes)`` accumulates what arrived on the port, cuts it into
requests and returns, per complete request, the reply bytes (``None``: the instrument stays
silent). By default a request ends with CR and/or LF (every protocol emulated here does:
docs/protocols/*.md); a protocol with fixed-length requests (the Heidenhain ``ESC Axxxx``
sequences) overrides ``split``. ``handle(request)`` answers one request without its terminator.
The numbers come from a *source*: anything with ``read(name) -> reading dict`` and
``move(target_deg) -> deg`` (an ``EmulatedBench``, or a stub in tests), so the byte formats can be
tested without the physics.

Connections (what a real instrument sees as "somebody plugged in and configured their port"):
``connect(framing)`` is called by the server when a client opens the port (a pseudo-terminal whose
line settings changed, or a new TCP connection). It throws away a partial request left by the
previous client (on a real serial line those bytes are noise the device discards when the next
terminator comes: here the previous client is gone, so they would only corrupt the first request
of the next one), and compares the client's line settings with the instrument's (``SERIAL``).
A client at the wrong baud rate (or odd parity on an even-parity instrument) is not understood by
the real device: its bytes are line noise, counted in ``noise_bytes`` and answered with silence,
and ``framing_notes`` says why. Which settings a pseudo-terminal shows is in pty.py.

Written from docs/protocols/*.md only (import-linter forbids importing ``benchtwin.hw.drivers``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import Any, Protocol

__all__ = ["ReadingSource", "ProtocolEmulator", "decimals_for", "Framing"]

_TERM = re.compile(rb"[\r\n]")

# What the server could see of the client's line settings: any key may be missing (unknown).
# {"baudrate": int, "stopbits": 1|2, "parity_odd": bool, "transport": "pty"|"tcp"}
Framing = dict


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
    """Base: framing on CR/LF, connections, request counting, a ``describe()`` for logs and bench
    files."""

    PROTOCOL = "generic"
    PROTOCOL_DOC = "docs/protocols/README.md"
    DRIVER = ""            # the bench-file driver name that talks this protocol
    SERIAL: dict[str, Any] = {}
    TCP_PORT = 0           # the instrument's own TCP port where its Ethernet interface has one (0: any)

    def __init_subclass__(cls, protocol: str | None = None, serial: Mapping[str, Any] | None = None,
                          **kwargs: Any) -> None:
        """``class X(ProtocolEmulator, protocol="tesa", serial={...})``: the protocol's name, which
        is also its driver's and names its document (docs/protocols/<name>.md), and the line
        settings. A class may instead set ``PROTOCOL``, ``DRIVER``, ``PROTOCOL_DOC``, ``SERIAL``."""
        super().__init_subclass__(**kwargs)
        if protocol is not None:
            cls.PROTOCOL = cls.DRIVER = protocol
            cls.PROTOCOL_DOC = f"docs/protocols/{protocol}.md"
        if serial is not None:
            cls.SERIAL = dict(serial)

    def __init__(self, name: str, source: ReadingSource):
        self.name = str(name)
        self.source = source
        self._buf = b""
        self.requests = 0
        self.log: list[tuple[bytes, bytes | None]] = []
        self.keep_log = False
        self.connections = 0
        self.client: Framing = {}
        self.understood = True
        self.noise_bytes = 0
        self.framing_notes: list[str] = []

    # ------------------------------------------------------------------ connections
    def framing_mismatch(self, framing: Framing) -> str | None:
        """Why a client with these line settings cannot talk to this instrument (None: it can).
        Only what a receiver really cannot cope with: a baud rate off by more than the few percent
        a UART tolerates, or odd parity where the instrument uses even/none. Stop bits are not
        compared: a receiver checks only the first one, so 7E1 talks to a 7E2 device."""
        want = self.SERIAL
        baud = framing.get("baudrate")
        if baud and want.get("baudrate") and abs(baud / want["baudrate"] - 1.0) > 0.03:
            return f"client at {baud} baud, the instrument is set to {want['baudrate']} baud"
        if framing.get("parity_odd") and want.get("parity", "N") not in ("O", "M"):
            return f"client set odd/mark parity, the instrument uses parity {want.get('parity', 'N')}"
        return None

    def connect(self, framing: Framing | None = None) -> None:
        """A client opened the port: drop the previous client's partial request, check its framing."""
        self.connections += 1
        self._buf = b""
        self.client = dict(framing or {})
        why = self.framing_mismatch(self.client)
        self.understood = why is None
        if why is not None:
            note = f"{self.name}: connection {self.connections}: {why}; its bytes are line noise to the device"
            self.framing_notes.append(note)
        self.on_connect()

    def on_connect(self) -> None:
        """Per-protocol state reset on a new connection (nothing by default)."""

    # ------------------------------------------------------------------ requests
    def split(self, buf: bytes) -> tuple[list[bytes], bytes]:
        """Complete requests in ``buf`` (terminators removed, empty lines dropped) and the rest."""
        out: list[bytes] = []
        while True:
            m = _TERM.search(buf)
            if m is None:
                return out, buf
            req, buf = buf[:m.start()], buf[m.end():]
            if req:
                out.append(req)

    def feed(self, data: bytes) -> list[tuple[bytes, bytes | None]]:
        """Bytes from the port -> [(request, reply or None)] for every complete request."""
        if not self.understood:
            self.noise_bytes += len(data)
            return []
        self._buf += bytes(data)
        reqs, self._buf = self.split(self._buf)
        out = []
        for req in reqs:
            self.requests += 1
            reply = self.handle(req)
            if self.keep_log:
                self.log.append((req, reply))
            out.append((req, reply))
        return out

    def pending_bytes(self) -> int:
        """Bytes of a request received without its terminator yet (a server limits them)."""
        return len(self._buf)

    def handle(self, request: bytes) -> bytes | None:  # pragma: no cover - abstract
        raise NotImplementedError

    def reading(self, instrument: str, *keys: str) -> tuple[float, ...] | None:
        """The values ``keys`` of the source's reading of ``instrument``, or None where the twin
        reports no valid reading (a status other than "ok", or a value that is not finite): each
        protocol then sends its own out-of-range reply."""
        r = self.source.read(instrument)
        values = tuple(float(r[k]) for k in keys)
        if r.get("status", "ok") != "ok" or not all(math.isfinite(v) for v in values):
            return None
        return values

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "protocol": self.PROTOCOL, "protocol_doc": self.PROTOCOL_DOC,
                "driver": self.DRIVER, "serial": dict(self.SERIAL)}


class ReadingEmulator(ProtocolEmulator):
    """An instrument that reports one reading of the source (``instrument``, default
    ``INSTRUMENT``) with ``decimals`` decimals (default ``DECIMALS``): the probe displays and the
    autocollimators."""

    INSTRUMENT = ""
    DECIMALS = 2

    def __init_subclass__(cls, instrument: str | None = None, decimals: int | None = None, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if instrument is not None:
            cls.INSTRUMENT = instrument
        if decimals is not None:
            cls.DECIMALS = int(decimals)

    def __init__(self, name: str, source: ReadingSource, instrument: str | None = None,
                 decimals: int | None = None):
        super().__init__(name, source)
        self.instrument = self.INSTRUMENT if instrument is None else instrument
        self.decimals = int(self.DECIMALS if decimals is None else decimals)
