"""The fused ball-set kernel (twin/ballsets.py) against the per-set reference formulas of
twin/bearing.py, and the bench's Newton matrix and tangent (twin/physics.py) against finite
differences. Agreement only: the speed is the benchmarks' (benchmarks/physics_floor.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.twin.ballsets import BallSets
from benchtwin.twin.bearing import BallBearingGeometry, BallSet, generate_ball_set
from benchtwin.twin.physics import Bench
from benchtwin.twin.scenario import load_scenario

GEOM = BallBearingGeometry(balls=12, ball_diameter_m=6.35e-3, pitch_diameter_m=31e-3,
                           contact_angle_rad=math.radians(15), preload_N=50.0)


def _sets(seed: int = 5) -> tuple[BallSet, BallSet]:
    rng = np.random.default_rng(seed)
    top = generate_ball_set(GEOM, "P4", "G5", rng)
    g2 = BallBearingGeometry(balls=9, ball_diameter_m=7.0e-3, pitch_diameter_m=35e-3,
                             contact_angle_rad=math.radians(25), preload_N=80.0)
    return top, generate_ball_set(g2, "P0", "G28", rng, waviness_scale=3.0)


def _reference(sets, u, th, cages):
    F, K = [], []
    for s, bs in enumerate(sets):
        f, k = bs.force_and_stiffness(np.asarray(u[2 * s:2 * s + 2]), th, cages[s])
        F += list(f)
        K.append(k)
    return np.array(F), K


@pytest.mark.parametrize("scale", [1e-8, 3e-7, 3e-6])   # 3 µm > delta_0: balls lose contact
def test_forces_and_stiffness_are_the_reference_formulas(scale):
    sets = _sets()
    kern = BallSets(sets)
    rng = np.random.default_rng(11)
    lost = 0
    for _ in range(20):
        u = rng.normal(0.0, scale, 4)
        th, cages, rates = rng.uniform(-10, 10), rng.uniform(0, 7, 2), rng.uniform(0.3, 0.5, 2)
        F, K, _g = kern.evaluate(u, th, cages, rates)
        Fr, Kr = _reference(sets, u, th, cages)
        np.testing.assert_allclose(F, Fr, rtol=0, atol=1e-12 * np.abs(Fr).max())
        for s in range(2):
            kr = Kr[s]
            np.testing.assert_allclose(K[s], [kr[0, 0], kr[0, 1], kr[1, 1]], rtol=0, atol=1e-12 * np.abs(kr).max())
        for s, bs in enumerate(sets):
            lost += int(np.any(bs.ball_loads_N(u[2 * s:2 * s + 2], th, cages[s]) == 0.0))
    if scale > 1e-6:
        assert lost > 0          # the unloaded-ball branch was exercised


def test_interference_is_the_reference_sum():
    sets = _sets()
    kern = BallSets(sets)
    th, cages = 2.3, (0.7, 5.1)
    w, _dw = kern.interference(th, cages, (0.4, 0.4))
    ref = []
    for s, bs in enumerate(sets):    # interference_m = cos(a)·(w_i + w_o) + dD
        ref += list((bs.interference_m(th, cages[s]) - bs._dd) / bs.cos_a)
    np.testing.assert_allclose(w, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


def test_shaft_angle_rate_is_the_derivative_of_the_forces():
    """g = ∂F/∂θ at fixed u, the cage turning at ``rates``: central differences of the reference
    forces (step 1e-6 rad: truncation ~1e-12, rounding ~1e-9 relative)."""
    sets = _sets()
    kern = BallSets(sets)
    rng = np.random.default_rng(2)
    for _ in range(10):
        u = rng.normal(0.0, 3e-7, 4)
        th, c0, rates = rng.uniform(-3, 3), rng.uniform(0, 7, 2), rng.uniform(0.3, 0.5, 2)
        _F, _K, g = kern.evaluate(u, th, c0, rates)
        h = 1e-6

        def F_at(t, u=u, th=th, c0=c0, rates=rates):
            return _reference(sets, u, t, c0 + rates * (t - th))[0]

        fd = (F_at(th + h) - F_at(th - h)) / (2 * h)
        np.testing.assert_allclose(g, fd, rtol=0, atol=1e-6 * np.abs(fd).max())


def test_no_lobes_and_replaced_sets():
    plain = BallSet(GEOM)
    kern = BallSets([plain, plain])
    F, K, g = kern.evaluate([1e-7, 0.0, 0.0, -1e-7], 0.3, [0.1, 0.2], [0.4, 0.4])
    Fr, _ = _reference([plain, plain], np.array([1e-7, 0.0, 0.0, -1e-7]), 0.3, [0.1, 0.2])
    # (components that cancel to ~1e-15 N: an absolute tolerance on the force's scale)
    np.testing.assert_allclose(F, Fr, rtol=0, atol=1e-12 * np.abs(Fr).max())
    # a bench whose ball set is replaced after construction uses the new one
    b = Bench(load_scenario())
    b.ball_sets["top"] = plain
    q = b._q_last.copy()
    F_kernel = b._ball_kernel(q)[0]
    np.testing.assert_allclose(F_kernel, b._ball_forces(q), rtol=0, atol=1e-12 * np.abs(F_kernel).max())


@pytest.fixture(scope="module")
def posed():
    b = Bench(load_scenario())
    b.pose_at(1.0, t_s=3.0, direction=+1)
    return b


def test_newton_matrix_is_the_jacobian_of_the_residual(posed):
    """J of ``_residual_and_K`` = −∂r/∂q of the full residual (MuJoCo + reference ball forces) by
    central differences, all six columns (the spin column carries the balls rolling on); the
    contraction J⁻¹·(J − J_fd) of the Newton iteration far below 1 (quadratic convergence)."""
    b = posed
    q = b._q_last.copy()
    b._solve_housing = b._housing_m + b._drift4
    b._set_loads(1.0, +1)
    try:
        r, J = b._residual_and_K(q)
        np.testing.assert_allclose(r, b._residual(q), rtol=0, atol=1e-9)
        J_fd = np.zeros((6, 6))
        for i in range(6):
            h = 1e-9 if i < 2 else 1e-8
            dq = np.zeros(6)
            dq[i] = h
            J_fd[:, i] = -(b._residual(q + dq) - b._residual(q - dq)) / (2 * h)
    finally:
        b._solve_housing = None
    assert np.abs(np.linalg.solve(J, J - J_fd)).max() < 1e-5
    # the spin column: the balls rolling on push the journals by tens of N/rad, which the matrix
    # without ∂F/∂θ (MuJoCo's part and Tᵀ·K_b·T alone) lacks
    col_fd = J_fd[:, 4]
    np.testing.assert_allclose(J[:, 4], col_fd, rtol=0, atol=1e-6 * np.abs(col_fd).max())
    col_old = b._K_mj[:, 4] + b._T.T @ (b._ball_kernel(q)[1] @ b._T[:, 4])
    assert np.abs(col_old - col_fd)[:4].max() > 1.0


def test_tangent_predicts_the_next_pose(posed):
    """The warm start's tangent dq/dcmd = J⁻¹·∂r/∂cmd against two solved poses (same stop)."""
    b = posed
    b.pose_at(1.0, t_s=3.0)
    q0, t = b._q_last.copy(), b._tangent.copy()
    dc = 1e-7
    b.pose_at(1.0 + dc, t_s=3.0)
    q1 = b._q_last.copy()
    np.testing.assert_allclose((q1 - q0) / dc, t, rtol=0, atol=1e-6 * np.abs(t).max())
    assert b.last_iterations == 1      # the prediction was within the settle criterion
