"""Sensor model of the CCD microscope of Jia 2019 sec. 4.2 (2048×1536 px, 0.667 µm/px object side).

Applied to an irradiance image in [0, 1] (1 = bright glass, see ``grating``), in the order light
takes: object (dust, scratches on the disk) → optics (blur) → illumination (vignetting) → detector
(shot noise, read noise, full-well saturation) → ADC (quantisation to ``bit_depth``).

Choices, and why:

- optical blur: the microscope is diffraction limited; the Airy core is replaced by its
  best-fit Gaussian, σ ≈ 0.21·λ/NA with λ = 0.55 µm (green, the peak of a white LED on a silicon
  CCD), converted to pixels with the TRUE object-side pixel; defocus adds a geometric blur disk of
  radius ≈ defocus·NA (pill-box kernel). Both kernels are symmetric, so they do not move a straight
  edge's 50 % point or its area centroid: blur degrades sub-pixel precision (through noise) but
  does not bias the line-end positions that Jia's circle fit uses;
- vignetting/illumination: cos⁴-like radial falloff, normalised so the image corner receives
  ``1 − vignetting`` of the centre: smooth, so it shifts thresholds (Jia's binarisation) a little
  and tests the pipeline's robustness, as the real microscope would;
- dust and scratches: on the disk surface (in focus, hence blurred with the image): dark blobs of
  radii 1–12 px (specks to lint) with partial opacity, and thin dark lines of several widths and
  lengths. Jia removes "the small parts that are caused by noise and dust" by an area threshold; the
  sizes span both sides of that threshold on purpose;
- shot noise: Poisson on the signal electrons ``exposure·full_well·signal``; drawn exactly below
  100 e⁻ and as a Gaussian of the same variance above (the skewness 1/√λ < 0.1 is far below
  anything the analysis can see, and it is 5× faster on 3 Mpx);
- read noise: Gaussian, in e⁻; saturation: clip at the full well; quantisation: full well maps to
  2^bits − 1, rounded (uint8 up to 8 bits, uint16 up to 16);
- camera rotation about its axis and pixel-scale error are GEOMETRY (``CcdCamera``): applied
  exactly when the scene is projected, never by resampling the image (resampling would blur and
  bias the very edges the analysis measures);
- randomness only from the ``np.random.Generator`` passed in: same seed → identical image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Any

import numpy as np

__all__ = ["SensorParams", "apply_sensor", "dust_map", "blur_sigma_px"]

WAVELENGTH_M = 0.55e-6  # green: peak of white-LED × silicon response


@dataclass(frozen=True)
class SensorParams:
    """CCD + microscope optics (SI units; px counts; electrons e⁻)."""

    width_px: int = 2048
    height_px: int = 1536
    pixel_pitch_m: float = 0.667e-6  # object side (Jia sec. 4.2.2)
    bit_depth: int = 8
    numerical_aperture: float = 0.1
    defocus_m: float = 0.0
    vignetting: float = 0.15  # fractional falloff at the image corner
    full_well_e: float = 20000.0
    read_noise_e: float = 12.0
    exposure: float = 0.7  # fraction of the full well on bright glass
    dust_count: int = 6
    scratch_count: int = 1
    rotation_rad: float = 0.0  # geometry: used by camera(), not here
    pixel_scale_error: float = 0.0  # geometry: used by camera(), not here
    wavelength_m: float = WAVELENGTH_M

    def __post_init__(self) -> None:
        if not (1 <= self.bit_depth <= 16):
            raise ValueError(f"bit_depth must be 1…16, got {self.bit_depth}")
        if self.full_well_e <= 0 or self.exposure < 0:
            raise ValueError("full_well must be positive and exposure non-negative")
        if not (0.0 <= self.vignetting < 1.0):
            raise ValueError(f"vignetting must be in [0, 1), got {self.vignetting}")

    @classmethod
    def from_section(cls, d: dict) -> "SensorParams":
        """From the SI-parsed ``[instruments.ccd]`` section (missing keys keep their defaults)."""
        names = {"width": "width_px", "height": "height_px", "pixel_pitch": "pixel_pitch_m",
                 "bit_depth": "bit_depth", "numerical_aperture": "numerical_aperture", "defocus": "defocus_m",
                 "vignetting": "vignetting", "full_well": "full_well_e", "read_noise": "read_noise_e",
                 "exposure": "exposure", "dust_count": "dust_count", "scratch_count": "scratch_count",
                 "rotation": "rotation_rad", "pixel_scale_error": "pixel_scale_error",
                 "wavelength": "wavelength_m"}
        ints = {"width_px", "height_px", "bit_depth", "dust_count", "scratch_count"}
        kw: dict[str, Any] = {}  # int or float by field: one dict, so mypy cannot match each to its field
        for key, name in names.items():
            if key in d:
                kw[name] = int(round(float(d[key]))) if name in ints else float(d[key])
        unknown = set(d) - set(names)
        if unknown:
            raise ValueError(f"[instruments.ccd]: unknown keys {sorted(unknown)}")
        return cls(**kw)

    def camera(self, azimuth_rad: float, look_at_radius_m: float | None = None, tangential: str = "+x"):
        """The geometric camera these parameters describe (size, pixel, rotation, scale error)."""
        from benchtwin.twin.render.grating import CcdCamera

        return CcdCamera(azimuth_rad=azimuth_rad, look_at_radius_m=look_at_radius_m, width_px=self.width_px,
                         height_px=self.height_px, pixel_pitch_m=self.pixel_pitch_m,
                         rotation_rad=self.rotation_rad, pixel_scale_error=self.pixel_scale_error,
                         tangential=tangential)

    @property
    def dtype(self) -> type:
        return np.uint8 if self.bit_depth <= 8 else np.uint16

    @property
    def max_dn(self) -> int:
        return 2 ** self.bit_depth - 1

    def replace(self, **kw) -> "SensorParams":
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d.update(kw)
        return SensorParams(**d)


def blur_sigma_px(sensor: SensorParams, pixel_m: float) -> tuple[float, float]:
    """(Gaussian σ of the Airy core, defocus disk radius), both in px of size ``pixel_m``."""
    sigma = 0.21 * sensor.wavelength_m / sensor.numerical_aperture / pixel_m if sensor.numerical_aperture > 0 else 0.0
    return sigma, abs(sensor.defocus_m) * sensor.numerical_aperture / pixel_m


def _disk_kernel(radius_px: float) -> np.ndarray:
    """Pill-box kernel with anti-aliased rim (4× supersampled), normalised to sum 1."""
    n = int(math.ceil(radius_px + 1))
    s = 4
    off = (np.arange(s) + 0.5) / s - 0.5
    ax = np.arange(-n, n + 1)
    X = (ax[:, None] + off[None, :]).ravel()
    inside = (X[:, None] ** 2 + X[None, :] ** 2) <= radius_px ** 2
    k = inside.reshape(2 * n + 1, s, 2 * n + 1, s).mean(axis=(1, 3))
    return k / k.sum()


@lru_cache(maxsize=4)
def vignetting_map(h: int, w: int, fraction: float) -> np.ndarray:
    """Relative illumination, 1 at the centre, 1 − fraction at the corners (cos⁴ law shape)."""
    if fraction <= 0:
        v = np.ones((h, w), np.float32)
        v.flags.writeable = False
        return v
    y = (np.arange(h, dtype=np.float32) - (h - 1) / 2.0)[:, None]
    x = (np.arange(w, dtype=np.float32) - (w - 1) / 2.0)[None, :]
    rho2 = (x * x + y * y) / np.float32(((w - 1) / 2.0) ** 2 + ((h - 1) / 2.0) ** 2)
    tan_c2 = math.tan(math.radians(30.0)) ** 2  # cos⁴ over a ±30° field: the law's shape, rescaled
    cos4 = 1.0 / (1.0 + rho2 * np.float32(tan_c2)) ** 2
    cos4_corner = 1.0 / (1.0 + tan_c2) ** 2
    v = (1.0 - fraction * (1.0 - cos4) / (1.0 - cos4_corner)).astype(np.float32)
    v.flags.writeable = False  # cached and shared between frames
    return v


def dust_map(h: int, w: int, dust_count: int, scratch_count: int, rng: np.random.Generator) -> np.ndarray:
    """Transmission (float32, ≤ 1) of dust specks (several sizes) and scratches on the disk."""
    import cv2

    opacity = np.zeros((h, w), np.float32)
    if dust_count <= 0 and scratch_count <= 0:
        return 1.0 - opacity
    sh = 4  # cv2 fractional bits: sub-pixel positions and sizes; LINE_AA gives area-like rims
    f = float(2 ** sh)
    for _ in range(dust_count):
        # log-uniform radius 1–12 px: many specks, a few large lint blobs; irregular = ellipses
        r = math.exp(rng.uniform(0.0, math.log(12.0)))
        op = float(rng.uniform(0.5, 0.95))
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        axes = (int(r * f), int(r * rng.uniform(0.5, 1.0) * f))
        cv2.ellipse(opacity, (int(cx * f), int(cy * f)), axes, float(rng.uniform(0, 180)), 0, 360, op, -1,
                    cv2.LINE_AA, sh)
    for _ in range(scratch_count):
        length = rng.uniform(0.1, 0.6) * max(w, h)
        width = max(1, int(round(rng.uniform(1.0, 3.0))))
        ang = rng.uniform(0, math.pi)
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        dx, dy = 0.5 * length * math.cos(ang), 0.5 * length * math.sin(ang)
        cv2.line(opacity, (int((cx - dx) * f), int((cy - dy) * f)), (int((cx + dx) * f), int((cy + dy) * f)),
                 float(rng.uniform(0.3, 0.8)), width, cv2.LINE_AA, sh)
    return 1.0 - np.clip(opacity, 0.0, 1.0)


def apply_sensor(irradiance: np.ndarray, sensor: SensorParams, rng: np.random.Generator,
                 pixel_m: float | None = None) -> np.ndarray:
    """Irradiance in [0, 1] (H×W) → digital image (uint8 / uint16) of ``sensor.bit_depth`` bits.

    ``pixel_m`` is the true object-side pixel (default: the nominal pitch); it sets the blur in px.
    """
    import cv2

    # float32 throughout; cv2's stubs type its filters' results as any integer or floating array
    img: np.ndarray = np.asarray(irradiance, dtype=np.float32)
    h, w = img.shape
    pixel_m = sensor.pixel_pitch_m if pixel_m is None else pixel_m
    if sensor.dust_count > 0 or sensor.scratch_count > 0:
        img = img * dust_map(h, w, sensor.dust_count, sensor.scratch_count, rng)
    sigma, rdisk = blur_sigma_px(sensor, pixel_m)
    if rdisk > 0.25:
        img = cv2.filter2D(img, -1, _disk_kernel(rdisk), borderType=cv2.BORDER_REFLECT)
    if sigma > 0.05:
        img = cv2.GaussianBlur(img, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    # mean electrons: illumination (vignetting) × exposure × full well, folded into one cached map;
    # the blurred irradiance of non-negative inputs is non-negative, no clip needed
    lam = img * _electron_map(h, w, sensor.vignetting, sensor.exposure * sensor.full_well_e)
    # shot + read noise as ONE Gaussian of variance λ + σ_read² where λ ≥ 100 e⁻ (the sum of two
    # independent Gaussians; one draw instead of two), exact Poisson + Gaussian read noise below.
    # In-place arithmetic: a 3 Mpx frame is memory-bound, each temporary costs ~3 ms.
    e = rng.standard_normal(lam.shape, dtype=np.float32)
    sd = lam + np.float32(sensor.read_noise_e ** 2)
    np.sqrt(sd, out=sd)
    e *= sd
    e += lam
    low = lam < 100.0
    if low.any():
        nl = int(np.count_nonzero(low))
        e[low] = (rng.poisson(lam[low]).astype(np.float32)
                  + np.float32(sensor.read_noise_e) * rng.standard_normal(nl, dtype=np.float32))
    np.clip(e, 0.0, sensor.full_well_e, out=e)  # saturation at the full well; no negative charge
    e *= np.float32(sensor.max_dn / sensor.full_well_e)
    np.rint(e, out=e)
    return e.astype(sensor.dtype)


@lru_cache(maxsize=4)
def _electron_map(h: int, w: int, vignetting: float, electrons_full: float) -> np.ndarray:
    m = vignetting_map(h, w, vignetting) * np.float32(electrons_full)
    m.flags.writeable = False
    return m
