"""Radial error motion perpendicular to the head direction (δX), which the ∫δY model omits.

Jia et al. 2019, sec. 3.4, drops δX from eq. 4 (arcsin((δX + e sin φ)/r) ≈ 0): the optical radius
does not change to first order, but the disk centre moving along X moves the lines under a head
on +Y, a reading error −δX/r (docs/conventions.md: with the head on +Y the reading error is −c_x/r
to first order). Eq. 5 describes the motion by ∫δY dθ/r instead; for a k-lobed whirl
(δX = ±quadrature of δY) that term holds only 1/k of the −δX/r the head reads. Parameters:

- with X probes (δX_disk from them by eq. 9): ``gain`` g on −δX/r, and optionally ``radial_gain`` h
  on −∫δY dθ/r (the share of eq. 5's motion term that is not there): residual = −(g·δX + h·∫δY)/r.
  g = 1, h = 0 when eq. 5 is right for δY and only δX is missing; g = h = 1 when the head reads
  the tangential component only (exact geometry, which the twin has): then the residual of a
  k-lobed whirl is −(1 − 1/k)·δX/r.
- without X probes δX is unknown. Two hypotheses remain: (a) the axis whirls along the lobes the Y
  probes see, δX = ±H[δY] (H: quadrature): the basis −(p·H[δY] + h·∫δY)/r (p = ±1, h = 1 for a
  whirl in the exact geometry), and a diagonal (in-phase, −q·δY/r) motion; (b) a motion along X
  the Y probes do not see at all: any harmonic, indistinguishable from a division error. So
  without X probes the result always carries an ambiguity set with graduation_error, and
  graduation_error's carries tangential_motion (``ambiguous_with``): "add X probes".
"""

from __future__ import annotations

import numpy as np

from ._base import (ARCSEC_PER_RAD, RADIAL_ORDERS, channels, coefs_from_json, coefs_to_json, fourier_eval, fourier_integral,
                    linear_predictor, quadrature, radius_um)

NAME = "tangential_motion"
MEANING = (
    "The shaft's radial error motion along X (perpendicular to the head direction) moves the "
    "grating lines tangentially under the head: a reading error −δX/r that Jia's eq. 5 does not "
    "contain (it describes the motion by ∫δY dθ/r, which for a k-lobed whirl is only 1/k of it). "
    "Fitted with the X-probe data when present (a gain on −δX/r, optionally one on −∫δY/r), "
    "otherwise with a whirl-shaped basis built from the Y probes (δY, its quadrature, ∫δY); "
    "without X probes it is always reported together with graduation_error (an X motion the Y "
    "probes do not see is any function of θ)."
)
PARAMS = {"gain": "1 (X probes present; 1 = δX fully missing from the model)",
          "radial_gain": "1 (share of eq. 5's ∫δY term that the head does not read)",
          "inphase_gain": "1 (no X probes)", "quadrature_gain": "1 (no X probes)"}
CHANNELS = channels(
    alpha="−(g·δX_disk + h·∫δY dθ)/r (without X probes −(q·δY + p·H[δY] + h·∫δY dθ)/r)",
    selfcal="the same for head 1 (an encoder reading error)",
    radial="δX_disk from the X probes by eq. 9 (the regressor itself)",
    heads="head at azimuth ψ sees −δ·(tangent at ψ)/r: raw head differences resolve δX and δY",
)
#: variants tried (the best BIC represents the effect): a parameter the data do not need costs ln n.
#: A variant is tried only when all its parameters are in the design (X probes or not).
SUBSETS = [["gain"], ["gain", "radial_gain"], ["quadrature_gain"], ["inphase_gain", "quadrature_gain"],
           ["quadrature_gain", "radial_gain"], ["radial_gain"]]
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


#: δX enters with every order the X probes' grid determines (analysis/radial_motion.py,
#: X_ORDERS_MAX), each with its type-A u as an errors-in-variables nuisance (regressor_perturbations):
#: the probes (0.1 µm repeatability: ~0.007 µm, 0.064″ at r = 22 mm per coefficient) resolve a ball
#: bearing's δX at few orders above 10, while the polygon sees −δX/r to ~0.02″ per coefficient; a
#: regressor cut to the resolved orders leaves the rest (aliased by the faces onto orders 23 − k)
#: to graduation_error. The nuisance enters every fit with a unit Gaussian prior (its Σν² is checked
#: against χ²(p) by selection._fit_gates); the information criterion counts only the gains (problem.py
#: ``ic``: k = rank of the design), no Occam factor of the nuisance. Where the probes' u per
#: coefficient far exceeds the polygon's (e.g. 0.016 µm = 0.148″ against 0.004…0.03″ per harmonic,
#: loop validation seed 660 null #0), the gain fitted beside its own nuisance is shrunk (0.1…0.3):
#: regression dilution by the probes' noise, which selection._evaluate's fixed point does not undo
#: (docs/loop-validation.md, "The measured motion's gain, attenuated by the probes' own noise").
def x_orders(ev) -> list[int]:
    return list(ev.radial.coefs("dX_um"))


def order1(ev) -> dict:
    """{1: (a, b)} µm: the order-1 δX the model misreads (RadialMotion.order1_model_error: the
    backward whirl of the disk centre, which the CCD's eccentricity, read as one forward circle,
    takes with the wrong sign), for the polygon's rows (head 1 against the CCD's eq. 3 term); {}
    for the self-calibration grid (its order 1 comes from the head differences, not from the CCD)
    and without X probes."""
    return ev.radial.order1_model_error(_ccd_azimuth(ev)) if _order1_applies(ev) else {}


def _order1_applies(ev) -> bool:
    """Whether :func:`order1` is non-empty on these rows: the polygon's (not the self-calibration
    grid's), with X probes that resolve the backward whirl (RadialMotion.resolves_backward_whirl)."""
    return getattr(ev, "parent", None) is None and _has_x(ev) and ev.radial.resolves_backward_whirl()


def _ccd_azimuth(ev) -> float:
    return float(getattr(ev, "ccd_azimuth_deg", 180.0))


def _dx(ev):
    """δX at the disk at the readings (µm): orders 2…X_ORDERS_MAX and the order-1 part :func:`order1`."""
    dx = ev.radial.at(ev.theta_deg, "dX_um", x_orders(ev))
    o1 = order1(ev)
    return dx + fourier_eval(ev.theta_deg, o1) if o1 else dx


def _k(ev):
    return ARCSEC_PER_RAD / radius_um(ev)


def design(ev, ctx=None):
    k = _k(ev)
    radial = -ev.radial.integral_at(ev.theta_deg, "dY_um") * k
    if _has_x(ev):
        return np.column_stack([-_dx(ev) * k, radial]), ["gain", "radial_gain"]
    c = ev.radial.coefs("dY_um")
    X = np.column_stack([-fourier_eval(ev.theta_deg, c) * k, -fourier_eval(ev.theta_deg, quadrature(c)) * k, radial])
    return X, ["inphase_gain", "quadrature_gain", "radial_gain"]


def regressor_perturbations(ev, params, ctx=None):
    """The probe data's uncertainty propagated through the fitted gain(s) (errors in variables):
    type A per Fourier coefficient and, for δX, the unmeasured sphere form (type B, as for δY)."""
    k = -_k(ev)
    cols = []
    if _has_x(ev):
        g = float(params.get("gain", 0.0))
        ks = x_orders(ev)
        cols.append(k * g * ev.radial.perturbations(ev.theta_deg, "dX_um", "value", ks))
        if ev.radial.resolves_backward_whirl():   # the order-1 part, zero on the self-calibration grid
            P1 = ev.radial.order1_model_error_perturbations(ev.theta_deg, _ccd_azimuth(ev))
            cols.append(k * g * (P1 if _order1_applies(ev) else np.zeros_like(P1)))
        form = getattr(ev, "sphere_form_um", None)
        if form and g and ks:
            # the spheres' form bound (Jia: 0.014 µm) is a bound on eq. 7's orders, as for δY
            kf = [q for q in ks if q in RADIAL_ORDERS]
            cols.append(k * g * ev.radial.form_perturbations(ev.theta_deg, "dX_um", form / np.sqrt(3.0), "value", kf))
    else:
        cols.append(k * (float(params.get("inphase_gain", 0.0)) * ev.radial.perturbations(ev.theta_deg, "dY_um", "value")
                         + float(params.get("quadrature_gain", 0.0)) * ev.radial.perturbations(ev.theta_deg, "dY_um", "quadrature")))
    h = float(params.get("radial_gain", 0.0))
    if h:
        cols.append(k * h * ev.radial.perturbations(ev.theta_deg, "dY_um", "integral"))
    return np.hstack(cols)


def heads(ev, params, heads_deg, ctx=None):
    """Head j at azimuth ψ_j (CCW from head 1 on +Y) reads the disk-centre motion c along its
    tangent (−cos ψ, −sin ψ): error_j = −(cos ψ·c_x + sin ψ·c_y)/r. The part this effect adds is
    the missing δX share: error_j = −g·cos ψ_j·δX/r, so δ_(1,j) = −g·(1 − cos ψ_j)·δX/r.
    Only with X probes (the generic basis has no δX)."""
    if not _has_x(ev):
        return None
    g = float(params.get("gain", 0.0))
    dx = ev.radial.at(ev.theta_deg, "dX_um", x_orders(ev)) / radius_um(ev) * ARCSEC_PER_RAD
    return np.column_stack([-g * (1 - np.cos(np.deg2rad(p))) * dx for p in heads_deg])


#: plausible gains: 1 is the physical value (the motion term entirely missing / not read); beyond
#: −0.5…1.5 a regressor is fitting something else than the motion it stands for.
GAIN_RANGE = (-0.5, 1.5)


def plausible(ev, params, u, ctx=None):
    lo, hi = GAIN_RANGE
    for n in ("gain", "radial_gain"):
        if n in params and not lo <= float(params[n]) <= hi:
            return False, f"{n} = {float(params[n]):.3g} outside {lo}…{hi}"
    for n in ("inphase_gain", "quadrature_gain"):
        if n in params and abs(float(params[n])) > max(abs(lo), abs(hi)):
            return False, f"{n} = {float(params[n]):.3g} beyond ±{max(abs(lo), abs(hi))}"
    return True, ""


predict = linear_predictor(design)


def aux(ev, ctx=None):
    cx = ev.radial.coefs("dX_um" if _has_x(ev) else "dY_um")
    if _has_x(ev):
        cx = {**order1(ev), **{k: v for k, v in cx.items() if k in x_orders(ev)}}
    return {"r_um": radius_um(ev), "coefs": coefs_to_json(cx),
            "coefs_dY": coefs_to_json(ev.radial.coefs("dY_um")), "x_probes": _has_x(ev)}


def term(params, aux, base_terms=None):
    c = coefs_from_json(aux["coefs"])
    cy = coefs_from_json(aux.get("coefs_dY", aux["coefs"]))
    k = ARCSEC_PER_RAD / float(aux["r_um"])
    h = float(params.get("radial_gain", 0.0))
    if aux["x_probes"]:
        g = float(params.get("gain", 0.0))
        return lambda th: -k * (g * fourier_eval(np.rad2deg(th), c) + h * fourier_integral(np.rad2deg(th), cy))
    p, q = float(params.get("inphase_gain", 0.0)), float(params.get("quadrature_gain", 0.0))
    cq = quadrature(c)
    return lambda th: -k * (p * fourier_eval(np.rad2deg(th), c) + q * fourier_eval(np.rad2deg(th), cq)
                            + h * fourier_integral(np.rad2deg(th), cy))
