"""What a CCD frame worker imports, loaded once by the forkserver its workers are forked from (issue #17).

Why: a spawned frame worker spent ≈ 2.4 s of CPU before its first frame (measured: the interpreter
and NumPy/OpenCV 0.3 s, the renderer's modules 0.2 s, pyrender 1.5 s, of which its trimesh import
alone is 1.0 s: SciPy's spatial and sparse modules, NetworkX; its GL context 0.1 s), and a run
starts two (twin/render/pipeline.py). ``FramePipeline`` therefore starts its workers from
multiprocessing's forkserver with this module preloaded: the imports are paid once, and each
worker is a fork of a process that holds no thread, no lock and no GL context (each worker makes
its own context after the fork, as before; GL contexts do not survive a fork).

The platform is configured first (``gl.configure``: PyOpenGL binds ``PYOPENGL_PLATFORM`` at
import), from the environment the forkserver inherited when it started. Importing this module
never raises: the forkserver must start on a machine without GL too; a worker then meets the
failure when it makes its renderer and reports it through ``probe``, as a spawned worker did.
"""

from __future__ import annotations

try:
    import cv2  # noqa: F401 - the sensor model's and the PNG encoder's OpenCV

    from benchtwin.analysis.dataset import encode_png  # noqa: F401 - the frame's PNG
    from benchtwin.fsio import atomic_write_bytes  # noqa: F401 - the frame's file
    from benchtwin.heap import keep_freed_memory  # noqa: F401 - _init_worker's first call
    from benchtwin.twin.render import Renderer  # noqa: F401 - grating, sensor, analytic backend
    from benchtwin.twin.render import gl, pyrender_backend  # noqa: F401 - the GL backend's module

    gl.pyrender()   # pyrender (and trimesh, PyOpenGL on the configured platform)
except Exception:  # noqa: BLE001 - see the module docstring: the worker reports it
    pass
