"""The one OpenGL skip marker of the tests that render through pyrender.

The probe (``gl_available``: a child process that makes an 8×8 off-screen render, ≈ 1.8 s of CPU) runs
once per test run: the process that starts an xdist run probes before its workers start
(``probe_for_workers``, tests/conftest.py) and hands them the answer in ``PROBE_ENV``; a run without
workers probes here, as before."""

from __future__ import annotations

import os

import pytest

#: the run's probe, "1 <status>" or "0 <status>", set by the process that starts the xdist workers
PROBE_ENV = "BENCHTWIN_TEST_GL_PROBE"


def probe_for_workers() -> None:
    """Probe once and put the answer where the workers (and the tests' subprocesses) inherit it."""
    if PROBE_ENV not in os.environ:
        from benchtwin.twin.render.gl import gl_available, gl_status

        os.environ[PROBE_ENV] = f"{int(gl_available())} {gl_status()}"


def _probe() -> tuple[bool, str]:
    memo = os.environ.get(PROBE_ENV)
    if memo:
        return memo[0] == "1", memo[2:]
    from benchtwin.twin.render.gl import gl_available, gl_status

    return gl_available(), gl_status()


GL, _STATUS = _probe()
needs_gl = pytest.mark.skipif(not GL, reason=f"no OpenGL context: {_STATUS if not GL else ''}")
