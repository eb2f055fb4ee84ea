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

from benchtwin.analysis.dataset import DatasetWriter, TableAppender
from benchtwin.units import quantise

from .bench import BenchConfig, close_instruments, dataset_manifest, iter_procedure, load_bench, open_instruments
from .runner import Runner, RunnerError, WallClock

__all__ = ["acquire", "AcquireClock", "TableSink", "write_tables", "JOURNAL"]

JOURNAL = "journal.jsonl"


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
            *, on_row: Callable[[dict, dict], None] | None = None) -> Path:
    """Run the bench file's procedures and write the dataset directory ``out_dir``; returns it.

    Flat memory: the procedure is generated lazily and every row goes straight from the runner to
    its table (``TableSink``: CSV rows appended and flushed under ``.<table>.csv.part``, renamed to
    ``<table>.csv`` when the run has ended), so nothing grows with the number of readings. A run that
    fails keeps its journal (every reading taken, fsynced) and removes the part files;
    ``resume=True`` rewrites the tables from the journal and continues. The manifest is written last: a dataset without it is
    unfinished."""
    from tqdm import tqdm

    cfg = load_bench(bench_path)
    out = Path(out_dir)
    n_steps = sum(1 for _ in iter_procedure(cfg))
    clock = AcquireClock(time.sleep if cfg.run["waits"] == "real" else None)
    inst, ports = open_instruments(cfg, sleep=_scaled_sleep(float(cfg.run["driver_sleep_scale"])), clock=clock.now)
    bar = tqdm(total=n_steps, desc=f"acquire {cfg.name}", unit="step", disable=not progress, leave=False)
    try:
        writer = DatasetWriter(out, dataset_manifest(cfg, inst))
        sink = TableSink(writer, cfg)
        try:
            Runner(inst, clock, journal=out / JOURNAL, stage=cfg.run["stage"], strict=cfg.run["strict"],
                   fsync=cfg.run["fsync"], on_step=lambda *a: bar.update(1),
                   on_row=on_row).stream(iter_procedure(cfg), sink, resume=resume)
        except BaseException:
            sink.abort()
            raise
    finally:
        bar.close()
        close_instruments(ports)
    sink.close()
    if cfg.text is not None:
        (out / "bench.toml").write_text(cfg.text, encoding="utf-8")
    writer.close()
    return out


# --------------------------------------------------------------------------- tables

def _reading(row: dict, name: str) -> dict:
    return row["readings"][name]


class TableSink:
    """The runner's sink for ``acquire``: each row becomes its table row(s) at once (same columns as
    the twin's ``simulate``): ``radial_motion.csv``, ``polygon.csv``, ``heads.csv`` (one row per
    head and reading) and, for a CCD sweep, ``ccd/index.csv`` + ``ccd/img_KKK.png`` (the image is
    written when the frame is taken, before the row is journaled; a replayed capture row checks
    that its image is there). Tables are opened at their first row (``DatasetWriter.open_table``);
    ``close()`` finishes them atomically, ``abort()`` removes the part files (a run that failed:
    every row taken is in the journal, which a resume replays through a new sink)."""

    def __init__(self, writer: DatasetWriter, cfg: BenchConfig):
        self.w, self.cfg = writer, cfg
        self.tables: dict[str, TableAppender] = {}
        tag_of = {"radial_motion": "radial_motion", "ccd_sweep": "ccd", "polygon_shift_angle": "polygon",
                  "polygon_traditional": "polygon", "selfcal": "selfcal"}  # procedure type -> rows' tag
        self.enc_of: dict[str, str] = {}
        for p in cfg.procedures:
            self.enc_of.setdefault(tag_of[p["type"]], p.get("encoder", "encoder"))
        self.ac = next((p.get("autocollimator", "autocollimator") for p in cfg.procedures
                        if p["type"].startswith("polygon")), "autocollimator")
        self.probes = next((p.get("probes", ["probe_top", "probe_bottom"]) for p in cfg.procedures
                            if p["type"] == "radial_motion"), [])
        self.res = float(cfg.geometry.get("encoder_resolution_arcsec", 0.0))
        self._ccd_read: tuple[Any, float] | None = None
        self.rows = 0

    def _table(self, name: str, columns: list[str]) -> TableAppender:
        t = self.tables.get(name)
        if t is None:
            t = self.tables[name] = self.w.open_table(name, columns)
        return t

    def _theta(self, r: dict, h1: float) -> float:
        return h1 if self.cfg.run["theta"] == "encoder" else float(r["tag"]["target_deg"])

    def __call__(self, r: dict, live: Any = None) -> None:
        self.rows += 1
        proc = r["tag"].get("procedure", "")
        if r["type"] == "capture":
            self._capture(r, live)
            return
        enc = self.enc_of.get(proc, "encoder")
        h1 = float(_reading(r, enc)["angle_deg"][0])
        if proc == "radial_motion":
            cols = ["rep", "theta_deg", *[f"{p}_um" for p in self.probes], "theta_read_deg", "t_s"]
            self._table("radial_motion", cols).append(
                [r["tag"]["rep"], self._theta(r, h1), *[_reading(r, p)["value_um"] for p in self.probes], h1, r["t_s"]])
        elif proc == "polygon":
            tag, ac = r["tag"], _reading(r, self.ac)
            self._table("polygon", ["shift_deg", "start_face", "step", "theta_deg", "ac_arcsec", "t_s", "rep",
                                    "direction", "ac_y_arcsec", "theta_read_deg"]).append(
                [tag["shift_deg"], tag["start_face"], tag["step"], self._theta(r, h1), ac["x_arcsec"], r["t_s"],
                 tag["rep"], tag["direction"], ac["y_arcsec"], h1])
        elif proc == "selfcal":
            a = _reading(r, enc)["angle_deg"]
            t = self._table("heads", ["theta_deg", "head", "delta_arcsec", "rep", "direction", "theta_read_deg", "t_s"])
            for j, aj in enumerate(a):
                t.append([self._theta(r, h1), j + 1, quantise((a[0] - aj) * 3600.0, self.res), r["tag"]["rep"],
                          r["tag"]["direction"], h1, r["t_s"]])
        elif proc == "ccd":
            self._ccd_read = (r["tag"]["k"], h1)

    def _capture(self, r: dict, live: Any) -> None:
        k = int(r["tag"]["k"])
        f = f"img_{k:03d}.png"
        if live is not None:
            self.w.write_image(f"ccd/{f}", live["image"])
        elif not (self.w.path / "ccd" / f).is_file():
            raise RunnerError(f"resume: the journal has capture k={k} but {self.w.path / 'ccd' / f} is missing")
        if self._ccd_read is None or self._ccd_read[0] != r["tag"]["k"]:
            raise RunnerError(f"capture k={k}: no encoder reading at the same stop before it (ccd_sweep reads the "
                              f"encoder, then captures)")
        h1 = self._ccd_read[1]
        self._table("ccd/index", ["k", "theta_deg", "file", "theta_read_deg", "t_s"]).append(
            [k, self._theta(r, h1), f, h1, r["t_s"]])

    def close(self) -> None:
        for t in self.tables.values():
            t.close()

    def abort(self) -> None:
        for t in self.tables.values():
            t.abort()


def write_tables(w: DatasetWriter, rows: list[dict[str, Any]], cfg: BenchConfig) -> None:
    """The dataset tables from a list of the runner's rows (``TableSink`` over the list)."""
    sink = TableSink(w, cfg)
    for r in rows:
        sink(r)
    sink.close()
