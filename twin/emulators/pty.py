"""Serve the protocol emulators on pseudo-terminals, with a fault plan.

    server = PtyServer({"encoder": HeidenhainEmulator(...), ...}, faults=plan)
    ports = server.start()        # {"encoder": "/tmp/benchtwin-emu-xyz/encoder", ...}
    ...                           # drivers open those paths (pyserial, open_transport)
    server.stop()

Each port is an ``os.openpty()`` pair: the slave is put in raw mode (``tty.setraw``), the server
keeps the master (and one slave descriptor, so the port survives a client closing it between
runs) and answers on the master from one thread per port. The backend (the twin) is shared, so
requests are handled under one lock.

Stable port paths: the server publishes each port as a symbolic link in ``link_dir``
(``<link_dir>/<port name>`` -> ``/dev/pts/N``), as udev's ``/dev/serial/by-id`` links do for USB
adapters. A disconnect fault closes the pseudo-terminal (the client's next read or write fails
with EIO: ``serial.SerialException``), opens a new one and re-points the link, so a driver whose
``reconnect`` re-opens the same path finds the instrument again.

Fault plan: a list of ``{"port": name, "request": n, "action": ..., "seconds": s}`` (a dict
``{"faults": [...]}`` or a TOML/JSON file with a ``[[faults]]`` array; ``load_fault_plan``). ``n``
counts the complete requests that port has received since start, from 1 (retries count too).
Actions on request n: ``drop`` (no reply: the driver times out and retries), ``garble`` (the
reply's first byte replaced by ``#``; the terminator is kept, so the line is complete but does not
parse), ``partial`` (the reply without its last byte: no terminator), ``delay`` (the reply after
``seconds``), ``disconnect`` (no reply; the port is closed and re-created behind the same link).
The plan lives in its own file passed to ``benchtwin emulate --faults`` (not in the scenario, not
in the bench file): faults are a property of the emulated instruments, and the bench file that
``emulate`` writes stays the same file a real bench would use.
"""

from __future__ import annotations

import errno
import json
import os
import select
import tempfile
import termios
import threading
import time
import tty
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from benchtwin.schema import Key, SchemaError, check_table, check_version, loads_json, loads_toml, read_input_text

__all__ = ["PtyServer", "load_fault_plan", "FAULT_ACTIONS"]

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


class _Port:
    def __init__(self, name: str, emulator: Any, link: Path):
        self.name = name
        self.emulator = emulator
        self.link = link
        self.master = -1
        self.slave = -1
        self.pts = ""
        self.count = 0
        self.faults: dict[int, dict[str, Any]] = {}
        self.fired: list[dict[str, Any]] = []
        self.thread: threading.Thread | None = None
        self.open()

    def open(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self.master, self.slave, self.pts = master, slave, os.ttyname(slave)
        tmp = self.link.with_name(self.link.name + ".new")
        if tmp.is_symlink() or tmp.exists():
            tmp.unlink()
        tmp.symlink_to(self.pts)
        os.replace(tmp, self.link)

    def reopen(self) -> None:
        old_m, old_s = self.master, self.slave
        self.open()
        for fd in (old_s, old_m):
            try:
                os.close(fd)
            except OSError:
                pass

    def close(self) -> None:
        for fd in (self.slave, self.master):
            try:
                os.close(fd)
            except OSError:
                pass
        self.master = self.slave = -1


class PtyServer:
    """Serve ``emulators`` (``{port name: ProtocolEmulator}``) on pseudo-terminals."""

    def __init__(self, emulators: Mapping[str, Any], faults: Any = None, link_dir: str | Path | None = None,
                 poll_s: float = 0.02):
        self.link_dir = Path(link_dir) if link_dir is not None else Path(tempfile.mkdtemp(prefix="benchtwin-emu-"))
        self.link_dir.mkdir(parents=True, exist_ok=True)
        self.emulators = dict(emulators)
        self.plan = load_fault_plan(faults)
        unknown = sorted({f["port"] for f in self.plan} - set(self.emulators))
        if unknown:
            raise ValueError(f"fault plan names unknown port(s) {unknown}; ports: {sorted(self.emulators)}")
        self.poll_s = float(poll_s)
        self.lock = threading.Lock()
        self._stop = threading.Event()
        self.ports: dict[str, _Port] = {}
        self.errors: list[str] = []

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> dict[str, str]:
        for name, emu in self.emulators.items():
            p = _Port(name, emu, self.link_dir / name)
            for f in self.plan:
                if f["port"] == name:
                    p.faults[f["request"]] = f
            self.ports[name] = p
        for p in self.ports.values():
            p.thread = threading.Thread(target=self._serve, args=(p,), name=f"emu-{p.name}", daemon=True)
            p.thread.start()
        return self.paths()

    def paths(self) -> dict[str, str]:
        """Stable paths (the links) of every port."""
        return {n: str(p.link) for n, p in self.ports.items()}

    def pts(self) -> dict[str, str]:
        """Current pseudo-terminal device of every port."""
        return {n: p.pts for n, p in self.ports.items()}

    def fired(self) -> list[dict[str, Any]]:
        return [f for p in self.ports.values() for f in p.fired]

    def stop(self) -> None:
        self._stop.set()
        for p in self.ports.values():
            if p.thread is not None:
                p.thread.join(timeout=2.0)
            p.close()
            try:
                p.link.unlink()
            except OSError:
                pass

    def __enter__(self) -> "PtyServer":
        if not self.ports:
            self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    # ------------------------------------------------------------------ serving
    def _serve(self, p: _Port) -> None:
        while not self._stop.is_set():
            try:
                r, _, _ = select.select([p.master], [], [], self.poll_s)
            except (OSError, ValueError):
                time.sleep(self.poll_s)
                continue
            if not r:
                self._idle(p)
                continue
            try:
                data = os.read(p.master, 4096)
            except BlockingIOError:
                continue
            except OSError as exc:
                if exc.errno == errno.EIO:  # no slave open (cannot happen while we hold one)
                    time.sleep(self.poll_s)
                    continue
                raise
            if not data:
                continue
            try:
                with self.lock:
                    exchanges = p.emulator.feed(data)
            except Exception as exc:  # noqa: BLE001 - an emulator bug must not kill the port silently
                self.errors.append(f"{p.name}: {type(exc).__name__}: {exc}")
                continue
            for _req, reply in exchanges:
                p.count += 1
                fault = p.faults.get(p.count)
                if fault is not None:
                    p.fired.append(dict(fault))
                    act = fault["action"]
                    if act == "drop" or reply is None and act != "disconnect":
                        continue
                    if act == "disconnect":
                        p.reopen()
                        break  # the rest of this read went to the dead port
                    if act == "garble":
                        reply = b"#" + reply[1:]
                    elif act == "partial":
                        reply = reply[:-1]
                    elif act == "delay":
                        time.sleep(fault["seconds"])
                if reply:
                    self._write(p, reply)

    @staticmethod
    def _idle(p: _Port) -> None:
        """Put the line speed back to the pristine B38400 while nobody talks. Linux pseudo-terminals
        force 8 data bits and no parity, and refuse (EINVAL) a ``tcsetattr`` that then changes only
        the character size or parity: pyserial re-opening a 7E2 port whose speed is already set
        would fail. With the speed changed too, the kernel accepts it."""
        try:
            attrs = termios.tcgetattr(p.slave)
            if attrs[4] != termios.B38400 or attrs[5] != termios.B38400:
                attrs[4] = attrs[5] = termios.B38400
                termios.tcsetattr(p.slave, termios.TCSANOW, attrs)
        except (termios.error, OSError):
            pass

    def _write(self, p: _Port, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(p.master, view)
                view = view[n:]
            except BlockingIOError:
                select.select([], [p.master], [], self.poll_s)
