"""The rendered bench view (MuJoCo offscreen, EGL): the bodies are in the picture and every
instrument's label points inside it, at a drawn (non-background) pixel."""

from __future__ import annotations

import numpy as np
import pytest

from tests.support.gl import needs_gl

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


def test_bench_render_cache_hit_miss_and_damaged_file(tmp_path, monkeypatch):
    """The render is kept per geometry: a second call reads it (no render), another geometry has
    another key, a damaged cache file is re-rendered and replaced, BENCHTWIN_CACHE=none is off."""
    from benchtwin.app import bench_view as bv
    from benchtwin.twin.scenario import load_scenario

    monkeypatch.setenv("BENCHTWIN_CACHE", str(tmp_path))
    calls = []
    real = bv.render_bench

    def counting(sc, width=bv.WIDTH, height=bv.HEIGHT):
        calls.append(1)
        return real(sc, width, height)

    monkeypatch.setattr(bv, "render_bench", counting)
    sc = load_scenario()
    img1, lab1 = bv.render_bench_cached(sc, 200, 150)
    img2, lab2 = bv.render_bench_cached(sc, 200, 150)
    assert len(calls) == 1 and np.array_equal(img1, img2) and lab1 == lab2
    files = list((tmp_path / "bench_view").glob("*.npz"))
    assert [f.stem for f in files] == [bv.bench_view_key(sc, 200, 150)]
    assert not list((tmp_path / "bench_view").glob("*.part"))  # written under a temporary name, renamed
    other = sc.with_overrides({"bench.L1": "30 mm"})
    assert bv.bench_view_key(other, 200, 150) != bv.bench_view_key(sc, 200, 150)
    assert bv.bench_view_key(sc, 200, 151) != bv.bench_view_key(sc, 200, 150)
    files[0].write_bytes(b"not an npz")
    img3, _ = bv.render_bench_cached(sc, 200, 150)
    assert len(calls) == 2 and np.array_equal(img3, img1)
    bv.render_bench_cached(sc, 200, 150)
    assert len(calls) == 2  # replaced by a good file
    bv.render_bench_cached(other, 200, 150)
    bv._evict(tmp_path / "bench_view", 1)  # only the most recently used picture is kept
    assert [f.stem for f in (tmp_path / "bench_view").glob("*.npz")] == [bv.bench_view_key(other, 200, 150)]
    monkeypatch.setenv("BENCHTWIN_CACHE", "none")
    assert bv.bench_view_cache_dir() is None
    bv.render_bench_cached(sc, 200, 150)
    assert len(calls) == 4


@needs_gl    # the serial frame path's pyrender renderer needs an OpenGL context, as the render tests
def test_bench_view_after_a_ccd_renderer_of_the_same_process_was_closed():
    """pyrender terminates the EGL display when its renderer is closed, and EGL hands MuJoCo the
    same display: a bench view drawn after the serial frame path's renderer was closed failed
    (EGL_NOT_INITIALIZED) until bench_view re-initialised it (the full suite's 10 warnings)."""
    from benchtwin.app.bench_view import render_bench
    from benchtwin.twin.render import Renderer
    from benchtwin.twin.scenario import load_scenario

    sc = load_scenario()
    first, _ = render_bench(sc, width=200, height=150)
    r = Renderer("pyrender")
    r._gl_renderer(64, 48)      # its GL context on this process's EGL display
    r.close()                   # pyrender: eglTerminate on that display
    again, _ = render_bench(sc, width=200, height=150)
    assert np.array_equal(first, again)
