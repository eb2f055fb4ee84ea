"""docs/img/bench_view.png: the picture that opens a run's report, for the jia2019 bench.

It is ``benchtwin.app.bench_view.fig_bench`` (MuJoCo's offscreen render of the twin's bodies at
θ = 0, the instruments marked where they read) of the default scenario, saved at 90 dpi (900 px
wide). tests/twin/test_doc_figures.py draws it again and compares the pixels.

Run: .venv/bin/python benchmarks/bench_view_figure.py [--out PNG]  ->  docs/img/bench_view.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "docs" / "img" / "bench_view.png"
DPI = 90


def main(argv: list[str] | None = None) -> None:
    from benchtwin.app.bench_view import fig_bench
    from benchtwin.twin.scenario import load_scenario

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT, help="the PNG to write (default docs/img/bench_view.png)")
    out = ap.parse_args(argv).out
    out.parent.mkdir(parents=True, exist_ok=True)
    fig_bench(load_scenario()).savefig(out, dpi=DPI)
    print(out)


if __name__ == "__main__":
    main()
