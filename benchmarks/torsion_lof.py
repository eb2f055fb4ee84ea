"""Eq. 3's lack of fit against pure error on one loop-validation bench (docs/loop-validation.md,
"Eq. 3's lack of fit against pure error" and "The twin fixed").

    .venv/bin/python benchmarks/torsion_lof.py SEED CLASS INDEX OUT [--dwell S] [--without-effect]

Draws the bench of ``benchmarks/loop_validation.py`` (``bench_scenario``: SEED, CLASS, INDEX; with
``--without-effect`` the same draw with its ``[hidden]`` section emptied), optionally with another
``procedure.dwell``, simulates it into OUT (analytic backend; the analysis is not run) and prints
one JSON line:

- eq. 3's residual sum of squares and dof (``analysis.shift_angle.reading_repeatability`` on the
  polygon readings referred to their commanded stops, ``analysis.pipeline.polygon_table``);
- the pure error: every (shift, direction, start face)'s R repetitions x N steps table after its
  row and column means, SS_pe with (R - 1)(N - 1) dof each (complete rows);
- F = s2_lof / s2_pe with (nu_eq3 - nu_pe, nu_pe) dof and its upper-tail p;
- ``r_twist``: the correlation of the truth's ``twist_arcsec`` at the same (shift, direction,
  start face, step) between repetitions 0 and 1.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def pure_error(table) -> tuple[float, int]:
    """SS and dof of the repetitions' scatter per (shift, direction, start face) after row and column means."""
    ss, nu = 0.0, 0
    N = table.n_faces
    for S in table.shifts_deg:
        groups: dict[tuple, list[np.ndarray]] = {}
        for (_rep, d), t in table.runs.get(float(S), {}).items():
            for j0 in range(N):
                if not np.any(np.isnan(t[j0])):
                    groups.setdefault((d, j0), []).append(t[j0])
        for ys in groups.values():
            if len(ys) < 2:
                continue
            Y = np.asarray(ys)
            Z = Y - Y.mean(axis=1, keepdims=True) - Y.mean(axis=0, keepdims=True) + Y.mean()
            ss += float((Z**2).sum())
            nu += (Y.shape[0] - 1) * (Y.shape[1] - 1)
    return ss, nu


def twist_correlation(truth: Path) -> float:
    tw = {}
    with open(truth / "polygon.csv", newline="") as f:
        for r in csv.DictReader(f):
            tw[(r["shift_deg"], r["direction"], r["start_face"], r["step"], int(r["rep"]))] = float(r["twist_arcsec"])
    k0 = [k for k in tw if k[4] == 0 and k[:4] + (1,) in tw]
    if not k0:
        return float("nan")
    return float(np.corrcoef([tw[k] for k in k0], [tw[k[:4] + (1,)] for k in k0])[0, 1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("seed", type=int)
    ap.add_argument("cls")
    ap.add_argument("index", type=int)
    ap.add_argument("out", type=Path)
    ap.add_argument("--dwell", type=float, default=None, help="procedure.dwell in s (default: the drawn bench's)")
    ap.add_argument("--without-effect", action="store_true")
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from benchmarks.loop_validation import bench_scenario, effect_classes
    from benchtwin.analysis.dataset import Dataset
    from benchtwin.analysis.distributions import f_sf
    from benchtwin.analysis.pipeline import BenchGeometry, polygon_table
    from benchtwin.analysis.shift_angle import reading_repeatability, tabulate_polygon
    from benchtwin.twin.simulate import simulate

    hidden = {} if a.without_effect else effect_classes()[a.cls]
    sc, b = bench_scenario(a.seed, a.cls, a.index, hidden, keep_causes=a.without_effect)
    if a.dwell is not None:
        sc = sc.with_overrides({"procedure.dwell": f"{a.dwell!r} s"})
    t0 = time.time()
    ds = Path(simulate(sc, a.out, progress=False, backend="analytic"))
    sim_s = time.time() - t0
    d = Dataset(ds)
    cols = polygon_table(d)
    table = tabulate_polygon(cols, BenchGeometry.from_manifest(d.bench).faces)
    rep = reading_repeatability(table)
    ss_pe, nu_pe = pure_error(table)
    nu_lof = rep.dof - nu_pe
    F = ((rep.rss_arcsec2 - ss_pe) / nu_lof) / (ss_pe / nu_pe)
    print(json.dumps({"seed": a.seed, "cls": a.cls, "index": a.index, "dwell": a.dwell,
                      "without_effect": a.without_effect, "draw": b["draw"], "F": F, "nu_lof": nu_lof,
                      "nu_pe": nu_pe, "p": float(f_sf(F, nu_lof, nu_pe)), "s_eq3": rep.s_arcsec,
                      "s_pe": math.sqrt(ss_pe / nu_pe), "r_twist": twist_correlation(ds / "truth"),
                      "simulate_s": round(sim_s, 1)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
