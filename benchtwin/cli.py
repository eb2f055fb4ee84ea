"""The ``benchtwin`` command line.

Subcommands land with their capability (no stubs that pretend):

- ``validate PATH``      a scenario file (.toml) or a dataset directory
- ``simulate SCENARIO``  twin -> dataset (+ truth/)
- ``analyze DATASET``    dataset -> results.json + report.html
- ``run [SCENARIO]``     simulate -> analyze -> report (the embedded default scenario if none)

Every subcommand takes ``--quiet`` (no progress, only the final line) and ``--json`` (one JSON
object on stdout, for scripts). Exit codes: 0 ok, 2 invalid input (the message names file, key or
row), 1 any other failure.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchtwin import __version__

Handler = Callable[[argparse.Namespace], dict[str, Any]]
_COMMANDS: dict[str, tuple[Handler, Callable[[argparse.ArgumentParser], None], str]] = {}


def command(name: str, help: str, args: Callable[[argparse.ArgumentParser], None] = lambda p: None):
    """Register a subcommand: the handler returns a JSON-ready dict whose 'message' is printed."""

    def deco(fn: Handler) -> Handler:
        _COMMANDS[name] = (fn, args, help)
        return fn

    return deco


class InputError(Exception):
    """Invalid user input (exit code 2)."""


# ----------------------------------------------------------------------------- validate


def _validate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", type=Path, help="a scenario file (.toml) or a dataset directory")


@command("validate", "check a scenario file or a dataset directory", _validate_args)
def cmd_validate(ns: argparse.Namespace) -> dict[str, Any]:
    from benchtwin.analysis.dataset import DatasetError, open_dataset
    from benchtwin.twin.scenario import ScenarioError, load_scenario

    path: Path = ns.path
    try:
        if path.is_dir():
            checked = open_dataset(path).validate()
            return {"ok": True, "kind": "dataset", "path": str(path), "checked": checked,
                    "message": f"{path}: valid dataset ({'; '.join(checked)})"}
        sc = load_scenario(path)
    except (ScenarioError, DatasetError) as exc:
        raise InputError(str(exc)) from None
    hidden = sorted(sc.hidden)
    return {"ok": True, "kind": "scenario", "path": str(path), "name": sc.name, "seed": sc.seed,
            "hidden_effects": len(hidden),
            "message": f"{path}: valid scenario {sc.name!r} (seed {sc.seed}, {len(hidden)} hidden effects)"}


# ----------------------------------------------------------------------------- main


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="benchtwin", description=__doc__.split("\n\n")[0])
    parser.add_argument("--version", action="version", version=f"benchtwin {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (fn, add_args, help) in _COMMANDS.items():
        p = sub.add_parser(name, help=help, description=help)
        add_args(p)
        p.add_argument("--quiet", action="store_true", help="no progress output; only the final line")
        p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
        p.set_defaults(_handler=fn)
    return parser


def main(argv: list[str] | None = None) -> int:
    _load_commands()
    ns = build_parser().parse_args(argv)
    try:
        result = ns._handler(ns)
    except InputError as exc:
        _emit(ns, {"ok": False, "error": str(exc)}, stream=sys.stderr)
        return 2
    _emit(ns, result)
    return 0


def _emit(ns: argparse.Namespace, result: dict[str, Any], stream=None) -> None:
    if ns.json:
        print(json.dumps(result, default=str))
    else:
        print(result.get("message") or result.get("error"), file=stream or sys.stdout)


def _load_commands() -> None:
    """Import the modules that register further subcommands (kept lazy: `validate` stays fast)."""
    import importlib

    for mod in ("benchtwin.app.commands", "benchtwin.app.commands_hw", "benchtwin.app.score_commands"):
        try:
            importlib.import_module(mod)
        except ModuleNotFoundError as exc:
            if exc.name != mod:
                raise


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
