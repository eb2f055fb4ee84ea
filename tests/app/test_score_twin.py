"""Scoring on a twin dataset of the suite (issue 19): the project's analysis against stored
expectations (so its score cannot get worse unnoticed), the naive fit visibly worse, the commands
end to end (score, suite --blind, score-suite) and benchtwin.score(fn, suite=...).

The suite itself is simulated with a stand-in for the simulation (copies of one real dataset):
what is tested there is the suite's layout, anonymisation and bookkeeping, not the physics.
"""

from __future__ import annotations

import json
import math
import shutil


import benchtwin
from benchtwin.app import suite as S
from benchtwin.app.score import canonical_results, read_truth, score_files, score_results
from benchtwin.cli import main

from .naive import naive

# The project's close-loop analysis on the suite's graduation_error dataset, seed 11, scored. Stored
# expectations with their tolerances; measured (seed 11, ball bearings without cage slip, main of
# 2026-12-05): e −0.00006 µm and θ0 −0.001° against the sweep's truth, α 0.030″, β 0.025″, coverage
# 96 % within 2u, named alone, after/floor 2.43 (path bearings before: e −0.0001 µm, θ0 +0.0007°,
# α 0.025″, β 0.010″, after/floor 0.68; docs/suite-scores.md).
# Tolerances: e 0.01 µm and θ0 0.02° (≈ the e, θ0 u of the suite's benches), α and β 0.04″ (a third of
# Hsieh's u_c ≈ 0.12″), after/floor 1.5 (the hidden suite's criterion, docs/hidden-suite.md).
# α since the drive servo holds the encoder's COUNT (twin/instruments/drive.py): at each commanded
# stop the disk rests anywhere in the held 0.39″ count, so the α measured at the commanded reading
# differs from the true continuous α by up to ±½ count (σ = res/√12 = 0.113″; measured 0.116″):
# the α tolerance is the 0.04″ combined with 1.2 × that floor. The analysis' noise floor does not
# (yet) hold that rest noise: after/floor measured 2.95 with the servo; 1.2 × that until it does.
ALPHA_FLOOR_ARCSEC = 0.39 / math.sqrt(12.0)
#
# e and θ0 are scored against the sweep's truth (score.py _sweep_truth: Jia eqs. 10-12 on the true
# d_ref of every frame), not the installed eccentricity: since the suite's benches run on ball
# bearings (issue 33), the axis's once-per-revolution motion during the sweep (0.12 µm, 0.58° here)
# is part of what every CCD sweep — and every head — sees as eccentricity (Jia sec. 4.2). Against the
# installed e the project's analysis and the naive fit both miss by that motion, which says nothing
# about either.
EXPECT = {"e_error_sweep_um": 0.01, "theta0_error_sweep_deg": 0.02,
          "alpha_rms_error_arcsec": math.hypot(0.04, 1.2 * ALPHA_FLOOR_ARCSEC),
          "beta_rms_error_arcsec": 0.04, "residual_after_over_floor": 3.5}
EXPECT_COVERAGE_2U = 0.85


def test_project_analysis_score_does_not_get_worse(grad_dataset, grad_results):
    s = score_files(grad_results, grad_dataset)
    for k, tol in EXPECT.items():
        assert s[k] is not None and abs(s[k]) <= tol, (k, s[k], tol)
    assert s["coverage_2u"] >= EXPECT_COVERAGE_2U
    assert s["named"] == "alone" and s["spurious"] == [] and s["identification_correct"] is True
    assert abs(_z_sweep(s, "e")) < 3 and abs(_z_sweep(s, "theta0")) < 3


def _z_sweep(s, q):
    """z of e (q = "e") or θ0 against the sweep's truth, with the u the results stated."""
    unit = "um" if q == "e" else "deg"
    u = s[f"{q}_error_{unit}"] / s[f"{q}_z"]
    return s[f"{q}_error_sweep_{unit}"] / u


def test_naive_fit_scores_visibly_worse(grad_dataset, grad_results):
    own = score_files(grad_results, grad_dataset)
    nv = score_results(canonical_results(naive(str(grad_dataset))), read_truth(grad_dataset / "truth", grad_dataset))
    assert abs(nv["e_error_sweep_um"]) > 10 * abs(own["e_error_sweep_um"]) and abs(nv["e_error_sweep_um"]) > 0.02
    assert abs(nv["theta0_error_sweep_deg"]) > 10 * abs(own["theta0_error_sweep_deg"])
    assert nv["alpha_rms_error_arcsec"] > 10 * own["alpha_rms_error_arcsec"]


def test_a_wrong_result_cannot_pass(grad_dataset, grad_results):
    """The project's own results, each criterion spoiled in turn: the score notices every one."""
    raw = json.loads(grad_results.read_text())
    truth = read_truth(grad_dataset / "truth", grad_dataset)
    good = score_results(canonical_results(raw), truth)
    bad = json.loads(json.dumps(raw))
    bad["eccentricity_um"] += 0.1
    bad["eccentricity_phase_deg"] += 1.0
    bad["encoder_error_arcsec"]["value"][3] += 0.5
    bad["polygon_pitch_deviation_arcsec"][0] += 0.5
    bad["polygon_pitch_deviation_arcsec"][1] -= 0.5
    bad["identified_effects"] = [{"name": "ac_scale"}]
    s = score_results(canonical_results(bad), truth)
    assert abs(s["e_error_sweep_um"]) > 0.09 and abs(_z_sweep(s, "e")) > 5
    assert abs(s["theta0_error_sweep_deg"]) > 0.9
    # +0.5″ at one stop: well above the good result's count-quantisation floor
    assert s["alpha_rms_error_arcsec"] > good["alpha_rms_error_arcsec"] + 0.02
    assert good["alpha_rms_error_arcsec"] < EXPECT["alpha_rms_error_arcsec"]
    assert s["beta_rms_error_arcsec"] > 0.14 > good["beta_rms_error_arcsec"]
    assert s["coverage_1u"] < good["coverage_1u"]
    assert s["named"] == "not named" and s["spurious"] == ["ac_scale"] and s["identification_correct"] is False


def test_cli_score_json(grad_dataset, grad_results, capsys):
    assert main(["score", str(grad_results), str(grad_dataset), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for k in ("e_error_um", "theta0_error_deg", "beta_rms_error_arcsec", "alpha_rms_error_arcsec", "coverage_1u",
              "coverage_2u", "named", "spurious"):
        assert k in out, k
    assert main(["score", str(grad_dataset / "nope.json"), str(grad_dataset)]) == 2
    assert "nope.json" in capsys.readouterr().err


def _fake_simulate(src):
    def fake(args):
        e, seed, out = args
        shutil.copytree(src, out)
        exp = e.expected()
        if exp is not None:
            (S.Path(out) / "truth" / "expected.json").write_text(json.dumps(exp))
        return e.name, 0.0
    return fake


def test_blind_suite_end_to_end(grad_dataset, grad_results, tmp_path, monkeypatch, capsys):
    """suite --blind → an algorithm on SUITE/datasets only → score-suite (README's command line)."""
    monkeypatch.setattr(S, "_simulate_one", _fake_simulate(grad_dataset))
    s = tmp_path / "s"
    assert main(["suite", "-o", str(s), "--blind", "--size", "small", "--seed", "5", "--quiet"]) == 0
    meta = json.loads((s / "suite.json").read_text())
    names = [e.name for e in S.entries("small")]
    assert meta["blind"] and sorted(meta["datasets"]) == [f"d{i:02d}" for i in range(1, len(names) + 1)]
    key = json.loads((s / "truth" / "key.json").read_text())["key"]
    assert sorted(v["name"] for v in key.values()) == sorted(names)
    for d in meta["datasets"]:
        ds = s / "datasets" / d
        assert not (ds / "truth").exists() and not (ds / "journal.jsonl").exists()
        m = (ds / "manifest.json").read_text()
        assert "scenario" not in json.loads(m) and "graduation" not in m
        assert (s / "truth" / d / "bench.json").exists()
    assert not any(n in " ".join(meta["datasets"]) for n in names)
    # a second suite into the same folder is refused (exit 2), the first is untouched
    assert main(["suite", "-o", str(s), "--blind", "--size", "small", "--quiet"]) == 2
    capsys.readouterr()
    # results: the project's for all but one dataset; that one gives the naive minimal results
    r = tmp_path / "r"
    for i, d in enumerate(meta["datasets"]):
        (r / d).mkdir(parents=True)
        if i == 0:
            (r / f"{d}.json").write_text(json.dumps(naive(str(s / "datasets" / d))))
            shutil.rmtree(r / d)
        else:
            shutil.copy(grad_results, r / d / "results.json")
    assert main(["score-suite", str(r), str(s), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    o = out["overall"]
    assert o["datasets"] == o["with_results"] == len(names)
    # the graduation_error results on every other dataset: right only where graduation_error is hidden or, on
    # jia2019, declared (its 3″ graduation error, beyond Jia's model)
    assert o["identification_scored"] == len(names) - 1  # the naive results name nothing: not scored
    expecting = {e.name for e in S.entries("small") if e.expect and "graduation_error" in e.expect}
    assert expecting == {"graduation_error", "jia2019"}
    assert o["identification_correct"] == sum(key[d]["name"] in expecting for d in meta["datasets"][1:])
    assert main(["score-suite", str(r), str(s)]) == 0
    table = capsys.readouterr().out
    assert "| criterion | overall |" in table and "graduation_error" in table


def test_incomplete_suite_is_refused(tmp_path, capsys):
    (tmp_path / "s" / ".partial").mkdir(parents=True)
    assert main(["score-suite", str(tmp_path), str(tmp_path / "s")]) == 2
    assert "no suite.json" in capsys.readouterr().err


def test_python_entry_point(grad_dataset, tmp_path, monkeypatch):
    """benchtwin.score(fn, suite=DIR) on a non-blind suite: fn never sees truth/."""
    monkeypatch.setattr(S, "_simulate_one", _fake_simulate(grad_dataset))
    S.write_suite(tmp_path / "s", seed=3, blind=False, size="small")
    seen = []

    def fn(ds):
        seen.append(ds)
        assert not (S.Path(ds) / "truth").exists()
        if len(seen) == 2:
            raise RuntimeError("my fit diverged")
        return naive(ds)

    out = benchtwin.score(fn, suite=tmp_path / "s")
    assert len(seen) == len(S.entries("small"))
    assert out["overall"]["with_results"] == len(seen) - 1 and "my fit diverged" in next(iter(out["errors"].values()))
    assert out["overall"]["e_error_sweep_um"] > 0.02 and "| criterion | overall |" in out["table"]


def test_readme_example_runs_and_is_worse(grad_dataset, grad_results, tmp_path, monkeypatch):
    """The README's ten-line example, executed as written (suite path substituted), on a suite of
    copies of the graduation_error dataset: it runs, and scores worse than the project's analysis."""
    import re

    monkeypatch.setattr(S, "_simulate_one", _fake_simulate(grad_dataset))
    S.write_suite(tmp_path / "s", seed=3, blind=True, size="small")
    text = (S.Path(__file__).resolve().parents[2] / "README.md").read_text()
    block = re.search(r"```python\n(.*?def naive.*?)```", text, re.S).group(1)
    assert len(block.strip().splitlines()) <= 12  # a ten-line example (plus import and print)
    assert 'suite="s"' in block
    printed = []
    ns = {"print": printed.append}
    exec(compile(block.replace('suite="s"', f'suite="{tmp_path / "s"}"'), "README.md", "exec"), ns)
    assert "| criterion | overall |" in printed[0]
    own = score_files(grad_results, grad_dataset)
    nv = benchtwin.score(ns["naive"], suite=tmp_path / "s")["overall"]
    assert nv["e_error_sweep_um"] > 10 * abs(own["e_error_sweep_um"]) and nv["alpha_rms_error_arcsec"] > 10 * own[
        "alpha_rms_error_arcsec"]


def test_python_entry_point_builds_and_reuses_a_cached_blind_suite(grad_dataset, tmp_path, monkeypatch):
    """suite=None: a small blind suite built once in $BENCHTWIN_CACHE, then reused (not rebuilt)."""
    calls = []
    fake = _fake_simulate(grad_dataset)
    monkeypatch.setattr(S, "_simulate_one", lambda a: calls.append(a[0].name) or fake(a))
    monkeypatch.setenv("BENCHTWIN_CACHE", str(tmp_path / "cache"))
    a = benchtwin.score(naive)
    assert S.Path(a["suite_dir"]).parent == tmp_path / "cache" and len(calls) == len(S.entries("small"))
    b = benchtwin.score(naive)
    assert len(calls) == len(S.entries("small")) and b["overall"] == a["overall"]
