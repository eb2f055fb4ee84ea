"""The drive servo: a digital PID on the encoder's COUNT, the spin drive train integrated by MuJoCo.

Why: a real rotary stage does not stop where its encoder reads the commanded value. Its position
loop closes on the quantised count (Jia et al. 2019 sec. 3: the Mercury 3000 resolves 0.39″), so
at rest the count equals the command while the continuous (interpolated) reading sits anywhere in
the count's cell, ±½ count: for a position uniform in the cell its standard deviation is
res/√12 (GUM, JCGM 100:2008 sec. 4.3.7, rectangular distribution; 0.113″ at 0.39″).

What is integrated (models/drive.xml, ``mj_step``, implicitfast, 20 µs):
- the motor rotor (inertia J_m, viscous drag b_m) driven by the current loop's torque, saturated;
- the torsional coupling rotor → shaft: the drive coupling in series with the shaft between
  polygon and disk (``bearings.drive_torsional_stiffness``, ``shaft_torsional_stiffness``), with
  light material damping (ζ = 2 %);
- the rotating bench as one inertia J_s taken from the bench's own MuJoCo model (twin/physics.py
  mass matrix M[spin, spin]: the same bodies);
- bearing friction as MuJoCo's dry friction (``frictionloss``: a constraint, so the shaft truly
  sticks while the transmitted torque is below it) with a Stribeck curve between the static
  (breakaway) torque T_s and the sliding torque T_c (``bearings.friction_torque``):
  T_f(ω) = T_c + (T_s − T_c)·exp(−(ω/ω_s)²) (Armstrong-Hélouvry, Dupont, Canudas de Wit 1994,
  Automatica 30(7) 1083, eq. 2; Olsson et al. 1998, Eur. J. Control 4, 176, sec. 2). The friction
  level is updated at every servo sample from the shaft speed (zero-order hold between samples).

The controller (``drive`` section of the scenario): a PID sampled at ``servo_rate`` on the error
in COUNTS between the trajectory generator's count and the encoder's count (head 1), with velocity
feed-forward, a first-order filtered count-difference velocity for the D term, and an integrator
clamped to the torque limit (anti-windup). Gains from the bandwidth ω_c and the total inertia J
(pole placement for a rigid inertia: K_p = J·ω_c², K_d = 2ζJ·ω_c with ζ = 0.7, K_i = K_p·ω_c/2 (a fast integrator: it, not K_p, carries the friction);
e.g. Franklin, Powell, Workman, *Digital Control of Dynamic Systems*, 3rd ed., ch. 8).
Amplifier current noise (``torque_noise``, white at the sample rate, seeded per stop) and the phase of
the free-running sample clock at the move's end are the random inputs: they set where in the cell
the shaft sticks.

The sample clock's phase (issue #33, "an honest servo"): drawn per move, uniform on [0, Ts), from
the move's own stream (``servo_clock``, keyed as the move's amplifier-noise draw:
twin/streams.py ``restream``), not derived from the bench time. Why: the drive's sample clock runs
free on the controller, and the host's move command reaches it through a link whose delay varies by
far more than one sample (Ts = 200 µs at 5 kHz), so at the scale of one sample the phase at which a
profile starts (and ends) is unrelated to the host's clock. Sources read for the link's time scales:
USB full and low speed schedule every transaction in 1 ms frames ("The host schedules transactions
within 1mS frames for low and full speed", Freescale TWR-MCF52259 user manual p. 110, "Frames in
More Detail", https://freescale-semiconductor.manymanuals.es/hardware/TWR-MCF52259-Ethenet/user-manual-35038/110;
a full-speed host's frame counter is 12000 at 12 MHz "to ensure a SOF generation every
1 ms", Microchip online docs, "37.12.5 Host Frame Length",
https://onlinedocs.microchip.com/oxy/GUID-23E87D1E-D394-4999-8B0C-DC4246E39160-en-US-3/GUID-C530CF47-FFDE-488D-B3B1-C47B04AAEFC7.html);
an FTDI USB-serial bridge holds a short reply (the controller's "move done" the host waits for
before its next command) until its latency timer expires, "The default value of the timer is set
to 16 milliseconds" (FTDI AN232B-04 "Data Throughput, Latency and Handshaking", "Small Amounts of
Data and End of Buffer Conditions", https://www.ftdichip.com/Support/Knowledgebase/an232b_04smalldataend.htm;
settable 1…255 ms, 1 ms "the same as the USB frame length",
https://www.ftdichip.com/Support/Knowledgebase/settingacustomdefaultlaten.htm). A character at
8N1 takes 10 bits, 1.04 ms at 9600 baud (87 µs at 115200), so a command's transfer alone varies with
its length by several samples. With every delay many samples long and varying by up to a USB frame (5 samples) or more, the phase
modulo 200 µs is uniform for all practical purposes and independent between moves. (Before: the
phase was the bench time modulo Ts; the twin's bench time is exact, so whenever a repetition's
period was a whole number of samples every stop repeated its phase, and the friction-held twist
repeated between repetitions: docs/loop-validation.md, "Eq. 3's lack of fit against pure error".)

What is simulated per move: only the tail of the trapezoidal profile (the last
``DRIVE_TAIL_S`` of the deceleration, starting on the reference with the steady tracking state:
friction carried by the integrator, the coupling twisted by it) and the settling after the
reference has stopped, until the count has equalled the command and the shaft has not moved by a
count for ``settle_window`` (or the controller's ``settle_time`` has passed: the stage then keeps
the count it holds, which may differ from the command by the hunting's amplitude, and reports it:
"ok" within the in-position window ``in_position_window_counts``, else "not_held" with the count). The stage
reports the move done ``settle_time`` after the profile ends, whenever the servo came to rest
within it (a fixed in-position wait, as motion controllers do): the bench clock advances by the
profile plus that time, never by a quantity of the simulated dynamics. Everything upstream of the
tail is the profile (the servo tracks it to well within a count at 20°/s; nothing of it survives
the stop but the state handed over). The result, ``Rest``: the offset of the continuous reading
from the centre of the held count's cell, the held count, the friction torque the bearing holds
at rest (it twists the shaft: twin/physics.py poses the bench with it) and the time it took.

Frame: the drive model's angles are the encoder's READING minus the cell centre of the commanded
count (the reading equals disk rotation + α, α varying by ≤ e/r ≈ 3e-4 of a displacement: within
a few counts the map is a shift; twin/instruments/stage.py then poses the bench where the exact
continuous reading is the rest value, so the reading at rest is exact, not linearised).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

import mujoco
import numpy as np

from benchtwin.twin.streams import restream
from benchtwin.units import ARCSEC

from .stage import sim_rng_from_key

#: seconds of the deceleration simulated before the reference stops (the rest is the profile)
DRIVE_TAIL_S = 0.003
#: longest physics step (s): 1/10 of the fastest motion the loop controls (its 200 Hz bandwidth ↔ 5 ms)
DRIVE_MAX_DT = 1e-4
#: inertia of the friction contact element (kg·m²): numerical, small against the shaft's
CONTACT_INERTIA = 1e-6
#: damping ratio of the PD part (pole placement) and of the coupling's material damping
PD_ZETA = 0.7
COUPLING_ZETA = 0.02
#: integrator corner: K_i = K_p·ω_c / INTEGRAL_RATIO
INTEGRAL_RATIO = 2.0
#: velocity filter of the D term: first order, corner at this fraction of the sample rate
VELOCITY_FILTER_FRACTION = 0.1


def drive_template_path() -> str:
    return str(resources.files("benchtwin.models").joinpath("drive.xml"))


@dataclass(frozen=True)
class DriveParams:
    """The drive train and servo, SI (kg·m², N·m/rad, N·m, rad/s, Hz, s)."""

    shaft_inertia: float           # J_s: the rotating bench (from the bench's mass matrix)
    motor_inertia: float = 1.8e-5
    motor_damping: float = 1e-4    # N·m·s/rad
    coupling_stiffness: float = 690.0
    friction_torque: float = 0.0   # T_c, sliding
    static_friction_ratio: float = 1.2
    stribeck_speed: float = 1e-3   # ω_s, rad/s
    presliding_angle: float = 5e-5  # rad: elastic pre-sliding range of the bearing at T_s
    bandwidth_hz: float = 200.0
    servo_rate_hz: float = 5000.0
    torque_limit: float = 0.5
    torque_noise: float = 0.0      # N·m rms per sample
    settle_window_s: float = 3e-3
    max_settle_s: float = 0.1
    resolution_rad: float = 0.39 * ARCSEC
    # The controller's in-position window (counts): the move is reported done ("ok") when the count
    # it holds at rest is within this many counts of the commanded one, else "not_held" with the
    # count held (SimRotaryStage.move_to). Motion controllers state completion this way (an
    # "in-position band" on the following error); ±1 count keeps the held reading within 1.5
    # counts of a target that is not itself a whole count. A controller constant, not a scenario
    # key: nothing a scenario states changes it.
    in_position_window_counts: int = field(default=1, init=False)

    @classmethod
    def from_scenario(cls, sc: Any, shaft_inertia: float, friction_torque: float | None = None) -> "DriveParams":
        """From the scenario's [drive] and [bearings]; ``friction_torque``: the TRUE sliding friction
        (the bench's, hidden extra friction included), else ``bearings.friction_torque``."""
        br, b = sc["bearings"], sc["bench"]
        dr = _section(sc, "drive")
        kd, ks = float(br["drive_torsional_stiffness"]), float(br["shaft_torsional_stiffness"])
        kw = {k: float(dr[k]) for k in ("motor_inertia", "motor_damping", "static_friction_ratio", "stribeck_speed",
                                        "presliding_angle", "torque_limit", "torque_noise", "settle_window", "settle_time")
              if k in dr}
        for a, b_ in (("settle_window", "settle_window_s"), ("settle_time", "max_settle_s")):
            if a in kw:
                kw[b_] = kw.pop(a)
        if "bandwidth" in dr:
            kw["bandwidth_hz"] = float(dr["bandwidth"])
        if "servo_rate" in dr:
            kw["servo_rate_hz"] = float(dr["servo_rate"])
        return cls(shaft_inertia=float(shaft_inertia), coupling_stiffness=kd * ks / (kd + ks),
                   friction_torque=float(br["friction_torque"] if friction_torque is None else friction_torque),
                   resolution_rad=float(b["encoder_resolution"]),
                   **kw)


def spin_inertia_kgm2(model: mujoco.MjModel, joint: str = "spin") -> float:
    """Moment of inertia about ``joint`` of everything it carries: the diagonal of MuJoCo's joint-
    space mass matrix at the model's reference pose (for the bench: disk, shaft, spheres, polygon)."""
    d = mujoco.MjData(model)
    mujoco.mj_forward(model, d)
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, d, M)
    i = model.joint(joint).dofadr[0]
    return float(M[i, i])


def _section(sc: Any, name: str) -> dict:
    try:
        s = sc[name]
    except (KeyError, TypeError):
        return {}
    return dict(s or {})


#: every input of one settle: (distance rad, speed rad/s, acceleration rad/s², bench time the profile
#: stops s, entropy of its amplifier-noise stream): the rest is a pure function of it. The bench time
#: identifies the move (settle_ahead.py matches keys bit for bit) but no longer enters the physics:
#: the sample clock's phase is drawn from the entropy's ``servo_clock`` twin (``clock_phase_s``).
SettleKey = tuple[float, float, float, float, tuple[int, ...]]


@dataclass(frozen=True)
class Rest:
    """Where the servo left the shaft."""

    offset_rad: float        # continuous reading − centre of the COMMANDED count's cell
    held_count: int          # count the encoder shows at rest − commanded count (0 when settled)
    friction_torque_Nm: float  # torque the bearing friction exerts on the shaft at rest (sign: +CCW)
    settle_s: float          # time from the reference's stop to rest
    steps: int               # mj_step calls
    settled: bool


class DriveServo:
    """The drive train (models/drive.xml) under the count servo. One ``MjData``: not thread-safe."""

    @classmethod
    def sim_from_bench(cls, sc: Any, bench: Any) -> "DriveServo":
        """The servo of a bench: its rotating inertia from the bench's MuJoCo model, its true
        friction (``Bench.friction_torque_Nm``)."""
        return cls(DriveParams.from_scenario(sc, spin_inertia_kgm2(bench.model),
                                             getattr(bench, "friction_torque_Nm", None)))

    def __init__(self, params: DriveParams):
        p = self.p = params
        m = self.model = mujoco.MjModel.from_xml_path(drive_template_path())
        self.data = mujoco.MjData(m)
        self._jr, self._js = m.joint("rotor").dofadr[0], m.joint("shaft").dofadr[0]
        self._jc = m.joint("contact").dofadr[0]
        self._qr, self._qs = m.joint("rotor").qposadr[0], m.joint("shaft").qposadr[0]
        self._qc = m.joint("contact").qposadr[0]
        m.body_inertia[m.body("rotor").id, 2] = p.motor_inertia
        m.body_inertia[m.body("shaft").id, 2] = p.shaft_inertia
        m.dof_damping[self._jr] = p.motor_damping
        t = m.tendon("coupling").id
        m.tendon_stiffness[t] = p.coupling_stiffness
        j_red = p.motor_inertia * p.shaft_inertia / (p.motor_inertia + p.shaft_inertia)
        m.tendon_damping[t] = 2 * COUPLING_ZETA * math.sqrt(p.coupling_stiffness * j_red)
        m.actuator_ctrlrange[0] = (-p.torque_limit, p.torque_limit)
        self.f_static = p.friction_torque * p.static_friction_ratio
        m.dof_frictionloss[self._jc] = self.f_static
        # Pre-sliding: the rolling contacts deform elastically before they slide (Dahl 1976;
        # Al-Bender & Symens 2005, ball bearings): a spring of stiffness T_s/δ_ps between shaft and
        # the contact element that carries the dry friction. No friction: the element is not needed.
        tp = m.tendon("presliding").id
        self.k_ps = self.f_static / p.presliding_angle if self.f_static > 0 else 0.0
        m.tendon_stiffness[tp] = self.k_ps
        # The contact element (the "bristles" of the LuGre picture, Olsson et al. 1998 sec. 3.5) has
        # a numerical inertia of 1e-6 kg·m² (≈ 2 % of the jia2019 shaft); its spring-damper is
        # damped at ζ = 0.7 against it.
        m.body_inertia[m.body("contact").id, 2] = CONTACT_INERTIA
        m.tendon_damping[tp] = 2.0 * PD_ZETA * math.sqrt(self.k_ps * CONTACT_INERTIA) if self.k_ps else 0.0
        # Time step: the servo period split into the fewest steps that keep ω·dt ≤ 1 for the
        # coupling mode (semi-implicit Euler is stable to ω·dt < 2; the mode is above the loop's
        # reach and only has to stay bounded), and at most DRIVE_MAX_DT.
        w_c = math.sqrt(p.coupling_stiffness * (1.0 / p.motor_inertia + 1.0 / p.shaft_inertia))
        # ... and for the pre-sliding mode of the contact element (its stick phase is where the
        # rest is decided: the rest offsets are converged to < 0.01″ in mean and σ from 5e-5 s
        # down to 1.25e-5 s, and are not at 1e-4 s)
        w_b = math.sqrt(self.k_ps / CONTACT_INERTIA) if self.k_ps else 0.0
        Ts = 1.0 / p.servo_rate_hz
        self.substeps = max(1, math.ceil(Ts / min(DRIVE_MAX_DT, 1.0 / max(w_c, w_b))))
        m.opt.timestep = Ts / self.substeps
        self.Ts = Ts
        self.coupling_mode_hz = w_c / (2 * math.pi)
        mujoco.mj_setConst(m, self.data)
        J = p.motor_inertia + p.shaft_inertia
        wc = 2 * math.pi * p.bandwidth_hz
        self.Kp = J * wc**2
        self.Kd = 2 * PD_ZETA * J * wc
        self.Ki = self.Kp * wc / INTEGRAL_RATIO
        self.J = J
        self._vf = math.exp(-2 * math.pi * VELOCITY_FILTER_FRACTION)   # pole of the velocity filter
        self.total_steps = 0

    def describe(self) -> dict[str, Any]:
        p = self.p
        return {"model": "models/drive.xml: rotor + coupling + shaft, PID on the encoder count",
                "motor_inertia_kgm2": p.motor_inertia, "shaft_inertia_kgm2": p.shaft_inertia,
                "coupling_stiffness_Nm_rad": p.coupling_stiffness, "sliding_friction_Nm": p.friction_torque,
                "static_friction_Nm": self.f_static, "stribeck_speed_rad_s": p.stribeck_speed,
                "bandwidth_hz": p.bandwidth_hz, "servo_rate_hz": 1.0 / self.Ts, "timestep_s": self.model.opt.timestep,
                "Kp_Nm_rad": self.Kp, "Ki_Nm_rad_s": self.Ki, "Kd_Nms_rad": self.Kd,
                "torque_limit_Nm": p.torque_limit, "torque_noise_Nm": p.torque_noise,
                "settle_window_s": p.settle_window_s, "max_settle_s": p.max_settle_s}

    def _friction(self, w: float) -> float:
        p = self.p
        if p.friction_torque == 0.0:
            return 0.0
        return p.friction_torque + (self.f_static - p.friction_torque) * math.exp(-(w / p.stribeck_speed) ** 2)

    def clock_phase_s(self, rng_key: tuple[int, ...]) -> float:
        """The sample clock's phase at the tail's start of the move whose amplifier-noise entropy is
        ``rng_key``: uniform on [0, Ts), one draw of its ``servo_clock`` stream (module docstring)."""
        return float(sim_rng_from_key(restream(rng_key, "servo_clock")).uniform(0.0, self.Ts))

    def settle_keyed(self, key: SettleKey) -> Rest:
        """``settle`` of a move given by its key (``SimRotaryStage.settle_key``): the noise stream
        and the clock's phase made from its entropy here, so a worker computes the same rest
        (settle_ahead.py)."""
        distance, speed, accel, _t_end, rng_key = key
        return self.settle(distance, speed, accel, self.clock_phase_s(rng_key), rng=sim_rng_from_key(rng_key))

    def _steps_before_first_sample(self, clock_phase_s: float) -> int:
        """Physics steps from the simulated tail's start to the servo's first sample: the
        free-running sample clock's phase there (drawn per move, module docstring), taken to the
        physics step below it, 0 … substeps − 1."""
        phase = float(clock_phase_s)
        if not 0.0 <= phase < self.Ts:
            raise ValueError(f"clock phase {phase!r} s outside [0, {self.Ts!r})")
        return min(self.substeps - 1, int(phase / self.model.opt.timestep))

    def settle(self, distance_rad: float, speed_rad_s: float, accel_rad_s2: float, clock_phase_s: float,
               rng: np.random.Generator | None = None, friction_scale: float = 1.0) -> Rest:
        """Simulate the end of a move of ``distance_rad`` (signed, in reading units) whose profile
        stops on the centre of the commanded count's cell, and the settling after it.
        ``clock_phase_s``: time from the simulated tail's start to the servo's first sample, in
        [0, Ts) (taken to the physics step below it). ``rng``: the stop's amplifier-noise stream
        (None: no noise)."""
        p, m, d = self.p, self.model, self.data
        res = p.resolution_rad
        sgn = 1.0 if distance_rad >= 0 else -1.0
        dist = abs(float(distance_rad))
        # The tail of the profile: deceleration a for the last τ seconds (shorter moves: the whole
        # triangular profile's deceleration half).
        t_dec = speed_rad_s / accel_rad_s2 if accel_rad_s2 > 0 else 0.0
        t_half = math.sqrt(dist / accel_rad_s2) if accel_rad_s2 > 0 else 0.0
        tau = min(DRIVE_TAIL_S, t_dec, t_half) if accel_rad_s2 > 0 else 0.0
        a = accel_rad_s2

        def ref(t):   # t: time to the profile's end (≥ 0) → (position, velocity, acceleration)
            if t <= 0.0:
                return 0.0, 0.0, 0.0
            return -sgn * 0.5 * a * t * t, sgn * a * t, -sgn * a

        # Steady tracking state at the start of the tail: on the reference, the friction opposing
        # the motion carried by the integrator, the coupling twisted by it.
        x0, v0, _ = ref(tau)
        Tf0 = sgn * p.friction_torque * friction_scale if v0 != 0.0 else 0.0
        mujoco.mj_resetData(m, d)
        d.qpos[self._qs] = x0
        d.qpos[self._qr] = x0 + Tf0 / p.coupling_stiffness
        d.qpos[self._qc] = x0 - (Tf0 / self.k_ps if self.k_ps else 0.0)
        d.qvel[self._js] = d.qvel[self._jr] = d.qvel[self._jc] = v0
        integ = Tf0
        n_pre = self._steps_before_first_sample(clock_phase_s)
        if n_pre:
            m.dof_frictionloss[self._jc] = self._friction(v0)
            mujoco.mj_step(m, d, nstep=n_pre)
        t = tau - n_pre * m.opt.timestep                  # time to the profile's end
        count_prev = round(d.qpos[self._qs] / res)
        vel = v0
        Ts, kp, ki, kd = self.Ts, self.Kp, self.Ki, self.Kd
        lim = p.torque_limit
        win = max(1, int(round(p.settle_window_s / Ts)))
        max_samples = int(math.ceil((tau + p.max_settle_s) / Ts))
        still, settled, steps = 0, False, n_pre
        ref_anchor = d.qpos[self._qs]
        noise = (rng.normal(0.0, p.torque_noise, max_samples) if (rng is not None and p.torque_noise > 0)
                 else np.zeros(max_samples)).tolist()
        # The loop runs once per servo sample: views and constants hoisted, and the state read as
        # Python floats (the same IEEE-754 operations as on NumPy scalars, at a third of their
        # cost; the benchmark's ratio to raw mj_step, docs/benchmarks.md, is this loop's Python
        # overhead).
        qpos, qvel, ctrl, fl = d.qpos, d.qvel, d.ctrl, m.dof_frictionloss
        qs, jc, nsub, vf, J = self._qs, self._jc, self.substeps, self._vf, self.J
        Tc, dT, ws = (friction_scale * p.friction_torque, friction_scale * (self.f_static - p.friction_torque),
                      p.stribeck_speed)
        step = mujoco.mj_step
        exp = math.exp
        half_a = 0.5 * a
        ref_anchor = float(ref_anchor)
        vel = float(vel)
        for k in range(max_samples):
            if t > 0.0:
                xr, vr, ar = -sgn * half_a * t * t, sgn * a * t, -sgn * a
            else:
                xr = vr = ar = 0.0
            x = float(qpos[qs])
            count = round(x / res)                         # the encoder's count (reading units)
            err = (round(xr / res) - count) * res            # the trajectory generator's count − count
            vel = vf * vel + (1 - vf) * (count - count_prev) * res / Ts
            count_prev = count
            integ = min(max(integ + ki * err * Ts, -lim), lim)
            ctrl[0] = kp * err + integ + kd * (vr - vel) + J * ar + noise[k]
            if Tc:
                w = float(qvel[jc]) / ws
                fl[jc] = Tc + dT * exp(-w * w)
            step(m, d, nstep=nsub)
            t -= Ts
            if t <= 0.0:
                # at rest: the count is the command and the shaft has not moved by a count
                x = float(qpos[qs])
                if round(x / res) == 0 and abs(x - ref_anchor) < res:
                    still += 1
                    if still >= win:
                        settled = True
                        break
                else:
                    still, ref_anchor = 0, x
        steps += (k + 1) * nsub
        self.total_steps += steps
        x = float(d.qpos[self._qs])
        mujoco.mj_forward(m, d)
        # torque the bearing exerts on the shaft at rest: the pre-sliding spring (and its damper)
        tf = float(d.qfrc_passive[self._jc]) * -1.0 if self.k_ps else 0.0
        settle_s = max(0.0, -t)
        return Rest(offset_rad=x, held_count=int(round(x / res)), friction_torque_Nm=tf, settle_s=settle_s,
                    steps=steps, settled=settled)


__all__ = ["DriveServo", "DriveParams", "Rest", "SettleKey", "drive_template_path", "spin_inertia_kgm2", "DRIVE_TAIL_S"]
