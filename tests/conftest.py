"""Suite-wide test configuration.

- Headless OpenGL is configured before anything imports pyrender or mujoco's renderer.
- ``--hardware`` opts in to tests that need a real bench (marker ``hardware``); never in CI.
- ``datasets``: the session's twin datasets, each scenario simulated once per run, shared by the
  xdist workers of a run (tests/support/datasets.py).
- ``BENCHTWIN_TEST_SIMLOG=FILE`` logs every simulation and process pool (tests/support/simlog.py).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

# Same platform for MuJoCo and PyOpenGL (they must match; EGL is Mesa's software path here).
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--hardware", action="store_true", default=False,
                     help="run tests that talk to a real bench (see hw/README); never in CI")


def pytest_configure(config: pytest.Config) -> None:
    from tests.support import simlog

    if os.environ.get(simlog.LOG_ENV) and not config.pluginmanager.has_plugin("tests.support.simlog"):
        config.pluginmanager.register(simlog, "tests.support.simlog")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--hardware"):
        return
    skip = pytest.mark.skip(reason="needs a real bench: opt in with --hardware")
    for item in items:
        if "hardware" in item.keywords:
            item.add_marker(skip)


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
# truth deleted: the inputs of the certificate's tests (tests/test_certificate.py) and of the
# calibration files' and honest certificate's tests (tests/app/); simulated once per session.


@pytest.fixture(scope="session")
def jia_results(tmp_path_factory, datasets) -> Path:
    """A reduced jia2019 run (the dataset tests/analysis/test_parallel_frames.py analyses too)."""
    from benchtwin.analysis.pipeline import analyze
    from benchtwin.twin.scenario import load_scenario

    sc = load_scenario().with_overrides({"procedure.radial_positions": 36, "procedure.ccd_step": "12 deg"})
    base = tmp_path_factory.mktemp("cert_jia")
    ds = datasets.copy(sc, base / "ds", ignore=("truth",))  # the certificate is made without ground truth
    analyze(ds, base / "out", progress=False, close_loop=True)
    return base / "out" / "results.json"


@pytest.fixture(scope="session")
def hsieh_results(tmp_path_factory) -> Path:
    """hsieh2022 reduced: 12 heads and self-calibration kept, fewer shifts, faces and stops, no CCD
    sweep worth the time (the eccentricity is covered by the jia run)."""
    from benchtwin.analysis.pipeline import analyze
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import simulate

    sc = load_scenario(Path(__file__).resolve().parents[1] / "scenarios" / "hsieh2022.toml").with_overrides({
        "procedure.radial_positions": 36, "procedure.radial_reps": 2, "procedure.polygon_shifts": ["0 deg", "5 deg", "10 deg"],
        "procedure.polygon_reps": 1, "procedure.ccd_step": "12 deg", "procedure.selfcal_step": "15 deg",
        "procedure.directions": ["forward"], "bench.polygon_faces": 12})
    base = tmp_path_factory.mktemp("cert_hsieh")
    ds = simulate(sc, base / "ds", progress=False, backend="analytic")
    shutil.rmtree(ds / "truth")
    analyze(ds, base / "out", progress=False, close_loop=True)
    return base / "out" / "results.json"
