"""Re-runs say what is true (issue 34 item 6): ``simulate -o`` onto a finished dataset says it is
complete (another folder, or --force), not that an unfinished run could be continued; onto an
interrupted one it says to continue with --resume, and ``simulate --resume`` exists and gives the
dataset an uninterrupted run writes (the twin's journal replay, tests/twin/test_simulate.py)."""

from __future__ import annotations

import json

from benchtwin.cli import main
from tests.support.interrupt import power_cut_after

# the frames of tests/support/resume.py's small bench (256×192 px, was 128×96): this bench is that one outside
# [procedure] and reads its α grid from the run's memo (twin/alpha_grid_memo.py; ≈ 2 s of CPU, issue 35)
SMALL = ["--set", "procedure.radial_reps=2", "--set", "procedure.radial_positions=24", "--set",
         'procedure.ccd_step="90 deg"', "--set", "bench.polygon_faces=8", "--set", "instruments.ccd.width=256 px",
         "--set", "instruments.ccd.height=192 px", "--set", 'procedure.directions=["forward"]']


def _sim(out, *extra: str) -> list[str]:
    return ["simulate", "-o", str(out), "--backend", "analytic", "--quiet", *SMALL, *extra]


def _files(d):
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def test_interrupted_simulation_is_continued_by_simulate_resume_and_then_said_complete(tmp_path, monkeypatch, capsys):
    from benchtwin.twin.instruments.probe import SimProbe

    assert main(_sim(tmp_path / "ref")) == 0
    orig = power_cut_after(monkeypatch, SimProbe, "read", 31)
    run = tmp_path / "run"
    assert main(_sim(run)) == 130
    monkeypatch.setattr(SimProbe, "read", orig)
    assert (run / "journal.jsonl").is_file() and not (run / "manifest.json").exists()
    capsys.readouterr()
    # unfinished: refused, and told how to continue
    assert main(_sim(run)) == 2
    err = capsys.readouterr().err
    assert "unfinished run" in err and "--resume" in err
    assert main(_sim(run, "--resume", "--force")) == 2
    assert "contradict" in capsys.readouterr().err
    # the option the message names exists, and continues the run to the uninterrupted run's dataset
    assert main(_sim(run, "--resume")) == 0
    ref, got = _files(tmp_path / "ref"), _files(run)
    assert ref.keys() == got.keys() and [k for k in ref if ref[k] != got[k]] == []
    capsys.readouterr()
    # finished: said to be complete; no --resume offered
    assert main(_sim(run)) == 2
    err = capsys.readouterr().err
    assert "complete dataset" in err and "--force" in err
    assert "unfinished" not in err and "--resume" not in err


def test_a_finished_dataset_is_said_complete_in_json_too(tmp_path, capsys):
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "journal.jsonl").write_text("{}\n")
    (ds / "manifest.json").write_text("{}\n")
    assert main(["simulate", "-o", str(ds), "--json"]) == 2
    res = json.loads(capsys.readouterr().out)
    assert "complete dataset" in res["error"] and "--resume" not in res["error"]
    assert sorted(p.name for p in ds.iterdir()) == ["journal.jsonl", "manifest.json"]   # nothing touched


def test_acquire_onto_a_finished_dataset_is_said_complete(tmp_path, capsys):
    """The same rule for acquire (its journal and manifest are simulate's): a bench file written by
    ``emulate`` (0.3 s of serving), a finished dataset refused before any instrument is opened."""
    assert main(["emulate", "--dir", str(tmp_path / "emu"), "--duration", "0.3", "--camera", "analytic",
                 "--quiet"]) == 0
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "journal.jsonl").write_text("{}\n")
    (ds / "manifest.json").write_text("{}\n")
    capsys.readouterr()
    rc = main(["acquire", str(tmp_path / "emu" / "bench.toml"), "-o", str(ds), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "complete dataset" in err and "--resume" not in err, err
