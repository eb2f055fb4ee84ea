"""Design-study throughput: points per second on 1 and 2 local workers and on a 2-worker Dask
LocalCluster, and the runner's overhead against the bare simulation of the same points.

Why: a study is only useful if the runner costs little next to the simulation it schedules; this
measures it on the shipped study (scenarios/studies/bearing_distance.toml, physics fidelity), with
a fresh cache for every timed run (a cached re-run is timed separately). "Bare" is the physics
point function called in a loop in this process: no validation, no pool, no cache, no table.

    .venv/bin/python benchmarks/study_bench.py [--reps N] [--full-reps N] [--no-write]

A second, smaller table does the same for the ``full`` fidelity (simulate → analyze per
point-run; ``FULL_STUDY`` below: the jia2019 bench with a reduced procedure so that one point-run
takes seconds, not minutes); its bare loop calls ``app.run.simulate_and_analyze`` +
``study_outputs`` directly. ``--full-reps 0`` skips it.

Prints a markdown table and writes it under "## Design studies" in docs/benchmarks.md (only that
section is replaced; the rest of the file is left as it is).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import re
import shutil
import tempfile
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STUDY = ROOT / "scenarios" / "studies" / "bearing_distance.toml"
DOC = ROOT / "docs" / "benchmarks.md"
SECTION = "## Design studies"


FULL_STUDY = """
[study]
name = "full_bench"
base = "jia2019"
seed = 3
repetitions = {reps}
order = 3
outputs = ["measured_angle_error_pv_arcsec", "predicted_angle_error_pv_arcsec", "residual_rms_arcsec",
           "measured_angle_error_u_arcsec", "true_angle_error_pv_arcsec", "measurement_error_rms_arcsec"]
[study.fixed]
"procedure.radial_positions" = 36
"procedure.radial_reps" = 2
"procedure.ccd_step" = "30 deg"
"instruments.ccd.width" = "512 px"
"instruments.ccd.height" = "384 px"
"bench.polygon_faces" = 8
[[study.parameters]]
key = "errors.eccentricity"
values = ["2 um", "7.1 um"]
"""


def _study_copy(tmp: Path, reps: int) -> Path:
    """The shipped study with its base path made absolute and ``repetitions`` set to ``reps``."""
    text = STUDY.read_text(encoding="utf-8")
    text = text.replace('base = "../jia2019.toml"', f'base = "{(STUDY.parent.parent / "jia2019.toml").as_posix()}"')
    text = re.sub(r"(?m)^repetitions = \d+", f"repetitions = {reps}", text)
    p = tmp / "bench_study.toml"
    p.write_text(text, encoding="utf-8")
    return p


def bare(study_path: Path) -> tuple[float, int]:
    """Sequential physics point function over the study's points, no runner around it."""
    from benchtwin.app import study as st
    from benchtwin.app.study import points as sp

    study = st.load_study(study_path)
    points = st.expand_points(study)
    seeds = [st.rep_seed(study.seed, k) for k in range(study.repetitions)]
    t0 = time.perf_counter()
    n = 0
    for pt in points:
        task = {"scenario": pt.scenario, "scenario_key": pt.scenario_key, "reps": list(range(study.repetitions)),
                "rep_seeds": seeds, "angles": study.angles, "outputs": study.outputs}
        n += len(sp.physics_point(task))
    return time.perf_counter() - t0, n


def bare_full(study_path: Path) -> tuple[float, int]:
    """Sequential simulate → analyze over the full study's point-runs, no runner around it."""
    from benchtwin.app import run
    from benchtwin.app import study as st

    study = st.load_study(study_path)
    points = st.expand_points(study)
    seeds = [st.rep_seed(study.seed, k) for k in range(study.repetitions)]
    t0 = time.perf_counter()
    n = 0
    for pt in points:
        for seed in seeds:
            with tempfile.TemporaryDirectory(prefix="study-bench-bare-") as d:
                res = run.simulate_and_analyze(pt.scenario, Path(d), rep_seed=seed, order=study.order,
                                               close_loop=study.close_loop)
                run.study_outputs(res, Path(d), study.outputs)
            n += 1
    return time.perf_counter() - t0, n


def full_section(tmp: Path, reps: int) -> list[str]:
    """Bare simulate → analyze loop vs the runner in-process, on 1 and on 2 local workers (one
    timing each: a point-run is seconds, so start-up noise is small next to it)."""
    sp = tmp / "full_bench.toml"
    sp.write_text(FULL_STUDY.format(reps=reps), encoding="utf-8")
    load0 = f"{os.getloadavg()[0]:.2f}"
    t_bare, n = bare_full(sp)
    rows = [("bare simulate → analyze, in-process loop", t_bare, n, 1, t_bare)]
    for j, (label, nw, kw) in enumerate((("runner, in-process (workers=0)", 1, {"workers": 0}),
                                         ("runner, local pool, 1 worker", 1, {"workers": 1}),
                                         ("runner, local pool, 2 workers", 2, {"workers": 2}))):
        t, r = timed(sp, tmp / f"full_{j}", **kw)
        rows.append((label, t, r["rows"], nw, r["point_s"]))
    lines = [
        "",
        "### Full fidelity",
        "",
        textwrap.fill(
            f"The same measurement for the `full` fidelity (`FULL_STUDY` in the script: jia2019 with 8 "
            f"polygon faces, 2 × 36 radial stops, 12 CCD frames of 512 × 384 px, analysis order 3; 2 points × "
            f"{reps} repetitions = {n} point-runs, each a complete simulate → analyze, one task per "
            "repetition). Bare = `app.run.simulate_and_analyze` + `study_outputs` in a loop. One timing "
            f"per row (fresh cache). Load average before/after: {load0} / {os.getloadavg()[0]:.2f}.", 100),
        "",
        "| run | wall time (s) | point-runs/s | s per point-run | overhead vs bare | runner share |",
        "| --- | ---: | ---: | ---: | ---: | ---: |",
    ]
    for label, t, k, nw, pt in rows:
        lines.append(f"| {label} | {t:.1f} | {k / t:.3f} | {t / k:.1f} | {t / t_bare:.2f} | "
                     f"{1 - pt / (nw * t):.0%} |")
    return lines


def timed(study_path: Path, out: Path, **kw) -> tuple[float, dict]:
    """Wall time of one run_study; ``r["point_s"]`` = Σ of the point functions' own times (workers)."""
    import pyarrow.parquet as pq

    from benchtwin.app.study import run_study

    t0 = time.perf_counter()
    r = run_study(study_path, out, progress=False, **kw)
    wall = time.perf_counter() - t0
    r["point_s"] = float(sum(pq.read_table(r["table_parquet"])["elapsed_s"].to_pylist()))
    return wall, r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=4, help="repetitions per point (default 4)")
    ap.add_argument("--repeat", type=int, default=3,
                    help="time every run this many times (fresh cache each time) and keep the fastest: "
                         "the machine may be shared (default 2)")
    ap.add_argument("--full-reps", type=int, default=2,
                    help="repetitions per point of the full-fidelity table (2 points; default 2; 0 = skip)")
    ap.add_argument("--no-write", action="store_true", help="print only; leave docs/benchmarks.md alone")
    ns = ap.parse_args()

    from benchtwin.app.study import execution as st

    version = st.code_version()
    st.code_version = lambda: version  # other work may edit twin/ meanwhile: keep one cache key set
    load0 = f"{os.getloadavg()[0]:.2f}"
    tmp = Path(tempfile.mkdtemp(prefix="study-bench-"))
    try:
        sp = _study_copy(tmp, ns.reps)
        best = lambda ts: min(ts, key=lambda x: x[0])  # noqa: E731
        from distributed import LocalCluster

        configs = (("runner, in-process (workers=0)", 1, {"workers": 0}),
                   ("runner, local pool, 1 worker", 1, {"workers": 1}),
                   ("runner, local pool, 2 workers", 2, {"workers": 2}),
                   ("runner, Dask LocalCluster, 2 workers", 2, {"scheduler": "dask"}))
        times: dict[str, list] = {"bare": []}
        times.update({label: [] for label, _, _ in configs})
        # round robin over the configurations, so that bursts of other work hit them alike
        for i in range(ns.repeat):
            times["bare"].append(bare(sp))
            for j, (label, _, kw) in enumerate(configs):
                out = tmp / f"{j}_{i}"
                if kw.get("scheduler") == "dask":
                    # the cluster's start-up is outside the timing (a cluster usually outlives a study)
                    with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, host="127.0.0.1",
                                      dashboard_address=None) as cluster:
                        times[label].append(timed(sp, out, scheduler=cluster.scheduler_address))
                else:
                    times[label].append(timed(sp, out, **kw))
        t_bare, n = best(times["bare"])
        rows = [("bare physics point function, in-process loop", t_bare, n, 1, t_bare)]
        for label, nw, _ in configs:
            t, r = best(times[label])
            rows.append((label, t, r["rows"], nw, r["point_s"]))
        t, r = timed(sp, out, workers=2)
        assert r["computed"] == 0
        rows.append(("re-run, all points cached", t, r["rows"], 2, float("nan")))
        full_lines = full_section(tmp, ns.full_reps) if ns.full_reps > 0 else []
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    from benchtwin.app.study import expand_points, load_study

    n_points = len(expand_points(load_study(STUDY)))
    lines = [
        SECTION,
        "",
        f"`benchmarks/study_bench.py` on `scenarios/studies/bearing_distance.toml` (physics fidelity, "
        f"{n_points} points × {ns.reps} repetitions = {n} point-runs, 360 shaft positions each; "
        f"{os.cpu_count()} cores, {platform.processor() or platform.machine()}, Python {platform.python_version()}; "
        f"code {version}). Wall time includes validation, pool start-up (not the Dask cluster's), "
        "cache writes, tables, figures and the written summary; every timed run starts with an empty "
        f"cache; best of {ns.repeat} (the machine may be shared). Overhead = wall time / bare in-process loop "
        "over the same point-runs; with 2 workers, 0.5 would be perfect scaling. Σ point time = the point "
        "functions' own times summed over workers; runner share = 1 − Σ point time / (workers · wall): "
        "the part of the workers' wall time not spent simulating (start-up, scheduling, cache, tables, "
        "figures, idle tail). Load average of the machine (shared with other work) before/after: "
        f"{load0} / {os.getloadavg()[0]:.2f}.",
        "",
        "| run | wall time (s) | point-runs/s | overhead vs bare | Σ point time (s) | runner share |",
        "| --- | ---: | ---: | ---: | ---: | ---: |",
    ]
    for label, t, k, nw, pt in rows:
        share = "" if math.isnan(pt) else f"{1 - pt / (nw * t):.0%}"
        pts = "" if math.isnan(pt) else f"{pt:.2f}"
        lines.append(f"| {label} | {t:.2f} | {k / t:.1f} | {t / t_bare:.2f} | {pts} | {share} |")
    by = {label: (t, pt) for label, t, _, _, pt in rows}
    p1 = by["runner, local pool, 1 worker"][1]
    p2 = by["runner, local pool, 2 workers"][1]
    lines += ["", textwrap.fill(
        f"Per point-run, the point functions took {p2 / p1:.2f}× as long with 2 workers as with 1"
        + (" — the two cores were not free (other work on the machine), so the 2-worker wall times here"
           " understate the scaling; the runner share is the figure to compare." if p2 / p1 > 1.3 else
           ": both cores were available, so the 2-worker rows show the scaling.")
        + f" A re-run with every point cached costs {by['re-run, all points cached'][0]:.2f} s"
          " (validation, cache reads, tables, figures).", 100)]
    lines[2] = textwrap.fill(lines[2], 100)
    lines += full_lines
    lines.append("")
    text = "\n".join(lines)
    print(text)
    if not ns.no_write:
        _write_section(text)
        print(f"written to {DOC}")


def _write_section(section: str) -> None:
    """Replace (or append) only the "## Design studies" section of docs/benchmarks.md."""
    old = DOC.read_text(encoding="utf-8") if DOC.exists() else "# Benchmarks\n\n"
    m = re.search(rf"(?ms)^{re.escape(SECTION)}\n.*?(?=^## |\Z)", old)
    if m:
        new = old[:m.start()] + section + ("\n" if old[m.end():] else "") + old[m.end():]
    else:
        new = old.rstrip("\n") + "\n\n" + section
    DOC.write_text(new, encoding="utf-8")


if __name__ == "__main__":
    main()
