"""Posed bodies: what the MuJoCo twin hands to the instruments.

All poses are in the lab frame of docs/conventions.md (z = rotation axis, origin on the axis
average line in the disk plane, head 1 on +Y), in metres and rotation matrices (float64).
Instruments compute readings from these poses with exact trigonometry; nothing here knows the
analysis model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class BodyPose:
    """Position of a body frame's origin and its orientation (columns = body axes in lab)."""

    pos: np.ndarray  # (3,) m
    R: np.ndarray  # (3, 3)

    def to_lab(self, p_body: np.ndarray) -> np.ndarray:
        """Body-frame point(s) (..., 3) -> lab frame."""
        return np.asarray(p_body) @ self.R.T + self.pos

    def to_body(self, p_lab: np.ndarray) -> np.ndarray:
        """Lab-frame point(s) (..., 3) -> body frame."""
        return (np.asarray(p_lab) - self.pos) @ self.R


@dataclass(frozen=True)
class BenchPose:
    """The bench at one instant.

    - ``disk``: frame at the grating's geometric centre, z along the disk normal; the graduation
      at body polar angle g is the line along body direction (cos g, sin g, 0). Graduation 0 is the
      encoder's index line.
    - ``polygon``: frame at the polygon's geometric centre; face k (1…N) has nominal outward normal
      at body polar angle 2π(k−1)/N (pitch deviations are applied by the twin's polygon model;
      ``extra["polygon_face_normal_angle_rad"]``), tilted out of the body's x–y plane by its
      pyramidal error where the scenario states one (``extra["polygon_face_pyramidal_rad"]``).
    - ``sphere_top`` / ``sphere_bottom``: frames at the sphere centres (form error in the body frame).
    - ``shaft_angle_rad``: true rotation of the shaft at the disk (what an ideal encoder would read).
    """

    t_s: float
    shaft_angle_rad: float
    disk: BodyPose
    polygon: BodyPose
    sphere_top: BodyPose
    sphere_bottom: BodyPose
    extra: dict = field(default_factory=dict)


def face_normals(azimuth_rad, pyramidal_rad=None) -> np.ndarray:
    """(N, 3) outward unit normals of a polygon's faces in its body frame: face k's normal at body
    polar angle g_k, tilted by its pyramidal error p_k out of the plane perpendicular to the axis
    (towards +z for p > 0): (cos p·cos g, cos p·sin g, sin p). ``pyramidal_rad`` None: all in the
    plane (z = 0; the same numbers as before the pyramidal error existed)."""
    g = np.asarray(azimuth_rad, dtype=float)
    if pyramidal_rad is None:
        return np.stack([np.cos(g), np.sin(g), np.zeros_like(g)], axis=1)
    p = np.asarray(pyramidal_rad, dtype=float)
    cp = np.cos(p)
    return np.stack([cp * np.cos(g), cp * np.sin(g), np.sin(p)], axis=1)
