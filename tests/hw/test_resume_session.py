"""Resuming an emulated acquisition against a fresh emulator session (issue #31): the fresh session
has lost the run's state (its place in the procedure, the polygon's clamping, its clock) and
served the resumed run wrong autocollimator readings with exit 0. The runner now checks the bench
before it appends a reading (hw/acquisition/runner.py ``verify_resume``): the stage must stand at
the journal's last move, and the last journaled reading, taken again at its stop, must be the
journal's. A mismatch is exit 2 saying what differs and what to do; the same session still
resumes to the uninterrupted dataset (tests/hw/test_disk_full_resume.py as well).

The run is cut at a chosen journal line (its fsync fails with ENOSPC), so the last journaled step
is a Move, a Wait or a Read, in the radial and in the polygon procedure.

The journal's header also records the emulator session (``[bench] session``), and a resume against
another session is refused before these checks (tests/hw/test_resume_session_id.py); here the
session check is off, as for a journal that records no session, so that the checks of the bench's
state are tested on their own.
"""

from __future__ import annotations

import json
import os

import pytest

from tests.support.resume import acquire_cli, full_at, journal_steps, same_dataset, small_scenario

pytestmark = [pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals"),
              pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="names an fd by /proc/self/fd")]


def _no_session_check(monkeypatch):
    from benchtwin.hw.acquisition.runner import Runner

    monkeypatch.setattr(Runner, "_verify_session", lambda self: None)


def _cut(tmp_path, monkeypatch, capsys, session, nth: int):
    bench = session.start(tmp_path / "emulator-a")
    out = tmp_path / "ds"
    full = full_at(monkeypatch, "/journal.jsonl", nth=nth)
    code, res = acquire_cli(bench, out, capsys=capsys)
    monkeypatch.undo()
    assert full["fired"] and code == 2, res
    return bench, out, journal_steps(out / "journal.jsonl")


# journal lines: 1 the header, then one per step; radial stops are Move, Wait, Read (steps 1, 2, 3, ...)
@pytest.mark.parametrize("nth, last", [(21, "move"), (22, "wait"), (152, "read"), (151, "wait")])
def test_a_fresh_emulator_session_is_refused_on_resume(tmp_path, monkeypatch, capsys, nth, last):
    from benchtwin.twin.emulators.serve import EmulationSession

    with EmulationSession(small_scenario(), camera="analytic") as first:
        _, out, steps = _cut(tmp_path, monkeypatch, capsys, first, nth)
    assert steps[-1]["step"]["type"] == last
    before = (out / "journal.jsonl").read_bytes()
    _no_session_check(monkeypatch)
    with EmulationSession(small_scenario(), camera="analytic") as fresh:
        bench = fresh.start(tmp_path / "emulator-b")
        code, res = acquire_cli(bench, out, "--resume", capsys=capsys)
    assert code == 2 and res["kind"] == "ResumeMismatchError", res
    msg = res["error"]
    assert "journal.jsonl: resume:" in msg and "not in the state the run left it in" in msg
    assert "stands at" in msg or "what the journal holds" in msg
    assert "resume against that session" in msg and "--force" in msg
    # nothing was appended: the journal is as the first run left it
    assert (out / "journal.jsonl").read_bytes() == before
    assert not (out / "manifest.json").exists()


def test_the_mismatch_names_the_reading_that_differs(tmp_path, monkeypatch, capsys):
    """Cut at a polygon reading: the fresh session's stage stands at 0°, and once moved to the
    journal's stop, its autocollimator reads another face's angle there."""
    from benchtwin.hw.acquisition.runner import Runner
    from benchtwin.twin.emulators.serve import EmulationSession

    with EmulationSession(small_scenario(), camera="analytic") as first:
        _, out, steps = _cut(tmp_path, monkeypatch, capsys, first, 152)
    last = steps[-1]["row"]
    assert last["tag"]["procedure"] == "polygon" and last["tag"]["target_deg"] != 0.0
    # the stage check off (as if the fresh session's stage stood at the journal's last stop)
    monkeypatch.setattr(Runner, "_verify_stage", lambda self, last_move, step: True)
    _no_session_check(monkeypatch)
    with EmulationSession(small_scenario(), camera="analytic") as fresh:
        bench = fresh.start(tmp_path / "emulator-b")
        code, res = acquire_cli(bench, out, "--resume", capsys=capsys)
    assert code == 2, res
    assert f"at step {last['i']}" in res["error"] and "autocollimator.x_arcsec: journal" in res["error"]
    assert json.loads(json.dumps(res))["kind"] == "ResumeMismatchError"


def test_the_same_session_resumes_to_the_uninterrupted_dataset(tmp_path, monkeypatch, capsys, simulated):
    from benchtwin.twin.emulators.serve import EmulationSession

    with EmulationSession(small_scenario(), camera="analytic") as session:
        bench, out, steps = _cut(tmp_path, monkeypatch, capsys, session, 151)
        assert steps[-1]["step"]["type"] == "wait"
        code, res = acquire_cli(bench, out, "--resume", capsys=capsys)
        assert code == 0, res
    same_dataset(simulated, out)
