"""The ``score``, ``suite`` and ``score-suite`` subcommands (issue 19; registered by benchtwin.cli).

- ``benchtwin score RESULTS DATASET``: one results file against one dataset's truth
  (:mod:`benchtwin.app.score`);
- ``benchtwin suite -o DIR [--seed N] [--blind] [--size small|full]``: the benchmark suite
  (:mod:`benchtwin.app.suite`);
- ``benchtwin score-suite RESULTS_DIR SUITE_DIR``: every dataset of a suite, one table and one
  overall figure per criterion.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from benchtwin.cli import InputError, command, force_argument


def _score_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("results", type=Path, help="results.json (benchtwin analyze / close-loop) or a minimal results "
                                              "file (.json or .csv, docs/scoring.md); a directory means DIR/results.json")
    p.add_argument("dataset", type=Path, help="the dataset the results are of (its truth/ is read)")
    p.add_argument("--truth", type=Path, default=None,
                   help="the truth folder when it is not DATASET/truth (a blind suite: SUITE/truth/<name>)")


@command("score", "compare a results file with a dataset's truth (docs/scoring.md)", _score_args)
def cmd_score(ns: argparse.Namespace) -> dict[str, Any]:
    from benchtwin.app.score import format_table, public, score_files

    s = score_files(ns.results, ns.dataset, ns.truth)
    out = public(s)
    out["ok"] = True
    out["message"] = f"{ns.results} against {ns.dataset}:\n" + format_table(s)
    return out


def _suite_args(p: argparse.ArgumentParser) -> None:
    from benchtwin.app.suite import DEFAULT_SEED, SIZES

    p.add_argument("-o", "--out", type=Path, required=True, help="suite directory to write")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"the seed of every dataset (default {DEFAULT_SEED})")
    p.add_argument("--blind", action="store_true",
                   help="anonymised folder names; truth and key moved to OUT/truth/, datasets in OUT/datasets/")
    p.add_argument("--size", choices=SIZES, default="full",
                   help="full: all 19 datasets (~6 min with --jobs 2); small: six of them")
    p.add_argument("--jobs", type=int, default=1, help="simulate this many datasets in parallel (default 1)")
    force_argument(p, "replace a non-empty suite folder (default: refuse it; docs/reliability.md)")


@command("suite", "write the fixed, versioned benchmark suite of twin datasets", _suite_args)
def cmd_suite(ns: argparse.Namespace) -> dict[str, Any]:
    from benchtwin.app.suite import write_suite

    if ns.jobs < 1:
        raise InputError(f"--jobs: expected an integer >= 1, got {ns.jobs}")
    say = None if (ns.quiet or ns.json) else (lambda m: print(m, file=sys.stderr, flush=True))
    meta = write_suite(ns.out, seed=ns.seed, blind=ns.blind, size=ns.size, jobs=ns.jobs, progress=say,
                       force=ns.force)
    where = f"{ns.out}/datasets" if ns.blind else str(ns.out)
    return {"ok": True, "suite": str(ns.out), **meta,
            "message": f"suite v{meta['suite_version']} ({meta['size']}, seed {meta['seed']}"
                       f"{', blind' if ns.blind else ''}): {len(meta['datasets'])} datasets in {where}"}


def _score_suite_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("results_dir", type=Path,
                   help="RESULTS_DIR/<dataset>/results.json (or results.csv, <dataset>.json, <dataset>.csv)")
    p.add_argument("suite_dir", type=Path, help="a suite written by `benchtwin suite`")


@command("score-suite", "score a directory of results against a suite: one table, one figure per criterion",
         _score_suite_args)
def cmd_score_suite(ns: argparse.Namespace) -> dict[str, Any]:
    from benchtwin.app.score import public
    from benchtwin.app.suite import format_suite_table, score_suite_files

    out = score_suite_files(ns.results_dir, ns.suite_dir)
    res = public(out)
    res["ok"] = True
    res["message"] = format_suite_table(out)
    return res
