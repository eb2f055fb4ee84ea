"""Suite-wide test configuration.

- Headless OpenGL is configured before anything imports pyrender or mujoco's renderer.
- ``--hardware`` opts in to tests that need a real bench (marker ``hardware``); never in CI.
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


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--hardware"):
        return
    skip = pytest.mark.skip(reason="needs a real bench: opt in with --hardware")
    for item in items:
        if "hardware" in item.keywords:
            item.add_marker(skip)


# ----------------------------------------------------------------------------- certified runs
# A small simulated jia2019 run and a reduced hsieh2022 run, analysed with the loop closed and the
# truth deleted: the inputs of the certificate's tests (tests/test_certificate.py) and of the
# calibration files' and honest certificate's tests (tests/app/); simulated once per session.


@pytest.fixture(scope="session")
def jia_results(tmp_path_factory) -> Path:
    from benchtwin.analysis.pipeline import analyze
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import simulate

    sc = load_scenario().with_overrides({"procedure.radial_positions": 36, "procedure.ccd_step": "12 deg"})
    base = tmp_path_factory.mktemp("cert_jia")
    ds = simulate(sc, base / "ds", progress=False, backend="analytic")
    shutil.rmtree(ds / "truth")  # the certificate is made without ground truth
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
