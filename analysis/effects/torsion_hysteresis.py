"""Direction-dependent offset between encoder and polygon: torsional wind-up / hysteresis.

Hsieh et al. 2022, eq. 3 assumes the setup error U_j is the same whatever the direction of the
rotation. A drive torque that twists the shaft between the grating disk and the polygon clamp
(friction reverses with direction) adds +h forward and −h backward. Observable when forward and
backward readings share one setup error (one closure group); then the residual is h·direction.
"""

from __future__ import annotations

import numpy as np

from ._base import linear_predict

NAME = "torsion_hysteresis"
MEANING = (
    "The shaft (or polygon clamp) winds up under the friction torque, whose sign follows the "
    "direction of rotation: an offset +h forward, −h backward between the encoder and the polygon. "
    "A property of the mechanical chain to the reference, not of the encoder's reading: absent "
    "from the self-calibration."
)
PARAMS = {"half_hysteresis_arcsec": "arcsec"}
CHANNELS = {
    "alpha": "h·direction (+1 forward, −1 backward)",
    "selfcal": "none",
    "radial": "none (a pure rotation about the axis)", "ccd": "none", "heads": "none",
}
SEEN_BY_SELFCAL = False
SEPARATED_BY = "Forward and backward sweeps sharing one polygon mounting; approaching each stop from both sides."
SEPARATES_FROM = {
    "ac_drift": "interleave forward and backward stops (hysteresis flips at once, drift does not)",
}


def available(ev, ctx=None):
    d = np.asarray(ev.direction, dtype=float)
    ok = bool(np.any(d > 0) and np.any(d < 0))
    return ok, "" if ok else "one direction of rotation only"


def design(ev, ctx=None):
    return np.asarray(ev.direction, dtype=float)[:, None], ["half_hysteresis_arcsec"]


#: plausible half-hysteresis: 20″ (1e-4 rad) of wind-up between disk and polygon would need a
#: broken or very soft coupling.
MAX_ARCSEC = 20.0


def plausible(ev, params, u, ctx=None):
    h = float(params.get("half_hysteresis_arcsec", 0.0))
    ok = abs(h) <= MAX_ARCSEC
    return ok, "" if ok else f"half hysteresis {h:.3g}″ is beyond ±{MAX_ARCSEC:g}″"

def predict(ev, params, ctx=None):
    return linear_predict(design, ev, params, ctx)


def aux(ev, ctx=None):
    return {}


def term(params, aux, base_terms=None):
    return None
