"""True L1 (top sphere → disk) differs from the nominal one: an error of the tilt (Abbe) correction.

Jia et al. 2019, eqs. 8–9: ε_X = (δ_top − δ_bottom)/L2 and δY = δ_top − ε_X·L1 =
((L2−L1)/L2)·δ_top + (L1/L2)·δ_bottom, with L1 = 6.81 mm "according to the design sizes". With the
true L1 + ΔL1 the disk's motion is δY + ΔL1·(δ_bottom − δ_top)/L2. How that reaches the reading
depends on how the motion does (see ``tangential_motion``), so there are two variants:

- ``dL1_mm`` (eq. 5's reading, ∫δY dθ/r): residual ΔL1/(L2·r)·∫(δ_bottom − δ_top) dθ;
- ``dL1_tangential_mm`` (the head reads the motion's tangential component, −δX/r, exact geometry):
  the extrapolated δX is wrong by ΔL1·(δ_bottom,x − δ_top,x)/L2 — measured with X probes; without
  them, for a whirl of the measured lobes δX = ±H[δY] (quadrature), so the residual is
  ∓ΔL1/(L2·r)·H[δ_bottom − δ_top]: the sign of ΔL1 then depends on the whirl's direction (reported
  as fitted, with a note).

Zero for a pure translation (δ_top = δ_bottom): only a tilt error motion makes L1 observable. When
the tilt motion has the same shape as the disk's motion (one worn bearing), an L1 error only
rescales the motion at the disk: it cannot be told from a whirl that is not circular (the
tangential gain), and the result is an ambiguity set {tilt_abbe, tangential_motion}.
"""

from __future__ import annotations

import numpy as np

from ._base import (ARCSEC_PER_RAD, channels, coefs_from_json, coefs_to_json, fourier_eval, fourier_integral,
                    linear_predictor, quadrature, radius_um)

NAME = "tilt_abbe"
MEANING = (
    "The axial distance from the top sphere to the grating disk (L1 of eq. 9) is not the design "
    "value, so the tilt error motion is extrapolated to the wrong plane (an Abbe error of the "
    "interpolation). Residual ∝ ΔL1·∫(δ_bottom − δ_top) dθ/(L2·r); needs a tilt motion (the two "
    "spheres moving differently) to be observable."
)
PARAMS = {"dL1_mm": "mm (eq. 5's ∫δY reading)", "dL1_tangential_mm": "mm (tangential reading, −δX/r)"}
#: variants: one per reading model (see the module docstring)
SUBSETS = [["dL1_mm"], ["dL1_tangential_mm"]]
CHANNELS = channels(
    alpha="ΔL1/(L2·r)·∫(δ_bottom − δ_top) dθ, or −ΔL1/(L2·r)·(δ_bottom − δ_top)_X (X probes; H[·] of the Y lobes without)",
    selfcal="the same (the model, not the encoder, is wrong)",
    radial="δY at the disk changes by ΔL1·(δ_bottom − δ_top)/L2 (probe readings unchanged)",
    heads="the corrected δY seen with each head's phase",
)
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
    if amp <= 0:
        return False, "no tilt motion (δ_top = δ_bottom)"
    return True, "" if _x(ev) else "dL1_tangential_mm without X probes assumes a whirl (δX = ±H[δY]): its sign follows the whirl's direction"


def _x(ev):
    return ev.radial.has_x


def design(ev, ctx=None):
    k = ARCSEC_PER_RAD / (float(ev.L2_mm) * radius_um(ev))
    col = fourier_integral(ev.theta_deg, _diff_coefs(ev)) * k
    if _x(ev):
        cx = ev.radial.coefs("bottom_x_um")
        ct = ev.radial.coefs("top_x_um")
        d = {kk: (cx[kk][0] - ct[kk][0], cx[kk][1] - ct[kk][1]) for kk in cx}
        tan = -fourier_eval(ev.theta_deg, d) * k
    else:
        tan = -fourier_eval(ev.theta_deg, quadrature(_diff_coefs(ev))) * k
    return np.column_stack([col, tan]), ["dL1_mm", "dL1_tangential_mm"]


def regressor_perturbations(ev, params, ctx=None):
    """The probe data's uncertainty propagated through the fitted ΔL1 (errors in variables)."""
    k = ARCSEC_PER_RAD / (float(ev.L2_mm) * radius_um(ev))
    cols = [k * float(params.get("dL1_mm", 0.0)) * ev.radial.perturbations(ev.theta_deg, "bottom_minus_top_um", "integral")]
    dt = float(params.get("dL1_tangential_mm", 0.0))
    if dt:
        if _x(ev):
            cols += [-k * dt * ev.radial.perturbations(ev.theta_deg, "bottom_x_um", "value"),
                     k * dt * ev.radial.perturbations(ev.theta_deg, "top_x_um", "value")]
        else:
            cols.append(-k * dt * ev.radial.perturbations(ev.theta_deg, "bottom_minus_top_um", "quadrature"))
    return np.hstack(cols)


#: plausible ΔL1: the spheres' heights are known from the drawing to a few mm; a quarter of the
#: sphere spacing L2 (31 mm for Jia's bench) is a gross error.
MAX_FRACTION_OF_L2 = 0.25


def plausible(ev, params, u, ctx=None):
    lim = MAX_FRACTION_OF_L2 * float(ev.L2_mm)
    for n in ("dL1_mm", "dL1_tangential_mm"):
        d = float(params.get(n, 0.0))
        if abs(d) > lim:
            return False, f"ΔL1 = {d:.3g} mm is beyond ±{lim:.3g} mm (L2/4)"
    return True, ""

predict = linear_predictor(design)


def aux(ev, ctx=None):
    out = {"r_um": radius_um(ev), "L2_mm": float(ev.L2_mm), "coefs": coefs_to_json(_diff_coefs(ev)), "x_probes": _x(ev)}
    if _x(ev):
        cx, ct = ev.radial.coefs("bottom_x_um"), ev.radial.coefs("top_x_um")
        out["coefs_x"] = coefs_to_json({kk: (cx[kk][0] - ct[kk][0], cx[kk][1] - ct[kk][1]) for kk in cx})
    return out


def term(params, aux, base_terms=None):
    c = coefs_from_json(aux["coefs"])
    k = ARCSEC_PER_RAD / (float(aux["L2_mm"]) * float(aux["r_um"]))
    d1, dt = float(params.get("dL1_mm", 0.0)), float(params.get("dL1_tangential_mm", 0.0))
    ct = coefs_from_json(aux["coefs_x"]) if aux.get("x_probes") else quadrature(c)
    return lambda th: k * (d1 * fourier_integral(np.rad2deg(th), c) - dt * fourier_eval(np.rad2deg(th), ct))
