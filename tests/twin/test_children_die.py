"""Children die with their parent, and a failed command always exits (issue #31).

Real processes: a ``simulate`` with pipelined CCD frames (its forkserver and frame workers, its
settle and truth children) and a ``study`` on a local pool are started in a session of their own
and killed with SIGKILL while they work; within a few seconds nothing of that session may run,
and no frame or cache entry may appear after the kill. A failed command's process ends
promptly even with a thread that would keep the interpreter's exit waiting, and a ``simulate``
under a memory limit ends (bounded wait).

The processes are found by their session (``start_new_session``: every descendant keeps the
session id unless it calls setsid, which nothing here does), so descendants reparented to init
after the kill are still found.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: seconds the killed run's descendants may take to go (they die within ≈ 0.1 s; the bound is
#: for a loaded 2-core machine)
DIE_WITHIN_S = 10.0
#: seconds to watch the output folder once they are gone
WATCH_S = 1.5


def _session(sid: int) -> list[tuple[int, str]]:
    """(pid, command) of the live processes of session ``sid`` (zombies excluded)."""
    found = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            stat = Path(f"/proc/{d}/stat").read_text()
            cmd = Path(f"/proc/{d}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        if int(fields[3]) == sid and fields[0] not in ("Z", "X"):
            found.append((int(d), cmd[:120]))
    return found


def _wait_session_gone(sid: int) -> list[tuple[int, str]]:
    deadline = time.monotonic() + DIE_WITHIN_S
    alive = _session(sid)
    while alive and time.monotonic() < deadline:
        time.sleep(0.05)
        alive = _session(sid)
    return alive


def _reap(sid: int) -> None:
    """Whatever the test leaves: killed (the test failed)."""
    for pid, _ in _session(sid):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def _names(folder: Path, pattern: str) -> set[str]:
    return {p.name for p in folder.glob(pattern)} if folder.is_dir() else set()


needs_linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc and PR_SET_PDEATHSIG: Linux")

#: a simulate whose CCD frames (24 of 640×480) are made by two pipelined workers from the
#: forkserver, with the settle worker and the truth's α-grid child (both forked)
SIMULATE = textwrap.dedent("""
    import sys
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import simulate

    OVR = {"procedure.radial_reps": 1, "procedure.radial_positions": 12, "procedure.ccd_step": "15 deg",
           "procedure.polygon_shifts": ["0 deg"], "procedure.directions": ["forward"], "procedure.selfcal": False,
           "bench.polygon_faces": 8, "instruments.ccd.width": "640 px", "instruments.ccd.height": "480 px"}
    if __name__ == "__main__":
        sc = load_scenario(sys.argv[1]).with_overrides(OVR)
        simulate(sc, sys.argv[2], progress=False, backend="analytic")
""")


@needs_linux
def test_killed_simulate_leaves_no_process_and_no_new_frame(tmp_path, kill_env):
    script = tmp_path / "sim.py"
    script.write_text(SIMULATE)
    out = tmp_path / "ds"
    env = {**kill_env, "BENCHTWIN_SIM_FRAMES": "pipeline", "BENCHTWIN_SIM_FRAME_WORKERS": "2"}
    proc = subprocess.Popen([sys.executable, str(script), str(ROOT / "scenarios" / "jia2019.toml"), str(out)],
                            env=env, start_new_session=True, stderr=subprocess.PIPE)
    try:
        ccd = out / "ccd"
        deadline = time.monotonic() + 300
        # the first frame under way (a worker's file, or a frame already renamed into place)
        while not (ccd.is_dir() and any(ccd.iterdir())):
            assert proc.poll() is None, f"simulate ended before its first frame: {proc.stderr.read()!r}"
            assert time.monotonic() < deadline, "no frame from simulate"
            time.sleep(0.01)
        assert len(_session(proc.pid)) >= 3     # the run, its forkserver and frame workers at least
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        frames_at_kill = _names(ccd, "img_*.png")
        alive = _wait_session_gone(proc.pid)
        assert not alive, f"alive after the run was killed: {alive}"
        files_then = _names(ccd, "*")
        time.sleep(WATCH_S)
        assert _names(ccd, "img_*.png") == frames_at_kill, "frames appeared after the run was killed"
        assert _names(ccd, "*") == files_then
        assert not (out / "manifest.json").exists()
    finally:
        _reap(proc.pid)
        if proc.poll() is None:
            proc.kill()
        proc.wait()


#: a study on a local pool of 2 workers whose point function takes 0.3 s a call and leaves one
#: file per call started (tests/support/study.py's stand-in)
STUDY = """
[study]
name = "killed"
base = "jia2019"
seed = 3
repetitions = 1
angles = 36
outputs = ["angle_error_pv_arcsec", "disk_motion_x_pv_um"]
[[study.parameters]]
key = "bench.L1"
values = ["1 mm", "2 mm", "3 mm", "4 mm", "5 mm", "6 mm", "7 mm", "8 mm", "9 mm", "10 mm", "11 mm", "12 mm"]
"""


@needs_linux
def test_killed_study_leaves_no_worker_and_no_new_entry(tmp_path, kill_env):
    study = tmp_path / "study.toml"
    study.write_text(STUDY)
    out, calls = tmp_path / "out", tmp_path / "calls"
    calls.mkdir()
    script = textwrap.dedent(f"""
        import functools, importlib, sys
        sys.path[:0] = [{str(ROOT)!r}]
        counting_point = importlib.import_module("tests.support.study").counting_point
        import benchtwin.app.study.execution as st
        if __name__ == "__main__":
            st.run_study({str(study)!r}, {str(out)!r}, workers=2, progress=False,
                         point_fn=functools.partial(counting_point, count_dir={str(calls)!r}, delay_s=0.3))
    """)
    (tmp_path / "run_study.py").write_text(script)
    proc = subprocess.Popen([sys.executable, str(tmp_path / "run_study.py")], start_new_session=True,
                            stderr=subprocess.PIPE, env=kill_env)
    try:
        deadline = time.monotonic() + 120
        while not list((out / "cache").rglob("*.json")) if (out / "cache").exists() else True:
            assert proc.poll() is None, f"the study ended before it could be killed: {proc.stderr.read()!r}"
            assert time.monotonic() < deadline, "no cache entry from the study"
            time.sleep(0.01)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        entries_at_kill = {p.name for p in (out / "cache").rglob("*")}
        started_at_kill = _names(calls, "*")
        alive = _wait_session_gone(proc.pid)
        assert not alive, f"alive after the study was killed: {alive}"
        time.sleep(WATCH_S)
        assert {p.name for p in (out / "cache").rglob("*")} == entries_at_kill
        # no point started after the kill (a worker may have been inside one when it came)
        assert len(_names(calls, "*")) <= len(started_at_kill) + 2
        assert len(started_at_kill) < 12
    finally:
        _reap(proc.pid)
        proc.wait()


# --------------------------------------------------------------------------- failed commands exit


def test_a_failed_command_ends_its_process_despite_a_lingering_thread(tmp_path):
    """An internal error in a command whose process keeps a non-daemon thread (what a process
    pool's manager is at the interpreter's exit) still ends with exit 1, within the grace."""
    launcher = textwrap.dedent("""
        import sys, threading, time
        import benchtwin.cli as cli
        import benchtwin.app.commands as commands

        def hang_then_fail(ns):
            threading.Thread(target=time.sleep, args=(3600,)).start()   # non-daemon: joined at exit
            raise MemoryError()

        cli._COMMANDS["validate"] = (hang_then_fail, cli._COMMANDS["validate"][1], "validate")
        cli._load_commands = lambda: None
        sys.argv = ["benchtwin", "validate", "x"]
        sys.exit(cli.main())
    """)
    proc = subprocess.Popen([sys.executable, "-c", launcher], start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("the failed command's process did not end")
    finally:
        _reap(proc.pid)
    assert proc.returncode == 1, err
    assert "internal error (MemoryError" in err


def test_main_with_arguments_returns_instead_of_ending_the_process(capsys):
    """``main(argv)`` (tests, scripts) returns the code; only the process's own command line ends it."""
    from benchtwin.cli import main

    assert main(["validate", "/nonexistent/scenario.toml"]) == 2
    assert "scenario.toml" in capsys.readouterr().err


@needs_linux
def test_simulate_under_a_memory_limit_ends(tmp_path):
    """``ulimit -v``: the run ends, and every child with it. Here (Debian 12, 2 cores) 640 MiB
    ends it after ≈ 3 s when the frame workers start (an ImportError of cv2 or a MemoryError: exit 1,
    "internal error"); where the limit suffices, the run completes instead (a dataset with its
    manifest). jia2019 with its procedure cut to one short radial revolution and one polygon
    mounting (``--set``): the paper's 2048×1536 px frames are what meets the limit, and the rest of
    the full procedure only made the test take 8 s of CPU instead of 2 (issue 35)."""
    import resource

    out = tmp_path / "ds"
    limit = 640 * 2**20

    def limit_memory() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    cmd = [str(Path(sys.executable).parent / "benchtwin"), "simulate", str(ROOT / "scenarios" / "jia2019.toml"),
           "-o", str(out), "--backend", "analytic", "--quiet",
           "--set", "procedure.radial_positions=24", "--set", "procedure.radial_reps=1",
           "--set", 'procedure.polygon_shifts=["0 deg"]', "--set", 'procedure.directions=["forward"]']
    proc = subprocess.Popen(cmd, start_new_session=True, preexec_fn=limit_memory, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        _, err = proc.communicate(timeout=400)
    except subprocess.TimeoutExpired:
        pytest.fail(f"simulate under a {limit >> 20} MiB limit did not end")
    finally:
        alive = _wait_session_gone(proc.pid)
        _reap(proc.pid)
    assert not alive, f"alive after simulate ended: {alive}"
    if proc.returncode == 0:
        assert (out / "manifest.json").is_file()
    else:
        assert proc.returncode == 1 and "internal error" in err, err
        assert not (out / "manifest.json").exists()


@needs_linux
def test_a_forkserver_that_never_answers_is_given_up():
    """The frame workers' forkserver stopped (as one stuck in its imports under ``ulimit -v``):
    the run's wait for its first worker ends after ``START_TIMEOUT_S``, the forkserver is killed
    and the frames fall back to serial (``backend()`` None, with a warning). In a process of its
    own: the forkserver is the process's."""
    script = textwrap.dedent("""
        import multiprocessing as mp, os, signal, warnings
        from concurrent.futures import ProcessPoolExecutor
        from multiprocessing import forkserver
        from benchtwin.twin.render import pipeline

        if __name__ == "__main__":
            pipeline.START_TIMEOUT_S = 1.0
            ctx = mp.get_context("forkserver")
            pipe = pipeline.FramePipeline(ProcessPoolExecutor(max_workers=1, mp_context=ctx), 1)
            forkserver.ensure_running()
            pid = forkserver._forkserver._forkserver_pid
            os.kill(pid, signal.SIGSTOP)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                assert pipe.backend() is None
            assert any("did not answer within 1 s" in str(w.message) for w in caught), caught
            assert os.waitpid(pid, 0)[0] == pid             # killed: reaped here
            print("given up")
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        out, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        pytest.fail("the wait for a forkserver that never answers did not end")
    finally:
        _reap(proc.pid)
    assert proc.returncode == 0 and "given up" in out, err
