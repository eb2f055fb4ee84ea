"""The bench's thermal state: lumped first-order nodes driven by the lab air and the drive motor.

Model (lumped capacitance, Incropera & DeWitt, *Fundamentals of Heat and Mass Transfer*, ch. 5:
a body whose Biot number is small follows its surroundings as a first-order lag with time
constant tau = m·c/(h·A)); every node starts in the periodic steady state of the lab (the bench
stood in the lab before the run) and the motor is switched on at t = 0 (cold start):

- lab air  T_a(t) = T_0 + A·sin(2·pi·t/P + phi): the papers' environment, 20 ± 1 °C (Jia 2019
  sec. 5 and Hsieh 2022 sec. 3: calibrations in a temperature-controlled room), varying slowly
  (``ambient_period``, a day by default; the phase is drawn from the seed unless given);
- motor  T_m = lag_{tau_m}(T_a) + dT_m·(1 - exp(-t/tau_m)): the drive's dissipation (servo
  holding current) raises it by dT_m at steady state;
- structure (shaft, housings)  T_s = lag_{tau_s}(T_a + share·(T_m - lag(T_a))): fed by the lab and
  a share of the motor's rise through the shaft (two lags in series for the motor's step);
- probe stand, microscope stand and autocollimator: lags of the lab air with their own time
  constants (they stand away from the motor);
- the room control's cycling (``hvac_amplitude``, ``hvac_period``): an air-conditioned room holds
  its set point by cycling, the air swinging ±A with a period of minutes (Bryan 1990, CIRP Annals
  39/2, "International status of thermal error research": the short-period environmental
  variation; ISO 230-3:2020 sec. 5, the environmental temperature variation error ETVE, measures
  exactly this drift). A second sinusoid of the air, phase from the seed; every node lags it with
  its own time constant (closed form as the daily one). Off by default.

Effects (each applied where it physically acts, with its own coefficient):
- axis drift: the housings' uneven growth translates the bearing seats by
  ``axis_drift``·(T_s(t) - T_s(0)) towards the azimuth ``axis_drift_azimuth`` (lab frame); the
  physics moves the housings (twin/physics.py), the shaft follows under its ball/spring forces;
- probe-stand drift: the stand grows along the probe axis by ``probe_stand_growth``·(T_p - T_p(0))
  (an uncompensated aluminium length: 23 ppm/K × 10 mm ≈ 0.2 µm/K); the probes read it as motion;
- microscope-stand drift: the CCD microscope's stand grows along the camera's radial line by
  ``microscope_stand_growth``·(T_c − T_c(0)); the camera sees the disk edge move by it
  (twin/instruments/camera.py renders the disk displaced relative to the microscope);
- autocollimator drift: its zero moves by ``ac_drift``·(T_ac - T_ac(0)) (both axes);
- the measuring loop's nodes (scenario section ``[measuring_loop]``, optional): the read-head mount
  and the autocollimator stand, each a lag of the room air with its own time constant. The mount
  moves every reading head by ``head_mount_growth``·ΔT_h along the disk's tangent (and
  ``head_mount_radial_growth``·ΔT_h outward): twin/instruments/encoder_head.py moves the heads'
  lines of sight, so the counter reads the graduation the displaced head sees (α drifts by
  −growth·ΔT_h/r, exactly through the geometry). The stand's two supports grow across the optical
  axis by different amounts, ``autocollimator_stand_growth``·ΔT over their spacing
  ``autocollimator_stand_base``: the line of sight turns about the vertical by that ratio
  (twin/instruments/autocollimator.py turns the instrument's axis). Sizes: CTE × length, aluminium
  23e-6/K, steel 11.5e-6/K (ASM Handbook vol. 2 / CRC Handbook, 20 °C);
- disk and polygon expansion (``disk_cte``, ``polygon_cte``): a UNIFORM expansion changes no
  angle — the graduation lines and the faces keep their angular positions; it scales radii only
  (the disk's edge radius grows 0.18 µm/K at 22.5 mm in glass). Recorded in truth (scale factors);
  not rendered by the camera (whose edge radius error it would be, ~0.3 px/K: left to the
  camera's model).

Every response is closed-form (the lag of a constant, an exponential and a sinusoid are exact), so
the state at any time costs a few exponentials and no integration error accumulates; ``state(t)``
is a pure function of t for a given scenario and seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

TWO_PI = 2.0 * math.pi


def _lag_sine(A: float, w: float, phi: float, tau: float, t: float) -> float:
    """Periodic steady state of tau·y' + y = A·sin(w·t + phi)."""
    if A == 0.0:
        return 0.0
    wt = w * tau
    return A / math.sqrt(1.0 + wt * wt) * math.sin(w * t + phi - math.atan(wt))


def _lag_step(tau: float, t: float) -> float:
    """Step response 1 - exp(-t/tau) of one lag (0 for t <= 0)."""
    return 0.0 if t <= 0 else -math.expm1(-t / tau)


def _lag2_step(tau1: float, tau2: float, t: float) -> float:
    """Step response of two lags in series (tau1 then tau2), 0 for t <= 0."""
    if t <= 0:
        return 0.0
    if abs(tau1 - tau2) < 1e-9 * max(tau1, tau2):
        x = t / tau1
        return 1.0 - math.exp(-x) * (1.0 + x)
    return 1.0 - (tau1 * math.exp(-t / tau1) - tau2 * math.exp(-t / tau2)) / (tau1 - tau2)


@dataclass(frozen=True)
class ThermalState:
    """Temperatures (°C) of the bench's nodes at one time."""

    t_s: float
    ambient_degC: float
    motor_degC: float
    structure_degC: float
    probe_stand_degC: float
    autocollimator_degC: float
    microscope_stand_degC: float = 0.0


class Thermal:
    """The thermal model of one bench (scenario section ``[thermal]``, SI / °C values)."""

    def __init__(self, th: dict, phase_rad: float, loop: dict | None = None):
        """``th``: the ``[thermal]`` values (SI); ``loop``: the optional ``[measuring_loop]`` values
        (None: none, no instrument of the loop moves)."""
        self.T0 = float(th["ambient"])
        self.A = float(th["ambient_amplitude"])
        self.P = float(th["ambient_period"])
        self.w = TWO_PI / self.P
        self.phi = float(phase_rad)
        self.dTm = float(th["motor_rise"])
        self.tau_m = float(th["motor_time_constant"])
        self.tau_s = float(th["structure_time_constant"])
        self.share = float(th["structure_motor_share"])
        self.tau_p = float(th["probe_stand_time_constant"])
        self.tau_ac = float(th["autocollimator_time_constant"])
        self.axis_drift_m_K = float(th["axis_drift"])
        self.axis_azimuth_rad = float(th["axis_drift_azimuth"])
        self.probe_stand_m_K = float(th["probe_stand_growth"])
        self.ac_rad_K = float(th["ac_drift"])
        self.disk_cte = float(th["disk_cte"])
        self.polygon_cte = float(th["polygon_cte"])
        # the room control's cycling (absent keys: none; older callers pass only the keys above)
        self.Ac = float(th.get("hvac_amplitude") or 0.0)
        self.wc = TWO_PI / float(th.get("hvac_period") or 1200.0)
        self.phic = float(th.get("hvac_phase") or 0.0)
        self.mic_m_K = float(th.get("microscope_stand_growth") or 0.0)
        self.tau_c = float(th.get("microscope_stand_time_constant") or 600.0)
        # the measuring loop's nodes ([measuring_loop]; absent: no growth)
        lp = dict(loop or {})
        self.head_t_m_K = float(lp.get("head_mount_growth") or 0.0)
        self.head_r_m_K = float(lp.get("head_mount_radial_growth") or 0.0)
        self.tau_h = float(lp.get("head_mount_time_constant") or 1000.0)
        self.acs_m_K = float(lp.get("autocollimator_stand_growth") or 0.0)
        self.acs_base_m = float(lp.get("autocollimator_stand_base") or 0.1)
        self.tau_acs = float(lp.get("autocollimator_stand_time_constant") or 3600.0)
        self._s0 = self.state(0.0)
        self._h0 = self.node_degC(self.tau_h, 0.0)
        self._acs0 = self.node_degC(self.tau_acs, 0.0)

    @property
    def active(self) -> bool:
        """False when nothing can change with time (all drifts or all variations zero)."""
        varies = self.A > 0 or self.dTm > 0 or self.Ac > 0
        acts = self.axis_drift_m_K or self.probe_stand_m_K or self.ac_rad_K or self.mic_m_K
        return bool(varies and acts)

    @property
    def loop_active(self) -> bool:
        """True when a node of the measuring loop moves an instrument ([measuring_loop] growths)."""
        return bool(self.head_t_m_K or self.head_r_m_K or self.acs_m_K)

    def node_degC(self, tau_s: float, t_s: float) -> float:
        """Temperature (°C) at t of a node that lags the lab air (daily cycle and the control's
        cycling) with time constant ``tau_s``, in the lab's periodic steady state (closed form)."""
        t = float(t_s)
        return self.T0 + (_lag_sine(self.A, self.w, self.phi, tau_s, t) + _lag_sine(self.Ac, self.wc, self.phic, tau_s, t))

    def state(self, t_s: float) -> ThermalState:
        t = float(t_s)
        T0, A, w, phi = self.T0, self.A, self.w, self.phi
        Ac, wc, phic = self.Ac, self.wc, self.phic

        def air(tau: float) -> float:   # the lab air's daily and cycling parts through one lag
            return _lag_sine(A, w, phi, tau, t) + _lag_sine(Ac, wc, phic, tau, t)

        amb = T0 + A * math.sin(w * t + phi) + Ac * math.sin(wc * t + phic)
        motor = T0 + air(self.tau_m) + self.dTm * _lag_step(self.tau_m, t)
        struct = (T0 + air(self.tau_s)
                  + self.share * self.dTm * _lag2_step(self.tau_m, self.tau_s, t))
        probe = T0 + air(self.tau_p)
        ac = T0 + air(self.tau_ac)
        mic = T0 + air(self.tau_c)
        return ThermalState(t, amb, motor, struct, probe, ac, mic)

    # ------------------------------------------------------------------ effects
    def axis_drift_m(self, t_s: float) -> np.ndarray:
        """Translation (x, y) of both bearing seats (lab frame, m) since t = 0."""
        d = self.axis_drift_m_K * (self.state(t_s).structure_degC - self._s0.structure_degC)
        return d * np.array([math.cos(self.axis_azimuth_rad), math.sin(self.axis_azimuth_rad)])

    def structure_rise_K(self, t_s: float) -> float:
        """Temperature of the structure (shaft, hub, housings) at t minus at t = 0 (K): drives the
        hidden clamp distortion of the disk (twin/hidden.py, thermal_growth)."""
        return self.state(t_s).structure_degC - self._s0.structure_degC

    def probe_stand_drift_m(self, t_s: float) -> float:
        """Growth of the probe stand along the probe axis since t = 0 (m), read as motion."""
        return self.probe_stand_m_K * (self.state(t_s).probe_stand_degC - self._s0.probe_stand_degC)

    def microscope_stand_drift_m(self, t_s: float) -> float:
        """Growth of the CCD microscope's stand along the camera's radial line since t = 0 (m):
        positive moves the microscope outward, so the edge appears that much further in."""
        if not self.mic_m_K:
            return 0.0
        return self.mic_m_K * (self.state(t_s).microscope_stand_degC - self._s0.microscope_stand_degC)

    def ac_drift_rad(self, t_s: float) -> float:
        """Autocollimator zero drift since t = 0 (rad, both axes)."""
        return self.ac_rad_K * (self.state(t_s).autocollimator_degC - self._s0.autocollimator_degC)

    def head_mount_degC(self, t_s: float) -> float:
        return self.node_degC(self.tau_h, t_s)

    def autocollimator_stand_degC(self, t_s: float) -> float:
        return self.node_degC(self.tau_acs, t_s)

    def head_mount_drift_m(self, t_s: float) -> tuple[float, float]:
        """Displacement of every reading head since t = 0 by its mount's growth (m): (along the
        disk's counter-clockwise tangent at the head, radially outward)."""
        if not (self.head_t_m_K or self.head_r_m_K):
            return 0.0, 0.0
        dT = self.head_mount_degC(t_s) - self._h0
        return self.head_t_m_K * dT, self.head_r_m_K * dT

    def autocollimator_stand_yaw_rad(self, t_s: float) -> float:
        """Turn of the autocollimator's line of sight about the lab z axis since t = 0 (rad,
        counter-clockwise positive): its stand's differential growth over the supports' spacing."""
        if not self.acs_m_K:
            return 0.0
        return self.acs_m_K * (self.autocollimator_stand_degC(t_s) - self._acs0) / self.acs_base_m

    def disk_scale(self, t_s: float) -> float:
        """Radius scale of the disk (uniform expansion of the structure's temperature)."""
        return 1.0 + self.disk_cte * (self.state(t_s).structure_degC - self.T0)

    def truth(self, t_end_s: float | None = None) -> dict:
        out: dict[str, Any] = {
            "ambient_degC": self.T0, "ambient_amplitude_K": self.A, "ambient_period_s": self.P,
            "ambient_phase_rad": self.phi, "motor_rise_K": self.dTm, "motor_time_constant_s": self.tau_m,
            "structure_time_constant_s": self.tau_s, "structure_motor_share": self.share,
            "probe_stand_time_constant_s": self.tau_p, "autocollimator_time_constant_s": self.tau_ac,
            "axis_drift_m_per_K": self.axis_drift_m_K, "axis_drift_azimuth_rad": self.axis_azimuth_rad,
            "probe_stand_growth_m_per_K": self.probe_stand_m_K, "ac_drift_rad_per_K": self.ac_rad_K,
            "disk_cte_per_K": self.disk_cte, "polygon_cte_per_K": self.polygon_cte,
        }
        if self.Ac > 0 or self.mic_m_K:   # only when on: the truth of other benches is unchanged
            out.update({"hvac_amplitude_K": self.Ac, "hvac_period_s": TWO_PI / self.wc, "hvac_phase_rad": self.phic,
                        "microscope_stand_growth_m_per_K": self.mic_m_K,
                        "microscope_stand_time_constant_s": self.tau_c})
        if self.loop_active:   # only when on: the truth of other benches is unchanged
            out["measuring_loop"] = {
                "head_mount_growth_m_per_K": self.head_t_m_K, "head_mount_radial_growth_m_per_K": self.head_r_m_K,
                "head_mount_time_constant_s": self.tau_h,
                "autocollimator_stand_growth_m_per_K": self.acs_m_K,
                "autocollimator_stand_base_m": self.acs_base_m,
                "autocollimator_stand_time_constant_s": self.tau_acs}
            if t_end_s is not None:
                out["measuring_loop"]["at_end"] = {
                    "t_s": float(t_end_s), "head_mount_degC": self.head_mount_degC(t_end_s),
                    "head_mount_drift_m": list(self.head_mount_drift_m(t_end_s)),
                    "autocollimator_stand_degC": self.autocollimator_stand_degC(t_end_s),
                    "autocollimator_stand_yaw_rad": self.autocollimator_stand_yaw_rad(t_end_s)}
        if t_end_s is not None:
            e = self.state(t_end_s)
            out["at_end"] = {"t_s": float(t_end_s), **{k: getattr(e, k) for k in
                             ("ambient_degC", "motor_degC", "structure_degC", "probe_stand_degC",
                              "autocollimator_degC")},
                             "axis_drift_m": self.axis_drift_m(t_end_s).tolist(),
                             "probe_stand_drift_m": self.probe_stand_drift_m(t_end_s),
                             "ac_drift_rad": self.ac_drift_rad(t_end_s)}
            if self.Ac > 0 or self.mic_m_K:
                out["at_end"]["microscope_stand_degC"] = e.microscope_stand_degC
                out["at_end"]["microscope_stand_drift_m"] = self.microscope_stand_drift_m(t_end_s)
        return out


__all__ = ["Thermal", "ThermalState"]
