"""The ``benchtwin`` command line.

Subcommands land with their capability (no stubs that pretend):

- ``validate PATH``      a scenario file (.toml) or a dataset directory
- ``simulate SCENARIO``  twin -> dataset (+ truth/)
- ``analyze DATASET``    dataset -> results.json + report.html
- ``run [SCENARIO]``     simulate -> analyze -> report (the embedded default scenario if none)

Every subcommand takes ``--quiet`` (no progress, only the final line) and ``--json`` (one JSON
object on stdout, for scripts). Exit codes: 0 ok, 2 invalid input (the message names file, key or
row), 1 any other failure.

One error path for every command (issue #13, docs/reliability.md): ``main`` turns the project's
own error types (``DOMAIN_ERRORS``: bad datasets, scenarios, studies, bench files, model files,
output folders, units, instrument and port failures) and ``OSError`` into exit 2 with their
message, and anything else into exit 1 with one line (``BENCHTWIN_TRACEBACK=1`` shows the
traceback); under ``--json`` either is one JSON object ``{"ok": false, "error": ..., "kind": ...}``
on stdout. Usage errors (argparse) are exit 2 and JSON too.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

from benchtwin import __version__

Handler = Callable[[argparse.Namespace], dict[str, Any]]
_COMMANDS: dict[str, tuple[Handler, Callable[[argparse.ArgumentParser], None], str]] = {}


def command(name: str, help: str,
            args: Callable[[argparse.ArgumentParser], None] = lambda p: None) -> Callable[[Handler], Handler]:
    """Register a subcommand: the handler returns a JSON-ready dict whose 'message' is printed."""

    def deco(fn: Handler) -> Handler:
        _COMMANDS[name] = (fn, args, help)
        return fn

    return deco


#: ``--force`` of a command writing an output folder (benchtwin.fsio's writing rule)
FORCE_HELP = ("replace a non-empty output folder (default: refuse it; never one a live run holds, nor an input; "
              "docs/reliability.md)")


def force_argument(p: argparse.ArgumentParser, help: str = FORCE_HELP) -> None:
    """The ``--force`` flag every writing command takes (a boolean, default off); ``help`` says what
    it replaces and what it never does."""
    p.add_argument("--force", action="store_true", help=help)


class InputError(Exception):
    """Invalid user input (exit code 2)."""


# ----------------------------------------------------------------------------- validate


def _validate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", type=Path, help="a scenario, study, bench or fault-plan file, or a dataset directory")
    p.add_argument("--order", type=int, default=10,
                   help="a dataset: check it for analyze --order (the Fourier order; default 10)")


@command("validate", "check a scenario file or a dataset directory", _validate_args)
def cmd_validate(ns: argparse.Namespace) -> dict[str, Any]:
    from benchtwin.analysis.dataset import DatasetError, open_dataset
    from benchtwin.twin.scenario import ScenarioError, load_scenario

    path: Path = ns.path
    try:
        if path.is_dir():
            checked = open_dataset(path, ns.order).validate()
            return {"ok": True, "kind": "dataset", "path": str(path), "checked": checked,
                    "message": f"{path}: valid dataset ({'; '.join(checked)})"}
        other = _validate_other_file(path)
        if other is not None:
            return other
        sc = load_scenario(path)
    except (ScenarioError, DatasetError) as exc:
        raise InputError(str(exc)) from None
    hidden = sorted(sc.hidden)
    return {"ok": True, "kind": "scenario", "path": str(path), "name": sc.name, "seed": sc.seed,
            "hidden_effects": len(hidden),
            "message": f"{path}: valid scenario {sc.name!r} (seed {sc.seed}, {len(hidden)} hidden effects)"}


def _is_results_file(path: Path) -> bool:
    """results.json of analyze / close-loop: by its name, or a JSON object of format bench-results."""
    if path.name == "results.json":
        return True
    try:
        with path.open("rb") as f:
            head = f.read(1 << 20)
        return b'"bench-results"' in head
    except OSError:
        return False


def _validate_fault_plan(path: Path) -> dict[str, Any]:
    """``validate`` of an emulator fault plan (TOML with [[faults]], or JSON)."""
    from benchtwin.twin.emulators.pty import load_fault_plan

    try:
        n = len(load_fault_plan(path))
    except ValueError as exc:
        raise InputError(str(exc)) from None
    return {"ok": True, "kind": "fault_plan", "path": str(path), "faults": n,
            "message": f"{path}: valid fault plan ({n} faults)"}


def _validate_other_file(path: Path) -> dict[str, Any] | None:
    """results.json (analysis/results.py), a study file ([study]), a bench file ([instruments]) or a
    fault plan ([[faults]] / .json),
    checked by the reader of the command that uses it (study, acquire, emulate --faults), so that
    what validate accepts, that command reads; None for anything else (a scenario)."""
    from benchtwin.schema import SchemaError, load_toml_file

    if path.suffix == ".json" and path.is_file() and _is_results_file(path):
        from benchtwin.analysis.results import ResultsError, read_results

        try:
            res = read_results(path)
        except ResultsError as exc:
            raise InputError(str(exc)) from None
        return {"ok": True, "kind": "results", "path": str(path), "keys": len(res),
                "message": f"{path}: valid results ({res['format']} v{res['version']}, {len(res)} keys; "
                           "docs/results-format.md)"}
    if path.suffix == ".json" and path.is_file():
        return _validate_fault_plan(path)
    try:
        top = set(load_toml_file(path))
    except SchemaError:
        return None  # the scenario reader gives the error, named as before
    if "scenario" in top:  # a scenario also has [bench] and [instruments.*]
        return None
    if "study" in top:
        from benchtwin.app.study import load_study

        st = load_study(path)
        return {"ok": True, "kind": "study", "path": str(path), "name": st.name,
                "message": f"{path}: valid study {st.name!r}"}
    if "instruments" in top:
        from benchtwin.hw.acquisition.bench import load_bench

        cfg = load_bench(path)
        return {"ok": True, "kind": "bench", "path": str(path), "name": cfg.name,
                "instruments": sorted(cfg.instruments), "message": f"{path}: valid bench file {cfg.name!r}"}
    if "faults" in top:
        return _validate_fault_plan(path)
    return None


# ----------------------------------------------------------------------------- main


# (module, class) of the project's own error types: each message names the file, key or row and
# what was expected, so they end as exit 2. Looked up in sys.modules only: a module that was never
# imported cannot have raised, and `validate` stays fast.
DOMAIN_ERRORS: tuple[tuple[str, str], ...] = (
    ("benchtwin.fsio", "OutputError"),
    ("benchtwin.units", "UnitError"),
    ("benchtwin.runtime", "EnvVarError"),
    ("benchtwin.analysis.dataset", "DatasetError"),
    ("benchtwin.analysis.shift_angle", "PolygonDataError"),
    ("benchtwin.analysis.eccentricity", "ImageAnalysisError"),
    ("benchtwin.analysis.model_file", "ModelFileError"),
    ("benchtwin.analysis.results", "ResultsError"),
    ("benchtwin.schema", "SchemaError"),
    ("benchtwin.twin.scenario", "ScenarioError"),
    ("benchtwin.app.study.spec", "StudyError"),
    ("benchtwin.hw.acquisition.bench", "BenchFileError"),
    ("benchtwin.hw.acquisition.runner", "RunnerError"),
    ("benchtwin.hw.drivers.base", "InstrumentError"),
    ("benchtwin.hw.drivers.base", "FormatError"),
    ("benchtwin.hw.interfaces", "SoftLimitError"),
    ("serial", "SerialException"),  # a port that vanished (device unplugged, emulator stopped)
)


def _domain_error_types() -> tuple[type, ...]:
    types: list[type] = [InputError, OSError]
    for mod, name in DOMAIN_ERRORS:
        cls = getattr(sys.modules.get(mod), name, None)
        if isinstance(cls, type) and issubclass(cls, BaseException):
            types.append(cls)
    return tuple(types)


def _error_kind(exc: BaseException) -> str:
    return "input" if isinstance(exc, InputError) else type(exc).__name__


def _error_text(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.filename is not None and str(exc.filename) not in str(exc):
        return f"{exc.filename}: {exc.strerror or exc}"
    msg = str(exc)
    if isinstance(exc, KeyError) and exc.args:  # KeyError's str() is the repr of its key
        msg = str(exc.args[0])
    return msg or type(exc).__name__


class _Parser(argparse.ArgumentParser):
    """argparse, with usage errors as one JSON object on stdout when ``--json`` was asked."""

    json_mode = False

    def error(self, message: str) -> NoReturn:  # argparse's hook
        if _Parser.json_mode:
            print(json.dumps({"ok": False, "error": f"{self.prog}: {message}", "kind": "usage"}))
            self.exit(2)
        super().error(message)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="benchtwin", description=__doc__.split("\n\n")[0])
    parser.add_argument("--version", action="version", version=f"benchtwin {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (fn, add_args, help) in _COMMANDS.items():
        p = sub.add_parser(name, help=help, description=help)
        add_args(p)
        p.add_argument("--quiet", action="store_true", help="no progress output; only the final line")
        p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
        p.set_defaults(_handler=fn)
    return parser


#: seconds a failed command's process may take to exit normally (its pools and threads joined)
#: before it is ended with its exit code (``_end_promptly``)
EXIT_GRACE_S = 3.0


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (default: this process's); returns the exit code. As the
    process's own command (``argv`` None, the ``benchtwin`` script) a failed command also ends
    the process promptly (``_end_promptly``)."""
    code = _main(argv)
    if code != 0 and argv is None:
        _end_promptly(code)
    return code


def _end_promptly(code: int, grace_s: float = EXIT_GRACE_S) -> None:
    """A failed command's process ends within ``grace_s`` with ``code``, whatever is still alive
    in it (issue #31: after a MemoryError, ``simulate`` printed its error and never exited: the
    interpreter's exit joins non-daemon threads and process pools, and a pool whose forkserver
    never answers is joined forever). The normal exit goes on meanwhile (pools shut down, exit
    handlers run); if it has not finished when the grace ends, a daemon thread flushes the output
    and ends the process (``os._exit``; every output file is atomic or journaled, so nothing is
    left half-written that a reader would take as complete)."""
    import threading
    import time

    def end() -> None:
        time.sleep(grace_s)
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # noqa: BLE001 - a closed or broken stream: exit all the same
                pass
        os._exit(code)

    threading.Thread(target=end, name="benchtwin-exit", daemon=True).start()


def _main(argv: list[str] | None) -> int:
    # Headless GL for the whole process, before anything imports mujoco (it binds its GL backend at
    # import): Mesa's EGL for the twin's renderer and the report's bench view alike, unless the
    # user chose a platform (twin/render/gl.py; the same default as the tests' conftest).
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
    _load_commands()
    args = sys.argv[1:] if argv is None else list(argv)
    _Parser.json_mode = "--json" in args
    try:
        ns = build_parser().parse_args(args)
    finally:
        _Parser.json_mode = False
    try:
        result = ns._handler(ns)
    except KeyboardInterrupt:
        _emit(ns, {"ok": False, "error": "interrupted", "kind": "interrupted"}, error=True)
        return 130
    except Exception as exc:
        domain = isinstance(exc, _domain_error_types())
        # a deep recursion is input too: deeply nested JSON/TOML that a reader let through
        domain = domain or isinstance(exc, RecursionError)
        text = _error_text(exc)
        if not domain:
            if os.environ.get("BENCHTWIN_TRACEBACK"):
                traceback.print_exc()
            text = (f"internal error ({type(exc).__name__}: {text}); this is a bug in benchtwin, please report "
                    "it with the command line (BENCHTWIN_TRACEBACK=1 shows the traceback)")
        _emit(ns, {"ok": False, "error": text, "kind": _error_kind(exc) if domain else "internal"}, error=True)
        return 2 if domain else 1
    _emit(ns, result)
    return 0


def _emit(ns: argparse.Namespace, result: dict[str, Any], error: bool = False) -> None:
    """The result (or error) as one JSON object on stdout under --json, else its message (errors
    on stderr)."""
    if ns.json:
        print(_json_line(result), flush=True)
    else:
        print(result.get("message") or result.get("error"), file=sys.stderr if error else sys.stdout, flush=True)


def _json_line(result: dict[str, Any]) -> str:
    """``result`` as strict JSON: JSON has no NaN or infinity (``score --json`` printed
    ``-Infinity``, which no JSON parser reads); a non-finite number becomes null and a note under
    ``notes`` names its key (issue 31). A result without one is written as before."""
    try:
        return json.dumps(result, default=str, allow_nan=False)
    except ValueError:
        pass
    notes: list[str] = []

    def clean(x: Any, at: str) -> Any:
        if isinstance(x, dict):
            return {k: clean(v, f"{at}.{k}" if at else str(k)) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v, f"{at}[{i}]") for i, v in enumerate(x)]
        if isinstance(x, float) and not math.isfinite(x):
            notes.append(f"{at}: {x} (not a finite number; written as null)")
            return None
        return x

    out = clean(result, "")
    out["notes"] = [*(out.get("notes") or []), *notes] if isinstance(out.get("notes") or [], list) else notes
    return json.dumps(out, default=str, allow_nan=False)


def _load_commands() -> None:
    """Import the modules that register further subcommands (kept lazy: `validate` stays fast)."""
    import importlib

    for mod in ("benchtwin.app.commands", "benchtwin.app.commands_hw", "benchtwin.app.score_commands",
                "benchtwin.app.commands_cert", "benchtwin.app.commands_loop", "benchtwin.app.commands_calib"):
        try:
            importlib.import_module(mod)
        except ModuleNotFoundError as exc:
            if exc.name != mod:
                raise


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
