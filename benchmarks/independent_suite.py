"""The loop on data it has never seen (issue 16 item 1): the verdict table of the independent generator.

Every case of ``tests/independent/generator.py`` (its own geometry, writers and rasteriser; nothing
from ``benchtwin.twin`` or ``benchtwin.analysis``) × seeds: write the dataset, run
``analysis.pipeline.analyze(dataset, out, close_loop=True)`` and score the verdict (the effects it
names or leaves in an ambiguity set, or "unexplained") against the case's correct verdicts. For the
reference-chain cases (autocollimator drift, non-linearity) the corrected curve
``encoder_error_corrected_arcsec`` is checked against the true α too (≥ 95 % of points within 2u).

    .venv/bin/python benchmarks/independent_suite.py [--seeds 1 2] [--jobs 1] [--only CASE ...]
                                                     [--work /tmp/independent_suite] [--json OUT]

Prints a table (case, expected, verdict per seed, right / total, RMS before → after) and the total.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def run_one(name: str, seed: int, work: str) -> dict:
    from benchtwin.analysis.pipeline import analyze
    from tests.independent.generator import CASES, corrected_check, verdict_of, write_case

    case = CASES[name]
    rec: dict = {"case": name, "seed": seed}
    d = Path(work) / name / f"seed{seed}"
    shutil.rmtree(d, ignore_errors=True)
    try:
        t0 = time.time()
        ds, truth = write_case(case, Path(work), seed)
        t1 = time.time()
        res = analyze(ds, d / "analysis", progress=False, close_loop=True)["results"]
        rec["generate_s"], rec["analyze_s"] = round(t1 - t0, 1), round(time.time() - t1, 1)
    except Exception as exc:  # noqa: BLE001 - recorded in the table
        rec["error"] = f"{type(exc).__name__}: {exc}"
        rec["traceback"] = traceback.format_exc()
        return rec
    v = verdict_of(res)
    rec["effects"] = sorted(v["effects"])
    rec["named"] = v["named"]
    rec["unexplained"] = v["unexplained"]
    rec["correct"] = case.correct(v)
    rec["rms_before"] = (res.get("residual_test") or {}).get("rms_arcsec")
    rec["rms_after"] = (res.get("residual_after_trace") or {}).get("rms_arcsec")
    if case.corrected:
        rec["corrected"] = corrected_check(res, truth)
    return rec


def describe(rec: dict) -> str:
    if "error" in rec:
        return "error"
    if rec["unexplained"]:
        s = "unexplained"
        if rec["effects"]:
            s += " (+" + ",".join(rec["effects"]) + ")"
        return s
    if not rec["effects"]:
        return "nothing"
    amb = sorted(set(rec["effects"]) - set(rec["named"]))
    return ",".join(rec["named"]) + (" {" + ",".join(amb) + "}" if amb else "")


def main(argv=None) -> int:
    from tests.independent.generator import CASES

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs="*", default=[1, 2])
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--work", default="/tmp/independent_suite")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    names = [n for n in CASES if not a.only or n in a.only]
    jobs = [(n, s) for n in names for s in a.seeds]
    recs: list[dict] = []
    t0 = time.time()
    with ProcessPoolExecutor(max_workers=max(1, a.jobs)) as ex:
        futs = [ex.submit(run_one, n, s, a.work) for n, s in jobs]
        for f in as_completed(futs):
            r = f.result()
            recs.append(r)
            print(f"[{len(recs)}/{len(jobs)}] {r['case']} seed {r['seed']}: {describe(r)}"
                  + ("" if r.get("correct") else "  <- WRONG"), flush=True)
    by = {(r["case"], r["seed"]): r for r in recs}
    print()
    print("| case | bench | correct verdicts | " + " | ".join(f"seed {s}" for s in a.seeds)
          + " | right | RMS before → after ″ | corrected curve |")
    print("| --- | --- | --- | " + " | ".join("---" for _ in a.seeds) + " | --- | --- | --- |")
    right = total = 0
    for n in names:
        c = CASES[n]
        cells, ok, rms, cor = [], 0, [], []
        for s in a.seeds:
            r = by[(n, s)]
            good = bool(r.get("correct"))
            ok += good
            cells.append(describe(r) if good else f"**{describe(r)}**")
            if r.get("rms_before") is not None:
                rms.append(f"{r['rms_before']:.3f} → {r['rms_after']:.3f}")
            if r.get("corrected"):
                k = r["corrected"]
                cor.append(f"{'ok' if k['ok'] else 'FAIL'} ({100 * k['within_frac']:.0f} % ≤ 2u, "
                           f"{k['rms_arcsec']:.3f}″ vs raw {k.get('raw_rms_arcsec', float('nan')):.3f}″)")
        right += ok
        total += len(a.seeds)
        print(f"| `{n}` | {c.what} | {c.why or 'nothing named'} | " + " | ".join(cells)
              + f" | {ok}/{len(a.seeds)} | {'; '.join(rms)} | {'; '.join(cor) or '–'} |")
    print(f"\n**Right: {right}/{total}** ({time.time() - t0:.0f} s, {a.jobs} worker(s))")
    if a.json:
        Path(a.json).write_text(json.dumps(recs, indent=1, default=str))
    for r in recs:
        if "error" in r:
            print(f"\n{r['case']} seed {r['seed']}: {r['traceback']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
