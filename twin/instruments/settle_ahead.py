"""The drive servo's settles computed ahead, on the other core (issue #17).

Why it is exact, not an approximation: a settle (``DriveServo.settle_keyed``, drive.py) is a pure
function of its move: the signed distance, the profile's speed and acceleration, and its
amplifier-noise stream, keyed by step (``SimBenchState.rng_key``), from whose key the sample
clock's phase is drawn too (stream ``servo_clock``, drive.py); the bench time its profile stops is
in the key to match the move, no longer an input. It starts from a freshly reset ``MjData``. And the bench clock never depends on how the servo settled
(``SimRotaryStage.move_duration_s``: a move takes its profile plus the controller's fixed
in-position wait); only the procedure's moves and waits advance it (``hw.acquisition.runner``). So
every settle of a procedure is known from its list of steps before it runs (``settle_plan``).
A forked worker computes them in the procedure's order while the run poses the bench and takes
its readings: the servo is about 60 % of the run's steps (docs/benchmarks.md).

Sharing the work: the worker and the run claim the plan's settles in order from one shared counter.
The run, needing settle i, takes the worker's result if the worker has claimed i (waiting at most
for that one settle), and otherwise claims i and computes it itself, so a slow worker costs nothing
but its share. While the run waits, its core serves the frame workers and the truth (niced).
(Settling the next unclaimed stops itself while it waits gained nothing: the cores are saturated,
docs/benchmarks.md.) The run uses a result only when its key, every input of the settle bit for
bit, is in the plan. A move off the plan is settled in the run: a resumed run's re-issued
move, or a procedure that is not the planned one. The worker is a fork of the run's servo (same
model, same MuJoCo build, same code), so its rests are the bytes the run would compute
(tests/twin/test_settle_ahead.py: a dataset with and without it). If the worker dies or fails,
the run settles the rest itself (an error is then raised by the run's own settle, where it belongs).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Iterable
from typing import Any

from benchtwin.forkcall import die_with_parent, fork_enabled
from benchtwin.hw.acquisition import procedures as P
from benchtwin.hw.acquisition.runner import SimClock
from benchtwin.runtime import in_pool_worker, usable_cores

from .drive import DriveServo, Rest, SettleKey
from .stage import SimRotaryStage, sim_rng_key

#: the claim counter is held for a few instructions; this long means its holder died (killed)
LOCK_TIMEOUT_S = 5.0


def settle_plan(steps: Iterable[Any], stage: SimRotaryStage) -> list[SettleKey]:
    """The keys of the settles a run of ``steps`` (the runner's list: the step index keys the
    noise) makes on ``stage``, in order, from where the stage stands and its clock reads now.
    The moves and waits advance the clock as the runner and ``SimRotaryStage.move_to`` do; a
    move to the target the servo already holds moves nothing (``move_to``). Empty without a servo."""
    if stage.servo_resolution_rad() <= 0:
        return []
    clock = SimClock(stage.state.clock.now())
    at, target = stage.position_deg, stage.target_deg
    seed = stage.state.seed
    keys: list[SettleKey] = []
    for i, step in enumerate(steps):
        if isinstance(step, P.Wait):
            clock.advance(step.seconds)
        elif isinstance(step, P.Move):
            to = float(step.target_deg)
            if to == target:
                continue
            duration = stage.move_duration_s(to, at)
            # the move's one draw of the servo's stream, at step i (SimBenchState.rng_key)
            keys.append(stage.settle_key(to, at, clock.now() + duration, sim_rng_key(seed, "servo", 0, i + 1, 0)))
            clock.advance(duration)
            at = target = to
    return keys


class SettleAhead:
    """A forked worker computing ``plan``'s settles on ``servo`` (a copy of the run's, by fork);
    ``rest(key)`` is the settle of ``key`` (the worker's, or computed here). ``close()`` stops it."""

    @classmethod
    def start(cls, stage: SimRotaryStage, steps: list[Any]) -> "SettleAhead | None":
        """The worker for the settles of ``steps`` on ``stage`` (``settle_plan``), or None where
        it cannot help: one usable core, no fork (``BENCHTWIN_FORK=0``), a run inside a process
        pool's worker (a study's points: the pool already fills the cores, runtime.in_pool_worker),
        fewer than two settles. The plan is made only when a worker may start."""
        if not fork_enabled() or usable_cores() < 2 or in_pool_worker():
            return None
        plan = settle_plan(steps, stage)
        return cls(stage.servo, plan) if len(plan) >= 2 else None

    def __init__(self, servo: DriveServo, plan: list[SettleKey]):
        self.servo = servo
        self.plan = plan
        self.index = {k: i for i, k in enumerate(plan)}
        ctx = multiprocessing.get_context("fork")
        # the next settle nobody has claimed (its lock: a semaphore in shared memory)
        self._next = ctx.Value("q", 0)
        recv, send = ctx.Pipe(duplex=False)
        parent = os.getpid()
        pid = os.fork()
        if pid == 0:    # the worker: compute, send, leave without the run's exit handlers
            code = 0
            try:
                recv.close()
                die_with_parent(parent)
                self._work(send)
            except BaseException:  # noqa: BLE001 - the run settles what the worker did not send
                code = 1
            finally:
                os._exit(code)
        send.close()
        self._pid: int | None = pid
        self._conn: Any = recv
        self._last = -1
        self.from_worker = 0     # settles taken from the worker (the others were computed here)
        self.off_plan = 0        # settles asked for that the plan did not hold

    def _work(self, send: Any) -> None:
        n = len(self.plan)
        while True:
            with self._next.get_lock():
                i = self._next.value
                if i >= n:
                    return
                self._next.value = i + 1
            try:
                rest = self.servo.settle_keyed(self.plan[i])
            except Exception:  # noqa: BLE001 - the run computes it again and raises it there
                send.send((i, None))
                return
            send.send((i, rest))

    def rest(self, key: SettleKey) -> Rest:
        """The settle of ``key``: the worker's if it has claimed it, else computed here."""
        i = self.index.get(key)
        if i is None or i <= self._last:
            self.off_plan += 1
            return self.servo.settle_keyed(key)
        self._last = i
        if self._conn is not None and self._worker_has(i):
            rest = self._receive(i)
            if rest is not None:
                self.from_worker += 1
                self.servo.total_steps += rest.steps
                return rest
        return self.servo.settle_keyed(key)

    def _worker_has(self, i: int) -> bool:
        """Whether the worker has claimed settle i; if not, the run claims it (passing over the
        ones before it that it skipped)."""
        lock = self._next.get_lock()
        if not lock.acquire(timeout=LOCK_TIMEOUT_S):     # the worker died holding it
            self.close()
            return False
        try:
            if self._next.value > i:
                return True
            self._next.value = i + 1
            return False
        finally:
            lock.release()

    def _receive(self, i: int) -> Rest | None:
        """The worker's settle i (the worker sends in the order it claims); None if it failed."""
        try:
            while True:
                j, rest = self._conn.recv()
                if j == i:
                    return rest
                if j > i:       # cannot happen: the worker claimed i before j
                    raise EOFError
        except (EOFError, OSError):
            self.close()        # the worker is gone: the run settles the rest itself
            return None

    def close(self) -> None:
        """Stop the worker (whatever it has left) and reap it."""
        if self._pid is not None:
            try:
                os.kill(self._pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.waitpid(self._pid, 0)
            self._pid = None
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def __enter__(self) -> "SettleAhead":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["SettleAhead", "settle_plan"]
