"""Serial drivers replayed from hand-written transcripts (tests/hw/transcripts/*.jsonl, written from
docs/protocols/*.md), fault handling, parser properties, and one driver over a real pseudo-terminal."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchtwin.hw.drivers.base import Command, CommandTable, InstrumentError, to_bytes
from benchtwin.hw.drivers.elcomat import Elcomat, format_elcomat
from benchtwin.hw.transport import ReplayMismatch, ReplayTransport

T = Path(__file__).parent / "transcripts"


class Sleeps(list):
    """Injected sleep: records the waits instead of waiting."""

    def __call__(self, s: float) -> None:
        self.append(s)


class Clock:
    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


def replay(name: str) -> ReplayTransport:
    return ReplayTransport(T / name, name=name)


# --- base machinery -------------------------------------------------------------------------------

def test_command_table_overrides_from_bench_section():
    defaults = {"read": Command("read", b"a\r\n", rb"\d+\r", "raw", b"\r")}
    table = CommandTable.build(defaults, {"read": {"template": "A\\r\\n", "terminator": "\r"},
                                          "extra": {"template": "\x1bA0200\r", "response": ".*"}})
    assert table["read"].template == b"A\r\n" and table["read"].response == rb"\d+\r"
    assert table["extra"].template == b"\x1bA0200\r"
    with pytest.raises(ValueError, match="unknown keys"):
        CommandTable.build(defaults, {"read": {"templat": "x"}})
    with pytest.raises(ValueError, match="needs at least a template"):
        CommandTable.build(defaults, {"new": {"response": "x"}})
    with pytest.raises(ValueError, match="bad response regex"):
        CommandTable.build(defaults, {"read": {"response": "("}})
    assert to_bytes("\\x1bA") == b"\x1bA" and to_bytes(b"x") == b"x"
    t2 = CommandTable.build(defaults, {"read": {"response": r"\d+\b\r"}})
    assert t2["read"].compiled().fullmatch(b"12\r")  # regex escapes are not decoded as string escapes


def test_unknown_parse_function_refused():
    with pytest.raises(ValueError, match="parse function"):
        Elcomat("ac", ReplayTransport([]), commands={"read_absolute": {"parse": "nope"}})


# --- ELCOMAT --------------------------------------------------------------------------------------

def test_elcomat_replay_absolute_and_relative():
    rt = replay("elcomat_basic.jsonl")
    clock = Clock()
    ac = Elcomat("ac", rt, clock=clock, sleep=Sleeps())
    r = ac.read()
    assert r == {"x_arcsec": 12.34, "y_arcsec": -5.67, "status": "ok", "code": "4 003", "t_s": 100.0}
    ac.mode = "relative"
    r = ac.read()
    assert (r["x_arcsec"], r["y_arcsec"], r["status"]) == (-0.5, 0.25, "ok")
    rt.assert_done()


def test_elcomat_faults_timeout_partial_garbled_status_reconnect():
    rt = replay("elcomat_faults.jsonl")
    sleeps = Sleeps()
    ac = Elcomat("ac", rt, sleep=sleeps, clock=Clock(), retries=2, backoff_s=0.1, reconnect=rt.reopen)
    assert ac.read()["x_arcsec"] == 12.34  # timeout, partial, then success
    assert sleeps == [0.1, 0.2]  # exponential backoff through the injected sleep
    assert ac.read()["y_arcsec"] == 2.0  # garbled, then success
    r = ac.read()  # well-formed but unknown code pair: reported, not retried
    assert r["status"] == "code_0_000" and math.isnan(r["x_arcsec"])
    r = ac.read()  # disconnect -> reconnect callable -> success
    assert (r["x_arcsec"], r["y_arcsec"]) == (3.0, 4.0)
    rt.assert_done()


def test_elcomat_persistent_failure_names_instrument_command_raw():
    rt = replay("elcomat_dead.jsonl")
    ac = Elcomat("ac_main", rt, sleep=Sleeps(), retries=2)
    with pytest.raises(InstrumentError) as exc:
        ac.read()
    e = exc.value
    assert e.instrument == "ac_main" and e.command == "read_absolute" and e.raw == b"4 003 nonsense\r"
    assert "ac_main" in str(e) and "read_absolute" in str(e) and "4 003 nonsense" in str(e)
    assert "3 attempt" in str(e)
    rt.assert_done()


def test_disconnect_without_reconnect_fails_clearly():
    rt = ReplayTransport([{"request": "a\r\n", "response": "", "error": "disconnect"}])
    ac = Elcomat("ac", rt, sleep=Sleeps())
    with pytest.raises(InstrumentError, match="disconnected.*no reconnect"):
        ac.read()


def test_replay_catches_wrong_request_from_overridden_table():
    rt = ReplayTransport([{"request": "a\r\n", "response": "4 003 1.0 2.0\r"}])
    ac = Elcomat("ac", rt, sleep=Sleeps(), commands={"read_absolute": {"template": "A\r"}})
    with pytest.raises(ReplayMismatch, match="expected"):
        ac.read()


_arcsec = st.floats(min_value=-2000, max_value=2000, allow_nan=False).map(lambda v: round(v, 2))


@given(x=_arcsec, y=_arcsec)
@settings(max_examples=60, deadline=None)
def test_elcomat_parser_round_trip(x, y):
    rt = ReplayTransport([{"request": "a\r\n", "response": format_elcomat(x, y).decode()}])
    r = Elcomat("ac", rt, sleep=Sleeps(), retries=0).read()
    assert r["status"] == "ok" and r["x_arcsec"] == pytest.approx(x, abs=1e-9) and r["y_arcsec"] == pytest.approx(y, abs=1e-9)


@given(junk=st.binary(max_size=30))
@settings(max_examples=80, deadline=None)
def test_elcomat_garbage_never_parses_silently(junk):
    rt = ReplayTransport([{"request": "a\r\n", "response": junk.decode("latin-1")}])
    ac = Elcomat("ac", rt, sleep=Sleeps(), retries=0)
    try:
        r = ac.read()
    except InstrumentError:
        return
    # only a well-formed line can get through, and then its numbers are exactly the bytes sent
    assert junk.endswith(b"\r") and Elcomat.DEFAULT_COMMANDS["read_absolute"].compiled().fullmatch(junk)
    assert r["status"] == "ok" or r["status"].startswith("code_")


# --- TriAngle -------------------------------------------------------------------------------------
from benchtwin.hw.drivers.triangle import TriAngle, format_triangle  # noqa: E402


def test_triangle_replay_fields_no_signal_and_short_reply():
    rt = replay("triangle_basic.jsonl")
    ac = TriAngle("tri", rt, sleep=Sleeps(), clock=Clock())
    r = ac.read()
    assert (r["x_arcsec"], r["y_arcsec"], r["signal"], r["status"]) == (12.5, -3.25, 0.85, "ok")
    r = ac.read()
    assert r["status"] == "no_signal" and math.isnan(r["x_arcsec"]) and math.isnan(r["y_arcsec"])
    r = ac.read()  # two fields only: a format error, retried
    assert (r["x_arcsec"], r["y_arcsec"]) == (2.0, 1.0)
    rt.assert_done()


@given(fields=st.lists(st.floats(min_value=-5000, max_value=5000, allow_nan=False).map(lambda v: round(v, 3)),
                       min_size=4, max_size=6))
@settings(max_examples=60, deadline=None)
def test_triangle_parser_round_trip(fields):
    rt = ReplayTransport([{"request": "P 1\r\n", "response": format_triangle(fields).decode()}])
    r = TriAngle("tri", rt, sleep=Sleeps(), retries=0).read()
    if fields[3] <= 0.01:
        assert r["status"] == "no_signal"
    else:
        assert r["x_arcsec"] == pytest.approx(fields[1]) and r["y_arcsec"] == pytest.approx(fields[0])


@given(junk=st.binary(max_size=40))
@settings(max_examples=80, deadline=None)
def test_triangle_garbage_never_parses_silently(junk):
    rt = ReplayTransport([{"request": "P 1\r\n", "response": junk.decode("latin-1")}])
    try:
        r = TriAngle("tri", rt, sleep=Sleeps(), retries=0).read()
    except InstrumentError:
        return
    assert TriAngle.DEFAULT_COMMANDS["poll"].compiled().fullmatch(junk) and junk.count(b";") >= 3
    assert r["status"] in ("ok", "no_signal")


# --- TESA -----------------------------------------------------------------------------------------
from benchtwin.hw.drivers.tesa import TesaTT, format_tesa  # noqa: E402


def test_tesa_replay():
    rt = replay("tesa_basic.jsonl")
    sleeps = Sleeps()
    p = TesaTT("probe_top", rt, sleep=sleeps, clock=Clock())
    assert p.read()["value_um"] == 12.34
    assert p.read()["value_um"] == -3.5
    assert p.read()["value_um"] == 0.0 and len(sleeps) == 1  # timeout, retry
    r = p.read()
    assert r["status"] == "instrument_message" and r["message"] == "ERR23" and math.isnan(r["value_um"])
    rt.assert_done()
    assert TesaTT.serial_settings() == {"baudrate": 4800, "bytesize": 7, "parity": "E", "stopbits": 2, "timeout": 0.5}


@given(v=st.floats(min_value=-9999.99, max_value=9999.99, allow_nan=False).map(lambda v: round(v, 2)))
@settings(max_examples=60, deadline=None)
def test_tesa_parser_round_trip(v):
    rt = ReplayTransport([{"request": "?\r", "response": format_tesa(v).decode()}])
    assert TesaTT("p", rt, sleep=Sleeps(), retries=0).read()["value_um"] == pytest.approx(v, abs=1e-9)


@given(junk=st.binary(max_size=20))
@settings(max_examples=80, deadline=None)
def test_tesa_garbage_never_parses_silently(junk):
    rt = ReplayTransport([{"request": "?\r", "response": junk.decode("latin-1")}])
    try:
        r = TesaTT("p", rt, sleep=Sleeps(), retries=0).read()
    except InstrumentError:
        return
    assert TesaTT.DEFAULT_COMMANDS["read"].compiled().fullmatch(junk)
    assert r["status"] == "ok" or (r["status"] == "instrument_message" and math.isnan(r["value_um"]))


# --- Millimar -------------------------------------------------------------------------------------
from benchtwin.hw.drivers.millimar import MillimarC1202, format_millimar  # noqa: E402


def test_millimar_two_channels_share_a_port():
    rt = replay("millimar_two_channels.jsonl")
    ch = MillimarC1202.channels(rt, {1: "probe_top", 2: "probe_bottom"}, sleep=Sleeps(), clock=Clock())
    assert ch[1].transport is ch[2].transport
    assert ch[1].read()["value_um"] == 12.34
    r = ch[2].read()
    assert r["value_um"] == pytest.approx(-50.0) and r["tolerance"] == "above" and r["status"] == "ok"
    r = ch[1].read()
    assert r["status"] == "feature_off" and math.isnan(r["value_um"])
    r = ch[2].read()  # first reply is for channel 1: retried
    assert r["value_um"] == pytest.approx(100.0) and r["warning"] == "within"
    rt.assert_done()


def test_millimar_angle_unit_refused_without_retry():
    rt = ReplayTransport([{"request": "M1?\r", "response": "1 +001.50 deg\r"}])
    with pytest.raises(InstrumentError, match="not a length"):
        MillimarC1202("p", rt, sleep=Sleeps()).read()
    rt.assert_done()


@given(ch=st.integers(1, 3), v=st.floats(min_value=-999.99, max_value=999.99, allow_nan=False).map(lambda v: round(v, 2)),
       unit=st.sampled_from(["um", "mm", "inch"]), tol=st.sampled_from([None, "<", "=", ">"]))
@settings(max_examples=60, deadline=None)
def test_millimar_parser_round_trip(ch, v, unit, tol):
    rt = ReplayTransport([{"request": f"M{ch}?\r", "response": format_millimar(ch, v, unit, tol=tol).decode()}])
    r = MillimarC1202("p", rt, channel=ch, sleep=Sleeps(), retries=0).read()
    assert r["value_um"] == pytest.approx(v * {"um": 1, "mm": 1000, "inch": 25400}[unit], abs=1e-6)


@given(junk=st.binary(max_size=30))
@settings(max_examples=80, deadline=None)
def test_millimar_garbage_never_parses_silently(junk):
    rt = ReplayTransport([{"request": "M1?\r", "response": junk.decode("latin-1")}])
    try:
        r = MillimarC1202("p", rt, sleep=Sleeps(), retries=0).read()
    except InstrumentError:
        return
    assert MillimarC1202.DEFAULT_COMMANDS["read"].compiled().fullmatch(junk) and junk.startswith(b"1 ")
    assert r["status"] in ("ok", "feature_off") or r["status"].startswith("error_")


# --- Heidenhain -----------------------------------------------------------------------------------
from benchtwin.hw.drivers.heidenhain import HeidenhainND, format_heidenhain  # noqa: E402


def test_heidenhain_two_heads_and_error_text():
    rt = replay("heidenhain_two_heads.jsonl")
    enc = HeidenhainND("encoder", rt, heads_deg=[0.0, 180.0], decimals=4, sleep=Sleeps(), clock=Clock())
    r = enc.read()
    assert r["heads_deg"] == [0.0, 180.0] and r["angle_deg"] == pytest.approx([123.4567, -0.5])
    r = enc.read()  # "FORMAT ERROR" text: garbled, retried
    assert r["angle_deg"] == pytest.approx([360.0, 180.0])
    rt.assert_done()


def test_heidenhain_heads_must_start_at_zero():
    with pytest.raises(ValueError, match="starts with 0"):
        HeidenhainND("e", ReplayTransport([]), heads_deg=[90.0])


@given(counts=st.lists(st.integers(-999_999_999, 999_999_999), min_size=1, max_size=4), dec=st.integers(0, 6))
@settings(max_examples=60, deadline=None)
def test_heidenhain_parser_round_trip(counts, dec):
    heads = [0.0] + [90.0 * i for i in range(1, len(counts))]
    rt = ReplayTransport([{"request": "\x1bA0200\r", "response": format_heidenhain(counts).decode("latin-1")}])
    r = HeidenhainND("e", rt, heads_deg=heads, decimals=dec, sleep=Sleeps(), retries=0).read()
    assert r["angle_deg"] == pytest.approx([c / 10**dec for c in counts])


@given(junk=st.binary(max_size=30))
@settings(max_examples=80, deadline=None)
def test_heidenhain_garbage_never_parses_silently(junk):
    rt = ReplayTransport([{"request": "\x1bA0200\r", "response": junk.decode("latin-1")}])
    try:
        HeidenhainND("e", rt, sleep=Sleeps(), retries=0).read()
    except InstrumentError:
        return
    assert HeidenhainND.DEFAULT_COMMANDS["read"].compiled().fullmatch(junk)


# --- Zaber ----------------------------------------------------------------------------------------
from benchtwin.hw.drivers.zaber import ZaberReply, ZaberRotaryStage, format_zaber_reply  # noqa: E402
from benchtwin.hw.interfaces import SoftLimitError  # noqa: E402

STAGE = dict(microsteps_per_deg=1000.0, soft_limits_deg=(-10.0, 370.0), max_speed_deg_s=20.0)


def test_zaber_move_polls_through_injected_sleep():
    rt = replay("zaber_move.jsonl")
    clock = Clock(0.0)
    sleeps = []

    def sleep(s):
        sleeps.append(s)
        clock.sleep(s)

    st_ = ZaberRotaryStage("stage", rt, sleep=sleep, clock=clock, poll_interval_s=0.25, **STAGE)
    r = st_.move_to(90.0)
    assert r["target_deg"] == 90.0 and r["status"] == "ok" and r["duration_s"] == pytest.approx(0.5)
    assert sleeps == [0.25, 0.25]
    p = st_.position()
    assert p["angle_deg"] == 90.0 and p["status"] == "ok"
    rt.assert_done()


def test_zaber_message_ids_checksums_and_alerts():
    # zaber_ids_checksums.jsonl: ids after the axis, checksums both ways, a stale reply (wrong id),
    # an alert before a reply, a reply with a bad checksum; each handled without a wrong reading
    rt = replay("zaber_ids_checksums.jsonl")
    st_ = ZaberRotaryStage("stage", rt, sleep=Sleeps(), clock=Clock(), poll_interval_s=0.0, message_ids=True,
                           checksums=True, **STAGE)
    assert st_.move_to(90.0)["status"] == "ok"
    assert st_.position()["angle_deg"] == 90.0
    rt.assert_done()
    assert st_.describe()["message_ids"] and st_.describe()["checksums"]
    assert format_zaber_reply(ZaberReply(5, msg_id=3), checksum=True) == b"@01 1 03 OK IDLE -- 5:04\r\n"


def test_zaber_stale_reply_is_skipped_and_the_own_reply_taken():
    # the reply to the previous attempt (id 00, 5) came late; this attempt's own (id 01, 7) follows it
    rt = ReplayTransport([{"request": "/1 1 00 get pos\n", "response": ""},
                          {"request": "/1 1 01 get pos\n",
                           "response": "@01 1 00 OK IDLE -- 5\r\n@01 1 01 OK IDLE -- 7\r\n"}])
    st_ = ZaberRotaryStage("stage", rt, sleep=Sleeps(), retries=1, message_ids=True, **STAGE)
    assert st_._stage_deg() == 0.007
    rt.assert_done()


def test_zaber_reply_without_checksum_when_checksums_are_on_is_retried():
    rt = ReplayTransport([{"request": "/1 1 get pos:AC\n", "response": "@01 1 OK IDLE -- 5\r\n"}])
    st_ = ZaberRotaryStage("stage", rt, sleep=Sleeps(), retries=0, checksums=True, **STAGE)
    with pytest.raises(InstrumentError, match="without checksum"):
        st_._stage_deg()


def test_zaber_soft_limit_refused_before_anything_is_sent():
    rt = ReplayTransport([])
    st_ = ZaberRotaryStage("stage", rt, sleep=Sleeps(), **STAGE)
    for bad in (400.0, -10.5, float("nan")):
        with pytest.raises(SoftLimitError, match=r"stage: move to .* refused: outside the soft limits \[-10, 370\] deg"):
            st_.move_to(bad)
    assert rt.written == []
    rt.assert_done()


def test_zaber_speed_limit_refused():
    rt = ReplayTransport([{"request": "/1 1 get maxspeed\n", "response": "@01 1 OK IDLE -- 163840\r\n"}])
    st_ = ZaberRotaryStage("stage", rt, sleep=Sleeps(), **STAGE)  # 100 deg/s on the stage > 20 deg/s
    with pytest.raises(InstrumentError, match="speed limit"):
        st_.move_to(1.0)
    rt.assert_done()  # only the read of maxspeed went out, no move
    with pytest.raises(InstrumentError, match="speed limit"):
        ZaberRotaryStage("s", ReplayTransport([]), write_settings=True, settings={"maxspeed": 1e6}, **STAGE)


def test_zaber_settings_need_explicit_flag_and_dict():
    with pytest.raises(ValueError, match="write_settings is False"):
        ZaberRotaryStage("s", ReplayTransport([]), settings={"maxspeed": 100}, **STAGE)
    with pytest.raises(ValueError, match="explicit settings"):
        ZaberRotaryStage("s", ReplayTransport([]), write_settings=True, **STAGE)


def test_zaber_writes_settings_then_rejects_and_faults():
    rt = replay("zaber_settings.jsonl")
    st_ = ZaberRotaryStage("stage", rt, sleep=Sleeps(), write_settings=True, settings={"maxspeed": 8192}, **STAGE)
    assert st_.move_to(-5.0)["status"] == "ok"
    with pytest.raises(InstrumentError, match="rejected.*BADDATA") as exc:
        st_.move_to(5.0)
    assert exc.value.raw == b"@01 1 RJ IDLE -- BADDATA\r\n"
    with pytest.raises(InstrumentError, match="fault FS"):
        st_.position()
    rt.assert_done()


def test_zaber_closed_loop_on_encoder():
    rt = replay("zaber_closed_loop.jsonl")
    enc_rt = replay("heidenhain_closed_loop.jsonl")
    enc = HeidenhainND("encoder", enc_rt, decimals=4, sleep=Sleeps())
    st_ = ZaberRotaryStage("stage", rt, sleep=Sleeps(), clock=Clock(), encoder=enc, tolerance_deg=0.0005, **STAGE)
    r = st_.move_to(10.0)
    assert r["status"] == "ok" and r["corrections"] == 1 and abs(r["error_deg"]) <= 0.0005
    rt.assert_done()
    enc_rt.assert_done()


@given(data=st.integers(-10**9, 10**9), busy=st.booleans(), flag=st.sampled_from(["--", "WR", "NI"]))
@settings(max_examples=60, deadline=None)
def test_zaber_parser_round_trip(data, busy, flag):
    rt = ReplayTransport([{"request": "/1 1 get pos\n",
                           "response": format_zaber_reply(ZaberReply(data, busy=busy, flag=flag)).decode()}])
    st_ = ZaberRotaryStage("s", rt, sleep=Sleeps(), retries=0, **STAGE)
    assert st_.position()["angle_deg"] == pytest.approx(data / 1000.0)


@given(junk=st.binary(max_size=40))
@settings(max_examples=80, deadline=None)
def test_zaber_garbage_never_parses_silently(junk):
    rt = ReplayTransport([{"request": "/1 1 get pos\n", "response": junk.decode("latin-1")}])
    try:
        ZaberRotaryStage("s", rt, sleep=Sleeps(), retries=0, **STAGE).position()
    except InstrumentError:
        return
    assert ZaberRotaryStage.DEFAULT_COMMANDS["get_pos"].compiled().fullmatch(junk)


# --- a real pseudo-terminal through pyserial ------------------------------------------------------
import os  # noqa: E402
import select  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402

from benchtwin.hw.transport import open_transport  # noqa: E402


class PtyInstrument:
    """A tiny instrument on the master side of a pty: answers each request in ``replies``."""

    def __init__(self, replies: dict[bytes, bytes]) -> None:
        import tty

        self.master, self.slave = os.openpty()
        tty.setraw(self.master)
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.replies = replies
        self.seen: list[bytes] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        buf = b""
        deadline = time.monotonic() + 10.0  # bounded: never outlives a test
        while not self.stop.is_set() and time.monotonic() < deadline:
            r, _, _ = select.select([self.master], [], [], 0.05)
            if not r:
                continue
            try:
                buf += os.read(self.master, 256)
            except OSError:
                return
            for req, resp in self.replies.items():
                while req in buf:
                    before, _, buf = buf.partition(req)
                    self.seen.append(req)
                    os.write(self.master, resp)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(2.0)
        os.close(self.master)
        os.close(self.slave)


@pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")
def test_tesa_driver_over_a_real_pty():
    inst = PtyInstrument({b"?\r": b"-0012.34\r\n"})
    try:
        port = open_transport(inst.path, **TesaTT.serial_settings(timeout=2.0))
        try:
            probe = TesaTT("probe_top", port, sleep=Sleeps())
            assert probe.read()["value_um"] == -12.34
            assert probe.read()["value_um"] == -12.34
        finally:
            port.close()
    finally:
        inst.close()
    assert inst.seen == [b"?\r", b"?\r"]


@pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")
def test_elcomat_over_pty_times_out_then_fails_clearly():
    inst = PtyInstrument({})  # a silent instrument
    try:
        port = open_transport(inst.path, **Elcomat.serial_settings(timeout=0.05))
        try:
            sleeps = Sleeps()
            with pytest.raises(InstrumentError, match="timeout"):
                Elcomat("ac", port, sleep=sleeps, retries=1).read()
            assert sleeps == [0.05]
        finally:
            port.close()
    finally:
        inst.close()


def test_heidenhain_nak_fails_at_once():
    rt = ReplayTransport([{"request": "\x1bA0200\r", "response": "\x15"}])
    sleeps = Sleeps()
    with pytest.raises(InstrumentError, match="NAK") as exc:
        HeidenhainND("encoder", rt, sleep=sleeps).read()
    assert exc.value.raw == b"\x15" and sleeps == []
    rt.assert_done()


def test_zaber_busy_forever_times_out_on_the_injected_clock():
    rt = ReplayTransport([{"request": "/1 1 get maxspeed\n", "response": "@01 1 OK IDLE -- 1638\r\n"},
                          {"request": "/1 1 move abs 1000\n", "response": "@01 1 OK BUSY -- 0\r\n"}]
                         + [{"request": "/1 1\n", "response": "@01 1 OK BUSY -- 0\r\n"}] * 4)
    clock = Clock(0.0)
    st_ = ZaberRotaryStage("stage", rt, sleep=clock.sleep, clock=clock, poll_interval_s=1.0, move_timeout_s=3.5,
                           **STAGE)
    with pytest.raises(InstrumentError, match="still BUSY"):
        st_.move_to(1.0)
    rt.assert_done()


@pytest.mark.parametrize("make", [
    lambda rt: Elcomat("a", rt), lambda rt: TriAngle("t", rt), lambda rt: TesaTT("p", rt),
    lambda rt: MillimarC1202("m", rt), lambda rt: HeidenhainND("e", rt),
    lambda rt: ZaberRotaryStage("s", rt, **STAGE)])
def test_describe_never_talks_to_the_instrument(make):
    rt = ReplayTransport([])
    d = make(rt).describe()
    assert {"name", "kind", "model", "units"} <= set(d) and rt.written == []


@pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")
def test_recorded_pty_session_replays_as_a_regression_test(tmp_path):
    from benchtwin.hw.transport import RecordingTransport, reopener

    inst = PtyInstrument({b"M1?\r": b"1 +001.25 mm\r"})
    path = tmp_path / "session.jsonl"
    try:
        settings_ = MillimarC1202.serial_settings(timeout=2.0)
        rec = RecordingTransport(open_transport(inst.path, **settings_), path)
        probe = MillimarC1202("probe_top", rec, sleep=Sleeps(), reconnect=reopener(inst.path, recorder=rec, **settings_))
        assert probe.read()["value_um"] == 1250.0
        rec.close()
    finally:
        inst.close()
    rt = ReplayTransport(path)
    assert MillimarC1202("probe_top", rt, sleep=Sleeps()).read()["value_um"] == 1250.0
    rt.assert_done()
