"""simulate's pipelined frame path (twin/render/pipeline.py): the CCD frames rendered, sensed, encoded
and written by a spawned worker while the physics runs give the serial path's dataset byte for byte,
and a run killed while frames are in flight journals no frame that is not on disk and resumes to
the same dataset."""

from __future__ import annotations

import json

import pytest

from benchtwin.twin.render.pipeline import (FRAME_WORKERS, FRAMES_ENV, WORKERS_ENV, FramePipeline, frame_mode,
                                             frame_workers)
from benchtwin.twin.simulate import simulate

from tests.support.scenarios import files, small_scenario

# xdist: one at a time on one worker (forkservers and frame-worker pools; tests/conftest.py)
pytestmark = pytest.mark.xdist_group("serial")

# ball bearings (the path-dependent cage state must survive the resume), 8 frames of 128×96
OVR = {"procedure.polygon_shifts": ["0 deg"], "procedure.directions": ["forward"], "procedure.ccd_step": "45 deg",
       "procedure.radial_reps": 1, "procedure.radial_positions": 12, "procedure.selfcal": False,
       "bearings.type": "ball"}


@pytest.fixture(scope="module")
def serial_ref(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    mp.setenv(FRAMES_ENV, "serial")
    try:
        return simulate(small_scenario(**OVR), tmp_path_factory.mktemp("serial") / "ds", progress=False,
                        backend="analytic")
    finally:
        mp.undo()


def test_frame_mode_choice(monkeypatch):
    monkeypatch.setenv(FRAMES_ENV, "serial")
    assert frame_mode(60, 2048, 1536) == "serial"
    monkeypatch.setenv(FRAMES_ENV, "pipeline")
    assert frame_mode(4, 128, 96) == "pipeline"
    assert frame_mode(60, 2048, 1536, live=True) == "serial"   # the live view watches this process
    assert frame_mode(0, 2048, 1536) == "serial"
    monkeypatch.setenv(FRAMES_ENV, "auto")
    assert frame_mode(4, 128, 96) == "serial"                   # not worth a process
    monkeypatch.setenv(FRAMES_ENV, "sometimes")
    with pytest.raises(ValueError, match=FRAMES_ENV):
        frame_mode(60, 2048, 1536)


def test_frame_workers(monkeypatch):
    import os

    from benchtwin.runtime import EnvVarError

    monkeypatch.delenv(WORKERS_ENV, raising=False)
    assert frame_workers() == max(1, min(len(os.sched_getaffinity(0)), FRAME_WORKERS))
    monkeypatch.setenv(WORKERS_ENV, "3")
    assert frame_workers() == 3
    for bad in ("0", "-1", "two", "1.5"):
        monkeypatch.setenv(WORKERS_ENV, bad)
        with pytest.raises(EnvVarError, match=WORKERS_ENV):
            frame_workers()


@pytest.mark.slow   # the default suite's pipelined frames: the resumed run of the next test
@pytest.mark.parametrize("workers", ["1", "2"])
def test_pipelined_dataset_is_the_serial_one(tmp_path, monkeypatch, serial_ref, workers):
    monkeypatch.setenv(FRAMES_ENV, "pipeline")
    monkeypatch.setenv(WORKERS_ENV, workers)
    started = []
    orig = FramePipeline.start.__func__

    def start(cls, *a, **kw):
        p = orig(cls, *a, **kw)
        started.append(p)
        return p

    monkeypatch.setattr(FramePipeline, "start", classmethod(start))
    out = simulate(small_scenario(**OVR), tmp_path / "pipe", progress=False, backend="analytic")
    assert len(started) == 1 and started[0] is not None and started[0].submitted == 8
    fr, fo = files(serial_ref), files(out)
    assert fr.keys() == fo.keys()
    assert [k for k in fr if fr[k] != fo[k]] == []


def test_killed_while_frames_are_in_flight_resumes_to_the_same_dataset(tmp_path, monkeypatch, serial_ref):
    """The worker's completions are hidden from the run (as if it were slow): every journal line from
    the first capture on is held; a kill at the 5th capture leaves a journal that ends before the
    first CCD stop (no frame named that may not be complete), and the resumed run (pipelined again)
    is byte-identical to the serial run (all of its frames made by the worker)."""
    from benchtwin.twin.instruments.camera import SimCamera

    monkeypatch.setenv(FRAMES_ENV, "pipeline")
    orig_completed = FramePipeline.completed
    monkeypatch.setattr(FramePipeline, "completed",
                        lambda self, wait=False: orig_completed(self, True) if wait else self.done)
    orig_capture = SimCamera.capture
    calls = {"n": 0}

    def flaky(self):
        calls["n"] += 1
        if calls["n"] == 5:
            raise KeyboardInterrupt("power cut")
        return orig_capture(self)

    monkeypatch.setattr(SimCamera, "capture", flaky)
    sc = small_scenario(**OVR)
    run = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        simulate(sc, run, progress=False, backend="analytic")
    assert not (run / "manifest.json").exists()
    recs = [json.loads(line) for line in (run / "journal.jsonl").read_text().splitlines()]
    steps = [r for r in recs if "i" in r]
    assert steps and not any(r.get("row", {}).get("type") == "capture" for r in steps)
    # a CCD stop's read is journaled with its capture (hw/acquisition/runner.py): the journal ends
    # at the first stop's wait, before its read
    assert steps[-1]["step"]["type"] == "wait"
    assert not any(r.get("row", {}).get("tag", {}).get("procedure") == "ccd" for r in steps)
    monkeypatch.setattr(SimCamera, "capture", orig_capture)
    monkeypatch.setattr(FramePipeline, "completed", orig_completed)
    out = simulate(sc, run, progress=False, backend="analytic", resume=True)
    fr, fo = files(serial_ref), files(out)
    assert fr.keys() == fo.keys()
    assert [k for k in fr if fr[k] != fo[k]] == []


@pytest.mark.slow
def test_pool_that_cannot_start_falls_back_to_serial(tmp_path, monkeypatch, serial_ref):
    monkeypatch.setenv(FRAMES_ENV, "pipeline")
    monkeypatch.setattr(FramePipeline, "start", classmethod(lambda cls, *a, **kw: None))
    out = simulate(small_scenario(**OVR), tmp_path / "fallback", progress=False, backend="analytic")
    fr, fo = files(serial_ref), files(out)
    assert [k for k in fr if fr[k] != fo.get(k)] == []


def test_auto_is_serial_for_a_script_without_the_main_guard(tmp_path, monkeypatch):
    """spawn re-imports the caller's script in the worker: without the guard it would run a second
    simulation there, so auto stays serial for it (an explicit ``pipeline`` is the caller's choice)."""
    import sys
    import types

    from benchtwin.twin.render.pipeline import main_is_spawn_safe

    bare, guarded = tmp_path / "bare.py", tmp_path / "guarded.py"
    bare.write_text("from benchtwin.twin.simulate import simulate\nsimulate(...)\n")
    guarded.write_text("def main():\n    pass\n\n\nif __name__ == '__main__':\n    main()\n")
    monkeypatch.setenv(FRAMES_ENV, "auto")
    for path, safe in ((bare, False), (guarded, True)):
        mod = types.ModuleType("__main__")
        mod.__file__ = str(path)
        mod.__spec__ = None
        monkeypatch.setitem(sys.modules, "__main__", mod)
        assert main_is_spawn_safe() is safe
        if not safe:
            assert frame_mode(60, 2048, 1536) == "serial"
    mod = types.ModuleType("__main__")
    mod.__spec__ = types.SimpleNamespace(name="pytest.__main__", origin=str(bare))
    monkeypatch.setitem(sys.modules, "__main__", mod)
    assert main_is_spawn_safe()      # a package's __main__ is not re-imported by spawn


def _render_stack_loaded() -> tuple[bool, bool]:
    """In a worker: whether the render stack was imported before the worker's first task (the
    preload module, and pyrender: it is imported by nothing else a worker runs before its
    initializer)."""
    import sys

    return "benchtwin.twin.render.worker_preload" in sys.modules, "pyrender" in sys.modules


def test_workers_fork_from_a_forkserver_that_imported_the_render_stack(monkeypatch):
    """The workers start with pyrender imported (by the forkserver, once); a process whose GL
    platform changed after its forkserver started gets spawned workers, which read the current
    environment."""
    import multiprocessing as mp
    import os
    from concurrent.futures import ProcessPoolExecutor

    from benchtwin.twin.render import pipeline

    ctx = pipeline.worker_context()
    if ctx.get_start_method() != "forkserver":
        pytest.skip("no forkserver on this platform: the workers are spawned")
    # this test process's forkserver may have been started already, without the preload, by a
    # design study's pool (app/study/execution.py): start it afresh (CPython's own
    # multiprocessing tests stop it the same way)
    from multiprocessing import forkserver

    forkserver._forkserver._stop()
    with ProcessPoolExecutor(max_workers=1, mp_context=ctx) as pool:
        assert pool.submit(_render_stack_loaded).result(timeout=120) == (True, True)
    recorded = dict(pipeline._forkserver_platform)
    monkeypatch.setitem(pipeline._forkserver_platform, "gl", ("another", "another"))
    assert pipeline.worker_context() is mp.get_context("spawn")
    monkeypatch.setitem(pipeline._forkserver_platform, "gl", recorded["gl"])
    assert pipeline.worker_context().get_start_method() == "forkserver"
    assert recorded["gl"] == (os.environ["MUJOCO_GL"], os.environ["PYOPENGL_PLATFORM"])
