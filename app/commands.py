"""Subcommands that need the twin or the analysis (imported lazily by ``benchtwin.cli``).

A command is registered only if the module that does its work is importable, so the CLI never
offers a capability that does not exist yet.
"""

from __future__ import annotations

import argparse
import json
import importlib.util
from pathlib import Path
from typing import TYPE_CHECKING, Any

from benchtwin.cli import InputError, command, force_argument

if TYPE_CHECKING:
    from benchtwin.twin.scenario import Scenario


def _have(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


def _scenario(path: Path | None, ns: argparse.Namespace | None = None) -> Scenario:
    """The scenario file (None: the embedded default) with the command line's ``--set`` and
    ``--seed`` applied and validated by the scenario's schema; the overrides are kept with the
    scenario (``Scenario.overrides``) and recorded in the dataset's truth/scenario.json."""
    from benchtwin.twin.scenario import ScenarioError, load_scenario

    try:
        sc = load_scenario(path)
        overrides = _cli_overrides(ns)
    except ScenarioError as exc:
        raise InputError(str(exc)) from None
    if not overrides:
        return sc
    file_path = sc.path
    try:
        sc = sc.with_overrides(overrides)
    except ScenarioError as exc:
        msg = str(exc)
        named = [k for k in overrides if f"{k}:" in msg or f"{k} " in msg]
        raise InputError(msg + (f" (the value given by --set {named[0]}" if named else " (with the --set values")
                         + ")") from None
    sc.path = file_path  # still that file's scenario (the input check, truth/scenario.json "path")
    return sc


def _override_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--set", dest="set_options", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scenario key (dotted, e.g. bench.L1=\"5 mm\", procedure.polygon_reps=2); "
                        "VALUE is a TOML value (text that is not TOML is taken as a string); validated by the "
                        "scenario's schema; repeatable")
    p.add_argument("--seed", type=int, default=None, metavar="N", help="the scenario's seed (scenario.seed)")


def _cli_overrides(ns: argparse.Namespace | None) -> dict[str, Any]:
    """``--set`` and ``--seed`` as one overrides dict (ScenarioError: a malformed option, or a
    ``--seed`` that contradicts ``--set scenario.seed``)."""
    from benchtwin.twin.scenario import ScenarioError, parse_set_options

    if ns is None:
        return {}
    overrides = parse_set_options(getattr(ns, "set_options", None) or [])
    seed = getattr(ns, "seed", None)
    if seed is not None:
        if "scenario.seed" in overrides and overrides["scenario.seed"] != seed:
            raise ScenarioError(f"--seed {seed} contradicts --set scenario.seed={overrides['scenario.seed']!r}")
        overrides["scenario.seed"] = seed
    return overrides


# ----------------------------------------------------------------------------- simulate

def _simulate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", type=Path, nargs="?", default=None,
                   help="scenario file (default: the embedded jia2019 scenario)")
    p.add_argument("-o", "--out", type=Path, required=True, help="dataset directory to write")
    p.add_argument("--backend", choices=("auto", "pyrender", "analytic"), default="auto",
                   help="CCD renderer (auto: pyrender when OpenGL is available)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted simulation from OUT/journal.jsonl (the same scenario, --set and "
                        "--seed): the dataset is the one an uninterrupted run writes")
    _override_args(p)
    force_argument(p)
    from benchtwin.app.live import add_live_argument

    add_live_argument(p)


def cmd_simulate(ns: argparse.Namespace) -> dict[str, Any]:
    from benchtwin.app.live import live_for
    from benchtwin.twin.simulate import simulate

    if ns.resume and ns.force:
        raise InputError("simulate: --resume and --force contradict each other (continue the run, or delete it)")
    sc = _scenario(ns.scenario, ns)
    live = live_for(ns, f"simulate {sc.name}")
    try:
        out = simulate(sc, ns.out, progress=not (ns.quiet or ns.json), backend=ns.backend, force=ns.force,
                       resume=ns.resume, live=live)
    except BaseException as exc:
        if live is not None:
            live.close(f"failed: {type(exc).__name__}: {exc}")
        raise
    if live is not None:
        live.close("finished")
    return {"ok": True, "dataset": str(out), "scenario": sc.name, "seed": sc.seed,
            **({"overrides": sc.overrides} if sc.overrides else {}),
            **({"live": str(live.path)} if live else {}), "message": f"dataset written: {out}"}


# ----------------------------------------------------------------------------- analyze

def _analyze_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", type=Path, help="dataset directory (format v1)")
    p.add_argument("-o", "--out", type=Path, required=True, help="output directory (results.json, report.html)")
    p.add_argument("--order", type=int, default=10, help="Fourier order (Jia eqs. 6, 10); default 10")
    p.add_argument("--model", type=Path, default=None,
                   help="a model file from close-loop: its effects join the error model")
    force_argument(p)


def cmd_analyze(ns: argparse.Namespace) -> dict[str, Any]:
    res = _analyze_atomically(ns, close_loop=False)
    return {"ok": True, **res["paths"], "message": f"report: {res['paths']['report']}"}


def _analyze_atomically(ns: argparse.Namespace, close_loop: bool) -> dict[str, Any]:
    """analyze/close-loop by the API's ``analyze`` and its writing rule (one rule for the CLI and the
    API, issue 31): into a temporary sibling of OUT, renamed onto OUT when complete, under OUT's lock
    (a killed analysis leaves neither a half report nor the previous results.json under OUT, issue
    #13; a second analysis into OUT is refused while the first runs)."""
    from benchtwin.analysis.pipeline import analyze

    from benchtwin.app.bench_view import bench_preface_for_dataset

    return analyze(ns.dataset, ns.out, force=ns.force, order=ns.order, model_file=ns.model,
                   progress=not (ns.quiet or ns.json), close_loop=close_loop,
                   preface=bench_preface_for_dataset(ns.dataset))


def cmd_close_loop(ns: argparse.Namespace) -> dict[str, Any]:
    res = _analyze_atomically(ns, close_loop=True)
    names = [e["name"] for e in res["results"].get("identified_effects", [])]
    out = {"ok": True, **res["paths"], "identified_effects": names,
           "message": f"identified: {', '.join(names) or 'none'}; report: {res['paths']['report']}"}
    if "arc_periods" in res["results"]:  # an arc: what it does support (analysis/arc_periods.py)
        from benchtwin.analysis.report.html import value_with_u

        per = res["results"]["arc_periods"]
        out["arc_periods"] = [p["period_deg"] for p in per]
        out["message"] = ("arc: " + ("; ".join(
            f"period {value_with_u(p['period_deg'], p['u_period_deg'], '°', k=1)} "
            f"(amplitude {value_with_u(p['amplitude_arcsec'], p['u'], '″', k=1)}, "
            f"false alarm {p['false_alarm']:.1g}, {p['n_periods_covered']:.1f} periods covered; "
            f"{p['drive_element']['note']})" for p in per) or "no period (no peak above noise)")
            + "; no turn harmonics, no closure. " + out["message"])
    return out


# ----------------------------------------------------------------------------- run

def _run_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", type=Path, nargs="?", default=None,
                   help="scenario file (default: the embedded jia2019 scenario)")
    p.add_argument("-o", "--out", type=Path, default=None,
                   help="output directory (default: out/<scenario name>); the dataset goes to OUT/dataset")
    p.add_argument("--backend", choices=("auto", "pyrender", "analytic"), default="auto")
    p.add_argument("--no-close-loop", action="store_true", help="stop after the Jia/Hsieh analysis")
    _override_args(p)
    force_argument(p)


def cmd_run(ns: argparse.Namespace) -> dict[str, Any]:
    from benchtwin.analysis.pipeline import analyze_into, retarget
    from benchtwin.fsio import AtomicDir
    from benchtwin.twin.simulate import simulate_apart

    sc = _scenario(ns.scenario, ns)
    out = ns.out or Path("out") / sc.name
    quiet = ns.quiet or ns.json
    from benchtwin.app.bench_view import bench_preface

    # The whole run (dataset + analysis) is built beside OUT and renamed onto it when complete. An
    # earlier run's own complete output (its RUN_MARKER and results.json) is replaced without
    # --force, so the README's command can be repeated; it is swapped only once the new run is
    # complete, so a killed re-run keeps the earlier one. Any other non-empty folder needs --force.
    # OUT's lock is held throughout: a second run into OUT is refused while this one lives.
    with AtomicDir(out, force=ns.force or _is_run_output(out), what="run output folder", owner="run",
                   inputs=[sc.path]) as tmp:
        # The truth never enters the dataset (principle 3): it is written to OUT/truth by a forked
        # child while the analysis reads the measured dataset (issue #17: the truth, with its α
        # grid, was 4–9 s on the run's critical path; the child computes both at low priority,
        # on the CPU the analysis leaves, twin/simulate.py); the run is complete only with it.
        truth = tmp / "truth"
        ds, truth_job = simulate_apart(sc, tmp / "dataset", truth, progress=not quiet, backend=ns.backend)
        with truth_job:
            res = analyze_into(ds, tmp, progress=not quiet, close_loop=not ns.no_close_loop,
                               preface=bench_preface(sc))
            truth_job.wait()
        from benchtwin.fsio import atomic_write_text

        paths = retarget({"dataset": str(ds), "truth": str(truth), **res["paths"]}, tmp, out)
        atomic_write_text(tmp / RUN_MARKER, json.dumps({"command": "benchtwin run", "scenario": sc.name,
                                                        "seed": int(sc.seed),
                                                        **({"overrides": sc.overrides} if sc.overrides else {})})
                          + "\n")
    return {"ok": True, **paths, "message": f"report: {paths['report']}"}


#: written last into a complete `benchtwin run` output folder: what a later run may replace unasked
RUN_MARKER = "benchtwin-run.json"


def _is_run_output(out: Path) -> bool:
    return (out.is_dir() and not out.is_symlink() and (out / RUN_MARKER).is_file()
            and (out / "results.json").is_file())


def _study_output(out: Path, force: bool, study: Path) -> Any:
    """The study's folder, locked for the run (``benchtwin.fsio.locked_output_dir``). It is
    resumable (its cache/ is keyed by content): an earlier study folder is continued; any other
    non-empty folder is refused unless --force (which clears it); never a folder another live study
    holds, nor one holding the study file."""
    from benchtwin.fsio import OutputFolder, locked_output_dir

    resume = (out / "cache").is_dir() and not out.is_symlink() and not force
    return locked_output_dir(out, OutputFolder("study output folder", "study", resume_marker="cache"), force=force,
                             resume=resume, inputs=[study])


if _have("benchtwin.twin.simulate"):
    command("simulate", "simulate a scenario on the twin and write a dataset (+ truth/)", _simulate_args)(cmd_simulate)
if _have("benchtwin.analysis.pipeline"):
    command("analyze", "analyse a dataset: results.json + report.html", _analyze_args)(cmd_analyze)
    if _have("benchtwin.analysis.tracing"):
        command("close-loop", "analyse, trace the residual to an effect, add it, report before/after",
                _analyze_args)(cmd_close_loop)
if _have("benchtwin.twin.simulate") and _have("benchtwin.analysis.pipeline"):
    command("run", "simulate -> analyze -> report (default: the embedded jia2019 scenario)", _run_args)(cmd_run)
if _have("benchtwin.app.study"):
    def _study_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("study", type=Path, help="study file (TOML)")
        p.add_argument("-o", "--out", type=Path, default=None, help="output directory (default: out/<study name>)")
        p.add_argument("--scheduler", default=None, help="Dask scheduler address tcp://HOST:PORT (default: local pool)")
        p.add_argument("--workers", type=int, default=None, help="local worker processes (default: all cores)")
        p.add_argument("--set", dest="set_options", action="append", default=[], metavar="KEY=VALUE",
                       help="a scenario key fixed for every point (joins [study.fixed]; VALUE a TOML value); repeatable")
        p.add_argument("--seed", type=int, default=None, metavar="N", help="the study's seed (study.seed)")
        force_argument(p)

    @command("study", "run a design study (parameter sweep with Monte Carlo repetitions)", _study_args)
    def cmd_study(ns: argparse.Namespace) -> dict[str, Any]:
        from benchtwin.app.study import load_study, run_study
        from benchtwin.app.study.spec import study_with_overrides
        from benchtwin.twin.scenario import ScenarioError

        study = load_study(ns.study)  # a bad study file: exit 2 before any output folder is touched
        try:
            overrides = _cli_overrides(ns)
        except ScenarioError as exc:
            raise InputError(str(exc)) from None
        if overrides:
            study_with_overrides(study, overrides)   # a bad --set: exit 2 before any output is touched
        out = ns.out or Path("out") / ns.study.stem
        with _study_output(out, ns.force, ns.study):
            res = run_study(ns.study, out, scheduler=ns.scheduler, workers=ns.workers,
                            progress=not (ns.quiet or ns.json), overrides=overrides or None)
        # run_study's dict is JSON-ready (it is also written as study.json): counts, wall time,
        # fidelity per output and the target verdict go to --json as they are
        return {**res, "ok": True, "message": res.get("message", f"study written to {out}")}

