"""An opt-in log of the work a test run does (issue 35: how many simulations, how many pools).

With ``BENCHTWIN_TEST_SIMLOG=FILE`` (tests/conftest.py registers this plugin then; or
``-p tests.support.simlog``) every twin simulation (``twin/simulate.py``'s ``_simulate``, which
``simulate`` and ``simulate_apart`` run) and every process pool started (``ProcessPoolExecutor``,
``multiprocessing.Pool``) appends one JSON line to FILE: what, the test running, the process, and
for a simulation the scenario's key (tests/support/datasets.py), its wall seconds and its CPU
seconds (this process's, and its children's: the settle worker and the α grid child it reaps). xdist
workers append to the same file (O_APPEND, one short write per line). Nothing changes without the
variable.
"""

from __future__ import annotations

import json
import os
import resource
import time

LOG_ENV = "BENCHTWIN_TEST_SIMLOG"


def _log(path: str, rec: dict) -> None:
    rec = {"pid": os.getpid(), "test": os.environ.get("PYTEST_CURRENT_TEST", ""), **rec}
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, (json.dumps(rec) + "\n").encode())
    finally:
        os.close(fd)


def _children_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def pytest_collection_finish(session) -> None:
    """Wrap the entry points once the conftests have set the GL platform (they import the twin)."""
    path = os.environ.get(LOG_ENV)
    if not path or getattr(pytest_collection_finish, "done", False):
        return
    pytest_collection_finish.done = True  # type: ignore[attr-defined]
    import concurrent.futures.process as cfp
    import multiprocessing.pool as mpp

    import benchtwin.twin.simulate as S

    from tests.support.datasets import scenario_key

    run = S._simulate

    def logged(sc, *a, **kw):
        # _simulate(sc, opts) with opts.backend (an older signature: sc, out, progress, backend, ...)
        opts = a[0] if a else kw.get("opts")
        backend = getattr(opts, "backend", a[2] if len(a) > 2 else kw.get("backend", "analytic"))
        t0, c0, k0 = time.perf_counter(), time.process_time(), _children_cpu_s()
        try:
            return run(sc, *a, **kw)
        finally:
            _log(path, {"what": "simulate", "scenario": scenario_key(sc, backend), "name": sc.name,
                        "wall_s": round(time.perf_counter() - t0, 3), "cpu_s": round(time.process_time() - c0, 3),
                        "children_cpu_s": round(_children_cpu_s() - k0, 3)})

    S._simulate = logged
    for cls, what in ((cfp.ProcessPoolExecutor, "ProcessPoolExecutor"), (mpp.Pool, "multiprocessing.Pool")):
        init = cls.__init__

        def counted(self, *a, _init=init, _what=what, **kw):
            if not isinstance(self, mpp.ThreadPool):
                _log(path, {"what": "pool", "kind": _what})
            _init(self, *a, **kw)

        cls.__init__ = counted
