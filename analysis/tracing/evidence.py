"""What the tracing knows about a dataset, per polygon reading: :class:`Evidence`.

α per polygon reading (Hsieh et al. 2022 eq. 3: ε_ij = α((i−1)·360/N + S) + Σβ + U_j, so α = ε − Σβ −
U), its uncertainty, the Jia et al. 2019 model terms (eq. 5: e·sin(θ−θ0) and ∫δY dθ / r), the
probes' radial motion (:class:`benchtwin.analysis.radial_motion.RadialMotion`, eq. 7), the multi-head self-calibration
(:class:`SelfCal`, Hsieh eqs. 8–9) and the CCD's d_ref (:class:`CCDData`, Jia eqs. 10–12).
:func:`evidence_from_polygon` builds it from polygon.csv's columns.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from benchtwin.units import ARCSEC_PER_RAD
from ..radial_motion import RadialMotion
from .thresholds import KMAX, KMAX_NYQUIST, SPHERE_FORM_UM, THETA_BIN_DEG


# ----------------------------------------------------------------------------------------------
# evidence containers
# ----------------------------------------------------------------------------------------------

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
    approach: np.ndarray | None = None
    step: np.ndarray | None = None
    face: np.ndarray | None = None
    n_faces: int = 23
    optical_radius_mm: float = 22.0
    L1_mm: float | None = 6.81      # None: not stated (a bench without radial probes)
    L2_mm: float | None = 122.96
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
    #: azimuth of the CCD from head 1 (deg, manifest ``ccd.position_deg``): where the eccentricity
    #: e, θ0 of the model's eq. 3 term was read (RadialMotion.order1_model_error)
    ccd_azimuth_deg: float = 180.0
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
        self.approach = self.direction.copy() if self.approach is None else np.sign(np.asarray(self.approach, dtype=float)).astype(int)
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
        # harmonics 1…kmax: below KMAX_NYQUIST (20), every order under the Nyquist of the positions (as always);
        # above, up to KMAX where the positions leave redundancy for each order: (P − 1)/3, the rule
        # of the probes' grid (RadialMotion's δX orders). A joint fit of (P − 1)/2 harmonics on P
        # positions is nearly a value per position, and each order's test loses its power to the
        # others (loop validation 662, interpolation_error: shifts 0/5/10°, 69 positions, kmax 34
        # missed the aliased order 8 that kmax 20 had flagged)
        self.kmax = int(min(KMAX, max(1, min(KMAX_NYQUIST, (n_theta - 1) // 2), (n_theta - 1) // 3)))
        # every order the sampling resolves (graduation_error's broadband variant, issue 32 item 5),
        # and whether every stop position was read at least twice (the design leaves degrees of
        # freedom for a value per position: repetitions, both directions, several start faces)
        self.kmax_resolved = int(max(1, (n_theta - 1) // 2))
        counts = np.unique(self.theta_bin, return_counts=True)[1]
        self.revisited = bool(counts.size and counts.min() >= 2)

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
                    "eccentricity_term", "kmax", "kmax_resolved", "revisited", "sphere_form_um"):
            return getattr(self.parent, name)
        if name == "ac_arcsec":
            return None
        raise AttributeError(name)


@dataclass
class _AtAngles:
    """The polygon's evidence at other angles θ (θ-functions only): a measured regressor's
    perturbation columns (``regressor_perturbations``) evaluated where the polygon did not stop, as
    the polygon's own rows see them (no ``parent``: not the self-calibration grid)."""

    theta_deg: np.ndarray
    source: Evidence

    def __getattr__(self, name):
        if name in ("optical_radius_mm", "L1_mm", "L2_mm", "radial", "sphere_form_um", "ccd_azimuth_deg"):
            return getattr(self.source, name)
        raise AttributeError(name)


def column(values: np.ndarray | float | None) -> np.ndarray:
    """A per-reading column of an :class:`Evidence` (``closure_group``, ``rep``, ``face``,
    ``u_arcsec``, ...): an array once ``Evidence.__post_init__`` has run. The dataclass types its
    fields as the constructor takes them (None or a scalar may stand there); this states, and
    checks, what they hold afterwards."""
    if not isinstance(values, np.ndarray):
        raise TypeError(f"Evidence column not filled in by Evidence.__post_init__: {type(values).__name__}")
    return values


#: The setup errors U_j of the shift-angle analysis (Hsieh eq. 7), arcsec: {(shift_deg, start_face): U}
#: or a function (shift_deg, start_face) → U
SetupErrors = Mapping[tuple[float, int], float] | Callable[[float, int], float]


#: The standard uncertainty of one α when the caller gives none: Hsieh et al. 2022 Table 3's combined
#: standard uncertainty of the shift-angle α, u_c = 0.069″ ≈ 0.07″ (the pipeline always passes the
#: dataset's own, from its readings' repeatability and its budget).
U_ALPHA_HSIEH2022_ARCSEC = 0.07


def approach_direction(theta_deg, t_s, direction) -> np.ndarray:
    """The direction (+1/−1) in which the stage approached each stop: the sign of the last move
    before the reading, the readings taken in time order (``t_s``) at the commanded angles
    ``theta_deg``.

    Why: a direction hysteresis (friction twisting the shaft between disk and polygon, backlash)
    follows the last motion, not the run's label. A polygon run's first stop is where the previous
    run ended or was sent back to (Hsieh's runs all start at θ = S): after a backward sweep that
    ends at 0° the next forward run reads 0° without moving, approached backward; a forward-only
    series returns from 344° to 0° (a backward move) before each run. Angles are the stage's
    absolute targets (a move from 344° to 0° is −344°, as a rotary stage without wrap-around
    commands it); a move shorter than ``THETA_BIN_DEG`` is no move (the approach is inherited).
    The first reading has no move before it in the table: its run's ``direction``."""
    th = np.asarray(theta_deg, dtype=float)
    d = np.sign(np.asarray(direction, dtype=float)).astype(int)
    out = d.copy()
    if th.size == 0:
        return out
    order = np.argsort(np.asarray(t_s, dtype=float), kind="stable")
    last = int(d[order[0]])
    prev = th[order[0]]
    for idx in order:
        step = th[idx] - prev
        if abs(step) > THETA_BIN_DEG:
            last = 1 if step > 0 else -1
        out[idx] = last
        prev = th[idx]
    return out


@dataclass(frozen=True)
class SelfCalCurve:
    """A multi-head self-calibration curve as the shift-angle analysis gives it (Hsieh eq. 9):
    head 1's μ(θ) in arcsec with its standard uncertainty (a self-calibration without u cannot be
    weighted), on its own θ grid (degrees), from ``n_heads`` heads. :func:`evidence_from_polygon`
    evaluates the model on its grid and makes it the evidence's :class:`SelfCal`."""

    theta_deg: np.ndarray
    value_arcsec: np.ndarray
    u_arcsec: np.ndarray | float
    n_heads: int

    def __post_init__(self) -> None:
        if self.u_arcsec is None:  # no assumed value: a self-calibration without u cannot be weighted
            raise ValueError("SelfCalCurve: u_arcsec is required with value_arcsec")


@dataclass(frozen=True)
class BenchContext:
    """What :func:`evidence_from_polygon` needs besides the polygon's readings, the shift-angle
    results and the model: the bench (``n_faces`` of the polygon, the encoder's geometry), the
    standard uncertainty of one α per reading (``u_arcsec``) and the other instruments' data
    (``radial``: the probes' radial motion, ``selfcal``: the multi-head self-calibration). The
    remaining fields are :class:`Evidence`'s of the same name, with its defaults."""

    n_faces: int
    u_arcsec: np.ndarray | float = U_ALPHA_HSIEH2022_ARCSEC
    radial: RadialMotion | None = None
    selfcal: SelfCalCurve | None = None
    optical_radius_mm: float = Evidence.optical_radius_mm
    L1_mm: float | None = Evidence.L1_mm
    L2_mm: float | None = Evidence.L2_mm
    grating_period_um: float | None = Evidence.grating_period_um
    encoder_lines: int | None = Evidence.encoder_lines
    radial_term: str | None = Evidence.radial_term
    sphere_form_um: float | None = Evidence.sphere_form_um
    u_floor_arcsec: float | None = Evidence.u_floor_arcsec
    ccd_azimuth_deg: float = Evidence.ccd_azimuth_deg


def evidence_from_polygon(columns: dict[str, Any], beta_arcsec: ArrayLike, setup_error_arcsec: SetupErrors,
                          model: Any, bench: BenchContext) -> Evidence:
    """Evidence from the polygon table (dataset ``polygon.csv`` columns) and the shift-angle results.

    ``columns``: ``shift_deg``, ``start_face``, ``step``, ``theta_deg``, ``ac_arcsec``, ``t_s`` and
    optionally ``rep``, ``direction`` (+1/−1 or "forward"/"backward"). ``beta_arcsec``: the N pitch
    deviations used; ``setup_error_arcsec``: {(shift_deg, start_face): U} (Hsieh eq. 7) or a callable
    (shift, face) → U. α per reading = ε − Σ_{k=j}^{j+i−1} β_k − U_j (eq. 3). ``model``: anything with
    ``predict_terms(theta_deg) -> {name: arcsec}`` (the project's ErrorModel) or a callable doing the
    same. ``bench``: the polygon's face count, u of α, the radial probes, the self-calibration and
    the encoder's geometry (:class:`BenchContext`).
    """
    N = int(bench.n_faces)
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
    # the approach of each stop from the readings' time order (a hysteresis follows the last move)
    approach = (approach_direction(th, c["t_s"], direction if direction is not None else np.ones(th.size))
                if "t_s" in c else None)
    sc = None
    if bench.selfcal is not None:
        tsc = np.asarray(bench.selfcal.theta_deg, dtype=float)
        sc = SelfCal(tsc, np.asarray(bench.selfcal.value_arcsec, dtype=float), bench.selfcal.u_arcsec,
                     int(bench.selfcal.n_heads or 1), dict(terms_fn(tsc)))
    return Evidence(theta_deg=th, alpha_arcsec=alpha, u_arcsec=bench.u_arcsec, model_terms=dict(terms_fn(th)),
                    t_s=c.get("t_s"), rep=c.get("rep"), direction=direction, approach=approach, start_face=j, shift_deg=S, step=i,
                    n_faces=N, radial=bench.radial, ac_arcsec=c["ac_arcsec"].astype(float), selfcal=sc,
                    optical_radius_mm=bench.optical_radius_mm, L1_mm=bench.L1_mm, L2_mm=bench.L2_mm,
                    grating_period_um=bench.grating_period_um, encoder_lines=bench.encoder_lines,
                    radial_term=bench.radial_term, sphere_form_um=bench.sphere_form_um,
                    u_floor_arcsec=bench.u_floor_arcsec, ccd_azimuth_deg=float(bench.ccd_azimuth_deg))


def _replace_alpha(ev: Evidence, alpha: np.ndarray) -> Evidence:
    import copy
    e2 = copy.copy(ev)
    e2.alpha_arcsec = np.asarray(alpha, dtype=float)
    return e2
