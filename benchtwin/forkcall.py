"""A function called in a forked child while the caller goes on (POSIX ``fork``, one level).

Why a fork and not a spawned process: the child must see the caller's objects bit for bit as they
are at the call, without pickling them (a MuJoCo model and data, a bench's warm starts and cached
paths). ``simulate`` computes the truth's α grid (about a quarter of its CPU) in such a child
while the run steps, and ``benchtwin run`` computes the grid and writes the truth in one while the
analysis reads the measured dataset (issue #17); the truth is the same bytes as an in-process
call's (tests/twin/test_truth_apart.py). (The servo's settle worker, twin/instruments/
settle_ahead.py, is a fork too, but streams many results: it has its own pipe.)

Fork safety, and why it holds for what is called here: the child is a copy of the caller with
only the calling thread. A lock another thread held at the fork stays held in the child, so the
function must not need one: it must not print, log, use a progress bar, OpenGL or OpenCV's pool
(analysis/parallel.py and twin/render/pipeline.py spawn for that reason). NumPy's OpenBLAS pool
is re-made by its own ``pthread_atfork`` handlers. The child leaves by ``os._exit``: no ``atexit``
handler, no multiprocessing finaliser (which would try to join the caller's workers), no flush of
the caller's buffered output (which would print it twice).

Errors: an exception in the child is pickled back through a pipe and raised again by ``wait()``
(its type kept, so a ``DatasetError`` still ends the command with exit 2); a child killed by a
signal is a ``ForkCallError`` naming the signal. Used as a context manager, a child not waited
for by the end of the block is cancelled (the caller failed). A child dies with its parent (Linux: a killed
command leaves nothing computing). Where ``os.fork`` does not exist, or with
``BENCHTWIN_FORK=0``, the function is called at once in the caller (same result, no overlap).
"""

from __future__ import annotations

import os
import pickle
import signal
import traceback
from collections.abc import Callable
from typing import Any

ENV = "BENCHTWIN_FORK"


class ForkCallError(RuntimeError):
    """The forked child died without reporting (killed by a signal, or its report was unreadable)."""


def fork_enabled() -> bool:
    return hasattr(os, "fork") and os.environ.get(ENV, "1").strip().lower() not in ("0", "no", "off", "false")


class ForkCall:
    """``fn()`` running in a forked child; ``wait()`` returns its (pickled) value when it is done,
    or raises its error."""

    def __init__(self, fn: Callable[[], Any], what: str = "child", nice: int = 0):
        """``nice``: added to the child's niceness (POSIX ``nice``), for a child whose result is
        wanted only later: the caller's work on the critical path keeps its core."""
        self.what = what
        self._pid: int | None = None
        self._fd: int | None = None
        self._done = False
        self._value: Any = None
        if not fork_enabled():
            self._value = fn()      # in the caller: the same work, no overlap
            self._done = True
            return
        r, w = os.pipe()
        parent = os.getpid()
        pid = os.fork()
        if pid == 0:        # the child: run, report, leave without the caller's exit handlers
            os.close(r)
            code = 0
            try:
                die_with_parent(parent)
                if nice:
                    os.nice(nice)
                _send(w, pickle.dumps(("ok", fn())))
            except BaseException as exc:  # noqa: BLE001 - every failure goes back to the caller
                code = 1
                _report(w, exc)
            finally:
                os._exit(code)
        os.close(w)
        self._pid, self._fd = pid, r

    def __enter__(self) -> "ForkCall":
        return self

    def __exit__(self, *exc: object) -> None:
        # leaving the block without having waited (the caller failed): stop the child
        self.cancel()

    @property
    def forked(self) -> bool:
        return self._pid is not None

    def wait(self) -> Any:
        """Block until the child is done and return ``fn()``'s value; raise its exception (or
        ``ForkCallError``) if it failed."""
        if self._done:
            return self._value
        assert self._pid is not None and self._fd is not None
        chunks = []
        with os.fdopen(self._fd, "rb") as fh:   # to EOF: the child's report, if any (before reaping)
            self._fd = None
            while True:
                b = fh.read(65536)
                if not b:
                    break
                chunks.append(b)
        _, status = os.waitpid(self._pid, 0)
        self._done = True
        report = b"".join(chunks)
        if os.WIFSIGNALED(status):
            sig = os.WTERMSIG(status)
            raise ForkCallError(f"{self.what}: killed by signal {signal.Signals(sig).name}")
        code = os.WEXITSTATUS(status)
        try:
            kind, *rest = pickle.loads(report)
        except Exception:  # noqa: BLE001 - an unreadable report is still a failure
            raise ForkCallError(f"{self.what}: exited with status {code}") from None
        if code == 0 and kind == "ok":
            self._value = rest[0]
            return self._value
        exc, tb = rest if len(rest) == 2 else (None, f"exit status {code}")
        if isinstance(exc, BaseException):
            raise exc from ForkCallError(f"{self.what} failed:\n{tb}")
        raise ForkCallError(f"{self.what} failed:\n{tb}")

    def cancel(self) -> None:
        """Stop the child (the caller failed and will not use its result) and reap it."""
        if self._done or self._pid is None:
            return
        try:
            os.kill(self._pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        os.waitpid(self._pid, 0)
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        self._done = True


def die_with_parent(parent: int) -> None:
    """Linux: this child is killed when its parent dies (``prctl(PR_SET_PDEATHSIG, SIGKILL)``), so
    a killed command leaves no child computing for nobody; elsewhere nothing. Linux sends the
    signal when the *thread* that forked the child ends: every ForkCall here is waited for (or
    cancelled) by the call that made it, on that thread, so that thread outlives its child."""
    import sys

    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)     # 1 = PR_SET_PDEATHSIG (linux/prctl.h)
    except (OSError, AttributeError):  # pragma: no cover - not glibc/musl: the child just finishes
        return
    if os.getppid() != parent:      # the parent died before prctl took effect
        os._exit(1)


def watch_creator() -> None:
    """A multiprocessing worker (a pool's: the frame workers, a study's points) ends the moment the
    process that created it ends (issue #31: after ``kill -9`` of ``simulate`` its frame workers
    wrote 5 more frames, then blocked for minutes on their task queue, which they hold open
    themselves).

    - Its creator is multiprocessing's ``parent_process()``, whose sentinel (a pipe the creator
      holds open) reads as closed once the creator is gone, however it died. A daemon thread waits
      on it and kills this process (SIGKILL: no exit handler, no flush, no half-finished write
      completed). This works for a worker forked by the forkserver, whose OS parent is the
      forkserver (PR_SET_PDEATHSIG cannot name a grandparent).
    - Where the OS parent is the creator (a spawned worker), ``die_with_parent`` as well: the
      kernel kills it without waiting for the thread to be scheduled.
    Not a multiprocessing child: nothing to do."""
    import multiprocessing as mp
    import threading

    creator = mp.parent_process()
    if creator is None:
        return
    if creator.pid is not None and os.getppid() == creator.pid:
        die_with_parent(creator.pid)
    sentinel = creator.sentinel

    def watch() -> None:
        from multiprocessing.connection import wait

        wait([sentinel])
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="benchtwin-creator-watch", daemon=True).start()


def creator_alive() -> bool:
    """Whether the process that created this multiprocessing worker still runs (True outside
    one). A worker asks before it writes into its creator's output (twin/render/pipeline.py)."""
    import multiprocessing as mp
    from multiprocessing.connection import wait

    creator = mp.parent_process()
    return creator is None or not wait([creator.sentinel], 0)


def _report(fd: int, exc: BaseException) -> None:
    tb = "".join(traceback.format_exception(exc))
    try:
        data = pickle.dumps(("err", exc, tb))
        pickle.loads(data)          # an exception that pickles but cannot be rebuilt is sent as text
    except Exception:  # noqa: BLE001
        data = pickle.dumps(("err", None, tb))
    _send(fd, data)


def _send(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


__all__ = ["ForkCall", "ForkCallError", "creator_alive", "die_with_parent", "fork_enabled", "watch_creator"]
