"""The bench's physics: a MuJoCo model of the shaft on two bearings, posed by a static solve.

What is modelled, and why (the error motion definitions are those of ISO 230-7:2015 sec. 3 /
ASME B89.3.4, which Jia et al. 2019 (Appl. Sci. 9, 3415) sec. 2 follows: radial error motion of
the axis of rotation, its synchronous (repeating) and asynchronous (non-repeating) parts, the
axis average line as reference):

- The shaft is rigid, carried by two bearings at ``bench.bearing_top_z`` / ``bearing_bottom_z``.
  Each bearing is a radial spring-damper per lab axis (a MuJoCo fixed tendon over the carrier's
  slide and tilt joints, see models/bench.xml) whose REST POSITION is the bearing's rolling-path
  offset. Radial error motion is never prescribed on the shaft: it is what the shaft does when
  its bearings' rolling paths move, under gravity and the other loads — so the disk, the spheres
  and the polygon move as one rigid body and the disk-plane motion follows from the bearing
  geometry (Jia sec. 6: "reduce the distance between the grating disk and the bearing").
- Bearings of ``bearings.type = "ball"`` (twin/bearing.py; Harris & Kotzalas, Wardle 1988): each
  bearing is a set of Z balls between a wavy inner race (turning with the shaft) and a wavy outer
  race (in the housing). The tendon springs are switched off; the journal displacement u = T·q
  (the tendons' lengths) relative to the housing gives every ball's Hertzian contact load at its
  actual azimuth, and the summed ball forces enter the equilibrium as generalized forces Tᵀ·F.
  So the shaft's radial and tilt motion is its response to those forces plus gravity, unbalance
  and the drive; which waviness orders move the centre, and at which frequencies, follows from
  the sums (tests/twin/test_bearing.py checks Wardle's rule emerges). The cage angle is the
  integral of the shaft's true rotation times the kinematic ratio rho along the bench's path,
  plus a seeded random slip (``bearings.cage_slip``, relative to the move's rolling): by default
  an independent draw per start/stop; with ``bearings.cage_slip_time`` > 0 a stationary random
  process s(t) in bench time with that correlation time (each move rolls at (1 − s(t))·rho), and
  ``bearings.cage_slip_mean`` the cage's mean lag behind its kinematic speed. Poses at a new
  ``t_s`` are a new stop (the path advances); poses at the same ``t_s``
  are the servo refining the same stop. A stop revisited after a different path therefore sees
  another ball configuration: the asynchronous error motion. Quasi-static: the bearings' radial
  modes are at ~1.6 kHz, the drive settles in ms, the stops last 0.5 s; a test integrates the same
  model with mj_step and finds the static pose.
- Bearings of ``bearings.type = "air"`` (twin/air_bearing.py; Powell 1970, Stout & Barrue 1977):
  aerostatic journals. The tendon springs take the film's stiffness computed from supply
  pressure, gap and restrictors; their rest positions are the unloaded journal centres the
  journals' form gives through the film's averaging (a sum over the feed sectors: no whirl
  direction imposed), and the supply pressure's fluctuation moves the loaded journals in TIME
  (added to the housings' time-keyed offsets, like the thermal drift).
- Rolling-path offsets of ``bearings.type = "path"`` (per bearing, lab x/y; the REPLAY of a given
  rolling path or a measured motion table, not a bearing model; never the default):
  * race waviness ``waviness_top/bottom``: lobes of the rotating (inner) race, synchronous with
    the shaft. A lobe {order k, amplitude a, phase ψ} moves the rolling-path centre by
    a·(cos(kθ − ψ), sin(kθ − ψ)) at shaft angle θ: a whirl at k cycles/rev (ISO 230-7 polar
    plot of a k-lobed path). Stationary (outer) race waviness is a constant offset and belongs to
    the housing position, which the axis-average-line centring below absorbs — so both races are
    accounted for consistently.
  * rolling-element / cage lobing: the ball set turns with the cage at ``cage_ratio`` (≈ 0.4 for
    an angular-contact bearing: ½·(1 − D_w·cos α / D_pw)) of the shaft speed, so its lobes are NOT
    harmonics of the shaft rotation; the cage slips between runs, so its phase is drawn per rep.
  * a small random non-repeating part (non-integer frequencies, spectrum ∝ 1/f), drawn per rep
    from the scenario seed. The two parts share ``async_rms`` (per bearing, per axis RMS).
  * ``motion_table`` (optional): a measured axis motion (θ, dx, dy, tilt_x, tilt_y in the disk
    plane) replaces the waviness: it is converted to the rolling-path offsets of the two bearings
    that make an unloaded rigid shaft follow it, so gravity and the rest still act physically.
- Gravity along ``bench.gravity_direction`` acts on every rotating mass (sag, and the moment of
  the unbalance about the axis). Unbalance U = m·r is a point mass on the shaft. The poses are
  QUASI-STATIC stops (the bench stops before each reading), so by default the centrifugal force
  m·r·ω² is zero and the unbalance acts through its weight only (a radial force m·g and a
  gravity torque U·g that changes the torque carried by the drive, hence the twist). For readings
  taken on the fly at a steady speed (optional key ``bench.speed``, rad/s) the force U·ω² turns
  with the shaft (xfrc_applied on the unbalance body); the rotor's kHz modes make the steady
  response the static one.
- Drive and torsion: a position actuator (the drive, stiffness ``drive_torsional_stiffness``)
  turns the polygon-side shaft end; the shaft twists between polygon and disk section
  (``shaft_torsional_stiffness``); bearing friction ``friction_torque`` acts on the disk section.
  A quasi-static approach in direction ±1 ends with the friction at its sliding value opposing
  the motion (static friction then holds the transmitted torque), so the twist changes sign with
  the direction: hysteresis. This static state is checked against a dynamic MuJoCo run with
  ``frictionloss`` in tests/twin/test_physics.py.

Lab frame (docs/conventions.md): the housings are placed so that the axis average line (least-
squares axis over one revolution of the synchronous motion) is the lab z axis through the origin
in the disk plane.

Statics instead of stepping: a pose is the equilibrium qfrc_smooth(q) = 0 of the 6 DOFs (radial
x/y, tilt x/y, spin, twist) for the commanded drive angle. It is found by Newton iterations to
|Δq| < 1e-14 m / 1e-14 rad (+ 4 ulp of q) on the last step, far below 1 nm / 0.001″ (4.8e-9 rad);
each iteration is one ``mj_forward``. Rolling-path bearings: a constant stiffness matrix (finite
differences of MuJoCo's generalized forces, once per bench). Ball sets: the full Jacobian, MuJoCo's
constant part plus the ball sets' stiffness and their rate along the spin (twin/ballsets.py) and
gravity's rate on the turning bodies at the pose's angle, so Newton converges quadratically; the
warm start moves the previous pose along its tangent dq/dcmd, and the servo's refinements of a
stop (command changes ≤ 1e-6 rad) settle in one step. MuJoCo warnings are checked
after each pose. Nothing here computes an encoder or probe reading: that is the instruments' job,
from the poses returned here.
"""

from __future__ import annotations

import math
from typing import Any, cast

import mujoco
import numpy as np

from benchtwin.units import ARCSEC

from .air_bearing import AirBearings, build_air_bearings
from .axial import Axial, build_axial
from .ballsets import BallSets
from .bearing import BallBearingGeometry, BallSet, generate_ball_set
from .build import BEARING_TENDONS, UNBALANCE_RADIUS_M, Placement, build_model, template_path
from .hidden import TrueScenario, hidden_for
from .pose import BenchPose, BodyPose, face_normals
from .streams import stream_rng as _rng  # the one stream table (seeded: one stream per quantity)
from .thermal import Thermal

TWO_PI = 2.0 * math.pi
#: components of the time-keyed cage-slip process (a random-phase sum; 64 make it Gaussian to
#: within a few per cent in its tails and keep one evaluation at ~µs)
SLIP_COMPONENTS = 64

# Joints of the model in the order of the solve vector q (names in models/bench.xml).
JOINTS = ("radial_x", "radial_y", "tilt_x", "tilt_y", "spin", "shaft_twist")
_LINEAR = np.array([True, True, False, False, False, False])

# Settle criterion: |Δq_i| <= ATOL + 4·eps·|q_i| on the last Newton step (m for slides, rad for
# hinges). 1e-14 m = 1e-5 nm and 1e-14 rad = 2e-9″: the pose noise is then the float64 rounding.
SETTLE_ATOL = 1e-14
SETTLE_MAX_ITER = 60
_EPS = float(np.finfo(float).eps)
# Largest command change predicted along the tangent dq/dcmd (_solve's warm start). Newton
# iterations per pose on jia2019 (tangent / previous lag kept): 0.1° moves 2.01 / 2.86, 1° 2.92 /
# 3.00, 6° 3.02 / 3.00, 15.65° 3.33 / 3.03, random angles 4.12 / 3.40.
TANGENT_MAX_STEP_RAD = 0.05

# Cage lobing (rolling-element set) and random non-repeating motion: model constants.
CAGE_ORDERS = (1, 2, 3)              # low orders: ball diameter variation around the set
ASYNC_COMPONENTS = 24                # random components per bearing, axis, rep
ASYNC_FREQ_RANGE = (0.5, 30.0)       # cycles per revolution, non-integer (drawn uniformly)
SPHERE_FORM_ORDERS = tuple(range(2, 16))
AXIS_AVERAGE_POINTS = 64             # poses per revolution for the axis-average-line centring


def _opt(sc, section: str, key: str, default):
    """A scenario value that the schema may not have (yet): the default when absent."""
    try:
        sec = sc[section]
    except KeyError:
        return default
    v = sec.get(key) if hasattr(sec, "get") else None
    return default if v is None else v


def _seed_of(sc) -> int:
    s = getattr(sc, "seed", None)
    return int(s if s is not None else sc["scenario"]["seed"])


def _lobes_arrays(lobes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    k = np.array([int(l["order"]) for l in lobes], dtype=float)
    a = np.array([float(l["amplitude"]) for l in lobes], dtype=float)
    p = np.array([float(l["phase"]) for l in lobes], dtype=float)
    return k, a, p


def _lobes_json(lobes) -> list[dict]:
    return [{"order": int(l["order"]), "amplitude_m": float(l["amplitude"]),
             "phase_rad": float(l["phase"])} for l in lobes]


def _table_column(table, *names):
    for n in names:
        if n in table:
            return np.asarray(table[n], dtype=float)
    return None


def disk_shift_overrides(sc, delta_m: float) -> dict[str, str]:
    """Design-study hook (Jia 2019 sec. 6: "reduce the distance between the grating disk and the
    bearing"): scenario overrides that mount the disk ``delta_m`` higher on the SAME rotor.

    Every axial position in a scenario is measured from the disk plane, so moving the disk along
    the shaft changes L1 (top sphere -> disk) and the bearing and polygon positions together; L2
    does not change. (Changing ``bench.L1`` alone moves the top sphere instead: disk and bearings
    stay, the disk-plane motion does not change, only the spheres' readings do.)
    Use with ``Scenario.with_overrides``; values are written with units, like a scenario file."""
    b = sc["bench"]
    out = {"bench.L1": b["L1"] - delta_m}
    for k in ("bearing_top_z", "bearing_bottom_z", "polygon_z"):
        out[f"bench.{k}"] = b[k] - delta_m
    return {k: f"{v * 1e3:.12g} mm" for k, v in out.items()}


def shift_disk(sc: dict, delta_m: float) -> dict:
    """``disk_shift_overrides`` for a plain nested dict of SI values (returns a copy)."""
    import copy

    s = copy.deepcopy(sc)
    b = s["bench"]
    b["L1"] -= delta_m
    for k in ("bearing_top_z", "bearing_bottom_z", "polygon_z"):
        b[k] -= delta_m
    return s


class Bench:
    """The posed bench of one scenario.

    ``pose_at(shaft_angle_rad, rep, t_s, direction)`` commands the drive to ``shaft_angle_rad``
    (approached in ``direction`` = +1 / −1), solves the statics and returns the posed bodies;
    ``BenchPose.shaft_angle_rad`` is the TRUE rotation of the disk section (the command minus the
    torsional lag). ``truth()`` lists every generated parameter; ``disk_plane_motion`` gives the
    true radial motion of the axis of rotation in the disk plane.

    One ``MjData`` per bench: not thread-safe; use one ``Bench`` per worker.
    """

    def __init__(self, sc: Any):
        self.sc = sc
        self.seed = _seed_of(sc)
        self._bearing_options(sc)
        self._generate(sc)
        self.thermal = self._thermal(sc)
        self._drift4 = np.zeros(4)           # thermal translation of the bearing seats now
        self._drift_t = math.nan             # the time of _drift4_t (pose_at's cache)
        self._drift4_t = self._drift4
        self._drift_src: Thermal | None = None
        self.placement = self._placement(sc)
        self._build(sc)
        self._index_model()
        self._linearise()
        # The shaft's axial DOF ([axial], optional; twin/axial.py): solved after the radial statics
        # and added to the posed shaft. None without the section: the poses as before, bit for bit.
        self.axial: Axial | None = None
        ax = sc.get("axial") if hasattr(sc, "get") else None
        if ax:
            self.axial = build_axial(dict(ax), self, _rng(self.seed, "axial"))
            m = self.model
            root = m.body("shaft_carrier").id
            moving = []
            for b in range(m.nbody):
                a = b
                while a not in (0, root):
                    a = int(m.body_parentid[a])
                if a == root:
                    moving.append(b)
            self._axial_bodies = np.array(moving, dtype=int)

    def _bearing_options(self, sc: Any) -> None:
        """The scenario's bench and bearing options the statics use (geometry checked), and the
        bench's [hidden] effects (twin/hidden.py: true values the dataset does not declare)."""
        b, br = sc["bench"], sc["bearings"]
        if abs(b["bearing_top_z"] - b["bearing_bottom_z"]) < 1e-3:
            raise ValueError("bench.bearing_top_z and bench.bearing_bottom_z must be at least 1 mm apart: "
                             "two bearings at one place cannot hold the shaft's tilt")
        self.n_faces = int(b["polygon_faces"])
        # [hidden] effects (twin/hidden.py): true values the dataset does not declare.
        self.hidden = hidden_for(sc)
        self.friction_torque_Nm = float(br["friction_torque"]) + self.hidden.extra_friction_torque_Nm
        self.cage_ratio = float(_opt(sc, "bearings", "cage_ratio", 0.4))
        self.async_cage_fraction = float(_opt(sc, "bearings", "async_cage_fraction", 0.5))
        self.async_rms_m = float(br["async_rms"])
        # Shaft speed while measuring: 0 = stop-and-go (quasi-static stops, the default).
        self.speed_rad_s = float(_opt(sc, "bench", "speed", 0.0))
        # Bearing model: "ball" = rolling-element sets (twin/bearing.py, Hertzian contact forces);
        # "air" = aerostatic journals (twin/air_bearing.py); "path" = the replay of a given rolling
        # path or a measured motion table (not a bearing model).
        self.bearing_type = str(_opt(sc, "bearings", "type", "ball"))
        if sc.get("motion_table") if hasattr(sc, "get") else None:
            self.bearing_type = "path"          # a measured motion replaces the bearings' own
        self.ball_sets: dict[str, BallSet] | None = None
        self.air_bearings: AirBearings | None = None
        self.cage_slip = float(_opt(sc, "bearings", "cage_slip", 0.0))
        # 0: the slip is an independent draw per start/stop (keyed by the stop's time); > 0: a
        # stationary random process s(t) in bench time with this correlation time (s)
        self.cage_slip_time_s = float(_opt(sc, "bearings", "cage_slip_time", 0.0))
        self.cage_slip_mean = float(_opt(sc, "bearings", "cage_slip_mean", 0.0))

    @staticmethod
    def _pyramidal(sc: Any, seed: int, N: int) -> np.ndarray | None:
        """Per physics face (1…N), the pyramidal error in rad from [polygon]: the stated values
        (Hsieh's face h is physics face ((1 − h) mod N) + 1; one value: every face) plus a seeded
        N(0, pyramidal_rms) draw. None when the scenario has no [polygon] section or all are 0."""
        given = _opt(sc, "polygon", "pyramidal_error", None)
        rms = float(_opt(sc, "polygon", "pyramidal_rms", 0.0))
        p = np.zeros(N)
        if given is not None:
            g = np.asarray(given, dtype=float)
            p_h = np.full(N, g[0]) if g.size == 1 else g
            for h in range(1, N + 1):
                p[((1 - h) % N)] = p_h[h - 1]
        if rms > 0:
            p = p + _rng(seed, "polygon_pyramidal").normal(0.0, rms, N)
        if not np.any(p):
            return None
        p.flags.writeable = False   # shared with every pose
        return p

    def _placement(self, sc: Any) -> Placement:
        """Where the generated errors put the bodies on the shaft (build.Placement)."""
        b, br, er = sc["bench"], sc["bearings"], sc["errors"]
        return Placement(
            disk_offset_m=self.disk_offset_m,
            disk_tilt_rad=float(er["disk_tilt"]),
            disk_tilt_azimuth_rad=float(_opt(sc, "errors", "disk_tilt_phase", 0.0)),
            sphere_top_offset_m=self.sphere_offset_m["top"],
            sphere_bottom_offset_m=self.sphere_offset_m["bottom"],
            polygon_offset_m=self.polygon_offset_m,
            polygon_tilt_rad=float(_opt(sc, "errors", "polygon_tilt", 0.0)),
            polygon_tilt_azimuth_rad=float(_opt(sc, "errors", "polygon_tilt_phase", 0.0)),
            unbalance_kgm=float(br["unbalance"]),
            unbalance_phase_rad=self.unbalance_phase_rad,
            unbalance_z_m=0.5 * (b["bearing_top_z"] + b["bearing_bottom_z"]),
        )

    def _build(self, sc: Any) -> None:
        """The MuJoCo model of the true bench (the spheres where they truly are), with the bearings'
        stiffness where the ball sets or the air film carry the shaft."""
        b = sc["bench"]
        sc_true = sc
        if self.hidden.delta_L1_m:
            L1 = float(b["L1"]) + self.hidden.delta_L1_m
            if not 0.0 <= L1 < float(b["L2"]):
                raise ValueError(f"hidden.tilt_abbe: true L1 = {L1:g} m must be in [0, L2)")
            sc_true = TrueScenario(sc, {"L1": L1})   # the spheres where they truly are
        self.model, self.geometry = build_model(sc_true, self.placement)
        m = self.model
        if self.ball_sets is not None:
            # The ball sets carry the shaft (forces from twin/bearing.py, added to MuJoCo's
            # generalized forces through the tendons' moment arms): the tendons keep only their
            # damping (dynamic runs) and measure the journal displacement.
            for n in BEARING_TENDONS:
                m.tendon_stiffness[m.tendon(n).id] = 0.0
        if self.air_bearings is not None:   # the film's stiffness, not bearings.radial_stiffness
            for n in BEARING_TENDONS:
                m.tendon_stiffness[m.tendon(n).id] = self.air_bearings.K0
            for n in ("tilt_x", "tilt_y"):
                m.jnt_stiffness[m.joint(n).id] = 2.0 * self.air_bearings.tilt_stiffness_Nm_rad
        # Statics: no constraint rows (no contacts, friction is applied as its sliding value).
        m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
        self.data = mujoco.MjData(m)

    def _index_model(self) -> None:
        """Addresses of the joints, tendons, actuator and bodies in the compiled model, and the
        statics' caches and counters."""
        m, br = self.model, self.sc["bearings"]
        self._qadr = np.array([m.joint(n).qposadr[0] for n in JOINTS])
        self._dadr = np.array([m.joint(n).dofadr[0] for n in JOINTS])
        if not (np.array_equal(self._qadr, np.arange(6)) and np.array_equal(self._dadr, np.arange(6))):
            raise RuntimeError("bench.xml: expected the six compliant joints in solve order")
        self._ten = np.array([m.tendon(n).id for n in BEARING_TENDONS])
        t0 = int(self._ten[0])
        consecutive = np.array_equal(self._ten, np.arange(t0, t0 + self._ten.size))
        self._ten_rows: slice | np.ndarray = slice(t0, t0 + self._ten.size) if consecutive else self._ten
        self._act = m.actuator("drive").id
        self._bid = {n: m.body(n).id for n in
                     ("shaft", "disk", "polygon", "polygon_section", "sphere_top", "sphere_bottom", "unbalance")}
        self._centrifugal_N = float(br["unbalance"]) * self.speed_rad_s**2
        self._housing_m = np.zeros(4)      # constant race offsets (housing position), per tendon
        self._solve_housing: np.ndarray | None = None
        self._rep_cache: dict[int, dict] = {}
        self._terms_cache: dict[tuple, Any] = {}
        self._q_last = np.zeros(6)
        self._cmd_last = 0.0
        self.last_iterations = 0
        self.total_iterations = 0
        self.n_poses = 0


    def _linearise(self) -> None:
        """The statics' linear parts: the tendon matrix, MuJoCo's stiffness (and the ball sets'
        kernel and assembly), the drive command's sensitivity and the Newton right-hand sides; the
        axis-average-line centring."""
        # Journal displacement at the bearings = T·q (the fixed tendons are linear in q).
        self._T = self._tendon_matrix()
        self.reset_path()
        self._Tt = np.ascontiguousarray(self._T.T)
        if self.ball_sets is not None:
            bs, self.ball_sets = self.ball_sets, None      # MuJoCo's part alone
            self._K_mj = self._stiffness_matrix()
            self.ball_sets = bs
            self._kernel = BallSets([bs["top"], bs["bottom"]])
            # MuJoCo's load along the spin is not linear: gravity on the bodies turning with the
            # shaft (unbalance, centred masses' tilt moments) is A + B·cos θ + C·sin θ. K_mj holds
            # its derivative at θ = 0 (−C); the Newton matrix takes it at the pose's θ.
            B, C = self._gravity_harmonics()
            self._K_mj[:, 4] += C
            self._assembly = self._assembly_matrix(B, C)
        # ∂(residual)/∂(drive command): the position actuator's kp along its moment arms (linear:
        # one difference is exact); with the Newton matrix it gives the tangent dq/dcmd that
        # predicts the next pose (_solve's warm start).
        self._dr_dcmd = self._command_sensitivity()
        self._K = self._stiffness_matrix()
        self._Kinv = np.linalg.inv(self._K)
        self._tangent = self._Kinv @ self._dr_dcmd
        # Newton's right-hand sides: the residual (column 0, per iteration) and ∂r/∂cmd (column 1)
        # in one solve, which gives the step and the tangent of the same matrix.
        self._rhs = np.zeros((6, 2))
        self._rhs[:, 1] = self._dr_dcmd
        self._center_axis_average_line()
        self.reset_path()

    # ------------------------------------------------------------------ generated parameters --
    def _generate(self, sc) -> None:
        b, br, er = sc["bench"], sc["bearings"], sc["errors"]
        seed = self.seed
        # Disk: geometric centre at body polar angle 90° − θ0, distance e (docs/conventions.md).
        e, th0 = float(er["eccentricity"]), float(er["theta0"])
        self.disk_eccentricity_azimuth_rad = 0.5 * math.pi - th0
        self.disk_offset_m = e * np.array([math.cos(self.disk_eccentricity_azimuth_rad),
                                           math.sin(self.disk_eccentricity_azimuth_rad), 0.0])
        # Spheres: centring error at body polar angle sphere_*_phase (shaft frame).
        self.sphere_offset_m = {}
        for s in ("top", "bottom"):
            c, ph = float(er[f"sphere_{s}_centring"]), float(er[f"sphere_{s}_phase"])
            self.sphere_offset_m[s] = c * np.array([math.cos(ph), math.sin(ph), 0.0])
        # Sphere form: equatorial lobes (orders 2…15, random phases, 1/k amplitudes) scaled so that
        # the peak deviation equals errors.sphere_form (Jia sec. 4.1 gives a max value).
        self.sphere_form = {}
        form = float(er["sphere_form"])
        for i, s in enumerate(("top", "bottom")):
            r = _rng(seed, "sphere_form", i)
            k = np.array(SPHERE_FORM_ORDERS, dtype=float)
            a = r.uniform(0.3, 1.0, k.size) / k
            p = r.uniform(0, TWO_PI, k.size)
            grid = np.linspace(0, TWO_PI, 2048, endpoint=False)
            peak = np.max(np.abs((a[:, None] * np.cos(k[:, None] * grid - p[:, None])).sum(0)))
            a = a * (form / peak) if peak > 0 else a * 0
            self.sphere_form[s] = [{"order": int(kk), "amplitude": float(aa), "phase": float(pp)}
                                   for kk, aa, pp in zip(k, a, p)] + self.hidden.sphere_form_lobes(s)
        # Polygon pitch deviations β_k (k = 1…N): angle from face k's normal to face k+1's normal
        # minus 2π/N; Σβ = 0 closes the polygon (Hsieh 2022 eq. 1). Face 1 defines body +x.
        N = self.n_faces
        beta = _rng(seed, "polygon_pitch").normal(0.0, float(er["polygon_pitch_rms"]), N)
        beta -= beta.mean()
        self.polygon_pitch_declared_rad = beta.copy()      # what a certificate of this polygon says
        beta = beta + self.hidden.polygon_pitch_pattern_rad(N)
        self.polygon_pitch_deviation_rad = beta
        cum = np.concatenate([[0.0], np.cumsum(beta[:-1])])
        self.polygon_face_normal_angle_rad = TWO_PI * np.arange(N) / N + cum
        self.polygon_face_normal_angle_rad.flags.writeable = False   # shared with every pose
        # Pyramidal error p_k ([polygon], optional): face k's normal tilted out of the plane
        # perpendicular to the polygon's axis, n_k = (cos p cos g, cos p sin g, sin p) in the body.
        # Given in the dataset's (Hsieh's) face numbering; stored per physics face. None when the
        # scenario states none: every normal in the plane, the poses and truth as before.
        self.polygon_pyramidal_rad = self._pyramidal(sc, seed, N)
        ph = _opt(sc, "errors", "polygon_eccentricity_phase", None)
        if ph is None:
            ph = _rng(seed, "polygon_eccentricity_phase").uniform(0, TWO_PI)
        self.polygon_eccentricity_phase_rad = float(ph)
        pe = float(er["polygon_eccentricity"])
        self.polygon_offset_m = pe * np.array([math.cos(ph), math.sin(ph), 0.0])
        ph = _opt(sc, "bearings", "unbalance_phase", None)
        if ph is None:
            ph = _rng(seed, "unbalance_phase").uniform(0, TWO_PI)
        self.unbalance_phase_rad = float(ph)
        # Synchronous race waviness, per bearing.
        self.waviness = {"top": list(br["waviness_top"]), "bottom": list(br["waviness_bottom"])}
        # hidden tangential_motion (twin/hidden.py): undeclared lobes of the same rotating races
        for s_ in ("top", "bottom"):
            self.waviness[s_] += self.hidden.race_waviness_lobes(s_)
        self._wav = {s: _lobes_arrays(self.waviness[s]) for s in ("top", "bottom")}
        # Cage lobing: fixed property of each bearing's ball set (orders 1…3, random phases),
        # scaled so its per-axis RMS is sqrt(async_cage_fraction)·async_rms.
        self.cage_lobes = {}
        rms_cage = math.sqrt(self.async_cage_fraction) * float(br["async_rms"])
        for i, s in enumerate(("top", "bottom")):
            r = _rng(seed, "cage_lobes", i)
            k = np.array(CAGE_ORDERS, dtype=float)
            a = r.uniform(0.5, 1.0, k.size)
            # per-axis RMS of whirls a·(cos, sin) is sqrt(Σa²/2)
            a *= rms_cage / math.sqrt(0.5 * np.sum(a**2)) if rms_cage > 0 else 0.0
            p = r.uniform(0, TWO_PI, k.size)
            self.cage_lobes[s] = (k, a, p)
        if self.bearing_type == "ball":
            self.ball_sets = {}
            for i, s_ in enumerate(("top", "bottom")):
                g = BallBearingGeometry(
                    balls=int(br["balls"]), ball_diameter_m=float(br["ball_diameter"]),
                    pitch_diameter_m=float(br["pitch_diameter"]), contact_angle_rad=float(br["contact_angle"]),
                    preload_N=float(br["preload"]), groove_inner=float(br["groove_inner"]),
                    groove_outer=float(br["groove_outer"]))
                self.ball_sets[s_] = generate_ball_set(g, str(br["grade"]), str(br["ball_grade"]),
                                                       _rng(seed, "ball_set", i),
                                                       float(_opt(sc, "bearings", "waviness_scale", 1.0)))
                extra = _lobes_arrays(self.hidden.race_waviness_lobes(s_))
                if extra[0].size:   # hidden tangential_motion: undeclared lobes of the inner race
                    bs = self.ball_sets[s_]
                    inner = cast(tuple[np.ndarray, np.ndarray, np.ndarray],
                                 tuple(np.concatenate([x, y]) for x, y in zip(bs.inner, extra)))
                    self.ball_sets[s_] = BallSet(bs.geometry, inner=inner, outer=bs.outer, ball_dd_m=bs.ball_dd_m)
            self.cage_ratio = self.ball_sets["top"].rho
        elif self.bearing_type == "air":
            if any(self.hidden.race_waviness_lobes(s_) for s_ in ("top", "bottom")):
                raise ValueError("hidden.tangential_motion (race waviness) needs ball or path bearings, "
                                 "not bearings.type = \"air\"")
            self.air_bearings = build_air_bearings(br, _rng(seed, "air_form"), _rng(seed, "air_supply"))
        # Optional measured motion table: replaces the synchronous waviness.
        self.motion_table: dict[str, Any] | None = None
        table = sc.get("motion_table") if hasattr(sc, "get") else None
        if table:
            self._set_motion_table(table, b)

    def _thermal(self, sc) -> Thermal:
        """The bench's thermal state (twin/thermal.py); random phases from the seed unless given."""
        try:
            th = dict(sc["thermal"])
        except KeyError:
            th = {}
        from .scenario_schema import SCHEMA

        for k, f in SCHEMA["thermal"].items():
            if th.get(k) is None:
                th[k] = f.default
        phase = th["ambient_phase"]
        if phase is None:
            phase = _rng(self.seed, "thermal_phase").uniform(0, TWO_PI)
        if th["axis_drift_azimuth"] is None:
            th["axis_drift_azimuth"] = _rng(self.seed, "thermal_axis_azimuth").uniform(0, TWO_PI)
        if th["hvac_phase"] is None:   # drawn only when the cycle is on: other benches draw nothing new
            th["hvac_phase"] = (_rng(self.seed, "thermal_cycle_phase").uniform(0, TWO_PI)
                                if th["hvac_amplitude"] > 0 else 0.0)
        loop = sc.get("measuring_loop") if hasattr(sc, "get") else None   # optional section
        return Thermal(th, float(phase), loop)

    def _set_motion_table(self, table, b) -> None:
        th = _table_column(table, "theta", "theta_rad")
        if th is None:
            raise ValueError("motion_table: needs a theta column (rad)")
        cols = {}
        for name, alias in (("dx", "dx_m"), ("dy", "dy_m"), ("tilt_x", "tilt_x_rad"), ("tilt_y", "tilt_y_rad")):
            c = _table_column(table, name, alias)
            cols[name] = np.zeros_like(th) if c is None else c
        order = np.argsort(np.mod(th, TWO_PI))
        th = np.mod(th, TWO_PI)[order]
        # Rolling-path offsets that carry an unloaded rigid shaft along the table's motion:
        # x(z) = dx + z·tilt_y, y(z) = dy − z·tilt_x at each bearing (same kinematics as the tendons).
        rows = []
        for z in (b["bearing_top_z"], b["bearing_bottom_z"]):
            rows.append(cols["dx"][order] + z * cols["tilt_y"][order])
            rows.append(cols["dy"][order] - z * cols["tilt_x"][order])
        off = np.array(rows)                                  # (4, n)
        th_p = np.concatenate([th, [th[0] + TWO_PI]])
        off_p = np.concatenate([off, off[:, :1]], axis=1)
        self.motion_table = {"theta_rad": th.tolist(), **{k: cols[k][order].tolist() for k in cols}}
        # imported here: only a scenario with a motion table needs it, and SciPy's interpolate
        # package costs ≈ 0.4 s of import in every process that builds a bench (issue #17)
        from scipy.interpolate import CubicSpline

        self._table_spline = CubicSpline(th_p, off_p, axis=1, bc_type="periodic")

    # --------------------------------------------------------------- rolling-path offsets ----
    def _rep_params(self, rep: int) -> dict:
        p = self._rep_cache.get(rep)
        if p is None:
            rms_rand = math.sqrt(max(0.0, 1.0 - self.async_cage_fraction)) * self.async_rms_m
            r = _rng(self.seed, "rep_async", rep)
            f = r.uniform(*ASYNC_FREQ_RANGE, (4, ASYNC_COMPONENTS))
            a = 1.0 / f
            # per-series RMS sqrt(Σa²/2) -> rms_rand
            a *= (rms_rand / np.sqrt(0.5 * np.sum(a**2, axis=1)))[:, None] if rms_rand > 0 else 0.0
            ph = r.uniform(0, TWO_PI, (4, ASYNC_COMPONENTS))
            cage_phase = _rng(self.seed, "rep_cage_phase", rep).uniform(0, TWO_PI, 2)
            p = {"f": f, "a": a, "ph": ph, "cage_phase": cage_phase}
            self._rep_cache[rep] = p
        return p

    def _race_terms(self, rep: int, include_async: bool) -> tuple | None:
        """The harmonic terms of ``race_offsets_m`` for one rep, cached: every lobe and random
        component is a·cos(f·θ + φ) or a·sin(f·θ + φ) on one of the four offsets, so the offsets are
        C·cos(F·θ + Φ) + S·sin(F·θ + Φ) with (4, n) coefficient matrices C, S (one cos, one sin
        and two small products per pose instead of Python loops)."""
        key = (int(rep), bool(include_async and self.async_rms_m > 0))
        t = self._terms_cache.get(key)
        if t is not None:
            return t
        F: list[np.ndarray] = []
        Ph: list[np.ndarray] = []
        C: list[np.ndarray] = []
        S: list[np.ndarray] = []

        def add(f, ph, row, a, use_sin):
            f, ph, a = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (f, ph, a))
            c, s = np.zeros((4, f.size)), np.zeros((4, f.size))
            (s if use_sin else c)[row] = a
            F.append(f)
            Ph.append(ph)
            C.append(c)
            S.append(s)

        if self.air_bearings is not None:   # the journals' form through the film (synchronous)
            for f, ph, row, amp, use_sin in self.air_bearings.offset_terms():
                add(f, ph, row, amp, use_sin)
        if self.motion_table is None and self.air_bearings is None:
            for i, s_ in enumerate(("top", "bottom")):
                k, a, p = self._wav[s_]
                if k.size:   # a lobe whirls: a·(cos(kθ − ψ), sin(kθ − ψ))
                    add(k, -p, 2 * i, a, False)
                    add(k, -p, 2 * i + 1, a, True)
        if key[1] and self.air_bearings is None:   # path bearings' synthetic async part only
            rp = self._rep_params(rep)
            for i, s_ in enumerate(("top", "bottom")):
                k, a, p = self.cage_lobes[s_]   # arg = k·(c·θ + φ_rep) − p
                add(k * self.cage_ratio, k * rp["cage_phase"][i] - p, 2 * i, a, False)
                add(k * self.cage_ratio, k * rp["cage_phase"][i] - p, 2 * i + 1, a, True)
            for row in range(4):
                add(rp["f"][row], rp["ph"][row], row, rp["a"][row], False)
        if F:
            Cm, Sm = np.concatenate(C, axis=1), np.concatenate(S, axis=1)
            t = (np.concatenate(F), np.concatenate(Ph), Cm, Sm if np.any(Sm) else None)
        else:
            t = None
        self._terms_cache[key] = t
        return t

    def race_offsets_m(self, theta_rad: float, rep: int = 0, include_async: bool = True) -> np.ndarray:
        """Rolling-path offsets (top_x, top_y, bottom_x, bottom_y) at shaft angle θ, without the
        constant housing position: the rest positions of the four bearing springs."""
        th = float(theta_rad)
        # ball bearings: the races' shapes act through the ball forces (_ball_forces), not here
        t = self._race_terms(rep, include_async) if self.ball_sets is None else None
        if self.motion_table is not None:
            out = np.asarray(self._table_spline(math.fmod(th, TWO_PI) % TWO_PI), dtype=float).copy()
        elif t is not None:
            out = None           # the first sum is the array (0 + x is x: one NumPy call less)
        else:
            out = np.zeros(4)
        if t is not None:
            f, ph, Cm, Sm = t
            arg = f * th + ph
            c = Cm @ np.cos(arg)
            if out is None:
                out = c
            else:
                out += c
            if Sm is not None:
                out += Sm @ np.sin(arg)
        assert out is not None   # a table, the terms' sum or zeros
        if self.hidden:
            dx = self.hidden.race_x_offset_m(th)        # hidden tangential motion: X only
            out[0] += dx
            out[2] += dx
        return out

    # --------------------------------------------------------------------------- statics -----
    def _residual(self, q: np.ndarray) -> np.ndarray:
        d = self.data
        d.qpos[:] = q
        mujoco.mj_forward(self.model, d)
        r = d.qfrc_smooth.copy()
        if self.ball_sets is not None:
            r += self._T.T @ self._ball_forces(q)
        return r

    def _residual_and_K(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual and the Newton matrix of a ball bench: MuJoCo's part of K (constant: its forces
        are linear in the small radial/tilt coordinates) plus the ball sets' Jacobian at this
        configuration (analytic, twin/ballsets.py): Tᵀ·K_balls·T for the journal displacements and,
        in the spin column, −Tᵀ·∂F/∂θ (the balls roll on with the shaft: cage angle and races'
        waviness at the balls), so Newton converges quadratically in all six coordinates."""
        d = self.data
        d.qpos[:] = q
        mujoco.mj_forward(self.model, d)
        F, K, g = self._fused().evaluate(*self._kernel_inputs(q))
        # one product assembles both: (K blocks, F, g) @ _assembly = (J − K_mj flattened, Tᵀ·F)
        th = float(q[4])
        out = np.array(K[0] + K[1] + tuple(F) + tuple(g) + (math.cos(th), math.sin(th))) @ self._assembly
        return d.qfrc_smooth + out[36:], self._K_mj + out[:36].reshape(6, 6)

    def _fused(self) -> BallSets:
        """The fused kernel of the current ball sets (rebuilt if a set was replaced, as the
        bearing tests and design studies do on a built bench)."""
        k, bs = self._kernel, self.ball_sets
        assert bs is not None   # only ball benches have a kernel
        if k.sets[0] is not bs["top"] or k.sets[1] is not bs["bottom"]:
            k = self._kernel = BallSets([bs["top"], bs["bottom"]])
        return k

    def _kernel_inputs(self, q: np.ndarray) -> tuple[list, float, list, list]:
        """(u, θ, cage angles, d(cage)/dθ) of the ball sets at q, as Python floats."""
        housing = self._housing_m if self._solve_housing is None else self._solve_housing
        u = (self._T @ q - housing).tolist()
        th = float(q[4])
        if self.hidden:
            dx = self.hidden.race_x_offset_m(th)     # hidden tangential motion: X only
            u[0] -= dx
            u[2] -= dx
        # cage_angles_rad on floats: ref + rho·(θ − θ_ref)·(1 + slip); its rate rho·(1 + slip)
        slip = self._path_slip.tolist()
        rho = self._kernel.rho
        dth = th - self._path_theta_ref
        cages = [c + r * dth * (1.0 + s) for c, r, s in zip(self._path_cage_ref.tolist(), rho, slip)]
        rates = [r * (1.0 + s) for r, s in zip(rho, slip)]
        return u, th, cages, rates

    def _ball_kernel(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The fused kernel's forces F (4,), block-diagonal stiffness −dF/du (4, 4) and explicit
        shaft-angle rate g = ∂F/∂θ at fixed u (4,): the quantities of ``_ball_forces`` (which keeps
        the per-set reference formulas of twin/bearing.py) plus g (tests compare them)."""
        F, K, g = self._fused().evaluate(*self._kernel_inputs(q))
        (a, b, c), (e, f, h) = K
        Kb = np.array([[a, b, 0.0, 0.0], [b, c, 0.0, 0.0], [0.0, 0.0, e, f], [0.0, 0.0, f, h]])
        return np.array(F), Kb, np.array(g)

    def _gravity_harmonics(self) -> tuple[np.ndarray, np.ndarray]:
        """B, C of MuJoCo's generalized force at q = (0, 0, 0, 0, θ, 0) with the drive at θ (no
        actuator force), springs at zero rest offset, no applied loads: A + B·cos θ + C·sin θ
        (gravity on rigid bodies turning about the spin axis; benchmarks/physics_floor.py checks the
        form to 1e-20)."""
        d = self.data
        self._set_springs(np.zeros(4))
        d.qvel[:] = 0.0
        d.qfrc_applied[:] = 0.0
        d.xfrc_applied[:] = 0.0
        g = []
        for th in (0.0, 0.5 * math.pi, math.pi):
            d.qpos[:] = 0.0
            d.qpos[4] = th
            d.ctrl[self._act] = th
            mujoco.mj_forward(self.model, d)
            g.append(d.qfrc_smooth.copy())
        d.qpos[:] = 0.0
        d.ctrl[self._act] = 0.0
        return 0.5 * (g[0] - g[2]), g[1] - 0.5 * (g[0] + g[2])

    def _assembly_matrix(self, B: np.ndarray, C: np.ndarray) -> np.ndarray:
        """(16, 42) map from the kernel's (kxx, kxy, kyy per set, F, g) and (cos θ, sin θ) to the
        flattened θ-dependent part of the Newton matrix (36): Tᵀ·K_b·T − Tᵀ·g·e_θᵀ, and MuJoCo's
        gravity rate in the spin column, B·sin θ − C·cos θ (−∂/∂θ of A + B·cos θ + C·sin θ; its value
        at θ = 0 is already in K_mj); and to Tᵀ·F (6)."""
        T = self._T
        P = np.zeros((16, 42))
        P[14, 4:36:6] = -C
        P[15, 4:36:6] = B
        for s in range(2):
            tx, ty = T[2 * s], T[2 * s + 1]
            P[3 * s] = np.concatenate([np.outer(tx, tx).ravel(), np.zeros(6)])
            P[3 * s + 1] = np.concatenate([(np.outer(tx, ty) + np.outer(ty, tx)).ravel(), np.zeros(6)])
            P[3 * s + 2] = np.concatenate([np.outer(ty, ty).ravel(), np.zeros(6)])
        for i in range(4):
            P[6 + i, 36:] = T[i]                 # Tᵀ·F
            P[10 + i, 4:36:6] = -T[i]            # spin column: −Tᵀ·g
        return P

    def _tendon_matrix(self) -> np.ndarray:
        """(4, 6) T with journal displacements (top x, top y, bottom x, bottom y) = T·q."""
        d = self.data
        T = np.zeros((4, 6))
        for i in range(6):
            d.qpos[:] = 0.0
            d.qpos[i] = 1.0
            mujoco.mj_kinematics(self.model, d)
            mujoco.mj_tendon(self.model, d)
            T[:, i] = d.ten_length[self._ten]
        d.qpos[:] = 0.0
        return T

    # ---------------------------------------------------------------- ball sets and cage path --
    def reset_path(self, run: int = 0) -> None:
        """Start the cage path afresh: every cage at its seeded initial angle, shaft angle 0, no
        stop yet (a new run on a bench whose history is forgotten). ``run`` keys the initial cage
        angles and the slip draws, so independent runs (a study's repetitions) are independent
        realisations whatever ran before on the same ``Bench``."""
        self._path_run = int(run)
        if self.ball_sets is not None:
            self._cage0 = _rng(self.seed, "cage_start", self._path_run).uniform(0, TWO_PI, 2)
        else:
            self._cage0 = np.zeros(2)
        self._slip_omega: np.ndarray | None = None
        self._slip_phase: np.ndarray | None = None
        if self.ball_sets is not None and self.cage_slip_time_s > 0 and self.cage_slip > 0:
            # s(t) = mean + cage_slip·ξ(t), ξ a unit-variance stationary process with correlation
            # exp(−|Δt|/τ) (a random-phase sum: angular frequencies Cauchy with scale 1/τ, i.e. a
            # Lorentzian spectrum), one per bearing, a function of bench time alone: any stop, in
            # any order, replayed or resumed, sees the same s at the same t.
            r = _rng(self.seed, "cage_slip_process", self._path_run)
            u = r.uniform(0.0, 1.0, (2, SLIP_COMPONENTS))
            self._slip_omega = np.tan(math.pi * (u - 0.5)) / self.cage_slip_time_s
            self._slip_phase = r.uniform(0.0, TWO_PI, (2, SLIP_COMPONENTS))
        # The stops of the path in TIME order: times, and each stop's end (shaft angle, cages).
        self._stop_t: list[float] = []
        self._stop_end: list[tuple[float, np.ndarray]] = []
        self._path_i = -1                     # index of the current stop (-1: none yet)
        self._path_t: float | None = None
        self._path_theta_ref = 0.0
        self._path_cage_ref = self._cage0.copy()
        self._path_slip = np.zeros(2)
        self._path_theta_last = 0.0

    def _advance_path(self, t_s: float, rolling: bool = False) -> None:
        """Select the stop of the path at time ``t_s``: its reference is the end of the stop
        BEFORE it in time (the initial state for the first), its slip is drawn from the seed, the
        run and the time (``rolling``: steady rotation, no slip). A pose at a known stop's time
        refines that stop (the servo's iterations); a pose at an earlier time than the last one
        (a replayed or resumed procedure whose clock was set back) continues from the stops that
        lie before it in time, so the configuration at a stop depends on the path that led there
        and not on how often the bench was asked about it."""
        import bisect

        if self.ball_sets is None:     # path bearings: nothing depends on the path
            return
        t = float(t_s)
        if self._path_t is not None and t == self._path_t:
            return
        k = bisect.bisect_left(self._stop_t, t)
        if not (k < len(self._stop_t) and self._stop_t[k] == t):
            self._stop_t.insert(k, t)
            self._stop_end.insert(k, (0.0, self._cage0.copy()))   # filled after the solve
        self._path_i = k
        self._path_t = t
        if k == 0:
            self._path_theta_ref, self._path_cage_ref = 0.0, self._cage0.copy()
        else:
            th, cg = self._stop_end[k - 1]
            self._path_theta_ref, self._path_cage_ref = th, cg.copy()
        if self._slip_omega is not None:
            # the time-keyed model: the move into this stop rolls at the slip of its time (also
            # in steady rotation: the slip is a property of the rolling, not of the start/stop)
            self._path_slip = -self.cage_slip_at(t)
        elif self.cage_slip > 0 and self.ball_sets is not None and not rolling:
            key = int(round(t * 1e6)) % (2**63)
            self._path_slip = _rng(self.seed, "cage_slip", self._path_run, key).normal(0.0, self.cage_slip, 2)
        else:
            self._path_slip = np.zeros(2)
        if self.cage_slip_mean > 0 and self.ball_sets is not None and self._slip_omega is None:
            self._path_slip = self._path_slip - self.cage_slip_mean     # the cage lags its kinematic speed

    def cage_slip_at(self, t_s: float) -> np.ndarray:
        """The cages' relative slip s(t) (top, bottom) at bench time ``t_s`` (time-keyed model,
        ``bearings.cage_slip_time`` > 0): the cage turns at (1 − s)·rho of the shaft's rotation.
        Zeros for the per-stop model."""
        omega, phase = self._slip_omega, self._slip_phase
        if omega is None or phase is None:
            return np.zeros(2)
        xi = math.sqrt(2.0 / SLIP_COMPONENTS) * np.cos(omega * float(t_s) + phase).sum(axis=1)
        return self.cage_slip_mean + self.cage_slip * xi

    def _end_stop(self, theta_rad: float) -> None:
        """Record the current stop's end state (after its solve)."""
        self._path_theta_last = float(theta_rad)
        if self._path_i >= 0 and self.ball_sets is not None:
            self._stop_end[self._path_i] = (float(theta_rad), self.cage_angles_rad(theta_rad))

    def cage_angles_rad(self, theta_rad: float) -> np.ndarray:
        """Cage angles (top, bottom; lab frame) with the shaft at ``theta_rad`` on the current
        move: the integral of the shaft's rotation times the kinematic ratio rho, each move
        rolling with a random relative slip (``bearings.cage_slip``) — so the balls' configuration
        at a stop depends on the path that led there."""
        if self.ball_sets is None:
            return np.zeros(2)
        rho = np.array([self.ball_sets["top"].rho, self.ball_sets["bottom"].rho])
        return self._path_cage_ref + rho * (float(theta_rad) - self._path_theta_ref) * (1.0 + self._path_slip)

    def _ball_forces(self, q: np.ndarray, housing_m: np.ndarray | None = None, with_stiffness: bool = False):
        """Ball-set forces on the journals (top x, top y, bottom x, bottom y), N (and, with
        ``with_stiffness``, their 4×4 block-diagonal stiffness −dF/du)."""
        housing = self._housing_m if housing_m is None else housing_m
        if self._solve_housing is not None:
            housing = self._solve_housing
        u = self._T @ q - housing
        th = float(q[4])
        if self.hidden:
            dx = self.hidden.race_x_offset_m(th)     # hidden tangential motion: X only
            u[0] -= dx
            u[2] -= dx
        cage = self.cage_angles_rad(th)
        bs = self.ball_sets
        assert bs is not None   # only ball benches take ball forces
        if with_stiffness:
            ft, kt = bs["top"].force_and_stiffness(u[:2], th, cage[0])
            fb, kb = bs["bottom"].force_and_stiffness(u[2:], th, cage[1])
            K = np.zeros((4, 4))
            K[:2, :2], K[2:, 2:] = kt, kb
            return np.concatenate([ft, fb]), K
        ft = bs["top"].force_on_shaft_N(u[:2], th, cage[0])
        fb = bs["bottom"].force_on_shaft_N(u[2:], th, cage[1])
        return np.concatenate([ft, fb])

    def _set_loads(self, cmd_rad: float, direction: int) -> None:
        d = self.data
        d.qvel[:] = 0.0
        d.ctrl[self._act] = cmd_rad
        d.qfrc_applied[:] = 0.0
        # Sliding bearing friction opposing the approach direction (see module docstring), or the
        # torque the friction holds at the drive servo's rest (twin/instruments/drive.py).
        held = getattr(self, "_held_torque_Nm", None)
        d.qfrc_applied[4] = -float(np.sign(direction)) * self.friction_torque_Nm if held is None else held

    def _set_centrifugal(self, spin_rad: float) -> None:
        """Unbalance force U·ω² at steady speed ``bench.speed`` (0 for stop-and-go readings):
        radial, through the unbalance mass, turning with the shaft. The rotor's modes (kHz) are
        far above the rotation frequency, so the steady response is the static one."""
        if self._centrifugal_N == 0.0:
            return
        a = spin_rad + self.unbalance_phase_rad
        self.data.xfrc_applied[self._bid["unbalance"], :3] = self._centrifugal_N * np.array([math.cos(a), math.sin(a), 0.0])

    def _set_springs(self, offsets: np.ndarray) -> None:
        # both ends of the dead band at the offset (a slice when the tendons are consecutive: the
        # static solve sets them at every Newton iteration of a rolling-path bench)
        ls = self.model.tendon_lengthspring
        ls[self._ten_rows] = np.asarray(offsets, dtype=float)[:, None]

    def _stiffness_matrix(self, housing_m: np.ndarray | None = None, q0: np.ndarray | None = None) -> np.ndarray:
        """K = −∂(generalized force)/∂q by central differences at q0 (default: the unposed
        state; springs held)."""
        self._set_loads(0.0 if q0 is None else float(q0[4]), +1)
        self._set_springs(np.zeros(4))
        self._solve_housing = np.zeros(4) if housing_m is None else np.asarray(housing_m, dtype=float)
        q0 = np.zeros(6) if q0 is None else np.asarray(q0, dtype=float).copy()
        h = np.where(_LINEAR, 1e-8, 1e-7)
        K = np.zeros((6, 6))
        for i in range(6):
            dq = np.zeros(6)
            dq[i] = h[i]
            K[:, i] = -(self._residual(q0 + dq) - self._residual(q0 - dq)) / (2 * h[i])
        self._solve_housing = None
        return K

    def _command_sensitivity(self) -> np.ndarray:
        """∂(generalized force)/∂(drive command) at rest: MuJoCo's forces at commands 1 and 0 (the
        position actuator is linear in its control, so the difference is its kp along the
        actuator's moment arms, exactly)."""
        d = self.data
        d.qpos[:] = 0.0
        d.qvel[:] = 0.0
        d.qfrc_applied[:] = 0.0
        f = []
        for c in (1.0, 0.0):
            d.ctrl[self._act] = c
            mujoco.mj_forward(self.model, d)
            f.append(d.qfrc_smooth.copy())
        return f[0] - f[1]

    def _solve(self, cmd_rad: float, direction: int, rep: int, include_async: bool = True,
               housing_m: np.ndarray | None = None) -> int:
        """Static equilibrium for drive command ``cmd_rad``; leaves ``self.data`` posed there.
        Returns the number of Newton iterations."""
        housing = self._housing_m + self._drift4 if housing_m is None else housing_m
        self._solve_housing = housing
        self._set_loads(cmd_rad, direction)
        # Warm start: the previous pose moved along its tangent dq/dcmd = J⁻¹·∂r/∂cmd (first order
        # in the command change; "keep the previous lag" was its spin component alone). The
        # servo's refinements of one stop change the command by < 1e-6 rad: the prediction is
        # then within the settle criterion and one Newton step confirms it.
        dc = cmd_rad - self._cmd_last
        if abs(dc) <= TANGENT_MAX_STEP_RAD:
            q = self._q_last + self._tangent * dc
        else:
            # a long move: the tangent would extrapolate the ball configuration's response far
            # beyond its validity (measured: more iterations from 6° on); keep the previous lag
            q = self._q_last.copy()
            q[4] += dc
        d = self.data
        ball = self.ball_sets is not None
        tol4 = 4 * _EPS
        for it in range(1, SETTLE_MAX_ITER + 1):
            if ball:
                # the ball sets carry the shaft: the tendon springs are off, their rest positions
                # (set below for the final pose) do not enter the residual
                self._set_centrifugal(q[4])
                r, Kq = self._residual_and_K(q)
                rhs = self._rhs
                rhs[:, 0] = r
                x = np.linalg.solve(Kq, rhs)
                dq = x[:, 0]
                self._tangent = x[:, 1]
            else:
                self._set_springs(housing + self.race_offsets_m(q[4], rep, include_async))
                self._set_centrifugal(q[4])
                r = self._residual(q)
                dq = self._Kinv @ r
            q = q + dq
            # the settle criterion on Python floats (six values: cheaper than four NumPy calls)
            if all(abs(a) <= SETTLE_ATOL + tol4 * abs(b) for a, b in zip(dq.tolist(), q.tolist())):
                break
        else:
            raise RuntimeError(f"static solve did not converge at command {cmd_rad} rad: |dq| = {np.abs(dq).max():g}")
        # Final evaluation at the converged q, so the poses read from d are those of q.
        self._set_springs(housing + self.race_offsets_m(q[4], rep, include_async))
        self._set_centrifugal(q[4])
        d.qpos[:] = q
        mujoco.mj_forward(self.model, d)
        if d.warning.number.any():
            raise RuntimeError(f"MuJoCo warnings during the static solve: {d.warning.number}")
        self._solve_housing = None
        self._q_last = q
        self._path_theta_last = float(q[4])
        self._cmd_last = cmd_rad
        return it

    def _axis_line(self) -> tuple[np.ndarray, np.ndarray]:
        """Current shaft axis: a point (its intersection with the lab plane z = 0) and direction."""
        d = self.data
        p = d.xpos[self._bid["shaft"]]
        a = d.xmat[self._bid["shaft"]].reshape(3, 3)[:, 2]
        return p - a * (p[2] / a[2]), a / a[2]

    def _center_axis_average_line(self) -> None:
        """Place the housings so that the axis average line (least-squares axis over a revolution
        of the synchronous motion, ISO 230-7) is the lab z axis: origin of docs/conventions.md."""
        disk: list[complex] = []
        angles: list[float] = []

        def mean_axis(housing):
            pts, dirs = [], []
            disk.clear()
            angles.clear()
            for th in TWO_PI * np.arange(AXIS_AVERAGE_POINTS) / AXIS_AVERAGE_POINTS:
                self._solve(th, +1, 0, include_async=False, housing_m=housing)
                p, a = self._axis_line()
                pts.append(p[:2])
                dirs.append(a[:2])
                c = self.data.xpos[self._bid["disk"]]
                disk.append(complex(float(c[0]), float(c[1])))
                angles.append(float(self.data.qpos[4]))
            return np.concatenate([np.mean(pts, axis=0), np.mean(dirs, axis=0)])

        h0 = np.zeros(4)
        y0 = mean_axis(h0)
        # The statics are linear in the housing offsets: one sensitivity matrix, one correction.
        J = np.zeros((4, 4))
        for i in range(4):
            dh = np.zeros(4)
            dh[i] = 1e-6
            self._solve(0.0, +1, 0, include_async=False, housing_m=dh)
            p1, a1 = self._axis_line()
            self._solve(0.0, +1, 0, include_async=False, housing_m=h0)
            p0, a0 = self._axis_line()
            J[:, i] = (np.concatenate([p1[:2], a1[:2]]) - np.concatenate([p0[:2], a0[:2]])) / 1e-6
        h = -np.linalg.solve(J, y0)
        y = mean_axis(h)
        # Rolling-element sets are nonlinear (Hertz): a few more corrections with the same J.
        for _ in range(8 if self.ball_sets is not None else 0):
            if np.abs(y).max() < 1e-15:
                break
            h = h - np.linalg.solve(J, y)
            y = mean_axis(h)
        self._housing_m = h
        self.axis_average_residual = y
        # The disk centre over that synchronous revolution (the last one, at the final housings):
        # its forward first harmonic c₁ (x + iy = c₁·e^{iθ} + ...) is the disk's eccentricity
        # about the axis of rotation — the installed offset plus the axis's synchronous
        # once-per-revolution motion at the disk plane (a journal's run-out, an inner race's
        # eccentricity), which turns with the shaft and is by definition centring (ISO 230-7:
        # the fundamental is not error motion). What the encoder's first harmonic and the CCD
        # sweep (Jia eqs. 10-12) see; truth/bench.json disk_eccentricity_axis_m (docs/scoring.md).
        zc, ang = np.array(disk), np.array(angles)
        self.disk_centre_axis_c1_m = complex(np.mean(zc * np.exp(-1j * ang)))
        self.disk_centre_axis_cm1_m = complex(np.mean(zc * np.exp(1j * ang)))
        self._q_last = np.zeros(6)
        self._cmd_last = 0.0
        self.total_iterations = 0
        self.n_poses = 0

    # ----------------------------------------------------------------------------- API -------
    def _body(self, name: str, frames: tuple[np.ndarray, np.ndarray] | None = None) -> BodyPose:
        """The posed body ``name``; ``frames``: one copy of (xpos, xmat as (nbody, 3, 3)) shared by
        the bodies of a pose (two copies per pose instead of two per body)."""
        i = self._bid[name]
        if frames is None:
            return BodyPose(pos=self.data.xpos[i].copy(), R=self.data.xmat[i].reshape(3, 3).copy())
        return BodyPose(pos=frames[0][i], R=frames[1][i])

    def pose_at(self, shaft_angle_rad: float, rep: int = 0, t_s: float = 0.0, direction: int = +1,
                rolling: bool = False, bearing_torque_Nm: float | None = None) -> BenchPose:
        """Command the drive to ``shaft_angle_rad`` approached in ``direction`` (+1 CCW, −1 CW),
        settle to static equilibrium and return the posed bodies (lab frame, m).

        ``rep`` selects the run for "path" bearings (their random non-repeating motion is drawn
        per rep). ``t_s`` is the bench clock: for ball bearings a pose at a new time is a new
        stop on the bench's path (the cages roll with the shaft from the previous stop, with
        slip), a pose at the same time refines the current stop (the servo's iterations).
        ``rolling``: a sample during steady rotation (twin/continuous.py): no start/stop slip.
        ``bearing_torque_Nm``: the friction torque the bearing holds on the disk section at rest
        (from the drive servo's dynamics, twin/instruments/drive.py); None: the sliding friction
        opposing ``direction`` (a quasi-static approach)."""
        if direction not in (1, -1):
            raise ValueError("direction must be +1 or -1")
        self._advance_path(t_s, rolling)
        if self.thermal.active:   # the housings' thermal drift at this time (twin/thermal.py)
            # a function of t_s alone: the servo's refinements of a stop (same t_s) reuse it
            t = float(t_s)
            if t != self._drift_t or self.thermal is not self._drift_src:
                d = self.thermal.axis_drift_m(t)
                self._drift4_t = np.array([d[0], d[1], d[0], d[1]])
                self._drift_t, self._drift_src = t, self.thermal
            self._drift4 = self._drift4_t
        if self.air_bearings is not None and self.air_bearings.supply.active:
            # the supply pressure at this time: the loaded journals' stiffness (twin/air_bearing.py)
            base = self._drift4_t if self.thermal.active else np.zeros(4)
            self._drift4 = base + self.air_bearings.supply_offsets_m(float(t_s), -self._housing_m)
        self._held_torque_Nm = None if bearing_torque_Nm is None else float(bearing_torque_Nm)
        try:
            it = self._solve(float(shaft_angle_rad), direction, int(rep))
        finally:
            self._held_torque_Nm = None
        self._end_stop(self.data.qpos[4])
        self.last_iterations = it
        self.total_iterations += it
        self.n_poses += 1
        d = self.data
        q = d.qpos
        axis_p, _ = self._axis_line()
        frames = (d.xpos.copy(), d.xmat.reshape(-1, 3, 3).copy())
        axial_extra = {} if self.axial is None else self._apply_axial(frames, q, float(t_s))
        extra = {
            "shaft": self._body("shaft", frames),
            "polygon_section": self._body("polygon_section", frames),
            "drive_angle_rad": float(shaft_angle_rad),
            "twist_disk_to_polygon_rad": float(q[5]),
            "drive_torque_Nm": float(d.actuator_force[self._act]),
            "axis_disk_plane_m": axis_p[:2].copy(),
            "polygon_face_normal_angle_rad": self.polygon_face_normal_angle_rad,
            **({"polygon_face_pyramidal_rad": self.polygon_pyramidal_rad}
               if self.polygon_pyramidal_rad is not None else {}),
            **axial_extra,
            "settle_iterations": it,
            "rep": int(rep),
            "direction": int(direction),
        }
        return BenchPose(
            t_s=float(t_s),
            shaft_angle_rad=float(q[4]),
            disk=self._body("disk", frames),
            polygon=self._body("polygon", frames),
            sphere_top=self._body("sphere_top", frames),
            sphere_bottom=self._body("sphere_bottom", frames),
            extra=extra,
        )

    def axial_z_m(self, q: np.ndarray, t_s: float) -> dict[str, float]:
        """The shaft's axial displacement along its spin axis at the settled state q and time t
        (twin/axial.py), by cause (m): the bearings' model (ball pair: Hertz equilibrium at this
        pose's ball loads; air: the runner form at this angle), the supply pressure (time), the
        structure's thermal growth (time)."""
        ax = self.axial
        assert ax is not None
        th = float(q[4])
        if ax.ball is not None:
            u, th, cages, _rates = self._kernel_inputs(q)
            bearing = ax.ball.solve_z_m(ax.ball.base_approaches_m(u, th, cages))
            supply = 0.0
        else:
            assert ax.air is not None
            bearing = ax.air.z0_m + ax.air.z_form_m(th)
            supply = ax.air.z_supply_m(t_s)
        thermal = ax.thermal_m(t_s)
        return {"bearing": bearing, "supply": supply, "thermal": thermal, "total": bearing + supply + thermal}

    def _apply_axial(self, frames: tuple[np.ndarray, np.ndarray], q: np.ndarray, t_s: float) -> dict:
        """Translate the posed shaft (every body on the shaft carrier) by z along its spin axis."""
        parts = self.axial_z_m(q, t_s)
        n = frames[1][self._bid["shaft"]][:, 2]
        frames[0][self._axial_bodies] += parts["total"] * n
        return {"axial_m": parts["total"], "axial_parts_m": parts, "spin_axis_lab": n.copy()}

    def disk_plane_motion(self, angles_rad, rep: int = 0, direction: int = +1) -> tuple[np.ndarray, np.ndarray]:
        """True motion (dx, dy) of the axis of rotation (the shaft's spin axis) where it crosses
        the disk plane z = 0, relative to the axis average line, at each commanded angle."""
        angles = np.atleast_1d(np.asarray(angles_rad, dtype=float))
        out = np.zeros((angles.size, 2))
        self._drift4 = np.zeros(4)    # the bench as at t = 0 (no thermal drift yet)
        for i, th in enumerate(angles):
            self._solve(float(th), direction, int(rep))
            out[i] = self._axis_line()[0][:2]
        return out[:, 0].copy(), out[:, 1].copy()

    def sphere_form_deviation_m(self, which: str, polar_angle_body_rad) -> np.ndarray:
        """Radius deviation of sphere ``which`` ("top"/"bottom") at a body-frame polar angle
        (equatorial lobing model; probes touch near the equator)."""
        k, a, p = _lobes_arrays(self.sphere_form[which])
        g = np.asarray(polar_angle_body_rad, dtype=float)
        return np.sum(a[:, None] * np.cos(k[:, None] * g.ravel()[None, :] - p[:, None]), axis=0).reshape(g.shape)

    def polygon_face_normals_body(self) -> np.ndarray:
        """(N, 3) outward unit normals of faces 1…N in the polygon body frame (pitch deviations
        included)."""
        return face_normals(self.polygon_face_normal_angle_rad, self.polygon_pyramidal_rad)

    def truth(self) -> dict:
        """Every generated or derived physical parameter, JSON-ready, SI, unit-suffixed keys."""
        sc = self.sc
        br = sc["bearings"]
        tf = self.friction_torque_Nm
        truth = {
            "model": "benchtwin.models/bench.xml + twin/build.py",
            "model_template": template_path().name,
            "mujoco_version": mujoco.__version__,
            "seed": self.seed,
            "gravity_m_s2": list(map(float, self.model.opt.gravity)),
            "geometry": {k: v for k, v in self.geometry.items()},
            "disk_eccentricity_m": float(np.hypot(*self.disk_offset_m[:2])),
            "disk_eccentricity_azimuth_body_rad": self.disk_eccentricity_azimuth_rad,
            "theta0_rad": float(sc["errors"]["theta0"]),
            # about the axis of rotation: the installed offset plus the axis's synchronous first
            # harmonic at the disk plane (_center_axis_average_line); the e and θ0 Jia eqs. 10-12 define
            "disk_eccentricity_axis_m": abs(self.disk_centre_axis_c1_m),
            "theta0_axis_rad": (0.5 * math.pi - math.atan2(self.disk_centre_axis_c1_m.imag, self.disk_centre_axis_c1_m.real)) % (2.0 * math.pi),
            "axis_first_harmonic_disk_plane_m": {
                "forward_m": abs(self.disk_centre_axis_c1_m - self.disk_offset_m[0] - 1j * self.disk_offset_m[1]),
                "backward_m": abs(self.disk_centre_axis_cm1_m),
                "note": "the disk centre's forward first harmonic over a synchronous revolution (no time-keyed "
                        "motion) minus the installed offset: the axis's once-per-revolution motion that turns "
                        "with the shaft; backward: the counter-rotating part (not an eccentricity)"},
            "disk_centre_body_m": self.disk_offset_m.tolist(),
            "disk_tilt_rad": self.placement.disk_tilt_rad,
            "disk_tilt_azimuth_rad": self.placement.disk_tilt_azimuth_rad,
            "sphere_top_centre_body_m": (self.sphere_offset_m["top"] + [0, 0, self.geometry["sphere_top_z_m"]]).tolist(),
            "sphere_bottom_centre_body_m": (self.sphere_offset_m["bottom"] + [0, 0, self.geometry["sphere_bottom_z_m"]]).tolist(),
            "sphere_top_form": _lobes_json(self.sphere_form["top"]),
            "sphere_bottom_form": _lobes_json(self.sphere_form["bottom"]),
            "polygon_faces": self.n_faces,
            "polygon_pitch_deviation_rad": self.polygon_pitch_deviation_rad.tolist(),
            "polygon_pitch_deviation_arcsec": (self.polygon_pitch_deviation_rad / ARCSEC).tolist(),
            "polygon_face_normal_angle_body_rad": self.polygon_face_normal_angle_rad.tolist(),
            **({"polygon_pyramidal_error_rad": self.polygon_pyramidal_rad.tolist(),
                "polygon_pyramidal_error_arcsec": (self.polygon_pyramidal_rad / ARCSEC).tolist()}
               if self.polygon_pyramidal_rad is not None else {}),
            "polygon_centre_body_m": self.polygon_offset_m.tolist(),
            "polygon_eccentricity_phase_rad": self.polygon_eccentricity_phase_rad,
            "polygon_tilt_rad": self.placement.polygon_tilt_rad,
            "polygon_tilt_azimuth_rad": self.placement.polygon_tilt_azimuth_rad,
            "waviness_top": _lobes_json(self.waviness["top"]),
            "waviness_bottom": _lobes_json(self.waviness["bottom"]),
            "motion_table": self.motion_table,
            "cage_ratio": self.cage_ratio,
            "async_rms_m": self.async_rms_m,
            "async_cage_fraction": self.async_cage_fraction,
            "cage_lobes_top": [{"order": int(k), "amplitude_m": float(a), "phase_rad": float(p)}
                               for k, a, p in zip(*self.cage_lobes["top"])],
            "cage_lobes_bottom": [{"order": int(k), "amplitude_m": float(a), "phase_rad": float(p)}
                                  for k, a, p in zip(*self.cage_lobes["bottom"])],
            "unbalance_kgm": float(br["unbalance"]),
            "unbalance_phase_body_rad": self.unbalance_phase_rad,
            "unbalance_radius_m": UNBALANCE_RADIUS_M,
            "unbalance_z_m": self.placement.unbalance_z_m,
            "housing_offsets_m": dict(zip(BEARING_TENDONS, self._housing_m.tolist())),
            "bearing_radial_stiffness_N_m": float(br["radial_stiffness"]),
            "bearing_tilt_stiffness_Nm_rad": float(br["tilt_stiffness"]),
            "friction_torque_Nm": tf,
            "drive_torsional_stiffness_Nm_rad": float(br["drive_torsional_stiffness"]),
            "shaft_torsional_stiffness_Nm_rad": float(br["shaft_torsional_stiffness"]),
            # Nominal (no unbalance torque) lags: what hysteresis to expect per direction.
            "twist_disk_to_polygon_nominal_rad": tf / float(br["shaft_torsional_stiffness"]),
            "lag_disk_behind_drive_nominal_rad": tf * (1 / float(br["drive_torsional_stiffness"])
                                                       + 1 / float(br["shaft_torsional_stiffness"])),
            "settle_atol": SETTLE_ATOL,
        }
        if self.thermal.active or self.thermal.loop_active:
            truth["thermal"] = self.thermal.truth()
        if self.air_bearings is not None:
            truth["bearing_type"] = self.bearing_type
            truth["air_bearings"] = self.air_bearings.truth()
        if self.ball_sets is not None:
            truth["bearing_type"] = self.bearing_type
            truth["ball_sets"] = {k: v.truth() for k, v in self.ball_sets.items()}
            truth["cage_slip_relative"] = self.cage_slip
            if self.cage_slip_time_s > 0 or self.cage_slip_mean > 0:   # absent for the per-stop model
                truth["cage_slip_model"] = "time" if self._slip_omega is not None else "per_stop"
                truth["cage_slip_time_s"] = self.cage_slip_time_s
                truth["cage_slip_mean"] = self.cage_slip_mean
            truth["cage_start_rad"] = self._cage0.tolist()
        if self.axial is not None:
            truth["axial"] = self.axial.truth()
            thrust = truth.get("air_bearings", {}).get("thrust")
            if thrust is not None:   # with [axial] the thrust bearing's film does carry the shaft
                thrust["note"] = "applied: the shaft's axial DOF of [axial] (twin/axial.py; truth axial.air_thrust)"
        return truth
