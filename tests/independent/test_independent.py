"""The loop on datasets from the independent generator (issue 16 item 1; tests/independent/generator.py).

The generator shares no code with twin/ or analysis/; each case lists its correct verdicts. The
default suite runs a few cases on one seed (``FAST``: a Y-probe null, the SelfA-like 12-head bench,
the autocollimator non-linearity, whose corrected curve is checked against the true α); every case
on two seeds runs behind ``@pytest.mark.slow``. ``benchmarks/independent_suite.py`` prints the table.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchtwin.analysis.pipeline import analyze
from tests.independent.generator import (ARCSEC_RAD, CASES, FAST, Physics, corrected_check, encoder_error_arcsec,
                                         head_error_rad, true_angle_rad, verdict_of, write_case)


def _run(name: str, seed: int, tmp_path):
    ds, truth = write_case(CASES[name], tmp_path, seed)
    assert not (ds / "truth").exists()  # the truth is beside the dataset, never in it
    res = analyze(ds, tmp_path / "out", progress=False, close_loop=True)["results"]
    json.loads((tmp_path / "out" / "results.json").read_text())  # written and valid JSON
    return res, truth


def _check(name: str, seed: int, tmp_path) -> None:
    case = CASES[name]
    res, truth = _run(name, seed, tmp_path)
    v = verdict_of(res)
    assert case.correct(v), f"{name} seed {seed}: verdict {v} (correct: {case.why})"
    if case.corrected:
        c = corrected_check(res, truth)
        assert c is not None and c["ok"], c
        assert c["applied"], "a reference-chain effect was identified but no correction applied"
        assert c["rms_arcsec"] < c["raw_rms_arcsec"], c


def test_geometry_closed_forms():
    """The exact head geometry against the textbook closed forms it should reduce to."""
    phi = np.radians(np.arange(0.0, 360.0, 7.5))
    a = head_error_rad(Physics(), phi, 0.0) / ARCSEC_RAD
    e_r = 7.1 / 22000.0
    closed = np.arctan2(e_r * np.sin(phi - np.radians(192.08)), 1 - e_r * np.cos(phi - np.radians(192.08))) / ARCSEC_RAD
    assert np.max(np.abs(a - closed)) < 1e-9
    # asin((e/r)·sin(φ − θ0)) differs by O(e²/r²) only
    asin = np.arcsin(e_r * np.sin(phi - np.radians(192.08))) / ARCSEC_RAD
    assert 1e-4 < np.max(np.abs(a - asin)) < 0.05
    # the servo holds the reading: φ + a(φ) = θ
    th = np.arange(0.0, 360.0, 15.0)
    ph = true_angle_rad(Physics(), th)
    assert np.max(np.abs(ph + head_error_rad(Physics(), ph, 0.0) - np.radians(th))) < 1e-14
    # a head radius 2 % larger scales the error by 1/1.02 (to O(e/r))
    big = encoder_error_arcsec(Physics(head_radius_mm=22.44), th)
    assert np.max(np.abs(big * 1.02 - encoder_error_arcsec(Physics(), th))) < 0.03
    # heads j see what head 1 saw ψ earlier (docs/conventions.md): the division error alone
    g = Physics(graduation=((2, 1.0, 30.0),))
    d = head_error_rad(g, ph, 0.0) - head_error_rad(g, ph + math.radians(30.0), 30.0)
    d_ecc = head_error_rad(Physics(), ph, 0.0) - head_error_rad(Physics(), ph + math.radians(30.0), 30.0)
    assert np.max(np.abs(d - d_ecc)) / ARCSEC_RAD < 1e-3


@pytest.mark.parametrize("name", FAST)
def test_independent_fast(name, tmp_path):
    _check(name, 1, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("name", sorted(set(CASES) - set(FAST)) + list(FAST))
def test_independent_all(name, seed, tmp_path):
    _check(name, seed, tmp_path)
