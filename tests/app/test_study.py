"""Design-study runner: sampling with units and seeds, validation errors, the on-disk cache (re-run
recomputes nothing; an interrupted study finishes only its missing points), the Dask cluster giving
the same table as the local pool, the tidy CSV/Parquet round trip, and one small run of the real
physics point function against closed-form expectations.

Runner tests use a cheap stand-in point function (tests/support/study.py: module-level, so worker
processes import it by reference) that counts its calls by writing one file per call.
"""

from __future__ import annotations

import functools
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from benchtwin.app.study import execution as st
from benchtwin.app.study import StudyError, expand_points, load_study, run_study
from benchtwin.units import ARCSEC
from tests.support.study import BASIC, counting_point
from tests.support.study import write_study as _write

# xdist: one at a time on one worker (process pools, a dask cluster, kills waited for on deadlines; tests/conftest.py)
pytestmark = pytest.mark.xdist_group("serial")

HERE = Path(__file__).resolve().parent


@pytest.fixture
def fixed_code_version(monkeypatch):
    """Cache tests must not depend on other work editing twin/ or analysis/ meanwhile."""
    monkeypatch.setattr(st, "code_version", lambda: "test-fixed")


# ----------------------------------------------------------------------------- stand-ins


def _calls(d: Path) -> int:
    return len(list(d.iterdir()))


# ------------------------------------------------------------------------------ sampling


def test_grid_with_units_and_int_grid(tmp_path):
    p = _write(tmp_path, """
        [study]
        name = "g"
        base = "jia2019"
        outputs = ["angle_error_pv_arcsec"]
        [[study.parameters]]
        key = "bench.L1"
        low = "2 mm"
        high = "3000 um"
        n = 3
        [[study.parameters]]
        key = "bench.polygon_faces"
        low = 12
        high = 24
        n = 3
        [[study.parameters]]
        key = "bearings.radial_stiffness"
        values = ["100 N/um", "2e8 N/m"]
    """)
    study = load_study(p)
    pts = expand_points(study)
    assert len(pts) == 3 * 3 * 2
    L1 = sorted({pt.values["bench.L1"] for pt in pts})
    assert np.allclose(L1, [2.0, 2.5, 3.0])  # shown in the unit of `low` (mm)
    assert sorted({pt.values["bench.polygon_faces"] for pt in pts}) == [12, 18, 24]
    assert sorted({pt.values["bearings.radial_stiffness"] for pt in pts}) == [100.0, 200.0]  # N/um
    sc = next(pt.scenario for pt in pts if pt.values["bench.L1"] == 2.5)
    assert sc["bench"]["L1"] == pytest.approx(2.5e-3)
    assert all(pt.scenario.seed == 0 for pt in pts)  # study seed default 0 -> scenario.seed
    assert [q.column for q in study.parameters] == ["bench.L1_mm", "bench.polygon_faces",
                                                    "bearings.radial_stiffness_N_per_um"]


@pytest.mark.parametrize("sampling", ["random", "lhs"])
def test_random_and_lhs_sampling_are_seeded_and_in_range(tmp_path, sampling):
    body = f"""
        [study]
        name = "r"
        base = "jia2019"
        seed = {{seed}}
        outputs = ["angle_error_pv_arcsec"]
        [[study.parameters]]
        key = "bench.L1"
        low = "2 mm"
        high = "30 mm"
        n = 20
        sampling = "{sampling}"
        [[study.parameters]]
        key = "errors.eccentricity"
        low = "0 um"
        high = "10 um"
        n = 20
        sampling = "{sampling}"
    """
    a = expand_points(load_study(_write(tmp_path, body.format(seed=1), "a.toml")))
    b = expand_points(load_study(_write(tmp_path, body.format(seed=1), "b.toml")))
    c = expand_points(load_study(_write(tmp_path, body.format(seed=2), "c.toml")))
    va = np.array([[pt.values["bench.L1"], pt.values["errors.eccentricity"]] for pt in a])
    vb = np.array([[pt.values["bench.L1"], pt.values["errors.eccentricity"]] for pt in b])
    vc = np.array([[pt.values["bench.L1"], pt.values["errors.eccentricity"]] for pt in c])
    assert va.shape == (20, 2)
    assert np.array_equal(va, vb) and not np.array_equal(va, vc)
    assert (va[:, 0] >= 2).all() and (va[:, 0] <= 30).all() and (va[:, 1] >= 0).all() and (va[:, 1] <= 10).all()
    assert a[3].scenario["bench"]["L1"] == pytest.approx(va[3, 0] * 1e-3)
    if sampling == "lhs":  # Latin hypercube: one sample in each of the n strata of every dimension
        for j, (lo, hi) in enumerate([(2, 30), (0, 10)]):
            strata = np.floor((va[:, j] - lo) / (hi - lo) * 20).astype(int)
            assert sorted(strata) == list(range(20))


def test_affine_set_and_labelled_tables(tmp_path):
    p = _write(tmp_path, """
        [study]
        name = "t"
        base = "jia2019"
        outputs = ["angle_error_pv_arcsec"]
        [[study.parameters]]
        name = "disk_to_bearing"
        values = ["2 mm", "20 mm"]
        set = { "bench.bearing_top_z" = { scale = -1 }, "bench.bearing_bottom_z" = { scale = -1, offset = "-88 mm" } }
        [[study.parameters]]
        name = "grade"
        labels = ["base", "better"]
        [[study.parameters.values]]
        [[study.parameters.values]]
        "bearings.grade" = "P2"
    """)
    pts = expand_points(load_study(p))
    assert len(pts) == 4
    pt = next(q for q in pts if q.values == {"disk_to_bearing": 20.0, "grade": "better"})
    assert pt.scenario["bench"]["bearing_top_z"] == pytest.approx(-0.020)
    assert pt.scenario["bench"]["bearing_bottom_z"] == pytest.approx(-0.108)
    assert pt.scenario["bearings"]["grade"] == "P2"
    base = next(q for q in pts if q.values == {"disk_to_bearing": 2.0, "grade": "base"})
    assert base.scenario["bearings"]["grade"] == "P4"


def test_shipped_studies_validate():
    studies = Path(__file__).resolve().parents[2] / "scenarios" / "studies"
    study = load_study(studies / "bearing_distance.toml")
    pts = expand_points(study)
    assert study.run_fidelity == "physics"
    assert len(pts) == len(study.parameters[0].levels) * 2
    assert all(pt.scenario["errors"]["eccentricity"] == 0 for pt in pts)
    at12 = next(pt for pt in pts if pt.values == {"disk_to_bearing": 12.0, "bearing_grade": "P4"})
    base = study.base.to_dict()["bench"]  # d = 12 mm is jia2019.toml's layout exactly
    for k in ("bearing_top_z", "bearing_bottom_z", "polygon_z", "L1", "L2"):
        assert at12.scenario["bench"][k] == pytest.approx(base[k], abs=1e-12)
    hm = load_study(studies / "heads_mounting.toml")
    assert len(expand_points(hm)) == 16 * 2 and hm.run_fidelity == "physics"
    cf = load_study(studies / "ccd_frames.toml")  # the shipped full-fidelity example
    assert (len(expand_points(cf)), cf.run_fidelity, cf.close_loop, cf.order) == (3, "full", False, 5)


# ---------------------------------------------------------------------------- validation


@pytest.mark.parametrize("patch, expect", [
    (("seed = 7", "seed = 7\nreps = 3"), "unknown key study.reps"),
    (('values = ["2 mm", "5 mm", "10 mm", "20 mm"]', 'values = ["2 mm", "5 deg"]'),
     "study.parameters[0].values[1] (bench.L1): '5 deg' is a angle"),
    (('values = ["2 mm", "5 mm", "10 mm", "20 mm"]', 'values = ["2 mm", "5"]'),
     "study.parameters[0].values[1] (bench.L1)"),
    (('key = "bench.L1"', 'key = "bench.L11"'), "study.parameters[0].key: unknown scenario key 'bench.L11'"),
    (('"disk_motion_x_pv_um"]', '"disk_motion_z_pv_um"]'), "unknown output 'disk_motion_z_pv_um'"),
    (('below = "1.2 arcsec"', 'below = "1.2 um"'), "study.target.below"),
    (('output = "angle_error_pv_arcsec"', 'output = "angle_error_rms_arcsec"'), "study.target.output"),
    (('"20 mm"]', '"200 mm"]'), "point 3 (bench.L1 = '200 mm') does not give a valid scenario: bench.L1"),
    (('base = "jia2019"', 'base = "nope.toml"'), "study.base: 'nope.toml' is neither"),
    (("repetitions = 2", "repetitions = 0"), "study.repetitions"),
    (("repetitions = 2", 'repetitions = 2\nfidelity = "physics"\n'
      'outputs = ["results.error_model.residual_pv_arcsec"]'), None),  # duplicate key: TOML error
])
def test_validation_errors_name_file_and_key(tmp_path, patch, expect):
    body = BASIC.replace(*patch)
    assert body != BASIC
    p = _write(tmp_path, body)
    with pytest.raises(StudyError) as ei:
        expand_points(load_study(p))
    msg = str(ei.value)
    assert msg.startswith(str(p))
    if expect:
        assert expect in msg


def test_physics_fidelity_refuses_pipeline_outputs(tmp_path):
    p = _write(tmp_path, BASIC.replace('seed = 7', 'seed = 7\nfidelity = "physics"').replace(
        '"disk_motion_x_pv_um"]', '"results.error_model.residual_pv_arcsec"]'))
    with pytest.raises(StudyError, match="needs fidelity 'full'"):
        load_study(p)


def test_fidelity_is_chosen_per_output(tmp_path):
    """The cheapest fidelity per output: physics outputs never start a simulation; named full outputs
    and results.<path> keys run simulate → analyze; only outputs that need it run the close loop."""
    from benchtwin.app.study import points as sp

    assert sp.output_fidelity("angle_error_pv_arcsec") == "physics"
    assert sp.output_fidelity("measured_angle_error_pv_arcsec") == "full"
    assert sp.output_fidelity("results.residual_before.pv_ratio") == "full"
    assert sp.output_fidelity("residual_after_rms_arcsec") == "full+close_loop"
    assert sp.output_fidelity("identified.tilt_abbe") == "full+close_loop"
    assert sp.output_fidelity("results.close_loop.status") == "full+close_loop"
    with pytest.raises(KeyError):
        sp.output_fidelity("identified.no_such_effect")
    assert load_study(_write(tmp_path, BASIC)).run_fidelity == "physics"
    full = load_study(_write(tmp_path, BASIC.replace('"disk_motion_x_pv_um"]', '"measured_angle_error_pv_arcsec"]')))
    assert (full.run_fidelity, full.close_loop) == ("full", False)
    assert full.output_fidelity() == {"angle_error_pv_arcsec": "physics (rep-seed realisation of the full run)",
                                      "measured_angle_error_pv_arcsec": "full"}
    cl = load_study(_write(tmp_path, BASIC.replace('"disk_motion_x_pv_um"]', '"identified.tilt_abbe"]')))
    assert (cl.run_fidelity, cl.close_loop) == ("full", True)
    with pytest.raises(StudyError, match="unknown output 'identified.nope'.*tilt_abbe"):
        load_study(_write(tmp_path, BASIC.replace('"disk_motion_x_pv_um"]', '"identified.nope"]')))
    with pytest.raises(StudyError, match="study.order: the analysis' Fourier order applies to full"):
        load_study(_write(tmp_path, BASIC.replace("seed = 7", "seed = 7\norder = 4")))
    with pytest.raises(StudyError, match="study.order: expected an integer"):
        load_study(_write(tmp_path, BASIC.replace("seed = 7", "seed = 7\norder = 0")))


# A full-fidelity study small enough for the default suite: 8 polygon faces, 36 × 2 radial stops,
# 12 CCD frames of 512 × 384 px, analysis order 3 (one point-run ≈ 15–30 s, most of it the
# simulation's 0.1°-grid truth and the report's figures).
TINY_FULL = """
[study]
name = "tiny_full"
base = "jia2019"
seed = 3
repetitions = 1
order = 3
outputs = ["measured_angle_error_pv_arcsec", "measured_angle_error_rms_arcsec", "measured_angle_error_u_arcsec",
           "predicted_angle_error_pv_arcsec", "predicted_angle_error_u_arcsec", "residual_rms_arcsec",
           "eccentricity_um", "eccentricity_u_um", "true_angle_error_pv_arcsec", "measurement_error_rms_arcsec",
           "angle_error_pv_arcsec", "results.residual_before.measured_pv_arcsec"]
[study.fixed]
"procedure.radial_positions" = 36
"procedure.radial_reps" = 2
"procedure.ccd_step" = "30 deg"
"instruments.ccd.width" = "512 px"
"instruments.ccd.height" = "384 px"
"bench.polygon_faces" = 8
# rolling-path bearings: the study's "true α" is the twin's α grid (one realisation of the motion);
# with jia2019's ball sets each polygon visit sees another ball configuration (docs/physics.md)
"bearings.type" = "path"
# the physics fidelity reads the posed disk without the encoder's graduation/interpolation error,
# which jia2019 now declares: off, so the physics and the full path read the same α
"errors.graduation_error_rms" = "0 arcsec"
"instruments.encoder.interpolation_error" = "0 arcsec"
[[study.parameters]]
key = "errors.eccentricity"
values = ["5 um"]
"""


def test_full_fidelity_simulates_and_analyses_against_the_truth(tmp_path, fixed_code_version, monkeypatch):
    """The full path end to end: the twin's dataset, the one analysis pipeline (which never sees
    truth/), and outputs checked against the twin's truth and the physics path of the same bench."""
    import pyarrow.parquet as pq

    from benchtwin.analysis import pipeline

    seen = []
    real_analyze = pipeline.analyze

    def guarded(dataset, *a, **kw):  # truth/ is moved out before the analysis runs
        seen.append(Path(dataset))
        assert not (Path(dataset) / "truth").exists()
        assert (Path(dataset).parent / "truth" / "encoder_error.csv").is_file()
        return real_analyze(dataset, *a, **kw)

    monkeypatch.setattr(pipeline, "analyze", guarded)
    p = _write(tmp_path, TINY_FULL)
    r = run_study(p, tmp_path / "out", workers=0, progress=False)
    assert len(seen) == 1 and (r["computed"], r["cached"], r["fidelity"]) == (1, 0, "full")
    row = pq.read_table(r["table_parquet"]).to_pylist()[0]
    assert row["fidelity"] == "full"
    # eccentricity from the CCD images: the scenario's 5 µm within its stated uncertainty (k = 3)
    assert row["eccentricity_um"] == pytest.approx(5.0, abs=3 * row["eccentricity_u_um"] + 0.02)
    # 12 frames (30° steps), each moved by the microscope stand's vibration (twin/vibration.py,
    # 1.21 µm per frame and axis): u(e) ≈ 1.21·√(2/12) ≈ 0.5 µm (measured 0.49)
    assert 0 < row["eccentricity_u_um"] < 1.0
    # the measured α (polygon) agrees with the twin's true α within its stated uncertainty
    assert 0 < row["measured_angle_error_u_arcsec"] < 0.5
    # ... plus what the analysis' budget does not hold: the drive servo rests where the bearing
    # friction sticks (twin/instruments/drive.py), holding a torque anywhere in ±T_s = ±1.2·0.02 N·m
    # that twists the shaft between disk and polygon by T/k_shaft (k_shaft = 5000 N·m/rad) per stop;
    # bound: a rectangular spread over the whole static band, σ ≤ T_s/(√3·k_shaft)
    sigma_twist = 1.2 * 0.02 / (math.sqrt(3.0) * 5000.0) / ARCSEC
    u = row["measured_angle_error_u_arcsec"]
    assert row["measurement_error_rms_arcsec"] < 2 * math.hypot(u, sigma_twist)
    # ≈ 2e/r: the once-per-turn eccentricity term dominates (P-V over 8 faces is a bit lower)
    two_e_over_r = 2 * 5e-6 / 22e-3 / ARCSEC
    assert 0.85 * two_e_over_r < row["true_angle_error_pv_arcsec"] < 1.1 * two_e_over_r
    assert row["measured_angle_error_pv_arcsec"] == pytest.approx(row["results.residual_before.measured_pv_arcsec"])
    assert row["measured_angle_error_pv_arcsec"] <= row["true_angle_error_pv_arcsec"] + 0.5
    # the Jia model predicts it; the residual is a small part of the error
    assert row["predicted_angle_error_pv_arcsec"] == pytest.approx(row["true_angle_error_pv_arcsec"], rel=0.05)
    assert row["residual_rms_arcsec"] < 0.1 * row["measured_angle_error_rms_arcsec"]
    assert row["predicted_angle_error_u_arcsec"] > 0
    # the physics path's exact reading of the same realisation gives the same true P-V
    assert row["angle_error_pv_arcsec"] == pytest.approx(row["true_angle_error_pv_arcsec"], abs=0.3)
    md = Path(r["summary_md"]).read_text()
    assert "[full]" in md and "full = simulate the whole dataset" in md and "Fourier order 3" in md
    # a re-run is all cache: no simulation, no analysis
    r2 = run_study(p, tmp_path / "out", workers=0, progress=False)
    assert (r2["computed"], r2["cached"], len(seen)) == (0, 1, 1)


@pytest.mark.slow
def test_full_fidelity_repetitions_and_close_loop_on_the_pool(tmp_path, fixed_code_version):
    """Realistic size (jia2019's procedure, 23 faces, 60 CCD frames, order 10): 2 points × 2 reps on
    2 workers, one task per repetition; reps are independent realisations shared across points
    (common random numbers); the close loop runs because an output needs it. Rolling-path bearings,
    as in TINY_FULL: with jia2019's ball sets the truth's α grid is one realisation of the cage
    configuration and the polygon's 23 visits of a stop are 23 others (docs/physics.md), and the grid
    differs from their mean by ~0.9″ RMS (seed 11), which is no error of the measurement."""
    import pyarrow.parquet as pq

    p = _write(tmp_path, """
        [study]
        name = "full_cl"
        base = "jia2019"
        seed = 11
        repetitions = 2
        outputs = ["measured_angle_error_pv_arcsec", "residual_rms_arcsec", "residual_after_rms_arcsec",
                   "n_identified_effects", "identified.tilt_abbe", "true_angle_error_pv_arcsec",
                   "measurement_error_rms_arcsec", "measured_angle_error_u_arcsec"]
        [study.fixed]
        "bearings.type" = "path"
        [[study.parameters]]
        key = "errors.eccentricity"
        values = ["0 um", "7.1 um"]
    """)
    r = run_study(p, tmp_path / "out", workers=2, progress=False)
    assert r["computed"] == 4 and r["output_fidelity"]["identified.tilt_abbe"] == "full+close_loop"
    t = pq.read_table(r["table_parquet"]).to_pylist()
    assert {row["fidelity"] for row in t} == {"full+close_loop"}
    # measured α against the twin's true α: the stated u plus the shaft's stick-slip twist between disk
    # and polygon, which the analysis' budget does not hold (the bound of TINY_FULL's test)
    sigma_twist = 1.2 * 0.02 / (math.sqrt(3.0) * 5000.0) / ARCSEC
    for row in t:
        assert row["measurement_error_rms_arcsec"] < 2 * math.hypot(row["measured_angle_error_u_arcsec"], sigma_twist)
        assert row["residual_after_rms_arcsec"] <= row["residual_rms_arcsec"] + 1e-9
        assert row["identified.tilt_abbe"] in (0.0, 1.0) and row["n_identified_effects"] >= 0
    by = {(row["point"], row["rep"]): row for row in t}
    assert by[(0, 0)]["measured_angle_error_pv_arcsec"] != by[(0, 1)]["measured_angle_error_pv_arcsec"]
    assert by[(0, 0)]["rep_seed"] == by[(1, 0)]["rep_seed"]
    assert by[(1, 0)]["true_angle_error_pv_arcsec"] > 100 > by[(0, 0)]["true_angle_error_pv_arcsec"]


# ------------------------------------------------------------------------- cache, resume


def test_rerun_recomputes_nothing(tmp_path, fixed_code_version, monkeypatch):
    p = _write(tmp_path, BASIC)
    calls = tmp_path / "calls"
    calls.mkdir()
    fn = functools.partial(counting_point, count_dir=str(calls))
    r1 = run_study(p, tmp_path / "out", workers=2, progress=False, point_fn=fn)
    assert (r1["computed"], r1["cached"]) == (8, 0)
    assert _calls(calls) == 4  # one task per point (both reps)
    r2 = run_study(p, tmp_path / "out", workers=2, progress=False, point_fn=fn)
    assert (r2["computed"], r2["cached"]) == (0, 8)
    assert _calls(calls) == 4
    assert (tmp_path / "out" / "table.csv").read_text() == (tmp_path / "out" / "table.csv").read_text()
    # a new point only computes that point; a changed repetition count only the new reps
    p.write_text(BASIC.replace('"20 mm"]', '"20 mm", "30 mm"]').replace("repetitions = 2", "repetitions = 3"))
    r3 = run_study(p, tmp_path / "out", workers=0, progress=False, point_fn=fn)
    assert (r3["computed"], r3["cached"]) == (15 - 8, 8)
    assert r3["target"]["groups"][0]["crossing"] == pytest.approx(11.8, abs=0.3)
    # a change of the code (version) recomputes everything
    monkeypatch.setattr(st, "code_version", lambda: "test-changed")
    r4 = run_study(p, tmp_path / "out", workers=0, progress=False, point_fn=fn)
    assert (r4["computed"], r4["cached"]) == (15, 0)


def test_interrupted_study_finishes_only_missing_points(tmp_path, fixed_code_version, kill_env):
    body = BASIC.replace('values = ["2 mm", "5 mm", "10 mm", "20 mm"]',
                         'values = ["1 mm", "2 mm", "3 mm", "4 mm", "5 mm", "6 mm", "7 mm", "8 mm"]')
    p = _write(tmp_path, body)
    out = tmp_path / "out"
    script = textwrap.dedent(f"""
        import functools, importlib, sys
        sys.path[:0] = [{str(HERE)!r}, {str(HERE.parents[1])!r}]
        # the same module name as in this process (the point function's name enters the cache key)
        counting_point = importlib.import_module({counting_point.__module__!r}).counting_point
        import benchtwin.app.study.execution as st
        st.code_version = lambda: "test-fixed"
        st.run_study({str(p)!r}, {str(out)!r}, workers=1, progress=False,
                  point_fn=functools.partial(counting_point, delay_s=0.4))
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], start_new_session=True, env=kill_env)
    try:
        deadline = time.monotonic() + 40
        while time.monotonic() < deadline:
            n = len(list((out / "cache").rglob("*.json"))) if (out / "cache").exists() else 0
            if n >= 6:  # 3 points × 2 reps
                break
            assert proc.poll() is None, "the study ended before it could be interrupted"
            time.sleep(0.05)
        else:
            pytest.fail("no progress from the study subprocess")
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    cached = len(list((out / "cache").rglob("*.json")))
    assert 6 <= cached < 16
    assert not (out / "table.csv").exists()
    calls = tmp_path / "calls"
    calls.mkdir()
    r = run_study(p, out, workers=2, progress=False, point_fn=functools.partial(counting_point, count_dir=str(calls)))
    assert r["cached"] == cached and r["computed"] == 16 - cached
    assert _calls(calls) == (16 - cached) // 2
    assert r["rows"] == 16


def test_killed_cli_study_resumes_with_only_the_missing_points(tmp_path, kill_env):
    """The real thing: ``benchtwin study`` with the physics point function on a local pool is
    killed (SIGKILL to its process group: the runner and its worker) midway; re-running the same
    command computes only the (point, repetition)s that were not cached."""
    import json

    p = _write(tmp_path, """
        [study]
        name = "killed"
        base = "jia2019"
        seed = 1
        repetitions = 2
        angles = 720
        outputs = ["angle_error_pv_arcsec", "disk_motion_x_pv_um"]
        [[study.parameters]]
        key = "bench.L1"
        low = "2 mm"
        high = "9 mm"
        n = 10
    """)
    out = tmp_path / "out"
    # the command line's own entry point (benchtwin.cli:main), with the code version pinned: other
    # work editing the sources between the two runs must not invalidate the cache under the test
    launcher = ("import sys, benchtwin.app.study.execution as st; st.code_version = lambda: 'test-fixed'; "
                "from benchtwin.cli import main; sys.exit(main(sys.argv[1:]))")

    def cli(*args: str) -> list[str]:
        return [sys.executable, "-c", launcher, "study", str(p), "-o", str(out), "--workers", "1", *args]

    proc = subprocess.Popen(cli("--quiet"), start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, env=kill_env)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            n = len(list((out / "cache").rglob("*.json"))) if (out / "cache").exists() else 0
            if n >= 4:  # 2 points × 2 reps
                break
            assert proc.poll() is None, f"the study ended before it could be killed: {proc.stderr.read()!r}"
            time.sleep(0.02)
        else:
            pytest.fail("no progress from `benchtwin study`")
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    cached = len(list((out / "cache").rglob("*.json")))
    assert 4 <= cached < 20 and cached % 2 == 0  # a point's reps are stored together
    assert not (out / "table.csv").exists()
    done = subprocess.run(cli("--json"), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    res = json.loads(done.stdout)
    assert (res["cached"], res["computed"], res["rows"]) == (cached, 20 - cached, 20)
    assert res["output_fidelity"] == {"angle_error_pv_arcsec": "physics", "disk_motion_x_pv_um": "physics"}
    assert (out / "table.csv").is_file()


# ------------------------------------------------------------------- executors and table


def test_dask_localcluster_gives_the_same_table_as_the_local_pool(tmp_path):
    import pyarrow.parquet as pq
    from distributed import LocalCluster

    p = _write(tmp_path, BASIC)
    fn = functools.partial(counting_point)
    local = run_study(p, tmp_path / "local", workers=2, progress=False, point_fn=fn)
    with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        remote = run_study(p, tmp_path / "dask", scheduler=cluster.scheduler_address, progress=False, point_fn=fn)
    assert remote["computed"] == 8 and remote["executor"].startswith("dask tcp://127.0.0.1")
    a = pq.read_table(local["table_parquet"]).drop(["elapsed_s"])
    b = pq.read_table(remote["table_parquet"]).drop(["elapsed_s"])
    assert a.equals(b)


def test_tidy_csv_parquet_round_trip_and_summary(tmp_path):
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    p = _write(tmp_path, BASIC)
    r = run_study(p, tmp_path / "out", workers=0, progress=False, point_fn=counting_point)
    t_pq = pq.read_table(r["table_parquet"])
    t_csv = pacsv.read_csv(r["table_csv"])
    assert t_pq.column_names == ["point", "rep", "rep_seed", "bench.L1_mm", "angle_error_pv_arcsec",
                                 "disk_motion_x_pv_um", "fidelity", "elapsed_s", "cache_key"]
    assert t_pq.num_rows == 8
    for name in t_pq.column_names:
        a, b = t_pq[name].to_pylist(), t_csv[name].to_pylist()
        if isinstance(a[0], float):
            assert np.allclose(a, b, rtol=0, atol=0)
        else:
            assert a == b
    meta = t_pq.schema.metadata
    assert meta[b"study"] == b"basic" and b"angle_error_pv_arcsec" in meta[b"fidelity"]
    assert t_pq["rep_seed"].to_pylist()[:2] == [st.rep_seed(7, 0), st.rep_seed(7, 1)]
    s = pq.read_table(r["summary_parquet"])
    x = np.array(t_pq["angle_error_pv_arcsec"].to_pylist()).reshape(4, 2)
    assert np.allclose(s["angle_error_pv_arcsec_mean"].to_pylist(), x.mean(axis=1))
    assert np.allclose(s["angle_error_pv_arcsec_std"].to_pylist(), x.std(axis=1, ddof=1))
    assert np.allclose(s["angle_error_pv_arcsec_u"].to_pylist(), x.std(axis=1, ddof=1) / math.sqrt(2))
    md = Path(r["summary_md"]).read_text()
    assert "bench.L1 = 2, 5, 10 mm" in md and "custom:" in md
    assert Path(r["summary_html"]).read_text().startswith("<section")
    assert all(Path(f).is_file() for f in r["figures"])
    report = Path(r["report_html"]).read_text()  # self-contained: summary + embedded figures
    assert report.startswith("<!DOCTYPE html>") and "Design study basic" in report
    assert report.count("data:image/png;base64,") == len(r["figures"]) == 2
    assert "stays below 1.2 arcsec" in report and "<table>" in report


# ---------------------------------------------------------------------- the real physics


def test_physics_point_function_on_the_real_bench(tmp_path):
    """Exact reading of the posed disk: eccentricity e gives P-V 2e/r; two opposite heads cancel it;
    without eccentricity the error is the disk's X motion over r (α ≈ −δx/r, docs/conventions.md)."""
    pytest.importorskip("benchtwin.twin.physics")
    p = _write(tmp_path, """
        [study]
        name = "phys"
        base = "jia2019"
        seed = 5
        repetitions = 1
        angles = 72
        outputs = ["angle_error_pv_arcsec", "disk_motion_x_pv_um", "disk_radial_motion_pv_um"]
        [[study.parameters]]
        name = "case"
        labels = ["ecc_only", "ecc_two_heads", "motion_only"]
        [[study.parameters.values]]
        "bearings.type" = "path"
        "bearings.waviness_top" = []
        "bearings.waviness_bottom" = []
        "bearings.async_rms" = "0 um"
        [[study.parameters.values]]
        "bearings.type" = "path"
        "bearings.waviness_top" = []
        "bearings.waviness_bottom" = []
        "bearings.async_rms" = "0 um"
        "bench.heads" = ["0 deg", "180 deg"]
        [[study.parameters.values]]
        "errors.eccentricity" = "0 um"
    """)
    r = run_study(p, tmp_path / "out", workers=0, progress=False)
    assert r["output_fidelity"] == {o: "physics" for o in r["output_fidelity"]}
    import pyarrow.parquet as pq

    t = pq.read_table(r["table_parquet"]).to_pylist()
    by = {row["case"]: row for row in t}
    e, rad = 7.1e-6, 22e-3
    motion = by["ecc_only"]["disk_motion_x_pv_um"] * 1e-6  # gravity/unbalance remain: small
    th = 2 * np.pi * np.arange(72) / 72  # Jia eq. 3 sampled at the study's 72 angles
    expected = e / rad * np.ptp(np.sin(th - np.deg2rad(192.08))) / ARCSEC
    assert by["ecc_only"]["angle_error_pv_arcsec"] == pytest.approx(expected, abs=motion / rad / ARCSEC + 0.02)
    assert by["ecc_two_heads"]["angle_error_pv_arcsec"] < 0.05 * by["ecc_only"]["angle_error_pv_arcsec"]
    m = by["motion_only"]
    assert m["angle_error_pv_arcsec"] == pytest.approx(m["disk_motion_x_pv_um"] * 1e-6 / rad / ARCSEC, rel=0.05)
    assert m["disk_radial_motion_pv_um"] >= m["disk_motion_x_pv_um"] - 1e-9
