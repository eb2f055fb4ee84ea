"""The disk's graduation as a line-position map, and what a reading head makes of it.

A circular graduation is ruled (or photo-replicated from a ruled master) line by line on a
dividing engine: each line is placed one nominal pitch p = 2π/N after the previous one, with a
small random error of the engine's step. The line positions are then a random walk of the
engine, and because the engine's table returns to its start after one turn (the last line is
one pitch before the first; circle closure: the division errors of a full circle sum to zero,
Estler 1998, "Uncertainty analysis for angle calibrations using circle closure", J. Res. NIST
103, 141–151), the walk is CLOSED over the turn: a Brownian bridge (our model choice: the random
walk conditioned on closure). Its Fourier coefficients fall as 1/k (power 1/k²), which is why the
low orders dominate a disk's division error.

On top of the ruling, the disk is distorted by its mounting and ruled about a centre that need
not be the centre of its edge:

- k-fold clamping: a disk clamped or glued at k points (or under k screws) is strained in a
  k-lobed pattern; its lines move tangentially by a_k·cos(k·g − φ_k) (the k-th harmonic of the
  map; Jia 2019 sec. 4.4 and Hsieh 2022 sec. 2.3 treat the graduation error as such harmonics);
- eccentric ruling: lines ruled radially from a point at ε from the disk's geometric centre (the
  centre of its edge, which the CCD measures) cross the head's circle of radius r at
  g − asin((ε/r)·sin(g − ψ)) (exact: the cross product of the line's direction with the point on
  the circle), a first harmonic the heads see and the edge does not.

The declared error of an encoder class (``errors.graduation_error_rms``) is such a map: a bridge
(ruling walk) plus a 3-fold clamping harmonic (ASSUMPTION: the disk glued to its hub at three
pads, 20 % of the variance, seeded phase), its mean and first harmonic removed (the maker
centres the disk's edge on its graduation, and the index defines the zero), scaled so that the
HEAD reads the declared rms.

A reading head does not see one line: its scanning reticle integrates the grating over a field of
many lines, and the signal's phase is the mean position of the lines under the field (the
fundamental of the summed line pattern; for small displacements, the average). ASSUMPTION:
``SCANNING_FIELD_LINES`` = 65 lines, 1.3 mm of a 20 µm grating (an imaging scanning reticle of
about 1 mm, as in exposed-grating heads; not given by either paper). The head's error at a
fractional line position x is the moving average over the field, linearly interpolated between
line positions. A k-th harmonic is thereby multiplied by the Dirichlet kernel
D_k = sin(π·k·W/N) / (W·sin(π·k/N)) ≈ 1 − (π·k·W/N)²/6 (0.986 at k = 10 for jia2019's 7069
lines, 0.9995 for hsieh2022's 36 000); the per-line roughness of the walk is averaged away. The sub-division (interpolation) error, periodic in the line pitch, is
not part of the map (``encoder_head.py``).

Pure functions over arrays; the random walk draws from the generator it is given (seeded by the
caller, its own stream).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

TWO_PI = 2.0 * math.pi
#: lines a head's scanning field integrates (ASSUMPTION, see the module docstring)
SCANNING_FIELD_LINES = 65
#: declared map: variance share and order of the clamping harmonic (ASSUMPTION: three glue pads)
DECLARED_CLAMP_ORDER = 3
DECLARED_CLAMP_SHARE = 0.2


def brownian_bridge(n_lines: int, rng: np.random.Generator) -> np.ndarray:
    """A closed random walk of ``n_lines`` steps (unit step variance): W_i − (i/N)·W_N, i = 0…N−1,
    so that the step from the last line to the first is an ordinary step of the walk."""
    steps = rng.normal(0.0, 1.0, int(n_lines))
    w = np.concatenate([[0.0], np.cumsum(steps)])
    i = np.arange(n_lines + 1) / n_lines
    return (w - i * w[-1])[:-1]


def remove_orders(x: np.ndarray, orders: Sequence[int]) -> np.ndarray:
    """``x`` (one value per line, a periodic sequence) without the given Fourier orders."""
    c = np.fft.rfft(x)
    for k in orders:
        if 0 <= k < c.size:
            c[k] = 0.0
    return np.fft.irfft(c, n=x.size)


def harmonics(n_lines: int, orders, amplitudes, phases) -> np.ndarray:
    """Σ a_k·cos(k·g_i − φ_k) at the nominal line angles g_i = 2π·i/N."""
    g = TWO_PI * np.arange(n_lines) / n_lines
    out = np.zeros(n_lines)
    for k, a, p in zip(orders, amplitudes, phases):
        out += float(a) * np.cos(float(k) * g - float(p))
    return out


def eccentric_ruling(n_lines: int, eccentricity_m: float, azimuth_rad: float, radius_m: float) -> np.ndarray:
    """Line displacement (rad) at radius r of lines ruled radially from a point at ε, azimuth ψ,
    from the disk's geometric centre: −asin((ε/r)·sin(g − ψ)) (exact)."""
    g = TWO_PI * np.arange(n_lines) / n_lines
    return -np.arcsin(float(eccentricity_m) / float(radius_m) * np.sin(g - float(azimuth_rad)))


def scanning_average(lines: np.ndarray, window_lines: int = SCANNING_FIELD_LINES) -> np.ndarray:
    """Circular moving average over an odd field of ``window_lines`` lines centred on each line:
    the head's error when its field is centred on line i."""
    w = int(window_lines)
    if w < 1 or w % 2 == 0:
        raise ValueError(f"scanning field: an odd number of lines ≥ 1, got {window_lines}")
    if w == 1:
        return np.array(lines, dtype=float)
    h = w // 2
    ext = np.concatenate([lines[-h:], lines, lines[:h]])
    c = np.concatenate([[0.0], np.cumsum(ext)])
    return (c[w:] - c[:-w]) / w


def dirichlet_factor(order: float, n_lines: int, window_lines: int = SCANNING_FIELD_LINES) -> float:
    """The factor a field of W lines applies to a k-th harmonic of the map."""
    k, n, w = float(order), int(n_lines), int(window_lines)
    s = math.sin(math.pi * k / n)
    if s == 0.0:
        return 1.0
    return math.sin(math.pi * k * w / n) / (w * s)


def declared_line_map(n_lines: int, rms_rad: float, rng: np.random.Generator,
                      window_lines: int = SCANNING_FIELD_LINES) -> np.ndarray:
    """Line positions minus nominal (rad) of the declared disk: ruling walk + 3-fold clamp, mean
    and first harmonic removed, scaled so that the head's average over its field has rms ``rms``."""
    n = int(n_lines)
    walk = remove_orders(brownian_bridge(n, rng), (0, 1))
    walk /= math.sqrt(np.mean(walk**2))
    clamp = harmonics(n, [DECLARED_CLAMP_ORDER], [math.sqrt(2.0)], [rng.uniform(0.0, TWO_PI)])
    lines = math.sqrt(1.0 - DECLARED_CLAMP_SHARE) * walk + math.sqrt(DECLARED_CLAMP_SHARE) * clamp
    head = scanning_average(lines, window_lines)
    return lines * (float(rms_rad) / math.sqrt(np.mean(head**2)))


class HeadMap:
    """The error a head reads at any graduation value: the field average of a line map,
    linearly interpolated between line positions (fixed to the disk)."""

    def __init__(self, line_error_rad: np.ndarray, window_lines: int = SCANNING_FIELD_LINES):
        self.lines = np.asarray(line_error_rad, dtype=float)
        self.n_lines = self.lines.size
        self.pitch_rad = TWO_PI / self.n_lines
        self.window_lines = int(window_lines)
        self.head = scanning_average(self.lines, self.window_lines)
        self._ext = np.append(self.head, self.head[0])   # the line after the last is line 0
        self._ext_list = self._ext.tolist()               # the same doubles, for error_at

    def error_rad(self, g) -> np.ndarray:
        """E(g) (rad): body angle of the graduation value g read by a head, minus g."""
        g = np.asarray(g, dtype=float)
        x = np.mod(g, TWO_PI) / self.pitch_rad
        fl = np.floor(x)
        f = x - fl
        i0 = fl.astype(np.intp) % self.n_lines
        return (1.0 - f) * self._ext[i0] + f * self._ext[i0 + 1]

    def error_at(self, g: float) -> float:
        """``error_rad`` of one float, bit for bit: the same IEEE operations in the same order
        (Python's float % and NumPy's float mod are both fmod plus the same sign fix-up, floor
        and the products are exact or correctly rounded), without NumPy's per-call overhead on
        the 1-12 values of a reading (tests/twin/test_graduation.py checks the identity)."""
        x = (g % TWO_PI) / self.pitch_rad
        fl = math.floor(x)
        f = x - fl
        i0 = fl % self.n_lines
        ext = self._ext_list
        return (1.0 - f) * ext[i0] + f * ext[i0 + 1]

    @property
    def rms_rad(self) -> float:
        return float(np.sqrt(np.mean(self.head**2)))


__all__ = ["HeadMap", "brownian_bridge", "declared_line_map", "dirichlet_factor", "eccentric_ruling",
           "harmonics", "remove_orders", "scanning_average", "SCANNING_FIELD_LINES"]
