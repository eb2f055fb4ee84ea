"""The polygon's pyramidal error and the autocollimator's second axis (issue 33 item 6).

A face whose normal is tilted by p out of the plane perpendicular to the polygon's axis returns the
beam tilted by ~2p vertically; the instrument's two axes come from the one reflected beam
r = d − 2(d·n)n (d the beam's direction towards the polygon), so the horizontal reading of such a
face is not exactly its in-plane angle:

- (1) against an independent closed form in (p, a): n = (cos p cos a, cos p sin a, sin p), the
  instrument on +x, d = −x̂: r = (2cos²p cos²a − 1, cos²p sin 2a, sin 2p cos a), horizontal
  x = −½·atan2(r_y, r_x), vertical y = ½·atan2(r_z, r_x); to 1e-12 rad, with p and a large enough
  that the cross-talk x + a ≈ −a·(cos²p/cos 2p − 1) ≈ −a·p² is many times the tolerance (a test
  that can fail);
- (2) a scenario without [polygon] (or with zero pyramidal error) poses and reads exactly as before
  (the datasets' bytes: `benchtwin simulate` + `diff -r`, reported in the commit);
- (3) jia2019 with 5″ on every face, on the bench's own poses (the shaft's tilt and wobble from the
  bearings, the polygon mounted 20″ tilted on the shaft): the horizontal exact reading changes by
  the predicted cross-talk −p·(w·e_t) − p²·u₀ − 3p·u₀·z₀ (w the polygon's axis in the lab, e_t
  the horizontal across the line of sight, u₀ and z₀ the untilted normal's components along e_t
  and z; small-angle expansion of the reflection, X' = u + u³/6 + (3/2)·u·z²), the vertical by p.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from benchtwin.twin.instruments.autocollimator import AutocollimatorSpec, SimAutocollimator
from benchtwin.twin.instruments.stage import SimBenchState, sim_hsieh_to_physics_face
from benchtwin.twin.physics import Bench
from benchtwin.twin.pose import face_normals
from benchtwin.twin.scenario import ScenarioError, load_scenario
from benchtwin.twin.simulate import sim_build
from benchtwin.units import ARCSEC

from tests.support.poses import make_pose

ROOT = Path(__file__).resolve().parents[2]
DEG = math.pi / 180


def closed_form(p: float, a: float) -> tuple[float, float]:
    """Horizontal and vertical face angles of a face with pyramidal angle p turned by a (CCW) in
    front of an instrument on +x, from r = d − 2(d·n)n written out by hand."""
    rx = 2 * math.cos(p) ** 2 * math.cos(a) ** 2 - 1
    ry = math.cos(p) ** 2 * math.sin(2 * a)
    rz = math.sin(2 * p) * math.cos(a)
    return -0.5 * math.atan2(ry, rx), 0.5 * math.atan2(rz, rx)


@pytest.mark.parametrize("p", [0.0, 5 * ARCSEC, -40 * ARCSEC, 0.5 * DEG, -2.0 * DEG])
def test_horizontal_and_vertical_against_the_reflection_closed_form(p):
    N = 8
    faces = 2 * np.pi * np.arange(N) / N
    st = SimBenchState(seed=1, n_faces=N, polygon_setup_rms_rad=0.0)
    ac = SimAutocollimator("ac", st, AutocollimatorSpec(range_rad=1000 * ARCSEC))
    pyr = np.full(N, p)
    worst_xtalk = 0.0
    for a in np.array([-1000.0, -250.0, -3.0, 0.0, 7.5, 400.0, 1000.0, 3600.0]) * ARCSEC:
        pose = make_pose(a, face_angles=faces)
        pose.extra["polygon_face_pyramidal_rad"] = pyr
        x, y, k = ac.sim_exact_angles(pose)
        xc, yc = closed_form(p, a)
        assert k == 1
        assert x == pytest.approx(xc, abs=1e-12), (p, a)
        assert y == pytest.approx(yc, abs=1e-12), (p, a)
        worst_xtalk = max(worst_xtalk, abs(x + a))
        # the cross-talk's law for small a: tan 2x' = k·tan 2a, k = cos²p / cos 2p = 1 + p² + O(p⁴),
        # so x + a = −a·(k − 1) + O(a³·p²): second order in p
        k_p = math.cos(p) ** 2 / math.cos(2 * p)
        assert x + a == pytest.approx(-a * (k_p - 1), abs=1e-15 + 2 * abs(a) ** 3 * p * p)
        assert k_p - 1 == pytest.approx(p * p, rel=1e-5 + 2 * p * p, abs=1e-30)   # (1e-5: the rounding of 1 − 6e-10)
    if abs(p) >= 0.5 * DEG:   # the cross-talk is real and resolved: ≥ 1e4 × the tolerance
        assert worst_xtalk > 1e-8
    else:
        # tens of arcsec: ≤ a·p², 6.6e-10 rad at 3600″ and 40″, 2e-12 rad at 1000″ and 5″
        assert worst_xtalk <= 1.01 * 3600 * ARCSEC * p * p + 1e-15


def test_face_normals_are_unit_and_tilted_by_p():
    g = np.linspace(0, 2 * np.pi, 7, endpoint=False)
    p = np.array([0.0, 5, -5, 20, 0.1, -60, 3]) * ARCSEC
    n = face_normals(g, p)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.arcsin(n[:, 2]), p, rtol=0, atol=1e-18)
    np.testing.assert_allclose(np.arctan2(n[:, 1], n[:, 0]), np.arctan2(np.sin(g), np.cos(g)), rtol=0, atol=1e-15)
    # p = 0 gives exactly the in-plane normals of before (bit for bit)
    assert np.array_equal(face_normals(g, np.zeros(7)), face_normals(g))


def scenario(**kw):
    return load_scenario(ROOT / "scenarios" / "jia2019.toml").with_overrides(kw)


def test_without_the_section_nothing_changes():
    """No [polygon] section, or every pyramidal error 0: no pose key, no truth key, the same
    exact readings bit for bit (the datasets' bytes)."""
    plain = Bench(scenario())
    zero = Bench(scenario(**{"polygon.pyramidal_error": ["0 arcsec"]}))
    assert plain.polygon_pyramidal_rad is None and zero.polygon_pyramidal_rad is None
    assert "polygon_pyramidal_error_rad" not in plain.truth()
    assert plain.truth() == zero.truth()
    angles = []
    for b in (plain, zero):
        st = SimBenchState(b)
        ac = SimAutocollimator.sim_from_scenario(b.sc, st)
        pose = b.pose_at(2 * np.pi / b.n_faces * 3, t_s=10.0)
        assert "polygon_face_pyramidal_rad" not in pose.extra
        angles.append(ac.sim_exact_angles(pose))
    assert angles[0] == angles[1]


def test_the_keys_are_validated():
    with pytest.raises(ScenarioError, match=r"polygon\.pyramidal_error: expected 1 value .* or 23"):
        scenario(**{"polygon.pyramidal_error": ["1 arcsec", "2 arcsec"]})
    with pytest.raises(ScenarioError, match=r"polygon\.pyramidal_error: item 0"):
        scenario(**{"polygon.pyramidal_error": ["2 arcmin"]})      # above 60″
    with pytest.raises(ScenarioError, match=r"polygon\.pyramidal_rms"):
        scenario(**{"polygon.pyramidal_rms": "5"})                  # no unit
    with pytest.raises(ScenarioError, match=r"unknown key polygon\.pyramid"):
        scenario(**{"polygon.pyramid": "5 arcsec"})


def test_numbering_and_seeded_draw():
    """The list is in the dataset's (Hsieh's) face numbering; the rms draw is seeded and added."""
    N = 23
    vals = [f"{h * 0.5:g} arcsec" for h in range(1, N + 1)]
    b = Bench(scenario(**{"polygon.pyramidal_error": vals}))
    for h in range(1, N + 1):
        assert b.polygon_pyramidal_rad[sim_hsieh_to_physics_face(h, N) - 1] == pytest.approx(h * 0.5 * ARCSEC, abs=1e-18)
    r1 = Bench(scenario(**{"polygon.pyramidal_rms": "3 arcsec"})).polygon_pyramidal_rad
    r2 = Bench(scenario(**{"polygon.pyramidal_rms": "3 arcsec"})).polygon_pyramidal_rad
    assert np.array_equal(r1, r2) and 1.0 * ARCSEC < np.std(r1) < 6.0 * ARCSEC
    t = Bench(scenario(**{"polygon.pyramidal_rms": "3 arcsec"})).truth()
    assert t["polygon_pyramidal_error_arcsec"] == pytest.approx((r1 / ARCSEC).tolist(), abs=1e-12)


def test_five_arcsec_on_every_face_changes_the_reading_by_the_predicted_cross_talk():
    """jia2019 (ball bearings: the shaft's tilt and wobble are the Hertz statics'), the polygon
    mounted 20″ tilted on the shaft, p = 5″ on every face: at every face position the exact
    horizontal reading changes by −p·(w·e_t) − p²·u₀ − 3p·u₀·z₀ (to 1e-13 rad), the vertical by p
    (to 1e-12 rad); the poses themselves do not change."""
    p = 5 * ARCSEC
    kw = {"errors.polygon_tilt": "20 arcsec", "errors.polygon_tilt_phase": "30 deg"}
    sc0 = scenario(**kw)
    sc1 = scenario(**kw, **{"polygon.pyramidal_error": ["5 arcsec"]})
    (b0, st0, _), (b1, st1, _) = sim_build(sc0, camera=False), sim_build(sc1, camera=False)
    ac0 = SimAutocollimator.sim_from_scenario(sc0, st0)
    ac1 = SimAutocollimator.sim_from_scenario(sc1, st1)
    N = b0.n_faces
    dx, pred, dy = [], [], []
    for i in range(N):
        th = 2 * np.pi * i / N + 3 * ARCSEC
        q0 = b0.pose_at(th, t_s=100.0 + i)
        q1 = b1.pose_at(th, t_s=100.0 + i)
        assert np.array_equal(q0.polygon.R, q1.polygon.R)      # the statics do not see the faces
        x0, y0, k0 = ac0.sim_exact_angles(q0)
        x1, y1, k1 = ac1.sim_exact_angles(q1)
        assert k0 == k1
        # the prediction from the untilted face and the polygon's axis in the lab
        Rp = st0.polygon_pose(q0).R
        a = np.array([math.cos(ac0.azimuth_rad), math.sin(ac0.azimuth_rad), 0.0])
        et = np.array([-a[1], a[0], 0.0])
        n0 = ac0.sim_face_normals_lab(q0)[k0 - 1]
        w = Rp[:, 2]
        u0, z0 = float(n0 @ et), float(n0[2])
        dx.append(x1 - x0)
        pred.append(-p * float(w @ et) - p * p * u0 - 3 * p * u0 * z0)
        dy.append(y1 - y0)
    dx, pred, dy = map(np.asarray, (dx, pred, dy))
    np.testing.assert_allclose(dx, pred, rtol=0, atol=1e-13)
    np.testing.assert_allclose(dy, p, rtol=0, atol=1e-12)
    # the cross-talk is resolved (p × the 20″ tilt's sideways part, ~5e-10 rad): not a null test
    assert np.max(np.abs(dx)) > 1e-10
    # and far below the readings' resolution (0.005″ = 2.4e-8 rad): the dataset's x barely moves
    assert np.max(np.abs(dx)) < 0.1 * 0.005 * ARCSEC
