"""Dataset format v1: the one contract between the twin, the hardware and the analysis.

A dataset is a directory (documented in docs/dataset-format.md)::

    manifest.json          format, version, source, bench geometry, ccd geometry
    radial_motion.csv      rep, theta_deg, probe_top_um, probe_bottom_um [, probe_*_x_um, probe_axial_um, probe_face_um]
    ccd/index.csv          k, theta_deg, file          (+ the PNG images it names)
    polygon.csv            shift_deg, start_face, step, theta_deg, ac_arcsec, t_s [, rep, direction]
    heads.csv              theta_deg, head, delta_arcsec [, rep, direction]
    truth (folder)         written by the twin only; the analysis never opens it

Readers validate what they read and name file, row and column in every error; extra columns and
files are allowed and ignored. They are strict (issue #13, docs/reliability.md): one number grammar
(``benchtwin.schema.parse_float``: ASCII decimal, no ``_``, finite, no overflow), a range or an
enumeration for every column (``TableSpec.ranges``/``choices``), every table a regular file inside
the dataset (no symlink out of it; an error never shows a line of a file outside it), every CCD
image named by a relative path that stays inside the dataset, one frame size for all images with
``reference_px`` inside it, frames checked against ``theta_read_deg`` (swapped angles) and against
each other (a duplicated or identical frame), and limits on sizes, counts, cell length and nesting. Writers write each file atomically (temporary file + rename) so an
interrupted writer never leaves a half file behind.

This module is in ``analysis`` because the analysis is the format's reader; the twin and the
hardware layer import it to write (the import direction the layering allows).
"""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.jsonable import json_default

from benchtwin.fsio import OutputError, atomic_write_bytes, check_output_dir, raise_if_disk_full
from benchtwin.schema import (MAX_CELL_CHARS, SchemaError, csv_rows, is_number, loads_json, parse_float, parse_int,
                              read_input_text, resolve_inside, check_relative_name)

FORMAT = "bench-dataset"
VERSION = 1
SOURCES = ("twin", "hardware", "emulated", "external")
TRUTH_DIR = "truth"  # named once, for writers; readers in analysis/ never use it


class DatasetError(ValueError):
    """A dataset that does not follow format v1; the message names file, row and column."""


@dataclass(frozen=True)
class TableSpec:
    required: dict[str, type]
    optional: dict[str, type]
    key: tuple[str, ...]  # columns that identify a row (duplicates are an error)
    # inclusive (lo, hi) of numeric columns (any column ending in _deg/_arcsec/_um/_s not listed
    # takes the default range of its unit, _UNIT_RANGES), and the allowed values of text columns
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    choices: dict[str, tuple[str, ...]] = field(default_factory=dict)


# Limits (issue #13: 36 000 frames ≈ 42 GB were accepted). The largest scenario the schema allows
# gives radial_reps·radial_positions = 10·100 000 = 1e6 rows; a real sweep is far below these.
MAX_TABLE_BYTES = 512 * 1024 * 1024
MAX_ROWS = 2_000_000
MAX_CCD_FRAMES = 720          # one frame every 0.5°; Jia sec. 4.2 takes one every 6° (60 frames)
MAX_IMAGE_BYTES = 64 * 1024 * 1024
MAX_IMAGE_PIXELS = 20000 * 20000  # the scenario's largest sensor (instruments.ccd width/height)
MAX_MANIFEST_BYTES = 1024 * 1024
DIRECTIONS = ("forward", "backward")

# Default ranges by unit suffix: angles of a turn (a reading may run past 360° by a shift or a
# backward overshoot, never by turns: 7200° is an error), error angles of at most 10° (the
# autocollimator's largest range in the scenario schema), probe readings within ±10 mm (the
# largest probe range), times of at most a year of running.
_UNIT_RANGES: dict[str, tuple[float, float]] = {
    "_deg": (-360.0, 720.0),
    "_arcsec": (-36000.0, 36000.0),
    "_um": (-10000.0, 10000.0),
    "_s": (0.0, 3.2e7),
}
THETA_RANGE = (-360.0, 720.0)
#: the Fourier order ``analyze`` uses unless told (``--order``; Jia eqs. 6 and 10: order 10)
ANALYSIS_ORDER = 10
#: the orders ``--order`` accepts (the largest needs a revolution of 2·1000 + 1 angles)
ORDER_RANGE = (1, 1000)


TABLES: dict[str, TableSpec] = {
    "radial_motion": TableSpec(
        {"rep": int, "theta_deg": float, "probe_top_um": float, "probe_bottom_um": float},
        {"probe_top_x_um": float, "probe_bottom_x_um": float, "theta_read_deg": float, "t_s": float,
         "probe_axial_um": float, "probe_face_um": float},
        ("rep", "theta_deg"),
        ranges={"rep": (0, 10000)},
    ),
    # ISO 230-7 continuous-rotation run (twin/continuous.py): probes sampled in time while turning
    "radial_continuous": TableSpec(
        {"t_s": float, "theta_deg": float, "probe_top_um": float, "probe_bottom_um": float},
        {"probe_top_x_um": float, "probe_bottom_x_um": float, "probe_axial_um": float, "probe_face_um": float},
        ("t_s",),
    ),
    "ccd/index": TableSpec({"k": int, "theta_deg": float, "file": str},
                           {"theta_read_deg": float, "t_s": float, "sweep": int},
                           ("k",), ranges={"k": (0, 10**6), "sweep": (0, 1000)}),
    "polygon": TableSpec(
        {"shift_deg": float, "start_face": int, "step": int, "theta_deg": float, "ac_arcsec": float, "t_s": float},
        {"rep": int, "direction": str, "theta_read_deg": float, "ac_y_arcsec": float},
        ("shift_deg", "start_face", "step", "rep", "direction"),
        ranges={"shift_deg": (-360.0, 360.0), "rep": (0, 10000)}, choices={"direction": DIRECTIONS},
    ),
    "heads": TableSpec(
        {"theta_deg": float, "head": int, "delta_arcsec": float},
        {"rep": int, "direction": str, "theta_read_deg": float, "t_s": float},
        ("theta_deg", "head", "rep", "direction"),
        ranges={"rep": (0, 10000)}, choices={"direction": DIRECTIONS},
    ),
    # an "error curve" dataset (kind "error-curve"): a measured encoder error α(θ), e.g. a lab's table
    # from an earlier calibration (benchtwin import); α = reading − reference, arcsec
    "error_curve": TableSpec(
        {"theta_deg": float, "error_arcsec": float},
        {"direction": str, "u_arcsec": float},
        ("theta_deg", "direction"),
    ),
}
#: manifest "kind": a bench dataset (default, the bench geometry required) or an error curve (an
#: imported α(θ) table: the bench keys are optional, they are unknown for most old tables)
KINDS = ("bench", "error-curve")
DIRECTIONS = ("forward", "backward")


def column_range(spec: TableSpec | None, col: str) -> tuple[float, float] | None:
    """The inclusive range of a numeric column: the spec's own, else its unit's default."""
    if spec is not None and col in spec.ranges:
        return spec.ranges[col]
    for suffix, rng in _UNIT_RANGES.items():
        if col.endswith(suffix):
            return rng
    return None

# manifest["bench"]: key -> (type, required)
BENCH_KEYS: dict[str, tuple[type, bool]] = {
    "optical_radius_mm": (float, True),
    "L1_mm": (float, True),
    "L2_mm": (float, True),
    "grating_period_um": (float, True),
    "polygon_faces": (int, True),
    "encoder_lines": (int, False),
    "scale_edge_radius_mm": (float, False),
    "heads_deg": (list, False),
    "encoder_resolution_arcsec": (float, False),
    "polygon_certificate_arcsec": (list, False),
    # the autocollimator's declared resolution and maximum error (GUM type B inputs of Hsieh's
    # budget, sec. 3.3 (2) and (4)); without them the analysis assumes Hsieh's ELCOMAT 3000 and says so
    "autocollimator_resolution_arcsec": (float, False),
    "autocollimator_accuracy_arcsec": (float, False),
    # the other type B inputs of Hsieh's budget (sec. 3.3 (3), (8)): the autocollimator's calibration
    # (expanded uncertainty and its k) and the polygon's setup misalignment; without them the analysis
    # uses Hsieh's values, names them in results.json (budget_inputs) and says so
    "autocollimator_traceability_U_arcsec": (float, False),
    "autocollimator_traceability_k": (float, False),
    "polygon_setup_misalignment_arcsec": (float, False),
    # {name: order per revolution} of the bearings (cage, ball pass): marks in the continuous run's spectrum
    "bearing_kinematic_orders": (dict, False),
}
CCD_KEYS: dict[str, tuple[type, bool]] = {
    "position_deg": (float, True),
    "outward": (str, True),
    "tangential": (str, True),
    "reference_px": (list, True),
    "pixel_um": (float, False),
}


# --------------------------------------------------------------------------- manifest


def validate_manifest(m: Any, where: str = "manifest.json") -> dict[str, Any]:
    """Check a manifest mapping; returns it unchanged or raises DatasetError naming the key."""
    if not isinstance(m, Mapping):
        raise DatasetError(f"{where}: expected a JSON object at the top level")
    if m.get("format") != FORMAT:
        raise DatasetError(f"{where}: key 'format': expected {FORMAT!r}, got {m.get('format')!r}")
    if m.get("version") != VERSION:
        raise DatasetError(f"{where}: key 'version': expected {VERSION}, got {m.get('version')!r}")
    if m.get("source") not in SOURCES:
        raise DatasetError(f"{where}: key 'source': expected one of {SOURCES}, got {m.get('source')!r}")
    kind = m.get("kind", "bench")
    if kind not in KINDS:
        raise DatasetError(f"{where}: key 'kind': expected one of {KINDS}, got {kind!r}")
    bench = m.get("bench")
    if kind == "error-curve":
        if not isinstance(bench, Mapping):
            raise DatasetError(f"{where}: key 'bench': expected an object (may be empty for an error curve)")
        _check_keys(bench, {k: (t, False) for k, (t, _) in BENCH_KEYS.items()}, f"{where}: bench")
        return dict(m)
    if not isinstance(bench, Mapping):
        raise DatasetError(f"{where}: key 'bench': expected an object with {', '.join(k for k, (_, r) in BENCH_KEYS.items() if r)}")
    _check_keys(bench, BENCH_KEYS, f"{where}: bench")
    for key, (lo, hi) in BENCH_RANGES.items():
        v = bench.get(key)
        if v is not None and not lo <= v <= hi:
            raise DatasetError(f"{where}: bench.{key}: expected {lo:g}…{hi:g}, got {v!r}")
    if bench["optical_radius_mm"] <= 0:
        raise DatasetError(f"{where}: bench.optical_radius_mm: expected > 0 mm, got {bench['optical_radius_mm']}")
    if bench["polygon_faces"] < 3:
        raise DatasetError(f"{where}: bench.polygon_faces: expected an integer >= 3, got {bench['polygon_faces']}")
    if not 0 <= bench["L1_mm"] < bench["L2_mm"]:
        raise DatasetError(f"{where}: bench.L1_mm/L2_mm: expected 0 <= L1 < L2, got {bench['L1_mm']}, {bench['L2_mm']}")
    if "heads_deg" in bench:
        heads = bench["heads_deg"]
        if not 1 <= len(heads) <= MAX_HEADS or not all(_is_number(h) and 0.0 <= h < 360.0 for h in heads):
            raise DatasetError(f"{where}: bench.heads_deg: expected 1…{MAX_HEADS} azimuths in degrees, each in [0, 360)")
        if len(set(heads)) != len(heads):
            raise DatasetError(f"{where}: bench.heads_deg: two heads at the same azimuth")
    if "polygon_certificate_arcsec" in bench:
        cert = bench["polygon_certificate_arcsec"]
        if len(cert) != bench["polygon_faces"] or not all(_is_number(c) and abs(c) <= 3600.0 for c in cert):
            raise DatasetError(f"{where}: bench.polygon_certificate_arcsec: expected {bench['polygon_faces']} numbers "
                               "of at most ±3600 arcsec")
    if "ccd" in m:
        ccd = m["ccd"]
        if not isinstance(ccd, Mapping):
            raise DatasetError(f"{where}: key 'ccd': expected an object")
        _check_keys(ccd, CCD_KEYS, f"{where}: ccd")
        if ccd["outward"] != "+x":
            raise DatasetError(f"{where}: ccd.outward: expected '+x' (image +x radially outward), got {ccd['outward']!r}")
        if ccd["tangential"] not in ("+x", "-x"):
            raise DatasetError(f"{where}: ccd.tangential: expected '+x' or '-x', got {ccd['tangential']!r}")
        ref = ccd["reference_px"]
        if len(ref) != 2 or not all(_is_number(v) and 0 <= v <= 20000 for v in ref):
            raise DatasetError(f"{where}: ccd.reference_px: expected [x, y] in pixels (0…20000), got {_short(ref)}")
        if not 0.0 <= ccd["position_deg"] < 360.0:
            raise DatasetError(f"{where}: ccd.position_deg: expected [0, 360) degrees, got {ccd['position_deg']!r}")
        if "pixel_um" in ccd and not 0.01 <= ccd["pixel_um"] <= 100.0:
            raise DatasetError(f"{where}: ccd.pixel_um: expected 0.01…100 µm, got {ccd['pixel_um']!r}")
    return dict(m)


def _is_number(x: Any) -> bool:
    return is_number(x)


def _short(v: Any, n: int = 60) -> str:
    s = repr(v)
    return s if len(s) <= n else s[: n - 1] + "…"


MAX_HEADS = 64
# manifest bench ranges, in the manifest's units (the scenario schema's bounds, twin/scenario_schema.py)
BENCH_RANGES: dict[str, tuple[float, float]] = {
    "optical_radius_mm": (1.0, 1000.0),
    "L1_mm": (0.0, 2000.0),
    "L2_mm": (1.0, 2000.0),
    "grating_period_um": (0.1, 1000.0),
    "polygon_faces": (3, 360),
    "encoder_lines": (0, 10_000_000),
    "scale_edge_radius_mm": (1.0, 1000.0),
    "encoder_resolution_arcsec": (0.0, 3600.0),
    "autocollimator_resolution_arcsec": (0.0, 3600.0),
    "autocollimator_accuracy_arcsec": (0.0, 3600.0),
    "autocollimator_traceability_U_arcsec": (0.0, 3600.0),
    "autocollimator_traceability_k": (1.0, 10.0),
    "polygon_setup_misalignment_arcsec": (0.0, 3600.0),
}


def _check_keys(d: Mapping[str, Any], spec: Mapping[str, tuple[type, bool]], where: str) -> None:
    for key, (typ, required) in spec.items():
        if key not in d:
            if required:
                raise DatasetError(f"{where}.{key}: missing (expected {typ.__name__})")
            continue
        v = d[key]
        ok = (
            _is_number(v) if typ is float
            else (isinstance(v, int) and not isinstance(v, bool)) if typ is int
            else isinstance(v, typ)
        )
        if not ok:
            raise DatasetError(f"{where}.{key}: expected {typ.__name__}, got {_short(v)}")


# --------------------------------------------------------------------------- writer


_atomic_write = atomic_write_bytes  # the project's one atomic writer (benchtwin.fsio)


def _cell(v: Any) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "1" if v else "0"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))  # shortest repr that round-trips exactly
    return str(v)


def table_to_csv(columns: Mapping[str, Sequence[Any]]) -> bytes:
    """Columns (name -> equal-length sequences) as CSV bytes, floats written to round-trip."""
    names = list(columns)
    cols = [list(np.asarray(columns[n]).tolist()) if isinstance(columns[n], np.ndarray) else list(columns[n]) for n in names]
    lengths = {len(c) for c in cols}
    if len(lengths) > 1:
        raise DatasetError(f"columns of unequal length: {dict(zip(names, map(len, cols)))}")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(names)
    for row in zip(*cols):
        w.writerow([_cell(v) for v in row])
    return buf.getvalue().encode("utf-8")


def encode_png(where: str, image: np.ndarray) -> bytes:
    """A dataset image's PNG bytes (2-D uint8/uint16 greyscale, OpenCV's default level): the one
    encoder of ``DatasetWriter.write_image`` and of the twin's frame pipeline
    (twin/render/pipeline.py), so both write the same bytes. ``where`` names the image in errors."""
    import cv2

    arr = np.asarray(image)
    if arr.ndim != 2 or arr.dtype not in (np.uint8, np.uint16):
        raise DatasetError(f"{where}: expected a 2-D uint8/uint16 greyscale image, got {arr.shape} {arr.dtype}")
    ok, png = cv2.imencode(".png", arr)
    if not ok:
        raise DatasetError(f"{where}: PNG encoding failed")
    return png.tobytes()


class TableAppender:
    """One table written row by row (flat memory for long acquisitions), finished atomically.

    Rows go to ``.<name>.csv.part`` next to the final file, flushed after every ``append``;
    ``close()`` fsyncs and renames it to ``<name>.csv`` (the bytes ``table_to_csv`` gives for the
    same rows), ``abort()`` removes it. Reopening truncates the part file (a resumed run rewrites
    the table from its journal)."""

    def __init__(self, path: Path, columns: Sequence[str]):
        self.path = Path(path)
        self.columns = list(columns)
        if len(set(self.columns)) != len(self.columns):
            raise DatasetError(f"{self.path.name}: duplicated column names {self.columns}")
        self.part = self.path.with_name(f".{self.path.name}.part")
        self.rows = 0
        try:
            self.part.parent.mkdir(parents=True, exist_ok=True)
            self._fh = open(self.part, "w", encoding="utf-8", newline="")
            self._w = csv.writer(self._fh, lineterminator="\n")
            self._w.writerow(self.columns)
            self._fh.flush()
        except OSError as exc:
            raise_if_disk_full(exc, self.part)
            raise

    def append(self, row: Mapping[str, Any] | Sequence[Any]) -> None:
        """One row: a mapping with every column, or a sequence in column order."""
        if isinstance(row, Mapping):
            missing = [c for c in self.columns if c not in row]
            if missing:
                raise DatasetError(f"{self.path.name}: row {self.rows + 2}: missing columns {missing}")
            row = [row[c] for c in self.columns]
        elif len(row) != len(self.columns):
            raise DatasetError(f"{self.path.name}: row {self.rows + 2}: expected {len(self.columns)} values, "
                               f"got {len(row)}")
        try:
            self._w.writerow([_cell(v) for v in row])
            self._fh.flush()
        except OSError as exc:  # a full disk names the table (benchtwin.fsio.DiskFullError)
            raise_if_disk_full(exc, self.part)
            raise
        self.rows += 1

    def close(self) -> Path:
        try:
            self._fh.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()
        except OSError as exc:
            raise_if_disk_full(exc, self.part)
            raise
        os.replace(self.part, self.path)
        return self.path

    def abort(self) -> None:
        if not self._fh.closed:
            try:
                self._fh.close()
            except OSError:     # the rows it could not flush (a full disk): the file goes anyway
                pass
        if self.part.exists():
            self.part.unlink()


JOURNAL = "journal.jsonl"  # the run journal simulate and acquire keep in the dataset folder


class DatasetWriter:
    """Write a dataset directory. The manifest is validated first and written last: it is the
    completion marker (a folder without it is unfinished, and ``Dataset`` refuses it).

    The folder must be new or empty (``force``: its contents are removed first; ``resume``: it holds
    the journal of an unfinished run, which continues) so a dataset never mixes two runs' files
    (issue #13: scenario B simulated over A's folder kept A's heads.csv). ``prepared=True``: the
    caller has already checked the folder with ``benchtwin.fsio.check_output_dir``."""

    def __init__(self, path: str | Path, manifest: Mapping[str, Any], *, force: bool = False,
                 resume: bool = False, prepared: bool = False, truth_to: str | Path | None = None):
        self.path = Path(path)
        # where write_truth_* go: the dataset's TRUTH_DIR by default; `benchtwin run` puts the
        # truth beside the dataset, never in it (principle 3), written while the analysis runs
        self.truth_path = Path(truth_to) if truth_to is not None else self.path / TRUTH_DIR
        self.manifest = validate_manifest(dict(manifest), f"{self.path}/manifest.json")
        if not prepared:
            try:
                check_output_dir(self.path, force=force, resume=resume, resume_marker=JOURNAL,
                                 what="dataset folder")
            except OutputError as exc:
                raise DatasetError(str(exc)) from None
        self.path.mkdir(parents=True, exist_ok=True)
        stale = self.path / "manifest.json"
        if resume and stale.is_file():  # resuming a run that had finished: complete again only when closed
            stale.unlink()

    def write_table(self, name: str, columns: Mapping[str, Sequence[Any]]) -> Path:
        if name in TABLES:
            missing = [c for c in TABLES[name].required if c not in columns]
            if missing:
                raise DatasetError(f"{name}.csv: missing required columns {missing}")
        p = self.path / f"{name}.csv"
        _atomic_write(p, table_to_csv(columns))
        return p

    def open_table(self, name: str, columns: Sequence[str]) -> TableAppender:
        """A table written row by row (``TableAppender``); same checks and bytes as ``write_table``."""
        if name in TABLES:
            missing = [c for c in TABLES[name].required if c not in columns]
            if missing:
                raise DatasetError(f"{name}.csv: missing required columns {missing}")
        return TableAppender(self.path / f"{name}.csv", columns)

    def write_image(self, relpath: str, image: np.ndarray) -> Path:
        p = self.path / relpath
        _atomic_write(p, encode_png(relpath, image))
        return p

    def write_truth_json(self, name: str, obj: Any) -> Path:
        p = self.truth_path / name
        _atomic_write(p, (json.dumps(obj, indent=1, sort_keys=True, default=_json_default) + "\n").encode())
        return p

    def write_truth_table(self, name: str, columns: Mapping[str, Sequence[Any]]) -> Path:
        p = self.truth_path / f"{name}.csv"
        _atomic_write(p, table_to_csv(columns))
        return p

    def close(self) -> Path:
        p = self.path / "manifest.json"
        _atomic_write(p, (json.dumps(self.manifest, indent=1, sort_keys=True) + "\n").encode())
        return p

    def __enter__(self) -> "DatasetWriter":
        return self

    def __exit__(self, exc_type, *_: Any) -> None:
        if exc_type is None:
            self.close()


_json_default = json_default  # the one numpy -> JSON conversion (benchtwin/jsonable.py)

# --------------------------------------------------------------------------- reader


def parse_table(text: str, name: str, where: str, spec: TableSpec | None = None) -> dict[str, np.ndarray]:
    """Parse and validate CSV text of table ``name``; errors name ``where``, the row and column.

    Rows are numbered as in a text editor (the header is row 1)."""
    spec = spec or TABLES.get(name)
    rows = csv_rows(text, where, DatasetError)
    try:
        _, header = next(rows)
    except StopIteration:
        raise DatasetError(f"{where}: empty file (expected a header row)") from None
    header = [h.strip() for h in header]
    if len(header) > 256 or any(len(h) > 128 for h in header):
        raise DatasetError(f"{where}: row 1: expected at most 256 column names of at most 128 characters")
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise DatasetError(f"{where}: row 1: duplicated column names {dup}")
    types: dict[str, type] = {}
    if spec is not None:
        missing = [c for c in spec.required if c not in header]
        if missing:
            raise DatasetError(f"{where}: row 1: missing required columns {missing} (has {header})")
        types = {**spec.required, **spec.optional}
    raw: dict[str, list[Any]] = {h: [] for h in header}
    n_rows = 0
    for rowno, row in rows:
        if not row or all(not c.strip() for c in row):
            continue
        n_rows += 1
        if n_rows > MAX_ROWS:
            raise DatasetError(f"{where}: more than {MAX_ROWS} rows; a table may have at most {MAX_ROWS}")
        if len(row) != len(header):
            raise DatasetError(f"{where}: row {rowno}: expected {len(header)} fields, got {len(row)}")
        for h, cell in zip(header, row):
            if len(cell) > MAX_CELL_CHARS:
                raise DatasetError(f"{where}: row {rowno}, column {h!r}: a cell of {len(cell)} characters; "
                                   f"at most {MAX_CELL_CHARS} are allowed")
            raw[h].append(_parse_cell(cell.strip(), types.get(h), where, rowno, h, spec))
    out: dict[str, np.ndarray] = {}
    for h, vals in raw.items():
        t = types.get(h)
        if t is int:
            out[h] = np.asarray(vals, dtype=np.int64)
        elif t is float:
            out[h] = np.asarray(vals, dtype=np.float64)
        else:
            out[h] = np.asarray(vals, dtype=object)
    if spec is not None:
        _check_duplicates(out, spec, where)
    return out


def _parse_cell(cell: str, typ: type | None, where: str, rowno: int, col: str,
                spec: TableSpec | None = None) -> Any:
    """One cell by the one number grammar (benchtwin.schema), checked against its column's range
    or enumeration."""
    at = f"{where}: row {rowno}, column {col!r}"
    if typ is None or typ is str:
        allowed = spec.choices.get(col) if spec is not None else None
        if allowed is not None and cell not in allowed:
            raise DatasetError(f"{at}: expected one of {', '.join(allowed)}, got {_short(cell)}")
        return cell
    if typ is int:
        try:
            x: float = parse_int(cell)
        except ValueError as exc:
            raise DatasetError(f"{at}: {exc}, got {_short(cell)}") from None
    else:
        try:
            x = parse_float(cell)
        except ValueError as exc:
            msg = str(exc)
            if cell.lower().lstrip("+-") in ("nan", "inf", "infinity"):
                msg = "expected a finite number"
            raise DatasetError(f"{at}: {msg}, got {_short(cell)}") from None
    rng = column_range(spec, col) if spec is not None else None
    if rng is not None and not rng[0] <= x <= rng[1]:
        raise DatasetError(f"{at}: expected {rng[0]:g}…{rng[1]:g}, got {cell}")
    return x


def _check_duplicates(cols: Mapping[str, np.ndarray], spec: TableSpec, where: str) -> None:
    keys = [k for k in spec.key if k in cols]
    n = len(next(iter(cols.values()))) if cols else 0
    seen: dict[tuple, int] = {}
    for i in range(n):
        key = tuple(cols[k][i] for k in keys)
        if key in seen:
            desc = ", ".join(f"{k}={v}" for k, v in zip(keys, key))
            raise DatasetError(f"{where}: rows {seen[key] + 2} and {i + 2}: duplicated reading ({desc})")
        seen[key] = i


class Dataset:
    """A dataset directory opened for reading. Validation happens on access and in ``validate()``."""

    def __init__(self, path: str | Path, order: int = ANALYSIS_ORDER):
        self.path = Path(path)
        # the Fourier order the analysis will use: check_tables checks what it needs of the tables
        # (analysis/structure.py: the angles a revolution or a CCD sweep needs)
        if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or \
                not ORDER_RANGE[0] <= order <= ORDER_RANGE[1]:
            raise DatasetError(f"Fourier order (analyze --order): expected an integer {ORDER_RANGE[0]}…"
                               f"{ORDER_RANGE[1]}, got {order!r}")
        self.order = int(order)
        if not self.path.is_dir():
            raise DatasetError(f"{self.path}: not a dataset directory")
        mp = self.path / "manifest.json"
        if not mp.exists() and not mp.is_symlink():
            raise DatasetError(f"{mp}: missing (every dataset starts with its manifest)")
        try:
            text = read_input_text(mp, max_bytes=MAX_MANIFEST_BYTES, what="manifest", root=self.path)
            m = loads_json(text, str(mp))
        except SchemaError as exc:
            raise DatasetError(str(exc).replace(": not valid JSON", ": not valid JSON", 1)) from None
        self.manifest = validate_manifest(m, str(mp))
        self._cache: dict[str, dict[str, np.ndarray]] = {}

    @property
    def bench(self) -> dict[str, Any]:
        return self.manifest["bench"]

    def has(self, name: str) -> bool:
        """The table is present: anything under its name counts (a folder or a dangling symlink
        there is an error when read, never a silently missing section)."""
        p = self.path / f"{name}.csv"
        return p.exists() or p.is_symlink()

    def tables(self) -> list[str]:
        """The known tables present in the dataset."""
        return [name for name in TABLES if self.has(name)]

    def require_tables(self) -> list[str]:
        """The tables present; a dataset with none is an error (issue #13: analyze exited 0)."""
        names = self.tables()
        if not names:
            raise DatasetError(f"{self.path}: no data tables (expected at least one of "
                               f"{', '.join(t + '.csv' for t in TABLES)})")
        return names

    def table(self, name: str) -> dict[str, np.ndarray]:
        if name not in self._cache:
            p = self.path / f"{name}.csv"
            if not self.has(name):
                raise DatasetError(f"{p}: missing")
            try:
                text = read_input_text(p, max_bytes=MAX_TABLE_BYTES, what="CSV table", root=self.path)
            except SchemaError as exc:
                raise DatasetError(str(exc)) from None
            cols = parse_table(text, name, str(p))
            self._check_semantics(name, cols, p)
            from benchtwin.analysis.structure import check_structure

            # the structure the analysis assumes (issue 31: a revolution cut short passed every cell check)
            check_structure(name, cols, str(p), self.bench)
            self._cache[name] = cols
        return self._cache[name]

    @property
    def kind(self) -> str:
        return str(self.manifest.get("kind", "bench"))

    def _check_semantics(self, name: str, cols: Mapping[str, np.ndarray], p: Path) -> None:
        if name == "error_curve":
            if "direction" in cols:
                wrong = [i for i, d in enumerate(cols["direction"]) if d not in DIRECTIONS]
                if wrong:
                    raise DatasetError(f"{p}: row {wrong[0] + 2}, column 'direction': expected one of {DIRECTIONS}, "
                                       f"got {cols['direction'][wrong[0]]!r}")
            if "u_arcsec" in cols:
                bad = np.flatnonzero(cols["u_arcsec"] <= 0)
                if bad.size:
                    raise DatasetError(f"{p}: row {bad[0] + 2}, column 'u_arcsec': expected > 0")
            return
        if self.kind == "error-curve":
            raise DatasetError(f"{p}: an error-curve dataset holds error_curve.csv only")
        n_faces = self.bench["polygon_faces"]
        if name == "polygon":
            for col in ("start_face", "step"):
                bad = np.flatnonzero((cols[col] < 1) | (cols[col] > n_faces))
                if bad.size:
                    raise DatasetError(
                        f"{p}: row {bad[0] + 2}, column {col!r}: expected 1…{n_faces} (bench.polygon_faces), "
                        f"got {cols[col][bad[0]]}" + (f" (and {bad.size - 1} more rows)" if bad.size > 1 else "")
                    )
        if name == "heads":
            nh = len(self.bench.get("heads_deg", []))
            if nh == 0:
                raise DatasetError(f"{p}: heads table present but manifest bench.heads_deg is missing")
            bad = np.flatnonzero((cols["head"] < 1) | (cols["head"] > nh))
            if bad.size:
                raise DatasetError(f"{p}: row {bad[0] + 2}, column 'head': expected 1…{nh}, got {cols['head'][bad[0]]}")
        if name == "radial_motion":
            bad = np.flatnonzero(cols["rep"] < 0)
            if bad.size:
                raise DatasetError(f"{p}: row {bad[0] + 2}, column 'rep': expected >= 0")
        if name == "ccd/index":
            self._check_ccd_index(cols, p)

    def _check_ccd_index(self, cols: Mapping[str, np.ndarray], p: Path) -> None:
        """The CCD sweep's index: a bounded number of frames, each file named once, each angle
        once, and (with ``theta_read_deg``) every commanded angle next to the encoder's reading of
        it: swapped or shifted angles are caught here (issue #13)."""
        n = len(cols["k"])
        if n > MAX_CCD_FRAMES:
            raise DatasetError(f"{p}: {n} CCD frames; at most {MAX_CCD_FRAMES} are allowed (one every 0.5°)")
        if "ccd" not in self.manifest:
            raise DatasetError(f"{self.path / 'manifest.json'}: key 'ccd' is required when ccd/index.csv is present")
        seen: dict[str, int] = {}
        for i, f in enumerate(cols["file"]):
            key = str(f).strip()
            if key in seen:
                raise DatasetError(f"{p}: rows {seen[key] + 2} and {i + 2}: the same image file {key!r} twice")
            seen[key] = i
        th = np.asarray(cols["theta_deg"], dtype=float)
        # repeated sweeps (optional column ``sweep``): each angle once per sweep
        sweeps = np.asarray(cols["sweep"], dtype=int) if "sweep" in cols else np.zeros(n, dtype=int)
        min_gap = 360.0
        for sw in np.unique(sweeps):
            rows = np.flatnonzero(sweeps == sw)
            wrapped = np.sort(np.mod(th[rows], 360.0), kind="stable")
            order = np.argsort(np.mod(th[rows], 360.0), kind="stable")
            same = np.flatnonzero(np.diff(wrapped) == 0.0)
            if same.size:
                a, b = sorted((int(rows[order[same[0]]]), int(rows[order[same[0] + 1]])))
                in_sweep = f" of sweep {int(sw)}" if "sweep" in cols else ""
                raise DatasetError(f"{p}: rows {a + 2} and {b + 2}: two frames{in_sweep} at the same angle "
                                   f"theta_deg = {th[a]:g}")
            if rows.size > 1:
                min_gap = min(min_gap, float(np.min(np.diff(np.concatenate([wrapped, wrapped[:1] + 360.0])))))
        if "theta_read_deg" in cols and n >= 1:
            # a reading belongs to its own commanded angle: within half the closest spacing of two
            # frames (else it is nearer another frame's angle: swapped rows) and within 1° (the
            # encoder's error is arcseconds; Jia eq. 5 with e/r ≤ 5 % stays well below)
            tol = min(1.0, 0.5 * min_gap)
            d = np.abs((np.asarray(cols["theta_read_deg"], dtype=float) - th + 180.0) % 360.0 - 180.0)
            bad = np.flatnonzero(d >= tol)
            if bad.size:
                i = int(bad[0])
                raise DatasetError(
                    f"{p}: row {i + 2}: theta_deg = {th[i]:g} but the encoder read theta_read_deg = "
                    f"{float(cols['theta_read_deg'][i]):g} (expected within {tol:g}°: swapped or wrong angles?)")

    def ccd_frames(self) -> Iterator[tuple[int, float, np.ndarray, str]]:
        """Yield (k, theta_deg, image, file) for every row of ccd/index.csv, checking each image:
        all frames one size, with ``ccd.reference_px`` inside it, and no two identical frames."""
        import hashlib

        idx = self.table("ccd/index")
        ref = self.manifest["ccd"]["reference_px"]
        shape: tuple[int, ...] | None = None
        first_row = 0
        digests: dict[bytes, int] = {}
        for i, (k, theta, f) in enumerate(zip(idx["k"], idx["theta_deg"], idx["file"])):
            row = i + 2
            img = self.read_image(str(f), row=row)
            where = f"{self.path / 'ccd' / 'index.csv'}: row {row}: image {str(f)!r}"
            if shape is None:
                shape, first_row = img.shape, row
                h, w = shape
                if not (0 <= ref[0] <= w - 1 and 0 <= ref[1] <= h - 1):
                    raise DatasetError(f"{where}: {w}×{h} px, but manifest ccd.reference_px = {ref} lies outside it")
            elif img.shape != shape:
                raise DatasetError(f"{where}: {img.shape[1]}×{img.shape[0]} px, but the frame of row {first_row} is "
                                   f"{shape[1]}×{shape[0]} px (expected one frame size for the whole sweep)")
            # a uniform frame (fogged, dark, saturated) carries no image: two of them are alike by
            # nature, and the image analysis rejects them with its own note; any other frame is unique
            uniform = img.size == 0 or int(img.min()) == int(img.max())
            dg = hashlib.blake2b(img.tobytes(), digest_size=16).digest()
            if not uniform and dg in digests:
                raise DatasetError(f"{where}: identical to the frame of row {digests[dg]}; a frame at another angle "
                                   "cannot be pixel-for-pixel the same (a duplicated file?)")
            digests[dg] = row
            yield int(k), float(theta), img, str(f)

    def read_image(self, relpath: str, row: int | None = None) -> np.ndarray:
        import cv2

        where = f"{self.path / 'ccd' / 'index.csv'}: row {row}: " if row else ""
        try:
            # relative to ccd/ (docs/dataset-format.md), or else to the dataset root; never outside
            # it (no absolute path, no '..', no symlink out: issue #13)
            check_relative_name(relpath, f"{where}image")  # the name as written
            in_ccd = self.path / "ccd" / relpath
            base = "" if (self.path / relpath).is_file() and not (in_ccd.exists() or in_ccd.is_symlink()) else "ccd/"
            p = resolve_inside(self.path, base + relpath, f"{where}image")
        except SchemaError as exc:
            raise DatasetError(str(exc)) from None
        if not p.exists():
            raise DatasetError(f"{where}image {relpath!r} is missing")
        if p.is_dir() or not p.is_file():
            raise DatasetError(f"{where}image {relpath!r}: not a regular file")
        size = p.stat().st_size
        if size > MAX_IMAGE_BYTES:
            raise DatasetError(f"{where}image {relpath!r}: {size} bytes; at most {MAX_IMAGE_BYTES} are allowed")
        data = np.fromfile(p, dtype=np.uint8)
        hdr = _png_size(data)
        if hdr is not None and hdr[0] * hdr[1] > MAX_IMAGE_PIXELS:
            raise DatasetError(f"{where}image {relpath!r}: {hdr[0]}×{hdr[1]} px; at most {MAX_IMAGE_PIXELS} pixels")
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
        if img is None:
            raise DatasetError(f"{where}image {p} is not a readable image")
        if img.ndim != 2:
            raise DatasetError(f"{where}image {p}: expected greyscale, got {img.shape[2]} channels")
        if img.dtype not in (np.uint8, np.uint16):
            raise DatasetError(f"{where}image {p}: expected 8- or 16-bit, got {img.dtype}")
        return img

    def check_tables(self) -> list[str]:
        """Read and check every known table (its cells and the structure the analysis assumes at
        ``self.order``); a dataset without tables is an error (issue #13: analyze exited 0). The one
        check ``validate`` and ``analyze`` both run before anything else (issue 31). Returns what
        was checked."""
        from benchtwin.analysis.structure import check_order

        checked = []
        for name in self.require_tables():
            cols = self.table(name)
            check_order(name, cols, str(self.path / f"{name}.csv"), self.order)
            checked.append(f"{name}.csv ({len(next(iter(cols.values())))} rows)")
        return checked

    def validate(self) -> list[str]:
        """Read every known table and image; returns a list of what was checked, raises on error."""
        checked = ["manifest.json", *self.check_tables()]
        if self.has("ccd/index"):
            n = sum(1 for _ in self.ccd_frames())
            checked.append(f"{n} CCD images")
        return checked


def _png_size(data: np.ndarray) -> tuple[int, int] | None:
    """(width, height) from a PNG's IHDR, before decoding it (a decompression bomb stops here)."""
    b = data[:24].tobytes()
    if len(b) == 24 and b[:8] == b"\x89PNG\r\n\x1a\n" and b[12:16] == b"IHDR":
        return int.from_bytes(b[16:20], "big"), int.from_bytes(b[20:24], "big")
    return None


def open_dataset(path: str | Path, order: int = ANALYSIS_ORDER) -> Dataset:
    """A dataset opened for reading; its tables are checked for the analysis at Fourier ``order``."""
    return Dataset(path, order)
