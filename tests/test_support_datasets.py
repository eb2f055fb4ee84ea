"""The suite's dataset factory (tests/support/datasets.py, issue 35): a scenario is simulated once
per run, by one process of the run, and handed out read-only or as a private copy; a test that
writes into a shared dataset is named. The twin is replaced by a recording stand-in here (the
datasets' bytes are the twin tests' business)."""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import time
from pathlib import Path

import pytest

import benchtwin.twin.simulate as S

from tests.support.datasets import DatasetFactory, scenario_key
from tests.support.scenarios import ROOT, small_scenario


def _stand_in(log: Path, pause_s: float = 0.0):
    """A ``simulate`` that writes a two-file dataset (manifest last) and logs each call."""

    def simulate(sc, out, progress=True, backend="auto", **kw):
        with open(log, "a") as fh:
            fh.write(f"{os.getpid()} {sc.seed}\n")
        out = Path(out)
        (out / "truth").mkdir(parents=True)
        (out / "truth" / "scenario.json").write_text(json.dumps({"seed": sc.seed}))
        time.sleep(pause_s)                 # a simulation takes a while: the others must wait for it
        (out / "manifest.json").write_text(json.dumps({"backend": backend}))
        return out

    return simulate


def test_a_scenario_is_simulated_once_and_a_copy_is_private(tmp_path, monkeypatch):
    log = tmp_path / "calls.log"
    monkeypatch.setattr(S, "simulate", _stand_in(log))
    f = DatasetFactory(tmp_path / "cache")
    a = f.dataset(small_scenario())
    assert f.dataset(small_scenario()) == a                  # the same content: the same dataset
    mine = f.copy(small_scenario(), tmp_path / "mine", ignore=("truth",))
    assert log.read_text().count("\n") == 1 and f.simulated == [scenario_key(small_scenario())]
    assert (mine / "manifest.json").is_file() and not (mine / "truth").exists()
    (mine / "manifest.json").write_text("changed")           # a copy is the test's own
    assert f.verify() == []
    f.dataset(small_scenario(**{"scenario.seed": 7}))        # another scenario: simulated
    assert log.read_text().count("\n") == 2
    (a / "truth" / "scenario.json").write_text("{}")         # writing into a shared one is named
    assert f.verify() == [str(a)]


def test_the_key_is_the_scenarios_content():
    sc = small_scenario()
    assert scenario_key(sc) == scenario_key(small_scenario())
    assert scenario_key(sc) != scenario_key(sc, backend="gl")
    assert scenario_key(sc) != scenario_key(small_scenario(**{"procedure.radial_reps": 3}))
    from benchtwin.twin.scenario import load_scenario

    file = load_scenario(ROOT / "scenarios" / "jia2019.toml")   # its path is written into truth/
    assert scenario_key(file) != scenario_key(file.with_overrides({}))
    # the same values, overrides recorded or not (truth/scenario.json differs): two datasets
    cleared = sc.with_overrides({})
    cleared.overrides = {}
    assert cleared.raw == sc.raw and scenario_key(cleared) != scenario_key(sc)


def _two_at_once(target, *args: str) -> list[int | None]:
    """Run ``target(*args)`` in two processes at once (as two xdist workers would ask) and return their
    exit codes. Forked, not spawned: the stand-ins the targets install (a fake twin, a ``make`` that
    logs its calls) are set in the child from this module's state, which a spawned child would not
    share; where the OS has no fork there is no such race to test."""
    if "fork" not in mp.get_all_start_methods():
        pytest.skip("needs fork: the stand-ins are module state a spawned child would not inherit")
    ctx = mp.get_context("fork")
    procs = [ctx.Process(target=target, args=args) for _ in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
    return [p.exitcode for p in procs]


def _ask(root: str, log: str) -> None:
    S.simulate = _stand_in(Path(log), pause_s=0.5)
    DatasetFactory(Path(root)).dataset(small_scenario())


def test_processes_of_one_run_share_one_simulation(tmp_path):
    """xdist's workers: two processes asking at once get one simulation between them."""
    log = tmp_path / "calls.log"
    assert _two_at_once(_ask, str(tmp_path / "cache"), str(log)) == [0, 0]
    assert log.read_text().count("\n") == 1
    assert (tmp_path / "cache" / scenario_key(small_scenario()) / "ds" / "manifest.json").is_file()


def _made_by(log: Path, pause_s: float = 0.0):
    """A ``make`` for ``DatasetFactory.shared`` that writes out/results.json and logs each call."""

    def make(base: Path) -> None:
        with open(log, "a") as fh:
            fh.write(f"{os.getpid()}\n")
        (base / "out").mkdir()
        time.sleep(pause_s)
        (base / "out" / "results.json").write_text("{}")

    return make


def test_a_shared_folder_is_made_once_and_checked_read_only(tmp_path):
    """``shared(name, make)`` (the session's analysed runs): made once, in place, then handed out;
    a left-over without its completion mark is made again; a write into it is named."""
    log = tmp_path / "calls.log"
    f = DatasetFactory(tmp_path / "cache")
    a = f.shared("an analysis", _made_by(log))
    assert f.shared("an analysis", _made_by(log)) == a and (a / "out" / "results.json").is_file()
    assert log.read_text().count("\n") == 1
    b = f.shared("another analysis", _made_by(log))
    assert b != a and log.read_text().count("\n") == 2
    (b / ".complete").unlink()                               # as if its maker had been killed
    (b / "out" / "stale").write_text("x")
    g = DatasetFactory(tmp_path / "cache")
    assert g.shared("another analysis", _made_by(log)) == b and not (b / "out" / "stale").exists()
    assert log.read_text().count("\n") == 3
    assert f.verify() == [] and g.verify() == []
    (a / "out" / "results.json").write_text("changed")       # writing into a shared one is named
    assert f.verify() == [str(a)]


def _ask_shared(root: str, log: str) -> None:
    DatasetFactory(Path(root)).shared("an analysis", _made_by(Path(log), pause_s=0.5))


def test_processes_of_one_run_share_one_made_folder(tmp_path):
    """Two xdist workers asking for the same shared folder at once: one makes it, the other waits."""
    log = tmp_path / "calls.log"
    assert _two_at_once(_ask_shared, str(tmp_path / "cache"), str(log)) == [0, 0]
    assert log.read_text().count("\n") == 1
