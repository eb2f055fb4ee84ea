"""Polygon pitch deviations not (or wrongly) removed: a pattern periodic in face index.

Hsieh et al. 2022, eq. 3: ε_ij = α((i−1)·360/N + S) + Σ_{k=j}^{j+i−1} β_k + U_j. If the β used to
extract α are wrong by Δβ (ignored, a stale certificate, too few start faces), the reading (i, j)
keeps Σ_{k=j}^{j+i−1} Δβ_k = C(f) − C(j−1), with f = j+i−1 (mod N) the face under the
autocollimator and C the cumulative sum of Δβ (C(N) = ΣΔβ = 0 by eq. 1). The C(j−1) part is a
constant per start face (absorbed into U_j); what remains is C(f): a pattern fixed to the face,
which moves in θ with the start face. Parameters: C(1)…C(N−1) (C(N) = 0).
With a single start face, face ≡ step ≡ θ and the pattern cannot be told from an error of the
encoder: the design then reports the ambiguity (all start faces separate it).
"""

from __future__ import annotations

import numpy as np

from ._base import channels, linear_predictor, no_term

NAME = "polygon_pitch_ignored"
MEANING = (
    "The polygon's pitch deviations β (Hsieh eq. 1) were ignored or taken from a wrong "
    "certificate. The leftover cumulative pitch C(f) is fixed to the polygon face f under the "
    "autocollimator, so it moves in θ when the start face changes — an error of the reference, "
    "absent from the self-calibration."
)
PARAMS = {"pitch_cum_f{f}_arcsec": "arcsec (f = 1…N−1; C(N) = 0)"}
CHANNELS = channels(alpha="C(f), f = (j + i − 2) mod N + 1", selfcal="none")
SEEN_BY_SELFCAL = False
SEPARATED_BY = "Several start faces (the pattern moves with the face, an encoder error stays at θ)."
SEPARATES_FROM = {
    "graduation_error": "measure with all N start faces (Hsieh Table 1) so that face and θ are crossed",
    "interpolation_error": "measure with all N start faces",
}


def faces(ev):
    return np.asarray(ev.face, dtype=int)


def available(ev, ctx=None):
    if getattr(ev, "face", None) is None or not getattr(ev, "n_faces", None):
        return False, "no face index"
    if len(np.unique(ev.start_face)) < 2:
        return True, "single start face: face pattern ≡ θ pattern (ambiguous with encoder errors)"
    return True, ""


def ambiguous_with(ev):
    """With one start face the face under the autocollimator is fixed by θ: any error of the
    encoder with that θ pattern fits as well."""
    return ["graduation_error"] if len(np.unique(ev.start_face)) < 2 else []


def design(ev, ctx=None):
    f = faces(ev)
    N = int(ev.n_faces)
    X = np.zeros((f.size, N - 1))
    for c in range(1, N):
        X[:, c - 1] = (f == c)
    return X, [f"pitch_cum_f{c}_arcsec" for c in range(1, N)]


predict = linear_predictor(design)
term = no_term  # an error of the reference chain: no θ-function, no ErrorModel term


#: plausible leftover cumulative pitch: 10″ per face — a polygon certificate is good to ~0.1–0.5″.
MAX_ARCSEC = 10.0


def plausible(ev, params, u, ctx=None):
    m = max((abs(float(v)) for v in params.values()), default=0.0)
    ok = m <= MAX_ARCSEC
    return ok, "" if ok else f"cumulative pitch {m:.3g}″ is beyond {MAX_ARCSEC:g}″"


def aux(ev, ctx=None):
    return {"n_faces": int(ev.n_faces)}
