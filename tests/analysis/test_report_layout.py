"""The report's fixed margins (analysis/report/layout.py) hold the figures' texts: every title, label
and tick label inside the figure, and no axes' texts over a neighbouring axes, for the grids the
report uses (one axes, two rows, one row of four) with one- and two-line titles and wide tick
labels."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from benchtwin.analysis.report.layout import fixed_margins


@pytest.mark.parametrize("size, grid, title", [
    ((7.0, 4.2), (1, 1), "Radial error motion (harmonics 2…10, eq. 7)\ndisk: total 0.233 µm, sync 0.193 µm"),
    ((7.0, 4.2), (1, 1), "one line"),
    ((9.0, 5.0), (2, 1), "status: explained"),
    ((15.0, 4.0), (1, 4), "vs polygon face (p = 1)"),
])
def test_texts_inside_the_figure_and_off_the_neighbours(size, grid, title):
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    axes = fig.subplots(*grid, squeeze=False).ravel()
    for i, ax in enumerate(axes):
        ax.plot(np.linspace(0, 2500, 50), np.linspace(-0.15, 10.0, 50) * (1 if i % 2 else -1))
        ax.set_xlabel("face under the autocollimator")
        ax.set_ylabel("residual [arcsec]")
        if i < grid[1]:
            ax.set_title(title, fontsize=10)
    fixed_margins(fig)
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    W, H = fig.canvas.get_width_height()
    # each axes' drawn texts (title, labels, tick labels: its tight box), 1 px for anti-aliased rims
    texts = [ax.get_tightbbox(r) for ax in axes]
    for b in texts:
        assert b.x0 >= -1 and b.y0 >= -1 and b.x1 <= W + 1 and b.y1 <= H + 1, (b, W, H)
    frames = [ax.get_window_extent(r) for ax in axes]
    for i, b in enumerate(texts):
        for j, frame in enumerate(frames):
            if i != j:
                assert not b.overlaps(frame), (i, j, b, frame)
