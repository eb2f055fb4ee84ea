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
With polygon and self-calibration data only, a form harmonic and a division harmonic are the same
function of θ: sphere_form is separable only by probe-side measurements (reversal), so it ends in
an ambiguity set with graduation_error — by design, documented.
"""

from __future__ import annotations

import numpy as np

from ._base import ARCSEC_PER_RAD, linear_predict, radius_um

NAME = "sphere_form"
MEANING = (
    "A test sphere is not round: its k-lobed form is part of the probe reading and Jia's eq. 7 "
    "takes it for radial motion, so the model contains a spurious −w·∫f dθ/r that the encoder does "
    "not have. Only harmonics present in one sphere's reading qualify; for a rigid shaft they would "
    "have to appear, consistently, as motion in the other channels (other sphere, X probes)."
)
PARAMS = {"{sphere}_h{k}_sin_um": "µm", "{sphere}_h{k}_cos_um": "µm"}
MIN_LOBE_UM = 0.01
CHANNELS = {
    "alpha": "−w_s/r·∫(f_s sin kθ + g_s cos kθ) dθ (the model's spurious share)",
    "selfcal": "the same (the model is wrong, the encoder is not)",
    "radial": "the sphere's reading contains f; δY at the disk is too large by w_s·f",
    "ccd": "none",
    "heads": "none beyond the model",
}
SEEN_BY_SELFCAL = True
SEPARATED_BY = "Donaldson reversal (or re-clamping the sphere rotated by 180°/k); a second sphere or X probe at the same height."
SEPARATES_FROM = {
    "graduation_error": "Donaldson reversal of the test sphere (or re-clamp it rotated by 180°/k): "
                        "a form error moves with the sphere, a division error stays with the disk",
    "tilt_abbe": "Donaldson reversal of the test sphere; measure L1 with a height gauge",
}


def _plan(ev, ctx):
    """[(sphere, k, weight, reading amplitude)] of the basis."""
    if ev.radial is None:
        return []
    L1, L2 = float(ev.L1_mm), float(ev.L2_mm)
    w = {"top": (L2 - L1) / L2, "bottom": L1 / L2}
    flagged = set(ctx["harmonics"]) if ctx and ctx.get("harmonics") is not None else None
    ct, cb = ev.radial.coefs("top_um"), ev.radial.coefs("bottom_um")
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


def available(ev, ctx=None):
    if ev.radial is None:
        return False, "no radial-motion data"
    ok = bool(_plan(ev, ctx))
    return ok, "" if ok else "no residual harmonic that a sphere reading shows"


def design(ev, ctx=None):
    th = np.deg2rad(np.asarray(ev.theta_deg, dtype=float))
    r = radius_um(ev)
    cols, names = [], []
    for s, k, w, _ in _plan(ev, ctx):
        # ∫ sin kθ = −cos kθ / k ; ∫ cos kθ = sin kθ / k ; residual = −w ∫ f / r
        cols += [w * np.cos(k * th) / (k * r) * ARCSEC_PER_RAD, -w * np.sin(k * th) / (k * r) * ARCSEC_PER_RAD]
        names += [f"{s}_h{k}_sin_um", f"{s}_h{k}_cos_um"]
    return (np.column_stack(cols) if cols else np.zeros((th.size, 0))), names


def predict(ev, params, ctx=None):
    return linear_predict(design, ev, params, ctx)


def plausible(ev, params, u, ctx=None):
    """(ok, reason): the fitted form may not exceed the sphere reading's amplitude by more than 3u."""
    for s, k, w, a in _plan(ev, ctx):
        fs, fc = params.get(f"{s}_h{k}_sin_um", 0.0), params.get(f"{s}_h{k}_cos_um", 0.0)
        amp = float(np.hypot(fs, fc))
        ua = float(np.hypot(u.get(f"{s}_h{k}_sin_um", 0.0), u.get(f"{s}_h{k}_cos_um", 0.0)))
        if amp > a + 3 * ua + 1e-12:
            return False, f"form {amp:.3f} µm in harmonic {k} exceeds the {s} sphere's reading {a:.3f} µm"
    return True, ""


def aux(ev, ctx=None):
    return {"r_um": radius_um(ev), "plan": [[s, k, w] for s, k, w, _ in _plan(ev, ctx)]}


def term(params, aux, base_terms=None):
    r = float(aux["r_um"])
    plan = aux["plan"]

    def fn(th):
        th = np.asarray(th, dtype=float)
        out = np.zeros_like(th)
        for s, k, w in plan:
            fs, fc = params.get(f"{s}_h{k}_sin_um", 0.0), params.get(f"{s}_h{k}_cos_um", 0.0)
            out += (w * fs * np.cos(k * th) - w * fc * np.sin(k * th)) / (k * r) * ARCSEC_PER_RAD
        return out
    return fn
