"""Where `benchtwin run`'s wall time goes: a timeline of its phases in one process (issue #17).

``run_bench.py`` gives each stage's total against its floor; this script shows the critical path
inside one ``benchtwin run``: when the run's steps end, when the CCD frames are submitted to the
frame workers and when they are on disk, each analysis step, the report and the truth's wait. Each
line: wall seconds since the start, CPU seconds of this process (all its threads) and of its reaped
children (the truth's and the report's forked children are counted when they end; the frame
workers, children of the forkserver, at the last line).

It wraps the phases' functions in this process only (nothing is changed in what they compute), so
it runs the README's command as the console script does, with ``--quiet``.

Usage: ``.venv/bin/python benchmarks/run_timeline.py OUT_DIR [scenario.toml]``
"""

from __future__ import annotations

import os
import resource
import sys
import time

T0 = time.perf_counter()


def mark(what: str) -> None:
    ru, rc = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    print(f"{time.perf_counter() - T0:7.2f} s   CPU self {ru.ru_utime + ru.ru_stime:6.2f} s   children "
          f"{rc.ru_utime + rc.ru_stime:6.2f} s   {what}", flush=True)


def wrap(owner, name: str, label: str | None = None) -> None:
    fn = getattr(owner, name)

    def timed(*a, **kw):
        mark(f"{label or name} start")
        try:
            return fn(*a, **kw)
        finally:
            mark(f"{label or name} end")

    setattr(owner, name, timed)


def main(argv: list[str]) -> None:
    if not argv or argv[0] in ("-h", "--help"):
        raise SystemExit(__doc__)
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
    import benchtwin.analysis.pipeline as AP
    import benchtwin.hw.acquisition.runner as R
    import benchtwin.twin.render.pipeline as PL
    import benchtwin.twin.simulate as S
    from benchtwin.cli import main as cli

    mark("imports done")
    wrap(R.Runner, "run", "run's steps")
    wrap(S._FrameGatedRunner, "drain", "frames' backlog (drain)")
    wrap(S.ForkCall, "wait", "wait for a forked child")
    for name in ("step_radial_motion", "step_eccentricity", "step_polygon", "_close_loop", "_write_report"):
        wrap(AP, name)
    wrap(AP, "analyze")
    frames: list[tuple[float, float | None]] = []
    submit = PL.FramePipeline.submit

    def timed_submit(self, *a, **kw):
        i = len(frames)
        frames.append((time.perf_counter() - T0, None))
        submit(self, *a, **kw)
        self._pending[-1].add_done_callback(
            lambda _f, i=i: frames.__setitem__(i, (frames[i][0], time.perf_counter() - T0)))

    PL.FramePipeline.submit = timed_submit
    args = ["run", "--quiet", "-o", argv[0], "--force"] + ([argv[1]] if len(argv) > 1 else [])
    try:
        rc = cli(args)
    finally:
        mark("end")
    # The frame workers are children of multiprocessing's forkserver (twin/render/pipeline.py), not
    # of this process: their CPU is counted once the forkserver is stopped and reaped here.
    from multiprocessing import forkserver

    forkserver._forkserver._stop()
    mark("the frame workers' forkserver reaped (its workers' CPU now in children)")
    if frames:
        sub = [s for s, _ in frames]
        done = [d for _, d in frames if d is not None]
        print(f"frames: {len(frames)} submitted {min(sub):.2f}–{max(sub):.2f} s, on disk "
              f"{min(done):.2f}–{max(done):.2f} s ({len(done)} seen), "
              f"{(max(done) - min(sub)) / len(frames) * 1e3:.0f} ms a frame through the workers")
    raise SystemExit(rc)


if __name__ == "__main__":
    main(sys.argv[1:])
