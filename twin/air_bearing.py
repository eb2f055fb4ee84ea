"""An aerostatic (externally pressurised air) journal bearing, and its thrust bearing, as physics.

What is computed, and where each piece comes from:

- **Restrictor flow.** Air enters the film through restrictors from the supply pressure p_s
  (absolute). An orifice (inherently compensated: the throttling section is the curtain
  pi·d·h around a feed hole of diameter d at the local gap h) passes the isentropic nozzle flow
      m = C_d·A·p_s·sqrt(2κ/((κ − 1)·R·T)·((p_d/p_s)^(2/κ) − (p_d/p_s)^((κ+1)/κ)))
  choked (the bracket at its maximum) below p_d/p_s = (2/(κ+1))^(κ/(κ−1)) = 0.528
  (Powell, *Design of Aerostatic Bearings*, Machinery Publishing 1970, ch. 2; van Beek,
  *Advanced Engineering Design*, TU Delft 2019, eq. 12.4). A porous insert of permeability k_p,
  thickness s and face area A_p passes the isothermal Darcy flow m = k_p·A_p·(p_s² − p_d²)/
  (2·μ·R·T·s) (van Beek ch. 12, porous restrictor).
- **Film flow.** From the feed row the air leaves through the lands to the bearing's ends as
  isothermal, viscous (Poiseuille) slot flow of an ideal gas: m = b·h³·(p_d² − p_a²)/(24·μ·R·T·l)
  for a land of width b and length l (Powell ch. 3; Slocum, *Precision Machine Design*, 1992,
  ch. 10, "Fluid film bearings"). The pressure along the land follows p(x)² linear in x, whose
  mean is (2/3)·(p_d³ − p_a³)/(p_d² − p_a²).
- **The sector (lumped-parameter) method.** The journal's circumference is split into N sectors,
  one per feed hole of a row (Stout & Barrue 1977, "Gas bearing design using a simplified method"
  — the line-source/sector simplification; Powell ch. 5): each sector's feed pressure p_d,i is
  the root of (inflow through its restrictors) = (outflow through its lands) at the sector's gap
  h_i, and the sector pushes on the journal with its pressure over its projected area
  R·2·sin(pi/N)·(plateau·(p_d − p_a) + 2·l·(p̄_land − p_a)). With two feed rows at L/4 from the
  ends, the half between them is a plateau at p_d and the lands are L/4 long; with one central row
  the lands are L/2 long and there is no plateau. Radial force: F = −Σ_i F_i(h_i)·e_i, e_i the unit
  vector to sector i. Stiffness −dF/du by central differences of this non-linear law.
- **Form error through the film's averaging.** A sector's pressure depends on its flow
  conductance, which integrates h³ over the sector; to first order in the form error that is the
  sector's MEAN gap. So the averaging function is a boxcar over the sector, 2pi/N wide
  (uniform axially over the land: cylindricity is not modelled), and a form lobe
  a·cos(k·φ − ψ) reaches sector i as a·G(k)·cos(k·φ_i − ψ) with
      G(k) = sin(k·pi/N)/(k·pi/N)            (the boxcar's Fourier transform)
  (the weighted-average transfer of a fluid film: Shamoto, Park & Moriwaki 2000, "Analysis and
  improvement of motion accuracy of hydrostatic feed table", CIRP Annals 49/1, 299 — the pad's
  pressure is the weighting function; here the lumped sector's is uniform). The journal's
  displacement u shifts the gap by G(1)·(u·e_i). Linearising F about the concentric journal
  (dF_i/dh = −c the same for every sector) gives K = c·G(1)·N/2 and, with no load, the journal
  centre at
      u(θ) = −(2/(G(1)·N))·Σ_i ⟨w⟩_i(θ)·e_i,    w(φ, θ) = w_s(φ − θ) + w_b(φ)
  (w_s the journal's (shaft's) form, turning with θ; w_b the bushing's, fixed: a constant offset
  the housing position absorbs). NOTHING here selects orders or a whirl direction: the sum over
  the sectors does. It leaves only orders k ≡ ±1 (mod N) of the journal: order 1 is the journal's
  own run-out (u = −a exactly), orders q·N + 1 a forward and q·N − 1 a backward whirl, attenuated
  by G(k)/G(1) ≈ 1/k (the averaging: an 8-hole row passes 1/7 of a 7-lobed and 1/9 of a 9-lobed
  form). tests/twin/test_air_bearing.py checks this emerges from the sector sums. The transfer is
  independent of the supply pressure to first order (c cancels).
- **Asynchronous motion from the supply pressure, keyed by TIME.** The supply pressure is
  p_s(t) = p_s0·(1 + r_c·sin(2pi·t/T_c + φ_c) + n(t)) with a seeded slow ripple (a regulator
  hunting, a compressor's load cycle through its receiver) and a seeded random part n(t) (a sum
  of sines, 1/f amplitudes, periods 5 s … 10 min, rms r_n). The stiffness follows K(p_s(t)) (the
  sector model at that pressure), so a journal carrying a static radial load W sits at
  W/K(p_s(t)): it moves by W·(1/K(t) − 1/K_0) along the load, in time and not with the angle. A
  vertical axis carries no radial load (hsieh2022): there the supply pressure moves the journal
  radially by nothing to first order, only the thrust bearing axially.
- **Thrust bearing** (double-acting, two annular pads of radii R_1 < R_2 fed by n_t orifices on
  the circle R_m, gaps h_t ∓ z): radial compressible flow between parallel plates,
  m = pi·h³·(p_d² − p_a²)/(12·μ·R·T·ln(r_2/r_1)) inward and outward (Powell ch. 4; van Beek
  ch. 12), p(r)² log-linear in r, force = ∫(p − p_a)·2pi·r·dr. Without an ``[axial]`` section the
  bench has no axial degree of freedom: the thrust bearing's stiffness is stated in truth/ only;
  with it (twin/axial.py, issue 33 item 6) the runner carries the shaft's weight at z_0(p_s(t)) and
  its faces' form moves it through the feed sectors.

Constants: air at 20 °C, μ = 1.81e-5 Pa·s, R = 287.05 J/(kg·K), κ = 1.4 (CRC Handbook of
Chemistry and Physics, "Viscosity of gases", "Properties of air"); standard atmosphere
p_a = 101 325 Pa. C_d = 0.8 for an inherent orifice (Powell ch. 2 measured 0.6–0.85; ASSUMPTION
within that range, a scenario may state it).

Validity: laminar isothermal film (Reynolds number of the land flow ≪ 1000), quasi-static (no
squeeze film: the stops last seconds, the film's time constant is milliseconds), small form
(a ≪ h_0: second-order terms ~a²/h_0 neglected in the transfer), rigid parts, no rotation-driven
(aerodynamic) pressure (stop-and-go bench: speed ≈ 0), pneumatic-hammer stability not assessed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

TWO_PI = 2.0 * math.pi

#: air at 20 °C (CRC Handbook): dynamic viscosity (Pa·s), gas constant (J/(kg·K)), κ = c_p/c_v
AIR_VISCOSITY_PA_S = 1.81e-5
AIR_GAS_CONSTANT = 287.05
AIR_KAPPA = 1.4
AIR_TEMPERATURE_K = 293.15
#: standard atmosphere (Pa)
P_AMBIENT_PA = 101_325.0
#: orifice discharge coefficient (Powell 1970 ch. 2: 0.6–0.85 measured; ASSUMPTION 0.8)
DISCHARGE_COEFFICIENT = 0.8
#: form orders generated for the journal (as twin/bearing.py: the sector sums select, not we)
MAX_FORM_ORDER = 40
#: a transferred form term below this (m) is the sector sums' rounding, not evaluated per pose
FORM_TERM_FLOOR_M = 1e-18
#: the random supply-pressure part: components and their period band (s)
SUPPLY_NOISE_COMPONENTS = 24
SUPPLY_NOISE_PERIODS_S = (5.0, 600.0)


def _critical_ratio(kappa: float = AIR_KAPPA) -> float:
    return (2.0 / (kappa + 1.0)) ** (kappa / (kappa - 1.0))


def orifice_mass_flow(area_m2, p_s: float, p_d, cd: float = DISCHARGE_COEFFICIENT,
                      kappa: float = AIR_KAPPA, RT: float = AIR_GAS_CONSTANT * AIR_TEMPERATURE_K):
    """Isentropic nozzle flow (kg/s) from p_s to p_d (absolute, Pa), choked below the critical
    ratio (Powell 1970 ch. 2)."""
    r = np.maximum(np.asarray(p_d, dtype=float) / p_s, _critical_ratio(kappa))
    r = np.minimum(r, 1.0)
    psi = np.sqrt(np.maximum(2.0 * kappa / ((kappa - 1.0) * RT) * (r ** (2.0 / kappa) - r ** ((kappa + 1.0) / kappa)), 0.0))
    return cd * np.asarray(area_m2, dtype=float) * p_s * psi


def porous_mass_flow(permeability_m2: float, area_m2: float, thickness_m: float, p_s: float, p_d,
                     mu: float = AIR_VISCOSITY_PA_S, RT: float = AIR_GAS_CONSTANT * AIR_TEMPERATURE_K):
    """Isothermal Darcy flow (kg/s) through a porous restrictor (van Beek ch. 12)."""
    return permeability_m2 * area_m2 * (p_s**2 - np.asarray(p_d, dtype=float) ** 2) / (2.0 * mu * RT * thickness_m)


def slot_mass_flow(width_m, gap_m, length_m: float, p_d, p_a: float = P_AMBIENT_PA,
                   mu: float = AIR_VISCOSITY_PA_S, RT: float = AIR_GAS_CONSTANT * AIR_TEMPERATURE_K):
    """Isothermal viscous flow (kg/s) of an ideal gas through a parallel slot (Powell ch. 3)."""
    return np.asarray(width_m) * np.asarray(gap_m) ** 3 * (np.asarray(p_d) ** 2 - p_a**2) / (24.0 * mu * RT * length_m)


def land_mean_pressure(p_d, p_a: float = P_AMBIENT_PA):
    """Mean of p over a land with p² linear along it: (2/3)(p_d³ − p_a³)/(p_d² − p_a²)."""
    p_d = np.asarray(p_d, dtype=float)
    den = p_d**2 - p_a**2
    safe = np.where(den > 0, den, 1.0)
    return np.where(den > 0, (2.0 / 3.0) * (p_d**3 - p_a**3) / safe, p_a)


def _bisect(f, lo, hi, n: int = 80):
    """Vector bisection for a decreasing f on [lo, hi] (f(lo) >= 0 >= f(hi))."""
    lo = np.array(lo, dtype=float)
    hi = np.array(hi, dtype=float)
    for _ in range(n):
        mid = 0.5 * (lo + hi)
        pos = f(mid) > 0
        lo = np.where(pos, mid, lo)
        hi = np.where(pos, hi, mid)
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class AerostaticJournal:
    """One aerostatic journal bearing (SI, pressures absolute)."""

    diameter_m: float
    length_m: float
    clearance_m: float                 # radial gap h_0 of the concentric journal
    supply_pressure_Pa: float          # absolute p_s0
    feed_holes: int = 8                # N per row
    rows: int = 2
    restrictor: str = "orifice"        # "orifice" (inherent) or "porous"
    orifice_diameter_m: float = 0.2e-3
    discharge_coefficient: float = DISCHARGE_COEFFICIENT
    porous_permeability_m2: float = 1e-15
    porous_thickness_m: float = 5e-3
    porous_area_m2: float = 2e-5        # face area of one porous insert (per feed position)
    ambient_Pa: float = P_AMBIENT_PA

    def __post_init__(self):
        if self.feed_holes < 3:
            raise ValueError("an aerostatic journal needs at least 3 feed holes per row")
        if self.rows not in (1, 2):
            raise ValueError("rows must be 1 (central) or 2 (at L/4 from the ends)")
        if self.restrictor not in ("orifice", "porous"):
            raise ValueError("restrictor must be 'orifice' or 'porous'")
        if not self.supply_pressure_Pa > self.ambient_Pa:
            raise ValueError("supply pressure must exceed the ambient pressure")
        if not 0 < self.clearance_m < 0.01 * self.diameter_m:
            raise ValueError("clearance must be > 0 and < 1 % of the diameter")

    # ------------------------------------------------------------------------- geometry ----
    @property
    def land_m(self) -> float:
        return self.length_m / (2.0 * self.rows)

    @property
    def plateau_m(self) -> float:
        return 0.0 if self.rows == 1 else 0.5 * self.length_m

    @property
    def sector_width_m(self) -> float:
        return math.pi * self.diameter_m / self.feed_holes

    def G(self, k) -> np.ndarray:
        """The sector's boxcar average of cos(k·φ): sin(k·pi/N)/(k·pi/N) (1 at k = 0)."""
        x = np.asarray(k, dtype=float) * math.pi / self.feed_holes
        return np.sinc(x / math.pi)

    # ------------------------------------------------------------------ sector pressures ----
    def feed_pressure_Pa(self, gap_m, p_s: float | None = None) -> np.ndarray:
        """p_d of sectors of mean gap ``gap_m``: inflow of the row(s) = outflow over both lands."""
        p_s = self.supply_pressure_Pa if p_s is None else float(p_s)
        h = np.asarray(gap_m, dtype=float)
        b = self.sector_width_m

        def inflow(p_d):
            if self.restrictor == "orifice":
                return self.rows * orifice_mass_flow(math.pi * self.orifice_diameter_m * h, p_s, p_d,
                                                     self.discharge_coefficient)
            return self.rows * porous_mass_flow(self.porous_permeability_m2, self.porous_area_m2,
                                                self.porous_thickness_m, p_s, p_d)

        def excess(p_d):
            return inflow(p_d) - 2.0 * slot_mass_flow(b, h, self.land_m, p_d, self.ambient_Pa)

        lo = np.full(h.shape, self.ambient_Pa)
        hi = np.full(h.shape, p_s)
        return _bisect(excess, lo, hi)

    def sector_force_N(self, gap_m, p_s: float | None = None) -> np.ndarray:
        """Each sector's push on the journal (N), along −e_i."""
        p_d = self.feed_pressure_Pa(gap_m, p_s)
        pa = self.ambient_Pa
        R = 0.5 * self.diameter_m
        proj = R * 2.0 * math.sin(math.pi / self.feed_holes)
        return proj * (self.plateau_m * (p_d - pa) + 2.0 * self.land_m * (land_mean_pressure(p_d, pa) - pa))

    def pressure_ratio(self, p_s: float | None = None) -> float:
        """(p_d − p_a)/(p_s − p_a) of the concentric journal (design optimum ≈ 0.5–0.7, Powell)."""
        p_s = self.supply_pressure_Pa if p_s is None else float(p_s)
        p_d = float(self.feed_pressure_Pa(np.array([self.clearance_m]), p_s)[0])
        return (p_d - self.ambient_Pa) / (p_s - self.ambient_Pa)

    def force_N(self, u_m, p_s: float | None = None, form_m=None) -> np.ndarray:
        """Radial force (x, y) of the film on a journal displaced by u (N), non-linear sector law;
        ``form_m``: each sector's mean form (reduces its gap), optional."""
        N = self.feed_holes
        phi = TWO_PI * np.arange(N) / N
        e = np.stack([np.cos(phi), np.sin(phi)])
        h = self.clearance_m - float(self.G(1)) * (np.asarray(u_m, dtype=float) @ e)
        if form_m is not None:
            h = h - np.asarray(form_m, dtype=float)
        if np.any(h <= 0):
            raise ValueError("the journal touches the bushing (gap <= 0)")
        return -(e @ self.sector_force_N(h, p_s))

    def stiffness_N_m(self, p_s: float | None = None) -> float:
        """Radial stiffness −dF_x/du_x about the concentric journal (central difference)."""
        du = 1e-3 * self.clearance_m
        fp = self.force_N(np.array([du, 0.0]), p_s)[0]
        fm = self.force_N(np.array([-du, 0.0]), p_s)[0]
        return -(fp - fm) / (2.0 * du)

    def mass_flow_kg_s(self, p_s: float | None = None) -> float:
        """Air consumption of the concentric journal (kg/s)."""
        p_d = self.feed_pressure_Pa(np.array([self.clearance_m]), p_s)
        return float(self.feed_holes * 2.0 * slot_mass_flow(self.sector_width_m, self.clearance_m, self.land_m,
                                                             p_d, self.ambient_Pa)[0])

    # ------------------------------------------------------------------------ form transfer ----
    def form_transfer(self, orders) -> tuple[np.ndarray, np.ndarray]:
        """For a journal lobe a·cos(k·(φ − θ) − ψ): the unloaded journal centre is
        u(θ) = a·(A_k·[cos ψ, sin ψ]ᵀ·cos kθ + B_k·[cos ψ, sin ψ]ᵀ·sin kθ)-like sums. Returned as the
        2×2 matrices P_k, Q_k with u = a·(P_k·c + Q_k·s), c = (cos(kθ + ψ)), s = sin(kθ + ψ) acting
        on the unit vectors; computed by summing over the sectors (no order is selected here)."""
        N = self.feed_holes
        phi = TWO_PI * np.arange(N) / N
        k = np.asarray(orders, dtype=float)
        g = self.G(k) / float(self.G(1))
        # <w>_i = a·G(k)·cos(k·φ_i − (kθ + ψ)) = a·G(k)·(cos kφ_i·cos X + sin kφ_i·sin X), X = kθ + ψ
        ck = np.cos(np.multiply.outer(k, phi))            # (K, N)
        sk = np.sin(np.multiply.outer(k, phi))
        ex, ey = np.cos(phi), np.sin(phi)
        scale = -(2.0 / N) * g
        # u_x = a·scale·(Σ ck·ex · cos X + Σ sk·ex · sin X), u_y likewise with ey
        return (scale[:, None] * np.stack([ck @ ex, ck @ ey], axis=1),
                scale[:, None] * np.stack([sk @ ex, sk @ ey], axis=1))


@dataclass(frozen=True)
class AerostaticThrust:
    """A double-acting aerostatic thrust bearing: two annular pads, n orifices on radius R_m."""

    inner_radius_m: float
    outer_radius_m: float
    feed_radius_m: float
    clearance_m: float
    supply_pressure_Pa: float
    feed_holes: int = 8
    orifice_diameter_m: float = 0.2e-3
    discharge_coefficient: float = DISCHARGE_COEFFICIENT
    ambient_Pa: float = P_AMBIENT_PA

    def __post_init__(self):
        if not 0 < self.inner_radius_m < self.feed_radius_m < self.outer_radius_m:
            raise ValueError("thrust pad: need 0 < R1 < R_feed < R2")

    def pad_force_N(self, gap_m: float, p_s: float | None = None, gap_film_m: float | None = None) -> float:
        """One pad's force at the gap ``gap_m``. With ``gap_film_m``, the orifices' curtain sees
        ``gap_m`` (the gap at the holes) and the film's conductance ``gap_film_m`` (the sector's mean
        gap: a runner whose form differs there, twin/axial.py); the same law, term for term."""
        p_s = self.supply_pressure_Pa if p_s is None else float(p_s)
        R1, Rm, R2, pa = self.inner_radius_m, self.feed_radius_m, self.outer_radius_m, self.ambient_Pa
        RT, mu = AIR_GAS_CONSTANT * AIR_TEMPERATURE_K, AIR_VISCOSITY_PA_S
        h = float(gap_m)
        hf = h if gap_film_m is None else float(gap_film_m)
        cond = math.pi * hf**3 / (12.0 * mu * RT) * (1.0 / math.log(R2 / Rm) + 1.0 / math.log(Rm / R1))

        def excess(p_d):
            return (self.feed_holes * orifice_mass_flow(math.pi * self.orifice_diameter_m * h, p_s, p_d,
                                                        self.discharge_coefficient)
                    - cond * (p_d**2 - pa**2))

        p_d = float(_bisect(excess, np.array(pa), np.array(p_s)))
        # p(r)² log-linear in r on each side of the feed circle; force = ∫(p − p_a)·2·pi·r dr
        x, w = np.polynomial.legendre.leggauss(48)
        total = 0.0
        for a, b in ((R1, Rm), (Rm, R2)):
            r = 0.5 * (b - a) * x + 0.5 * (b + a)
            frac = np.log(r / Rm) / math.log((R2 if b == R2 else R1) / Rm)
            p = np.sqrt(p_d**2 - (p_d**2 - pa**2) * frac)
            total += 0.5 * (b - a) * float(np.sum(w * (p - pa) * TWO_PI * r))
        return total

    def force_N(self, z_m: float, p_s: float | None = None) -> float:
        """Net axial force (+z) on the runner displaced by z: the lower pad (gap h + z) pushes it up,
        the upper pad (gap h − z) down."""
        return self.pad_force_N(self.clearance_m + z_m, p_s) - self.pad_force_N(self.clearance_m - z_m, p_s)

    def stiffness_N_m(self, p_s: float | None = None) -> float:
        dz = 1e-3 * self.clearance_m
        return -(self.force_N(dz, p_s) - self.force_N(-dz, p_s)) / (2.0 * dz)

    def position_under_load_m(self, load_N: float, p_s: float | None = None) -> float:
        """z at which the film carries ``load_N`` along +z (the runner's weight on a vertical axis
        is a load along −z: pass it negative), Newton on the non-linear law."""
        z = 0.0
        for _ in range(30):
            k = self.stiffness_N_m(p_s) if abs(z) < 1e-12 else -(self.force_N(z + 1e-9, p_s) - self.force_N(z - 1e-9, p_s)) / 2e-9
            dz = (self.force_N(z, p_s) + load_N) / k
            z += dz
            if abs(dz) < 1e-15:
                break
        return z


class SupplyPressure:
    """p_s(t) = p_s0·(1 + r_c·sin(2pi·t/T_c + φ_c) + n(t)), n a seeded sum of sines (1/f
    amplitudes over SUPPLY_NOISE_PERIODS_S) scaled to rms r_n. A function of TIME only."""

    def __init__(self, p0_Pa: float, ripple: float, ripple_period_s: float, noise_rms: float,
                 rng: np.random.Generator):
        self.p0 = float(p0_Pa)
        self.ripple = float(ripple)
        self.period = float(ripple_period_s)
        self.noise_rms = float(noise_rms)
        self.phase = float(rng.uniform(0, TWO_PI))
        lo, hi = SUPPLY_NOISE_PERIODS_S
        self.f = rng.uniform(1.0 / hi, 1.0 / lo, SUPPLY_NOISE_COMPONENTS)
        a = 1.0 / self.f
        self.a = a * (self.noise_rms / math.sqrt(0.5 * float(np.sum(a**2)))) if self.noise_rms > 0 else 0 * a
        self.ph = rng.uniform(0, TWO_PI, SUPPLY_NOISE_COMPONENTS)

    @property
    def active(self) -> bool:
        return self.ripple > 0 or self.noise_rms > 0

    def relative(self, t_s) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)
        out = self.ripple * np.sin(TWO_PI * t / self.period + self.phase)
        if self.noise_rms > 0:
            out = out + np.tensordot(self.a, np.sin(TWO_PI * np.multiply.outer(self.f, t)
                                                    + self.ph.reshape((-1,) + (1,) * t.ndim)), axes=1)
        return out

    def __call__(self, t_s) -> np.ndarray:
        """p_s(t), absolute (Pa)."""
        return self.p0 * (1.0 + self.relative(t_s))


def generate_form(roundness_m: float, rng: np.random.Generator, max_order: int = MAX_FORM_ORDER
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A journal's form as lobes k = 2…max: a_k ∝ (2/k)·U(0.5, 1.5) (the falling spectrum of
    ground/lapped parts, dominated by the low orders: Lubricants 2026, 14(3), 105, measured rotor
    harmonics 1–5 dominate; the 1/k law is an ASSUMPTION, as in twin/bearing.py), scaled so the
    profile's peak-to-valley (the ISO 12181 roundness, evaluated on 4096 points) is
    ``roundness_m``. Random phases. Order 1 is the journal's centring on the shaft, a separate key."""
    k = np.arange(2, max_order + 1, dtype=float)
    a = (2.0 / k) * rng.uniform(0.5, 1.5, k.size)
    p = rng.uniform(0, TWO_PI, k.size)
    if roundness_m <= 0:
        return k, 0 * a, p
    grid = np.linspace(0, TWO_PI, 4096, endpoint=False)
    prof = (a[:, None] * np.cos(k[:, None] * grid - p[:, None])).sum(0)
    return k, a * (roundness_m / float(prof.max() - prof.min())), p


class AirBearings:
    """The bench's two aerostatic journals (top, bottom), their forms and the supply.

    ``offset_terms()``: harmonic terms (frequency, phase, per-offset cos and sin coefficients) of
    the unloaded journal centres against the shaft angle (synchronous: the journals' form through
    the film's averaging); ``supply_offsets_m(t, u_load)``: the journals' time-keyed motion under
    their static loads u_load·K_0 from the supply pressure at bench time t."""

    def __init__(self, journal: AerostaticJournal, forms: dict, runout: dict, supply: SupplyPressure,
                 thrust: AerostaticThrust | None = None):
        self.journal = journal
        self.forms = forms            # side -> (k, a, p) journal lobes (shaft frame)
        self.runout = runout          # side -> (a, p): the journal's order 1 (centring on the shaft)
        self.supply = supply
        self.thrust = thrust
        self.K0 = journal.stiffness_N_m()
        # Moment stiffness of one journal: two rows at ±L/4 each carry K_0/2 (K_0·L²/16); one
        # central row spreads its film over the length: K_0·L²/12 (a uniform distributed
        # stiffness). ASSUMPTION of the sector model, which is axially lumped.
        L = journal.length_m
        self.tilt_stiffness_Nm_rad = self.K0 * L**2 / (16.0 if journal.rows == 2 else 12.0)
        # K(p_s) is smooth: a quadratic through three exact sector solutions over ±2 % of p_s0
        # (the fluctuation stays within ±1 %; tests check it against the sector model).
        p0 = journal.supply_pressure_Pa
        ps = np.array([0.98, 1.0, 1.02]) * p0
        ks = np.array([journal.stiffness_N_m(p) for p in ps])
        self._kfit = np.polyfit(ps - p0, ks, 2)

    def stiffness_at(self, p_s) -> np.ndarray:
        return np.polyval(self._kfit, np.asarray(p_s, dtype=float) - self.journal.supply_pressure_Pa)

    def offset_terms(self) -> list[tuple[np.ndarray, np.ndarray, int, np.ndarray, bool]]:
        """[(freq, phase, row, amplitude, use_sin)] for the four offsets (top x, y, bottom x, y):
        u = Σ a·(P_k·cos(kθ + ψ) + Q_k·sin(kθ + ψ)), order 1 being the run-out lobe."""
        out = []
        for i, s in enumerate(("top", "bottom")):
            k, a, p = self.forms[s]
            a1, p1 = self.runout[s]
            k = np.concatenate([[1.0], k])
            a = np.concatenate([[a1], a])
            p = np.concatenate([[p1], p])
            P, Q = self.journal.form_transfer(k)
            for axis in (0, 1):
                for M, use_sin in ((P, False), (Q, True)):
                    amp = a * M[:, axis]
                    # the sector sums leave the orders k ≢ ±1 (mod N) at rounding (~1e-24 m): not
                    # evaluated at every pose (the sums decided, this only skips their zeros)
                    keep = np.abs(amp) > FORM_TERM_FLOOR_M
                    if keep.any():
                        out.append((k[keep], p[keep], 2 * i + axis, amp[keep], use_sin))
        return out

    def offsets_m(self, theta_rad: float) -> np.ndarray:
        """The same sum evaluated directly (for tests and docs)."""
        u = np.zeros(4)
        for f, ph, row, amp, use_sin in self.offset_terms():
            arg = f * float(theta_rad) + ph
            u[row] += float(amp @ (np.sin(arg) if use_sin else np.cos(arg)))
        return u

    def supply_offsets_m(self, t_s: float, u_load_m: np.ndarray) -> np.ndarray:
        """Shift of the spring's rest positions so that the journals (stiffness K_0 in the bench)
        carry their static loads W = K_0·u_load at K(p_s(t)): r = u_load·(1 − K(t)/K_0)."""
        if not self.supply.active:
            return np.zeros(4)
        k = float(self.stiffness_at(self.supply(float(t_s))))
        return np.asarray(u_load_m, dtype=float) * (1.0 - k / self.K0)

    def truth(self) -> dict:
        j = self.journal
        out = {
            "journal": {"diameter_m": j.diameter_m, "length_m": j.length_m, "clearance_m": j.clearance_m,
                        "supply_pressure_abs_Pa": j.supply_pressure_Pa, "feed_holes_per_row": j.feed_holes,
                        "rows": j.rows, "restrictor": j.restrictor, "orifice_diameter_m": j.orifice_diameter_m,
                        "discharge_coefficient": j.discharge_coefficient,
                        "pressure_ratio": j.pressure_ratio(), "radial_stiffness_N_m": self.K0,
                        "mass_flow_kg_s": j.mass_flow_kg_s(),
                        "tilt_stiffness_Nm_rad": self.tilt_stiffness_Nm_rad,
                        "dK_dps_N_m_per_Pa": float(self._kfit[1])},
            "journal_form": {s: [{"order": int(k), "amplitude_m": float(a), "phase_rad": float(p)}
                                 for k, a, p in zip(*self.forms[s])] for s in self.forms},
            "journal_runout": {s: {"amplitude_m": float(a), "phase_rad": float(p)} for s, (a, p) in self.runout.items()},
            "supply": {"ripple_relative": self.supply.ripple, "ripple_period_s": self.supply.period,
                       "ripple_phase_rad": self.supply.phase, "noise_rms_relative": self.supply.noise_rms},
        }
        if self.thrust is not None:
            t = self.thrust
            out["thrust"] = {"inner_radius_m": t.inner_radius_m, "outer_radius_m": t.outer_radius_m,
                             "feed_radius_m": t.feed_radius_m, "clearance_m": t.clearance_m,
                             "axial_stiffness_N_m": t.stiffness_N_m(),
                             "note": "no axial degree of freedom in the bench: stated, not applied"}
        return out


def journal_from_bearings(br) -> AerostaticJournal:
    """One journal of the bench from a scenario's resolved ``[bearings]`` (SI; gauge supply)."""
    return AerostaticJournal(
        diameter_m=float(br["air_journal_diameter"]), length_m=float(br["air_journal_length"]),
        clearance_m=float(br["air_clearance"]), supply_pressure_Pa=P_AMBIENT_PA + float(br["air_supply_pressure"]),
        feed_holes=int(br["air_feed_holes"]), rows=int(br["air_feed_rows"]), restrictor=str(br["air_restrictor"]),
        orifice_diameter_m=float(br["air_orifice_diameter"]),
        discharge_coefficient=float(br["air_discharge_coefficient"]),
        porous_permeability_m2=float(br["air_porous_permeability"]),
        porous_thickness_m=float(br["air_porous_thickness"]), porous_area_m2=float(br["air_porous_area"]))


def build_air_bearings(br, rng_form: np.random.Generator, rng_supply: np.random.Generator) -> AirBearings:
    """The bench's two journals from a scenario's resolved ``[bearings]`` (SI; gauge supply)."""
    j = journal_from_bearings(br)
    forms, runout = {}, {}
    for s in ("top", "bottom"):
        forms[s] = generate_form(float(br["journal_roundness"]), rng_form)
        runout[s] = (float(br["journal_runout"]), float(rng_form.uniform(0, TWO_PI)))
    supply = SupplyPressure(j.supply_pressure_Pa, float(br["supply_ripple"]), float(br["supply_ripple_period"]),
                            float(br["supply_noise"]), rng_supply)
    thrust = None
    if float(br["thrust_outer_radius"]) > 0:
        thrust = AerostaticThrust(float(br["thrust_inner_radius"]), float(br["thrust_outer_radius"]),
                                  float(br["thrust_feed_radius"]), float(br["thrust_clearance"]),
                                  j.supply_pressure_Pa, orifice_diameter_m=j.orifice_diameter_m,
                                  discharge_coefficient=j.discharge_coefficient)
    return AirBearings(j, forms, runout, supply, thrust)


__all__ = ["build_air_bearings", "journal_from_bearings", "AerostaticJournal", "AerostaticThrust", "AirBearings", "SupplyPressure", "generate_form",
           "orifice_mass_flow", "porous_mass_flow", "slot_mass_flow", "land_mean_pressure"]
