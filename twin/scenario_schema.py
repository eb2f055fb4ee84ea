"""The scenario schema: every key a scenario file may hold, its dimension, default and range.

Kept apart from the loader (``scenario.py``) so that adding a parameter is a one-line change
here. Physics parameters (``[bench]``, ``[bearings]``, ``[errors]``: they edit the MuJoCo model)
are kept apart from measurement parameters (``[instruments.*]``: they act on the signals), as
MuJoCo's sysid module separates model and sensor parameters.

A field's ``dim`` is a dimension of ``benchtwin.units`` ("length", "angle", …), or one of the
plain kinds "int", "bool", "str", or a list kind "list[<dim>]" / "lobes" (a list of
``{order, amplitude, phase}`` tables).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from benchtwin.units import ARCSEC, DEG, MM, UM

_REQUIRED = object()


@dataclass(frozen=True)
class Field:
    dim: str
    default: Any = _REQUIRED
    lo: float | None = None  # inclusive bounds, in SI
    hi: float | None = None
    choices: tuple[str, ...] | None = None
    doc: str = ""
    # an absent key is left out of the validated scenario (readers take the default): a key added
    # later keeps the truth/scenario.json of the scenarios that do not state it byte-identical
    omit_default: bool = False

    @property
    def required(self) -> bool:
        return self.default is _REQUIRED



SCHEMA: dict[str, dict[str, Field]] = {
    "scenario": {
        "name": Field("str"),
        "description": Field("str", ""),
        "seed": Field("int", lo=0, hi=2**63 - 1),
    },
    "bench": {
        "optical_radius": Field("length", lo=1 * MM, hi=1.0, doc="r of Jia eq. 5"),
        "scale_edge_radius": Field("length", lo=1 * MM, hi=1.0),
        "grating_period": Field("length", 20 * UM, lo=0.1 * UM, hi=1 * MM),
        "grating_line_length": Field("length", 1.2 * MM, lo=10 * UM, hi=50 * MM),
        "grating_duty": Field("dimensionless", 0.5, lo=0.05, hi=0.95),
        "encoder_lines": Field("int", 0, lo=0, hi=10_000_000, doc="0: derive from period and radius"),
        "encoder_resolution": Field("angle", lo=0.0, hi=1 * DEG),
        "heads": Field("list[angle]", [0.0], lo=0.0, hi=360 * DEG, doc="head azimuths from head 1, CCW"),
        "L1": Field("length", lo=0.0, hi=2.0, doc="top sphere -> disk"),
        "L2": Field("length", lo=1 * MM, hi=2.0, doc="top sphere -> bottom sphere"),
        "bearing_top_z": Field("length", lo=-2.0, hi=2.0, doc="from the disk plane"),
        "bearing_bottom_z": Field("length", lo=-2.0, hi=2.0),
        "shaft_mass": Field("mass", 1.0, lo=1e-3, hi=1e4),
        "polygon_faces": Field("int", lo=3, hi=360),
        "polygon_z": Field("length", lo=-2.0, hi=2.0),
        "ccd_position": Field("angle", 180 * DEG, lo=0.0, hi=360 * DEG),
        "gravity_direction": Field("str", "-z", choices=("-x", "+x", "-y", "+y", "-z", "+z", "none")),
        "speed": Field("angular_speed", 0.0, lo=0.0, hi=1000.0,
                       doc="shaft speed while reading; 0 = the bench stops at each reading"),
    },
    "bearings": {
        "radial_stiffness": Field("stiffness", lo=1e3, hi=1e12),
        "radial_damping": Field("damping", 1e3, lo=0.0, hi=1e9),
        "tilt_stiffness": Field("torsional_stiffness", 0.0, lo=0.0, hi=1e9),
        "friction_torque": Field("torque", 0.0, lo=0.0, hi=100.0),
        "waviness_top": Field("lobes", []),
        "waviness_bottom": Field("lobes", []),
        "unbalance": Field("unbalance", 0.0, lo=0.0, hi=1.0),
        "async_rms": Field("length", 0.0, lo=0.0, hi=1 * MM),
        "drive_torsional_stiffness": Field("torsional_stiffness", 1e4, lo=1.0, hi=1e12),
        "shaft_torsional_stiffness": Field("torsional_stiffness", 1e5, lo=1.0, hi=1e12),
        "cage_ratio": Field("dimensionless", 0.4, lo=0.3, hi=0.5, doc="cage speed / shaft speed"),
        "async_cage_fraction": Field("dimensionless", 0.5, lo=0.0, hi=1.0,
                                     doc="share of async_rms² from cage lobing; the rest is random"),
        "unbalance_phase": Field("angle", None, lo=-360 * DEG, hi=360 * DEG, doc="absent: drawn from the seed"),
        # The bearing model (docs/physics.md). "ball": rolling-element sets (twin/bearing.py); "air":
        # aerostatic journals (twin/air_bearing.py); "path": the REPLAY of a given rolling path or
        # [motion_table] (radial_stiffness, waviness_*, async_rms), not a bearing model: never the
        # default, and it should say where its motion was measured (path_provenance).
        "type": Field("str", "ball", choices=("ball", "air", "path"),
                      doc="ball: angular-contact ball sets with Hertzian contact; air: aerostatic journals "
                          "(film stiffness from supply pressure, gap and restrictors); path: the replay of a "
                          "given rolling path / measured motion table"),
        "path_provenance": Field("str", "", doc="path type: where the replayed motion was measured (instrument, "
                                               "spindle, date, report); empty: a synthetic path"),
        "balls": Field("int", 12, lo=3, hi=200, doc="Z per bearing (ball type)"),
        "ball_diameter": Field("length", 6.35 * MM, lo=0.1 * MM, hi=0.2, doc="Dw"),
        "pitch_diameter": Field("length", 31 * MM, lo=1 * MM, hi=2.0, doc="Dpw"),
        "contact_angle": Field("angle", 15 * DEG, lo=1 * DEG, hi=60 * DEG, doc="under preload"),
        "preload": Field("force", 50.0, lo=0.1, hi=1e5, doc="axial preload of the pair"),
        "groove_inner": Field("dimensionless", 0.52, lo=0.501, hi=0.6, doc="inner groove radius / Dw"),
        "groove_outer": Field("dimensionless", 0.53, lo=0.501, hi=0.6, doc="outer groove radius / Dw"),
        "grade": Field("str", "P4", choices=("P0", "P6", "P5", "P4", "P2"),
                       doc="ISO 492 class: ring run-out and race waviness level"),
        "ball_grade": Field("str", "G5", choices=("G3", "G5", "G10", "G16", "G20", "G28"),
                            doc="ISO 3290-1: ball diameter variation"),
        "waviness_scale": Field("dimensionless", 1.0, lo=0.0, hi=100.0, doc="scales the grade's race waviness"),
        "cage_slip": Field("dimensionless", 0.0, lo=0.0, hi=0.5,
                           doc="std of the cage's relative slip (ball type): per start/stop, or of the "
                               "slip process when cage_slip_time > 0"),
        "cage_slip_time": Field("time", 0.0, lo=0.0, hi=1e7,
                                doc="0: an independent slip per start/stop; > 0: the slip is a stationary "
                                    "random process in bench time with this correlation time (ball type)",
                                omit_default=True),
        "cage_slip_mean": Field("dimensionless", 0.0, lo=0.0, hi=0.5,
                                doc="mean slip: the cage runs this fraction below its kinematic speed (ball type)",
                                omit_default=True),
        # Aerostatic journals (type = "air"; twin/air_bearing.py, docs/physics.md "Air bearings").
        "air_journal_diameter": Field("length", 50 * MM, lo=2 * MM, hi=1.0, doc="journal diameter D"),
        "air_journal_length": Field("length", 50 * MM, lo=2 * MM, hi=1.0, doc="journal length L"),
        "air_clearance": Field("length", 8 * UM, lo=1 * UM, hi=100 * UM, doc="radial gap h0 of the centred journal"),
        "air_supply_pressure": Field("pressure", 5e5, lo=1e4, hi=2e6, doc="supply pressure above ambient (gauge)"),
        "air_feed_holes": Field("int", 8, lo=3, hi=64, doc="feed holes per row"),
        "air_feed_rows": Field("int", 2, lo=1, hi=2, doc="1: a central row; 2: rows at L/4 from the ends"),
        "air_restrictor": Field("str", "orifice", choices=("orifice", "porous"), doc="inherent orifice or porous insert"),
        "air_orifice_diameter": Field("length", 0.15 * MM, lo=0.01 * MM, hi=2 * MM),
        "air_discharge_coefficient": Field("dimensionless", 0.8, lo=0.3, hi=1.0, doc="orifice C_d (Powell: 0.6–0.85)"),
        "air_porous_permeability": Field("area", 1e-15, lo=1e-18, hi=1e-10),
        "air_porous_thickness": Field("length", 5 * MM, lo=0.1 * MM, hi=0.1),
        "air_porous_area": Field("area", 2e-5, lo=1e-8, hi=1e-2, doc="face of one porous insert"),
        "journal_roundness": Field("length", 0.0, lo=0.0, hi=10 * UM,
                                   doc="peak-to-valley roundness of each journal (orders 2…40)"),
        "journal_runout": Field("length", 0.0, lo=0.0, hi=10 * UM,
                                doc="each journal's centring on the shaft (order 1)"),
        "supply_ripple": Field("dimensionless", 0.0, lo=0.0, hi=0.1,
                               doc="slow ripple of the supply pressure, relative amplitude"),
        "supply_ripple_period": Field("time", 300.0, lo=1.0, hi=1e6),
        "supply_noise": Field("dimensionless", 0.0, lo=0.0, hi=0.1,
                              doc="random supply-pressure fluctuation, relative rms (periods 5 s…10 min)"),
        "thrust_inner_radius": Field("length", 0.0, lo=0.0, hi=1.0, doc="0: no thrust bearing stated"),
        "thrust_outer_radius": Field("length", 0.0, lo=0.0, hi=1.0),
        "thrust_feed_radius": Field("length", 0.0, lo=0.0, hi=1.0),
        "thrust_clearance": Field("length", 10 * UM, lo=1 * UM, hi=100 * UM),
    },
    "errors": {
        "eccentricity": Field("length", lo=0.0, hi=5 * MM),
        "theta0": Field("angle", lo=-360 * DEG, hi=360 * DEG),
        "disk_tilt": Field("angle", 0.0, lo=0.0, hi=1 * DEG),
        "sphere_top_centring": Field("length", 0.0, lo=0.0, hi=1 * MM),
        "sphere_top_phase": Field("angle", 0.0, lo=-360 * DEG, hi=360 * DEG),
        "sphere_bottom_centring": Field("length", 0.0, lo=0.0, hi=1 * MM),
        "sphere_bottom_phase": Field("angle", 0.0, lo=-360 * DEG, hi=360 * DEG),
        "sphere_form": Field("length", 0.0, lo=0.0, hi=10 * UM),
        "polygon_pitch_rms": Field("angle", 0.0, lo=0.0, hi=60 * ARCSEC),
        "polygon_eccentricity": Field("length", 0.0, lo=0.0, hi=5 * MM),
        "graduation_error_rms": Field("angle", 0.0, lo=0.0, hi=60 * ARCSEC),
        "disk_tilt_phase": Field("angle", 0.0, lo=-360 * DEG, hi=360 * DEG),
        "polygon_eccentricity_phase": Field("angle", None, lo=-360 * DEG, hi=360 * DEG,
                                            doc="absent: drawn from the seed"),
        "polygon_tilt": Field("angle", 0.0, lo=0.0, hi=1 * DEG),
        "polygon_tilt_phase": Field("angle", 0.0, lo=-360 * DEG, hi=360 * DEG),
    },
    # The bench's thermal state (twin/thermal.py; docs/physics.md). The defaults make the bench
    # thermally inert (no variation, no coefficient): a scenario states its environment.
    "thermal": {
        "ambient": Field("temperature", 20.0, lo=-50.0, hi=100.0, doc="lab mean, °C"),
        "ambient_amplitude": Field("temperature_difference", 0.0, lo=0.0, hi=20.0, doc="slow lab variation ±A"),
        "ambient_period": Field("time", 86400.0, lo=60.0, hi=1e7),
        "ambient_phase": Field("angle", None, lo=-360 * DEG, hi=360 * DEG, doc="absent: drawn from the seed"),
        "motor_rise": Field("temperature_difference", 0.0, lo=0.0, hi=100.0, doc="steady rise of the drive motor"),
        "motor_time_constant": Field("time", 1200.0, lo=1.0, hi=1e7),
        "structure_time_constant": Field("time", 7200.0, lo=1.0, hi=1e7, doc="shaft and housings"),
        "structure_motor_share": Field("dimensionless", 0.3, lo=0.0, hi=1.0, doc="share of the motor rise reaching them"),
        "probe_stand_time_constant": Field("time", 1800.0, lo=1.0, hi=1e7),
        "autocollimator_time_constant": Field("time", 3600.0, lo=1.0, hi=1e7),
        "axis_drift": Field("length_per_kelvin", 0.0, lo=-1e-4, hi=1e-4, doc="bearing seats' translation per K of the structure"),
        "axis_drift_azimuth": Field("angle", None, lo=-360 * DEG, hi=360 * DEG, doc="absent: drawn from the seed"),
        "probe_stand_growth": Field("length_per_kelvin", 0.0, lo=-1e-4, hi=1e-4, doc="along the probe axis, per K"),
        "ac_drift": Field("angle_per_kelvin", 0.0, lo=-1e-4, hi=1e-4, doc="autocollimator zero per K"),
        "hvac_amplitude": Field("temperature_difference", 0.0, lo=0.0, hi=5.0,
                                doc="the room control's cycling of the air, ±A (0: none)"),
        "hvac_period": Field("time", 1200.0, lo=10.0, hi=1e6, doc="period of that cycling"),
        "hvac_phase": Field("angle", None, lo=-360 * DEG, hi=360 * DEG, doc="absent: drawn from the seed"),
        "microscope_stand_growth": Field("length_per_kelvin", 0.0, lo=-1e-4, hi=1e-4,
                                         doc="CCD microscope stand, along the camera's radial line, per K"),
        "microscope_stand_time_constant": Field("time", 600.0, lo=1.0, hi=1e7),
        "disk_cte": Field("per_kelvin", 8e-6, lo=0.0, hi=1e-4, doc="uniform: no angle change (truth only)"),
        "polygon_cte": Field("per_kelvin", 8e-6, lo=0.0, hi=1e-4, doc="uniform: no angle change (truth only)"),
    },
    # The drive servo (twin/instruments/drive.py): a PID on the encoder's count, the drive train
    # integrated by MuJoCo (models/drive.xml). Coupling and shaft stiffness, sliding friction:
    # [bearings]. Defaults: ASSUMPTIONS (a small brushless torque motor and a ball-bearing spindle;
    # sources in drive.py).
    "drive": {
        "motor_inertia": Field("inertia", 1.8e-5, lo=1e-9, hi=10.0, doc="rotor + coupling hub"),
        "static_friction_ratio": Field("dimensionless", 1.2, lo=1.0, hi=3.0,
                                       doc="breakaway / sliding friction torque (Stribeck)"),
        "stribeck_speed": Field("angular_speed", 1e-3, lo=1e-6, hi=10.0),
        "presliding_angle": Field("angle", 5e-5, lo=1e-8, hi=0.01,
                                  doc="elastic (pre-sliding) rotation of the bearing at breakaway"),
        "bandwidth": Field("frequency", 200.0, lo=1.0, hi=2000.0, doc="position-loop bandwidth"),
        "servo_rate": Field("frequency", 5000.0, lo=100.0, hi=20000.0, doc="sample rate of the loop"),
        "torque_limit": Field("torque", 0.5, lo=1e-3, hi=100.0),
        "torque_noise": Field("torque", 2e-5, lo=0.0, hi=1.0, doc="amplifier current noise, rms per sample"),
        "settle_window": Field("time", 3e-3, lo=1e-4, hi=1.0, doc="count held and shaft still this long = at rest"),
        "settle_time": Field("time", 0.1, lo=1e-3, hi=10.0,
                             doc="the stage reports the move done this long after the profile"),
    },
    "instruments.probe": {
        "repeatability": Field("length", 0.1 * UM, lo=0.0, hi=100 * UM),
        "linearity_a": Field("length", 0.2 * UM, lo=0.0, hi=100 * UM),
        "linearity_b": Field("length", 50 * UM, lo=0.0, hi=1 * MM, doc="µm per mm² of deflection"),
        "range": Field("length", 0.3 * MM, lo=1 * UM, hi=10 * MM),
        "resolution": Field("length", 0.01 * UM, lo=0.0, hi=10 * UM),
        "x_probes": Field("bool", False),
    },
    "instruments.encoder": {
        "noise": Field("angle", 0.0, lo=0.0, hi=60 * ARCSEC),
        "interpolation_error": Field("angle", 0.0, lo=0.0, hi=60 * ARCSEC),
    },
    "instruments.autocollimator": {
        "resolution": Field("angle", 0.005 * ARCSEC, lo=0.0, hi=10 * ARCSEC),
        "accuracy": Field("angle", 0.25 * ARCSEC, lo=0.0, hi=60 * ARCSEC),
        "range": Field("angle", 1000 * ARCSEC, lo=1 * ARCSEC, hi=10 * DEG),
        "noise": Field("angle", 0.0, lo=0.0, hi=10 * ARCSEC),
        "drift_rate": Field("angular_speed", 0.0, lo=-1e-3, hi=1e-3),
    },
    "instruments.ccd": {
        "width": Field("pixels", 2048, lo=16, hi=20000),
        "height": Field("pixels", 1536, lo=16, hi=20000),
        "pixel_pitch": Field("pixel_pitch", 0.667 * UM, lo=0.01 * UM, hi=100 * UM),
        "bit_depth": Field("int", 8, choices=("8", "12", "16")),
        "numerical_aperture": Field("dimensionless", 0.1, lo=0.001, hi=1.5),
        "defocus": Field("length", 0.0, lo=-1 * MM, hi=1 * MM),
        "vignetting": Field("dimensionless", 0.0, lo=0.0, hi=0.9),
        "full_well": Field("electrons", 20000, lo=10, hi=1e7),
        "read_noise": Field("electrons", 0.0, lo=0.0, hi=1e4),
        "exposure": Field("dimensionless", 0.7, lo=0.01, hi=10.0),
        "dust_count": Field("int", 0, lo=0, hi=1000),
        "scratch_count": Field("int", 0, lo=0, hi=100),
        "rotation": Field("angle", 0.0, lo=-10 * DEG, hi=10 * DEG),
        "pixel_scale_error": Field("dimensionless", 0.0, lo=-0.1, hi=0.1),
    },
    "procedure": {
        "radial_reps": Field("int", 3, lo=1, hi=25, doc="range method: d_n tabulated for n ≤ 25"),
        "radial_positions": Field("int", 360, lo=8, hi=100_000),
        "ccd_step": Field("angle", 6 * DEG, lo=0.5 * DEG, hi=180 * DEG,
                          doc="≥ 0.5°: at most 720 frames (a dataset's limit)"),
        "ccd_reps": Field("int", 1, lo=1, hi=25,
                          doc="repeated CCD sweeps (Jia sec. 5: u(e) from their scatter); frames ≤ 720 in all"),
        "polygon_shifts": Field("list[angle]", [0.0], lo=0.0, hi=360 * DEG, doc="distinct shift angles S"),
        "traditional_start_face": Field("int", 1, lo=1, hi=360),
        "selfcal": Field("bool", False),
        "selfcal_step": Field("angle", 1 * DEG, lo=0.001 * DEG, hi=90 * DEG),
        "directions": Field("list[str]", ["forward"], choices=("forward", "backward")),
        "dwell": Field("time", 0.5, lo=0.0, hi=3600.0),
        "polygon_reps": Field("int", 1, lo=1, hi=100),
        # ISO 230-7 continuous-rotation radial error motion run (twin/continuous.py): 0 = off
        "continuous_revolutions": Field("int", 0, lo=0, hi=10_000, doc="0: no continuous run; ISO 230-7: >= 20"),
        "continuous_speed": Field("angular_speed", 60 * DEG, lo=1e-3, hi=1000.0, doc="shaft speed of the run"),
        "continuous_samples_per_rev": Field("int", 256, lo=8, hi=100_000),
    },
}

# Optional sections: validated only when present (absent: no such data at all).
OPTIONAL_SCHEMA: dict[str, dict[str, Field]] = {
    # The CCD microscope's vibration relative to the disk (twin/vibration.py; docs/physics.md,
    # "Non-repeatability of the jia2019 bench"): the table's floor-borne vibration at a generic
    # criterion (Gordon 1991; Amick et al. 2005) through the microscope stand's mode, averaged over
    # the exposure. Optional, so a scenario that does not state it keeps its dataset's bytes.
    "vibration": {
        "floor_velocity": Field("speed", 0.0, lo=0.0, hi=0.01,
                                doc="one-third-octave band RMS velocity of the table, each axis (VC-A: 50 um/s); 0: still"),
        "floor_corner_frequency": Field("frequency", 8.0, lo=0.1, hi=1000.0,
                                        doc="below it the criterion is constant acceleration"),
        "floor_low_frequency": Field("frequency", 4.0, lo=0.1, hi=1000.0, doc="lower end of the criterion's band"),
        "floor_high_frequency": Field("frequency", 80.0, lo=0.1, hi=10000.0, doc="upper end of the criterion's band"),
        "microscope_stand_frequency": Field("frequency", 100.0, lo=1.0, hi=10000.0,
                                            doc="the stand's in-plane sway mode (both image axes)"),
        "microscope_stand_damping": Field("dimensionless", 0.03, lo=1e-4, hi=0.99, doc="its damping ratio ζ"),
        "exposure_time": Field("time", 0.0, lo=0.0, hi=10.0,
                               doc="the CCD's exposure: the frame shows the motion's mean over it"),
    },
    # The measuring loop's thermal nodes (twin/thermal.py; docs/physics.md, "The measuring loop's
    # thermal drift"): first-order lags of the room air of [thermal] (its daily cycle and the room
    # control's cycling), each with its own time constant, whose growth moves an instrument in the
    # exact geometry. Optional (and zero growth by default), so a scenario that does not state it
    # keeps its dataset's bytes.
    "measuring_loop": {
        "head_mount_growth": Field("length_per_kelvin", 0.0, lo=-1e-4, hi=1e-4,
                                   doc="read-head mount: the head's displacement along the disk's tangent "
                                       "(counter-clockwise), per K of the mount (CTE × arm: 23 ppm/K × 20 mm = 0.46 um/K)"),
        "head_mount_radial_growth": Field("length_per_kelvin", 0.0, lo=-1e-4, hi=1e-4,
                                          doc="the same mount's growth radially outward, per K"),
        "head_mount_time_constant": Field("time", 1000.0, lo=1.0, hi=1e7,
                                          doc="lumped lag of the mount behind the room air"),
        "autocollimator_stand_growth": Field("length_per_kelvin", 0.0, lo=-1e-4, hi=1e-4,
                                             doc="differential growth, across the optical axis, of the "
                                                 "stand's two supports of the autocollimator, per K"),
        "autocollimator_stand_base": Field("length", 0.1, lo=1 * MM, hi=2.0,
                                           doc="spacing of those supports along the optical axis"),
        "autocollimator_stand_time_constant": Field("time", 3600.0, lo=1.0, hi=1e7,
                                                    doc="lumped lag of the stand behind the room air"),
    },
    # The polygon's faces out of the plane (twin/physics.py, twin/instruments/autocollimator.py;
    # docs/physics.md, "The polygon's pyramidal error and the autocollimator's second axis"): each
    # face normal tilted by p out of the plane perpendicular to the polygon's axis. Optional (and
    # no tilt by default), so a scenario that does not state it keeps its dataset's bytes.
    "polygon": {
        "pyramidal_error": Field("list[angle]", None, lo=-60 * ARCSEC, hi=60 * ARCSEC,
                                 doc="per face, faces 1…N in the dataset's numbering (polygon.csv's start_face, "
                                     "truth polygon_beta's face): the normal's tilt out of the plane perpendicular "
                                     "to the polygon's axis, + towards the axis's top (+z); one value: every face"),
        "pyramidal_rms": Field("angle", 0.0, lo=0.0, hi=60 * ARCSEC,
                               doc="a seeded per-face draw N(0, rms) added to pyramidal_error (stream polygon_pyramidal)"),
    },
    # The shaft's axial degree of freedom (twin/axial.py; docs/physics.md, "The shaft's axial degree
    # of freedom"): z(θ, t) from the ball pair's Hertz contacts or the air thrust bearing, added to
    # the posed shaft, and the ISO 230-7 axial / face probes that read it. Optional: a scenario that
    # does not state it keeps its dataset's bytes (no axial DOF, no axial probes).
    "axial": {
        "load": Field("force", 0.0, lo=-1e4, hi=1e4,
                      doc="external axial load on the shaft along +z (the weight along z is added from the masses)"),
        "race_face_waviness_scale": Field("dimensionless", 1.0, lo=0.0, hi=100.0,
                                          doc="ball bearings: the raceways' axial lobes relative to the grade's "
                                              "(ASSUMPTION: the radial waviness spectrum; order 1 from ISO 492 S_ia)"),
        "runner_flatness": Field("length", 0.2 * UM, lo=0.0, hi=10 * UM,
                                 doc="air bearings: each thrust-runner face's peak-to-valley form (ASSUMPTION)"),
        "thermal_growth": Field("length_per_kelvin", 0.0, lo=-1e-4, hi=1e-4,
                                doc="target's axial growth per K of the structure node, relative to the axial "
                                    "probe (CTE × effective length: 11.5 ppm/K × 20 mm = 0.23 um/K)"),
        "sphere_probe": Field("bool", True, doc="an axial probe on the top sphere's pole (ISO 230-7 axial "
                                                "error motion), column probe_axial_um"),
        "face_probe_radius": Field("length", 0.0, lo=0.0, hi=1.0,
                                   doc="a probe parallel to the axis on the disk's face at this radius "
                                       "(ISO 230-7 face error motion), column probe_face_um; 0: none"),
        "face_probe_azimuth": Field("angle", 0.0, lo=-360 * DEG, hi=360 * DEG,
                                    doc="lab azimuth of the face probe from +x, CCW"),
    },
    # A measured axis motion in the disk plane, replacing the bearings' race waviness (for replaying
    # a real spindle). Equal-length lists; missing motion columns count as 0.
    "motion_table": {
        "theta": Field("list[angle]", lo=-360 * DEG, hi=360 * DEG, doc="strictly increasing, within one turn"),
        "dx": Field("list[length]", None, lo=-1 * MM, hi=1 * MM),
        "dy": Field("list[length]", None, lo=-1 * MM, hi=1 * MM),
        "tilt_x": Field("list[angle]", None, lo=-1 * DEG, hi=1 * DEG),
        "tilt_y": Field("list[angle]", None, lo=-1 * DEG, hi=1 * DEG),
    },
}

# Sections that must be present in every scenario file (others take their defaults).
REQUIRED_SECTIONS = ("scenario", "bench", "bearings", "errors")

# [hidden]: effects the twin simulates without declaring them to the analysis. Each entry maps an
# effect name to the schema of its parameters; a name not registered here is an error, so a typo
# can never silently give a "null" scenario. Effects register here as the twin learns them.
HIDDEN_EFFECTS: dict[str, dict[str, Field]] = {
    "graduation_error": {
        "orders": Field("list[dimensionless]", [], lo=1, hi=1000, doc="disk harmonics k (integers)"),
        "amplitudes": Field("list[angle]", [], lo=-600 * ARCSEC, hi=600 * ARCSEC,
                            doc="k-fold clamping: the lines move by a_k·cos(k·g − φ_k), g the line's nominal value"),
        "phases": Field("list[angle]", [], lo=-360 * DEG, hi=360 * DEG, doc="φ_k"),
        "ruling_walk_rms": Field("angle", 0.0, lo=0.0, hi=60 * ARCSEC,
                                 doc="rms of the ruling engine's closed random walk of the line positions (orders ≥ 2)"),
        "ruling_eccentricity": Field("length", 0.0, lo=0.0, hi=1 * MM,
                                     doc="lines ruled radially from a point this far from the edge's centre"),
        "ruling_eccentricity_azimuth": Field("angle", 0.0, lo=-360 * DEG, hi=360 * DEG),
        "form_rms": Field("angle", 0.0, lo=0.0, hi=60 * ARCSEC,
                          doc="mounted form / master-wheel error: broadband orders 2…K, ∝ k^−slope, seeded phases"),
        "form_slope": Field("dimensionless", 1.5, lo=0.0, hi=4.0, doc="amplitude envelope k^−slope"),
        "form_max_order": Field("int", 200, lo=2, hi=2000, doc="highest order K of the form spectrum"),
    },
    "optical_radius": {
        "relative": Field("dimensionless", 0.0, lo=-0.2, hi=0.2,
                          doc="heads at r·(1 + relative); the manifest keeps r"),
    },
    "ccd_pixel_scale": {
        "pixel_relative": Field("dimensionless", 0.0, lo=-0.1, hi=0.1,
                                doc="true pixel = nominal·(1 + x); cancels in a grating-scaled d_ref"),
        "grating_period_relative": Field("dimensionless", 0.0, lo=-0.1, hi=0.1,
                                         doc="true period at the scale edge = datasheet·(1 + x), same line count"),
    },
    "tangential_motion": {
        "race_waviness_top": Field("lobes", [], doc="undeclared waviness of the top bearing's rotating race "
                                   "(through the bearing model: a whirl, or Hertz sums for ball bearings)"),
        "race_waviness_bottom": Field("lobes", [], doc="the same for the bottom bearing"),
        "x_lobes": Field("lobes", [], doc="legacy template: a·cos(k·θ − φ) on both rolling paths' x only"),
    },
    "tilt_abbe": {
        "delta_L1": Field("length", 0.0, lo=-0.05, hi=0.05, doc="true L1 = L1 + ΔL1 (spheres higher), L2 kept"),
    },
    "ac_drift": {
        "zero_per_kelvin": Field("angle_per_kelvin", 0.0, lo=-1e-4, hi=1e-4,
                                 doc="zero shift per K of the instrument's own temperature"),
        "warmup_rise": Field("temperature_difference", 0.0, lo=0.0, hi=20.0,
                             doc="steady internal rise after switch-on (light source, electronics)"),
        "warmup_time_constant": Field("time", 1800.0, lo=1.0, hi=1e6, doc="lumped node's time constant τ"),
        "switched_on_before": Field("time", 0.0, lo=0.0, hi=1e7, doc="switch-on this long before t = 0"),
        "room_amplitude": Field("temperature_difference", 0.0, lo=0.0, hi=5.0,
                                doc="room control cycle ±A the instrument lags with τ"),
        "room_period": Field("time", 1200.0, lo=10.0, hi=1e6),
        "room_phase": Field("angle", None, lo=-360 * DEG, hi=360 * DEG, doc="absent: drawn from the seed"),
        "rate": Field("angular_speed", 0.0, lo=-1e-3, hi=1e-3, doc="legacy template: zero drift rate·t"),
    },
    # The autocollimator's optics (twin/instruments/ac_optics.py): physical keys, or the legacy
    # small-angle coefficients gain / quadratic_per_arcsec, mapped to the focal-length error and
    # detector tilt with those first- and second-order terms (not both at once).
    "ac_scale": {
        "focal_length_error": Field("dimensionless", 0.0, lo=-0.95, hi=0.5,
                                    doc="true f = f_nom·(1 + δf); the firmware inverts with f_nom"),
        "detector_tilt": Field("angle", 0.0, lo=-89.9 * DEG, hi=89.9 * DEG,
                               doc="detector turned about its y axis: even (v²) non-linearity on x"),
        "distortion_k1": Field("dimensionless", 0.0, lo=-1e4, hi=1e4,
                               doc="Seidel distortion s·(1 + k1·(s/f_nom)²): odd (v³)"),
        "focal_length": Field("length", 0.3, lo=1 * MM, hi=10.0, doc="f_nom of the objective (300 mm: TriAngle 300-57)"),
        "gain": Field("dimensionless", 0.0, lo=-0.1, hi=0.1,
                      doc="legacy: small-angle reading v·(1 + gain) + q·v²/1″, mapped to δf and tilt"),
        "quadratic_per_arcsec": Field("dimensionless", 0.0, lo=-0.01, hi=0.01, doc="legacy: q, per arcsec"),
    },
    "sphere_form": {
        "top": Field("lobes", [], doc="extra form lobes of the top sphere (body frame)"),
        "bottom": Field("lobes", [], doc="extra form lobes of the bottom sphere"),
    },
    "torsion_hysteresis": {
        "extra_friction_torque": Field("torque", 0.0, lo=0.0, hi=10.0,
                                       doc="twist ±T/k_shaft between disk and polygon"),
    },
    "polygon_pitch_ignored": {
        "rms": Field("angle", 0.0, lo=0.0, hi=60 * ARCSEC,
                     doc="true polygon = certificate + seeded zero-sum pattern; certificate in the manifest"),
    },
    "interpolation_error": {
        "offset_cos": Field("dimensionless", 0.0, lo=-0.2, hi=0.2, doc="Heydemann p: offset of u = cos φ + p"),
        "offset_sin": Field("dimensionless", 0.0, lo=-0.2, hi=0.2, doc="Heydemann q: offset of v = r·sin(φ + δ) + q"),
        "amplitude_ratio": Field("dimensionless", 1.0, lo=0.5, hi=2.0, doc="Heydemann r: amplitude of v / u"),
        "quadrature_error": Field("angle", 0.0, lo=-30 * DEG, hi=30 * DEG, doc="Heydemann δ: departure from 90°"),
        "c1": Field("angle", 0.0, lo=0.0, hi=60 * ARCSEC, doc="legacy template: c1·sin(L·g + φ1), L lines"),
        "c1_phase": Field("angle", 0.0, lo=-360 * DEG, hi=360 * DEG),
        "c2": Field("angle", 0.0, lo=0.0, hi=60 * ARCSEC, doc="c2·sin(2·L·g + φ2)"),
        "c2_phase": Field("angle", 0.0, lo=-360 * DEG, hi=360 * DEG),
    },
    "thermal_growth": {
        "order": Field("int", 7, lo=1, hi=100, doc="k clamping screws: outside the library, the lobes follow the hub's ΔT"),
        "phase": Field("angle", 0.0, lo=-360 * DEG, hi=360 * DEG),
        "cte_mismatch": Field("per_kelvin", 15e-6, lo=-1e-4, hi=1e-4,
                              doc="α_hub − α_disk (aluminium on glass: 23 − 8 ppm/K)"),
        "hub_radius": Field("length", 10 * MM, lo=1 * MM, hi=0.5, doc="radius of the clamping screws"),
        "lobe_coupling": Field("dimensionless", 0.5, lo=0.0, hi=2.0,
                               doc="tangential lobe / constrained radial mismatch at the graduation (ASSUMPTION)"),
    },
}


def schema_markdown() -> str:
    """The reference table of docs/scenario-format.md, generated from SCHEMA (a test keeps the
    committed document equal to this)."""
    from benchtwin.units import units_of

    lines = []
    optional = [(f"{k} (optional)", v) for k, v in OPTIONAL_SCHEMA.items()]
    for section, fields in list(SCHEMA.items()) + optional + [(f"hidden.{k}", v) for k, v in HIDDEN_EFFECTS.items()]:
        lines += [f"### [{section}]", "", "| key | kind | default | range | note |", "| --- | --- | --- | --- | --- |"]
        for key, f in fields.items():
            if f.dim in ("int", "bool", "str", "lobes", "dimensionless") or f.dim.startswith("list["):
                kind = f.dim
            else:
                kind = f"{f.dim} ({', '.join(units_of(f.dim)[:4])})"
            default = ("**required**" if f.required else
                       f"`{f.default:g}` (SI)" if isinstance(f.default, float) else f"`{f.default!r}`")
            rng = ""
            if f.choices:
                rng = " / ".join(f.choices)
            elif f.lo is not None or f.hi is not None:
                rng = f"{f.lo:g} … {f.hi:g} (SI)"
            lines.append(f"| `{key}` | {kind} | {default} | {rng} | {f.doc} |")
        lines.append("")
    return "\n".join(lines)
