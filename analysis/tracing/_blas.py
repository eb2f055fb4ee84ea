"""One BLAS thread for the tracing's many small least-squares fits (a performance guard, no
numerics: the results do not depend on the thread count of these fits).
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numpy as np


# ----------------------------------------------------------------------------------------------
# BLAS threads: the fits are hundreds of small least-squares problems; a multi-threaded OpenBLAS
# on a busy machine spends more time spinning than computing (measured: 25× slower on 2 busy
# cores). Run them on one thread and restore the setting afterwards (no-op if not found).
# ----------------------------------------------------------------------------------------------

#: OpenBLAS's (get_num_threads, set_num_threads)
_Threads = tuple[Any, Any]
_F = TypeVar("_F", bound=Callable[..., Any])


def _openblas() -> _Threads | None:
    import ctypes
    import glob

    d = os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs")
    for f in glob.glob(os.path.join(d, "*openblas*")):
        try:
            lib = ctypes.CDLL(f)
            for pre in ("scipy_openblas_", "openblas_"):
                for suf in ("64_", ""):
                    g, s_ = getattr(lib, f"{pre}get_num_threads{suf}", None), getattr(lib, f"{pre}set_num_threads{suf}", None)
                    if g is not None and s_ is not None:
                        s_.argtypes = [ctypes.c_int]
                        return g, s_
        except OSError:
            continue
    return None


#: None: not looked up yet; False: not found (no-op)
_BLAS: _Threads | bool | None = None


def _one_blas_thread(fn: _F) -> _F:

    @functools.wraps(fn)
    def wrapper(*a, **k):
        global _BLAS
        if _BLAS is None:
            try:
                _BLAS = _openblas() or False
            except Exception:  # pragma: no cover - platform specific
                _BLAS = False
        if not isinstance(_BLAS, tuple):      # False: no OpenBLAS found
            return fn(*a, **k)
        get, set_ = _BLAS
        n = int(get())
        set_(1)
        try:
            return fn(*a, **k)
        finally:
            set_(n)
    return cast(_F, wrapper)
