"""Headless OpenGL set-up for the CCD renderer (Jia 2019 sec. 4.2: the microscope images of the
grating edge are rendered off-screen, on machines without a GPU or a screen).

One place decides the platform so that MuJoCo's renderer and PyOpenGL (used by pyrender) agree:

- ``MUJOCO_GL`` and ``PYOPENGL_PLATFORM`` are set with ``setdefault`` to ``"egl"`` (Mesa's
  llvmpipe via EGL: 4× MSAA, which the pyrender backend relies on for quarter-pixel coverage;
  OSMesa has no multisampling) and then made equal, because both libraries load one GL platform
  per process and a mismatch fails at the first context creation, far from the cause;
- PyOpenGL reads ``PYOPENGL_PLATFORM`` at import time, so this module must run before anything
  imports ``OpenGL``/``pyrender``: pyrender is therefore only imported lazily, by ``pyrender()``;
- pyrender 0.1.45 still uses ``np.infty`` (removed in numpy 2): the alias is restored before import.
"""

from __future__ import annotations

import os
import subprocess
import sys
from functools import lru_cache

import numpy as np

DEFAULT_PLATFORM = "egl"


def configure() -> str:
    """Set up the environment for headless GL (idempotent); return the platform name.

    An explicit ``MUJOCO_GL`` wins (it is what the user or CI chose for the whole process), else an
    explicit ``PYOPENGL_PLATFORM``, else EGL. If OpenGL was already imported with another platform,
    nothing can be changed any more: the already-loaded platform is reported.
    """
    platform = os.environ.get("MUJOCO_GL") or os.environ.get("PYOPENGL_PLATFORM") or DEFAULT_PLATFORM
    if "OpenGL" in sys.modules and os.environ.get("PYOPENGL_PLATFORM"):
        # PyOpenGL has bound its platform already; changing the variable now would only lie.
        platform = os.environ["PYOPENGL_PLATFORM"]
    os.environ.setdefault("MUJOCO_GL", platform)
    os.environ.setdefault("PYOPENGL_PLATFORM", platform)
    if os.environ["MUJOCO_GL"] != os.environ["PYOPENGL_PLATFORM"] and "OpenGL" not in sys.modules:
        os.environ["PYOPENGL_PLATFORM"] = os.environ["MUJOCO_GL"]
    # pyrender 0.1.45 (scene.py, camera.py) uses numpy 1's alias np.infty, which numpy 2 removed (and
    # its stubs do not declare): put it back in the module's namespace when it is missing
    vars(np).setdefault("infty", np.inf)
    return os.environ["PYOPENGL_PLATFORM"]


def pyrender():
    """The pyrender module, imported after ``configure()``."""
    configure()
    import pyrender as _pyrender

    return _pyrender


_PROBE = """
import numpy as np
np.infty = np.inf
import pyrender as pr
r = pr.OffscreenRenderer(8, 8)
s = pr.Scene(bg_color=[1.0, 1.0, 1.0, 1.0])
s.add(pr.OrthographicCamera(xmag=4.0, ymag=4.0, znear=0.1, zfar=10.0))
c, _ = r.render(s, flags=pr.RenderFlags.FLAT)
assert c.shape == (8, 8, 3) and int(c.min()) == 255, c
r.delete()
"""


@lru_cache(maxsize=1)
def _probe() -> tuple[bool, str]:
    # In a child process: creating and deleting an EGL context here could tear down the display
    # that MuJoCo renderers of this process share (Mesa's eglTerminate is not reference-counted),
    # and a crashing driver must not take the caller down with it.
    platform = configure()
    env = dict(os.environ, PYOPENGL_PLATFORM=platform, MUJOCO_GL=platform)
    try:
        res = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return False, f"GL probe could not run: {exc}"
    if res.returncode != 0:
        tail = (res.stderr.strip().splitlines() or ["(no message)"])[-1]
        return False, f"no OpenGL context via {platform}: {tail}"
    return True, f"OpenGL via {platform}"


def gl_available() -> bool:
    """Whether an off-screen OpenGL context can be created here (probed once per process)."""
    return _probe()[0]


def gl_status() -> str:
    """Why ``gl_available()`` said what it said (for skip reasons and error messages)."""
    return _probe()[1]
