"""Reading heads of the angle encoder, read from the posed grating disk (exact geometry).

Geometry (docs/conventions.md, twin/pose.py): head j sits at lab azimuth 90° + h_j (head 1 on +Y,
h_1 = 0) at the optical radius r. Its line of sight is the lab line through P_j = r·(cos, sin,
0) parallel to the lab z axis; it meets the posed disk plane (through the disk frame's origin,
normal = disk body z) at Q_j. Q_j in the disk body frame has the polar angle γ_j about the disk's
GEOMETRIC centre (the body origin): that is the graduation position under the head, whatever the
eccentricity, radial motion or tilt of the disk. No small-angle step anywhere.

Graduation (division) error, fixed to the disk: the line of nominal value g lies at body angle
g + E(g); the head that sees body angle γ therefore reads the value g solving g + E(g) = γ
(fixed-point iteration, E is a few arcsec). E = low-order harmonics (orders 2…10, amplitudes
∝ 1/k, seeded phases; 90 % of the variance) + random per-line errors averaged over the head's
scanning window (``head_window_lines``, 10 %), scaled to ``errors.graduation_error_rms``.

Reading: head j reports (90° + h_j) − g_j: the graduation value counted from the index (the line
under head 1 at zero shaft angle of a centred disk, body polar angle 90°), plus its own azimuth,
so that every head of a perfect, centred disk reads the true shaft angle. The counter is
multi-turn: the reading is unwrapped next to the shaft's angle. Then, in this order: the
interpolation error (periodic in the grating pitch: first order of amplitude
``instruments.encoder.interpolation_error`` and second order of a third of it, seeded phases),
noise (``instruments.encoder.noise``, rms, independent per head), resolution quantisation
(``bench.encoder_resolution``).

Eccentricity alone gives, exactly (law of sines in the triangle axis–centre–head):
sin α = (e/r)·sin(θ − θ0) with θ the reading; tests/twin/test_instruments.py checks it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from benchtwin.hw.interfaces import EncoderReading
from benchtwin.twin.pose import BenchPose

from .stage import ARCSEC, TWO_PI, SimBenchState, sim_rng

GRADUATION_ORDERS = tuple(range(2, 11))
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


class SimEncoder:
    """``AngleEncoder`` of the twin: one counter, one or more reading heads."""

    kind = "encoder"

    def __init__(self, name: str, state: SimBenchState, heads_rad: Sequence[float] = (0.0,),
                 radius_m: float = 22e-3, n_lines: int = 7069, resolution_rad: float = 0.39 * ARCSEC,
                 noise_rad: float = 0.0, interpolation_error_rad: float = 0.0,
                 graduation_error_rms_rad: float = 0.0, seed: int = 0, key: int = 0,
                 per_line_fraction: float = 0.1, head_window_lines: int = 64):
        self.name = name
        self.state = state
        self.heads_rad = np.asarray(heads_rad, dtype=float)
        if self.heads_rad.size < 1 or self.heads_rad[0] != 0.0:
            raise ValueError("heads: head 1 must be at 0 (azimuths are measured from head 1)")
        self.radius_m = float(radius_m)
        self.n_lines = int(n_lines)
        self.pitch_rad = TWO_PI / self.n_lines
        self.resolution_rad = float(resolution_rad)
        self.noise_rad = float(noise_rad)
        self.key = int(key)
        # Graduation error: harmonics + per-line part (a property of the disk: seeded, fixed).
        self.graduation_error_rms_rad = float(graduation_error_rms_rad)
        r = sim_rng(seed, "encoder_graduation")
        k = np.array(GRADUATION_ORDERS, dtype=float)
        a = r.uniform(0.5, 1.0, k.size) / k
        ph = r.uniform(0, TWO_PI, k.size)
        a *= math.sqrt(1.0 - per_line_fraction) * self.graduation_error_rms_rad / math.sqrt(0.5 * np.sum(a**2))
        self.graduation_harmonics = {"order": k.astype(int), "amplitude_rad": a, "phase_rad": ph}
        self._line_err = None
        if self.graduation_error_rms_rad > 0 and per_line_fraction > 0:
            e = r.normal(0.0, 1.0, self.n_lines)
            w = max(1, int(head_window_lines))
            c = np.concatenate([e[-w:], e, e[:w]])  # circular moving average over the head window
            avg = np.convolve(c, np.full(w, 1.0 / w), mode="same")[w:w + self.n_lines]
            avg -= avg.mean()
            avg *= math.sqrt(per_line_fraction) * self.graduation_error_rms_rad / np.sqrt(np.mean(avg**2))
            self._line_err = avg
        # Interpolation error: orders 1 and 2 of the grating pitch.
        ri = sim_rng(seed, "encoder_interpolation")
        self.interpolation = {"amplitude_rad": np.array([1.0, 1.0 / 3.0]) * float(interpolation_error_rad),
                              "phase_rad": ri.uniform(0, TWO_PI, 2)}
        # [hidden] effects of the disk and heads (twin/hidden.py); None: none.
        self.hidden = None
        self._harm_cols = None
        self._line_err_ext = None
        self._head_points = None
        # (pose, exact readings) of the stage's last stop: read() there reuses them (the servo's
        # last evaluation of the same pose); set by SimRotaryStage.move_to.
        self.sim_last_exact: tuple | None = None

    @classmethod
    def sim_from_scenario(cls, sc: Any, state: SimBenchState, name: str = "encoder") -> "SimEncoder":
        from benchtwin.twin.hidden import Hidden

        b, enc = sc["bench"], sc["instruments"]["encoder"]
        hidden = Hidden.from_scenario(sc)
        # hidden.optical_radius: the heads sit at the TRUE radius (the manifest keeps the nominal)
        obj = cls(name, state, heads_rad=[float(h) for h in b["heads"]],
                  radius_m=float(b["optical_radius"]) * hidden.optical_radius_factor,
                  n_lines=sim_lines_from_bench(b), resolution_rad=float(b["encoder_resolution"]),
                  noise_rad=float(enc["noise"]), interpolation_error_rad=float(enc["interpolation_error"]),
                  graduation_error_rms_rad=float(sc["errors"]["graduation_error_rms"]), seed=state.seed)
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

    def sim_graduation_error(self, g, t_s: float = 0.0) -> np.ndarray:
        """E(g): body angle of the line of nominal value g minus g (rad), at time t (the hidden
        thermal deformation is the only time-dependent part)."""
        g = np.asarray(g, dtype=float)
        out = self._declared_graduation_error(g)
        if self._hidden_graduation():
            out = out + self.hidden.graduation_error_rad(g, t_s)
        return out

    def _declared_graduation_error(self, g: np.ndarray) -> np.ndarray:
        h = self.graduation_harmonics
        if self.graduation_error_rms_rad == 0:
            return np.zeros_like(g)
        gf = g.reshape(-1)
        k_col, ph_col = self._harmonic_columns()
        out = h["amplitude_rad"] @ np.cos(k_col * gf - ph_col)
        if self._line_err is not None:
            # linear interpolation between lines (the line after the last is line 0 again)
            ext = self._line_err_ext
            if ext is None or ext.size != self._line_err.size + 1:
                ext = self._line_err_ext = np.append(self._line_err, self._line_err[0])
            x = np.mod(gf, TWO_PI) / self.pitch_rad
            fl = np.floor(x)
            f = x - fl
            i0 = fl.astype(np.intp) % self.n_lines
            out = out + (1 - f) * ext[i0] + f * ext[i0 + 1]
        return out.reshape(g.shape)

    def _harmonic_columns(self) -> tuple[np.ndarray, np.ndarray]:
        """(orders, phases) of the graduation harmonics as float column vectors (cached)."""
        h = self.graduation_harmonics
        c = self._harm_cols
        if c is None or c[0] is not h["order"] or c[1] is not h["phase_rad"]:
            c = self._harm_cols = (h["order"], h["phase_rad"], np.asarray(h["order"], dtype=float)[:, None],
                                   np.asarray(h["phase_rad"], dtype=float)[:, None])
        return c[2], c[3]

    def sim_graduation_value(self, gamma, t_s: float = 0.0) -> np.ndarray:
        """Value g of the graduation seen at body polar angle γ: solves g + E(g) = γ."""
        gamma = np.asarray(gamma, dtype=float)
        if self.graduation_error_rms_rad == 0 and not self._hidden_graduation():
            return gamma
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

    def sim_interpolation_error(self, g) -> np.ndarray:
        g = np.asarray(g, dtype=float)
        ip = self.interpolation
        out = np.zeros_like(g)
        for m, (a, p) in enumerate(zip(ip["amplitude_rad"], ip["phase_rad"]), start=1):
            if a:
                out = out + a * np.sin(m * self.n_lines * g + p)
        if self.hidden is not None:
            out = out + self.hidden.interpolation_error_rad(self.n_lines * g)
        return out

    # ------------------------------------------------------------------ geometry
    def sim_head_body_angles(self, pose: BenchPose) -> np.ndarray:
        """Body polar angle γ_j (about the disk's geometric centre) of each head's line of sight."""
        hp = self._head_points
        if hp is None or hp[0] != self.radius_m or hp[1] is not self.heads_rad:
            az = 0.5 * math.pi + self.heads_rad
            P = np.stack([self.radius_m * np.cos(az), self.radius_m * np.sin(az), np.zeros_like(az)], axis=1)
            hp = self._head_points = (self.radius_m, self.heads_rad, P)
        P = hp[2]
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
        pose = self.state.pose if pose is None else pose
        g = self.sim_graduation_value(self.sim_head_body_angles(pose), pose.t_s)
        raw = 0.5 * math.pi + self.heads_rad - g + self.sim_interpolation_error(g)
        phi = pose.shaft_angle_rad
        return phi + _wrap_pi(raw - phi)

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
