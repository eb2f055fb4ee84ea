"""A full disk during ``acquire`` (issue #31): exit 2 naming the file, the space free and the space
the rest of the run needs, and how to resume; ``--resume`` then takes the step that failed again
(for a CCD stop: its encoder reading, which makes the hot-folder camera's frame, and the frame)
and gives the dataset of an uninterrupted run.

The full disk is injected (portable): ``os.fsync`` of one chosen file fails with ENOSPC, as the
kernel reports a full file system at the latest when the data is flushed. One check on a real
small tmpfs (root, ``mount``) fills it for real and is skipped where mounting is not permitted.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.support.resume import acquire_cli, full_at, journal_steps, same_dataset, small_scenario

pytestmark = [pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals"),
              pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="names an fd by /proc/self/fd")]


def test_a_full_disk_at_a_frame_names_it_and_resume_takes_the_frame_again(tmp_path, monkeypatch, simulated, capsys):
    from benchtwin.twin.emulators.serve import EmulationSession

    out = tmp_path / "ds"
    with EmulationSession(small_scenario(), camera="analytic") as session:
        bench = session.start(tmp_path / "emulator")
        full = full_at(monkeypatch, "/.img_002.png.")
        code, res = acquire_cli(bench, out, capsys=capsys)
        assert full["fired"], "the injected full disk never came"
        assert code == 2 and not res["ok"], res
        msg = res["error"]
        (tmp_path / "message.txt").write_text(msg)
        for part in ("img_002.png", "the disk is full", "No space left on device", "free there", "free at least",
                     "MiB", "--resume", str(out)):
            assert part in msg, (part, msg)
        # the journal ends before the failed stop's reading: its frame is taken again on resume
        steps = journal_steps(out / "journal.jsonl")
        ccd = [s["row"]["tag"]["k"] for s in steps if s.get("row", {}).get("tag", {}).get("procedure") == "ccd"]
        assert ccd and max(ccd) < 2
        assert not (out / "ccd" / "img_002.png").exists() and not (out / "manifest.json").exists()
        assert not [p for p in (out / "ccd").iterdir() if p.name.startswith(".img_002")]
        monkeypatch.undo()
        code, res = acquire_cli(bench, out, "--resume", capsys=capsys)
        assert code == 0, res
        assert session.server.errors == []
    same_dataset(simulated, out)


def test_a_full_disk_at_the_journal_or_a_table_resumes_the_step_that_failed(tmp_path, monkeypatch, simulated, capsys):
    from benchtwin.twin.emulators.serve import EmulationSession

    out = tmp_path / "ds"
    with EmulationSession(small_scenario(), camera="analytic") as session:
        bench = session.start(tmp_path / "emulator")
        # the journal's 20th line: a radial stop's reading
        full = full_at(monkeypatch, "/journal.jsonl", nth=20)
        code, res = acquire_cli(bench, out, capsys=capsys)
        assert full["fired"] and code == 2, res
        assert "journal.jsonl: the disk is full" in res["error"] and "--resume" in res["error"]
        n1 = len(journal_steps(out / "journal.jsonl"))
        monkeypatch.undo()
        # then the finished tables: radial_motion's part file cannot be fsynced
        full = full_at(monkeypatch, "/.radial_motion.csv.part")
        code, res = acquire_cli(bench, out, "--resume", capsys=capsys)
        assert full["fired"] and code == 2, res
        assert ".radial_motion.csv.part: the disk is full" in res["error"]
        assert len(journal_steps(out / "journal.jsonl")) > n1       # the readings of the second run are kept
        assert not (out / "manifest.json").exists()
        monkeypatch.undo()
        code, res = acquire_cli(bench, out, "--resume", capsys=capsys)
        assert code == 0, res
        assert session.server.errors == []
    same_dataset(simulated, out)


def _mount_tmpfs(where: Path, size: str) -> bool:
    where.mkdir(parents=True, exist_ok=True)
    if shutil.which("mount") is None or os.geteuid() != 0:
        return False
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)], capture_output=True)
    return r.returncode == 0


def test_a_real_full_tmpfs_then_more_space_resumes(tmp_path, simulated, capsys):
    """A tmpfs of 160 KiB fills during the run (the journal, the radial table, each 256×192 frame
    ≈ 50 kB); grown to 64 MiB (``mount -o remount``), the resumed run completes."""
    from benchtwin.twin.emulators.serve import EmulationSession

    mnt = tmp_path / "small"
    if not _mount_tmpfs(mnt, "160k"):
        pytest.skip("mounting a tmpfs is not permitted here")
    try:
        out = mnt / "ds"
        with EmulationSession(small_scenario(), camera="analytic") as session:
            bench = session.start(tmp_path / "emulator")
            code, res = acquire_cli(bench, out, capsys=capsys)
            assert code == 2, res
            (tmp_path / "message.txt").write_text(res["error"])
            assert "the disk is full" in res["error"] and str(out) in res["error"] and "--resume" in res["error"]
            subprocess.run(["mount", "-o", "remount,size=64m", str(mnt)], check=True)
            code, res = acquire_cli(bench, out, "--resume", capsys=capsys)
            assert code == 0, res
            same_dataset(simulated, out)
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)
