"""Form error of a test sphere read as shaft motion: a probe artefact in the model's ∫δY term.

Jia et al. 2019, sec. 4.1 / eq. 7: the probe reading of each sphere is taken as the sphere's
motion after removing orders 0 and 1 (probe position, sphere centring); the sphere's roundness
(they quote only its roughness, 0.014 µm) is assumed zero. A k-lobed form f_k of a sphere is then
integrated by eq. 5 as if it were motion, with the weight of that sphere in eq. 9
(w_top = (L2−L1)/L2, w_bottom = L1/L2): the residual is −w·∫f_k dθ/r.

Only harmonics present in that sphere's reading can be form (the form is part of the reading), so
the basis is: the harmonics flagged in the residual (context ``harmonics``) that the sphere's
reading shows (amplitude ≥ ``MIN_LOBE_UM``), for the sphere with the larger weight × amplitude.
Plausibility: the fitted form cannot exceed the sphere's reading amplitude in that harmonic by more
than 3u (a form larger than the reading would need a motion cancelling it exactly).

With X probes the form is read twice: the X probe, a quarter turn before the Y probe, reads the
same lobes, X(θ) = Y(θ + 90°). The X readings make δX at the disk (eq. 9's weights), the regressor
of ``tangential_motion``, so δX is too large by w·f_x, and the tangential term at its geometric
gain (−g·δX/r, g = 1) takes that share for motion; with h = 1 it also cancels eq. 5's ∫f_y term.
The readings then need +w·f_x/r: the variant ``{sphere}_x_h{k}`` (one sin/cos pair per flagged
order of eq. 7's 2…10 that the X reading shows), to be fitted beside tangential_motion. Its
plausibility is looser than the Y variant's: the form may exceed the X reading, because the motion
at the same order cancels part of it (loop validation lv785: 0.10 µm of form at order 5 under an
X reading of 0.033 µm and a Y reading of 0.082 µm), but not the two readings together, which needs
a motion cancelling it in both channels at once. Without this variant the X-probe benches named
graduation_error for a sphere form (lv783, lv785); with it lv783 names the form, lv785 still not
(docs/loop-validation.md, "sphere_form read through the X probes").

With polygon and self-calibration data only, a form harmonic and a division harmonic are the same
function of θ: sphere_form is separable only by probe-side measurements (reversal), so a named
sphere_form carries graduation_error in its ambiguity set (``ambiguous_with``).
"""

from __future__ import annotations

import numpy as np

from ..radial_motion import disk_weights
from ._base import ARCSEC_PER_RAD, channels, linear_predictor, radius_um

NAME = "sphere_form"
MEANING = (
    "A test sphere is not round: its k-lobed form is part of the probe reading and Jia's eq. 7 "
    "takes it for radial motion, so the model contains a spurious −w·∫f dθ/r that the encoder does "
    "not have. Only harmonics present in one sphere's reading qualify; for a rigid shaft they would "
    "have to appear, consistently, as motion in the other channels (other sphere, X probes)."
)
PARAMS = {"{sphere}_h{k}_sin_um": "µm", "{sphere}_h{k}_cos_um": "µm",
          "{sphere}_x_h{k}_sin_um": "µm (the form as the X probe reads it)",
          "{sphere}_x_h{k}_cos_um": "µm (the form as the X probe reads it)"}
MIN_LOBE_UM = 0.01
CHANNELS = channels(
    alpha="−w_s/r·∫(f_s sin kθ + g_s cos kθ) dθ (the model's spurious share); with X probes also "
          "+w_s/r·(f_x sin kθ + g_x cos kθ), the form in δX that the tangential term takes for motion",
    selfcal="the same (the model is wrong, the encoder is not)",
    radial="the sphere's readings contain f (X a quarter turn before Y); δY and δX at the disk are too large by w_s·f",
    heads="none beyond the model",
)
SEEN_BY_SELFCAL = True
SEPARATED_BY = "Donaldson reversal (or re-clamping the sphere rotated by 180°/k); a second sphere or X probe at the same height."
SEPARATES_FROM = {
    "graduation_error": "Donaldson reversal of the test sphere (or re-clamp it rotated by 180°/k): "
                        "a form error moves with the sphere, a division error stays with the disk",
    "tilt_abbe": "Donaldson reversal of the test sphere; measure L1 with a height gauge",
}


def _weights(ev) -> dict[str, float]:
    """Each sphere's weight at the disk (eq. 9)."""
    wt, wb = disk_weights(float(ev.L1_mm), float(ev.L2_mm))
    return {"top": wt, "bottom": wb}


def _plan(ev, ctx, axis: str = ""):
    """[(sphere, k, weight, reading amplitude)] of the basis: the harmonics flagged in the residual,
    of eq. 7's orders 2…10, that a sphere's reading shows (amplitude ≥ ``MIN_LOBE_UM``), for the
    sphere with the larger weight × amplitude. ``axis`` "_x": the X probes' readings (the X-channel
    variant; [] without X probes)."""
    if ev.radial is None or (axis and not ev.radial.has_x):
        return []
    w = _weights(ev)
    flagged = set(ctx["harmonics"]) if ctx and ctx.get("harmonics") is not None else None
    ct, cb = ev.radial.coefs(f"top{axis}_um"), ev.radial.coefs(f"bottom{axis}_um")
    plan = []
    for k in sorted(ct):
        if flagged is not None and k not in flagged:
            continue
        at, ab = float(np.hypot(*ct[k])), float(np.hypot(*cb[k]))
        cand = [(w["top"] * at, "top", at), (w["bottom"] * ab, "bottom", ab)]
        wa, s, a = max(cand)
        if a >= MIN_LOBE_UM:
            plan.append((s, k, w[s], a))
    return plan


def _plan_x(ev, ctx):
    """:func:`_plan` of the X probes' readings."""
    return _plan(ev, ctx, "_x")


def ambiguous_with(ev):
    """A form harmonic and a division harmonic are the same function of θ on the polygon and the
    self-calibration, with or without X probes: only a probe-side measurement (Donaldson reversal,
    or re-clamping the sphere) separates them, so a named sphere_form always carries
    graduation_error in its set."""
    return ["graduation_error"]


def available(ev, ctx=None):
    if ev.radial is None:
        return False, "no radial-motion data"
    ok = bool(_plan(ev, ctx)) or bool(_plan_x(ev, ctx))
    return ok, "" if ok else "no residual harmonic that a sphere reading shows"


#: variants: the form harmonic by harmonic (2 parameters each, any amplitude and phase up to the
#: reading), or ``form_fraction``: the share f of the sphere's whole reading (orders 2…10) that is
#: form (1 parameter; f = 1: the lobes are entirely form). The second predicts the residual's phase and
#: amplitude ratios from the probe reading — a coincidence a division error would not reproduce.


def design(ev, ctx=None):
    th = np.deg2rad(np.asarray(ev.theta_deg, dtype=float))
    r = radius_um(ev)
    cols, names = [], []
    plan = _plan(ev, ctx)
    for s, k, w, _ in plan:
        # ∫ sin kθ = −cos kθ / k ; ∫ cos kθ = sin kθ / k ; residual = −w ∫ f / r
        cs, cc = w * np.cos(k * th) / (k * r) * ARCSEC_PER_RAD, -w * np.sin(k * th) / (k * r) * ARCSEC_PER_RAD
        cols += [cs, cc]
        names += [f"{s}_h{k}_sin_um", f"{s}_h{k}_cos_um"]
    if plan:
        cols.append(_fraction_column(ev, _fraction_plan(ev, ctx)))
        names.append("form_fraction")
    for s, k, w, _ in _plan_x(ev, ctx):
        # the X probe reads the form too: δX at the disk is too large by w·f_x, and the tangential
        # term (−g·δX/r, g = 1 in the exact geometry) takes it for motion: +w·f_x/r is missing
        cols += [w * np.sin(k * th) / r * ARCSEC_PER_RAD, w * np.cos(k * th) / r * ARCSEC_PER_RAD]
        names += [f"{s}_x_h{k}_sin_um", f"{s}_x_h{k}_cos_um"]
    return (np.column_stack(cols) if cols else np.zeros((th.size, 0))), names


def _fraction_plan(ev, ctx):
    """[(sphere, k, w)] of the fraction variant: every order of eq. 7's series (2…10) of each sphere the
    plan uses — a form is the whole reading's lobes, not only the ones the residual happens to flag."""
    spheres = sorted({s for s, *_ in _plan(ev, ctx)})
    w = _weights(ev)
    return [(s, k, w[s]) for s in spheres for k in sorted(ev.radial.coefs(f"{s}_um"))]


def _fraction_column(ev, fplan):
    th = np.deg2rad(np.asarray(ev.theta_deg, dtype=float))
    r = radius_um(ev)
    out = np.zeros(th.size)
    for s, k, w in fplan:
        a, b = ev.radial.coefs(f"{s}_um")[k]   # the reading's own harmonic k (sin, cos), µm
        out += (w * a * np.cos(k * th) - w * b * np.sin(k * th)) / (k * r) * ARCSEC_PER_RAD
    return out


def variants(names, ev=None, ctx=None):
    """Parameter subsets tried (tracing): per-harmonic form in eq. 7's ∫δY term, one fraction of the
    reading, or (X probes) per-harmonic form in the X probe's δX."""
    per = [n for n in names if n != "form_fraction" and "_x_h" not in n]
    per_x = [n for n in names if "_x_h" in n]
    return [v for v in (per, ["form_fraction"], per_x) if v and all(n in names for n in v)]


predict = linear_predictor(design)


def _amplitude(params, u, lobe: str) -> tuple[float, float]:
    """(amplitude, its u) of the fitted lobe ``lobe`` (µm): the hypot of its sin and cos parameters."""
    return (float(np.hypot(params.get(f"{lobe}_sin_um", 0.0), params.get(f"{lobe}_cos_um", 0.0))),
            float(np.hypot(u.get(f"{lobe}_sin_um", 0.0), u.get(f"{lobe}_cos_um", 0.0))))


def plausible(ev, params, u, ctx=None):
    """(ok, reason): the fitted form may not exceed the sphere reading's amplitude by more than 3u;
    the fraction of the reading that is form lies in 0…1 (within 3u)."""
    if "form_fraction" in params:
        f, uf = float(params["form_fraction"]), float(u.get("form_fraction", 0.0))
        if not -3 * uf <= f <= 1 + 3 * uf:
            return False, f"form fraction {f:.3g} ± {uf:.2g} outside 0…1 of the reading"
    for s, k, w, a in _plan(ev, ctx):
        amp, ua = _amplitude(params, u, f"{s}_h{k}")
        if amp > a + 3 * ua + 1e-12:
            return False, f"form {amp:.3f} µm in harmonic {k} exceeds the {s} sphere's reading {a:.3f} µm"
    for s, k, w, a in _plan_x(ev, ctx):
        amp, ua = _amplitude(params, u, f"{s}_x_h{k}")
        # both probes read the same form (X a quarter turn before Y): a form larger than the two
        # readings together needs a motion that cancels it in both channels at once
        a_y = float(np.hypot(*ev.radial.coefs(f"{s}_um")[k]))
        if amp > a + a_y + 3 * ua + 1e-12:
            return False, (f"form {amp:.3f} µm in harmonic {k} exceeds the {s} sphere's X and Y readings "
                           f"together ({a:.3f} + {a_y:.3f} µm)")
    return True, ""


def aux(ev, ctx=None):
    plan = _plan(ev, ctx)
    fplan = _fraction_plan(ev, ctx) if plan else []
    out = {"r_um": radius_um(ev), "plan": [[s, k, w] for s, k, w, _ in plan],
           "fraction_plan": [[s, k, w] for s, k, w in fplan],
           "reading": [list(ev.radial.coefs(f"{s}_um")[k]) for s, k, w in fplan]}
    plan_x = _plan_x(ev, ctx)
    if plan_x:   # only with X probes (the model file of a Y-probe bench keeps its keys)
        out["plan_x"] = [[s, k, w] for s, k, w, _ in plan_x]
    return out


def term(params, aux, base_terms=None):
    r = float(aux["r_um"])
    plan = aux["plan"]
    fr = float(params.get("form_fraction", 0.0))
    reading = aux.get("reading") or []

    fplan = aux.get("fraction_plan") or []

    def fn(th):
        th = np.asarray(th, dtype=float)
        out = np.zeros_like(th)
        lobes = [(s, k, w, params.get(f"{s}_h{k}_sin_um", 0.0), params.get(f"{s}_h{k}_cos_um", 0.0)) for s, k, w in plan]
        lobes += [(s, k, w, fr * ra, fr * rb) for (s, k, w), (ra, rb) in zip(fplan, reading)]
        for s, k, w, fs, fc in lobes:
            out += (w * fs * np.cos(k * th) - w * fc * np.sin(k * th)) / (k * r) * ARCSEC_PER_RAD
        for s, k, w in aux.get("plan_x") or []:
            fs, fc = params.get(f"{s}_x_h{k}_sin_um", 0.0), params.get(f"{s}_x_h{k}_cos_um", 0.0)
            out += w * (fs * np.sin(k * th) + fc * np.cos(k * th)) / r * ARCSEC_PER_RAD
        return out
    return fn
