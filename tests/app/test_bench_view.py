"""The rendered bench view (MuJoCo offscreen, EGL): the bodies are in the picture and every
instrument's label points inside it, at a drawn (non-background) pixel."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.render


def test_bench_render_shows_bodies_and_instruments():
    from benchtwin.app.bench_view import render_bench
    from benchtwin.twin.scenario import load_scenario

    img, labels = render_bench(load_scenario(), width=500, height=380)
    assert img.shape == (380, 500, 3)
    drawn = ~np.all(img == 238, axis=2)
    assert 0.05 < drawn.mean() < 0.8  # the bench fills part of the frame
    for name in ("reading head", "probe tops (Y, X)", "probe bottoms (Y, X)", "autocollimator", "CCD microscope",
                 "@shaft", "@grating disk", "@polygon", "@bearing top", "@bearing bottom"):
        assert name in labels, name
        u, v = labels[name]
        assert 0 <= u < 500 and 0 <= v < 380, name
        win = drawn[max(int(v) - 6, 0):int(v) + 7, max(int(u) - 6, 0):int(u) + 7]
        assert win.any(), f"{name}: the label points at empty background"
