"""A full disk during ``acquire`` (issue #31): exit 2 naming the file, the space free and the space
the rest of the run needs, and how to resume; ``--resume`` then takes the step that failed again
(for a CCD stop: its encoder reading, which makes the hot-folder camera's frame, and the frame)
and gives the dataset of an uninterrupted run.

The full disk is injected (portable): ``os.fsync`` of one chosen file fails with ENOSPC, as the
kernel reports a full file system at the latest when the data is flushed. One check on a real
small tmpfs (root, ``mount``) fills it for real and is skipped where mounting is not permitted.
"""

from __future__ import annotations

import errno
import filecmp
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from benchtwin.analysis.dataset import open_dataset

ROOT = Path(__file__).resolve().parents[2]
#: 12 radial stops, 4 CCD frames of 256×192 px, one polygon shift over 8 faces
SMALL = {"procedure.radial_positions": 12, "procedure.radial_reps": 1, "procedure.polygon_shifts": ["0 deg"],
         "procedure.polygon_reps": 1, "procedure.ccd_step": "90 deg", "procedure.selfcal": False,
         "procedure.directions": ["forward"], "bench.polygon_faces": 8,
         "instruments.ccd.width": "256 px", "instruments.ccd.height": "192 px"}
TABLES = ("radial_motion", "ccd/index", "polygon")

pytestmark = [pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals"),
              pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="names an fd by /proc/self/fd")]


def _scenario():
    from benchtwin.twin.scenario import load_scenario

    return load_scenario(ROOT / "scenarios" / "jia2019.toml").with_overrides(SMALL)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    from benchtwin.twin.simulate import simulate

    return simulate(_scenario(), tmp_path_factory.mktemp("sim") / "ds", progress=False, backend="analytic")


def _full_at(monkeypatch, fragment: str, nth: int = 1) -> dict:
    """``os.fsync`` of the ``nth`` file whose path contains ``fragment`` fails with ENOSPC."""
    real = os.fsync
    seen = {"n": 0, "fired": []}

    def fsync(fd: int) -> None:
        try:
            name = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            name = ""
        if fragment in name:
            seen["n"] += 1
            if seen["n"] == nth:
                seen["fired"].append(name)
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    return seen


def _steps(journal: Path) -> list[dict]:
    return [r for r in map(json.loads, journal.read_text().splitlines()) if "i" in r]


def _tables(path: Path) -> dict:
    ds = open_dataset(path)
    return {n: ds.table(n) for n in TABLES if ds.has(n)}


def _same_dataset(sim: Path, out: Path) -> None:
    a, b = _tables(sim), _tables(out)
    assert set(a) == set(b) == set(TABLES)
    for name in TABLES:
        for col in a[name]:
            if col in ("t_s", "theta_read_deg"):   # wall clock; the display's 6 decimals
                continue
            va, vb = np.asarray(a[name][col]), np.asarray(b[name][col])
            assert va.shape == vb.shape and (va == vb).all(), f"{name}.{col}"
    for f in b["ccd/index"]["file"]:
        assert filecmp.cmp(sim / "ccd" / f, out / "ccd" / f, shallow=False), f


def _acquire_cli(bench: Path, out: Path, *extra: str, capsys) -> tuple[int, dict]:
    from benchtwin.cli import main

    code = main(["acquire", str(bench), "-o", str(out), "--json", "--quiet", *extra])
    return code, json.loads(capsys.readouterr().out)


def test_a_full_disk_at_a_frame_names_it_and_resume_takes_the_frame_again(tmp_path, monkeypatch, simulated, capsys):
    from benchtwin.twin.emulators.serve import EmulationSession

    out = tmp_path / "ds"
    with EmulationSession(_scenario(), camera="analytic") as session:
        bench = session.start(tmp_path / "emulator")
        full = _full_at(monkeypatch, "/.img_002.png.")
        code, res = _acquire_cli(bench, out, capsys=capsys)
        assert full["fired"], "the injected full disk never came"
        assert code == 2 and not res["ok"], res
        msg = res["error"]
        (tmp_path / "message.txt").write_text(msg)
        for part in ("img_002.png", "the disk is full", "No space left on device", "free there", "free at least",
                     "MiB", "--resume", str(out)):
            assert part in msg, (part, msg)
        # the journal ends before the failed stop's reading: its frame is taken again on resume
        steps = _steps(out / "journal.jsonl")
        ccd = [s["row"]["tag"]["k"] for s in steps if s.get("row", {}).get("tag", {}).get("procedure") == "ccd"]
        assert ccd and max(ccd) < 2
        assert not (out / "ccd" / "img_002.png").exists() and not (out / "manifest.json").exists()
        assert not [p for p in (out / "ccd").iterdir() if p.name.startswith(".img_002")]
        monkeypatch.undo()
        code, res = _acquire_cli(bench, out, "--resume", capsys=capsys)
        assert code == 0, res
        assert session.server.errors == []
    _same_dataset(simulated, out)


def test_a_full_disk_at_the_journal_or_a_table_resumes_the_step_that_failed(tmp_path, monkeypatch, simulated, capsys):
    from benchtwin.twin.emulators.serve import EmulationSession

    out = tmp_path / "ds"
    with EmulationSession(_scenario(), camera="analytic") as session:
        bench = session.start(tmp_path / "emulator")
        # the journal's 20th line: a radial stop's reading
        full = _full_at(monkeypatch, "/journal.jsonl", nth=20)
        code, res = _acquire_cli(bench, out, capsys=capsys)
        assert full["fired"] and code == 2, res
        assert "journal.jsonl: the disk is full" in res["error"] and "--resume" in res["error"]
        n1 = len(_steps(out / "journal.jsonl"))
        monkeypatch.undo()
        # then the finished tables: radial_motion's part file cannot be fsynced
        full = _full_at(monkeypatch, "/.radial_motion.csv.part")
        code, res = _acquire_cli(bench, out, "--resume", capsys=capsys)
        assert full["fired"] and code == 2, res
        assert ".radial_motion.csv.part: the disk is full" in res["error"]
        assert len(_steps(out / "journal.jsonl")) > n1       # the readings of the second run are kept
        assert not (out / "manifest.json").exists()
        monkeypatch.undo()
        code, res = _acquire_cli(bench, out, "--resume", capsys=capsys)
        assert code == 0, res
        assert session.server.errors == []
    _same_dataset(simulated, out)


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
        with EmulationSession(_scenario(), camera="analytic") as session:
            bench = session.start(tmp_path / "emulator")
            code, res = _acquire_cli(bench, out, capsys=capsys)
            assert code == 2, res
            (tmp_path / "message.txt").write_text(res["error"])
            assert "the disk is full" in res["error"] and str(out) in res["error"] and "--resume" in res["error"]
            subprocess.run(["mount", "-o", "remount,size=64m", str(mnt)], check=True)
            code, res = _acquire_cli(bench, out, "--resume", capsys=capsys)
            assert code == 0, res
            _same_dataset(simulated, out)
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)
