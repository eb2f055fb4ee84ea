"""``--set KEY=VALUE`` and ``--seed N`` on simulate, run and study (issue 34 item 5): values parsed
as TOML, validated by the scenario's schema (exit 2 naming the key), and recorded where the run's
scenario is recorded (truth/scenario.json, the run marker, study.json and the study's summary), so
the run can be repeated. And the scenario's repr a notebook shows."""

from __future__ import annotations

import json
import textwrap

import numpy as np
import pytest

from benchtwin.cli import main
from benchtwin.twin.scenario import ScenarioError, load_scenario, parse_set_options

#: a small jia2019 run the analysis can still use (24 CCD frames: order 10 needs ≥ 24), as --set options
SMALL_SET = ["procedure.radial_reps=2", "procedure.radial_positions=24", 'procedure.ccd_step="15 deg"',
             "bench.polygon_faces=8", "instruments.ccd.width=1024 px", "instruments.ccd.height=768 px"]


#: what the simulate-only tests need (no analysis): a short sweep of small frames (issue 35). The frames are
#: 256×192 px, as tests/support/resume.py's small bench's, whose values outside [procedure] these share: the
#: truth's α grid memo (twin/alpha_grid_memo.py) is keyed by those values, so the run of the file as it is (the
#: scenario's own seed) reads the grid that bench's session dataset computed, instead of a grid of its own
#: (≈ 2 s of CPU; 128×96 px frames made another key). What these tests check (the overrides reach the dataset
#: and are recorded) does not depend on the frames' size.
SIM_SET = [*SMALL_SET[:2], 'procedure.ccd_step="90 deg"', "bench.polygon_faces=8", "instruments.ccd.width=256 px",
           "instruments.ccd.height=192 px"]


def _set_args(items: list[str]) -> list[str]:
    return [a for it in items for a in ("--set", it)]


def test_set_values_are_toml_and_text_that_is_not_toml_is_a_string():
    got = parse_set_options(["procedure.polygon_reps=2", "procedure.selfcal=true", 'bench.L1="5 mm"',
                             "bench.L2=120 mm", 'procedure.polygon_shifts=["0 deg", "5 deg"]',
                             "hidden.graduation_error.amplitude = 1 arcsec"])
    assert got == {"procedure.polygon_reps": 2, "procedure.selfcal": True, "bench.L1": "5 mm", "bench.L2": "120 mm",
                   "procedure.polygon_shifts": ["0 deg", "5 deg"], "hidden.graduation_error.amplitude": "1 arcsec"}
    assert isinstance(got["procedure.polygon_reps"], int)
    # two keys smuggled into one value are not TOML for one key: the text is kept, and the schema refuses it
    assert parse_set_options(["procedure.polygon_reps=2\nbench.L1 = 1"]) == {"procedure.polygon_reps": "2\nbench.L1 = 1"}
    for bad in ("bench.L1", "L1=5 mm", "=3", "bench..L1=3", "bench.L1 x=3"):
        with pytest.raises(ScenarioError, match="--set"):
            parse_set_options([bad])


def test_overrides_are_kept_with_the_scenario_and_its_repr_is_readable():
    sc = load_scenario(None)
    assert sc.overrides == {}
    r = repr(sc)
    assert r.startswith("Scenario('jia2019', seed=") and "object at 0x" not in r
    assert "L1=6.81 mm" in r and "polygon=23 faces" in r and "hidden effects=0" in r
    s2 = sc.with_overrides({"bench.L1": "5 mm"}).with_overrides({"scenario.seed": 3})
    assert s2.overrides == {"bench.L1": "5 mm", "scenario.seed": 3}
    assert s2["bench"]["L1"] == pytest.approx(5e-3) and s2.seed == 3
    assert "L1=5 mm" in repr(s2) and "overrides={bench.L1='5 mm', scenario.seed=3}" in repr(s2)


def test_simulate_set_and_seed_reach_the_dataset_and_are_recorded(tmp_path, capsys):
    out = tmp_path / "ds"
    rc = main(["simulate", "-o", str(out), "--backend", "analytic", "--json", "--seed", "5",
               *_set_args(SIM_SET)])
    res = json.loads(capsys.readouterr().out)
    assert rc == 0, res
    assert res["seed"] == 5 and res["overrides"]["scenario.seed"] == 5
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["seed"] == 5 and manifest["bench"]["polygon_faces"] == 8
    from benchtwin.analysis.dataset import open_dataset

    assert len(open_dataset(out).table("radial_motion")["rep"]) == 2 * 24
    truth = json.loads((out / "truth" / "scenario.json").read_text())
    assert truth["overrides"]["bench.polygon_faces"] == 8
    assert truth["overrides"]["instruments.ccd.width"] == "256 px"
    assert truth["overrides"]["scenario.seed"] == 5
    assert truth["path"].endswith("jia2019.toml")   # still the file's scenario, with these overrides
    # reproducible from what was recorded: the file + the overrides give the same dataset again
    again = tmp_path / "again"
    from benchtwin.twin.simulate import simulate

    simulate(load_scenario(truth["path"]).with_overrides(truth["overrides"]), again, progress=False,
             backend="analytic")
    for name in ("manifest.json", "radial_motion.csv", "polygon.csv", "ccd/index.csv"):
        assert (again / name).read_bytes() == (out / name).read_bytes(), name


def test_a_run_of_the_file_as_it_is_records_no_overrides(tmp_path):
    """Without --set the truth's scenario.json keeps the bytes it had (no "overrides" key)."""
    from benchtwin.twin.simulate import simulate

    sc = load_scenario(None)
    sc2 = sc.with_overrides(parse_set_options(SIM_SET))
    sc2.overrides = {}   # as a scenario file with these values would be
    simulate(sc2, tmp_path / "ds", progress=False, backend="analytic")
    assert "overrides" not in json.loads((tmp_path / "ds" / "truth" / "scenario.json").read_text())


@pytest.mark.parametrize("args, named", [
    (["--set", "bench.L1=5"], "bench.L1"),                  # a bare number: the schema wants a unit
    (["--set", "bench.nope=3"], "bench.nope"),
    (["--set", "procedure.polygon_reps"], "procedure.polygon_reps"),
    (["--seed", "-1"], "scenario.seed"),
    (["--seed", "3", "--set", "scenario.seed=4"], "--seed 3"),
])
def test_a_bad_override_is_exit_2_naming_it_and_nothing_is_written(tmp_path, capsys, args, named):
    for cmd in ("simulate", "run"):
        out = tmp_path / cmd
        rc = main([cmd, "-o", str(out), "--backend", "analytic", "--quiet", *args])
        err = capsys.readouterr().err
        assert rc == 2 and named in err, err
        assert not out.exists()


def test_run_records_the_overrides_in_its_marker_and_truth(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["run", "-o", str(out), "--backend", "analytic", "--quiet", "--no-close-loop", "--seed", "11",
               *_set_args(SMALL_SET)])
    assert rc == 0, capsys.readouterr().err
    marker = json.loads((out / "benchtwin-run.json").read_text())
    assert marker["seed"] == 11 and marker["overrides"]["procedure.radial_positions"] == 24
    assert json.loads((out / "truth" / "scenario.json").read_text())["overrides"] == marker["overrides"]
    assert json.loads((out / "dataset" / "manifest.json").read_text())["seed"] == 11


# ------------------------------------------------------------------------------- study

STUDY = """
[study]
name = "ov"
base = "jia2019"
seed = 7
repetitions = 2
outputs = ["angle_error_pv_arcsec", "disk_motion_x_pv_um"]
[[study.parameters]]
key = "bench.L1"
values = ["2 mm", "5 mm"]
"""


def l2_point(task: dict) -> list[dict]:
    """A stand-in point function: outputs from the point's scenario (L2 in mm) and its rep seeds."""
    L2_mm = task["scenario"]["bench"]["L2"] * 1e3
    return [{"angle_error_pv_arcsec": L2_mm + 1e-6 * (seed % 1000), "disk_motion_x_pv_um": float(seed % 1000)}
            for seed in task["rep_seeds"]]


def test_study_set_joins_the_fixed_keys_and_seed_replaces_the_studys(tmp_path):
    import pyarrow.csv as pacsv

    from benchtwin.app.study import rep_seed, run_study

    p = tmp_path / "s.toml"
    p.write_text(textwrap.dedent(STUDY), encoding="utf-8")
    res = run_study(p, tmp_path / "out", workers=0, progress=False, point_fn=l2_point,
                    overrides={"bench.L2": "150 mm", "scenario.seed": 9})
    assert res["overrides"] == {"bench.L2": "150 mm", "scenario.seed": 9}
    assert json.loads((tmp_path / "out" / "study.json").read_text())["overrides"] == res["overrides"]
    t = pacsv.read_csv(tmp_path / "out" / "table.csv").to_pydict()
    assert np.allclose(t["angle_error_pv_arcsec"], 150.0, atol=1e-2)          # L2 = 150 mm at every point
    assert sorted(set(t["rep_seed"])) == sorted(rep_seed(9, k) for k in range(2))
    summary = (tmp_path / "out" / "summary.md").read_text()
    assert "bench.L2 = 150 mm" in summary and "seed 9" in summary


@pytest.mark.parametrize("opt, named", [("bench.L1=3 mm", "a study parameter varies"),
                                        ("bench.nope=3", "unknown scenario key"),
                                        ("bench.L2=1 mm", "bench.L1")])   # L1 ≥ L2: no valid point
def test_study_refuses_a_bad_set_before_any_output(tmp_path, capsys, opt, named):
    p = tmp_path / "s.toml"
    p.write_text(textwrap.dedent(STUDY), encoding="utf-8")
    rc = main(["study", str(p), "-o", str(tmp_path / "out"), "--quiet", "--set", opt])
    err = capsys.readouterr().err
    assert rc == 2 and named in err, err
    assert not (tmp_path / "out").exists()
