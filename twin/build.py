"""Build the bench's MuJoCo model from a scenario: template ``models/bench.xml`` + MjSpec edits.

Why a template plus MjSpec rather than either alone: the XML shows the whole kinematic tree in one
readable, loadable file (MuJoCo Menagerie style: every element named, default classes, comments),
and MjSpec lets the scenario change numbers (positions, masses, stiffnesses, gravity, the bearing
tendons' coefficients) without string templating. Nothing here computes a reading or an error
motion: this module only places bodies and sets physical constants; ``physics.py`` poses them.

Geometry sources (see models/README.md): Jia et al. 2019, Appl. Sci. 9, 3415 (sec. 4.1 and 5:
L1, L2; fig. 2/7/12: layout); bearing positions, masses and stiffnesses are scenario ASSUMPTIONs.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import mujoco
import numpy as np

# Standard gravity (CGPM 1901, exact by definition), m/s².
G_STANDARD = 9.80665

# Dimensions of parts that the papers do not give (ASSUMPTIONs, listed in models/README.md).
SHAFT_RADIUS_M = 0.010          # Ø 20 mm steel shaft
SHAFT_TOP_MARGIN_M = 0.008      # shaft end above the top sphere centre
SHAFT_BOTTOM_MARGIN_M = 0.010   # shaft end below the polygon centre (coupling clamp)
DISK_THICKNESS_M = 0.0015       # glass grating disk
DISK_MASS_KG = 0.005
DISK_RIM_M = 0.002              # disk outer radius beyond the scale edge
SPHERE_RADIUS_M = 0.006         # Ø 12 mm precision test spheres
SPHERE_MASS_KG = 0.009          # Ø 12 mm steel ball
POLYGON_INSCRIBED_RADIUS_M = 0.020
POLYGON_HEIGHT_M = 0.015
POLYGON_MASS_KG = 0.10          # Ø 40 × 15 mm glass polygon
POLYGON_SECTION_MASS_KG = 0.02  # clamp and coupling hub on the polygon-side shaft end
UNBALANCE_RADIUS_M = 0.010      # radius of the unbalance point mass: only U = m·r matters
HOUSING_RADIUS_M = 0.022

BEARINGS = ("top", "bottom")
BEARING_TENDONS = ("bearing_top_x", "bearing_top_y", "bearing_bottom_x", "bearing_bottom_y")


def template_path() -> Path:
    """The MJCF template shipped in ``benchtwin.models``."""
    return Path(str(resources.files("benchtwin.models").joinpath("bench.xml")))


def gravity_vector(direction: str) -> np.ndarray:
    """``"-y"`` -> (0, -g, 0); ``"none"`` -> 0. Lab frame of docs/conventions.md."""
    if direction == "none":
        return np.zeros(3)
    if len(direction) != 2 or direction[0] not in "+-" or direction[1] not in "xyz":
        raise ValueError(f"gravity_direction must be one of ±x, ±y, ±z, none; got {direction!r}")
    v = np.zeros(3)
    v["xyz".index(direction[1])] = (1.0 if direction[0] == "+" else -1.0) * G_STANDARD
    return v


def tilt_quat(tilt_rad: float, azimuth_rad: float) -> np.ndarray:
    """Quaternion (w, x, y, z) of a rotation by ``tilt_rad`` about the in-plane axis at polar
    angle ``azimuth_rad + 90°``: the body normal then leans towards ``azimuth_rad``."""
    ax = np.array([-np.sin(azimuth_rad), np.cos(azimuth_rad), 0.0])
    h = 0.5 * tilt_rad
    return np.concatenate([[np.cos(h)], np.sin(h) * ax])


@dataclass(frozen=True)
class Placement:
    """Scenario-derived placements handed from ``physics`` (which owns the seeded draws)."""

    disk_offset_m: np.ndarray          # disk geometric centre in the shaft frame
    disk_tilt_rad: float
    disk_tilt_azimuth_rad: float
    sphere_top_offset_m: np.ndarray    # sphere centres in the shaft frame
    sphere_bottom_offset_m: np.ndarray
    polygon_offset_m: np.ndarray       # polygon centre in the polygon-section frame
    polygon_tilt_rad: float
    polygon_tilt_azimuth_rad: float
    unbalance_kgm: float
    unbalance_phase_rad: float
    unbalance_z_m: float


def build_model(sc, place: Placement) -> tuple[mujoco.MjModel, dict]:
    """Compile the bench for scenario ``sc``; returns the model and a dict of the geometry used."""
    b, br = sc["bench"], sc["bearings"]
    spec = mujoco.MjSpec.from_file(str(template_path()))
    spec.option.gravity = gravity_vector(b["gravity_direction"])
    z_top, z_bot = b["bearing_top_z"], b["bearing_bottom_z"]
    _set_bearings(spec, br, z_top, z_bot)
    _set_drive(spec, br)
    parts = _set_rotating_parts(spec, b, place)
    shaft = _set_shaft(spec, b, parts, z_top, z_bot)
    model = spec.compile()
    geometry = {
        "bearing_top_z_m": z_top,
        "bearing_bottom_z_m": z_bot,
        "sphere_top_z_m": parts["sphere_top_z_m"],
        "sphere_bottom_z_m": parts["sphere_bottom_z_m"],
        "polygon_z_m": parts["polygon_z_m"],
        "sphere_radius_m": SPHERE_RADIUS_M,
        "disk_radius_m": parts["disk_radius_m"],
        "disk_thickness_m": DISK_THICKNESS_M,
        "polygon_inscribed_radius_m": POLYGON_INSCRIBED_RADIUS_M,
        "polygon_height_m": POLYGON_HEIGHT_M,
        "shaft_radius_m": SHAFT_RADIUS_M,
        "shaft_cylinder_mass_kg": shaft["shaft_cylinder_mass_kg"],
        "unbalance_mass_kg": parts["unbalance_mass_kg"],
        "unbalance_radius_m": UNBALANCE_RADIUS_M,
        "rotating_mass_kg": shaft["rotating_mass_kg"],
        "gravity_m_s2": spec.option.gravity.tolist(),
    }
    return model, geometry


def _set_bearings(spec: mujoco.MjSpec, br, z_top: float, z_bot: float) -> None:
    """The bearings: four fixed tendons, rebuilt with this scenario's axial positions, their sites
    and housings, and the two bearings' moment stiffness (in parallel on the shaft tilt)."""
    for name in BEARING_TENDONS:
        spec.delete(spec.tendon(name))
    for which, z in (("top", z_top), ("bottom", z_bot)):
        for axis in ("x", "y"):
            t = spec.add_tendon(name=f"bearing_{which}_{axis}")
            t.stiffness = [br["radial_stiffness"], 0.0, 0.0]
            t.damping = [br["radial_damping"], 0.0, 0.0]
            t.springlength = [0.0, 0.0]
            if axis == "x":   # x at height z = radial_x + z·tilt_y
                t.wrap_joint("radial_x", 1.0)
                t.wrap_joint("tilt_y", z)
            else:             # y at height z = radial_y - z·tilt_x
                t.wrap_joint("radial_y", 1.0)
                t.wrap_joint("tilt_x", -z)
    for which, z in (("top", z_top), ("bottom", z_bot)):
        spec.site(f"bearing_{which}").pos = [0, 0, z]
        spec.site(f"journal_{which}").pos = [0, 0, z]
        g = spec.geom(f"bearing_{which}_housing")
        g.pos = [0, 0, z]
        g.size = [HOUSING_RADIUS_M, 0.005, 0]

    # Moment stiffness of the two bearings act in parallel on the shaft tilt.
    for j in ("tilt_x", "tilt_y"):
        spec.joint(j).stiffness = [2.0 * br["tilt_stiffness"], 0.0, 0.0]


def _set_drive(spec: mujoco.MjSpec, br) -> None:
    """Torsion and drive: the spin joint's friction, the shaft's and the drive's torsional stiffness."""
    spec.joint("spin").frictionloss = br["friction_torque"]
    spec.joint("shaft_twist").stiffness = [br["shaft_torsional_stiffness"], 0.0, 0.0]
    act = spec.actuator("drive")
    kp = br["drive_torsional_stiffness"]
    act.gainprm[0] = kp
    act.biasprm[1] = -kp


def _set_rotating_parts(spec: mujoco.MjSpec, b, place: Placement) -> dict[str, float]:
    """The rotating parts placed: disk, spheres, unbalance, polygon. Returns their heights (m), the
    disk's radius (m) and the unbalance point mass (kg)."""
    r = b["optical_radius"]
    disk = spec.body("disk")
    disk.pos = place.disk_offset_m
    disk.quat = tilt_quat(place.disk_tilt_rad, place.disk_tilt_azimuth_rad)
    gd = spec.geom("disk")
    disk_radius = b["scale_edge_radius"] + DISK_RIM_M
    gd.size = [disk_radius, 0.5 * DISK_THICKNESS_M, 0]
    gd.mass = DISK_MASS_KG
    spec.site("head_1").pos = [0, r, 0]

    L1, L2, z_poly = b["L1"], b["L2"], b["polygon_z"]
    z_sph_top, z_sph_bot = L1, L1 - L2
    spec.body("sphere_top").pos = place.sphere_top_offset_m + [0, 0, z_sph_top]
    spec.body("sphere_bottom").pos = place.sphere_bottom_offset_m + [0, 0, z_sph_bot]
    for s in ("sphere_top", "sphere_bottom"):
        spec.geom(s).size = [SPHERE_RADIUS_M, 0, 0]
        spec.geom(s).mass = SPHERE_MASS_KG

    m_unb = place.unbalance_kgm / UNBALANCE_RADIUS_M
    ub = spec.body("unbalance")
    ub.pos = [UNBALANCE_RADIUS_M * np.cos(place.unbalance_phase_rad),
              UNBALANCE_RADIUS_M * np.sin(place.unbalance_phase_rad), place.unbalance_z_m]
    # A zero unbalance gives a massless geom on a welded body, which MuJoCo accepts.
    spec.geom("unbalance").mass = m_unb

    spec.body("polygon_section").pos = [0, 0, z_poly]
    poly = spec.body("polygon")
    poly.pos = place.polygon_offset_m
    poly.quat = tilt_quat(place.polygon_tilt_rad, place.polygon_tilt_azimuth_rad)
    gp = spec.geom("polygon")
    gp.size = [POLYGON_INSCRIBED_RADIUS_M, 0.5 * POLYGON_HEIGHT_M, 0]
    gp.mass = POLYGON_MASS_KG
    return {"sphere_top_z_m": z_sph_top, "sphere_bottom_z_m": z_sph_bot, "polygon_z_m": z_poly,
            "disk_radius_m": disk_radius, "unbalance_mass_kg": m_unb}


def _set_shaft(spec: mujoco.MjSpec, b, parts: dict[str, float], z_top: float, z_bot: float) -> dict[str, float]:
    """The shaft cylinder from above the top sphere down to below the polygon; its mass is what is
    left of bench.shaft_mass (the whole rotating assembly) after the other parts. Returns its mass
    and the rotating mass (kg)."""
    z_sph_top, z_sph_bot, z_poly = parts["sphere_top_z_m"], parts["sphere_bottom_z_m"], parts["polygon_z_m"]
    z_hi = max(z_sph_top, 0.0) + SHAFT_TOP_MARGIN_M
    z_lo = min(z_poly, z_sph_bot, z_bot, z_top) - SHAFT_BOTTOM_MARGIN_M
    others = (DISK_MASS_KG + 2 * SPHERE_MASS_KG + parts["unbalance_mass_kg"] + POLYGON_MASS_KG
              + POLYGON_SECTION_MASS_KG)
    m_shaft = max(b["shaft_mass"] - others, 0.1 * b["shaft_mass"])
    gs = spec.geom("shaft")
    gs.size = [SHAFT_RADIUS_M, 0.5 * (z_hi - z_lo), 0]
    gs.pos = [0, 0, 0.5 * (z_hi + z_lo)]
    gs.mass = m_shaft
    return {"shaft_cylinder_mass_kg": m_shaft, "rotating_mass_kg": float(m_shaft + others)}
