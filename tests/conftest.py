"""Suite-wide test configuration.

- Headless OpenGL is configured before anything imports pyrender or mujoco's renderer.
- ``--hardware`` opts in to tests that need a real bench (marker ``hardware``); never in CI.
- ``datasets``: the session's twin datasets, each scenario simulated once per run, shared by the
  xdist workers of a run (tests/support/datasets.py).
- ``BENCHTWIN_TEST_SIMLOG=FILE`` logs every simulation and process pool (tests/support/simlog.py).
- ``BENCHTWIN_ALPHA_GRID_CACHE``: one memo of the truth's α grid per run (twin/alpha_grid_memo.py).
- Compiled modules in the pytest cache where the host forbids writing them beside the sources
  (``_bytecode``).
- pytest-xdist (``-n auto --dist loadgroup`` in pyproject.toml): a test module runs on one worker
  (its module-scoped fixtures are built once), and the tests marked ``xdist_group("serial")`` (those
  that start process pools, forkservers or a browser, or wait on deadlines) run one after another on
  one worker, never two of them at once on the machine's cores.
"""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

import pytest

# Same platform for MuJoCo and PyOpenGL (they must match; EGL is Mesa's software path here).
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
# One OpenBLAS thread per test process (set before anything imports NumPy; the xdist workers, the forked
# children and the tests' subprocesses inherit it). The suite's processes already fill the cores (two xdist
# workers, their children), and OpenBLAS's own threads then spin waiting for each other on the shared
# cores: tests/analysis/test_probe_drift.py took 12.6 s of CPU with the default threads and 1.9 s with one
# (-n 0, load 4-6), a close-loop analysis 11-13.5 s and 10.6 s (issue 35). A value the caller sets is kept.
# The tests' results do not depend on it: no test holds a BLAS result to its last bit across
# configurations (CI runs the whole suite under another OpenBLAS kernel as well, .ci/run).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--hardware", action="store_true", default=False,
                     help="run tests that talk to a real bench (see hw/README); never in CI")


#: the run's memo of the truth's α grid (twin/alpha_grid_memo.py), made by the process that starts the
#: run (xdist's workers and the tests' subprocesses inherit the variable) and removed at its end
_grid_memo_made: str | None = None


def _bytecode(config: pytest.Config) -> None:
    """Compiled modules kept outside the tree on a host that forbids writing them (issue 35 part 5).

    With ``PYTHONDONTWRITEBYTECODE`` set (this host sets it) every process of a run compiled the test
    modules (pytest's assertion rewriting: ≈ 5.5 s of CPU of each xdist worker's 10 s collection) and
    benchtwin's modules (≈ 0.4 s in each process that imports the twin: workers, subprocesses, the
    forkservers and spawned pools) from source, in every run. With the pytest cache (the README's
    command) the run's processes write and share them in a folder of it (``PYTHONPYCACHEPREFIX``;
    the tree gets no ``__pycache__``), so later runs start warm: a warm worker collects in ≈ 4 s of
    CPU instead of 10 s. The prefix holds every module a process compiles, the virtual
    environment's too (a prefix hides the ``__pycache__`` beside the sources), so the first run
    compiles them once more (≈ +2.5 s of CPU a process); without the pytest cache
    (``-p no:cacheprovider``, a one-off run) nothing changes. Python and pytest check a compiled
    module against its source's size and mtime and write it atomically, so workers racing on one
    module are safe. A prefix the caller sets is kept; xdist's workers and the tests' subprocesses
    inherit the variables."""
    cache = getattr(config, "cache", None)
    if cache is None or not os.environ.get("PYTHONDONTWRITEBYTECODE") or os.environ.get("PYTHONPYCACHEPREFIX"):
        return
    folder = str(cache.mkdir("benchtwin-pycache"))
    del os.environ["PYTHONDONTWRITEBYTECODE"]
    os.environ["PYTHONPYCACHEPREFIX"] = folder
    sys.pycache_prefix = folder
    sys.dont_write_bytecode = False


def pytest_configure(config: pytest.Config) -> None:
    global _rootpath, _grid_memo_made
    _rootpath = config.rootpath
    _bytecode(config)
    # The α grid is a property of the bench, not of the procedure: the many small runs of one bench
    # (tests/support/scenarios.py) compute it once per test run instead of once per simulation (≈ 2 s
    # of CPU each on jia2019's ball bench). The same bytes either way (tests/twin/test_alpha_grid_memo.py).
    from benchtwin.twin.alpha_grid_memo import ENV as GRID_MEMO_ENV

    if not os.environ.get(GRID_MEMO_ENV):
        import tempfile

        _grid_memo_made = os.environ[GRID_MEMO_ENV] = tempfile.mkdtemp(prefix="benchtwin-alpha-grids-")
    if not hasattr(config, "workerinput") and (getattr(config.option, "numprocesses", None) or 0) > 0:
        from tests.support.gl import probe_for_workers

        probe_for_workers()     # one GL probe for the run, not one per worker (tests/support/gl.py)
    from tests.support import simlog

    if os.environ.get(simlog.LOG_ENV) and not config.pluginmanager.has_plugin("tests.support.simlog"):
        config.pluginmanager.register(simlog, "tests.support.simlog")


def pytest_unconfigure(config: pytest.Config) -> None:
    if _grid_memo_made is not None:
        import shutil

        shutil.rmtree(_grid_memo_made, ignore_errors=True)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--hardware"):
        return
    skip = pytest.mark.skip(reason="needs a real bench: opt in with --hardware")
    for item in items:
        if "hardware" in item.keywords:
            item.add_marker(skip)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_auto_num_workers(config: pytest.Config) -> int | None:
    """``-n auto`` (pyproject.toml) spreads the whole suite (the README's command, CI) over the
    cores; a run of named files or folders stays in this process (on a shared machine a second
    worker would start, collect and idle: a file is one work unit). ``-n N`` asks for N anyway."""
    if config.args_source != pytest.Config.ArgsSource.TESTPATHS:
        return 0
    return None        # xdist's own count: one worker per core


#: the pytest cache's record of the seconds each xdist work unit (a module, or a group) took last time
SCOPE_SECONDS = "benchtwin/xdist-scope-seconds"


SERIAL_MARK = 'pytest.mark.xdist_group("serial")'


@functools.cache
def _serial(module: Path) -> bool:
    try:
        return SERIAL_MARK in module.read_text(encoding="utf-8")
    except OSError:
        return False


def _scope(rootpath: Path, nodeid: str) -> str:
    """A test's xdist work unit: "serial" for a module that holds ``SERIAL_MARK`` (its
    ``pytestmark``: the whole module goes; read from the file, because xdist 3.8's own marking of
    the node id has no effect under pytest 9, whose node ids are no longer ``_nodeid``), else its
    module."""
    if "@" in nodeid:                   # a later xdist's marking, should it work again
        return nodeid.rsplit("@", 1)[-1]
    module = nodeid.split("::", 1)[0]
    return "serial" if _serial(rootpath / module) else module


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """``--dist loadgroup`` by module. xdist's own loadgroup sends each unmarked test anywhere (a
    module's fixtures then built on every worker); here a test goes with its module or its group.
    The longest units start first (by the seconds the last run took, in the pytest cache), so no
    long one is left for the end while the other worker idles; without a record, xdist's order."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadGroupScheduling

    cache = getattr(config, "cache", None)
    seconds: dict[str, float] = cache.get(SCOPE_SECONDS, {}) if cache is not None else {}

    class ModuleOrGroupScheduling(LoadGroupScheduling):
        ordered = False

        def _split_scope(self, nodeid: str) -> str:
            return _scope(config.rootpath, nodeid)

        def _seconds(self, scope: str) -> float:
            """The unit's seconds last time, else its modules' (a group recorded module by module)."""
            if scope in seconds:
                return seconds[scope]
            return sum(seconds.get(m, 0.0) for m in {n.split("::", 1)[0] for n in self.workqueue[scope]})

        def _assign_work_unit(self, node) -> None:
            if not self.ordered:
                self.ordered = True
                for scope in sorted(self.workqueue, key=lambda s: -self._seconds(s)):
                    self.workqueue.move_to_end(scope)
            super()._assign_work_unit(node)

    return ModuleOrGroupScheduling(config, log)


_seconds_this_run: dict[str, float] = {}
_rootpath: Path | None = None


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    scope = _scope(_rootpath or Path.cwd(), report.nodeid)
    _seconds_this_run[scope] = _seconds_this_run.get(scope, 0.0) + report.duration


def pytest_sessionfinish(session: pytest.Session) -> None:
    """The controller (or a run without xdist) records the units' seconds for the next run's order."""
    cache = getattr(session.config, "cache", None)
    if cache is None or hasattr(session.config, "workerinput") or not _seconds_this_run:
        return
    seconds = cache.get(SCOPE_SECONDS, {})
    seconds.update({k: round(v, 2) for k, v in _seconds_this_run.items()})
    cache.set(SCOPE_SECONDS, seconds)


@pytest.fixture(scope="session")
def datasets(tmp_path_factory: pytest.TempPathFactory):
    """The run's twin datasets by scenario (``datasets.dataset(sc)``: shared, read-only;
    ``datasets.copy(sc, dest)``: a test's own copy). Under xdist the workers share the folder
    (their base temporary folders' parent), so a scenario is simulated once per run."""
    from tests.support.datasets import DatasetFactory

    base = tmp_path_factory.getbasetemp()
    root: Path = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "twin-datasets"
    factory = DatasetFactory(root)
    yield factory
    changed = factory.verify()
    assert not changed, f"a test wrote into a shared dataset (take datasets.copy(sc, dest) to change one): {changed}"


# ----------------------------------------------------------------------------- certified runs
# A small simulated jia2019 run and a reduced hsieh2022 run, analysed with the loop closed and the
# truth deleted: the inputs of the certificate's tests (tests/app/test_certificate.py) and of the
# calibration files' and honest certificate's tests (tests/app/); simulated once per session.


@pytest.fixture(scope="session")
def jia_results(datasets) -> Path:
    """A reduced jia2019 run (the dataset tests/analysis/test_parallel_frames.py analyses too)."""
    from benchtwin.analysis.pipeline import analyze
    from benchtwin.twin.scenario import load_scenario

    sc = load_scenario().with_overrides({"procedure.radial_positions": 36, "procedure.ccd_step": "12 deg"})

    def make(base: Path) -> None:
        ds = datasets.copy(sc, base / "ds", ignore=("truth",))  # the certificate is made without ground truth
        analyze(ds, base / "out", progress=False, close_loop=True)

    # analysed once per run, by one xdist worker (the modules reading it run on either): read-only
    return datasets.shared("jia_results: jia2019 36 positions, ccd_step 12 deg, close_loop, no truth", make) \
        / "out" / "results.json"


@pytest.fixture(scope="session")
def hsieh_results(datasets) -> Path:
    """hsieh2022 reduced: 12 heads and self-calibration kept, fewer shifts, faces and stops, no CCD
    sweep worth the time (the eccentricity is covered by the jia run)."""
    from benchtwin.analysis.pipeline import analyze
    from benchtwin.twin.scenario import load_scenario

    sc = load_scenario(Path(__file__).resolve().parents[1] / "scenarios" / "hsieh2022.toml").with_overrides({
        "procedure.radial_positions": 36, "procedure.radial_reps": 2, "procedure.polygon_shifts": ["0 deg", "5 deg", "10 deg"],
        "procedure.polygon_reps": 1, "procedure.ccd_step": "12 deg", "procedure.selfcal_step": "15 deg",
        "procedure.directions": ["forward"], "bench.polygon_faces": 12})

    def make(base: Path) -> None:
        ds = datasets.copy(sc, base / "ds", ignore=("truth",))
        analyze(ds, base / "out", progress=False, close_loop=True)

    # simulated and analysed once per run, by one xdist worker (the modules reading it run on either)
    return datasets.shared("hsieh_results: hsieh2022 reduced, close_loop, no truth", make) / "out" / "results.json"


@pytest.fixture
def kill_env():
    """The environment for a subprocess the test kills with SIGKILL. A killed process cannot remove its
    multiprocessing listener folder (`pymp-*`), so its TMPDIR is a folder of its own, removed with what
    is left in it when the test ends (two `pymp-*` stayed in /tmp per suite run before this). The folder
    is short and in the system's temporary folder: a listener's AF_UNIX path must stay under 108 bytes,
    which a folder inside tmp_path does not."""
    import shutil
    import tempfile

    tmp = tempfile.mkdtemp(prefix="bt-kill-")
    yield {**os.environ, "TMPDIR": tmp}
    shutil.rmtree(tmp, ignore_errors=True)
