"""An integer CCD frame analysed in its own levels gives the float path's results, bit for bit.

analysis/frame_levels.py and the integer path of analysis/eccentricity.py (issue #17: no float copy
of the frame): percentiles, Otsu's threshold, the binary images, the labels' statistics, the small
medians of the edge loop, and so a frame's edges, pixel scale and rejections, each compared with
what the float path computes (the frame's float copy, ``to_grey``, analysed as before).
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from benchtwin.analysis import eccentricity as ecc
from benchtwin.analysis.frame_levels import (binary_above, binary_below, integer_frame, level_counts,
                                             percentiles_from_counts)

R_PX = 22.5e3 / 0.667
PERIOD_PX = 20.0 / 0.667


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


def test_integer_frame_only_2d_unsigned_8_16_bit():
    assert integer_frame(np.zeros((3, 3), np.uint8)) is not None
    assert integer_frame(np.zeros((3, 3), np.uint16)) is not None
    for a in (np.zeros((3, 3)), np.zeros((3, 3), np.int16), np.zeros((3, 3, 3), np.uint8), np.zeros((3, 3), np.uint32)):
        assert integer_frame(a) is None


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_percentiles_from_counts_equal_numpy(dtype):
    rng = np.random.default_rng(7)
    top = int(np.iinfo(dtype).max)
    for n in (1, 2, 3, 7, 100, 101, 1000, 4097):
        for _ in range(20):
            hi = int(rng.integers(1, top + 1))
            a = rng.integers(0, hi + 1, n).astype(dtype)
            if rng.random() < 0.2:
                a[:] = a[0]  # constant
            got = percentiles_from_counts(level_counts(a, top), (1, 99))
            want = np.percentile(a.astype(float), [1, 99])
            assert _same(got, want), (n, got, want)
    with pytest.raises(ValueError):
        percentiles_from_counts(np.zeros(256, np.int64), (1, 99))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_otsu_from_levels_equals_float_otsu(dtype, grating_renderer):
    rng = np.random.default_rng(3)
    top = np.iinfo(dtype).max
    imgs = [rng.integers(0, top, (60, 80)).astype(dtype), np.full((40, 40), 9, dtype),
            (rng.normal(0.3, 0.05, (1100, 1000)).clip(0, 1) * top).astype(dtype)]  # > 1 Mpx: the sample
    g = grating_renderer(400, 300, (200 - R_PX - 2, 160), R_PX, PERIOD_PX, blur_px=1.0, noise=2.0, seed=1)
    imgs.append((g / 255 * top).round().astype(dtype))
    for img in imgs:
        assert ecc.otsu_threshold(img) == ecc.otsu_threshold(img.astype(float))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_binary_images_equal_float_comparisons(dtype):
    rng = np.random.default_rng(5)
    top = int(np.iinfo(dtype).max)
    a = rng.integers(0, top + 1, (50, 70)).astype(dtype)
    a[0, :3] = (0, top, top // 2)
    f = a.astype(float)
    for t in (-3.0, -0.5, 0.0, 0.5, 1.0, 91.999, 92.0, 92.0000001, 127.5, top - 1.0, top - 0.5, float(top), top + 4.0):
        assert _same(binary_below(a, t), (f < t).astype(np.uint8)), t
        assert _same(binary_above(a, t), (f > t).astype(np.uint8)), t


def test_labels_and_statistics_equal_cv2():
    rng = np.random.default_rng(11)
    cases = [np.ones((30, 40), np.uint8), np.zeros((30, 40), np.uint8), np.eye(40, dtype=np.uint8)[:30],
             (rng.random((200, 300)) < 0.5).astype(np.uint8),     # > _BOX_COUNT_MAX_PARTS parts: the histogram
             (rng.random((200, 300)) < 0.03).astype(np.uint8)]
    ring = np.zeros((60, 60), np.uint8)
    cv2.circle(ring, (30, 30), 20, 1, 3)
    ring[28:33, 28:33] = 1  # a part inside another's hole
    cases.append(ring)
    for b in cases:
        _n, lab, st, _ = cv2.connectedComponentsWithStats(b, connectivity=8)
        lab2, st2 = ecc._labelled(b)
        assert _same(lab, lab2) and _same(st, st2)


def test_small_median_equals_numpy():
    rng = np.random.default_rng(2)
    for n in range(1, 30):
        for _ in range(30):
            a = rng.normal(size=n) * 10.0 ** rng.integers(-3, 4)
            if rng.random() < 0.3:
                a = np.where(rng.random(n) < 0.5, -0.0, 0.0)  # np.median's sum starts at +0.0
            m, m2 = np.median(a), ecc._median(a)
            assert m == m2 and np.signbit(m) == np.signbit(m2) and type(m) is type(m2)
            b = rng.integers(0, 255, (4, n)).astype(float)
            assert _same(ecc._median(b), np.median(b, axis=1))
    assert np.isnan(ecc._median(np.array([1.0, np.nan, 2.0])))


def _frames(grating_renderer):
    """8-bit and 16-bit frames: dark and bright lines, blur, noise, dust; and bad frames."""
    W, H = 400, 300
    c = (W / 2.0 - (R_PX + 2.0), H / 2.0 + 10.0)
    dark = grating_renderer(W, H, c, R_PX, PERIOD_PX, blur_px=1.2, noise=1.0, seed=3, to_uint8=True)
    bright = grating_renderer(W, H, c, R_PX, PERIOD_PX, glass=25.0, chrome=210.0, blur_px=0.8, noise=2.0, seed=4,
                              to_uint8=True)
    dusty = dark.copy()
    cv2.circle(dusty, (int(W / 2 + 2), 120), 4, 20, -1)
    deep = grating_renderer(W, H, c, R_PX, PERIOD_PX, blur_px=1.0, noise=1.0, seed=5)
    deep16 = (deep / 255 * 65535 + np.random.default_rng(1).integers(0, 300, deep.shape)).clip(0, 65535).astype(np.uint16)
    rng = np.random.default_rng(9)
    fog = np.clip(np.rint(160 + rng.normal(0, 2, dark.shape)), 0, 255).astype(np.uint8)
    sat = np.where(rng.random(dark.shape) < 0.6, 255, dark).astype(np.uint8)
    black = np.where(rng.random(dark.shape) < 0.6, 0, dark).astype(np.uint8)
    return {"dark": dark, "bright": bright, "dusty": dusty, "deep16": deep16, "fog": fog, "sat": sat, "black": black,
            "tiny": dark[:10, :50].copy()}


def test_integer_frame_analysis_equals_the_float_path(grating_renderer):
    """edge_details, the pixel scale and d_ref of an 8/16-bit frame equal those of its float copy
    (the former path: to_grey first), field for field; rejections give the same message."""
    seen_ok, seen_rejected = 0, 0
    for name, img in _frames(grating_renderer).items():
        grey = img.astype(float)  # the float copy to_grey made of a 2-D frame
        for hint in (None, "dark", "bright"):
            got = ecc.frame_edges_and_scale(img, 20.0, name, hint)
            want = ecc.frame_edges_and_scale(grey, 20.0, name, hint)
            assert str(got[2]) == str(want[2]) and type(got[2]) is type(want[2]), name
            assert got[1] == want[1] or (got[1] is None and want[1] is None)
            if want[0] is None:
                assert got[0] is None
                seen_rejected += 1
                continue
            seen_ok += 1
            for fld in dataclasses.fields(want[0]):
                assert _same(getattr(got[0], fld.name), getattr(want[0], fld.name)), (name, fld.name)
            d1 = ecc.d_ref_px(img, (200.0, 150.0), radius_px=R_PX, name=name)
            d0 = ecc.d_ref_px(grey, (200.0, 150.0), radius_px=R_PX, name=name)
            for k in ("d_ref_px", "u_d_ref_px", "centre_px", "points_px", "rejected_points_px", "cov_circle"):
                assert _same(d1[k], d0[k]), (name, k)
    assert seen_ok >= 3 * 4 and seen_rejected >= 3 * 3
