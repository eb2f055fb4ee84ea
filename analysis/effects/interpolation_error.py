"""Interpolation (sub-division) error of the reading head: periodic with the grating period.

Jia et al. 2019 use a Mercury 3000 (0.39″ resolution, interpolated from a 20 µm grating): the
interpolator's error repeats every grating line, angular period 360°/L (L lines; L = 2πr/p when
only r and the period p are known). Its first two orders are fitted:
Σ_m c_m,s sin(2π m L θ/360°) + c_m,c cos(2π m L θ/360°).

Sampling: on the polygon grid of Hsieh et al. 2022 eq. 3, θ_i = (i−1)·360°/N + S, the phase m·L·θ/360° advances by m·L/N per
step, so the error shows up as the alias harmonic (m·L mod N) folded into 0…N/2 — for L = 36000,
N = 23 a 5th harmonic. If m·L is a multiple of N (and all shifts S are multiples of 360°/(m·L)),
every reading of a run has the same phase: the error is a per-run constant that the closure
removes, and this sampling cannot see it (``available`` says so; ``visibility`` gives the alias).
Shift angles S change the alias's phase differently from a real harmonic's (k·S versus
m·L·S/360° of a period), and a jitter of the stops spreads the phase: both separate it from a
division error of the alias order.
"""

from __future__ import annotations

import math

import numpy as np

from ._base import alias_harmonic, amplitudes_within, channels, disk_fixed_heads_of, linear_predictor

NAME = "interpolation_error"
MEANING = (
    "The reading head's interpolation of the sin/cos signals is imperfect (offsets, amplitude "
    "mismatch, phase error): an error periodic with one grating period (first order) and half of it "
    "(second order). On the coarse polygon grid it appears as an alias harmonic of θ; the encoder "
    "reading tells the phase within the period, so shifts and stop jitter separate it from a real "
    "low-order harmonic."
)
PARAMS = {"c{m}_sin_arcsec": "arcsec", "c{m}_cos_arcsec": "arcsec"}
ORDERS = (1, 2)
CHANNELS = channels(
    alpha="Σ_m c_m sin/cos(2π m L θ/360°), seen as the alias harmonic m·L mod N",
    selfcal="the same for head 1 at the self-calibration angles (a constant if they are whole multiples of the period)",
    heads="each head's own interpolation error",
)
#: variants tried (the best BIC represents the effect): a parameter the data do not need costs ln n.
SUBSETS = [["c1_sin_arcsec", "c1_cos_arcsec"], ["c2_sin_arcsec", "c2_cos_arcsec"],
           ["c1_sin_arcsec", "c1_cos_arcsec", "c2_sin_arcsec", "c2_cos_arcsec"]]
SEEN_BY_SELFCAL = True
SEPARATED_BY = "Shift angles S (phase of the period differs from the alias harmonic's phase); stop jitter; fine-grid self-calibration."
SEPARATES_FROM = {
    "graduation_error": "repeat at shift angles S with S·L/360° not an integer shifted by the same amount as k·S "
                        "(e.g. S = 5°, 10°), or read the head's Lissajous signals",
}


def lines(ev):
    L = getattr(ev, "encoder_lines", None)
    if L:
        return int(L)
    p = getattr(ev, "grating_period_um", None)
    if p:
        return int(round(2 * math.pi * float(ev.optical_radius_mm) * 1000.0 / float(p)))
    return None


#: an order is visible when, inside the runs (closure groups), its phases are spread: mean resultant
#: length of exp(i·m·phase) below this (1 = all readings of a run at one phase of the period).
MAX_RESULTANT = 0.8


def _phase(theta_deg, L):
    return 2 * np.pi * ((np.asarray(theta_deg, dtype=float) * L / 360.0) % 1.0)


def visible_orders(ev) -> list[int]:
    """Orders whose phase the polygon sampling spreads inside a run (computed on the polygon
    readings, also for the self-calibration view, so that both give the same parameters)."""
    pe = getattr(ev, "parent", ev)
    L = lines(pe)
    if L is None:
        return []
    ph = _phase(pe.theta_deg, L)
    g = np.asarray(pe.closure_group)
    out = []
    for m in ORDERS:
        z = np.exp(1j * m * ph)
        R = [abs(z[g == k].mean()) for k in np.unique(g)]
        if float(np.mean(R)) < MAX_RESULTANT:
            out.append(m)
    return out


def available(ev, ctx=None):
    L = lines(ev)
    if L is None:
        return False, "no encoder line count or grating period"
    vis = visible_orders(ev)
    if not vis:
        N = int(getattr(ev, "n_faces", 0) or 0)
        return False, (f"the sampling cannot see it: inside each run the stops fall at (nearly) one phase of the "
                       f"grating period (L = {L} lines, N = {N} faces: m·L/N integer or shifts at whole periods); "
                       "change the shift angle by a fraction of 360°/L or use a polygon with N not dividing L")
    return True, "" if len(vis) == len(ORDERS) else f"only orders {vis} visible with this sampling"


def design(ev, ctx=None):
    L = lines(ev)
    ph = _phase(ev.theta_deg, L)
    cols, names = [], []
    for m in visible_orders(ev):
        cols += [np.sin(m * ph), np.cos(m * ph)]
        names += [f"c{m}_sin_arcsec", f"c{m}_cos_arcsec"]
    return (np.column_stack(cols) if cols else np.zeros((ph.size, 0))), names


predict = linear_predictor(design)


#: plausible sub-division error: 10″ — one grating period of a 7069-line disk is 183″; an error of
#: 1/18 of a period is a failed interpolator, not a calibration finding.
MAX_ARCSEC = 10.0


def plausible(ev, params, u, ctx=None):
    return amplitudes_within(params, [(f"order {m}", f"c{m}_sin_arcsec", f"c{m}_cos_arcsec") for m in ORDERS], MAX_ARCSEC)


def visibility(ev) -> dict:
    """The alias harmonic of each order on the N-face grid and whether the sampling can see it."""
    L = lines(ev)
    N = int(getattr(ev, "n_faces", 0) or 0)
    out = {"lines": L}
    if L and N:
        out["alias_harmonic"] = {str(m): alias_harmonic(m * L, N) for m in ORDERS}
    return out


def aux(ev, ctx=None):
    return {"lines": lines(ev)}


def term(params, aux, base_terms=None):
    L = int(aux["lines"])

    def fn(th):
        ph = 2 * np.pi * ((np.rad2deg(np.asarray(th, dtype=float)) * L / 360.0) % 1.0)
        return sum(params.get(f"c{m}_sin_arcsec", 0.0) * np.sin(m * ph) + params.get(f"c{m}_cos_arcsec", 0.0) * np.cos(m * ph)
                   for m in ORDERS) + 0.0 * ph
    return fn


#: the multi-head differences δ_(1,j)(θ) = g(θ) − g(θ − ψ_j) (Hsieh eq. 8): the error is fixed to the disk
heads = disk_fixed_heads_of(term, aux)
