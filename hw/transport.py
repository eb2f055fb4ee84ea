"""Byte transports for the serial drivers: the contract, how a port is opened, and transcripts.

The contract is pyserial's subset that the drivers use (``Transport``): ``read(n)``, ``write(b)``,
``readline()``, ``read_until(expected)``, a ``timeout`` attribute, ``reset_input_buffer()`` and
``close()``. A ``serial.Serial`` satisfies it, and so do the two wrappers here:

- ``RecordingTransport`` wraps a live transport and saves every request/response pair to a JSON-lines
  transcript while passing the bytes through unchanged.
- ``ReplayTransport`` serves a transcript in strict order: a request that differs from the next
  recorded one raises ``ReplayMismatch`` showing expected and received bytes; ``assert_done()``
  raises if exchanges are left over. Drivers are tested this way (tests/hw/transcripts/).

Drivers never open ports themselves: the caller opens one with ``open_transport(spec, ...)`` (a port
name such as ``COM3``/``/dev/ttyUSB0``, a pseudo-terminal path such as ``/dev/pts/7``, an instrument's
Ethernet interface ``tcp://host:port``, or any pyserial URL such as ``loop://`` or
``socket://host:port``) and hands it to the driver.

``tcp://host:port`` opens a ``SocketTransport``: the same contract over a TCP connection (an
instrument's LAN interface carrying its serial protocol, e.g. Zaber ASCII on port 55550, or
``benchtwin emulate --tcp``). A socket has no line settings: baud rate, data bits, parity and stop
bits are ignored; ``timeout`` applies to every read as on a serial port. A closed connection raises
``TransportClosed`` (a ``serial.SerialException``), so the drivers' reconnect path handles it like
an unplugged serial cable.

Transcript format (one JSON object per line; byte strings are JSON strings holding one character per
byte, i.e. bytes decoded as latin-1, so ``"\\r\\n"`` and ``"\\u001b"`` read naturally)::

    {"request": "a\\r\\n", "response": "4 003 1.23 -4.56\\r"}
    {"request": "a\\r\\n", "response": ""}                        # nothing came back: a timeout
    {"request": "a\\r\\n", "response": "4 00"}                    # partial line, then timeout
    {"request": "a\\r\\n", "response": "", "error": "disconnect"} # the port died on this request
    {"event": "reopen"}                                        # the caller re-opened the port
    {"comment": "free text"}                                   # ignored

Optional keys ``note`` (free text) are ignored. Protocol notes: docs/protocols/*.md.
"""

from __future__ import annotations

import json
import select
import socket
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import serial

__all__ = [
    "Transport", "open_transport", "RecordingTransport", "ReplayTransport", "ReplayMismatch",
    "TransportClosed", "bytes_to_text", "text_to_bytes", "load_transcript", "reopener", "SocketTransport",
]


@runtime_checkable
class Transport(Protocol):
    """The byte-level contract every driver talks through (a subset of ``serial.Serial``).

    ``read``/``readline``/``read_until`` return what arrived before ``timeout`` seconds passed, which
    may be fewer bytes than asked for or no terminator at all: the drivers treat that as a timeout or
    a partial line. ``write`` returns the number of bytes written. A disconnected port raises
    ``serial.SerialException`` (or ``OSError``) from any call.
    """

    timeout: float | None

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes) -> int | None: ...

    def readline(self, size: int | None = -1) -> bytes: ...

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes: ...

    def reset_input_buffer(self) -> None: ...

    def close(self) -> None: ...


class TransportClosed(serial.SerialException):
    """The transport was closed or the instrument disconnected (a ``serial.SerialException``)."""


class ReplayMismatch(AssertionError):
    """A driver sent something other than the transcript's next request (or left exchanges over)."""


_PARITY = {"N": serial.PARITY_NONE, "E": serial.PARITY_EVEN, "O": serial.PARITY_ODD,
           "M": serial.PARITY_MARK, "S": serial.PARITY_SPACE}


def bytes_to_text(data: bytes) -> str:
    """Bytes as a transcript string: one character per byte (latin-1)."""
    return bytes(data).decode("latin-1")


def text_to_bytes(text: str) -> bytes:
    """Inverse of ``bytes_to_text``; characters above U+00FF are refused."""
    try:
        return text.encode("latin-1")
    except UnicodeEncodeError as exc:
        raise ValueError(f"transcript strings hold one character per byte (U+0000..U+00FF); got {text!r}") from exc


def open_transport(spec: str | Mapping[str, Any], *, baudrate: int = 9600, bytesize: int = 8,
                   parity: str = "N", stopbits: float = 1, timeout: float = 1.0,
                   xonxoff: bool = False, rtscts: bool = False) -> serial.SerialBase:
    """Open a port explicitly and return it (a ``serial.Serial`` or URL handler).

    ``spec`` is a port name (``COM3``, ``/dev/ttyUSB0``), a pseudo-terminal path (``/dev/pts/7``), a
    pyserial URL (``loop://``, ``socket://localhost:7777``, ``rfc2217://...``) or a mapping (a
    bench-file section) with ``port`` and optionally the keyword settings below, which then override
    the keyword arguments (a driver's ``SERIAL_SETTINGS`` are the usual keyword arguments).
    ``parity`` is one letter N/E/O/M/S. The port is opened here, never inside a driver.
    """
    settings: dict[str, Any] = dict(baudrate=baudrate, bytesize=bytesize, parity=parity, stopbits=stopbits,
                                    timeout=timeout, xonxoff=xonxoff, rtscts=rtscts)
    if isinstance(spec, Mapping):
        section = dict(spec)
        try:
            port = section.pop("port")
        except KeyError:
            raise ValueError(f"transport section needs a 'port' key, got keys {sorted(section)}") from None
        unknown = set(section) - set(settings)
        if unknown:
            raise ValueError(f"unknown transport settings {sorted(unknown)}; known: {sorted(settings)}")
        settings.update(section)
    else:
        port = spec
    if not isinstance(port, str) or not port:
        raise ValueError(f"transport spec must be a non-empty port name, path or URL, got {port!r}")
    par = str(settings["parity"]).upper()[:1]
    if par not in _PARITY:
        raise ValueError(f"parity must be one of N/E/O/M/S, got {settings['parity']!r}")
    if port.startswith("tcp://"):
        return SocketTransport.open(port, timeout=settings["timeout"])
    return serial.serial_for_url(port, baudrate=int(settings["baudrate"]), bytesize=int(settings["bytesize"]),
                                 parity=_PARITY[par], stopbits=settings["stopbits"],
                                 timeout=settings["timeout"], xonxoff=bool(settings["xonxoff"]),
                                 rtscts=bool(settings["rtscts"]))


class _BufferedReads:
    """``read``/``read_until``/``readline``/``in_waiting`` of a transport over its byte buffer
    ``_buf``, which ``_fill`` tops up until a deadline (a socket: the bytes as they arrive; a
    transcript: its response is queued on the write, so ``_fill`` has nothing more: reads never
    wait). pyserial's semantics: a read returns what arrived by the timeout."""

    _buf = b""

    def _check(self) -> None:  # pragma: no cover - each transport says when it is closed
        raise NotImplementedError

    def _fill(self, deadline: float | None) -> bool:
        """Wait for more bytes until ``deadline``; False when none can come."""
        return False

    def _deadline(self) -> float | None:
        return None

    def read(self, size: int = 1) -> bytes:
        self._check()
        deadline = self._deadline()
        while len(self._buf) < size and self._fill(deadline):
            pass
        out, self._buf = self._buf[:size], self._buf[size:]
        return out

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes:
        self._check()
        deadline = self._deadline()
        while True:
            idx = self._buf.find(expected)
            if idx >= 0 or (size is not None and 0 <= size <= len(self._buf)):
                break
            if not self._fill(deadline):
                break
        end = len(self._buf) if idx < 0 else idx + len(expected)
        if size is not None and size >= 0:
            end = min(end, size)
        out, self._buf = self._buf[:end], self._buf[end:]
        return out

    def readline(self, size: int | None = -1) -> bytes:
        return self.read_until(b"\n", None if size is None or size < 0 else size)

    @property
    def in_waiting(self) -> int:
        return len(self._buf)


class SocketTransport(_BufferedReads):
    """The ``Transport`` contract over a TCP connection (see the module docstring).

    ``SocketTransport.open("tcp://127.0.0.1:55550", timeout=0.5)`` connects (``serial.SerialException``
    naming the address when it cannot). Reads wait at most ``timeout`` seconds in all (``None``:
    forever), as pyserial's do, and return what arrived."""

    def __init__(self, sock: socket.socket, *, timeout: float | None = 1.0, name: str = "") -> None:
        self.sock = sock
        self.timeout = timeout
        self.name = name
        self.port = name
        self._buf = b""
        self.is_open = True

    @classmethod
    def open(cls, url: str, *, timeout: float | None = 1.0, connect_timeout_s: float = 5.0) -> "SocketTransport":
        host, sep, port = url[len("tcp://"):].rpartition(":")
        if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise ValueError(f"TCP port spec must be tcp://HOST:PORT, got {url!r}")
        try:
            sock = socket.create_connection((host.strip("[]"), int(port)), timeout=connect_timeout_s)
        except OSError as exc:
            raise serial.SerialException(f"cannot connect to {host}:{port}: {exc}") from exc
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.setblocking(False)
        return cls(sock, timeout=timeout, name=url)

    def _check(self) -> None:
        if not self.is_open:
            raise TransportClosed(f"{self.name}: connection is closed")

    def _fill(self, deadline: float | None) -> bool:
        """Wait for more bytes until ``deadline``; False on timeout. Raises when the peer closed."""
        wait = None if deadline is None else max(0.0, deadline - time.monotonic())
        try:
            r, _, _ = select.select([self.sock], [], [], wait)
        except (OSError, ValueError) as exc:
            raise TransportClosed(f"{self.name}: {exc}") from exc
        if not r:
            return False
        self._buf += self._recv()
        return True

    def _recv(self) -> bytes:
        """What has arrived (b"": nothing after all). Raises ``TransportClosed`` when the connection
        is lost or the instrument closed it."""
        try:
            chunk = self.sock.recv(4096)
        except BlockingIOError:
            return b""
        except OSError as exc:
            raise self._lost(exc) from exc
        if not chunk:
            self.is_open = False
            raise TransportClosed(f"{self.name}: the instrument closed the connection")
        return chunk

    def _lost(self, exc: OSError) -> TransportClosed:
        self.is_open = False
        return TransportClosed(f"{self.name}: connection lost: {exc}")

    def _deadline(self) -> float | None:
        return None if self.timeout is None else time.monotonic() + float(self.timeout)

    def write(self, data: bytes) -> int:
        self._check()
        try:
            self.sock.setblocking(True)
            self.sock.sendall(bytes(data))
        except OSError as exc:
            raise self._lost(exc) from exc
        finally:
            if self.is_open:
                self.sock.setblocking(False)
        return len(data)

    def reset_input_buffer(self) -> None:
        self._check()
        self._buf = b""
        while True:   # drain what has arrived
            try:
                r, _, _ = select.select([self.sock], [], [], 0)
            except OSError as exc:
                raise self._lost(exc) from exc
            if not r or not self._recv():
                return

    def close(self) -> None:
        if self.is_open:
            self.is_open = False
            try:
                self.sock.close()
            except OSError:
                pass


def reopener(spec: str | Mapping[str, Any], *, recorder: "RecordingTransport | None" = None,
             **settings: Any) -> Callable[[], Any]:
    """A ``reconnect`` callable for the drivers: each call opens ``spec`` afresh with ``settings``
    (the same arguments as ``open_transport``). With ``recorder``, the new port is swapped into that
    ``RecordingTransport`` (and the reopen is recorded), and the recorder is returned."""

    def _reopen() -> Any:
        port = open_transport(spec, **settings)
        return recorder.reopen(port) if recorder is not None else port

    return _reopen


def load_transcript(source: str | Path | list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Transcript entries (comments dropped) from a JSON-lines file or an already-parsed list."""
    if isinstance(source, (str, Path)):
        from benchtwin.schema import loads_json, read_input_text

        entries = []
        # the one reader (benchtwin.schema): a regular file (a FIFO is refused, not opened), bounded
        # size, strict JSON per line; its SchemaError is a ValueError naming the file
        for lineno, line in enumerate(read_input_text(source, what="transcript").splitlines(), 1):
            if not line.strip():
                continue
            e = loads_json(line, f"{source}:{lineno}")
            if not isinstance(e, dict):
                raise ValueError(f"{source}:{lineno}: expected a JSON object, got {type(e).__name__}")
            entries.append(e)
    else:
        entries = [dict(e) for e in source]
    out = []
    for i, e in enumerate(entries):
        if set(e) <= {"comment", "note"}:
            continue
        if "event" in e:
            if e["event"] != "reopen":
                raise ValueError(f"transcript entry {i}: unknown event {e['event']!r}")
        elif "request" not in e:
            raise ValueError(f"transcript entry {i} has neither 'request' nor 'event': {e}")
        out.append(e)
    return out


class ReplayTransport(_BufferedReads):
    """Serves a transcript in strict order; see the module docstring for the format.

    Writes accumulate until they make up the next entry's request (a write that stops being a prefix
    of it raises ``ReplayMismatch`` at once); then that entry's response is queued for the reads. Reads
    never wait: a response without its terminator is what a timeout returns. An entry with
    ``"error": "disconnect"`` makes the port raise ``TransportClosed`` until ``reopen()``, which must
    match a ``{"event": "reopen"}`` entry.
    """

    def __init__(self, transcript: str | Path | list[dict[str, Any]], *, timeout: float | None = 1.0,
                 name: str = "replay") -> None:
        self.entries = load_transcript(transcript)
        self.source = str(transcript) if isinstance(transcript, (str, Path)) else "<list>"
        self.name = name
        self.timeout = timeout
        self.pos = 0
        self._pending = b""
        self._buf = b""
        self.is_open = True
        self.written: list[bytes] = []

    # --- pyserial subset -------------------------------------------------------------------------
    def write(self, data: bytes) -> int:
        self._check()
        data = bytes(data)
        self.written.append(data)
        self._pending += data
        while self._pending:
            entry = self._next_entry("a request")
            if "event" in entry:
                raise ReplayMismatch(self._where() + f"expected event {entry['event']!r} (reconnect), "
                                     f"got a write of {self._pending!r}")
            expected = text_to_bytes(entry["request"])
            if not expected.startswith(self._pending) and not self._pending.startswith(expected):
                raise ReplayMismatch(self._where() + f"unexpected request\n  expected: {expected!r}\n"
                                     f"  got:      {self._pending!r}")
            if len(self._pending) < len(expected):
                break
            self._pending = self._pending[len(expected):]
            self.pos += 1
            if entry.get("error") == "disconnect":
                self.is_open = False
                self._buf = b""
                raise TransportClosed(f"{self.name}: instrument disconnected (transcript entry {self.pos - 1})")
            self._buf += text_to_bytes(entry.get("response", ""))
        return len(data)

    def reset_input_buffer(self) -> None:
        self._check()
        self._buf = b""

    def close(self) -> None:
        self.is_open = False

    # --- replay control --------------------------------------------------------------------------
    def reopen(self) -> "ReplayTransport":
        """Re-open after a disconnect (what a reconnect callable does); consumes a reopen event."""
        entry = self._next_entry("a reopen event")
        if entry.get("event") != "reopen":
            raise ReplayMismatch(self._where() + f"port re-opened but the transcript expects request "
                                 f"{text_to_bytes(entry.get('request', ''))!r}")
        self.pos += 1
        self.is_open = True
        self._pending = b""
        self._buf = b""
        return self

    def assert_done(self) -> None:
        """Raise ``ReplayMismatch`` if exchanges are left over or a request is half written."""
        if self._pending:
            raise ReplayMismatch(self._where() + f"incomplete request written: {self._pending!r}")
        left = self.entries[self.pos:]
        if left:
            shown = [e.get("request", e.get("event")) for e in left[:3]]
            raise ReplayMismatch(f"{self.name} ({self.source}): {len(left)} exchange(s) left over, "
                                 f"starting at entry {self.pos}: {shown}")

    @property
    def done(self) -> bool:
        return self.pos >= len(self.entries) and not self._pending

    def _next_entry(self, what: str) -> dict[str, Any]:
        if self.pos >= len(self.entries):
            raise ReplayMismatch(self._where() + f"transcript exhausted, but got {what}"
                                 + (f": {self._pending!r}" if self._pending else ""))
        return self.entries[self.pos]

    def _where(self) -> str:
        return f"{self.name} ({self.source}), entry {self.pos}: "

    def _check(self) -> None:
        if not self.is_open:
            raise TransportClosed(f"{self.name}: port is closed (disconnected)")


class RecordingTransport:
    """Wraps a transport and appends each request/response pair to a JSON-lines transcript.

    A pair is the bytes written since the last read plus the bytes read until the next write (or
    ``close()``/``flush_pair()``). A ``serial.SerialException``/``OSError`` raised by the inner
    transport is recorded as ``"error": "disconnect"`` and re-raised. The file is written as it goes,
    so a crash leaves a usable transcript. ``reopen(new_inner)`` swaps the port after a reconnect and
    records the event.
    """

    def __init__(self, inner: Transport, path: str | Path, *, append: bool = False) -> None:
        self.inner = inner
        self.path = Path(path)
        self._file = self.path.open("a" if append else "w", encoding="utf-8")
        self._request = b""
        self._response = b""
        self._lock = threading.Lock()

    @property
    def timeout(self) -> float | None:
        return self.inner.timeout

    @timeout.setter
    def timeout(self, value: float | None) -> None:
        self.inner.timeout = value

    def _emit(self, obj: dict[str, Any]) -> None:
        self._file.write(json.dumps(obj, ensure_ascii=True) + "\n")
        self._file.flush()

    def flush_pair(self, error: str | None = None) -> None:
        with self._lock:
            if self._request or self._response or error:
                obj: dict[str, Any] = {"request": bytes_to_text(self._request),
                                       "response": bytes_to_text(self._response)}
                if error:
                    obj["error"] = error
                self._emit(obj)
            self._request = b""
            self._response = b""

    def _guard(self, fn, *args):
        try:
            return fn(*args)
        except (serial.SerialException, OSError):
            self.flush_pair(error="disconnect")
            raise

    def write(self, data: bytes) -> int | None:
        if self._response:
            self.flush_pair()
        self._request += bytes(data)
        return self._guard(self.inner.write, data)

    def _got(self, data: bytes) -> bytes:
        self._response += data
        return data

    def read(self, size: int = 1) -> bytes:
        return self._got(self._guard(self.inner.read, size))

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes:
        return self._got(self._guard(self.inner.read_until, expected, size))

    def readline(self, size: int | None = -1) -> bytes:
        return self._got(self._guard(self.inner.readline, size))

    def reset_input_buffer(self) -> None:
        self._guard(self.inner.reset_input_buffer)

    def reopen(self, inner: Transport) -> "RecordingTransport":
        self.flush_pair()
        self.inner = inner
        self._emit({"event": "reopen"})
        return self

    def close(self) -> None:
        self.flush_pair()
        try:
            self.inner.close()
        finally:
            self._file.close()
