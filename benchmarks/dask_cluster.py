"""A real Dask cluster on loopback for tests and benchmarks: one ``dask scheduler`` and N ``dask worker``
processes of this venv, started as subprocesses and always killed.

Why not ``distributed.LocalCluster``: a study run against ``scheduler="tcp://HOST:PORT"`` talks to
a scheduler and workers that are separate programs (what a user starts on a cluster), each worker
importing benchtwin on its own. This starts exactly those command-line programs
(``.venv/bin/dask scheduler --host 127.0.0.1 --port 0 --scheduler-file F``, and per worker
``dask worker --scheduler-file F --nworkers 1 --nthreads 1``), with ``PYTHONPATH`` set to the
worktree so that the workers import this checkout's benchtwin whatever the caller's directory.

Every wait is bounded (``timeout_s``); every process is started in its own session and its whole
process group (the worker's nanny and its child) is ended on exit, also when the body raised.

    with loopback_cluster(2, Path("/tmp/x")) as address:   # "tcp://127.0.0.1:PORT"
        run_study(study, out, scheduler=address)
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DASK = Path(sys.executable).with_name("dask")


def _dask_cmd(kind: str) -> list[str]:
    """``dask scheduler`` / ``dask worker`` of this venv (its console script, else the module form)."""
    return [str(DASK), kind] if DASK.is_file() else [sys.executable, "-m", f"distributed.cli.dask_{kind}"]


def _log_tail(path: Path, n: int = 2000) -> str:
    try:
        return path.read_text(errors="replace")[-n:]
    except OSError:
        return ""


def _stop(procs: list[subprocess.Popen], grace_s: float = 10.0) -> None:
    """SIGTERM each process group, wait up to ``grace_s``, then SIGKILL what is left."""
    for p in procs:
        if p.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGTERM)
    deadline = time.monotonic() + grace_s
    for p in procs:
        with contextlib.suppress(subprocess.TimeoutExpired):
            p.wait(timeout=max(0.0, deadline - time.monotonic()))
    for p in procs:
        # the group may outlive its leader (the nanny's worker child): kill it in any case
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(p.pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            p.wait(timeout=5.0)


@contextlib.contextmanager
def loopback_cluster(n_workers: int, workdir: Path, timeout_s: float = 120.0) -> Iterator[str]:
    """Start a scheduler and ``n_workers`` single-threaded workers on 127.0.0.1; yield the
    scheduler's address once all workers are connected; end every process on exit."""
    from distributed import Client

    workdir.mkdir(parents=True, exist_ok=True)
    sched_file = workdir / "scheduler.json"
    sched_file.unlink(missing_ok=True)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    procs: list[subprocess.Popen] = []
    logs: list[Path] = []

    def start(name: str, kind: str, args: list[str]) -> subprocess.Popen:
        log = workdir / f"{name}.log"
        logs.append(log)
        with open(log, "wb") as fh:
            p = subprocess.Popen([*_dask_cmd(kind), *args], cwd=workdir, env=env, stdout=fh,
                                 stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
        procs.append(p)
        return p

    def failed(what: str) -> RuntimeError:
        tails = "\n".join(f"--- {log.name}\n{_log_tail(log)}" for log in logs)
        return RuntimeError(f"loopback Dask cluster: {what} within {timeout_s:.0f} s\n{tails}")

    try:
        deadline = time.monotonic() + timeout_s
        sched = start("scheduler", "scheduler", ["--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                    "--scheduler-file", str(sched_file)])
        address = None
        while address is None:
            if sched.poll() is not None:
                raise failed(f"the scheduler exited (code {sched.returncode})")
            if time.monotonic() > deadline:
                raise failed("no scheduler file")
            with contextlib.suppress(FileNotFoundError, json.JSONDecodeError):
                address = json.loads(sched_file.read_text())["address"]
            time.sleep(0.1)
        for i in range(n_workers):
            start(f"worker{i}", "worker", ["--scheduler-file", str(sched_file), "--nworkers", "1",
                                 "--nthreads", "1", "--host", "127.0.0.1", "--no-dashboard",
                                 "--local-directory", str(workdir / f"worker{i}"),
                                 "--death-timeout", str(int(timeout_s))])
        with Client(address, timeout=f"{max(1.0, deadline - time.monotonic()):.0f}s") as client:
            try:
                client.wait_for_workers(n_workers, timeout=max(1.0, deadline - time.monotonic()))
            except TimeoutError:
                raise failed(f"fewer than {n_workers} workers connected") from None
        yield address
    finally:
        _stop(procs)
