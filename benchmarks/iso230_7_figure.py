"""docs/img/iso230_7_polar.png: the ISO 230-7 polar plots along Y of the default scenario (jia2019).

The default scenario is simulated (``benchtwin simulate``, the default backend: a minute of CPU)
into a temporary folder, unless ``--dataset`` names such a dataset already made, and its radial
motion drawn by ``benchtwin.analysis.figures.figure_radial_motion_polar`` (the report's figure:
analysis/report/figures_iso.py ``fig_polar``) at the report's 110 dpi. The slow test
tests/twin/test_doc_figures.py draws it again and compares the pixels.

Run: .venv/bin/python benchmarks/iso230_7_figure.py [--dataset DIR] [--out PNG]  ->  docs/img/iso230_7_polar.png
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "docs" / "img" / "iso230_7_polar.png"
DPI = 110  # analysis/report/html.py FIGURE_DPI


def main(argv: list[str] | None = None) -> None:
    from benchtwin.analysis.figures import figure_radial_motion_polar
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import simulate

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path, default=None, help="a dataset of the default scenario (else simulated)")
    ap.add_argument("--out", type=Path, default=OUT, help="the PNG to write (default docs/img/iso230_7_polar.png)")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="iso230_7_figure_") as tmp:
        ds = a.dataset or simulate(load_scenario(), Path(tmp) / "ds", progress=False)
        a.out.parent.mkdir(parents=True, exist_ok=True)
        figure_radial_motion_polar(ds).savefig(a.out, dpi=DPI)
    print(a.out)


if __name__ == "__main__":
    main()
