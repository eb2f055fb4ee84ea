"""What the study tests share (tests/app/test_study.py, tests/app/test_readers_strict.py): a cheap
stand-in point function (module-level, so worker processes import it by reference) that counts its
calls by writing one file per call, a study file writer and a basic study."""

from __future__ import annotations

import textwrap
import time
import uuid
from pathlib import Path

import numpy as np


def counting_point(task: dict, count_dir: str | None = None, delay_s: float = 0.0) -> list[dict]:
    """Cheap analytic outputs of L1 (and the rep seed); one file per call in ``count_dir``."""
    if count_dir:
        Path(count_dir, uuid.uuid4().hex).write_text(str(task["point"]))
    if delay_s:
        time.sleep(delay_s)
    L1_mm = task["scenario"]["bench"]["L1"] * 1e3
    out = []
    for seed in task["rep_seeds"]:
        rng = np.random.default_rng(seed)
        out.append({"angle_error_pv_arcsec": 0.1 * L1_mm + 0.01 * rng.standard_normal(),
                    "disk_motion_x_pv_um": 0.02 * L1_mm})
    return out


def write_study(tmp_path: Path, body: str, name: str = "s.toml") -> Path:
    p = tmp_path / name
    p.write_text(textwrap.dedent(body), encoding="utf-8")
    return p


BASIC = """
[study]
name = "basic"
base = "jia2019"
seed = 7
repetitions = 2
outputs = ["angle_error_pv_arcsec", "disk_motion_x_pv_um"]
[[study.parameters]]
key = "bench.L1"
values = ["2 mm", "5 mm", "10 mm", "20 mm"]
[study.target]
output = "angle_error_pv_arcsec"
below = "1.2 arcsec"
"""
