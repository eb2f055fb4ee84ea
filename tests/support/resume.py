"""What the resume tests share (tests/hw/test_disk_full_resume.py, tests/hw/test_resume_session.py):
a small jia2019 acquisition, a full disk injected at a chosen fsync, the journal's steps, the CLI's
``acquire``, and the check that a resumed dataset is the uninterrupted one (the ``simulated``
fixture of tests/hw/conftest.py)."""

from __future__ import annotations

import errno
import filecmp
import json
import os
from pathlib import Path

import numpy as np

from benchtwin.analysis.dataset import open_dataset

ROOT = Path(__file__).resolve().parents[2]
#: 12 radial stops, 4 CCD frames of 256×192 px, one polygon shift over 8 faces
SMALL = {"procedure.radial_positions": 12, "procedure.radial_reps": 1, "procedure.polygon_shifts": ["0 deg"],
         "procedure.polygon_reps": 1, "procedure.ccd_step": "90 deg", "procedure.selfcal": False,
         "procedure.directions": ["forward"], "bench.polygon_faces": 8,
         "instruments.ccd.width": "256 px", "instruments.ccd.height": "192 px"}
TABLES = ("radial_motion", "ccd/index", "polygon")


def small_scenario():
    from benchtwin.twin.scenario import load_scenario

    return load_scenario(ROOT / "scenarios" / "jia2019.toml").with_overrides(SMALL)


def full_at(monkeypatch, fragment: str, nth: int = 1) -> dict:
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


def journal_steps(journal: Path) -> list[dict]:
    return [r for r in map(json.loads, journal.read_text().splitlines()) if "i" in r]


def _tables(path: Path) -> dict:
    ds = open_dataset(path)
    return {n: ds.table(n) for n in TABLES if ds.has(n)}


def same_dataset(sim: Path, out: Path) -> None:
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


def acquire_cli(bench: Path, out: Path, *extra: str, capsys) -> tuple[int, dict]:
    from benchtwin.cli import main

    code = main(["acquire", str(bench), "-o", str(out), "--json", "--quiet", *extra])
    return code, json.loads(capsys.readouterr().out)
