"""An opt-in memo of the truth's α grid (``twin/simulate.py`` ``_alpha_grid``), keyed by the bench.

The α grid (``truth/encoder_error.csv``: every head's α at readings 0.1° apart) is a property of the
bench as built, not of the run (``_alpha_grid``'s docstring; tests/twin/test_truth_apart.py checks
it against the bench as the run left it): it is a pure function of the scenario *without* its
``[procedure]`` and of the code that computes it. It is also the largest fixed cost of a small
simulation: 3600 stops of the statics, ≈ 1.2 s of CPU on a path bench and ≈ 2.1 s on jia2019's ball
bench, more than the rest of a short run. Runs that differ only in their procedure (the test
suite's small benches, a study of the procedure) compute the same grid again and again.

With ``BENCHTWIN_ALPHA_GRID_CACHE=DIR`` a grid is written to ``DIR/KEY.json`` once and read back by
later runs of the same bench, in any process. Without the variable nothing changes. The key is the
SHA-256 of:

- the scenario's values (``Scenario.raw``, overrides applied) without ``[procedure]`` and without
  ``[instruments.ccd]`` (:data:`NOT_READ`: the camera's sensor, read by the camera alone,
  ``twin/instruments/camera.py``, which the grid's stops never build: a bench, a state, the encoder,
  a stage; the test suite's benches differ there more than anywhere else, issue 35);
- the source of every module the grid can depend on (the ``benchtwin`` floor, ``twin/``, ``hw/``,
  ``analysis/``) and the MuJoCo models (``models/*.xml``): any code change is a new key, so a stale
  grid is never read;
- the versions of NumPy, SciPy and MuJoCo (their arithmetic sets the grid's last bits).

The values are JSON floats, written with ``repr`` (exact round trip), so a grid read back gives the
dataset the same bytes as a grid computed (tests/twin/test_alpha_grid_memo.py). A file is written
atomically (``fsio``): a reader finds a whole grid or none; an unreadable or incomplete file is
computed again (and replaced).
"""

from __future__ import annotations

import fcntl
import functools
import hashlib
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .code_digest import update_with_sources

ENV = "BENCHTWIN_ALPHA_GRID_CACHE"

#: the scenario's tables the α grid does not read, as (section, table): the CCD's sensor (frame size,
#: pixel pitch, optics, noise), read only by ``SimCamera.sim_from_scenario`` (the camera's position
#: is ``[bench]``'s, and a hidden effect on the camera ``[hidden]``'s: both stay in the key).
#: tests/twin/test_alpha_grid_memo.py computes the grid of two such benches and compares the bits.
NOT_READ = (("instruments", "ccd"),)


@functools.cache
def _code_digest() -> str:
    """SHA-256 over the sources the α grid's computation can reach (the ``benchtwin`` floor, the twin,
    the hardware layer, the analysis: the twin's dataset writer lives there) and the MuJoCo models."""
    h = hashlib.sha256()
    update_with_sources(h, [(name, "*.py") for name in ("benchtwin", "benchtwin.twin", "benchtwin.hw",
                                                         "benchtwin.analysis")] + [("benchtwin.models", "*")])
    return h.hexdigest()


def grid_key(sc: Any) -> str:
    """The memo key of scenario ``sc``'s α grid (see the module docstring)."""
    import mujoco
    import numpy
    import scipy

    raw = {k: v for k, v in dict(sc.raw).items() if k != "procedure"}
    for section, table in NOT_READ:
        if isinstance(raw.get(section), dict) and table in raw[section]:
            raw[section] = {k: v for k, v in raw[section].items() if k != table}
    blob = json.dumps({"raw": raw, "code": _code_digest(),
                       "versions": [numpy.__version__, scipy.__version__, mujoco.__version__]},
                      sort_keys=True, default=str, ensure_ascii=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def _load(path: Path) -> dict[str, list] | None:
    try:
        cols = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(cols, dict) or "theta_deg" not in cols or "alpha_arcsec" not in cols:
        return None
    n = len(cols["theta_deg"])
    if n == 0 or any(not isinstance(v, list) or len(v) != n for v in cols.values()):
        return None
    return cols


def memoised(sc: Any, compute: Callable[[], dict[str, list]]) -> dict[str, list]:
    """``compute()``, or the grid a run of the same bench stored under ``$BENCHTWIN_ALPHA_GRID_CACHE``."""
    folder = os.environ.get(ENV)
    if not folder:
        return compute()
    from benchtwin.fsio import atomic_write_text

    path = Path(folder) / f"{grid_key(sc)}.json"
    cols = _load(path)
    if cols is not None:
        return cols
    path.parent.mkdir(parents=True, exist_ok=True)
    # one computer per grid: processes asking for the same bench at once (the suite's xdist workers,
    # a study's pool) wait on the grid's lock and read what the first one wrote, instead of each
    # computing it (≈ 2 s of CPU); the kernel drops the lock with a killed holder, and a grid is only
    # ever read whole (atomic write)
    with open(path.with_suffix(".lock"), "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        cols = _load(path)
        if cols is None:
            cols = compute()
            atomic_write_text(path, json.dumps({k: [float(x) for x in v] for k, v in cols.items()}), fsync=False)
    return cols
