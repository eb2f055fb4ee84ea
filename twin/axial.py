"""The shaft's axial degree of freedom: z(θ, t) from its causes (issue #33 item 6; ISO 230-7:2015
axial and face error motion).

Opt-in: built only when the scenario has an ``[axial]`` section (twin/scenario_schema.py). Without
it nothing here runs and every dataset keeps its bytes.

**First order and decoupled.** z is solved AFTER the bench's radial/tilt statics (twin/physics.py),
from the same ball loads / film, and added to the posed rotating bodies as a translation along the
spin axis. It does not feed back into the radial solve. Neglected couplings, sized in
docs/physics.md ("The shaft's axial degree of freedom"):

- an axial displacement z changes the two sets' approaches by ±sin(a)·z and so their radial
  stiffness by ±(z·sin a)/(2·δ0) (the (3/2)·K_n·δ^½ law), opposite in the two sets: jia2019's pair
  (δ0 = 1.62 µm) standing vertical sags 0.33–0.40 µm under its 7.85 N: ±2.7–3.2 % (a constant), and
  its 0.55 µm P-V of axial motion over a revolution modulates them by ±2.2 % — the radial motion
  would change by that fraction of itself (a few nm of its ~0.2 µm);
- the contact angle's change with z (the 5-DOF Jones model): Δa ≈ z·cos(a)/(Dw·(f_i + f_o − 1))
  = 1.2e-3 rad at 0.4 µm: ≈ 2·cot(a)·Δa = 0.9 % of the axial stiffness;
- the races' axial lobes of orders q·Z ± 1 (and the thrust runner's orders q·N ± 1) push a tilting
  MOMENT, not an axial force: that tilt is not added to the tilt DOF (its size is stated in truth).

**Ball-bearing pair** (preloaded back to back; twin/bearing.py's Hertz contacts, Harris & Kotzalas
vol. 1 ch. 7, Jones' quasi-static method reduced to the axial direction): ball j of the top set
has the normal approach of the radial model plus the axial part,
    δ_j = δ0 + cos(a)·(u·e_j) + w_j + sin(a)·v_j + s·sin(a)·z,     s = +1 (top), −1 (bottom)
(w_j the radial interference of twin/bearing.py: race waviness and ball-diameter deviation; v_j the
raceways' AXIAL (face) lobes, inner v_i(ψ_j − θ), outer v_o(ψ_j)), Q_j = K_n·max(δ_j, 0)^1.5, and the
balls push the shaft along z with F_z = sin(a)·(Σ_bottom Q_j − Σ_top Q_j). z is the root of
F_z(z) + F_ext = 0 (Newton on the full non-linear law; F_ext the shaft's weight along z plus
``axial.load``). Linearised about the preloaded state the pair's axial stiffness is
    K_a = (3/2)·K_n·sin²(a)·(Z_top·δ0_top^½ + Z_bottom·δ0_bottom^½)
and NOTHING here selects orders: the sums over the balls pass only the race orders q·Z (a ball set
at Z equal azimuths averages every other order out of Σ_j), at q·Z·(1 − ρ) and q·Z·ρ cycles per
revolution; the ball lot's mean diameter deviation is a constant offset (every ball always
loaded), its order-1 content around the set tilts the shaft at cage order (already in the tilt
DOF of the radial model, so it reaches the face motion as R × tilt).
Axial race lobes: ISO 492:2014 limits the assembled inner ring's axial run-out S_ia (P5 / P4 / P2 for
18 < d <= 30 mm: 8 / 4 / 2.5 µm) and no axial waviness; ASSUMPTION: the raceways' axial waviness
has the radial one's spectrum (twin/bearing.py RACE_GRADES W2·(2/k)·U(0.5, 1.5), orders 2…40),
scaled by ``axial.race_face_waviness_scale``, and the inner raceway's order 1 (its S_ia wobble) is
RUNOUT_FRACTION·S_ia/2 as for the radial run-out (a tilt moment only: orders 1 ≠ q·Z).

**Air bearing** (twin/air_bearing.py's double-acting thrust, Powell 1970 ch. 4): the shaft's weight W
on the film sits the runner at z_0(p_s) (the non-linear ``position_under_load_m``); the supply
pressure p_s(t) (SupplyPressure, keyed by TIME) moves it by z_0(p_s(t)) − z_0(p_s0) ≈
W·(1/K(t) − 1/K_0) (asynchronous); the runner's two faces' form v(φ − θ) turns with the shaft and
reaches the film sector by sector (N feed holes): an inherent orifice senses the gap AT its hole
(its curtain π·d·h), the sector's outflow its MEAN gap (boxcar over 2π/N, G(k) as the journal), so
    z_form(θ) = (A_l·m_hl + B_l·m_fl − A_u·m_hu − B_u·m_fu)/(A_l + B_l + A_u + B_u)
with A = ∂F_pad/∂h_hole, B = ∂F_pad/∂h_film of each pad at its loaded gap (central differences of
the two-gap pad law below) and m the sector means of the lower (l) and upper (u) faces' lobes —
again only orders q·N survive the sums (at the holes; the boxcar's G(q·N) = 0). Synchronous.
Runner flatness: ASSUMPTION 0.2 µm peak-to-valley per face (lapped thrust runners of air-bearing
tables are specified at ~0.1–0.5 µm flatness; no source found for a specific table), 1/k spectrum
as the journal (generate_form).

**Thermal** (both types): the shaft grows from the pair's axial location to the target by
``axial.thermal_growth``·ΔT_s(t) (m/K of the structure node of twin/thermal.py, keyed by TIME):
CTE × (distance from the axial location to the target − the probe stand's own height over which
it grows the same way); ASSUMPTION, a scenario states it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .air_bearing import AerostaticThrust, SupplyPressure, generate_form
from .bearing import MAX_WAVINESS_ORDER, RACE_GRADES, RUNOUT_FRACTION, BallSet, lobes_value

TWO_PI = 2.0 * math.pi
#: standard gravity (m/s²)
G_N = 9.80665
#: ISO 492:2014 inner-ring axial run-out of the assembled bearing S_ia (µm), 18 < d <= 30 mm;
#: P0 / P6 have no S_ia limit: ASSUMPTION twice the P5 value
AXIAL_RUNOUT_SIA_UM: dict[str, float] = {"P0": 16.0, "P6": 16.0, "P5": 8.0, "P4": 4.0, "P2": 2.5}
#: Newton tolerance of the axial equilibrium (m)
Z_TOL_M = 1e-16


def generate_face_lobes(race_grade: str, rng: np.random.Generator, scale: float = 1.0):
    """Axial (face) lobes of the inner and outer raceway of one bearing: (k, a, p) each (see the
    module docstring: the radial waviness spectrum, order 1 of the inner race from S_ia)."""
    _kia, _kea, w2 = RACE_GRADES[race_grade]
    k = np.arange(2, MAX_WAVINESS_ORDER + 1, dtype=float)
    ai = scale * w2 * 1e-6 * (2.0 / k) * rng.uniform(0.5, 1.5, k.size)
    pi_ = rng.uniform(0, TWO_PI, k.size)
    a1 = scale * RUNOUT_FRACTION * 0.5 * AXIAL_RUNOUT_SIA_UM[race_grade] * 1e-6
    p1 = rng.uniform(0, TWO_PI)
    ao = scale * w2 * 1e-6 * (2.0 / k) * rng.uniform(0.5, 1.5, k.size)
    po = rng.uniform(0, TWO_PI, k.size)
    inner = (np.concatenate([[1.0], k]), np.concatenate([[a1], ai]), np.concatenate([[p1], pi_]))
    return inner, (k, ao, po)


def pair_axial_stiffness_N_m(top: BallSet, bottom: BallSet) -> float:
    """K_a of the preloaded pair, linearised: (3/2)·K_n·sin²a·Σ_sets Z·δ0^½ (sets in parallel)."""
    out = 0.0
    for bs in (top, bottom):
        sa = math.sin(bs.geometry.contact_angle_rad)
        out += 1.5 * bs.Kn * sa * sa * bs.Z * math.sqrt(bs.delta0_m)
    return out


def palmgren_axial_stiffness_N_m(bs: BallSet) -> float:
    """An independent closed form for the tests: Palmgren's axial deflection of one angular-contact
    ball bearing, δ_a = 0.00044/sin(a)·(Q²/D_w)^(1/3) mm (Q N, D_w mm; Palmgren, *Ball and Roller
    Bearing Engineering*, 1959; Harris & Kotzalas vol. 2 ch. 8), at Q = F_a/(Z sin a): K = dF_a/dδ_a."""
    g = bs.geometry
    sa = math.sin(g.contact_angle_rad)
    Dw_mm = g.ball_diameter_m * 1e3
    # δ_a [m] = c·F_a^(2/3): c = 0.00044e-3/sa·(1/(Z sa))^(2/3)·Dw_mm^(-1/3)
    c = 0.00044e-3 / sa * (1.0 / (bs.Z * sa)) ** (2.0 / 3.0) * Dw_mm ** (-1.0 / 3.0)
    return 1.5 * g.preload_N ** (1.0 / 3.0) / c


class BallPairAxial:
    """The axial equilibrium of the two ball sets (top s = +1, bottom s = −1)."""

    def __init__(self, top: BallSet, bottom: BallSet, face: dict, load_N: float):
        self.sets = (top, bottom)
        self.face = face                    # side -> (inner (k, a, p), outer (k, a, p))
        self.load_N = float(load_N)         # external axial load along +z (weight included)
        self.K_lin = pair_axial_stiffness_N_m(top, bottom)
        self._sa = [math.sin(bs.geometry.contact_angle_rad) for bs in self.sets]

    def face_interference_m(self, side: str, theta_rad: float, cage_rad: float) -> np.ndarray:
        """sin(a)·v_j: each ball's extra normal approach from the raceways' axial lobes."""
        bs = self.sets[0 if side == "top" else 1]
        psi = bs.ball_azimuths(cage_rad)
        (ki, ai, pi_), (ko, ao, po) = self.face[side]
        v = lobes_value(ki, ai, pi_, psi - theta_rad) + lobes_value(ko, ao, po, psi)
        return math.sin(bs.geometry.contact_angle_rad) * v

    def base_approaches_m(self, u4, theta_rad: float, cages) -> list[np.ndarray]:
        """δ_j at z = 0 of each set: the radial model's approach plus the axial lobes."""
        u4 = np.asarray(u4, dtype=float)
        return [bs.approaches_m(u4[2 * i:2 * i + 2], theta_rad, float(cages[i]))
                + self.face_interference_m(side, theta_rad, float(cages[i]))
                for i, (side, bs) in enumerate(zip(("top", "bottom"), self.sets))]

    def axial_force_N(self, z_m: float, base: list[np.ndarray]) -> tuple[float, float]:
        """F_z on the shaft from both sets at z, and dF_z/dz (N, N/m)."""
        F = dF = 0.0
        for s, bs, sa, b in zip((1.0, -1.0), self.sets, self._sa, base):
            d = np.maximum(b + s * sa * z_m, 0.0)
            F += -s * sa * float(np.sum(bs.Kn * d**1.5))
            dF += -sa * sa * float(np.sum(1.5 * bs.Kn * np.sqrt(d)))
        return F, dF

    def solve_z_m(self, base: list[np.ndarray], extra_load_N: float = 0.0) -> float:
        """z with F_z(z) + load = 0 (Newton from the linear estimate)."""
        load = self.load_N + float(extra_load_N)
        F0, dF0 = self.axial_force_N(0.0, base)
        z = -(F0 + load) / dF0
        for _ in range(60):
            F, dF = self.axial_force_N(z, base)
            if dF == 0.0:
                raise ValueError("axial: both ball sets unloaded")
            dz = -(F + load) / dF
            z += dz
            if abs(dz) <= Z_TOL_M:
                break
        return z

    def truth(self) -> dict:
        top, bottom = self.sets
        return {"model": "ball pair, Hertz axial equilibrium (decoupled, after the radial statics)",
                "axial_stiffness_linearised_N_m": self.K_lin,
                "axial_load_N": self.load_N,
                "static_deflection_linear_m": self.load_N / self.K_lin,
                "palmgren_pair_stiffness_N_m": palmgren_axial_stiffness_N_m(top) + palmgren_axial_stiffness_N_m(bottom),
                "race_face_lobes": {s: {r: [{"order": int(k), "amplitude_m": float(a), "phase_rad": float(p)}
                                            for k, a, p in zip(*lobes)]
                                        for r, lobes in zip(("inner", "outer"), self.face[s])}
                                    for s in self.face}}


class AirThrustAxial:
    """z of an aerostatic thrust runner: weight, supply pressure (time), runner form (angle)."""

    def __init__(self, thrust: AerostaticThrust, supply: SupplyPressure, load_N: float,
                 runner_form: dict):
        self.thrust, self.supply, self.load_N = thrust, supply, float(load_N)
        self.runner_form = runner_form       # "lower"/"upper" -> (k, a, p), shaft frame
        p0 = thrust.supply_pressure_Pa
        self.K0 = thrust.stiffness_N_m()
        ps = np.array([0.98, 1.0, 1.02]) * p0
        zs = np.array([thrust.position_under_load_m(self.load_N, p) for p in ps])
        self.z0_m = float(zs[1])
        # z_0(p_s) is smooth over ±2 % (the fluctuation stays within ±1 %): a quadratic through
        # three exact non-linear solutions (tests check it against position_under_load_m)
        self._zfit = np.polyfit(ps - p0, zs, 2)
        h = thrust.clearance_m
        dh = 1e-3 * h
        self.AB = {}
        for pad, gap in (("lower", h + self.z0_m), ("upper", h - self.z0_m)):
            A = (thrust.pad_force_N(gap + dh, gap_film_m=gap) - thrust.pad_force_N(gap - dh, gap_film_m=gap)) / (2 * dh)
            B = (thrust.pad_force_N(gap, gap_film_m=gap + dh) - thrust.pad_force_N(gap, gap_film_m=gap - dh)) / (2 * dh)
            self.AB[pad] = (A, B)
        N = thrust.feed_holes
        self._phi = TWO_PI * np.arange(N) / N

    def z_static_m(self, p_s) -> np.ndarray:
        return np.polyval(self._zfit, np.asarray(p_s, dtype=float) - self.thrust.supply_pressure_Pa)

    def z_supply_m(self, t_s: float) -> float:
        """z_0(p_s(t)) − z_0(p_s0): the supply pressure's axial motion at bench time t."""
        if not self.supply.active:
            return 0.0
        return float(self.z_static_m(self.supply(float(t_s)))) - self.z0_m

    def _sector_means(self, face: str, theta_rad: float) -> tuple[float, float]:
        """(mean over the holes of the face's form at the holes, mean of the sectors' boxcar means)."""
        k, a, p = self.runner_form[face]
        N = self.thrust.feed_holes
        x = self._phi - float(theta_rad)
        at_holes = lobes_value(k, a, p, x)
        G = np.sinc(k / N)        # sin(k·pi/N)/(k·pi/N)
        boxcar = lobes_value(k, a * G, p, x)
        return float(np.mean(at_holes)), float(np.mean(boxcar))

    def z_form_m(self, theta_rad: float) -> float:
        (Al, Bl), (Au, Bu) = self.AB["lower"], self.AB["upper"]
        hl, fl = self._sector_means("lower", theta_rad)
        hu, fu = self._sector_means("upper", theta_rad)
        return (Al * hl + Bl * fl - Au * hu - Bu * fu) / (Al + Bl + Au + Bu)

    def truth(self) -> dict:
        return {"model": "aerostatic thrust: weight at z_0(p_s(t)), runner form through the feed sectors",
                "axial_stiffness_N_m": self.K0, "axial_load_N": self.load_N, "static_position_m": self.z0_m,
                "dz_dps_m_per_Pa": float(self._zfit[1]),
                "hole_and_film_derivatives_N_m": {k: list(v) for k, v in self.AB.items()},
                "runner_form": {f: [{"order": int(k), "amplitude_m": float(a), "phase_rad": float(p)}
                                    for k, a, p in zip(*v)] for f, v in self.runner_form.items()}}


@dataclass
class Axial:
    """The bench's axial DOF: z(θ, t) = model(θ, u, cages) + thermal(t) [+ supply(t)]."""

    ball: BallPairAxial | None
    air: AirThrustAxial | None
    thermal_growth_m_K: float
    thermal: object | None       # twin.thermal.Thermal

    def thermal_m(self, t_s: float) -> float:
        if not self.thermal_growth_m_K or self.thermal is None:
            return 0.0
        return self.thermal_growth_m_K * float(self.thermal.structure_rise_K(float(t_s)))  # type: ignore[attr-defined]

    def truth(self) -> dict:
        out: dict = {"thermal_growth_m_K": self.thermal_growth_m_K}
        if self.ball is not None:
            out["ball_pair"] = self.ball.truth()
        if self.air is not None:
            out["air_thrust"] = self.air.truth()
        return out


def build_axial(ax: dict, bench, rng: np.random.Generator) -> Axial:
    """The axial DOF of a built ``twin.physics.Bench`` from the scenario's ``[axial]`` section."""
    br = bench.sc["bearings"]
    g = str(bench.sc["bench"]["gravity_direction"])
    mass = float(bench.model.body_subtreemass[bench._bid["shaft"]])
    weight_z = {"-z": -1.0, "+z": 1.0}.get(g, 0.0) * mass * G_N     # the weight's component along +z
    load = weight_z + float(ax["load"])
    ball = air = None
    if bench.ball_sets is not None:
        scale = float(ax["race_face_waviness_scale"])
        face = {}
        for s in ("top", "bottom"):
            face[s] = generate_face_lobes(str(br["grade"]), rng, scale)
        ball = BallPairAxial(bench.ball_sets["top"], bench.ball_sets["bottom"], face, load)
    elif bench.air_bearings is not None:
        if bench.air_bearings.thrust is None:
            raise ValueError("[axial] on an air bench needs a thrust bearing (bearings.thrust_outer_radius > 0)")
        flat = float(ax["runner_flatness"])
        forms = {f: generate_form(flat, rng) for f in ("lower", "upper")}
        air = AirThrustAxial(bench.air_bearings.thrust, bench.air_bearings.supply, load, forms)
    else:
        raise ValueError("[axial] needs bearings.type = \"ball\" or \"air\" (a path bearing replays radial motion only)")
    return Axial(ball, air, float(ax["thermal_growth"]), bench.thermal)


__all__ = ["Axial", "AirThrustAxial", "BallPairAxial", "build_axial", "generate_face_lobes",
           "pair_axial_stiffness_N_m", "palmgren_axial_stiffness_N_m"]
