"""The simulated drive and the shared bench state of the twin's instruments.

- ``SimBenchState``: what every simulated instrument looks at: the ``Bench`` (physics), the
  simulated clock, the current ``BenchPose``, and the run context (rep, approach direction,
  polygon mounting: start face j and shift S). It also hands out the instruments' random streams,
  keyed by (scenario seed, stream, instrument, runner step index), so a run interrupted and
  resumed from its journal draws exactly the same noise as an uninterrupted one.
- ``SimRotaryStage``: ``hw.interfaces.RotaryStage`` on the simulated clock. ``move_to(target_deg)``
  finds the drive command at which head 1 of the encoder READS the target (the bench stops at
  commanded encoder readings, as a real servo closes its loop on the interpolated encoder signal),
  by fixed-point iteration on the exact (noise-free, unquantised) reading, to ``tol_arcsec``
  (1e-6″ by default: 2.5e-6 of the 0.39″ resolution), starting from the command offset found
  the last time the same target was approached in the same rep and direction (else the previous
  stop's); advances the clock by the move time
  (trapezoidal profile, ``speed``/``accel``) and poses the bench there. Soft limits
  (``soft_limits_deg``, none by default) follow ``hw.interfaces.RotaryStage``'s contract: a target
  outside them raises ``SoftLimitError`` before anything moves or the clock advances.

Polygon mounting (re-clamping) is a property of the state, not of the physics: the physics poses
the polygon in its nominal mounting (face 1's normal on body +x, ``Bench.pose_at``); the state
turns the polygon's body frame about its own axis by the mounting angle
    μ = ψ_AC + (j − 1)·2π/N − S + U'_j
(ψ_AC the autocollimator's azimuth, j the start face in Hsieh's numbering, S the shift, U'_j a
random clamping error, seeded per (rep, shift, start face), ``polygon_setup_rms`` = 1″ by
default), so that face j faces the autocollimator when the encoder reads S (Hsieh 2022 sec. 3).
Hsieh's face h is the physics face k = ((1 − h) mod N) + 1: the physics numbers faces
counter-clockwise in the body, and a counter-clockwise rotation brings the next face in Hsieh's
sequence (clockwise in the body) in front of the autocollimator.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from benchtwin.hw.acquisition.procedures import move_time_s
from benchtwin.hw.acquisition.runner import SimClock
from benchtwin.hw.interfaces import MOVE_NOT_HELD, SoftLimitError, StageMove, StagePosition
from benchtwin.twin.pose import BenchPose, BodyPose
from benchtwin.twin.streams import INSTRUMENT_STREAMS as SIM_STREAMS  # noqa: F401 - simulate.py reads it here
from benchtwin.twin.streams import rng_from_key as sim_rng_from_key
from benchtwin.twin.streams import stream_key as sim_rng_key
from benchtwin.twin.streams import stream_rng as sim_rng
from benchtwin.units import ARCSEC

if TYPE_CHECKING:
    from .drive import SettleKey

TWO_PI = 2.0 * math.pi
#: warm-start offsets the sim stage remembers (LRU; see SimRotaryStage.move_to)
SIM_OFFSET_CACHE_SIZE = 8192

def sim_rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def sim_hsieh_to_physics_face(h: int, n_faces: int) -> int:
    """Physics face index k (1…N, counter-clockwise in the body) of Hsieh's face h (1…N)."""
    return ((1 - int(h)) % n_faces) + 1


def sim_direction(d: Any) -> int:
    if d in ("forward", 1, +1):
        return 1
    if d in ("backward", -1):
        return -1
    raise ValueError(f"direction must be 'forward'/'backward' or ±1, got {d!r}")


class SimBenchState:
    """The shared state of the simulated bench (one per simulation; not thread-safe)."""

    def __init__(self, bench: Any = None, clock: SimClock | None = None, seed: int = 0,
                 pose: BenchPose | None = None, n_faces: int | None = None,
                 ac_azimuth_rad: float = 0.0, polygon_setup_rms_rad: float = 1.0 * ARCSEC):
        self.bench = bench
        self.clock = clock if clock is not None else SimClock()
        self.seed = int(seed if bench is None else getattr(bench, "seed", seed))
        self.pose = pose
        self.n_faces = int(n_faces if n_faces is not None else (bench.n_faces if bench is not None else 0))
        self.ac_azimuth_rad = float(ac_azimuth_rad)
        self.polygon_setup_rms_rad = float(polygon_setup_rms_rad)
        self.rep = 0
        self.direction = 1
        self.polygon_start_face = 1
        self.polygon_shift_rad = 0.0
        self.polygon_setup_error_rad = 0.0
        self.step_index: int | None = None
        self._draws: dict[str, int] = {}
        self.mountings: dict[tuple, dict] = {}   # truth: every polygon mounting used
        self.set_polygon_mounting(1, 0.0)

    # ------------------------------------------------------------------ context
    def apply_context(self, ctx: dict) -> None:
        """Run context from the procedure's Marks: rep, direction, polygon start face and shift."""
        if "rep" in ctx:
            self.rep = int(ctx["rep"])
        if "direction" in ctx:
            self.direction = sim_direction(ctx["direction"])
        if "polygon_start_face" in ctx:
            self.set_polygon_mounting(int(ctx["polygon_start_face"]), math.radians(float(ctx.get("shift_deg", 0.0))))

    def posed(self, pose: BenchPose | None = None) -> BenchPose:
        """``pose``, else the bench's current pose (RuntimeError before the bench is first posed)."""
        p = self.pose if pose is None else pose
        if p is None:
            raise RuntimeError("the bench has not been posed yet")
        return p

    def on_step(self, i: int, step: Any, context: dict, replay: bool) -> None:
        """Runner hook: key the noise streams by step index; apply the context of Marks."""
        self.step_index = int(i)
        self._draws = {}
        if type(step).__name__ == "Mark":
            self.apply_context(context)

    def rng(self, stream: str, instrument_key: int = 0) -> np.random.Generator:
        """Noise stream for one draw of an instrument at the current step (keyed, reproducible)."""
        return sim_rng_from_key(self.rng_key(stream, instrument_key))

    def rng_key(self, stream: str, instrument_key: int = 0) -> tuple[int, ...]:
        """``rng``'s entropy (the draw is counted): the n-th draw of ``stream`` at step i is keyed
        (seed, stream, instrument, i + 1, n)."""
        k = f"{stream}:{instrument_key}"
        n = self._draws.get(k, 0)
        self._draws[k] = n + 1
        step = -1 if self.step_index is None else self.step_index
        return sim_rng_key(self.seed, stream, instrument_key, step + 1, n)

    # ------------------------------------------------------------------ polygon mounting
    def set_polygon_mounting(self, start_face: int, shift_rad: float) -> None:
        N = self.n_faces
        if N and not 1 <= start_face <= N:
            raise ValueError(f"polygon start face must be in 1…{N}, got {start_face}")
        u = 0.0
        if self.polygon_setup_rms_rad > 0:  # seeded per (rep, shift in µdeg, start face)
            shift_key = int(round(math.degrees(shift_rad) * 1e6)) % (2**63)
            u = float(sim_rng(self.seed, "polygon_setup", self.rep, shift_key, start_face)
                      .normal(0.0, self.polygon_setup_rms_rad))
        self.polygon_start_face = int(start_face)
        self.polygon_shift_rad = float(shift_rad)
        self.polygon_setup_error_rad = u
        self.mountings[(self.rep, float(math.degrees(shift_rad)), int(start_face))] = {
            "rep": self.rep, "shift_deg": math.degrees(shift_rad), "start_face": int(start_face),
            "mounting_rad": self.polygon_mounting_rad, "setup_error_rad": u}

    @property
    def polygon_mounting_rad(self) -> float:
        N = self.n_faces or 1
        return (self.ac_azimuth_rad + (self.polygon_start_face - 1) * TWO_PI / N - self.polygon_shift_rad
                + self.polygon_setup_error_rad)

    def polygon_pose(self, pose: BenchPose | None = None) -> BodyPose:
        """The polygon as clamped now: the physics' polygon frame turned by the mounting angle
        about its own axis."""
        p = self.posed(pose)
        return BodyPose(pos=p.polygon.pos, R=p.polygon.R @ sim_rz(self.polygon_mounting_rad))

    # ------------------------------------------------------------------ posing
    def pose_at_command(self, command_rad: float, bearing_torque_Nm: float | None = None) -> BenchPose:
        if bearing_torque_Nm is None:   # (keeps the physics' call as before for the ideal positioner)
            self.pose = self.bench.pose_at(float(command_rad), rep=self.rep, t_s=self.clock.now(),
                                           direction=self.direction)
        else:
            self.pose = self.bench.pose_at(float(command_rad), rep=self.rep, t_s=self.clock.now(),
                                           direction=self.direction, bearing_torque_Nm=bearing_torque_Nm)
        return self.pose


@dataclass(frozen=True)
class StageSpec:
    """The twin stage's motion and stop: speed (deg/s), acceleration (deg/s²), settle time (s),
    the tolerance of a stop on head 1's reading (arcsec), the search's iterations at most, and the
    soft limits (deg; None: none)."""

    speed_deg_s: float = 20.0
    accel_deg_s2: float = 40.0
    settle_s: float = 0.0
    tol_arcsec: float = 1e-6
    max_iter: int = 20
    soft_limits_deg: tuple[float, float] | None = None


class SimRotaryStage:
    """``RotaryStage`` of the twin: stops where head 1 of ``encoder`` reads the target."""

    kind = "stage"

    def __init__(self, name: str, state: SimBenchState, encoder: Any, spec: StageSpec = StageSpec(),
                 servo: Any = None, secant: bool = False):
        self.name = name
        self.spec = spec
        # The search for the command at which head 1 reads the target: the fixed point (the
        # command corrected by the reading's error, slope 1) or, with ``secant``, the secant of the
        # last two poses (the slope 1 − ε of reading vs command, ε the torsional lag's and α's
        # share: superlinear, ~3 poses per stop instead of ~3.7). Both stop at ``tol_arcsec``; the
        # journaled moves keep the fixed point (the count of iterations is in the journal), the truth
        # α grid (twin/simulate.py, not journaled) uses the secant.
        self.secant = bool(secant)
        # The drive servo (twin/instruments/drive.py): None = an ideal positioner that lands the
        # continuous reading on the target (the truth grid of α(θ) uses it).
        self.servo = servo
        self.last_rest = None
        # The settles computed ahead on another core (settle_ahead.py; set by twin/simulate.py for
        # one run of a procedure known in advance): None = every settle here.
        self.sim_ahead: Any = None
        self.state = state
        self.encoder = encoder
        self.speed_deg_s = float(spec.speed_deg_s)
        self.accel_deg_s2 = float(spec.accel_deg_s2)
        self.settle_s = float(spec.settle_s)
        self.tol_rad = float(spec.tol_arcsec) * ARCSEC
        self.max_iter = int(spec.max_iter)
        soft_limits_deg = spec.soft_limits_deg
        if soft_limits_deg is not None and not float(soft_limits_deg[0]) < float(soft_limits_deg[1]):
            raise ValueError(f"{name}: soft_limits_deg must be (low, high) with low < high, got {soft_limits_deg}")
        self.soft_limits_deg = None if soft_limits_deg is None else (float(soft_limits_deg[0]),
                                                                      float(soft_limits_deg[1]))
        self.command_rad = 0.0
        self.held_deg = 0.0
        self.held = True              # the last move ended within the servo's in-position window
        self.target_deg: float | None = None
        self.position_deg = 0.0
        self.last_iterations = 0
        # The last stop's pose and its exact readings (every head; the servo's last evaluation),
        # for the simulation's truth of the readings taken there (twin/simulate.py).
        self.last_pose: BenchPose | None = None
        self.last_exact: np.ndarray | None = None
        # Resume (twin/simulate.py): the simulation has replayed the journaled moves itself, so the
        # runner's re-issued move to where the bench stands holds (nothing moves, no time passes).
        self.sim_hold = False
        # (target_deg, rep, direction) -> command − target, least recently used first. Bounded, so a
        # long acquisition of ever-new stops keeps flat memory (issue 8); 8192 holds every stop of
        # hsieh2022 (15 shifts × 24 faces × 2 directions × 6 runs = 4320).
        self._offsets: OrderedDict[tuple, float] = OrderedDict()

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "kind": "stage", "model": "sim rotary stage (twin)",
                "units": {"target_deg": "deg", "angle_deg": "deg", "duration_s": "s", "t_s": "s"},
                "speed_deg_s": self.speed_deg_s, "accel_deg_s2": self.accel_deg_s2,
                "tolerance_arcsec": self.tol_rad / ARCSEC,
                "soft_limits_deg": None if self.soft_limits_deg is None else [float(v) for v in self.soft_limits_deg]}

    def servo_resolution_rad(self) -> float:
        """The count the servo closes its loop on (rad); 0: no servo (an ideal positioner)."""
        return getattr(self.encoder, "resolution_rad", 0.0) if self.servo is not None else 0.0

    def move_duration_s(self, target_deg: float, from_deg: float) -> float:
        """How long a move takes on the bench clock: the profile, the stage's settle time and, with
        the servo, the controller's fixed in-position wait (drive.py). The clock never depends on
        how the servo settled, so a stop passed through without dynamics (``dynamics=False``)
        leaves every later stop exactly as with them, and every settle of a procedure is known
        before it runs (twin/instruments/settle_ahead.py)."""
        duration = move_time_s(target_deg - from_deg, self.speed_deg_s, self.accel_deg_s2) + self.settle_s
        if self.servo_resolution_rad() > 0:
            duration += self.servo.p.max_settle_s
        return duration

    def settle_key(self, target_deg: float, from_deg: float, t_end_s: float, rng_key: tuple[int, ...]) -> SettleKey:
        """Every input of the servo's settle at the end of a move (``settle_keyed``)."""
        return (math.radians(target_deg - from_deg), math.radians(self.speed_deg_s), math.radians(self.accel_deg_s2),
                t_end_s, rng_key)

    def move_to(self, target_deg: float, dynamics: bool = True) -> StageMove:
        """Move to ``target_deg`` (an encoder reading). ``dynamics=False``: no servo simulation for
        this move (an ideal landing on the target; the clock advances as with it, by the profile
        plus the servo's settle time): for callers that pass through stops nobody reads (the
        emulators fast-forwarding their script)."""
        target_deg = float(target_deg)
        st = self.state
        lim = self.soft_limits_deg
        if not math.isfinite(target_deg) or (lim is not None and not lim[0] <= target_deg <= lim[1]):
            # hw.interfaces.RotaryStage contract: refused before anything moves or the clock runs
            raise SoftLimitError(self.name, target_deg, lim)
        if self.sim_hold:
            self.sim_hold = False
            if self.target_deg == target_deg and self.last_pose is not None and st.pose is self.last_pose:
                return self._result(target_deg, 0.0, 0)
        if (self.servo is not None and self.target_deg == target_deg and self.last_pose is not None
                and st.pose is self.last_pose):
            # Commanding the count the servo already holds moves nothing: the shaft stays stuck where
            # it rests (a re-issued move, e.g. an emulated acquisition resumed at this stop): it still
            # holds the count it held (and says so).
            return self._result(target_deg, 0.0, 0)
        duration = self.move_duration_s(target_deg, self.position_deg)
        target = math.radians(target_deg)
        torque = None
        res = self.servo_resolution_rad()
        if res > 0 and dynamics:
            # The servo holds the COUNT nearest the target: simulate the end of the move and the
            # settling (drive.py); the continuous reading at rest is the count's cell centre plus
            # the rest offset, and the bearing holds the rest torque.
            n_cmd = round(target / res)
            key = self.settle_key(target_deg, self.position_deg, st.clock.now() + duration, st.rng_key("servo", 0))
            rest = self.servo.settle_keyed(key) if self.sim_ahead is None else self.sim_ahead.rest(key)
            self.last_rest = rest
            target = n_cmd * res + rest.offset_rad        # the continuous reading to land on
            torque = rest.friction_torque_Nm
            held_deg = math.degrees((n_cmd + rest.held_count) * res)
            # honest completion: within the controller's in-position window, or "not_held" (below)
            held = abs(rest.held_count) <= self.servo.p.in_position_window_counts
        else:
            held_deg = target_deg
            held = True
        st.clock.advance(duration)
        # Warm start: the offset between command and reading found the last time this target was
        # approached in this rep and direction (the polygon runs come back to the same stops for
        # every start face: the first pose usually holds), else the previous stop's offset.
        warm = (target_deg, st.rep, st.direction)
        offset = self._offsets.get(warm)
        if offset is not None:
            self._offsets.move_to_end(warm)
        else:
            offset = self.command_rad - (math.radians(self.position_deg) if self.target_deg is not None else 0.0)
        cmd = target + offset
        prev: tuple[float, float] | None = None        # the secant's other point (command, error)
        for it in range(1, self.max_iter + 1):
            pose = st.pose_at_command(cmd, torque)
            x = self.encoder.sim_exact_readings(pose)
            err = x[0] - target
            if abs(err) <= self.tol_rad:
                break
            step = err
            if self.secant and prev is not None and cmd != prev[0]:
                slope = (err - prev[1]) / (cmd - prev[0])
                # a slope far from 1 is the rounding of two nearly equal errors: the fixed point
                if 0.5 < slope < 2.0:
                    step = err / slope
            prev = (cmd, err)
            cmd -= step
        else:
            raise RuntimeError(f"{self.name}: no convergence to {target_deg}° (|error| {abs(err) / ARCSEC:.3g}″)")
        self.last_iterations = it
        self._offsets[warm] = cmd - target
        if len(self._offsets) > SIM_OFFSET_CACHE_SIZE:
            self._offsets.popitem(last=False)
        self.last_pose, self.last_exact = pose, x
        if hasattr(self.encoder, "sim_last_exact"):
            self.encoder.sim_last_exact = (pose, x)
        self.command_rad = cmd
        self.target_deg = target_deg
        self.position_deg = target_deg
        self.held_deg = held_deg      # the count the encoder shows at rest (the target without a servo)
        self.held = held
        return self._result(target_deg, duration, it)

    def _result(self, target_deg: float, duration_s: float, iterations: int) -> StageMove:
        """The move's result (``hw.interfaces.StageMove``): "ok" when the servo holds a count within
        its in-position window of the command (drive.py ``in_position_window_counts``); else
        "not_held" with ``held_deg``, the reading of the count it holds (the runner keeps such a
        stop: its readings are valid where the stage stands, and the tables' ``theta_read_deg`` is
        the encoder's reading there)."""
        out: StageMove = {"target_deg": target_deg, "t_s": self.state.clock.now(), "duration_s": duration_s,
                          "status": "ok" if self.held else MOVE_NOT_HELD, "iterations": iterations}
        if not self.held:
            out["held_deg"] = self.held_deg
        return out

    def position(self) -> StagePosition:
        return {"angle_deg": self.position_deg, "t_s": self.state.clock.now(), "status": "ok"}
