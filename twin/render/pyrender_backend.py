"""pyrender (OpenGL) backend of the CCD renderer: line coverage of Jia 2019 sec. 4.2 images.

Jia et al. 2019, sec. 4.2: 60 microscope images (2048×1536 px, 0.667 µm/px) of the scale edge; the
analysis locates line ends to a fraction of a pixel, so the rasteriser's edge accuracy matters.

Choices, and why:

- orthographic camera (``pyrender.OrthographicCamera``): the microscope is telecentric-like; one
  GL world unit = one output pixel, the scene in camera-local pixel coordinates (see ``grating``)
  so float32 vertices keep 1e-4 px;
- coverage only: lines are black on a white clear colour, read back as one 8-bit channel; the
  irradiance (glass / chrome transmission) is formed in float64 afterwards. A coverage image needs
  no lighting, no depth readback and no RGB conversion;
- sub-pixel accuracy: llvmpipe's 4× MSAA samples a pixel at x, y ∈ {1/8, 3/8, 5/8, 7/8} (rotated
  grid): an edge's coverage moves in quarter-pixel steps, so its position is off by up to 1/8 px.
  Two remedies, combinable:
  * ``supersample`` k: render at k·W × k·H and area-average k×k blocks (exact box filter);
    4k sample positions per axis at k² cost;
  * ``jitter`` n: accumulate n passes with the camera shifted along the diagonal by
    (m/(4n) − (n−1)/(8n))/k px, m = 0…n−1 (the classical accumulation-buffer antialiasing): the
    union of the 4 MSAA positions and the n shifts is the stratified set (2q+1)/(8n) in x and in y,
    i.e. again an exact box filter with 4n positions per axis, at n× (not n²×) cost.
  The worst edge error is 1/(8·k·n) px (plus 8-bit rounding, ≤ 0.002 px per pass); the default
  k = 1, n = 8 gives ≤ 0.016 px, measured ≤ 0.01 px against the analytic renderer;
- one persistent ``OffscreenRenderer`` per sweep (creating a context costs more than a frame), the
  scene kept and only the line mesh node swapped per frame; the framebuffer readback is replaced,
  on this renderer instance only, by a single-channel read (pyrender always reads float depth and
  RGB: 2/3 of a bare frame's time at 2048×1536).
"""

from __future__ import annotations

import types

import numpy as np

from benchtwin.twin.render import gl

__all__ = ["GlCoverageRenderer"]


def _lean_read(self, scene, flags):
    """Resolve the MSAA buffer and read the red channel only (bound to one pyrender Renderer)."""
    from OpenGL.GL import (GL_COLOR_BUFFER_BIT, GL_DRAW_FRAMEBUFFER, GL_NEAREST, GL_PACK_ALIGNMENT,
                           GL_READ_FRAMEBUFFER, GL_RED, GL_UNSIGNED_BYTE, glBindFramebuffer,
                           glBlitFramebuffer, glPixelStorei, glReadPixels)

    width, height = self._main_fb_dims
    glBindFramebuffer(GL_READ_FRAMEBUFFER, self._main_fb_ms)
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, self._main_fb)
    # NEAREST is the plain MSAA resolve (average of the samples); the images are the same size
    glBlitFramebuffer(0, 0, width, height, 0, 0, width, height, GL_COLOR_BUFFER_BIT, GL_NEAREST)
    glBindFramebuffer(GL_READ_FRAMEBUFFER, self._main_fb)
    glPixelStorei(GL_PACK_ALIGNMENT, 1)
    buf = glReadPixels(0, 0, width, height, GL_RED, GL_UNSIGNED_BYTE)
    return np.frombuffer(buf, dtype=np.uint8).reshape(height, width)  # bottom row first


class GlCoverageRenderer:
    """Persistent off-screen GL context rendering line coverage images of W×H px.

    Use as a context manager or call ``close()``; under EGL close MuJoCo renderers first (deleting a
    pyrender context tears down the EGL display they share).
    """

    def __init__(self, width_px: int, height_px: int, supersample: int = 1, jitter: int = 8):
        if supersample < 1 or jitter < 1:
            raise ValueError("supersample and jitter must be ≥ 1")
        self.width_px, self.height_px = int(width_px), int(height_px)
        self.k, self.n = int(supersample), int(jitter)
        pr = gl.pyrender()
        self._pr = pr
        self._r = pr.OffscreenRenderer(self.width_px * self.k, self.height_px * self.k)
        self._r._renderer._read_main_framebuffer = types.MethodType(_lean_read, self._r._renderer)
        self._scene = pr.Scene(bg_color=[1.0, 1.0, 1.0, 1.0], ambient_light=[1.0, 1.0, 1.0])
        cam = pr.OrthographicCamera(xmag=self.width_px / 2.0, ymag=self.height_px / 2.0, znear=0.5, zfar=10.0)
        self._cam_node = self._scene.add(cam, pose=self._cam_pose(0.0))
        self._mesh_node = None

    @staticmethod
    def _cam_pose(shift: float) -> np.ndarray:
        pose = np.eye(4)
        pose[:3, 3] = (shift, shift, 2.0)  # looking down −z onto the z = 0 plane
        return pose

    def shifts(self) -> np.ndarray:
        m = np.arange(self.n)
        return (m / (4.0 * self.n) - (self.n - 1) / (8.0 * self.n)) / self.k

    def coverage(self, polygons: list[np.ndarray]) -> np.ndarray:
        """Coverage in [0, 1] (float64, H×W) of polygons given in camera-local px relative to the
        reference point (W/2, H/2); pixel (x, y) centre at x, y."""
        from benchtwin.twin.render.grating import to_trimesh

        pr = self._pr
        if self._r is None:
            raise RuntimeError("renderer is closed")
        if self._mesh_node is not None:
            self._scene.remove_node(self._mesh_node)
            self._mesh_node = None
        W, H = self.width_px, self.height_px
        if polygons:
            # camera-local px (origin at the reference point W/2, H/2) → GL world: origin at the
            # image's geometric centre ((W−1)/2, (H−1)/2 in pixel-centre coordinates), y up
            tm = to_trimesh(polygons, offset_px=(W / 2.0 - (W - 1) / 2.0, H / 2.0 - (H - 1) / 2.0))
            tm.visual.vertex_colors = np.tile(np.array([0, 0, 0, 255], np.uint8), (len(tm.vertices), 1))
            self._mesh_node = self._scene.add(pr.Mesh.from_trimesh(tm, smooth=False))
        acc = np.zeros((H * self.k, W * self.k), np.uint32)
        for s in self.shifts():
            self._scene.set_pose(self._cam_node, self._cam_pose(float(s)))
            acc += self._r.render(self._scene, flags=pr.RenderFlags.FLAT)
        if self.k > 1:
            acc = acc.reshape(H, self.k, W, self.k).sum(axis=(1, 3))
        white = 255.0 * self.n * self.k * self.k
        return (1.0 - acc[::-1].astype(np.float64) / white)

    def close(self) -> None:
        if self._r is not None:
            if self._mesh_node is not None:
                self._scene.remove_node(self._mesh_node)
                self._mesh_node = None
            self._r.delete()
            self._r = None

    def __enter__(self) -> "GlCoverageRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):  # last resort; explicit close() is the contract
        try:
            self.close()
        except Exception:
            pass
