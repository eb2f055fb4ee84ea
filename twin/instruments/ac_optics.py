"""The autocollimator's optics: its reading from where the returned beam lands on the detector.

An autocollimator (TRIOPTICS TriAngle US 300-57: objective focal length 300 mm, 57 mm aperture;
MÖLLER-WEDEL ELCOMAT 3000: 300 mm) sends a collimated beam to the polygon face; a face turned by v
returns it turned by 2v (law of reflection), and the objective images the reticle in its focal
plane at

    s = f·tan(2v)                                   (ideal focal plane, per axis)

(Malacara, *Optical Shop Testing*, 3rd ed., sec. 1.5). The firmware inverts that law with its
NOMINAL focal length: v_read = ½·atan(s / f_nom). An ideal instrument reads v exactly. What this
module adds, each a physical cause with its own parameter (none of them the analysis's
"gain + quadratic" template, analysis/effects/ac_scale.py):

- a focal-length error δf (tube temperature, refocus after service: f = f_nom·(1 + δf)): the
  firmware's f_nom then scales every reading by (1 + δf) to first order;
- a detector tilted by τ about its y axis (the axis across the measuring direction x), through
  the focal point. The chief ray of direction (1, t_x, t_y) in (axis, x, y) meets the plane
  {(f + s_x·sinτ, s_x·cosτ, s_y)} at

      s_x = f·t_x / (cosτ − sinτ·t_x),    s_y = f·t_y / (1 − tanτ·t_x)

  (intersection of a line and a plane, exact): a scale 1/cosτ and an EVEN non-linearity,
  2·tanτ·v² to second order (the x reading is (ρ·v + 2ρ·tanτ·v² + O(v³)) with ρ = (1 + δf)/cosτ;
  tests/twin/test_ac_optics.py checks these coefficients);
- third-order radial (Seidel) distortion of the objective, s_d = s·(1 + k₁·|s|²/f_nom²)
  (Born & Wolf, *Principles of Optics*, 7th ed., sec. 5.3 and 5.5: the distortion term of the
  primary aberrations, the image height's cubic term): ODD, the x reading gains 4·k₁·v³.

The tan law itself is exact here; a firmware that linearised it (v = s/(2f)) would add the odd
(4/3)·v³ (0.03″ at ±1000″): the firmware modelled inverts with atan, as the instruments'
calibrated look-up does.

Validity: geometrical optics of the chief ray (the spot's centroid; the blur of a tilted detector
moves the centroid by far less than the tilt's own term at the apertures used), a rigid tube, a
plane detector. Everything is evaluated exactly (no series), so large parameters (the hidden
suite's stress values) give the full non-linearity, not just its leading terms.

Legacy keys: ``[hidden.ac_scale] gain`` / ``quadratic_per_arcsec`` (a reading v·(1 + g) + q·v²/1″
at small angles) map to the focal-length error and tilt with those first- and second-order
coefficients: ρ = (1 + δf)/cosτ = 1 + g and 2ρ·tanτ = q/1″ (``from_coefficients``). A real
autocollimator of 0.05–0.25″ accuracy over ±1000″ has |q| ≲ 1e-7/″ (q·v² ≤ 0.1″ at 1000″), i.e.
tanτ = q/(2·1″) ≈ 0.01: τ ≲ 0.6° (an earlier draft said 0.01°, reading q as per radian); the
suite's q = 1e-4/″ needs τ ≈ 84° (and δf ≈ −0.9): a stress test of the analysis, not a real
instrument. The legacy keys described the X reading only, so their optics act on X alone (the Y
axis of such an instrument, at f ≈ 0.1·f_nom, would read a tenth of the face's tilt); the physical
keys act on both axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from benchtwin.units import ARCSEC

#: objective focal length of the papers' autocollimators (TriAngle US 300-57, ELCOMAT 3000), m
FOCAL_LENGTH_M = 0.3


@dataclass(frozen=True)
class AutocollimatorOptics:
    """Objective, detector and firmware of the autocollimator (both axes; the tilt is about the
    detector's y axis, so it bends the x (measuring) axis)."""

    focal_length_error: float = 0.0   # δf: f = f_nom·(1 + δf)
    detector_tilt_rad: float = 0.0    # τ, about the detector's y axis
    distortion_k1: float = 0.0        # k₁, at the normalised field height s/f_nom
    focal_length_m: float = FOCAL_LENGTH_M   # f_nom, what the firmware uses
    x_only: bool = False              # the Y axis reads ideally (the legacy coefficients' X-only mapping)

    def __post_init__(self) -> None:
        if not self.focal_length_m > 0:
            raise ValueError(f"autocollimator optics: focal length must be > 0, got {self.focal_length_m}")
        if not self.focal_length_error > -1.0:
            raise ValueError(f"autocollimator optics: focal_length_error must be > -1, got {self.focal_length_error}")
        if not abs(self.detector_tilt_rad) < 0.5 * math.pi:
            raise ValueError(f"autocollimator optics: |detector tilt| must be < 90°, got {self.detector_tilt_rad} rad")

    @classmethod
    def from_coefficients(cls, gain: float, quadratic_per_arcsec: float,
                          focal_length_m: float = FOCAL_LENGTH_M, distortion_k1: float = 0.0) -> "AutocollimatorOptics":
        """The focal-length error and detector tilt whose x reading is v·(1 + gain) + q·v²/1″ to
        second order in v: ρ = (1 + δf)/cosτ = 1 + gain, 2ρ·tanτ = q/1″."""
        rho = 1.0 + float(gain)
        tilt = math.atan(float(quadratic_per_arcsec) / ARCSEC / (2.0 * rho))
        return cls(focal_length_error=rho * math.cos(tilt) - 1.0, detector_tilt_rad=tilt,
                   distortion_k1=float(distortion_k1), focal_length_m=float(focal_length_m), x_only=True)

    @property
    def ideal(self) -> bool:
        return self.focal_length_error == 0.0 and self.detector_tilt_rad == 0.0 and self.distortion_k1 == 0.0

    def detector_position_m(self, vx_rad: float, vy_rad: float) -> tuple[float, float]:
        """Where the returned beam of a face turned by (vx, vy) lands on the detector, along its
        (tilted) x and y axes, distortion included."""
        f = self.focal_length_m * (1.0 + self.focal_length_error)
        tx, ty = math.tan(2.0 * float(vx_rad)), math.tan(2.0 * float(vy_rad))
        tau = self.detector_tilt_rad
        den = math.cos(tau) - math.sin(tau) * tx
        if den <= 0.0:
            raise ValueError(f"autocollimator optics: the beam at {vx_rad / ARCSEC:g}″ misses the tilted detector")
        sx = f * tx / den
        sy = f * ty * math.cos(tau) / den
        r2 = (sx * sx + sy * sy) / (self.focal_length_m * self.focal_length_m)
        d = 1.0 + self.distortion_k1 * r2
        return sx * d, sy * d

    def reading_rad(self, vx_rad: float, vy_rad: float = 0.0) -> tuple[float, float]:
        """The firmware's angles ½·atan(s / f_nom) per axis (an ideal instrument reads (vx, vy)
        exactly, without the tan/atan round trip)."""
        if self.ideal:
            return float(vx_rad), float(vy_rad)
        if self.x_only:
            sx, _ = self.detector_position_m(vx_rad, 0.0)
            return 0.5 * math.atan(sx / self.focal_length_m), float(vy_rad)
        sx, sy = self.detector_position_m(vx_rad, vy_rad)
        return 0.5 * math.atan(sx / self.focal_length_m), 0.5 * math.atan(sy / self.focal_length_m)

    def small_angle_coefficients(self) -> tuple[float, float, float]:
        """(c1, c2, c3) of the x reading c1·v + c2·v² + c3·v³ (v in rad, vy = 0) from the series of
        the exact law (for tests and truth/): c1 = ρ, c2 = 2ρ·tanτ, c3 = 4ρ·tan²τ + 4ρ·k₁·ρ²cos²τ
        − (4/3)(ρ³ − ρ) with ρ = (1 + δf)/cosτ."""
        rho = (1.0 + self.focal_length_error) / math.cos(self.detector_tilt_rad)
        t = math.tan(self.detector_tilt_rad)
        # s/f_nom = ρ·(x + t·x² + t²·x³) with x = tan 2v = 2v + (8/3)v³; distortion adds
        # k₁·(s/f_nom)³; the firmware's ½·atan(u) = u/2 − u³/6.
        c1 = rho
        c2 = 2.0 * rho * t
        c3 = 4.0 * rho * t * t + 4.0 * self.distortion_k1 * rho**3 + (4.0 / 3.0) * (rho - rho**3)
        return c1, c2, c3

    def truth(self) -> dict:
        c1, c2, c3 = self.small_angle_coefficients()
        return {"focal_length_nominal_m": self.focal_length_m, "focal_length_error": self.focal_length_error,
                "detector_tilt_rad": self.detector_tilt_rad, "distortion_k1": self.distortion_k1,
                "x_reading_coefficients": {"c1": c1, "c2_per_rad": c2, "c3_per_rad2": c3,
                                           "c2_per_arcsec": c2 * ARCSEC}}


__all__ = ["AutocollimatorOptics", "FOCAL_LENGTH_M"]
