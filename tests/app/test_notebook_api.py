"""The notebook API (issue 34 item 5): simulate(scenario) and analyze(dataset) in memory, the typed
Results (a read-only mapping of results.json's keys, typed properties, curves as arrays and
DataFrames), the public figure functions. In memory nothing is written; with an output folder the
files are those of the dict the Results wraps."""

from __future__ import annotations

import json
import os
import pickle
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pytest

import benchtwin
from benchtwin.analysis.dataset import Dataset

SMALL = {"procedure.radial_reps": 2, "procedure.radial_positions": 24, "procedure.ccd_step": "15 deg",
         "bench.polygon_faces": 8, "instruments.ccd.width": "1024 px", "instruments.ccd.height": "768 px"}
#: the shortest procedure that still makes a dataset (as tests/app/test_calibrate_twin.py's)
TRUTH_ONLY = {"procedure.radial_positions": 12, "procedure.radial_reps": 1, "procedure.ccd_step": "180 deg",
              "procedure.polygon_shifts": ["0 deg"], "procedure.directions": ["forward"], "procedure.polygon_reps": 1}


def _tree(d: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(d)): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(d.rglob("*"))}


@pytest.fixture(scope="module")
def sim():
    ds = benchtwin.simulate(benchtwin.load_scenario(None).with_overrides(SMALL), progress=False, backend="analytic")
    yield ds
    ds.cleanup()


@pytest.fixture(scope="module")
def in_memory(sim):
    before = _tree(sim.path.parent)
    r = benchtwin.analyze(sim, progress=False)
    return r, before


def test_simulate_without_a_folder_gives_a_temporary_dataset_the_analysis_takes(sim):
    assert isinstance(sim, Dataset) and sim.path.name == "dataset" and os.fspath(sim) == str(sim.path)
    assert sim.tables() == ["radial_motion", "ccd/index", "polygon"]
    assert sim.manifest["bench"]["polygon_faces"] == 8 and (sim.path / "truth").is_dir()
    assert "SimulatedDataset(" in repr(sim) and "temporary" in repr(sim)


def test_the_temporary_dataset_goes_when_asked_or_collected_and_stays_with_keep():
    import gc

    # three simulations of the shortest procedure of ``sim``'s bench (the same α grid, read from the run's
    # memo): what is checked is the temporary folder's life, which does not depend on the procedure (issue 35)
    sc = benchtwin.load_scenario(None).with_overrides({**SMALL, **TRUTH_ONLY})
    with benchtwin.simulate(sc, progress=False, backend="analytic") as ds:
        root = ds.path.parent
        assert root.is_dir()
    assert not root.exists()
    ds = benchtwin.simulate(sc, progress=False, backend="analytic")
    root = ds.path.parent
    del ds
    gc.collect()
    assert not root.exists()
    kept = benchtwin.simulate(sc, progress=False, backend="analytic", keep=True)
    try:
        root = kept.path.parent
        kept.cleanup()
        del kept
        gc.collect()
        assert (root / "dataset" / "manifest.json").is_file()
    finally:
        import shutil

        shutil.rmtree(root, ignore_errors=True)
    with pytest.raises(ValueError, match="out_dir"):
        benchtwin.simulate(sc, resume=True)


def test_analyze_in_memory_writes_nothing_and_returns_typed_results(in_memory, sim, tmp_path, monkeypatch):
    r, before = in_memory
    assert _tree(sim.path.parent) == before                 # not a byte added or touched beside the dataset
    assert isinstance(r, benchtwin.Results) and isinstance(r, Mapping)
    assert r["eccentricity_um"] == r.eccentricity.value and r["eccentricity_u_um"] == r.eccentricity.u
    assert r.eccentricity.unit == "µm" and r.theta0.unit == "deg"
    assert r.theta0.value == r["eccentricity_phase_deg"] and r.theta0.u == r["eccentricity_phase_u_deg"]
    assert abs(r.eccentricity.value - 7.1) < 4 * r.eccentricity.u        # the scenario's e, at its u
    assert r.residual_before["rms_arcsec"] == r["residual_before"]["rms_arcsec"]
    assert r.effect_names == [e["name"] for e in r["identified_effects"]]
    assert r.kind == "bench" and r.notes == list(r["notes"])
    with pytest.raises(TypeError):
        r["eccentricity_um"] = 0.0                       # read-only
    with pytest.raises(ValueError, match="needs an output folder"):
        benchtwin.analyze(sim, force=True, progress=False)
    assert pickle.loads(pickle.dumps(r))["eccentricity_um"] == r["eccentricity_um"]


def test_curves_as_arrays_and_dataframes(in_memory):
    r, _ = in_memory
    c = r.calibration
    df = r.to_dataframe()
    assert list(df.columns) == ["theta_deg", "error_arcsec", "u_arcsec", "U_arcsec", "k"]
    assert np.allclose(df["error_arcsec"], c.error_arcsec) and np.allclose(df["U_arcsec"], c.k * df["u_arcsec"])
    assert "comparison" in r.curves() and "ccd" in r.curves()
    cmp = r.curve("comparison")
    assert np.allclose(cmp["residual_arcsec"], cmp["measured_arcsec"] - cmp["model_arcsec"])
    rm = r.to_dataframe("radial_motion")
    assert len(rm) == len(r["radial_motion"]["theta_deg"]) and "dY_um" in rm
    with pytest.raises(KeyError, match="expected one of calibration"):
        r.curve("nope")
    with pytest.raises(KeyError, match="no comparison_after curve"):
        r.curve("comparison_after")                       # no effect identified on this bench


def test_with_an_output_folder_the_file_is_the_results_object_and_callers_keep_their_dict_access(sim, in_memory,
                                                                                              tmp_path):
    r, _ = in_memory
    res = benchtwin.analyze(sim, tmp_path / "out", progress=False)
    assert set(res) == {"results", "paths"} and isinstance(res["results"], benchtwin.Results)
    text = Path(res["paths"]["results"]).read_text(encoding="utf-8")
    assert json.dumps(res["results"].to_json(), indent=1, sort_keys=True) + "\n" == text
    back = benchtwin.Results.read(res["paths"]["results"])
    assert back.to_json() == json.loads(text) and back.eccentricity == res["results"].eccentricity
    # the in-memory analysis is the same analysis: the same numbers as the file
    mem = r.to_json()
    assert mem.keys() == json.loads(text).keys()
    assert mem["eccentricity_um"] == back["eccentricity_um"] and mem["encoder_error_arcsec"] == back["encoder_error_arcsec"]


def test_the_figures_are_public_and_return_matplotlib_figures(sim, in_memory):
    from matplotlib.figure import Figure

    r, _ = in_memory
    figs = [benchtwin.figure_error_curve(r), benchtwin.figure_residual(r),
            benchtwin.figure_radial_motion_polar(sim), benchtwin.figure_ccd_frame(sim, 3, r),
            benchtwin.figure_ccd_frame(sim.path)]
    for f in figs:
        assert isinstance(f, Figure) and f.axes
    assert "± U" in " ".join(t.get_text() for t in figs[0].axes[0].get_legend().get_texts())
    assert len(figs[2].axes) == 3 * 3                    # top, bottom, disk × total / synchronous / asynchronous
    with pytest.raises(ValueError, match="frame 99"):
        benchtwin.figure_ccd_frame(sim, 99)
    assert isinstance(benchtwin.figure_radial_motion_polar(sim, axis="x"), Figure)   # jia2019 has X probes
    with pytest.raises(ValueError, match="axis 'z'"):
        benchtwin.figure_radial_motion_polar(sim, axis="z")
    with pytest.raises(ValueError, match="no encoder error curve"):
        benchtwin.figure_error_curve({"format": "bench-results"})
