"""CCD microscope images of the grating edge: the twin's side of Jia 2019 sec. 4.2.

Jia et al., Appl. Sci. 9 (2019) 3415, sec. 4.2: a CCD microscope looks through a hole opposite
the reading head at the outer ends of the radial graduation lines; 60 images (every 6°, 2048×1536
px, 0.667 µm/px, reference point R = (1024, 768)) give, by a circle fit through the line ends, the
disk's geometric centre and hence the installation eccentricity (eqs. 10–13).

Public entry::

    frame = render_ccd(disk, grating, camera, sensor, rng, backend="auto")

or, for a sweep (one GL context for all frames)::

    with Renderer() as r:
        for pose in poses:
            frame = r.render(pose.disk, grating, camera, sensor, rng)

- ``disk``: lab-frame ``BodyPose`` of the grating disk (eccentricity, radial motion, tilt
  included; the frame sits at the grating's geometric centre);
- ``GratingSpec``/``CcdCamera``: see ``grating``; ``SensorParams``: see ``sensor``;
- ``CcdFrame.truth``: ``centre_px`` (x, y) of the disk's geometric centre in pixel coordinates,
  ``edge_radius_px`` (R_edge over the TRUE pixel), ``pixel_um`` (true), ``reference_px``,
  ``line_ends_px`` (outer-end midpoints of the lines in view), ``backend``.

Backends: ``"pyrender"`` (OpenGL rasteriser, supersampled; see ``pyrender_backend``),
``"analytic"`` (exact pixel coverage in numpy; see ``analytic``), ``"auto"``: pyrender if an
OpenGL context can be created, else analytic (the images agree to ≤ 0.02 px on edge positions).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from benchtwin.twin.pose import BodyPose
from benchtwin.twin.render.grating import CcdCamera, GratingSpec, SceneGeometry, build_scene
from benchtwin.twin.render.sensor import SensorParams, apply_sensor

if TYPE_CHECKING:  # imported when the first GL frame is rendered (it loads OpenGL)
    from benchtwin.twin.render.pyrender_backend import GlCoverageRenderer

__all__ = ["render_ccd", "Renderer", "CcdFrame", "GratingSpec", "CcdCamera", "SensorParams", "BACKENDS"]

BACKENDS = ("auto", "pyrender", "analytic")


@dataclass
class CcdFrame:
    """One CCD image and the geometric truth it was rendered from."""

    image: np.ndarray  # H×W uint8 / uint16
    truth: dict = field(default_factory=dict)


class Renderer:
    """Renders CCD frames; holds the GL context (if any) for a whole sweep. Context manager.

    ``supersample`` (k) and ``jitter`` (n) set the GL backend's sub-pixel accuracy (worst edge error
    1/(8·k·n) px); see ``pyrender_backend``. The GL context is created at the first frame (its
    size is the camera's) and recreated only if the frame size changes.
    """

    def __init__(self, backend: str = "auto", supersample: int = 1, jitter: int = 2, end_band: bool = True):
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
        self.backend = backend
        self.supersample, self.jitter, self.end_band = supersample, jitter, end_band
        self._gl: GlCoverageRenderer | None = None
        self._gl_failed = False

    # ------------------------------------------------------------------ coverage
    def _gl_renderer(self, w: int, h: int) -> GlCoverageRenderer:
        from benchtwin.twin.render.pyrender_backend import CoverageSampling, GlCoverageRenderer

        if self._gl is not None and (self._gl.width_px, self._gl.height_px) != (w, h):
            self._gl.close()
            self._gl = None
        if self._gl is None:
            self._gl = GlCoverageRenderer(w, h, CoverageSampling(self.supersample, self.jitter, self.end_band))
        return self._gl

    def coverage(self, disk: BodyPose, grating: GratingSpec, camera: CcdCamera) -> tuple[np.ndarray, SceneGeometry, str]:
        """Chrome coverage in [0, 1] (H×W; float32 from GL, float64 analytic), the scene geometry,
        and the backend used."""
        scene = build_scene(disk, grating, camera)
        w, h = camera.width_px, camera.height_px
        if self.backend in ("auto", "pyrender") and not self._gl_failed:
            try:
                cov = self._gl_renderer(w, h).coverage(scene.polygons, scene.end_x_px(camera.reference_px))
                return cov, scene, "pyrender"
            except Exception as exc:
                if self.backend == "pyrender":
                    raise
                self._gl_failed = True
                warnings.warn(f"OpenGL rendering unavailable ({type(exc).__name__}: {exc}); "
                              "using the analytic renderer", RuntimeWarning, stacklevel=2)
        from benchtwin.twin.render.analytic import coverage_image

        return coverage_image(scene.polygons, w, h, camera.reference_px), scene, "analytic"

    def irradiance(self, disk: BodyPose, grating: GratingSpec, camera: CcdCamera) -> tuple[np.ndarray, SceneGeometry, str]:
        """Noise-free irradiance in [0, 1]: glass where no chrome, chrome transmission on lines."""
        cov, scene, used = self.coverage(disk, grating, camera)
        irr = cov.astype(np.float32, copy=False)  # coverage() returns a fresh array: reuse it in place
        irr *= np.float32(grating.chrome_transmission - grating.glass_transmission)
        irr += np.float32(grating.glass_transmission)
        return irr, scene, used

    # ------------------------------------------------------------------ frames
    def render(self, disk: BodyPose, grating: GratingSpec, camera: CcdCamera, sensor: SensorParams,
               rng: np.random.Generator) -> CcdFrame:
        if (camera.width_px, camera.height_px) != (sensor.width_px, sensor.height_px):
            raise ValueError(f"camera is {camera.width_px}×{camera.height_px} px but the sensor "
                             f"{sensor.width_px}×{sensor.height_px} px")
        irr, scene, used = self.irradiance(disk, grating, camera)
        image = apply_sensor(irr, sensor, rng, pixel_m=camera.true_pixel_m)
        truth = {"centre_px": scene.centre_px, "edge_radius_px": scene.edge_radius_px,
                 "pixel_um": camera.true_pixel_m * 1e6, "reference_px": camera.reference_px,
                 "line_ends_px": scene.end_mid_px, "line_index": scene.line_index, "backend": used}
        return CcdFrame(image=image, truth=truth)

    def close(self) -> None:
        """Release the GL context (under EGL: after MuJoCo's renderers are closed)."""
        if self._gl is not None:
            self._gl.close()
            self._gl = None

    def __enter__(self) -> "Renderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def render_ccd(disk: BodyPose, grating: GratingSpec, camera: CcdCamera, sensor: SensorParams,
               rng: np.random.Generator, backend: str = "auto") -> CcdFrame:
    """One CCD frame (creates and closes a renderer: for sweeps use ``Renderer``)."""
    with Renderer(backend) as r:
        return r.render(disk, grating, camera, sensor, rng)
