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

The client's line settings: Linux pseudo-terminals carry no parity and force 8 data bits (the
kernel clears ``CSIZE``/``PARENB`` in every ``tcsetattr`` on a pty), so a 7E2 client and an 8N1
client send the same bytes. What a pty does keep is the speed, ``CSTOPB`` and ``PARODD``. The
server therefore parks each idle port at a speed no client uses (``B50``, "pristine") and reads the
slave side's settings with ``termios.tcgetattr`` on every turn of its loop: when they leave the
pristine state, a client has opened and configured the port (pyserial always sets the speed on
open). That is a *connection*: the emulator's ``connect(framing)`` drops the previous client's
partial request and compares the client's baud rate and parity kind with the instrument's
(_base.py); then the port is parked again, so the next open is seen too (and so that pyserial
re-opening a 7E2 port does not fail: a pty refuses with EINVAL a ``tcsetattr`` whose only change is
the character size or parity, and with the speed changed as well the kernel accepts it). Data bits
and even-vs-no parity cannot be seen on a pty: a client at 8N1 talking to a 7E2 instrument is
understood here, where the real instrument would see parity errors (docs/protocols/README.md).

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


PRISTINE = termios.B50   # the speed an idle port is parked at: no client uses 50 baud
_SPEEDS = {getattr(termios, f"B{b}"): b for b in (50, 75, 110, 134, 150, 200, 300, 600, 1200, 1800, 2400, 4800,
                                                   9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000,
                                                   576000, 921600, 1000000, 1152000, 1500000, 2000000)
           if hasattr(termios, f"B{b}")}


def park(fd: int) -> None:
    """Put a pty slave back to the pristine settings (speed B50, one stop bit, no PARODD)."""
    try:
        attrs = termios.tcgetattr(fd)
        if attrs[4] != PRISTINE or attrs[5] != PRISTINE or attrs[2] & (termios.CSTOPB | termios.PARODD):
            attrs[4] = attrs[5] = PRISTINE
            attrs[2] &= ~(termios.CSTOPB | termios.PARODD)
            termios.tcsetattr(fd, termios.TCSANOW, attrs)
    except (termios.error, OSError):
        pass


def client_framing(fd: int) -> dict[str, Any] | None:
    """The line settings a client put on the pty slave ``fd`` (None: still pristine, nobody opened
    and configured it since it was parked). Only what a pty keeps: speed, stop bits, PARODD."""
    try:
        attrs = termios.tcgetattr(fd)
    except (termios.error, OSError):
        return None
    if attrs[4] == PRISTINE and attrs[5] == PRISTINE and not attrs[2] & (termios.CSTOPB | termios.PARODD):
        return None
    return {"transport": "pty", "baudrate": _SPEEDS.get(attrs[4], 0),
            "stopbits": 2 if attrs[2] & termios.CSTOPB else 1, "parity_odd": bool(attrs[2] & termios.PARODD)}


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
        park(slave)
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
                self._watch(p)
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
            self._watch(p)  # after the read: a client sets its line before it writes
            try:
                with self.lock:
                    exchanges = p.emulator.feed(data)
            except Exception as exc:  # noqa: BLE001 - an emulator bug must not kill the port silently
                self.errors.append(f"{p.name}: {type(exc).__name__}: {exc}")
                continue
            for _req, reply in exchanges:
                reply, disconnect = fault_reply(p, reply)
                if disconnect:
                    p.reopen()
                    break  # the rest of this read went to the dead port
                if reply:
                    self._write(p, reply)

    def _watch(self, p: _Port) -> None:
        """A client (re)configured the port since the last look: a connection (module docstring)."""
        framing = client_framing(p.slave)
        if framing is None:
            return
        park(p.slave)
        with self.lock:
            p.emulator.connect(framing)

    def _write(self, p: _Port, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(p.master, view)
                view = view[n:]
            except BlockingIOError:
                select.select([], [p.master], [], self.poll_s)


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
