"""Ethernet instruments (issue 18): the emulators on loopback TCP sockets, our drivers through the
socket transport (``tcp://HOST:PORT``), and a whole acquisition over TCP with faults that equals
the direct simulation, as the pseudo-terminal one does (test_hil.py)."""

from __future__ import annotations

import json
import time

import pytest
import serial

from benchtwin.hw.drivers.tesa import TesaTT
from benchtwin.hw.transport import SocketTransport, TransportClosed, open_transport, reopener
from benchtwin.twin.emulators.tcp import TcpServer
from benchtwin.twin.emulators.tesa import TesaEmulator

from tests.support.acquisition import Stub
from tests.support.acquisition import compare_tables as _compare


def test_socket_transport_contract_and_faults(monkeypatch):
    import types

    import benchtwin.hw.transport as T

    src = Stub(probe_top={"value_um": 1.25, "status": "ok"})
    plan = [{"port": "tesa", "request": 2, "action": "partial"}, {"port": "tesa", "request": 3, "action": "disconnect"}]
    with TcpServer({"tesa": TesaEmulator("tesa", src, "probe_top")}, plan) as server:
        url = server.paths()["tesa"]
        assert url.startswith("tcp://127.0.0.1:")
        t = open_transport(url, timeout=0.3, baudrate=4800, bytesize=7, parity="E", stopbits=2)  # line ignored
        assert isinstance(t, SocketTransport)
        t.write(b"?\r")
        assert t.read_until(b"\r\n") == b"+1.25\r\n"
        t.write(b"?\r")
        # "Reads wait at most ``timeout`` seconds in all": one deadline for the whole read, and no
        # wait past it (counted, not timed: a busy machine cannot fail this)
        deadlines, waits = [], []
        monkeypatch.setattr(t, "_deadline", lambda d=t._deadline: deadlines.append(d()) or deadlines[-1])
        monkeypatch.setattr(T, "select", types.SimpleNamespace(
            select=lambda r, w, x, wait, s=T.select.select: waits.append(wait) or s(r, w, x, wait)))
        t0 = time.monotonic()
        assert t.read_until(b"\r\n") == b"+1.25\r"           # partial: what came before the timeout
        assert time.monotonic() - t0 > 0.25                  # it waited for the timeout
        assert len(deadlines) == 1 and waits and all(0.0 <= w <= 0.3 for w in waits)
        monkeypatch.undo()
        t.write(b"?\r")                                       # 3: the instrument drops the connection
        with pytest.raises(TransportClosed):
            t.read_until(b"\r\n")
            t.write(b"?\r")
            t.read_until(b"\r\n")
        assert isinstance(TransportClosed("x"), serial.SerialException)
        # a driver re-connects through the same path as for a serial port
        drv = TesaTT("tesa", t, reconnect=reopener(url, timeout=0.3), sleep=lambda s: None)
        assert drv.read()["value_um"] == 1.25
        drv.close()
        assert [f["action"] for f in server.fired()] == ["partial", "disconnect"] and not server.errors
    with pytest.raises(serial.SerialException, match="cannot connect to 127.0.0.1"):
        open_transport(url, timeout=0.1)                      # the server is gone
    with pytest.raises(ValueError, match="tcp://HOST:PORT"):
        open_transport("tcp://nohost", timeout=0.1)


def test_tcp_base_port_is_validated():
    with pytest.raises(ValueError, match="TCP base port"):
        TcpServer({"a": None}, base_port=80)


def test_acquisition_over_tcp_equals_the_simulation(tmp_path, simulated):
    """``simulated``: the session's dataset of the resume tests' small jia2019 bench (tests/hw/conftest.py;
    12 radial stops, 4 frames of 256×192 px, one polygon shift over 8 faces), simulated once per run.
    This test simulated a bench of its own before, differing only by 6 polygon faces instead of 8 (a
    simulation and an α grid more, ≈ 3 s of CPU, issue 35): the property, every reading over TCP with
    faults equal to the direct simulation's, is the same on either bench, and the faults (the 3rd
    encoder and 9th stage request) fall in the radial stops on both."""
    from benchtwin.analysis.dataset import open_dataset
    from benchtwin.hw.acquisition.acquire import acquire
    from benchtwin.twin.emulators.serve import EmulationSession

    from tests.support.resume import small_scenario

    sc = small_scenario()
    faults = [{"port": "encoder", "request": 3, "action": "garble"},
              {"port": "stage", "request": 9, "action": "disconnect"}]
    sim = simulated
    with EmulationSession(sc, faults=faults, tcp=True) as session:
        bench = session.start(tmp_path / "emu")
        text = bench.read_text()
        assert 'port = "tcp://127.0.0.1:' in text and "loopback TCP sockets" in text
        out = acquire(bench, tmp_path / "ds", progress=False)
        assert session.server.errors == []
        assert sorted(f["action"] for f in session.server.fired()) == ["disconnect", "garble"]
    assert json.loads((out / "manifest.json").read_text())["source"] == "emulated"
    a, b = open_dataset(sim), open_dataset(out)
    assert len(b.table("radial_motion")["rep"]) == 12 and len(b.table("polygon")["ac_arcsec"]) == 8 * 8   # N start faces x N faces (one shift)
    # the same readings as the direct simulation (the emulators draw the twin's noise of the same steps)
    tables = ("radial_motion", "polygon")
    _compare({n: a.table(n) for n in tables}, {n: b.table(n) for n in tables})


def test_cli_emulate_tcp_writes_tcp_ports(tmp_path, capsys, monkeypatch):
    import tempfile

    from benchtwin import cli
    from benchtwin.hw.acquisition.bench import load_bench
    import benchtwin.app.commands_hw  # noqa: F401

    assert cli.main(["emulate", "--tcp", "--dir", str(tmp_path / "emu"), "--duration", "0.2", "--camera", "none",
                     "--json"]) == 0
    res = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    cfg = load_bench(res["bench_file"])
    ports = {n: s["port"] for n, s in cfg.instruments.items()}
    assert all(p.startswith("tcp://127.0.0.1:") for p in ports.values()), ports
    assert cfg.instruments["stage"]["options"]["message_ids"] is True
    # without --dir the emulator's temporary folder is made for it, and goes when nothing was written in it
    (tmp_path / "t").mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "t"))
    assert cli.main(["emulate", "--tcp", "--tcp-port", "80", "--duration", "0", "--camera", "none"]) == 2
    assert list((tmp_path / "t").iterdir()) == []
