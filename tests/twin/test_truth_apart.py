"""simulate_apart: the measured dataset first, the truth written beside it by a forked child
(benchtwin/forkcall.py), the same bytes as simulate's truth/ (issue #17: `benchtwin run` overlaps
the truth with the analysis)."""

from __future__ import annotations

import os
import sys

import pytest

from benchtwin.analysis.dataset import DatasetError
from benchtwin.forkcall import ForkCall, ForkCallError
from benchtwin.twin import simulate as S

from tests.support.scenarios import files, small_scenario


@pytest.mark.parametrize("bearings", ["path", "ball"])
def test_truth_apart_is_the_same_bytes_as_simulates_truth(tmp_path, bearings, datasets):
    sc = small_scenario(**{"procedure.polygon_shifts": ["0 deg"], "procedure.directions": ["forward"],
                           "bearings.type": bearings})
    ref = datasets.dataset(sc)
    ds, job = S.simulate_apart(sc, tmp_path / "ds", tmp_path / "truth", progress=False, backend="analytic")
    assert (ds / "manifest.json").is_file()          # the measured dataset is complete at once
    job.wait()
    assert job.forked
    fr = files(ref)
    truth = {k[len("truth/"):]: v for k, v in fr.items() if k.startswith("truth/")}
    measured = {k: v for k, v in fr.items() if not k.startswith("truth/")}
    assert truth and files(tmp_path / "truth") == truth
    assert files(ds) == measured                     # no truth/ in the dataset, the rest identical


def test_a_failing_truth_child_fails_the_call_with_its_own_error(tmp_path, monkeypatch):
    def broken(*a, **kw):
        raise DatasetError("truth/encoder_error.csv: the disk fell off")

    monkeypatch.setattr(S, "_write_truth", broken)
    sc = small_scenario(**{"procedure.polygon_shifts": ["0 deg"], "procedure.directions": ["forward"],
                           "procedure.selfcal": False})
    ds, job = S.simulate_apart(sc, tmp_path / "ds", tmp_path / "truth", progress=False, backend="analytic")
    with pytest.raises(DatasetError, match="the disk fell off"):
        job.wait()


def test_forkcall_reports_signals_and_unpicklable_errors():
    def killed():
        os.kill(os.getpid(), 9)

    with pytest.raises(ForkCallError, match="SIGKILL"):
        ForkCall(killed, what="the victim").wait()

    class Local(Exception):   # not picklable by reference: sent back as text
        pass

    def local():
        raise Local("spelled out")

    with pytest.raises(ForkCallError, match="spelled out"):
        ForkCall(local).wait()


def test_forkcall_off_runs_in_the_caller(monkeypatch):
    monkeypatch.setenv("BENCHTWIN_FORK", "0")
    seen = []
    job = ForkCall(lambda: seen.append(os.getpid()))
    assert seen == [os.getpid()] and not job.forked
    job.wait()


def test_forkcall_cancel_stops_a_running_child(tmp_path):
    """The child is stopped, not waited for: it never gets past its sleep to write its marker (a
    cancel that waited would return after the sleep, with the marker written)."""
    import time

    marker = tmp_path / "finished"
    job = ForkCall(lambda: (time.sleep(60), marker.write_text("the child ran to its end")))
    job.cancel()
    job.wait()                                         # cancelled: nothing left to wait for
    assert not marker.exists()


@pytest.mark.slow
def test_benchtwin_run_end_to_end_keeps_the_truth_beside_the_dataset(tmp_path, monkeypatch):
    """The real `benchtwin run` on a small bench: OUT/truth is the truth simulate writes (same
    bytes), the dataset holds none, and the analysis ran (results.json, report.html). Slow (30
    frames of 2048×1536 px, ~20 s); the plumbing with a real fork is in tests/app/test_reliability.py
    (the twin and analysis replaced) and the truth's bytes in the tests above."""
    import benchtwin.app.commands as commands
    from benchtwin.cli import main

    # frames the eccentricity step can use: the paper's 2048×1536 px, 30 of them (tests/analysis/test_pipeline.py)
    sc = small_scenario(**{"procedure.polygon_shifts": ["0 deg"], "procedure.directions": ["forward"],
                           "procedure.selfcal": False, "procedure.ccd_step": "12 deg",
                           "instruments.ccd.width": "2048 px", "instruments.ccd.height": "1536 px"})
    monkeypatch.setattr(commands, "_scenario", lambda path, *overrides: sc)  # (path, --set/--seed)
    out = tmp_path / "out"
    assert main(["run", "-o", str(out), "--backend", "analytic", "--quiet", "--no-close-loop"]) == 0
    ref = S.simulate(sc, tmp_path / "ref", progress=False, backend="analytic")
    truth = {k[len("truth/"):]: v for k, v in files(ref).items() if k.startswith("truth/")}
    assert files(out / "truth") == truth
    assert not (out / "dataset" / "truth").exists()
    assert (out / "results.json").is_file() and (out / "report.html").is_file()


@pytest.mark.parametrize("bearings", ["path", "ball"])
def test_the_alpha_grid_is_the_benchs_not_the_runs(tmp_path, monkeypatch, bearings):
    """The truth's α grid is computed from the bench as built, in a child forked when the run
    starts (twin/simulate.py ``_alpha_grid``). The grid of the bench as the run left it (warm
    starts, cage path, servo rests behind it) is the same to the statics' numerical floor: the
    grid is a property of the bench, so computing it early changes nothing a metrologist reads."""
    import copy
    import csv

    import numpy as np

    built = {}
    orig = S.sim_build

    def spy(*a, **kw):
        r = orig(*a, **kw)
        built["bench"] = r[0]
        return r

    monkeypatch.setattr(S, "sim_build", spy)
    sc = small_scenario(**{"procedure.polygon_shifts": ["0 deg"], "procedure.directions": ["forward"],
                           "bearings.type": bearings})
    ds = S.simulate(sc, tmp_path / "ds", progress=False, backend="analytic")
    with open(ds / "truth" / "encoder_error.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    after = S._alpha_grid(sc, copy.deepcopy(built["bench"]))
    assert len(rows) == len(after["theta_deg"]) == 3600
    for col, values in after.items():
        written = np.array([float(r[col]) for r in rows])
        # α in arcsec, axis offsets in µm, angles in degrees: 1e-9 of each is far below any
        # uncertainty the analysis states (the statics settle to 1e-14 m / 1e-14 rad)
        np.testing.assert_allclose(written, values, rtol=0, atol=1e-9, err_msg=col)


@pytest.mark.skipif(not sys.platform.startswith("linux"),
                    reason="the mechanism under test, prctl(PR_SET_PDEATHSIG), exists only on Linux (forkcall.die_with_parent "
                           "does nothing elsewhere); /proc is read to see the child gone")
def test_a_forked_child_dies_with_its_killed_parent():
    """A command killed while a ForkCall child computes (the α grid, the truth) leaves nothing
    computing for nobody: the child gets SIGKILL when its parent dies."""
    import subprocess
    import time
    from pathlib import Path

    script = ("import os, signal, time\n"
              "from benchtwin.forkcall import ForkCall\n"
              "job = ForkCall(lambda: time.sleep(60))\n"
              "print(job._pid, flush=True)\n"
              "time.sleep(0.3)\n"
              "os.kill(os.getpid(), signal.SIGKILL)\n")
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert p.returncode == -9, p.stderr
    child = Path(f"/proc/{int(p.stdout.strip())}/stat")

    def running() -> bool:
        try:
            return child.read_text().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
        except (FileNotFoundError, ProcessLookupError):
            return False

    deadline = time.monotonic() + 10
    while running() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not running()


def test_a_forked_child_can_yield_the_cores():
    """``nice``: the α grid's child runs at a lower priority than the run it overlaps."""
    base = os.nice(0)
    assert ForkCall(lambda: os.nice(0), nice=5).wait() == min(base + 5, 19)
    assert ForkCall(lambda: os.nice(0)).wait() == base
    assert S.GRID_NICE > 0


def test_a_child_not_waited_for_is_cancelled_at_the_end_of_its_block():
    """ForkCall as a context manager (the α grid, the truth of `run`, the report's figures): a
    block left by an error stops and reaps the child; a waited child is left as it is."""
    import time

    with pytest.raises(RuntimeError, match="the caller failed"):
        with ForkCall(lambda: time.sleep(60)) as job:
            raise RuntimeError("the caller failed")
    assert job._done and not os.path.exists(f"/proc/{job._pid}") or not job.forked
    with ForkCall(lambda: 42) as done:
        assert done.wait() == 42
    assert done.wait() == 42
