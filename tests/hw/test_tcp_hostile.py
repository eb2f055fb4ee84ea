"""The TCP emulator survives a hostile client (issue #31, twin/emulators/tcp.py): a client that
floods requests without reading the replies, or sends a line without end, loses its connection;
the port serves the next client, and the other ports are served throughout. Loopback only,
bounded in bytes and time (socket timeouts guard against a hang; nothing is timed)."""

from __future__ import annotations

import select
import socket

import pytest

from benchtwin.twin.emulators import tcp
from benchtwin.twin.emulators.tcp import MAX_LINE_BYTES, TcpServer
from benchtwin.twin.emulators.tesa import TesaEmulator

from tests.support.acquisition import Stub

REQUEST, REPLY = b"?\r", b"+1.25\r\n"


def _servers(monkeypatch, send_timeout_s: float = 0.5) -> TcpServer:
    monkeypatch.setattr(tcp, "SEND_TIMEOUT_S", send_timeout_s)
    src = Stub(probe_top={"value_um": 1.25, "status": "ok"}, probe_bottom={"value_um": 1.25, "status": "ok"})
    return TcpServer({"top": TesaEmulator("top", src, "probe_top"), "bottom": TesaEmulator("bottom", src, "probe_bottom")})


def _connect(url: str, rcvbuf: int | None = None) -> socket.socket:
    """A client of ``url``; ``rcvbuf``: its receive buffer (a small one fills after a few replies)."""
    host, port = url.removeprefix("tcp://").rsplit(":", 1)
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    if rcvbuf is not None:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    s.settimeout(10.0)
    s.connect((host, int(port)))
    return s


def _ask(s: socket.socket) -> bytes:
    s.sendall(REQUEST)
    got = b""
    while not got.endswith(b"\n"):
        chunk = s.recv(64)
        if not chunk:
            break
        got += chunk
    return got


def _flood(s: socket.socket, max_bytes: int = 64 << 20, stuck_s: float = 2.0) -> str:
    """Send requests without reading a reply until the server closes the connection ("closed"),
    takes nothing more for ``stuck_s`` ("stuck": it no longer reads this client), or ``max_bytes``
    are sent ("sent")."""
    s.setblocking(False)
    sent, block = 0, REQUEST * 4096
    try:
        while sent < max_bytes:
            try:
                sent += s.send(block)
            except BlockingIOError:
                _, writable, _ = select.select([], [s], [], stuck_s)
                if not writable:
                    return "stuck"
        return "sent"
    except (BrokenPipeError, ConnectionResetError):
        return "closed"
    finally:
        s.setblocking(True)
        s.settimeout(10.0)


def _wait_closed(s: socket.socket) -> bool:
    """Whether the server closed ``s`` (EOF or reset), draining what it sent first."""
    s.settimeout(10.0)
    try:
        while s.recv(65536):
            pass
    except (ConnectionResetError, BrokenPipeError):
        pass
    except TimeoutError:
        return False
    return True


def test_a_client_that_never_reads_does_not_block_the_port(monkeypatch):
    """The flooding client's connection is closed by the server (before: the port's thread stuck
    in ``sendall`` for good, and no other client of that port was ever served again)."""
    with _servers(monkeypatch) as server:
        urls = server.paths()
        hostile = _connect(urls["top"], rcvbuf=4096)
        other = _connect(urls["bottom"])
        assert _ask(other) == REPLY
        assert _flood(hostile) == "closed"
        assert _ask(other) == REPLY                  # another port, after the flood
        assert len(server.closed) == 1 and server.closed[0].startswith("top: ")
        assert "read none" in server.closed[0] or "did not read" in server.closed[0]
        hostile.close()
        again = _connect(urls["top"])
        assert _ask(again) == REPLY                  # the port serves the next client
        assert server.errors == []
        for c in (again, other):
            c.close()


def test_a_new_client_is_served_while_a_flooding_one_is_connected(monkeypatch):
    """The next client replaces the flooding one at once (one client per instrument), without
    waiting for the flooding one's timeout."""
    with _servers(monkeypatch, send_timeout_s=3600.0) as server:
        url = server.paths()["top"]
        hostile = _connect(url, rcvbuf=4096)
        assert _flood(hostile) == "stuck"            # the server reads it no more, keeps the connection
        fresh = _connect(url)
        assert _ask(fresh) == REPLY
        assert _wait_closed(hostile)
        fresh.close()
        hostile.close()
        assert server.errors == []


def test_a_line_without_end_closes_the_connection(monkeypatch):
    with _servers(monkeypatch) as server:
        urls = server.paths()
        s = _connect(urls["top"])
        s.sendall(b"A" * (MAX_LINE_BYTES + 1024))
        assert _wait_closed(s)
        s.close()
        assert any("without its line end" in c for c in server.closed)
        s = _connect(urls["top"])
        assert _ask(s) == REPLY                      # the emulator's buffer was dropped with the connection
        s.close()
        assert server.errors == []


@pytest.mark.parametrize("junk", [b"\x00" * 3000 + b"\r", bytes(range(256)) * 8 + b"\r", b"\r\n" * 5000])
def test_binary_junk_and_empty_lines_leave_the_port_serving(monkeypatch, junk):
    with _servers(monkeypatch) as server:
        s = _connect(server.paths()["top"])
        s.sendall(junk)
        s.settimeout(1.0)
        try:                                          # whatever the instrument answers to junk
            while s.recv(65536):
                pass
        except (TimeoutError, ConnectionResetError):
            pass
        s.close()
        s = _connect(server.paths()["top"])
        assert _ask(s) == REPLY
        s.close()
        assert server.errors == []
