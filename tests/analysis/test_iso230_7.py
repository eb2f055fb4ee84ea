"""ISO 230-7 error motion values (analysis.iso230_7) on synthetic revolutions with known content."""

from __future__ import annotations

import numpy as np
import pytest

from benchtwin.analysis.iso230_7 import error_motion, radial_error_motion, remove_fundamental, spectrum_orders

TH = np.arange(0.0, 360.0, 5.0)


def _sync(th):
    return 0.3 * np.cos(np.deg2rad(3 * th) + 0.4) + 0.1 * np.sin(np.deg2rad(5 * th))


def test_values_of_known_motion():
    rng = np.random.default_rng(7)
    n = 4
    asyn = rng.normal(0.0, 0.02, (n, TH.size))
    asyn -= asyn.mean(axis=0)  # the synchronous part is exactly _sync
    # each revolution also carries a centring offset (fundamental) and a probe offset: removed
    revs = _sync(TH) + asyn + 1.7 * np.cos(np.deg2rad(TH - 30.0)) + 5.0
    em = error_motion(TH, revs, sigma_um=0.01)
    assert em["synchronous_um"] == pytest.approx(np.ptp(_sync(TH)), abs=1e-12)
    assert em["asynchronous_um"] == pytest.approx(np.max(np.ptp(asyn, axis=0)), abs=1e-12)
    assert np.ptp(_sync(TH)) <= em["total_um"] <= np.ptp(_sync(TH)) + np.ptp(asyn) + 1e-12
    assert em["total_u_um"] == pytest.approx(np.sqrt(2) * 0.01)
    assert em["synchronous_u_um"] == pytest.approx(np.sqrt(2 / n) * 0.01)


def test_fundamental_does_not_change_the_values():
    rng = np.random.default_rng(1)
    revs = _sync(TH) + rng.normal(0, 0.03, (3, TH.size))
    a = error_motion(TH, revs)
    b = error_motion(TH, revs + 0.8 * np.sin(np.deg2rad(TH)) - 0.2 * np.cos(np.deg2rad(TH)) + 3.0)
    for k in ("total_um", "synchronous_um", "asynchronous_um"):
        assert a[k] == pytest.approx(b[k], abs=1e-12)
    d, coef = remove_fundamental(TH, 2.0 + 0.5 * np.cos(np.deg2rad(TH)))
    assert np.max(np.abs(d)) < 1e-12 and coef == pytest.approx([2.0, 0.5, 0.0], abs=1e-12)


def test_disk_plane_and_unequal_angles_fall_back_to_series():
    n = 3
    rep = np.repeat(np.arange(n), TH.size)
    th = np.tile(TH, n)
    top = np.tile(_sync(TH), n)
    bot = np.tile(0.5 * _sync(TH), n)
    res = radial_error_motion(rep, th, {"probe_top_um": top, "probe_bottom_um": bot}, L1_mm=10.0, L2_mm=100.0)
    disk = next(loc for loc in res["locations"] if loc["name"] == "disk")
    assert disk["synchronous_um"] == pytest.approx(np.ptp(0.9 * _sync(TH) + 0.1 * 0.5 * _sync(TH)), abs=1e-12)
    assert not res["filtered"] and [loc["name"] for loc in res["locations"]] == ["top", "bottom", "disk"]
    th2 = th.copy()
    th2[rep == 1] += 1.0  # revolutions not at the same angles: needs the eq. 7 series
    with pytest.raises(ValueError, match="different angles"):
        radial_error_motion(rep, th2, {"probe_top_um": top, "probe_bottom_um": bot}, L1_mm=10.0, L2_mm=100.0)


def test_spectrum_finds_orders():
    th = np.arange(0, 8 * 360, 2.0)
    d = 0.2 * np.sin(np.deg2rad(7 * th)) + 0.05 * np.cos(np.deg2rad(2.4 * th))
    s = spectrum_orders(th, d)
    assert s["n_revolutions"] == 8
    i7 = np.argmin(np.abs(s["order"] - 7))
    assert s["amplitude_um"][i7] == pytest.approx(0.2, rel=2e-3)  # leakage of the non-integer 2.4
    assert s["order"][np.argmax(s["amplitude_um"] * (np.abs(s["order"] - 7) > 0.5))] == pytest.approx(2.375, abs=0.13)
