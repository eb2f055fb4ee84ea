"""Design study (Jia 2019 sec. 6): where to put the grating disk relative to the bearings.

"Regarding the design aspect, one can reduce the distance between the grating disk and the
bearing, which is close to grating disk, so as to reduce the radial error motion of the grating
disk." This script moves the disk along the same rotor (bearings, spheres and polygon stay where
they are on the shaft; L1 and every axial position measured from the disk change) and plots the
synchronous radial motion of the axis in the disk plane that the twin's statics give
(Bench.disk_plane_motion). Nothing here uses the analysis model: it is the rigid rotor on its two
bearings, so outside the bearing span the motion grows with the lever arm of the shaft's tilt.

Run: .venv/bin/python benchmarks/l1_figure.py [--out PNG]  ->  docs/img/l1_study.png
(tests/twin/test_doc_figures.py draws it again and compares the pixels)
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from benchtwin.twin.physics import Bench, shift_disk  # noqa: E402
from benchtwin.twin.scenario import load_scenario  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "docs" / "img" / "l1_study.png"


def main(argv: list[str] | None = None) -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=OUT, help="the PNG to write (default docs/img/l1_study.png)")
    out = ap.parse_args(argv).out
    sc = load_scenario().to_dict()
    sc["bearings"]["async_rms"] = 0.0          # the synchronous (repeating) motion only
    zt0 = sc["bench"]["bearing_top_z"]          # -12 mm: the jia2019 design
    zb0 = sc["bench"]["bearing_bottom_z"]
    theta = 2 * np.pi * np.arange(180) / 180
    # distance of the disk above the top bearing, from the bottom bearing's plane to 18 mm above
    # the top bearing (L1 stays > 0: the top sphere remains above the disk).
    dist_mm = np.linspace((zt0 - zb0) * -1e3, -zt0 * 1e3 + 6.0, 45)
    pp_x, pp_y, curves = [], [], {}
    for d in dist_mm:
        delta = d * 1e-3 + zt0                  # disk shift that puts it d above the top bearing
        b = Bench(shift_disk(sc, delta))
        dx, dy = b.disk_plane_motion(theta)
        pp_x.append(np.ptp(dx) * 1e6)
        pp_y.append(np.ptp(dy) * 1e6)
    for d in (-(zt0 - zb0) * 1e3 / 2, -zt0 * 1e3, -zt0 * 1e3 + 6.0):
        b = Bench(shift_disk(sc, d * 1e-3 + zt0))
        curves[d] = b.disk_plane_motion(theta)[1] * 1e6

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    for d, y in curves.items():
        lab = f"disk {d:+.0f} mm from top bearing" + ("  (jia2019)" if abs(d + zt0 * 1e3) < 1e-9 else "")
        ax1.plot(np.degrees(theta), y, label=lab)
    ax1.set_xlabel("shaft angle θ (deg)")
    ax1.set_ylabel("δY of the axis in the disk plane (µm)")
    ax1.set_title("Synchronous radial motion at the disk (twin statics)")
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    ax2.plot(dist_mm, pp_y, "o-", ms=3, label="δY peak-to-valley")
    ax2.plot(dist_mm, pp_x, "s-", ms=3, label="δX peak-to-valley")
    ax2.axvline(0, color="k", lw=0.8)
    ax2.axvline((zb0 - zt0) * 1e3, color="k", lw=0.8)
    ax2.text(0.5, ax2.get_ylim()[1] * 0.95, "top bearing", fontsize=8, va="top")
    ax2.text((zb0 - zt0) * 1e3 + 0.5, ax2.get_ylim()[1] * 0.95, "bottom bearing", fontsize=8, va="top")
    ax2.axvline(-zt0 * 1e3, color="C3", ls="--", lw=0.8, label="jia2019 design (12 mm)")
    ax2.set_xlabel("disk position above the top bearing (mm; < 0: between the bearings)")
    ax2.set_ylabel("peak-to-valley over one revolution (µm)")
    ax2.set_title("Moving the disk along the rotor (L1 changes)")
    ax2.legend(fontsize=8)
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(out)


if __name__ == "__main__":
    main()
