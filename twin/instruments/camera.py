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

from typing import Any

import numpy as np

from benchtwin.hw.interfaces import CameraFrame

from .stage import SimBenchState


class SimCamera:
    """``Camera`` of the twin. Use as a context manager (or call ``close``) to release GL."""

    kind = "camera"

    def __init__(self, name: str, state: SimBenchState, grating: Any, camera: Any, sensor: Any,
                 backend: str = "auto", renderer: Any = None, key: int = 0):
        from benchtwin.twin.render import Renderer

        self.name = name
        self.state = state
        self.grating, self.camera, self.sensor = grating, camera, sensor
        self.backend = backend
        self._own = renderer is None
        self.renderer = Renderer(backend) if renderer is None else renderer
        self.key = int(key)
        self.last_truth: dict | None = None
        # twin/render/pipeline.py: frames rendered in a worker process (simulate sets it)
        self.pipeline: Any = None
        self.pending_job: tuple | None = None

    @classmethod
    def sim_from_scenario(cls, sc: Any, state: SimBenchState, name: str = "ccd", backend: str = "auto",
                          tangential: str = "+x", hidden: Any = None) -> "SimCamera":
        """``hidden``: the bench's ``Hidden`` (built once per bench, ``Bench.hidden``); None: built
        from the scenario."""
        import dataclasses

        from benchtwin.twin.hidden import Hidden
        from benchtwin.twin.render import GratingSpec, SensorParams

        b = sc["bench"]
        sensor = SensorParams.from_section(sc["instruments"]["ccd"])
        grating = GratingSpec.from_bench(b)
        hidden = Hidden.from_scenario(sc) if hidden is None else hidden
        if "ccd_pixel_scale" in hidden.effects:
            # true pixel ≠ nominal (camera.pixel_pitch_m stays the nominal: the manifest's value);
            # true grating period at the edge ≠ datasheet, same line count (larger ruling radius)
            sensor = dataclasses.replace(sensor, pixel_scale_error=sensor.pixel_scale_error + hidden.pixel_scale_extra)
            s = hidden.grating_scale_factor
            grating = dataclasses.replace(grating, period_m=grating.period_m * s,
                                          edge_radius_m=grating.edge_radius_m * s)
        camera = sensor.camera(float(b["ccd_position"]), tangential=tangential)
        return cls(name, state, grating, camera, sensor, backend=backend)

    def describe(self) -> dict[str, Any]:
        c = self.camera
        return {"name": self.name, "kind": "camera", "model": "sim CCD microscope (twin)",
                "units": {"image": "DN", "t_s": "s"}, "width_px": c.width_px, "height_px": c.height_px,
                "pixel_um": c.pixel_pitch_m * 1e6, "position_deg": float(np.degrees(c.azimuth_rad)),
                "tangential": c.tangential, "reference_px": list(c.reference_px), "bit_depth": self.sensor.bit_depth}

    def sim_frame_truth(self, pose: Any = None) -> dict[str, Any]:
        """The geometric truth of a frame taken at ``pose`` (default: the bench's current pose),
        without rendering it: what the renderer draws from (``build_scene``)."""
        from benchtwin.twin.render.grating import build_scene

        p = self.state.pose if pose is None else pose
        scene = build_scene(p.disk, self.grating, self.camera)
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
            disk = st.pose.disk
            self.pending_job = (disk, st.rng("ccd", self.key))
            backend = self.pipeline.backend()
            self.last_truth = {**self.sim_frame_truth(), "backend": backend}
            c = self.camera
            return {"image": None, "t_s": float(st.clock.now()), "status": "ok", "backend": backend,
                    "image_shape": [int(c.height_px), int(c.width_px)],
                    "image_dtype": str(np.dtype(self.sensor.dtype))}
        frame = self.renderer.render(st.pose.disk, self.grating, self.camera, self.sensor, st.rng("ccd", self.key))
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
