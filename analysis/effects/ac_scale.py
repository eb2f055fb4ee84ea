"""Autocollimator scale error and non-linearity: a residual ∝ reading and reading².

Hsieh et al. 2022, eq. 3: everything rests on the autocollimator reading ε_ij (their sec. 3.3
budgets its "angle error" at 0.07″/√3 over ±1000″). A scale error k multiplies every ε; because β
(eq. 6, averages of differences) and U (eq. 7, sums) are linear in ε, the α they deliver is
scaled by the same (1 + k): the linear part of the residual is k·α ≈ k·model (the model, not the measured
α, is the regressor, so that the residual's own noise is not on both sides) — on polygon data
exactly collinear with a gain on the model (``optical_radius``), separated only by the self-calibration, which does not see
the reference chain. A quadratic term q·ε² does not pass through the linear analysis unchanged;
to first order it adds q·ε² to the reading (its per-run mean goes into U_j). ε is ``ac_arcsec``
when the evidence has it, else α (then the quadratic column differs from q·ε² by the Σβ + U
cross terms — noted in the result).

The non-linearity acts on the whole reading the autocollimator measures, ε = α + Σβ + U (Hsieh
eq. 3), not on α alone: the instrument shows ε = m + (k/100)·m + q·m² for the true angle m, so
to the order the fit resolves m = ε − (k/100)·ε − q·ε², the same function of the measured ε as the
columns (``reading_correction``). The pipeline subtracts it from every reading and repeats the
shift-angle solution (β, U, α), so the corrected curve comes out of the same analysis as the
measured one; subtracting the α response of q·ε² afterwards is equal to first order, but a residual
α after the loop is only meaningful on the curve the instrument would have given (issue 32 item 6:
with the raw α, a 2–4e-4/″ non-linearity named as ac_scale left the residual at 0.8–1.0× of before).
"""

from __future__ import annotations

import numpy as np

from ._base import channels, linear_predictor, no_aux, no_term

NAME = "ac_scale"
MEANING = (
    "The autocollimator's scale is wrong by k % and/or non-linear (q·ε²). The linear part scales "
    "the whole measured α (hence looks like a gain on the model); the quadratic part follows the "
    "raw reading ε, which differs from α by the polygon's pitch sums and setup errors. Not an "
    "encoder error: absent from the self-calibration."
)
PARAMS = {"gain_pct": "%", "quad_per_arcsec": "1/arcsec"}
CHANNELS = channels(alpha="(k/100)·α + q·ε² (α ≈ model in the design)", selfcal="none (reference chain)")
SEEN_BY_SELFCAL = False
SEPARATED_BY = ("Self-calibration (absent there); readings with large setup offsets U (tilt the polygon) "
                "for the quadratic part.")
SEPARATES_FROM = {
    "optical_radius": "multi-head self-calibration, or calibrate the autocollimator against a small-angle generator",
    "ccd_pixel_scale": "multi-head self-calibration, or calibrate the autocollimator",
    "graduation_error": "re-measure with deliberately offset setup errors U_j (tilted polygon): the quadratic term moves, a division error does not",
}
#: variants tried (the best BIC represents the effect): a parameter the data do not need costs ln n.
SUBSETS = [["gain_pct"], ["quad_per_arcsec"], ["gain_pct", "quad_per_arcsec"]]


def _eps(ev):
    ac = getattr(ev, "ac_arcsec", None)
    return np.asarray(ac if ac is not None else ev.alpha_arcsec, dtype=float)


def available(ev, ctx=None):
    return True, "" if getattr(ev, "ac_arcsec", None) is not None else "no raw autocollimator readings: ε ≈ α used for the quadratic term"


def _quad(ev):
    """The quadratic column: q·ε² as the shift-angle analysis passes it to α (the evidence's
    ``ac_quadratic_response``: its face-fixed part is in β, its per-run mean in U — ε² alone left
    0.75–0.8 of a 2–4e-4/″ non-linearity in the residual, issue 16), else ε²."""
    r = getattr(ev, "ac_quadratic_response", None)
    if r is not None and len(r) == len(ev.theta_deg):
        return np.asarray(r, dtype=float)
    e = _eps(ev)
    return e * e


def design(ev, ctx=None):
    # α ≈ the model: the measured α itself would put the residual (and its noise) into the regressor
    a = sum(np.asarray(v, dtype=float) for v in ev.model_terms.values()) + np.zeros(len(ev.theta_deg))
    return np.column_stack([a / 100.0, _quad(ev)]), ["gain_pct", "quad_per_arcsec"]


predict = linear_predictor(design)
aux, term = no_aux, no_term  # an error of the reference chain: no θ-function, no ErrorModel term


#: plausible ranges: an autocollimator's scale is calibrated to well below 1 % (TriAngle: 0.25″ over
#: ±1000″, 0.025 %); 5 % is a gross error. The non-linearity may not exceed ``MAX_QUAD_ARCSEC`` over
#: the readings' own range (20 × the 0.25″ accuracy class).
MAX_GAIN_PCT = 5.0
MAX_QUAD_ARCSEC = 5.0


def plausible(ev, params, u, ctx=None):
    g = float(params.get("gain_pct", 0.0))
    if abs(g) > MAX_GAIN_PCT:
        return False, f"scale error {g:.3g} % is beyond ±{MAX_GAIN_PCT:g} %"
    q = float(params.get("quad_per_arcsec", 0.0))
    e2 = float(np.max(_eps(ev) ** 2)) if len(ev.theta_deg) else 0.0
    if abs(q) * e2 > MAX_QUAD_ARCSEC:
        return False, f"non-linearity {abs(q) * e2:.3g}″ over the readings' range is beyond {MAX_QUAD_ARCSEC:g}″"
    return True, ""


def reading_correction(ev, params) -> np.ndarray:
    """What the autocollimator added to each raw reading ε (arcsec): (k/100)·ε + q·ε², so that the
    true reading is m = ε − this (the model of the columns, with ε the measured reading: the linear
    column's regressor is the model only to keep α's noise off it). Needs the raw readings."""
    e = np.asarray(ev.ac_arcsec, dtype=float)
    return float(params.get("gain_pct", 0.0)) / 100.0 * e + float(params.get("quad_per_arcsec", 0.0)) * e * e
