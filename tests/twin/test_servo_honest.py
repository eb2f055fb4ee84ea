"""An honest servo (issue 33 item 5): a move either holds the commanded count (within the
controller's in-position window of ±1 count) or reports "not_held" with the count it held; the
runner keeps such a stop, the tables carry the encoder's reading there (``theta_read_deg``) and
the analysis refers the polygon's readings to the commanded stop with it.

The slow drive of the issue (``bandwidth = 50 Hz``, ``servo_rate = 2000 Hz``) on a short
jia2019 procedure (one radial revolution of 24 stops, 8 polygon faces): most of its stops end
~57 counts from their target, which the default drive never does."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from benchtwin.analysis.dataset import Dataset
from benchtwin.analysis.pipeline import polygon_table
from benchtwin.hw.acquisition.procedures import Move, Read
from benchtwin.hw.acquisition.runner import Runner, RunnerError, SimClock
from benchtwin.hw.interfaces import MOVE_NOT_HELD
from benchtwin.twin.instruments.drive import Rest
from benchtwin.twin.scenario import load_scenario
from benchtwin.twin.simulate import sim_build, simulate
from benchtwin.units import ARCSEC

ROOT = Path(__file__).resolve().parents[2]
RES_ARCSEC = 0.39      # jia2019's count

SHORT = {
    "procedure.radial_reps": 1,
    "procedure.radial_positions": 24,
    "procedure.ccd_step": "90 deg",
    "procedure.polygon_shifts": ["0 deg"],
    "procedure.directions": ["forward"],
    "bench.polygon_faces": 8,
    # the frames of tests/support/resume.py's small bench (256×192 px, was 128×96): with them the default
    # drive's bench is that one outside [procedure], and reads its α grid from the run's memo
    # (twin/alpha_grid_memo.py) instead of computing one (≈ 2 s of CPU, issue 35); no test here reads a frame
    "instruments.ccd.width": "256 px",
    "instruments.ccd.height": "192 px",
}
SLOW_DRIVE = {"drive.bandwidth": "50 Hz", "drive.servo_rate": "2000 Hz"}


def short_scenario(**extra):
    return load_scenario(ROOT / "scenarios" / "jia2019.toml").with_overrides({**SHORT, **extra})


@pytest.fixture(scope="module")
def slow_ds(tmp_path_factory) -> Path:
    return simulate(short_scenario(**SLOW_DRIVE), tmp_path_factory.mktemp("slow") / "ds", progress=False,
                    backend="analytic")


@pytest.fixture(scope="module")
def default_ds(tmp_path_factory) -> Path:
    return simulate(short_scenario(), tmp_path_factory.mktemp("default") / "ds", progress=False,
                    backend="analytic")


def _csv(p: Path) -> list[dict[str, str]]:
    with p.open() as f:
        return list(csv.DictReader(f))


def _moves_before_reads(ds: Path) -> dict[int, dict]:
    """Journal: read step index -> the result of the last move before it."""
    out, last = {}, None
    for line in (ds / "journal.jsonl").read_text().splitlines():
        rec = json.loads(line)
        if "result" in rec:
            last = rec["result"]
        elif "row" in rec and rec["row"]["type"] == "read":
            out[rec["i"]] = last
    return out


def test_no_stop_off_its_count_reports_ok(slow_ds):
    """Every stop more than 1.5 counts from its target (the count the servo held, from truth/)
    reports "not_held" with that count; "ok" stops are within 1.5 counts."""
    move_of = _moves_before_reads(slow_ds)
    journal_reads = [json.loads(x)["row"] for x in (slow_ds / "journal.jsonl").read_text().splitlines()
                     if '"row"' in x]
    reads = [r for r in journal_reads if r["type"] == "read" and r["tag"].get("procedure") in ("radial_motion",
                                                                                                  "polygon")]
    truth = (_csv(slow_ds / "truth" / "radial_motion.csv") + _csv(slow_ds / "truth" / "polygon.csv"))
    assert len(reads) == len(truth) == 24 + 64
    order = {"radial_motion": 0, "polygon": 1}
    reads.sort(key=lambda r: (order[r["tag"]["procedure"]], r["i"]))
    off, n_ok = 0, 0
    for r, t in zip(reads, truth):
        res = move_of[r["i"]]
        assert res["target_deg"] == float(t["target_deg"])
        held_deg = float(t["theta_deg"])
        counts = abs(held_deg - float(t["target_deg"])) * 3600.0 / RES_ARCSEC
        if counts > 1.5:
            off += 1
            assert res["status"] == MOVE_NOT_HELD, (r["i"], counts, res)
            assert res["held_deg"] == pytest.approx(held_deg, abs=1e-12)
        if res["status"] == "ok":
            n_ok += 1
            assert counts <= 1.5 + 1e-9 and "held_deg" not in res
    # the slow drive leaves most stops tens of counts off (the issue: up to 58 counts)
    assert off >= len(reads) // 3
    assert n_ok >= 1


def test_the_tables_carry_the_held_reading(slow_ds):
    """theta_read_deg is the encoder's reading at the stop: the count the servo held (its display
    flips to the next count where the rest lies within the encoder's noise, 0.05″, of a cell edge)."""
    for table in ("radial_motion", "polygon"):
        rows = _csv(slow_ds / f"{table}.csv")
        truth = _csv(slow_ds / "truth" / f"{table}.csv")
        read = np.array([float(r["theta_read_deg"]) for r in rows])
        held = np.array([float(t["theta_deg"]) for t in truth])
        cmd = np.array([float(r["theta_deg"]) for r in rows])
        counts = np.abs(read - held) * 3600.0 / RES_ARCSEC
        assert np.all(counts < 1.0 + 1e-6)
        assert np.mean(counts < 1e-6) >= 0.8
        assert np.max(np.abs(read - cmd)) * 3600 > 10 * RES_ARCSEC      # and it differs from the command


def test_the_analysis_refers_the_polygon_readings_to_the_commanded_stop(slow_ds, default_ds):
    """The polygon's readings with the held reading (analysis.pipeline.polygon_table: ε + q, q = θ_read − θ)
    agree with those of the default drive, whose stops hold, at every reading (the same procedure,
    clock and noise; what differs is where in its count each stop rests and the friction's twist:
    < 1″); the raw readings differ by the counts the slow drive missed (≈ 22″)."""
    a, b = Dataset(slow_ds), Dataset(default_ds)
    ca, cb = (np.asarray(polygon_table(d)["ac_arcsec"], dtype=float) for d in (a, b))
    ra, rb = (np.asarray(d.table("polygon")["ac_arcsec"], dtype=float) for d in (a, b))
    assert np.max(np.abs(ca - cb)) < 1.0
    assert np.max(np.abs(ra - rb)) > 10.0


def test_default_drive_holds_every_stop(default_ds):
    move_of = _moves_before_reads(default_ds)
    assert {m["status"] for m in move_of.values()} == {"ok"}


class _FixedRest:
    """A servo that always rests ``held`` counts from the command (to test the stage's report)."""

    def __init__(self, servo, held: int):
        self.p, self.held = servo.p, int(held)

    def settle_keyed(self, key) -> Rest:
        return Rest(offset_rad=self.held * self.p.resolution_rad, held_count=self.held, friction_torque_Nm=0.0,
                    settle_s=self.p.max_settle_s, steps=0, settled=False)


@pytest.mark.parametrize("held, status", [(0, "ok"), (1, "ok"), (-1, "ok"), (2, MOVE_NOT_HELD),
                                          (-3, MOVE_NOT_HELD)])
def test_stage_reports_the_count_it_holds(held, status):
    sc = short_scenario(**{"bearings.type": "path"})
    _bench, state, inst = sim_build(sc, camera=False)
    stage = inst["stage"]
    stage.servo = _FixedRest(stage.servo, held)
    res = stage.move_to(1.0)
    assert res["status"] == status
    n_cmd = round(math.radians(1.0) / stage.servo.p.resolution_rad)
    held_deg = math.degrees((n_cmd + held) * stage.servo.p.resolution_rad)
    assert stage.held_deg == held_deg
    if status == "ok":
        assert "held_deg" not in res
    else:
        assert res["held_deg"] == held_deg
        # the continuous reading rests in the held count's cell
        assert abs(inst["encoder"].read()["angle_deg"][0] - held_deg) * 3600 < 1e-6 * RES_ARCSEC + 1e-9
    # a re-issued move to the stop it stands at moves nothing and reports the same
    again = stage.move_to(1.0)
    assert again["status"] == status and again["duration_s"] == 0.0
    assert again.get("held_deg") == res.get("held_deg")


class _Stage:
    kind = "stage"

    def __init__(self, clock, status):
        self.clock, self.status, self.name = clock, status, "stage"

    def describe(self):
        return {"name": "stage", "kind": "stage", "model": "test", "units": {}}

    def move_to(self, target_deg):
        out = {"target_deg": target_deg, "t_s": self.clock.now(), "duration_s": 0.0, "status": self.status}
        if self.status == MOVE_NOT_HELD:
            out["held_deg"] = target_deg + 1e-3
        return out


class _Probe:
    kind = "probe"

    def __init__(self, clock):
        self.clock, self.name = clock, "probe"

    def read(self):
        return {"value_um": 0.0, "t_s": self.clock.now(), "status": "ok"}


def test_runner_keeps_a_stop_held_elsewhere_and_stops_on_other_statuses(tmp_path):
    clock = SimClock()
    steps = [Move(1.0), Read("probe"), Move(2.0), Read("probe")]
    run = Runner({"stage": _Stage(clock, MOVE_NOT_HELD), "probe": _Probe(clock)}, clock, journal=tmp_path / "j.jsonl")
    assert len(run.run(steps)) == 2
    results = [json.loads(x)["result"] for x in (tmp_path / "j.jsonl").read_text().splitlines() if '"result"' in x]
    assert [r["status"] for r in results] == [MOVE_NOT_HELD] * 2 and results[0]["held_deg"] == 1.0 + 1e-3
    clock = SimClock()
    with pytest.raises(RunnerError, match="not_settled"):
        Runner({"stage": _Stage(clock, "not_settled"), "probe": _Probe(clock)}, clock).run(steps)
    # "not_held" without the count held is not a report: the run stops
    st = _Stage(clock, MOVE_NOT_HELD)
    st.move_to = lambda target_deg: {"target_deg": target_deg, "t_s": 0.0, "duration_s": 0.0,  # type: ignore
                                     "status": MOVE_NOT_HELD}
    with pytest.raises(RunnerError, match="not_held"):
        Runner({"stage": st, "probe": _Probe(clock)}, clock).run(steps)


def test_resolution_constant_is_jias():
    sc = short_scenario()
    assert float(sc["bench"]["encoder_resolution"]) / ARCSEC == pytest.approx(RES_ARCSEC)
