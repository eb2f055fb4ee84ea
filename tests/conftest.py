"""Suite-wide test configuration.

- Headless OpenGL is configured before anything imports pyrender or mujoco's renderer.
- ``--hardware`` opts in to tests that need a real bench (marker ``hardware``); never in CI.
"""

from __future__ import annotations

import os

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
