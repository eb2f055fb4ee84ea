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


def _measure() -> str:
    """The probe itself, as ``PROBE_ENV`` holds it: "1 <status>" or "0 <status>"."""
    from benchtwin.twin.render.gl import gl_available, gl_status

    return f"{int(gl_available())} {gl_status()}"


def probe_for_workers() -> None:
    """Probe once and put the answer where the workers (and the tests' subprocesses) inherit it."""
    if PROBE_ENV not in os.environ:
        os.environ[PROBE_ENV] = _measure()


def _probe() -> tuple[bool, str]:
    memo = os.environ.get(PROBE_ENV) or _measure()
    return memo[0] == "1", memo[2:]


GL, _STATUS = _probe()
needs_gl = pytest.mark.skipif(not GL, reason=f"no OpenGL context: {_STATUS if not GL else ''}")
