"""Whole-frame statistics of an integer CCD frame from its histogram of levels, with no float copy.

Jia et al., Appl. Sci. 9 (2019) 3415, sec. 4.2.1 thresholds each greyscale image (a histogram
threshold: Otsu's here, analysis/eccentricity.py) before labelling its connected parts. The
dataset's frames are 8- or 16-bit integers (docs/dataset-format.md). analysis/eccentricity.py takes
its whole-frame statistics (frame checks, percentiles, Otsu's threshold, the binary image) from a
float copy of the frame: 25 MB for 2048×1536 and a pass over it per statistic (issue #17: ~25 ms
of a frame's ~100). Each of these statistics depends only on the frame's levels, so here each is
taken from a histogram of the integer levels instead, giving the float path's values bit for bit
(tests/analysis/test_frame_levels.py compares the two on frames and random arrays):

- saturated / black fractions: the counts of the top level and of level 0 (for integer levels,
  ``grey >= full − 0.5`` is ``grey == full`` and ``grey <= 0.5`` is ``grey == 0``);
- percentiles (numpy's default, linear, method, Hyndman & Fan type 7): the two order statistics
  around the virtual index ``(n − 1)·q`` read from the cumulative histogram, interpolated by
  ``np.quantile`` of those two values at the same fraction (so by numpy's own formula);
- Otsu's histogram: numpy's uniform-bin histogram puts each value in its bin on its own, so the
  histogram of the values equals that of the distinct levels weighted by their counts;
- the binary image: for an integer level ``g`` and a float threshold ``t``, ``g < t`` is
  ``g <= ceil(t) − 1`` and ``g > t`` is ``g > floor(t)``: an integer comparison (``cv2.threshold``,
  which compares 8/16-bit images with ``floor`` of its threshold, multi-threaded).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["integer_frame", "level_counts", "percentiles_from_counts", "binary_below", "binary_above"]

#: integer frame types analysed in their own levels (the dataset's: docs/dataset-format.md)
INTEGER_TYPES = (np.uint8, np.uint16)


def integer_frame(image: np.ndarray) -> np.ndarray | None:
    """The frame itself if it is a 2-D 8- or 16-bit unsigned image, else None (colour, float and
    other integer frames take the float path of analysis/eccentricity.py)."""
    img = np.asarray(image)
    if img.ndim == 2 and img.dtype in INTEGER_TYPES:
        return img
    return None


def level_counts(levels: np.ndarray, full: int) -> np.ndarray:
    """Histogram (int64) of the integer ``levels`` over 0…``full``, one bin per level."""
    import cv2

    a = np.ascontiguousarray(levels)
    if a.size < 2**24:  # cv2's float32 counts are exact below 2^24 per bin; it is ~2× np.bincount's speed
        h = cv2.calcHist([a], [0], None, [full + 1], [0, full + 1])
        return np.rint(h.ravel()).astype(np.int64)
    return np.bincount(a.ravel(), minlength=full + 1).astype(np.int64)


def percentiles_from_counts(counts: np.ndarray, q: tuple[float, ...]) -> np.ndarray:
    """``np.percentile(values, q)`` (linear method) of the values whose level histogram is ``counts``.

    numpy: virtual index ``v = (n − 1)·q/100``, ``i = floor(v)``, ``γ = v − i``, then its linear
    interpolation between the i-th and (i+1)-th smallest values (the (n−1)-th above the top). The
    order statistics come from the cumulative counts; the interpolation is ``np.quantile`` of the two
    values at γ, whose virtual index is 1·γ = γ exactly, so its arithmetic is numpy's own."""
    n = int(counts.sum())
    if n == 0:
        raise ValueError("percentiles of an empty histogram")
    cum = np.cumsum(counts)
    v = (n - 1) * (np.asarray(q, dtype=float) / 100)
    out = np.empty(v.shape)
    for j, vj in enumerate(v):
        i = int(math.floor(vj))
        if vj >= n - 1:  # numpy takes the largest value
            out[j] = float(np.searchsorted(cum, n - 1, side="right"))
            continue
        a = float(np.searchsorted(cum, i, side="right"))      # the i-th smallest (0-based) level
        b = float(np.searchsorted(cum, i + 1, side="right"))
        out[j] = np.quantile(np.array([a, b]), vj - i)
    return out


def binary_below(levels: np.ndarray, t: float) -> np.ndarray:
    """``(levels < t)`` as uint8 0/1 for integer ``levels``: ``levels <= ceil(t) − 1``."""
    import cv2

    k = math.ceil(t) - 1
    if k < 0:
        return np.zeros(levels.shape, np.uint8)
    # THRESH_BINARY_INV: 1 where level <= k (cv2 compares integer images with floor(k) = k)
    return cv2.threshold(levels, float(k), 1, cv2.THRESH_BINARY_INV)[1].astype(np.uint8, copy=False)


def binary_above(levels: np.ndarray, t: float) -> np.ndarray:
    """``(levels > t)`` as uint8 0/1 for integer ``levels``: ``levels > floor(t)``."""
    import cv2

    k = math.floor(t)
    if k < 0:
        return np.ones(levels.shape, np.uint8)
    return cv2.threshold(levels, float(k), 1, cv2.THRESH_BINARY)[1].astype(np.uint8, copy=False)
