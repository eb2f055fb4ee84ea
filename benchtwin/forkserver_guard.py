"""Imported first by the frame workers' forkserver (twin/render/pipeline.py ``worker_context``):
the forkserver dies with the process that started it (issue #31).

Why a module of its own, imported before anything else: the forkserver is a fresh interpreter
that multiprocessing starts by ``exec``, so nothing of the caller runs in it before its preload
imports. It normally leaves when its last client is gone (the "alive" pipe every client holds
reads EOF), but only from its serving loop: a forkserver still importing the render stack never
sees it (under ``ulimit -v`` OpenBLAS's thread start loops on a failed allocation, and the
forkserver spun for good after its ``simulate`` had ended). So it asks Linux, before NumPy is
loaded, to kill it when its parent ends (``benchtwin.forkcall.die_with_parent``: the thread that
started it, ``FramePipeline.start`` on the run's thread). Importing this module anywhere but as
the forkserver's preload would tie that process to its parent: only ``worker_context`` names it.
This imports nothing heavy (``benchtwin`` and ``benchtwin.forkcall`` load only the standard
library).
"""

from __future__ import annotations

import os

from benchtwin.forkcall import die_with_parent

die_with_parent(os.getppid())
