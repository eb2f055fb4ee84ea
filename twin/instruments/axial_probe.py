"""Probes parallel to the axis (ISO 230-7:2015 axial and face error motion), on the shaft's axial DOF.

Two targets, exact geometry on the posed bodies (twin/physics.py adds the shaft's axial
displacement z along its spin axis, twin/axial.py), the signal chain of the radial probes
(``SimProbe``: linearity envelope, repeatability, resolution, range; the same [instruments.probe]
data sheet):

- ``probe_axial``: on the top sphere's POLE, along lab +z through the nominal axis, touching from
  above. The contact point of the vertical line x = y = 0 with the posed sphere (centre c, radius R):
  z = c_z + √(R² − c_x² − c_y²); the reading is z − (nominal pole height). A centring error e of
  the sphere changes it by −e²/(2R) only (second order: ISO 230-7 puts the axial probe on the axis for
  that reason). The sphere's form is equatorial lobes (twin/physics.py): at the pole it is taken as
  zero (ASSUMPTION: a grade-G5 sphere's form, ≤ 0.13 µm, is not modelled off the equator).
- ``probe_face``: parallel to the axis at lab (R·cos β, R·sin β), touching the disk's face (the disk
  body's plane z_b = 0) from above; the reading is where that vertical line meets the posed plane.
  It sees the axial motion, the tilt of the axis times R (ISO 230-7 face motion) and the disk's own
  wobble (its placement tilt on the shaft: the target's squareness, a once-per-revolution term).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .probe import ProbeSpec, SimProbe

#: noise/linearity stream keys of the axial probes (the radial ones use 0…3)
AXIAL_PROBE_KEYS = {"probe_axial": 10, "probe_face": 11}


class SimAxialProbe(SimProbe):
    """An inductive probe along lab +z: ``target`` "sphere_pole" (top sphere) or "disk_face"."""

    def __init__(self, name: str, state: Any, spec: ProbeSpec, target: str, radius_m: float = 0.0,
                 azimuth_rad: float = 0.0, seed: int = 0, key: int = 0):
        super().__init__(name, state, spec, seed=seed, key=key)
        if target not in ("sphere_pole", "disk_face"):
            raise ValueError("target must be 'sphere_pole' or 'disk_face'")
        self.target = target
        self.u = np.array([0.0, 0.0, 1.0])
        self.axis = "z"
        self.radius_m = float(radius_m)
        self.azimuth_rad = float(azimuth_rad)

    @classmethod
    def axial_from_scenario(cls, sc: Any, state: Any, bench: Any, which: str) -> "SimAxialProbe":
        p, ax, g = sc["instruments"]["probe"], sc["axial"], bench.geometry
        spec = ProbeSpec("top", "y", +1, sphere_radius_m=g["sphere_radius_m"], nominal_z_m=g["sphere_top_z_m"],
                         form_lobes=(), repeatability_m=p["repeatability"], linearity_a_m=p["linearity_a"],
                         linearity_b_m=p["linearity_b"], range_m=p["range"], resolution_m=p["resolution"])
        if which == "probe_axial":
            return cls(which, state, spec, "sphere_pole", seed=state.seed, key=AXIAL_PROBE_KEYS[which])
        return cls(which, state, spec, "disk_face", radius_m=float(ax["face_probe_radius"]),
                   azimuth_rad=float(ax["face_probe_azimuth"]), seed=state.seed, key=AXIAL_PROBE_KEYS[which])

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        d.update({"model": "sim inductive probe (twin), parallel to the axis", "axis": "+z", "target": self.target})
        if self.target == "disk_face":
            d.update({"radius_mm": self.radius_m * 1e3, "azimuth_deg": math.degrees(self.azimuth_rad)})
        return d

    def sim_displacement_m(self, pose=None) -> float:
        """Exact displacement of the target along +z at the probe's line (m), no instrument error."""
        pose = self.state.pose if pose is None else pose
        if self.target == "sphere_pole":
            c = pose.sphere_top.pos
            r2 = self.R * self.R - float(c[0]) ** 2 - float(c[1]) ** 2
            if r2 <= 0:
                raise ValueError(f"{self.name}: the probe axis misses the sphere")
            return float(c[2]) + math.sqrt(r2) - (self.nominal_z_m + self.R)
        x = self.radius_m * math.cos(self.azimuth_rad)
        y = self.radius_m * math.sin(self.azimuth_rad)
        d = pose.disk
        n = d.R[:, 2]
        return float(d.pos[2] - (n[0] * (x - d.pos[0]) + n[1] * (y - d.pos[1])) / n[2])


def face_truth_m(pose: Any, radius_m: float, azimuth_rad: float) -> float:
    """ISO 230-7 face motion at (R, β) by its definition from the axis itself (not the disk): the
    height, at that point, of the plane perpendicular to the spin axis through the axis point of the
    disk plane moved by the axial displacement z: (z − n_x·(x − a_x) − n_y·(y − a_y))/n_z ≈
    z − R·(n_x·cos β + n_y·sin β) = axial + R × tilt component."""
    n = np.asarray(pose.extra["spin_axis_lab"], dtype=float)
    a = pose.extra["axis_disk_plane_m"]
    z = float(pose.extra["axial_m"])
    x, y = radius_m * math.cos(azimuth_rad), radius_m * math.sin(azimuth_rad)
    return (z - float(n[0]) * (x - float(a[0])) - float(n[1]) * (y - float(a[1]))) / float(n[2])


__all__ = ["SimAxialProbe", "AXIAL_PROBE_KEYS", "face_truth_m"]
