"""Reading heads of the angle encoder, read from the posed grating disk (exact geometry).

Geometry (docs/conventions.md, twin/pose.py): head j sits at lab azimuth 90° + h_j (head 1 on +Y,
h_1 = 0) at the optical radius r. Its line of sight is the lab line through P_j = r·(cos, sin,
0) parallel to the lab z axis (displaced by its mount's thermal growth, twin/thermal.py
[measuring_loop], at the pose's time); it meets the posed disk plane (through the disk frame's origin,
normal = disk body z) at Q_j. Q_j in the disk body frame has the polar angle γ_j about the disk's
GEOMETRIC centre (the body origin): that is the graduation position under the head, whatever the
eccentricity, radial motion or tilt of the disk. No small-angle step anywhere.

Graduation (division) error, fixed to the disk: the line of nominal value g lies at body angle
g + E(g); the head that sees body angle γ therefore reads the value g solving g + E(g) = γ
(fixed-point iteration, E is a few arcsec). E is the head's view of the disk's LINE-POSITION MAP
(``graduation.py``): the ruling engine's closed random walk plus the disk's clamping harmonics
(declared: ``errors.graduation_error_rms``, the rms the head reads; hidden: ``[hidden]
graduation_error``), averaged over the head's scanning field and interpolated between lines; the
hidden ``thermal_growth`` adds a k-lobed distortion that follows the clamp's temperature.

Reading: head j reports (90° + h_j) − g_j: the graduation value counted from the index (the line
under head 1 at zero shaft angle of a centred disk, body polar angle 90°), plus its own azimuth,
so that every head of a perfect, centred disk reads the true shaft angle. The counter is
multi-turn: the reading is unwrapped next to the shaft's angle. Then, in this order: the
interpolation error (periodic in the grating pitch: first order of amplitude
``instruments.encoder.interpolation_error`` and second order of a third of it, seeded phases),
noise (``instruments.encoder.noise``, rms, independent per head), resolution quantisation
(``bench.encoder_resolution``).

Without hidden effects the graduation fixed point and the reading's tail run per head on Python
floats (1-3 heads: NumPy's call overhead was most of a reading's cost); the same IEEE operations
in the same order, the sines and atan2 NumPy's on the same arrays, so the readings are the array
expression's doubles (tests/twin/test_instruments.py, tests/twin/test_graduation.py).

Eccentricity alone gives, exactly (law of sines in the triangle axis–centre–head):
sin α = (e/r)·sin(θ − θ0) with θ the reading; tests/twin/test_instruments.py checks it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchtwin.hw.interfaces import EncoderReading
from benchtwin.twin.pose import BenchPose

from .graduation import SCANNING_FIELD_LINES, HeadMap, declared_line_map
from .stage import ARCSEC, TWO_PI, SimBenchState, sim_rng

# Fixed point g + E(g) = γ: stop when the step is ≤ 8 ulp of π (1.8e-15 rad = 3.7e-10″).
GRADUATION_FIXED_POINT_TOL_RAD = 8 * math.ulp(math.pi)


def _wrap_pi(x):
    return (np.asarray(x) + math.pi) % TWO_PI - math.pi


def sim_lines_from_bench(bench: dict) -> int:
    """Lines on the disk: ``bench.encoder_lines`` or, if 0, the count that gives the catalogue
    period at the scale edge (the same count the CCD renderer draws)."""
    n = int(bench.get("encoder_lines", 0) or 0)
    if n > 0:
        return n
    return int(round(TWO_PI * float(bench["scale_edge_radius"]) / float(bench["grating_period"])))


@dataclass(frozen=True)
class EncoderSpec:
    """An encoder's geometry and data sheet: its heads' azimuths from head 1 (rad; head 1 at 0), the
    optical radius (m), the lines on the disk, the display's resolution (rad), the heads' noise
    (rms, rad), the interpolation error's amplitude (rad, order 1 of the grating pitch; order 2
    a third of it), the declared line map's rms (rad) and the scanning field (lines a head averages)."""

    heads_rad: Sequence[float] = (0.0,)
    radius_m: float = 22e-3
    n_lines: int = 7069
    resolution_rad: float = 0.39 * ARCSEC
    noise_rad: float = 0.0
    interpolation_error_rad: float = 0.0
    graduation_error_rms_rad: float = 0.0
    scanning_field_lines: int = SCANNING_FIELD_LINES


class SimEncoder:
    """``AngleEncoder`` of the twin: one counter, one or more reading heads; ``seed`` and ``key``:
    its disk's and noise's random streams."""

    kind = "encoder"

    def __init__(self, name: str, state: SimBenchState, spec: EncoderSpec = EncoderSpec(), seed: int = 0,
                 key: int = 0):
        self.name = name
        self.state = state
        self.spec = spec
        self.heads_rad = np.asarray(spec.heads_rad, dtype=float)
        if self.heads_rad.size < 1 or self.heads_rad[0] != 0.0:
            raise ValueError("heads: head 1 must be at 0 (azimuths are measured from head 1)")
        self.radius_m = float(spec.radius_m)
        self.n_lines = int(spec.n_lines)
        self.pitch_rad = TWO_PI / self.n_lines
        self.resolution_rad = float(spec.resolution_rad)
        self.noise_rad = float(spec.noise_rad)
        self.key = int(key)
        # Graduation error: the declared line-position map (a property of the disk: seeded, fixed).
        self.graduation_error_rms_rad = float(spec.graduation_error_rms_rad)
        self.scanning_field_lines = int(spec.scanning_field_lines)
        self._declared_lines = None
        if self.graduation_error_rms_rad > 0:
            self._declared_lines = declared_line_map(self.n_lines, self.graduation_error_rms_rad,
                                                     sim_rng(seed, "encoder_graduation"), self.scanning_field_lines)
        self._map_cache: tuple | None = None
        # Interpolation error: orders 1 and 2 of the grating pitch.
        ri = sim_rng(seed, "encoder_interpolation")
        self.interpolation = {"amplitude_rad": np.array([1.0, 1.0 / 3.0]) * float(spec.interpolation_error_rad),
                              "phase_rad": ri.uniform(0, TWO_PI, 2)}
        self._interpolation_terms = [(m * self.n_lines, float(p), float(a)) for m, (a, p) in enumerate(
            zip(self.interpolation["amplitude_rad"], self.interpolation["phase_rad"]), start=1) if a]
        # [hidden] effects of the disk and heads (twin/hidden.py); None: none.
        self.hidden = None
        self._head_points: tuple | None = None
        # (pose, exact readings) of the stage's last stop: read() there reuses them (the servo's
        # last evaluation of the same pose); set by SimRotaryStage.move_to.
        self.sim_last_exact: tuple | None = None

    @classmethod
    def sim_from_scenario(cls, sc: Any, state: SimBenchState, name: str = "encoder",
                          hidden: Any = None) -> "SimEncoder":
        """``hidden``: the bench's ``Hidden`` (built once per bench, ``Bench.hidden``); None: built
        from the scenario."""
        from benchtwin.twin.hidden import hidden_for

        b, enc = sc["bench"], sc["instruments"]["encoder"]
        hidden = hidden_for(sc, hidden)
        # hidden.optical_radius: the heads sit at the TRUE radius (the manifest keeps the nominal)
        spec = EncoderSpec(heads_rad=[float(h) for h in b["heads"]],
                           radius_m=float(b["optical_radius"]) * hidden.optical_radius_factor,
                           n_lines=sim_lines_from_bench(b), resolution_rad=float(b["encoder_resolution"]),
                           noise_rad=float(enc["noise"]), interpolation_error_rad=float(enc["interpolation_error"]),
                           graduation_error_rms_rad=float(sc["errors"]["graduation_error_rms"]))
        obj = cls(name, state, spec, seed=state.seed)
        obj.hidden = hidden if hidden else None
        return obj

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "kind": "encoder", "model": "sim encoder (twin): exact head geometry",
                "units": {"angle_deg": "deg", "heads_deg": "deg", "t_s": "s"},
                "heads_deg": np.degrees(self.heads_rad).tolist(), "lines": self.n_lines,
                "optical_radius_m": self.radius_m, "resolution_arcsec": self.resolution_rad / ARCSEC,
                "noise_arcsec": self.noise_rad / ARCSEC}

    # ------------------------------------------------------------------ disk properties
    def _hidden_graduation(self) -> bool:
        return self.hidden is not None and self.hidden.has_graduation

    def sim_graduation_map(self) -> HeadMap | None:
        """The disk's static line-position map as the heads read it (declared + hidden), None when
        the disk is perfect."""
        key = (self.hidden, self._declared_lines is None)
        c = self._map_cache
        if c is not None and c[0] is key[0] and c[1] == key[1]:
            return c[2]
        lines = None if self._declared_lines is None else self._declared_lines.copy()
        if self.hidden is not None:
            h = self.hidden.graduation_line_error_rad(self.n_lines, self.radius_m)
            if h is not None:
                lines = h if lines is None else lines + h
        m = None if lines is None else HeadMap(lines, self.scanning_field_lines)
        self._map_cache = (key[0], key[1], m)
        return m

    def sim_graduation_error(self, g, t_s: float = 0.0) -> np.ndarray:
        """E(g): body angle of the line of nominal value g minus g (rad), as the head reads it, at
        time t (the hidden thermal deformation is the only time-dependent part)."""
        g = np.asarray(g, dtype=float)
        m = self.sim_graduation_map()
        out = np.zeros_like(g) if m is None else m.error_rad(g)
        if self.hidden is not None:
            thermal = getattr(getattr(self.state, "bench", None), "thermal", None)   # twin/thermal.py
            out = out + self.hidden.thermal_graduation_error_rad(g, t_s, thermal, self.radius_m, self.n_lines,
                                                                 self.scanning_field_lines)
        return out

    def sim_graduation_value(self, gamma, t_s: float = 0.0) -> np.ndarray:
        """Value g of the graduation seen at body polar angle γ: solves g + E(g) = γ."""
        gamma = np.asarray(gamma, dtype=float)
        if self.graduation_error_rms_rad == 0 and not self._hidden_graduation():
            return gamma
        if self.hidden is None:
            m = self.sim_graduation_map()
            if m is not None:
                return self._graduation_value_static(gamma, m)
        g = gamma - self.sim_graduation_error(gamma, t_s)
        # Contraction factor |E'| ≲ 1e-4: the step shrinks ~1e4-fold per iteration, so a step of
        # a few ulp of γ (|γ| ≤ π) leaves g within float rounding of the fixed point (≪ 1e-9″;
        # a tolerance below one ulp would never be met and always ran all iterations).
        tol = GRADUATION_FIXED_POINT_TOL_RAD
        for _ in range(8):
            g_new = gamma - self.sim_graduation_error(g, t_s)
            done = np.max(np.abs(g_new - g)) <= tol
            g = g_new
            if done:
                break
        return g

    @staticmethod
    def _graduation_value_static(gamma: np.ndarray, m: HeadMap) -> np.ndarray:
        """``sim_graduation_value`` of a disk with a time-independent map (no hidden effects), bit
        for bit: the same iteration and joint stopping rule on Python floats (``HeadMap.error_at``
        is ``error_rad`` of one value); NumPy's per-call overhead on 1-12 heads was most of a
        reading's cost (tests/twin/test_instruments.py checks the identity)."""
        err = m.error_at
        gam = gamma.tolist()
        g = [c - err(c) for c in gam]
        tol = GRADUATION_FIXED_POINT_TOL_RAD
        for _ in range(8):
            g_new = [c - err(x) for c, x in zip(gam, g)]
            done = max([abs(a - b) for a, b in zip(g_new, g)]) <= tol
            g = g_new
            if done:
                break
        return np.array(g)

    def sim_interpolation_error(self, g) -> np.ndarray:
        g = np.asarray(g, dtype=float)
        out = np.zeros_like(g)
        # (m·L, phase, amplitude) of the non-zero orders, built once: the same floats as iterating
        # ``self.interpolation`` (which is not changed after __init__)
        for k, p, a in self._interpolation_terms:
            out = out + a * np.sin(k * g + p)
        if self.hidden is not None:
            out = out + self.hidden.interpolation_error_rad(self.n_lines * g, self.n_lines)
        return out

    # ------------------------------------------------------------------ geometry
    def _head_geometry(self) -> tuple[np.ndarray, list[float]]:
        """Lab points P_j of the heads' lines of sight at z = 0, and their azimuths 90° + h_j as
        floats; rebuilt when the radius or the heads change."""
        hp = self._head_points
        if hp is None or hp[0] != self.radius_m or hp[1] is not self.heads_rad:
            az = 0.5 * math.pi + self.heads_rad
            P = np.stack([self.radius_m * np.cos(az), self.radius_m * np.sin(az), np.zeros_like(az)], axis=1)
            hp = self._head_points = (self.radius_m, self.heads_rad, P, az.tolist())
        return hp[2], hp[3]

    def sim_head_mount_drift_m(self, t_s: float) -> tuple[float, float]:
        """The heads' displacement by their mount's thermal growth at bench time t (m): (along the
        disk's counter-clockwise tangent, radially outward); twin/thermal.py, [measuring_loop]."""
        th = getattr(getattr(self.state, "bench", None), "thermal", None)
        if th is None or not (getattr(th, "head_t_m_K", 0.0) or getattr(th, "head_r_m_K", 0.0)):
            return 0.0, 0.0
        return th.head_mount_drift_m(t_s)

    def sim_head_body_angles(self, pose: BenchPose) -> np.ndarray:
        """Body polar angle γ_j (about the disk's geometric centre) of each head's line of sight;
        each line of sight where its mount holds it at the pose's time (the counter still adds the
        head's nominal azimuth: it does not know that the head moved)."""
        P = self._head_geometry()[0]
        d_t, d_r = self.sim_head_mount_drift_m(pose.t_s)
        if d_t or d_r:
            az = 0.5 * math.pi + self.heads_rad
            c, s = np.cos(az), np.sin(az)
            P = P + np.stack([d_r * c - d_t * s, d_r * s + d_t * c, np.zeros_like(az)], axis=1)
        n = pose.disk.R[:, 2]
        c = pose.disk.pos
        t = ((c - P) @ n) / n[2]  # along lab z onto the disk plane
        Q = P.copy()
        Q[:, 2] += t
        q = pose.disk.to_body(Q)
        return np.arctan2(q[:, 1], q[:, 0])

    def sim_exact_readings(self, pose: BenchPose | None = None) -> np.ndarray:
        """Readings (rad) of every head from the exact geometry, graduation and interpolation
        errors included; no noise, no quantisation."""
        pose = self.state.posed(pose)
        g = self.sim_graduation_value(self.sim_head_body_angles(pose), pose.t_s)
        phi = pose.shaft_angle_rad
        if self.hidden is not None:
            raw = 0.5 * math.pi + self.heads_rad - g + self.sim_interpolation_error(g)
            return phi + _wrap_pi(raw - phi)
        # Without hidden effects, the same expression per head on Python floats (the sines stay
        # NumPy's, on the same arrays: libm's may differ in the last bit): +, −, × and Python's
        # float % are the IEEE operations NumPy applies element-wise, in the same order, and 1-12
        # heads cost mostly NumPy call overhead (tests/twin/test_instruments.py checks the identity).
        az = self._head_geometry()[1]
        out = [0.0] * len(az)       # the interpolation error: np.zeros_like(g) + each term
        for k, p, a in self._interpolation_terms:
            out = [o + a * s for o, s in zip(out, np.sin(k * g + p).tolist())]
        pi = math.pi
        return np.array([phi + ((((z - x) + o) - phi + pi) % TWO_PI - pi)
                         for z, x, o in zip(az, g.tolist(), out)])

    def read(self) -> EncoderReading:
        st = self.state
        c = self.sim_last_exact
        x = c[1].copy() if c is not None and c[0] is st.pose else self.sim_exact_readings(st.pose)
        if self.noise_rad > 0:
            x = x + st.rng("encoder_noise", self.key).normal(0.0, self.noise_rad, x.size)
        if self.resolution_rad > 0:
            x = np.round(x / self.resolution_rad) * self.resolution_rad
        return {"heads_deg": np.degrees(self.heads_rad).tolist(), "angle_deg": np.degrees(x).tolist(),
                "t_s": float(st.clock.now()), "status": "ok"}
