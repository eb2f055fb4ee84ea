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

With X probes the same form is also read by the sphere's X probe, 90° further round the sphere:
f_X(θ) = f_Y(θ + 90°) (docs/conventions.md: the Y probe on +Y, the X probe on +X, both readings
positive towards their axis, the shaft turning CCW). Its X reading enters the disk's δX by eq. 9
with the same weight w, so the tangential motion, which takes that δX as its regressor (gain g on
−δX/r, radial gain h on −∫δY/r; g = h = 1 in the exact geometry), carries −g·w·f_X/r that the encoder
does not have, and h·∫δY takes the model's −w·∫f_Y/r. Beside it the form's whole imprint on the
residual is +w·f_X/r at g = h = 1: k times the ∫f_Y/r of the Y-bench template per µm (loop
validation lv93 sphere_form #0: 0.15 µm at k = 3 is 1.37″ of −δX/r; the tangential motion alone fails its
errors-in-variables gate, and the form read as ∫f_Y/r needs 5× the reading). The ``x`` variant
(``{sphere}_xh{k}_sin_um``, ``_cos_um``: the form's coefficients as the Y probe sees them) holds that
imprint; it describes the effect only beside the tangential motion (``requires``). In θ its columns
are harmonics k, as a division error's: only their size, bounded by the sphere's readings
(``plausible``), tells the two apart; any g and h give the same column space (the µm scale assumes
g = h = 1).
"""

from __future__ import annotations

import numpy as np

from ._base import ARCSEC_PER_RAD, channels, linear_predictor, radius_um

NAME = "sphere_form"
MEANING = (
    "A test sphere is not round: its k-lobed form is part of the probe reading and Jia's eq. 7 "
    "takes it for radial motion, so the model contains a spurious −w·∫f dθ/r that the encoder does "
    "not have. Only harmonics present in one sphere's reading qualify; for a rigid shaft they would "
    "have to appear, consistently, as motion in the other channels (other sphere, X probes)."
)
PARAMS = {"{sphere}_h{k}_sin_um": "µm", "{sphere}_h{k}_cos_um": "µm",
          "{sphere}_xh{k}_sin_um": "µm", "{sphere}_xh{k}_cos_um": "µm"}
MIN_LOBE_UM = 0.01
CHANNELS = channels(
    alpha="−w_s/r·∫(f_s sin kθ + g_s cos kθ) dθ (the model's spurious share)",
    selfcal="the same (the model is wrong, the encoder is not)",
    radial="the sphere's reading contains f; δY at the disk is too large by w_s·f",
    heads="none beyond the model",
)
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


def _has_x(ev):
    return ev.radial is not None and getattr(ev.radial, "has_x", False)


def _x_plan(ev, ctx):
    """[(sphere, k, weight, bound µm)] of the ``x`` variant (X probes only): the harmonics flagged in the
    residual that a sphere's Y or X reading shows (≥ ``MIN_LOBE_UM``), for the sphere with the larger
    weight × reading; the bound is that sphere's larger reading amplitude at k (the form is in both
    readings, the motion may cancel part of it in one)."""
    if not _has_x(ev):
        return []
    L1, L2 = float(ev.L1_mm), float(ev.L2_mm)
    w = {"top": (L2 - L1) / L2, "bottom": L1 / L2}
    flagged = set(ctx["harmonics"]) if ctx and ctx.get("harmonics") is not None else None
    c = {(s, ch): ev.radial.coefs(f"{s}{ch}_um") for s in ("top", "bottom") for ch in ("", "_x")}
    plan = []
    for k in sorted(set(c[("top", "")]) & set(c[("top", "_x")])):
        if flagged is not None and k not in flagged:
            continue
        amp = {s: max(float(np.hypot(*c[(s, ch)].get(k, (0.0, 0.0)))) for ch in ("", "_x")) for s in w}
        wa, s, a = max((w[s] * amp[s], s, amp[s]) for s in w)
        if a >= MIN_LOBE_UM:
            plan.append((s, k, w[s], a))
    return plan


def _x_lobe(th, k, w, r, fs, fc):
    """+w·f_X/r (arcsec) of a lobe whose Y-probe coefficients are (fs, fc) µm: f_X(θ) = f_Y(θ + 90°)."""
    ph = k * np.pi / 2
    return w * (fs * np.sin(k * th + ph) + fc * np.cos(k * th + ph)) / r * ARCSEC_PER_RAD


def available(ev, ctx=None):
    if ev.radial is None:
        return False, "no radial-motion data"
    ok = bool(_plan(ev, ctx))
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
    for s, k, w, _ in _x_plan(ev, ctx):
        cols += [_x_lobe(th, k, w, r, 1.0, 0.0), _x_lobe(th, k, w, r, 0.0, 1.0)]
        names += [f"{s}_xh{k}_sin_um", f"{s}_xh{k}_cos_um"]
    return (np.column_stack(cols) if cols else np.zeros((th.size, 0))), names


def _fraction_plan(ev, ctx):
    """[(sphere, k, w)] of the fraction variant: every order of eq. 7's series (2…10) of each sphere the
    plan uses — a form is the whole reading's lobes, not only the ones the residual happens to flag."""
    spheres = sorted({s for s, *_ in _plan(ev, ctx)})
    L1, L2 = float(ev.L1_mm), float(ev.L2_mm)
    w = {"top": (L2 - L1) / L2, "bottom": L1 / L2}
    return [(s, k, w[s]) for s in spheres for k in sorted(ev.radial.coefs(f"{s}_um"))]


def _fraction_column(ev, fplan):
    th = np.deg2rad(np.asarray(ev.theta_deg, dtype=float))
    r = radius_um(ev)
    out = np.zeros(th.size)
    for s, k, w in fplan:
        a, b = ev.radial.coefs(f"{s}_um")[k]   # the reading's own harmonic k (sin, cos), µm
        out += (w * a * np.cos(k * th) - w * b * np.sin(k * th)) / (k * r) * ARCSEC_PER_RAD
    return out


def _is_x(name):
    return "_xh" in name


def variants(names, ev=None, ctx=None):
    """Parameter subsets tried (tracing): per-harmonic form, one fraction of the reading, and with X
    probes the form read by them beside the tangential motion (``x``)."""
    per = [n for n in names if n != "form_fraction" and not _is_x(n)]
    out = [v for v in (per, ["form_fraction"]) if v and all(n in names for n in v)]
    # the form read by the X probes: the largest lobes of the sphere's readings first, nested (a form
    # is lobes of the reading; which of them are form and which the axis's motion the polygon decides,
    # the information criterion choosing among the nested sets); a variant only with all its lobes
    lobes = [(a, s, k) for s, k, _, a in (_x_plan(ev, ctx) if ev is not None else [])]
    lobes.sort(key=lambda t: (-t[0], t[2]))
    for i in range(1, len(lobes) + 1):
        v = [f"{s}_xh{k}_{sc}_um" for _, s, k in lobes[:i] for sc in ("sin", "cos")]
        if all(n in names for n in v):
            out.append(v)
    return out


def requires(names):
    """The effects a variant describes the form beside: the ``x`` variant is the form in the X probes'
    δX, which only the tangential motion takes into the model."""
    return ["tangential_motion"] if any(_is_x(n) for n in names) else []


predict = linear_predictor(design)


def plausible(ev, params, u, ctx=None):
    """(ok, reason): the fitted form may not exceed the sphere reading's amplitude by more than 3u;
    the fraction of the reading that is form lies in 0…1 (within 3u)."""
    if "form_fraction" in params:
        f, uf = float(params["form_fraction"]), float(u.get("form_fraction", 0.0))
        if not -3 * uf <= f <= 1 + 3 * uf:
            return False, f"form fraction {f:.3g} ± {uf:.2g} outside 0…1 of the reading"
    for tag, plan in (("h", _plan(ev, ctx)), ("xh", _x_plan(ev, ctx))):
        for s, k, w, a in plan:
            fs, fc = params.get(f"{s}_{tag}{k}_sin_um", 0.0), params.get(f"{s}_{tag}{k}_cos_um", 0.0)
            amp = float(np.hypot(fs, fc))
            ua = float(np.hypot(u.get(f"{s}_{tag}{k}_sin_um", 0.0), u.get(f"{s}_{tag}{k}_cos_um", 0.0)))
            if amp > a + 3 * ua + 1e-12:
                return False, f"form {amp:.3f} µm in harmonic {k} exceeds the {s} sphere's reading {a:.3f} µm"
    return True, ""


def aux(ev, ctx=None):
    plan = _plan(ev, ctx)
    fplan = _fraction_plan(ev, ctx) if plan else []
    return {"r_um": radius_um(ev), "plan": [[s, k, w] for s, k, w, _ in plan],
            "x_plan": [[s, k, w] for s, k, w, _ in _x_plan(ev, ctx)],
            "fraction_plan": [[s, k, w] for s, k, w in fplan],
            "reading": [list(ev.radial.coefs(f"{s}_um")[k]) for s, k, w in fplan]}


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
        for s, k, w in aux.get("x_plan") or []:
            out += _x_lobe(th, k, w, r, params.get(f"{s}_xh{k}_sin_um", 0.0), params.get(f"{s}_xh{k}_cos_um", 0.0))
        return out
    return fn
