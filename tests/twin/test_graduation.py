"""The disk's graduation as a line-position map (twin/instruments/graduation.py): the ruling walk
closes over the turn and has the 1/k² power of a Brownian bridge, the head's field multiplies the
map's harmonics by the Dirichlet kernel, the declared map has the declared rms, an eccentric
ruling is the exact geometry, and the head interpolates between lines."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.twin.hidden import Hidden
from benchtwin.twin.instruments.encoder_head import EncoderSpec, SimEncoder
from benchtwin.twin.instruments.graduation import (SCANNING_FIELD_LINES, HeadMap, brownian_bridge,
                                                    declared_line_map, dirichlet_factor, eccentric_ruling,
                                                    harmonics, remove_orders, scanning_average)
from benchtwin.twin.instruments.stage import SimBenchState
from benchtwin.units import ARCSEC

N = 7069      # jia2019's line count (2π·22.5 mm / 20 µm)


def test_ruling_walk_closes_over_the_turn():
    """The step from the last line back to the first is an ordinary step of the walk (< 5σ over
    20 seeds), where an open walk's would be ~√N σ."""
    for s in range(20):
        b = brownian_bridge(N, np.random.default_rng(s))
        steps = np.diff(np.append(b, b[0]))
        assert abs(steps[-1]) < 5.0 * np.std(steps)
        assert np.std(steps) == pytest.approx(1.0, rel=0.05)
    w = np.cumsum(np.random.default_rng(0).normal(size=N))
    assert abs(w[-1] - w[0]) > 5.0   # an open walk does not close (|W_N| ~ 84 here)


def test_ruling_walk_has_the_bridge_spectrum():
    """Power ∝ 1/k² (amplitudes ∝ 1/k): the log-log slope of band-averaged power over k = 4…400,
    averaged over 30 seeds, is −2 ± 0.1; and the exact discrete bridge power 1/(4·sin²(πk/N))
    (relative) matches within 15 % per band."""
    k = np.arange(4, 401)
    p = np.zeros(k.size)
    for s in range(30):
        c = np.fft.rfft(brownian_bridge(N, np.random.default_rng(100 + s)))
        p += np.abs(c[k]) ** 2 / 30
    slope = np.polyfit(np.log(k), np.log(p), 1)[0]
    assert slope == pytest.approx(-2.0, abs=0.1)
    theory = N / (4.0 * np.sin(np.pi * k / N) ** 2)     # E|c_k|² of unit steps
    bands = np.array_split(np.arange(k.size), 8)
    for b in bands:
        assert np.mean(p[b]) / np.mean(theory[b]) == pytest.approx(1.0, rel=0.15)


def test_head_field_multiplies_harmonics_by_the_dirichlet_kernel():
    lines = remove_orders(brownian_bridge(N, np.random.default_rng(5)), (0, 1))
    head = scanning_average(lines, SCANNING_FIELD_LINES)
    cl, ch = np.fft.rfft(lines), np.fft.rfft(head)
    for kk in (2, 7, 50, 108, 300):
        d = dirichlet_factor(kk, N, SCANNING_FIELD_LINES)
        assert ch[kk] == pytest.approx(d * cl[kk], rel=1e-9, abs=1e-9 * abs(cl[kk]))
    # low orders pass: 1 − (π·k·W/N)²/6 (0.986 at k = 10 for 7069 lines)
    assert dirichlet_factor(10, N) == pytest.approx(1 - (math.pi * 10 * 65 / N) ** 2 / 6, abs=1e-4)
    assert abs(dirichlet_factor(N / 65, N)) < 1e-12      # the field's first zero at N/W
    # the per-line roughness is averaged away: the head's steps are ~√W smaller than the lines'
    assert np.std(np.diff(head)) < np.std(np.diff(lines)) / 5


def test_declared_map_has_the_declared_rms_without_orders_0_and_1():
    rms = 2.0 * ARCSEC
    lines = declared_line_map(N, rms, np.random.default_rng(3))
    m = HeadMap(lines)
    assert m.rms_rad == pytest.approx(rms, rel=1e-12)
    c = np.fft.rfft(m.head) * 2 / N
    assert abs(c[0]) < 1e-12 * rms and abs(c[1]) < 1e-12 * rms
    # most of the variance in the low orders 2…10, as a bridge (85 %) plus the 3-fold clamp
    share = np.sum(np.abs(c[2:11]) ** 2) / np.sum(np.abs(c[2:]) ** 2)
    assert 0.7 < share < 0.99


def test_eccentric_ruling_is_the_exact_geometry():
    """Lines radial from C' = ε·(cos ψ, sin ψ) cross the circle of radius r at the polar angle the
    map gives (intersection solved here independently), a first harmonic of amplitude ε/r."""
    eps, psi, r = 5e-6, math.radians(40.0), 22e-3
    e = eccentric_ruling(N, eps, psi, r)
    g = 2 * np.pi * np.arange(N) / N
    cx, cy = eps * math.cos(psi), eps * math.sin(psi)
    u = np.stack([np.cos(g), np.sin(g)])
    b = cx * u[0] + cy * u[1]
    rho = -b + np.sqrt(b * b - (cx * cx + cy * cy - r * r))       # |C' + ρu| = r, ρ > 0
    gamma = np.arctan2(cy + rho * u[1], cx + rho * u[0])
    np.testing.assert_allclose(np.angle(np.exp(1j * (gamma - g))), e, atol=1e-15)
    c = np.fft.rfft(e) * 2 / N
    assert abs(c[1]) == pytest.approx(eps / r, rel=1e-6)


def test_head_interpolates_between_lines_and_wraps():
    lines = harmonics(N, [4], [1e-5], [0.3]) + np.random.default_rng(1).normal(0, 1e-7, N)
    m = HeadMap(lines)
    i = np.array([0, 17, N - 1])
    np.testing.assert_allclose(m.error_rad(i * m.pitch_rad), m.head[i], atol=1e-20)
    mid = m.error_rad((N - 0.5) * m.pitch_rad)                    # between the last line and line 0
    assert mid == pytest.approx(0.5 * (m.head[-1] + m.head[0]), rel=1e-12)
    g = np.linspace(0.1, 0.2, 7)
    np.testing.assert_allclose(m.error_rad(g + 2 * np.pi), m.error_rad(g), atol=1e-20)


def test_encoder_reads_declared_plus_hidden_map_with_its_own_streams():
    """The hidden walk has its own seed stream: it changes no declared line; it has its rms; same
    seed, same disk."""
    st = SimBenchState(seed=11)

    def enc(hidden):
        e = SimEncoder("encoder", st, EncoderSpec(radius_m=22e-3, n_lines=N, resolution_rad=0.0,
                                                  graduation_error_rms_rad=1.0 * ARCSEC), seed=11)
        e.hidden = hidden
        return e

    walk = Hidden({"graduation_error": {"ruling_walk_rms": 0.5 * ARCSEC}}, seed=11)
    a, b = enc(None), enc(walk)
    np.testing.assert_array_equal(a._declared_lines, b._declared_lines)
    hidden_lines = b.sim_graduation_map().lines - a.sim_graduation_map().lines
    assert np.sqrt(np.mean(hidden_lines**2)) == pytest.approx(0.5 * ARCSEC, rel=1e-9)
    np.testing.assert_array_equal(enc(Hidden({"graduation_error": {"ruling_walk_rms": 0.5 * ARCSEC}}, seed=11))
                                  .sim_graduation_map().head, b.sim_graduation_map().head)
    other = Hidden({"graduation_error": {"ruling_walk_rms": 0.5 * ARCSEC}}, seed=12)
    assert not np.allclose(enc(other).sim_graduation_map().head, b.sim_graduation_map().head)


def test_error_at_is_error_rad_bit_for_bit():
    """The scalar path of the encoder's fixed point (``HeadMap.error_at``) is ``error_rad`` to the
    last bit: random values over several turns both signs, exact multiples of the pitch and of 2π,
    their neighbours, and ±0."""
    m = HeadMap(harmonics(N, [3, 4], [1e-5, 2e-6], [0.3, 1.1]) + np.random.default_rng(2).normal(0, 1e-7, N))
    rng = np.random.default_rng(5)
    k = np.arange(-2 * N, 2 * N + 1, 97)
    edges = np.concatenate([k * m.pitch_rad, np.arange(-3, 4) * 2 * np.pi, [0.0, -0.0, -1e-300, 1e-300]])
    g = np.concatenate([rng.uniform(-4 * np.pi, 4 * np.pi, 20000), edges, np.nextafter(edges, np.inf),
                        np.nextafter(edges, -np.inf)])
    ref = m.error_rad(g)
    fast = np.array([m.error_at(x) for x in g.tolist()])
    assert np.array_equal(fast.view(np.int64), ref.view(np.int64))
