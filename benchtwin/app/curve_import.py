"""`benchtwin import TABLE.csv -o DATASET`: a lab's measured error table → an "error curve" dataset.

The commonest record of an earlier calibration is a table: the angle and the encoder's error there,
sometimes a second column for the other direction of rotation. This command reads such a CSV by
column name, converts the error to arcsec, and writes a dataset of kind "error-curve"
(docs/dataset-format.md: ``error_curve.csv`` with ``theta_deg``, ``error_arcsec``, ``direction``
[, ``u_arcsec``]) that ``analyze`` / ``close-loop`` read like any other dataset (analysis/error_curve.py).

Every cell is checked: a missing column, an empty or non-numeric cell, a non-finite value or a
repeated angle is an input error naming the file, the row (as in a text editor: the header is
row 1) and the column. The dataset is written atomically, manifest last (analysis.dataset).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

from benchtwin.units import ARCSEC

__all__ = ["import_table", "ERROR_UNITS", "ImportError_"]

#: arcsec per unit of the error column
ERROR_UNITS = {"arcsec": 1.0, "urad": 1e-6 / ARCSEC, "deg": 3600.0}


class ImportError_(ValueError):
    """A table that cannot be imported; the message names the file, row and column."""


def _number(cell: str, where: str, row: int, col: str) -> float:
    c = cell.strip().replace("\u2212", "-")  # a typeset minus sign (U+2212) is a minus
    if not c:
        raise ImportError_(f"{where}: row {row}, column {col!r}: empty cell (expected a number)")
    try:
        x = float(c)
    except ValueError:
        raise ImportError_(f"{where}: row {row}, column {col!r}: expected a number, got {cell!r}") from None
    if not math.isfinite(x):
        raise ImportError_(f"{where}: row {row}, column {col!r}: expected a finite number, got {cell!r}")
    return x


def read_columns(table: str | Path, angle: str, error: str, reverse: str | None = None,
                 u: str | None = None) -> dict[str, list[float]]:
    """The named columns of a CSV table as floats (``u`` and ``reverse`` optional)."""
    p = Path(table)
    if not p.is_file():
        raise ImportError_(f"{p}: no such file")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ImportError_(f"{p}: not UTF-8 text: {exc}") from None
    rd = csv.reader(text.splitlines())
    try:
        header = [h.strip() for h in next(rd)]
    except StopIteration:
        raise ImportError_(f"{p}: empty file (expected a header row)") from None
    want = {"angle": angle, "error": error, "reverse": reverse, "u": u}
    for what, col in want.items():
        if col is not None and col not in header:
            raise ImportError_(f"{p}: row 1: no column {col!r} (--{what if what != 'u' else 'u'}; the header has {header})")
    idx = {k: header.index(c) for k, c in want.items() if c is not None}
    out: dict[str, list[float]] = {k: [] for k in idx}
    for rowno, row in enumerate(rd, start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise ImportError_(f"{p}: row {rowno}: expected {len(header)} fields, got {len(row)}")
        for k, i in idx.items():
            out[k].append(_number(row[i], str(p), rowno, str(want[k])))
    if len(out["angle"]) < 3:
        raise ImportError_(f"{p}: {len(out['angle'])} data rows; an error curve needs at least 3")
    seen: dict[float, int] = {}
    for i, a in enumerate(out["angle"]):
        key = round(a % 360.0, 9)
        if key in seen:
            raise ImportError_(f"{p}: rows {seen[key] + 2} and {i + 2}, column {angle!r}: the same angle twice "
                               f"({a}°; 0° and 360° are the same position)")
        seen[key] = i
    return out


def import_table(table: str | Path, out: str | Path, *, angle: str, error: str, reverse: str | None = None,
                 error_unit: str = "arcsec", u: str | None = None, force: bool = False) -> dict[str, Any]:
    """Write the dataset; returns a summary. ``reverse``: the column of the other direction
    (``error`` is then the forward one); ``u``: a column of standard uncertainties (same unit).
    The writing rule (``benchtwin.fsio.locked_output_dir``): a non-empty ``out`` is replaced only
    with ``force``, never while another live run holds it, never when it holds the table."""
    from benchtwin.analysis.dataset import DatasetWriter
    from benchtwin.fsio import check_not_input, locked_output_dir

    check_not_input(out, [table], "dataset folder")  # before reading: the table is never the output

    if error_unit not in ERROR_UNITS:
        raise ImportError_(f"--error-unit: expected one of {sorted(ERROR_UNITS)}, got {error_unit!r}")
    f = ERROR_UNITS[error_unit]
    cols = read_columns(table, angle, error, reverse, u)
    th = cols["angle"]
    rows: dict[str, list[Any]] = {"theta_deg": list(th), "error_arcsec": [v * f for v in cols["error"]],
                                  "direction": ["forward"] * len(th)}
    if u is not None:
        rows["u_arcsec"] = [v * f for v in cols["u"]]
        bad = [i for i, v in enumerate(rows["u_arcsec"]) if v <= 0]
        if bad:
            raise ImportError_(f"{table}: row {bad[0] + 2}, column {u!r}: expected u > 0")
    if reverse is not None:
        rows["theta_deg"] += th
        rows["error_arcsec"] += [v * f for v in cols["reverse"]]
        rows["direction"] += ["backward"] * len(th)
        if u is not None:
            rows["u_arcsec"] += rows["u_arcsec"][: len(th)]
    manifest = {"format": "bench-dataset", "version": 1, "source": "external", "kind": "error-curve", "bench": {},
                "created_by": "benchtwin import",
                "import": {"table": str(table), "angle_column": angle, "error_column": error,
                           "reverse_column": reverse, "u_column": u, "error_unit": error_unit,
                           "convention": "error = encoder reading − reference angle (docs/conventions.md); "
                                         "the error column is the forward direction"}}
    with locked_output_dir(out, force=force, what="dataset folder", owner="import", inputs=[table]):
        w = DatasetWriter(out, manifest, prepared=True)
        w.write_table("error_curve", rows)
        w.close()
    return {"dataset": str(out), "n_angles": len(th), "directions": 2 if reverse else 1}
