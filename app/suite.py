"""A fixed, versioned benchmark suite of twin datasets for encoder-calibration algorithms (issue 19).

The suite is the set of scenarios the project's hidden-effect suite decided outcomes for (issue 7,
docs/hidden-suite.md: the nulls, each effect of the analysis's library, effects the measurement
absorbs, an effect outside the library) plus the two paper benches (Jia et al. 2019, Hsieh et al.
2022), each simulated with one seed. Every dataset's ``truth/`` gets an ``expected.json``: what a
correct effect tracer reports on it (and why), so :mod:`benchtwin.app.score` can score the naming.

``--blind`` anonymises the folder names (d01, d02, … in an order drawn from the seed), strips the
scenario's name and seed from each manifest, drops the twin's resume journal, and moves every
truth folder to ``SUITE/truth/<name>/`` with ``SUITE/truth/key.json`` (anonymous name → scenario):
the algorithm runs on ``SUITE/datasets/*`` alone.

A suite is complete when ``SUITE/suite.json`` exists: it is written last (atomically), so an
interrupted ``benchtwin suite`` is never taken for a suite.

Changing the list, a scenario, an override or an expectation changes :data:`SUITE_VERSION`.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.cli import InputError
from benchtwin.schema import Key, SchemaError, check_table, loads_json, read_input_text

SUITE_FORMAT = "benchtwin-suite"
SUITE_VERSION = 2  # 2: jia2019 expects its declared graduation error (issue 32); the hidden effects from their physical causes (issue 33 item 4)
DEFAULT_SEED = 11  # the first seed of benchmarks/hidden_suite.py
SIZES = ("small", "full")
NAMED = ["named"]
NAMED_OR_SET = ["named", "ambiguous"]

#: the paper benches' procedures made affordable (minutes, not hours) on the suite's 2-core budget;
#: the physics and instruments are the papers' (scenarios/*.toml), only the stops are fewer
JIA_SMALL = {"procedure.radial_positions": 120, "procedure.ccd_step": "12 deg"}
HSIEH_REDUCED = {"procedure.polygon_reps": 1, "procedure.polygon_shifts": ["0 deg", "5 deg", "10 deg"],
                 "procedure.selfcal_step": "5 deg", "procedure.radial_positions": 72, "procedure.ccd_step": "12 deg"}


@dataclass(frozen=True)
class Entry:
    """One dataset of the suite: a scenario file (relative to scenarios/), its category, what a
    correct tracer reports (``expect`` names, ``accept`` outcomes; None = naming not scored)."""

    name: str
    scenario: str
    category: str
    expect: tuple[str, ...] | None
    accept: tuple[str, ...] | None
    why: str
    overrides: Mapping[str, Any] = field(default_factory=dict)
    small: bool = False

    def expected(self) -> dict[str, Any]:
        """truth/expected.json: the decided naming outcome (accept None: naming not scored)."""
        return {"expect": None if self.expect is None else list(self.expect),
                "accept": None if self.accept is None else list(self.accept), "why": self.why,
                "suite_version": SUITE_VERSION}


# The decided outcomes are those of docs/hidden-suite.md (benchmarks/hidden_suite.py, EXPECTED),
# with the physics behind each in its notes and in docs/effects.md.
ENTRIES: tuple[Entry, ...] = (
    Entry("null_a", "hidden/null_a.toml", "null", (), ("nothing",), "nothing hidden", small=True),
    Entry("null_b", "hidden/null_b.toml", "null", (), ("nothing",), "nothing hidden (X probes, 3 heads, shifts)"),
    Entry("graduation_error", "hidden/graduation_error.toml", "library", ("graduation_error",), ("named",),
          "named: the X probes rule out a tangential motion", small=True),
    Entry("optical_radius", "hidden/optical_radius.toml", "library", ("optical_radius",), ("named", "ambiguous"),
          "named or in a set with ccd_pixel_scale / ac_scale (a scale the data cannot split)"),
    Entry("ccd_pixel_scale", "hidden/ccd_pixel_scale.toml", "library", ("ccd_pixel_scale",), ("named", "ambiguous"),
          "named or in a set with optical_radius / ac_scale"),
    Entry("tangential_motion", "hidden/tangential_motion.toml", "library", ("tangential_motion",), ("named",),
          "named: X probes on both spheres"),
    Entry("tangential_motion_no_x", "hidden/tangential_motion_no_x.toml", "library", ("tangential_motion",),
          ("ambiguous",), "the set {tangential_motion, graduation_error}: without X probes the two read alike",
          small=True),
    Entry("tilt_abbe", "hidden/tilt_abbe.toml", "library", ("tilt_abbe",), ("named", "ambiguous"),
          "named or in a set with tangential_motion (one worn bearing; a height gauge separates them)"),
    Entry("ac_drift", "hidden/ac_drift.toml", "absorbed", (), ("nothing",),
          "absorbed: a physically sized warm-up drift (1.5″/K × 5 K, τ = 20 min) is taken by the per-run setup "
          "constants U_j (Hsieh eq. 3) but for 0.04″ RMS, below the size gate (issue 33 item 4)"),
    Entry("ac_scale", "hidden/ac_scale.toml", "library", ("ac_scale",), ("named",), "named: self-calibration"),
    Entry("sphere_form", "hidden/sphere_form.toml", "library", ("sphere_form",), ("named", "ambiguous"),
          "named or in a set with graduation_error / tangential_motion (a Donaldson reversal separates them)"),
    Entry("torsion_hysteresis", "hidden/torsion_hysteresis.toml", "library", ("torsion_hysteresis",), ("named",),
          "named: both directions in one mounting"),
    Entry("interpolation_error", "hidden/interpolation_error.toml", "library", ("interpolation_error",), ("named",),
          "named: shifts 0/5/10°"),
    Entry("ccd_pixel_scale_pixel_only", "hidden/ccd_pixel_scale_pixel_only.toml", "absorbed", (), ("nothing",),
          "absorbed: the image scale is measured from the grating (Jia eq. 13)"),
    Entry("polygon_pitch_ignored", "hidden/polygon_pitch_ignored.toml", "absorbed", (), ("nothing",),
          "absorbed: β from the closure of all start faces (Hsieh eq. 3)", small=True),
    Entry("thermal_growth", "hidden/thermal_growth.toml", "outside", (), ("unexplained",),
          "unexplained: outside the library (the pattern grows with time)", small=True),
    Entry("null_paper", "hidden/null_paper.toml", "paper", ("tangential_motion",), ("named",),
          "the paper's bearing waviness (X probes): its whirls leave (1 − 1/k) of each lobe, which −δX/r "
          "describes and ∫δY does not"),
    Entry("jia2019", "jia2019.toml", "paper", ("graduation_error",), ("named", "ambiguous"),
          "the default bench declares the Mercury 3000's graduation error (3″ RMS), a division error Jia's eq. 5 "
          "lacks: the loop names it (X probes; ball bearings, no waviness)", overrides=JIA_SMALL, small=True),
    Entry("hsieh2022", "hsieh2022.toml", "paper", None, None,
          "the Hsieh bench (12 heads, no X probes, order-3 waviness): scored on the measurands only; "
          "no decided tracing outcome", overrides=HSIEH_REDUCED),
)


def entries(size: str) -> list[Entry]:
    if size not in SIZES:
        raise InputError(f"--size: expected one of {', '.join(SIZES)}, got {size!r}")
    return [e for e in ENTRIES if size == "full" or e.small]


def _scenario_path(e: Entry) -> Path:
    import benchtwin.scenarios as scen

    return Path(scen.__file__).resolve().parent / e.scenario


def _simulate_one(args: tuple[Entry, int, str]) -> tuple[str, float]:
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import simulate

    e, seed, out = args
    t0 = time.time()
    if Path(out).exists():
        shutil.rmtree(out)  # a partial dataset from an interrupted suite: redo it
    sc = load_scenario(_scenario_path(e)).with_overrides({**e.overrides, "scenario.seed": seed})
    simulate(sc, Path(out), progress=False, backend="analytic")
    (Path(out) / "truth" / "expected.json").write_text(json.dumps(e.expected(), indent=1) + "\n", encoding="utf-8")
    return e.name, time.time() - t0


def _write_json_atomic(path: Path, obj: Any) -> None:
    from benchtwin.fsio import atomic_write_text

    atomic_write_text(path, json.dumps(obj, indent=1) + "\n")


def anonymous_names(names: list[str], seed: int) -> dict[str, str]:
    """name → d01, d02, … in an order drawn from the seed (the order says nothing of the category)."""
    order = np.random.default_rng(np.random.SeedSequence([seed, 19])).permutation(len(names))
    width = max(2, len(str(len(names))))
    return {names[int(i)]: f"d{j + 1:0{width}d}" for j, i in enumerate(order)}


def write_suite(out: str | Path, seed: int = DEFAULT_SEED, blind: bool = False, size: str = "full",
                jobs: int = 1, progress: Callable[[str], None] | None = None, *, force: bool = False
                ) -> dict[str, Any]:
    """Simulate the suite into ``out`` (see the module docstring); returns the suite.json content.

    The writing rule (``benchtwin.fsio.locked_output_dir``): ``out`` is held under its lock for the
    run (a second suite into it is refused while the first lives); a non-empty ``out`` is refused
    unless ``force`` (which clears it), except the folder of an interrupted suite (its ``.partial``
    and no suite.json), which is started again."""
    from benchtwin.fsio import OutputFolder, locked_output_dir

    out = Path(out)
    if (out / "suite.json").exists() and not force:
        raise InputError(f"{out}: a suite is already there (suite.json); choose another -o, or --force to replace it")
    interrupted = (out / ".partial").is_dir() and not (out / "suite.json").exists() and not out.is_symlink()
    with locked_output_dir(out, OutputFolder("suite folder", "suite"), force=force or interrupted):
        return _write_suite(out, seed, blind, size, jobs, progress)


def _write_suite(out: Path, seed: int, blind: bool, size: str, jobs: int,
                 progress: Callable[[str], None] | None) -> dict[str, Any]:
    es = entries(size)
    work = out / ".partial"
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    todo = [(e, int(seed), str(work / e.name)) for e in es]
    done = []
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs) as ex:
            for name, dt in ex.map(_simulate_one, todo):
                done.append(name)
                if progress:
                    progress(f"[{len(done)}/{len(todo)}] {name}: {dt:.0f} s")
    else:
        for t in todo:
            name, dt = _simulate_one(t)
            done.append(name)
            if progress:
                progress(f"[{len(done)}/{len(todo)}] {name}: {dt:.0f} s")
    from benchtwin import __version__

    meta: dict[str, Any] = {"format": SUITE_FORMAT, "suite_version": SUITE_VERSION, "size": size, "seed": int(seed),
                            "blind": bool(blind), "benchtwin_version": __version__}
    if blind:
        anon = anonymous_names([e.name for e in es], int(seed))
        (out / "datasets").mkdir(exist_ok=True)
        (out / "truth").mkdir(exist_ok=True)
        for e in es:
            src, a = work / e.name, anon[e.name]
            shutil.move(str(src / "truth"), str(out / "truth" / a))
            (src / "journal.jsonl").unlink(missing_ok=True)  # the twin's resume journal holds poses
            m = json.loads((src / "manifest.json").read_text(encoding="utf-8"))
            for k in ("scenario", "seed"):
                m.pop(k, None)
            m["dataset"] = a
            _write_json_atomic(src / "manifest.json", m)
            shutil.move(str(src), str(out / "datasets" / a))
        _write_json_atomic(out / "truth" / "key.json", {
            "suite_version": SUITE_VERSION, "seed": int(seed),
            "key": {anon[e.name]: {"name": e.name, "category": e.category, "scenario": e.scenario,
                                   "overrides": dict(e.overrides)} for e in es}})
        meta["datasets"] = sorted(anon.values())
    else:
        for e in es:
            shutil.move(str(work / e.name), str(out / e.name))
        meta["datasets"] = [e.name for e in es]
        meta["entries"] = [{"name": e.name, "category": e.category, "scenario": e.scenario,
                            "overrides": dict(e.overrides)} for e in es]
    shutil.rmtree(work, ignore_errors=True)
    meta["simulate_s"] = round(time.time() - t0, 1)
    _write_json_atomic(out / "suite.json", meta)  # last: the marker of a complete suite
    return meta


# =========================================================================== reading a suite


@dataclass(frozen=True)
class SuiteItem:
    name: str        # the folder name (anonymous in a blind suite)
    dataset: Path
    truth: Path
    label: str       # the scenario name (from the key in a blind suite)
    category: str


def open_suite(suite_dir: str | Path) -> tuple[dict[str, Any], list[SuiteItem]]:
    """suite.json and its datasets (with where each truth is)."""
    sd = Path(suite_dir)
    sj = sd / "suite.json"
    if not sj.exists():
        raise InputError(f"{sd}: no suite.json (not a suite, or `benchtwin suite` did not finish)")
    meta = _read_suite_json(sj)
    if meta.get("format") != SUITE_FORMAT:
        raise InputError(f"{sj}: key 'format': expected {SUITE_FORMAT!r}, got {meta.get('format')!r}")
    if meta.get("suite_version") != SUITE_VERSION:
        raise InputError(f"{sj}: suite_version {meta.get('suite_version')!r}; this benchtwin scores version "
                         f"{SUITE_VERSION} (re-create the suite)")
    items = []
    if meta.get("blind"):
        kp = sd / "truth" / "key.json"
        if not kp.exists():
            raise InputError(f"{kp}: missing (a blind suite keeps its truth and key in SUITE/truth/)")
        key = check_table(_read_suite_json(kp), {"key": Key("table", required=True)}, str(kp), extra=True,
                          fail=InputError)["key"]
        for n in meta["datasets"]:
            k = check_table(key.get(n, {}), {"name": Key("str", n_min=1, n_max=200),
                                             "category": Key("str", n_min=1, n_max=200)},
                            str(kp), f"key.{n}", extra=True, fail=InputError)
            items.append(SuiteItem(n, sd / "datasets" / n, sd / "truth" / n, k.get("name", n), k.get("category", "?")))
    else:
        entries = meta.get("entries", [])
        for i, e in enumerate(entries):
            check_table(e, {"name": Key("str", required=True), "category": Key("str", required=True)},
                        str(sj), f"entries[{i}]", extra=True, fail=InputError)
        cat = {e["name"]: e["category"] for e in entries}
        for n in meta["datasets"]:
            items.append(SuiteItem(n, sd / n, sd / n / "truth", n, cat.get(n, "?")))
    for it in items:
        if not it.dataset.is_dir():
            raise InputError(f"{it.dataset}: dataset of the suite missing")
    return meta, items


def _read_suite_json(path: Path) -> dict[str, Any]:
    """suite.json / truth/key.json by the one JSON reader (benchtwin.schema), its keys checked: the
    datasets are folder names inside the suite (no '..', no path), the entries tables."""
    try:
        obj = loads_json(read_input_text(path, what="suite file"), str(path))
    except SchemaError as exc:
        raise InputError(str(exc)) from None
    if path.name != "suite.json":
        return check_table(obj, {}, str(path), extra=True, fail=InputError)
    meta = check_table(obj, {"datasets": Key("list[str]", required=True, n_max=10_000),
                             "entries": Key("list[table]"), "blind": Key("bool", required=True),
                             "size": Key("str", required=True), "seed": Key("int", required=True)},
                       str(path), extra=True, fail=InputError)
    for i, n in enumerate(meta["datasets"]):
        if not n or n in (".", "..") or "/" in n or "\\" in n or "\x00" in n:
            raise InputError(f"{path}: key 'datasets'[{i}]: expected a folder name of the suite, got {n!r}")
    return meta


def find_results(results_dir: Path, name: str) -> Path | None:
    """RESULTS_DIR/<name>/results.json, <name>/results.csv, <name>.json or <name>.csv."""
    for p in (results_dir / name / "results.json", results_dir / name / "results.csv", results_dir / f"{name}.json",
              results_dir / f"{name}.csv"):
        if p.exists():
            return p
    return None


# =========================================================================== scoring a suite

#: canonical results with nothing in them (a dataset the algorithm gave no results for)
EMPTY_RESULTS: dict[str, Any] = {k: None for k in (
    "e_um", "e_u_um", "theta0_deg", "theta0_u_deg", "alpha", "alpha_corrected", "beta", "selfcal", "named",
    "ambiguous", "unexplained", "residual_before_arcsec", "residual_after_arcsec")}

#: the overall figures per criterion (docs/scoring.md)
CRITERIA = ("e_error_um", "theta0_error_deg", "beta_rms_error_arcsec", "alpha_rms_error_arcsec",
            "selfcal_rms_error_arcsec", "coverage_1u", "coverage_2u", "identification", "spurious",
            "residual_after_over_floor")


def _qmean(vals: Iterable[float | None]) -> tuple[float | None, int]:
    v = [x for x in vals if x is not None]
    return (float(np.sqrt(np.mean(np.square(v)))) if v else None), len(v)


def overall(scores: Mapping[str, Mapping[str, Any] | None]) -> dict[str, Any]:
    """One figure per criterion over the suite: quadratic means of the errors (and of z), pooled
    coverage, the count of correct namings, spurious names, the residual-after/floor ratio."""
    got = [s for s in scores.values() if s is not None and not s.get("missing")]
    o: dict[str, Any] = {"datasets": len(scores), "with_results": len(got)}
    for k in ("e_error_um", "theta0_error_deg", "e_z", "theta0_z", "e_error_sweep_um", "theta0_error_sweep_deg",
              "beta_rms_error_arcsec", "alpha_rms_error_arcsec", "selfcal_rms_error_arcsec"):
        o[k], o[f"{k}_n"] = _qmean(s.get(k) for s in got)
    n = w1 = w2 = 0
    for s in got:
        for c in (s.get("coverage") or {}).values():
            if c:
                n += c["n"]
                w1 += c["within_1u"]
                w2 += c["within_2u"]
    o["coverage_n"] = n
    o["coverage_1u"] = w1 / n if n else None
    o["coverage_2u"] = w2 / n if n else None
    # scored where the results name (or decline to name) effects and the suite decided the outcome
    idents = [s["identification_correct"] for s in got if s.get("identification_correct") is not None]
    o["identification_scored"] = len(idents)
    o["identification_correct"] = sum(1 for x in idents if x)
    o["spurious"] = sum(len(s.get("spurious") or []) for s in got)
    ratios = sorted(s["residual_after_over_floor"] for s in got if s.get("residual_after_over_floor") is not None)
    o["residual_after_over_floor_median"] = ratios[len(ratios) // 2] if ratios else None
    o["residual_after_over_floor_max"] = ratios[-1] if ratios else None
    return o


def score_suite(results_for: Callable[[SuiteItem], Mapping[str, Any] | None], suite_dir: str | Path) -> dict[str, Any]:
    """Score every dataset of a suite; ``results_for(item)`` gives canonical results or None."""
    from benchtwin.app.score import read_truth, score_results

    meta, items = open_suite(suite_dir)
    scores: dict[str, Any] = {}
    labels = {}
    for it in items:
        res = results_for(it)
        labels[it.name] = {"label": it.label, "category": it.category}
        sc = score_results(res if res is not None else EMPTY_RESULTS, read_truth(it.truth, it.dataset))
        sc["missing"] = res is None
        scores[it.name] = sc
    return {"suite": {k: meta[k] for k in ("suite_version", "size", "seed", "blind")}, "labels": labels,
            "scores": scores, "overall": overall(scores)}


def score_suite_files(results_dir: str | Path, suite_dir: str | Path) -> dict[str, Any]:
    from benchtwin.app.score import read_results

    rd = Path(results_dir)
    if not rd.is_dir():
        raise InputError(f"{rd}: not a directory of results (RESULTS_DIR/<dataset>/results.json or <dataset>.json)")
    found: dict[str, str | None] = {}

    def results_for(it: SuiteItem) -> dict[str, Any] | None:
        p = find_results(rd, it.name)
        found[it.name] = str(p) if p else None
        return read_results(p) if p else None

    out = score_suite(results_for, suite_dir)
    out["results_files"] = found
    return out


def _c(v: Any, fmt: str) -> str:
    return "–" if v is None else format(v, fmt)


def format_suite_table(out: Mapping[str, Any]) -> str:
    """A Markdown table: one row per dataset, then one overall figure per criterion."""
    hdr = ("| dataset | scenario | e err µm | θ0 err ° | β RMS ″ | α RMS ″ | self-cal RMS ″ | ≤1u / ≤2u | "
           "naming | spurious | after ″ | floor ″ | after/floor |")
    lines = [hdr, "|" + " --- |" * (hdr.count("|") - 1)]
    for name, s in out["scores"].items():
        lab = out["labels"][name]
        if s.get("missing"):
            lines.append(f"| {name} | {lab['label']} | no results |" + " |" * 10)
            continue
        cov = [c for c in (s.get("coverage") or {}).values() if c]
        n = sum(c["n"] for c in cov)
        covs = f"{sum(c['within_1u'] for c in cov)}/{n} / {sum(c['within_2u'] for c in cov)}/{n}" if n else "–"
        ident = s.get("identification") or {}
        naming = "–" if ident.get("correct") is None else (
            f"{ident.get('outcome')} ({'ok' if ident.get('correct') else 'WRONG'})")
        lines.append(
            f"| {name} | {lab['label']} | {_c(s['e_error_um'], '+.4f')} | {_c(s['theta0_error_deg'], '+.4f')} | "
            f"{_c(s['beta_rms_error_arcsec'], '.4f')} | {_c(s['alpha_rms_error_arcsec'], '.4f')} | "
            f"{_c(s['selfcal_rms_error_arcsec'], '.4f')} | {covs} | {naming} | "
            f"{', '.join(s['spurious']) if s.get('spurious') else ('–' if s.get('spurious') is None else 'none')} | "
            f"{_c(s['residual_after_arcsec'], '.3f')} | {_c(s['floor_arcsec'], '.3f')} | "
            f"{_c(s['residual_after_over_floor'], '.2f')} |")
    o = out["overall"]
    lines += ["", "| criterion | overall | over |", "| --- | --- | --- |",
              f"| e error (RMS) | {_c(o['e_error_um'], '.4f')} µm (z RMS {_c(o['e_z'], '.2f')}) | {o['e_error_um_n']} |",
              f"| θ0 error (RMS) | {_c(o['theta0_error_deg'], '.4f')}° (z RMS {_c(o['theta0_z'], '.2f')}) | "
              f"{o['theta0_error_deg_n']} |",
              f"| e, θ0 error vs each sweep's exact image analysis (RMS) | {_c(o['e_error_sweep_um'], '.4f')} µm, "
              f"{_c(o['theta0_error_sweep_deg'], '.4f')}° | {o['e_error_sweep_um_n']} |",
              f"| β RMS error (quadratic mean) | {_c(o['beta_rms_error_arcsec'], '.4f')}″ | "
              f"{o['beta_rms_error_arcsec_n']} |",
              f"| α RMS error (quadratic mean) | {_c(o['alpha_rms_error_arcsec'], '.4f')}″ | "
              f"{o['alpha_rms_error_arcsec_n']} |",
              f"| self-calibration RMS error | {_c(o['selfcal_rms_error_arcsec'], '.4f')}″ | "
              f"{o['selfcal_rms_error_arcsec_n']} |",
              "| coverage ≤1u / ≤2u (pooled; normal 68.3 % / 95.4 %) | "
              + ("–" if o["coverage_1u"] is None else f"{o['coverage_1u']:.1%} / {o['coverage_2u']:.1%}")
              + f" | {o['coverage_n']} points |",
              f"| effect named correctly | {o['identification_correct']}/{o['identification_scored']} | "
              f"{o['identification_scored']} |",
              f"| spurious names | {o['spurious']} | {o['with_results']} |",
              f"| residual after / floor (median, worst) | {_c(o['residual_after_over_floor_median'], '.2f')}, "
              f"{_c(o['residual_after_over_floor_max'], '.2f')} | |",
              f"| datasets with results | {o['with_results']}/{o['datasets']} | |"]
    return "\n".join(lines)


# =========================================================================== a Python algorithm


def cache_dir() -> Path:
    """Where :func:`score_callable` keeps the suites it builds ($BENCHTWIN_CACHE or ~/.cache/benchtwin)."""
    return Path(os.environ.get("BENCHTWIN_CACHE") or Path.home() / ".cache" / "benchtwin")


def score_callable(fn: Callable[[str], Mapping[str, Any] | None], suite: str | Path | None = None, *,
                   seed: int = DEFAULT_SEED, size: str = "small", jobs: int = 1) -> dict[str, Any]:
    """Score ``fn`` (dataset path → results dict, the project's results.json keys or the minimal
    results format) on a suite, without files: ``suite`` is a suite directory, or None / "small" /
    "full" for a blind suite of that size built once in :func:`cache_dir` (minutes) and reused.

    ``fn`` gets each dataset without its truth (a non-blind suite's dataset is copied without
    truth/ and journal first). An exception in ``fn`` is that dataset's missing result (its
    message in ``errors``); bad results (wrong keys, not numbers) raise :class:`InputError`."""
    import tempfile

    from benchtwin.app.score import canonical_results

    if suite is None or str(suite) in SIZES:
        size = str(suite) if suite is not None else size
        path = cache_dir() / f"suite-v{SUITE_VERSION}-{size}-seed{int(seed)}-blind"
        if not (path / "suite.json").exists():
            write_suite(path, seed=seed, blind=True, size=size, jobs=jobs)
    else:
        path = Path(suite)
    meta, _ = open_suite(path)
    errors: dict[str, str] = {}
    name = getattr(fn, "__name__", "fn")
    with tempfile.TemporaryDirectory(prefix="benchtwin-score-") as tmp:
        def results_for(it: SuiteItem) -> dict[str, Any] | None:
            ds = it.dataset
            if not meta.get("blind"):
                ds = Path(tmp) / it.name
                shutil.copytree(it.dataset, ds, ignore=shutil.ignore_patterns("truth", "journal.jsonl"))
            try:
                raw = fn(str(ds))
            except Exception as exc:  # noqa: BLE001 - the algorithm's failure is its missing result
                errors[it.name] = f"{type(exc).__name__}: {exc}"
                return None
            return None if raw is None else canonical_results(raw, f"{name}({it.name})")

        out = score_suite(results_for, path)
    out["errors"] = errors
    out["suite_dir"] = str(path)
    out["table"] = format_suite_table(out)
    return out
