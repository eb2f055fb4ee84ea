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
import time
import tty
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from .byteserver import FAULT_ACTIONS, BytePort, ByteServer, fault_reply, load_fault_plan

__all__ = ["PtyServer", "load_fault_plan", "FAULT_ACTIONS", "fault_reply"]

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


class _Port(BytePort):
    def __init__(self, name: str, emulator: Any, link: Path, faults: Mapping[int, dict[str, Any]]):
        super().__init__(name, emulator, faults)
        self.link = link
        self.master = -1
        self.slave = -1
        self.pts = ""
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


class PtyServer(ByteServer):
    """Serve ``emulators`` (``{port name: ProtocolEmulator}``) on pseudo-terminals (the loop:
    byteserver.ByteServer)."""

    def __init__(self, emulators: Mapping[str, Any], faults: Any = None, link_dir: str | Path | None = None,
                 poll_s: float = 0.02):
        # A folder this server made for its links is its to remove on stop (one per server left in /tmp
        # otherwise: 7 per test run); a caller's folder is the caller's.
        # (after the plan's check, which raises: no folder is made for a server that never was)
        super().__init__(emulators, faults, poll_s)
        self._own_dir = link_dir is None
        self.link_dir = Path(link_dir) if link_dir is not None else Path(tempfile.mkdtemp(prefix="benchtwin-emu-"))
        self.link_dir.mkdir(parents=True, exist_ok=True)

    def stop(self) -> None:
        super().stop()
        if self._own_dir:
            try:
                self.link_dir.rmdir()  # empty once every port's link is gone; anything else left stays
            except OSError:
                pass

    # ------------------------------------------------------------------ lifecycle
    def _open_ports(self) -> None:
        for name, emu in self.emulators.items():
            self.ports[name] = _Port(name, emu, self.link_dir / name, self.faults_of(name))

    def paths(self) -> dict[str, str]:
        """Stable paths (the links) of every port."""
        return {n: str(p.link) for n, p in self.ports.items()}

    def pts(self) -> dict[str, str]:
        """Current pseudo-terminal device of every port."""
        return {n: p.pts for n, p in self.ports.items()}

    def _close_port(self, p: _Port) -> None:
        p.close()
        try:
            p.link.unlink()
        except OSError:
            pass

    # ------------------------------------------------------------------ the pseudo-terminal transport
    def _receive(self, p: _Port) -> bytes | None:
        try:
            r, _, _ = select.select([p.master], [], [], self.poll_s)
        except (OSError, ValueError):
            time.sleep(self.poll_s)
            return None
        if not r:
            self._watch(p)
            return None
        try:
            data = os.read(p.master, 4096)
        except BlockingIOError:
            return None
        except OSError as exc:
            if exc.errno == errno.EIO:  # no slave open (cannot happen while we hold one)
                time.sleep(self.poll_s)
                return None
            raise
        if data:
            self._watch(p)  # after the read: a client sets its line before it writes
        return data

    def _disconnect(self, p: _Port) -> None:
        p.reopen()

    def _watch(self, p: _Port) -> None:
        """A client (re)configured the port since the last look: a connection (module docstring)."""
        framing = client_framing(p.slave)
        if framing is None:
            return
        park(p.slave)
        with self.lock:
            p.emulator.connect(framing)

    def _reply(self, p: _Port, data: bytes) -> None:
        view = memoryview(data)
        while view:
            try:
                n = os.write(p.master, view)
                view = view[n:]
            except BlockingIOError:
                select.select([], [p.master], [], self.poll_s)
