"""Figures of a rendered CCD frame, like Jia 2019 fig. 11 (sec. 4.2.2).

Writes
- docs/img/ccd_frame.png: a 2048×1536 frame of the jia2019 scenario (eccentricity 7.1 µm at
  θ0 = 192.08°, shaft at 0°; dust, a scratch, vignetting, noise), downscaled to 800 px wide
  (INTER_AREA, i.e. pixel averaging, so the 30 px grating period stays visible);
- docs/img/ccd_binary.png: the same frame binarised with Otsu's threshold (cv2), as in Jia's
  fig. 11b, downscaled with nearest-neighbour so it stays binary.

Usage: ``.venv/bin/python benchmarks/make_ccd_figures.py [--backend auto] [--out docs/img]``.
tests/twin/test_doc_figures.py renders them again and compares (the docs' figures are pyrender's).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import cv2
import numpy as np

from benchtwin.twin.pose import BodyPose
from benchtwin.twin.render import GratingSpec, Renderer, SensorParams
from benchtwin.twin.scenario import load_scenario

OUT = Path(__file__).resolve().parents[1] / "docs" / "img"
WIDTH_PX = 800


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", default="auto")
    ap.add_argument("--theta-deg", type=float, default=0.0)
    ap.add_argument("--out", type=Path, default=OUT, help="folder of the two PNGs (default docs/img)")
    args = ap.parse_args(argv)
    out = args.out
    sc = load_scenario()
    grating = GratingSpec.from_bench(sc["bench"])
    sensor = SensorParams.from_section(sc["instruments"]["ccd"])
    camera = sensor.camera(sc["bench"]["ccd_position"])
    e, th0, t = sc["errors"]["eccentricity"], sc["errors"]["theta0"], math.radians(args.theta_deg)
    a = math.pi / 2 - th0 + t  # docs/conventions.md: centre at e, polar angle 90° − θ0 + t
    c, s = math.cos(t), math.sin(t)
    disk = BodyPose(pos=np.array([e * math.cos(a), e * math.sin(a), 0.0]),
                    R=np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))
    with Renderer(backend=args.backend) as r:
        frame = r.render(disk, grating, camera, sensor, np.random.default_rng(sc.seed))
    img = frame.image
    h = round(img.shape[0] * WIDTH_PX / img.shape[1])
    out.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out / "ccd_frame.png"), cv2.resize(img, (WIDTH_PX, h), interpolation=cv2.INTER_AREA))
    grey = img if img.dtype == np.uint8 else (img / (img.max() / 255.0)).astype(np.uint8)
    thr, binary = cv2.threshold(grey, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    cv2.imwrite(str(out / "ccd_binary.png"), cv2.resize(binary, (WIDTH_PX, h), interpolation=cv2.INTER_NEAREST))
    print(f"backend {frame.truth['backend']}, Otsu threshold {thr:.0f}, centre_px {frame.truth['centre_px']}, "
          f"wrote {out / 'ccd_frame.png'} and {out / 'ccd_binary.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
