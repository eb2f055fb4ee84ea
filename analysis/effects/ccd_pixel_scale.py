"""CCD pixel scale error: a gain on the eccentricity term only.

Jia et al. 2019, eq. 13: d_ref = 0.667 µm/px × d_p_ref, the pixel size from counting 90 px over
three 20 µm grating periods — a ±1 px count is ±1.1 % of e. Eq. 11 then gives e scaled by the same
factor, and eq. 3's term e/r·sin(θ−θ0) inherits it; the ∫δY term (probes) does not. The residual
is s·[e/r·sin(θ−θ0)] with s the relative scale error (in %).
"""

from __future__ import annotations

import numpy as np

from ._base import channels, linear_predictor, within

NAME = "ccd_pixel_scale"
MEANING = (
    "The object-side pixel size of the CCD microscope (Jia eq. 13, 0.667 µm from a 90-pixel count "
    "over three grating periods) is wrong by s %, so the eccentricity e from eq. 11 is wrong by "
    "the same fraction. The residual is s/100 times the eccentricity term; the phase θ0 is not "
    "affected. Seen by the self-calibration (the model, not the encoder, is wrong)."
)
PARAMS = {"scale_error_pct": "%"}
CHANNELS = channels(
    alpha="(s/100)·e/r·sin(θ−θ0) (the model's eccentricity term)", selfcal="the same",
    ccd="d_ref scaled by 1/(1+s/100): invisible in the CCD data alone (its shape is unchanged)",
    heads="the eccentricity signature of every head scaled by s",
)
SEEN_BY_SELFCAL = True
SEPARATED_BY = "A calibrated scale in the CCD's field of view; otherwise only the absence of a gain on the ∫δY term."
SEPARATES_FROM = {
    "optical_radius": "image a calibrated stage micrometer with the CCD, or a larger radial motion "
                      "(a radius error scales ∫δY too, a pixel-scale error does not)",
    "ac_scale": "multi-head self-calibration, or calibrate the CCD scale with a stage micrometer",
}


def _ecc(ev):
    name = getattr(ev, "eccentricity_term", "eccentricity")
    return np.asarray(ev.model_terms.get(name, np.zeros(len(ev.theta_deg))), dtype=float)


def available(ev, ctx=None):
    ok = float(np.max(np.abs(_ecc(ev)), initial=0.0)) > 0
    return ok, "" if ok else "no eccentricity term in the model"


def design(ev, ctx=None):
    return (_ecc(ev) / 100.0)[:, None], ["scale_error_pct"]


predict = linear_predictor(design)


#: plausible range of the scale error: Jia's count (90 px over 3 periods) is good to ±1 px
#: (±1.1 %); a wrong datasheet period or magnification of more than 10 % would show in the image
#: as a visibly wrong line count.
MAX_PCT = 10.0


def plausible(ev, params, u, ctx=None):
    return within(params, "scale_error_pct", MAX_PCT, "scale error", " %")


def aux(ev, ctx=None):
    return {"term": getattr(ev, "eccentricity_term", "eccentricity")}


def term(params, aux, base_terms=None):
    if not base_terms or aux["term"] not in base_terms:
        return None
    f = base_terms[aux["term"]]
    s = float(params["scale_error_pct"]) / 100.0
    return lambda theta_rad: s * np.asarray(f(theta_rad), dtype=float)
