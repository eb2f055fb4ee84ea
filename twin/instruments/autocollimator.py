"""Two-axis autocollimator on the polygon (Hsieh 2022 sec. 2.1, Jia 2019 sec. 4.3).

Placement (the scenario is silent; documented choice): the autocollimator sits on the lab +X
side of the axis at azimuth ψ_AC (default 0 rad), its optical axis a = (cos ψ_AC, sin ψ_AC, 0)
pointing from the polygon to the instrument, horizontal in the lab x–y plane (the rotation plane);
its stand's thermal yaw (twin/thermal.py, [measuring_loop]) turns it about the lab z axis in time.
With the polygon in its nominal mounting (start face 1, S = 0) face 1's normal points along +X at
zero shaft angle; re-clamping for start face j and shift S is applied by ``SimBenchState``
(``polygon_pose``), see ``stage``.

Exact reading: the posed polygon's face normals n_k (lab) come from the body-frame face angles
including the pitch deviations (``BenchPose.extra["polygon_face_normal_angle_rad"]``), the faces'
pyramidal errors (``extra["polygon_face_pyramidal_rad"]``: the normal tilted out of the plane
perpendicular to the polygon's axis, ``pose.face_normals``) and the polygon's tilt and wobble on
the shaft (its pose: the bearings' tilt motion included); the face seen is the one whose normal
is closest to a. Both axes come from the one reflected beam, so a pyramidal face's horizontal
reading carries the exact second-order cross-talk (docs/physics.md). The
beam leaves along −a and returns along r = −a + 2(a·n)n. With e_t = ẑ × a (horizontal, across the
axis) the instrument measures the return beam's angles atan2(r·e_t, r·a) and atan2(r·ẑ, r·a);
the face angles are half of them. Sign (docs/conventions.md, Hsieh eq. 3 with α = reading − true):
    x_arcsec = −½·atan2(r·e_t, r·a),   y_arcsec = +½·atan2(r·ẑ, r·a)
i.e. X is positive when the face normal is turned CLOCKWISE (seen from +z) from the instrument's
axis: an encoder that reads too much (α > 0) leaves the polygon short of its nominal angle, and
the autocollimator shows +α. Y is positive when the normal tilts towards +z.

The reading is where the returned beam lands on the detector, inverted by the firmware
(``ac_optics.py``): exact for the ideal instrument of a declared scenario; a hidden ``ac_scale``
gives the true optics (focal-length error, detector tilt, distortion).

Imperfections, in this order: accuracy (a deterministic seeded error curve inside ±``accuracy``
over ±``range``: a scale error plus one smooth bow), zero drift ``drift_rate``·t_s, noise (rms,
independent per axis), resolution quantisation; beyond ±``range`` on either axis the status is
"out_of_range" (values NaN).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchtwin.hw.interfaces import AutocollimatorReading
from benchtwin.twin.pose import face_normals
from benchtwin.units import quantise

from .ac_optics import AutocollimatorOptics
from .stage import ARCSEC, TWO_PI, SimBenchState, sim_rng


@dataclass(frozen=True)
class AutocollimatorSpec:
    """An autocollimator's data sheet: resolution, accuracy (maximum error), range ±range, noise
    (rms) in rad, drift rate (rad/s), and its azimuth in the lab (rad; None: the bench state's)."""

    resolution_rad: float = 0.0
    accuracy_rad: float = 0.0
    range_rad: float = 1000 * ARCSEC
    noise_rad: float = 0.0
    drift_rate_rad_s: float = 0.0
    azimuth_rad: float | None = None


class SimAutocollimator:
    """``Autocollimator`` of the twin; ``seed`` and ``key``: its accuracy curve's and noise's
    random streams."""

    kind = "autocollimator"

    def __init__(self, name: str, state: SimBenchState, spec: AutocollimatorSpec = AutocollimatorSpec(),
                 seed: int = 0, key: int = 0):
        self.name = name
        self.state = state
        self.spec = spec
        azimuth_rad = spec.azimuth_rad
        self.azimuth_rad = float(state.ac_azimuth_rad if azimuth_rad is None else azimuth_rad)
        if azimuth_rad is not None and abs(azimuth_rad - state.ac_azimuth_rad) > 0:
            state.ac_azimuth_rad = self.azimuth_rad  # the polygon mounting follows the instrument
            state.set_polygon_mounting(state.polygon_start_face, state.polygon_shift_rad)
        self.resolution_rad = float(spec.resolution_rad)
        self.accuracy_rad = float(spec.accuracy_rad)
        self.range_rad = float(spec.range_rad)
        self.noise_rad = float(spec.noise_rad)
        self.drift_rate_rad_s = float(spec.drift_rate_rad_s)
        self.key = int(key)
        r = sim_rng(seed, "ac_accuracy", key)
        c1 = r.uniform(-0.6, 0.6, 2)
        c2 = (1.0 - np.abs(c1)) * r.uniform(0.5, 1.0, 2) * np.sign(r.uniform(-1, 1, 2))
        self._acc = {"scale": c1, "bow": c2, "phase": r.uniform(0, TWO_PI, 2)}
        self.hidden = None   # [hidden] ac_drift (twin/hidden.py)
        # The true optics (ac_optics.py; [hidden] ac_scale): None = ideal, the reading is the face
        # angle itself (no tan/atan round trip, so an ideal instrument's datasets are unchanged).
        self.optics: AutocollimatorOptics | None = None

    @classmethod
    def sim_from_scenario(cls, sc: Any, state: SimBenchState, name: str = "autocollimator",
                          hidden: Any = None) -> "SimAutocollimator":
        """``hidden``: the bench's ``Hidden`` (built once per bench, ``Bench.hidden``); None: built
        from the scenario."""
        from benchtwin.twin.hidden import hidden_for

        a = sc["instruments"]["autocollimator"]
        spec = AutocollimatorSpec(resolution_rad=a["resolution"], accuracy_rad=a["accuracy"], range_rad=a["range"],
                                  noise_rad=a["noise"], drift_rate_rad_s=a["drift_rate"])
        obj = cls(name, state, spec, seed=state.seed)
        hidden = hidden_for(sc, hidden)
        obj.hidden = hidden if ("ac_scale" in hidden.effects or "ac_drift" in hidden.effects) else None
        obj.optics = hidden.ac_optics()
        return obj

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "kind": "autocollimator", "model": "sim autocollimator (twin)",
                "units": {"x_arcsec": "arcsec", "y_arcsec": "arcsec", "t_s": "s"},
                "azimuth_deg": math.degrees(self.azimuth_rad), "range_arcsec": self.range_rad / ARCSEC,
                "resolution_arcsec": self.resolution_rad / ARCSEC, "accuracy_arcsec": self.accuracy_rad / ARCSEC}

    # ------------------------------------------------------------------ physics
    def sim_face_normals_lab(self, pose=None) -> np.ndarray:
        pose = self.state.pose if pose is None else pose
        g = pose.extra.get("polygon_face_normal_angle_rad") if pose.extra else None
        if g is None:
            g = TWO_PI * np.arange(self.state.n_faces) / self.state.n_faces
        p = pose.extra.get("polygon_face_pyramidal_rad") if pose.extra else None
        nb = face_normals(g, p)    # pyramidal error: the normal out of the plane ⊥ the polygon's axis
        return nb @ self.state.polygon_pose(pose).R.T

    def sim_exact_angles(self, pose=None) -> tuple[float, float, int]:
        """(x, y) face angles in rad from the exact reflection, and the physics face index seen
        (1…N); no instrument error. The optical axis is where the stand holds it at the pose's time
        (its thermal yaw, twin/thermal.py [measuring_loop]; the polygon's mounting keeps the nominal
        azimuth it was set up to)."""
        pose = self.state.pose if pose is None else pose
        psi = self.azimuth_rad
        th = getattr(self.state.bench, "thermal", None)
        acs_m_K = getattr(th, "acs_m_K", 0.0) if th is not None else 0.0
        if th is not None and acs_m_K:
            psi = psi + th.autocollimator_stand_yaw_rad(pose.t_s)
        a = np.array([math.cos(psi), math.sin(psi), 0.0])
        n = self.sim_face_normals_lab(pose)
        k = int(np.argmax(n @ a))
        nk = n[k]
        r = -a + 2.0 * float(a @ nk) * nk
        et = np.array([-a[1], a[0], 0.0])
        ra = float(r @ a)
        return -0.5 * math.atan2(float(r @ et), ra), 0.5 * math.atan2(float(r[2]), ra), k + 1

    def sim_accuracy_error(self, v: float, axis: int) -> float:
        c = self._acc
        x = v / self.range_rad
        return self.accuracy_rad * (c["scale"][axis] * x + c["bow"][axis] * math.sin(math.pi * x + c["phase"][axis]))

    # ------------------------------------------------------------------ signal chain
    def read(self) -> AutocollimatorReading:
        st = self.state
        t = float(st.clock.now())
        x, y, _ = self.sim_exact_angles(st.pose)
        if abs(x) > self.range_rad or abs(y) > self.range_rad:
            return {"x_arcsec": float("nan"), "y_arcsec": float("nan"), "t_s": t, "status": "out_of_range"}
        vals = []
        th = getattr(st.bench, "thermal", None)
        drift_T = th.ac_drift_rad(t) if th is not None and th.ac_rad_K else 0.0   # twin/thermal.py
        if self.optics is not None:       # where the beam lands on the detector, read by the firmware
            x, y = self.optics.reading_rad(x, y)
        for axis, v in enumerate((x, y)):
            if self.hidden is not None:   # undeclared zero drift of the instrument
                v = v + self.hidden.ac_zero_drift_rad(t)
            v = v + self.sim_accuracy_error(v, axis) + self.drift_rate_rad_s * t
            if drift_T:
                v = v + drift_T
            vals.append(v)
        if self.noise_rad > 0:
            nz = st.rng("ac_noise", self.key).normal(0.0, self.noise_rad, 2)
            vals = [vals[0] + nz[0], vals[1] + nz[1]]
        res = self.resolution_rad / ARCSEC
        return {"x_arcsec": quantise(vals[0] / ARCSEC, res), "y_arcsec": quantise(vals[1] / ARCSEC, res),
                "t_s": t, "status": "ok"}
