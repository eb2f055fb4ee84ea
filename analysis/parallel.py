"""Ordered, bounded map over a thread pool: per-frame image analysis on both cores (issue #17).

Why: the CCD sweep's frames are independent (Jia 2019 sec. 4.2: one d_ref per image). Threads,
not processes: a frame's heavy parts are OpenCV calls (PNG decoding, thresholding, connected
parts), which release the GIL, so two threads keep two cores busy; the Python between them
(sub-pixel edges, circle fits, ~20 ms of a frame's ~55) is what the threads share. The former
``spawn`` process pool was slower than the serial loop (docs/benchmarks.md: two interpreters'
imports, ~0.5 s CPU each, and every frame pickled to a worker outweighed the second core), and it
needed every argument picklable; a thread shares the frame in memory.

Guarantees, so the parallel path is the serial path, only faster:

- results come back in input order (the caller's loop, its progress bar and its error order are
  unchanged), and each call is the same pure function on the same arguments (no shared mutable
  state: each call builds its own arrays), so the results are bit-identical to a serial loop
  whatever the threads' scheduling (tests/analysis/test_parallel_frames.py checks results.json and
  the per-frame results);
- at most ``window`` items are in flight: a long sweep of large frames is not all held in memory
  (the serial loop held one frame at a time);
- ``workers <= 1`` (or one item) runs in the calling thread, no pool;
- an exception raised by ``fn`` is re-raised here, in order, like the serial loop would; so is one
  raised by ``items`` itself (a dataset error on reading frame k): only after the results of the
  items before it, as the serial loop would meet it.

``BENCHTWIN_WORKERS`` (environment) overrides the default worker count in :func:`default_workers`
(1 = serial in the calling thread).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, TypeVar

__all__ = ["default_workers", "ordered_map"]

T = TypeVar("T")
R = TypeVar("R")

#: default upper bound on the worker count. Measured (the step on the default jia2019 dataset, 60
#: frames of 2048×1536, 2 cores shared with other sessions at load 2.4–5.1; 9 fresh processes
#: alternating with main's): 2 threads took the step's wall to a median 0.94 of the serial loop's
#: (0.65–1.18) for the same CPU (5.90 vs 5.93 s). The scheduler shares the cores between sessions:
#: only 2 of the 9 processes got more than one core (1.35, 1.48), and there 2 threads took 0.77 and
#: 0.76 of the serial wall. A serial profile puts ≈ 40 % of the step in calls that
#: release the GIL (PNG decode, labelling, thresholds, hashing): ≈ 0.6 of serial is the most 2 threads
#: can give, and a third has no core here. So 2; BENCHTWIN_WORKERS=1 gives the serial loop
MAX_DEFAULT_WORKERS = 2


def default_workers() -> int:
    """Worker threads for per-frame analysis: ``BENCHTWIN_WORKERS`` if set, else
    min(cores, MAX_DEFAULT_WORKERS),
    and 1 in a process that multiprocessing started (a design study's pool worker, a Dask worker):
    its parent already spreads the work over the cores."""
    from benchtwin.runtime import env_whole_number, in_pool_worker, usable_cores

    n = env_whole_number("BENCHTWIN_WORKERS", "worker threads")
    if n is not None:
        return n
    if in_pool_worker():
        return 1
    return max(1, min(usable_cores(), MAX_DEFAULT_WORKERS))


def ordered_map(fn: Callable[..., R], items: Iterable[tuple[Any, ...]], workers: int | None = None,
                window: int | None = None) -> Iterator[R]:
    """``fn(*args)`` for each ``args`` tuple of ``items``, yielded in order.

    ``workers``: threads (default :func:`default_workers`); ``window``: items in flight at most
    (default 2 × workers). ``fn`` must not change shared state (it runs in several threads at once);
    ``items`` is iterated in the calling thread only.
    """
    n = default_workers() if workers is None else max(1, int(workers))
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
    win = max(n, int(window) if window else 2 * n)
    pending: deque[Future[R]] = deque()
    with ThreadPoolExecutor(max_workers=n, thread_name_prefix="benchtwin-frames") as pool:
        try:
            pending.append(pool.submit(fn, *first))
            pending.append(pool.submit(fn, *second))
            while True:
                try:
                    args = next(it)
                except StopIteration:
                    break
                except BaseException:
                    # the serial loop would have finished the items before this one first (and
                    # raised their errors first): so do we, then raise this one
                    while pending:
                        yield pending.popleft().result()
                    raise
                while len(pending) >= win:
                    yield pending.popleft().result()
                pending.append(pool.submit(fn, *args))
            while pending:
                yield pending.popleft().result()
        finally:
            for f in pending:
                f.cancel()
