"""Autocollimator (or bench) drift during the polygon sweep: a residual ∝ time of the reading.

Hsieh et al. 2022, eq. 3 assumes ε_ij = α + Σβ + U_j with U_j constant for a start face; a drift
of the autocollimator's zero (thermal, ~0.1–1″/h) adds d·t_s. The part common to a start face is
absorbed into U_j by eq. 7; what remains is d·(t_s − mean t_s of the run): a ramp in reading order,
which is a ramp in θ for a forward sweep and the opposite ramp for a backward one — that is what
separates it from any error fixed to θ.
"""

from __future__ import annotations

import numpy as np

from ._base import MIN_FREE_FRACTION, channels, linear_predictor, no_aux, no_term, theta_free_fraction, within

NAME = "ac_drift"
MEANING = (
    "The autocollimator's zero drifts linearly with time (warm-up, room temperature). The error "
    "belongs to the reference chain, not to the encoder: it follows the reading time t_s, not θ, "
    "changes sign with the direction of rotation in θ and is absent from the self-calibration."
)
PARAMS = {"drift_arcsec_per_s": "arcsec/s"}
CHANNELS = channels(alpha="d·t_s (the per-run mean goes into the setup error U_j)",
                    selfcal="none (not an encoder error)")
SEEN_BY_SELFCAL = False
SEPARATED_BY = "Reading order ≠ θ order: backward sweeps, shifted start angles, repetitions; self-calibration (absent there)."
SEPARATES_FROM = {
    "graduation_error": "repeat the sweep backward or in a shuffled order (a drift follows time, a division error θ)",
    "torsion_hysteresis": "dwell at one face for a while (drift grows with time, hysteresis does not)",
}


# a drift is observable only through the part of the reading time, inside each run (closure group),
# that is not a function of θ: when every run reads the stops in the same θ order at the same pace
# (forward sweeps from the same start angle), t − t̄_run is a sawtooth in θ that any encoder error
# of that shape fits equally. Below this fraction of its variance left after removing every
# function of θ the drift is declared unobservable (``_base.MIN_FREE_FRACTION``, shared with
# torsion_hysteresis's approach direction).
def free_fraction(ev) -> float:
    """Share of the run-centred reading time's variance not explained by a function of θ (stop
    position) — what can tell a drift from an encoder error (``_base.theta_free_fraction``)."""
    return theta_free_fraction(ev, ev.t_s)


def available(ev, ctx=None):
    t = np.asarray(ev.t_s, dtype=float)
    ok = t.size > 2 and np.all(np.isfinite(t)) and np.ptp(t) > 0
    if not ok:
        return False, "no reading times"
    if hasattr(ev, "closure_group") and hasattr(ev, "theta_bin"):
        f = free_fraction(ev)
        if f < MIN_FREE_FRACTION:
            return False, (f"the reading order follows θ in every run (only {f:.0%} of the reading time's variance is "
                           "not a function of θ): a drift is a θ sawtooth, indistinguishable from an encoder error; "
                           "sweep backward as well, or start the runs at other angles")
    return True, ""


def design(ev, ctx=None):
    return np.asarray(ev.t_s, dtype=float)[:, None], ["drift_arcsec_per_s"]


predict = linear_predictor(design)
aux, term = no_aux, no_term  # an error of the reference chain: no θ-function, no ErrorModel term


#: plausible drift: 0.02″/s (72″/h) is far beyond a thermally settled autocollimator (≲ 1″/h).
MAX_RATE = 0.02


def plausible(ev, params, u, ctx=None):
    return within(params, "drift_arcsec_per_s", MAX_RATE, "drift", "″/s")
