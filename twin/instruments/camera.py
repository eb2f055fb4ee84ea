"""CCD microscope looking at the grating edge through the hole opposite the head (Jia 2019 sec. 4.2).

The instrument takes the posed disk from the shared state and calls the renderer
(``benchtwin.twin.render``): the image comes from the exact posed geometry (eccentricity, radial
motion, tilt), then the sensor model (blur, vignetting, shot/read noise, dust, quantisation).
``capture()`` returns the ``Camera`` protocol shape plus ``truth``: the disk's geometric centre in
pixels (``centre_px``), the edge radius in true pixels (``edge_radius_px``), the true pixel size,
the reference point and the backend used. The sensor noise stream is keyed by the runner's step,
so a resumed run renders identical frames.
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

    @classmethod
    def sim_from_scenario(cls, sc: Any, state: SimBenchState, name: str = "ccd", backend: str = "auto",
                          tangential: str = "+x") -> "SimCamera":
        import dataclasses

        from benchtwin.twin.hidden import Hidden
        from benchtwin.twin.render import GratingSpec, SensorParams

        b = sc["bench"]
        sensor = SensorParams.from_section(sc["instruments"]["ccd"])
        grating = GratingSpec.from_bench(b)
        hidden = Hidden.from_scenario(sc)
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

    def capture(self) -> CameraFrame:
        st = self.state
        frame = self.renderer.render(st.pose.disk, self.grating, self.camera, self.sensor, st.rng("ccd", self.key))
        tr = frame.truth
        truth = {"centre_px": [float(v) for v in tr["centre_px"]], "edge_radius_px": float(tr["edge_radius_px"]),
                 "pixel_um": float(tr["pixel_um"]), "reference_px": [float(v) for v in tr["reference_px"]],
                 "backend": tr["backend"]}
        self.last_truth = truth
        return {"image": frame.image, "t_s": float(st.clock.now()), "status": "ok", "truth": truth}

    def close(self) -> None:
        if self._own:
            self.renderer.close()

    def __enter__(self) -> "SimCamera":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
