"""CCD microscope looking at the grating edge through the hole opposite the head (Jia 2019 sec. 4.2).

The instrument takes the posed disk from the shared state and calls the renderer
(``benchtwin.twin.render``): the image comes from the exact posed geometry (eccentricity, radial
motion, tilt), then the sensor model (blur, vignetting, shot/read noise, dust, quantisation).
``capture()`` returns the ``Camera`` protocol shape (image, time, status) and the backend that
rendered it — never a true value: a capture's row goes to the run's journal in the dataset root,
and truth lives only in truth/ (issue 15). The frame's truth — the disk's geometric centre in
pixels (``centre_px``), the edge radius in true pixels (``edge_radius_px``), the true pixel size and
the reference point — is ``sim_frame_truth()``, computed from the posed geometry alone (no
rendering; ``simulate`` takes it for every frame, live or replayed on resume, and writes it to
truth/ccd.csv); ``last_truth`` is the last captured frame's. The sensor noise stream is keyed by the
runner's step, so a resumed run renders identical frames. With ``pipeline`` set (``simulate``'s
frame pipeline, twin/render/pipeline.py) ``capture()`` renders nothing: it draws the frame's noise
stream as the serial path does and keeps (disk pose, stream) for ``take_job()``; its reading
states the image's shape, dtype and backend, and ``image`` is None (the worker writes the file).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from benchtwin.hw.interfaces import CameraFrame

from .stage import SimBenchState

#: the stand's vibration draws: a sub-stream of the camera's "ccd" stream (``SimCamera.vibration_m``)
VIBRATION_SUBSTREAM = 1


@dataclass(frozen=True)
class CcdOptics:
    """What the CCD microscope sees and how: the disk's grating (``render.GratingSpec``), the camera's
    geometry (``render.Camera``: pose, pixels) and its sensor (``render.SensorParams``: noise, bit
    depth)."""

    grating: Any
    camera: Any
    sensor: Any


class SimCamera:
    """``Camera`` of the twin. Use as a context manager (or call ``close``) to release GL.
    ``backend``: the renderer's ("auto", "pyrender", "analytic"), or ``renderer`` itself; ``key``:
    its noise stream's."""

    kind = "camera"

    def __init__(self, name: str, state: SimBenchState, optics: CcdOptics, backend: str = "auto",
                 renderer: Any = None, key: int = 0):
        from benchtwin.twin.render import Renderer

        self.name = name
        self.state = state
        self.optics = optics
        self.grating, self.camera, self.sensor = optics.grating, optics.camera, optics.sensor
        self.backend = backend
        self._own = renderer is None
        self.renderer = Renderer(backend) if renderer is None else renderer
        self.key = int(key)
        self.last_truth: dict | None = None
        # twin/render/pipeline.py: frames rendered in a worker process (simulate sets it)
        self.pipeline: Any = None
        self.pending_job: tuple | None = None
        # the microscope stand's floor-borne vibration (twin/vibration.py ``StandVibration``); None: still
        self.vibration: Any = None

    @classmethod
    def sim_from_scenario(cls, sc: Any, state: SimBenchState, name: str = "ccd", backend: str = "auto",
                          tangential: str = "+x", hidden: Any = None) -> "SimCamera":
        """``hidden``: the bench's ``Hidden`` (built once per bench, ``Bench.hidden``); None: built
        from the scenario."""
        import dataclasses

        from benchtwin.twin.hidden import hidden_for
        from benchtwin.twin.render import GratingSpec, SensorParams

        b = sc["bench"]
        sensor = SensorParams.from_section(sc["instruments"]["ccd"])
        grating = GratingSpec.from_bench(b)
        hidden = hidden_for(sc, hidden)
        if "ccd_pixel_scale" in hidden.effects:
            # true pixel ≠ nominal (camera.pixel_pitch_m stays the nominal: the manifest's value);
            # true grating period at the edge ≠ datasheet, same line count (larger ruling radius)
            sensor = dataclasses.replace(sensor, pixel_scale_error=sensor.pixel_scale_error + hidden.pixel_scale_extra)
            s = hidden.grating_scale_factor
            grating = dataclasses.replace(grating, period_m=grating.period_m * s,
                                          edge_radius_m=grating.edge_radius_m * s)
        camera = sensor.camera(float(b["ccd_position"]), tangential=tangential)
        cam = cls(name, state, CcdOptics(grating, camera, sensor), backend=backend)
        from benchtwin.twin.vibration import StandVibration

        cam.vibration = StandVibration.from_section(sc.get("vibration") if hasattr(sc, "get") else None)
        return cam

    def describe(self) -> dict[str, Any]:
        c = self.camera
        return {"name": self.name, "kind": "camera", "model": "sim CCD microscope (twin)",
                "units": {"image": "DN", "t_s": "s"}, "width_px": c.width_px, "height_px": c.height_px,
                "pixel_um": c.pixel_pitch_m * 1e6, "position_deg": float(np.degrees(c.azimuth_rad)),
                "tangential": c.tangential, "reference_px": list(c.reference_px), "bit_depth": self.sensor.bit_depth}

    def vibration_m(self) -> tuple[float, float]:
        """The microscope's (radial, tangential) displacement relative to the table during the
        current step's exposure (m; twin/vibration.py): an independent draw per frame (frames are
        many correlation times apart) from the stream keyed by the runner's step, so the truth taken
        in ``on_step`` and the frame rendered by ``capture`` see the same value, and a resumed run
        the same as an uninterrupted one. (0, 0) without vibration. The draw is a sub-stream of the
        camera's own stream "ccd" — keys (key, step + 1, 0, VIBRATION_SUBSTREAM), where the sensor
        noise uses (key, step + 1, n): independent of it, and no new stream id (truth/seeds.json,
        which lists the stream ids, keeps its bytes for benches without vibration)."""
        if self.vibration is None:
            return 0.0, 0.0
        from .stage import sim_rng

        st = self.state
        step = -1 if st.step_index is None else st.step_index
        return self.vibration.sample(sim_rng(st.seed, "ccd", self.key, step + 1, 0, VIBRATION_SUBSTREAM))

    def disk_seen(self, pose: Any = None) -> Any:
        """The disk's pose relative to the microscope: the posed disk, displaced by the stand's
        thermal drift (twin/thermal.py ``microscope_stand_drift_m``: the stand growing outward
        along the camera's radial line moves the edge inward in the image) and by the stand's
        vibration during this frame's exposure (``vibration_m``: the microscope moving by
        (δr, δt) shows the disk moved by −(δr, δt), radial u and tangential ẑ × u in the disk
        plane). The identical object when the bench has neither (datasets without them are
        unchanged)."""
        from benchtwin.twin.pose import BodyPose

        p = self.state.posed(pose)
        th = getattr(self.state.bench, "thermal", None)
        d = th.microscope_stand_drift_m(p.t_s) if th is not None else 0.0
        vr, vt = self.vibration_m()
        if not d and not vr and not vt:
            return p.disk
        u = self.camera.axes_lab()[0]
        t = np.array([-u[1], u[0], 0.0])   # ẑ × u: tangential in the disk plane (vr = vt = 0: the bytes of −d·u)
        return BodyPose(pos=p.disk.pos - (d + vr) * u - vt * t, R=p.disk.R)

    def sim_frame_truth(self, pose: Any = None) -> dict[str, Any]:
        """The geometric truth of a frame taken at ``pose`` (default: the bench's current pose),
        without rendering it: what the renderer draws from (``build_scene``), the disk as the
        microscope sees it (``disk_seen``)."""
        from benchtwin.twin.render.grating import build_scene

        p = self.state.pose if pose is None else pose
        scene = build_scene(self.disk_seen(p), self.grating, self.camera)
        return {"centre_px": [float(v) for v in scene.centre_px], "edge_radius_px": float(scene.edge_radius_px),
                "pixel_um": float(self.camera.true_pixel_m * 1e6),
                "reference_px": [float(v) for v in self.camera.reference_px]}

    def capture(self) -> CameraFrame:
        st = self.state
        if self.pipeline is not None and self.pipeline.backend() is not None:
            # Pipelined (twin/render/pipeline.py): the frame's inputs — the posed disk and its noise
            # stream, drawn exactly as below — are kept for the caller to hand to the worker with
            # the frame's file name (``take_job``); the image is not returned. The reading carries
            # what the rendered one would: the backend, the image's shape and dtype.
            disk = self.disk_seen(st.pose)   # relative to the microscope (its stand's drift)
            self.pending_job = (disk, st.rng("ccd", self.key))
            backend = self.pipeline.backend()
            self.last_truth = {**self.sim_frame_truth(), "backend": backend}
            c = self.camera
            # (no image: the reading is a CameraFrame without its image, and with its shape and dtype)
            return cast(CameraFrame, {"image": None, "t_s": float(st.clock.now()), "status": "ok", "backend": backend,
                                      "image_shape": [int(c.height_px), int(c.width_px)],
                                      "image_dtype": str(np.dtype(self.sensor.dtype))})
        frame = self.renderer.render(self.disk_seen(st.pose), self.grating, self.camera, self.sensor,
                                     st.rng("ccd", self.key))
        tr = frame.truth
        self.last_truth = {"centre_px": [float(v) for v in tr["centre_px"]],
                           "edge_radius_px": float(tr["edge_radius_px"]), "pixel_um": float(tr["pixel_um"]),
                           "reference_px": [float(v) for v in tr["reference_px"]], "backend": tr["backend"]}
        # no true value in the reading: it is journaled outside truth/
        return {"image": frame.image, "t_s": float(st.clock.now()), "status": "ok", "backend": tr["backend"]}

    def take_job(self) -> tuple:
        """The last pipelined capture's (disk pose, noise stream), once."""
        job, self.pending_job = self.pending_job, None
        if job is None:
            raise RuntimeError(f"{self.name}: no pipelined capture to hand over")
        return job

    def close(self) -> None:
        if self._own:
            self.renderer.close()

    def __enter__(self) -> "SimCamera":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
