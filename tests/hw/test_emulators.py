"""The protocol emulators answer the requests documented in docs/protocols/*.md, byte for byte
(no driver involved: the expected replies are written from the documents), and the pty server
serves them with a fault plan."""

from __future__ import annotations

import math
import os
import re
import time

import pytest
import serial

from benchtwin.twin.emulators.elcomat import ElcomatEmulator
from benchtwin.twin.emulators.heidenhain import HeidenhainEmulator
from benchtwin.twin.emulators.millimar import MillimarEmulator
from benchtwin.twin.emulators.pty import PtyServer, load_fault_plan
from benchtwin.twin.emulators.tesa import TesaEmulator
from benchtwin.twin.emulators.triangle import TriAngleEmulator
from benchtwin.twin.emulators.zaber import ZaberDeviceSpec, ZaberEmulator

from tests.support.acquisition import Stub


def one(emu, data: bytes):
    out = emu.feed(data)
    assert len(out) == 1, out
    return out[0][1]


# --------------------------------------------------------------------------- ELCOMAT

def test_elcomat_absolute_and_relative():
    src = Stub(autocollimator={"x_arcsec": 12.285, "y_arcsec": -0.1, "status": "ok"})
    e = ElcomatEmulator("ac", src, decimals=3)
    # elcomat.md: request "a" CR LF -> "4 003 <X> <Y>" CR, one space between fields
    assert one(e, b"a\r\n") == b"4 003 12.285 -0.100\r"
    assert re.fullmatch(rb"4 003 [-+]?\d+\.\d+ [-+]?\d+\.\d+\r", one(e, b"a\r\n"))
    # relative: "2 103 ..." against the reading at the first "r"
    assert one(e, b"r\r\n") == b"2 103 0.000 0.000\r"
    src.readings["autocollimator"]["x_arcsec"] = 13.285
    assert one(e, b"r\r\n") == b"2 103 1.000 0.000\r"
    assert one(e, b"x\r\n") is None          # unknown request: silence


def test_elcomat_out_of_range_is_another_code_pair():
    src = Stub(autocollimator={"x_arcsec": math.nan, "y_arcsec": math.nan, "status": "out_of_range"})
    assert one(ElcomatEmulator("ac", src), b"a\r\n") == b"4 000 0.000 0.000\r"


# --------------------------------------------------------------------------- TriAngle

def test_triangle_poll_fields_y_x_unknown_signal():
    src = Stub(autocollimator={"x_arcsec": 1.5, "y_arcsec": -2.25, "status": "ok"})
    e = TriAngleEmulator("ac", src)
    # triangle.md: "P 1" -> numbers separated by ';': field 0 = Y, 1 = X, 3 = signal level
    r = one(e, b"P 1\r\n")
    assert r == b"-2.250;1.500;0.000;1.000\r\n"
    assert one(e, b"P\r\n") == r             # short form
    assert one(e, b"p 1\r\n") is None        # case sensitive
    src.readings["autocollimator"].update(status="out_of_range", x_arcsec=math.nan)
    assert one(e, b"P 1\r\n").split(b";")[3] == b"0.000\r\n"   # signal <= 0.01: no signal


# --------------------------------------------------------------------------- TESA

def test_tesa_displayed_value():
    src = Stub(probe_top={"value_um": -3.98, "status": "ok"})
    e = TesaEmulator("p", src, "probe_top", decimals=2)
    # tesa.md: "?" CR -> "±xxxx.xx" CR LF
    r = one(e, b"?\r")
    assert r == b"-3.98\r\n"
    assert re.fullmatch(rb"[-+]\d+\.\d{2}\r\n", r)
    assert one(e, b"UNI?\r") == b"UM\r\n"
    assert one(e, b"FNC\r") == b"ERR23\r\n"
    src.readings["probe_top"].update(status="out_of_range", value_um=math.nan)
    assert one(e, b"?\r") == b"OVER\r\n"


# --------------------------------------------------------------------------- Millimar

def test_millimar_features():
    src = Stub(probe_top={"value_um": 2.42, "status": "ok"}, probe_bottom={"value_um": -13.5, "status": "ok"})
    e = MillimarEmulator("m", src, {1: "probe_top", 2: "probe_bottom"}, decimals=2)
    # millimar.md: "M1?" CR -> "1 ±XXX.XX um" CR (leading zeros), "ERR6" for a deactivated feature
    assert one(e, b"M1?\r") == b"1 +002.42 um\r"
    assert one(e, b"M2?\r") == b"2 -013.50 um\r"
    assert one(e, b"M3?\r") == b"3 ERR6\r"
    assert one(e, b"?\r") == b"1 +002.42 um;2 -013.50 um;3 ERR6\r"
    assert one(e, b"ID?\r").startswith(b"C1202")
    assert one(e, b"M4?\r") is None
    with pytest.raises(ValueError):
        MillimarEmulator("m", src, {4: "probe_top"})


# --------------------------------------------------------------------------- Heidenhain

def test_heidenhain_current_value_two_heads():
    src = Stub(encoder={"angle_deg": [123.4567891, -0.0000014], "heads_deg": [0.0, 180.0], "status": "ok"})
    e = HeidenhainEmulator("enc", src, decimals=6)
    # heidenhain-nd.md: ESC A0200 CR -> STX, per axis sign + 9 digits (no decimal point) + CR LF
    r = one(e, b"\x1bA0200\r")
    assert r == b"\x02+123456789\r\n-000000001\r\n"
    assert one(e, b"\x1bA0300\r") == b"\x15"      # NAK: invalid command
    src.readings["encoder"]["angle_deg"] = [1234.0]
    assert one(e, b"\x1bA0200\r").startswith(b"\x02OVERFLOW")  # error text, STX + 13 chars + CR LF
    assert len(one(e, b"\x1bA0200\r")) == 1 + 13 + 2


# --------------------------------------------------------------------------- Zaber

def test_zaber_move_poll_get_set():
    src = Stub()
    z = ZaberEmulator("stage", src, ZaberDeviceSpec(microsteps_per_deg=1000, busy_polls=1))
    # zaber.md: "/1 1 move abs 90000" LF -> "@01 1 OK BUSY -- 0" CR LF; polls until IDLE
    assert one(z, b"/1 1 move abs 90000\n") == b"@01 1 OK BUSY -- 0\r\n"
    assert src.moves == [90.0]
    assert one(z, b"/1 1\n") == b"@01 1 OK BUSY -- 0\r\n"
    assert one(z, b"/1 1\n") == b"@01 1 OK IDLE -- 0\r\n"
    assert one(z, b"/1 1 get pos\n") == b"@01 1 OK IDLE -- 90000\r\n"
    assert one(z, b"/1 1 move rel -500\n").startswith(b"@01 1 OK BUSY")
    assert src.moves[-1] == pytest.approx(89.5)
    # maxspeed in Zaber units: microsteps/s x 1.6384 (20 deg/s x 1000 = 20000 -> 32768)
    assert one(z, b"/1 1 get maxspeed\n").endswith(b"-- 32768\r\n")
    assert one(z, b"/1 1 set maxspeed 1000\n") == b"@01 1 OK IDLE -- 0\r\n"
    assert one(z, b"/1 1 get maxspeed\n").endswith(b"-- 1000\r\n")
    assert one(z, b"/1 1 fly\n") == b"@01 1 RJ IDLE -- BADCOMMAND\r\n"
    assert one(z, b"/1 1 move abs x\n") == b"@01 1 RJ IDLE -- BADDATA\r\n"
    assert one(z, b"/2 1 get pos\n") is None       # another device on the chain
    assert re.fullmatch(rb"@\d{2} \d (OK|RJ) (IDLE|BUSY) (--|[FWN][A-Z]) [ -~]*\r\n", one(z, b"/0 0\n"))


def test_framing_across_chunks_and_cr_lf():
    src = Stub(autocollimator={"x_arcsec": 1.0, "y_arcsec": 2.0, "status": "ok"})
    e = ElcomatEmulator("ac", src, decimals=2)
    assert e.feed(b"a") == []
    assert e.feed(b"\r") == [(b"a", b"4 003 1.00 2.00\r")]
    assert e.feed(b"\na\r\na\r\n") == [(b"a", b"4 003 1.00 2.00\r")] * 2
    assert e.requests == 3


# --------------------------------------------------------------------------- pty server + faults

def _port(path, timeout=0.3):
    return serial.serial_for_url(path, baudrate=4800, timeout=timeout)   # the TESA TT is at 4800 baud (tesa.md)


def test_pty_server_serves_and_applies_faults(tmp_path):
    src = Stub(probe_top={"value_um": 1.25, "status": "ok"})
    plan = {"faults": [{"port": "tesa", "request": 2, "action": "drop"},
                       {"port": "tesa", "request": 3, "action": "garble"},
                       {"port": "tesa", "request": 4, "action": "partial"},
                       {"port": "tesa", "request": 5, "action": "delay", "seconds": 0.2},
                       {"port": "tesa", "request": 6, "action": "disconnect"}]}
    server = PtyServer({"tesa": TesaEmulator("tesa", src, "probe_top")}, plan, link_dir=tmp_path / "ports")
    with server:
        link = server.paths()["tesa"]
        assert os.path.islink(link) and os.readlink(link).startswith("/dev/")
        pts0 = server.pts()["tesa"]
        s = _port(link)
        s.write(b"?\r")
        assert s.read_until(b"\r\n") == b"+1.25\r\n"           # 1: normal
        s.write(b"?\r")
        assert s.read_until(b"\r\n") == b""                     # 2: dropped -> timeout
        s.write(b"?\r")
        assert s.read_until(b"\r\n") == b"#1.25\r\n"            # 3: garbled, terminator kept
        s.write(b"?\r")
        assert s.read_until(b"\r\n") == b"+1.25\r"              # 4: partial, no terminator
        s.reset_input_buffer()
        t0 = time.monotonic()
        s.timeout = 1.0
        s.write(b"?\r")
        assert s.read_until(b"\r\n") == b"+1.25\r\n"            # 5: delayed
        assert time.monotonic() - t0 >= 0.18
        s.write(b"?\r")                                         # 6: disconnect
        with pytest.raises((serial.SerialException, OSError)):
            s.read_until(b"\r\n")
            s.write(b"?\r")
            s.read_until(b"\r\n")
        s.close()
        assert server.pts()["tesa"] != pts0
        s2 = _port(link)                                        # the link points at the new port
        s2.write(b"?\r")
        assert s2.read_until(b"\r\n") == b"+1.25\r\n"
        s2.close()
        assert [f["action"] for f in server.fired()] == ["drop", "garble", "partial", "delay", "disconnect"]
        assert not server.errors


def test_a_pty_servers_own_link_folder_goes_with_it(tmp_path, monkeypatch):
    """A server given no link folder makes one in the temporary directory and removes it on stop; a
    caller's folder stays (it is the caller's)."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    src = Stub(probe_top={"value_um": 1.25, "status": "ok"})
    with PtyServer({"tesa": TesaEmulator("tesa", src, "probe_top")}) as server:
        own = server.link_dir
        assert own.parent == tmp_path and os.path.islink(server.paths()["tesa"])
    assert not own.exists()
    with pytest.raises(ValueError, match="unknown port"):
        PtyServer({"a": None}, [{"port": "b", "request": 1, "action": "drop"}])
    assert list(tmp_path.iterdir()) == []
    given = tmp_path / "ports"
    with PtyServer({"tesa": TesaEmulator("tesa", src, "probe_top")}, link_dir=given):
        pass
    assert given.is_dir() and list(given.iterdir()) == []


def test_fault_plan_validation(tmp_path):
    f = tmp_path / "faults.toml"
    f.write_text('[[faults]]\nport = "stage"\nrequest = 3\naction = "drop"\n')
    assert load_fault_plan(f) == [{"port": "stage", "request": 3, "action": "drop", "seconds": 0.0}]
    f.write_text('[[faults]]\nport = "stage"\nrequest = 0\naction = "drop"\n')
    with pytest.raises(ValueError, match=r"faults\.toml: faults\[0\]: key 'request'"):
        load_fault_plan(f)
    with pytest.raises(ValueError, match="key 'action'"):
        load_fault_plan([{"port": "x", "request": 1, "action": "explode"}])
    with pytest.raises(ValueError, match="unknown port"):
        PtyServer({"a": None}, [{"port": "b", "request": 1, "action": "drop"}], link_dir=tmp_path / "p")


# --------------------------------------------------------------------------- issue 18: faithful protocols

def _cs(body: bytes) -> bytes:
    """zaber.md: the checksum makes the byte sum after '/' or '@' zero mod 256."""
    return f"{(-sum(body)) & 0xFF:02X}".encode()


def test_zaber_message_ids_checksums_and_identity():
    z = ZaberEmulator("stage", Stub())
    assert one(z, b"/1 1 07 get pos\n") == b"@01 1 07 OK IDLE -- 0\r\n"        # the id is echoed
    req = b"1 0 42 get deviceid"
    r = one(z, b"/" + req + b":" + _cs(req) + b"\n")
    body, cs = r[1:-2].split(b":")
    assert body == b"01 0 42 OK IDLE -- 50419" and cs == _cs(body)             # checksummed reply
    assert (sum(body) + int(cs, 16)) % 256 == 0
    assert one(z, b"/1 0 get deviceid:00\n") is None                           # corrupted: dropped
    assert one(z, b"/1 1 get deviceid\n") == b"@01 1 RJ IDLE -- BADAXIS\r\n"   # a device setting
    assert one(z, b"/1 2 get pos\n") == b"@01 2 RJ IDLE -- BADAXIS\r\n"        # no such axis
    for key, want in [("system.serial", b"70001"), ("version", b"7.38"), ("limit.min", b"-360000"),
                      ("limit.max", b"720000"), ("resolution", b"1800")]:
        assert one(z, b"/1 0 get " + key.encode() + b"\n").endswith(b" " + want + b"\r\n"), key
    assert one(z, b"/1 1 move abs 900000\n") == b"@01 1 RJ IDLE -- BADDATA\r\n"   # beyond limit.max
    assert one(z, b"noise /1 1\n") == b"@01 1 OK IDLE -- 0\r\n"   # bytes before '/' are line noise


def test_zaber_alerts_info_and_warnings():
    src = Stub()
    z = ZaberEmulator("stage", src, ZaberDeviceSpec(busy_polls=1))
    assert one(z, b"/1 0 set comm.alert 1\n") == b"@01 0 OK IDLE -- 0\r\n"
    assert one(z, b"/1 1 move abs 1000\n") == b"@01 1 OK BUSY -- 0\r\n"
    # the move ends after the last BUSY reply: the unsolicited alert follows it (zaber.md)
    assert one(z, b"/1 1\n") == b"@01 1 OK BUSY -- 0\r\n!01 1 IDLE --\r\n"
    assert one(z, b"/1 1\n") == b"@01 1 OK IDLE -- 0\r\n"
    z.warnings |= {"WL", "NC", "FS"}
    assert one(z, b"/1 1\n") == b"@01 1 OK IDLE FS 0\r\n"                     # highest priority: fault
    assert one(z, b"/1 1 warnings clear\n") == b"@01 1 OK IDLE FS 03 FS WL NC\r\n"
    assert one(z, b"/1 1 warnings\n") == b"@01 1 OK IDLE FS 01 FS\r\n"          # a fault is not cleared
    assert one(z, b"/1 help\n").split(b"\r\n")[1].startswith(b"#01 0 ")          # info line
    assert one(z, b"/1 0 system reset\n") == b"@01 0 OK IDLE -- 0\r\n"


def test_heidenhain_fixed_length_sequences_identification_error_status():
    src = Stub(encoder={"angle_deg": [1.5], "status": "ok"})
    e = HeidenhainEmulator("enc", src, decimals=4)
    # ESC sequences are fixed length: no CR needed, a CR after one is ignored, noise before ESC dropped
    assert e.feed(b"\x1bA0200") == [(b"\x1bA0200", b"\x02+000015000\r\n")]
    assert e.feed(b"\r") == []
    assert e.feed(b"xx\x1bA02") == []
    assert e.feed(b"00\r\n") == [(b"\x1bA0200", b"\x02+000015000\r\n")]
    ident = one(e, b"\x1bA0000")
    assert len(ident) == 37 and ident.startswith(b"\x02ND 287 ") and ident.endswith(b"\r\n")
    assert one(e, b"\x1bA0301") == b"\x02" + b"NO ERROR".ljust(33) + b"\r\n"
    assert one(e, b"\x1bA0800") == b"\x02REF OK DEG   \r\n"
    assert one(e, b"\x1bX9999") == b"\x15"
    assert one(e, b"hello\r") == b"\x15"                            # a line that is no sequence: NAK
    e.connect({"baudrate": 9600, "stopbits": 2})
    assert e.feed(b"\x1bA02") == [] and e.understood
    e.connect({"baudrate": 9600, "stopbits": 1})                    # 7E1 talks to a 7E2 device
    assert e.feed(b"00\r") == [(b"00", b"\x15")]    # the old half request is gone: "00" alone is NAK
    e.connect({"baudrate": 19200})
    assert not e.understood and e.feed(b"\x1bA0200") == [] and e.noise_bytes == 6
    assert "19200 baud" in e.framing_notes[-1]
