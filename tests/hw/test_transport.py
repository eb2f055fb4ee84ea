"""Transport contract, open_transport, RecordingTransport and ReplayTransport (hw/transport.py)."""

from __future__ import annotations

import json

import pytest
import serial

from benchtwin.hw.transport import (RecordingTransport, ReplayMismatch, ReplayTransport, Transport,
                                    TransportClosed, load_transcript, open_transport)


def test_serial_loop_url_satisfies_contract():
    port = open_transport("loop://", timeout=0.1)
    try:
        assert isinstance(port, Transport)
        port.write(b"hello\r\n")
        assert port.read_until(b"\r\n") == b"hello\r\n"
        port.write(b"partial")
        assert port.read_until(b"\r\n") == b"partial"  # timeout: no terminator
        port.write(b"x")
        port.reset_input_buffer()
        assert port.read(5) == b""
    finally:
        port.close()


def test_open_transport_from_section_and_settings():
    port = open_transport({"port": "loop://", "baudrate": 4800, "bytesize": 7, "parity": "E", "stopbits": 2,
                           "timeout": 0.05})
    try:
        assert port.baudrate == 4800 and port.bytesize == 7 and port.parity == serial.PARITY_EVEN
        assert port.stopbits == 2 and port.timeout == 0.05
    finally:
        port.close()
    with pytest.raises(ValueError, match="port"):
        open_transport({"baudrate": 9600})
    with pytest.raises(ValueError, match="unknown transport settings"):
        open_transport({"port": "loop://", "speed": 1})
    with pytest.raises(ValueError, match="parity"):
        open_transport("loop://", parity="Q")


def test_replay_serves_in_strict_order_and_reports_mismatch():
    rt = ReplayTransport([{"request": "a\r\n", "response": "one\r"}, {"request": "b\r\n", "response": "two\r"}])
    assert isinstance(rt, Transport)
    rt.write(b"a")
    rt.write(b"\r\n")  # a request may arrive in pieces
    assert rt.read_until(b"\r") == b"one\r"
    with pytest.raises(ReplayMismatch) as exc:
        rt.write(b"c\r\n")
    msg = str(exc.value)
    assert "expected: b'b\\r\\n'" in msg and "got:      b'c\\r\\n'" in msg


def test_replay_leftovers_detected():
    rt = ReplayTransport([{"request": "a", "response": "1"}, {"request": "b", "response": "2"}])
    rt.write(b"a")
    assert rt.read(1) == b"1"
    with pytest.raises(ReplayMismatch, match="1 exchange\\(s\\) left over"):
        rt.assert_done()
    rt.write(b"b")
    rt.assert_done()
    with pytest.raises(ReplayMismatch, match="exhausted"):
        rt.write(b"c")


def test_replay_disconnect_and_reopen():
    rt = ReplayTransport([{"request": "q", "response": "", "error": "disconnect"}, {"event": "reopen"},
                          {"request": "q", "response": "ok\n"}])
    with pytest.raises(TransportClosed):
        rt.write(b"q")
    assert isinstance(TransportClosed("x"), serial.SerialException)
    with pytest.raises(TransportClosed):
        rt.read(1)
    rt.reopen()
    rt.write(b"q")
    assert rt.readline() == b"ok\n"
    rt.assert_done()


def test_replay_reopen_out_of_order_is_a_mismatch():
    rt = ReplayTransport([{"request": "q", "response": "x"}])
    with pytest.raises(ReplayMismatch, match="re-opened"):
        rt.reopen()


def test_transcript_validation(tmp_path):
    p = tmp_path / "t.jsonl"
    p.write_text('{"comment": "c"}\n\n{"request": "a", "response": "b"}\n')
    assert load_transcript(p) == [{"request": "a", "response": "b"}]
    p.write_text("not json\n")
    with pytest.raises(ValueError, match="t.jsonl:1"):
        load_transcript(p)
    with pytest.raises(ValueError, match="unknown event"):
        load_transcript([{"event": "explode"}])
    with pytest.raises(ValueError, match="neither"):
        load_transcript([{"response": "x"}])


def test_recording_round_trips_through_replay(tmp_path):
    inner = open_transport("loop://", timeout=0.05)
    path = tmp_path / "rec.jsonl"
    rec = RecordingTransport(inner, path)
    assert isinstance(rec, Transport)
    rec.write(b"\x1bA0200\r")  # loop:// echoes: the "response" is the request itself
    assert rec.read_until(b"\r") == b"\x1bA0200\r"
    rec.write(b"P 1\r\n")
    assert rec.readline() == b"P 1\r\n"
    rec.timeout = 0.01
    assert inner.timeout == 0.01
    rec.close()
    lines = [json.loads(x) for x in path.read_text().splitlines()]
    assert lines == [{"request": "\x1bA0200\r", "response": "\x1bA0200\r"},
                     {"request": "P 1\r\n", "response": "P 1\r\n"}]
    assert "\\u001b" in path.read_text()  # control bytes stay readable escapes
    rt = ReplayTransport(path)
    rt.write(b"\x1bA0200\r")
    assert rt.read_until(b"\r") == b"\x1bA0200\r"
    rt.write(b"P 1\r\n")
    assert rt.readline() == b"P 1\r\n"
    rt.assert_done()


def test_recording_records_disconnect(tmp_path):
    class Dying:
        timeout = 0.1

        def write(self, b):
            raise serial.SerialException("device reports readiness to read but returned no data")

        def read_until(self, expected=b"\n", size=None):
            return b""

        def read(self, n=1):
            return b""

        def readline(self, size=-1):
            return b""

        def reset_input_buffer(self):
            pass

        def close(self):
            pass

    path = tmp_path / "d.jsonl"
    rec = RecordingTransport(Dying(), path)
    with pytest.raises(serial.SerialException):
        rec.write(b"a\r\n")
    rec.reopen(ReplayTransport([]))
    rec.close()
    assert [json.loads(x) for x in path.read_text().splitlines()] == [
        {"request": "a\r\n", "response": "", "error": "disconnect"}, {"event": "reopen"}]
