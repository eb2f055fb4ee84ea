"""Eccentricity of the grating disk from CCD images of the scale edge (Jia 2019, sec. 4.2).

Jia et al., Appl. Sci. 9 (2019) 3415, sec. 4.2.1-4.2.2, eqs. 10-13:

- per image: greyscale → histogram threshold → binary → inverted → connected parts → remove small
  parts (dust) → middle point of the outer ("right") edge of each line → least-squares circle
  (centre O_p, radius r_fitting) → ``l = |O_p − R|`` with R the reference point (image centre,
  (1024, 768) for 2048×1536) → ``d_ref = l − r_fitting`` (px);
- pixel scale from the grating period (eq. 13): 3 periods counted over m_p = 90 px → 0.667 µm/px;
- over the sweep (60 images every 6°): ``d_ref(θ) = c0 + Σ (c_i sin iθ + d_i cos iθ)`` (eq. 10,
  order 10), ``e = sqrt(c1² + d1²)`` (eq. 11), ``θ0 = atan2(c1, d1)`` (eq. 12, all quadrants).

Conventions (docs/conventions.md): image +x points radially outward, pixel (x, y) = (column, row)
with the origin at the centre of the top-left pixel. For a camera at 180° from the head,
``d_ref(θ) = const + e·cos(θ − θ0)``. For a camera at azimuth ψ (counter-clockwise from the head)
the radial unit vector at the camera is at lab polar angle 90° + ψ and the disk centre at
90° − θ0 + θ, so ``d_ref = const − e·cos(θ − θ0 − ψ) = const + e·cos(θ − (θ0 + ψ − 180°))``: the
fitted phase is θ0 + (ψ − 180°), and the analysis rotates it back, ``θ0 = atan2(c1, d1) − (ψ − 180°)``.

Choices where the paper is silent (each is a parameter):

- threshold: Otsu on a 256-bin histogram (works for 8/16-bit and float images);
- polarity ("the value of the binary image is reversed"): the lines are the class that splits into
  many separate parts; the other class (gaps + glass beyond the edge) is one connected region.
  Reported as ``"dark"`` (chrome on bright glass, transmitted light) or ``"bright"``;
- parts that are not elongated along x (bounding-box width < 2 × mean thickness area/width) and
  parts whose area is below ``min_area_frac`` (0.3) × the median line area are dust; parts touching
  the top, bottom or right image border are dropped (their end, or their width, is cut);
  a part touching the left border (the inner end of the line, outside the view) is kept;
- contaminated line ends are outliers, not failures: a part's end rows (those reaching its
  outermost columns) are split into runs of consecutive rows, one per line end, so two lines
  bridged by a dust speck further inside still give two clean ends; an end whose height is outside
  0.5…1.5 × the median (a speck on the end, two ends merged at the end) is rejected, and so is a
  line end further than max(5 robust σ, 0.05 px) from the fitted circle (one at a time). The
  image fails only if fewer than ``MIN_LINES`` (5) ends remain;
- sub-pixel edge: the binary edge is only the start. Along each fully covered row of a line the
  50 % point between the line's level and the glass level is located by the area (zeroth-moment)
  method, ``x_e = x_a − ½ + Σ f_i`` with ``f_i = (G − I_i)/(G − C)`` the chrome fraction over a
  window across the edge: exact for a pixel-integrated step and for any symmetric blur, where
  linear interpolation between the two samples around 50 % is biased by up to ~0.1 px
  (``edge_method="crossing"`` gives that variant). ``x_e(y)`` is fitted by a straight line over the
  rows and taken at the line's centre row ``y_m``, the centroid of the chrome fraction across the
  line just inside its end;
- circle: algebraic fit (Kasa, on centred and scaled coordinates) as the start, then a geometric
  Levenberg-Marquardt fit (scipy ``least_squares``); covariance ``s²(JᵀJ)⁻¹`` from the residuals
  (or a given ``u_px``). With a known radius only the centre is fitted. ``d_ref``'s uncertainty
  uses the full covariance (l and r are strongly correlated on a short arc; d_ref is not);
- pixel scale: the paper's count (pixels over three periods, integer, along a column near the edge)
  and a better one: a robust linear fit of the positions of the line ends along the edge circle
  against their index (lines are radial, their spacing grows with radius; measured on the edge
  circle itself it is the period at the edge radius). Indices come from the majority of regular
  spacings; line ends off the integer grid (a point between two lines, a speck shifting a centre
  along the edge) or off the fitted line are rejected (``rejected_spacing_px``), missing lines are
  allowed; fewer than a majority of the ends (or < ``MIN_LINES``) on a regular pitch is an
  ImageAnalysisError, never a silent scale;
- grating period convention: ``period_um`` is the period AT THE SCALE EDGE RADIUS (the radius of
  the line ends the camera sees; Jia sec. 4.2.2 "grating period is 20 µm"). The twin draws
  ``N = round(2π·R_edge/period)`` lines, i.e. the same convention: its true period at the edge is
  2π·R_edge/N, within 1/(2N) relative of the nominal (jia2019: N = 7069, 19.99883 µm, −5.9e-5:
  pixel scale 0.667030 instead of 0.667 µm/px, 4e-4 µm on e = 7.1 µm, negligible). A period given
  at another radius (e.g. the optical radius of the reading head) must be referred to the edge
  with ``period_radius_um``/``edge_radius_um`` (×R_edge/R): using it unscaled would scale every
  length by R_head/R_edge (−2.2 % for jia2019's 22 mm vs 22.5 mm).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchtwin.analysis.fourier import FourierFit, amplitude_phase, fit_fourier
from benchtwin.analysis.frame_levels import (binary_above, binary_below, integer_frame, level_counts,
                                             percentiles_from_counts)

__all__ = [
    "ImageAnalysisError",
    "ImageOptions",
    "CcdSweep",
    "LineEdges",
    "to_grey",
    "otsu_threshold",
    "segment_lines",
    "edge_points",
    "edge_details",
    "fit_circle",
    "d_ref_px",
    "pixel_scale_um",
    "eccentricity_from_dref",
    "eccentricity_from_sweep",
    "median_u",
    "with_async_motion",
    "eccentricity_monte_carlo",
    "eccentricity_range_method",
    "eccentricity_from_sweeps",
    "eccentricity_from_images",
    "frame_edges_and_scale",
]

MIN_LINES = 5


@dataclass(frozen=True)
class ImageOptions:
    """How a CCD frame is read (module docstring), one object for every image function.

    ``half_window_px``: the sub-pixel edge window's half width (px); ``edge_method``: ``"area"`` or
    ``"crossing"``; ``min_area_frac``: parts below this fraction of the median line area are dust;
    ``min_lines``: the fewest usable line ends; ``reject_outliers``: contaminated line ends are
    rejected (else they fail the frame); ``u_px``: the edge points' standard uncertainty for the
    circle fit (px; None: from its residuals); ``count_periods``: the periods counted along a column
    for the paper's pixel scale (eq. 13).
    """

    half_window_px: int = 6
    edge_method: str = "area"
    min_area_frac: float = 0.3
    min_lines: int = MIN_LINES
    reject_outliers: bool = True
    u_px: float | None = None
    count_periods: int = 3


@dataclass(frozen=True)
class CcdSweep:
    """What a sweep's eccentricity needs besides its images: the pixel scale (``um_per_px``, or the
    grating ``period_um`` at the edge radius to measure it), the reference point R (px; None: the
    image centre), the camera's azimuth (deg), the Fourier order of eq. 11 and a known edge radius
    (px; None: fitted)."""

    period_um: float | None = None
    um_per_px: float | None = None
    reference_px: Sequence[float] | None = None
    camera_azimuth_deg: float = 180.0
    order: int = 10
    radius_px: float | None = None


class ImageAnalysisError(ValueError):
    """An image the pipeline cannot analyse; the message names the image and what was expected."""


def _where(name: str | int | None) -> str:
    if name is None:
        return "image"
    if isinstance(name, (int, np.integer)):
        return f"image #{int(name)}"
    return f"image {name!r}"


# --------------------------------------------------------------------------- greyscale, threshold


def to_grey(image: np.ndarray, name: str | int | None = None) -> tuple[np.ndarray, float]:
    """Greyscale float image and its full-scale value (255 / 65535 for integer images; for float
    images 1, 255 or 65535, whichever is the smallest not below the maximum).

    Colour images (H×W×3, BGR as OpenCV reads them, or H×W×4) are converted with the ITU-R 601
    weights. Raises ImageAnalysisError for anything that is not a 2-D image.
    """
    img = np.asarray(image)
    _check_shape(img, name)
    if img.ndim == 3:
        b, g, r = (img[..., i].astype(float) for i in range(3))
        grey = 0.114 * b + 0.587 * g + 0.299 * r
    else:
        grey = img.astype(float)
    if np.issubdtype(img.dtype, np.integer):
        full = float(np.iinfo(img.dtype).max)
    else:
        if not np.all(np.isfinite(grey)):
            raise ImageAnalysisError(f"{_where(name)}: non-finite pixel values")
        mx = float(grey.max())
        # float images: assume the nearest usual full scale (1, 8-bit or 16-bit range)
        full = 1.0 if mx <= 1.0 else 255.0 if mx <= 255.0 else 65535.0 if mx <= 65535.0 else mx
    return grey, full


def _check_shape(img: np.ndarray, name: str | int | None) -> None:
    """ImageAnalysisError unless ``img`` is a 2-D or H×W×3/4 image of at least 20×20 px."""
    if not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] in (3, 4))):
        raise ImageAnalysisError(f"{_where(name)}: expected a 2-D greyscale or H×W×3 colour image, got shape {img.shape}")
    if img.shape[0] < 20 or img.shape[1] < 20:
        raise ImageAnalysisError(f"{_where(name)}: image {img.shape[1]}×{img.shape[0]} px is too small (need ≥ 20×20)")


def to_grey_column(image: np.ndarray, col: int) -> np.ndarray:
    """Column ``col`` of :func:`to_grey` of ``image`` (the same per-pixel formula), without
    converting the rest of the frame."""
    img = np.asarray(image)
    if img.ndim == 3:
        b, g, r = (img[:, col, i].astype(float) for i in range(3))
        return 0.114 * b + 0.587 * g + 0.299 * r
    return img[:, col].astype(float)


def check_frame(grey: np.ndarray, full_scale: float, name: str | int | None = None,
                min_contrast: float = 0.08, max_saturated: float = 0.5) -> None:
    """Blank / saturated frame check. Raises ImageAnalysisError when the 1-99 % percentile spread is
    below ``min_contrast`` × full scale (uniform frame: no grating), or when more than
    ``max_saturated`` of the pixels sit at full scale (or at zero: a black frame)."""
    n = grey.size
    sat = np.count_nonzero(grey >= full_scale - 0.5) / n
    black = np.count_nonzero(grey <= 0.5) / n if full_scale > 1.5 else 0.0
    _judge_frame(sat, black, lambda: np.percentile(_sample(grey), [1, 99]), full_scale, name, min_contrast,
                 max_saturated)


def _check_integer_frame(levels: np.ndarray, full_scale: int, sample_counts: np.ndarray,
                         name: str | int | None = None, min_contrast: float = 0.08, max_saturated: float = 0.5) -> None:
    """:func:`check_frame` of an 8/16-bit frame from its levels (analysis/frame_levels.py: the same
    fractions and percentiles, bit for bit, without a float copy). ``sample_counts``: the level
    histogram of :func:`_sample` of the frame."""
    n = levels.size
    sat = np.count_nonzero(levels == full_scale) / n
    black = np.count_nonzero(levels == 0) / n
    _judge_frame(sat, black, lambda: percentiles_from_counts(sample_counts, (1, 99)), float(full_scale), name,
                 min_contrast, max_saturated)


def _judge_frame(sat: float, black: float, p1_p99, full_scale: float, name: str | int | None,
                 min_contrast: float, max_saturated: float) -> None:
    """The verdict of :func:`check_frame` from the saturated and black fractions and the 1/99 %
    percentiles of the sample (``p1_p99()``, computed only when the fractions pass)."""
    if sat > max_saturated:
        raise ImageAnalysisError(f"{_where(name)}: saturated frame ({sat:.0%} of the pixels at full scale "
                                 f"{full_scale:g}); expected grating lines on glass below saturation")
    if black > max_saturated:
        raise ImageAnalysisError(f"{_where(name)}: black frame ({black:.0%} of the pixels at 0); "
                                 "expected an exposed image of the grating")
    p1, p99 = p1_p99()
    if p99 - p1 < min_contrast * full_scale:
        raise ImageAnalysisError(f"{_where(name)}: blank frame, no grating visible (grey levels {p1:.1f}…{p99:.1f}, spread < "
                                 f"{min_contrast:.0%} of full scale {full_scale:g}); expected grating lines")


def _sample(grey: np.ndarray) -> np.ndarray:
    """Every second row and column of a frame above 1 Mpx (histograms and percentiles: the same
    statistics at a quarter of the cost); smaller frames whole."""
    return grey[::2, ::2] if grey.size > 1_000_000 else grey


def otsu_threshold(grey: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold (maximum between-class variance) on a ``bins``-bin histogram (of every
    second row and column above 1 Mpx). An 8/16-bit frame is taken in its levels
    (:func:`_otsu_from_counts`, the same threshold)."""
    levels = integer_frame(grey)
    if levels is not None:
        return _otsu_from_counts(level_counts(_sample(levels), int(np.iinfo(levels.dtype).max)), bins)
    grey = _sample(grey)
    lo, hi = float(grey.min()), float(grey.max())
    if hi <= lo:
        return lo
    hist, edges = np.histogram(grey, bins=bins, range=(lo, hi))
    return _otsu_from_hist(hist, edges)


def _otsu_from_counts(counts: np.ndarray, bins: int = 256) -> float:
    """:func:`otsu_threshold` from the level histogram of the sample: numpy's histogram of the
    distinct levels weighted by their counts is that of the values (each value is binned on its own;
    analysis/frame_levels.py), the same histogram, so the same threshold."""
    lv = np.flatnonzero(counts)
    lo, hi = float(lv[0]), float(lv[-1])
    if hi <= lo:
        return lo
    hist, edges = np.histogram(lv.astype(float), bins=bins, range=(lo, hi), weights=counts[lv])
    return _otsu_from_hist(hist, edges)


def _otsu_from_hist(hist: np.ndarray, edges: np.ndarray) -> float:
    """The threshold (an upper bin edge) maximising Otsu's between-class variance of ``hist``."""
    p = hist.astype(float) / hist.sum()
    centres = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(p)
    m = np.cumsum(p * centres)
    mt = m[-1]
    w1 = 1.0 - w0
    with np.errstate(divide="ignore", invalid="ignore"):
        between = (mt * w0 - m) ** 2 / (w0 * w1)
    between[~np.isfinite(between)] = -1.0
    k = int(np.argmax(between))
    return float(edges[k + 1])


# --------------------------------------------------------------------------- segmentation


@dataclass(frozen=True)
class Segmentation:
    labels: np.ndarray       # int32 label image of the chosen polarity
    stats: np.ndarray        # cv2 stats (x, y, w, h, area) per label
    lines: np.ndarray        # labels kept as graduation lines
    polarity: str            # "dark" or "bright"
    threshold: float
    removed_dust: int
    removed_border: int


POLARITIES = ("dark", "bright")


def _big_parts(binary: np.ndarray, min_area_px: int, at_most: int | None = None) -> int:
    """Number of 8-connected parts of ≥ ``min_area_px`` pixels: labels only (``connectedComponents``
    + a histogram of the labels, ~half the cost of ``connectedComponentsWithStats``); the parts, and
    so the count, are those the stats would give (a partition into connected parts is unique).

    ``at_most``: the caller only needs to know whether the count exceeds it; when the number of
    parts of any size does not (the glass class of a frame is a handful of parts), that number is
    returned without the histogram: it bounds the count from above, so the comparison is the same."""
    import cv2

    n, lab = cv2.connectedComponents(binary, connectivity=8)
    if at_most is not None and n - 1 <= at_most:
        return n - 1
    return int(np.count_nonzero(np.bincount(lab.ravel(), minlength=n)[1:] >= min_area_px))


#: above this many parts their areas come from one histogram of the label image, below from a
#: count inside each part's bounding box (cheaper while the boxes are few)
_BOX_COUNT_MAX_PARTS = 1000


def _labelled(binary: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """8-connected labels of ``binary`` and their statistics (rows as cv2's CC_STAT_LEFT, TOP, WIDTH,
    HEIGHT, AREA; row 0 the background), as ``cv2.connectedComponentsWithStats`` gives them.

    Why not that call: its statistics cost ~4× the labelling itself (it also sums every pixel's
    coordinates for the centroids, which are not used here). The same labels (the same
    ``connectedComponents`` algorithm: label images equal) and the bounding boxes of
    ``scipy.ndimage.find_objects`` (one pass), the areas counted inside each box, give the same
    table; the degenerate case of no background pixels, or no parts, is left to cv2."""
    import cv2
    from scipy import ndimage

    n, lab = cv2.connectedComponents(binary, connectivity=8)
    boxes = ndimage.find_objects(lab)
    H, W = binary.shape
    st = np.empty((n, 5), np.int32)
    for i, (sy, sx) in enumerate(boxes, start=1):
        st[i, :4] = (sx.start, sy.start, sx.stop - sx.start, sy.stop - sy.start)
    if n - 1 <= _BOX_COUNT_MAX_PARTS:
        for i, (sy, sx) in enumerate(boxes, start=1):
            st[i, 4] = np.count_nonzero(lab[sy, sx] == i)
    else:
        st[1:, 4] = np.bincount(lab.ravel(), minlength=n)[1:]
    bg_area = H * W - int(st[1:, 4].sum())
    if n < 2 or bg_area == 0:
        _n, lab_cv, st_cv, _ = cv2.connectedComponentsWithStats(binary, connectivity=8)
        return lab_cv, st_cv
    # the background's box: the rows and columns holding a background pixel
    x, y, w, h = cv2.boundingRect((binary == 0).view(np.uint8))
    st[0] = (x, y, w, h, bg_area)
    return lab, st


def segment_lines(grey: np.ndarray, name: str | int | None = None, min_area_frac: float = 0.3,
                  min_area_px: int = 20, expect_polarity: str | None = None,
                  threshold: float | None = None) -> Segmentation:
    """Threshold (Otsu), choose the polarity, label parts, drop dust and border-cut parts.

    The lines are the class with more parts of ≥ ``min_area_px`` (dark on a tie; module docstring),
    decided in every frame. Only the chosen class needs its parts' statistics: the expected class
    (``expect_polarity``, the sweep's so far; default dark) is labelled with statistics and the
    other one only counted (:func:`_big_parts`); the other is labelled with statistics only when it
    wins. The choice is the same whatever is expected — the hint only orders the work (one full
    labelling pass and a count per frame instead of two full passes).

    ``grey``: a float greyscale image, or an 8/16-bit frame itself (compared in its integer levels,
    analysis/frame_levels.py: the same binary images). ``threshold``: Otsu's threshold of ``grey``
    when the caller already has it (:func:`edge_details` takes it from the frame check's histogram)."""
    import cv2

    if expect_polarity is not None and expect_polarity not in POLARITIES:
        raise ValueError(f"expect_polarity must be one of {POLARITIES} or None, got {expect_polarity!r}")
    t = otsu_threshold(grey) if threshold is None else float(threshold)
    levels = integer_frame(grey)

    def binary(pol: str) -> np.ndarray:
        if levels is not None:
            return binary_below(levels, t) if pol == "dark" else binary_above(levels, t)
        return (grey < t if pol == "dark" else grey > t).astype(np.uint8)

    def labelled(pol: str) -> tuple[np.ndarray, np.ndarray]:
        return _labelled(binary(pol))

    first = expect_polarity or "dark"
    other = "bright" if first == "dark" else "dark"
    labels, stats = labelled(first)
    big_first = int(np.count_nonzero(stats[1:, cv2.CC_STAT_AREA] >= min_area_px))
    # the other class wins with more big parts (dark first) or as many (bright first, dark wins ties):
    # beyond big_first (resp. big_first − 1) big parts its exact count does not matter
    big_other = _big_parts(binary(other), min_area_px, at_most=big_first if first == "dark" else big_first - 1)
    # dark wins a tie (the rule's order: dark, then bright only if it has more parts)
    take_other = big_other > big_first if first == "dark" else big_other >= big_first
    pol = other if take_other else first
    if take_other:
        labels, stats = labelled(other)
    H, W = grey.shape
    ids = np.arange(1, stats.shape[0])
    areas = stats[1:, cv2.CC_STAT_AREA]
    cand = ids[areas >= min_area_px]
    if cand.size == 0:
        raise ImageAnalysisError(f"{_where(name)}: no grating found (no connected parts ≥ {min_area_px} px after "
                                 f"thresholding at {t:.1f}); expected ≥ {MIN_LINES} graduation lines")
    # line-like: longer (radially, along x) than twice the mean thickness area/width; dust is not
    wid = stats[cand, cv2.CC_STAT_WIDTH].astype(float)
    cand = cand[wid >= 2.0 * stats[cand, cv2.CC_STAT_AREA] / wid]
    if cand.size == 0:
        raise ImageAnalysisError(f"{_where(name)}: no grating found (no elongated parts after thresholding at "
                                 f"{t:.1f}); expected ≥ {MIN_LINES} radial graduation lines along image x")
    med = float(np.median(stats[cand, cv2.CC_STAT_AREA]))
    keep = cand[stats[cand, cv2.CC_STAT_AREA] >= min_area_frac * med]
    n_dust = int(ids.size - keep.size)
    x, y, w, h = (stats[keep, i] for i in (cv2.CC_STAT_LEFT, cv2.CC_STAT_TOP, cv2.CC_STAT_WIDTH, cv2.CC_STAT_HEIGHT))
    border = (y <= 0) | (y + h >= H) | (x + w >= W)
    lines = keep[~border]
    return Segmentation(labels, stats, lines, pol, t, n_dust, int(np.count_nonzero(border)))


# --------------------------------------------------------------------------- edge points


def _median(a: np.ndarray) -> np.ndarray:
    """``np.median(a, axis=-1)`` of a small float array, bit for bit, at a tenth of its cost (its
    dispatch costs ~40 µs a call, and a frame's line ends take ~350 medians): the middle of the sorted
    values, or the two middle ones added and halved, which is np.median's mean of them. With a NaN in
    ``a`` (sorted last) np.median itself decides."""
    s = np.sort(a, axis=-1)
    n = s.shape[-1]
    if n == 0 or np.isnan(s[..., -1]).any():
        return np.median(a, axis=-1)
    h = n // 2
    # np.median's mean starts its sum at +0.0 (so a −0.0 median comes out +0.0)
    out = 0.0 + s[..., h] if n % 2 else (0.0 + s[..., h - 1] + s[..., h]) / 2
    return out[()]  # a 1-D array's median as a numpy scalar, as np.median gives it


@dataclass(frozen=True)
class LineEdges:
    """Per-line results of :func:`edge_details` (one row per kept line, sorted by y).

    ``points_px``: (N, 2) middle points of the outer edge (x, y); ``centre_col_px``: the column
    (mean) where the line centre ``points_px[:, 1]`` was measured; ``rows_used``: rows per line;
    ``edge_scatter_px``: RMS of the row edges about their straight-line fit (per line).
    """

    points_px: np.ndarray
    centre_col_px: np.ndarray
    rows_used: np.ndarray
    edge_scatter_px: np.ndarray
    polarity: str
    threshold: float
    glass_level: np.ndarray
    line_level: np.ndarray
    removed_dust: int
    removed_border: int
    rejected_ends_px: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))


def _frame_levels(image: np.ndarray, name: str | int | None) -> tuple[np.ndarray, float | None]:
    """The frame to segment and Otsu's threshold when it is known already (None: segment_lines finds it).

    An 8/16-bit frame is analysed in its own levels: no float copy of the whole frame; its check and
    Otsu's threshold from one histogram of the sample (analysis/frame_levels.py), and only the few
    pixels around each line end are taken as float later. Other frames: grey, checked."""
    levels = integer_frame(image)
    if levels is not None:
        _check_shape(levels, name)
        full = int(np.iinfo(levels.dtype).max)
        counts = level_counts(_sample(levels), full)
        _check_integer_frame(levels, full, counts, name)
        return levels, _otsu_from_counts(counts)
    grey, full_f = to_grey(image, name)
    check_frame(grey, full_f, name)
    return grey, None


def _px(grey: np.ndarray, rows: Any, cols: Any) -> np.ndarray:
    """grey[rows, cols] as float (the frame may be integer levels)."""
    return np.asarray(grey[rows, cols], dtype=float)


def _line_ends(seg: Segmentation, hw: int, lev: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Line ends: the rows where a part reaches its outermost columns, with the last line pixel per
    row. A part may hold several line ends (neighbouring lines bridged by dust or a scratch further
    inside the lines): the end rows are split into runs of consecutive rows, one run per line end."""
    ends = []
    for lab in seg.lines:
        x0, y0, w, h = (int(seg.stats[lab, i]) for i in range(4))
        # end region of the part: its last 2·hw + lev + 4 columns (lines are tilted by up to a few
        # degrees, so rows further left belong to the line's sides, not to its end)
        xr_ = x0 + w - 1
        xa_ = max(x0, xr_ - (2 * hw + lev + 4))
        sub = seg.labels[y0:y0 + h, xa_:xr_ + 1] == lab
        rows = np.flatnonzero(sub.any(axis=1))
        if rows.size < 3:
            continue
        xb = xa_ + (sub.shape[1] - 1 - np.argmax(sub[rows, ::-1], axis=1))  # last line pixel per row
        end_rows = xb >= xr_ - 3
        rows, xb = rows[end_rows], xb[end_rows]
        brk = np.flatnonzero(np.diff(rows) > 1) + 1
        for r_, x_ in zip(np.split(rows, brk), np.split(xb, brk)):
            ends.append((y0 + r_, x_))
    return ends


def _full_rows(grey: np.ndarray, ys: np.ndarray, xb: np.ndarray, hw: int,
               lev: int) -> tuple[float, np.ndarray, np.ndarray] | None:
    """The glass level G, the line level per row and the interior rows fully covered by the line (near-
    full contrast, never the first or last row of the end: a line side crosses those); None if too few."""
    y_lo, y_hi = int(ys.min()), int(ys.max())
    g_idx = xb[:, None] + hw + 1 + np.arange(lev)[None, :]
    c_idx = xb[:, None] - hw - 1 - np.arange(lev)[None, :]
    G_rows = _median(_px(grey, ys[:, None], g_idx))
    C_rows = _median(_px(grey, ys[:, None], c_idx))
    G = float(_median(G_rows))
    contrast = G - C_rows
    cmax = np.max(np.abs(contrast))
    if cmax <= 0:
        return None
    inner = (ys > y_lo) & (ys < y_hi)
    full_rows = inner & (np.abs(contrast) >= 0.95 * cmax)
    if np.count_nonzero(full_rows) < 3:
        full_rows = inner & (np.abs(contrast) >= 0.85 * cmax)
    if np.count_nonzero(full_rows) < 2:
        return None
    return G, C_rows, full_rows


def _row_edges(grey: np.ndarray, ys_f: np.ndarray, xb_f: np.ndarray, G: float, C_f: np.ndarray, hw: int,
               edge_method: str) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The sub-pixel edge of each full row from its chrome fraction (1 on the line, 0 on glass):
    ``area`` sums it, ``crossing`` interpolates its last 0.5 crossing. (rows, edges, line levels) of
    the rows with an edge; None when fewer than 2."""
    win = xb_f[:, None] + np.arange(-hw, hw + 1)[None, :]
    prof = _px(grey, ys_f[:, None], win)
    f = (G - prof) / (G - C_f)[:, None]  # chrome fraction, 1 on the line, 0 on glass
    if edge_method == "area":
        return ys_f, (xb_f - hw - 0.5) + f.sum(axis=1), C_f
    xe = np.empty(ys_f.size)
    for k in range(ys_f.size):
        fk = f[k]
        below = np.flatnonzero((fk[:-1] >= 0.5) & (fk[1:] < 0.5))
        if below.size == 0:
            xe[k] = np.nan
            continue
        i = below[-1]
        xe[k] = win[k, i] + (fk[i] - 0.5) / (fk[i] - fk[i + 1])
    good = np.isfinite(xe)
    ys_f, xe, C_f = ys_f[good], xe[good], C_f[good]
    if ys_f.size < 2:
        return None
    return ys_f, xe, C_f


def _centre_row(grey: np.ndarray, y_span: tuple[int, int], xe: np.ndarray, levels: tuple[float, float],
                hw: int, lev: int) -> tuple[float, np.ndarray] | None:
    """Centre row of the line end: centroid of the chrome fraction across the line, in columns just
    inside the end. (y, the columns used); None if there are none or a column has no chrome."""
    H, W = grey.shape
    y_lo, y_hi = y_span
    G, C = levels
    xe_med = float(_median(xe))
    cs = np.arange(int(round(xe_med)) - hw - lev, int(round(xe_med)) - hw)
    cs = cs[(cs >= 0) & (cs < W)]
    if cs.size == 0:
        return None
    ya, yb = max(y_lo - 4, 0), min(y_hi + 5, H)
    yy = np.arange(ya, yb)
    fc = (G - _px(grey, slice(ya, yb), cs)) / (G - C)
    wsum = fc.sum(axis=0)
    if np.any(wsum <= 0):
        return None
    return float(np.mean((fc * yy[:, None]).sum(axis=0) / wsum)), cs


def _edge_at(ys_f: np.ndarray, xe: np.ndarray, y_cent: float) -> tuple[float, float, int]:
    """The straight line through the row edges taken at the centre row, after a robust rejection of
    rows spoilt by dust or a scratch at the line end: (x, RMS scatter about the line, rows used)."""
    if ys_f.size >= 2 and np.ptp(ys_f) > 0:
        pf = np.polyfit(ys_f.astype(float), xe, 1)
        rr = xe - np.polyval(pf, ys_f)
        sig = 1.4826 * float(_median(np.abs(rr - _median(rr))))
        good = np.abs(rr) <= max(4.0 * sig, 0.25)
        if 3 <= np.count_nonzero(good) < good.size:
            ys_f, xe = ys_f[good], xe[good]
            pf = np.polyfit(ys_f.astype(float), xe, 1)
        x_mid = float(np.polyval(pf, y_cent))
        sc = float(np.sqrt(np.mean((xe - np.polyval(pf, ys_f)) ** 2)))
    else:
        x_mid, sc = float(np.mean(xe)), float("nan")
    return x_mid, sc, int(ys_f.size)


def _measure_end(grey: np.ndarray, ys: np.ndarray, xb: np.ndarray, hw: int, lev: int,
                 edge_method: str, threshold: float | None = None) -> tuple[float, ...] | None:
    """One line end measured: (x_mid, y_centre, centre column, rows used, scatter, glass level, line
    level), or None when it is not usable (too close to the border, too little contrast, ...)."""
    W = grey.shape[1]
    y_lo, y_hi = int(ys.min()), int(ys.max())
    ok = (xb - hw - lev >= 0) & (xb + hw + lev < W)
    if np.count_nonzero(ok) < 3:
        return None
    ys, xb = ys[ok], xb[ok]
    full = _full_rows(grey, ys, xb, hw, lev)
    if full is None:
        return None
    G, C_rows, full_rows = full
    edges = _row_edges(grey, ys[full_rows], xb[full_rows], G, C_rows[full_rows], hw, edge_method)
    if edges is None:
        return None
    ys_f, xe, C_f = edges
    C = float(_median(C_f))
    if threshold is not None and not abs(G - C) >= abs(G - threshold):
        # the segmentation took this end's pixels for line (beyond the frame's threshold), but the line
        # level measured lev pixels inside it is not: the part is narrower than the edge window (a
        # thin scratch, a speck), not a line end. Its chrome fraction would divide by G − C ≈ 0
        # (seed 660 of issue 32's validation: G = C = 177.25, a NaN point, the frame lost)
        return None
    centre = _centre_row(grey, (y_lo, y_hi), xe, (G, C), hw, lev)
    if centre is None:
        return None
    y_cent, cs = centre
    x_mid, sc, n_rows = _edge_at(ys_f, xe, y_cent)
    return x_mid, y_cent, float(np.mean(cs)), n_rows, sc, G, C


def edge_details(image: np.ndarray, name: str | int | None = None, options: ImageOptions | None = None,
                 expect_polarity: str | None = None) -> LineEdges:
    """Sub-pixel middle points of the outer edge of each graduation line, with details.

    See the module docstring for the method and :class:`ImageOptions` for ``options``. With
    ``reject_outliers`` line ends whose height (rows reaching the end) is outside 0.5…1.5 × the
    median are rejected as contaminated (``rejected_ends_px``). Raises ImageAnalysisError for blank,
    saturated or black frames, frames without a grating, and frames with fewer than ``min_lines``
    usable line ends.
    ``expect_polarity``: the polarity the lines probably have (the sweep's so far), which orders the
    labelling work only (:func:`segment_lines`: the choice is the frame's own either way).

    Stages: :func:`_frame_levels`, :func:`segment_lines`, :func:`_line_ends`, the height check, then
    per end :func:`_measure_end` (:func:`_full_rows`, :func:`_row_edges`, :func:`_centre_row`,
    :func:`_edge_at`).
    """
    opt = options if options is not None else ImageOptions()
    edge_method, min_lines, reject_outliers = opt.edge_method, opt.min_lines, opt.reject_outliers
    if edge_method not in ("area", "crossing"):
        raise ValueError(f"edge_method must be 'area' or 'crossing', got {edge_method!r}")
    grey, t = _frame_levels(image, name)
    seg = segment_lines(grey, name, opt.min_area_frac, expect_polarity=expect_polarity, threshold=t)
    hw = int(opt.half_window_px)
    lev = 6  # pixels used for each level, beyond the edge window
    ends = _line_ends(seg, hw, lev)
    # an end much shorter or taller than the typical line width is contaminated (a speck on the end,
    # two ends merged by dust at the end): an outlier, rejected (with ``reject_outliers``)
    heights = np.array([int(e[0][-1] - e[0][0] + 1) for e in ends])
    big = heights[heights >= 3]
    med_h = float(np.median(big)) if big.size else 0.0
    rejected, rows_out = [], []
    for ys, xb in ends:
        y_lo, y_hi = int(ys.min()), int(ys.max())
        if reject_outliers and not (0.5 * med_h <= y_hi - y_lo + 1 <= 1.5 * med_h):
            rejected.append((float(xb.max()), 0.5 * (y_lo + y_hi)))
            continue
        m = _measure_end(grey, ys, xb, hw, lev, edge_method, seg.threshold)
        # an end whose edge or centre row is not a finite number is not a measured point
        if m is not None and np.all(np.isfinite(m[:2])):
            rows_out.append(m)
    if len(rows_out) < min_lines:
        raise ImageAnalysisError(
            f"{_where(name)}: too few edge points: {len(rows_out)} usable line ends (need ≥ {min_lines}); "
            f"{seg.lines.size} parts kept as lines, {len(rejected)} contaminated line ends rejected, {seg.removed_dust} small parts (dust) and "
            f"{seg.removed_border} border-cut parts removed, threshold {seg.threshold:.1f}, "
            f"{seg.polarity} lines; expected radial graduation lines ending inside the field of view")
    pts = [(m[0], m[1]) for m in rows_out]
    cols, nrows, scat, glv, lnv = ([m[i] for m in rows_out] for i in range(2, 7))
    order = np.argsort([p[1] for p in pts])
    a = lambda v: np.asarray(v)[order]  # noqa: E731
    return LineEdges(np.asarray(pts, dtype=float)[order], a(cols), a(nrows), a(scat), seg.polarity,
                     seg.threshold, a(glv), a(lnv), seg.removed_dust, seg.removed_border,
                     np.asarray(rejected, dtype=float).reshape(-1, 2))


def edge_points(image: np.ndarray, name: str | int | None = None, options: ImageOptions | None = None) -> np.ndarray:
    """(N, 2) sub-pixel middle points (x, y) in px of the outer edge of each graduation line."""
    return edge_details(image, name, options).points_px


# --------------------------------------------------------------------------- circle fit


def _kasa(points: np.ndarray) -> tuple[float, float, float]:
    """Algebraic circle fit (Kasa) on centred, scaled coordinates."""
    m = points.mean(axis=0)
    q = points - m
    s = float(np.sqrt(np.mean(np.sum(q**2, axis=1)))) or 1.0
    q = q / s
    A = np.column_stack([q[:, 0], q[:, 1], np.ones(len(q))])
    bvec = np.sum(q**2, axis=1)
    sol, *_ = np.linalg.lstsq(A, bvec, rcond=None)
    a, b, c = sol
    cx, cy = a / 2, b / 2
    r = math.sqrt(max(c + cx**2 + cy**2, 0.0))
    return cx * s + m[0], cy * s + m[1], r * s


def fit_circle(points: np.ndarray, radius: float | None = None, u_px: float | None = None,
               start: tuple[float, float] | None = None) -> tuple[float, float, float, np.ndarray]:
    """Least-squares circle through ``points`` (N×2, px): returns (cx, cy, r, cov).

    Kasa's algebraic fit gives the start (or ``start`` = (cx, cy) for the centre), then a geometric
    Levenberg-Marquardt fit minimises Σ(|p_i − c| − r)². With ``radius`` given, only the centre is
    fitted and ``r = radius``; ``cov`` is 3×3 in (cx, cy, r) with zero row/column for r in that
    case. ``cov = s²(JᵀJ)⁻¹`` with ``s² = RSS/(N − p)``, or ``u_px²(JᵀJ)⁻¹`` if ``u_px`` is given.
    """
    from scipy.optimize import least_squares

    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2:
        raise ValueError(f"points must be N×2, got shape {P.shape}")
    npar = 2 if radius is not None else 3
    if P.shape[0] < npar + 1:
        raise ValueError(f"need at least {npar + 1} points for a circle fit, got {P.shape[0]}")
    cx0, cy0, r0 = _kasa(P)
    if start is not None:
        cx0, cy0 = start
    if radius is not None:
        # start: move the algebraic centre along its direction to the known radius
        m = P.mean(axis=0)
        d = np.array([cx0, cy0]) - m
        nd = float(np.hypot(*d)) or 1.0
        c = m + d / nd * radius
        cx0, cy0 = float(c[0]), float(c[1])
    # work relative to the data mean for conditioning
    m = P.mean(axis=0)
    Q = P - m

    if radius is None:
        def res(p):
            return np.hypot(Q[:, 0] - p[0], Q[:, 1] - p[1]) - p[2]

        def jac(p):
            d = np.hypot(Q[:, 0] - p[0], Q[:, 1] - p[1])
            return np.column_stack([-(Q[:, 0] - p[0]) / d, -(Q[:, 1] - p[1]) / d, -np.ones(len(Q))])

        x0 = np.array([cx0 - m[0], cy0 - m[1], r0])
    else:
        R = float(radius)

        def res(p):
            return np.hypot(Q[:, 0] - p[0], Q[:, 1] - p[1]) - R

        def jac(p):
            d = np.hypot(Q[:, 0] - p[0], Q[:, 1] - p[1])
            return np.column_stack([-(Q[:, 0] - p[0]) / d, -(Q[:, 1] - p[1]) / d])

        x0 = np.array([cx0 - m[0], cy0 - m[1]])
    sol = least_squares(res, x0, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
    p = sol.x
    J = jac(p)
    rr = res(p)
    dof = P.shape[0] - npar
    s2 = (u_px**2) if u_px is not None else (float(rr @ rr) / dof if dof > 0 else float("nan"))
    try:
        cov_p = np.linalg.inv(J.T @ J) * s2
    except np.linalg.LinAlgError:
        cov_p = np.full((npar, npar), np.nan)
    cov = np.zeros((3, 3))
    cov[:npar, :npar] = cov_p
    r = float(p[2]) if radius is None else float(radius)
    return float(p[0] + m[0]), float(p[1] + m[1]), r, cov


# --------------------------------------------------------------------------- d_ref and scale


def _dref_from_circle(cx: float, cy: float, r: float, cov: np.ndarray, reference_px: Sequence[float]) -> tuple[float, float, float]:
    xr, yr = float(reference_px[0]), float(reference_px[1])
    l = math.hypot(cx - xr, cy - yr)
    g = np.array([(cx - xr) / l, (cy - yr) / l, -1.0])
    var = float(g @ cov @ g)
    return l - r, math.sqrt(var) if var >= 0 else float("nan"), l


def d_ref_px(image: np.ndarray | None, reference_px: Sequence[float] | None = None, radius_px: float | None = None,
             name: str | int | None = None, edges: LineEdges | None = None, options: ImageOptions | None = None) -> dict:
    """Jia's d_ref = l − r_fitting (px) of one image: edge points → circle → distance to R.

    ``reference_px``: the reference point R (default: the image centre (W/2, H/2), (1024, 768) for
    2048×1536 as in the paper). ``radius_px``: known edge radius (circle fit with the radius fixed);
    otherwise the radius is fitted. After a first fit the line-centre points are moved along their
    radial line (through the fitted centre) from the column where the centre was measured to the
    edge, and the circle is refitted. With ``reject_outliers`` line ends further than
    max(5 robust σ, 0.05 px) from the circle are dropped one at a time (``rejected_points_px``).

    Keys: d_ref_px, u_d_ref_px, l_px, centre_px (cx, cy), radius_px, cov_circle (cx, cy, r),
    points_px, residual_rms_px, n_lines, polarity, reference_px, edges (LineEdges),
    rejected_points_px.

    ``options``: :class:`ImageOptions` (``u_px``, ``reject_outliers``, ``min_lines`` and the edge
    finding's). ``edges``: this image's :func:`edge_details` (found once per frame, with the same
    ``options``), so a caller that needs the edges for the pixel
    scale and for d_ref does not find them twice; by default they are found here. With ``edges``
    and ``reference_px`` given, ``image`` is not used (may be None).
    """
    opt = options if options is not None else ImageOptions()
    u_px, reject_outliers, min_lines = opt.u_px, opt.reject_outliers, opt.min_lines
    if edges is not None:
        ed = edges
    elif image is not None:
        ed = edge_details(image, name, opt)
    else:
        raise ValueError("d_ref_px: give the image or its edges")
    if reference_px is None:
        if image is None:
            raise ValueError("d_ref_px: give the image or the reference point reference_px")
        H, W = np.asarray(image).shape[:2]
        ref = (W / 2.0, H / 2.0)
    else:
        ref = (float(reference_px[0]), float(reference_px[1]))
    P = ed.points_px.copy()
    cols = ed.centre_col_px.copy()
    rejected = ed.rejected_ends_px.copy()  # contaminated ends rejected before the fit
    try:
        cx, cy, r, cov = fit_circle(P, radius_px, u_px)
        # y of the line centre was measured at column centre_col_px; follow the radial line to x_mid
        t = (P[:, 0] - cx) / (cols - cx)
        P[:, 1] = cy + (P[:, 1] - cy) * t
        cx, cy, r, cov = fit_circle(P, radius_px, u_px, start=(cx, cy))
        # one bad line end (dust on the end, a merged part) at a time: reject if > 5 robust σ
        while reject_outliers and P.shape[0] > max(min_lines, 5):
            res_ = np.hypot(P[:, 0] - cx, P[:, 1] - cy) - r
            sig = 1.4826 * float(np.median(np.abs(res_ - np.median(res_))))
            worst = int(np.argmax(np.abs(res_)))
            if abs(res_[worst]) <= max(5.0 * sig, 0.05):
                break
            rejected = np.vstack([rejected, P[worst]])
            P = np.delete(P, worst, axis=0)
            cx, cy, r, cov = fit_circle(P, radius_px, u_px, start=(cx, cy))
    except ValueError as exc:
        raise ImageAnalysisError(f"{_where(name)}: circle fit failed: {exc}") from None
    if cx > ref[0]:
        raise ImageAnalysisError(f"{_where(name)}: fitted disk centre ({cx:.1f}, {cy:.1f}) px lies on the outward "
                                 "side (+x) of the reference point; expected the disk centre at −x (image +x is "
                                 "radially outward), check the image orientation")
    d, ud, l = _dref_from_circle(cx, cy, r, cov, ref)
    resid = np.hypot(P[:, 0] - cx, P[:, 1] - cy) - r
    return {
        "d_ref_px": d, "u_d_ref_px": ud, "l_px": l, "centre_px": (cx, cy), "radius_px": r, "cov_circle": cov,
        "points_px": P, "residual_rms_px": float(np.sqrt(np.mean(resid**2))), "n_lines": int(P.shape[0]),
        "polarity": ed.polarity, "reference_px": ref, "edges": ed, "rejected_points_px": rejected,
    }


def _period_at_edge(period_um: float, period_radius_um: float | None, edge_radius_um: float | None) -> float:
    """The grating period at the edge radius (µm): ``period_um`` itself, or referred from the radius
    ``period_radius_um`` where it is specified to the edge radius."""
    if not period_um > 0:
        raise ValueError(f"period_um must be > 0, got {period_um}")
    p_edge = float(period_um)
    if period_radius_um is not None:
        if edge_radius_um is None:
            raise ValueError("period_radius_um given: edge_radius_um is needed to refer the period to the edge")
        p_edge = period_um * edge_radius_um / period_radius_um
    return p_edge


def _pitch_start(chords: np.ndarray) -> float:
    """Pitch start (px): the median chord, refined over the chords that are a whole number of pitches."""
    step = float(np.median(chords))
    k = np.round(chords / step)
    ok = (k >= 1) & (np.abs(chords / np.maximum(k, 1) - step) < 0.1 * step)
    if np.count_nonzero(ok) >= 2:
        step = float(np.median(chords[ok] / k[ok]))
    return step


@dataclass(frozen=True)
class _PitchFit:
    """The robust straight-line fit s = pitch·n + s0 of the line ends' positions along the edge."""

    inliers: np.ndarray    # the line ends used
    index: np.ndarray      # each end's integer index (float)
    A: np.ndarray          # the design matrix [n, 1] of the inliers
    sol: np.ndarray        # (pitch px, s0 px)


def _regular_pitch(s: np.ndarray, step: float, need: int, reject: bool, name: str | int | None,
                   chords: np.ndarray) -> _PitchFit:
    """Index of each line end: nearest integer to s/step after removing the common phase; then a
    robust straight-line fit s = pitch·n + s0 (outliers: > 0.2 pitch off the integer grid, or
    > max(5 robust σ, 0.05 px) off the line; one line end per index), iterated to a fixed point.
    ImageAnalysisError when fewer than ``need`` (a majority; all without ``reject``) remain."""
    n_pts = s.size
    ph = np.angle(np.mean(np.exp(2j * np.pi * s / step))) / (2 * np.pi)
    pitch, s0 = step, ph * step
    inl = np.ones(n_pts, bool)
    for it in range(10):
        u = (s - s0) / pitch
        idx = np.round(u)
        res_px = (u - idx) * pitch
        new_inl = np.abs(res_px) < 0.2 * pitch
        if it > 0 and np.count_nonzero(new_inl) >= 3:  # after the first fit: residuals about the line
            sig = 1.4826 * float(np.median(np.abs(res_px[new_inl] - np.median(res_px[new_inl]))))
            new_inl &= np.abs(res_px) <= max(5.0 * sig, 0.05)
        # two line ends on one index: keep the closer one
        for n_dup in np.unique(idx[new_inl]):
            same = np.flatnonzero(new_inl & (idx == n_dup))
            if same.size > 1:
                new_inl[same[np.argsort(np.abs(res_px[same]))[1:]]] = False
        n_in = int(np.count_nonzero(new_inl))
        if n_in < max(need, 3) or np.ptp(idx[new_inl]) < 2 or (not reject and n_in < n_pts):
            raise ImageAnalysisError(
                f"{_where(name)}: line spacing is irregular: only {n_in} of {n_pts} line ends lie on a regular "
                f"pitch (need ≥ {n_pts if not reject else max(need, 3)}"
                f"{', a majority' if reject else ', outlier rejection off'}); chords {np.round(chords, 1)} px")
        A = np.column_stack([idx[new_inl], np.ones(int(np.count_nonzero(new_inl)))])
        sol, *_ = np.linalg.lstsq(A, s[new_inl], rcond=None)
        done = np.array_equal(new_inl, inl) and abs(sol[0] - pitch) < 1e-9 * pitch
        inl, pitch, s0 = new_inl, float(sol[0]), float(sol[1])
        if done:
            break
    return _PitchFit(inl, idx, A, sol)


def _pitch_scatter(s: np.ndarray, fit: _PitchFit, name: str | int | None, chords: np.ndarray) -> tuple[float, float]:
    """(RMS of the used ends about the pitch line in px, u of the pitch in px); ImageAnalysisError when
    the scatter exceeds 1 % of the pitch (a grating's ends scatter by ~0.02 px, not by px)."""
    inl, A, sol = fit.inliers, fit.A, fit.sol
    pitch = float(sol[0])
    resid = s[inl] - A @ sol
    rms = float(np.sqrt(np.mean(resid**2)))
    if rms > 0.01 * pitch:
        raise ImageAnalysisError(
            f"{_where(name)}: line spacing is irregular: the {int(np.count_nonzero(inl))} line ends used scatter "
            f"by {rms:.2f} px (RMS) about a regular pitch of {pitch:.2f} px (allowed ≤ 1 % of the pitch); "
            f"chords {np.round(chords, 1)} px")
    dof = int(np.count_nonzero(inl)) - 2
    if dof > 0:
        s2 = float(resid @ resid) / dof
        u_slope = math.sqrt(s2 * np.linalg.inv(A.T @ A)[0, 0])
    else:
        u_slope = float("nan")
    return rms, u_slope


def _counted_scale(image: np.ndarray, name: str | int | None, ed: LineEdges, periods: int,
                   p_edge: float) -> tuple[int, int, float]:
    """The paper's count (Jia eq. 13) along one column a little inside the line ends: (column, pixels
    over ``periods`` periods (median over the runs), µm/px; 0 and NaN without enough lines)."""
    img = np.asarray(image)
    _check_shape(img, name)
    col = int(round(float(np.median(ed.points_px[:, 0])) - 10))
    col = min(max(col, 0), img.shape[1] - 1)
    # one column of the greyscale image (to_grey of that column alone: the same values, per pixel)
    prof = to_grey_column(img, col)
    is_line = prof < ed.threshold if ed.polarity == "dark" else prof > ed.threshold
    starts = np.flatnonzero(~is_line[:-1] & is_line[1:]) + 1
    if starts.size > periods:
        runs = starts[periods:] - starts[:-periods]
        m_p = int(np.median(runs))
        return col, m_p, periods * p_edge / m_p
    return col, 0, float("nan")


def pixel_scale_um(image: np.ndarray, period_um: float, name: str | int | None = None,
                   period_radius_um: float | None = None, edge_radius_um: float | None = None,
                   edges: LineEdges | None = None, options: ImageOptions | None = None) -> dict:
    """Object-side pixel size (µm/px) from the grating period (Jia eq. 13 and a better estimate).

    - ``um_per_px_count``: the paper's way: the pixels over ``options.count_periods`` (3) periods, counted as an
      integer along a column near the edge (``m_p_px``, Jia: 90 px → 0.667 µm/px); the median over
      all runs of 3 periods in the column;
    - ``um_per_px`` (recommended): the middle points of the line ends lie on the edge circle, so the
      distance between neighbours along the edge is the period at the edge radius, exactly (the line
      centres are measured a few px inside the end and moved along their radial line to the edge,
      see :func:`d_ref_px`). Cumulative chord length (= arc length to 1e-8) fitted linearly against
      the line index (missing lines allowed) gives the pitch in px, independent of the fitted
      centre and radius (which are poorly determined on a short arc). Robust: the indices come from
      the majority of regular spacings, line ends off the integer grid by > 0.2 pitch or off the
      line by > max(5 robust σ, 0.05 px) are rejected (``rejected_spacing_px``), one end per index;
      ImageAnalysisError ("line spacing is irregular") if fewer than a majority of the ends, or
      fewer than ``min_lines``, remain.
      ``u_um_per_px``: its standard uncertainty from that linear fit. ``pixel_um`` is an alias of
      ``um_per_px`` (the manifest's ``ccd.pixel_um`` name).

    ``period_um`` is the period at the edge radius (the twin's and Jia's convention: the twin draws
    ``N = round(2π·R_edge/period)`` lines; see the module docstring), unless ``period_radius_um``
    says at which radius it is specified; then ``edge_radius_um`` (the scale edge radius) is needed
    to refer it to the edge.

    Extra keys: ``n_lines`` (line ends used), ``line_index`` (their integer indices),
    ``rejected_spacing_px``, ``spacing_residual_rms_px``.

    ``edges``: this image's :func:`edge_details`, if already found (see :func:`d_ref_px`);
    ``options``: :class:`ImageOptions`.

    Stages: :func:`_period_at_edge`, :func:`d_ref_px`, :func:`_pitch_start`, :func:`_regular_pitch`,
    :func:`_pitch_scatter`, :func:`_counted_scale`.
    """
    p_edge = _period_at_edge(period_um, period_radius_um, edge_radius_um)
    opt = options if options is not None else ImageOptions()
    reject = bool(opt.reject_outliers)
    res = d_ref_px(image, None, name=name, edges=edges, options=opt)
    ed: LineEdges = res["edges"]
    r = res["radius_px"]
    P = res["points_px"]  # middle points of the line ends, on the edge circle, sorted by y
    n_pts = P.shape[0]
    need = max(int(opt.min_lines), (n_pts + 2) // 2)  # a majority, ≥ min_lines
    chords = np.hypot(np.diff(P[:, 0]), np.diff(P[:, 1]))
    # position of each line end along the edge: cumulative chord (= arc to (p/R)²/24 ≈ 1e-8). A
    # contaminated point displaced along the edge changes its two chords by ±δ and nobody else's
    # position; a point between two lines (two ends merged) sits at a half-integer index
    s = np.concatenate([[0.0], np.cumsum(chords)])
    fit = _regular_pitch(s, _pitch_start(chords), need, reject, name, chords)
    rms, u_slope = _pitch_scatter(s, fit, name, chords)
    inl = fit.inliers
    pitch_px = float(fit.sol[0])
    um_per_px = p_edge / pitch_px
    u_um = um_per_px * u_slope / pitch_px
    col, m_p, um_count = _counted_scale(image, name, ed, opt.count_periods, p_edge)
    return {
        "um_per_px": um_per_px, "pixel_um": um_per_px, "u_um_per_px": u_um, "pitch_px": pitch_px, "pitch_angle_rad": pitch_px / r,
        "edge_radius_px": r, "period_at_edge_um": p_edge, "m_p_px": m_p, "um_per_px_count": um_count,
        "count_column_px": col, "n_lines": int(np.count_nonzero(inl)), "line_index": fit.index[inl].astype(int),
        "rejected_spacing_px": P[~inl], "spacing_residual_rms_px": rms,
    }


def frame_edges_and_scale(image: np.ndarray, period_um: float, name: str | int | None = None,
                          expect_polarity: str | None = None,
                          ) -> tuple[LineEdges | None, float | None, ImageAnalysisError | None]:
    """One frame of a sweep, its image work done once: (edges, pixel scale µm/px, None), or
    (None, None, error) for a frame the analysis rejects.

    The edges (:func:`edge_details`, the expensive part: threshold, connected parts, sub-pixel
    edges) are found once and serve both the pixel scale here (:func:`pixel_scale_um`, eq. 13) and
    the later d_ref with the sweep's fixed radius (:func:`d_ref_px` with ``edges=``), which needs the
    median scale of all frames first. Pure (an array in, small results out), so frames can be
    analysed in parallel processes (analysis/parallel.py) with the serial path's results.
    ``expect_polarity``: the sweep's line polarity (from its first usable frame), which only orders
    the labelling work (:func:`segment_lines`); every frame still decides its own.
    """
    try:
        ed = edge_details(image, name, expect_polarity=expect_polarity)
        scale = float(pixel_scale_um(image, period_um, name=name, edges=ed)["pixel_um"])
    except ImageAnalysisError as exc:
        return None, None, exc
    return ed, scale, None


# --------------------------------------------------------------------------- sweep → e, θ0


def eccentricity_from_dref(theta_deg: np.ndarray, dref_um: np.ndarray, camera_azimuth_deg: float = 180.0,
                           order: int = 10, u_dref_um: float | np.ndarray | None = None) -> dict:
    """e (eq. 11) and θ0 (eq. 12) from d_ref(θ) (eq. 10), with GUM uncertainties.

    The Fourier covariance comes from the fit residuals (or ``u_dref_um`` per point). θ0 is rotated
    by the camera azimuth: ``θ0 = atan2(c1, d1) − (ψ − 180°)`` (module docstring), in [0°, 360°).

    Keys: e_um, e_u_um, theta0_deg, theta0_u_deg, cov_e_theta0 (µm·deg), c0_um, c1_um, d1_um,
    coefficients (FourierFit of d_ref, µm), harmonics_um (amplitudes of harmonics 1…order),
    residual_rms_um, phase_fit_deg (atan2(c1, d1) before the camera rotation), camera_azimuth_deg.
    """
    th = np.asarray(theta_deg, dtype=float).ravel()
    d = np.asarray(dref_um, dtype=float).ravel()
    if th.size != d.size:
        raise ValueError(f"theta_deg has {th.size} values, dref_um {d.size}")
    fit = fit_fourier(th, d, order, u_dref_um)
    ap = amplitude_phase(fit, 1)
    phase_fit = ap["phase_deg"]
    theta0 = (phase_fit - (camera_azimuth_deg - 180.0)) % 360.0
    harm = np.hypot(fit.a, fit.b)
    return {
        "e_um": ap["amplitude"], "e_u_um": ap["u_amplitude"],
        "theta0_deg": theta0, "theta0_u_deg": ap["u_phase_deg"],
        "cov_e_theta0": float(math.degrees(ap["cov_amp_phase"][0, 1])),
        "c0_um": fit.a0, "c1_um": ap["a"], "d1_um": ap["b"],
        "coefficients": fit, "harmonics_um": harm,
        "residual_rms_um": float(np.sqrt(np.mean(fit.residual**2))),
        "phase_fit_deg": phase_fit, "camera_azimuth_deg": float(camera_azimuth_deg),
        "phase_defined": ap["phase_defined"],
    }


def median_u(values: np.ndarray) -> float:
    """Standard uncertainty of the median of n independent values: √(π/2)·σ/√n (asymptotic, normal),
    σ estimated robustly (1.4826·MAD) so that a rejected-looking outlier frame does not inflate it."""
    v = np.asarray(values, dtype=float).ravel()
    if v.size < 2:
        return float("nan")
    sd = 1.4826 * float(np.median(np.abs(v - np.median(v))))
    if sd == 0.0:
        sd = float(np.std(v, ddof=1))
    return math.sqrt(math.pi / 2.0) * sd / math.sqrt(v.size)


def eccentricity_from_sweep(theta_deg: np.ndarray, dref_px: np.ndarray, scales_um_per_px: np.ndarray,
                            camera_azimuth_deg: float = 180.0, order: int = 10) -> dict:
    """e and θ0 from d_ref in pixels and the per-frame pixel scales (Jia eqs. 10-13), GUM.

    The scale is the median of the per-frame scales (eq. 13, one per frame); ``d_ref = d_ref_px ·
    scale``; e and θ0 from :func:`eccentricity_from_dref`. e is proportional to the scale, θ0 does not
    depend on it, so ``u(e)² = u_fit(e)² + (e·u(s)/s)²`` with u(s) the standard uncertainty of the
    median (:func:`median_u`); cov(e, θ0) is unchanged (the scale does not move θ0). Extra keys:
    e_u_fit_um, theta0_u_fit_deg (the fit-only values), pixel_um, u_pixel_um, n_scales.
    """
    s_all = np.asarray(scales_um_per_px, dtype=float).ravel()
    if s_all.size == 0 or not np.all(np.isfinite(s_all)) or np.any(s_all <= 0):
        raise ValueError("scales_um_per_px: need ≥ 1 finite, positive pixel scale")
    s = float(np.median(s_all))
    us = median_u(s_all) if s_all.size >= 2 else 0.0
    out = eccentricity_from_dref(theta_deg, np.asarray(dref_px, dtype=float) * s, camera_azimuth_deg, order)
    e = out["e_um"]
    out["e_u_fit_um"], out["theta0_u_fit_deg"] = out["e_u_um"], out["theta0_u_deg"]
    out["e_u_um"] = math.hypot(out["e_u_um"], e * us / s)
    out["pixel_um"], out["u_pixel_um"], out["n_scales"] = s, us, int(s_all.size)
    return out


def with_async_motion(ecc: dict, u_h1_um: float, dof: float | None = None) -> dict:
    """Add the asynchronous motion's share in the 1st harmonic to u(e) and u(θ0) (GUM, type A).

    One CCD sweep sees the disk centre during ONE revolution: the once-per-revolution part of the
    non-repeating spindle motion during that revolution adds to the fitted first harmonic (eq. 11)
    and cannot be told from e by the sweep itself; its fit residual shows only the other
    frequencies. ``u_h1_um`` is the standard deviation of one revolution's 1st-harmonic coefficient
    (per component; :func:`benchtwin.analysis.radial_motion.radial_motion` gives it as
    ``u_h1_async_um`` from the repetitions of the two-sphere measurement, along the same lab axis Y
    as the camera at 180°). A whirl of that size moves e by ``u`` along (c1, d1) and θ0 by ``u/e``
    across it: ``u(e)² = u_fit(e)² + u²``, ``u(θ0)² = u_fit(θ0)² + (u/e)²``. Returns a copy with
    e_u_um, theta0_u_deg updated and e_u_fit_um, theta0_u_fit_deg (the fit alone), u_async_h1_um,
    u_async_h1_dof added. NaN or None ``u_h1_um`` (one repetition): returned unchanged but for the
    keys, with a note and a u_source saying that part is not in u.

    e itself is about the axis of rotation: a synchronous first harmonic of the axis (a journal's
    run-out, an inner race's eccentricity) turns with the shaft and is centring (ISO 230-7), part
    of e for the sweep and for the encoder alike, not a term of u (docs/scoring.md "e: which truth")."""
    out = dict(ecc)
    out.setdefault("e_u_fit_um", ecc["e_u_um"])
    out.setdefault("theta0_u_fit_deg", ecc["theta0_u_deg"])
    if u_h1_um is None or not math.isfinite(u_h1_um):
        out["u_async_h1_um"], out["u_async_h1_dof"] = float("nan"), 0
        out["async_note"] = "no repeated revolutions: the asynchronous motion's share in e and θ0 is not estimated"
        # u_source says what u(e) includes, and so what it does not
        out["u_source"] = (f"one sweep: the eq. 10 fit (u = {ecc['e_u_um']:.3g} µm) alone; the axis's asynchronous "
                           "1st harmonic during the sweep is not in u (the radial run has one revolution: no "
                           "repetitions to measure it)")
        return out
    if u_h1_um < 0:
        raise ValueError(f"u_h1_um must be >= 0, got {u_h1_um}")
    e = ecc["e_um"]
    out["u_source"] = (f"one sweep: the eq. 10 fit (u = {ecc['e_u_um']:.3g} µm) ⊕ the radial run's asynchronous "
                       f"1st harmonic (type B from the probes' repetitions, u = {u_h1_um:.3g} µm"
                       + (f", {dof:g} dof" if dof else "") + ")")
    out["e_u_um"] = math.hypot(ecc["e_u_um"], u_h1_um)
    out["theta0_u_deg"] = math.hypot(ecc["theta0_u_deg"], math.degrees(u_h1_um / e)) if e > 0 else float("nan")
    out["u_async_h1_um"], out["u_async_h1_dof"] = float(u_h1_um), dof
    return out


def eccentricity_monte_carlo(theta_deg: np.ndarray, dref_um: np.ndarray, u_dref_um: float | np.ndarray | None = None,
                             n: int = 2000, seed: int = 0, camera_azimuth_deg: float = 180.0, order: int = 10) -> dict:
    """Monte Carlo check of the GUM uncertainties of e and θ0 (GUM Supplement 1 style).

    The fitted series is taken as the truth; ``n`` data sets = series + Gaussian noise of standard
    deviation ``u_dref_um`` (default: the residual σ of the fit) are refitted. Returns e_mean_um,
    e_std_um, theta0_mean_deg (circular mean), theta0_std_deg (circular), e_u_gum_um,
    theta0_u_gum_deg, samples_e_um, samples_theta0_deg.
    """
    base = eccentricity_from_dref(theta_deg, dref_um, camera_azimuth_deg, order, u_dref_um)
    fit: FourierFit = base["coefficients"]
    th = np.asarray(theta_deg, dtype=float).ravel()
    sigma = fit.sigma if u_dref_um is None else np.broadcast_to(np.asarray(u_dref_um, dtype=float), th.shape)
    rng = np.random.default_rng(seed)
    from benchtwin.analysis.fourier import design_matrix

    A = design_matrix(th, order)
    y0 = A @ fit.params
    Y = y0[None, :] + rng.normal(size=(n, th.size)) * sigma
    P, *_ = np.linalg.lstsq(A, Y.T, rcond=None)
    c1, d1 = P[1], P[2]
    e = np.hypot(c1, d1)
    ph = np.arctan2(c1, d1) - math.radians(camera_azimuth_deg - 180.0)
    mc = np.angle(np.mean(np.exp(1j * ph)))
    dev = np.angle(np.exp(1j * (ph - mc)))
    return {
        "e_mean_um": float(e.mean()), "e_std_um": float(e.std(ddof=1)),
        "theta0_mean_deg": math.degrees(mc) % 360.0, "theta0_std_deg": float(np.degrees(dev.std(ddof=1))),
        "e_u_gum_um": base["e_u_um"], "theta0_u_gum_deg": base["theta0_u_deg"],
        "samples_e_um": e, "samples_theta0_deg": np.degrees(ph) % 360.0,
    }


def eccentricity_range_method(e_um: Sequence[float], theta0_deg: Sequence[float], d_n: float | None = None) -> dict:
    """Jia sec. 5: uncertainty of e and θ0 from repeated sweeps by the range method, u = range / d_n
    (Jia: range of e 0.4 µm → u_e = 0.24 µm; range of θ0 1.91° → u_θ0 = 1.13°, n = 3, d_n = 1.69).
    The range of θ0 is taken on the circle (the smallest arc containing all values)."""
    from benchtwin.analysis.radial_motion import D_N

    e = np.asarray(e_um, dtype=float).ravel()
    t = np.asarray(theta0_deg, dtype=float).ravel() % 360.0
    n = e.size
    if n < 2 or t.size != n:
        raise ValueError(f"need ≥ 2 repeated sweeps with e and θ0 each, got {e.size} and {t.size}")
    if d_n is None:
        if n not in D_N:
            raise ValueError(f"no d_n tabulated for n = {n}; pass d_n")
        d_n = D_N[n]
    ts = np.sort(t)
    gaps = np.diff(np.concatenate([ts, [ts[0] + 360.0]]))
    rng_t = 360.0 - float(gaps.max())
    return {"e_range_um": float(np.ptp(e)), "theta0_range_deg": rng_t, "e_u_um": float(np.ptp(e)) / d_n,
            "theta0_u_deg": rng_t / d_n, "d_n": d_n, "n": n}


def eccentricity_from_sweeps(sweeps: Sequence[dict]) -> dict:
    """e and θ0 of n ≥ 2 repeated CCD sweeps, u(e) and u(θ0) type A from their scatter (GUM 4.2).

    ``sweeps``: one :func:`eccentricity_from_dref` result per sweep (each a revolution of its own:
    its first harmonic carries that revolution's asynchronous motion, the per-frame noise of d_ref and
    whatever else changes from sweep to sweep). The estimate is the mean first-harmonic vector
    (c̄1, d̄1) of the sweeps (eqs. 11, 12 on it), so a mean over sweeps and the phase are consistent.

    Its uncertainty, and why:

    - ``s_e``, ``s_θ0``: the experimental standard deviation (n − 1 dof) of the sweeps' e and θ0
      (θ0 about its circular mean). This is σ of ONE sweep, the quantity Jia quotes (u_e = σ_e,
      sec. 5) — the range method (range/d_n, Jia's) is reported beside it (``*_range_u_*``); s is the
      estimator used, since it is unbiased in variance and uses every value, where the range of n = 3
      is equivalent to s with 1.8 dof.
    - u(e) of the stated e is that of the MEAN of the n sweeps, s/√n (GUM 4.2.3), because the
      stated e is the mean. With n = 3, s has 2 dof (its relative sd is ≈ 50 %); it is floored by the
      fits' own pooled u (``e_u_fit_um``, √(mean u_fit,i²)/√n, from ~40 residual dof per sweep), which
      the sweeps' scatter cannot be smaller than in expectation: a chance-small s does not make u(e)
      smaller than the frames' measured noise. Likewise u(θ0) = max(s_θ0, u_fit(θ0))/√n.
    - The probes' asynchronous first harmonic (:func:`with_async_motion`) is NOT added: each sweep's
      revolution already carries its own, so the sweeps' scatter contains it.

    Keys: e_um, e_u_um, theta0_deg, theta0_u_deg, n_sweeps, dof, e_sweeps_um, theta0_sweeps_deg,
    e_sweep_sd_um, theta0_sweep_sd_deg (s of one sweep), e_range_u_um, theta0_range_u_deg (range/d_n of
    one sweep), e_u_fit_um, theta0_u_fit_deg (the pooled fit u of the mean), c1_um, d1_um,
    camera_azimuth_deg, u_source (a sentence)."""
    n = len(sweeps)
    if n < 2:
        raise ValueError(f"need ≥ 2 sweeps for a type-A u(e) from their scatter, got {n}")
    c1 = np.array([float(r["c1_um"]) for r in sweeps])
    d1 = np.array([float(r["d1_um"]) for r in sweeps])
    az = {float(r["camera_azimuth_deg"]) for r in sweeps}
    if len(az) != 1:
        raise ValueError(f"the sweeps were taken at different camera azimuths {sorted(az)}")
    camera = az.pop()
    e_i = np.hypot(c1, d1)
    t_i = np.array([float(r["theta0_deg"]) for r in sweeps]) % 360.0
    cm, dm = float(c1.mean()), float(d1.mean())
    e = math.hypot(cm, dm)
    theta0 = (math.degrees(math.atan2(cm, dm)) - (camera - 180.0)) % 360.0
    dev = (t_i - theta0 + 180.0) % 360.0 - 180.0       # θ0 of each sweep about the mean's
    s_e = float(np.std(e_i, ddof=1))
    s_t = float(np.sqrt(np.sum((dev - dev.mean()) ** 2) / (n - 1)))
    uf_e = math.sqrt(float(np.mean([float(r["e_u_um"]) ** 2 for r in sweeps])))
    uf_t = math.sqrt(float(np.mean([float(r["theta0_u_deg"]) ** 2 for r in sweeps])))
    rm = eccentricity_range_method(e_i.tolist(), t_i.tolist()) if n in _d_n_table() else {"e_u_um": float("nan"),
                                                                         "theta0_u_deg": float("nan")}
    floor_e = s_e < uf_e
    src = (f"type A from {n} repeated CCD sweeps: u = s/√n of the mean (s = {s_e:.3g} µm, {n - 1} dof"
           + (f"; floored by the fits' pooled u = {uf_e:.3g} µm" if floor_e else "") + ")")
    return {
        "e_um": e, "e_u_um": max(s_e, uf_e) / math.sqrt(n),
        "theta0_deg": theta0, "theta0_u_deg": max(s_t, uf_t) / math.sqrt(n),
        "n_sweeps": n, "dof": n - 1,
        "e_sweeps_um": e_i.tolist(), "theta0_sweeps_deg": t_i.tolist(),
        "e_sweep_sd_um": s_e, "theta0_sweep_sd_deg": s_t,
        "e_range_u_um": float(rm["e_u_um"]), "theta0_range_u_deg": float(rm["theta0_u_deg"]),
        "e_u_fit_um": uf_e / math.sqrt(n), "theta0_u_fit_deg": uf_t / math.sqrt(n),
        "c1_um": cm, "d1_um": dm, "camera_azimuth_deg": camera, "u_source": src,
    }


def _d_n_table() -> dict[int, float]:
    from benchtwin.analysis.radial_motion import D_N

    return D_N


def eccentricity_from_images(images: Sequence[np.ndarray], theta_deg: Sequence[float], sweep: CcdSweep,
                             names: Sequence[str] | None = None, options: ImageOptions | None = None) -> dict:
    """The whole sweep (sec. 4.2): d_ref per image, scale, e and θ0. Pure: images are arrays.

    The scale is ``sweep.um_per_px`` if given, else the median of :func:`pixel_scale_um` over the
    images (needs ``sweep.period_um``). Errors name the image (``names[k]`` or its index).
    ``options``: how each frame is read (:class:`ImageOptions`).

    Keys: as :func:`eccentricity_from_dref`, plus theta_deg, dref_px, u_dref_px, dref_um, um_per_px,
    um_per_px_count, per_image (list of d_ref_px dicts without the edge details).
    """
    opt = options if options is not None else ImageOptions()
    th = np.asarray(theta_deg, dtype=float).ravel()
    if len(images) != th.size:
        raise ValueError(f"{len(images)} images but {th.size} angles")
    per, dpx, upx, scales, counts = [], [], [], [], []
    for k, img in enumerate(images):
        nm = names[k] if names is not None else k
        # the edges once per image, for d_ref and the pixel scale alike
        ed = edge_details(img, nm, opt)
        r = d_ref_px(img, sweep.reference_px, sweep.radius_px, name=nm, edges=ed, options=opt)
        dpx.append(r["d_ref_px"])
        upx.append(r["u_d_ref_px"])
        per.append({k2: v for k2, v in r.items() if k2 != "edges"})
        if sweep.um_per_px is None:
            if sweep.period_um is None:
                raise ValueError("give um_per_px or period_um")
            s = pixel_scale_um(img, sweep.period_um, name=nm, edges=ed, options=opt)
            scales.append(s["um_per_px"])
            counts.append(s["um_per_px_count"])
    scale = float(sweep.um_per_px) if sweep.um_per_px is not None else float(np.median(scales))
    dref_um = np.asarray(dpx) * scale
    out = eccentricity_from_dref(th, dref_um, sweep.camera_azimuth_deg, sweep.order)
    out.update(theta_deg=th, dref_px=np.asarray(dpx), u_dref_px=np.asarray(upx), dref_um=dref_um,
               um_per_px=scale, um_per_px_count=float(np.nanmedian(counts)) if counts else float("nan"),
               per_image=per)
    return out
