"""A supersampled renderer of radial grating images.

The renderer draws the scale edge as the analysis expects it (docs/conventions.md, "CCD image
axes"): image +x radially outward, graduation lines radial from the disk centre, of angular pitch
``period/R`` (period measured at the edge radius R), ending on the circle r = R. Pixel (x, y) =
(column, row), origin at the centre of the top-left pixel; a pixel's value is the mean over its
area (box-integrated), computed exactly where the pixel is uniform (its four corners and its
neighbours' agree) and by s×s supersampling where an edge crosses it (s = 64 near the line ends,
where sub-pixel accuracy matters, 6 along the line sides).
"""

from __future__ import annotations

import math

import numpy as np


def _chrome(x: np.ndarray, y: np.ndarray, g: dict) -> np.ndarray:
    dx = x - g["cx"]
    dy = y - g["cy"]
    r = np.hypot(dx, dy)
    u = (np.arctan2(dy, dx) - g["phase_rad"]) / g["pitch_rad"]
    frac = u - np.floor(u)
    return (r <= g["R"]) & (r >= g["R"] - g["L"]) & (frac < g["duty"])


def render_grating(width: int, height: int, centre_px: tuple[float, float], radius_px: float, period_px: float,
                   phase_rad: float = 0.0, duty: float = 0.5, line_length_px: float = 1800.0,
                   glass: float = 200.0, chrome: float = 30.0, ss_end: int = 64, ss_side: int = 6,
                   blur_px: float = 0.0, noise: float = 0.0, seed: int | None = None,
                   to_uint8: bool = False) -> np.ndarray:
    """Grey image of a radial grating; ``period_px`` is the line period at the edge radius."""
    g = {"cx": float(centre_px[0]), "cy": float(centre_px[1]), "R": float(radius_px), "L": float(line_length_px),
         "pitch_rad": period_px / radius_px, "phase_rad": float(phase_rad), "duty": float(duty)}
    xs = np.arange(width + 1) - 0.5
    ys = np.arange(height + 1) - 0.5
    corners = _chrome(xs[None, :], ys[:, None], g)
    c00, c01, c10, c11 = corners[:-1, :-1], corners[:-1, 1:], corners[1:, :-1], corners[1:, 1:]
    mixed = (c00 != c01) | (c00 != c10) | (c00 != c11)
    # neighbours of a mixed pixel are mixed too (an edge corner may poke into a pixel between corners)
    m = mixed.copy()
    m[1:, :] |= mixed[:-1, :]
    m[:-1, :] |= mixed[1:, :]
    m[:, 1:] |= mixed[:, :-1] | m[:, 1:]
    m2 = m.copy()
    m2[:, :-1] |= m[:, 1:]
    mixed = m2
    cover = c00.astype(float)
    py, px = np.nonzero(mixed)
    rc = np.hypot(px - g["cx"], py - g["cy"])
    near_end = np.abs(rc - g["R"]) < 3.0
    for sel, s in ((near_end, ss_end), (~near_end, ss_side)):
        off = (np.arange(s) + 0.5) / s - 0.5
        ox, oy = np.meshgrid(off, off)
        ox, oy = ox.ravel(), oy.ravel()
        idx = np.flatnonzero(sel)
        chunk = max(1, 2_000_000 // (s * s))
        for k in range(0, idx.size, chunk):
            j = idx[k:k + chunk]
            X = px[j][:, None] + ox[None, :]
            Y = py[j][:, None] + oy[None, :]
            cover[py[j], px[j]] = _chrome(X, Y, g).mean(axis=1)
    img = glass + (chrome - glass) * cover
    if blur_px > 0:
        import cv2

        img = cv2.GaussianBlur(img, (0, 0), blur_px, borderType=cv2.BORDER_REPLICATE)
    if noise > 0:
        img = img + np.random.default_rng(seed).normal(0.0, noise, img.shape)
    if to_uint8:
        img = np.clip(np.round(img), 0, 255).astype(np.uint8)
    return img


def lab_to_image_centre(t_deg: float, e_um: float, theta0_deg: float, R_ref_um: float, um_per_px: float,
                        reference_px: tuple[float, float], camera_azimuth_deg: float = 180.0,
                        tangential_sign: float = +1.0) -> tuple[float, float]:
    """Disk centre in image px for a camera at ψ, following docs/conventions.md.

    Disk centre in the lab: e at polar angle 90° − θ0 + t. Camera radial unit u at polar 90° + ψ,
    reference point R_ref·u; image +x = u, image +y = tangential_sign · (ẑ × u) = tangential_sign ·
    (u rotated by +90°), which for ψ = 180° (u = −Y) is lab +X (``ccd.tangential = "+x"``), as in
    docs/conventions.md and the twin's camera (``CcdCamera.axes_lab``).
    """
    a = math.radians(90.0 - theta0_deg + t_deg)
    c = np.array([e_um * math.cos(a), e_um * math.sin(a)])
    psi = math.radians(90.0 + camera_azimuth_deg)
    u = np.array([math.cos(psi), math.sin(psi)])
    v = tangential_sign * np.array([-u[1], u[0]])  # ẑ × u
    rel = c - R_ref_um * u
    return (reference_px[0] + float(rel @ u) / um_per_px, reference_px[1] + float(rel @ v) / um_per_px)
