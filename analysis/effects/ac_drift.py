"""Autocollimator (or bench) drift during the polygon sweep: a residual ∝ time of the reading.

Hsieh et al. 2022, eq. 3 assumes ε_ij = α + Σβ + U_j with U_j constant for a start face; a drift
of the autocollimator's zero (thermal, ~0.1–1″/h) adds d·t_s. The part common to a start face is
absorbed into U_j by eq. 7; what remains is d·(t_s − mean t_s of the run): a ramp in reading order,
which is a ramp in θ for a forward sweep and the opposite ramp for a backward one — that is what
separates it from any error fixed to θ.
"""

from __future__ import annotations

import numpy as np

from ._base import linear_predict

NAME = "ac_drift"
MEANING = (
    "The autocollimator's zero drifts linearly with time (warm-up, room temperature). The error "
    "belongs to the reference chain, not to the encoder: it follows the reading time t_s, not θ, "
    "changes sign with the direction of rotation in θ and is absent from the self-calibration."
)
PARAMS = {"drift_arcsec_per_s": "arcsec/s"}
CHANNELS = {
    "alpha": "d·t_s (the per-run mean goes into the setup error U_j)",
    "selfcal": "none (not an encoder error)",
    "radial": "none", "ccd": "none", "heads": "none",
}
SEEN_BY_SELFCAL = False
SEPARATED_BY = "Reading order ≠ θ order: backward sweeps, shifted start angles, repetitions; self-calibration (absent there)."
SEPARATES_FROM = {
    "graduation_error": "repeat the sweep backward or in a shuffled order (a drift follows time, a division error θ)",
    "torsion_hysteresis": "dwell at one face for a while (drift grows with time, hysteresis does not)",
}


def available(ev, ctx=None):
    t = np.asarray(ev.t_s, dtype=float)
    ok = t.size > 2 and np.all(np.isfinite(t)) and np.ptp(t) > 0
    return ok, "" if ok else "no reading times"


def design(ev, ctx=None):
    return np.asarray(ev.t_s, dtype=float)[:, None], ["drift_arcsec_per_s"]


def predict(ev, params, ctx=None):
    return linear_predict(design, ev, params, ctx)


def aux(ev, ctx=None):
    return {}


def term(params, aux, base_terms=None):
    return None
