"""Direction-dependent offset between encoder and polygon: torsional wind-up / hysteresis.

Hsieh et al. 2022, eq. 3 assumes the setup error U_j is the same whatever the direction of the
rotation. A drive torque that twists the shaft between the grating disk and the polygon clamp
(friction reverses with direction) adds +h forward and −h backward. Observable when forward and
backward readings share one setup error (one closure group); then the residual is h·direction.

The direction is that of the APPROACH to the stop (``Evidence.approach``: the sign of the last
move, from the readings' time order), not the run's label: the friction that the servo holds at
rest, hence the twist, is set by the last motion. A run's first stop is read where the previous run
left the stage (after a backward sweep ending at 0°, a forward run's 0° is approached backward;
after a forward run, the return 344° → 0° is a backward move). Labelled by run, those stops carry
the opposite twist, 2h off at the two ends of the curve (the physical twin, hidden suite: 0.48″ at
0° and 344°, 2 of 23 angles outside 2u).

What h is: the mean twist of the stops approached in one direction. A servo holds at rest the
torque its settling leaves (stick-slip: between −T_s and +T_s, twin/instruments/drive.py is one such
drive), so the twist also scatters from stop to stop around ±h; that scatter repeats nowhere (no
column of θ, time or face describes it) and is part of the readings' repeatability (type A,
``pooled_sd_eps``), not of this effect.
"""

from __future__ import annotations

import numpy as np

from ._base import MIN_FREE_FRACTION, channels, linear_predictor, no_aux, no_term, theta_free_fraction, within

NAME = "torsion_hysteresis"
MEANING = (
    "The shaft (or polygon clamp) winds up under the friction torque, whose sign follows the "
    "direction of rotation: an offset +h forward, −h backward between the encoder and the polygon. "
    "A property of the mechanical chain to the reference, not of the encoder's reading: absent "
    "from the self-calibration."
)
PARAMS = {"half_hysteresis_arcsec": "arcsec"}
CHANNELS = channels(alpha="h·approach direction (+1 forward, −1 backward: the last move before the stop)",
                    selfcal="none", radial="none (a pure rotation about the axis)")
SEEN_BY_SELFCAL = False
SEPARATED_BY = "Forward and backward sweeps sharing one polygon mounting; approaching each stop from both sides."
SEPARATES_FROM = {
    "ac_drift": "interleave forward and backward stops (hysteresis flips at once, drift does not)",
}


def _approach(ev):
    a = getattr(ev, "approach", None)
    return ev.direction if a is None else a


def available(ev, ctx=None):
    d = np.asarray(_approach(ev), dtype=float)
    ok = bool(np.any(d > 0) and np.any(d < 0))
    if not ok:
        return False, "one direction of rotation only"
    if hasattr(ev, "closure_group") and hasattr(ev, "theta_bin"):
        # Forward-only runs approach backward only their first stop (the return to the start angle S),
        # and that position is read as a first stop only: inside every run the approach is a
        # function of θ, and h·approach is an encoder error of −2h at the start angles to the data
        # (as ac_drift's reading time of forward sweeps). Observable only through the approach's part
        # that no function of θ holds: a stop position reached from both sides.
        f = theta_free_fraction(ev, d)
        if f < MIN_FREE_FRACTION:
            return False, (f"the approach direction follows θ in every run (only {f:.0%} of its variance is not a "
                           "function of θ: backward only to the runs' first stops, which no run approaches "
                           "forward): a hysteresis is an encoder error at those stops to these data; sweep "
                           "backward as well, in the same mounting")
    return True, ""


def design(ev, ctx=None):
    return np.asarray(_approach(ev), dtype=float)[:, None], ["half_hysteresis_arcsec"]


predict = linear_predictor(design)
aux, term = no_aux, no_term  # an error of the reference chain: no θ-function, no ErrorModel term


#: plausible half-hysteresis: 20″ (1e-4 rad) of wind-up between disk and polygon would need a
#: broken or very soft coupling.
MAX_ARCSEC = 20.0


def plausible(ev, params, u, ctx=None):
    return within(params, "half_hysteresis_arcsec", MAX_ARCSEC, "half hysteresis", "″")
