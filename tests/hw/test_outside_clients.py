"""Hardware-in-the-loop the other way round (issue 18): the emulated instruments answer clients
written for the real devices, not for our drivers.

- the official Zaber Motion Library (``zaber-motion``, PyPI): detect, generic commands, move and
  position, on a pseudo-terminal and on TCP (Zaber's Ethernet port protocol);
- pymeasure's Heidenhain ND287 driver, unchanged: position, id, error message, status; also after a
  reconnect with a previous client's half-sent request left in the line;
- raw pyserial scripts that follow the vendor manuals where no public client exists (TESA TT,
  Millimar C1202, TriAngle; docs/protocols/*.md), opened at the manuals' framing (7E2 where the
  manual says so);
- a client at the wrong baud rate gets silence (its bytes are line noise to the device), and the
  emulator says why.

What the Zaber Motion Library cannot do here: identify the device and convert units
(``Units.ANGLE_DEGREES``) — that needs Zaber's device database (a web service, or a database file
downloaded from Zaber; neither is on PyPI nor reachable here). The tests point the library at a
missing local database file, so it never tries the network, and do not ask for identification
(docs/protocols/README.md, "Outside clients"). The library runs in a process of its own, as a
lab's software would.
"""

from __future__ import annotations

import os
import re
import time

import pytest
import serial

from benchtwin.twin.emulators.heidenhain import HeidenhainEmulator
from benchtwin.twin.emulators.millimar import MillimarEmulator
from benchtwin.twin.emulators.pty import PtyServer
from benchtwin.twin.emulators.tcp import TcpServer
from benchtwin.twin.emulators.tesa import TesaEmulator
from benchtwin.twin.emulators.triangle import TriAngleEmulator
from benchtwin.twin.emulators.zaber import ZaberEmulator

from tests.support.acquisition import Stub

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")


def _wait(cond, timeout_s: float = 2.0) -> bool:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > timeout_s:
            return False
        time.sleep(0.01)
    return True


# --------------------------------------------------------------------------- Zaber Motion Library

# The library runs in its own process, as a lab's bench software would (the emulator serves from
# this one): its Go core installs signal handlers that must not share the test process with MuJoCo
# and the other native libraries. Its device database is pointed at a local file that does not
# exist, so nothing can go to the network. Identification is not attempted: without a database
# the library 10.3.0 raises DeviceDbFailedException from the web source, but with a missing file
# source it can also crash with a nil-pointer panic in its Go core (identify.go:342), which would
# take the client process down (docs/protocols/README.md, "Outside clients").
ZML_CLIENT = r"""
import json, sys
from zaber_motion import DeviceDbSourceType, Library
from zaber_motion.ascii import Connection
from zaber_motion.exceptions import MotionLibException

kind, where, db = sys.argv[1], sys.argv[2], sys.argv[3]
Library.set_device_db_source(DeviceDbSourceType.FILE, db)
out = {}
conn = Connection.open_serial_port(where) if kind == "serial" else Connection.open_tcp("127.0.0.1", int(where))
with conn:
    devices = conn.detect_devices(identify_devices=False)
    out["addresses"] = [d.device_address for d in devices]
    out["ids"] = {k: conn.generic_command(f"get {k}", device=1).data
                  for k in ("deviceid", "system.serial", "version", "system.axiscount")}
    r = conn.generic_command("get pos", device=1, axis=1)
    out["status"] = [r.reply_flag, r.status, r.warning_flag, r.data]
    axis = devices[0].get_axis(1)
    axis.move_absolute(90000)                 # native units: microsteps
    out["pos1"] = axis.get_position()
    axis.move_relative(-2500)
    out["pos2"] = axis.get_position()
    try:
        conn.generic_command("fly", device=1, axis=1)
    except MotionLibException as exc:
        out["rejected"] = str(exc)
print(json.dumps(out))
"""


def _zml(kind: str, where: str, tmp_path) -> dict:
    import json
    import subprocess
    import sys

    script = tmp_path / "zml_client.py"
    script.write_text(ZML_CLIENT)
    run = subprocess.run([sys.executable, str(script), kind, where, str(tmp_path / "no-devices.sqlite")],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.strip().splitlines()[-1])


def _check_zml(out: dict, src: Stub) -> None:
    assert out["addresses"] == [1]
    assert out["ids"] == {"deviceid": "50419", "system.serial": "70001", "version": "7.38", "system.axiscount": "1"}
    assert out["status"] == ["OK", "IDLE", "--", "0"]
    assert out["pos1"] == 90000.0 and out["pos2"] == 87500.0
    assert src.moves == [90.0, pytest.approx(87.5)]         # the twin's stage got both moves
    assert "BADCOMMAND" in out["rejected"]


def test_zaber_motion_library_on_a_pty(tmp_path):
    src = Stub()
    emu = ZaberEmulator("stage", src)
    emu.keep_log = True
    with PtyServer({"stage": emu}) as server:
        out = _zml("serial", server.paths()["stage"], tmp_path)
        assert server.errors == []
    _check_zml(out, src)
    sent = [q for q, _ in emu.log]
    # the library numbers its messages and checksums them; the emulator answered every one
    assert all(re.fullmatch(rb"/\d+ \d+ \d\d[ -~]*:[0-9A-F]{2}", q) for q in sent), sent[:3]
    assert all(r is not None and r.endswith(b"\r\n") for _, r in emu.log)


def test_zaber_motion_library_over_tcp(tmp_path):
    src = Stub()
    with TcpServer({"stage": ZaberEmulator("stage", src)}) as server:
        out = _zml("tcp", server.paths()["stage"].rsplit(":", 1)[1], tmp_path)
        assert server.errors == []
    _check_zml(out, src)


# --------------------------------------------------------------------------- pymeasure ND287

def _nd287(path):
    from pymeasure.adapters import SerialAdapter
    from pymeasure.instruments.heidenhain import ND287

    # the framing of the display's manual: 9600 baud, 7 data bits, even parity, 2 stop bits
    return ND287(SerialAdapter(path, baudrate=9600, bytesize=7, parity="E", stopbits=2, timeout=0.3))


def test_pymeasure_nd287_position_id_errors_status():
    src = Stub(encoder={"angle_deg": [12.3456], "status": "ok"})
    # pymeasure's ND287 scales the 9 digits by 1e-4 (a display set to 4 decimals, "mm" mode): the
    # emulated display is set to 4 decimals, so position reads the twin's angle in degrees
    emu = HeidenhainEmulator("encoder", src, decimals=4)
    with PtyServer({"encoder": emu}) as server:
        path = server.paths()["encoder"]
        nd = _nd287(path)
        assert nd.position == pytest.approx(12.3456, abs=1e-9)      # the first request is answered
        ident = nd.id
        assert len(ident) == 37 and ident.startswith("\x02ND 287") and ident.endswith("\r\n")
        assert nd.check_errors().startswith("\x02NO ERROR")
        assert "REF OK" in nd.status
        nd.adapter.connection.write(b"\x1bA02")   # a client leaves with half a request in the line
        nd.adapter.connection.close()
        src.readings["encoder"]["angle_deg"] = [-0.0123]
        nd = _nd287(path)                          # the next client is answered at once
        assert nd.position == pytest.approx(-0.0123, abs=1e-9)
        nd.adapter.connection.close()
        assert emu.connections == 2 and server.errors == []


# --------------------------------------------------------------------------- vendor-manual scripts

def _ask(port: serial.Serial, request: bytes, end: bytes) -> bytes:
    port.reset_input_buffer()
    port.write(request)
    return port.read_until(end)


def test_tesa_tt_script_from_the_manual():
    src = Stub(probe_top={"value_um": -3.98, "status": "ok"})
    with PtyServer({"tesa": TesaEmulator("tesa", src, "probe_top")}) as server:
        # TT80/TT90 manual ch. 11: 4800 baud, 7 data bits, even parity, 2 stop bits; "?" CR
        with serial.Serial(server.paths()["tesa"], 4800, bytesize=7, parity="E", stopbits=2, timeout=1) as p:
            assert _ask(p, b"?\r", b"\r\n") == b"-3.98\r\n"
            assert _ask(p, b"UNI?\r", b"\r\n") == b"UM\r\n"


def test_millimar_c1202_script_from_the_manual():
    src = Stub(probe_top={"value_um": 2.42, "status": "ok"}, probe_bottom={"value_um": -13.5, "status": "ok"})
    emu = MillimarEmulator("probes", src, {1: "probe_top", 2: "probe_bottom"})
    with PtyServer({"probes": emu}) as server:
        # C1202 instructions 7.2: 9600 baud, 7 bits, even parity, 2 stop bits; everything ends with CR
        with serial.Serial(server.paths()["probes"], 9600, bytesize=7, parity="E", stopbits=2, timeout=1) as p:
            assert _ask(p, b"ID?\r", b"\r").startswith(b"C1202")
            assert _ask(p, b"M1?\r", b"\r") == b"1 +002.42 um\r"
            assert _ask(p, b"?\r", b"\r") == b"1 +002.42 um;2 -013.50 um;3 ERR6\r"


def test_triangle_script_from_the_help_text():
    src = Stub(autocollimator={"x_arcsec": 1.5, "y_arcsec": -2.25, "status": "ok"})
    with PtyServer({"ac": TriAngleEmulator("ac", src)}) as server:
        with serial.Serial(server.paths()["ac"], 9600, timeout=1) as p:
            y, x, _f2, sig = (float(v) for v in _ask(p, b"P 1\r\n", b"\r\n").split(b";"))
            assert (y, x, sig) == (-2.25, 1.5, 1.0)


def test_wrong_baud_rate_is_line_noise_and_said_so():
    src = Stub(probe_top={"value_um": 1.0, "status": "ok"})
    emu = TesaEmulator("tesa", src, "probe_top")
    with PtyServer({"tesa": emu}) as server:
        path = server.paths()["tesa"]
        with serial.Serial(path, 9600, bytesize=7, parity="E", stopbits=2, timeout=0.3) as p:
            assert _ask(p, b"?\r", b"\r\n") == b""                 # the TT is at 4800: silence
        assert _wait(lambda: emu.framing_notes)
        assert "9600 baud" in emu.framing_notes[-1] and "4800" in emu.framing_notes[-1]
        with serial.Serial(path, 4800, bytesize=7, parity="E", stopbits=2, timeout=1) as p:
            assert _ask(p, b"?\r", b"\r\n") == b"+1.00\r\n"       # the right framing: understood


def test_what_a_pty_shows_of_the_client_line_settings():
    """docs/protocols/README.md: on a pty, speed, stop bits and odd parity are visible, data bits and
    even parity are not (the kernel forces CS8 and clears PARENB)."""
    src = Stub(probe_top={"value_um": 1.0, "status": "ok"})
    emu = TesaEmulator("tesa", src, "probe_top")
    with PtyServer({"tesa": emu}) as server:
        path = server.paths()["tesa"]
        with serial.Serial(path, 4800, bytesize=7, parity="E", stopbits=2, timeout=1) as p:
            assert _ask(p, b"?\r", b"\r\n") == b"+1.00\r\n"
        assert emu.client == {"transport": "pty", "baudrate": 4800, "stopbits": 2, "parity_odd": False}
        with serial.Serial(path, 4800, bytesize=8, parity="N", stopbits=1, timeout=1) as p:
            assert _ask(p, b"?\r", b"\r\n") == b"+1.00\r\n"     # 8N1: indistinguishable from 7E1 on a pty
        assert emu.client["stopbits"] == 1
        with serial.Serial(path, 4800, bytesize=7, parity="O", stopbits=2, timeout=0.3) as p:
            assert _ask(p, b"?\r", b"\r\n") == b""              # odd parity on an even-parity display
        assert emu.client["parity_odd"] and "odd/mark parity" in emu.framing_notes[-1]
        assert emu.connections == 3
