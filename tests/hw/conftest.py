"""Shared fixtures of the hardware-layer tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def simulated(datasets):
    """The twin's dataset of the small jia2019 acquisition (tests/support/resume.py), shared and
    read-only: what a resumed acquisition must equal."""
    from tests.support.resume import small_scenario

    return datasets.dataset(small_scenario(), backend="analytic")
