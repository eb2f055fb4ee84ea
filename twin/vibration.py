"""The CCD microscope's vibration relative to the disk: floor-borne vibration through its stand.

The microscope (a CCD camera and its optics on a stand clamped to the bench's table, looking at
the disk edge through the hole opposite the head, Jia 2019 sec. 4.2) and the spindle carrying the
disk stand on the same table. The table follows the floor (no isolation); the spindle follows the
table rigidly (its radial modes are at ~1.6 kHz, twin/physics.py), the stand does not: it is a
base-excited oscillator whose mass (camera, optics, arm) moves relative to its base. That relative
motion, in the image plane, moves the disk as the camera sees it.

Model (each step a textbook result, computed here with scipy/numpy):

- **Floor (table) vibration: a generic vibration criterion** (Gordon 1991, "Generic criteria for
  vibration-sensitive equipment", Proc. SPIE 1619; Amick, Gendreau, Busch, Gordon 2005, "Evolving
  criteria for research facilities: I — vibration", Proc. SPIE 5933): the one-third-octave band
  RMS velocity v_b is at most the class's level, flat from ``floor_corner_frequency`` (8 Hz) to
  ``floor_high_frequency`` (80 Hz), constant acceleration below the corner (v_b ∝ 1/f) down to
  ``floor_low_frequency``; the criteria apply in each of the three axes. The floor is taken AT its
  class in every band (the largest spectrum the class admits). A band's mean square is the PSD
  times its width (one-third octave: B = (2^(1/6) − 2^(−1/6))·f = 0.2316·f, IEC 61260), so the
  velocity PSD is S_v(f) = v_b(f)²/B(f) and the acceleration PSD S_a = (2πf)²·S_v.
- **The stand: a base-excited single-degree-of-freedom oscillator** (natural frequency f_n,
  damping ratio ζ; Thomson & Dahleh, *Theory of Vibration with Applications*, sec. 3.5; Harris'
  *Shock and Vibration Handbook*, ch. 2): the mass's displacement relative to its base per base
  acceleration is H(f) = −1/((2π)²·(f_n² − f² + 2jζ·f_n·f)); the relative displacement's variance
  σ² = ∫ S_a(f)·|H(f)|² df (integrated by ``scipy.integrate.quad`` over the criterion's band).
  For a locally white input it is Miles' equation (Miles 1954, J. Aeronaut. Sci. 21, 753):
  σ² = S_a(f_n)·Q/(32π³f_n³), Q = 1/(2ζ) (``miles_relative_rms``, the test's closed form).
- **The exposure averages the motion**: the sensor integrates the image over its exposure time T,
  so the frame shows the disk at the motion's mean over T, whose spectrum is the motion's times
  sinc²(f·T) (a box average's transfer, ``numpy.sinc``); for a lightly damped mode
  σ_frame ≈ σ·|sinc(f_n·T)|. The rest of the motion (σ² − σ_frame²) blurs the frame during the
  exposure; it is not rendered (see Validity).
- **Frames are independent**: the mode's correlation time is 1/(ζ·ω_n) (the envelope of the
  autocorrelation, ``autocorrelation``); frames taken seconds apart (jia2019: 1.35 s, against
  0.09 s) see uncorrelated samples, so each frame's displacement is an independent normal draw
  (radial and tangential: a round column sways alike in both, independently), from a stream keyed
  by the runner's step (reproducible and resumable bit for bit).

Validity: linear, stationary, Gaussian floor motion; the stand a single mode per in-plane axis
(higher modes and the arm's own bending are stiffer); the disk rigid with the table; motion along
the optical axis (focus) not modelled; the within-exposure motion (σ² − σ_frame²) is a sub-pixel
blur next to the optics' own (symmetric, so it does not move the edge's 50 % point) and is not
rendered — the frame is the instantaneous image of the disk at the exposure's mean displacement
(quasi-static in the frame).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import integrate

#: one-third-octave band width over its centre frequency (base-2 bands, IEC 61260-1)
THIRD_OCTAVE_BW = 2.0 ** (1.0 / 6.0) - 2.0 ** (-1.0 / 6.0)


def criterion_velocity(f: np.ndarray | float, v_band: float, f_corner: float, f_lo: float, f_hi: float) -> np.ndarray:
    """One-third-octave band RMS velocity (m/s) of a generic vibration criterion at frequency f:
    flat ``v_band`` on [f_corner, f_hi], constant acceleration (∝ 1/f) on [f_lo, f_corner), 0
    outside [f_lo, f_hi] (the band over which the criterion is stated)."""
    f = np.asarray(f, dtype=float)
    v = np.where(f >= f_corner, v_band, v_band * f_corner / np.maximum(f, 1e-300))
    return np.where((f >= f_lo) & (f <= f_hi), v, 0.0)


def acceleration_psd(f: np.ndarray | float, v_band: float, f_corner: float, f_lo: float, f_hi: float) -> np.ndarray:
    """One-sided acceleration PSD ((m/s²)²/Hz) of a floor at the criterion in every band:
    S_a = (2πf)²·v_b(f)²/(0.2316·f)."""
    f = np.asarray(f, dtype=float)
    v = criterion_velocity(f, v_band, f_corner, f_lo, f_hi)
    return (2.0 * math.pi * f) ** 2 * v**2 / (THIRD_OCTAVE_BW * np.maximum(f, 1e-300))


def relative_receptance_sq(f: np.ndarray | float, f_n: float, zeta: float) -> np.ndarray:
    """|H(f)|², H the base-excited oscillator's relative displacement per base acceleration (s²)."""
    f = np.asarray(f, dtype=float)
    return 1.0 / ((2.0 * math.pi) ** 4 * ((f_n**2 - f**2) ** 2 + (2.0 * zeta * f_n * f) ** 2))


def exposure_gain_sq(f: np.ndarray | float, exposure_s: float) -> np.ndarray:
    """|transfer|² of the mean over an exposure of ``exposure_s``: sinc²(f·T) (numpy's normalised sinc)."""
    return np.sinc(np.asarray(f, dtype=float) * exposure_s) ** 2


def miles_relative_rms(s_a: float, f_n: float, zeta: float) -> float:
    """Miles' equation for the relative displacement (m RMS) under a white base acceleration of
    one-sided PSD ``s_a`` ((m/s²)²/Hz): sqrt(s_a·Q/(32π³f_n³)), Q = 1/(2ζ)."""
    return math.sqrt(s_a * (1.0 / (2.0 * zeta)) / (32.0 * math.pi**3 * f_n**3))


def cantilever_frequency(youngs_modulus: float, diameter: float, length: float, tip_mass: float,
                         density: float) -> float:
    """First bending frequency (Hz) of a round column clamped at its foot with a mass at its top:
    k = 3EI/L³, I = πd⁴/64, effective mass M + (33/140)·m_column (Rayleigh's method with the static
    deflection shape, the classical result; Thomson & Dahleh, *Theory of Vibration with
    Applications*, ch. 2)."""
    inertia = math.pi * diameter**4 / 64.0
    k = 3.0 * youngs_modulus * inertia / length**3
    m_col = density * math.pi * diameter**2 / 4.0 * length
    return math.sqrt(k / (tip_mass + 33.0 / 140.0 * m_col)) / (2.0 * math.pi)


@dataclass(frozen=True)
class StandVibration:
    """The microscope stand's response to a floor at a generic vibration criterion (SI units)."""

    floor_velocity: float            # m/s, one-third-octave band RMS (VC-A: 50e-6)
    stand_frequency: float           # Hz
    stand_damping: float             # ζ
    exposure_time: float = 0.0       # s
    floor_corner_frequency: float = 8.0
    floor_low_frequency: float = 4.0
    floor_high_frequency: float = 80.0
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        if not 0.0 < self.floor_low_frequency <= self.floor_corner_frequency <= self.floor_high_frequency:
            raise ValueError("vibration: need 0 < floor_low_frequency ≤ floor_corner_frequency ≤ floor_high_frequency, "
                             f"got {self.floor_low_frequency}, {self.floor_corner_frequency}, {self.floor_high_frequency} Hz")
        if not 0.0 < self.stand_damping < 1.0:
            raise ValueError(f"vibration.microscope_stand_damping: expected 0 < ζ < 1, got {self.stand_damping}")
        if self.stand_frequency <= 0.0 or self.floor_velocity < 0.0 or self.exposure_time < 0.0:
            raise ValueError("vibration: stand frequency must be positive, floor velocity and exposure time ≥ 0")

    @classmethod
    def from_section(cls, d: Any) -> "StandVibration | None":
        """From the SI-parsed optional ``[vibration]`` section; None when absent or the floor is still."""
        if not d or not float(d.get("floor_velocity", 0.0) or 0.0):
            return None
        return cls(floor_velocity=float(d["floor_velocity"]), stand_frequency=float(d["microscope_stand_frequency"]),
                   stand_damping=float(d["microscope_stand_damping"]), exposure_time=float(d["exposure_time"]),
                   floor_corner_frequency=float(d["floor_corner_frequency"]),
                   floor_low_frequency=float(d["floor_low_frequency"]),
                   floor_high_frequency=float(d["floor_high_frequency"]))

    # ------------------------------------------------------------------ spectra
    def floor_psd(self, f: np.ndarray | float) -> np.ndarray:
        return acceleration_psd(f, self.floor_velocity, self.floor_corner_frequency, self.floor_low_frequency,
                                self.floor_high_frequency)

    def motion_psd(self, f: np.ndarray | float, exposure_s: float | None = None) -> np.ndarray:
        """One-sided PSD (m²/Hz) of the stand's relative displacement per axis, averaged over
        ``exposure_s`` (default: the exposure time; 0: instantaneous)."""
        T = self.exposure_time if exposure_s is None else exposure_s
        return (self.floor_psd(f) * relative_receptance_sq(f, self.stand_frequency, self.stand_damping)
                * exposure_gain_sq(f, T))

    def _integral(self, fn: Any, key: str) -> float:
        if key not in self._cache:
            lo, hi = self.floor_low_frequency, self.floor_high_frequency
            pts = sorted({p for p in (self.floor_corner_frequency, self.stand_frequency) if lo < p < hi})
            edges = [lo, *pts, hi]
            total = 0.0
            for a, b in zip(edges[:-1], edges[1:]):
                total += integrate.quad(fn, a, b, limit=400, epsabs=0.0, epsrel=1e-10)[0]
            self._cache[key] = total
        return self._cache[key]

    def rms(self, exposure_s: float | None = None) -> float:
        """Relative displacement RMS per axis (m): sqrt(∫ S_a·|H|²·sinc²(f·T) df) over the band."""
        T = self.exposure_time if exposure_s is None else float(exposure_s)
        return math.sqrt(self._integral(lambda f: float(self.motion_psd(f, T)), f"var:{T!r}"))

    @property
    def frame_rms(self) -> float:
        """Per axis, the displacement a frame shows (the exposure's mean), m RMS."""
        return self.rms()

    @property
    def blur_rms(self) -> float:
        """Per axis, the motion within one exposure about its mean (not rendered), m RMS."""
        return math.sqrt(max(self.rms(0.0) ** 2 - self.frame_rms**2, 0.0))

    @property
    def correlation_time(self) -> float:
        """The envelope time constant of the mode's autocorrelation, 1/(ζ·ω_n) (s)."""
        return 1.0 / (self.stand_damping * 2.0 * math.pi * self.stand_frequency)

    def autocorrelation(self, tau: float) -> float:
        """Correlation coefficient of two frames ``tau`` apart (Wiener–Khinchin:
        ∫ S(f)·cos(2πfτ) df / ∫ S(f) df, with the exposure-averaged spectrum)."""
        lo, hi = self.floor_low_frequency, self.floor_high_frequency
        pts = sorted({p for p in (self.floor_corner_frequency, self.stand_frequency) if lo < p < hi})
        edges = [lo, *pts, hi]
        num = 0.0
        for a, b in zip(edges[:-1], edges[1:]):
            num += integrate.quad(lambda f: float(self.motion_psd(f)), a, b, weight="cos",
                                  wvar=2.0 * math.pi * float(tau), limit=2000, epsabs=0.0, epsrel=1e-10)[0]
        return num / self.frame_rms**2

    def miles_frame_rms(self) -> float:
        """The closed form: Miles' equation at the floor's PSD at f_n, times |sinc(f_n·T)|."""
        return (miles_relative_rms(float(self.floor_psd(self.stand_frequency)), self.stand_frequency,
                                   self.stand_damping) * abs(float(np.sinc(self.stand_frequency * self.exposure_time))))

    # ------------------------------------------------------------------ samples
    def sample(self, rng: np.random.Generator) -> tuple[float, float]:
        """One frame's (radial, tangential) displacement of the microscope relative to the disk (m)."""
        r, t = rng.normal(0.0, self.frame_rms, 2)
        return float(r), float(t)

    def truth(self) -> dict[str, float]:
        return {"floor_velocity_um_s": self.floor_velocity * 1e6, "stand_frequency_hz": self.stand_frequency,
                "stand_damping": self.stand_damping, "exposure_time_ms": self.exposure_time * 1e3,
                "rms_um": self.rms(0.0) * 1e6, "frame_rms_um": self.frame_rms * 1e6,
                "blur_rms_um": self.blur_rms * 1e6, "correlation_time_s": self.correlation_time}
