"""pyrender (OpenGL) backend of the CCD renderer: line coverage of Jia 2019 sec. 4.2 images.

Jia et al. 2019, sec. 4.2: 60 microscope images (2048×1536 px, 0.667 µm/px) of the scale edge; the
analysis locates line ends to a fraction of a pixel, so the rasteriser's edge accuracy matters.

Choices, and why:

- orthographic camera (``pyrender.OrthographicCamera``): the microscope is telecentric-like; one
  GL world unit = one output pixel, the scene in camera-local pixel coordinates (see ``grating``)
  so float32 vertices keep 1e-4 px;
- coverage only: lines are black on a white clear colour, rendered into a single-channel GL_R8
  multisample buffer without depth (the lines never overlap) and read back as one 8-bit channel;
  the irradiance (glass / chrome transmission) is formed afterwards. pyrender's own framebuffer
  (RGBA8 + DEPTH24, RGB + float depth readback) costs 3.5× more per pass at 2048×1536; both
  replacements are bound to this renderer instance only (``types.MethodType``), pyrender itself is
  not patched;
- where the context offers OpenGL ≥ 4.4 (llvmpipe: 4.5), not even that buffer: each pass's fragment
  shader ORs its 4-sample coverage masks into an integer image, and a table turns a pixel's masks
  into the bytes the resolves would have summed (``sample_count``: byte-identical, ≈ 2× cheaper a
  frame, as the clear and resolve of 12 MB of samples per pass are gone);
- sub-pixel accuracy: llvmpipe's 4× MSAA samples a pixel at x, y ∈ {1/8, 3/8, 5/8, 7/8} (rotated
  grid): an edge's coverage moves in quarter-pixel steps, so its position is off by up to 1/8 px
  (measured: 0.13 px at the line ends). Three remedies, combinable:
  * ``supersample`` k: render at k·W × k·H and area-average k×k blocks (exact box filter);
    4k sample positions per axis at k² cost;
  * ``jitter`` n: accumulate n passes with the camera shifted along the diagonal by
    (m/(4n) − (n−1)/(8n))/k px, m = 0…n−1 (the classical accumulation-buffer antialiasing): the
    union of the 4 MSAA positions and the n shifts is the stratified set (2q+1)/(8n) in x and in y,
    i.e. again a box filter with 4n positions per axis, at n× (not k²×) cost;
  * ``end_band``: the line ENDS are what Jia's circle fit measures (sec. 4.2.2: "middle point of
    the right edge of each part"); they lie in a band of ~30 columns (the edge arc's sagitta over
    the view plus eccentric motion). That band is rendered again by an anisotropic orthographic
    camera, W/band_width× magnified in x only, and its columns area-averaged: 4·W/band_width
    (≈ 256) positions per pixel across the end, ≤ 0.005 px, for ``band_jitter`` passes (jittered
    diagonally too, x on the scale of a band sub-column).
  Default k = 1, n = 2, band on (4 passes): line ends ≤ 0.005 px from the exact coverage, line
  sides ≤ 1/16 px (they only set each line's centre row, whose error enters d_ref scaled by the
  edge slope y/R ≤ 0.02). Plus 8-bit rounding ≤ 0.002 px per pass;
- one persistent ``OffscreenRenderer`` per sweep (creating a context and compiling shaders costs
  ~2.5 s, 20 frames' worth), the scene kept and only the line mesh node swapped per frame.
"""

from __future__ import annotations

import types
from dataclasses import dataclass

import numpy as np

from benchtwin.twin.render import gl, sample_count
from benchtwin.twin.render.sample_count import SampleCounter

__all__ = ["GlCoverageRenderer", "CoverageSampling"]


@dataclass(frozen=True)
class CoverageSampling:
    """The sub-pixel sampling of the coverage (the module's docstring): ``supersample`` k (each pixel
    rendered as k×k and area-averaged), ``jitter`` n (diagonally shifted passes), and the line ends'
    band: ``end_band`` (render it again, magnified in x), its ``band_jitter`` passes and
    ``band_margin_px``, the columns kept on either side of the outermost line ends (px)."""

    supersample: int = 1
    jitter: int = 2
    end_band: bool = True
    band_jitter: int = 2
    band_margin_px: float = 4.0


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


def _aniso_ortho_camera(pr, xmag: float, ymag: float, znear: float, zfar: float):
    """An orthographic camera whose xmag is honoured: pyrender's OrthographicCamera replaces xmag
    by width/height·ymag whenever it knows the viewport, which forbids the end band's anisotropic
    (x-only) magnification."""

    class AnisoOrthographicCamera(pr.OrthographicCamera):
        def get_projection_matrix(self, width=None, height=None):
            return super().get_projection_matrix(None, None)

    return AnisoOrthographicCamera(xmag=xmag, ymag=ymag, znear=znear, zfar=zfar)


def _lean_framebuffer(self):
    """pyrender's main framebuffers, but one 8-bit channel and no depth (bound to one Renderer).

    Coverage needs neither colour nor depth: the lines never overlap. A GL_R8 multisample buffer
    is a quarter of the RGBA8 + DEPTH24 traffic per sample that llvmpipe clears, fills and resolves.
    """
    from OpenGL.GL import (GL_COLOR_ATTACHMENT0, GL_DRAW_FRAMEBUFFER, GL_R8, GL_RENDERBUFFER,
                           glBindFramebuffer, glBindRenderbuffer, glFramebufferRenderbuffer,
                           glGenFramebuffers, glGenRenderbuffers, glRenderbufferStorage,
                           glRenderbufferStorageMultisample)

    if self._main_fb is not None and (self.viewport_width, self.viewport_height) != self._main_fb_dims:
        self._delete_main_framebuffer()
    if self._main_fb is None:
        self._main_cb, self._main_cb_ms = glGenRenderbuffers(2)
        glBindRenderbuffer(GL_RENDERBUFFER, self._main_cb)
        glRenderbufferStorage(GL_RENDERBUFFER, GL_R8, self.viewport_width, self.viewport_height)
        glBindRenderbuffer(GL_RENDERBUFFER, self._main_cb_ms)
        glRenderbufferStorageMultisample(GL_RENDERBUFFER, 4, GL_R8, self.viewport_width, self.viewport_height)
        self._main_fb, self._main_fb_ms = glGenFramebuffers(2)
        glBindFramebuffer(GL_DRAW_FRAMEBUFFER, self._main_fb)
        glFramebufferRenderbuffer(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, self._main_cb)
        glBindFramebuffer(GL_DRAW_FRAMEBUFFER, self._main_fb_ms)
        glFramebufferRenderbuffer(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, self._main_cb_ms)
        self._main_fb_dims = (self.viewport_width, self.viewport_height)


def _lean_delete_framebuffer(self):
    from OpenGL.GL import glDeleteFramebuffers, glDeleteRenderbuffers

    if self._main_fb is not None:
        glDeleteFramebuffers(2, [self._main_fb, self._main_fb_ms])
        glDeleteRenderbuffers(2, [self._main_cb, self._main_cb_ms])
    self._main_fb = self._main_cb = self._main_fb_ms = self._main_cb_ms = None
    self._main_db = self._main_db_ms = None
    self._main_fb_dims = (None, None)


def _scaled(acc: np.ndarray, samples: int) -> np.ndarray:
    """Coverage 1 − acc/(255·samples) in float32 (8-bit passes averaged need no more, and it halves
    the memory traffic per frame), in place on one copy: 3 Mpx temporaries cost ms. Applied to a
    whole sum image or to a table of its values: the same float32 operations, the same bits."""
    cov = acc.astype(np.float32)
    cov *= np.float32(-1.0 / (255.0 * samples))
    cov += np.float32(1.0)
    return cov


class GlCoverageRenderer:
    """Persistent off-screen GL context rendering line coverage images of W×H px.

    Use as a context manager or call ``close()``; under EGL close MuJoCo renderers first (deleting a
    pyrender context tears down the EGL display they share).
    """

    def __init__(self, width_px: int, height_px: int, sampling: CoverageSampling = CoverageSampling(), *,
                 lean_framebuffer: bool = True, count_samples: bool | None = None):
        if sampling.supersample < 1 or sampling.jitter < 1:
            raise ValueError("supersample and jitter must be ≥ 1")
        self.width_px, self.height_px = int(width_px), int(height_px)
        self.k, self.n = int(sampling.supersample), int(sampling.jitter)
        self.end_band, self.band_jitter = bool(sampling.end_band), int(sampling.band_jitter)
        self.band_margin_px = float(sampling.band_margin_px)
        pr = gl.pyrender()
        self._pr = pr
        self._r = pr.OffscreenRenderer(self.width_px * self.k, self.height_px * self.k)
        rr = self._r._renderer
        rr._read_main_framebuffer = types.MethodType(_lean_read, rr)
        # OSMesa has no framebuffer objects in pyrender: one sample at the pixel centre, the
        # default buffer read as RGB + depth. Keep the accuracy by 4× the passes (4× slower).
        self.samples_per_axis = 4 if self._r._platform.supports_framebuffers() else 1
        if self.samples_per_axis == 1:
            self.n, self.band_jitter = 4 * self.n, 4 * self.band_jitter
        # sample masks instead of a resolved MSAA buffer (sample_count.py): the same bytes, without
        # the clear and resolve of 12 MB of samples per pass; ``count_samples`` None = where the
        # context offers it, False = the resolve path (kept for older GL and as the cross-check)
        self._counter: SampleCounter | None = None
        if count_samples is not False and self.samples_per_axis == 4:
            if sample_count.supported():
                passes = max(self.n, self.band_jitter if self.end_band else 1)
                self._counter = sample_count.SampleCounter(rr, self.width_px * self.k, self.height_px * self.k,
                                                           max_passes=passes)
            elif count_samples:
                raise RuntimeError("sample counting needs OpenGL ≥ 4.4 with 4-sample framebuffers")
        if self._counter is None and lean_framebuffer and self.samples_per_axis == 4:
            rr._delete_main_framebuffer()  # (none yet) then replace how it is (re)built
            rr._configure_main_framebuffer = types.MethodType(_lean_framebuffer, rr)
            rr._delete_main_framebuffer = types.MethodType(_lean_delete_framebuffer, rr)
        self._scene = pr.Scene(bg_color=[1.0, 1.0, 1.0, 1.0], ambient_light=[1.0, 1.0, 1.0])
        cam = _aniso_ortho_camera(pr, self.width_px / 2.0, self.height_px / 2.0, 0.5, 10.0)
        self._cam = cam
        self._cam_node = self._scene.add(cam, pose=self._cam_pose(0.0, 0.0))
        self._mesh_node = None

    @staticmethod
    def _cam_pose(shift_x: float, shift_y: float, x_centre: float = 0.0) -> np.ndarray:
        pose = np.eye(4)
        pose[:3, 3] = (x_centre + shift_x, shift_y, 2.0)  # looking down −z onto the z = 0 plane
        return pose

    def shifts(self, n: int | None = None) -> np.ndarray:
        """Stratified sub-pixel camera shifts (output px) for n passes: with the S sample positions
        (2j+1)/(2S) per axis of a rendered pixel (S = 4 with MSAA, 1 without) they give the
        positions (2q+1)/(2Sn) of a box filter."""
        n = self.n if n is None else n
        S = self.samples_per_axis
        m = np.arange(n)
        return (m / (S * n) - (n - 1) / (2.0 * S * n)) / self.k

    def _band_columns(self, end_x_px: np.ndarray | None) -> tuple[int, int] | None:
        """(first column, width) of the end band, or None. The width divides W so that the band
        camera's x magnification W/width is an integer (whole sub-columns per output column)."""
        if end_x_px is None or len(end_x_px) == 0 or not self.end_band:
            return None
        W = self.width_px
        lo = int(np.floor(np.min(end_x_px) - self.band_margin_px))
        hi = int(np.ceil(np.max(end_x_px) + self.band_margin_px))
        lo, hi = max(lo, 0), min(hi, W - 1)
        if hi < lo:
            return None  # no line end in view
        need = hi - lo + 1
        widths = [d for d in range(need, W // 4 + 1) if W % d == 0]
        if not widths:
            return None  # ends spread over too wide a band: uniform jitter only
        wb = widths[0]
        c0 = min(max(lo - (wb - need) // 2, 0), W - wb)
        return c0, wb

    def _render_passes(self, xmag: float, x_centre: float, shifts_x: np.ndarray, shifts_y: np.ndarray) -> None:
        """The passes into the sample counter's mask image (read with ``read``/``planes``)."""
        assert self._counter is not None
        pr = self._pr
        self._cam.xmag = xmag
        self._counter.begin()
        for j, (sx, sy) in enumerate(zip(shifts_x, shifts_y)):
            self._counter.select(j)
            self._scene.set_pose(self._cam_node, self._cam_pose(float(sx), float(sy), x_centre))
            self._r.render(self._scene, flags=pr.RenderFlags.FLAT)

    def _accumulate(self, xmag: float, x_centre: float, shifts_x: np.ndarray, shifts_y: np.ndarray) -> np.ndarray:
        pr = self._pr
        self._cam.xmag = xmag
        if self._counter is not None:
            self._render_passes(xmag, x_centre, shifts_x, shifts_y)
            return self._counter.read(len(shifts_x))
        acc = np.zeros((self.height_px * self.k, self.width_px * self.k), np.uint16)
        for sx, sy in zip(shifts_x, shifts_y):
            self._scene.set_pose(self._cam_node, self._cam_pose(float(sx), float(sy), x_centre))
            out = self._r.render(self._scene, flags=pr.RenderFlags.FLAT)
            if isinstance(out, tuple):  # OSMesa path: (RGB top row first, depth)
                out = out[0][::-1, :, 0]
            acc += out
        return acc

    def coverage(self, polygons: list[np.ndarray], end_x_px: np.ndarray | None = None) -> np.ndarray:
        """Coverage in [0, 1] (float32, H×W) of polygons given in camera-local px relative to the
        reference point (W/2, H/2); pixel (x, y) centre at x, y. ``end_x_px``: image x of the
        line-end vertices, which sets the end band (rendered at W/width× in x)."""
        from benchtwin.twin.render.grating import to_trimesh

        pr = self._pr
        if self._r is None:
            raise RuntimeError("renderer is closed")
        if self._mesh_node is not None:
            self._scene.remove_node(self._mesh_node)
            self._mesh_node = None
        W, H, k = self.width_px, self.height_px, self.k
        if polygons:
            # camera-local px (origin at the reference point W/2, H/2) → GL world: origin at the
            # image's geometric centre ((W−1)/2, (H−1)/2 in pixel-centre coordinates), y up
            tm = to_trimesh(polygons, offset_px=(W / 2.0 - (W - 1) / 2.0, H / 2.0 - (H - 1) / 2.0))
            tm.visual.vertex_colors = np.tile(np.array([0, 0, 0, 255], np.uint8), (len(tm.vertices), 1))
            self._mesh_node = self._scene.add(pr.Mesh.from_trimesh(tm, smooth=False))
        shifts = self.shifts()
        if self._counter is not None and k == 1 and len(shifts) <= 2:
            # one byte of masks per pixel: the sum of the passes AND its scaling below become one
            # float32 table (the same float32 operations on each of its 256 values), ≈ 5 ms less
            self._render_passes(W / 2.0, 0.0, shifts, shifts)
            import cv2

            table = _scaled(self._counter.table(len(shifts)), len(shifts) * k * k)
            cov = cv2.LUT(cv2.flip(self._counter.planes(len(shifts))[0], 0), table)
        else:
            acc = self._accumulate(W / 2.0, 0.0, shifts, shifts)  # diagonal: stratified in x and y
            if k > 1:
                acc = acc.reshape(H, k, W, k).sum(axis=(1, 3), dtype=np.uint32)
            cov = _scaled(acc[::-1], len(shifts) * k * k)
        band = self._band_columns(end_x_px)
        if band is not None:
            c0, wb = band
            m = W // wb  # output columns are m·k rendered columns wide in the band pass
            x_centre = (c0 - 0.5 + wb / 2.0) - (W - 1) / 2.0  # band centre in GL world units
            # diagonal jitter again, but in x on the scale of a band sub-column (1/m px): an x
            # shift of output-pixel size would smear the band's box filter
            nb = self.band_jitter
            sy = self.shifts(nb)
            accb = self._accumulate(wb / 2.0, x_centre, sy / m, sy)
            accb = accb.reshape(H, k, wb, m * k).sum(axis=(1, 3), dtype=np.uint32)
            cov[:, c0:c0 + wb] = 1.0 - accb[::-1].astype(np.float64) / (255.0 * nb * m * k * k)  # (float32 store)
        self._cam.xmag = W / 2.0
        return cov

    def close(self) -> None:
        if self._r is not None:
            if self._mesh_node is not None:
                self._scene.remove_node(self._mesh_node)
                self._mesh_node = None
            if self._counter is not None:
                self._r._platform.make_current()
                self._counter.close()
                self._counter = None
            self._r.delete()
            self._r = None

    def __enter__(self) -> "GlCoverageRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
