"""Serve the protocol emulators on loopback TCP sockets (``benchtwin emulate --tcp``).

Many current instruments have an Ethernet interface that carries the same ASCII protocol as their
serial port: Zaber's Ethernet controllers speak Zaber ASCII on TCP port 55550, position displays
and autocollimators with a LAN option speak their serial protocol over a raw socket (the
"serial device server" model). ``TcpServer`` serves each emulator on its own socket of
``127.0.0.1`` (loopback only: nothing listens on another address), with the same fault plan as
``PtyServer`` (pty.py: ``drop``, ``garble``, ``partial``, ``delay``; ``disconnect`` closes the
client's connection, and the next connection is served again).

    server = TcpServer({"encoder": HeidenhainEmulator(...), ...}, faults=plan, base_port=0)
    ports = server.start()        # {"encoder": "tcp://127.0.0.1:40123", ...}
    server.stop()

Ports: ``base_port`` 0 (default) lets the system choose a free port for every emulator; otherwise
port ``base_port + k`` for the k-th emulator (in the bench's order). A socket has no line settings,
so a connection is only a connection: ``emulator.connect({"transport": "tcp"})`` drops a previous
client's partial request. One client per instrument at a time, as the instruments' single command
channel: a new connection replaces the old one (a client that re-connects after a network fault
is served at once; the stale connection is closed).

A hostile or broken client cannot take a port down (issue #31: one client that sent requests
without reading the replies blocked its port for good, its thread stuck in ``sendall``). Per
connection:

- replies are sent without blocking, from a buffer of at most ``MAX_OUTPUT_BYTES`` (and a socket
  send buffer of that size); while replies
  wait, no further request is read (the client's own sends back up, not the server); replies
  still waiting after ``SEND_TIMEOUT_S`` (a client of this request/reply protocol takes each reply
  before it asks again: its replies never wait long), or a buffer over the limit, close the
  connection;
- a request line longer than ``MAX_LINE_BYTES`` without its terminator closes the connection (an
  instrument's input buffer is a few hundred bytes; the protocols' requests are under 100);
- requests are read ``RECV_BYTES`` at a time, and the emulators' lock is released between reads,
  so a flood on one port leaves the other ports served;
- the listening socket is watched all the time: a new connection is served at once (and replaces
  the old one, as above).

Each closed connection is noted in ``TcpServer.closed`` (port and why); these are the clients'
faults, not the emulator's (``errors``).
"""

from __future__ import annotations

import select
import socket
import time
from collections.abc import Mapping
from typing import Any

from .byteserver import BytePort, ByteServer

__all__ = ["TcpServer", "HOST"]

HOST = "127.0.0.1"
#: longest request line (bytes) a connection may send without its terminator
MAX_LINE_BYTES = 4096
#: most reply bytes kept for a connection that is not reading them
MAX_OUTPUT_BYTES = 65536
#: seconds replies may wait for a client that reads none of them
SEND_TIMEOUT_S = 5.0
#: bytes read from a connection at a time (the emulators' lock is released in between)
RECV_BYTES = 1024
#: closed connections noted at most (``TcpServer.closed``)
CLOSED_KEPT = 100


class _Endpoint(BytePort):
    def __init__(self, name: str, emulator: Any, sock: socket.socket, faults: Mapping[int, dict[str, Any]]):
        super().__init__(name, emulator, faults)
        self.sock = sock
        self.port = sock.getsockname()[1]
        self.client: socket.socket | None = None
        self.out = bytearray()           # replies not yet sent to the client
        self.out_since = 0.0             # monotonic time since when replies have been waiting

    @property
    def url(self) -> str:
        return f"tcp://{HOST}:{self.port}"


class TcpServer(ByteServer):
    """Serve ``emulators`` (``{port name: ProtocolEmulator}``) on loopback TCP sockets (the loop:
    byteserver.ByteServer)."""

    thread_prefix = "emu-tcp"

    def __init__(self, emulators: Mapping[str, Any], faults: Any = None, base_port: int = 0,
                 poll_s: float = 0.02):
        super().__init__(emulators, faults, poll_s)
        if not isinstance(base_port, int) or not (base_port == 0 or 1024 <= base_port <= 65535 - len(emulators)):
            raise ValueError(f"TCP base port must be 0 (any free port) or 1024..{65535 - len(emulators)}, "
                             f"got {base_port!r}")
        self.base_port = base_port
        self.closed: list[str] = []      # connections closed for a client's fault (see the module docstring)

    def _open_ports(self) -> None:
        try:
            for k, (name, emu) in enumerate(self.emulators.items()):
                s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                try:
                    s.bind((HOST, self.base_port + k if self.base_port else 0))
                except OSError as exc:
                    s.close()
                    raise ValueError(f"cannot listen on {HOST}:{self.base_port + k} for {name!r}: {exc}") from None
                s.listen(2)
                s.setblocking(False)
                self.ports[name] = _Endpoint(name, emu, s, self.faults_of(name))
        except BaseException:
            for e in self.ports.values():
                e.sock.close()
            raise

    def paths(self) -> dict[str, str]:
        return {n: e.url for n, e in self.ports.items()}

    def pts(self) -> dict[str, str]:
        """Where each port listens (the same as ``paths``: a socket has no device behind it)."""
        return {n: f"{HOST}:{e.port}" for n, e in self.ports.items()}

    def _close_port(self, e: _Endpoint) -> None:
        self._drop(e)
        e.sock.close()

    # ------------------------------------------------------------------ the socket transport
    @staticmethod
    def _drop(e: _Endpoint) -> None:
        if e.client is not None:
            try:
                e.client.close()
            except OSError:
                pass
            e.client = None
        e.out.clear()

    def _close(self, e: _Endpoint, why: str) -> None:
        """Close the client's connection for its own fault, and note why."""
        if len(self.closed) < CLOSED_KEPT:
            self.closed.append(f"{e.name}: {why}")
        self._drop(e)

    def _send(self, e: _Endpoint) -> None:
        """Send what the client's socket takes now (never blocks)."""
        if e.client is None or not e.out:
            return
        try:
            n = e.client.send(e.out)
        except BlockingIOError:
            n = 0
        except OSError:
            self._drop(e)
            return
        del e.out[:n]

    def _receive(self, e: _Endpoint) -> bytes | None:
        readers: list[socket.socket] = [e.sock]
        writers: list[socket.socket] = []
        if e.client is not None:
            # replies waiting: send them before reading more requests (back-pressure)
            (writers if e.out else readers).append(e.client)
        try:
            r, w, _ = select.select(readers, writers, [], self.poll_s)
        except (OSError, ValueError):
            self._drop(e)
            return None
        if e.sock in r:
            try:
                conn, _ = e.sock.accept()
            except OSError:
                conn = None
            if conn is not None:
                self._drop(e)
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                # a fixed send buffer: the kernel's autotuning would take megabytes of replies
                # for a client that reads none (and hide that it reads none)
                conn.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, MAX_OUTPUT_BYTES)
                conn.setblocking(False)
                e.client = conn
                with self.lock:
                    e.emulator.connect({"transport": "tcp"})
            return None
        if e.client is not None and e.client in w:
            self._send(e)
        if e.client is not None and e.out and time.monotonic() - e.out_since > SEND_TIMEOUT_S:
            self._close(e, f"the client read none of {len(e.out)} reply bytes for {SEND_TIMEOUT_S:g} s")
        if e.client is None or e.client not in r:
            return None
        try:
            data = e.client.recv(RECV_BYTES)
        except BlockingIOError:
            return None
        except OSError:
            data = b""
        if not data:          # the client closed its end
            self._drop(e)
        return data

    def _disconnect(self, e: _Endpoint) -> None:
        self._drop(e)

    def _reply(self, e: _Endpoint, reply: bytes) -> None:
        if e.client is not None:
            if not e.out:
                e.out_since = time.monotonic()
            e.out += reply

    def _fed(self, e: _Endpoint, pending: int) -> None:
        if e.client is None:
            return
        if pending > MAX_LINE_BYTES:
            self._close(e, f"a request of over {MAX_LINE_BYTES} bytes without its line end")
            return
        self._send(e)
        if len(e.out) > MAX_OUTPUT_BYTES:
            self._close(e, f"over {MAX_OUTPUT_BYTES} reply bytes the client did not read")
