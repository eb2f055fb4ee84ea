"""Execute a procedure (a generator of steps) against a dict of instruments and a clock.

    rows = Runner(instruments, SimClock(), journal="run.jsonl").run(procedure)

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

This module never imports the twin (``hw`` is usable without it).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .procedures import Capture, Mark, Move, Read, Step, Wait, describe_step

__all__ = ["SimClock", "WallClock", "Runner", "RunnerError", "dry_run", "read_journal"]

JOURNAL_VERSION = 1


class RunnerError(RuntimeError):
    """The run cannot go on (failed reading status, journal mismatch on resume)."""


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


def _plain(x: Any) -> Any:
    """JSON-ready copy: numpy scalars -> Python, arrays -> lists (images are not journaled)."""
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    return x


def read_journal(path: str | Path) -> list[dict[str, Any]]:
    """Journal records (a torn last line from a crash is ignored)."""
    p = Path(path)
    if not p.is_file():
        return []
    recs = []
    lines = p.read_text(encoding="utf-8").splitlines()
    for n, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            recs.append(json.loads(line))
        except json.JSONDecodeError:
            if n == len(lines) - 1:
                break  # torn write of the step in progress
            raise RunnerError(f"{p}: line {n + 1} is not JSON")
    return recs


def _drop_torn_tail(path: Path) -> None:
    """Cut a half-written last line (a crash during a write) before appending to the journal."""
    if not path.is_file():
        return
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        with open(path, "r+b") as f:
            f.truncate(data.rfind(b"\n") + 1)


class Runner:
    def __init__(self, instruments: Mapping[str, Any], clock: Any, journal: str | Path | None = None,
                 stage: str = "stage", on_step: Callable[..., None] | None = None,
                 on_row: Callable[[dict, dict], None] | None = None, strict: bool = True, fsync: bool = True):
        self.instruments = dict(instruments)
        self.clock = clock
        self.journal = Path(journal) if journal is not None else None
        self.stage = stage
        self.on_step = on_step
        self.on_row = on_row
        self.strict = strict  # raise on a reading whose status is not "ok"
        self.fsync = fsync    # hardware: fsync every line; the twin may only flush (fast, same file)

    # ------------------------------------------------------------------ internals
    def _inst(self, name: str) -> Any:
        try:
            return self.instruments[name]
        except KeyError:
            raise RunnerError(f"procedure needs instrument {name!r}; have {sorted(self.instruments)}") from None

    def _check(self, name: str, reading: Mapping[str, Any], i: int) -> None:
        if self.strict and reading.get("status", "ok") != "ok":
            raise RunnerError(f"step {i}: {name} returned status {reading.get('status')!r}")

    def _append(self, fh, rec: dict) -> None:
        if fh is None:
            return
        fh.write(json.dumps(rec, sort_keys=True, allow_nan=True) + "\n")
        fh.flush()
        if self.fsync:
            os.fsync(fh.fileno())

    # ------------------------------------------------------------------ run
    def run(self, procedure: Iterable[Step], resume: bool = False) -> list[dict[str, Any]]:
        done: list[dict] = []
        if self.journal is not None and resume:
            done = [r for r in read_journal(self.journal) if "i" in r]
            _drop_torn_tail(self.journal)
        elif self.journal is not None and self.journal.exists():
            self.journal.unlink()
        fh = None
        if self.journal is not None:
            self.journal.parent.mkdir(parents=True, exist_ok=True)
            fh = open(self.journal, "a", encoding="utf-8")
            if not done:
                self._append(fh, {"journal": "benchtwin-run", "version": JOURNAL_VERSION})
        rows: list[dict] = []
        context: dict[str, Any] = {}
        last_move: float | None = None
        pending_restore = False
        try:
            for i, step in enumerate(procedure):
                desc = describe_step(step)
                if isinstance(step, Mark):
                    context.update(step.context)
                if i < len(done):
                    rec = done[i]
                    if rec["i"] != i or rec["step"] != _plain(desc):
                        raise RunnerError(f"resume: step {i} of the procedure ({desc}) differs from the "
                                          f"journal ({rec.get('step')}); not the same procedure")
                    if self.on_step is not None:
                        self.on_step(i, step, dict(context), True)
                    if isinstance(step, Move):
                        last_move = step.target_deg
                    if "row" in rec:
                        rows.append(rec["row"])
                    pending_restore = True
                    continue
                if pending_restore:
                    pending_restore = False
                    if last_move is not None:  # stand where the bench stood (move times count from there)
                        self._inst(self.stage).move_to(last_move)
                    self.clock.set(done[-1]["t_s"])
                if self.on_step is not None:
                    self.on_step(i, step, dict(context), False)
                rec: dict[str, Any] = {"i": i, "step": _plain(desc)}
                if isinstance(step, Move):
                    res = self._inst(self.stage).move_to(step.target_deg)
                    self._check(self.stage, res, i)
                    last_move = step.target_deg
                    rec["result"] = _plain(res)
                elif isinstance(step, Wait):
                    self.clock.advance(step.seconds)
                elif isinstance(step, Read):
                    readings = {}
                    for name in step.names:
                        r = self._inst(name).read()
                        self._check(name, r, i)
                        readings[name] = r
                    row = {"i": i, "type": "read", "tag": _plain({**context, **step.tag}),
                           "t_s": float(self.clock.now()), "readings": _plain(readings)}
                    rec["row"] = row
                    rows.append(row)
                    if self.on_row is not None:
                        self.on_row(row, readings)
                elif isinstance(step, Capture):
                    res = self._inst(step.camera).capture()
                    self._check(step.camera, res, i)
                    meta = {k: v for k, v in res.items() if k != "image"}
                    img = res.get("image")
                    if img is not None:
                        meta["image_shape"] = list(np.shape(img))
                        meta["image_dtype"] = str(np.asarray(img).dtype)
                    row = {"i": i, "type": "capture", "camera": step.camera, "tag": _plain({**context, **step.tag}),
                           "t_s": float(self.clock.now()), "reading": _plain(meta)}
                    rec["row"] = row
                    rows.append(row)
                    if self.on_row is not None:
                        self.on_row(row, res)
                rec["t_s"] = float(self.clock.now())
                self._append(fh, rec)
        finally:
            if fh is not None:
                fh.close()
        return rows
