"""Serial drivers replayed from hand-written transcripts (tests/hw/transcripts/*.jsonl, written from
docs/protocols/*.md), fault handling, parser properties, and one driver over a real pseudo-terminal."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchtwin.hw.drivers.base import Command, CommandTable, InstrumentError, SerialInstrument, to_bytes
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
