"""Issue #31: a fresh emulator session whose stage stands at the journal's last stop (0°, the
start of the next procedure) with no reading journaled there passed the resume checks of
``verify_resume`` (stage position, the last reading taken again), and its wrong readings were
appended with exit 0. ``benchtwin emulate`` now writes ``[bench] session`` (a uuid4's 32 hex
characters) into its bench file; ``acquire`` journals it in the journal's header line, and a resume
whose bench file names another session, or none, is exit 2 before anything is appended.
"""

from __future__ import annotations

import json
import os

import pytest

from tests.support.resume import acquire_cli, full_at, journal_steps, small_scenario

pytestmark = [pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals"),
              pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="names an fd by /proc/self/fd")]


def _cut_after_move_to_zero(tmp_path, monkeypatch, capsys, session):
    """Run until the journal's last step is the Move to 0° that starts the polygon procedure (the
    last reading journaled: the CCD sweep's at 270°): the journal's next fsync fails."""
    bench = session.start(tmp_path / "emulator-a")
    out = tmp_path / "ds"
    full = full_at(monkeypatch, "/journal.jsonl", nth=54)
    code, res = acquire_cli(bench, out, capsys=capsys)
    monkeypatch.undo()
    assert full["fired"] and code == 2, res
    steps = journal_steps(out / "journal.jsonl")
    assert steps[-1]["step"] == {"type": "move", "target_deg": 0.0}, steps[-1]
    last_read = max(k for k, s in enumerate(steps) if s["step"]["type"] == "read")
    stop = [s["step"]["target_deg"] for s in steps[:last_read] if s["step"]["type"] == "move"][-1]
    assert stop == 270.0    # no reading journaled at 0° since: the reading check has nothing to take again
    return bench, out


def test_a_fresh_session_at_the_journals_last_stop_is_refused(tmp_path, monkeypatch, capsys):
    """Without the session check this resume exits 0: the fresh session's stage stands at 0°, the
    journal's last move, and its polygon readings differ from the uninterrupted run's (ac_arcsec by
    0.06 to 0.8 arcsec, by the first run's timing)."""
    from benchtwin.twin.emulators.serve import EmulationSession

    with EmulationSession(small_scenario(), camera="analytic") as first:
        _, out = _cut_after_move_to_zero(tmp_path, monkeypatch, capsys, first)
        header = json.loads((out / "journal.jsonl").read_text().splitlines()[0])
        assert header == {"journal": "benchtwin-run", "version": 1, "session": first.session_id}
    before = (out / "journal.jsonl").read_bytes()
    with EmulationSession(small_scenario(), camera="analytic") as fresh:
        assert fresh.session_id != first.session_id
        bench = fresh.start(tmp_path / "emulator-b")
        code, res = acquire_cli(bench, out, "--resume", capsys=capsys)
    assert code == 2 and res["kind"] == "ResumeMismatchError", res
    msg = res["error"]
    assert "journal.jsonl: resume:" in msg and first.session_id in msg and fresh.session_id in msg
    assert "emulator was restarted" in msg and "belong to the other session" in msg
    assert "resume against that session" in msg and "--force" in msg
    assert (out / "journal.jsonl").read_bytes() == before    # nothing appended
    assert not (out / "manifest.json").exists()


def test_a_bench_file_without_the_session_is_refused_too(tmp_path, monkeypatch, capsys):
    from benchtwin.twin.emulators.serve import EmulationSession

    with EmulationSession(small_scenario(), camera="analytic") as first:
        bench, out = _cut_after_move_to_zero(tmp_path, monkeypatch, capsys, first)
        text = bench.read_text()
        bench.write_text("".join(line for line in text.splitlines(keepends=True) if not line.startswith("session =")))
        code, res = acquire_cli(bench, out, "--resume", capsys=capsys)
    assert code == 2 and res["kind"] == "ResumeMismatchError", res
    assert "names no emulator session" in res["error"]


@pytest.mark.parametrize("value", ['"abc"', '"' + "G" * 32 + '"', "12", '"' + "A" * 32 + '"'])
def test_a_bad_session_key_names_the_key(tmp_path, value):
    from benchtwin.hw.acquisition.bench import BenchFileError, load_bench
    from benchtwin.twin.emulators.serve import EmulationSession

    with EmulationSession(small_scenario()) as s:
        bench = s.start(tmp_path / "emulator")
        good = load_bench(bench)
        assert good.session == s.session_id and len(good.session) == 32
        bench.write_text(bench.read_text().replace(f'"{s.session_id}"', value))
        with pytest.raises(BenchFileError, match=r"key 'bench.session': expected 32 lower-case hex"):
            load_bench(bench)
