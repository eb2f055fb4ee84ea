"""Reference scores of the project's own analysis on the benchmark suite (issue 19).

For each seed: ``benchtwin suite --blind`` (benchtwin.app.suite.write_suite), the project's analysis
``benchtwin.analysis.pipeline.analyze(dataset, out, close_loop=True)`` on every dataset of
``SUITE/datasets/`` (truth is in ``SUITE/truth/``, out of the analysis's reach), then
``benchtwin score-suite`` (benchtwin.app.suite.score_suite_files).

Writes, after each seed:

- docs/data/suite-scores.json (``--data``): the scores of every seed (each dataset's score, the
  overall figures, the README naive fit's overall figures, the analysis failures, the times) and
  the commit the run started from;
- docs/suite-scores.md (``--doc``): rendered from that JSON alone (:func:`render_doc`; the prose
  is ``NOTES`` below), so a test (tests/app/test_suite_scores_doc.py) re-renders it from the
  stored JSON and compares it byte for byte: a hand edit of the doc, or a change of the renderer
  or of the prose without re-rendering, fails;
- tests/app/data/suite_small_seed11.json (``--expectations``, from the seed-11 full run): what
  tests/app/test_suite_reference.py defends, derived from the same JSON (checked by the same test
  file), so the doc's seed-11 figures and the slow test's expectations come from one run.

    nice .venv/bin/python benchmarks/suite_scores.py [--seeds 11 22 33] [--size full] [--jobs 2]
                                                     [--work /tmp/suite_scores] [--doc docs/suite-scores.md]
    .venv/bin/python benchmarks/suite_scores.py --render   # the doc again from the JSON (prose edits)
    .venv/bin/python benchmarks/suite_scores.py --check    # exit 1 with a diff if the doc has drifted

Resumable: a seed's suite and each dataset's results.json are kept in --work and not redone (a
stale --work is reused as it is: give a fresh one after the code changed).

Times (wall and CPU of the simulation and of the close-loop analyses, per seed) are printed and
kept in --work/times_SIZE_seedN.json by the run that did the work; the CPU time is that of this
process and of all its descendants (resource.getrusage; the process is their subreaper on Linux,
so the frame workers of the simulations count too).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _analyze(args):
    ds, out = args
    from benchtwin.analysis.pipeline import analyze

    if (Path(out) / "results.json").exists():
        return ds, 0.0, None
    t0 = time.time()
    try:
        analyze(Path(ds), Path(out), progress=False, close_loop=True)
    except Exception as exc:  # noqa: BLE001 - an analysis failure is a result without results.json
        return ds, time.time() - t0, f"{type(exc).__name__}: {exc}"
    return ds, time.time() - t0, None


#: the files a run writes (a change to them is no change to the code the run measured)
OUTPUTS = ("docs/suite-scores.md", "docs/data/suite-scores.json", "tests/app/data/suite_small_seed11.json")


def _commit() -> str:
    """HEAD's short id, and the tracked files changed beside it (other than this script's outputs)."""
    import subprocess

    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True,
                              check=True).stdout

    try:
        head = git("rev-parse", "--short", "HEAD").strip()
        changed = [ln[3:] for ln in git("status", "--porcelain", "--untracked-files=no").splitlines()
                   if ln[3:] not in OUTPUTS]
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + (f" with uncommitted changes to {', '.join(changed)}" if changed else "")


def readme_naive():
    """The README's ten-line naive eccentricity fit, taken from the README itself (so what is
    measured here is what the README shows)."""
    import re

    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = re.search(r"```python\n(.*?def naive.*?)```", text, re.S).group(1)
    code = block.split("\nprint(benchtwin.score")[0]
    ns: dict = {}
    exec(compile(code, "README.md", "exec"), ns)  # noqa: S102 - our own README
    return ns["naive"]


def _run_bench():
    """benchmarks/run_bench.py, for its subreaper and reaper (one implementation of both): importing it
    makes this process the subreaper of its orphaned descendants (``prctl(PR_SET_CHILD_SUBREAPER)``),
    so their CPU is counted once reaped: the frame workers of ``simulate`` are children of a
    forkserver (twin/render/pipeline.py) that the pool worker which started it does not wait for.
    Imported here, not at the top: a test that loads this module must not become a subreaper."""
    here = str(Path(__file__).resolve().parent)
    if here not in sys.path:   # called for every CPU reading: put the folder on the path once
        sys.path.insert(0, here)
    import run_bench

    return run_bench


def _cpu_s() -> float:
    """CPU seconds (user + system) of this process and its reaped descendants (the pools' workers,
    and through run_bench's subreaper their orphaned forkservers and frame workers); called only
    after a pool has shut down, so no child of the pool's is taken from it."""
    import resource

    _run_bench()._reap_descendants()
    return sum(getattr(resource.getrusage(w), k) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
               for k in ("ru_utime", "ru_stime"))


def run_seed(seed: int, size: str, jobs: int, work: Path, commit: str) -> dict:
    from benchtwin.app.suite import open_suite, score_suite_files, write_suite

    sd, rd = work / f"suite_{size}_seed{seed}", work / f"results_{size}_seed{seed}"
    c0 = _cpu_s()  # first: it may wait for orphans to end
    t0 = time.time()
    if not (sd / "suite.json").exists():
        write_suite(sd, seed=seed, blind=True, size=size, jobs=jobs, progress=lambda m: print(f"seed {seed} {m}",
                                                                                               flush=True))
    t_sim, c_sim = time.time() - t0, _cpu_s() - c0
    print(f"seed {seed} simulate: wall {t_sim:.0f} s, CPU {c_sim:.0f} s", flush=True)
    _, items = open_suite(sd)
    c0 = _cpu_s()
    t0 = time.time()
    errors = {}
    with ProcessPoolExecutor(max_workers=jobs) as ex:
        for ds, dt, err in ex.map(_analyze, [(str(it.dataset), str(rd / it.name)) for it in items]):
            print(f"seed {seed} analyse {Path(ds).name}: {dt:.0f} s {err or ''}", flush=True)
            if err:
                errors[Path(ds).name] = err
    t_an, c_an = time.time() - t0, _cpu_s() - c0
    print(f"seed {seed} close-loop analyses: wall {t_an:.0f} s, CPU {c_an:.0f} s", flush=True)
    out = score_suite_files(rd, sd)
    out["errors"] = errors
    import benchtwin

    out["naive"] = benchtwin.score(readme_naive(), suite=sd)
    times = work / f"times_{size}_seed{seed}.json"  # kept from the run that did the work (resumes are fast)
    if t_sim > 60 or not times.exists():
        times.write_text(json.dumps({"simulate_s": round(t_sim, 1), "analyze_s": round(t_an, 1),
                                     "simulate_cpu_s": round(c_sim, 1), "analyze_cpu_s": round(c_an, 1),
                                     "jobs": jobs, "cpus": os.cpu_count(),
                                     "load_average_1min": round(os.getloadavg()[0], 1), "commit": commit}))
    out["times"] = json.loads(times.read_text())
    return out


NOTES = """## Reading the figures

The prose below is written by hand (``NOTES`` in benchmarks/suite_scores.py) from the run shown;
a range is over the three seeds.

- **e, θ0 errors and their z** are against the installed eccentricity (truth `e_um`). The suite's
  benches run on ball bearings (hsieh2022 on air bearings), and the axis's once-per-revolution
  motion during the CCD sweep is part of the eccentricity the CCD and every head see (Jia sec. 4.2):
  on the Jia-procedure benches the sweep's e is 0.13–0.19 µm above the installed 7.1 µm, θ0
  0.36–0.58° off. The analysis reports the sweep's values — against each sweep's exact image analysis
  (`e_error_sweep_um`) within 0.006 µm and 0.03° everywhere but `ccd_pixel_scale` — with a u
  (0.012–0.023 µm) that does not hold that motion: |z| ≈ 8–13 for e and 2–6 for θ0 on most
  datasets, which makes the z RMS. The largest errors: `tilt_abbe` (the disk's tilt adds to the
  sweep's e: +0.55 to +0.94 µm, θ0 up to 3.4°), `jia2019` (its own bench: −0.18 to +0.53 µm, θ0 up
  to 2.4°, mostly inside its u of ≈ 0.27 µm: |z| 0.5–2.0). `hsieh2022` is the same story on air
  bearings: e within 0.015 µm and θ0 0.6–0.8° off the installed values, right against the sweep,
  with a u so small that |z| is 13–75. `ccd_pixel_scale` (a grating period 3 % off the datasheet)
  is the one image-scale miss: −0.21 µm against the sweep at every seed; the tracer puts it in an
  ambiguity set and the reported e is not corrected. Since 2026-12-06 the scorer compares e and θ0
  with the disk's eccentricity about the axis of rotation (installed ⊕ the axis's synchronous first
  harmonic, docs/scoring.md), which the synchronous part of that motion belongs to; the figures
  here were measured against the installed e before that and await the full re-run.
- **α RMS** is dominated by `ac_scale` (0.46–0.50″: the autocollimator's hidden gain error is in α
  itself; the tracer puts ac_scale in an ambiguity set and α is not corrected) and `jia2019`
  (0.24–0.25″), then `torsion_hysteresis` (0.14–0.15″), `interpolation_error` and `null_b`
  (0.10–0.11″); elsewhere ≤ 0.06″.
- **Self-calibration** (three datasets): 0.32–0.43″ on the two ball-bearing benches that run one
  (`ac_scale`, `null_b`), where the stated u covers 13–33 % of the points within 1u, against
  0.02–0.04″ on `hsieh2022` (4–61 % within 1u).
- **Naming** (10–12 of 18): wrong at every seed are `ac_drift` (absorbed by the analysis: nothing to
  name; reported as unexplained), `ac_scale` and `torsion_hysteresis` (only in an ambiguity set
  where the suite wants them named), `tilt_abbe` (missed) and `interpolation_error` (in a set or
  missed); `sphere_form` is missed at seeds 11 and 22, and at seed 33 named spuriously on three
  benches without it (`null_a`, `polygon_pitch_ignored`, `ccd_pixel_scale_pixel_only`: the
  3 spurious names); `null_b` is reported unexplained at seed 22. `thermal_growth` (outside the
  library) is reported unexplained, with no ambiguity set beside it. `hsieh2022`'s naming is not
  scored (no decided outcome).
- **after / floor**: the floor (the autocollimator's own error, ≈ 0.03–0.04″) does not hold the
  bearings' axis motion that repeats neither per revolution nor between the radial revolutions and
  the polygon run (docs/scoring.md): the null benches leave 0.12–0.20″ after the model
  (after/floor 3.3–6.6; the median is 3.3–5.7); ≈ 2.4–3.0 where a traced effect takes some of
  it; 7–10 on `thermal_growth` (outside the library); 13–20 on `jia2019` and `torsion_hysteresis`,
  the worst.
"""


def doc_data(runs: dict[int, dict], size: str) -> dict:
    """What the doc shows, JSON-ready: per seed the suite's metadata, the label of each anonymous
    folder, each dataset's score (benchtwin.app.score.public), the overall figures, the naive fit's
    overall figures, the analysis failures, the times and the commit of the run that did the work.
    The results files' paths (in --work) are left out."""
    from benchtwin.app.score import public

    seeds = {}
    for s, r in sorted(runs.items()):
        t = dict(r["times"])
        commit = t.pop("commit", "unknown")
        seeds[str(s)] = public({"suite": r["suite"], "commit": commit, "times": t, "labels": r["labels"],
                                "scores": r["scores"], "overall": r["overall"],
                                "naive_overall": r["naive"]["overall"], "errors": r["errors"]})
    return {"generated_by": "benchmarks/suite_scores.py", "size": size, "seeds": seeds}


def _seeds(data: dict) -> list[str]:
    return sorted(data["seeds"], key=int)


def render_doc(data: dict) -> str:
    """docs/suite-scores.md from :func:`doc_data`'s JSON alone (and NOTES, the hand-written prose)."""
    from benchtwin.app.suite import format_suite_table

    f = lambda v, fmt: "–" if v is None else format(v, fmt)  # noqa: E731
    seeds = _seeds(data)
    runs = data["seeds"]
    versions = sorted({str(runs[s]["suite"]["suite_version"]) for s in seeds})
    commits: dict[str, list[str]] = {}
    for s in seeds:
        commits.setdefault(runs[s]["commit"], []).append(s)
    at = (f"commit {next(iter(commits), 'unknown')}" if len(commits) <= 1 else "commits " + "; ".join(
        f"{c} (seed {', '.join(ss)})" for c, ss in commits.items()))
    L = ["# Reference scores of the project's analysis on the benchmark suite", "",
         "Generated by `benchmarks/suite_scores.py` from [data/suite-scores.json](data/suite-scores.json) — do "
         "not edit by hand (tests/app/test_suite_scores_doc.py re-renders it from the JSON). The suite is "
         f"`benchtwin suite --blind --size {data['size']} --seed N` (suite version {', '.join(versions)}, "
         "app/suite.py); the algorithm scored is the project's own "
         "`benchtwin close-loop` (analysis.pipeline.analyze with close_loop=True) on "
         "`SUITE/datasets/*` with the truth out of reach; the scores are `benchtwin score-suite` "
         "(rules: [scoring.md](scoring.md)). Compare your algorithm's `score-suite` output "
         f"with the row of the same seed. Generated at {at}.", "",
         "## Overall figures per criterion and seed", "",
         "| criterion | " + " | ".join(f"seed {s}" for s in seeds) + " |",
         "| --- | " + " | ".join("---" for _ in seeds) + " |"]
    rows = [
        ("e error RMS, µm", lambda o: f(o["e_error_um"], ".4f")),
        ("e z RMS", lambda o: f(o["e_z"], ".2f")),
        ("θ0 error RMS, °", lambda o: f(o["theta0_error_deg"], ".4f")),
        ("θ0 z RMS", lambda o: f(o["theta0_z"], ".2f")),
        ("β RMS error, ″", lambda o: f(o["beta_rms_error_arcsec"], ".4f")),
        ("α RMS error, ″", lambda o: f(o["alpha_rms_error_arcsec"], ".4f")),
        ("self-calibration RMS error, ″", lambda o: f(o["selfcal_rms_error_arcsec"], ".4f")),
        ("coverage ≤1u (normal 68.3 %)", lambda o: f(o["coverage_1u"], ".1%")),
        ("coverage ≤2u (normal 95.4 %)", lambda o: f(o["coverage_2u"], ".1%")),
        ("effect named correctly", lambda o: f"{o['identification_correct']}/{o['identification_scored']}"),
        ("spurious names", lambda o: str(o["spurious"])),
        ("residual after / floor, median", lambda o: f(o["residual_after_over_floor_median"], ".2f")),
        ("residual after / floor, worst", lambda o: f(o["residual_after_over_floor_max"], ".2f")),
        ("datasets with results", lambda o: f"{o['with_results']}/{o['datasets']}"),
    ]
    for name, fn in rows:
        L.append(f"| {name} | " + " | ".join(fn(runs[s]["overall"]) for s in seeds) + " |")
    L += ["", NOTES, "## The README's naive eccentricity fit on the same suites", "",
          "The README's ten-line example (first harmonic of one start face's autocollimator readings; "
          "β and the axis motion ignored) scored with `benchtwin.score(naive, suite=...)`; it touches e, θ0 "
          "and α only (no u: no coverage; no naming). Project's analysis → naive:", "",
          "| criterion | " + " | ".join(f"seed {s}" for s in seeds) + " |",
          "| --- | " + " | ".join("---" for _ in seeds) + " |"]
    for name, key, fmt in (("e error RMS, µm", "e_error_um", ".4f"), ("θ0 error RMS, °", "theta0_error_deg", ".4f"),
                           ("α RMS error, ″", "alpha_rms_error_arcsec", ".4f")):
        L.append(f"| {name} | " + " | ".join(
            f"{f(runs[s]['overall'][key], fmt)} → {f(runs[s]['naive_overall'][key], fmt)}" for s in seeds) + " |")
    L += ["", "## Times", "",
          "Wall and CPU time (the script's process and all its descendants) of `benchtwin suite` (the simulation of "
          "the suite's datasets) and of the close-loop analyses of its datasets, per seed, on a machine shared "
          "with other work (load average at the end of each seed's analyses); speed is not what this "
          "document measures.", "",
          "| seed | simulate: wall / CPU, min | close-loop analyses: wall / CPU, min | workers | CPUs | load average |",
          "| --- | --- | --- | --- | --- | --- |"]
    for s in seeds:
        t = runs[s]["times"]
        m = lambda k, t=t: "–" if t.get(k) is None else f"{t[k] / 60:.1f}"  # noqa: E731
        L.append(f"| {s} | {m('simulate_s')} / {m('simulate_cpu_s')} | {m('analyze_s')} / {m('analyze_cpu_s')} | "
                 f"{t.get('jobs', '–')} | {t.get('cpus', '–')} | {t.get('load_average_1min', '–')} |")
    L.append("")
    notes = [f"Seed {s}: {runs[s]['times']['note']}" for s in seeds if runs[s]["times"].get("note")]
    L += [*notes, ""] if notes else []
    for s in seeds:
        r = runs[s]
        L += [f"## Seed {s}", "", "Anonymous folder → scenario from `SUITE/truth/key.json`.", "",
              format_suite_table(r), ""]
        if r.get("errors"):
            L += ["Analysis failures: " + "; ".join(f"`{k}`: {v}" for k, v in r["errors"].items()), ""]
    return "\n".join(L)


def data_text(data: dict) -> str:
    """The JSON file's text (sorted keys: a re-run that changes nothing changes no byte)."""
    return json.dumps(data, indent=1, sort_keys=True, ensure_ascii=False) + "\n"


#: what tests/app/test_suite_reference.py compares (criteria of the small suite, per dataset label)
STORED = ("e_error_um", "theta0_error_deg", "beta_rms_error_arcsec", "alpha_rms_error_arcsec",
          "selfcal_rms_error_arcsec", "coverage_1u", "coverage_2u", "identification_correct", "spurious",
          "residual_after_over_floor")


def expectations(run: dict, seed: int) -> str:
    """The small suite's part of a full run (same datasets at the same seed), per scenario label,
    and its overall figures: the stored expectations of the reference-score test (the text of
    tests/app/data/suite_small_seed11.json). ``run`` is a seed of :func:`doc_data` (or the run
    itself: the same keys)."""
    from benchtwin.app.score import public
    from benchtwin.app.suite import entries, overall

    small = {e.name for e in entries("small")}
    per = {run["labels"][n]["label"]: {k: run["scores"][n].get(k) for k in STORED}
           for n in run["scores"] if run["labels"][n]["label"] in small}
    for n, s in run["scores"].items():
        # a run scored before the scorer compared e and θ0 with the disk's eccentricity about the
        # axis of rotation (its scores have no ``e_reference``) measured them against the installed
        # offset: not what the scorer computes now, so no expectation for them (the slow test skips a
        # None) until benchmarks/suite_scores.py is run again (docs/scoring.md "e: which truth")
        if run["labels"][n]["label"] in small and s.get("e_reference") is None:
            per[run["labels"][n]["label"]].update(e_error_um=None, theta0_error_deg=None)
    sub = {n: s for n, s in run["scores"].items() if run["labels"][n]["label"] in small}
    return json.dumps(public({"seed": seed, "size": "small", "datasets": per, "overall": overall(sub)}),
                      indent=1, sort_keys=True) + "\n"


def drift(data_path: Path, doc_path: Path) -> str:
    """A unified diff of the doc against its rendering from the JSON ('' where they agree)."""
    import difflib

    want = render_doc(json.loads(data_path.read_text(encoding="utf-8")))
    have = doc_path.read_text(encoding="utf-8") if doc_path.exists() else ""
    if want == have:
        return ""
    return "".join(difflib.unified_diff(have.splitlines(True), want.splitlines(True), str(doc_path),
                                        f"render_doc({data_path})")) or "(they differ in line endings only)"


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs="*", default=[11, 22, 33])
    ap.add_argument("--size", default="full")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--work", default="/tmp/suite_scores")
    ap.add_argument("--doc", default=str(ROOT / "docs" / "suite-scores.md"))
    ap.add_argument("--data", default=str(ROOT / "docs" / "data" / "suite-scores.json"),
                    help="the scores the doc is rendered from")
    ap.add_argument("--expectations", default=str(ROOT / "tests" / "app" / "data" / "suite_small_seed11.json"),
                    help="where the small suite's figures of seed 11 are stored for the reference-score test")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--render", action="store_true", help="only render --doc from --data (no run)")
    mode.add_argument("--check", action="store_true", help="only compare --doc with its rendering from --data: "
                                                           "exit 1 with the diff where they differ")
    a = ap.parse_args(argv)
    doc, data_path = Path(a.doc), Path(a.data)
    if a.check:
        d = drift(data_path, doc)
        print(d or f"{doc} is what {data_path} renders to")
        return 1 if d else 0
    if a.render:
        _write(doc, render_doc(json.loads(data_path.read_text(encoding="utf-8"))))
        print(f"wrote {doc}")
        return 0
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    commit = _commit()
    _run_bench()   # the subreaper, before any pool starts
    runs = {}
    for s in a.seeds:
        runs[s] = run_seed(s, a.size, a.jobs, work, commit)
        _write(data_path, data_text(doc_data(runs, a.size)))
        data = json.loads(data_path.read_text(encoding="utf-8"))  # from the file, as the test (the datasets'
        _write(doc, render_doc(data))                              # order, and so the sums' rounding)
        if s == 11 and a.size == "full" and a.expectations:
            _write(Path(a.expectations), expectations(data["seeds"]["11"], 11))
        print(f"wrote {data_path} and {doc} (seeds so far: {sorted(runs)})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
