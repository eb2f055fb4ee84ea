"""Exact pixel-coverage renderer of the CCD scene (numpy), for Jia 2019 sec. 4.2 images.

Why: the eccentricity analysis (Jia sec. 4.2.2, eqs. 10–13) fits a circle through the outer ends of
the graduation lines with sub-pixel edge estimates; a renderer whose edges are off by 0.1 px would
put a pattern of that size into d_ref(θ). This renderer computes, for every pixel, the exact area
of the pixel square covered by the line polygons of ``grating.build_scene`` (the same polygons the
pyrender backend rasterises), so it is (a) the cross-check of the GL backend and (b) the fallback
where no OpenGL context exists.

Method (vectorised per line, on the line's bounding box only):

- classify pixels by the signed distances d_i of the pixel centre to the polygon's edges: outside
  if some d_i ≤ −h_i, inside if all d_i ≥ h_i, where h_i = (|n_x|+|n_y|)/2 is the half-extent of
  the unit square along the edge normal; only the remaining "mixed" pixels (≈ 2 per column along
  each line side, a few at the end) need an area;
- mixed pixels: area(P ∩ B) for the square B = [x0,x1]×[y0,y1] by Green's theorem,
  area = −orient·Σ_edges ∫ 1[x0≤x≤x1]·(clamp(y, y0, y1) − y0) dx, evaluated in closed form for each
  straight edge (the clamp's antiderivative is piecewise quadratic). Exact for any convex or
  non-convex polygon, any number of edges crossing the pixel (corners, chord joints), in float64.
"""

from __future__ import annotations

import numpy as np

__all__ = ["coverage_image", "polygon_pixel_area"]


def _G(y: np.ndarray, y0: np.ndarray, y1: np.ndarray) -> np.ndarray:
    """Antiderivative of F(y) = clamp(y, y0, y1) − y0 with G(y0) = 0."""
    h = y1 - y0
    yc = np.clip(y, y0, y1)
    return 0.5 * (yc - y0) ** 2 + h * np.maximum(y - y1, 0.0)


def polygon_pixel_area(poly: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Exact area of the polygon ``poly`` (n, 2) inside the unit pixel squares centred at (px, py)."""
    x0, x1 = px - 0.5, px + 0.5
    y0, y1 = py - 0.5, py + 0.5
    a = np.asarray(poly, dtype=np.float64)
    b = np.roll(a, -1, axis=0)
    orient = np.sign(np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]))
    S = np.zeros(np.broadcast(px, py).shape)
    for (xa, ya), (xb, yb) in zip(a, b):
        if xa == xb:
            continue  # vertical edge: dx = 0
        m = (yb - ya) / (xb - xa)
        lo = np.maximum(min(xa, xb), x0)
        hi = np.minimum(max(xa, xb), x1)
        w = np.maximum(hi - lo, 0.0)
        ylo = ya + (lo - xa) * m
        yhi = ya + (hi - xa) * m
        dy = yhi - ylo
        # mean of F over the clipped edge; where the edge is (nearly) level use F at the midpoint
        small = np.abs(dy) < 1e-9
        safe = np.where(small, 1.0, dy)
        mean_F = np.where(small, np.clip(0.5 * (ylo + yhi), y0, y1) - y0,
                          (_G(yhi, y0, y1) - _G(ylo, y0, y1)) / safe)
        S += np.sign(xb - xa) * w * mean_F
    return -orient * S


def _edges(poly: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inward unit normals n_i, offsets c_i (inside: n·p ≥ c), half-extents h_i of a convex polygon."""
    a = np.asarray(poly, dtype=np.float64)
    b = np.roll(a, -1, axis=0)
    orient = np.sign(np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1]))
    e = b - a
    L = np.hypot(e[:, 0], e[:, 1])
    ok = L > 0
    e, a, L = e[ok], a[ok], L[ok]
    n = orient * np.stack([-e[:, 1], e[:, 0]], axis=1) / L[:, None]  # left normal for CCW (y-up maths)
    c = np.sum(n * a, axis=1)
    h = 0.5 * (np.abs(n[:, 0]) + np.abs(n[:, 1]))
    return n, c, h


def coverage_image(polygons: list[np.ndarray], width_px: int, height_px: int,
                   ref_px: tuple[float, float]) -> np.ndarray:
    """Coverage in [0, 1] (float64, H×W) of disjoint convex polygons given in camera-local px
    (relative to ``ref_px``). Overlaps are clipped to 1 (the scene's lines never overlap)."""
    cov = np.zeros((height_px, width_px))
    rx, ry = ref_px
    for poly in polygons:
        P = np.asarray(poly, dtype=np.float64) + np.array([rx, ry])  # image px, float64
        xa = max(int(np.floor(P[:, 0].min())) - 1, 0)
        xb = min(int(np.ceil(P[:, 0].max())) + 1, width_px - 1)
        ya = max(int(np.floor(P[:, 1].min())) - 1, 0)
        yb = min(int(np.ceil(P[:, 1].max())) + 1, height_px - 1)
        if xa > xb or ya > yb:
            continue
        X, Y = np.meshgrid(np.arange(xa, xb + 1, dtype=np.float64), np.arange(ya, yb + 1, dtype=np.float64))
        n, c, h = _edges(P)
        inside = np.ones(X.shape, bool)
        outside = np.zeros(X.shape, bool)
        for i in range(len(c)):
            d = n[i, 0] * X + n[i, 1] * Y - c[i]
            inside &= d >= h[i]
            outside |= d <= -h[i]
        block = inside.astype(np.float64)
        mixed = ~inside & ~outside
        if mixed.any():
            block[mixed] = polygon_pixel_area(P, X[mixed], Y[mixed])
        sub = cov[ya:yb + 1, xa:xb + 1]
        np.add(sub, block, out=sub)
    np.clip(cov, 0.0, 1.0, out=cov)
    return cov
