"""Execute a procedure (a generator of steps) against a dict of instruments and a clock.

    rows = Runner(instruments, SimClock(), journal="run.jsonl").run(procedure)
    n = Runner(instruments, clock, journal="run.jsonl").stream(procedure, sink)   # flat memory

- Instruments follow ``hw.interfaces`` (the stage is ``instruments[stage]``, default "stage").
- The clock: ``SimClock`` for the twin (the stage advances it by the move time, Wait advances it),
  ``WallClock`` for hardware (Wait really waits; moves take their own time).
- Rows: one per Read / Capture step: ``{"i": step index, "type": "read"|"capture", "tag": context +
  step tag, "t_s", "readings": {instrument: reading}}`` (a capture row has ``camera`` and
  ``reading`` without the image; the image goes to ``on_row`` live only).
- Journal (JSON lines): every executed step is appended and flushed (fsync) as it completes, so an
  interrupted run loses at most the step in progress. ``run(..., resume=True)`` reads the journal,
  checks that the procedure's steps match the journaled ones, replays them (Marks are re-applied
  through ``on_step``; no instrument is read again), re-issues the last Move so the bench stands
  where it stood, restores the clock to the last journaled time, and continues. An interrupted and
  resumed run returns the same rows as an uninterrupted one (the twin's noise is keyed by step).
- ``on_step(i, step, context, replay)`` is called before every step (the twin uses it to key its
  noise streams and apply re-clamping); ``on_row(row, live_result)`` after every live row.
- Memory: ``stream(procedure, sink)`` keeps no row: every row, replayed from the journal or live,
  goes to ``sink(row, live_result)`` (``live_result`` is None for a replayed row) in procedure order
  and is then dropped; the procedure is consumed lazily and a resumed journal is read line by line
  in step with it, so a run of any length uses O(1) memory in the number of readings
  (benchmarks/hil_bench.py). ``run`` is ``stream`` with a sink that collects the rows into a list.
  Order per live row: ``on_row``, then ``sink``, then the journal line (so whatever the sink writes
  for a row exists before the row is journaled).
- A stop's Read and the Capture right after it are journaled together, once the frame is on disk
  (one write): the encoder reading at a CCD stop is what makes a hot-folder camera's frame (the
  emulator renders it then, twin/emulators/backend.py), so a run that failed at the frame (a full
  disk, issue #31) resumes at the Read and takes the frame again, instead of asking the camera
  for a frame it already gave. The journal's lines and their order are unchanged.
- ``verify_resume`` (emulated benches: ``acquire`` with ``source = "emulated"``): before the first
  live step of a resumed run the stage must stand at the journal's last move (or at the move in
  progress when the run stopped); if it stands at the last move and the last journaled Read was
  taken there, that Read is taken again once the move is re-issued (not after a move elsewhere
  and back: that changes the bench's path, and with it the readings); every number must be the
  journaled one (an emulator draws the same value at the same stop of the same session), else
  ``ResumeMismatchError`` says which reading differs and what to do. A fresh emulator session has
  lost the run's state (its place in the procedure, the polygon's clamping, its clock) and served
  a resumed run wrong readings with exit 0 (issue #31).
- ``session`` (an emulated bench file's ``[bench] session``) is journaled in the header line; a
  resume whose bench file names another session, or none, is ``ResumeMismatchError`` before
  anything is replayed or appended (a fresh session whose stage happens to stand at the journal's
  last stop, with no reading journaled there, passes the checks above). A header without a session
  (hardware) is not checked.
- A full disk (ENOSPC, EDQUOT) while a journal line is written is ``benchtwin.fsio.DiskFullError``
  naming the journal; the torn line is cut on resume and its step done again.

This module never imports the twin (``hw`` is usable without it).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.fsio import raise_if_disk_full
from benchtwin.jsonable import to_json
from benchtwin.hw.interfaces import MOVE_NOT_HELD

from .procedures import Capture, Mark, Move, Read, Step, Wait, describe_step

__all__ = ["SimClock", "WallClock", "Runner", "RunnerSettings", "RunnerError", "ResumeMismatchError", "dry_run", "read_journal", "iter_journal"]

JOURNAL_VERSION = 1


class RunnerError(RuntimeError):
    """The run cannot go on (failed reading status, journal mismatch on resume)."""


class ResumeMismatchError(RunnerError):
    """On resume, the instruments do not read at the journal's last stop what the journal holds."""


#: how far the stage may stand from the journal's last move on resume (a microstep is 1e-3° or less)
STAGE_TOLERANCE_DEG = 1e-3
_MISMATCH_HINT = ("An emulator keeps that state (its place in the procedure, the polygon's clamping, its clock) only "
                  "within the session that served the run: resume against that session, or start the run again "
                  "with --force on a fresh session (the journaled readings are then deleted)")


class SimClock:
    """Simulated time in seconds: advanced explicitly, never sleeps."""

    def __init__(self, t0: float = 0.0):
        self._t = float(t0)

    def now(self) -> float:
        return self._t

    def advance(self, dt: float) -> float:
        if dt < 0:
            raise ValueError("time runs forwards")
        self._t += float(dt)
        return self._t

    def set(self, t: float) -> None:
        self._t = float(t)


class WallClock:
    """Monotonic wall time from the run start; ``advance`` sleeps (hardware waits for real)."""

    def __init__(self):
        self._t0 = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self._t0

    def advance(self, dt: float) -> float:
        if dt > 0:
            time.sleep(dt)
        return self.now()

    def set(self, t: float) -> None:
        """Resume: continue the journal's time line (t_s keeps increasing across restarts)."""
        self._t0 = time.monotonic() - float(t)


def dry_run(procedure: Iterable[Step]) -> list[dict[str, Any]]:
    """The steps of a procedure as JSON-ready dicts, without instruments."""
    return [describe_step(s) for s in procedure]


# JSON-ready copy: numpy scalars -> Python, arrays -> lists (images are not journaled)
_plain = to_json

def iter_journal(path: str | Path) -> Iterator[dict[str, Any]]:
    """Journal records, read line by line. A last line without its newline is a torn write from a
    crash and is ignored (even if it parses: the step is re-executed); a bad line anywhere else is
    an error naming the file and line."""
    p = Path(path)
    if not p.is_file():
        return
    with open(p, encoding="utf-8") as fh:
        n = 0
        line = fh.readline()
        while line:
            n += 1
            nxt = fh.readline()
            if not nxt and not line.endswith("\n"):
                return  # torn write of the step in progress (cut by _drop_torn_tail before appending)
            if line.strip():
                try:
                    rec = json.loads(line)
                except json.JSONDecodeError:
                    if not nxt:
                        return  # torn write of the step in progress
                    raise RunnerError(f"{p}: line {n} is not JSON") from None
                yield rec
            line = nxt


def read_journal(path: str | Path) -> list[dict[str, Any]]:
    """Journal records as a list (``iter_journal`` streams them)."""
    return list(iter_journal(path))


def _numbers_differ(old: Any, new: Any, key: str = "") -> Iterator[tuple[str, Any, Any]]:
    """(key, journaled, now) of every number of a reading that differs (time stamps excepted)."""
    if isinstance(old, Mapping):
        for k, v in old.items():
            if k != "t_s":
                yield from _numbers_differ(v, new.get(k) if isinstance(new, Mapping) else None, f"{key}.{k}" if key else k)
    elif isinstance(old, list):
        if not isinstance(new, list) or len(new) != len(old):
            yield key, old, new
            return
        for j, (a, b) in enumerate(zip(old, new)):
            yield from _numbers_differ(a, b, f"{key}[{j}]")
    elif isinstance(old, (int, float)) and not isinstance(old, bool):
        if not isinstance(new, (int, float)) or float(new) != float(old):
            yield key, old, new


def _with_next(procedure: Iterable[Step]) -> Iterator[tuple[Step, Step | None]]:
    """(step, the step after it or None), consuming the procedure lazily (one step ahead)."""
    it = iter(procedure)
    cur = next(it, None)
    while cur is not None:
        nxt = next(it, None)
        yield cur, nxt
        cur = nxt


def _drop_torn_tail(path: Path) -> None:
    """Cut a half-written last line (a crash during a write) before appending to the journal; reads
    only the file's tail."""
    if not path.is_file():
        return
    with open(path, "r+b") as f:
        size = f.seek(0, os.SEEK_END)
        if size == 0:
            return
        f.seek(size - 1)
        if f.read(1) == b"\n":
            return
        pos, block = size, 1 << 16
        cut = 0
        while pos > 0:
            start = max(0, pos - block)
            f.seek(start)
            chunk = f.read(pos - start)
            k = chunk.rfind(b"\n")
            if k >= 0:
                cut = start + k + 1
                break
            pos = start
        f.truncate(cut)


@dataclass(frozen=True)
class RunnerSettings:
    """How a ``Runner`` runs: the stage's instrument name; ``on_step(i, step, context, replay)``
    before every step and ``on_row(row, live_result)`` after every live row; ``strict``: a reading
    whose status is not "ok" stops the run; ``fsync``: every journal line is fsynced (hardware; the
    twin may only flush: fast, the same file); ``verify_resume``: re-read the last journaled stop on
    resume (module docstring); ``session``: the emulator session serving the instruments (journaled;
    None: hardware)."""

    stage: str = "stage"
    on_step: Callable[..., None] | None = None
    on_row: Callable[[dict, dict], None] | None = None
    strict: bool = True
    fsync: bool = True
    verify_resume: bool = False
    session: str | None = None


@dataclass
class _StreamState:
    """What ``Runner.stream`` carries from step to step: the journal being replayed (None once the
    run is live), the open journal, the counts, the context of the Marks so far, the last journaled
    time and move, a Read's line held for the Capture after it, and the last journaled Read."""

    journal_iter: Iterator[dict] | None = None
    fh: Any = None
    n_rows: int = 0
    n_done: int = 0
    last_t: float | None = None
    context: dict[str, Any] = field(default_factory=dict)
    last_move: float | None = None
    held: dict | None = None
    last_read: tuple[dict, float | None] | None = None


class Runner:
    def __init__(self, instruments: Mapping[str, Any], clock: Any, journal: str | Path | None = None,
                 settings: RunnerSettings | None = None, **kw: Any):
        """``settings`` (a ``RunnerSettings``), or its fields as keywords (``stage=``, ``on_step=``, …)."""
        if settings is not None and kw:
            raise TypeError("Runner: give settings or its fields as keywords, not both")
        settings = settings if settings is not None else RunnerSettings(**kw)
        self.settings = settings
        self.instruments = dict(instruments)
        self.clock = clock
        self.journal = Path(journal) if journal is not None else None
        self.stage = settings.stage
        self.on_step = settings.on_step
        self.on_row = settings.on_row
        self.strict = settings.strict
        self.fsync = settings.fsync
        self.verify_resume = settings.verify_resume
        self.session = settings.session

    # ------------------------------------------------------------------ internals
    def _inst(self, name: str) -> Any:
        try:
            return self.instruments[name]
        except KeyError:
            raise RunnerError(f"procedure needs instrument {name!r}; have {sorted(self.instruments)}") from None

    def _check(self, name: str, reading: Mapping[str, Any], i: int) -> None:
        if self.strict and reading.get("status", "ok") != "ok":
            raise RunnerError(f"step {i}: {name} returned status {reading.get('status')!r}")

    def _append(self, fh, *recs: dict) -> None:
        """Journal ``recs`` (one write: a Read and its stop's Capture go in together)."""
        if fh is None:
            return
        text = "".join(json.dumps(rec, sort_keys=True, allow_nan=True) + "\n" for rec in recs)
        try:
            fh.write(text)
            fh.flush()
            if self.fsync:
                os.fsync(fh.fileno())
        except OSError as exc:
            raise_if_disk_full(exc, self.journal or Path(fh.name), len(text.encode()))
            raise

    def _verify_stage(self, last_move: float, step: Step) -> bool:
        """Resume: the stage must stand where the journal left it (its last move), or at the target
        of the move the run was making when it stopped (done, not yet journaled). Returns whether
        it stands at the last move (then a reading taken there may be taken again: a stage sent
        on and back has another path, and the twin reads otherwise at the display's last digits)."""
        pos = self._inst(self.stage).position()
        deg = float(pos.get("stage_deg", pos["angle_deg"]))
        stops = [last_move] + ([step.target_deg] if isinstance(step, Move) else [])
        if all(abs(deg - s) > STAGE_TOLERANCE_DEG for s in stops):
            raise ResumeMismatchError(
                f"{self.journal}: resume: the stage {self.stage!r} stands at {deg:.6g}°, the journal left it at "
                f"{last_move:.6g}°: the bench is not in the state the run left it in. {_MISMATCH_HINT}")
        return abs(deg - last_move) <= STAGE_TOLERANCE_DEG

    def _verify_position(self, rec: dict) -> None:
        """Resume, the bench standing at the stop of the journaled Read ``rec``: take it again;
        every number of every reading (but its time stamp) must be the journal's
        (ResumeMismatchError)."""
        differ = []
        for name, old in rec["row"]["readings"].items():
            new = _plain(self._inst(name).read())
            differ += [f"{name}.{key}: journal {a!r}, now {b!r}" for key, a, b in _numbers_differ(old, new)]
        if differ:
            where = ", ".join(f"{k} {v}" for k, v in rec["row"]["tag"].items())
            raise ResumeMismatchError(
                f"{self.journal}: resume: the instruments do not read at step {rec['i']} ({where}) what the journal "
                f"holds ({'; '.join(differ[:4])}{'; …' if len(differ) > 4 else ''}): the bench is not in the state the "
                f"run left it in. {_MISMATCH_HINT}")

    def _verify_session(self) -> None:
        """Resume: a journal whose header records an emulator session is continued only by that
        session (ResumeMismatchError). A fresh session whose stage stands at the journal's last stop,
        with no reading journaled there, passes the stage and reading checks: only its id tells."""
        header = next(iter_journal(self.journal), None) if self.journal is not None else None
        if header is None or "journal" not in header or header.get("session") is None:
            return  # nothing journaled yet, or a run without a session (hardware)
        if header["session"] == self.session:
            return
        now = (f"the bench file is of emulator session {self.session}" if self.session is not None
               else "the bench file names no emulator session")
        raise ResumeMismatchError(
            f"{self.journal}: resume: the journal was written against emulator session {header['session']}, {now}: "
            f"the emulator was restarted, and the journaled readings belong to the other session, so the bench is "
            f"not in the state the run left it in. {_MISMATCH_HINT}")

    # ------------------------------------------------------------------ run
    def run(self, procedure: Iterable[Step], resume: bool = False, restart: bool = False) -> list[dict[str, Any]]:
        """Execute the procedure; returns every row (replayed and live), in order."""
        rows: list[dict] = []
        self.stream(procedure, lambda row, _res: rows.append(row), resume=resume, restart=restart)
        return rows

    def stream(self, procedure: Iterable[Step], sink: Callable[[dict, Any], None] | None = None,
               resume: bool = False, restart: bool = False) -> int:
        """Execute the procedure, handing every row to ``sink(row, live_result)`` and keeping none;
        returns the number of rows. ``live_result`` is the instrument's result (with a capture's
        image) for a live row, None for a row replayed from the journal.

        An existing journal is continued with ``resume`` and replaced only with ``restart``; with
        neither, the run stops (RunnerError) rather than discard the readings it holds (issue #13)."""
        st = _StreamState(journal_iter=self._start_journal(resume, restart))
        failed = False
        try:
            if self.journal is not None and st.journal_iter is None:
                st.fh = self._open_journal(False)
            for i, (step, nxt) in enumerate(_with_next(procedure)):
                desc = describe_step(step)
                if isinstance(step, Mark):
                    st.context.update(step.context)
                rec = next(st.journal_iter, None) if st.journal_iter is not None else None
                if rec is not None:
                    self._replay(st, i, step, desc, rec, sink)
                    continue
                if st.journal_iter is not None:  # the first live step after the journaled ones
                    self._go_live(st, step)
                self._live_step(st, i, step, nxt, desc, sink)
        except BaseException:
            failed = True
            raise
        finally:
            if st.fh is not None:
                try:
                    st.fh.close()
                except OSError:     # what a full disk kept in the buffer: the error in flight says so
                    if not failed:
                        raise
        return st.n_rows

    def _start_journal(self, resume: bool, restart: bool) -> Iterator[dict] | None:
        """The journaled steps to replay (``resume``), or None; an earlier run's journal is deleted
        only with ``restart`` (RunnerError otherwise)."""
        if self.journal is not None and resume:
            self._verify_session()
            return (r for r in iter_journal(self.journal) if "i" in r)
        if self.journal is not None and self.journal.exists():
            if not restart:
                raise RunnerError(f"{self.journal}: a journal of an earlier run exists (its readings are kept); "
                                  "resume it, or restart (which deletes it)")
            self.journal.unlink()
        return None

    def _open_journal(self, cut_torn_tail: bool) -> Any:
        """The journal opened for appending (its header written when it is new)."""
        assert self.journal is not None
        self.journal.parent.mkdir(parents=True, exist_ok=True)
        if cut_torn_tail:
            _drop_torn_tail(self.journal)
        f = open(self.journal, "a", encoding="utf-8")
        if f.tell() == 0:
            head = {"journal": "benchtwin-run", "version": JOURNAL_VERSION}
            self._append(f, head if self.session is None else {**head, "session": self.session})
        return f

    def _replay(self, st: _StreamState, i: int, step: Step, desc: dict, rec: dict,
                sink: Callable[[dict, Any], None] | None) -> None:
        """A journaled step: checked against the procedure, re-applied through ``on_step``, its row
        (if any) handed to the sink; no instrument is read."""
        if rec["i"] != i or rec["step"] != _plain(desc):
            raise RunnerError(f"resume: step {i} of the procedure ({desc}) differs from the "
                              f"journal ({rec.get('step')}); not the same procedure")
        if self.on_step is not None:
            self.on_step(i, step, dict(st.context), True)
        if isinstance(step, Move):
            st.last_move = step.target_deg
        if isinstance(step, Read) and "row" in rec:
            st.last_read = (rec, st.last_move)
        if "row" in rec:
            st.n_rows += 1
            if sink is not None:
                sink(rec["row"], None)
        st.n_done += 1
        st.last_t = rec["t_s"]

    def _go_live(self, st: _StreamState, step: Step) -> None:
        """The first live step after the journaled ones: the bench checked (``verify_resume``) and
        stood where the journal left it, the clock restored, the journal reopened (its torn tail cut)."""
        st.journal_iter = None
        if st.n_done:
            still = False   # the stage has not left the journal's last stop
            if self.verify_resume and st.last_move is not None:
                still = self._verify_stage(st.last_move, step)
            if st.last_move is not None:  # stand where the bench stood (move times count from there)
                self._inst(self.stage).move_to(st.last_move)
            if still and st.last_read is not None and st.last_read[1] == st.last_move:
                self._verify_position(st.last_read[0])
            self.clock.set(st.last_t)
        st.fh = self._open_journal(True)

    def _live_step(self, st: _StreamState, i: int, step: Step, nxt: Step | None, desc: dict,
                   sink: Callable[[dict, Any], None] | None) -> None:
        """A live step: done on the instruments, its row handed to ``on_row`` and the sink, then
        journaled (a Read's line held for the Capture right after it)."""
        if self.on_step is not None:
            self.on_step(i, step, dict(st.context), False)
        rec: dict[str, Any] = {"i": i, "step": _plain(desc)}
        row, live = self._execute(st, i, step, rec)
        if row is not None:
            rec["row"] = row
            st.n_rows += 1
            if self.on_row is not None:
                self.on_row(row, live)
            if sink is not None:
                sink(row, live)
        rec["t_s"] = float(self.clock.now())
        if isinstance(step, Read) and isinstance(nxt, Capture):
            st.held = rec
        elif st.held is not None:
            self._append(st.fh, st.held, rec)
            st.held = None
        else:
            self._append(st.fh, rec)

    def _execute(self, st: _StreamState, i: int, step: Step, rec: dict[str, Any]) -> tuple[dict[str, Any] | None, Any]:
        """Do ``step`` on the instruments: (its row or None, the live result); a Move's result goes
        into its journal line ``rec``."""
        if isinstance(step, Move):
            res = self._inst(self.stage).move_to(step.target_deg)
            if not (res.get("status") == MOVE_NOT_HELD and "held_deg" in res):
                # (a stop held on another count is kept: journaled with its held_deg)
                self._check(self.stage, res, i)
            st.last_move = step.target_deg
            rec["result"] = _plain(res)
            return None, None
        if isinstance(step, Wait):
            self.clock.advance(step.seconds)
            return None, None
        if isinstance(step, Read):
            readings = {}
            for name in step.names:
                r = self._inst(name).read()
                self._check(name, r, i)
                readings[name] = r
            return {"i": i, "type": "read", "tag": _plain({**st.context, **step.tag}),
                    "t_s": float(self.clock.now()), "readings": _plain(readings)}, readings
        if isinstance(step, Capture):
            res = self._inst(step.camera).capture()
            self._check(step.camera, res, i)
            meta = {k: v for k, v in res.items() if k != "image"}
            img = res.get("image")
            if img is not None:
                meta["image_shape"] = list(np.shape(img))
                meta["image_dtype"] = str(np.asarray(img).dtype)
            return {"i": i, "type": "capture", "camera": step.camera, "tag": _plain({**st.context, **step.tag}),
                    "t_s": float(self.clock.now()), "reading": _plain(meta)}, res
        return None, None
