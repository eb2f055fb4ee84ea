"""Run a bench file's procedures on real (or emulated) instruments and write the standard dataset.

    acquire("bench.toml", "out/dataset", resume=False, progress=True) -> Path

The same procedures and ``Runner`` as the twin (``hw.acquisition.procedures``/``runner``); only the
instruments (serial drivers built from the bench file, ``hw.acquisition.bench``) and the clock
differ: a ``WallClock`` whose Waits really wait (``[run] waits = "real"``), or do not
(``"skip"``: emulated instruments have nothing to settle); the drivers' own waits (retry backoff,
stage status polls) are scaled by ``[run] driver_sleep_scale`` (0 for emulators). Readings are
stamped on the runner's clock (seconds since the run started, continued across a resume).

Journal: ``OUT/journal.jsonl`` (fsync per step); ``resume=True`` continues an interrupted run (the
Runner checks that the bench file's procedure is the journaled one, re-issues the last move and
continues). Dataset (docs/dataset-format.md): ``manifest.json`` (source "hardware" or "emulated"
per the bench file, bench geometry from ``[geometry]``), ``radial_motion.csv``, ``polygon.csv``,
``heads.csv`` as the procedures produce them, with the same columns as ``simulate`` writes
(``theta_deg`` = the commanded encoder reading, or head 1's reading with ``[run] theta =
"encoder"``; ``theta_read_deg`` = head 1's reading), and ``bench.toml``, the bench file as run.
This module never imports the twin.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchtwin.analysis.dataset import DatasetWriter
from benchtwin.fsio import DiskFullError, OutputError, OutputFolder, atomic_write_text, locked_output_dir

from .bench import BenchConfig, BenchFileError, close_instruments, dataset_manifest, iter_procedure, load_bench, open_instruments
from .runner import Runner, WallClock
from .tables import TableSink

__all__ = ["acquire", "AcquireClock", "TableSink", "sink_for_bench", "write_tables", "JOURNAL"]

JOURNAL = "journal.jsonl"  # = benchtwin.analysis.dataset.JOURNAL


class AcquireClock(WallClock):
    """``WallClock`` whose ``advance`` (a procedure's Wait) goes through an injected ``sleep``."""

    def __init__(self, sleep: Callable[[float], None] | None = time.sleep):
        super().__init__()
        self._sleep = sleep

    def advance(self, dt: float) -> float:
        if dt > 0 and self._sleep is not None:
            self._sleep(dt)
        return self.now()


def _scaled_sleep(scale: float) -> Callable[[float], None]:
    if scale <= 0:
        return lambda s: None
    return lambda s: time.sleep(s * scale) if s > 0 else None


def acquire(bench_path: str | Path, out_dir: str | Path, resume: bool = False, progress: bool = True,
            *, on_row: Callable[[dict, dict], None] | None = None, force: bool = False,
            live: Any | None = None) -> Path:
    """Run the bench file's procedures and write the dataset directory ``out_dir``; returns it.

    Flat memory: the procedure is generated lazily and every row goes straight from the runner to
    its table (``TableSink``: CSV rows appended and flushed under ``.<table>.csv.part``, renamed to
    ``<table>.csv`` when the run has ended), so nothing grows with the number of readings. A run that
    fails keeps its journal (every reading taken, fsynced) and removes the part files;
    ``resume=True`` rewrites the tables from the journal and continues. The manifest is written last: a dataset without it is
    unfinished. ``live``: an observer with ``start(n_steps)``, ``on_step(i, step, context, replay)``
    and ``on_row(row, result)`` (the live view of ``acquire --live``); it never changes the run.

    Readings are never discarded unasked: a folder holding a journal is refused without ``resume``
    (the error says to resume, or to restart with ``force``, which clears the folder); any other
    non-empty folder is refused without ``force``; a lock file (``benchtwin.fsio.DirLock``, O_EXCL
    with the pid) stops a second run on the same folder (issue #13: two acquires interleaved one
    journal), and is taken before ``force`` clears anything (issue 31: ``--force`` deleted a live
    run's journal).

    A full disk (ENOSPC, EDQUOT) is ``BenchFileError`` (exit 2) naming the file that could not be
    written, the space free and the space the rest of the run needs (``_rest_of_run``), and how to
    resume; the step that failed was not journaled, so the resume takes it again (for a CCD stop,
    its encoder reading and frame: hw/acquisition/runner.py).

    An emulated bench (``source = "emulated"``) is checked before a resumed run appends a reading
    (``Runner(verify_resume=True)``): the stage must stand where the journal left it and the last
    journaled reading must read the same again, and the bench file's ``[bench] session`` (written by
    ``benchtwin emulate``, journaled in the journal's header) must be the journal's; a fresh emulator
    session fails that check (``ResumeMismatchError``, exit 2) instead of serving the run wrong readings."""
    cfg = load_bench(bench_path)
    out = Path(out_dir)
    try:
        # the lock first, then the check (and --force's clearing): never a live run's journal
        folder = OutputFolder("dataset folder", "acquire", resume_marker=JOURNAL, complete_marker="manifest.json")
        with locked_output_dir(out, folder, force=force, resume=resume, inputs=[bench_path]):
            return _acquire(cfg, out, resume, progress, on_row, live)
    except DiskFullError as exc:
        raise BenchFileError(str(exc.with_hint(_rest_of_run(exc, cfg, bench_path, out)))) from exc
    except OutputError as exc:
        raise BenchFileError(str(exc)) from None


def _rest_of_run(exc: DiskFullError, cfg: BenchConfig, bench_path: str | Path, out: Path) -> str:
    """What a full disk's message adds: the space the rest of the run needs, estimated from what
    the steps journaled so far wrote (the folder's bytes per step × the steps left, with the
    failed write's own bytes as the least), and the command that resumes."""
    from .runner import iter_journal

    n_steps = sum(1 for _ in iter_procedure(cfg))
    done = sum(1 for r in iter_journal(out / JOURNAL) if "i" in r) if (out / JOURNAL).is_file() else 0
    written = sum(p.stat().st_size for p in out.rglob("*") if p.is_file() and not p.is_symlink())
    rest = written / done * (n_steps - done) if done else 0.0
    need = max(rest, float(exc.needed_bytes or 0))
    how = (f"free at least {_mib(need)} (the rest of the run: {n_steps - done} of {n_steps} steps, estimated "
           f"from the {done} written) and continue with `benchtwin acquire {bench_path} -o {out} --resume`; "
           "every reading journaled is kept, and the step that failed is taken again")
    return how


def _mib(n: float) -> str:
    return f"{n / 2**20:.1f} MiB"


def _acquire(cfg: BenchConfig, out: Path, resume: bool, progress: bool,
             on_row: Callable[[dict, dict], None] | None, live: Any | None = None) -> Path:
    from tqdm.auto import tqdm  # a notebook widget in Jupyter, the text bar elsewhere (issue 34)

    n_steps = sum(1 for _ in iter_procedure(cfg))
    clock = AcquireClock(time.sleep if cfg.run["waits"] == "real" else None)
    inst, ports = open_instruments(cfg, sleep=_scaled_sleep(float(cfg.run["driver_sleep_scale"])), clock=clock.now)
    bar = tqdm(total=n_steps, desc=f"acquire {cfg.name}", unit="step", disable=not progress, leave=False)
    try:
        writer = DatasetWriter(out, dataset_manifest(cfg, inst), prepared=True, resume=resume)
        sink = sink_for_bench(writer, cfg)

        def step_cb(*a):
            bar.update(1)
            if live is not None:
                live.on_step(*a)

        def row_cb(row, result):
            if on_row is not None:
                on_row(row, result)
            if live is not None:
                live.on_row(row, result)

        if live is not None:
            live.start(n_steps)
        try:
            Runner(inst, clock, journal=out / JOURNAL, stage=cfg.run["stage"], strict=cfg.run["strict"],
                   fsync=cfg.run["fsync"], on_step=step_cb, verify_resume=cfg.source == "emulated",
                   session=cfg.session,
                   on_row=row_cb if (on_row is not None or live is not None) else None).stream(
                       iter_procedure(cfg), sink, resume=resume)
        except BaseException:
            sink.abort()
            raise
    finally:
        bar.close()
        close_instruments(ports)
    sink.close()
    if cfg.text is not None:
        atomic_write_text(out / "bench.toml", cfg.text)
    writer.close()
    return out


# --------------------------------------------------------------------------- tables

def sink_for_bench(writer: DatasetWriter, cfg: BenchConfig) -> TableSink:
    """The sink for a bench file's procedures and instrument names."""
    tag_of = {"radial_motion": "radial_motion", "ccd_sweep": "ccd", "polygon_shift_angle": "polygon",
              "polygon_traditional": "polygon", "selfcal": "selfcal"}  # procedure type -> rows' tag
    enc_of: dict[str, str] = {}
    for p in cfg.procedures:
        enc_of.setdefault(tag_of[p["type"]], p.get("encoder", "encoder"))
    ac = next((p.get("autocollimator", "autocollimator") for p in cfg.procedures
               if p["type"].startswith("polygon")), "autocollimator")
    probes: list[str] = next((p.get("probes", ["probe_top", "probe_bottom"]) for p in cfg.procedures
                   if p["type"] == "radial_motion"), [])
    return TableSink(writer, probes=probes, resolution_arcsec=float(cfg.geometry.get("encoder_resolution_arcsec", 0.0)),
                     theta=cfg.run["theta"], encoder_of=enc_of, autocollimator=ac)


def write_tables(w: DatasetWriter, rows: list[dict[str, Any]], cfg: BenchConfig) -> None:
    """The dataset tables from a list of the runner's rows (``TableSink`` over the list)."""
    sink = sink_for_bench(w, cfg)
    for r in rows:
        sink(r)
    sink.close()
