"""`benchtwin import TABLE.csv -o DATASET`: a lab's measured error table → an "error curve" dataset.

The commonest record of an earlier calibration is a table: the angle and the encoder's error there,
sometimes a second column for the other direction of rotation. This command reads such a CSV by
column name, converts the error to arcsec, and writes a dataset of kind "error-curve"
(docs/dataset-format.md: ``error_curve.csv`` with ``theta_deg``, ``error_arcsec``, ``direction``
[, ``u_arcsec``]) that ``analyze`` / ``close-loop`` read like any other dataset (analysis/error_curve.py).

Every cell is checked as the dataset reader checks it (issue 31, docs/reliability.md): the file is
read by ``benchtwin.schema`` (a regular file, bounded size, UTF-8), every number by its one number
grammar (``1_000`` is an error, not 1000), every value within the range ``validate`` gives its
column (angles −360…720°, errors and u within ±36 000″); a missing or repeated column, an empty or
non-numeric cell and a repeated angle are input errors naming the file, the row (as in a text
editor: the header is row 1) and the column. The table is checked by the dataset reader's own
``parse_table`` before anything is written, so ``validate`` accepts what ``import`` writes. The
dataset is written atomically, manifest last (analysis.dataset).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from benchtwin.schema import MAX_CELL_CHARS, SchemaError, csv_rows, parse_float, read_input_text
from benchtwin.units import ARCSEC

__all__ = ["import_table", "TableColumns", "ERROR_UNITS", "ImportError_"]

#: arcsec per unit of the error column
ERROR_UNITS = {"arcsec": 1.0, "urad": 1e-6 / ARCSEC, "deg": 3600.0}


class ImportError_(ValueError):
    """A table that cannot be imported; the message names the file, row and column."""


@dataclass(frozen=True)
class TableColumns:
    """Which columns of the table hold what, by header name: the angle (deg), the encoder's error (in
    ``error_unit``, one of ``ERROR_UNITS``), optionally the error in the other direction of rotation
    (``reverse``; ``error`` is then the forward one) and a column of standard uncertainties (``u``,
    in ``error_unit``)."""

    angle: str
    error: str
    reverse: str | None = None
    u: str | None = None
    error_unit: str = "arcsec"

    def named(self) -> dict[str, str]:
        """The columns given, by role (``angle``, ``error``, ``reverse``, ``u``: the option names)."""
        roles = {"angle": self.angle, "error": self.error, "reverse": self.reverse, "u": self.u}
        return {k: c for k, c in roles.items() if c is not None}


def _number(cell: str, where: str, row: int, col: str) -> float:
    """One cell by the project's number grammar (benchtwin.schema.parse_float: no ``1_000``, no
    ``nan``/``inf``, no overflow); a typeset minus sign (U+2212) is a minus."""
    c = cell.strip().replace("\u2212", "-")
    if not c:
        raise ImportError_(f"{where}: row {row}, column {col!r}: empty cell (expected a number)")
    try:
        return parse_float(c)
    except ValueError as exc:
        detail = str(exc).removeprefix("expected ")
        raise ImportError_(f"{where}: row {row}, column {col!r}: expected a number, got {_short(cell)} "
                           f"({detail})") from None


def _short(v: str, n: int = 40) -> str:
    s = repr(v)
    return s if len(s) <= n else s[: n - 1] + "…"


def read_columns(table: str | Path, columns: TableColumns) -> dict[str, list[float]]:
    """The named columns of a CSV table as floats, by role (``u`` and ``reverse`` optional). The file is
    read as every input is (benchtwin.schema: a regular file, bounded size, UTF-8); a column named
    twice in the header, a malformed row or cell, and an angle given twice are errors."""
    from benchtwin.analysis.dataset import MAX_ROWS, MAX_TABLE_BYTES

    p = Path(table)
    try:
        text = read_input_text(p, max_bytes=MAX_TABLE_BYTES, what="table")
    except SchemaError as exc:
        raise ImportError_(str(exc)) from None
    text = text.removeprefix("\ufeff")  # a byte-order mark (spreadsheet exports)
    rows = csv_rows(text, str(p), ImportError_)
    try:
        _, first = next(rows)
    except StopIteration:
        raise ImportError_(f"{p}: empty file (expected a header row)") from None
    header = [h.strip() for h in first]
    want = columns.named()
    for what, col in want.items():
        if col not in header:
            raise ImportError_(f"{p}: row 1: no column {col!r} (--{what}; the header has {_short(str(header), 200)})")
        if header.count(col) > 1:
            raise ImportError_(f"{p}: row 1: column {col!r} (--{what}) appears {header.count(col)} times; "
                               "expected it once")
    idx = {k: header.index(c) for k, c in want.items()}
    out: dict[str, list[float]] = {k: [] for k in idx}
    for rowno, row in rows:
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise ImportError_(f"{p}: row {rowno}: expected {len(header)} fields, got {len(row)}")
        if len(out["angle"]) >= MAX_ROWS:
            raise ImportError_(f"{p}: more than {MAX_ROWS} data rows; a table may have at most {MAX_ROWS}")
        for k, i in idx.items():
            if len(row[i]) > MAX_CELL_CHARS:
                raise ImportError_(f"{p}: row {rowno}, column {want[k]!r}: a cell of {len(row[i])} characters; "
                                   f"at most {MAX_CELL_CHARS} are allowed")
            out[k].append(_number(row[i], str(p), rowno, str(want[k])))
        out.setdefault("_row", []).append(rowno)
    if len(out["angle"]) < 3:
        raise ImportError_(f"{p}: {len(out['angle'])} data rows; an error curve needs at least 3")
    seen: dict[float, int] = {}
    for a, r in zip(out["angle"], (int(x) for x in out["_row"])):
        key = round(a % 360.0, 9) % 360.0
        if key in seen:
            raise ImportError_(f"{p}: rows {seen[key]} and {r}, column {columns.angle!r}: the same angle twice "
                               f"({a}°; 0° and 360° are the same position)")
        seen[key] = r
    return out


def _check_range(table: str | Path, values: list[float], rows: list[int], col: str, column: str,
                 factor: float, unit: str) -> None:
    """Every value within the range the dataset reader gives ``column`` (analysis.dataset:
    ``column_range``), so that ``validate`` accepts what ``import`` writes; the error names the
    source row and column and the range in the table's unit."""
    from benchtwin.analysis.dataset import TABLES, column_range

    rng = column_range(TABLES["error_curve"], column)
    assert rng is not None  # every numeric column of error_curve has a unit suffix
    lo, hi = rng
    for v, r in zip(values, rows):
        x = v * factor
        if not lo <= x <= hi:
            extra = f" ({lo / factor:g}…{hi / factor:g} {unit})" if factor != 1.0 else ""
            raise ImportError_(f"{table}: row {r}, column {col!r}: expected {lo:g}…{hi:g} "
                               f"{column.rsplit('_', 1)[1]}{extra}, got {v:g}")


def import_table(table: str | Path, out: str | Path, columns: TableColumns, *, force: bool = False) -> dict[str, Any]:
    """Write the dataset of the table's ``columns``; returns a summary.
    The writing rule (``benchtwin.fsio.locked_output_dir``): a non-empty ``out`` is replaced only
    with ``force``, never while another live run holds it, never when it holds the table."""
    from benchtwin.analysis.dataset import DatasetError, DatasetWriter, parse_table, table_to_csv
    from benchtwin.fsio import OutputFolder, check_not_input, locked_output_dir

    check_not_input(out, [table], "dataset folder")  # before reading: the table is never the output

    angle, error, reverse, u, error_unit = columns.angle, columns.error, columns.reverse, columns.u, columns.error_unit
    if error_unit not in ERROR_UNITS:
        raise ImportError_(f"--error-unit: expected one of {sorted(ERROR_UNITS)}, got {error_unit!r}")
    f = ERROR_UNITS[error_unit]
    cols = read_columns(table, columns)
    th = cols["angle"]
    src_rows = [int(r) for r in cols["_row"]]  # the source table's row numbers, for the errors
    _check_range(table, th, src_rows, angle, "theta_deg", 1.0, "deg")
    for k in ("error", "reverse", "u"):
        if k in cols:
            _check_range(table, cols[k], src_rows, columns.named()[k],
                         "u_arcsec" if k == "u" else "error_arcsec", f, error_unit)
    rows: dict[str, list[Any]] = {"theta_deg": list(th), "error_arcsec": [v * f for v in cols["error"]],
                                  "direction": ["forward"] * len(th)}
    if u is not None:
        rows["u_arcsec"] = [v * f for v in cols["u"]]
        bad = [r for r, v in zip(src_rows, rows["u_arcsec"]) if v <= 0]
        if bad:
            raise ImportError_(f"{table}: row {bad[0]}, column {u!r}: expected u > 0")
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
    # what validate will read: the dataset reader's own check of the table, before anything is written
    try:
        parse_table(table_to_csv(rows).decode("utf-8"), "error_curve", f"{table} (as error_curve.csv)")
    except DatasetError as exc:
        raise ImportError_(str(exc)) from None
    with locked_output_dir(out, OutputFolder("dataset folder", "import"), force=force, inputs=[table]):
        w = DatasetWriter(out, manifest, prepared=True)
        w.write_table("error_curve", rows)
        w.close()
    return {"dataset": str(out), "n_angles": len(th), "directions": 2 if reverse else 1}
