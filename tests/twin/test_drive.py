"""The drive servo on the encoder's count (twin/instruments/drive.py): holds the count, settles,
stick-slip at the stop, and the held count's truth in a simulated dataset."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from benchtwin.twin.instruments.drive import DriveParams, DriveServo, spin_inertia_kgm2
from benchtwin.twin.physics import Bench
from benchtwin.twin.scenario import load_scenario

from benchtwin.units import ARCSEC  # noqa: E402
from tests.support.scenarios import small_scenario
RES = 0.39 * ARCSEC
CELL_SIGMA = RES / math.sqrt(12.0)          # rectangular distribution over one count (GUM 4.3.7)


def stops(servo: DriveServo, n: int, seed: int, distance_deg: float = 1.0, direction: int = +1):
    """n moves of ``distance_deg`` in ``direction``, each at its own sample-clock phase (uniform on
    [0, Ts), as ``settle_keyed`` draws it) and with its own amplifier-noise draw."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        phase = rng.uniform(0.0, servo.Ts)
        out.append(servo.settle(direction * math.radians(distance_deg), math.radians(20.0), math.radians(40.0), phase,
                                rng))
    return out


def test_frictionless_servo_rests_uniformly_within_the_held_count():
    """Air bearing (hsieh2022: no friction): the count is held and the continuous reading sits
    anywhere in its cell, σ = res/√12."""
    servo = DriveServo(DriveParams(shaft_inertia=2.7e-4, coupling_stiffness=9.1e3, friction_torque=0.0,
                                   torque_noise=2e-5, resolution_rad=RES))
    rs = stops(servo, 150, seed=1)
    off = np.array([r.offset_rad for r in rs])
    # without friction nothing holds the shaft but the loop: with the amplifier noise a few stops
    # still dither across a count edge after max_settle (the count they end on is then held)
    assert sum(r.settled for r in rs) >= 0.85 * len(rs)
    assert sum(r.held_count == 0 for r in rs) >= 0.95 * len(rs)
    assert np.all(np.abs(off) <= 1.5 * RES)
    off = np.array([r.offset_rad for r in rs if r.held_count == 0])
    assert np.all(np.abs(off) <= 0.5 * RES + 1e-12)
    assert np.std(off) == pytest.approx(CELL_SIGMA, rel=0.2)
    assert abs(np.mean(off)) < 0.5 * CELL_SIGMA          # a slight lean toward the approach side
    assert 0.0 < np.median([r.settle_s for r in rs]) < 0.05


def test_stick_slip_servo_holds_the_count_with_the_friction_it_sticks_at():
    """Ball bearing (jia2019: 0.02 N·m sliding, ×1.2 breakaway): the shaft sticks inside the count's
    cell, displaced toward the approach side's far end (it slides into the cell and the friction
    stops it), holding a torque within the static friction band; the rest is mirrored backward."""
    p = DriveParams(shaft_inertia=5.57e-5, coupling_stiffness=690.0, friction_torque=0.02, torque_noise=2e-5,
                    resolution_rad=RES)
    servo = DriveServo(p)
    fwd, bwd = stops(servo, 60, seed=2), stops(servo, 60, seed=3, direction=-1)
    for rs, sgn in ((fwd, +1), (bwd, -1)):
        held = [r for r in rs if r.settled and r.held_count == 0]
        assert len(held) >= 0.95 * len(rs)
        off = np.array([r.offset_rad for r in held])
        tf = np.array([r.friction_torque_Nm for r in held])
        assert np.all(np.abs(off) <= 0.5 * RES + 1e-12)
        assert sgn * np.mean(off) > 0                       # past the cell centre, in the approach direction
        assert np.std(off) > 0.2 * CELL_SIGMA               # not one fixed point
        assert np.all(np.abs(tf) <= 1.2 * 0.02 * 1.02)      # within the static friction
        assert sgn * np.mean(tf) < -0.25 * 0.02             # the friction opposing the motion holds
    # more breakaway friction than sliding friction is what makes it stick-slip: without it the
    # same stops end elsewhere
    flat = DriveServo(DriveParams(**{**p.__dict__, "static_friction_ratio": 1.0}))
    off_flat = np.array([r.offset_rad for r in stops(flat, 60, seed=2)])
    assert np.max(np.abs(off_flat - np.array([r.offset_rad for r in fwd]))) > 0.01 * ARCSEC


def test_servo_is_reproducible_and_the_noise_stream_matters():
    p = DriveParams(shaft_inertia=5.57e-5, friction_torque=0.02, torque_noise=2e-5, resolution_rad=RES)
    a = [r.offset_rad for r in stops(DriveServo(p), 5, seed=4)]
    b = [r.offset_rad for r in stops(DriveServo(p), 5, seed=4)]
    c = [r.offset_rad for r in stops(DriveServo(p), 5, seed=5)]
    assert a == b and a != c


def test_the_sample_clock_phase_is_the_moves_own_draw():
    """Issue #33 (an honest servo): the free-running sample clock's phase at a stop is drawn per
    move, uniform on [0, Ts), from the move's ``servo_clock`` stream: the same key gives the same
    phase and rest (settle_ahead.py's workers), the bench time no longer enters, the amplifier
    noise keeps its own draws, and a phase outside [0, Ts) is refused."""
    from scipy import stats

    from benchtwin.twin.streams import restream, rng_from_key, stream_key

    p = DriveParams(shaft_inertia=5.57e-5, friction_torque=0.02, torque_noise=2e-5, resolution_rad=RES)
    servo = DriveServo(p)
    keys = [stream_key(7, "servo", 0, i + 1, 0) for i in range(400)]
    ph = np.array([servo.clock_phase_s(k) for k in keys])
    assert np.all((ph >= 0.0) & (ph < servo.Ts))
    assert stats.kstest(ph / servo.Ts, "uniform").pvalue > 1e-3
    assert servo.clock_phase_s(keys[0]) == ph[0]
    # the clock's stream is not the noise's: the noise is drawn from the move's key as before
    assert restream(keys[0], "servo_clock") == (7, 111, 0, 1, 0) != keys[0]
    d, v, a = math.radians(1.0), math.radians(20.0), math.radians(40.0)
    assert servo.settle_keyed((d, v, a, 1.0, keys[1])) == servo.settle(d, v, a, ph[1], rng=rng_from_key(keys[1]))
    # one move at two bench times a whole number of samples apart, and 0.35 sample apart: the same rest
    # (before: the first pair repeated, the second did not), the key alone decides
    r0 = servo.settle_keyed((d, v, a, 10.0, keys[3]))
    assert servo.settle_keyed((d, v, a, 10.5, keys[3])) == r0
    assert servo.settle_keyed((d, v, a, 10.50007, keys[3])) == r0
    assert servo.settle_keyed((d, v, a, 10.0, keys[4])) != r0
    with pytest.raises(ValueError):
        servo.settle(d, v, a, servo.Ts)
    with pytest.raises(ValueError):
        servo.settle(d, v, a, -1e-9)


def test_shaft_inertia_is_the_bench_models():
    b = Bench(load_scenario("scenarios/jia2019.toml"))
    J = spin_inertia_kgm2(b.model)
    assert 1e-5 < J < 1e-3                                   # disk + shaft + spheres + polygon
    servo = DriveServo.sim_from_bench(b.sc, b)
    assert servo.p.shaft_inertia == J
    assert servo.p.friction_torque == b.friction_torque_Nm
    assert servo.p.coupling_stiffness == pytest.approx(800.0 * 5000.0 / 5800.0)


def _truth(path, name):
    rows = list(csv.DictReader(open(path / "truth" / f"{name}.csv")))
    return {k: np.array([float(r[k]) for r in rows]) for k in ("theta_deg", "target_deg", "true_deg", "alpha_arcsec")}


@pytest.fixture(scope="module")
def small_servo_ds(datasets):
    """tests/twin/test_simulate.py's small bench (the same dataset: simulated once per run)."""
    return datasets.dataset(small_scenario())


def test_truth_keeps_the_held_count_and_the_continuous_error(small_servo_ds):
    """truth/polygon.csv and truth/radial_motion.csv: theta_deg = the held count, true_deg, and
    α at the true pose, so (θ − true)·3600 − α is minus the rest offset in the count's cell."""
    res = small_scenario()["bench"]["encoder_resolution"] / ARCSEC
    for name in ("polygon", "radial_motion"):
        t = _truth(small_servo_ds, name)
        counts = t["theta_deg"] * 3600.0 / res
        np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)     # a whole count
        dn = np.abs(t["theta_deg"] - t["target_deg"]) * 3600.0 / res          # counts from the target
        assert np.max(dn) <= 1.5 and np.mean(dn > 0.5 + 1e-9) <= 0.05       # (a rare unsettled stop: ±1)
        r = (t["theta_deg"] - t["true_deg"]) * 3600.0 - t["alpha_arcsec"]
        assert np.max(np.abs(r)) <= 0.5 * res + 1e-4
        assert np.std(r) > 0.2 * res / math.sqrt(12.0)
