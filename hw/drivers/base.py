"""Shared machinery of the serial drivers: command tables, retries, faults, reconnects.

Protocol documents: docs/protocols/*.md (one per driver). Every vendor protocol we rely on is only
partly documented in public, so the byte-level details live in a declarative ``CommandTable``: each
``Command`` has a request template (bytes with ``{field}`` placeholders), a response regex, the
name of a parse function and the response terminator. A driver ships defaults; a bench-file section
overrides any of them (``commands = {read = {template = "a\\r\\n", response = "..."}}``) so a user
adapts an uncertain protocol in configuration, not code.

``SerialInstrument.query(command, **fields)`` sends a command and returns the parsed reply. It
handles, in order of what can go wrong:

- a disconnected port (``serial.SerialException``/``OSError``): re-open through the ``reconnect``
  callable if one was given, else fail at once;
- a timeout (nothing came back), a partial line (no terminator), a garbled line (regex does not
  match) or a format error (parse function raises ``ValueError``): retry;
- retries are bounded (``retries``) with exponential backoff (``backoff_s * backoff_factor**k``);
  the wait goes through the injectable ``sleep`` so tests never wait;
- when the attempts are used up: ``InstrumentError`` naming the instrument, the command and the raw
  bytes received.

What the instrument itself reports ("no signal", out of range, a deactivated channel) is not a
fault: parse functions return it in the reading's ``status`` field and nothing is retried. A parse
function raises ``InstrumentError`` for a well-formed refusal that retrying cannot fix.
"""

from __future__ import annotations

import codecs
import re
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import serial

from benchtwin.hw.transport import Transport

__all__ = ["Command", "CommandTable", "InstrumentError", "FormatError", "LinkSettings", "SerialInstrument", "SharedPort",
           "ProbeDisplay", "to_bytes"]


class InstrumentError(RuntimeError):
    """An instrument did not give a usable answer. Carries ``instrument``, ``command`` and ``raw``
    (the bytes last received) so the message says who failed, on what, and with which bytes."""

    def __init__(self, instrument: str, command: str, message: str, raw: bytes | None = b"",
                 attempts: int | None = None) -> None:
        self.instrument = instrument
        self.command = command
        self.raw = raw if raw is not None else b""
        self.attempts = attempts
        tries = f" after {attempts} attempt(s)" if attempts else ""
        super().__init__(f"{instrument}: command {command!r} failed{tries}: {message}; "
                         f"raw bytes received: {self.raw!r}")


class FormatError(ValueError):
    """A reply matched nothing sensible (raised by parse functions; the query retries)."""


def to_bytes(value: str | bytes) -> bytes:
    """Bench-file strings to bytes: characters are bytes (latin-1); backslash escapes such as
    ``\\r``, ``\\n``, ``\\x1b`` written literally (TOML literal strings) are decoded too."""
    if isinstance(value, bytes):
        return value
    if not isinstance(value, str):
        raise TypeError(f"expected str or bytes, got {type(value).__name__}")
    raw = value.encode("latin-1")
    if b"\\" in raw:
        raw = codecs.escape_decode(raw)[0]
    return raw


@dataclass(frozen=True)
class Command:
    """One request/response exchange.

    ``template``: request bytes; ``{name}`` placeholders are filled from ``query(**fields)``.
    ``response``: regex (bytes) that the whole reply must match (``fullmatch``; named groups go to the
    parse function). ``parse``: name of a parse function in the driver's ``PARSERS``. ``terminator``:
    the bytes that end one reply line; ``lines``: how many such lines make the reply (``0``: the
    command has no reply). ``options``: free per-command settings a parse function may read (e.g.
    which status codes count as "ok"); the base reads ``nak``: reply bytes meaning "command refused",
    which fail at once instead of being retried.
    """

    name: str
    template: bytes
    response: bytes = rb"(?s).*"
    parse: str = "raw"
    terminator: bytes = b"\r\n"
    lines: int = 1
    options: Mapping[str, Any] = field(default_factory=dict)

    def request(self, **fields: Any) -> bytes:
        if not fields:
            return self.template
        try:
            return self.template.decode("latin-1").format(**fields).encode("latin-1")
        except (KeyError, IndexError) as exc:
            raise ValueError(f"command {self.name!r}: template {self.template!r} needs field {exc}") from None

    def compiled(self) -> re.Pattern[bytes]:
        return re.compile(self.response)


_COMMAND_KEYS = {"template", "response", "parse", "terminator", "lines", "options"}


class CommandTable(dict):
    """``{name: Command}`` built from a driver's defaults and a bench-file override section."""

    @classmethod
    def build(cls, defaults: Mapping[str, Command],
              overrides: Mapping[str, Mapping[str, Any]] | None = None) -> "CommandTable":
        table = cls(defaults)
        for name, section in (overrides or {}).items():
            if not isinstance(section, Mapping):
                raise ValueError(f"command override {name!r} must be a table of "
                                 f"{sorted(_COMMAND_KEYS)}, got {section!r}")
            unknown = set(section) - _COMMAND_KEYS
            if unknown:
                raise ValueError(f"command override {name!r}: unknown keys {sorted(unknown)}; "
                                 f"known: {sorted(_COMMAND_KEYS)}")
            kw: dict[str, Any] = {}
            for key in ("template", "terminator"):
                if key in section:
                    kw[key] = to_bytes(section[key])
            if "response" in section:  # a regex: its own escapes (\d, \r, \x1b) are left to `re`
                resp = section["response"]
                kw["response"] = resp if isinstance(resp, bytes) else str(resp).encode("latin-1")
            if "parse" in section:
                kw["parse"] = str(section["parse"])
            if "lines" in section:
                kw["lines"] = int(section["lines"])
            if "options" in section:
                base = dict(table[name].options) if name in table else {}
                kw["options"] = {**base, **dict(section["options"])}
            if name in table:
                table[name] = replace(table[name], **kw)
            else:
                if "template" not in kw:
                    raise ValueError(f"new command {name!r} needs at least a template")
                table[name] = Command(name=name, **kw)
            try:
                table[name].compiled()
            except re.error as exc:
                raise ValueError(f"command {name!r}: bad response regex {table[name].response!r}: {exc}") from None
        return table

    def describe(self) -> dict[str, dict[str, Any]]:
        return {n: {"template": c.template.decode("latin-1"), "response": c.response.decode("latin-1"),
                    "parse": c.parse, "terminator": c.terminator.decode("latin-1"), "lines": c.lines}
                for n, c in self.items()}


class SharedPort:
    """One open transport shared by several driver objects (e.g. the channels of a multi-channel
    amplifier). Exchanges are serialised with a lock, and a reconnect by any sharer is seen by all."""

    def __init__(self, transport: Transport) -> None:
        self.transport = transport
        self.lock = threading.RLock()


Parser = Callable[["SerialInstrument", re.Match[bytes], Command], dict[str, Any]]


def parse_raw(inst: "SerialInstrument", m: re.Match[bytes], cmd: Command) -> dict[str, Any]:
    return {"raw": m.group(0)}


@dataclass(frozen=True)
class LinkSettings:
    """How a serial driver talks to its instrument, common to every driver: the bench file's
    overrides of the command table; extra attempts after the first (``retries``); the wait before
    retry k, ``backoff_s * backoff_factor**k`` (s); ``sleep`` (callable taking seconds; default
    ``time.sleep``, tests inject a recorder); ``clock`` (seconds for ``t_s``, default
    ``time.monotonic``); ``reconnect`` (callable returning a fresh open transport after a
    disconnect, or None)."""

    commands: Mapping[str, Mapping[str, Any]] | None = None
    retries: int = 2
    backoff_s: float = 0.05
    backoff_factor: float = 2.0
    sleep: Callable[[float], None] | None = None
    clock: Callable[[], float] | None = None
    reconnect: Callable[[], Transport] | None = None


class SerialInstrument:
    """Base of the serial drivers. Subclasses set ``KIND``, ``MODEL``, ``UNITS``, ``SERIAL_SETTINGS``
    (what the caller passes to ``open_transport``), ``DEFAULT_COMMANDS`` and ``PARSERS``.

    Constructor arguments common to every driver: ``name``; ``transport`` (an open ``Transport``, or a
    ``SharedPort`` when several driver objects share one port);
    ``commands`` (bench-file overrides of the command table); ``retries`` (extra attempts after the
    first, default 2); ``backoff_s``/``backoff_factor`` (wait before retry k is
    ``backoff_s * backoff_factor**k``); ``sleep`` (callable taking seconds; default ``time.sleep``,
    tests inject a recorder); ``clock`` (seconds for ``t_s``, default ``time.monotonic``);
    ``reconnect`` (callable returning a fresh open transport after a disconnect, or ``None``).
    """

    KIND = "instrument"
    MODEL = "generic"
    UNITS: dict[str, str] = {}
    SERIAL_SETTINGS: dict[str, Any] = {}
    DEFAULT_COMMANDS: dict[str, Command] = {}
    PARSERS: dict[str, Parser] = {"raw": parse_raw}
    PROTOCOL_DOC = "docs/protocols/"

    def __init__(self, name: str, transport: Transport, link: LinkSettings | None = None, **kw: Any) -> None:
        """``link`` (a ``LinkSettings``), or its fields as keywords (``retries=``, ``sleep=``, …)."""
        if link is not None and kw:
            raise TypeError(f"{name}: give link or its fields as keywords, not both")
        link = link if link is not None else LinkSettings(**kw)
        retries, backoff_s, backoff_factor = link.retries, link.backoff_s, link.backoff_factor
        sleep, clock, reconnect = link.sleep, link.clock, link.reconnect
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        self.link = link
        self.name = str(name)
        self.port = transport if isinstance(transport, SharedPort) else SharedPort(transport)
        self.commands = CommandTable.build(self.DEFAULT_COMMANDS, link.commands)
        for cmd in self.commands.values():
            if cmd.parse not in self.PARSERS:
                raise ValueError(f"{self.name}: command {cmd.name!r} names parse function {cmd.parse!r}; "
                                 f"known: {sorted(self.PARSERS)}")
        self.retries = int(retries)
        self.backoff_s = float(backoff_s)
        self.backoff_factor = float(backoff_factor)
        self.sleep = sleep if sleep is not None else time.sleep
        self.clock = clock if clock is not None else time.monotonic
        self.reconnect = reconnect
        self.last_raw = b""

    @property
    def transport(self) -> Transport:
        return self.port.transport

    @transport.setter
    def transport(self, value: Transport) -> None:
        self.port.transport = value

    @classmethod
    def serial_settings(cls, **overrides: Any) -> dict[str, Any]:
        """Keyword arguments for ``open_transport`` (the vendor defaults, overridable)."""
        return {**cls.SERIAL_SETTINGS, **overrides}

    # --- describe ----------------------------------------------------------------------------------
    def describe(self) -> dict[str, Any]:
        """Static metadata; never talks to the instrument."""
        return {"name": self.name, "kind": self.KIND, "model": self.MODEL, "units": dict(self.UNITS),
                "serial": dict(self.SERIAL_SETTINGS), "protocol_doc": self.PROTOCOL_DOC,
                "commands": self.commands.describe()}

    # --- exchanges ---------------------------------------------------------------------------------
    def _read_reply(self, cmd: Command) -> bytes:
        raw = b""
        for _ in range(cmd.lines):
            chunk = self.transport.read_until(cmd.terminator)
            raw += chunk
            if not chunk.endswith(cmd.terminator):
                break
        return raw

    def frame_request(self, cmd: Command, request: bytes) -> bytes:
        """The bytes sent for one attempt of ``request`` (a protocol's message id or checksum goes
        here; the default sends the request as it is)."""
        return request

    def send(self, command: str, **fields: Any) -> None:
        """Send a command that has no reply (``lines = 0``); disconnects handled as in ``query``."""
        self.query(command, **fields)

    def query(self, command: str, _post: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
              **fields: Any) -> dict[str, Any]:
        """Send ``command`` and return the parse function's dict; see the module docstring.

        ``_post`` (optional) turns the parsed dict into the driver's result inside the retry loop, so a
        ``ValueError`` it raises (say, too few fields) is retried like any format error."""
        with self.port.lock:
            return self._query(command, _post, **fields)

    def _query(self, command: str, _post: Callable[[dict[str, Any]], dict[str, Any]] | None,
               **fields: Any) -> dict[str, Any]:
        try:
            cmd = self.commands[command]
        except KeyError:
            raise InstrumentError(self.name, command, f"no such command; known: {sorted(self.commands)}") from None
        request = cmd.request(**fields)
        pattern = cmd.compiled()
        parser = self.PARSERS[cmd.parse]
        attempts = self.retries + 1
        raw = b""
        reason = ""
        for attempt in range(attempts):
            if attempt:
                self.sleep(self.backoff_s * self.backoff_factor ** (attempt - 1))
            try:
                self.transport.reset_input_buffer()
                self.transport.write(self.frame_request(cmd, request))
                if cmd.lines == 0:
                    self.last_raw = b""
                    return {}
                raw = self._read_reply(cmd)
            except (serial.SerialException, OSError) as exc:
                reason = f"disconnected ({exc})"
                raw = b""
                if self.reconnect is None:
                    raise InstrumentError(self.name, command, reason + "; no reconnect configured", raw,
                                          attempt + 1) from exc
                try:
                    self.transport.close()
                except Exception:  # noqa: BLE001 - the old port is gone either way
                    pass
                try:
                    self.transport = self.reconnect()
                except (serial.SerialException, OSError) as exc2:
                    raise InstrumentError(self.name, command, f"{reason}; re-open failed: {exc2}", raw,
                                          attempt + 1) from exc2
                continue
            self.last_raw = raw
            nak = cmd.options.get("nak")
            if nak and raw.startswith(to_bytes(nak)):
                raise InstrumentError(self.name, command, "instrument answered NAK (command not recognised "
                                      "or invalid); check the command table", raw, attempt + 1)
            if not raw:
                reason = f"timeout: no reply within {self.transport.timeout} s"
                continue
            if not raw.endswith(cmd.terminator):
                reason = f"partial reply (no terminator {cmd.terminator!r})"
                continue
            m = pattern.fullmatch(raw)
            if m is None:
                reason = f"garbled reply (does not match {cmd.response!r})"
                continue
            try:
                result = parser(self, m, cmd)
                return _post(result) if _post is not None else result
            except InstrumentError:
                raise
            except (ValueError, IndexError) as exc:
                reason = f"format error: {exc}"
                continue
        raise InstrumentError(self.name, command, reason, raw, attempts)

    def reading(self, **values: Any) -> dict[str, Any]:
        """A reading dict stamped with ``t_s`` from the injected clock; ``status`` defaults to "ok"."""
        out = dict(values)
        out.setdefault("status", "ok")
        out["t_s"] = float(self.clock())
        return out

    def close(self) -> None:
        self.transport.close()


class ProbeDisplay(SerialInstrument):
    """Base of the displays of displacement probes (hw.interfaces.DisplacementProbe: kind ``probe``):
    ``read()`` -> ``{"value_um", "t_s", "status", ...}``, the displacement in µm whatever the unit
    the instrument displays."""

    KIND = "probe"
    UNITS = {"value_um": "um"}


def parse_float(text: bytes | str, what: str = "value") -> float:
    """``float`` of a reply field, tolerating a space between sign and digits (``"+  12.5"``)."""
    s = text.decode("ascii") if isinstance(text, bytes) else text
    s = s.replace(" ", "")
    try:
        v = float(s)
    except ValueError:
        raise FormatError(f"{what} {text!r} is not a number") from None
    if v != v or v in (float("inf"), float("-inf")):
        raise FormatError(f"{what} {text!r} is not finite")
    return v
