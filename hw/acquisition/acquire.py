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

from .bench import BenchConfig, build_procedure, close_instruments, dataset_manifest, load_bench, open_instruments
from .runner import Runner, WallClock

__all__ = ["acquire", "AcquireClock", "write_tables", "JOURNAL"]

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
    """Run the bench file's procedures and write the dataset directory ``out_dir``; returns it."""
    from tqdm import tqdm

    cfg = load_bench(bench_path)
    out = Path(out_dir)
    steps = build_procedure(cfg)
    clock = AcquireClock(time.sleep if cfg.run["waits"] == "real" else None)
    inst, ports = open_instruments(cfg, sleep=_scaled_sleep(float(cfg.run["driver_sleep_scale"])), clock=clock.now)
    bar = tqdm(total=len(steps), desc=f"acquire {cfg.name}", unit="step", disable=not progress, leave=False)
    try:
        writer = DatasetWriter(out, dataset_manifest(cfg, inst))
        rows = Runner(inst, clock, journal=out / JOURNAL, stage=cfg.run["stage"], strict=cfg.run["strict"],
                      fsync=cfg.run["fsync"], on_step=lambda *a: bar.update(1), on_row=on_row).run(steps, resume=resume)
    finally:
        bar.close()
        close_instruments(ports)
    write_tables(writer, rows, cfg)
    if cfg.text is not None:
        (out / "bench.toml").write_text(cfg.text, encoding="utf-8")
    writer.close()
    return out


# --------------------------------------------------------------------------- tables

def _quantise(x: float, step: float) -> float:
    if not step or step <= 0:
        return float(x)
    inv = 1.0 / step
    k = round(x / step)
    if abs(inv - round(inv)) < 1e-9 * inv:
        return k / round(inv)
    return k * step


def _reading(row: dict, name: str) -> dict:
    return row["readings"][name]


def write_tables(w: DatasetWriter, rows: list[dict[str, Any]], cfg: BenchConfig) -> None:
    """The dataset tables from the runner's rows (same columns as the twin's ``simulate``)."""
    by_proc: dict[str, list[dict]] = {}
    for r in rows:
        if r["type"] == "read":
            by_proc.setdefault(r["tag"].get("procedure", ""), []).append(r)
    enc_of = {p["type"]: p.get("encoder", "encoder") for p in cfg.procedures}

    def h1(r: dict, enc: str) -> float:
        return float(_reading(r, enc)["angle_deg"][0])

    def theta(r: dict, enc: str) -> float:
        return h1(r, enc) if cfg.run["theta"] == "encoder" else float(r["tag"]["target_deg"])

    radial = by_proc.get("radial_motion", [])
    if radial:
        enc = enc_of.get("radial_motion", "encoder")
        probes = next(p.get("probes", ["probe_top", "probe_bottom"]) for p in cfg.procedures
                      if p["type"] == "radial_motion")
        cols: dict[str, list] = {"rep": [r["tag"]["rep"] for r in radial], "theta_deg": [theta(r, enc) for r in radial]}
        for p in probes:
            cols[f"{p}_um"] = [_reading(r, p)["value_um"] for r in radial]
        cols["theta_read_deg"] = [h1(r, enc) for r in radial]
        cols["t_s"] = [r["t_s"] for r in radial]
        w.write_table("radial_motion", cols)
    poly = by_proc.get("polygon", [])
    if poly:
        pp = next(p for p in cfg.procedures if p["type"].startswith("polygon"))
        enc, ac = pp.get("encoder", "encoder"), pp.get("autocollimator", "autocollimator")
        w.write_table("polygon", {
            "shift_deg": [r["tag"]["shift_deg"] for r in poly], "start_face": [r["tag"]["start_face"] for r in poly],
            "step": [r["tag"]["step"] for r in poly], "theta_deg": [theta(r, enc) for r in poly],
            "ac_arcsec": [_reading(r, ac)["x_arcsec"] for r in poly],
            "t_s": [r["t_s"] for r in poly], "rep": [r["tag"]["rep"] for r in poly],
            "direction": [r["tag"]["direction"] for r in poly],
            "ac_y_arcsec": [_reading(r, ac)["y_arcsec"] for r in poly],
            "theta_read_deg": [h1(r, enc) for r in poly]})
    sc_rows = by_proc.get("selfcal", [])
    if sc_rows:
        enc = enc_of.get("selfcal", "encoder")
        res = float(cfg.geometry.get("encoder_resolution_arcsec", 0.0))
        hc: dict[str, list] = {"theta_deg": [], "head": [], "delta_arcsec": [], "rep": [], "direction": [],
                               "theta_read_deg": [], "t_s": []}
        for r in sc_rows:
            a = _reading(r, enc)["angle_deg"]
            for j, aj in enumerate(a):
                hc["theta_deg"].append(theta(r, enc))
                hc["theta_read_deg"].append(float(a[0]))
                hc["head"].append(j + 1)
                hc["delta_arcsec"].append(_quantise((a[0] - aj) * 3600.0, res))
                hc["rep"].append(r["tag"]["rep"])
                hc["direction"].append(r["tag"]["direction"])
                hc["t_s"].append(r["t_s"])
        w.write_table("heads", hc)
