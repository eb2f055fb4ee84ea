"""Execution of a design study: seeds, cache keys, the process pool or Dask cluster, the tables.

Why a module of its own: what a study *is* (``spec``: the study file, its parameters and points)
and how its results are *shown* (``report``: verdict, figures, HTML) do not depend on where the
points run. This module owns the rest:

- repetition seeds (``rep_seed``: ``numpy.random.SeedSequence([study seed, rep])``, the same for
  every point: common random numbers);
- the cache: one JSON file per (point, repetition) keyed by a hash of the resolved scenario, the
  repetition seed, the point functions and ``code_version()``, so an interrupted study resumes and
  a re-run recomputes nothing;
- the executors: in-process, a local process pool (forkserver/spawn: MuJoCo objects are built
  inside the workers), or a Dask cluster (``scheduler="tcp://HOST:PORT"``);
- the tidy tables: one row per (point, repetition) and one per point (mean, standard deviation,
  standard uncertainty of the mean u = s/√n, GUM 4.2.3), as CSV and Parquet.

Entry point: ``run_study(study_path, out_dir, scheduler=None, workers=None, progress=True,
point_fn=None) -> dict`` (also written as ``study.json``).
"""

from __future__ import annotations

import concurrent.futures as cf
import hashlib
import json
import math
import multiprocessing as mp
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from benchtwin.fsio import atomic_write_text
from benchtwin.runtime import usable_cores
from benchtwin.schema import SchemaError, loads_json, read_input_text

from . import points as study_points
from . import report
from .spec import (_SEED_MAX, Point, Study, StudyError, _column, _hash, expand_points, load_study,
                   study_with_overrides)

PointFn = Callable[[dict[str, Any]], list[dict[str, float]]]


def rep_seed(study_seed: int, rep: int) -> int:
    """Seed of repetition ``rep``: the same for every point (common random numbers)."""
    return int(np.random.SeedSequence([study_seed, rep]).generate_state(1, np.uint64)[0]) & _SEED_MAX


def code_version() -> str:
    """benchtwin.__version__ plus a hash of every source a point can run (cache invalidation): the
    ``.py`` files of twin/, analysis/, hw/ (the acquisition runner and procedures the simulation
    uses), benchtwin/ (units, the app layer), and every file of models/ (the MuJoCo model).

    Computed afresh by every ``run_study`` (a few ms): pool workers import the code as it is on
    disk now, so a version remembered from an earlier run could be stale."""
    import benchtwin.analysis
    import benchtwin.hw
    import benchtwin.models
    import benchtwin.twin

    h = hashlib.sha256()
    for pkg, pattern in ((benchtwin.twin, "*.py"), (benchtwin.analysis, "*.py"), (benchtwin.hw, "*.py"),
                         (benchtwin, "*.py"), (benchtwin.models, "*")):
        root = Path(list(pkg.__path__)[0])
        for f in sorted(root.rglob(pattern)):
            if not f.is_file() or "__pycache__" in f.parts:
                continue
            h.update(f"{pkg.__name__}/{f.relative_to(root).as_posix()}".encode())
            h.update(f.read_bytes())
    return f"{benchtwin.__version__}+{h.hexdigest()[:16]}"


def _fn_id(fn: Callable[..., Any]) -> str:
    base = getattr(fn, "func", fn)  # functools.partial: identity of the wrapped function
    return f"{base.__module__}.{base.__qualname__}"


def _run_task(task: dict[str, Any]) -> dict[str, Any]:
    """Worker side: compute the missing repetitions of one point (module-level: picklable)."""
    t0 = time.perf_counter()
    results: list[dict[str, float]] = [{} for _ in task["reps"]]
    for fn in task["point_fns"]:
        for r, part in zip(results, fn(task)):
            r.update(part)
    return {"point": task["point"], "reps": task["reps"], "results": results,
            "elapsed_s": time.perf_counter() - t0}


def _mp_context() -> Any:
    methods = mp.get_all_start_methods()
    return mp.get_context("forkserver" if "forkserver" in methods else "spawn")


#: a cache entry is one point's outputs (a few hundred bytes); anything far larger is not one
MAX_CACHE_ENTRY_BYTES = 1024 * 1024


class _Cache:
    """One JSON file per (point, repetition) under ``<out_dir>/cache``, written atomically.

    An entry that is not one this module wrote (unreadable, not a regular file, not JSON, not
    ``{"outputs": {name: number}, "elapsed_s": number, "code": text}``) is a miss: the point is
    recomputed and the entry replaced, with a note in ``notes`` (study.json). Why not an error: the
    cache is derived data keyed by content, so recomputing gives exactly what a good entry would
    hold; an error would only make the user delete it by hand (issue 31)."""

    def __init__(self, root: Path):
        self.root = root
        self.notes: list[str] = []

    def path(self, key: str) -> Path:
        return self.root / key[:2] / f"{key}.json"

    def get(self, key: str) -> dict[str, Any] | None:
        p = self.path(key)
        if not p.exists() and not p.is_symlink():
            return None
        try:  # the one JSON reader; NaN allowed: a point's output may be NaN and json.dumps wrote it so
            entry = loads_json(read_input_text(p, max_bytes=MAX_CACHE_ENTRY_BYTES, what="cache entry"), str(p),
                               allow_nan=True)
            why = _entry_problem(entry)
        except SchemaError as exc:
            why = str(exc).removeprefix(f"{p}: ")
        if why is not None:
            self.notes.append(f"cache entry {p}: {why}; recomputed")
            if p.is_dir() and not p.is_symlink():
                raise StudyError(f"{p}: a folder where a cache entry belongs; remove it to resume the study")
            return None
        return entry

    def put(self, key: str, entry: dict[str, Any]) -> None:
        atomic_write_text(self.path(key), json.dumps(entry), fsync=False)  # benchtwin.fsio


def _entry_problem(entry: Any) -> str | None:
    """What makes ``entry`` not a cache entry this module wrote, or None."""
    if not isinstance(entry, dict):
        return "not a JSON object"
    outs = entry.get("outputs")
    if not isinstance(outs, dict):
        return "key 'outputs': expected an object of numbers"
    for k, v in outs.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return f"key 'outputs.{k[:40]}': expected a number"
    if isinstance(entry.get("elapsed_s"), bool) or not isinstance(entry.get("elapsed_s"), (int, float)):
        return "key 'elapsed_s': expected a number"
    if not isinstance(entry.get("code"), str):
        return "key 'code': expected the code version"
    return None


class _Bar(Protocol):
    def update(self, n: int) -> Any: ...

    def close(self) -> Any: ...


@dataclass
class _Plan:
    """What a study run has to do: the cache key of every (point, rep), what the cache already
    holds, and the tasks (one per point for physics, one per repetition for full) still to run."""

    keys: dict[tuple[int, int], str] = field(default_factory=dict)
    done: dict[tuple[int, int], dict[str, Any]] = field(default_factory=dict)
    tasks: list[dict[str, Any]] = field(default_factory=list)


def _plan(study: Study, points: list[Point], fns: list[PointFn], fn_ids: list[str], seeds: list[int],
          version: str, cache: _Cache) -> _Plan:
    plan = _Plan()
    fidelity = study.run_fidelity
    pipeline = {"order": study.order, "close_loop": study.close_loop} if fidelity == "full" else None
    for pt in points:
        missing = []
        for k in range(study.repetitions):
            spec: dict[str, Any] = {"scenario": pt.scenario_key, "rep": k, "rep_seed": seeds[k],
                                    "angles": study.angles, "point_fns": fn_ids, "code": version}
            if pipeline is not None:
                spec["pipeline"] = pipeline
            key = _hash(spec)
            plan.keys[(pt.index, k)] = key
            entry = cache.get(key)
            if entry is not None and all(o in entry["outputs"] for o in study.outputs):
                plan.done[(pt.index, k)] = entry
            else:
                missing.append(k)
        # physics: one task per point (its repetitions share one Bench); full: one task per
        # repetition (each is a separate simulation of tens of seconds: both workers share a point,
        # and the progress bar moves per run)
        for reps in ([missing] if fidelity != "full" else [[k] for k in missing]) if missing else []:
            plan.tasks.append({"point": pt.index, "scenario": pt.scenario, "scenario_key": pt.scenario_key,
                               "reps": reps, "rep_seeds": [seeds[k] for k in reps], "angles": study.angles,
                               "outputs": study.outputs, "point_fns": fns, "order": study.order,
                               "close_loop": study.close_loop})
    return plan


def run_study(study_path: str | Path, out_dir: str | Path, scheduler: Any = None, workers: int | None = None,
              progress: bool = True, point_fn: PointFn | None = None,
              overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Run a study file; write table, summary, figures under ``out_dir``; return a JSON-ready dict.

    - ``scheduler``: ``None`` for a local process pool, or a Dask scheduler address
      ``"tcp://HOST:PORT"`` (or an object with ``scheduler_address``, e.g. a ``LocalCluster``).
    - ``workers``: local pool size (default: all cores); ``0`` runs the points in this process.
    - ``point_fn``: replaces the fidelity's point function (a module-level callable or a
      ``functools.partial`` of one; used by tests and benchmarks); its name enters the cache key.
    - ``overrides``: ``{"bench.L1": "5 mm", "scenario.seed": 3}`` (``study --set``, ``--seed``):
      joined to ``[study.fixed]``, the seed the study's (``spec.study_with_overrides``); recorded in
      study.json and the summary.
    """
    study = load_study(study_path)
    if overrides:
        study = study_with_overrides(study, overrides)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # study.json is written last (the completion marker): an earlier run's must not outlive a new
    # run that is killed (benchtwin.fsio; issue #13)
    (out / "study.json").unlink(missing_ok=True)
    points = expand_points(study)
    fidelity = study.run_fidelity
    if point_fn is not None:
        fns: list[PointFn] = [point_fn]
        fid_map = {o: f"custom:{_fn_id(point_fn)}" for o in study.outputs}
    else:
        # full: one pipeline run per repetition gives every output (physics ones on its realisation)
        fns = [study_points.full_point] if fidelity == "full" else [study_points.physics_point]
        fid_map = study.output_fidelity()
    version = code_version()
    fn_ids = [_fn_id(f) for f in fns]
    seeds = [rep_seed(study.seed, k) for k in range(study.repetitions)]
    cache = _Cache(out / "cache")
    plan = _plan(study, points, fns, fn_ids, seeds, version, cache)
    n_total = len(points) * study.repetitions
    n_cached = len(plan.done)
    t0 = time.perf_counter()

    def store(res: dict[str, Any]) -> None:
        per_rep = res["elapsed_s"] / max(1, len(res["reps"]))
        for k, outs in zip(res["reps"], res["results"]):
            missing = [o for o in study.outputs if o not in outs]
            if missing:
                raise StudyError(f"{study.path}: point {res['point']} rep {k}: the point function "
                                 f"({', '.join(fn_ids)}) returned no {', '.join(missing)}")
            entry = {"outputs": outs, "elapsed_s": per_rep, "code": version}
            cache.put(plan.keys[(res["point"], k)], entry)
            plan.done[(res["point"], k)] = entry

    bar = _progress_bar(progress, n_total, n_cached, study.name)
    try:
        if not plan.tasks:
            pass
        elif scheduler is not None:
            _run_dask(scheduler, plan.tasks, store, bar)
        elif workers == 0:
            for task in plan.tasks:
                res = _run_task(task)
                store(res)
                bar.update(len(res["reps"]))
        else:
            _run_pool(workers or usable_cores(), plan.tasks, store, bar)
    finally:
        bar.close()
    info = report.RunInfo(
        fid_map=fid_map, fidelity=fidelity, version=version, computed=n_total - n_cached, cached=n_cached,
        wall_s=time.perf_counter() - t0,
        where="dask " + str(getattr(scheduler, "scheduler_address", scheduler))
        if scheduler is not None else ("in-process" if workers == 0 else
                                       f"local pool, {workers or usable_cores()} workers"),
        overrides=overrides, notes=tuple(cache.notes or ()))
    return _write_results(study, points, plan, seeds, out, info)


def _run_pool(n_workers: int, tasks: list[dict[str, Any]], store: Callable[[dict[str, Any]], None],
              bar: _Bar) -> None:
    from benchtwin.forkcall import watch_creator

    # every worker ends with this process (issue #31: after a kill -9 of `study` its workers went on
    # computing, then blocked on the task queue): the cache is written here only (store), so no
    # entry appears once this process is gone
    pool = cf.ProcessPoolExecutor(max_workers=min(n_workers, len(tasks)), mp_context=_mp_context(),
                                  initializer=watch_creator)
    try:
        futs = [pool.submit(_run_task, t) for t in tasks]
        for fut in cf.as_completed(futs):
            res = fut.result()
            store(res)
            bar.update(len(res["reps"]))
    except cf.process.BrokenProcessPool as exc:
        pool.shutdown(wait=False, cancel_futures=True)
        raise RuntimeError(
            "a worker process of the study pool died (killed, out of memory, or — when run_study "
            "is called from a script — the script lacks the `if __name__ == \"__main__\":` guard "
            "that spawned worker processes need); finished points are cached: re-run to resume"
        ) from exc
    except BaseException:
        # interrupted or a point failed: what is stored stays cached; a re-run resumes
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    else:
        pool.shutdown(wait=True)


def _progress_bar(enabled: bool, total: int, initial: int, name: str) -> _Bar:
    if enabled:
        from tqdm.auto import tqdm  # a notebook widget in Jupyter, the text bar elsewhere (issue 34)

        bar: _Bar = tqdm(total=total, initial=initial, desc=f"study {name}", unit="pt", smoothing=0.1)
        return bar

    class _Null:
        def update(self, n: int) -> None: ...

        def close(self) -> None: ...

    return _Null()


def _run_dask(scheduler: Any, tasks: list[dict[str, Any]], store: Callable[[dict[str, Any]], None],
              bar: _Bar) -> None:
    from distributed import Client, as_completed

    address = getattr(scheduler, "scheduler_address", scheduler)
    with Client(address, timeout="30s") as client:
        futs = client.map(_run_task, tasks, pure=False)
        try:
            for fut in as_completed(futs):
                res = fut.result()
                store(res)
                bar.update(len(res["reps"]))
        except BaseException:
            client.cancel(futs)
            raise


# ----------------------------------------------------------------------------------- tables


def _split_num(text: str) -> float:
    return float(str(text).split()[0])


def _write_tables(study: Study, points: list[Point], plan: _Plan, seeds: list[int], out: Path,
                  info: report.RunInfo) -> list[dict[str, Any]]:
    """``table.{csv,parquet}`` (one row per point and repetition) and ``summary.{csv,parquet}`` (per
    point: mean, s, u = s/√n); returns the summary rows the report is made from."""
    import pyarrow as pa
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    params = study.parameters
    done, keys = plan.done, plan.keys
    run_label = info.run_label(study)
    cols: dict[str, list[Any]] = {"point": [], "rep": [], "rep_seed": []}
    for p in params:
        cols[p.column] = []
        for key in p.sets:
            cols[_column(key, p.unit)] = []
    for o in study.outputs:
        cols[o] = []
    cols["fidelity"] = []
    cols["elapsed_s"] = []
    cols["cache_key"] = []
    for pt in points:
        for k in range(study.repetitions):
            e = done[(pt.index, k)]
            cols["point"].append(pt.index)
            cols["rep"].append(k)
            cols["rep_seed"].append(seeds[k])
            for p in params:
                cols[p.column].append(pt.values[p.name])
                for key in p.sets:
                    cols[_column(key, p.unit)].append(float(_split_num(pt.overrides[key])))
            for o in study.outputs:
                cols[o].append(float(e["outputs"][o]))
            cols["fidelity"].append(run_label)
            cols["elapsed_s"].append(float(e.get("elapsed_s", float("nan"))))
            cols["cache_key"].append(keys[(pt.index, k)][:16])
    meta = {"study": study.name, "base": study.base_ref, "seed": str(study.seed),
            "code_version": info.version, "fidelity": json.dumps(info.fid_map)}
    table = pa.table(cols).replace_schema_metadata(meta)
    pq.write_table(table, out / "table.parquet")
    pacsv.write_csv(table, out / "table.csv")

    # per-point summary
    scols: dict[str, list[Any]] = {"point": [], "n": [], "fidelity": []}
    for p in params:
        scols[p.column] = []
    for o in study.outputs:
        for s in ("mean", "std", "u"):
            scols[f"{o}_{s}"] = []
    summary_rows = []
    for pt in points:
        scols["point"].append(pt.index)
        scols["n"].append(study.repetitions)
        scols["fidelity"].append(run_label)
        for p in params:
            scols[p.column].append(pt.values[p.name])
        row: dict[str, Any] = {"point": pt.index, "values": pt.values}
        for o in study.outputs:
            x = np.array([done[(pt.index, k)]["outputs"][o] for k in range(study.repetitions)], float)
            mean = float(x.mean())
            std = float(x.std(ddof=1)) if len(x) > 1 else float("nan")
            u = std / math.sqrt(len(x)) if len(x) > 1 else float("nan")
            scols[f"{o}_mean"].append(mean)
            scols[f"{o}_std"].append(std)
            scols[f"{o}_u"].append(u)
            row[o] = (mean, std, u)
        summary_rows.append(row)
    stable = pa.table(scols).replace_schema_metadata(meta)
    pq.write_table(stable, out / "summary.parquet")
    pacsv.write_csv(stable, out / "summary.csv")
    return summary_rows


def _write_results(study: Study, points: list[Point], plan: _Plan, seeds: list[int], out: Path,
                   info: report.RunInfo) -> dict[str, Any]:
    """study.json (written last: the completion marker), after the tables and the report."""
    overrides, notes = info.overrides, info.notes
    summary_rows = _write_tables(study, points, plan, seeds, out, info)
    written = report.write_report(study, summary_rows, plan.done, out, info)
    verdict = written.verdict
    result = {
        "ok": True, "study": study.name, "out_dir": str(out), "points": len(points),
        "repetitions": study.repetitions, "rows": len(points) * study.repetitions,
        "computed": info.computed, "cached": info.cached, "wall_s": info.wall_s, "executor": info.where,
        "fidelity": info.fidelity, "output_fidelity": info.fid_map, "code_version": info.version,
        "table_csv": str(out / "table.csv"), "table_parquet": str(out / "table.parquet"),
        "summary_csv": str(out / "summary.csv"), "summary_parquet": str(out / "summary.parquet"),
        "summary_md": str(out / "summary.md"),
        "summary_html": str(out / "summary.html"), "report_html": str(written.report),
        "figures": [str(f) for f in written.figures],
        "target": verdict,
        **({"overrides": dict(overrides)} if overrides else {}),   # --set / --seed, as given
        "message": (verdict or {}).get("sentence") or
        f"study {study.name}: {len(points)} points × {study.repetitions} reps ({info.computed} computed, "
        f"{info.cached} from cache) -> {out}",
    }
    if notes:  # only then: the study.json of a run without them stays as it was
        result["notes"] = list(notes)
        result["message"] = (f"{result['message']} ({len(notes)} unusable cache "
                             f"entr{'y' if len(notes) == 1 else 'ies'} recomputed: see notes)")
    atomic_write_text(out / "study.json", json.dumps(result, indent=2, default=str))  # last: the completion marker
    return result
