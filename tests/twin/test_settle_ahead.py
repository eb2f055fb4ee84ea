"""The servo's settles computed ahead by a forked worker (twin/instruments/settle_ahead.py, issue #17):
the plan holds every settle the run makes, and the dataset is the same bytes whoever settled."""

from __future__ import annotations

import math
import os
import signal
import time

import pytest

from benchtwin.twin import simulate as S
from benchtwin.twin.instruments import settle_ahead as SA
from benchtwin.twin.instruments.drive import DriveServo

from tests.support.scenarios import files, small_scenario

# xdist: one at a time on one worker (a forked worker waited for on a deadline; tests/conftest.py)
pytestmark = pytest.mark.xdist_group("serial")

needs_fork = pytest.mark.skipif(not hasattr(os, "fork"), reason="the worker is a forked process (POSIX fork)")


def _small():
    return small_scenario(**{"procedure.polygon_shifts": ["0 deg"], "procedure.directions": ["forward"]})


@needs_fork
def test_the_dataset_is_the_same_bytes_with_the_worker_as_without(tmp_path, monkeypatch):
    sc = _small()
    monkeypatch.setenv("BENCHTWIN_FORK", "0")          # no worker: every settle in the run
    ref = S.simulate(sc, tmp_path / "ref", progress=False, backend="analytic")
    monkeypatch.delenv("BENCHTWIN_FORK")
    monkeypatch.setattr(SA, "usable_cores", lambda: 2)   # the worker even on a one-core machine
    seen: list[SA.SettleAhead] = []
    start = SA.SettleAhead.start.__func__

    def spy(cls, stage, steps):
        a = start(cls, stage, steps)
        seen.append(a)
        return a

    monkeypatch.setattr(SA.SettleAhead, "start", classmethod(spy))
    ds = S.simulate(sc, tmp_path / "ds", progress=False, backend="analytic")
    assert files(ds) == files(ref)
    (ahead,) = seen
    assert ahead is not None and ahead.off_plan == 0        # the plan held every settle of the run
    assert ahead.from_worker > 0                            # and the worker computed some of them


def _stage_and_steps():
    sc = _small()
    bench, state, inst = S.sim_build(sc, backend="analytic", camera=False)
    return inst["stage"], S.sim_procedure(sc)


def _servo_and_plan():
    stage, steps = _stage_and_steps()
    return stage.servo, SA.settle_plan(steps, stage)


def test_the_plan_follows_the_clock_and_the_step_index():
    _, plan = _servo_and_plan()
    assert len(plan) > 10
    t_ends = [k[3] for k in plan]
    steps = [k[4][3] for k in plan]                      # (seed, stream, instrument, step + 1, draw)
    assert t_ends == sorted(t_ends) and len(set(steps)) == len(steps)
    assert all(k[4][4] == 0 for k in plan)              # one draw of the servo's stream per move
    # a move to the target the servo holds settles nothing (the first, from the start, does)
    assert all(math.isfinite(k[0]) for k in plan) and all(k[0] != 0.0 for k in plan[1:])


@needs_fork
def test_keys_off_the_plan_and_a_killed_worker_leave_the_settles_to_the_run(monkeypatch):
    servo, plan = _servo_and_plan()
    plan = plan[:4]
    own = DriveServo(servo.p)                            # the reference: a servo nobody shares
    want = [own.settle_keyed(k) for k in plan]
    run, real = os.getpid(), servo.settle_keyed

    def stuck_in_the_worker(key):
        if os.getpid() != run:
            time.sleep(60)
        return real(key)

    servo.settle_keyed = stuck_in_the_worker
    with SA.SettleAhead(servo, plan) as ahead:          # the worker, whatever the machine
        assert ahead is not None
        t0 = time.monotonic()
        while ahead._next.value == 0 and time.monotonic() - t0 < 30:   # the worker claims the first
            time.sleep(0.01)
        off = (plan[1][0] * 0.5, *plan[1][1:])
        assert ahead.rest(off) == own.settle_keyed(off) and ahead.off_plan == 1
        os.kill(ahead._pid, signal.SIGKILL)               # the worker dies holding settle 0
        assert ahead.rest(plan[0]) == want[0]            # settled here: the worker is gone
        assert [ahead.rest(k) for k in plan[2:]] == want[2:]
        assert ahead.rest(plan[1]) == want[1] and ahead.off_plan == 2   # passed over: settled here
        assert ahead.from_worker == 0


def test_no_worker_where_it_cannot_help(monkeypatch):
    stage, steps = _stage_and_steps()
    monkeypatch.setattr(SA, "usable_cores", lambda: 1)
    assert SA.SettleAhead.start(stage, steps) is None
    monkeypatch.setattr(SA, "usable_cores", lambda: 2)
    monkeypatch.setattr(SA, "in_pool_worker", lambda: True)   # a study pool's worker
    assert SA.SettleAhead.start(stage, steps) is None
    monkeypatch.undo()
    monkeypatch.setattr(SA, "usable_cores", lambda: 2)
    monkeypatch.setenv("BENCHTWIN_FORK", "0")
    assert SA.SettleAhead.start(stage, steps) is None
    stage.servo = None                                    # an ideal positioner settles nothing
    assert SA.settle_plan(steps, stage) == []
