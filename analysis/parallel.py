"""Ordered, bounded map over a process pool: per-frame image analysis on every core (issue #17).

Why: the CCD sweep's frames are independent (Jia 2019 sec. 4.2: one d_ref per image), and the
per-frame work (threshold, connected parts, sub-pixel edges, circle fits) is single-threaded
Python/NumPy, so a pool of processes uses the machine's cores where threads would not (the GIL).

Guarantees, so the parallel path is the serial path, only faster:

- results come back in input order (the caller's loop, its progress bar and its error order are
  unchanged), and each call is the same pure function on the same arguments, so the results are
  bit-identical to a serial loop (tests/analysis/test_parallel_frames.py checks results.json);
- at most ``window`` items are in flight: a long sweep of large frames is not all held in memory
  (the serial loop held one frame at a time);
- ``workers <= 1`` (or one item) runs in this process, no pool; so does a daemonic process;
- an exception raised by ``fn`` is re-raised here, in order, like the serial loop would.

The pool starts its workers with ``spawn`` (a fresh interpreter that imports ``fn``'s module,
~0.5 s of CPU per worker). Not ``fork``: the caller may hold threads (OpenGL/EGL, OpenCV's and
OpenBLAS's pools, a progress bar's monitor), and a child forked while one of them held a lock
hangs for ever (seen in the test suite after a simulate in the same process). Not
``forkserver``: its server is never reaped by the caller, so the CPU time of the workers would
vanish from the caller's accounting (benchmarks/run_bench.py reports CPU time). Each worker sets
OpenCV to one thread: the pool already uses every core.

``BENCHTWIN_WORKERS`` (environment) overrides the default worker count in :func:`default_workers`
(1, i.e. serial, as measured: see ``MAX_DEFAULT_WORKERS``; ``BENCHTWIN_WORKERS=2`` for the pool).
"""

from __future__ import annotations

import multiprocessing as mp
import os
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any, TypeVar

__all__ = ["default_workers", "ordered_map"]

T = TypeVar("T")
R = TypeVar("R")

#: default upper bound on the worker count. Measured (benchmarks/ecc_bench.py, default jia2019
#: dataset, 60 frames of 2048×1536, 2 cores): at load ≈ 2 the pool of 2 took 6.9 s wall / 8.4 s CPU
#: against 6.2 s / 6.4 s serial (two spawned interpreters' imports and the frames' pickling outweigh
#: the second core for ~0.1 s of work a frame); at load ≈ 20, 55.9 s against 61.0 s wall. So the
#: default is serial; BENCHTWIN_WORKERS=2 turns the pool on (larger or more frames)
MAX_DEFAULT_WORKERS = 1


def default_workers() -> int:
    """Worker processes for per-frame analysis: ``BENCHTWIN_WORKERS`` if set, else
    min(cores, MAX_DEFAULT_WORKERS),
    and 1 in a process that multiprocessing started (a design study's pool worker, a Dask worker):
    its parent already spreads the work over the cores, and a daemonic process may not have children."""
    env = os.environ.get("BENCHTWIN_WORKERS", "").strip()
    if env:
        try:
            n = int(env)
        except ValueError:
            raise ValueError(f"BENCHTWIN_WORKERS={env!r}: expected a whole number of worker processes") from None
        return max(1, n)
    if mp.parent_process() is not None or mp.current_process().daemon:
        return 1
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return max(1, min(cores, MAX_DEFAULT_WORKERS))


def _init_worker() -> None:
    try:
        import cv2

        cv2.setNumThreads(1)
    except ImportError:  # pragma: no cover - OpenCV is a dependency; a worker without it still works
        pass


def ordered_map(fn: Callable[..., R], items: Iterable[tuple[Any, ...]], workers: int | None = None,
                window: int | None = None) -> Iterator[R]:
    """``fn(*args)`` for each ``args`` tuple of ``items``, yielded in order.

    ``workers``: processes (default :func:`default_workers`); ``window``: items in flight at most
    (default 2 × workers). ``fn`` must be a module-level function (picklable), its arguments and
    results picklable.
    """
    n = default_workers() if workers is None else max(1, int(workers))
    if mp.current_process().daemon:
        n = 1  # a daemonic process (e.g. a Dask worker) may not start children
    it = iter(items)
    if n <= 1:
        for args in it:
            yield fn(*args)
        return
    first = next(it, None)
    if first is None:
        return
    second = next(it, None)
    if second is None:  # one item: not worth a pool
        yield fn(*first)
        return
    ctx = mp.get_context("spawn")
    win = max(n, int(window) if window else 2 * n)
    pending: deque[Future[R]] = deque()
    with ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=_init_worker) as pool:
        try:
            pending.append(pool.submit(fn, *first))
            pending.append(pool.submit(fn, *second))
            for args in it:
                while len(pending) >= win:
                    yield pending.popleft().result()
                pending.append(pool.submit(fn, *args))
            while pending:
                yield pending.popleft().result()
        finally:
            for f in pending:
                f.cancel()
