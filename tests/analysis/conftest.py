"""Fixtures for the Jia 2019 analysis tests: the grating renderer of tests/support/grating.py."""

from __future__ import annotations

import pytest

from tests.support.grating import lab_to_image_centre, render_grating


@pytest.fixture
def grating_renderer():
    return render_grating


@pytest.fixture
def lab_centre():
    return lab_to_image_centre
