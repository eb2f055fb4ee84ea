"""One request/reply byte server for the protocol emulators, whatever carries the bytes.

``PtyServer`` (pty.py: pseudo-terminals) and ``TcpServer`` (tcp.py: loopback TCP sockets) are two
transports of one server, ``ByteServer``: one thread per port runs one loop (``_serve``), which
takes the next request bytes from the transport, feeds them to the port's emulator under the
emulators' shared lock (the backend, the twin, is shared), applies the fault plan to each reply
(``fault_reply``: a fault plan means the same on a pseudo-terminal and on a socket) and hands the
replies back to the transport. What differs, a transport says:

- ``_open_ports``: one port per emulator in ``self.ports`` (a ``BytePort`` with the transport's
  handles);
- ``_receive(port)``: wait at most ``poll_s`` for request bytes (None: nothing to feed this turn);
- ``_reply(port, bytes)``: send or queue one reply;
- ``_disconnect(port)``: a ``disconnect`` fault (the rest of that read is dropped);
- ``_fed(port, pending)``: after the replies of one read (``pending``: the emulator's request bytes
  still without their terminator);
- ``_close_port(port)``: on ``stop``; and ``paths``/``pts``.

The fault plan is read here too (``load_fault_plan``: a TOML/JSON file, a dict or a list; the
actions are documented in pty.py).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from benchtwin.schema import Key, SchemaError, check_table, check_version, loads_json, loads_toml, read_input_text

__all__ = ["ByteServer", "BytePort", "load_fault_plan", "fault_reply", "FAULT_ACTIONS"]

FAULT_ACTIONS = ("drop", "garble", "partial", "delay", "disconnect")
MAX_FAULTS = 10_000
# the fault plan's schema (benchtwin.schema: the one validator mechanism of the input files)
FAULT_PLAN_KEYS = {"version": Key("int"), "faults": Key("list")}
FAULT_KEYS = {
    "port": Key("str", required=True, n_min=1, n_max=64, doc="the port's name in the bench file"),
    "request": Key("int", required=True, lo=1, hi=10**9, doc="the n-th request on that port"),
    "action": Key("str", required=True, choices=FAULT_ACTIONS),
    "seconds": Key("float", lo=0.0, hi=3600.0, doc="delay/disconnect duration"),
}


def load_fault_plan(source: str | Path | Mapping[str, Any] | list | None) -> list[dict[str, Any]]:
    """A validated fault list from a file (TOML or JSON), a ``{"faults": [...]}`` dict or a list."""
    where = "<fault plan>"
    if source is None:
        return []
    if isinstance(source, (str, Path)):
        p = Path(source)
        where = str(p)
        if not p.exists():
            raise ValueError(f"{p}: no such fault plan file")
        # bounded, regular, UTF-8, nesting-limited, finite numbers (benchtwin.schema; issue #13)
        try:
            text = read_input_text(p, what="fault plan")
            data: Any = loads_json(text, where) if p.suffix == ".json" else loads_toml(text, where)
        except SchemaError as exc:
            raise ValueError(str(exc)) from None
    else:
        data = source
    if isinstance(data, Mapping):
        check_version(data, where, fail=ValueError)
        check_table(data, FAULT_PLAN_KEYS, where, fail=ValueError)
        items = data.get("faults", [])
    else:
        items = data
    if not isinstance(items, list) or len(items) > MAX_FAULTS:
        raise ValueError(f"{where}: key 'faults': expected an array of at most {MAX_FAULTS} tables")
    out = []
    for k, f in enumerate(items):
        # one declarative check (benchtwin.schema.check_table): seconds = nan stops here, not in
        # the emulator's port thread (issue #13)
        f = check_table(f, FAULT_KEYS, where, at=f"faults[{k}]", fail=ValueError)
        out.append({"port": f["port"], "request": int(f["request"]), "action": f["action"],
                    "seconds": float(f.get("seconds", 0.0))})
    return out


def fault_reply(port: Any, reply: bytes | None) -> tuple[bytes | None, bool]:
    """Count one request/reply exchange of ``port`` (pty or TCP: ``count``, ``faults``, ``fired``)
    and apply the fault plan's action planned for it. Returns (the bytes to send, or None; whether
    to disconnect the client). One implementation for both servers, so a fault plan means the same
    on a pseudo-terminal and on a socket."""
    port.count += 1
    fault = port.faults.get(port.count)
    if fault is None:
        return reply, False
    port.fired.append(dict(fault))
    act = fault["action"]
    if act == "disconnect":
        return None, True
    if act == "drop" or reply is None:
        return None, False
    if act == "garble":
        return b"#" + reply[1:], False
    if act == "partial":
        return reply[:-1], False
    if act == "delay":
        time.sleep(fault["seconds"])
    return reply, False


_S = TypeVar("_S", bound="ByteServer")


class BytePort:
    """What the loop keeps of one port: its emulator, the requests counted and the faults planned
    (``fault_reply``), those fired, and its thread. A transport adds its own handles."""

    def __init__(self, name: str, emulator: Any, faults: Mapping[int, dict[str, Any]] | None = None):
        self.name = name
        self.emulator = emulator
        self.count = 0
        self.faults: dict[int, dict[str, Any]] = dict(faults or {})
        self.fired: list[dict[str, Any]] = []
        self.thread: threading.Thread | None = None


class ByteServer:
    """Serve ``emulators`` (``{port name: ProtocolEmulator}``) with the fault plan ``faults``; the
    transport is the subclass's (module docstring)."""

    thread_prefix = "emu"

    def __init__(self, emulators: Mapping[str, Any], faults: Any = None, poll_s: float = 0.02):
        self.emulators = dict(emulators)
        self.plan = load_fault_plan(faults)
        unknown = sorted({f["port"] for f in self.plan} - set(self.emulators))
        if unknown:
            raise ValueError(f"fault plan names unknown port(s) {unknown}; ports: {sorted(self.emulators)}")
        self.poll_s = float(poll_s)
        self.lock = threading.Lock()
        self._stop = threading.Event()
        self.ports: dict[str, Any] = {}
        self.errors: list[str] = []

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> dict[str, str]:
        self._open_ports()
        for p in self.ports.values():
            p.thread = threading.Thread(target=self._serve, args=(p,), name=f"{self.thread_prefix}-{p.name}",
                                        daemon=True)
            p.thread.start()
        return self.paths()

    def faults_of(self, name: str) -> dict[int, dict[str, Any]]:
        """The fault plan of port ``name``, by request number (a later entry replaces an earlier one)."""
        return {f["request"]: f for f in self.plan if f["port"] == name}

    def fired(self) -> list[dict[str, Any]]:
        return [f for p in self.ports.values() for f in p.fired]

    def stop(self) -> None:
        self._stop.set()
        for p in self.ports.values():
            if p.thread is not None:
                p.thread.join(timeout=2.0)
            self._close_port(p)

    def __enter__(self: _S) -> _S:
        if not self.ports:
            self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    # ------------------------------------------------------------------ serving: the one loop
    def _serve(self, p: Any) -> None:
        while not self._stop.is_set():
            data = self._receive(p)
            if not data:
                continue
            try:
                with self.lock:
                    exchanges = p.emulator.feed(data)
                    pending = p.emulator.pending_bytes()
            except Exception as exc:  # noqa: BLE001 - an emulator bug must not kill the port silently
                self.errors.append(f"{p.name}: {type(exc).__name__}: {exc}")
                continue
            for _req, reply in exchanges:
                reply, disconnect = fault_reply(p, reply)
                if disconnect:
                    self._disconnect(p)
                    break  # the rest of this read went to the dead connection
                if reply:
                    self._reply(p, reply)
            self._fed(p, pending)

    # ------------------------------------------------------------------ the transport's part
    def _open_ports(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def paths(self) -> dict[str, str]:  # pragma: no cover - abstract
        raise NotImplementedError

    def _receive(self, p: Any) -> bytes | None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _reply(self, p: Any, reply: bytes) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _disconnect(self, p: Any) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _fed(self, p: Any, pending: int) -> None:
        """After the replies of one read (nothing by default)."""

    def _close_port(self, p: Any) -> None:  # pragma: no cover - abstract
        raise NotImplementedError
