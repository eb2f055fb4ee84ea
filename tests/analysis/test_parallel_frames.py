"""The CCD sweep's frames analysed once each and in parallel give the serial path's results, bit for bit.

analysis/parallel.py (ordered, bounded thread-pool map) and the eccentricity step's decode-once /
edges-once path (analysis/pipeline.py step_eccentricity with analysis/eccentricity.py
frame_edges_and_scale): the pool and the serial loop must give byte-identical results.json, the
same rejected frames in the same order, and the same d_ref as the former two-pass path (edges found
separately for the pixel scale and for d_ref). Issue #17.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from benchtwin.analysis import eccentricity as ecc
from benchtwin.analysis.dataset import open_dataset
from benchtwin.analysis.parallel import default_workers, ordered_map
from benchtwin.analysis.pipeline import analyze, step_eccentricity
from benchtwin.twin.scenario import load_scenario

# xdist: one at a time on one worker (process pools; tests/conftest.py)
pytestmark = pytest.mark.xdist_group("serial")

REDUCED = {"procedure.radial_positions": 36, "procedure.ccd_step": "12 deg"}  # 30 frames (≥ 24 at order 10)


def _square(x: int) -> int:
    return x * x


def _fail_on_three(x: int) -> int:
    if x == 3:
        raise ValueError("three")
    return x


def test_ordered_map_keeps_order_and_raises_in_order():
    items = [(i,) for i in range(23)]
    assert list(ordered_map(_square, iter(items), workers=2, window=3)) == [i * i for i in range(23)]
    assert list(ordered_map(_square, items, workers=1)) == [i * i for i in range(23)]
    assert list(ordered_map(_square, [], workers=2)) == []
    assert list(ordered_map(_square, [(5,)], workers=2)) == [25]
    got = []
    with pytest.raises(ValueError, match="three"):
        for r in ordered_map(_fail_on_three, [(i,) for i in range(8)], workers=2):
            got.append(r)
    assert got == [0, 1, 2]


def _items_failing_at(k: int, n: int):
    for i in range(n):
        if i == k:
            raise KeyError(f"item {k}")
        yield (i,)


def test_ordered_map_items_error_comes_after_the_items_before_it():
    """An error reading item k (a dataset error) is raised after the results of items < k, and after
    an error of fn on one of them, as the serial loop meets them."""
    for w in (1, 2):
        got = []
        with pytest.raises(KeyError, match="item 5"):
            for r in ordered_map(_square, _items_failing_at(5, 9), workers=w, window=4):
                got.append(r)
        assert got == [0, 1, 4, 9, 16]
        with pytest.raises(ValueError, match="three"):
            list(ordered_map(_fail_on_three, _items_failing_at(5, 9), workers=w, window=4))


def _workers_in_child() -> int:
    return default_workers()


def test_pool_workers_analyse_serially(monkeypatch):
    """A process multiprocessing started (a study's pool worker) does not start a pool of its own."""
    import concurrent.futures as cf
    import multiprocessing as mp

    monkeypatch.delenv("BENCHTWIN_WORKERS", raising=False)
    with cf.ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as pool:
        assert pool.submit(_workers_in_child).result() == 1


def test_default_workers_env(monkeypatch):
    monkeypatch.setenv("BENCHTWIN_WORKERS", "1")
    assert default_workers() == 1
    monkeypatch.setenv("BENCHTWIN_WORKERS", "two")
    with pytest.raises(ValueError, match="BENCHTWIN_WORKERS"):
        default_workers()
    monkeypatch.delenv("BENCHTWIN_WORKERS")
    assert 1 <= default_workers() <= 2


@pytest.fixture(scope="module")
def small_ds(tmp_path_factory, datasets) -> Path:
    """A reduced jia2019 dataset (30 frames; tests/app/test_certificate.py's) with its first frame fogged
    (rejected by the analysis)."""
    import cv2

    sc = load_scenario().with_overrides(REDUCED)
    ds = datasets.copy(sc, tmp_path_factory.mktemp("par") / "ds", ignore=("truth",))
    f = (ds / "ccd" / "index.csv").read_text().splitlines()[1].split(",")[2]
    img = cv2.imread(str(ds / "ccd" / f), cv2.IMREAD_UNCHANGED)
    fog = np.median(img) + np.random.default_rng(3).normal(0.0, 2.0, img.shape)
    cv2.imwrite(str(ds / "ccd" / f), np.clip(np.rint(fog), 0, np.iinfo(img.dtype).max).astype(img.dtype))
    return ds


def test_pool_and_serial_results_json_byte_identical(small_ds, tmp_path, monkeypatch):
    """The serial analysis writes its folder (results.json, report); the pool's runs in memory and is
    written out as results.json is (``json.dumps(results, indent=1, sort_keys=True)``: the serial run's own
    file is checked to be exactly that), so the report is not drawn a second time (≈ 2 s of CPU, issue 35):
    the frames' pool changes the eccentricity step, every number of which results.json holds."""
    def as_file(res) -> bytes:
        return (json.dumps(res.to_json(), indent=1, sort_keys=True) + "\n").encode("utf-8")

    monkeypatch.setenv("BENCHTWIN_WORKERS", "1")
    r = analyze(small_ds, tmp_path / "out1", progress=False, close_loop=False)
    out = {"1": Path(r["paths"]["results"]).read_bytes()}
    assert as_file(r["results"]) == out["1"]
    monkeypatch.setenv("BENCHTWIN_WORKERS", "2")
    out["2"] = as_file(analyze(small_ds, progress=False, close_loop=False))
    assert out["1"] == out["2"]
    res = json.loads(out["2"])
    rej = res["ccd_rejected_frames"]
    assert rej and rej[0]["file"] == "img_000.png"  # the fogged frame, first in index order
    assert res["ccd"]["n_images"] == 30 - len(rej)


def test_threads_give_the_serial_per_frame_results(small_ds):
    """Each frame's edges, scale and rejection, in 2 threads, equal the serial loop's, field for field
    (in order whatever the scheduling: the window is small, the frames many)."""
    ds = open_dataset(small_ds)
    args = [(img, ds.bench["grating_period_um"], f, "dark") for _k, _t, img, f in ds.ccd_frames()]
    serial = list(ordered_map(ecc.frame_edges_and_scale, args, workers=1))
    for _ in range(2):
        threaded = list(ordered_map(ecc.frame_edges_and_scale, args, workers=2, window=3))
        assert len(threaded) == len(serial) == 30
        for (e1, s1, x1), (e2, s2, x2) in zip(serial, threaded):
            assert s1 == s2 and str(x1) == str(x2)
            assert (e1 is None) == (e2 is None)
            if e1 is not None:
                for fld in dataclasses.fields(e1):
                    a, b = getattr(e1, fld.name), getattr(e2, fld.name)
                    assert np.array_equal(a, b, equal_nan=isinstance(a, np.ndarray) and a.dtype.kind == "f")
    assert serial[0][0] is None  # the fogged frame


@pytest.fixture(scope="module")
def step_ecc(small_ds):
    """The eccentricity step on the dataset, in 2 threads (read, never changed, by the two tests below:
    the same call in each, computed once)."""
    return step_eccentricity(open_dataset(small_ds), 10, False, workers=2)


def test_report_overlay_is_the_steps_own_fit(small_ds, step_ecc):
    """The report draws the first used frame's fit from the step (not found again); it is the fit
    the figure code would recompute from the frame."""
    ds = open_dataset(small_ds)
    res = step_ecc
    own = res.detail["first_frame_fit"]
    assert own["file"] == res.frames.files[0] == "img_001.png"  # img_000 is fogged
    img = ds.read_image(own["file"])
    again = ecc.d_ref_px(img, tuple(ds.manifest["ccd"]["reference_px"]), radius_px=res.frames.radius_fixed_px,
                         name=own["file"])
    for k in ("d_ref_px", "residual_rms_px", "centre_px", "radius_px", "reference_px", "points_px",
              "rejected_points_px"):
        assert np.array_equal(np.asarray(own["fit"][k]), np.asarray(again[k])), k
    assert own["fit"]["d_ref_px"] * res.frames.pixel_um == res.frames.d_ref_um[0]


def test_edges_once_equals_the_two_pass_path(small_ds, step_ecc):
    """The former path: pixel scale and d_ref each found the frame's edges themselves."""
    ds = open_dataset(small_ds)
    new = step_ecc
    ccd = ds.manifest["ccd"]
    scales, frames, rejected = [], [], []
    for _k, _theta, image, f in ds.ccd_frames():
        try:
            scales.append(ecc.pixel_scale_um(image, ds.bench["grating_period_um"], name=f)["pixel_um"])
        except ecc.ImageAnalysisError:
            rejected.append((f, "pixel scale (eq. 13)"))
            continue
        frames.append((f, image))
    scale = float(np.median(scales))
    radius_px = ds.bench["scale_edge_radius_mm"] * 1000.0 / scale
    d_old, files = [], []
    for f, img in frames:
        try:
            d_old.append(ecc.d_ref_px(img, tuple(ccd["reference_px"]), radius_px=radius_px, name=f)["d_ref_px"])
        except ecc.ImageAnalysisError:
            rejected.append((f, "d_ref (eqs. 10-12)"))
            continue
        files.append(f)
    assert new.frames.pixel_um == scale
    assert new.frames.files == files
    assert np.array_equal(np.asarray(new.frames.d_ref_um), np.asarray(d_old) * scale)
    assert [(r["file"], r["stage"]) for r in new.frames.rejected_frames] == rejected
    assert rejected[0] == ("img_000.png", "pixel scale (eq. 13)")


def _two_pass_polarity(grey, min_area_px=20):
    """The per-frame rule as it was written before: both classes labelled with statistics."""
    import cv2

    t = ecc.otsu_threshold(grey)
    best = None
    for pol, b in (("dark", grey < t), ("bright", grey > t)):
        _n, _lab, st, _ = cv2.connectedComponentsWithStats(b.astype(np.uint8), connectivity=8)
        big = int(np.count_nonzero(st[1:, cv2.CC_STAT_AREA] >= min_area_px))
        if best is None or big > best[0]:
            best = (big, pol)
    return best[1]


def test_expected_polarity_orders_the_work_only(grating_renderer):
    """Whatever polarity is expected (the sweep's), each frame's choice, labels and edges are those
    of the per-frame rule with both classes labelled; the expected class losing is handled."""
    R_px = 22.5e3 / 0.667
    W, H = 400, 300
    centre = (W / 2.0 - (R_px + 2.0), H / 2.0 + 10.0)
    period_px = 20.0 / 0.667
    dark = grating_renderer(W, H, centre, R_px, period_px, to_uint8=True)
    bright = grating_renderer(W, H, centre, R_px, period_px, glass=25.0, chrome=210.0, to_uint8=True)
    for img, pol in ((dark, "dark"), (bright, "bright")):
        grey, _ = ecc.to_grey(img)
        assert _two_pass_polarity(grey) == pol
        free = ecc.segment_lines(grey)
        ref = ecc.frame_edges_and_scale(img, 20.0, "f")
        assert ref[0] is not None and ref[0].polarity == pol
        for hint in ("dark", "bright"):
            known = ecc.segment_lines(grey, expect_polarity=hint)
            assert free.polarity == known.polarity == pol
            assert np.array_equal(free.labels, known.labels) and np.array_equal(free.lines, known.lines)
            assert np.array_equal(free.stats, known.stats)
            ed, scale, exc = ecc.frame_edges_and_scale(img, 20.0, "f", hint)
            assert exc is None and ed is not None and ed.polarity == pol and scale == ref[1]
            assert np.array_equal(ed.points_px, ref[0].points_px)
    with pytest.raises(ValueError, match="polarity"):
        ecc.segment_lines(ecc.to_grey(dark)[0], expect_polarity="grey")
