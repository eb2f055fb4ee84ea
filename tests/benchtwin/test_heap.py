"""benchtwin/heap.py: with glibc's thresholds fixed, a frame's freed 12 MB arrays are reused
without page faults (the frame worker's ≈ 3000 minor faults and 15 ms of kernel CPU a frame).
Counts page faults (getrusage), never time; each case in a fresh interpreter (mallopt is
process-wide and the test process's own allocations would blur the count)."""

from __future__ import annotations

import subprocess
import sys

import pytest

_CASE = """
import resource, sys
import numpy as np
from benchtwin.heap import keep_freed_memory
kept = keep_freed_memory() if sys.argv[1] == "keep" else None
def frame():   # a frame's temporaries, of several sizes, all touched and freed
    a = np.ones((1536, 2048), np.float32)
    b = a * np.float32(2.0)
    c = np.ones((1537, 2048))
    d = b > 1.0
    e = b.astype(np.uint8)
    return float(a[0, 0] + c[0, 0]) + int(d[0, 0]) + int(e[0, 0])
frame(); frame()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
frame()
print(kept, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> tuple[str, int]:
    out = subprocess.run([sys.executable, "-c", _CASE, mode], capture_output=True, text=True, check=True)
    kept, faults = out.stdout.split()
    return kept, int(faults)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_freed_frame_memory_is_reused():
    kept, with_keep = _faults("keep")
    if kept != "True":
        pytest.skip("mallopt refused (not glibc)")
    _, default = _faults("default")
    pages = 1536 * 2048 * 4 // 4096   # one 12 MB array
    assert default > pages // 2      # glibc's default: the third frame on fresh pages again
    assert with_keep < pages // 20   # kept: the earlier frames' pages
