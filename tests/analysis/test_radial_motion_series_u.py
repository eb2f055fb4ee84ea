"""The order-2…10 series' error-motion values carry their own u (issue 34 item 4: Jia's series and ISO
230-7's unfiltered values are two quantities, each with its bandwidth and u).

Theory: with a probe's reading u given, each revolution's least-squares Fourier fit of order K on N
equally spaced angles has cov = u²·(AᵀA)⁻¹ = (2u²/N)·I for the harmonic coefficients, so the series of
orders 2…K at a point has variance u²·2(K − 1)/N; a range (total, asynchronous) is the difference of
two such points, u = √2 of it, the synchronous mean of n revolutions √(2/n) of it, and the disk plane
(Jia eq. 9) weights the two probes' variances by w_top², w_bot².
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchtwin.analysis.radial_motion import ProbeReadings, RadialOptions, SphereSpacing, disk_weights, radial_motion

L1, L2 = 6.81, 122.96  # mm, Jia sec. 5


@pytest.mark.parametrize("n_theta, reps", [(36, 3), (72, 2)])
def test_series_values_u_is_the_reading_u_through_the_fit(n_theta, reps):
    rng = np.random.default_rng(34)
    th = np.tile(np.arange(n_theta) * 360.0 / n_theta, reps)
    rep = np.repeat(np.arange(reps), n_theta)
    t = np.radians(th)
    top = 2.0 * np.cos(3 * t) + rng.normal(0.0, 0.05, th.size)
    bot = 1.0 * np.sin(5 * t) + rng.normal(0.0, 0.05, th.size)
    u = 0.05
    rm = radial_motion(ProbeReadings(rep, th, top, bot), SphereSpacing(L1, L2), RadialOptions(u_probe_um=u))
    K = rm["order"]
    point = u**2 * 2 * (K - 1) / n_theta
    w_top, w_bot = disk_weights(L1, L2)
    for name, var in (("top", point), ("bottom", point), ("disk", (w_top**2 + w_bot**2) * point)):
        s = rm["summary"][name]
        assert s["total_u_um"] == pytest.approx(math.sqrt(2 * var), rel=1e-9), name
        assert s["asynchronous_u_um"] == pytest.approx(math.sqrt(2 * var), rel=1e-9), name
        assert s["synchronous_u_um"] == pytest.approx(math.sqrt(2 * var / reps), rel=1e-9), name
    assert (rm["bandwidth"]["lowest_order"], rm["bandwidth"]["highest_order"]) == (2, K)


def test_one_revolution_has_no_asynchronous_u():
    th = np.arange(36) * 10.0
    t = np.radians(th)
    rm = radial_motion(ProbeReadings(np.zeros(36, int), th, np.cos(2 * t), np.sin(3 * t)), SphereSpacing(L1, L2),
                       RadialOptions(u_probe_um=0.05))
    assert math.isnan(rm["summary"]["disk"]["asynchronous_u_um"]) and rm["summary"]["disk"]["total_u_um"] > 0
