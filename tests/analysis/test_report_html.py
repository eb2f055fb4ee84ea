"""The HTML report draws its figures when rendered, shared with a forked child (issue #17): the
same file as drawing them all in one process, in the order they were added."""

from __future__ import annotations

import re

import numpy as np
import pytest

from benchtwin.analysis.report.html import Report


def _fig(k: int):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3, 2))
    ax = fig.subplots()
    x = np.linspace(0, 2 * np.pi, 200)
    ax.plot(x, np.sin((k + 1) * x))
    ax.set_title(f"order {k + 1}")
    return fig


def _report(n: int) -> str:
    rep = Report("t")
    for k in range(n):
        rep.paragraph(f"before {k}")
        rep.figure(_fig(k), f"figure {k}")
    rep.paragraph("end")
    return rep.render()


@pytest.mark.parametrize("n", [1, 2, 5])
def test_figures_drawn_in_a_child_give_the_same_report(n, monkeypatch):
    forked = _report(n)
    monkeypatch.setenv("BENCHTWIN_FORK", "0")
    assert forked == _report(n)
    # each figure in its place, with its own picture
    captions = re.findall(r"<figcaption>(figure \d+)</figcaption>", forked)
    assert captions == [f"figure {k}" for k in range(n)]
    imgs = re.findall(r'src="data:image/png;base64,([^"]+)"', forked)
    assert len(set(imgs)) == n and all(len(i) > 1000 for i in imgs)


def test_a_figure_that_fails_to_draw_fails_the_report_whichever_process_draws_it():
    class Broken:
        def savefig(self, *a, **kw):
            raise ValueError("a broken figure")

    rep = Report("t")
    rep.figure(_fig(0), "fine")
    rep.figure(Broken(), "broken")      # drawn by this process or by the child
    with pytest.raises(ValueError, match="a broken figure"):
        rep.render()
