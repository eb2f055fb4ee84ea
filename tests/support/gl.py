"""The one OpenGL skip marker of the tests that render through pyrender."""

from __future__ import annotations

import pytest

from benchtwin.twin.render.gl import gl_available, gl_status

GL = gl_available()
needs_gl = pytest.mark.skipif(not GL, reason=f"no OpenGL context: {gl_status() if not GL else ''}")
