"""A small, complete, valid dataset written directly (no twin), and its manifest."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from benchtwin.analysis.dataset import DatasetWriter

MANIFEST = {
    "format": "bench-dataset", "version": 1, "source": "external",
    "bench": {"optical_radius_mm": 22.0, "L1_mm": 6.81, "L2_mm": 122.96, "grating_period_um": 20.0,
              "polygon_faces": 4, "heads_deg": [0.0, 180.0]},
    "ccd": {"position_deg": 180.0, "outward": "+x", "tangential": "+x", "reference_px": [8, 6], "pixel_um": 0.667},
}


def make_dataset(root: Path, **overrides) -> Path:
    """A small, complete, valid dataset (4-face polygon, 2 heads, 60 tiny images) with the structure
    the analysis needs at order 10 (issue 31: every revolution and the CCD sweep cover the turn with
    gaps below 18°, the heads on a full-circle grid); the images are not gratings."""
    m = json.loads(json.dumps(MANIFEST))
    m.update(overrides.pop("manifest", {}))
    w = DatasetWriter(root, m)
    th = np.arange(0, 360, 15.0)
    w.write_table("radial_motion", {"rep": np.repeat([0, 1], th.size), "theta_deg": np.tile(th, 2),
                                    "probe_top_um": np.sin(np.radians(np.tile(th, 2))), "probe_bottom_um": np.zeros(2 * th.size)})
    rows = [(0.0, j, i, (i - 1) * 90.0, 0.1 * i - 0.05 * j, float(4 * j + i)) for j in range(1, 5) for i in range(1, 5)]
    w.write_table("polygon", dict(zip(["shift_deg", "start_face", "step", "theta_deg", "ac_arcsec", "t_s"], map(list, zip(*rows)))))
    w.write_table("heads", {"theta_deg": [0.0, 0.0, 90.0, 90.0, 180.0, 180.0, 270.0, 270.0], "head": [1, 2] * 4,
                            "delta_arcsec": [0.0, 0.3, 0.0, -0.2, 0.0, 0.1, 0.0, -0.1]})
    for k in range(60):  # frames at different angles are never pixel-identical (the reader checks)
        img = np.full((12, 16), 200, np.uint8)
        img[:, 8 + min(k, 1):] = 30
        if k >= 2:
            img[k % 12, k // 12] = 100
        w.write_image(f"ccd/img_{k:03d}.png", img)
    w.write_table("ccd/index", {"k": list(range(60)), "theta_deg": [6.0 * k for k in range(60)],
                                "file": [f"img_{k:03d}.png" for k in range(60)]})
    w.close()
    return root
