"""Radial error motion perpendicular to the head direction (δX), which the ∫δY model omits.

Jia et al. 2019, sec. 3.4, drops δX from eq. 4 (arcsin((δX + e sin φ)/r) ≈ 0): the optical radius
does not change to first order, but the disk centre moving along X moves the lines under a head
on +Y, a reading error −δX/r (docs/conventions.md: with the head on +Y the reading error is −c_x/r
to first order). Residual: −g·δX_disk/r, δX_disk from the X probes by eq. 9; g = 1 when the model
ignores δX completely.

Without X probes δX is unknown. A rigid orbit's k-lobe component has two free numbers per harmonic
in X for the two measured in Y, so the data can only support a "motion-shaped" surrogate: the
measured δY lobes and their quadrature (a forward/backward whirl of the same lobes):
−(p·δY + q·H[δY])/r. That basis is generic — a division error with those harmonics fits it too —
so when it is chosen the result always carries an ambiguity set (context key ``generic``).
"""

from __future__ import annotations

import numpy as np

from ._base import ARCSEC_PER_RAD, fourier_eval, linear_predict, quadrature, radius_um, coefs_to_json, coefs_from_json

NAME = "tangential_motion"
MEANING = (
    "The shaft's radial error motion along X (perpendicular to the head direction) moves the "
    "grating lines tangentially under the head: a reading error −δX/r that Jia's eq. 5 (which keeps "
    "only δY, through the optical radius) does not contain. Fitted with the X-probe data when "
    "present (one gain), otherwise with a generic motion-shaped basis (δY and its quadrature), "
    "which is then reported as ambiguous."
)
PARAMS = {"gain": "1 (X probes present; 1 = δX fully missing from the model)",
          "inphase_gain": "1 (no X probes)", "quadrature_gain": "1 (no X probes)"}
CHANNELS = {
    "alpha": "−g·δX_disk(θ)/r (or −(p·δY + q·H[δY])/r without X probes)",
    "selfcal": "the same for head 1 (an encoder reading error)",
    "radial": "δX_disk from the X probes by eq. 9 (the regressor itself)",
    "ccd": "none",
    "heads": "head at azimuth ψ sees −δ·(tangent at ψ)/r: raw head differences resolve δX and δY",
}
#: variants tried (the best BIC represents the effect): a parameter the data do not need costs ln n.
SUBSETS = [["gain"], ["inphase_gain"], ["quadrature_gain"], ["inphase_gain", "quadrature_gain"]]
SEEN_BY_SELFCAL = True
SEPARATED_BY = "X probes on both spheres; raw multi-head differences δ_(1,j) (heads at 90° see δX as a radial motion)."
SEPARATES_FROM = {
    "graduation_error": "X probes on both spheres (then δX is a regressor with one gain), or re-mount "
                        "the disk rotated on the shaft",
    "sphere_form": "X probes on both spheres, or Donaldson reversal of the sphere",
}


def _has_x(ev):
    return ev.radial is not None and ev.radial.has_x


def available(ev, ctx=None):
    if ev.radial is None:
        return False, "no radial-motion data"
    return True, "" if _has_x(ev) else "no X probes: generic motion-shaped basis (ambiguous by construction)"


def is_generic(ev):
    return not _has_x(ev)


def ambiguous_with(ev):
    """Effects this one cannot be told from with these data, whatever the information criterion says."""
    return ["graduation_error"] if is_generic(ev) else []


def design(ev, ctx=None):
    r = radius_um(ev)
    if _has_x(ev):
        dx = ev.radial.at(ev.theta_deg, "dX_um")
        return (-dx / r * ARCSEC_PER_RAD)[:, None], ["gain"]
    c = ev.radial.coefs("dY_um")
    X = np.column_stack([-fourier_eval(ev.theta_deg, c), -fourier_eval(ev.theta_deg, quadrature(c))]) / r * ARCSEC_PER_RAD
    return X, ["inphase_gain", "quadrature_gain"]


def regressor_perturbations(ev, params, ctx=None):
    """The probe data's uncertainty propagated through the fitted gain(s) (errors in variables)."""
    k = -ARCSEC_PER_RAD / radius_um(ev)
    if _has_x(ev):
        return k * float(params.get("gain", 0.0)) * ev.radial.perturbations(ev.theta_deg, "dX_um", "value")
    return k * (float(params.get("inphase_gain", 0.0)) * ev.radial.perturbations(ev.theta_deg, "dY_um", "value")
                + float(params.get("quadrature_gain", 0.0)) * ev.radial.perturbations(ev.theta_deg, "dY_um", "quadrature"))


def heads(ev, params, heads_deg, ctx=None):
    """Head j at azimuth ψ_j (CCW from head 1 on +Y) reads the disk-centre motion c along its
    tangent (−cos ψ, −sin ψ): error_j = −(cos ψ·c_x + sin ψ·c_y)/r. The part this effect adds is
    the missing δX share: error_j = −g·cos ψ_j·δX/r, so δ_(1,j) = −g·(1 − cos ψ_j)·δX/r.
    Only with X probes (the generic basis has no δX)."""
    if not _has_x(ev):
        return None
    g = float(params.get("gain", 0.0))
    dx = ev.radial.at(ev.theta_deg, "dX_um") / radius_um(ev) * ARCSEC_PER_RAD
    return np.column_stack([-g * (1 - np.cos(np.deg2rad(p))) * dx for p in heads_deg])


def predict(ev, params, ctx=None):
    return linear_predict(design, ev, params, ctx)


def aux(ev, ctx=None):
    key = "dX_um" if _has_x(ev) else "dY_um"
    return {"r_um": radius_um(ev), "coefs": coefs_to_json(ev.radial.coefs(key)), "x_probes": _has_x(ev)}


def term(params, aux, base_terms=None):
    c = coefs_from_json(aux["coefs"])
    k = ARCSEC_PER_RAD / float(aux["r_um"])
    if aux["x_probes"]:
        g = float(params["gain"])
        return lambda th: -g * k * fourier_eval(np.rad2deg(th), c)
    p, q = float(params["inphase_gain"]), float(params["quadrature_gain"])
    cq = quadrature(c)
    return lambda th: -k * (p * fourier_eval(np.rad2deg(th), c) + q * fourier_eval(np.rad2deg(th), cq))
