"""benchmarks/physics_floor.py solves the twin's own poses again by the closed form (issue 17's physics
floor): its equilibria must be the twin's, or its ratio would compare different physics. Agreement
only: the speed is the benchmark's (docs/benchmarks.md), never a timed test."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from benchtwin.twin.scenario import load_scenario
from benchtwin.units import ARCSEC

ROOT = Path(__file__).resolve().parents[2]


def _floor():
    spec = importlib.util.spec_from_file_location("physics_floor", ROOT / "benchmarks" / "physics_floor.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", ["jia2019", "hsieh2022"])
def test_closed_form_equilibria_are_the_twins(name):
    f = _floor()
    sc = load_scenario(ROOT / "scenarios" / f"{name}.toml")
    bench, rec, _spent, n = f.record_twin_poses(sc, 24)
    assert n >= 24
    G, check = f.gravity_harmonics(bench)
    assert check < 1e-12
    q, its = f.closed_form(bench, rec, G)
    q_twin = np.stack([r[6] for r in rec])
    d = np.abs(q - q_twin)
    # far below the twin's numerical floors (1 nm, 0.001″): the same physics, solved twice
    assert d[:, :2].max() < 1e-12 and d[:, 2:4].max() < 1e-10
    assert d[:, 4:].max() / ARCSEC < 1e-4
    assert its >= 1
