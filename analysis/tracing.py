"""Close the loop: trace the residual between Jia's model and the measured encoder error to the effect
the model lacks.

Jia et al. 2019 (Appl. Sci. 9, 3415) validate their model Δθ = [e·sin(θ−θ0) + ∫δY dθ]/r (eq. 5)
against an autocollimator and a 23-face polygon and are left with a residual within ±6″, 9 % of the
encoder error, whose cause they only guess ("imperfect manufacturing of the grating disk and other
minor errors", sec. 6). Hsieh et al. 2022 (Appl. Sci. 12, 5008) give the polygon data's structure
(eq. 3: ε_ij = α((i−1)·360/N + S) + Σβ + U_j, start faces j, shift angles S) and the multi-head
self-calibration (eqs. 8–9) that sees the encoder's own errors but not the reference chain's.

This module takes everything the analysis knows about a dataset, per polygon reading
(:class:`Evidence`), and answers, in order:

1. Is there anything to explain? χ² of the residual against the combined uncertainty of the
   measurement and of the model (model parameter uncertainties enter as nuisance columns with a
   unit Gaussian prior, i.e. the covariance diag(u²) + S·Sᵀ), and a harmonic-by-harmonic test.
2. Its signature: harmonic spectrum, drift with time, repetition (synchronous or not), start face
   and shift (polygon-related or not), direction (hysteresis), self-calibration, correlation with
   the radial motion and with each of the model's own terms.
3. Which effect of the library (:mod:`benchtwin.analysis.effects`) explains it: each candidate alone
   and in pairs, weighted least squares, BIC and AICc, leave-one-group-out cross-validation,
   significance gates against over-fitting; ambiguity sets with the separating measurement;
   "unexplained" when nothing brings the residual down to the noise.

The polygon closure (Hsieh eq. 2: Σα = 0 per run; eq. 7 solves U_j from it) leaves α known only up
to a constant per set of readings that share one setup error U ("closure group", default: one
(shift, start face, repetition) mounting: the twin and Hsieh's six measurements mount the polygon
anew for every repetition; the two directions of one repetition share it). Every fit here therefore removes the weighted mean per closure group
from the residual and from every column (equivalent to free offsets per group); the degrees of
freedom count them.

Thresholds (tuned on the synthetic tests, see docs/effects.md): ``P_SIG`` = 1e-3 for χ² tests,
harmonic flags at a Bonferroni-corrected 1e-3, candidate gates ``Z_GATE`` = 4 and ``DBIC_GATE`` = 10,
ambiguity when ΔBIC < ``AMBIG_DBIC`` = 6 and the predictions' cos² > ``COLLINEAR`` = 0.9.
"""

from __future__ import annotations

import functools
import itertools
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from benchtwin.jsonable import to_json

from .effects import ALL
from .effects._base import (ARCSEC_PER_RAD, RADIAL_ORDERS, fourier_eval, fourier_fit, fourier_integral,
                            perturbation_columns)

__all__ = [
    "Evidence", "RadialMotion", "SelfCal", "CCDData", "trace", "signature", "residual_test",
    "save_model", "load_model", "model_terms_from_payload", "add_to_error_model", "evidence_from_polygon",
    "P_SIG", "Z_GATE", "DBIC_GATE", "AMBIG_DBIC", "COLLINEAR", "TIE_REL",
]

P_SIG = 1e-3        # χ² tests (residual before/after, nested signature tests)
Z_GATE = 4.0        # a candidate's parameters must be ≥ 4 standard uncertainties from zero (jointly)
DBIC_GATE = 10.0    # ... and lower the BIC by ≥ 10 ("very strong" on Kass & Raftery's scale)
AMBIG_DBIC = 6.0    # candidates within 6 BIC units (less than "strong" evidence, Kass & Raftery) ...
COLLINEAR = 0.9     # ... whose predictions have cos² > 0.9 cannot be told apart
Z_PAIR = 2.0        # a pair is tried only if one of its members alone reaches z ≥ 2 (saves fits on nulls)
MAX_CV_FOLDS = 12
F_SIG = 1e-3        # F-test of a candidate's χ² improvement against the residual scatter it leaves
#: practical significance: each effect of a candidate must change the readings by at least this share
#: of the noise floor (the combined standard uncertainty u_c of one α, GUM type A and B; RMS over the
#: polygon readings). Every real bench has declared imperfections below u_c that 500 readings resolve
#: statistically (the autocollimator's accuracy curve within its class is a gain of ~5e-4 on α,
#: 0.024″ RMS; the spheres' 0.014 µm form read as motion, ~0.04″): they change no calibrated value
#: beyond its uncertainty and are not findings. The same bound applies to "is there anything to
#: explain?" (the residual's RMS beyond the uncertainties, u·√(χ²/ν − 1)).
SIZE_GATE = 0.5
#: Test-sphere form not measured by the analysis: Jia sec. 4.1 quotes the spheres' max roughness,
#: 0.014 µm. A form of that size is read as motion by eq. 7 (orders 2…10 kept), so the model's ∫δY
#: term carries it; it enters the model's uncertainty (type B) as nuisance columns with a
#: rectangular distribution within ±0.014 µm per Fourier coefficient (u = 0.014/√3 µm).
SPHERE_FORM_UM = 0.014
#: Non-repeating (asynchronous) motion of the axis: its part along X at the time of the polygon
#: readings is unmeasured (the probes run in other revolutions) and reads −δX_async/r. Its size is
#: known from the probes' rep-to-rep scatter (isotropic: the same along X as along Y); it enters the
#: model's uncertainty as one random offset per stop position and polygon rep (nuisance columns),
#: counted only if the scatter exceeds the probes' noise at p < ASYNC_P (F test).
ASYNC_P = 0.01
ASYNC_NOISE_ORDER = 40
ASYNC_BAND = 10
#: Two effects fitted together whose contributions are nearly collinear (cos² > COLLINEAR), of
#: opposite sign and each more than 1/DEGENERATE_RATIO times larger than their sum explain only a
#: small difference with two large terms: a degenerate pair (e.g. +105 % on the eccentricity term and
#: −105 % on the whole model for 0.05″ of ∫δY). Physical pairs may cancel partly — a wrong ∫δY term
#: against the tilt-extrapolated motion, 3:1 — and are not rejected for it.
DEGENERATE_RATIO = 0.1
THETA_BIN_DEG = 0.05  # readings closer than this in θ count as one stop position (harmonic Nyquist, cells)
#: Ties. Two information criteria (BIC, AICc, held-out χ²) closer than TIE_REL × the scale of the
#: problem's χ² (max(χ² of no effect, number of rows)) are equal: the comparison is decided by the
#: stated preference of :func:`_prefer` instead of by rounding. Why 1e-6: the χ² of a least-squares
#: fit on unit-norm columns carries a rounding error of ~κ·ε·χ² (ε = 2.2e-16; κ ≤ ~1e4 for these
#: designs after column scaling, columns worse than 1e-8 in rank are dropped), so ~1e-12 relative,
#: and another BLAS kernel (OpenBLAS Prescott / Haswell / SkylakeX) reorders sums at that level; 1e-6
#: is six orders above it. On the other side 1e-6 × χ² is ~1e-3 BIC units for n ≈ 1000 readings,
#: three orders below the smallest difference read as evidence (2 units: "not worth more than a bare
#: mention", Kass & Raftery 1995). Exactly collinear candidates (a sphere form read as motion and a
#: division error at the same harmonics: the same column space) are the tie this settles.
TIE_REL = 1e-6


# ----------------------------------------------------------------------------------------------
# BLAS threads: the fits are hundreds of small least-squares problems; a multi-threaded OpenBLAS
# on a busy machine spends more time spinning than computing (measured: 25× slower on 2 busy
# cores). Run them on one thread and restore the setting afterwards (no-op if not found).
# ----------------------------------------------------------------------------------------------

def _openblas():
    import ctypes
    import glob

    d = os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs")
    for f in glob.glob(os.path.join(d, "*openblas*")):
        try:
            lib = ctypes.CDLL(f)
            for pre in ("scipy_openblas_", "openblas_"):
                for suf in ("64_", ""):
                    g, s_ = getattr(lib, f"{pre}get_num_threads{suf}", None), getattr(lib, f"{pre}set_num_threads{suf}", None)
                    if g is not None and s_ is not None:
                        s_.argtypes = [ctypes.c_int]
                        return g, s_
        except OSError:
            continue
    return None


_BLAS = None


def _one_blas_thread(fn):
    import functools

    @functools.wraps(fn)
    def wrapper(*a, **k):
        global _BLAS
        if _BLAS is None:
            try:
                _BLAS = _openblas() or False
            except Exception:  # pragma: no cover - platform specific
                _BLAS = False
        if not _BLAS:
            return fn(*a, **k)
        get, set_ = _BLAS
        n = int(get())
        set_(1)
        try:
            return fn(*a, **k)
        finally:
            set_(n)
    return wrapper


# ----------------------------------------------------------------------------------------------
# evidence containers
# ----------------------------------------------------------------------------------------------

@dataclass
class RadialMotion:
    """Sphere probe readings on a θ grid (radial_motion.csv), µm, all reps pooled.

    Each channel is reduced to its Fourier series of orders 2…10 (Jia eq. 7: orders 0 and 1 are
    probe position and sphere centring); δY at the disk by eq. 9, δX likewise from the X probes.
    Channels: ``top_um``, ``bottom_um``, ``dY_um`` and, with X probes, ``top_x_um``,
    ``bottom_x_um``, ``dX_um``. ``at``/``integral_at`` evaluate a channel or its antiderivative in θ
    (radians; µm·rad) anywhere.
    """

    theta_deg: np.ndarray
    top_um: np.ndarray
    bottom_um: np.ndarray
    L1_mm: float
    L2_mm: float
    top_x_um: np.ndarray | None = None
    bottom_x_um: np.ndarray | None = None
    orders: tuple = RADIAL_ORDERS
    rep: np.ndarray | None = None
    _coefs: dict = field(default_factory=dict, init=False, repr=False)
    _u: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self):
        th = np.asarray(self.theta_deg, dtype=float)
        wt, wb = (self.L2_mm - self.L1_mm) / self.L2_mm, self.L1_mm / self.L2_mm
        raw = {"top_um": self.top_um, "bottom_um": self.bottom_um}
        if self.has_x:
            raw.update(top_x_um=self.top_x_um, bottom_x_um=self.bottom_x_um)
        for name, y in raw.items():
            # orders 0 and 1 fitted and dropped (eq. 7), orders 2…10 kept, with their type-A u
            self._coefs[name], self._u[name] = fourier_fit(th, y, self.orders, nuisance_ks=(1,), return_u=True)
        self.combos = {n: {n: 1.0} for n in raw}
        self.combos["dY_um"] = {"top_um": wt, "bottom_um": wb}
        if self.has_x:
            self.combos["dX_um"] = {"top_x_um": wt, "bottom_x_um": wb}
        self.combos["bottom_minus_top_um"] = {"bottom_um": 1.0, "top_um": -1.0}
        for out, combo in self.combos.items():
            if out not in self._coefs:
                self._coefs[out] = {k: (sum(w * self._coefs[c][k][0] for c, w in combo.items()),
                                        sum(w * self._coefs[c][k][1] for c, w in combo.items())) for k in self.orders}

    def perturbations(self, theta_deg, name: str, kind: str = "value", orders=None) -> np.ndarray:
        """(n × m) change of channel ``name`` (value, integral or quadrature) at θ for a 1-u change of
        each raw Fourier coefficient it is made of (the probe data's own uncertainty); ``orders``:
        only those harmonics."""
        sel = (lambda u: u) if orders is None else (lambda u: {k: v for k, v in u.items() if k in orders})
        return np.hstack([perturbation_columns(theta_deg, sel(self._u[c]), w, kind) for c, w in self.combos[name].items()])

    def form_perturbations(self, theta_deg, name: str, u_um: float, kind: str = "integral", orders=None) -> np.ndarray:
        """(n × m) change of channel ``name`` at θ for a change of u_um (µm) in each Fourier coefficient
        (orders 2…10, or ``orders``) of the spheres' readings it is made of: the unmeasured sphere
        form (type B)."""
        if not u_um or u_um <= 0:
            return np.zeros((np.size(theta_deg), 0))
        u = {k: (float(u_um), float(u_um)) for k in (self.orders if orders is None else orders)}
        return np.hstack([perturbation_columns(theta_deg, u, w, kind) for c, w in self.combos[name].items()])

    def async_rms(self, name: str = "dY_um", p: float = ASYNC_P) -> dict:
        """The non-repeating (asynchronous) motion of channel ``name`` (µm RMS over θ), in the band of
        orders 1…``ASYNC_BAND`` (eq. 7's series and the order 1 that a sphere's centring hides only
        when it repeats): the scatter of each rep's Fourier coefficients about their mean over the
        reps (ISO 230-7's asynchronous error, band-limited), minus the probes' own noise in that band
        (the noise from each rep's residual about a series of order ``ASYNC_NOISE_ORDER``: white
        noise, smooth motion). ``sigma_um`` = 0 unless the scatter exceeds the noise at
        significance ``p`` (F test). Needs ``rep`` with ≥ 3 reps; {} otherwise."""
        if self.rep is None:
            return {}
        rep = np.asarray(self.rep).astype(int)
        reps = np.unique(rep)
        R = reps.size
        if R < 3:
            return {}
        th = np.deg2rad(np.asarray(self.theta_deg, dtype=float))
        raw = {"top_um": self.top_um, "bottom_um": self.bottom_um, "top_x_um": self.top_x_um, "bottom_x_um": self.bottom_x_um}
        y = sum(w * np.asarray(raw[c], dtype=float) for c, w in self.combos[name].items())
        KB = ASYNC_BAND
        coefs, d2, nd, v = [], 0.0, 0, []
        for r in reps:
            m = rep == r
            n_r = int(m.sum())
            K = int(min(ASYNC_NOISE_ORDER, (n_r - 1) // 3))
            if K < KB:
                return {}
            X = np.column_stack([np.ones(n_r)] + [f(k * th[m]) for k in range(1, K + 1) for f in (np.sin, np.cos)])
            beta, *_ = np.linalg.lstsq(X, y[m], rcond=None)
            d2 += float(np.sum((y[m] - X @ beta) ** 2))
            nd += n_r - X.shape[1]
            coefs.append(beta[1:2 * KB + 1])
            v.append(2.0 / n_r)   # a sine/cosine coefficient's variance per unit noise variance
        n2 = d2 / max(nd, 1)
        C = np.array(coefs)
        dev = C - C.mean(axis=0)
        s2 = float(np.sum(dev ** 2)) / 2.0 / (R - 1)        # band RMS² of a rep's deviation
        noise_band = KB * n2 * float(np.mean(v))             # the noise's share of it
        f_crit = float(stats.f.isf(p, 2 * KB * (R - 1), max(nd, 1)))
        sig = s2 > f_crit * noise_band
        return {"sigma_um": math.sqrt(max(s2 - noise_band, 0.0)) if sig else 0.0, "scatter_um": math.sqrt(s2),
                "noise_in_band_um": math.sqrt(noise_band), "noise_um": math.sqrt(n2), "band_orders": KB,
                "significant": bool(sig), "n_reps": int(R)}

    def coef_u(self, name: str) -> dict[int, tuple[float, float]]:
        """Type-A standard uncertainties of channel ``name``'s coefficients {k: (u(a_k), u(b_k))}."""
        combo = self.combos[name]
        return {k: (math.sqrt(sum((w * self._u[c][k][0]) ** 2 for c, w in combo.items())),
                    math.sqrt(sum((w * self._u[c][k][1]) ** 2 for c, w in combo.items()))) for k in self.orders}

    def significant_orders(self, name: str, z_min: float = 3.0) -> list[int]:
        """Orders whose amplitude in channel ``name`` is ≥ z_min standard uncertainties (type A):
        the motion the probes resolve, as opposed to their noise."""
        c, u = self.coefs(name), self.coef_u(name)
        out = []
        for k in self.orders:
            a, b = c[k]
            amp = math.hypot(a, b)
            ua = math.sqrt((a * u[k][0]) ** 2 + (b * u[k][1]) ** 2) / amp if amp > 0 else 0.0
            if amp > 0 and (ua == 0 or amp / ua >= z_min):
                out.append(k)
        return out

    @property
    def has_x(self) -> bool:
        return self.top_x_um is not None and self.bottom_x_um is not None

    @property
    def channels(self) -> list[str]:
        return [c for c in self._coefs if c != "bottom_minus_top_um"]

    def coefs(self, name: str) -> dict[int, tuple[float, float]]:
        return self._coefs[name]

    def at(self, theta_deg, name: str, orders=None) -> np.ndarray:
        c = self._coefs[name]
        return fourier_eval(theta_deg, c if orders is None else {k: c[k] for k in orders if k in c})

    def integral_at(self, theta_deg, name: str) -> np.ndarray:
        return fourier_integral(theta_deg, self._coefs[name])


@dataclass
class SelfCal:
    """Multi-head self-calibration curve μ(θ) of head 1 (Hsieh eq. 9), arcsec, on its own θ grid.

    Harmonics that are multiples of ``n_heads`` are blind (eq. 9 removes them); ``model_terms``
    (and ``model_sensitivity`` if the evidence has one) are the model's terms at ``theta_deg``.
    """

    theta_deg: np.ndarray
    value_arcsec: np.ndarray
    u_arcsec: np.ndarray | float
    n_heads: int
    model_terms: dict[str, np.ndarray]
    model_sensitivity: dict[str, np.ndarray] | None = None


@dataclass
class CCDData:
    """CCD d_ref(θ) (Jia eqs. 10–13), µm."""

    theta_deg: np.ndarray
    d_ref_um: np.ndarray
    u_um: np.ndarray | float | None = None


@dataclass
class Evidence:
    """Everything the analysis has about one dataset, per polygon reading.

    Per reading (arrays of length n):

    - ``theta_deg``: encoder reading at the stop (Hsieh eq. 3's (i−1)·360/N + S, as read).
    - ``alpha_arcsec``: the measured α contribution: ε − Σβ − U (the polygon's pitch sums and the
      setup error removed), i.e. the measured encoder error at θ (conventions: reading − true).
    - ``u_arcsec``: standard uncertainty of ``alpha_arcsec`` (scalar or per reading).
    - ``model_terms``: the model's own named terms at θ, arcsec (e.g. ``"eccentricity"``,
      ``"radial_motion_integral"``; the residual is alpha − Σ terms).
    - ``t_s`` (time of the reading), ``rep`` (int), ``direction`` (+1 forward / −1 backward),
      ``start_face`` (1…N), ``shift_deg`` (S), ``step`` (position index i, 1…N; derived from θ and
      S if omitted), ``face`` (face under the autocollimator, derived as (j + i − 2) mod N + 1).
    - ``ac_arcsec``: raw autocollimator reading ε (optional; used by ``ac_scale``).
    - ``closure_group``: readings sharing one setup error U (default: one per (shift, start face,
      repetition): each repetition a new mounting, both directions of a repetition in one).
    - ``model_sensitivity``: optional dict name → per-reading change of the model (arcsec) for a
      one-standard-uncertainty change of one model parameter (e.g. u(e), u(θ0), u(δY) per
      harmonic) — the model's uncertainty, entered as nuisance columns with a unit prior.

    Bench: ``n_faces``, ``optical_radius_mm``, ``L1_mm``, ``L2_mm``, ``grating_period_um``,
    ``encoder_lines``; ``radial``: :class:`RadialMotion` (the measured radial motion; evaluated at
    θ as ``radial_at``), ``selfcal``: :class:`SelfCal`, ``ccd``: :class:`CCDData`.

    ``radial_term``: name of the model term computed from ``radial`` (∫δY/r, eq. 5); when set and
    present, the probe data's own uncertainty (type A, per Fourier coefficient) is added to the
    model's uncertainty as nuisance columns. ``None`` if the term comes from elsewhere.
    ``sphere_form_um``: bound of the test spheres' unmeasured form (µm, default Jia's 0.014 µm); it
    enters the ∫δY term's uncertainty as type B (``SPHERE_FORM_UM``); ``None`` or 0: not included.
    ``u_floor_arcsec``: the combined standard uncertainty of one α (GUM, type A and B, e.g. Hsieh's
    budget u_c): the noise floor of the practical-significance gate (``SIZE_GATE``); default: the
    RMS of ``u_arcsec``.
    """

    theta_deg: np.ndarray
    alpha_arcsec: np.ndarray
    u_arcsec: np.ndarray | float
    model_terms: dict[str, np.ndarray]
    t_s: np.ndarray | None = None
    rep: np.ndarray | None = None
    direction: np.ndarray | None = None
    start_face: np.ndarray | None = None
    shift_deg: np.ndarray | None = None
    step: np.ndarray | None = None
    face: np.ndarray | None = None
    n_faces: int = 23
    optical_radius_mm: float = 22.0
    L1_mm: float = 6.81
    L2_mm: float = 122.96
    grating_period_um: float | None = 20.0
    encoder_lines: int | None = None
    radial: RadialMotion | None = None
    ac_arcsec: np.ndarray | None = None
    selfcal: SelfCal | None = None
    ccd: CCDData | None = None
    model_sensitivity: dict[str, np.ndarray] | None = None
    closure_group: np.ndarray | None = None
    eccentricity_term: str = "eccentricity"
    radial_term: str | None = "radial_motion_integral"
    sphere_form_um: float | None = SPHERE_FORM_UM
    u_floor_arcsec: float | None = None
    #: per reading: the α that ε² added to every autocollimator reading produces after the
    #: shift-angle analysis (the closure puts its face-fixed part into β, its per-run mean into U);
    #: the exact column of a quadratic autocollimator non-linearity (ac_scale). None: ε² itself
    ac_quadratic_response: np.ndarray | None = None

    def __post_init__(self):
        self.theta_deg = np.asarray(self.theta_deg, dtype=float).ravel()
        n = self.theta_deg.size
        self.alpha_arcsec = np.asarray(self.alpha_arcsec, dtype=float).ravel()
        if self.alpha_arcsec.size != n:
            raise ValueError("alpha_arcsec and theta_deg differ in length")
        self.u_arcsec = np.broadcast_to(np.asarray(self.u_arcsec, dtype=float), (n,)).copy()
        if np.any(~np.isfinite(self.u_arcsec)) or np.any(self.u_arcsec <= 0):
            raise ValueError("u_arcsec must be finite and > 0")
        self.model_terms = {k: np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy() for k, v in self.model_terms.items()}
        self.t_s = np.arange(n, dtype=float) if self.t_s is None else np.asarray(self.t_s, dtype=float)
        self.rep = np.zeros(n, int) if self.rep is None else np.asarray(self.rep).astype(int)
        self.direction = np.ones(n, int) if self.direction is None else np.sign(np.asarray(self.direction, dtype=float)).astype(int)
        self.start_face = np.ones(n, int) if self.start_face is None else np.asarray(self.start_face).astype(int)
        self.shift_deg = np.zeros(n) if self.shift_deg is None else np.broadcast_to(np.asarray(self.shift_deg, dtype=float), (n,)).copy()
        N = int(self.n_faces)
        if self.step is None:
            self.step = (np.round((self.theta_deg - self.shift_deg) / (360.0 / N)).astype(int) % N) + 1
        self.step = np.asarray(self.step).astype(int)
        if self.face is None:
            self.face = (self.start_face + self.step - 2) % N + 1
        self.face = np.asarray(self.face).astype(int)
        if self.ac_arcsec is not None:
            self.ac_arcsec = np.asarray(self.ac_arcsec, dtype=float)
        if self.closure_group is None:
            # one mounting per (shift, start face, repetition): a repetition is a new run of the
            # closure (Hsieh eq. 2 holds per run, sec. 3.3 (1): "the average of six measurement
            # results", each one mounted anew); its two directions are swept in one mounting
            keys = np.column_stack([np.round(self.shift_deg, 6), self.start_face, self.rep])
            self.closure_group = np.unique(keys, axis=0, return_inverse=True)[1].ravel()
        else:
            self.closure_group = np.unique(np.asarray(self.closure_group), return_inverse=True)[1].ravel()
        if self.model_sensitivity:
            self.model_sensitivity = {k: np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()
                                      for k, v in self.model_sensitivity.items()}
        # stop positions to THETA_BIN_DEG (stop jitter of a few arcsec is not a new position)
        self.theta_bin = np.round((self.theta_deg % 360.0) / THETA_BIN_DEG).astype(int) % int(round(360 / THETA_BIN_DEG))
        n_theta = np.unique(self.theta_bin).size
        self.kmax = int(min(20, max(1, (n_theta - 1) // 2)))

    @property
    def n(self) -> int:
        return self.theta_deg.size

    @property
    def model_arcsec(self) -> np.ndarray:
        return sum(self.model_terms.values()) + np.zeros(self.n) if self.model_terms else np.zeros(self.n)

    @property
    def residual_arcsec(self) -> np.ndarray:
        return self.alpha_arcsec - self.model_arcsec

    @property
    def radial_at(self) -> dict[str, np.ndarray]:
        """The measured radial motion channels (µm) at the readings' θ."""
        if self.radial is None:
            return {}
        return {c: self.radial.at(self.theta_deg, c) for c in self.radial.channels}

    def add_eccentricity_uncertainty(self, e_um: float, theta0_deg: float, u_e_um: float, u_theta0_deg: float) -> None:
        """Add u(e) and u(θ0) of the CCD eccentricity (Jia sec. 5: 0.24 µm, 1.13°) to the model's
        uncertainty: the sensitivities of e/r·sin(θ−θ0) (eq. 3) times u, at the readings and on the
        self-calibration grid."""
        def sens(th_deg):
            t = np.deg2rad(np.asarray(th_deg, dtype=float) - theta0_deg)
            k = ARCSEC_PER_RAD / (self.optical_radius_mm * 1000.0)
            return {"u_e": k * u_e_um * np.sin(t), "u_theta0": -k * e_um * np.cos(t) * math.radians(u_theta0_deg)}
        self.model_sensitivity = {**(self.model_sensitivity or {}), **sens(self.theta_deg)}
        if self.selfcal is not None:
            self.selfcal.model_sensitivity = {**(self.selfcal.model_sensitivity or {}), **sens(self.selfcal.theta_deg)}

    def selfcal_view(self) -> "_View | None":
        if self.selfcal is None:
            return None
        sc = self.selfcal
        return _View(theta_deg=np.asarray(sc.theta_deg, dtype=float), alpha_arcsec=np.asarray(sc.value_arcsec, dtype=float),
                     model_terms={k: np.asarray(v, dtype=float) for k, v in sc.model_terms.items()}, parent=self)


@dataclass
class _View:
    """The self-calibration grid seen as evidence (θ-related attributes only)."""

    theta_deg: np.ndarray
    alpha_arcsec: np.ndarray
    model_terms: dict
    parent: Evidence

    def __getattr__(self, name):
        if name in ("optical_radius_mm", "L1_mm", "L2_mm", "grating_period_um", "encoder_lines", "radial", "n_faces",
                    "eccentricity_term", "kmax", "sphere_form_um"):
            return getattr(self.parent, name)
        if name == "ac_arcsec":
            return None
        raise AttributeError(name)


def evidence_from_polygon(columns: dict, beta_arcsec, setup_error_arcsec, model, *, n_faces: int,
                          u_arcsec=0.07, radial: RadialMotion | None = None, selfcal_theta_deg=None,
                          selfcal_value_arcsec=None, selfcal_u_arcsec=None, n_heads: int | None = None,
                          **bench) -> Evidence:
    """Evidence from the polygon table (dataset ``polygon.csv`` columns) and the shift-angle results.

    ``columns``: ``shift_deg``, ``start_face``, ``step``, ``theta_deg``, ``ac_arcsec``, ``t_s`` and
    optionally ``rep``, ``direction`` (+1/−1 or "forward"/"backward"). ``beta_arcsec``: the N pitch
    deviations used; ``setup_error_arcsec``: {(shift_deg, start_face): U} (Hsieh eq. 7) or a callable
    (shift, face) → U. α per reading = ε − Σ_{k=j}^{j+i−1} β_k − U_j (eq. 3). ``model``: anything with
    ``predict_terms(theta_deg) -> {name: arcsec}`` (the project's ErrorModel) or a callable doing the
    same. ``bench``: further Evidence keywords (optical_radius_mm, L1_mm, L2_mm, encoder_lines, ...).
    """
    N = int(n_faces)
    c = {k: np.asarray(v) for k, v in columns.items()}
    S = c["shift_deg"].astype(float)
    j = c["start_face"].astype(int)
    i = c["step"].astype(int)
    th = c["theta_deg"].astype(float)
    beta = np.asarray(beta_arcsec, dtype=float)
    cum = np.concatenate([[0.0], np.cumsum(np.concatenate([beta, beta]))])
    sumbeta = cum[j - 1 + i] - cum[j - 1]  # Σ_{k=j}^{j+i−1} β_k, indices mod N via the doubled sum
    U_of = setup_error_arcsec if callable(setup_error_arcsec) else (
        lambda s, f: setup_error_arcsec[(float(s), int(f))])
    U = np.array([U_of(float(s), int(f)) for s, f in zip(S, j)], dtype=float)
    alpha = c["ac_arcsec"].astype(float) - sumbeta - U
    terms_fn = model.predict_terms if hasattr(model, "predict_terms") else model
    direction = None
    if "direction" in c:
        d = c["direction"]
        direction = np.where(np.char.startswith(d.astype(str), "b"), -1, 1) if d.dtype.kind in "US" else d.astype(float)
    sc = None
    if selfcal_theta_deg is not None:
        tsc = np.asarray(selfcal_theta_deg, dtype=float)
        sc = SelfCal(tsc, np.asarray(selfcal_value_arcsec, dtype=float),
                     0.01 if selfcal_u_arcsec is None else selfcal_u_arcsec, int(n_heads or 1), dict(terms_fn(tsc)))
    return Evidence(theta_deg=th, alpha_arcsec=alpha, u_arcsec=u_arcsec, model_terms=dict(terms_fn(th)),
                    t_s=c.get("t_s"), rep=c.get("rep"), direction=direction, start_face=j, shift_deg=S, step=i,
                    n_faces=N, radial=radial, ac_arcsec=c["ac_arcsec"].astype(float), selfcal=sc, **bench)


# ----------------------------------------------------------------------------------------------
# the weighted least-squares problem (closure groups, self-calibration rows, model nuisance)
# ----------------------------------------------------------------------------------------------

def _z_from_chi2(d: float, k: int) -> float:
    """Two-sided normal z equivalent of a χ²_k statistic d (Δχ² of k parameters)."""
    d = max(float(d), 0.0)
    k = max(int(k), 1)
    if k == 1:
        return math.sqrt(d)
    lp = float(stats.chi2.logsf(d, k))
    if lp > -700:
        return float(stats.norm.isf(math.exp(lp) / 2.0))
    return math.sqrt(-2.0 * lp)


def _center(x: np.ndarray, groups: np.ndarray, w2: np.ndarray) -> np.ndarray:
    """Remove the w²-weighted mean of each group from each column of x."""
    x2 = x if x.ndim == 2 else x[:, None]
    ng = int(groups.max()) + 1
    sw = np.bincount(groups, weights=w2, minlength=ng)
    out = np.empty_like(x2, dtype=float)
    for c in range(x2.shape[1]):
        m = np.bincount(groups, weights=w2 * x2[:, c], minlength=ng) / np.where(sw > 0, sw, 1.0)
        out[:, c] = x2[:, c] - m[groups]
    return out if x.ndim == 2 else out[:, 0]


class _Problem:
    """Rows: the polygon readings (closure-centred) and, optionally, the self-calibration curve
    (centred, harmonics that are multiples of the head count projected out)."""

    def __init__(self, ev: Evidence, use_selfcal: bool = True):
        self.ev = ev
        n = ev.n
        self.view = ev.selfcal_view() if use_selfcal else None
        w_a = 1.0 / ev.u_arcsec
        self.n_alpha = n
        y_a = _center(ev.residual_arcsec, ev.closure_group, w_a ** 2)
        self.n_groups = int(ev.closure_group.max()) + 1
        sens_keys = sorted(ev.model_sensitivity) if ev.model_sensitivity else []
        S_a = (np.column_stack([ev.model_sensitivity[k] for k in sens_keys]) if sens_keys else np.zeros((n, 0)))
        S_a = np.hstack([S_a, self._radial_nuisance(ev)])
        S_a = _center(S_a, ev.closure_group, w_a ** 2) if S_a.shape[1] else S_a
        if self.view is not None:
            sc = ev.selfcal
            m = self.view.theta_deg.size
            w_s = np.broadcast_to(1.0 / np.asarray(sc.u_arcsec, dtype=float), (m,)).astype(float)
            th = np.deg2rad(self.view.theta_deg)
            blind = [np.ones(m)]
            k = int(sc.n_heads)
            while k > 0 and k <= (m - 1) // 2 and k <= 60:
                blind += [np.sin(k * th), np.cos(k * th)]
                k += int(sc.n_heads)
            self._Q = np.linalg.qr(np.column_stack(blind))[0]
            y_s = self._filt(self.view.alpha_arcsec - sum(self.view.model_terms.values()))
            if sens_keys:
                if not sc.model_sensitivity or set(sc.model_sensitivity) != set(sens_keys):
                    raise ValueError("selfcal.model_sensitivity must have the same keys as evidence.model_sensitivity")
                S_s = np.column_stack([sc.model_sensitivity[k] for k in sens_keys])
            else:
                S_s = np.zeros((m, 0))
            S_s = self._filt(np.hstack([S_s, self._radial_nuisance(self.view)]))
            self.y = np.concatenate([y_a, y_s])
            self.w = np.concatenate([w_a, w_s])
            self.S = np.vstack([S_a, S_s])
            self.n_groups += 1
        else:
            self.y, self.w, self.S = y_a, w_a, S_a
        self.n_rows = self.y.size
        self.alpha_rows = np.zeros(self.n_rows, bool)
        self.alpha_rows[:n] = True
        self.folds = self._folds()
        self.null = self.fit(np.zeros((self.n_rows, 0)))

    def _radial_nuisance(self, e) -> np.ndarray:
        ev = self.ev
        if ev.radial is None or not ev.radial_term or ev.radial_term not in ev.model_terms:
            return np.zeros((len(e.theta_deg), 0))
        k = ARCSEC_PER_RAD / (ev.optical_radius_mm * 1000.0)
        cols = [ev.radial.perturbations(e.theta_deg, "dY_um", "integral") * k]
        if ev.sphere_form_um:
            cols.append(ev.radial.form_perturbations(e.theta_deg, "dY_um", ev.sphere_form_um / math.sqrt(3.0)) * k)
        if e is ev:
            cols.append(self._async_nuisance(ev) * k)
        else:
            cols.append(np.zeros((len(e.theta_deg), self._async_nuisance(ev).shape[1])))
        return np.hstack(cols)

    def _async_nuisance(self, ev) -> np.ndarray:
        """−δX_async/r at the polygon readings (before the factor ARC/r): the non-repeating motion
        of the polygon's revolution is unmeasured along X; its size along Y (``RadialMotion.async_rms``,
        isotropic) sets one random offset per stop position and polygon rep (the stops sample it
        at their angles; its spectrum reaches far beyond the polygon's harmonics and aliases)."""
        if getattr(self, "_async_cache", None) is not None:
            return self._async_cache
        a = ev.radial.async_rms("dY_um") if ev.radial is not None else {}
        self.async_info = a
        sg = float(a.get("sigma_um", 0.0)) if a else 0.0
        cols = []
        if sg > 0:
            for r in np.unique(ev.rep):
                m = ev.rep == r
                for b in np.unique(ev.theta_bin[m]):
                    cols.append(sg * (m & (ev.theta_bin == b)).astype(float))
        self._async_cache = np.column_stack(cols) if cols else np.zeros((ev.n, 0))
        return self._async_cache

    def regressor_nuisance(self, modules, params_by_member, ctx) -> np.ndarray:
        """Nuisance columns for the uncertainty of measured regressors (radial motion), scaled by the
        fitted parameters: errors in variables, linearised."""
        cols = []
        for mod, P in zip(modules, params_by_member):
            fn = getattr(mod, "regressor_perturbations", None)
            if fn is None:
                continue
            R_a = np.asarray(fn(self.ev, P, ctx), dtype=float)
            if R_a.shape[1] == 0:
                continue
            R_a = _center(R_a, self.ev.closure_group, self.w[: self.ev.n] ** 2)
            if self.view is not None:
                R_s = self._filt(np.asarray(fn(self.view, P, ctx), dtype=float)) if mod.SEEN_BY_SELFCAL else \
                    np.zeros((self.n_rows - self.ev.n, R_a.shape[1]))
                R_a = np.vstack([R_a, R_s])
            cols.append(R_a)
        return np.hstack(cols) if cols else np.zeros((self.n_rows, 0))

    def _filt(self, x):
        x2 = x if x.ndim == 2 else x[:, None]
        out = x2 - self._Q @ (self._Q.T @ x2)
        return out if x.ndim == 2 else out[:, 0]

    def _folds(self):
        """Cross-validation folds over the polygon rows (self-calibration rows always train).

        Every training set must still identify what the candidates fit, whatever the design:
        - leave-one-repetition-out when there are ≥ 3 repetitions: a repetition is the same design
          again (all shifts, start faces and directions stay in every training set);
        - else leave-one-start-face-out with ≥ 3 start faces (the other faces keep the face pattern
          determined; a shift set with one face per shift loses one θ set per fold);
        - else leave-one-shift-out with ≥ 3 shifts (shift sets: SelfA-like 0…14° in 1° steps);
        - else interleaved stop positions: every MAX_CV_FOLDS-th position of θ held out (one rep,
          one start face, one shift, one or both directions; or keys whose largest group holds more
          than a third of the readings): the held-out stops are between trained ones, so the
          harmonics a candidate fits are still determined.
        Groups are merged cyclically into ≤ MAX_CV_FOLDS folds. None with fewer than 3 groups."""
        ev = self.ev
        f = np.full(self.n_rows, -1)
        for key in (ev.rep, ev.start_face, ev.shift_deg):
            u, inv = np.unique(np.round(np.asarray(key, dtype=float), 6), return_inverse=True)
            # balanced only: no group may hold more than a third of the readings (all start faces
            # at S = 0 but one face at the other shifts put every shifted reading into one fold)
            if u.size >= 3 and np.bincount(inv).max() <= ev.n / 3.0 + 1e-9:
                f[: ev.n] = inv % MAX_CV_FOLDS
                return f
        u, inv = np.unique(ev.theta_bin, return_inverse=True)
        k = min(MAX_CV_FOLDS, u.size // 4)   # ≥ 4 positions per fold's complement share
        if k >= 3:
            f[: ev.n] = inv % k
            return f
        return None

    # -- columns -----------------------------------------------------------------------------
    def columns(self, module, ctx) -> tuple[np.ndarray, list[str]]:
        ev = self.ev
        X_a, names = module.design(ev, ctx)
        X_a = np.asarray(X_a, dtype=float).reshape(ev.n, -1)
        X_a = _center(X_a, ev.closure_group, self.w[: ev.n] ** 2) if X_a.shape[1] else X_a
        if self.view is None:
            return X_a, list(names)
        m = self.view.theta_deg.size
        if module.SEEN_BY_SELFCAL and X_a.shape[1]:
            X_s, names_s = module.design(self.view, ctx)
            X_s = np.asarray(X_s, dtype=float).reshape(m, -1)
            if list(names_s) != list(names):
                raise RuntimeError(f"{module.NAME}: self-calibration design has other parameters")
            X_s = self._filt(X_s)
        else:
            X_s = np.zeros((m, X_a.shape[1]))
        return np.vstack([X_a, X_s]), list(names)

    # -- fits --------------------------------------------------------------------------------
    def fit(self, X: np.ndarray, train: np.ndarray | None = None, extra: np.ndarray | None = None) -> dict:
        w = self.w
        rows = np.ones(self.n_rows, bool) if train is None else train
        S = self.S if extra is None or extra.shape[1] == 0 else np.hstack([self.S, extra])
        p, q = X.shape[1], S.shape[1]
        A = np.hstack([X, S])[rows] * w[rows, None]
        b = self.y[rows] * w[rows]
        if q:
            prior = np.hstack([np.zeros((q, p)), np.eye(q)])
            A = np.vstack([A, prior])
            b = np.concatenate([b, np.zeros(q)])
        if A.shape[1]:
            scale = np.linalg.norm(A, axis=0)
            scale[scale == 0] = 1.0
            As = A / scale
            sol, _, rank, sv = np.linalg.lstsq(As, b, rcond=None)
            beta_all = sol / scale
            covs = np.linalg.pinv(As.T @ As, rcond=1e-10, hermitian=True)
            cov_all = covs / np.outer(scale, scale)
            rank_x = int(np.linalg.matrix_rank(X[rows] * w[rows, None] / np.where(scale[:p] > 0, scale[:p], 1), tol=1e-8)) if p else 0
            chi2 = float(np.sum((b - A @ beta_all) ** 2))
        else:
            beta_all, cov_all, rank_x = np.zeros(0), np.zeros((0, 0)), 0
            chi2 = float(np.sum(b ** 2))
        n_fit = int(rows.sum())
        dof = max(n_fit - self.n_groups - rank_x, 1)
        return {"beta": beta_all[:p], "cov": cov_all[:p, :p], "nuis": beta_all[p:], "chi2": chi2, "dof": dof,
                "k": rank_x, "n": n_fit, "S": S}

    def predict_rows(self, X, fit, rows=None, nuisance=True):
        rows = np.ones(self.n_rows, bool) if rows is None else rows
        out = X[rows] @ fit["beta"] if X.shape[1] else np.zeros(int(rows.sum()))
        if nuisance and fit["S"].shape[1]:
            out = out + fit["S"][rows] @ fit["nuis"]
        return out

    def cv(self, X, extra=None) -> float | None:
        """Held-out weighted χ² summed over leave-one-group-out folds (None without folds)."""
        if self.folds is None:
            return None
        tot = 0.0
        for f in np.unique(self.folds[self.folds >= 0]):
            test = self.folds == f
            fit = self.fit(X, train=~test, extra=extra)
            r = (self.y[test] - self.predict_rows(X, fit, test)) * self.w[test]
            tot += float(np.sum(r ** 2))
        return tot

    def ic(self, fit) -> tuple[float, float]:
        n, k, chi2 = fit["n"], fit["k"], fit["chi2"]
        bic = chi2 + k * math.log(n)
        aicc = chi2 + 2 * k + (2 * k * (k + 1) / (n - k - 1) if n - k - 1 > 0 else math.inf)
        return bic, aicc


# ----------------------------------------------------------------------------------------------
# 1. anything to explain?
# ----------------------------------------------------------------------------------------------

def noise_floor(ev: Evidence) -> float:
    """The per-reading noise floor (arcsec): ``u_floor_arcsec`` if given (GUM u_c of one α, type A
    and B), else the RMS of the readings' u."""
    u = float(np.sqrt(np.mean(np.square(ev.u_arcsec))))
    return max(u, float(ev.u_floor_arcsec)) if ev.u_floor_arcsec else u


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else 0.0


@_one_blas_thread
def residual_test(ev: Evidence) -> dict:
    """χ² of the (closure-centred) residual against the combined uncertainty, and its summary."""
    pb = _Problem(ev, use_selfcal=False)
    r = pb.y[: ev.n]
    chi2, dof = pb.null["chi2"], pb.null["dof"]
    return {"rms_arcsec": _rms(r), "pv_arcsec": float(np.ptp(r)) if r.size else 0.0,
            "fraction_of_error": _rms(r) / max(_rms(_center(ev.alpha_arcsec, ev.closure_group, 1 / ev.u_arcsec ** 2)), 1e-300),
            "chi2": chi2, "dof": dof, "p_value": float(stats.chi2.sf(chi2, dof))}


@_one_blas_thread
def harmonic_test(ev: Evidence, pb: _Problem | None = None) -> list[dict]:
    """Each harmonic 1…kmax of θ fitted jointly; amplitude, its u and a χ²_2 test (Bonferroni over
    the harmonics tested; u scaled by √(χ²/dof) when that exceeds 1)."""
    pb = pb or _Problem(ev, use_selfcal=False)
    ks = list(range(1, ev.kmax + 1))
    th = np.deg2rad(ev.theta_deg)
    X = np.column_stack([f(k * th) for k in ks for f in (np.sin, np.cos)])
    X = _center(X, ev.closure_group, pb.w ** 2)
    fit = pb.fit(X)
    scale = max(1.0, fit["chi2"] / fit["dof"])
    out = []
    for i, k in enumerate(ks):
        a, b = fit["beta"][2 * i], fit["beta"][2 * i + 1]
        C = fit["cov"][2 * i:2 * i + 2, 2 * i:2 * i + 2] * scale
        amp = math.hypot(a, b)
        try:
            q = float(np.array([a, b]) @ np.linalg.solve(C, np.array([a, b])))
        except np.linalg.LinAlgError:
            q = 0.0
        g = np.array([a, b]) / amp if amp > 0 else np.array([1.0, 0.0])
        u_amp = float(math.sqrt(max(g @ C @ g, 0.0)))
        p = float(stats.chi2.sf(q, 2))
        out.append({"k": k, "amplitude_arcsec": amp, "u_arcsec": u_amp, "phase_deg": math.degrees(math.atan2(a, b)),
                    "a_arcsec": float(a), "b_arcsec": float(b), "chi2": q, "z": _z_from_chi2(q, 2), "p_value": p,
                    "significant": bool(p * len(ks) < P_SIG)})
    return out


# ----------------------------------------------------------------------------------------------
# 2. signature
# ----------------------------------------------------------------------------------------------

def _one_column(pb: _Problem, col: np.ndarray, name: str) -> dict:
    ev = pb.ev
    X = _center(np.asarray(col, dtype=float)[:, None], ev.closure_group, pb.w ** 2)
    if not np.any(np.abs(X) > 1e-12 * (np.max(np.abs(col)) + 1e-300)):
        return {"available": False, "reason": f"{name}: no variation inside the closure groups"}
    fit = pb.fit(X)
    scale = max(1.0, fit["chi2"] / fit["dof"])
    g = float(fit["beta"][0])
    u = float(math.sqrt(fit["cov"][0, 0] * scale))
    xw, yw = X[:, 0] * pb.w, pb.y * pb.w
    corr = float(xw @ yw / math.sqrt((xw @ xw) * (yw @ yw))) if (xw @ xw) > 0 and (yw @ yw) > 0 else 0.0
    return {"available": True, "gain": g, "u": u, "z": abs(g) / u if u > 0 else math.inf, "corr": corr,
            "significant": bool(u > 0 and abs(g) / u > Z_GATE)}


def _nested(pb: _Problem, X0: np.ndarray, X1: np.ndarray) -> dict:
    f0, f1 = pb.fit(X0), pb.fit(np.hstack([X0, X1]))
    d, k = f0["chi2"] - f1["chi2"], f1["k"] - f0["k"]
    if k <= 0:
        return {"available": False}
    p = float(stats.chi2.sf(d, k))
    return {"available": True, "delta_chi2": float(d), "dof": int(k), "p_value": p, "significant": bool(p < P_SIG)}


def _free_of_theta(pb: _Problem, col: np.ndarray) -> np.ndarray:
    """The closure-centred column with every function of the stop position θ removed (weighted)."""
    ev = pb.ev
    w2 = pb.w[: ev.n] ** 2
    x = _center(col, ev.closure_group, w2)
    D = _center(_dummies(ev.theta_bin), ev.closure_group, w2)
    sw = np.sqrt(w2)
    beta, *_ = np.linalg.lstsq(D * sw[:, None], x * sw, rcond=None)
    out = x - D @ beta
    return np.where(np.abs(out) > 1e-9 * (np.max(np.abs(x)) + 1e-300), out, 0.0)


def _dummies(keys: np.ndarray) -> np.ndarray:
    inv = np.unique(keys, return_inverse=True)[1]
    X = np.zeros((keys.size, inv.max() + 1))
    X[np.arange(keys.size), inv] = 1.0
    return X


#: fewest closure groups (sweeps) whose own harmonic fits make the between-sweep test of
#: :func:`_time_pattern` (a regression of each coefficient on time with G − 2 dof; 5 → 3 dof)
MIN_TIME_GROUPS = 5


def _time_pattern(pb: _Problem, ks: list[int]) -> dict:
    """Is the θ pattern stationary? A significant change of amplitude or phase of harmonics ``ks``
    during the session (thermal growth, wear) is not an effect fixed to the disk, the motion or the
    reference.

    The unit of the test is the closure group (one sweep of the polygon, one mounting) whenever
    there are ≥ ``MIN_TIME_GROUPS`` of them, each with enough readings to fit ``ks`` itself: the
    asynchronous (non-repeating) motion of a ball-bearing shaft is not white from reading to
    reading. Its components at non-integer orders (outer-race lobes at q·Z·ρ cycles/rev, 4.81 for
    jia2019's bearings; inner-race lobes at q·Z·(1 − ρ) ± 1; the balls at ρ) look like harmonics
    of θ within one sweep, with a phase that jumps from sweep to sweep (docs/physics.md, "Why the
    default run's θ pattern looked non-stationary"). Tested reading by reading, a beat of that
    kind projects onto "harmonic × time" far beyond the per-reading noise (z ≈ 10 on the default
    jia2019 run, where the true α itself has it). So each sweep's own harmonic coefficients are
    regressed on its mean reading time and each slope is compared with the scatter of that
    coefficient between sweeps (t-test, G − 2 dof): the asynchronous motion enters as the noise
    it is, with the size the data show, and a real drift of the pattern (smooth in time,
    coherent over sweeps) still stands out. Designs with fewer sweeps (one start face, one rep)
    keep the reading-by-reading nested test (harmonics × (t − t̄)/T)."""
    ev = pb.ev
    ks = [int(k) for k in ks if 1 <= int(k) <= ev.kmax]
    if not ks:
        return {"available": False, "reason": "no harmonic to follow in time"}
    t = np.asarray(ev.t_s, dtype=float)
    T = float(np.ptp(t))
    if not np.all(np.isfinite(t)) or T <= 0:
        return {"available": False, "reason": "no reading times"}
    between = _time_pattern_between_groups(pb, ks, t, T)
    if between is not None:
        return between
    th = np.deg2rad(ev.theta_deg)
    tt = (t - t.mean()) / T
    H = np.column_stack([f(k * th) for k in ks for f in (np.sin, np.cos)])
    X0 = _center(H, ev.closure_group, pb.w ** 2)
    X1 = _center(H * tt[:, None], ev.closure_group, pb.w ** 2)
    f0, f1 = pb.fit(X0), pb.fit(np.hstack([X0, X1]))
    d, k = f0["chi2"] - f1["chi2"], f1["k"] - f0["k"]
    if k <= 0:
        return {"available": False, "reason": "the harmonics do not change inside the sampling"}
    scale = max(1.0, f1["chi2"] / f1["dof"])
    z = _z_from_chi2(d / scale, k)
    beta = f1["beta"]
    amp0 = [float(math.hypot(beta[2 * i], beta[2 * i + 1])) for i in range(len(ks))]
    slope = [float(math.hypot(beta[2 * len(ks) + 2 * i], beta[2 * len(ks) + 2 * i + 1])) for i in range(len(ks))]
    return {"available": True, "test": "harmonics × (t − t̄)/T, nested over the harmonics", "harmonics": ks,
            "amplitude_arcsec": amp0, "change_over_session_arcsec": slope, "delta_chi2": float(d), "dof": int(k),
            "z": z, "p_value": float(stats.chi2.sf(d / scale, k)), "significant": bool(z >= Z_GATE)}


def _time_pattern_between_groups(pb: _Problem, ks: list[int], t: np.ndarray, T: float) -> dict | None:
    """The between-sweep form of :func:`_time_pattern`, or None when the design has fewer than
    ``MIN_TIME_GROUPS`` closure groups able to fit ``ks`` (2·len(ks) + 1 parameters, ≥ 1 dof)."""
    ev = pb.ev
    n = ev.n
    y, w = pb.y[:n], pb.w[:n]
    th = np.deg2rad(ev.theta_deg)
    H = np.column_stack([f(k * th) for k in ks for f in (np.sin, np.cos)])
    coef, times = [], []
    for g in np.unique(ev.closure_group):
        m = ev.closure_group == g
        if int(m.sum()) < H.shape[1] + 2:
            continue
        A = np.column_stack([np.ones(int(m.sum())), H[m]]) * w[m, None]
        if np.linalg.matrix_rank(A) < A.shape[1]:
            continue
        beta, *_ = np.linalg.lstsq(A, y[m] * w[m], rcond=None)
        coef.append(beta[1:])
        times.append(float(np.average(t[m], weights=w[m] ** 2)))
    G = len(coef)
    if G < MIN_TIME_GROUPS:
        return None
    o = np.argsort(times, kind="stable")
    C = np.asarray(coef)[o]
    tg = (np.asarray(times)[o] - float(np.mean(times))) / T
    stt = float(tg @ tg)
    if stt <= 0:
        return None
    slope = (tg @ (C - C.mean(axis=0))) / stt
    res = C - C.mean(axis=0) - np.outer(tg, slope)
    nu = G - 2
    # serial correlation of the sweeps' deviations: the cage creeps (its slip accumulates over
    # the moves between sweeps), so consecutive sweeps see nearly the same ball configuration and
    # the asynchronous pattern wanders like a random walk. Against a random walk a trend is only
    # what the increments show on average (first differences, "random walk with drift"): weaker,
    # but it does not take the walk for a drift. Lag-1 autocorrelation pooled over the
    # coefficients, ~N(0, 1/(G·2K)) for independent sweeps; flagged at P_SIG (one-sided).
    den = float(np.sum(res ** 2))
    r1 = float(np.sum(res[1:] * res[:-1]) / den) if den > 0 else 0.0
    serial = bool(r1 * math.sqrt(res.size) > stats.norm.isf(P_SIG))
    if serial:
        D, dt = np.diff(C, axis=0), np.diff(tg)
        sdd = float(dt @ dt)
        if sdd <= 0:
            return None
        slope = (dt @ D) / sdd
        nu = G - 2
        s2 = np.sum((D - np.outer(dt, slope)) ** 2, axis=0) / nu
        u = np.sqrt(np.where(s2 > 0, s2, np.inf) / sdd)
        s2 = s2 / 2.0          # an increment's variance is twice a sweep's (reported below)
    else:
        s2 = np.sum(res ** 2, axis=0) / nu
        u = np.sqrt(np.where(s2 > 0, s2, np.inf) / stt)
    tstat = np.abs(slope) / u
    # each two-sided t-test as its χ²₁ equivalent; the coefficients of distinct harmonics are
    # orthogonal on the sweep's grid, so their sum is χ² with 2·len(ks) dof under stationarity
    p = np.clip(2.0 * stats.t.sf(tstat, nu), 1e-300, 1.0)
    q = float(np.sum(stats.chi2.isf(p, 1)))
    k2 = int(C.shape[1])
    z = _z_from_chi2(q, k2)
    mean = C.mean(axis=0)
    amp0 = [float(math.hypot(mean[2 * i], mean[2 * i + 1])) for i in range(len(ks))]
    change = [float(math.hypot(slope[2 * i], slope[2 * i + 1])) for i in range(len(ks))]
    scatter = [float(math.sqrt((s2[2 * i] + s2[2 * i + 1]) / 2.0)) for i in range(len(ks))]
    return {"available": True,
            "test": "each sweep's harmonics regressed on its time, against their scatter between sweeps",
            "harmonics": ks, "n_sweeps": G, "dof_per_coefficient": nu,
            "serial_correlation": r1, "random_walk": serial,
            "amplitude_arcsec": amp0, "change_over_session_arcsec": change,
            "between_sweep_sd_arcsec": scatter, "chi2_equivalent": q, "dof": k2,
            "z": z, "p_value": float(stats.chi2.sf(q, k2)), "significant": bool(z >= Z_GATE)}


@_one_blas_thread
def signature(ev: Evidence, harmonics: list[dict] | None = None, time_ks: list[int] | None = None) -> dict:
    """The residual's signature (JSON-ready): see the module docstring, step 2. ``time_ks``: the
    harmonics whose stationarity is tested (default: this residual's significant harmonics)."""
    pb = _Problem(ev, use_selfcal=False)
    harmonics = harmonics if harmonics is not None else harmonic_test(ev, pb)
    sig: dict[str, Any] = {"harmonics": harmonics,
                           "significant_harmonics": [h["k"] for h in harmonics if h["significant"]]}
    sig["time_pattern"] = _time_pattern(pb, sig["significant_harmonics"] if time_ks is None else time_ks)
    # drift: only the part of the reading time that is not a function of θ can show it (a forward
    # sweep's time is a θ sawtooth that any encoder error of that shape fits as well)
    d = _one_column(pb, _free_of_theta(pb, np.asarray(ev.t_s, dtype=float)), "t_s (beyond any θ pattern)")
    sig["drift"] = {"slope_arcsec_per_s": d.get("gain"), "u": d.get("u"), "z": d.get("z"),
                    "significant": d.get("significant", False), "available": d["available"],
                    "test": "reading time beyond any function of θ"}
    if not d["available"]:
        sig["drift"]["reason"] = "the reading order follows θ in every run: a drift cannot be told from a θ pattern"
    # repetition: synchronous (same at the same θ in every rep) or not
    if np.unique(ev.rep).size >= 2:
        cell = ev.theta_bin * 10 + ev.direction
        inv = np.unique(cell, return_inverse=True)[1]
        w2 = pb.w ** 2
        m = np.bincount(inv, weights=w2 * pb.y) / np.bincount(inv, weights=w2)
        dev = pb.y - m[inv]
        chi2 = float(np.sum(w2 * dev ** 2))
        dof = max(ev.n - inv.max() - 1, 1)
        p = float(stats.chi2.sf(chi2, dof))
        sig["repetition"] = {"available": True, "n_reps": int(np.unique(ev.rep).size), "synchronous_rms_arcsec": _rms(m[inv]),
                             "asynchronous_rms_arcsec": _rms(dev), "chi2_async": chi2, "dof": int(dof), "p_value": p,
                             "synchronous": bool(p >= P_SIG)}
    else:
        sig["repetition"] = {"available": False, "reason": "one repetition"}
    # polygon-related: a pattern fixed to the face (moves with the start face)?
    base = _center(_dummies(ev.theta_bin * 10 + ev.direction), ev.closure_group, pb.w ** 2)
    if np.unique(ev.start_face).size >= 2:
        fx = _center(_dummies(ev.face), ev.closure_group, pb.w ** 2)
        sig["start_face"] = {"test": "face pattern beyond the θ pattern", **_nested(pb, base, fx)}
    else:
        sig["start_face"] = {"available": False, "reason": "one start face: face ≡ θ"}
    # shift: does the θ pattern depend on the shift angle (beyond a function of θ)?
    shifts = np.unique(np.round(ev.shift_deg, 6))
    if shifts.size >= 2:
        kk = range(1, max(1, (int(ev.n_faces) - 1) // 2) + 1)
        th = np.deg2rad(ev.theta_deg)
        H = np.column_stack([f(k * th) for k in kk for f in (np.sin, np.cos)])
        Hs = np.column_stack([H * (np.round(ev.shift_deg, 6) == s)[:, None] for s in shifts[1:]])
        sig["shift"] = {"test": "harmonics 1…(N−1)/2 differing between shifts",
                        **_nested(pb, _center(H, ev.closure_group, pb.w ** 2), _center(Hs, ev.closure_group, pb.w ** 2))}
    else:
        sig["shift"] = {"available": False, "reason": "one shift angle"}
    # direction of rotation
    dd = _one_column(pb, ev.direction.astype(float), "direction")
    sig["direction"] = {"half_difference_arcsec": dd.get("gain"), "u": dd.get("u"), "z": dd.get("z"),
                        "significant": dd.get("significant", False), "available": dd["available"]}
    # self-calibration
    sig["selfcal"] = _selfcal_signature(ev, pb)
    # correlation with the radial motion and with the model's own terms
    cor = {}
    for name, v in ev.model_terms.items():
        cor[f"term:{name}"] = _one_column(pb, v, name)
    ecc = ev.model_terms.get(ev.eccentricity_term)
    if ecc is not None and np.any(ecc != 0):
        c1 = fourier_fit(ev.theta_deg, ecc, [1])
        cor["term:eccentricity_quadrature (θ0 error)"] = _one_column(pb, fourier_eval(ev.theta_deg, {1: (c1[1][1], -c1[1][0])}), "q")
    if ev.radial is not None:
        for c in ev.radial.channels:
            cor[f"radial:{c}"] = _one_column(pb, ev.radial.at(ev.theta_deg, c), c)
            cor[f"radial:integral_{c}"] = _one_column(pb, ev.radial.integral_at(ev.theta_deg, c), c)
    sig["correlations"] = cor
    if ev.ccd is not None:
        cc = fourier_fit(ev.ccd.theta_deg, ev.ccd.d_ref_um, range(1, 11))
        c1, d1 = cc[1]
        higher = fourier_eval(ev.ccd.theta_deg, {k: v for k, v in cc.items() if k >= 2})
        sig["ccd"] = {"e_um": math.hypot(c1, d1), "theta0_deg": math.degrees(math.atan2(c1, d1)) % 360,
                      "rms_orders_2_10_um": _rms(higher)}
    return sig


def _selfcal_signature(ev: Evidence, pb: _Problem) -> dict:
    if ev.selfcal is None:
        return {"available": False, "reason": "no self-calibration curve"}
    full = _Problem(ev, use_selfcal=True)
    m = full.n_rows - ev.n
    r_s = full.y[ev.n:]
    th_s = np.asarray(ev.selfcal.theta_deg, dtype=float) % 360
    o = np.argsort(th_s)
    interp = np.interp(ev.theta_deg % 360, th_s[o], r_s[o], period=360.0)
    one = _one_column(pb, interp, "selfcal")
    return {"available": True, "rms_selfcal_residual_arcsec": _rms(r_s), "n_points": int(m),
            "gain_polygon_on_selfcal": one.get("gain"), "u": one.get("u"),
            "consistent": bool(one.get("available") and one["u"] > 0 and abs(one["gain"] - 1) < 3 * max(one["u"], 0.05)),
            "note": "a residual absent from the self-calibration belongs to the reference chain (polygon, autocollimator, drive)"}


# ----------------------------------------------------------------------------------------------
# 3. selection
# ----------------------------------------------------------------------------------------------

@dataclass
class _Cand:
    names: tuple[str, ...]
    X: np.ndarray
    pnames: list[list[str]]         # per member
    fit: dict = field(default_factory=dict)
    bic: float = math.inf
    aicc: float = math.inf
    z: dict = field(default_factory=dict)
    cv: float | None = None
    notes: list[str] = field(default_factory=list)
    passed: bool = False
    reasons: list[str] = field(default_factory=list)
    extra: np.ndarray | None = None
    extras: dict = field(default_factory=dict)
    f_p: float | None = None
    equivalent: bool = False

    @property
    def key(self):
        return "+".join(self.names)


def _params_u(c: _Cand, scale: float):
    out_p, out_u, i = {}, {}, 0
    for member, names in zip(c.names, c.pnames):
        P, U = {}, {}
        for n in names:
            P[n] = float(c.fit["beta"][i])
            U[n] = float(math.sqrt(max(c.fit["cov"][i, i], 0.0) * scale))
            i += 1
        out_p[member], out_u[member] = P, U
    return out_p, out_u


def _prepare(pb: _Problem, name: str, module, ctx) -> tuple[list[_Cand], str]:
    ok, reason = module.available(pb.ev, ctx)
    if not ok:
        return [], reason
    X, names = pb.columns(module, ctx)
    if not names:
        return [], reason or "no columns"
    norms = np.linalg.norm(X * pb.w[:, None], axis=0)
    raw = np.linalg.norm(np.asarray(module.design(pb.ev, ctx)[0]).reshape(pb.ev.n, -1) * pb.w[: pb.ev.n, None], axis=0)
    keep = norms > 1e-6 * np.maximum(raw, 1e-300)
    if not np.any(keep):
        return [], "unobservable with this sampling: the closure (per-run constant) removes it"
    notes = [reason] if reason else []
    if not np.all(keep):
        notes.append("unobservable parameters (removed by the closure): " + ", ".join(n for n, k in zip(names, keep) if not k))
    X = X[:, keep]
    names = [n for n, k in zip(names, keep) if k]
    subsets = getattr(module, "SUBSETS", None)
    if hasattr(module, "variants"):
        subsets = module.variants(names)
    out = []
    if subsets:
        for sub in subsets:
            idx = [i for i, n in enumerate(names) if n in sub]
            if idx and len(idx) == len(sub):  # a variant only with all its parameters observable
                out.append(_Cand((name,), X[:, idx], [[names[i] for i in idx]], notes=list(notes)))
    else:
        out.append(_Cand((name,), X, [names], notes=list(notes)))
    return out, ""


def _evaluate(pb: _Problem, c: _Cand, mods: dict, ctx: dict):
    c.fit = pb.fit(c.X)
    members = [mods[n] for n in c.names]
    if any(hasattr(m, "regressor_perturbations") for m in members):
        P, _ = _params_u(c, 1.0)
        c.extras = {n: pb.regressor_nuisance([mods[n]], [P[n]], ctx) for n in c.names}
        c.extra = np.hstack(list(c.extras.values()))
        if c.extra.shape[1]:
            c.fit = pb.fit(c.X, extra=c.extra)
    c.bic, c.aicc = pb.ic(c.fit)
    scale = max(1.0, c.fit["chi2"] / c.fit["dof"])
    # joint z of each member: Δχ² when its columns are dropped, scaled by the reduced χ² if > 1
    i = 0
    for member, names in zip(c.names, c.pnames):
        idx = list(range(i, i + len(names)))
        rest = [j for j in range(c.X.shape[1]) if j not in idx]
        others = [c.extras[n] for n in c.names if n != member and n in c.extras]
        ex = np.hstack(others) if others else None
        f0 = pb.fit(c.X[:, rest], extra=ex) if rest else pb.null
        d = (f0["chi2"] - c.fit["chi2"]) / scale
        c.z[member] = _z_from_chi2(d, max(c.fit["k"] - f0["k"], 1))
        i += len(names)


def _member_predictions(pb: _Problem, c: _Cand) -> list[np.ndarray]:
    """Each member's fitted contribution on all rows (polygon and self-calibration)."""
    out, i = [], 0
    for names in c.pnames:
        j = i + len(names)
        out.append(c.X[:, i:j] @ c.fit["beta"][i:j])
        i = j
    return out


def _cos_signed(pb, a, b):
    wa, wb = a * pb.w, b * pb.w
    na, nb = math.sqrt(wa @ wa), math.sqrt(wb @ wb)
    return float(wa @ wb / (na * nb)) if na > 0 and nb > 0 else 0.0


def _cos2(pb, a, b):
    wa, wb = a * pb.w, b * pb.w
    na, nb = wa @ wa, wb @ wb
    return float((wa @ wb) ** 2 / (na * nb)) if na > 0 and nb > 0 else 0.0


def _sep_text(names) -> str:
    texts = []
    for a, b in itertools.combinations(names, 2):
        t = ALL[a].SEPARATES_FROM.get(b) if a in ALL else None
        t = t or (ALL[b].SEPARATES_FROM.get(a) if b in ALL else None)
        if not t:
            t = f"{a}: {ALL[a].SEPARATED_BY} / {b}: {ALL[b].SEPARATED_BY}"
        texts.append(f"{a} vs {b}: {t}")
    return "; ".join(texts)


def _prior_rank(names, order) -> tuple:
    """A candidate's place in the library's stated order (``effects.ALL``: the encoder's own division
    error first, then the model's geometry, the motion, the reference chain, the rarer causes)."""
    return tuple(sorted(order.index(n) if n in order else len(order) for n in names))


def _prefer(c: "_Cand", order) -> tuple:
    """The tie-break between candidates whose criterion is equal within the tie tolerance: fewer
    effects first (a single effect before a pair), then the library order of its members, then fewer
    parameters. Never a float comparison."""
    return (len(c.names), _prior_rank(c.names, order), int(c.X.shape[1]))


def _ordered(cands: list, value, tol: float, order) -> list:
    """``cands`` sorted by ``value(c)`` with ties (values within ``tol`` of the first of a run of
    close values) broken by :func:`_prefer`: the order does not depend on rounding."""
    rest = sorted(cands, key=lambda c: (value(c), _prefer(c, order)))
    out = []
    while rest:
        v0 = value(rest[0])
        tied = [c for c in rest if value(c) <= v0 + tol]
        tied.sort(key=lambda c: _prefer(c, order))
        out += tied
        rest = [c for c in rest if value(c) > v0 + tol]
    return out


def _better(c: "_Cand", b: "_Cand", tol: float, order, flag=lambda c: c.passed) -> bool:
    """Does ``c`` beat the incumbent ``b``: passing before failing, then a BIC lower by more than
    ``tol``, then (tied) the stated preference."""
    if flag(c) != flag(b):
        return flag(c)
    if abs(c.bic - b.bic) > tol:
        return c.bic < b.bic
    return _prefer(c, order) < _prefer(b, order)


@_one_blas_thread
def trace(evidence: Evidence, candidates=None) -> dict:
    """Trace the residual of ``evidence`` to the candidate effects (default: all of ``effects.ALL``).

    Returns a JSON-ready dict: ``status``, ``residual_before``, ``signature``,
    ``identified_effects``, ``ambiguous``, ``partial_effects``, ``residual_after``, ``unexplained``,
    ``unexplained_signature``, ``candidates`` (every fit's numbers), ``skipped``, ``thresholds``,
    ``model_file`` (payload for :func:`save_model`).
    """
    ev = evidence
    cands_mod = ALL if candidates is None else {n: ALL[n] for n in candidates} if not isinstance(candidates, dict) else candidates
    before = residual_test(ev)
    pa = _Problem(ev, use_selfcal=False)
    harm = harmonic_test(ev, pa)
    sig = signature(ev, harm)
    flagged = sig["significant_harmonics"]
    u_rms = noise_floor(ev)
    before["noise_floor_arcsec"] = u_rms
    # the residual's RMS beyond what the measurement and the model's uncertainties explain
    excess = float(np.sqrt(np.mean(np.square(ev.u_arcsec)))) * math.sqrt(max(before["chi2"] / before["dof"] - 1.0, 0.0))
    before["excess_rms_arcsec"] = excess
    significant = bool((before["p_value"] < P_SIG and excess >= SIZE_GATE * u_rms) or _significant_parts(sig, ev.n, u_rms))
    before["significant"] = significant
    ctx = {"harmonics": flagged}

    pb = _Problem(ev, use_selfcal=True)
    a = getattr(pb, "async_info", None) or {}
    if a:
        before["async_motion"] = {**a, "per_stop_arcsec": float(a.get("sigma_um", 0.0)) * ARCSEC_PER_RAD
                                  / (ev.optical_radius_mm * 1000.0),
                                  "note": "non-repeating motion of the probes' revolutions (isotropic); its X part at "
                                          "the polygon's stops is in the model's uncertainty"}
    skipped, singles = {}, []
    for name, mod in cands_mod.items():
        cs, why = _prepare(pb, name, mod, ctx)
        if not cs:
            skipped[name] = why
        singles += cs
    for c in singles:
        _evaluate(pb, c, cands_mod, ctx)
    variants = list(singles)
    bic0, aicc0 = pb.ic(pb.null)
    cv0 = pb.cv(np.zeros((pb.n_rows, 0)))
    order = list(ALL) + [n for n in cands_mod if n not in ALL]  # the stated preference (ALL), whatever the call order
    tol = TIE_REL * max(float(pb.null["chi2"]), float(pb.n_rows))

    def gate(c: _Cand, member_bics: dict | None = None):
        c.reasons = []
        c.equivalent = False
        # Parameters must be identifiable with the data at hand: e.g. on 23 polygon stops the
        # interpolation error of a 7069-line disk aliases onto harmonic 8, exactly the column of a
        # graduation harmonic 8; such a pair fits anything with parameters of ~1e9.
        if c.fit["k"] < c.X.shape[1]:
            c.reasons.append(f"parameters not identifiable: design rank {c.fit['k']} < {c.X.shape[1]} columns "
                             "(effects alias onto each other at these sampling angles)")
        if min(c.z.values()) < Z_GATE:
            c.reasons.append(f"z = {min(c.z.values()):.1f} < {Z_GATE}")
        if bic0 - c.bic < DBIC_GATE:
            c.reasons.append(f"ΔBIC = {bic0 - c.bic:.1f} < {DBIC_GATE}")
        if member_bics is not None and c.bic > min(member_bics) - DBIC_GATE:
            c.reasons.append("the pair does not beat its members by ΔBIC ≥ 10")
        scale = max(1.0, c.fit["chi2"] / c.fit["dof"])
        P, U = _params_u(c, scale)
        # physically plausible: every module states the range its parameters can take on a real bench
        for member in c.names:
            pl = getattr(cands_mod[member], "plausible", None)
            if pl:
                ok, why = pl(ev, P[member], U[member], ctx)
                if not ok:
                    c.reasons.append(f"{member}: implausible: {why}")
        # the χ² improvement against the scatter the candidate leaves (F-test): an effect must
        # bring the residual down by more than the noise would by chance, whatever u was assumed
        k_c = max(c.fit["k"], 1)
        d_chi2 = pb.null["chi2"] - c.fit["chi2"]
        F = (d_chi2 / k_c) / max(c.fit["chi2"] / c.fit["dof"], 1e-300)
        c.f_p = float(stats.f.sf(F, k_c, c.fit["dof"])) if d_chi2 > 0 else 1.0
        if c.f_p >= F_SIG:
            c.reasons.append(f"F-test of the improvement: p = {c.f_p:.2g} ≥ {F_SIG}")
        # size: the candidate must bring the residual down, and each member must change the readings,
        # by a meaningful share of the noise floor
        parts = _member_predictions(pb, c)
        r0a = pb.y[pb.alpha_rows]
        red = math.sqrt(max(_rms(r0a) ** 2 - _rms(r0a - sum(parts)[pb.alpha_rows]) ** 2, 0.0))
        if red < SIZE_GATE * u_rms:
            c.reasons.append(f"reduces the residual by only {red:.3g}″ RMS (√(before² − after²)) < {SIZE_GATE} × "
                             f"the noise floor ({u_rms:.3g}″)")
        if len(parts) == 2:
            for j, member in enumerate(c.names):
                alone = _rms(r0a - parts[1 - j][pb.alpha_rows])
                both = _rms(r0a - sum(parts)[pb.alpha_rows])
                red_m = math.sqrt(max(alone ** 2 - both ** 2, 0.0))
                if red_m < SIZE_GATE * u_rms:
                    c.reasons.append(f"{member}: reduces the residual left by the other member by only {red_m:.3g}″ RMS "
                                     f"< {SIZE_GATE} × the noise floor")
        for member, pp in zip(c.names, parts):
            size = _rms(pp[pb.alpha_rows])
            if size < SIZE_GATE * u_rms:
                c.reasons.append(f"{member}: contribution {size:.3g}″ RMS < {SIZE_GATE} × the noise floor "
                                 f"({u_rms:.3g}″): below what the measurement can resolve in practice")
        # a pair of nearly collinear, cancelling members is a degenerate fit, not two effects
        if len(c.names) == 2:
            cs = _cos_signed(pb, parts[0], parts[1])
            n0, n1 = (_rms(pp[pb.alpha_rows]) for pp in parts)
            n01 = _rms((parts[0] + parts[1])[pb.alpha_rows])
            if cs * abs(cs) < -COLLINEAR and n01 < DEGENERATE_RATIO * max(n0, n1):
                c.reasons.append(f"degenerate pair: the members are nearly collinear (cos = {cs:.3f}) and cancel "
                                 f"({n0:.3g}″ and {n1:.3g}″ RMS, together {n01:.3g}″)")
        if not c.reasons:
            c.cv = pb.cv(c.X, extra=c.extra)
            if c.cv is not None and cv0 is not None and c.cv >= cv0 - tol:
                c.reasons.append("cross-validation no better than no effect")
        if not c.reasons and member_bics is not None and best_single is not None and c.bic > best_single - DBIC_GATE - tol:
            # as good as the best single effect with its own gates passed: an alternative explanation
            c.equivalent = True
            c.reasons.append("the pair does not beat the best single effect by ΔBIC ≥ 10 (an equivalent alternative)")
        c.passed = not c.reasons

    best_single = None
    for c in variants:
        gate(c)
    # per effect its best variant (SUBSETS): the best BIC among the variants that pass, else the best BIC
    best_var: dict[str, _Cand] = {}
    for c in variants:
        b = best_var.get(c.names[0])
        if b is None or _better(c, b, tol, order):
            best_var[c.names[0]] = c
    singles = list(best_var.values())
    best_single = min((c.bic for c in singles if c.passed), default=None)
    pairs = []
    # pairs of variants of two effects: an effect may earn its place next to one variant of another
    # (e.g. a tilt error next to the whirl's quadrature term) and not next to its best variant
    for a, b in itertools.combinations(variants, 2):
        if a.names[0] == b.names[0] or max(a.z[a.names[0]], b.z[b.names[0]]) < Z_PAIR:
            continue
        c = _Cand(a.names + b.names, np.hstack([a.X, b.X]), a.pnames + b.pnames, notes=a.notes + b.notes)
        _evaluate(pb, c, cands_mod, ctx)
        gate(c, [a.bic, b.bic])
        pairs.append(c)
    # one entry per effect pair: the best-BIC variant combination among those that pass, else the best
    best_pair: dict[tuple, _Cand] = {}
    for c in pairs:
        key = tuple(sorted(c.names))
        b = best_pair.get(key)
        if b is None or _better(c, b, tol, order, flag=lambda x: x.passed or x.equivalent):
            best_pair[key] = c
    pairs = list(best_pair.values())
    passed = _ordered([c for c in singles + pairs if c.passed], lambda c: c.bic, tol, order)
    equivalents = [c for c in pairs if c.equivalent]

    def cand_json(c: _Cand) -> dict:
        scale = max(1.0, c.fit["chi2"] / c.fit["dof"])
        P, U = _params_u(c, scale)
        return {"names": list(c.names), "params": P, "u": U, "chi2": c.fit["chi2"], "dof": c.fit["dof"], "k": c.fit["k"],
                "bic": c.bic, "aicc": c.aicc, "delta_bic": bic0 - c.bic, "delta_aicc": aicc0 - c.aicc, "z": c.z,
                "cv_gain": (None if c.cv is None or not cv0 else 1.0 - c.cv / cv0), "f_test_p": c.f_p, "passed": c.passed,
                "rejected_because": c.reasons, "notes": c.notes}

    alpha = pb.alpha_rows
    r0 = pb.y[alpha]
    result: dict[str, Any] = {"residual_before": before, "signature": sig, "identified_effects": [], "ambiguous": [],
                              "partial_effects": [], "skipped": skipped,
                              "thresholds": {"P_SIG": P_SIG, "Z_GATE": Z_GATE, "DBIC_GATE": DBIC_GATE,
                                             "AMBIG_DBIC": AMBIG_DBIC, "COLLINEAR": COLLINEAR, "F_SIG": F_SIG,
                                             "SIZE_GATE": SIZE_GATE, "DEGENERATE_RATIO": DEGENERATE_RATIO,
                                             "SPHERE_FORM_UM": SPHERE_FORM_UM, "TIE_REL": TIE_REL,
                                             "tie_tolerance_chi2": tol},
                              "candidates": [cand_json(c) for c in _ordered(singles + pairs, lambda c: c.bic, tol, order)][:30]}
    total_err = _rms(_center(ev.alpha_arcsec, ev.closure_group, 1 / ev.u_arcsec ** 2))
    chosen = passed[0] if passed else None
    # the three criteria side by side (the choice is BIC among candidates that pass all gates, CV
    # included; AICc, which penalises less, is reported so that a disagreement is visible)
    result["selection"] = {
        "by_bic": passed[0].key if passed else None,
        "by_aicc": _ordered(passed, lambda c: c.aicc, tol, order)[0].key if passed else None,
        "by_cv": (_ordered([c for c in passed if c.cv is not None], lambda c: c.cv, tol, order)[0].key
                  if any(c.cv is not None for c in passed) else None),
        "n_passed": len(passed), "cv_folds": None if pb.folds is None else int(len(np.unique(pb.folds[pb.folds >= 0]))),
    }
    result["selection"]["agree"] = len({v for k, v in result["selection"].items() if k.startswith("by_") and v}) <= 1
    if chosen is None:
        result["residual_after"] = {k: before[k] for k in ("rms_arcsec", "pv_arcsec", "fraction_of_error", "chi2", "dof", "p_value")}
        result["unexplained"] = significant
        result["status"] = "unexplained" if significant else "no_significant_residual"
        result["unexplained_signature"] = ({**_short_signature(sig), "left": _significant_parts(sig, ev.n, u_rms)}
                                           if significant else None)
        result["model_file"] = _payload(ev, [], [], result["status"], ctx)
        return _jsonable(result)

    pred = pb.predict_rows(chosen.X, chosen.fit, nuisance=False)
    # errors in variables: a measured regressor (δX from the X probes, the tilt motion) is adjusted
    # by the joint fit within its own uncertainty; the adjustment is part of the effect's estimate
    # (after-residual, model file), as Fourier coefficients in θ (the perturbations are harmonics)
    adjust = _regressor_adjustments(pb, chosen, cands_mod, ctx)
    adj_alpha = sum(adjust.values()) if adjust else np.zeros(ev.n)
    adj_alpha = _center(np.asarray(adj_alpha, dtype=float) + np.zeros(ev.n), ev.closure_group, pb.w[: ev.n] ** 2)
    pred = pred.copy()
    pred[alpha] = pred[alpha] + adj_alpha
    r1 = r0 - pred[alpha]
    # χ² after: the alpha rows without the chosen effect, model nuisance (and the chosen effect's
    # regressor uncertainty) refitted
    pa_y = pa.y
    pa.y = r1
    f_after = pa.fit(np.zeros((ev.n, 0)))
    pa.y = pa_y
    chi2_a = f_after["chi2"]
    dof_a = max(f_after["dof"] - chosen.fit["k"], 1)
    p_after = float(stats.chi2.sf(chi2_a, dof_a))
    result["residual_after"] = {"rms_arcsec": _rms(r1), "pv_arcsec": float(np.ptp(r1)),
                                "fraction_of_error": _rms(r1) / max(total_err, 1e-300), "chi2": chi2_a, "dof": dof_a,
                                "p_value": p_after}
    scale = max(1.0, chosen.fit["chi2"] / chosen.fit["dof"])
    P, U = _params_u(chosen, scale)
    cj = cand_json(chosen)
    effects = []
    for member in chosen.names:
        adj_c = _harmonic_coefs(ev.theta_deg, adjust[member], ev.kmax) if member in adjust else None
        effects.append({"name": member, "params": P[member], "u": U[member],
                        **({"regressor_adjustment_coefs": adj_c} if adj_c else {}),
                        "evidence": {"delta_bic": cj["delta_bic"], "delta_aicc": cj["delta_aicc"], "cv_gain": cj["cv_gain"],
                                     "z": chosen.z[member], "chi2": chosen.fit["chi2"], "dof": chosen.fit["dof"],
                                     "with": [n for n in chosen.names if n != member], "notes": chosen.notes}})
    # ambiguity: other passing candidates within AMBIG_DBIC whose predictions are nearly collinear
    amb_cands, amb_fits = [set(chosen.names)], {chosen.key: cj}
    for c in passed[1:] + equivalents:
        if c.bic - chosen.bic < AMBIG_DBIC and set(c.names) not in amb_cands:
            pc = pb.predict_rows(c.X, c.fit, nuisance=False)
            if _cos2(pb, pc, pred) > COLLINEAR:
                amb_cands.append(set(c.names))
                amb_fits[c.key] = cand_json(c)
    # sets forced by design: those of the chosen candidate and of every alternative tied with it
    # (an exact tie is a choice by stated preference only: the design's ambiguities of the other
    # candidate hold as much)
    forced = set()
    tied = [chosen] + [c for c in passed[1:] if c.bic - chosen.bic <= tol]
    for c in tied:
        for member in c.names:
            fn = getattr(cands_mod[member], "ambiguous_with", None)
            forced |= set(fn(ev)) if fn else set()
    forced -= set().union(*amb_cands)
    for other in sorted(forced):
        amb_cands.append({other})
        for c in singles:
            if c.names == (other,):
                amb_fits[c.key] = cand_json(c)
    # members shared by every alternative are identified whatever the choice: not part of the set,
    # unless the alternatives differ only by one optional member (then the set names both)
    common = set.intersection(*amb_cands)
    amb_names = set.union(*amb_cands) - (common if len(amb_cands) > 1 else set())
    if len(amb_cands) > 1 and len(amb_names) == 1:
        amb_names = set.union(*amb_cands)
    if len(amb_cands) > 1 and len(amb_names) > 1:
        names = sorted(amb_names)
        result["ambiguous"].append({"names": names, "separating_measurement": _sep_text(names), "fits": amb_fits,
                                    "alternatives": ["+".join(sorted(a)) for a in amb_cands],
                                    "forced_by_design": sorted(forced)})
    # the residual after must show no signature left either (same tests as "anything to explain?")
    sig_after = signature(_replace_alpha(ev, ev.alpha_arcsec - pred[alpha]), time_ks=flagged)
    left = _significant_parts(sig_after, ev.n, u_rms)
    if p_after < P_SIG:
        left.insert(0, f"χ² after: p = {p_after:.2g}")
    result["residual_after"]["signature_left"] = left
    if left:
        result["partial_effects"] = effects
        result["unexplained"] = True
        result["status"] = "unexplained"
        result["unexplained_signature"] = {**_short_signature(sig), "after_best_candidate": _short_signature(sig_after),
                                           "left": left}
    else:
        result["identified_effects"] = effects
        result["unexplained"] = False
        result["status"] = "ambiguous" if result["ambiguous"] else "explained"
        result["unexplained_signature"] = None
    result["model_file"] = _payload(ev, effects if not result["unexplained"] else [], result["ambiguous"], result["status"], ctx)
    result["reference_corrections"] = (_reference_corrections(pb, chosen, cands_mod, scale)
                                       if not result["unexplained"] else {})
    return _jsonable(result)


def _reference_corrections(pb: _Problem, c: _Cand, mods: dict, scale: float) -> dict[str, dict[str, Any]]:
    """Per polygon reading, the contribution of each identified member that is not an encoder
    error (SEEN_BY_SELFCAL false: the autocollimator's scale, non-linearity and drift, the polygon's
    pitch, the twist between disk and polygon) and its standard uncertainty from the parameters'
    covariance (× √(χ²/dof) when > 1): what is subtracted from the measured α to give the encoder's
    own error (pipeline: ``encoder_error_corrected_arcsec``). Closure-centred, as α is."""
    out: dict[str, dict[str, Any]] = {}
    i = 0
    n = pb.ev.n
    for member, names in zip(c.names, c.pnames):
        j = i + len(names)
        if not mods[member].SEEN_BY_SELFCAL:
            Xm = c.X[:n, i:j]
            Cm = c.fit["cov"][i:j, i:j] * scale
            val = Xm @ c.fit["beta"][i:j]
            u = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", Xm, Cm, Xm), 0.0, None))
            out[member] = {"value_arcsec": val, "u_arcsec": u, "params": list(names)}
        i = j
    return out


def _significant_parts(sig: dict, n: int, u_rms: float = 0.0) -> list[str]:
    """The parts of a signature that would pass as an effect themselves: a harmonic whose χ²₂ clears
    both candidate gates (z ≥ Z_GATE and ΔBIC = χ² − 2 ln n ≥ DBIC_GATE), a drift or direction
    offset with z ≥ Z_GATE, a significant face pattern. (The Bonferroni flags of the signature are
    laxer: a harmonic can be flagged yet too small for any two-parameter effect to earn its BIC.)"""
    out = []
    hk = [h["k"] for h in sig["harmonics"]
          if h["significant"] and h["z"] >= Z_GATE and h["chi2"] - 2 * math.log(n) >= DBIC_GATE
          and h["amplitude_arcsec"] / math.sqrt(2.0) >= SIZE_GATE * u_rms]
    if hk:
        out.append(f"harmonics {hk}")
    if sig["drift"].get("significant"):
        out.append("drift with time")
    if sig["direction"].get("significant"):
        out.append("direction of rotation")
    if sig["start_face"].get("significant"):
        out.append("pattern fixed to the polygon face")
    tp = sig.get("time_pattern") or {}
    if tp.get("significant"):
        out.append(f"the θ pattern changes with time (harmonics {tp['harmonics']}, z = {tp['z']:.1f}): not stationary")
    return out


def _replace_alpha(ev: Evidence, alpha: np.ndarray) -> Evidence:
    import copy
    e2 = copy.copy(ev)
    e2.alpha_arcsec = np.asarray(alpha, dtype=float)
    return e2


def _short_signature(sig: dict) -> dict:
    return {"significant_harmonics": sig["significant_harmonics"],
            "top_harmonics": sorted(({"k": h["k"], "amplitude_arcsec": h["amplitude_arcsec"], "z": h["z"]} for h in sig["harmonics"]),
                                    key=lambda h: -h["z"])[:5],
            "drift": sig["drift"], "direction": sig["direction"],
            "repetition_synchronous": sig["repetition"].get("synchronous"),
            "face_pattern": sig["start_face"].get("significant"), "shift_dependent": sig["shift"].get("significant"),
            "time_pattern": sig.get("time_pattern"),
            "selfcal_consistent": sig["selfcal"].get("consistent")}


# ----------------------------------------------------------------------------------------------
# model file
# ----------------------------------------------------------------------------------------------

def _regressor_adjustments(pb: _Problem, c: _Cand, mods: dict, ctx: dict) -> dict[str, np.ndarray]:
    """{member: change of its contribution at the polygon readings (arcsec)} from the joint fit's
    adjustment of its measured regressor (errors in variables): the regressor-perturbation columns
    (uncentred) times their fitted nuisance values."""
    out: dict[str, np.ndarray] = {}
    if not c.extras:
        return out
    q = pb.S.shape[1]
    nuis = c.fit["nuis"][q:]
    P, _ = _params_u(c, 1.0)
    i = 0
    for member in c.names:
        if member not in c.extras:
            continue
        m = c.extras[member].shape[1]
        if m:
            R = np.asarray(mods[member].regressor_perturbations(pb.ev, P[member], ctx), dtype=float)
            if R.shape[1] == m:
                out[member] = R @ nuis[i:i + m]
        i += m
    return out


def _harmonic_coefs(theta_deg, values, kmax: int) -> dict[str, list[float]] | None:
    """Fourier coefficients {k: [a_k, b_k]} (orders 1…min(10, kmax)) of a harmonic function sampled at θ."""
    ks = list(range(1, min(10, int(kmax)) + 1))
    if not ks:
        return None
    c = fourier_fit(np.asarray(theta_deg, dtype=float), np.asarray(values, dtype=float), ks)
    return {str(k): [float(a), float(b)] for k, (a, b) in c.items()}


def _payload(ev: Evidence, effects: list[dict], ambiguous: list[dict], status: str, ctx: dict) -> dict:
    out = []
    for e in effects:
        mod = ALL[e["name"]]
        aux = _jsonable(mod.aux(ev, ctx))
        if e.get("regressor_adjustment_coefs"):
            aux["regressor_adjustment_coefs"] = e["regressor_adjustment_coefs"]
        out.append({"name": e["name"], "params": e["params"], "u": e["u"], "aux": aux,
                    "encoder_error": bool(mod.SEEN_BY_SELFCAL)})
    return {"format": "benchtwin-traced-effects", "version": 1, "status": status, "effects": out,
            "ambiguous": [{"names": a["names"], "separating_measurement": a["separating_measurement"]} for a in ambiguous],
            "created_by": "benchtwin.analysis.tracing.trace"}


# plain JSON types, non-finite floats -> null (benchtwin/jsonable.py)
_jsonable = functools.partial(to_json, nonfinite="null")

def save_model(path, payload: dict) -> None:
    """Write the ``model_file`` payload as JSON, atomically (temporary file, fsync, rename)."""
    from benchtwin.fsio import atomic_write_text

    atomic_write_text(path, json.dumps(_jsonable(payload), indent=2, allow_nan=False))


def _read(path_or_payload) -> dict:
    if isinstance(path_or_payload, dict):
        return path_or_payload
    d = json.loads(Path(path_or_payload).read_text(encoding="utf-8"))
    if d.get("format") != "benchtwin-traced-effects" or d.get("version") != 1:
        raise ValueError(f"{path_or_payload}: not a benchtwin-traced-effects v1 file")
    for e in d["effects"]:
        if e["name"] not in ALL:
            raise ValueError(f"{path_or_payload}: unknown effect {e['name']!r}")
    return d


def load_model(path) -> list[tuple[str, dict[str, float]]]:
    """[(effect_name, params)] from a file written by :func:`save_model`."""
    return [(e["name"], {k: float(v) for k, v in e["params"].items()}) for e in _read(path)["effects"]]


def model_terms_from_payload(path_or_payload, base_terms: dict | None = None) -> dict:
    """Named terms {name: callable(theta_rad) -> arcsec} for ``ErrorModel.add_term``.

    Only encoder errors give terms (reference-chain effects — drift, autocollimator scale,
    hysteresis, polygon pitch — correct the reference data, not the encoder). Effects that scale
    the model's own terms (optical_radius, ccd_pixel_scale) need ``base_terms`` (the ErrorModel's
    ``terms``); without them they are left out.
    """
    d = _read(path_or_payload)
    out = {}
    for e in d["effects"]:
        fn = ALL[e["name"]].term(e["params"], e["aux"], base_terms)
        if fn is not None:
            adj = e["aux"].get("regressor_adjustment_coefs") if isinstance(e.get("aux"), dict) else None
            if adj:
                coefs = {int(k): (float(v[0]), float(v[1])) for k, v in adj.items()}
                fn = (lambda f, cc: (lambda th: np.asarray(f(th), dtype=float)
                                     + fourier_eval(np.rad2deg(np.asarray(th, dtype=float)), cc)))(fn, coefs)
            out[f"traced:{e['name']}"] = fn
    return out


def add_to_error_model(model, path_or_payload) -> list[str]:
    """Add the traced effects to an ``ErrorModel`` (anything with ``terms`` and ``add_term``)."""
    base = dict(getattr(model, "terms", {}) or {})
    terms = model_terms_from_payload(path_or_payload, base)
    for name, fn in terms.items():
        model.add_term(name, fn)
    return list(terms)
