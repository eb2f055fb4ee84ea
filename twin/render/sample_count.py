"""Coverage passes of the GL renderer as sample masks: no MSAA colour buffer, no resolve (issue 17).

Why: a coverage pass of ``pyrender_backend`` on llvmpipe cost ≈ 45–57 ms at 2048×1536 (measured,
load 3), of which the MSAA resolve (``glBlitFramebuffer`` of the 4-sample R8 buffer: a texel
fetch per sample of every pixel, in llvmpipe's shader JIT) ≈ 33 ms, the clear and raster of the
12 MB sample buffer 8–20 ms, the read 4 ms. What the frame needs from a pass is only, per pixel,
which of its 4 samples a line covers.

Theory (OpenGL 4.6 core §14.3.1 multisampling, §15.2.2 shader inputs; GLSL 4.50 §7.1):

- with 4× MSAA a fragment carries a coverage mask, the samples of its pixel that the primitive
  covers; ``gl_SampleMaskIn[0]`` is that mask (reading it does not force per-sample shading), and
  it is exactly the set of samples a colour write would store;
- a framebuffer WITHOUT attachments but with ``GL_FRAMEBUFFER_DEFAULT_SAMPLES = 4``
  (ARB_framebuffer_no_attachments, core 4.3) is rasterised multisampled all the same, so the
  fragment shader sees the same masks while nothing is cleared, written or resolved;
- the fragment shader ORs each fragment's mask into an integer image (``imageAtomicOr``, core
  4.2): fragments of the fan's triangles share the pixels along the fan's inner edges, and the
  OR is idempotent, so a sample reported by two fragments counts once, as in a colour buffer (a
  first prototype that summed the fragments' sample counts instead was off by one in 2 pixels of
  a 3 Mpx jia2019 frame; bits above the 4 samples are masked off for the same caution);
- the lines are black (0) on white (255) and never overlap, so a pixel's resolved byte is a
  function of its number c of covered samples: round(255·(4 − c)/4) with halves rounded up
  (llvmpipe's resolve; measured: the values 255, 191, 128, 64, 0), and the sum of a frame's
  passes is a table lookup of the masks. Byte-identical to the resolved passes (tested).

Layout: an R32UI image of ⌈W/4⌉ words × (H · planes): pixel x of pass j lands in word x // 4,
bits 8·(x mod 4) + 4·(j mod 2) … +3, row y + H·(j // 2). Read back as bytes (little-endian),
plane p is then an H×W uint8 image whose byte holds the masks of passes 2p and 2p + 1: half the
resolves' reads, and a 256-entry table turns it into the passes' sum.
"""

from __future__ import annotations

import os

import numpy as np

__all__ = ["SampleCounter", "supported", "resolved_byte", "pair_table"]

#: the 4-sample MSAA this method reproduces (llvmpipe's only multisample count)
SAMPLES = 4

_FRAG = """#version 450 core
// coverage mask of this fragment OR-ed into the pass's nibble (sample_count.py)
layout(binding = 0, r32ui) uniform uimage2D masks;
uniform int plane_row;
uniform uint nibble;
void main()
{
    uint m = uint(gl_SampleMaskIn[0]) & 15u;
    if (m != 0u) {
        ivec2 p = ivec2(gl_FragCoord.xy);
        imageAtomicOr(masks, ivec2(p.x >> 2, p.y + plane_row), m << (uint(p.x & 3) * 8u + nibble));
    }
}
"""


def resolved_byte(covered: int) -> int:
    """The byte a 4× MSAA resolve gives a white pixel with ``covered`` black samples (halves up)."""
    return ((SAMPLES - covered) * 255 + 2) // SAMPLES


def pair_table(passes: int) -> np.ndarray:
    """uint16[256]: a plane byte (low nibble: one pass's mask, high nibble: the next's) → the sum
    of the passes' resolved bytes; ``passes`` = 1 (the high nibble is unused) or 2."""
    v = np.arange(256)
    out = np.zeros(256, np.int64)
    for j in range(passes):
        nib = (v >> (4 * j)) & 15
        covered = sum((nib >> b) & 1 for b in range(SAMPLES))
        out += ((SAMPLES - covered) * 255 + 2) // SAMPLES
    return out.astype(np.uint16)


def supported() -> bool:
    """Whether the current GL context offers what the counting needs (core 4.4: image atomics,
    framebuffers without attachments, glClearTexImage) and 4-sample rasterisation."""
    from OpenGL.GL import GL_MAJOR_VERSION, GL_MAX_FRAMEBUFFER_SAMPLES, GL_MINOR_VERSION, glGetIntegerv

    try:
        version = (int(glGetIntegerv(GL_MAJOR_VERSION)), int(glGetIntegerv(GL_MINOR_VERSION)))
        return version >= (4, 4) and int(glGetIntegerv(GL_MAX_FRAMEBUFFER_SAMPLES)) >= SAMPLES
    except Exception:
        return False


def _program_class():
    """pyrender's ShaderProgram with our fragment stage (its vertex stage, hence the same vertex
    positions, kept) and the pass's plane/nibble set as uniforms whenever pyrender binds it."""
    from OpenGL.GL import glGetUniformLocation, glUniform1i, glUniform1ui
    from pyrender.shader_program import ShaderProgram

    class CountingProgram(ShaderProgram):
        def __init__(self, counter: "SampleCounter", **kw):
            super().__init__(**kw)
            self._counter = counter
            self._locs: tuple[int, int] | None = None

        def _load(self, shader_filename):
            return _FRAG if shader_filename is None else super()._load(shader_filename)

        def _add_to_context(self):
            super()._add_to_context()
            self._locs = (glGetUniformLocation(self._program_id, "plane_row"),
                          glGetUniformLocation(self._program_id, "nibble"))

        def _remove_from_context(self):
            super()._remove_from_context()
            self._locs = None

        def _bind(self):
            super()._bind()
            row, nibble = self._counter.pass_uniforms()
            assert self._locs is not None
            glUniform1i(self._locs[0], row)
            glUniform1ui(self._locs[1], nibble)

    return CountingProgram


class SampleCounter:
    """Installed on one pyrender ``Renderer``: its FLAT passes draw into a framebuffer without
    attachments (4 samples) and OR the sample masks into an image; ``read`` returns the sum of the
    passes' resolved bytes, bottom row first, like the resolve's ``glReadPixels``."""

    def __init__(self, renderer, width_px: int, height_px: int, max_passes: int = 8):
        from OpenGL.GL import (GL_R32UI, GL_TEXTURE_2D, glBindTexture, glGenTextures, glTexStorage2D)

        self.width_px, self.height_px = int(width_px), int(height_px)
        self.words = -(-self.width_px // 4)
        self.max_planes = -(-int(max_passes) // 2)
        self._pass = 0
        self._r = renderer
        self._tex = glGenTextures(1)
        glBindTexture(GL_TEXTURE_2D, self._tex)
        glTexStorage2D(GL_TEXTURE_2D, 1, GL_R32UI, self.words, self.height_px * self.max_planes)
        glBindTexture(GL_TEXTURE_2D, 0)
        self._buf = np.empty((self.height_px * self.max_planes, self.words), np.uint32)
        self._tables = {1: pair_table(1), 2: pair_table(2)}
        self._install(renderer)

    # ------------------------------------------------------------------ pyrender hooks
    def _install(self, rr) -> None:
        import types

        from pyrender.shader_program import ShaderProgramCache

        counter, program_cls = self, _program_class()
        vert_dir = ShaderProgramCache().shader_dir

        class Programs(ShaderProgramCache):
            """FLAT passes get the counting program; anything else stays pyrender's."""

            def get_program(self, vertex_shader, fragment_shader, geometry_shader=None, defines=None):
                if fragment_shader != "flat.frag" or geometry_shader is not None:
                    return super().get_program(vertex_shader, fragment_shader, geometry_shader, defines)
                key = ("count", vertex_shader) + tuple(sorted((defines or {}).items()))
                if key not in self._program_cache:
                    self._program_cache[key] = program_cls(
                        counter, vertex_shader=os.path.join(vert_dir, vertex_shader), fragment_shader=None,
                        defines=defines)
                return self._program_cache[key]

        rr._program_cache.clear()
        rr._program_cache = Programs()
        rr._delete_main_framebuffer()
        rr._configure_main_framebuffer = types.MethodType(_configure_framebuffer, rr)
        rr._delete_main_framebuffer = types.MethodType(_delete_framebuffer, rr)
        rr._read_main_framebuffer = types.MethodType(lambda self, scene, flags: None, rr)

    def pass_uniforms(self) -> tuple[int, int]:
        """(first image row, bit offset in the byte) of the current pass."""
        return self.height_px * (self._pass // 2), 4 * (self._pass % 2)

    # ------------------------------------------------------------------ per frame
    def begin(self) -> None:
        """Clear the masks; the next pass is pass 0."""
        from OpenGL.GL import (GL_FALSE, GL_R32UI, GL_READ_WRITE, GL_RED_INTEGER, GL_UNSIGNED_INT,
                               glBindImageTexture, glClearTexImage)

        glClearTexImage(self._tex, 0, GL_RED_INTEGER, GL_UNSIGNED_INT, np.zeros(1, np.uint32))
        glBindImageTexture(0, self._tex, 0, GL_FALSE, 0, GL_READ_WRITE, GL_R32UI)
        self._pass = 0

    def select(self, j: int) -> None:
        """The next pyrender pass is pass ``j`` of this frame."""
        if not (0 <= j < 2 * self.max_planes):
            raise ValueError(f"pass {j} beyond the {2 * self.max_planes} the mask image holds")
        self._pass = j

    def table(self, passes: int) -> np.ndarray:
        """uint16[256]: a plane's byte → the sum of its ``passes`` (1 or 2) passes' resolved bytes."""
        return self._tables[passes]

    def read(self, passes: int) -> np.ndarray:
        """uint16 H×W (bottom row first): per pixel the sum over ``passes`` passes of the byte the
        4× MSAA resolve would have given (black lines on white)."""
        import cv2

        acc = None
        for p, plane in enumerate(self.planes(passes)):
            part = cv2.LUT(plane, self._tables[min(2, passes - 2 * p)])
            acc = part if acc is None else acc + part
        assert acc is not None
        return acc

    def planes(self, passes: int) -> list[np.ndarray]:
        """The mask planes of ``passes`` passes: uint8 H×W (bottom row first), contiguous, a byte
        holding the masks of passes 2p (low nibble) and 2p + 1; they may share the counter's buffer:
        valid until the next read."""
        from OpenGL.GL import (GL_PACK_ALIGNMENT, GL_RED_INTEGER, GL_TEXTURE_2D,
                               GL_TEXTURE_UPDATE_BARRIER_BIT, GL_UNSIGNED_INT, glBindTexture,
                               glGetTexImage, glMemoryBarrier, glPixelStorei)

        glMemoryBarrier(GL_TEXTURE_UPDATE_BARRIER_BIT)  # the atomics before the read
        glBindTexture(GL_TEXTURE_2D, self._tex)
        glPixelStorei(GL_PACK_ALIGNMENT, 4)
        glGetTexImage(GL_TEXTURE_2D, 0, GL_RED_INTEGER, GL_UNSIGNED_INT, self._buf)
        glBindTexture(GL_TEXTURE_2D, 0)
        H, W = self.height_px, self.width_px
        planes = self._buf.view(np.uint8).reshape(self.max_planes, H, 4 * self.words)[:, :, :W]
        return [np.ascontiguousarray(planes[p]) for p in range(-(-passes // 2))]

    def close(self) -> None:
        from OpenGL.GL import glDeleteTextures

        if self._tex is not None:
            glDeleteTextures(1, [self._tex])
            self._tex = None


def _configure_framebuffer(self):
    """pyrender's main framebuffer replaced by one without attachments, rasterised with 4 samples
    (bound to one pyrender Renderer)."""
    from OpenGL.GL import (GL_DRAW_FRAMEBUFFER, GL_FRAMEBUFFER_DEFAULT_HEIGHT, GL_FRAMEBUFFER_DEFAULT_SAMPLES,
                           GL_FRAMEBUFFER_DEFAULT_WIDTH, glBindFramebuffer, glFramebufferParameteri,
                           glGenFramebuffers)

    if self._main_fb_ms is not None and (self.viewport_width, self.viewport_height) != self._main_fb_dims:
        self._delete_main_framebuffer()
    if self._main_fb_ms is None:
        self._main_fb_ms = glGenFramebuffers(1)
        glBindFramebuffer(GL_DRAW_FRAMEBUFFER, self._main_fb_ms)
        glFramebufferParameteri(GL_DRAW_FRAMEBUFFER, GL_FRAMEBUFFER_DEFAULT_WIDTH, self.viewport_width)
        glFramebufferParameteri(GL_DRAW_FRAMEBUFFER, GL_FRAMEBUFFER_DEFAULT_HEIGHT, self.viewport_height)
        glFramebufferParameteri(GL_DRAW_FRAMEBUFFER, GL_FRAMEBUFFER_DEFAULT_SAMPLES, SAMPLES)
        self._main_fb_dims = (self.viewport_width, self.viewport_height)


def _delete_framebuffer(self):
    from OpenGL.GL import glDeleteFramebuffers

    if self._main_fb_ms is not None:
        glDeleteFramebuffers(1, [self._main_fb_ms])
    self._main_fb = self._main_cb = self._main_fb_ms = self._main_cb_ms = None
    self._main_db = self._main_db_ms = None
    self._main_fb_dims = (None, None)
