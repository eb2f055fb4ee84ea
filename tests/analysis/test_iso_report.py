"""The report's ISO 230-7 section: the values table, polar plots, and the spectrum of a continuous
rotation with the bearing's kinematic orders when the dataset has such a table."""

from __future__ import annotations

import matplotlib
import numpy as np

from benchtwin.analysis.iso230_7 import radial_error_motion
from benchtwin.analysis.report.figures_iso import add_iso230_7_section
from benchtwin.analysis.report.html import Report

matplotlib.use("Agg")


class FakeDataset:
    def __init__(self, tables, bench):
        self.tables, self.bench = tables, bench

    def has(self, name):
        return name in self.tables

    def table(self, name):
        return self.tables[name]


def _iso():
    th = np.arange(0.0, 360.0, 10.0)
    rep = np.repeat([0, 1], th.size)
    t = np.tile(th, 2)
    top = 0.2 * np.cos(np.deg2rad(3 * t)) + 0.01 * rep
    return radial_error_motion(rep, t, {"probe_top_um": top, "probe_bottom_um": 0.5 * top}, 10.0, 100.0)


def test_section_without_and_with_a_continuous_rotation():
    rep = Report("t")
    add_iso230_7_section(rep, _iso(), FakeDataset({}, {"L1_mm": 10.0, "L2_mm": 100.0}))
    html = rep.render()
    assert "Radial error motion values (ISO 230-7:2015)" in html and html.count("<img") == 1
    assert "Spectrum of the continuous rotation" not in html

    th = np.arange(0, 20 * 360, 3.0)
    d = 0.1 * np.sin(np.deg2rad(th * 4.6)) + 0.05 * np.sin(np.deg2rad(th * 0.41))
    ds = FakeDataset({"continuous_rotation": {"theta_deg": th, "probe_top_um": d, "probe_bottom_um": d}},
                     {"L1_mm": 10.0, "L2_mm": 100.0, "bearing_kinematic_orders": {"cage": 0.41, "ball pass outer": 4.6}})
    rep2 = Report("t")
    add_iso230_7_section(rep2, _iso(), ds)
    html2 = rep2.render()
    assert "Spectrum of the continuous rotation" in html2 and html2.count("<img") == 2
