"""The dataset tables from the runner's rows, one row at a time (``TableSink``) — the one mapping from
procedure rows to the tables of the dataset format (docs/dataset-format.md), used by ``acquire``
(real or emulated instruments) and by the twin's ``simulate`` alike. Imports no driver, so the twin
and its emulators can use it.
"""

from __future__ import annotations

from typing import Any

from benchtwin.analysis.dataset import DatasetWriter, TableAppender
from benchtwin.units import quantise

from .runner import RunnerError


def _reading(row: dict, name: str) -> dict:
    return row["readings"][name]


class TableSink:
    """The runner's sink (``acquire`` streams into it; ``simulate`` feeds it the run's rows): each row
    becomes its table row(s) at once: ``radial_motion.csv``, ``polygon.csv``, ``heads.csv`` (one row per
    head and reading) and, for a CCD sweep, ``ccd/index.csv`` + ``ccd/img_KKK.png`` (the image is
    written when the frame is taken, before the row is journaled; a replayed capture row checks
    that its image is there). Tables are opened at their first row (``DatasetWriter.open_table``);
    ``close()`` finishes them atomically, ``abort()`` removes the part files (a run that failed:
    every row taken is in the journal, which a resume replays through a new sink)."""

    def __init__(self, writer: DatasetWriter, *, probes: list[str], resolution_arcsec: float,
                 theta: str = "target", encoder_of: dict[str, str] | None = None,
                 autocollimator: str = "autocollimator"):
        """``probes``: the radial-motion probe instruments, in column order (``<name>_um``);
        ``resolution_arcsec``: the encoder's, for the heads' differences; ``theta``: ``"encoder"`` →
        theta_deg is head 1's displayed reading, else the stop's commanded encoder position;
        ``encoder_of``: rows' procedure tag → encoder instrument name (default ``"encoder"``)."""
        self.w = writer
        self.tables: dict[str, TableAppender] = {}
        self.enc_of = dict(encoder_of or {})
        self.ac = autocollimator
        self.probes = list(probes)
        self.res = float(resolution_arcsec)
        self.theta_mode = theta
        self._ccd_read: tuple[Any, float] | None = None
        self.rows = 0

    def _table(self, name: str, columns: list[str]) -> TableAppender:
        t = self.tables.get(name)
        if t is None:
            t = self.tables[name] = self.w.open_table(name, columns)
        return t

    def _theta(self, r: dict, h1: float) -> float:
        return h1 if self.theta_mode == "encoder" else float(r["tag"]["target_deg"])

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
        if "sweep" in r["tag"]:   # repeated sweeps (ccd_sweep reps > 1): the sweep index is kept
            self._table("ccd/index", ["k", "theta_deg", "file", "theta_read_deg", "t_s", "sweep"]).append(
                [k, self._theta(r, h1), f, h1, r["t_s"], int(r["tag"]["sweep"])])
            return
        self._table("ccd/index", ["k", "theta_deg", "file", "theta_read_deg", "t_s"]).append(
            [k, self._theta(r, h1), f, h1, r["t_s"]])

    def close(self) -> None:
        for t in self.tables.values():
            t.close()

    def abort(self) -> None:
        for t in self.tables.values():
            t.abort()
