"""True L1 (top sphere → disk) differs from the nominal one: an error of the tilt (Abbe) correction.

Jia et al. 2019, eqs. 8–9: ε_X = (δ_top − δ_bottom)/L2 and δY = δ_top − ε_X·L1 =
((L2−L1)/L2)·δ_top + (L1/L2)·δ_bottom, with L1 = 6.81 mm "according to the design sizes". With the
true L1 + ΔL1 the disk's motion is δY + ΔL1·(δ_bottom − δ_top)/L2, and eq. 5 gives the residual
ΔL1/(L2·r)·∫(δ_bottom − δ_top) dθ. Zero for a pure translation (δ_top = δ_bottom): only a tilt
error motion makes L1 observable.
"""

from __future__ import annotations

import numpy as np

from ._base import ARCSEC_PER_RAD, coefs_from_json, coefs_to_json, fourier_integral, linear_predict, radius_um

NAME = "tilt_abbe"
MEANING = (
    "The axial distance from the top sphere to the grating disk (L1 of eq. 9) is not the design "
    "value, so the tilt error motion is extrapolated to the wrong plane (an Abbe error of the "
    "interpolation). Residual ∝ ΔL1·∫(δ_bottom − δ_top) dθ/(L2·r); needs a tilt motion (the two "
    "spheres moving differently) to be observable."
)
PARAMS = {"dL1_mm": "mm"}
CHANNELS = {
    "alpha": "ΔL1/(L2·r)·∫(δ_bottom − δ_top) dθ",
    "selfcal": "the same (the model, not the encoder, is wrong)",
    "radial": "δY at the disk changes by ΔL1·(δ_bottom − δ_top)/L2 (probe readings unchanged)",
    "ccd": "none",
    "heads": "the corrected δY seen with each head's phase",
}
SEEN_BY_SELFCAL = True
SEPARATED_BY = "A tilt error motion whose lobes differ from the top sphere's (so ∫(δ_bottom−δ_top) is not collinear with ∫δY); measure L1 directly (height gauge)."
SEPARATES_FROM = {
    "optical_radius": "measure L1 with a height gauge, or add a third sphere / probe level",
    "graduation_error": "measure L1 with a height gauge; change the bearing preload (changes the tilt motion, not the division)",
    "sphere_form": "Donaldson reversal of the top sphere; measure L1 with a height gauge",
}


def _diff_coefs(ev):
    return ev.radial.coefs("bottom_minus_top_um")


def available(ev, ctx=None):
    if ev.radial is None:
        return False, "no radial-motion data"
    amp = max((np.hypot(*v) for v in _diff_coefs(ev).values()), default=0.0)
    return (amp > 0, "" if amp > 0 else "no tilt motion (δ_top = δ_bottom)")


def design(ev, ctx=None):
    col = fourier_integral(ev.theta_deg, _diff_coefs(ev)) / (float(ev.L2_mm) * radius_um(ev)) * ARCSEC_PER_RAD
    return col[:, None], ["dL1_mm"]


def regressor_perturbations(ev, params, ctx=None):
    """The probe data's uncertainty propagated through the fitted ΔL1 (errors in variables)."""
    k = float(params.get("dL1_mm", 0.0)) / (float(ev.L2_mm) * radius_um(ev)) * ARCSEC_PER_RAD
    return k * ev.radial.perturbations(ev.theta_deg, "bottom_minus_top_um", "integral")


def predict(ev, params, ctx=None):
    return linear_predict(design, ev, params, ctx)


def aux(ev, ctx=None):
    return {"r_um": radius_um(ev), "L2_mm": float(ev.L2_mm), "coefs": coefs_to_json(_diff_coefs(ev))}


def term(params, aux, base_terms=None):
    c = coefs_from_json(aux["coefs"])
    k = float(params["dL1_mm"]) / (float(aux["L2_mm"]) * float(aux["r_um"])) * ARCSEC_PER_RAD
    return lambda th: k * fourier_integral(np.rad2deg(th), c)
