"""Keep a frame process's freed memory for its next frame (issue 17: the cost of a CCD frame).

Why: a CCD frame makes a dozen 3 Mpx temporaries (12 MB float32: irradiance, dust map, blur, mean
electrons, noise; the PNG encoder's buffers), freed at the end of the frame. glibc's malloc
(``mallopt(3)``) serves a request above ``M_MMAP_THRESHOLD`` (dynamic: 128 kB, raised up to 32 MB
by each free of such a block) with a fresh ``mmap`` and unmaps it on free, and gives the top of
the heap back to the kernel when more than ``M_TRIM_THRESHOLD`` of it is free. Either way the next
frame's arrays arrive as fresh zero-filled pages: ≈ 3000 minor page faults a frame, 15–19 ms of
kernel CPU measured (``getrusage``) against ≈ 1 ms with the thresholds fixed — the same values
computed, the kernel's time only.

``keep_freed_memory()`` fixes both thresholds (fixing them also turns the dynamic adjustment off):
blocks up to 32 MB (glibc's largest mmap threshold on 64-bit) come from the heap, and the heap is
not trimmed below 1 GB free, so a process keeps about its peak frame's memory. Meant for a
process that makes frames and nothing else (the frame worker of ``twin/render/pipeline.py``, the
benchmarks), not for the caller's process. It was also tried in the commands that analyse frames
(``analyze``: 211 k → 83 k minor page faults, 1.9 → 0.7 s of kernel CPU) and withdrawn: in a
long-lived process that also forks and uses EGL (the test suite calling the commands in-process),
the bench picture's EGL context then failed to initialise (EGL_NOT_INITIALIZED) in 10 tests; not
explained, gone with either the fork or the thresholds off. Elsewhere (not glibc) it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["keep_freed_memory", "MMAP_THRESHOLD", "TRIM_THRESHOLD"]

#: glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD = 32 * 1024 * 1024
TRIM_THRESHOLD = 1024 * 1024 * 1024


def keep_freed_memory() -> bool:
    """Fix glibc's mmap and trim thresholds for this process; True if both were accepted."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) & bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
