"""Reference scores of the project's own analysis on the benchmark suite (issue 19).

For each seed: ``benchtwin suite --blind`` (benchtwin.app.suite.write_suite), the project's analysis
``benchtwin.analysis.pipeline.analyze(dataset, out, close_loop=True)`` on every dataset of
``SUITE/datasets/`` (truth is in ``SUITE/truth/``, out of the analysis's reach), then
``benchtwin score-suite`` (benchtwin.app.suite.score_suite_files). Writes docs/suite-scores.md: the
overall figures per criterion and seed, and each seed's table.

    nice .venv/bin/python benchmarks/suite_scores.py [--seeds 11 22 33] [--size full] [--jobs 2]
                                                     [--work /tmp/suite_scores] [--doc docs/suite-scores.md]

Resumable: a seed's suite and each dataset's results.json are kept in --work and not redone.
"""

from __future__ import annotations

import argparse
import json
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


def _commit() -> str:
    import subprocess

    try:
        return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


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


def run_seed(seed: int, size: str, jobs: int, work: Path) -> dict:
    from benchtwin.app.suite import open_suite, score_suite_files, write_suite

    sd, rd = work / f"suite_{size}_seed{seed}", work / f"results_{size}_seed{seed}"
    t0 = time.time()
    if not (sd / "suite.json").exists():
        write_suite(sd, seed=seed, blind=True, size=size, jobs=jobs, progress=lambda m: print(f"seed {seed} {m}",
                                                                                               flush=True))
    t_sim = time.time() - t0
    _, items = open_suite(sd)
    t0 = time.time()
    errors = {}
    with ProcessPoolExecutor(max_workers=jobs) as ex:
        for ds, dt, err in ex.map(_analyze, [(str(it.dataset), str(rd / it.name)) for it in items]):
            print(f"seed {seed} analyse {Path(ds).name}: {dt:.0f} s {err or ''}", flush=True)
            if err:
                errors[Path(ds).name] = err
    out = score_suite_files(rd, sd)
    out["errors"] = errors
    import benchtwin

    out["naive"] = benchtwin.score(readme_naive(), suite=sd)
    times = work / f"times_{size}_seed{seed}.json"  # kept from the run that did the work (resumes are fast)
    if t_sim > 60 or not times.exists():
        times.write_text(json.dumps({"simulate_s": round(t_sim, 1), "analyze_s": round(time.time() - t0, 1)}))
    out.update(json.loads(times.read_text()))
    return out


NOTES = """## Reading the figures

- **e, θ0 z RMS** are dominated by two datasets. `ccd_pixel_scale`: its hidden effect is a grating
  period 3 % off the datasheet, so the image scale (Jia eq. 13) and with it e are 3 % off (≈ 0.2 µm)
  while the stated u is ≈ 0.01 µm; the tracer names the effect (in a set with optical_radius /
  ac_scale) but the reported e is not corrected. `hsieh2022` (one radial revolution in the suite's
  reduced procedure): the CCD sweep's once-per-revolution axis motion moves e and θ0 by a few nm /
  up to 0.4° from the installed values, beyond a u that one revolution cannot size (|z| up to 10 for
  e, 20 for θ0 at seed 33). Against each sweep's exact image analysis (`e_error_sweep_um`) both stay
  within a nm and 0.02°: the image processing is right, the stated u is what is short. On
  `jia2019` / `null_paper` the same motion (0.06 µm) shifts e by up to 0.1 µm and θ0 by 0.5°, and
  there u covers it (|z| ≤ 1.6).
- **α RMS** is dominated by `ac_scale`: the autocollimator's hidden gain error is in α itself (the
  polygon calibration measures α through the AC); the tracer names ac_scale, the reported α is not
  corrected for it.
- **Naming**: the project's tracer on `thermal_growth` reports the residual as unexplained (right)
  and, beside it, an ambiguity set of library effects for the stationary part of the pattern: those
  names are counted as spurious (docs/scoring.md), which docs/hidden-suite.md does not do.
- **after / floor**: ≈ 0.6–1.0 where the model is complete; ≈ 6–12 on the paper benches (`null_paper`,
  `jia2019`), whose non-repeating axis motion is not in the floor (docs/scoring.md); ≈ 2 on
  `thermal_growth` (outside the library, ≈ 2–3). `hsieh2022`'s naming is not scored (no decided outcome).
"""


def write_doc(doc: Path, runs: dict[int, dict], size: str) -> None:
    from benchtwin.app.suite import SUITE_VERSION, format_suite_table

    f = lambda v, fmt: "–" if v is None else format(v, fmt)  # noqa: E731
    seeds = sorted(runs)
    L = ["# Reference scores of the project's analysis on the benchmark suite", "",
         "Generated by `benchmarks/suite_scores.py` — do not edit by hand. The suite is "
         f"`benchtwin suite --blind --size {size} --seed N` (suite version {SUITE_VERSION}, "
         "app/suite.py); the algorithm scored is the project's own "
         "`benchtwin close-loop` (analysis.pipeline.analyze with close_loop=True) on "
         "`SUITE/datasets/*` with the truth out of reach; the scores are `benchtwin score-suite` "
         "(rules: [scoring.md](scoring.md)). Compare your algorithm's `score-suite` output "
         "with the row of the same seed. Generated at commit " + _commit() + ".", "",
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
            f"{f(runs[s]['overall'][key], fmt)} → {f(runs[s]['naive']['overall'][key], fmt)}" for s in seeds) + " |")
    L += ["", "Times (2 workers on a shared 2-core machine, load average ≈ 19): " + "; ".join(
        f"seed {s}: simulate {runs[s]['simulate_s'] / 60:.1f} min, analyse {runs[s]['analyze_s'] / 60:.1f} min"
        for s in seeds) + ".", ""]
    for s in seeds:
        r = runs[s]
        L += [f"## Seed {s}", "", "Anonymous folder → scenario from `SUITE/truth/key.json`.", "",
              format_suite_table(r), ""]
        if r.get("errors"):
            L += ["Analysis failures: " + "; ".join(f"`{k}`: {v}" for k, v in r["errors"].items()), ""]
    doc.write_text("\n".join(L), encoding="utf-8")


#: what tests/app/test_suite_reference.py compares (criteria of the small suite, per dataset label)
STORED = ("e_error_um", "theta0_error_deg", "beta_rms_error_arcsec", "alpha_rms_error_arcsec",
          "selfcal_rms_error_arcsec", "coverage_1u", "coverage_2u", "identification_correct", "spurious",
          "residual_after_over_floor")


def write_expectations(path: Path, run: dict, seed: int) -> None:
    """The small suite's part of a full run (same datasets at the same seed), per scenario label,
    and its overall figures: the stored expectations of the reference-score test."""
    from benchtwin.app.suite import entries, overall

    small = {e.name for e in entries("small")}
    per = {run["labels"][n]["label"]: {k: run["scores"][n].get(k) for k in STORED}
           for n in run["scores"] if run["labels"][n]["label"] in small}
    sub = {n: s for n, s in run["scores"].items() if run["labels"][n]["label"] in small}
    from benchtwin.app.score import public

    path.write_text(json.dumps(public({"seed": seed, "size": "small", "datasets": per, "overall": overall(sub)}),
                               indent=1, sort_keys=True) + "\n", encoding="utf-8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs="*", default=[11, 22, 33])
    ap.add_argument("--size", default="full")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--work", default="/tmp/suite_scores")
    ap.add_argument("--doc", default=str(ROOT / "docs" / "suite-scores.md"))
    ap.add_argument("--expectations", default=str(ROOT / "tests" / "app" / "data" / "suite_small_seed11.json"),
                    help="where the small suite's figures of seed 11 are stored for the reference-score test")
    a = ap.parse_args(argv)
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    runs = {}
    for s in a.seeds:
        runs[s] = run_seed(s, a.size, a.jobs, work)
        (work / f"scores_{a.size}_seed{s}.json").write_text(json.dumps(
            __import__("benchtwin.app.score", fromlist=["public"]).public(runs[s]), indent=1, default=str))
        write_doc(Path(a.doc), runs, a.size)
        if s == 11 and a.size == "full" and a.expectations:
            Path(a.expectations).parent.mkdir(parents=True, exist_ok=True)
            write_expectations(Path(a.expectations), runs[s], s)
        print(f"wrote {a.doc} (seeds so far: {sorted(runs)})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
