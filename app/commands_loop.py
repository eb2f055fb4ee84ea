"""Commands of the loop (issue 16): ``import`` (a measured error table → an error-curve dataset)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from benchtwin.cli import InputError, command, force_argument


def _import_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("table", type=Path, help="a CSV table of measured encoder errors (header row, column names)")
    p.add_argument("-o", "--out", type=Path, required=True, help="the dataset directory to write (kind error-curve)")
    p.add_argument("--angle", required=True, help="the column of the angles, degrees")
    p.add_argument("--error", required=True, help="the column of the errors (forward direction)")
    p.add_argument("--reverse", default=None, help="the column of the errors in the other direction")
    p.add_argument("--u", default=None, help="a column of standard uncertainties of the errors (same unit)")
    p.add_argument("--error-unit", default="arcsec", choices=("arcsec", "urad", "deg"),
                   help="unit of the error columns (default arcsec)")
    force_argument(p, "replace a non-empty dataset folder (default: refuse it; never the folder of the table)")


@command("import", "read a measured error table (CSV) into an error-curve dataset", _import_args)
def cmd_import(ns: argparse.Namespace) -> dict[str, Any]:
    from benchtwin.analysis.dataset import DatasetError
    from benchtwin.app.curve_import import ImportError_, TableColumns, import_table

    try:
        columns = TableColumns(ns.angle, ns.error, reverse=ns.reverse, u=ns.u, error_unit=ns.error_unit)
        res = import_table(ns.table, ns.out, columns, force=ns.force)
    except (ImportError_, DatasetError) as exc:
        raise InputError(str(exc)) from None
    return {"ok": True, **res, "message": f"dataset written: {res['dataset']} ({res['n_angles']} angles, "
                                          f"{res['directions']} direction{'s' if res['directions'] > 1 else ''})"}
