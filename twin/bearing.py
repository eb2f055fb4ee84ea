"""A rolling bearing as a set of balls between two wavy races: Hertzian contact forces on the shaft.

Theory, and where each piece comes from:

- Kinematics (Harris & Kotzalas, *Rolling Bearing Analysis*, 5th ed., vol. 1, ch. 7): with the
  outer race fixed and the inner race turning with the shaft, the cage (and every ball centre)
  turns at the kinematic ratio  rho = (1 - Dw·cos(a)/Dpw)/2  of the shaft angle (pure rolling).
  Ball j sits at lab azimuth  psi_j = phi_cage + 2·pi·j/Z.
- Contact (Harris & Kotzalas vol. 1 ch. 6, Hertz 1881; closed form of Hamrock & Brewe 1983,
  J. Lubr. Technol. 105, 171, "Simplified solution for stresses and deformations"): a ball pressed
  on a race by a normal load Q approaches it by  delta = F·[(9/(2·E·R))·(Q/(pi·k·E'))^2]^(1/3)
  with the ellipticity k = 1.0339·(Ry/Rx)^0.636, E = 1.0003 + 0.5968·Rx/Ry,
  F = 1.5277 + 0.6023·ln(Ry/Rx) (elliptic integrals, < 3 % error for 1 <= Ry/Rx <= 100) and the
  curvature radii of the ball/race pair (Hamrock, *Fundamentals of Fluid Film Lubrication*,
  ch. 24): inner Rx = Dw·(Dpw - Dw·cos a)/(2·Dpw), Ry = f_i·Dw/(2·f_i - 1); outer with + cos a and
  f_o. Inner and outer contact in series give the load-deflection law  Q = K_n·delta^1.5  with
  K_n = (C_i + C_o)^(-3/2), C = delta/Q^(2/3) of each contact (Harris eq. 7.7 form).
- Preload: an axial preload F_a of an angular-contact bearing (the shaft's pair is preloaded
  back to back; the axial position is held by the pair) loads every ball with
  Q_0 = F_a/(Z·sin a), i.e. an initial normal approach  delta_0 = (Q_0/K_n)^(2/3).
- Load distribution (Harris vol. 1 ch. 7, Jones' quasi-static method reduced to the radial
  plane): a radial displacement u of the journal (inner race) relative to the housing (outer
  race) and the local interferences w_j change ball j's approach to
  delta_j = delta_0 + cos(a)·(u·e_j) + w_j,   Q_j = K_n·max(delta_j, 0)^1.5,
  and the balls push the shaft with  F = -cos(a)·sum_j Q_j·e_j  (e_j the unit vector to ball j).
  A ball that loses contact (delta_j <= 0) carries nothing: the law is the full nonlinear one,
  no linearisation.
- Waviness and ball-diameter variation (Wardle 1988, Proc IMechE 202C, 305; Yhland 1992, J.
  Tribology 114, 348): inner-race waviness w_i(phi) (phi in the shaft frame), outer-race
  waviness w_o(psi) (lab frame) as sums of lobes a_k·cos(k·x - p_k), each a radial deviation of
  the rolling path towards the balls, and a per-ball diameter deviation dD_j (riding with the
  cage) give  w_j = cos(a)·(w_i(psi_j - theta) + w_o(psi_j)) + dD_j.  NOTHING here selects
  orders: the sum over the balls at their actual azimuths does. For equal balls the linear part of
  sum_j cos(k·psi_j + c)·e_j vanishes unless k = q·Z +- 1 — Wardle's rule (inner- and outer-race
  orders qZ +- 1 move the centre, at frequencies qZ·(1 - rho) +- 1 and qZ·rho cycles per shaft
  revolution; ball-diameter variation at the cage frequency rho). tests/twin/test_bearing.py
  checks that the rule emerges from these sums.

Grades (amplitudes per order): ``RACE_GRADES`` maps an ISO 492 tolerance class to the radial
run-out limits of the rings (ISO 492:2014, inner ring Kia for 18 < d <= 30 mm, outer ring Kea for
30 < D <= 50 mm, µm) and to a WAVINESS level (ASSUMPTION: ISO 492 does not limit waviness; the
order-2 amplitude below is about a tenth of Kia, falling as 1/k with the order, the shape of the
spectra measured by Yhland 1992; the actual once-per-revolution eccentricity of a mounted raceway
is taken as 10 % of Kia/2: selected, matched bearings sit far inside the class limit).
``BALL_GRADES``: ISO 3290-1 ball grades, lot diameter variation V_DWL (µm): the balls of one bearing
are drawn uniformly within +- V_DWL/2.

Validity: elastic Hertz contact of smooth steel bodies (no lubricant film, whose stiffness would
be in series, no centrifugal or gyroscopic ball loads: below ~1000 rpm they are < 1 % of Q_0 for
these balls), rigid rings, axial position and contact angle fixed at their preloaded values
(the 5-DOF Jones model would let them vary; the change of a by a 0.1 µm radial motion is
< 1e-4 rad), waviness << delta_0 (checked: the model warns nothing but stays exact when a ball
unloads). The force on the shaft is evaluated at the cage angle the bench's path gives
(``twin/physics.py``: cage angle = integral of the shaft's rotation times rho, plus a seeded
random slip per start/stop).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

TWO_PI = 2.0 * math.pi

#: bearing steel (AISI 52100): Young's modulus (Pa) and Poisson's ratio (Harris vol. 1, table 5.x)
STEEL_E_PA = 208e9
STEEL_NU = 0.3

#: ISO 492 class -> (Kia inner-ring radial run-out µm, Kea outer-ring µm, order-2 waviness µm)
#: run-out: ISO 492:2014 tables for d 18–30 mm / D 30–50 mm; waviness: ASSUMPTION (see docstring)
RACE_GRADES: dict[str, tuple[float, float, float]] = {
    "P0": (13.0, 20.0, 1.0),
    "P6": (8.0, 10.0, 0.6),
    "P5": (4.0, 7.0, 0.3),
    "P4": (3.0, 5.0, 0.2),
    "P2": (2.5, 2.5, 0.1),
}
#: ISO 3290-1 ball grade -> lot diameter variation V_DWL (µm)
BALL_GRADES: dict[str, float] = {"G3": 0.13, "G5": 0.25, "G10": 0.5, "G16": 0.8, "G20": 1.0, "G28": 1.4}
#: waviness orders generated per race (Wardle: only q·Z ± 1 move the centre; the others are
#: generated anyway, so the selection is the physics', not ours)
MAX_WAVINESS_ORDER = 40
#: fraction of Kia/2 taken as the mounted raceway's actual once-per-revolution eccentricity
RUNOUT_FRACTION = 0.1


@dataclass(frozen=True)
class BallBearingGeometry:
    """The physical parameters of one angular-contact ball bearing (SI)."""

    balls: int                  # Z
    ball_diameter_m: float      # Dw
    pitch_diameter_m: float     # Dpw
    contact_angle_rad: float    # a (nominal, under preload)
    preload_N: float            # axial preload F_a
    groove_inner: float = 0.52  # f_i = groove radius / Dw (Harris: 0.515–0.53 typical)
    groove_outer: float = 0.53
    E_Pa: float = STEEL_E_PA
    nu: float = STEEL_NU

    def __post_init__(self):
        if self.balls < 3:
            raise ValueError("a ball bearing needs at least 3 balls")
        if not 0 < self.ball_diameter_m < self.pitch_diameter_m:
            raise ValueError("ball diameter must be positive and smaller than the pitch diameter")
        if not 0 < self.contact_angle_rad < 0.5 * math.pi:
            raise ValueError("contact angle must be in (0°, 90°): an angular-contact bearing")
        if self.preload_N <= 0:
            raise ValueError("preload must be > 0 N: an unloaded ball set has no stiffness")
        if not (0.5 < self.groove_inner and 0.5 < self.groove_outer):
            raise ValueError("groove radius ratios f = r/Dw must be > 0.5")
        # Balls must fit on the pitch circle.
        if self.balls * self.ball_diameter_m >= math.pi * self.pitch_diameter_m:
            raise ValueError("the balls do not fit on the pitch circle (Z·Dw >= pi·Dpw)")

    @property
    def cage_ratio(self) -> float:
        """rho = (1 - Dw cos a / Dpw)/2: cage angle per shaft angle, outer race fixed (Harris ch. 7)."""
        return 0.5 * (1.0 - self.ball_diameter_m * math.cos(self.contact_angle_rad) / self.pitch_diameter_m)


def _hertz_C(Rx: float, Ry: float, E_eff: float) -> float:
    """delta / Q^(2/3) of one elliptical contact (Hamrock & Brewe 1983)."""
    k = 1.0339 * (Ry / Rx) ** 0.6360
    Ecal = 1.0003 + 0.5968 * Rx / Ry
    Fcal = 1.5277 + 0.6023 * math.log(Ry / Rx)
    R = 1.0 / (1.0 / Rx + 1.0 / Ry)
    return Fcal * (9.0 / (2.0 * Ecal * R)) ** (1.0 / 3.0) * (1.0 / (math.pi * k * E_eff)) ** (2.0 / 3.0)


def load_deflection_constant(g: BallBearingGeometry) -> float:
    """K_n (N/m^1.5) of Q = K_n·delta^1.5 for one ball between both races (contacts in series)."""
    d, dm, ca = g.ball_diameter_m, g.pitch_diameter_m, math.cos(g.contact_angle_rad)
    E_eff = 2.0 / (2.0 * (1.0 - g.nu**2) / g.E_Pa)          # E' of two equal steel bodies
    Rx_i = d * (dm - d * ca) / (2.0 * dm)
    Rx_o = d * (dm + d * ca) / (2.0 * dm)
    Ry_i = g.groove_inner * d / (2.0 * g.groove_inner - 1.0)
    Ry_o = g.groove_outer * d / (2.0 * g.groove_outer - 1.0)
    C = _hertz_C(Rx_i, Ry_i, E_eff) + _hertz_C(Rx_o, Ry_o, E_eff)
    return C ** -1.5


def preload_approach_m(g: BallBearingGeometry, Kn: float | None = None) -> float:
    """delta_0: each ball's normal approach under the axial preload, Q_0 = F_a/(Z sin a)."""
    Kn = load_deflection_constant(g) if Kn is None else Kn
    Q0 = g.preload_N / (g.balls * math.sin(g.contact_angle_rad))
    return (Q0 / Kn) ** (2.0 / 3.0)


def radial_stiffness_N_m(g: BallBearingGeometry) -> float:
    """Linearised radial stiffness about the preloaded, centred state: (3/4)·Z·K_n·delta_0^½·cos²a
    (d/du of the summed contact forces; Z >= 3). For the docs and the tests: the bench itself
    uses the full nonlinear forces."""
    Kn = load_deflection_constant(g)
    d0 = preload_approach_m(g, Kn)
    return 0.75 * g.balls * Kn * math.sqrt(d0) * math.cos(g.contact_angle_rad) ** 2


def lobes_value(k: np.ndarray, a: np.ndarray, p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """sum_k a_k·cos(k·x - p_k) at every x (x any shape)."""
    x = np.asarray(x, dtype=float)
    if k.size == 0:
        return np.zeros_like(x)
    return np.tensordot(a, np.cos(np.multiply.outer(k, x) - p.reshape((-1,) + (1,) * x.ndim)), axes=1)


@dataclass
class BallSet:
    """One bearing's balls and races: geometry plus the generated imperfections (all SI)."""

    geometry: BallBearingGeometry
    inner: tuple[np.ndarray, np.ndarray, np.ndarray] = field(default_factory=lambda: (np.zeros(0),) * 3)
    outer: tuple[np.ndarray, np.ndarray, np.ndarray] = field(default_factory=lambda: (np.zeros(0),) * 3)
    ball_dd_m: np.ndarray | None = None      # per-ball diameter deviation dD_j (Z,)

    def __post_init__(self):
        g = self.geometry
        self.Kn = load_deflection_constant(g)
        self.delta0_m = preload_approach_m(g, self.Kn)
        self.cos_a = math.cos(g.contact_angle_rad)
        self.Z = int(g.balls)
        self.rho = g.cage_ratio
        self._slots = TWO_PI * np.arange(self.Z) / self.Z
        dd = np.zeros(self.Z) if self.ball_dd_m is None else np.asarray(self.ball_dd_m, dtype=float)
        if dd.shape != (self.Z,):
            raise ValueError("ball_dd_m must have one value per ball")
        self.ball_dd_m = self._dd = dd

        # Each race's lobes at the Z balls as one complex product: the balls sit at
        # x_j = x_0 + 2·pi·j/Z, so sum_k a_k cos(k x_j - p_k) = Re(sum_k W[j, k]·c_k·e^(i k x_0)) with
        # c_k = a_k e^(-i p_k) and the constant W[j, k] = e^(2·pi·i·j·k/Z). Exact (no truncation);
        # the bench evaluates it at every Newton iteration of every pose, hence the care.
        self._ci, self._ki = self._dense(self.inner)
        self._co, self._ko = self._dense(self.outer)
        j = np.arange(self.Z)[:, None]
        self._Wi = np.exp(2j * np.pi * j * self._ki[None, :] / self.Z)
        self._Wo = np.exp(2j * np.pi * j * self._ko[None, :] / self.Z)

    @staticmethod
    def _dense(lobes) -> tuple[np.ndarray, np.ndarray]:
        k, a, p = (np.asarray(v, dtype=float) for v in lobes)
        if k.size and (np.any(k < 0) or np.any(k != np.round(k))):
            raise ValueError("race lobe orders must be integers >= 0")
        return a * np.exp(-1j * p), k

    def ball_azimuths(self, cage_rad: float) -> np.ndarray:
        return cage_rad + self._slots

    def interference_m(self, theta_rad: float, cage_rad: float) -> np.ndarray:
        """w_j: extra normal approach of each ball from waviness and diameter deviation."""
        w = np.zeros(self.Z, dtype=complex)
        if self._ki.size:   # inner race: ball j at shaft-frame angle psi_j - theta
            w += self._Wi @ (self._ci * np.exp(1j * self._ki * (cage_rad - theta_rad)))
        if self._ko.size:   # outer race: ball j at lab angle psi_j
            w += self._Wo @ (self._co * np.exp(1j * self._ko * cage_rad))
        return self.cos_a * w.real + self._dd

    def force_on_shaft_N(self, u_m: np.ndarray, theta_rad: float, cage_rad: float) -> np.ndarray:
        """Radial force (x, y) of the ball set on the journal displaced by u (inner race relative
        to outer race), shaft angle theta, cage angle phi_cage (lab frame)."""
        psi = cage_rad + self._slots
        c, s = np.cos(psi), np.sin(psi)
        delta = self.delta0_m + self.cos_a * (u_m[0] * c + u_m[1] * s) + self.interference_m(theta_rad, cage_rad)
        Q = self.Kn * np.maximum(delta, 0.0) ** 1.5
        return -self.cos_a * np.array([Q @ c, Q @ s])

    def force_and_stiffness(self, u_m: np.ndarray, theta_rad: float, cage_rad: float) -> tuple[np.ndarray, np.ndarray]:
        """The force of ``force_on_shaft_N`` and its stiffness −dF/du (2×2, N/m): the sum over the
        loaded balls of (3/2)·K_n·delta_j^½·cos²a·e_j·e_jᵀ (the Newton step of the bench's statics)."""
        psi = cage_rad + self._slots
        c, s = np.cos(psi), np.sin(psi)
        delta = self.delta0_m + self.cos_a * (u_m[0] * c + u_m[1] * s) + self.interference_m(theta_rad, cage_rad)
        dp = np.maximum(delta, 0.0)
        root = np.sqrt(dp)
        Q = self.Kn * dp * root
        k = 1.5 * self.Kn * root * self.cos_a**2
        F = -self.cos_a * np.array([Q @ c, Q @ s])
        kc, ks = k * c, k * s
        K = np.array([[kc @ c, kc @ s], [kc @ s, ks @ s]])
        return F, K

    def approaches_m(self, u_m: np.ndarray, theta_rad: float, cage_rad: float) -> np.ndarray:
        """delta_j: each ball's normal approach with the journal displaced by u (the preload's, the
        displacement's along the ball's contact direction, waviness and diameter deviation)."""
        psi = self.ball_azimuths(cage_rad)
        return (self.delta0_m + self.cos_a * (u_m[0] * np.cos(psi) + u_m[1] * np.sin(psi))
                + self.interference_m(theta_rad, cage_rad))

    def ball_loads_N(self, u_m: np.ndarray, theta_rad: float, cage_rad: float) -> np.ndarray:
        return self.Kn * np.maximum(self.approaches_m(u_m, theta_rad, cage_rad), 0.0) ** 1.5

    def kinematic_orders(self) -> dict[str, float]:
        """Frequencies (cycles per shaft revolution) at which the set's imperfections move the
        centre (Wardle 1988): cage rho, outer-race ball pass Z·rho, inner-race ball pass Z·(1 - rho)."""
        return {"cage": self.rho, "ball_pass_outer": self.Z * self.rho, "ball_pass_inner": self.Z * (1.0 - self.rho)}

    def truth(self) -> dict:
        g = self.geometry
        return {
            "balls": self.Z, "ball_diameter_m": g.ball_diameter_m, "pitch_diameter_m": g.pitch_diameter_m,
            "contact_angle_rad": g.contact_angle_rad, "preload_N": g.preload_N,
            "groove_inner": g.groove_inner, "groove_outer": g.groove_outer,
            "load_deflection_constant_N_m1_5": self.Kn, "preload_approach_m": self.delta0_m,
            "radial_stiffness_linearised_N_m": radial_stiffness_N_m(g), "cage_ratio": self.rho,
            "kinematic_orders_per_rev": self.kinematic_orders(),
            "inner_race_lobes": [{"order": int(k), "amplitude_m": float(a), "phase_rad": float(p)}
                                 for k, a, p in zip(*self.inner)],
            "outer_race_lobes": [{"order": int(k), "amplitude_m": float(a), "phase_rad": float(p)}
                                 for k, a, p in zip(*self.outer)],
            "ball_diameter_deviation_m": self._dd.tolist(),
        }


def generate_ball_set(g: BallBearingGeometry, race_grade: str, ball_grade: str,
                      rng: np.random.Generator, waviness_scale: float = 1.0) -> BallSet:
    """Imperfections of one bearing of the stated grades, drawn from ``rng``:
    inner race: order 1 (mounted eccentricity, RUNOUT_FRACTION·Kia/2) and orders 2…MAX with
    amplitude W2·(2/k)·U(0.5, 1.5); outer race: orders 2…MAX likewise (its order 1 is the housing
    position: a constant offset the axis average line absorbs); balls: dD_j ~ U(-V_DWL/2, V_DWL/2).
    Random phases. ``waviness_scale`` scales every race amplitude (design studies)."""
    if race_grade not in RACE_GRADES:
        raise ValueError(f"bearing grade {race_grade!r}: expected one of {', '.join(RACE_GRADES)} (ISO 492)")
    if ball_grade not in BALL_GRADES:
        raise ValueError(f"ball grade {ball_grade!r}: expected one of {', '.join(BALL_GRADES)} (ISO 3290-1)")
    kia, _kea, w2 = RACE_GRADES[race_grade]
    k = np.arange(2, MAX_WAVINESS_ORDER + 1, dtype=float)
    ai = waviness_scale * w2 * 1e-6 * (2.0 / k) * rng.uniform(0.5, 1.5, k.size)
    pi_ = rng.uniform(0, TWO_PI, k.size)
    a1 = waviness_scale * RUNOUT_FRACTION * 0.5 * kia * 1e-6
    p1 = rng.uniform(0, TWO_PI)
    ao = waviness_scale * w2 * 1e-6 * (2.0 / k) * rng.uniform(0.5, 1.5, k.size)
    po = rng.uniform(0, TWO_PI, k.size)
    vdwl = BALL_GRADES[ball_grade] * 1e-6
    dd = rng.uniform(-0.5 * vdwl, 0.5 * vdwl, int(g.balls))
    return BallSet(g, inner=(np.concatenate([[1.0], k]), np.concatenate([[a1], ai]), np.concatenate([[p1], pi_])),
                   outer=(k, ao, po), ball_dd_m=dd)


__all__ = ["BallBearingGeometry", "BallSet", "generate_ball_set", "load_deflection_constant",
           "preload_approach_m", "radial_stiffness_N_m", "RACE_GRADES", "BALL_GRADES"]
