"""The α grid's memo (twin/alpha_grid_memo.py): a stored grid is the computed one to the last bit, its
key follows the bench and the code but not the procedure nor the CCD's sensor, and a damaged file is
computed again."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

import benchtwin.twin.alpha_grid_memo as M
import benchtwin.twin.simulate as S
from tests.support.scenarios import small_scenario

PATH = {"bearings.type": "path", "procedure.polygon_shifts": ["0 deg"], "procedure.directions": ["forward"]}


def _never():
    pytest.fail("the grid was computed although the memo holds it")


def test_a_stored_grid_reads_back_bit_for_bit(tmp_path, monkeypatch):
    monkeypatch.setenv(M.ENV, str(tmp_path / "memo"))
    sc = small_scenario(**PATH)
    bench, _, _ = S.sim_build(sc, "analytic", camera=False)
    computed = S._alpha_grid(sc, copy.deepcopy(bench))
    assert M.memoised(sc, lambda: computed) is computed              # a miss: computed, and stored
    (stored,) = (tmp_path / "memo").glob("*.json")          # beside its lock file
    assert stored.name == f"{M.grid_key(sc)}.json"
    got = M.memoised(sc, _never)                                       # a hit: read back
    assert got.keys() == computed.keys()
    for k, v in computed.items():
        a, b = np.asarray(v, dtype=float), np.asarray(got[k], dtype=float)
        # the dataset writes repr(float(v)) (analysis/dataset.py): equal bits are equal bytes
        assert a.tobytes() == b.tobytes(), k
    # the same bench under another procedure reads the same grid
    other = small_scenario(**{**PATH, "procedure.radial_positions": 12, "procedure.polygon_reps": 2})
    assert M.grid_key(other) == M.grid_key(sc) and M.memoised(other, _never) == got


def test_the_key_follows_the_bench_the_seed_and_the_code(monkeypatch):
    sc = small_scenario(**PATH)
    k = M.grid_key(sc)
    assert M.grid_key(small_scenario(**PATH, **{"bench.L1": "5 mm"})) != k
    assert M.grid_key(small_scenario(**PATH, **{"scenario.seed": 3})) != k
    assert M.grid_key(small_scenario(**{**PATH, "bearings.type": "ball"})) != k
    assert M.grid_key(small_scenario(**{**PATH, "errors.eccentricity": "2 um"})) != k
    assert M.grid_key(small_scenario(**PATH, **{"instruments.encoder.interpolation_error": "0.2 arcsec"})) != k
    assert M.grid_key(small_scenario(**PATH, **{"bench.ccd_position": "90 deg"})) != k
    monkeypatch.setattr(M, "_code_digest", lambda: "another version of the twin")
    assert M.grid_key(sc) != k


def test_the_ccd_sensor_is_not_in_the_key_and_not_in_the_grid(monkeypatch):
    """``[instruments.ccd]`` (M.NOT_READ) leaves the key: the grid of a bench whose camera differs in
    every sensor value is computed here (no memo) and is the same bits as the grid of the bench."""
    monkeypatch.delenv(M.ENV, raising=False)
    sc = small_scenario(**PATH)
    other = small_scenario(**PATH, **{"instruments.ccd.width": "128 px", "instruments.ccd.height": "96 px",
                                      "instruments.ccd.pixel_pitch": "0.6 um/px", "instruments.ccd.read_noise": "30 e-",
                                      "instruments.ccd.defocus": "3 um", "instruments.ccd.dust_count": 0})
    assert other["instruments"]["ccd"] != sc["instruments"]["ccd"]
    assert M.grid_key(other) == M.grid_key(sc)
    grids = []
    for s in (sc, other):
        bench, _, _ = S.sim_build(s, "analytic", camera=True)
        grids.append(S._alpha_grid(s, copy.deepcopy(bench)))
    assert grids[0].keys() == grids[1].keys()
    for k in grids[0]:
        assert np.asarray(grids[0][k], dtype=float).tobytes() == np.asarray(grids[1][k], dtype=float).tobytes(), k


def test_no_variable_no_memo_and_a_damaged_file_is_computed_again(tmp_path, monkeypatch):
    sc = small_scenario(**PATH)
    grid = {"theta_deg": [0.0, 0.1], "alpha_arcsec": [1.5, -2.25]}
    monkeypatch.delenv(M.ENV, raising=False)
    calls = []
    assert M.memoised(sc, lambda: calls.append(1) or grid) == grid and calls == [1]
    monkeypatch.setenv(M.ENV, str(tmp_path))
    path = tmp_path / f"{M.grid_key(sc)}.json"
    for bad in ('{"theta_deg": [0.0, 0.1], "alpha_arc', '{"theta_deg": [0.0], "alpha_arcsec": [1.0, 2.0]}', "[]"):
        path.write_text(bad)
        assert M.memoised(sc, lambda: calls.append(1) or grid) == grid
        assert json.loads(path.read_text()) == grid                     # replaced by the whole grid
    assert len(calls) == 4
