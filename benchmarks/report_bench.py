"""Where `benchtwin analyze` (or `close-loop`) spends its time, in one process: imports, the analysis
steps, the tracing, the bench picture and the HTML report (each figure's draw + PNG encode), wall and CPU.

Issue #17 (docs/benchmarks.md, "What the rest of the time is"). Runs the same code as
``benchtwin analyze DATASET -o OUT`` (``benchtwin.app.commands.cmd_analyze``) with timers wrapped
around its parts, so the figures are the command's own; nothing is changed in what it computes
(``results.json`` is written as usual and can be compared with ``cmp``). Each part's time is
*inclusive* of what it calls: "analysis steps" excludes the report and the bench picture, which
are listed separately. CPU = ``time.process_time`` of this process, all its threads (the
eccentricity step's worker threads, analysis/parallel.py, included).

Usage: ``.venv/bin/python benchmarks/report_bench.py DATASET [-o OUT] [--close-loop] [--json]``
(``--close-loop``: the tracing's own time, measured inside the one process, issue 17's "tracing the
default ≤ 1 s"). The bench
picture's cache (app/bench_view.py) is used as configured: ``BENCHTWIN_CACHE=none``
measures the render itself.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

_T0 = (time.perf_counter(), time.process_time())

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


class Timers:
    def __init__(self) -> None:
        self.wall: dict[str, float] = defaultdict(float)
        self.cpu: dict[str, float] = defaultdict(float)
        self.n: dict[str, int] = defaultdict(int)

    def wrap(self, obj: Any, attr: str, name: str) -> None:
        fn = getattr(obj, attr)
        timers = self

        def timed(*a: Any, **k: Any) -> Any:
            w0, c0 = time.perf_counter(), time.process_time()
            try:
                return fn(*a, **k)
            finally:
                timers.wall[name] += time.perf_counter() - w0
                timers.cpu[name] += time.process_time() - c0
                timers.n[name] += 1

        setattr(obj, attr, timed)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("-o", "--out", type=Path, default=None, help="analysis output folder (default: a temporary one)")
    ap.add_argument("--close-loop", action="store_true",
                    help="run close-loop (cmd_close_loop: analyze + tracing) instead of analyze")
    ap.add_argument("--json", action="store_true", help="print a JSON summary as the last line")
    args = ap.parse_args(argv)

    t = Timers()
    w0, c0 = time.perf_counter(), time.process_time()
    import argparse as _ap

    import matplotlib.figure

    import benchtwin.analysis.pipeline as pipeline
    import benchtwin.app.bench_view as bench_view
    import benchtwin.app.commands as commands
    imports = (time.perf_counter() - w0, time.process_time() - c0)

    t.wrap(pipeline, "_write_report", "report (all figures + HTML)")
    t.wrap(matplotlib.figure.Figure, "savefig", "  figures: draw + PNG encode")
    t.wrap(bench_view, "bench_preface_for_dataset", "bench picture (figure built)")
    t.wrap(bench_view, "render_bench", "  bench render (MuJoCo, cache miss)")
    t.wrap(pipeline, "_step", "analysis steps (radial, CCD, polygon)")
    t.wrap(pipeline, "_close_loop", "close the loop (tracing + model after)")
    # the tracing alone (issue #17's "≤ 1 s"): _close_loop imports trace from the package when called
    import benchtwin.analysis.tracing as tracing
    t.wrap(tracing, "trace", "tracing alone (trace, inside close the loop)")

    out = args.out or Path(tempfile.mkdtemp(prefix="benchtwin-report-bench-")) / "an"
    ns = _ap.Namespace(dataset=args.dataset, out=out, order=10, model=None, force=True, quiet=True, json=False)
    w1, c1 = time.perf_counter(), time.process_time()
    (commands.cmd_close_loop if args.close_loop else commands.cmd_analyze)(ns)
    total = (time.perf_counter() - w1, time.process_time() - c1)
    proc = (time.perf_counter() - _T0[0], time.process_time() - _T0[1])

    where = getattr(bench_view, "bench_view_cache_dir", None)  # absent before the cache existed
    cache = (where() or "off") if where else "none in this version"
    what = "close-loop" if args.close_loop else "analyze"
    print(f"benchtwin {what} {args.dataset} (in-process, cmd_{what.replace('-', '_')}); load average {os.getloadavg()[0]:.1f}; "
          f"bench picture cache: {cache}")
    print(f"{'part':44s} {'calls':>5s} {'wall s':>8s} {'CPU s':>8s}")
    rows = [("imports (pipeline, app, matplotlib)", 1, *imports)]
    rows += [(k, t.n[k], t.wall[k], t.cpu[k]) for k in t.wall]
    rows += [(f"cmd_{what.replace('-', '_')} total", 1, *total), ("process (incl. interpreter start-up)", 1, *proc)]
    for name, n, w, c in rows:
        print(f"{name:44s} {n:5d} {w:8.3f} {c:8.3f}")
    print(f"results: {out / 'results.json'}")
    if args.json:
        print(json.dumps({"parts": {name: {"calls": n, "wall_s": w, "cpu_s": c} for name, n, w, c in rows}}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
