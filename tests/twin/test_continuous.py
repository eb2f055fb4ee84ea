"""The ISO 230-7 continuous-rotation run (twin/continuous.py): its spectrum shows the ball sets'
kinematic orders, which nothing in the twin writes down as frequencies — they come from the cages
rolling at rho and the ball forces summed at the balls' azimuths (twin/bearing.py)."""

from __future__ import annotations

import math

import numpy as np

from benchtwin.twin.continuous import continuous_run, spectrum_per_rev
from benchtwin.twin.scenario import load_scenario
from benchtwin.twin.simulate import sim_build

SPR = 32      # samples per revolution: Nyquist 16 cycles/rev, above the orders checked
REVS = 20     # ISO 230-7: at least 20 revolutions; resolution 1/20 = 0.05 cycles/rev


def test_continuous_run_spectrum_shows_the_ball_sets_kinematic_orders():
    sc = load_scenario()                      # jia2019: P4 ball bearings, G5 balls
    bench, state, inst = sim_build(sc, camera=False)
    cols = continuous_run(bench, state, inst, math.radians(60.0), REVS, SPR)
    assert len(cols["t_s"]) == REVS * SPR
    assert np.all(np.diff(cols["t_s"]) > 0)
    assert cols["t_s"][-1] - cols["t_s"][0] == (REVS * SPR - 1) * 6.0 / SPR or np.isclose(
        cols["t_s"][-1] - cols["t_s"][0], (REVS * SPR - 1) * 6.0 / SPR)
    bs = bench.ball_sets["top"]
    Z, rho = bs.Z, bs.rho
    orders = {"ball pass, outer race": Z * rho, "ball pass, inner race - 1": Z * (1 - rho) - 1,
              "ball pass, inner race + 1": Z * (1 - rho) + 1}
    ratio = {name: 0.0 for name in orders}
    kin = list(orders.values()) + [rho, 2 * Z * rho, 2 * Z * (1 - rho) - 1, 3 * Z * rho]
    for probe in ("probe_top_x_um", "probe_top_um"):
        f, a = spectrum_per_rev(np.array(cols[probe]), SPR)
        band = (f > 0.2) & (f < 15.5) & (np.abs(f - np.round(f)) > 0.11)   # asynchronous bins
        floor = np.median(a[band])
        for name, fk in orders.items():
            near = np.abs(f - fk) <= 0.051
            ratio[name] = max(ratio[name], a[near].max() / floor)
        # the largest asynchronous peak is a kinematic order (or a multiple of one, or the cage)
        fpk = f[band][np.argmax(a[band])]
        assert min(abs(fpk - k) for k in kin) <= 0.051, (probe, fpk)
    # every ball-pass order stands well above the asynchronous floor in X or Y (how strongly in
    # each depends on the drawn waviness and on how the two bearings' motions add at the sphere)
    assert min(ratio.values()) > 4.0, ratio
