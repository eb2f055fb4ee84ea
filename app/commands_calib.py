"""Commands of the twin's own loop (issue 16, item 3): ``calibrate-twin`` (a measured dataset ->
a scenario whose twin reproduces it) and ``compare`` (twin against bench).

Registered by ``benchtwin.cli._load_commands``.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from benchtwin.cli import InputError, command, force_argument


def _calibrate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", type=Path,
                   help="a bench dataset, or the folder of analyze / close-loop / run (its results.json is used)")
    p.add_argument("-o", "--out", type=Path, required=True, help="the scenario file to write (TOML)")
    p.add_argument("--base", type=Path, default=None,
                   help="scenario whose non-fitted values are kept (default: the embedded one + the dataset's manifest)")
    p.add_argument("--results", type=Path, default=None,
                   help="results.json of close-loop on DATASET (default: one beside it, else close-loop is run)")
    force_argument(p, "replace an existing scenario file (default: refuse it; never an input file)")


@command("calibrate-twin", "write a scenario whose twin reproduces a measured dataset (fitted values with u)",
         _calibrate_args)
def cmd_calibrate_twin(ns: argparse.Namespace) -> dict[str, Any]:
    from benchtwin.app.calibrate_twin import CalibrationInputError, calibrate_twin

    try:
        res = calibrate_twin(ns.dataset, ns.out, base=ns.base, results=ns.results,
                             progress=not (ns.quiet or ns.json), force=ns.force)
    except CalibrationInputError as exc:
        raise InputError(str(exc)) from None
    return {"ok": True, **res,
            "message": f"scenario written: {res['scenario']} (e = {res['eccentricity_um']:.4g} µm; "
                       f"{len(res['fitted'])} fitted values; effects: {', '.join(res['identified_effects']) or 'none'})"}


def _compare_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("a", type=Path, help="reference: a dataset or a results folder (usually the bench)")
    p.add_argument("b", type=Path, help="the other: a dataset or a results folder (usually the twin)")


@command("compare", "twin against bench: α curves, radial motion, e and residuals of two datasets or results",
         _compare_args)
def cmd_compare(ns: argparse.Namespace) -> dict[str, Any]:
    from benchtwin.app.compare import CompareInputError, compare, format_comparison

    try:
        c = compare(ns.a, ns.b)
    except CompareInputError as exc:
        raise InputError(str(exc)) from None
    return {"ok": True, **c, "message": format_comparison(c)}
