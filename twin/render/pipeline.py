"""CCD frames rendered, sensed, encoded and written in a second process while the physics runs (issue 17).

Why: a frame of the jia2019 sweep costs ≈ 0.2 s of CPU (GL coverage 0.13 s, sensor model
0.05 s, PNG encode 0.03 s; docs/benchmarks.md) and is a pure function of

- the posed disk (``BodyPose``, from the physics at the capture's stop),
- the instrument (``GratingSpec``, ``CcdCamera``, ``SensorParams``: fixed for the run),
- the frame's noise stream (a ``numpy.random.Generator`` keyed by the runner's step,
  ``SimBenchState.rng("ccd", key)``; pickled with its exact bit-generator state),

so it can be made anywhere. ``FramePipeline`` hands those to worker processes (two:
``frame_workers()``), each holding its GL context for the whole sweep and writing each frame's PNG
atomically (temporary sibling, fsync, rename: ``benchtwin.fsio.atomic_write_bytes``), while the
caller's process goes on stepping the servo and solving the bearings. Same code, same arguments:
the files are byte-identical to the serial path's (``Renderer.render`` + ``DatasetWriter.write_image``
in the caller), whichever worker made them.

- Why two workers on two cores: the CCD sweep's captures come in a burst (jia2019: all 60 within
  0.4 s, 8 s into the run), and one worker then took ≈ 10 s for them (≈ 165 ms a frame, its sensor
  model and PNG encode on one thread), ≈ 6 s of it after the physics had ended, with a core idle.
  Two workers render the backlog on both cores (docs/benchmarks.md); while the physics runs they
  share the cores, at nice ``WORKER_NICE``, with the run and its settle worker
  (twin/instruments/settle_ahead.py).
- Frames may finish out of order across workers; ``completed()`` counts the finished prefix in
  submission order. The caller (twin/simulate.py) journals a capture, and every step after it,
  only once its frame — and every frame before it — is on disk, so the journal never names a
  frame that is not complete.
- The workers die with the caller and never add a frame after it is gone (issue #31: after a
  ``kill -9`` of ``simulate`` they wrote 5 more frames, then blocked for minutes): a worker writes
  a frame's bytes into a temporary sibling (``benchtwin.fsio.stage_bytes``: fsynced, mode set)
  and the caller renames it onto its name when it collects the frame (``completed``), so only a
  live caller makes a frame appear; each worker kills itself the moment its creator is gone
  (``benchtwin.forkcall.watch_creator``) and the forkserver dies with its parent
  (``benchtwin.forkserver_guard``, its first preload). A frame staged but not collected when the
  caller fails is removed (``close``); after a ``kill -9`` at most one dot-file per worker may
  remain, which no reader takes for a frame, and a resume renders the frame again.
- Not forked from the caller: it may hold threads (EGL, OpenBLAS, OpenCV, a progress bar) and a
  forked child of a process holding a lock hangs (analysis/parallel.py); and each process creates
  its own EGL/OSMesa context (GL contexts do not survive a fork). The workers are forked from
  multiprocessing's forkserver (a fresh, single-threaded process) with the render stack imported
  once (twin/render/worker_preload.py: ≈ 2.4 s of CPU a worker when each was spawned and imported
  it itself, issue #17); ``spawn`` where the forkserver cannot serve (``worker_context``). The
  workers inherit ``MUJOCO_GL``/``PYOPENGL_PLATFORM`` from the environment (twin/render/gl.py).
- The backend is settled before the first frame: each worker creates its GL context when it
  starts and reports "pyrender", or "analytic" when ``backend="auto"`` and GL is unavailable —
  what the serial ``Renderer`` would have fallen back to. Workers that disagree fall back to the
  serial path (with a warning); a later GL failure in a worker is an error (never a silent switch
  of backend behind rows already journaled as "pyrender").
- ``frame_mode()`` decides serial or pipelined: ``BENCHTWIN_SIM_FRAMES`` = ``serial`` | ``pipeline``
  | ``auto`` (default). ``auto`` pipelines a sweep of at least ``AUTO_MIN_MPX`` megapixels on a
  machine with ≥ 2 cores, outside a process multiprocessing started (a design study's worker: its
  parent already spreads work over the cores), when the caller's main module is safe to spawn
  from (``main_is_spawn_safe``). A pool that cannot start falls back to serial
  with a warning (``FramePipeline.start`` returns None).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import warnings
from collections import deque
from concurrent import futures     # futures.wait: ``wait`` is close()'s parameter here
from concurrent.futures import Future, ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.runtime import env_choice, env_whole_number, in_pool_worker, usable_cores

__all__ = ["FramePipeline", "frame_mode", "frame_workers", "main_is_spawn_safe", "render_and_write", "worker_context",
           "FRAMES_ENV", "WORKERS_ENV", "AUTO_MIN_MPX", "FRAME_WORKERS", "PRELOAD_MODULE"]

#: environment variable choosing the frame path of ``simulate``: serial | pipeline | auto
FRAMES_ENV = "BENCHTWIN_SIM_FRAMES"
#: environment variable overriding the number of frame workers (a whole number ≥ 1)
WORKERS_ENV = "BENCHTWIN_SIM_FRAME_WORKERS"
#: frame workers at most (fewer on fewer cores): two fill a 2-core machine once the physics ends;
#: each is a process of its own (interpreter, GL context, a frame's working memory)
FRAME_WORKERS = 2
#: niceness of the frame workers (POSIX nice): the caller's physics is the run's critical path
WORKER_NICE = 10
#: ``auto`` pipelines sweeps of at least this many megapixels: the workers cost ≈ 2.4 s of CPU to
#: start (the forkserver's interpreter, NumPy, OpenCV, pyrender; then ≈ 0.1 s a worker for its
#: fork and GL context; spawned, 2.4 s each), ≈ 12 full 2048×1536 frames' work (0.2 s each, spent
#: before the sweep's captures in a long run); smaller sweeps (the test suite's 128×96 frames) stay
#: in the caller's process.
AUTO_MIN_MPX = 30.0
#: seconds to wait for the worker to start and report its backend before falling back to serial
START_TIMEOUT_S = 120.0

#: the module the forkserver imports before it forks the workers (twin/render/worker_preload.py)
PRELOAD_MODULE = "benchtwin.twin.render.worker_preload"
#: imported by the forkserver before ``PRELOAD_MODULE``: it dies with its parent (benchtwin/forkserver_guard.py)
GUARD_MODULE = "benchtwin.forkserver_guard"

_worker: dict[str, Any] = {}
#: the GL platform this process's forkserver was started with (``worker_context``)
_forkserver_platform: dict[str, tuple[str | None, str | None]] = {}


def frame_mode(n_frames: int, width_px: int, height_px: int, live: bool = False) -> str:
    """``"serial"`` or ``"pipeline"`` for a sweep of ``n_frames`` frames (see the module docstring).
    ``live``: a live view watches the run (it is served from this process; frames stay serial)."""
    env = env_choice(FRAMES_ENV, ("serial", "pipeline", "auto"), "auto")
    if n_frames <= 0 or live:
        return "serial"
    if env != "auto":
        return env
    if in_pool_worker() or not main_is_spawn_safe():
        return "serial"
    if usable_cores() < 2:
        return "serial"
    return "pipeline" if n_frames * width_px * height_px >= AUTO_MIN_MPX * 1e6 else "serial"


def frame_workers() -> int:
    """Worker processes of a pipelined sweep: ``BENCHTWIN_SIM_FRAME_WORKERS`` if set, else
    min(cores, ``FRAME_WORKERS``)."""
    n = env_whole_number(WORKERS_ENV, "frame workers")
    if n is not None:
        return n
    return max(1, min(usable_cores(), FRAME_WORKERS))


def main_is_spawn_safe() -> bool:
    """Whether a ``spawn``ed child can start without running the caller's script again.
    ``multiprocessing``'s spawn (and the forkserver's children) import the parent's ``__main__`` in
    the child (as ``__mp_main__``),
    except a package's ``__main__`` (``python -m pytest``) and an interactive session; a script
    without the ``if __name__ == "__main__":`` guard would run its whole body — a second
    simulation — in the frame worker. So ``auto`` pipelines only when the main module is not
    imported in the child or its source has that guard (the ``benchtwin`` console script has it)."""
    import sys

    main = sys.modules.get("__main__")
    if main is None:
        return True
    spec = getattr(main, "__spec__", None)
    name = getattr(spec, "name", None)
    if name is not None and (name == "__main__" or name.endswith(".__main__")):
        return True
    path = getattr(spec, "origin", None) if name is not None else getattr(main, "__file__", None)
    if not path:
        return True     # interactive: nothing to re-import
    try:
        src = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return False
    return "__name__" in src and "__main__" in src


def worker_context() -> Any:
    """The multiprocessing context the frame workers start from: the forkserver with the render
    stack preloaded (``worker_preload``), else ``spawn``.

    The forkserver is one per process, started by the first pipeline that asks for it, and keeps
    the environment it started with; PyOpenGL binds its GL platform at import. So it is used only
    while the GL platform (``MUJOCO_GL``, ``PYOPENGL_PLATFORM`` after ``gl.configure``) is the one
    it was started with; a process that changes it afterwards (a test) gets spawned workers, which
    read the current environment. Where there is no forkserver (Windows), spawn. A forkserver that
    something else in the process started first (a design study's pool) has not imported the render
    stack: its workers import it themselves, as spawned ones do (the same frames, later)."""
    from benchtwin.twin.render import gl

    gl.configure()
    platform = (os.environ.get("MUJOCO_GL"), os.environ.get("PYOPENGL_PLATFORM"))
    try:
        ctx = mp.get_context("forkserver")
    except ValueError:  # pragma: no cover - no forkserver on this platform
        return mp.get_context("spawn")
    if _forkserver_platform.setdefault("gl", platform) != platform:
        return mp.get_context("spawn")
    ctx.set_forkserver_preload([GUARD_MODULE, PRELOAD_MODULE])
    return ctx


def _kill_forkserver() -> None:
    """Kill this process's multiprocessing forkserver (one that does not answer)."""
    import signal
    from multiprocessing import forkserver

    pid = getattr(getattr(forkserver, "_forkserver", None), "_forkserver_pid", None)
    if pid:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


# ------------------------------------------------------------------------------ worker side

def _init_worker(backend: str, grating: Any, camera: Any, sensor: Any) -> None:
    from benchtwin.forkcall import watch_creator
    from benchtwin.heap import keep_freed_memory

    watch_creator()     # this worker ends with the run that started it (issue #31)

    # a frame's 12 MB temporaries reused from frame to frame instead of fresh pages from the
    # kernel (≈ 3000 page faults, 15 ms of kernel CPU a frame; benchtwin/heap.py): this process only makes frames
    keep_freed_memory()
    # the caller's physics first: the frames fill the cores around it (each capture's frame is
    # wanted only when the run has ended, docs/benchmarks.md); once the physics ends they have both
    os.nice(WORKER_NICE)
    try:
        import cv2

        cv2.setNumThreads(1)   # one frame at a time; the caller's physics has the other core
    except ImportError:  # pragma: no cover - OpenCV is a dependency
        pass
    _worker.clear()
    _worker.update(backend=backend, grating=grating, camera=camera, sensor=sensor, renderer=None, used=None,
                   error=None)
    # the renderer and its GL context now, before the first frame (every worker starts at once:
    # FramePipeline._start_workers); a failure is reported by ``probe``
    try:
        _worker["used"] = _make_renderer()
    except Exception as exc:  # noqa: BLE001 - handed to the caller through probe()
        _worker["error"] = exc


def probe() -> str:
    """Worker: the backend frames will use (its renderer was made when the worker started); the
    error if it could not be made."""
    if _worker["error"] is not None:
        raise _worker["error"]
    return str(_worker["used"])


def _make_renderer() -> str:
    """Worker: create the renderer (and its GL context); the backend frames will use."""
    from benchtwin.twin.render import Renderer

    backend, cam = _worker["backend"], _worker["camera"]
    used = "analytic"
    if backend in ("auto", "pyrender"):
        r = Renderer("pyrender")
        try:
            r._gl_renderer(cam.width_px, cam.height_px)
            used = "pyrender"
        except Exception:
            r.close()
            if backend == "pyrender":
                raise
            r = Renderer("analytic")
    else:
        r = Renderer("analytic")
    _worker["renderer"] = r
    return used


def render_and_write(path: str, disk: Any, rng: np.random.Generator) -> tuple[str, str]:
    """Worker: one frame from the posed disk and its noise stream, its PNG written complete to a
    temporary sibling of ``path``; returns (that file, the backend). The caller renames it onto
    ``path`` (``FramePipeline.completed``): a worker never makes a frame appear by itself."""
    import signal

    from benchtwin.analysis.dataset import encode_png
    from benchtwin.forkcall import creator_alive
    from benchtwin.fsio import stage_bytes

    w = _worker
    frame = w["renderer"].render(disk, w["grating"], w["camera"], w["sensor"], rng)
    png = encode_png(path, frame.image)
    if not creator_alive():     # the run is gone: write nothing into its folder
        os.kill(os.getpid(), signal.SIGKILL)
    return str(stage_bytes(path, png)), str(frame.truth["backend"])


# ------------------------------------------------------------------------------ caller side

class FramePipeline:
    """Worker processes rendering and writing frames, completed in submission order (see module
    docstring)."""

    def __init__(self, pool: ProcessPoolExecutor, n_workers: int):
        self._pool: ProcessPoolExecutor | None = pool
        self._n_workers = n_workers
        self._started: list[Future] | None = None    # one probe per worker, once they are started
        self._failed = False
        self._backend: str | None = None
        self._pending: deque[tuple[str, Future]] = deque()   # (frame path, its worker's future)
        self.submitted = 0
        self.done = 0

    @classmethod
    def start(cls, backend: str, grating: Any, camera: Any, sensor: Any) -> "FramePipeline | None":
        """Start the workers in the background; None if the pool cannot be created.

        Spawned workers start now (each imports the render stack itself while the caller's physics
        runs). From the forkserver, only the server starts now: it imports the render stack in the
        background, and the workers are forked from it when the first frame is wanted (``backend``:
        a fork and a GL context, ≈ 0.1 s), because the first worker's start waits for the server's
        imports (≈ 2 s of the caller's time at the start of its run if the workers started here)."""
        n = frame_workers()     # a bad BENCHTWIN_SIM_FRAME_WORKERS is the user's error (exit 2), not the host's
        try:
            ctx = worker_context()
            pool = ProcessPoolExecutor(max_workers=n, mp_context=ctx,
                                       initializer=_init_worker, initargs=(backend, grating, camera, sensor))
            pipe = cls(pool, n)
            if ctx.get_start_method() == "forkserver":
                from multiprocessing import forkserver

                forkserver.ensure_running()
            else:
                pipe._start_workers()
            return pipe
        except Exception as exc:  # pragma: no cover - depends on the host (no /dev/shm, no fork/spawn)
            warnings.warn(f"frame pipeline unavailable ({type(exc).__name__}: {exc}); rendering frames serially",
                          RuntimeWarning, stacklevel=2)
            return None

    def _start_workers(self) -> None:
        # one probe per worker: each submit finds no idle worker and starts the next, so all start
        # now (their imports, if any, and GL contexts)
        if self._started is None and self._pool is not None:
            self._started = [self._pool.submit(probe) for _ in range(self._n_workers)]

    def _start_workers_within(self, timeout_s: float) -> None:
        """``_start_workers``, given up after ``timeout_s``. A worker's start waits for the
        forkserver's answer, and a forkserver that never answers (under ``ulimit -v``, OpenBLAS
        loops in its thread start while the forkserver imports the render stack, issue #31) would
        hold the run for good: it is killed, which ends that wait (the run then renders its frames
        serially; the next pipeline starts a new forkserver)."""
        import threading

        if self._started is not None or self._pool is None:
            return
        failed: list[BaseException] = []

        def start() -> None:
            try:
                self._start_workers()
            except BaseException as exc:  # noqa: BLE001 - handed to the caller below
                failed.append(exc)

        t = threading.Thread(target=start, name="benchtwin-frame-workers-start", daemon=True)
        t.start()
        t.join(timeout_s)
        if t.is_alive():
            _kill_forkserver()
            t.join(timeout_s)
            if t.is_alive():    # still inside the pool's lock: leave the pool alone (no shutdown)
                self._pool = None
            raise RuntimeError(f"the frame workers' forkserver did not answer within {timeout_s:g} s")
        if failed:
            raise failed[0]

    def backend(self) -> str | None:
        """The workers' backend (starts them if they are not yet, and waits for their start); None
        if they could not start or found different backends (fall back to serial: nothing has been
        submitted yet)."""
        if self._backend is None and not self._failed:
            try:
                self._start_workers_within(START_TIMEOUT_S)
                used = {f.result(timeout=START_TIMEOUT_S) for f in self._started or []}
                if len(used) != 1:
                    raise RuntimeError(f"workers found different backends {sorted(used)}")
                self._backend = used.pop()
            except Exception as exc:
                warnings.warn(f"frame pipeline did not start ({type(exc).__name__}: {exc}); "
                              "rendering frames serially", RuntimeWarning, stacklevel=2)
                self._failed = True
                self.close(wait=False)
        return self._backend

    def submit(self, path: str | Path, disk: Any, rng: np.random.Generator) -> None:
        if self._backend is None:
            raise RuntimeError("FramePipeline.submit before the worker reported its backend")
        if self._pool is None:
            raise RuntimeError("FramePipeline.submit after close")
        self._pending.append((str(path), self._pool.submit(render_and_write, str(path), disk, rng)))
        self.submitted += 1

    def completed(self, wait: bool = False) -> int:
        """Frames finished and on disk under their names (the finished prefix, in submission
        order: each renamed here from the worker's temporary file); ``wait``: all of them.
        Re-raises a frame's error."""
        from benchtwin.fsio import commit_staged, discard_staged

        while self._pending and (wait or self._pending[0][1].done()):
            path, fut = self._pending.popleft()
            tmp, used = fut.result()
            if used != self._backend:   # a worker whose probe was not asked (another took both) and whose GL failed
                discard_staged(tmp)
                raise RuntimeError(f"frame rendered by {used!r}, journaled as {self._backend!r}")
            commit_staged(tmp, path)
            self.done += 1
        return self.done

    def close(self, wait: bool = True) -> None:
        """Stop the workers: ``wait`` for the submitted frames and rename them into place (else
        cancel those not started, wait for those in flight and remove their files).
        The workers then leave in the background (their GL teardown and interpreter exit, ≈ 0.6 s
        on the run's critical path when waited for, issue #17): every frame is on disk already."""
        if self._pool is None:
            return
        if wait:
            self.completed(wait=True)
        else:   # a failed run: the frames in flight are waited for and their files removed
            for _, fut in self._pending:
                fut.cancel()
            futures.wait([fut for _, fut in self._pending], timeout=START_TIMEOUT_S)   # (a hung worker: not for good)
            self._discard_pending()
        self._pool.shutdown(wait=False, cancel_futures=not wait)
        self._pool = None

    def _discard_pending(self) -> None:
        from benchtwin.fsio import discard_staged

        while self._pending:
            _, fut = self._pending.popleft()
            if fut.done() and not fut.cancelled() and fut.exception() is None:
                discard_staged(fut.result()[0])
