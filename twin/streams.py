"""The twin's random streams: one table, one way to draw.

Every random quantity of the twin is drawn from ``numpy.random.default_rng(SeedSequence([scenario
seed, stream id, keys…]))``: one independent stream per generated quantity, so adding a quantity
never changes the others for a given scenario seed, and a draw keyed by (instrument, runner step,
draw count) is the same in an interrupted and resumed run as in an uninterrupted one.

The ids are grouped by who draws: the bench's physics 1…17 (``twin/physics.py``), the instruments
101…111 (``twin/instruments``: noise, calibration errors, the servo; ``INSTRUMENT_STREAMS`` is what
``truth/seeds.json`` lists), the hidden quantities of the hidden suite 201…204 (``twin/hidden.py``).
An id never changes meaning: a new quantity takes a new id.
"""

from __future__ import annotations

import numpy as np

__all__ = ["STREAMS", "INSTRUMENT_STREAMS", "HIDDEN_STREAMS", "stream_rng", "stream_key", "rng_from_key", "restream"]

STREAMS: dict[str, int] = {
    # the bench's physics (twin/physics.py)
    "polygon_pitch": 1,
    "polygon_eccentricity_phase": 2,
    "unbalance_phase": 3,
    "cage_lobes": 4,
    "sphere_form": 5,
    "rep_cage_phase": 6,
    "rep_async": 7,
    "ball_set": 8,
    "cage_slip": 9,
    "cage_start": 10,
    "thermal_phase": 11,
    "thermal_axis_azimuth": 12,
    "thermal_cycle_phase": 13,
    "air_form": 14,
    "air_supply": 15,
    "polygon_pyramidal": 16,
    "cage_slip_process": 17,
    "axial": 18,
    # the instruments (twin/instruments; keyed further by instrument, runner step and draw)
    "probe_noise": 101,
    "probe_linearity": 102,
    "encoder_noise": 103,
    "encoder_graduation": 104,
    "encoder_interpolation": 105,
    "ac_noise": 106,
    "ac_accuracy": 107,
    "polygon_setup": 108,
    "ccd": 109,
    "servo": 110,
    # the phase of the servo's free-running sample clock at a move's stop (twin/instruments/drive.py):
    # keyed as the move's "servo" draw (``restream``), so the amplifier noise keeps its draws
    "servo_clock": 111,
    # the hidden suite's quantities (twin/hidden.py)
    "polygon_pitch_pattern": 201,
    "graduation_walk": 202,
    "graduation_form": 203,
    "ac_room_phase": 204,
}

#: the instruments' streams, in the table's order (truth/seeds.json "instrument_streams")
INSTRUMENT_STREAMS = {k: v for k, v in STREAMS.items() if 100 < v < 200}
#: the hidden quantities' streams
HIDDEN_STREAMS = {k: v for k, v in STREAMS.items() if 200 < v < 300}


def stream_key(seed: int, stream: str, *keys: int) -> tuple[int, ...]:
    """The entropy of ``stream_rng(seed, stream, keys…)``: a plain tuple, for a draw made elsewhere
    (twin/instruments/settle_ahead.py: the servo's noise of a settle computed in a worker)."""
    return (int(seed), STREAMS[stream], *map(int, keys))


def restream(key: tuple[int, ...], stream: str) -> tuple[int, ...]:
    """``key`` (a ``stream_key``) on ``stream`` instead: the same seed and keys, so a second quantity
    of one draw (the servo's clock phase of the stop whose amplifier noise ``key`` draws) gets its
    own independent stream and leaves the first one's draws as they were."""
    return (int(key[0]), STREAMS[stream], *map(int, key[2:]))


def rng_from_key(key: tuple[int, ...]) -> np.random.Generator:
    """The generator of an entropy tuple (``stream_key``)."""
    return np.random.default_rng(np.random.SeedSequence(list(key)))


def stream_rng(seed: int, stream: str, *keys: int) -> np.random.Generator:
    """An independent generator for (seed, stream, keys…)."""
    return rng_from_key(stream_key(seed, stream, *keys))
