"""The report reads as a metrologist expects (issue 34, "report polish"): the GUM table shows ν = ∞
for a type B input and – for the combined row's sensitivity, never "None"; a u that is zero to the
arithmetic's precision is 0, not 1.651e-15; "(standard uncertainty)" is said once where the values
start, not after every value."""

from __future__ import annotations

import json
import re

from benchtwin.analysis.report.bench_report import _budget_rows
from benchtwin.analysis.report.html import U_CONVENTION, value_with_u


def test_value_with_u_states_k_only_when_expanded():
    assert value_with_u(7.1234, 0.0512, "µm") == "7.123 ± 0.051 µm"
    assert value_with_u(7.1234, 0.0512, "µm", k=2) == "7.123 ± 0.051 µm (k = 2)"


def test_budget_rows_show_infinity_dash_and_zero():
    budget = [
        {"name": "traceability", "u": 0.005, "sensitivity": 1.0, "contribution": 0.005, "dof": None},
        {"name": "setup calculation", "u": 1.651e-15, "sensitivity": 1.0, "contribution": 1.651e-15, "dof": 50.0},
        {"name": "combined standard uncertainty", "u": 0.2394, "sensitivity": None, "contribution": 0.2394,
         "dof": 250.9},
    ]
    rows = _budget_rows(budget)
    assert rows[0] == ["traceability", 0.005, 1.0, 0.005, "∞"]
    assert rows[1] == ["setup calculation", 0, 1.0, 0, 50.0]
    assert rows[2] == ["combined standard uncertainty", 0.2394, "–", 0.2394, 250.9]
    # a small but real u stays what it is
    assert _budget_rows([{"name": "x", "u": 1e-4, "sensitivity": 1.0, "contribution": 1e-4, "dof": 9.0},
                         budget[2]])[0][1] == 1e-4


def test_the_analysed_runs_report_says_it_once(hsieh_results):
    html = (hsieh_results.parent / "report.html").read_text(encoding="utf-8")
    text = re.sub(r"<[^>]+>", " ", html)
    assert text.count("(standard uncertainty)") <= 1
    assert text.count(U_CONVENTION) == 1
    # the budget's table alone, cut at its end before the tags go (a window of the text spilled into
    # the loop's section, whose p-values are rightly written as 4.4e-18)
    budget = html[html.index("Uncertainty budget"):]
    budget = re.sub(r"<[^>]+>", " ", budget[:budget.index("</table>")])
    assert not re.search(r"\bNone\b", budget)
    assert not re.search(r"\de-1\d\b", budget)


def test_the_face_panel_says_why_it_is_empty_with_one_start_face():
    import numpy as np

    from benchtwin.analysis.report.figures_loop import plot_signature
    from benchtwin.analysis.tracing import trace
    from tests.synthetic.evidence import make_evidence

    def face_panel(start_faces):
        ev, _ = make_evidence(np.random.default_rng(41), start_faces=start_faces,
                              inject={"graduation_error": {2: (0.4, 0.3)}})
        fig = plot_signature(ev, trace(ev))
        return fig.axes[2]

    one = face_panel([1])
    assert not one.lines and not one.collections and "one start face" in one.texts[0].get_text()
    several = face_panel(range(1, 24, 3))
    assert several.lines and not several.texts   # the errorbar of each face's mean


def test_the_polar_rings_labels_are_drawn_over_the_traces_on_a_white_ground():
    import numpy as np
    from matplotlib.figure import Figure

    from benchtwin.analysis.report.figures_iso import _PanelStyle, _polar_panel

    ax = Figure().subplots()
    t = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    _polar_panel(ax, t, np.array([0.3 * np.sin(7 * t)]), 1.0, 0.3, _PanelStyle("total", "0.4", 1.0), "x")
    rings = [txt for txt in ax.texts if txt.get_text() in ("-0.30", "+0.00", "+0.30")]
    assert len(rings) == 3
    top_line = max(line.get_zorder() for line in ax.lines)
    for txt in rings:
        assert txt.get_zorder() > top_line and txt.get_bbox_patch() is not None


def test_the_selfcal_figure_says_which_harmonics_its_curve_leaves_out(hsieh_results):
    """Principle 5: the self-calibration curve holds the harmonics no head set sees (and the Nyquist
    term) at 0; the report's caption names them, and says the curve's u does not include them."""
    import html as _html

    from benchtwin.analysis.report.bench_report import _blind_caption

    res = json.loads(hsieh_results.read_text(encoding="utf-8"))
    blind = res["selfcal_error_arcsec"]["unobservable_harmonics"]
    assert blind, "the reduced hsieh2022 run's 12 heads leave some harmonics unseen"
    caption = _blind_caption(res["selfcal_error_arcsec"])
    assert f"k = {blind[0]}" in caption and "u does not include them" in caption
    page = _html.unescape((hsieh_results.parent / "report.html").read_text(encoding="utf-8"))
    assert caption in page
    assert _blind_caption({"unobservable_harmonics": []}) == "" and _blind_caption(None) == ""
