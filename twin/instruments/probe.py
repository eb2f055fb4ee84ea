"""Inductive (TESA-like lever) probe on a precision test sphere (Jia 2019 sec. 4.1).

Geometry, exact: the probe's measuring axis is the lab line through the sphere's NOMINAL centre
(on the lab z axis at the sphere's nominal height) along the unit vector u (lab +Y, or +X for the
optional X probes); the tip touches the sphere from the ``side`` (+1: from +u, the default; −1:
from −u). The contact point is the intersection of that line with the posed sphere: centre c
(the sphere frame's origin), radius ρ = R + f(polar angle of the contact direction in the sphere's
body frame), f the form error (equatorial lobes, ``Bench.sphere_form``); ρ depends on the contact
point, so the intersection is iterated (three passes converge far below 1e-15 m for nm-size form
errors). The reading is the contact point's displacement along +u relative to the nominal surface
point (s − side·R along the axis): positive when the sphere moves towards +u, whatever side the
probe touches from (docs/conventions.md).

Imperfections, in this order, on the deflection L (the displacement, the probe zeroed at the
nominal): linearity error = a smooth seeded curve inside the permissible envelope
±(a + b·(L/1 mm)²) (``linearity_a``, ``linearity_b``; 0 at L = 0), repeatability noise (rms),
resolution quantisation; outside ±``range`` the status is "out_of_range" (value NaN).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchtwin.hw.interfaces import ProbeReading
from benchtwin.units import UM, quantise

from .stage import SimBenchState, sim_rng



@dataclass(frozen=True)
class ProbeSpec:
    """A probe's geometry and data sheet: the sphere it touches ("top"/"bottom") and its measuring
    axis ("y" or "x"), the side it touches from (+1: from +u; −1: from −u), the sphere's radius and
    nominal centre height (m), its form lobes ({order, amplitude (m), phase (rad)}), repeatability
    (rms, m), the linearity envelope ±(a + b·(L/1 mm)²) (m), the range ±range (m) and the
    resolution (m)."""

    sphere: str = "top"
    axis: str = "y"
    side: int = +1
    sphere_radius_m: float = 6e-3
    nominal_z_m: float = 0.0
    form_lobes: Sequence[dict] = ()
    repeatability_m: float = 0.0
    linearity_a_m: float = 0.0
    linearity_b_m: float = 0.0
    range_m: float = 0.3e-3
    resolution_m: float = 0.0

    def __post_init__(self) -> None:
        if self.sphere not in ("top", "bottom"):
            raise ValueError("sphere must be 'top' or 'bottom'")
        if self.axis not in ("x", "y"):
            raise ValueError("axis must be 'x' or 'y'")
        if self.side not in (1, -1):
            raise ValueError("side must be +1 or -1")


class SimProbe:
    """``DisplacementProbe`` of the twin on sphere ``spec.sphere`` ("top"/"bottom"), axis "y" or "x";
    ``seed`` and ``key``: its linearity curve's and noise's random streams."""

    kind = "probe"

    def __init__(self, name: str, state: SimBenchState, spec: ProbeSpec, seed: int = 0, key: int = 0):
        self.spec = spec
        self.name, self.state, self.sphere, self.axis, self.side = name, state, spec.sphere, spec.axis, int(spec.side)
        self.u = np.array([1.0, 0.0, 0.0]) if spec.axis == "x" else np.array([0.0, 1.0, 0.0])
        self.R = float(spec.sphere_radius_m)
        self.nominal_z_m = float(spec.nominal_z_m)
        self.form = [(int(l["order"]), float(l["amplitude"]), float(l["phase"])) for l in spec.form_lobes]
        self.repeatability_m = float(spec.repeatability_m)
        self.linearity_a_m = float(spec.linearity_a_m)
        self.linearity_b_m = float(spec.linearity_b_m)
        self.range_m = float(spec.range_m)
        self.resolution_m = float(spec.resolution_m)
        self.key = int(key)
        # Linearity curve: g(L) = Σ c_k [sin(kπL/(2·range) + φ_k) − sin φ_k], |g| ≤ 0.9 on ±range.
        r = sim_rng(seed, "probe_linearity", key)
        self._lin_c = r.normal(0.0, 1.0, 3) / np.arange(1, 4)
        self._lin_p = r.uniform(0, 2 * math.pi, 3)
        grid = np.linspace(-self.range_m, self.range_m, 2001)
        peak = np.max(np.abs(self._lin_shape(grid)))
        self._lin_scale = 0.9 / peak if peak > 0 else 0.0

    @classmethod
    def sim_from_scenario(cls, sc: Any, state: SimBenchState, bench: Any, sphere: str, axis: str = "y",
                          name: str | None = None, key: int = 0) -> "SimProbe":
        p = sc["instruments"]["probe"]
        g = bench.geometry
        spec = ProbeSpec(sphere, axis, +1, sphere_radius_m=g["sphere_radius_m"], nominal_z_m=g[f"sphere_{sphere}_z_m"],
                         form_lobes=bench.sphere_form[sphere], repeatability_m=p["repeatability"],
                         linearity_a_m=p["linearity_a"], linearity_b_m=p["linearity_b"], range_m=p["range"],
                         resolution_m=p["resolution"])
        return cls(name or f"probe_{sphere}" + ("_x" if axis == "x" else ""), state, spec, seed=state.seed, key=key)

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "kind": "probe", "model": "sim inductive probe (twin), TESA-like",
                "units": {"value_um": "um", "t_s": "s"}, "sphere": self.sphere, "axis": "+" + self.axis,
                "range_um": self.range_m / UM, "resolution_um": self.resolution_m / UM,
                "repeatability_um": self.repeatability_m / UM}

    # ------------------------------------------------------------------ physics
    def _form(self, polar: float) -> float:
        return sum(a * math.cos(k * polar - p) for k, a, p in self.form)

    def sim_displacement_m(self, pose=None) -> float:
        """Exact displacement of the sphere surface along +u at the probe axis (m), no
        instrument error."""
        pose = self.state.pose if pose is None else pose
        body = pose.sphere_top if self.sphere == "top" else pose.sphere_bottom
        p0 = np.array([0.0, 0.0, self.nominal_z_m])
        w = p0 - body.pos
        b = float(w @ self.u)
        ww = float(w @ w)
        # first guess of the contact direction: the nominal one
        d = (p0 + self.side * self.R * self.u - body.pos) @ body.R
        rho = self.R + self._form(math.atan2(d[1], d[0]))
        for _ in range(3):
            disc = b * b - ww + rho * rho
            if disc < 0:
                raise ValueError(f"{self.name}: the probe axis misses the sphere")
            s = -b + self.side * math.sqrt(disc)
            d = (p0 + s * self.u - body.pos) @ body.R
            rho = self.R + self._form(math.atan2(d[1], d[0]))
        disc = b * b - ww + rho * rho
        s = -b + self.side * math.sqrt(disc)
        return s - self.side * self.R

    # ------------------------------------------------------------------ signal chain
    def _lin_shape(self, L):
        L = np.asarray(L, dtype=float)
        k = np.arange(1, 4)[:, None]
        x = k * math.pi * L.ravel()[None, :] / (2 * self.range_m)
        g = np.sum(self._lin_c[:, None] * (np.sin(x + self._lin_p[:, None]) - np.sin(self._lin_p[:, None])), axis=0)
        return g.reshape(L.shape)

    def sim_linearity_error_m(self, L) -> np.ndarray:
        """Deterministic linearity error (m) at deflection L (m): inside ±(a + b·(L/mm)²)."""
        L = np.asarray(L, dtype=float)
        env = self.linearity_a_m + self.linearity_b_m * (L / 1e-3) ** 2
        return env * self._lin_scale * self._lin_shape(L)

    def read(self) -> ProbeReading:
        st = self.state
        L = self.sim_displacement_m(st.pose)
        t = float(st.clock.now())
        if abs(L) > self.range_m:
            return {"value_um": float("nan"), "t_s": t, "status": "out_of_range"}
        v = L + float(self.sim_linearity_error_m(L))
        th = getattr(st.bench, "thermal", None)
        if th is not None and th.probe_stand_m_K:   # the stand's thermal growth (twin/thermal.py)
            v += th.probe_stand_drift_m(t)
        if self.repeatability_m > 0:
            v += st.rng("probe_noise", self.key).normal(0.0, self.repeatability_m)
        return {"value_um": quantise(v / UM, self.resolution_m / UM), "t_s": t, "status": "ok"}
