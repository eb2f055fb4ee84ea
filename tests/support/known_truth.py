"""A truth folder written by hand, of known values (issue 19): e, θ0, β of a 4-face polygon, α at
its stops and on a 16-point grid; no simulation. The scorer's tests (tests/app/) score results of
known error against it (the ``truth`` fixture of tests/app/conftest.py)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

E_UM, THETA0_DEG = 7.1, 359.9
BETA = {1: 0.5, 2: -0.2, 3: -0.6, 4: 0.3}
STOPS = np.array([0.0, 90.0, 180.0, 270.0])
GRID = np.arange(0.0, 360.0, 22.5)  # 16 points


def alpha_true(th_deg):
    th = np.radians(th_deg)
    return 66.6 * np.sin(th - math.radians(THETA0_DEG)) + 0.4 * np.cos(2 * th) + 0.2 * np.sin(4 * th)


def write_csv(path, cols):
    keys = list(cols)
    lines = [",".join(keys)] + [",".join(repr(float(cols[k][i])) if not isinstance(cols[k][i], str) else cols[k][i]
                                         for k in keys) for i in range(len(cols[keys[0]]))]
    path.write_text("\n".join(lines) + "\n")


def write_truth(root: Path) -> Path:
    """A dataset folder ``root/ds`` holding only the hand-made truth/; returns ``root/ds``."""
    ds = root / "ds"
    td = ds / "truth"
    td.mkdir(parents=True)
    (td / "bench.json").write_text(json.dumps({"disk_eccentricity_m": E_UM * 1e-6,
                                               "theta0_rad": math.radians(THETA0_DEG)}))
    write_csv(td / "polygon_beta.csv", {"face": list(BETA), "beta_arcsec": list(BETA.values())})
    # polygon stops read twice each (two start faces), same true α
    th = np.repeat(STOPS, 2)
    write_csv(td / "polygon.csv", {"theta_deg": th, "alpha_arcsec": alpha_true(th)})
    fine = np.arange(0.0, 360.0, 0.1)
    write_csv(td / "encoder_error.csv", {"theta_deg": fine, "alpha_arcsec": alpha_true(fine)})
    (td / "hidden.json").write_text(json.dumps({"effects": {}}))
    return ds
