"""benchmarks/area_floor.py, the render floor at the twin's quality (issue 17), is the exact pixel
coverage: it agrees with the twin's analytic renderer (twin/render/analytic.py) to float32 rounding.
Correctness only: its speed is the benchmark's (docs/benchmarks.md), never a timed test."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from benchtwin.twin.pose import BodyPose
from benchtwin.twin.render import CcdCamera, GratingSpec
from benchtwin.twin.render.analytic import coverage_image
from benchtwin.twin.render.grating import build_scene

ROOT = Path(__file__).resolve().parents[2]
GRATING = GratingSpec(period_m=20e-6, duty=0.5, line_length_m=1.2e-3, edge_radius_m=22.5e-3)


@pytest.fixture(scope="module")
def area_coverage():
    spec = importlib.util.spec_from_file_location("area_floor", ROOT / "benchmarks" / "area_floor.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.area_coverage


@pytest.mark.parametrize("t_rad, pos_um, tilt_rad, cam_rot", [
    (0.0, (0.0, 0.0, 0.0), 0.0, 0.0),
    (0.777, (7.1, -3.0, 0.2), 2e-4, 0.003),
    (2.5, (-4.0, 6.0, 0.0), 0.0, -0.2),      # steep sides: pieces over several rows
])
def test_scene_coverage_is_exact(area_coverage, t_rad, pos_um, tilt_rad, cam_rot):
    cam = CcdCamera(azimuth_rad=math.pi, rotation_rad=cam_rot, width_px=512, height_px=384)
    c, s = math.cos(t_rad), math.sin(t_rad)
    ct, st = math.cos(tilt_rad), math.sin(tilt_rad)
    R = np.array([[1.0, 0.0, 0.0], [0.0, ct, -st], [0.0, st, ct]]) @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    scene = build_scene(BodyPose(pos=np.asarray(pos_um) * 1e-6, R=R), GRATING, cam)
    assert len(scene.polygons) > 5
    got = area_coverage(scene.polygons, 512, 384, cam.reference_px)
    exact = coverage_image(scene.polygons, 512, 384, cam.reference_px)
    assert got.dtype == np.float32 and got.shape == (384, 512)
    assert 0 < np.count_nonzero((exact > 0) & (exact < 1))
    np.testing.assert_allclose(got, exact, atol=1e-6, rtol=0)


def test_both_windings_and_the_frame_border(area_coverage):
    # a triangle and quadrilaterals crossing every border of a 40×30 frame, either winding
    polys = [np.array([[-30.0, -25.0], [35.0, -12.3], [-3.7, 40.0]]),
             np.array([[12.2, 3.1], [12.9, -20.0], [25.0, -19.5], [24.1, 3.6]])[::-1],
             np.array([[-16.0, 5.5], [-5.0, 5.5], [-5.0, 9.25], [-16.0, 9.25]])]
    ref = (20.0, 15.0)
    for group in ([polys[0]], [np.vstack([p, p[-1:]]) for p in polys[1:]]):
        got = area_coverage(group, 40, 30, ref)
        np.testing.assert_allclose(got, coverage_image(group, 40, 30, ref), atol=1e-6, rtol=0)
