"""Optical radius of the reading head differs from the datasheet value: a gain on the WHOLE model.

Jia et al. 2019, eq. 5: Δθ = [e·sin(θ−θ0) + ∫δY dθ]/r with r "known from the datasheet" (sec. 5).
If the true radius is r + Δr, every term of eq. 5 is too large by the factor r/(r+Δr), so the
residual (measured − model) is model·(r/(r+Δr) − 1) ≈ −(Δr/r)·model: one parameter, a gain on the
sum of all model terms. Since the eccentricity term (66″ for e = 7.1 µm, r = 22 mm) dominates,
this is almost collinear with ``ccd_pixel_scale`` (a gain on the eccentricity term only) and with
the linear part of ``ac_scale``; only the ∫δY term (and, for ac_scale, the self-calibration) tells
them apart.
"""

from __future__ import annotations

import numpy as np

from ._base import channels, linear_predictor

NAME = "optical_radius"
MEANING = (
    "The reading head scans the grating at a radius r + Δr, not at the datasheet radius r used in "
    "Jia eq. 5. Every term of the model (eccentricity and ∫δY) is then scaled by r/(r+Δr): the "
    "residual is −Δr/r times the whole model. It is a property of the encoder, so the multi-head "
    "self-calibration residual shows it too."
)
PARAMS = {"delta_r_mm": "mm"}
CHANNELS = channels(alpha="−(Δr/r)·Σ model terms",
                    selfcal="the same (−Δr/r times the model evaluated on the self-calibration grid)",
                    ccd="none (the CCD measures e in µm, not e/r)",
                    heads="the same gain on each head's eccentricity signature")
SEEN_BY_SELFCAL = True
SEPARATED_BY = ("The ∫δY term (scaled too, unlike ccd_pixel_scale) — needs radial motion large "
                "compared with the noise; self-calibration (sees it, does not see ac_scale).")
SEPARATES_FROM = {
    "ccd_pixel_scale": "image a calibrated stage micrometer with the CCD (fixes the pixel scale), or "
                       "measure with a larger radial motion so that the ∫δY term is scaled visibly",
    "ac_scale": "multi-head self-calibration (sees a radius error, not an autocollimator scale error), "
                "or calibrate the autocollimator against a small-angle generator",
}


def _model(ev):
    return sum(np.asarray(v, dtype=float) for v in ev.model_terms.values()) + np.zeros(len(ev.theta_deg))


def available(ev, ctx=None):
    ok = bool(ev.model_terms) and float(np.max(np.abs(_model(ev)))) > 0
    return ok, "" if ok else "no model terms"


def design(ev, ctx=None):
    return (-_model(ev) / float(ev.optical_radius_mm))[:, None], ["delta_r_mm"]


predict = linear_predictor(design)


#: plausible range of Δr/r: a reading head mounted, or a disk ruled, more than 5 % (1.1 mm at
#: r = 22 mm) off the datasheet radius is a gross assembly error that would be seen at once; a fit
#: beyond it compensates something else (e.g. two cancelling gains).
MAX_RELATIVE = 0.05


def plausible(ev, params, u, ctx=None):
    d = float(params.get("delta_r_mm", 0.0))
    lim = MAX_RELATIVE * float(ev.optical_radius_mm)
    ok = abs(d) <= lim
    return ok, "" if ok else f"Δr = {d:.3g} mm is beyond ±{lim:.3g} mm ({MAX_RELATIVE:.0%} of r)"


def aux(ev, ctx=None):
    return {"optical_radius_mm": float(ev.optical_radius_mm), "scales_terms": sorted(ev.model_terms)}


def term(params, aux, base_terms=None):
    if not base_terms:
        return None
    g = -float(params["delta_r_mm"]) / float(aux["optical_radius_mm"])
    fns = [base_terms[n] for n in aux["scales_terms"] if n in base_terms]
    return lambda theta_rad: g * sum(np.asarray(f(theta_rad), dtype=float) for f in fns)
