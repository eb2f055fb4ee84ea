"""Bench poses built by hand: the disk, polygon and spheres where a test puts them."""

from __future__ import annotations

import math

import numpy as np

from benchtwin.twin.instruments.stage import sim_rz
from benchtwin.twin.pose import BenchPose, BodyPose

Z_TOP, Z_BOT = 6.81e-3, 6.81e-3 - 122.96e-3


def make_pose(phi=0.0, disk_centre=(0.0, 0.0, 0.0), disk_R=None, top=(0.0, 0.0), bottom=(0.0, 0.0),
              poly_R=None, face_angles=None, t_s=0.0):
    disk_R = sim_rz(phi) if disk_R is None else disk_R
    poly_R = sim_rz(phi) if poly_R is None else poly_R
    extra = {} if face_angles is None else {"polygon_face_normal_angle_rad": np.asarray(face_angles)}
    return BenchPose(t_s=t_s, shaft_angle_rad=phi,
                     disk=BodyPose(np.asarray(disk_centre, float), disk_R),
                     polygon=BodyPose(np.array([0.0, 0.0, -0.13]), poly_R),
                     sphere_top=BodyPose(np.array([top[0], top[1], Z_TOP]), sim_rz(phi)),
                     sphere_bottom=BodyPose(np.array([bottom[0], bottom[1], Z_BOT]), sim_rz(phi)),
                     extra=extra)


def eccentric_pose(phi, e, theta0, shift=(0.0, 0.0)):
    """Disk rotated by φ about the lab axis, its geometric centre at body angle 90° − θ0, distance e."""
    a = math.pi / 2 - theta0 + phi
    return make_pose(phi, (e * math.cos(a) + shift[0], e * math.sin(a) + shift[1], 0.0))
