"""Fixed margins, in inches, for the report's figures (a grid of axes with their titles and labels).

Why not one of matplotlib's layout engines (constrained, tight): with an engine set, ``savefig``
draws the figure twice, a dry run that lays it out and then the real draw
(``FigureCanvasBase.print_figure``, matplotlib 3.x), and the layout itself measures every text's
extent. The report's figures have known content (tick labels of a few characters, a title of one
or two lines over each top axes, x and y labels), so margins in inches fit them at any figure
size. Measured on the default report (issue #17, docs/benchmarks.md): the seven figures that used
``constrained`` took ≈ 1 s of CPU more than with these margins.
"""

from __future__ import annotations

from typing import Any

#: inches: y tick labels and the y label (left), the x tick labels and the x label (bottom)
LEFT_IN, RIGHT_IN, BOTTOM_IN = 0.75, 0.2, 0.5
#: inches above the top axes: without a title, and per line of a (fontsize 10) title
TOP_BARE_IN, TITLE_LINE_IN = 0.15, 0.19
#: inches between rows (the upper axes' x tick labels and x label) and between columns (the right
#: axes' y tick labels)
ROW_GAP_IN, COL_GAP_IN = 0.55, 0.7


def fixed_margins(fig: Any, *, left_in: float = LEFT_IN, right_in: float = RIGHT_IN, bottom_in: float = BOTTOM_IN,
                  row_gap_in: float = ROW_GAP_IN, col_gap_in: float = COL_GAP_IN) -> Any:
    """Place ``fig``'s grid of axes with these margins (inches); the top margin holds the top row's
    longest title (a title on a lower row must fit in ``row_gap_in``). Returns ``fig``."""
    w, h = (float(v) for v in fig.get_size_inches())
    axes = [ax for ax in fig.get_axes() if ax.get_subplotspec() is not None]
    gs = axes[0].get_subplotspec().get_gridspec() if axes else None
    nrows, ncols = gs.get_geometry() if gs is not None else (1, 1)
    top_row = [ax for ax in axes if ax.get_subplotspec().is_first_row()]
    lines = max((ax.get_title().count("\n") + 1 for ax in top_row if ax.get_title()), default=0)
    top_in = TOP_BARE_IN + TITLE_LINE_IN * lines
    # subplots_adjust takes the gaps as fractions of the mean axes' height and width
    ax_h = (h - top_in - bottom_in - (nrows - 1) * row_gap_in) / nrows
    ax_w = (w - left_in - right_in - (ncols - 1) * col_gap_in) / ncols
    fig.subplots_adjust(left=left_in / w, right=1.0 - right_in / w, bottom=bottom_in / h, top=1.0 - top_in / h,
                        hspace=row_gap_in / ax_h if nrows > 1 else None,
                        wspace=col_gap_in / ax_w if ncols > 1 else None)
    return fig


__all__ = ["fixed_margins"]
