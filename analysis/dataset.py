"""Dataset format v1: the one contract between the twin, the hardware and the analysis.

A dataset is a directory (documented in docs/dataset-format.md)::

    manifest.json          format, version, source, bench geometry, ccd geometry
    radial_motion.csv      rep, theta_deg, probe_top_um, probe_bottom_um [, probe_*_x_um]
    ccd/index.csv          k, theta_deg, file          (+ the PNG images it names)
    polygon.csv            shift_deg, start_face, step, theta_deg, ac_arcsec, t_s [, rep, direction]
    heads.csv              theta_deg, head, delta_arcsec [, rep, direction]
    truth (folder)         written by the twin only; the analysis never opens it

Readers validate what they read and name file, row and column in every error; extra columns and
files are allowed and ignored. Writers write each file atomically (temporary file + rename) so an
interrupted writer never leaves a half file behind.

This module is in ``analysis`` because the analysis is the format's reader; the twin and the
hardware layer import it to write (the import direction the layering allows).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

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


TABLES: dict[str, TableSpec] = {
    "radial_motion": TableSpec(
        {"rep": int, "theta_deg": float, "probe_top_um": float, "probe_bottom_um": float},
        {"probe_top_x_um": float, "probe_bottom_x_um": float},
        ("rep", "theta_deg"),
    ),
    # ISO 230-7 continuous-rotation run (twin/continuous.py): probes sampled in time while turning
    "radial_continuous": TableSpec(
        {"t_s": float, "theta_deg": float, "probe_top_um": float, "probe_bottom_um": float},
        {"probe_top_x_um": float, "probe_bottom_x_um": float},
        ("t_s",),
    ),
    "ccd/index": TableSpec({"k": int, "theta_deg": float, "file": str}, {}, ("k",)),
    "polygon": TableSpec(
        {"shift_deg": float, "start_face": int, "step": int, "theta_deg": float, "ac_arcsec": float, "t_s": float},
        {"rep": int, "direction": str},
        ("shift_deg", "start_face", "step", "rep", "direction"),
    ),
    "heads": TableSpec(
        {"theta_deg": float, "head": int, "delta_arcsec": float},
        {"rep": int, "direction": str},
        ("theta_deg", "head", "rep", "direction"),
    ),
}

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
    bench = m.get("bench")
    if not isinstance(bench, Mapping):
        raise DatasetError(f"{where}: key 'bench': expected an object with {', '.join(k for k, (_, r) in BENCH_KEYS.items() if r)}")
    _check_keys(bench, BENCH_KEYS, f"{where}: bench")
    if bench["optical_radius_mm"] <= 0:
        raise DatasetError(f"{where}: bench.optical_radius_mm: expected > 0 mm, got {bench['optical_radius_mm']}")
    if bench["polygon_faces"] < 3:
        raise DatasetError(f"{where}: bench.polygon_faces: expected an integer >= 3, got {bench['polygon_faces']}")
    if not 0 <= bench["L1_mm"] < bench["L2_mm"]:
        raise DatasetError(f"{where}: bench.L1_mm/L2_mm: expected 0 <= L1 < L2, got {bench['L1_mm']}, {bench['L2_mm']}")
    if "heads_deg" in bench and not all(_is_number(h) for h in bench["heads_deg"]):
        raise DatasetError(f"{where}: bench.heads_deg: expected a list of numbers in degrees")
    if "polygon_certificate_arcsec" in bench:
        cert = bench["polygon_certificate_arcsec"]
        if len(cert) != bench["polygon_faces"] or not all(_is_number(c) for c in cert):
            raise DatasetError(f"{where}: bench.polygon_certificate_arcsec: expected {bench['polygon_faces']} numbers")
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
        if len(ref) != 2 or not all(_is_number(v) for v in ref):
            raise DatasetError(f"{where}: ccd.reference_px: expected [x, y] in pixels, got {ref!r}")
    return dict(m)


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


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
            raise DatasetError(f"{where}.{key}: expected {typ.__name__}, got {v!r}")


# --------------------------------------------------------------------------- writer


def _atomic_write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


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
        self.part.parent.mkdir(parents=True, exist_ok=True)
        self._fh = open(self.part, "w", encoding="utf-8", newline="")
        self._w = csv.writer(self._fh, lineterminator="\n")
        self._w.writerow(self.columns)
        self._fh.flush()
        self.rows = 0

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
        self._w.writerow([_cell(v) for v in row])
        self._fh.flush()
        self.rows += 1

    def close(self) -> Path:
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self._fh.close()
        os.replace(self.part, self.path)
        return self.path

    def abort(self) -> None:
        if not self._fh.closed:
            self._fh.close()
        if self.part.exists():
            self.part.unlink()


class DatasetWriter:
    """Write a dataset directory. The manifest is validated first and written last."""

    def __init__(self, path: str | Path, manifest: Mapping[str, Any]):
        self.path = Path(path)
        self.manifest = validate_manifest(dict(manifest), f"{self.path}/manifest.json")
        self.path.mkdir(parents=True, exist_ok=True)

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
        import cv2

        arr = np.asarray(image)
        if arr.ndim != 2 or arr.dtype not in (np.uint8, np.uint16):
            raise DatasetError(f"{relpath}: expected a 2-D uint8/uint16 greyscale image, got {arr.shape} {arr.dtype}")
        ok, png = cv2.imencode(".png", arr)
        if not ok:
            raise DatasetError(f"{relpath}: PNG encoding failed")
        p = self.path / relpath
        _atomic_write(p, png.tobytes())
        return p

    def write_truth_json(self, name: str, obj: Any) -> Path:
        p = self.path / TRUTH_DIR / name
        _atomic_write(p, (json.dumps(obj, indent=1, sort_keys=True, default=_json_default) + "\n").encode())
        return p

    def write_truth_table(self, name: str, columns: Mapping[str, Sequence[Any]]) -> Path:
        p = self.path / TRUTH_DIR / f"{name}.csv"
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


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON-serialisable: {type(o).__name__}")


# --------------------------------------------------------------------------- reader


def parse_table(text: str, name: str, where: str, spec: TableSpec | None = None) -> dict[str, np.ndarray]:
    """Parse and validate CSV text of table ``name``; errors name ``where``, the row and column.

    Rows are numbered as in a text editor (the header is row 1)."""
    spec = spec or TABLES.get(name)
    reader = csv.reader(io.StringIO(text))
    try:
        header = next(reader)
    except StopIteration:
        raise DatasetError(f"{where}: empty file (expected a header row)") from None
    header = [h.strip() for h in header]
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
    for rowno, row in enumerate(reader, start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise DatasetError(f"{where}: row {rowno}: expected {len(header)} fields, got {len(row)}")
        for h, cell in zip(header, row):
            raw[h].append(_parse_cell(cell.strip(), types.get(h), where, rowno, h))
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


def _parse_cell(cell: str, typ: type | None, where: str, rowno: int, col: str) -> Any:
    if typ is None or typ is str:
        return cell
    if typ is int:
        try:
            return int(cell)
        except ValueError:
            raise DatasetError(f"{where}: row {rowno}, column {col!r}: expected an integer, got {cell!r}") from None
    try:
        x = float(cell)
    except ValueError:
        raise DatasetError(f"{where}: row {rowno}, column {col!r}: expected a number, got {cell!r}") from None
    if not math.isfinite(x):
        raise DatasetError(f"{where}: row {rowno}, column {col!r}: expected a finite number, got {cell!r}")
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

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if not self.path.is_dir():
            raise DatasetError(f"{self.path}: not a dataset directory")
        mp = self.path / "manifest.json"
        if not mp.is_file():
            raise DatasetError(f"{mp}: missing (every dataset starts with its manifest)")
        try:
            m = json.loads(mp.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise DatasetError(f"{mp}: not valid JSON: {exc}") from None
        self.manifest = validate_manifest(m, str(mp))
        self._cache: dict[str, dict[str, np.ndarray]] = {}

    @property
    def bench(self) -> dict[str, Any]:
        return self.manifest["bench"]

    def has(self, name: str) -> bool:
        return (self.path / f"{name}.csv").is_file()

    def table(self, name: str) -> dict[str, np.ndarray]:
        if name not in self._cache:
            p = self.path / f"{name}.csv"
            if not p.is_file():
                raise DatasetError(f"{p}: missing")
            try:
                text = p.read_text(encoding="utf-8")
            except UnicodeDecodeError as exc:
                raise DatasetError(f"{p}: not UTF-8 text: {exc}") from None
            cols = parse_table(text, name, str(p))
            self._check_semantics(name, cols, p)
            self._cache[name] = cols
        return self._cache[name]

    def _check_semantics(self, name: str, cols: Mapping[str, np.ndarray], p: Path) -> None:
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

    def ccd_frames(self) -> Iterator[tuple[int, float, np.ndarray, str]]:
        """Yield (k, theta_deg, image, file) for every row of ccd/index.csv, checking each image."""
        idx = self.table("ccd/index")
        for i, (k, theta, f) in enumerate(zip(idx["k"], idx["theta_deg"], idx["file"])):
            yield int(k), float(theta), self.read_image(str(f), row=i + 2), str(f)

    def read_image(self, relpath: str, row: int | None = None) -> np.ndarray:
        import cv2

        where = f"{self.path / 'ccd' / 'index.csv'}: row {row}: " if row else ""
        p = (self.path / "ccd" / relpath) if not (self.path / relpath).is_file() else (self.path / relpath)
        if not p.is_file():
            raise DatasetError(f"{where}image {relpath!r} is missing")
        img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise DatasetError(f"{where}image {p} is not a readable image")
        if img.ndim != 2:
            raise DatasetError(f"{where}image {p}: expected greyscale, got {img.shape[2]} channels")
        if img.dtype not in (np.uint8, np.uint16):
            raise DatasetError(f"{where}image {p}: expected 8- or 16-bit, got {img.dtype}")
        return img

    def validate(self) -> list[str]:
        """Read every known table and image; returns a list of what was checked, raises on error."""
        checked = ["manifest.json"]
        for name in TABLES:
            if self.has(name):
                cols = self.table(name)
                checked.append(f"{name}.csv ({len(next(iter(cols.values())))} rows)")
        if self.has("ccd/index"):
            n = sum(1 for _ in self.ccd_frames())
            checked.append(f"{n} CCD images")
        if len(checked) == 1:
            raise DatasetError(f"{self.path}: no data tables (expected at least one of {', '.join(t + '.csv' for t in TABLES)})")
        return checked


def open_dataset(path: str | Path) -> Dataset:
    return Dataset(path)
