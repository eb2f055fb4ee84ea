"""The GL renderer's sample-mask passes (twin/render/sample_count.py) give the bytes of the MSAA
resolve they replace: datasets stay byte-identical (issue 17)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.twin.pose import BodyPose
from benchtwin.twin.render import CcdCamera, GratingSpec
from benchtwin.twin.render.grating import build_scene
from benchtwin.twin.render.sample_count import pair_table, resolved_byte
from tests.support.gl import needs_gl  # the one GL skip marker of the render tests

GRATING = GratingSpec(period_m=20e-6, duty=0.5, line_length_m=1.2e-3, edge_radius_m=22.5e-3)


def test_resolved_bytes_and_tables():
    # llvmpipe's resolve of white (255) and black (0) samples: the mean, halves rounded up
    assert [resolved_byte(c) for c in range(5)] == [255, 191, 128, 64, 0]
    one, two = pair_table(1), pair_table(2)
    assert one.dtype == two.dtype == np.uint16
    assert one[0] == 255 and one[0b1111] == 0 and one[0b0101] == 128 and one[0b1000] == 191
    assert two[0x00] == 510 and two[0xFF] == 0 and two[0x31] == 191 + 128 and two[0x8E] == 64 + 191


def _pose(t_rad: float, pos_um=(0.0, 0.0, 0.0), tilt_rad: float = 0.0) -> BodyPose:
    c, s = math.cos(t_rad), math.sin(t_rad)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    ct, st = math.cos(tilt_rad), math.sin(tilt_rad)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, ct, -st], [0.0, st, ct]])
    return BodyPose(pos=np.asarray(pos_um, float) * 1e-6, R=rx @ rz)


def _jia2019_at(t_deg: float) -> tuple[GratingSpec, BodyPose]:
    """The default scenario's grating and disk at t (its eccentricity at θ0), as
    benchmarks/render_floor.py poses it."""
    from benchtwin.twin.scenario import load_scenario

    sc = load_scenario()
    e, th0, t = sc["errors"]["eccentricity"], sc["errors"]["theta0"], math.radians(t_deg)
    a = math.pi / 2 - th0 + t
    p = _pose(t)
    return GratingSpec.from_bench(sc["bench"]), BodyPose(pos=np.array([e * math.cos(a), e * math.sin(a), 0.0]), R=p.R)


@pytest.mark.render
@needs_gl
@pytest.mark.parametrize("size, k, n, poses", [
    # the default, on jia2019 at 37° (benchmarks/render_floor.py's frame) and a tilted disk
    ((2048, 1536), 1, 2, ["jia37", (3.35, (7.1, -3.0, 0.2), 2e-4)]),
    ((512, 384), 2, 3, [(0.777, (7.1, -3.0, 0.2), 0.0)]),     # supersampled, an odd pass count
    ((512, 384), 1, 5, [(2.5, (-4.0, 6.0, 0.0), 2e-4)]),      # three mask planes
])
def test_sample_masks_give_the_resolved_bytes(size, k, n, poses):
    from benchtwin.twin.render.pyrender_backend import CoverageSampling, GlCoverageRenderer

    w, h = size
    cam = CcdCamera(azimuth_rad=math.pi, rotation_rad=0.0 if k == 1 else 0.003, width_px=w, height_px=h)
    scenes = [build_scene(*(_jia2019_at(37.0)[::-1] if p == "jia37" else (_pose(*p), GRATING)), cam) for p in poses]
    out = {}
    for counting in (True, False):
        with GlCoverageRenderer(w, h, CoverageSampling(supersample=k, jitter=n), count_samples=counting) as g:
            assert (g._counter is not None) == counting
            out[counting] = [g.coverage(s.polygons, s.end_x_px(cam.reference_px)) for s in scenes]
    for a, b in zip(out[True], out[False]):
        assert a.dtype == b.dtype == np.float32
        # glass (0), chrome (1) and edges in view
        assert float(a.min()) == 0.0 and float(a.max()) == 1.0 and np.count_nonzero((a > 0) & (a < 1)) > 100
        np.testing.assert_array_equal(a, b)


def _fan_reference(polygons, offset_px, flip_y=True, z=0.0):
    """to_trimesh's arrays assembled one polygon at a time (its former implementation)."""
    verts, faces, base = [], [], 0
    for poly in polygons:
        n = len(poly)
        v = np.asarray(poly, dtype=np.float64) + np.asarray(offset_px)
        if flip_y:
            v = v * np.array([1.0, -1.0])
        verts.append(np.column_stack([v, np.full(n, z)]))
        tri = np.column_stack([np.zeros(n - 2, int), np.arange(1, n - 1), np.arange(2, n)]) + base
        area = 0.5 * np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
        faces.append(tri if area > 0 else tri[:, ::-1])
        base += n
    return np.concatenate(verts).astype(np.float32), np.concatenate(faces)


def test_fan_arrays_are_the_per_polygon_mesh():
    from benchtwin.twin.render.grating import fan_arrays

    cam = CcdCamera(azimuth_rad=math.pi, width_px=2048, height_px=1536)
    polys = build_scene(_pose(0.777, (7.1, -3.0, 0.2), 2e-4), GRATING, cam).polygons
    assert len(polys) > 40
    # both windings and other vertex counts, between runs of the scene's 7-vertex polygons
    extra = [np.array([[0.1, 0.2], [10.0, 0.0], [10.0, 5.3]]), np.array([[0.0, 0.0], [0.0, 5.0], [10.0, 5.0], [10.0, 0.0]])]
    for pp in (polys, polys[:5] + extra + polys[5:]):
        V, F = fan_arrays(pp, (0.5, 0.5))
        Vr, Fr = _fan_reference(pp, (0.5, 0.5))
        assert V.dtype == np.float32 and V.tobytes() == Vr.tobytes()
        np.testing.assert_array_equal(F, Fr)
    V, F = fan_arrays([], (0.5, 0.5))
    assert V.shape == (0, 3) and F.shape == (0, 3)
