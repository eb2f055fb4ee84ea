"""Procedures as step generators (dry runs, counts, durations) and the journaled runner (resume).
No twin here: fake instruments that are deterministic functions of position and time."""

from __future__ import annotations

import json
import math

import pytest

from benchtwin.hw.acquisition.procedures import (Capture, Mark, Move, PolygonSetup, Read, Wait, ccd_sweep,
                                                 count_steps, estimate_duration, move_time_s, polygon_shift_angle,
                                                 polygon_traditional, radial_motion_run, selfcal_sweep)
from benchtwin.hw.acquisition.runner import Runner, RunnerError, SimClock, WallClock, dry_run, read_journal


# --------------------------------------------------------------------------- dry runs

def test_shift_angle_reading_counts():
    assert count_steps(polygon_shift_angle(PolygonSetup(24), [0.0]))["read"] == 576
    assert count_steps(polygon_shift_angle(PolygonSetup(23), [0.0]))["read"] == 529
    # further shifts: start face 1 only (Hsieh sec. 3), both directions double everything
    assert count_steps(polygon_shift_angle(PolygonSetup(24), [0.0, 5.0, 10.0]))["read"] == 576 + 2 * 24
    assert count_steps(polygon_shift_angle(PolygonSetup(24, ("forward", "backward")), [0.0, 5.0]))["read"] == \
        2 * (576 + 24)
    assert count_steps(polygon_shift_angle(PolygonSetup(24), [0.0, 5.0], all_faces_each_shift=True, reps=2))["read"] == 2 * 2 * 576
    assert count_steps(polygon_traditional(PolygonSetup(24)))["read"] == 24
    assert count_steps(radial_motion_run(3, 360))["read"] == 1080
    c = count_steps(ccd_sweep(6.0))
    assert c["capture"] == 60 and c["read"] == 60
    assert count_steps(selfcal_sweep([0, 120, 240], 1.0))["read"] == 720


def test_polygon_steps_follow_hsieh_eq3_indexing():
    steps = list(polygon_shift_angle(PolygonSetup(24), [0.0, 5.0]))
    reads = [s for s in steps if isinstance(s, Read)]
    moves = [s for s in steps if isinstance(s, Move)]
    assert reads[0].tag == {"shift_deg": 0.0, "start_face": 1, "step": 1, "target_deg": 0.0}
    assert reads[0].names == ("encoder", "autocollimator")
    assert [r.tag["step"] for r in reads[:24]] == list(range(1, 25))
    assert moves[3].target_deg == pytest.approx(45.0)
    assert {r.tag["start_face"] for r in reads[:576]} == set(range(1, 25))
    assert [r.tag["target_deg"] for r in reads[576:579]] == pytest.approx([5.0, 20.0, 35.0])
    assert {r.tag["start_face"] for r in reads[576:]} == {1}
    clamps = [s for s in steps if isinstance(s, Mark) and "polygon_start_face" in s.context]
    assert len(clamps) == 25 and clamps[1].context["polygon_start_face"] == 2
    # backward: same mounting, steps N…1
    back = [s for s in polygon_traditional(PolygonSetup(8, ("forward", "backward")), 3) if isinstance(s, Read)]
    assert [r.tag["step"] for r in back] == [1, 2, 3, 4, 5, 6, 7, 8, 8, 7, 6, 5, 4, 3, 2, 1]


def test_dry_run_is_json_and_needs_no_instrument():
    d = dry_run(ccd_sweep(60.0))
    json.dumps(d)
    assert [x["type"] for x in d[:5]] == ["mark", "move", "wait", "read", "capture"]
    assert d[-1] == {"type": "capture", "camera": "ccd", "tag": {"k": 5, "target_deg": 300.0}}


def test_duration_estimate():
    assert move_time_s(0, 20, 40) == 0
    assert move_time_s(30, 20, 40) == pytest.approx(30 / 20 + 20 / 40)
    assert move_time_s(5, 20, 40) == pytest.approx(2 * math.sqrt(5 / 40))
    proc = [Move(10.0), Wait(0.5), Read("probe"), Move(0.0), Wait(1.0)]
    t = estimate_duration(proc, speed_deg_s=20, accel_deg_s2=40, read_s=0.1)
    assert t == pytest.approx(2 * (10 / 20 + 0.5) + 1.5 + 0.1)
    # the standard Jia radial run: 3 × 360 stops of 1° (triangular moves) + 0.5 s dwell + returns
    t = estimate_duration(radial_motion_run(3, 360))
    assert t == pytest.approx(3 * 359 * 2 * math.sqrt(1 / 40) + 1080 * 0.5 + 2 * (359 / 20 + 0.5), rel=1e-12)


def test_procedures_reject_bad_arguments():
    with pytest.raises(ValueError):
        list(ccd_sweep(7.0))
    with pytest.raises(ValueError):
        list(polygon_traditional(PolygonSetup(12), 13))
    with pytest.raises(ValueError):
        list(polygon_traditional(PolygonSetup(12, ("sideways",)), 1))


# --------------------------------------------------------------------------- runner

class FakeStage:
    name = "stage"

    def __init__(self, clock):
        self.clock, self.pos = clock, 0.0

    def describe(self):
        return {"name": self.name, "kind": "stage", "model": "fake", "units": {}}

    def move_to(self, target_deg):
        dt = move_time_s(target_deg - self.pos, 20.0, 40.0)
        self.clock.advance(dt)
        self.pos = target_deg
        return {"target_deg": target_deg, "t_s": self.clock.now(), "duration_s": dt, "status": "ok"}

    def position(self):
        return {"angle_deg": self.pos, "t_s": self.clock.now(), "status": "ok"}


class FakeProbe:
    """value = f(stage position, time); raises after ``fail_after`` reads (an interrupted run)."""

    def __init__(self, name, stage, clock, fail_after=None):
        self.name, self.stage, self.clock, self.fail_after, self.n = name, stage, clock, fail_after, 0

    def describe(self):
        return {"name": self.name, "kind": "probe", "model": "fake", "units": {"value_um": "um"}}

    def read(self):
        self.n += 1
        if self.fail_after is not None and self.n > self.fail_after:
            raise KeyboardInterrupt("operator stopped the run")
        v = math.sin(math.radians(self.stage.pos)) + 1e-3 * self.clock.now()
        return {"value_um": v, "t_s": self.clock.now(), "status": "ok"}


class FakeAC(FakeProbe):
    def read(self):
        r = super().read()
        return {"x_arcsec": r["value_um"], "y_arcsec": 0.0, "t_s": r["t_s"], "status": "ok"}


def _bench(fail_after=None):
    clock = SimClock()
    stage = FakeStage(clock)
    inst = {"stage": stage, "encoder": FakeProbe("encoder", stage, clock),
            "autocollimator": FakeAC("autocollimator", stage, clock, fail_after)}
    return clock, inst


def test_runner_rows_context_and_clock():
    clock, inst = _bench()
    marks = []
    rows = Runner(inst, clock, on_step=lambda i, s, c, replay: marks.append(c) if isinstance(s, Mark) else None).run(
        polygon_traditional(PolygonSetup(6, ("forward", "backward"), dwell_s=1.0), 2, 10.0))
    assert len(rows) == 12
    r0 = rows[0]
    assert r0["tag"]["polygon_start_face"] == 2 and r0["tag"]["direction"] == "forward"
    assert r0["tag"]["step"] == 1 and r0["tag"]["procedure"] == "polygon"
    assert set(r0["readings"]) == {"encoder", "autocollimator"}
    assert rows[6]["tag"]["direction"] == "backward" and rows[6]["tag"]["step"] == 6
    assert rows[-1]["t_s"] > rows[0]["t_s"]
    assert rows[0]["t_s"] == pytest.approx(move_time_s(10.0, 20, 40) + 1.0)
    assert marks[-1]["direction"] == "backward"


def test_runner_failed_status_raises():
    clock, inst = _bench()

    class Bad(FakeProbe):
        def read(self):
            return {"value_um": float("nan"), "t_s": 0.0, "status": "out_of_range"}

    inst["encoder"] = Bad("encoder", inst["stage"], clock)
    with pytest.raises(RunnerError, match="out_of_range"):
        Runner(inst, clock).run(polygon_traditional(PolygonSetup(4)))
    with pytest.raises(RunnerError, match="needs instrument"):
        Runner({"stage": inst["stage"]}, clock).run(polygon_traditional(PolygonSetup(4)))


@pytest.mark.parametrize("n", [1, 7, 23])
def test_journal_resume_gives_identical_rows(tmp_path, n):
    proc = lambda: polygon_shift_angle(PolygonSetup(6, ("forward", "backward"), dwell_s=0.5), [0.0, 3.0])
    clock, inst = _bench()
    full = Runner(inst, clock, journal=tmp_path / "full.jsonl").run(proc())

    clock, inst = _bench(fail_after=n)
    j = tmp_path / "run.jsonl"
    with pytest.raises(KeyboardInterrupt):
        Runner(inst, clock, journal=j).run(proc())
    assert sum(1 for r in read_journal(j) if "row" in r) == n
    clock, inst = _bench()  # a fresh process: new instruments, clock at 0, stage at 0
    rows = Runner(inst, clock, journal=j).run(proc(), resume=True)
    assert rows == full
    assert j.read_text() == (tmp_path / "full.jsonl").read_text()


def test_journal_resume_checks_the_procedure_and_tolerates_a_torn_line(tmp_path):
    j = tmp_path / "run.jsonl"
    clock, inst = _bench(fail_after=3)
    with pytest.raises(KeyboardInterrupt):
        Runner(inst, clock, journal=j).run(polygon_traditional(PolygonSetup(6)))
    with j.open("a") as f:
        f.write('{"i": 99, "step": {"ty')  # crash in the middle of a line
    clock, inst = _bench()
    rows = Runner(inst, clock, journal=j).run(polygon_traditional(PolygonSetup(6)), resume=True)
    assert len(rows) == 6
    clock, inst = _bench()
    with pytest.raises(RunnerError, match="not the same procedure"):
        Runner(inst, clock, journal=j).run(polygon_traditional(PolygonSetup(6), start_face=2), resume=True)


def test_no_resume_keeps_the_journal_and_restart_starts_a_new_one(tmp_path):
    j = tmp_path / "run.jsonl"
    clock, inst = _bench()
    Runner(inst, clock, journal=j).run(polygon_traditional(PolygonSetup(4)))
    before = j.read_bytes()
    clock, inst = _bench()
    with pytest.raises(RunnerError, match="resume it, or restart"):
        Runner(inst, clock, journal=j).run(polygon_traditional(PolygonSetup(4)))
    assert j.read_bytes() == before  # issue #13: a run without --resume deleted the readings taken
    clock, inst = _bench()
    Runner(inst, clock, journal=j).run(polygon_traditional(PolygonSetup(4)), restart=True)
    recs = read_journal(j)
    assert recs[0]["journal"] == "benchtwin-run" and sum("row" in r for r in recs) == 4


def test_clocks():
    c = SimClock()
    c.advance(2.5)
    assert c.now() == 2.5
    with pytest.raises(ValueError):
        c.advance(-1)
    w = WallClock()
    w.set(100.0)
    assert 100.0 <= w.now() < 101.0
    t = w.advance(0.01)
    assert t >= 100.01


def test_capture_rows_keep_the_image_out_of_the_journal(tmp_path):
    import numpy as np

    class Cam:
        name = "ccd"

        def describe(self):
            return {"name": "ccd", "kind": "camera", "model": "fake", "units": {}}

        def capture(self):
            return {"image": np.zeros((4, 6), np.uint8), "t_s": 0.0, "status": "ok", "truth": {"c": 1}}

    clock, inst = _bench()
    inst["ccd"] = Cam()
    got = []
    rows = Runner(inst, clock, journal=tmp_path / "j.jsonl", on_row=lambda r, res: got.append(res)).run(
        [Move(0.0), Capture("ccd", {"k": 0})])
    assert rows[0]["reading"]["image_shape"] == [4, 6] and "image" not in rows[0]["reading"]
    assert got[0]["image"].shape == (4, 6)
    assert "\"image\":" not in (tmp_path / "j.jsonl").read_text()


# --------------------------------------------------------------------------- streaming (flat memory)

def test_stream_hands_every_row_to_the_sink_and_keeps_none(tmp_path):
    proc = lambda: polygon_shift_angle(PolygonSetup(5, ("forward", "backward"), dwell_s=0.1), [0.0, 2.0])
    clock, inst = _bench()
    rows = Runner(inst, clock).run(proc())
    clock, inst = _bench()
    got = []
    n = Runner(inst, clock, journal=tmp_path / "j.jsonl").stream(proc(), lambda r, live: got.append((r, live)))
    assert n == len(rows) == len(got) == 5 * 5 * 2 + 5 * 2
    assert [r for r, _ in got] == rows
    assert all(live is not None and set(live) == {"encoder", "autocollimator"} for _, live in got)
    # resumed: the journaled rows come back through the sink (live result None), in order
    clock, inst = _bench(fail_after=17)
    with pytest.raises(KeyboardInterrupt):
        Runner(inst, clock, journal=tmp_path / "k.jsonl").stream(proc(), lambda r, live: None)
    clock, inst = _bench()
    got = []
    Runner(inst, clock, journal=tmp_path / "k.jsonl").stream(proc(), lambda r, live: got.append((r, live)), resume=True)
    assert [r for r, _ in got] == rows
    assert [live is None for _, live in got] == [True] * 17 + [False] * (len(rows) - 17)


def test_stream_memory_is_flat_in_the_number_of_readings(tmp_path):
    """6 000 readings through the journaled runner: traced memory between the 1 000th and the
    6 000th reading grows by less than 256 KiB (keeping the rows, as ``run`` does, takes ~4 MiB)."""
    import tracemalloc

    clock, inst = _bench()
    marks = {}

    def sink(row, live):
        k = row["tag"]["k"] + 1
        if k in (1000, 6000):
            marks[k] = tracemalloc.get_traced_memory()[0]

    tracemalloc.start()
    try:
        n = Runner(inst, clock, journal=tmp_path / "j.jsonl", fsync=False).stream(
            radial_motion_run(1, 6000, 0.0, probes=("autocollimator",)), sink)
    finally:
        tracemalloc.stop()
    assert n == 6000
    assert marks[6000] - marks[1000] < 2**18, marks


def test_torn_tail_that_parses_is_still_re_executed(tmp_path):
    """A crash between the JSON and its newline: the line parses but is incomplete; the step is
    run again and the journal ends identical to an uninterrupted one's."""
    proc = lambda: polygon_traditional(PolygonSetup(6))
    clock, inst = _bench()
    Runner(inst, clock, journal=tmp_path / "full.jsonl").run(proc())
    full = (tmp_path / "full.jsonl").read_text()
    lines = full.splitlines(keepends=True)
    j = tmp_path / "run.jsonl"
    j.write_text("".join(lines[:9]) + lines[9].rstrip("\n"))
    assert json.loads(lines[9])  # the torn line is valid JSON
    clock, inst = _bench()
    rows = Runner(inst, clock, journal=j).run(proc(), resume=True)
    assert len(rows) == 6 and j.read_text() == full


def test_repeated_ccd_sweeps_number_frames_on_and_carry_the_sweep():
    one = list(ccd_sweep(60.0))
    assert all("sweep" not in s.tag for s in one if isinstance(s, (Read, Capture)))   # one sweep: as before
    three = list(ccd_sweep(60.0, reps=3))
    caps = [s for s in three if isinstance(s, Capture)]
    assert [c.tag["k"] for c in caps] == list(range(18))
    assert [c.tag["sweep"] for c in caps] == [0] * 6 + [1] * 6 + [2] * 6
    assert [c.tag["target_deg"] for c in caps[6:12]] == [c.tag["target_deg"] for c in caps[:6]]
    assert sum(isinstance(s, Mark) for s in three) == 3
    with pytest.raises(ValueError, match="reps"):
        list(ccd_sweep(60.0, reps=0))
