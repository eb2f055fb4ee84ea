"""The README's deliberately naive eccentricity fit (issue 19), importable by the tests.

e and θ0 from the first harmonic of one start face's autocollimator readings, α = those readings:
it ignores the polygon's pitch errors β (the closure of Hsieh eq. 3 removes them) and the axis's
radial motion (Jia eq. 5), so its e, θ0 and α carry β's first harmonic and β itself.
"""

import csv
import json

import numpy as np


def naive(ds):  # eccentricity from one start face's autocollimator readings, polygon errors ignored
    rows = [r for r in csv.DictReader(open(f"{ds}/polygon.csv")) if r["start_face"] == "1"
            and float(r["shift_deg"]) == 0 and r.get("rep", "0") == "0" and r.get("direction", "forward") == "forward"]
    th, ac = (np.array([float(r[k]) for r in rows]) for k in ("theta_deg", "ac_arcsec"))
    a, b, _ = np.linalg.lstsq(np.c_[np.sin(np.radians(th)), np.cos(np.radians(th)), np.ones_like(th)], ac, rcond=None)[0]
    r_um = json.load(open(f"{ds}/manifest.json"))["bench"]["optical_radius_mm"] * 1e3
    return {"format": "benchtwin-min-results", "e_um": float(np.hypot(a, b) * r_um * np.pi / 648000),
            "theta0_deg": float(np.degrees(np.arctan2(-b, a)) % 360),
            "alpha": {"theta_deg": th.tolist(), "value_arcsec": ac.tolist()}}
