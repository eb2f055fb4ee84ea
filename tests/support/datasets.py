"""The session's twin datasets: each scenario simulated once per test run (issue 35).

``DatasetFactory.dataset(sc)`` returns the dataset of scenario ``sc``, simulated by the first test
that asks for it and shared by every later one, read-only; ``copy(sc, dest)`` hands a test its own
copy to change (delete truth/, fog a frame, ...). Datasets are keyed by the scenario's content
(``scenario_key``): its text values (``Scenario.raw``), its overrides and its file path (the truth's
scenario.json records both) and the renderer backend; the same seed gives the same bytes (tests/twin/test_simulate.py
checks it), so a dataset simulated for one test is the dataset any other test would simulate.

Under pytest-xdist every worker has its own session but the folder is shared (the run's base
temporary folder): a scenario's first asker takes an exclusive ``flock`` on ``KEY.lock``,
simulates into a partial folder and renames it onto ``KEY/ds``; the others wait on the lock and
find it there. A kill releases the lock (the kernel drops it with the process), and the partial
folder is never taken for a dataset: only a complete one is renamed in (simulate writes its
manifest last).

Read-only is checked, not trusted: each dataset's file list, sizes and modification times are
recorded when it is made, and ``verify()`` (the fixture's teardown) fails the run naming any
dataset a test changed.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path

from benchtwin.twin.scenario import Scenario

FINGERPRINT = "fingerprint.json"


def scenario_key(sc: Scenario, backend: str = "analytic") -> str:
    """The content hash of a scenario: what decides the bytes ``simulate`` writes."""
    # the overrides too: truth/scenario.json records them (a scenario with its overrides cleared, as
    # tests/app/test_cli_overrides.py makes one, has the same values and other bytes)
    blob = json.dumps({"raw": sc.raw, "path": str(sc.path) if sc.path is not None else None, "backend": backend,
                       "overrides": dict(getattr(sc, "overrides", None) or {})},
                      sort_keys=True, default=str, ensure_ascii=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def _fingerprint(d: Path) -> dict[str, list[int]]:
    return {str(p.relative_to(d)): [p.stat().st_size, p.stat().st_mtime_ns]
            for p in sorted(d.rglob("*")) if p.is_file()}


class DatasetFactory:
    """Datasets under ``root`` (shared by the xdist workers of one run), one per scenario key."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.simulated: list[str] = []      # keys this process simulated
        self.served: dict[str, int] = {}    # key -> datasets handed out by this process

    def dataset(self, sc: Scenario, backend: str = "analytic") -> Path:
        """The scenario's dataset, shared: read it, never write into it (``copy`` for that)."""
        key = scenario_key(sc, backend)
        final = self.root / key / "ds"
        if not (final / "manifest.json").is_file():
            with open(self.root / f"{key}.lock", "a") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)       # released when the file is closed
                if not (final / "manifest.json").is_file():
                    self._simulate(sc, backend, key, final)
        self.served[key] = self.served.get(key, 0) + 1
        return final

    def copy(self, sc: Scenario, dest: str | Path, backend: str = "analytic",
             ignore: tuple[str, ...] = ()) -> Path:
        """A private copy of the scenario's dataset at ``dest`` (new), without the ``ignore`` names."""
        src = self.dataset(sc, backend)
        shutil.copytree(src, dest, ignore=shutil.ignore_patterns(*ignore) if ignore else None)
        return Path(dest)

    def shared(self, name: str, make: Callable[[Path], None]) -> Path:
        """A folder made once per test run by ``make(folder)`` (the first asker's; the others, other
        xdist workers included, wait on the lock and read it), e.g. an analysis of a dataset that
        several test modules read. Shared and read-only as ``dataset``'s: checked by ``verify``.
        ``name`` must say what is made (the folder is found by it alone)."""
        key = "shared-" + hashlib.sha256(name.encode()).hexdigest()[:20]
        final = self.root / key / "made"
        if not (final / ".complete").is_file():
            with open(self.root / f"{key}.lock", "a") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)
                if not (final / ".complete").is_file():
                    # made in place (what it writes may name its own paths); a killed maker's leftovers
                    # are removed by the next asker, who finds no .complete
                    shutil.rmtree(final, ignore_errors=True)
                    final.mkdir(parents=True)
                    make(final)
                    (final / ".complete").write_text(name)
                    (final.parent / FINGERPRINT).write_text(json.dumps(_fingerprint(final)))
                    self.simulated.append(key)
        self.served[key] = self.served.get(key, 0) + 1
        return final

    def _simulate(self, sc: Scenario, backend: str, key: str, final: Path) -> None:
        from benchtwin.twin.simulate import simulate

        partial = self.root / key / f"partial-{os.getpid()}"
        shutil.rmtree(partial, ignore_errors=True)
        simulate(sc, partial, progress=False, backend=backend)
        (partial.parent / FINGERPRINT).write_text(json.dumps(_fingerprint(partial)))
        os.replace(partial, final)
        self.simulated.append(key)

    def verify(self) -> list[str]:
        """The datasets (of this process's use) whose files differ from when they were made."""
        changed = []
        for key in sorted(self.served):
            d = self.root / key
            made = d / ("made" if key.startswith("shared-") else "ds")
            if json.loads((d / FINGERPRINT).read_text()) != _fingerprint(made):
                changed.append(str(made))
        return changed
