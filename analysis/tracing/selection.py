"""Which effect of the library (:mod:`benchtwin.analysis.effects`) explains the residual.

Each candidate alone and in pairs: weighted least squares, BIC and AICc, leave-one-group-out
cross-validation, significance gates against over-fitting (``Z_GATE``, ``DBIC_GATE``, ``F_SIG``,
``SIZE_GATE``); ambiguity sets with the separating measurement; "unexplained" when nothing brings the
residual down to the noise. :func:`trace` runs the whole chain (significance, signature, selection)
and returns the tracing result with the model file payload, as a model-selection pipeline whose
stages run once each, in this order, and hand small frozen dataclasses on:

1. evidence (:func:`_residual_stage` → :class:`_Residual`): anything to explain?
2. candidates (:func:`_candidate_stage` → :class:`_Candidates`): each effect's variants, or why not;
3. fit and select (:func:`_select` → :class:`_Selection`): screening fits and the no-effect
   baseline (:class:`_Gates`), the gates with the cross-validation folds (:func:`_gate`), each
   effect's best variant, the pairs, the representative of the best;
4. report (:class:`_Reporter`, :func:`_result_head`): the reference solver's numbers;
5. ambiguity sets (:func:`_ambiguity`): what the data cannot tell apart, and what would;
6. outcome (:func:`_explained` / :func:`_unexplained`): the residual after, status, model file.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from benchtwin.units import ARCSEC_PER_RAD

from ..distributions import chi2_isf, chi2_sf, f_sf
from ..effects import ALL
from ..fourier import fit_harmonics, harmonic_columns
from ._blas import _one_blas_thread
from .errors_in_variables import gauss_newton
from .evidence import Evidence, _AtAngles, _replace_alpha, column
from .problem import _digest, _Problem, _center, _rms, _z_from_chi2, chi2_scale, closure_kept, noise_floor
from .signature import _short_signature, _significant_parts, signature
from .significance import harmonic_test, residual_test
from .thresholds import (AMBIG_DBIC, COLLINEAR, DBIC_GATE, DEGENERATE_RATIO, F_SIG, P_DOUBT, P_SIG, SIZE_GATE, SPHERE_FORM_UM,
                         TIE_REL, Z_GATE, Z_PAIR)
from .traced_model import _jsonable, _payload


# ----------------------------------------------------------------------------------------------
# 3. selection
# ----------------------------------------------------------------------------------------------

@dataclass
class _Cand:
    names: tuple[str, ...]
    X: np.ndarray
    pnames: list[list[str]]         # per member
    fit: dict[str, Any] = field(default_factory=dict)
    bic: float = math.inf
    aicc: float = math.inf
    z: dict[str, float] = field(default_factory=dict)
    cv: float | None = None
    notes: list[str] = field(default_factory=list)
    passed: bool = False
    reasons: list[str] = field(default_factory=list)
    extra: np.ndarray | None = None
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    f_p: float | None = None
    equivalent: bool = False
    member_bics: list[float] | None = None    # a pair's members' BIC (its gate compares with them)
    size_reasons: list[str] = field(default_factory=list)   # what its size gates found (set by _gate)
    eiv: "_EivMove | None" = None           # its measured regressors' adjustment (set by the fit gates)

    @property
    def key(self):
        return "+".join(self.names)

    def extra_slices(self) -> dict[str, slice]:
        """{member: its columns in ``extra``} (``extras`` stacked in member order)."""
        out, i = {}, 0
        for n in self.names:
            if n in self.extras:
                m = self.extras[n].shape[1]
                out[n] = slice(i, i + m)
                i += m
        return out


def _params(c: _Cand) -> dict[str, dict[str, float]]:
    """{member: {parameter: value}} of a candidate's fit: :func:`_params_u`'s values without the
    uncertainties, so that a fit whose covariance is computed only when read (the reference's, a
    pseudo-inverse of its whole stacked matrix) is not asked for it (the errors-in-variables
    re-linearisation reads the parameters of every pass and never their uncertainties)."""
    out_p, i = {}, 0
    for member, names in zip(c.names, c.pnames):
        P = {}
        for n in names:
            P[n] = float(c.fit["beta"][i])
            i += 1
        out_p[member] = P
    return out_p


def _params_u(c: _Cand, scale: float):
    """:func:`_params` and, with the same layout, each parameter's u (√ of its covariance diagonal
    × ``scale``): the one place that reads the fit's covariance."""
    out_u, i = {}, 0
    for member, names in zip(c.names, c.pnames):
        U = {}
        for n in names:
            U[n] = float(math.sqrt(max(c.fit["cov"][i, i], 0.0) * scale))
            i += 1
        out_u[member] = U
    return _params(c), out_u


def _prepare(pb: _Problem, name: str, module, ctx) -> tuple[list[_Cand], str]:
    ok, reason = module.available(pb.ev, ctx)
    if not ok:
        return [], reason
    X, names = pb.columns(module, ctx)
    if not names:
        return [], reason or "no columns"
    keep = closure_kept(X, np.asarray(module.design(pb.ev, ctx)[0]).reshape(pb.ev.n, -1), pb.w)
    if not np.any(keep):
        return [], "unobservable with this sampling: the closure (per-run constant) removes it"
    notes = [reason] if reason else []
    if not np.all(keep):
        notes.append("unobservable parameters (removed by the closure): " + ", ".join(n for n, k in zip(names, keep) if not k))
    X = X[:, keep]
    names = [n for n, k in zip(names, keep) if k]
    subsets = getattr(module, "SUBSETS", None)
    if hasattr(module, "variants"):
        subsets = module.variants(names, pb.ev, ctx)
    out = []
    if subsets:
        for sub in subsets:
            idx = [i for i, n in enumerate(names) if n in sub]
            if idx and len(idx) == len(sub):  # a variant only with all its parameters observable
                out.append(_Cand((name,), X[:, idx], [[names[i] for i in idx]], notes=list(notes)))
    else:
        out.append(_Cand((name,), X, [names], notes=list(notes)))
    return out, ""


#: errors-in-variables re-linearisation: at most EIV_ITER passes, until the parameters change by < EIV_RTOL
EIV_ITER = 10
EIV_RTOL = 1e-6


def _regressor_extras(pb: _Problem, c: _Cand, mods: dict, ctx: dict, P: dict) -> dict[str, np.ndarray]:
    """{member: its regressor-perturbation columns scaled by its parameters ``P``} (0 columns for a
    member whose regressor is not measured): the errors-in-variables nuisance E(β), per member."""
    return {n: pb.regressor_nuisance([mods[n]], [P[n]], ctx) for n in c.names}


def _eiv_extras(pb: _Problem, c: _Cand, mods: dict, ctx: dict, P: dict) -> np.ndarray:
    """E(β): :func:`_regressor_extras` stacked in member order."""
    return np.hstack(list(_regressor_extras(pb, c, mods, ctx, P).values()))


def _implausible(mods: dict, ev: Evidence, c: _Cand, P: dict, U: dict, ctx: dict) -> list[str]:
    """Each member's parameters beyond the range its module states a real bench can take
    (``plausible``): the fit gates' reasons, and why a consistent estimate is not adopted."""
    out = []
    for member in c.names:
        pl = getattr(mods[member], "plausible", None)
        if pl:
            ok, why = pl(ev, P[member], U[member], ctx)
            if not ok:
                out.append(f"{member}: implausible: {why}")
    return out


def _eiv_units(pb: _Problem, c: _Cand, mods: dict, ctx: dict) -> list[np.ndarray] | None:
    """U_j = ∂E/∂β_j, one matrix per parameter (E's shape), for the Gauss–Newton estimate
    (errors_in_variables.py). E(β) is linear in each parameter (its perturbation columns are scaled
    by it), so E at β_j doubled less E at β is exactly β_j·U_j. None where a parameter is 0 or
    doubling one changes E's columns (a parameter that switches a block on or off)."""
    P = _params(c)
    E = _eiv_extras(pb, c, mods, ctx, P)
    if c.extra is None or E.shape != c.extra.shape:
        return None
    out = []
    for member, names in zip(c.names, c.pnames):
        for n in names:
            if not c.extras.get(member, E[:, :0]).shape[1]:
                out.append(np.zeros_like(E))   # a member whose regressor is not measured: E does not hold it
                continue
            b = P[member][n]
            if b == 0.0:
                return None
            P2 = {m: dict(v) for m, v in P.items()}
            P2[member][n] = 2.0 * b
            E2 = _eiv_extras(pb, c, mods, ctx, P2)
            if E2.shape != E.shape:
                return None
            out.append((E2 - E) / b)
    return out


def _consistent(pb: _Problem, c: _Cand, mods: dict, ctx: dict) -> tuple[_Cand, dict[str, Any] | None]:
    """The chosen candidate re-estimated consistently where a member's regressor is measured (δX,
    ∫δY, the tilt motion): Deming's joint least squares (errors_in_variables.gauss_newton) from the
    selection's fit, whose fixed point is the attenuated fit of the measured regressor. A copy, so
    the selection's figures (gates, z, BIC, ambiguity) stay those the gates were derived on; the
    effects' parameters, u, regressor adjustments, residual after and corrections are the copy's.
    Where the estimate is implausible for a member (its module's ``plausible``, the bound the gates
    applied to the selection's fit), ``c`` is kept and the record says why: along a direction the
    data leave flat the joint minimum can lie far out (loop validation seed 803, ac_nonlinearity:
    graduation_error + tilt_abbe on Y probes, ΔL1 19.8 mm at the selection's fit, 287 ± 348 mm at
    the joint minimum, χ² 1670.7 → 1658.8). Returns (the estimate, the estimator's record for
    results.json) or (``c``, None) where nothing is measured."""
    if not c.extras or c.extra is None or not c.extra.shape[1]:
        return c, None
    units = _eiv_units(pb, c, mods, ctx)
    if units is None:
        return c, None
    q = pb.S.shape[1]
    d = gauss_newton(pb.fit, pb.y, c.X, units, np.asarray(c.fit["beta"], dtype=float),
                     np.asarray(c.fit["nuis"], dtype=float)[q:], q)
    sl = c.extra_slices()
    est = replace(c, fit=d.fit, extra=d.extra, extras={n: d.extra[:, sl[n]] for n in sl})
    P0 = _params(c)
    measured = [m for m, E in c.extras.items() if E.shape[1]]
    record: dict[str, Any] = {
        "method": "errors in variables, Gauss–Newton on the joint least squares (Deming; "
                  "analysis/tracing/errors_in_variables.py)",
        "steps": d.steps, "converged": d.converged,
        "objective_chi2_selection": d.objective_start, "objective_chi2": d.objective,
        "params_selection": {m: P0[m] for m in measured}, "adopted": True}
    P1, U1 = _params_u(est, chi2_scale(est.fit))
    why_not = _implausible(mods, pb.ev, est, P1, U1, ctx)
    if why_not:
        record.update(adopted=False, why_not=why_not[0], params_consistent={m: P1[m] for m in measured})
        return c, record
    return est, record


def _evaluate(pb: _Problem, c: _Cand, mods: dict, ctx: dict):
    c.fit = pb.fit(c.X)
    members = [mods[n] for n in c.names]
    if any(hasattr(m, "regressor_perturbations") for m in members):
        P = _params(c)
        c.extras = _regressor_extras(pb, c, mods, ctx, P)
        c.extra = np.hstack(list(c.extras.values()))
        if c.extra.shape[1]:
            c.fit = pb.fit(c.X, extra=c.extra)
            # the nuisance columns are scaled by the parameters (g·δX's u): linearised at the fit
            # without them, then re-linearised at the joint fit's parameters until they settle.
            # The gain's column stays the *measured* regressor, so this fixed point is the fit of
            # the measured regressor (xᵀW·r = 0): the nuisance widens the gain's u but does not undo
            # the attenuation by the regressor's own noise (regression dilution; X-probe benches
            # fit g = 0.38–0.85 where the truth's is 1). docs/loop-validation.md, "The measured
            # motion's gain, attenuated by the probes' own noise": a Gauss–Newton step measured.
            for _ in range(EIV_ITER):
                P0 = np.asarray(c.fit["beta"], dtype=float)
                P = _params(c)
                c.extras = _regressor_extras(pb, c, mods, ctx, P)
                c.extra = np.hstack(list(c.extras.values()))
                c.fit = pb.fit(c.X, extra=c.extra)
                if np.allclose(np.asarray(c.fit["beta"], dtype=float), P0, rtol=EIV_RTOL, atol=0.0):
                    break
    c.bic, c.aicc = pb.ic(c.fit)
    scale = chi2_scale(c.fit)
    # joint z of each member: Δχ² when its columns are dropped, scaled by the scatter of the readings
    # that determine the member (:func:`_member_scale`: the reduced χ² if > 1, or the larger
    # leverage-weighted mean square of the residual in the rows that carry its own columns)
    rw = (pb.y - pb.predict_rows(c.X, c.fit, nuisance=True)) * pb.w
    i = 0
    for member, names in zip(c.names, c.pnames):
        idx = list(range(i, i + len(names)))
        rest = [j for j in range(c.X.shape[1]) if j not in idx]
        others = [c.extras[n] for n in c.names if n != member and n in c.extras]
        ex = np.hstack(others) if others else None
        f0 = pb.fit(c.X[:, rest], extra=ex) if rest else pb.null
        d = (f0["chi2"] - c.fit["chi2"]) / max(scale, _member_scale(pb, c.X[:, idx], c.X[:, rest], rw))
        c.z[member] = _z_from_chi2(d, max(c.fit["k"] - f0["k"], 1))
        i += len(names)


def _member_scale(pb: _Problem, Xm: np.ndarray, Xrest: np.ndarray, rw: np.ndarray) -> float:
    """The scatter a member's Δχ² is judged against: the mean square of the fit's weighted residual
    ``rw`` over the rows, weighted by their leverage h_i on the member's own columns (those columns
    with the other members' span removed; Σ h_i = their rank). Under the fit's model every weighted
    residual has the same variance and this equals the reduced χ² (a little below it: the fit took its
    share); where the readings that determine the member scatter more than the rest, the member's Δχ²
    must be read against their scatter, not the average's. E.g. 23 start faces at shift 0 and one run
    at 5° and at 10° (loop validation lv669 tilt_abbe #0): an interpolation error is graduation
    harmonics 8 and 7 at shift 0, so next to them 98 % of its leverage is in the 46 shifted readings,
    which alone see the worn bearing's motion above the flagged orders (truth: 0.27″ at orders 23…40,
    folded onto orders ≤ 11 at shift 0): residual 2.8 u there, 0.94 u at shift 0, χ²/dof 1.46; its
    z fell from 7.7 to 3.3. A heteroscedasticity-consistent (sandwich) reading of the member's
    covariance restricted to its own direction; 0 when the member has no column of its own (its gates
    say so elsewhere)."""
    w = pb.w[:, None]
    B = Xm * w
    if Xrest.shape[1]:
        # the other members' span: the same few sets of columns recur across the candidates (22
        # distinct among 379 calls on a drawn bench), so its Q is kept per problem (freed with it:
        # 43 MB on the hsieh2022 default, 18 sets)
        Qs = pb.__dict__.setdefault("_member_scale_q", {})
        key = _digest(Xrest)
        Q = Qs.get(key)
        if Q is None:
            Q = Qs[key] = np.linalg.qr(Xrest * w)[0]
        B = B - Q @ (Q.T @ B)
    if not B.shape[1]:
        return 0.0
    U, sv, _ = np.linalg.svd(B, full_matrices=False)
    keep = sv > 1e-8 * sv[0]        # B has a column here, so sv[0] exists; all False when B = 0
    if not np.any(keep):
        return 0.0
    h = np.sum(U[:, keep] ** 2, axis=1)
    return float(h @ (rw ** 2) / h.sum())


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


def _sep_text(names, has_x: bool = False) -> str:
    """The measurement that would separate each pair of ``names``; on a bench with X probes a
    module's ``SEPARATES_WITH_X_PROBES`` first (its ``SEPARATES_FROM`` may advise those probes)."""
    texts = []
    for a, b in itertools.combinations(names, 2):
        t = _separation(a, b, has_x) or _separation(b, a, has_x)
        if not t:
            t = f"{a}: {ALL[a].SEPARATED_BY} / {b}: {ALL[b].SEPARATED_BY}"
        texts.append(f"{a} vs {b}: {t}")
    return "; ".join(texts)


def _separation(a: str, b: str, has_x: bool) -> str | None:
    if a not in ALL:
        return None
    t = getattr(ALL[a], "SEPARATES_WITH_X_PROBES", {}).get(b) if has_x else None
    return t or ALL[a].SEPARATES_FROM.get(b)


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


# ----------------------------------------------------------------------------------------------
# the pipeline, one stage after the other:
#   1. evidence         is there anything to explain?              _residual_stage  → _Residual
#   2. candidates       each library effect's variants, ready       _candidate_stage → _Candidates
#   3. fit and select   screening fits, gates (CV folds), pairs,    _select          → _Selection
#                       the representative of the best
#   4. report           the reference solver's numbers              _Reporter, _result_head
#   5. ambiguity sets   what the data cannot tell apart             _ambiguity
#   6. outcome          residual after, status, model file          _explained / _unexplained
# ----------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Residual:
    """Stage 1 (evidence): the residual before any effect, its signature and whether it is worth
    explaining; ``alpha_problem`` is the fit problem on the polygon's rows alone (the χ² after)."""

    before: dict[str, Any]
    signature: dict[str, Any]
    flagged_harmonics: list[int]
    noise_floor_arcsec: float
    significant: bool
    alpha_problem: _Problem


@dataclass(frozen=True)
class _Candidates:
    """Stage 2 (candidates): the fit problem on every row (polygon and self-calibration), the
    library modules, each effect's variants with their design columns, and the effects skipped."""

    pb: _Problem
    mods: dict[str, Any]
    ctx: dict[str, Any]
    variants: list[_Cand]
    skipped: dict[str, str]
    async_motion: dict[str, Any] | None


@dataclass(frozen=True)
class _Gates:
    """What every candidate is compared with in stage 3: the no-effect fit's BIC, AICc and
    cross-validated χ² (``cv0``), the tie tolerance (χ² units), the noise floor, the library order,
    and for pairs the best single effect's BIC (``None`` while the single effects are gated). The
    fit problem, the library modules and their context are stage 2's (``cands``)."""

    cands: _Candidates
    order: list[str]
    tie_tol_chi2: float
    noise_floor_arcsec: float
    bic0: float
    aicc0: float
    cv0: float | None
    best_single_bic: float | None = None

    @property
    def pb(self) -> _Problem:
        return self.cands.pb

    @property
    def mods(self) -> dict[str, Any]:
        return self.cands.mods

    @property
    def ctx(self) -> dict[str, Any]:
        return self.cands.ctx


@dataclass(frozen=True)
class _Selection:
    """Stage 3 (fit and select): the best variant of each effect, the best pairs, those that pass
    every gate (ordered by BIC), the pairs that only equal the best single effect, and the chosen
    representative (``None``: nothing passes)."""

    gates: _Gates
    singles: list[_Cand]
    pairs: list[_Cand]
    passed: list[_Cand]
    equivalents: list[_Cand]
    chosen: _Cand | None


@dataclass(frozen=True)
class _After:
    """The chosen candidate applied: its prediction on every row (arcsec, with its measured
    regressors' adjustment on the polygon rows), those adjustments per member, the residual after
    at the polygon's readings (arcsec) and its test (``residual_after`` of the result)."""

    pred_arcsec: np.ndarray
    adjust_arcsec: dict[str, np.ndarray]
    residual_arcsec: np.ndarray
    test: dict[str, Any]
    #: the adjustments as functions of θ: {member: {order: [a, b]}} (:func:`_adjustment_coefs`)
    adjust_coefs: dict[str, dict[str, list[float]]] = field(default_factory=dict)


@_one_blas_thread
def trace(evidence: Evidence, candidates: Iterable[str] | dict[str, Any] | None = None) -> dict:
    """Trace the residual of ``evidence`` to the candidate effects (default: all of ``effects.ALL``).

    Returns a JSON-ready dict: ``status``, ``residual_before``, ``signature``,
    ``identified_effects``, ``ambiguous``, ``partial_effects``, ``residual_after``, ``unexplained``,
    ``unexplained_signature``, ``candidates`` (every fit's numbers), ``skipped``, ``thresholds``,
    ``model_file`` (payload for :func:`save_model`).
    """
    mods = ALL if candidates is None else candidates if isinstance(candidates, dict) else {n: ALL[n] for n in candidates}
    res = _residual_stage(evidence)
    cands = _candidate_stage(evidence, res, mods)
    sel = _select(cands, res)
    rep = _Reporter.for_selection(sel)
    head = _result_head(res, cands, sel, rep)
    if sel.chosen is None:
        return _jsonable(_unexplained(head, evidence, res, cands.ctx))
    return _jsonable(_explained(head, evidence, res, sel, sel.chosen, rep))


def _residual_stage(ev: Evidence) -> _Residual:
    """Stage 1, evidence: anything to explain? The residual's χ² against its uncertainties, its
    harmonics and signature (time, direction, face patterns), the noise floor, and the residual's
    RMS beyond what the measurement and the model's uncertainties explain."""
    before = residual_test(ev)
    pa = _Problem(ev, use_selfcal=False)
    harm = harmonic_test(ev, pa)
    sig = signature(ev, harm)
    u_rms = noise_floor(ev)
    before["noise_floor_arcsec"] = u_rms
    excess = _excess_rms(ev, before["chi2"], before["dof"])
    before["excess_rms_arcsec"] = excess
    significant = bool(_chi2_matters(before["p_value"], excess, u_rms) or _significant_parts(sig, ev.n, u_rms))
    before["significant"] = significant
    return _Residual(before=before, signature=sig, flagged_harmonics=sig["significant_harmonics"],
                     noise_floor_arcsec=u_rms, significant=significant, alpha_problem=pa)


def _excess_rms(ev: Evidence, chi2: float, dof: int) -> float:
    """The residual's RMS beyond what the readings' uncertainties explain (arcsec):
    RMS(u)·√(max(χ²/dof − 1, 0)). "Anything to explain?" asks it to reach SIZE_GATE × the noise
    floor besides p < P_SIG, before the candidates (:func:`_residual_stage`) and after the chosen one
    (:func:`_explained`): one rule for both. Thousands of readings resolve a χ² excess far below
    what a calibration states (loop validation seed 71, ac_drift #0: χ² after 4017 for 3104 dof,
    p = 1e-26, an excess of 0.032″ RMS against a 0.158″ floor, read as "unexplained")."""
    return float(np.sqrt(np.mean(np.square(ev.u_arcsec)))) * math.sqrt(max(chi2 / dof - 1.0, 0.0))


def _chi2_matters(p_value: float, excess_rms: float, noise_floor: float) -> bool:
    """"Anything to explain?" for a χ²: significant (p < P_SIG) and of a size a calibration states
    (an excess RMS ≥ SIZE_GATE × the noise floor). One rule for the residual before the candidates and
    after the chosen one."""
    return p_value < P_SIG and excess_rms >= SIZE_GATE * noise_floor


def _candidate_stage(ev: Evidence, res: _Residual, mods: dict[str, Any]) -> _Candidates:
    """Stage 2, candidates: the fit problem on every row (the polygon's readings and the
    self-calibration), and each library effect's variants (:func:`_prepare`: available on this
    bench, its observable columns) or why it is skipped."""
    ctx: dict[str, Any] = {"harmonics": res.flagged_harmonics}
    pb = _Problem(ev, use_selfcal=True)
    a = getattr(pb, "async_info", None) or {}
    async_motion = None
    if a:
        async_motion = {**a, "per_stop_arcsec": float(a.get("sigma_um", 0.0)) * ARCSEC_PER_RAD
                        / (ev.optical_radius_mm * 1000.0),
                        "note": "non-repeating motion of the probes' revolutions (isotropic); its X part at "
                                "the polygon's stops is in the model's uncertainty"}
    skipped: dict[str, str] = {}
    variants: list[_Cand] = []
    for name, mod in mods.items():
        cs, why = _prepare(pb, name, mod, ctx)
        if not cs:
            skipped[name] = why
        variants += cs
    return _Candidates(pb=pb, mods=mods, ctx=ctx, variants=variants, skipped=skipped, async_motion=async_motion)


def _select(cands: _Candidates, res: _Residual) -> _Selection:
    """Stage 3, fit and select: screen every variant (:func:`_screen`), gate them and keep each
    effect's best (:func:`_best_variants`), form and gate the pairs (:func:`_pairs`), order those
    that pass by BIC and pick the representative of the best (:func:`_representative`)."""
    g = _screen(cands, res.noise_floor_arcsec)
    singles = _best_variants(cands.variants, g)
    g = replace(g, best_single_bic=min((c.bic for c in singles if c.passed), default=None))
    pairs = _pairs(cands.variants, g)
    passed = _ordered([c for c in singles + pairs if c.passed], lambda c: c.bic, g.tie_tol_chi2, g.order)
    equivalents = [c for c in pairs if c.equivalent]
    g.pb.fast = False
    return _Selection(gates=g, singles=singles, pairs=pairs, passed=passed, equivalents=equivalents,
                      chosen=_representative(passed, g))


def _screen(cands: _Candidates, noise_floor_arcsec: float) -> _Gates:
    """Stage 3a, screening: every variant fitted by the block solver (pb.fast,
    analysis.tracing.blockfit; ~1e-13 from the reference, far below every threshold and tie
    tolerance), and the no-effect baseline the gates compare with: BIC and AICc of the null fit
    (the reference's, fitted before the screening) and its leave-one-group-out CV over the folds.
    The candidates whose numbers are reported are refitted with the reference afterwards
    (:class:`_Reporter`), so that the results are the reference's to the last bit."""
    pb = cands.pb
    pb.fast = True
    for c in cands.variants:
        _evaluate(pb, c, cands.mods, cands.ctx)
    bic0, aicc0 = pb.ic(pb.null)
    cv0 = pb.cv(np.zeros((pb.n_rows, 0)))
    order = list(ALL) + [n for n in cands.mods if n not in ALL]  # the stated preference (ALL), whatever the call order
    tol = TIE_REL * max(float(pb.null["chi2"]), float(pb.n_rows))
    return _Gates(cands=cands, order=order, tie_tol_chi2=tol,
                  noise_floor_arcsec=noise_floor_arcsec, bic0=bic0, aicc0=aicc0, cv0=cv0)


def _gate(c: _Cand, g: _Gates, member_bics: list[float] | None = None) -> None:
    """Stage 3b, the gates: a candidate passes when its fit gates (:func:`_fit_gates`) and size
    gates (:func:`_size_gates`) find nothing, and then its cross-validated χ² beats no effect's;
    a pair that passes but does not beat the best single effect by ΔBIC ≥ DBIC_GATE is an
    equivalent alternative. Sets ``c.reasons``, ``c.passed``, ``c.equivalent``, ``c.f_p``, ``c.cv``."""
    c.reasons = []
    c.equivalent = False
    c.reasons += _fit_gates(c, g, member_bics)
    c.size_reasons = _size_gates(c, g)
    c.reasons += c.size_reasons
    if not c.reasons:
        c.cv = g.pb.cv(c.X, extra=c.extra)
        if c.cv is not None and g.cv0 is not None and c.cv >= g.cv0 - g.tie_tol_chi2:
            c.reasons.append("cross-validation no better than no effect")
    if (not c.reasons and member_bics is not None and g.best_single_bic is not None
            and c.bic > g.best_single_bic - DBIC_GATE - g.tie_tol_chi2):
        # as good as the best single effect with its own gates passed: an alternative explanation
        c.equivalent = True
        c.reasons.append("the pair does not beat the best single effect by ΔBIC ≥ 10 (an equivalent alternative)")
    c.passed = not c.reasons


def _improvement_p(chi2_before: float, dk: int, fit: dict) -> float:
    """p of the F-test of a fit's χ² improvement over ``chi2_before`` for its ``dk`` more
    parameters, against the scatter the fit leaves (χ²/dof); 1 where it does not improve. The one
    test of an improvement: a candidate against no effect (:func:`_fit_gates`), a superset variant
    against its nested one (:func:`_needed_superset`, :func:`_size_from_needed`)."""
    d_chi2 = chi2_before - fit["chi2"]
    if d_chi2 <= 0:
        return 1.0
    return float(f_sf((d_chi2 / dk) / max(fit["chi2"] / fit["dof"], 1e-300), dk, fit["dof"]))


def _fit_gates(c: _Cand, g: _Gates, member_bics: list[float] | None) -> list[str]:
    """The fit's gates: identifiable, each member's z, the measured regressors moved within their
    u, ΔBIC against no effect (and a pair against its members that pass alone), physically plausible parameters,
    and the F-test of the χ² improvement (sets ``c.f_p``). Returns the reasons it fails."""
    pb, reasons = g.pb, []
    # Parameters must be identifiable with the data at hand: e.g. on 23 polygon stops the
    # interpolation error of a 7069-line disk aliases onto harmonic 8, exactly the column of a
    # graduation harmonic 8; such a pair fits anything with parameters of ~1e9.
    if c.fit["k"] < c.X.shape[1]:
        reasons.append(f"parameters not identifiable: design rank {c.fit['k']} < {c.X.shape[1]} columns "
                       "(effects alias onto each other at these sampling angles)")
    if min(c.z.values()) < Z_GATE:
        reasons.append(f"z = {min(c.z.values()):.1f} < {Z_GATE}")
    if c.extra is not None and c.extra.shape[1]:
        # errors in variables: the fit may move a measured regressor only within its u; a fit
        # that needs it moved by more (Σν̂² beyond χ²(p) at P_SIG) explains the residual with a
        # motion (or form) the probes did not measure
        c.eiv = m = _eiv_move(g, c.X, c.fit, c.extra, c.extras.get("tangential_motion"),
                              c.extra_slices().get("tangential_motion"))
        if m.pooled_beyond(P_SIG):
            reasons.append(f"the measured regressor moved beyond its uncertainty: Σν² = {m.sum_nu2:.1f} for "
                           f"{m.p_eff:.1f} determined directions (p < {P_SIG:g})")
        if m.order_beyond(P_SIG):
            k, d2 = m.worst_order()
            reasons.append(f"the X probes' δX moved beyond its uncertainty at order {k}: χ²₂ = {d2:.1f} "
                           f"> {m.order_bound(P_SIG):.1f} (Šidák over the probes' orders at p < {P_SIG:g})")
    if g.bic0 - c.bic < DBIC_GATE:
        reasons.append(f"ΔBIC = {g.bic0 - c.bic:.1f} < {DBIC_GATE}")
    if member_bics and c.bic > min(member_bics) - DBIC_GATE:
        reasons.append("the pair does not beat its members by ΔBIC ≥ 10")
    scale = chi2_scale(c.fit)
    P, U = _params_u(c, scale)
    # physically plausible: every module states the range its parameters can take on a real bench
    reasons.extend(_implausible(g.mods, pb.ev, c, P, U, g.ctx))
    # the χ² improvement against the scatter the candidate leaves (F-test): an effect must
    # bring the residual down by more than the noise would by chance, whatever u was assumed
    c.f_p = _improvement_p(pb.null["chi2"], max(c.fit["k"], 1), c.fit)
    if c.f_p >= F_SIG:
        reasons.append(f"F-test of the improvement: p = {c.f_p:.2g} ≥ {F_SIG}")
    return reasons


@dataclass(frozen=True)
class _EivMove:
    """How far a fit moved its measured regressors (errors in variables): Σν̂² of the unit-prior
    nuisance's posterior mean over the ``p_eff`` directions the readings determine
    (:meth:`_Problem.eiv_posterior`), and, with X probes and a tangential_motion among the members,
    that motion's share order by order (:func:`_adjustment_by_order` over tangential_motion's
    ``x_orders``: ``orders``, χ²₂ each in ``d2``). One set of figures, read at two levels: the fit
    gates refuse beyond P_SIG; a chosen motion beyond P_DOUBT has the division error beside it
    (:func:`_division_error_alternative`)."""

    sum_nu2: float
    p_eff: float
    orders: list[int]
    d2: np.ndarray

    def pooled_beyond(self, p: float) -> bool:
        return self.p_eff > 0 and self.sum_nu2 > float(chi2_isf(p, self.p_eff))

    def order_bound(self, p: float) -> float:
        """The Šidák bound of χ²₂ at ``p`` over the probes' orders."""
        return float(chi2_isf(1.0 - (1.0 - p) ** (1.0 / max(len(self.orders), 1)), 2))

    def worst_order(self) -> tuple[int, float]:
        i = int(np.argmax(self.d2))
        return int(self.orders[i]), float(self.d2[i])

    def order_beyond(self, p: float) -> bool:
        """One order moved beyond the Šidák bound at ``p``: the pooled Σν² lets one order carry a
        division error among ~40 directions (loop validation seeds 668 and 773, selfa_graduation:
        order 2 moved by χ²₂ 28–34 with Σν² 44.4 for 20.1 and 73.8 for 40.7, the division error missed)."""
        return bool(self.d2.size) and float(np.max(self.d2)) > self.order_bound(p)

    def beyond(self, p: float) -> bool:
        return self.pooled_beyond(p) or self.order_beyond(p)


def _eiv_move(g: _Gates, X: np.ndarray, fit: dict, extra: np.ndarray, E_motion: np.ndarray | None,
              motion: slice | None) -> _EivMove:
    """:class:`_EivMove` of a fit of ``X`` with the nuisance ``extra``; ``E_motion``: the columns of
    ``extra`` (at ``motion``) that are tangential_motion's δX, or None."""
    pb = g.pb
    nu, p_eff = pb.eiv_posterior(X, fit, extra)
    orders: list[int] = []
    d2 = np.zeros(0)
    if E_motion is not None and motion is not None and pb.ev.radial is not None and pb.ev.radial.has_x:
        orders = g.mods["tangential_motion"].x_orders(pb.ev)
        d2 = _adjustment_by_order(pb, E_motion, nu[motion], orders)
    return _EivMove(sum_nu2=float(nu @ nu), p_eff=p_eff, orders=orders, d2=d2)


def _size_gates(c: _Cand, g: _Gates) -> list[str]:
    """The practical-significance gates: the candidate must bring the residual down, and each
    member must change the readings, by a meaningful share (SIZE_GATE) of the noise floor; a pair
    of nearly collinear, cancelling members is a degenerate fit. Returns the reasons it fails."""
    pb, u_rms, reasons = g.pb, g.noise_floor_arcsec, []
    parts = _member_predictions(pb, c)
    r0a = pb.y[pb.alpha_rows]
    red = math.sqrt(max(_rms(r0a) ** 2 - _rms(r0a - _sum_rows(parts)[pb.alpha_rows]) ** 2, 0.0))
    if red < SIZE_GATE * u_rms:
        reasons.append(f"reduces the residual by only {red:.3g}″ RMS (√(before² − after²)) < {SIZE_GATE} × "
                       f"the noise floor ({u_rms:.3g}″)")
    if len(parts) == 2:
        for j, member in enumerate(c.names):
            alone = _rms(r0a - parts[1 - j][pb.alpha_rows])
            both = _rms(r0a - _sum_rows(parts)[pb.alpha_rows])
            red_m = math.sqrt(max(alone ** 2 - both ** 2, 0.0))
            if red_m < SIZE_GATE * u_rms:
                reasons.append(f"{member}: reduces the residual left by the other member by only {red_m:.3g}″ RMS "
                               f"< {SIZE_GATE} × the noise floor")
    for member, pp in zip(c.names, parts):
        size = _rms(pp[pb.alpha_rows])
        if size < SIZE_GATE * u_rms:
            reasons.append(f"{member}: contribution {size:.3g}″ RMS < {SIZE_GATE} × the noise floor "
                           f"({u_rms:.3g}″): below what the measurement can resolve in practice")
    # a pair of nearly collinear, cancelling members is a degenerate fit, not two effects
    if len(c.names) == 2:
        cs = _cos_signed(pb, parts[0], parts[1])
        n0, n1 = (_rms(pp[pb.alpha_rows]) for pp in parts)
        n01 = _rms((parts[0] + parts[1])[pb.alpha_rows])
        if cs * abs(cs) < -COLLINEAR and n01 < DEGENERATE_RATIO * max(n0, n1):
            reasons.append(f"degenerate pair: the members are nearly collinear (cos = {cs:.3f}) and cancel "
                           f"({n0:.3g}″ and {n1:.3g}″ RMS, together {n01:.3g}″)")
    return reasons


def _sum_rows(parts: list[np.ndarray]) -> np.ndarray:
    """Σ of per-row arrays, as the built-in sum adds them: 0 + a + b + … (a non-empty list)."""
    total = 0.0 + parts[0]
    for p in parts[1:]:
        total = total + p
    return total


def _best_variants(variants: list[_Cand], g: _Gates) -> list[_Cand]:
    """Stage 3c: every variant gated; per effect its best variant (SUBSETS): the best BIC among the
    variants that pass, else the best BIC (ties by the stated preference)."""
    for c in variants:
        _gate(c, g)
    _size_from_needed(variants)
    best_var: dict[str, _Cand] = {}
    for c in variants:
        b = best_var.get(c.names[0])
        if b is None or _better(c, b, g.tie_tol_chi2, g.order):
            best_var[c.names[0]] = c
    span = _Span(g.pb)
    for name, b in list(best_var.items()):
        if b.passed:
            best_var[name] = _needed_superset(b, [c for c in variants if c.names[0] == name], g, span)
    return list(best_var.values())


def _nested_extra_needed(b: _Cand, c: _Cand) -> float | None:
    """p of the nested F-test of ``c``'s extra parameters over ``b`` (:func:`_improvement_p`) when ``b`` is ``c`` less some of its parameters: the
    same effects, each member's parameters in ``b`` among its parameters in ``c``, fewer in all;
    else None."""
    if b is c or b.names != c.names or b.fit["k"] >= c.fit["k"]:
        return None
    if not all(set(pb_) <= set(pc_) for pb_, pc_ in zip(b.pnames, c.pnames)):
        return None
    return _improvement_p(b.fit["chi2"], c.fit["k"] - b.fit["k"], c.fit)


def _size_from_needed(cands: list[_Cand]) -> None:
    """A candidate's practical size must rest on parameters the data need. Where a passing
    candidate has a nested version (the same effects, some of its parameters left out) whose left-out
    parameters the nested F-test does not need (p ≥ F_SIG), and that version fails a size gate, the
    candidate fails it too: its size came from parameters that are not determined. Why: loop
    validation seeds 790 and 791, ac_drift #0 (a warm-up drift of the autocollimator's zero, forward
    sweeps): beside the division error ac_scale's quadratic term was significant (z 5–8) but
    changed the readings by 0.046–0.063″ RMS, below the size gate (0.075″); on 791, with its gain
    added (z 1.7, not needed), the gain's 0.30″ RMS of the model's first harmonic carried the
    member over the gate, and the pair took the place of the division error alone. The converse
    of :func:`_needed_superset`. Mutates ``passed``, ``equivalent`` and ``reasons`` of the
    candidates it demotes."""
    for c in cands:
        if not c.passed and not c.equivalent:
            continue
        for b in cands:
            if not b.size_reasons:
                continue
            p = _nested_extra_needed(b, c)
            if p is None or p < F_SIG:
                continue
            extra = sorted(set(n for pc_ in c.pnames for n in pc_) - set(n for pb_ in b.pnames for n in pb_))
            c.reasons = [f"its size rests on parameters the data do not need ({', '.join(extra)}: nested F-test "
                         f"p = {p:.2g} ≥ {F_SIG}); without them: {b.size_reasons[0]}"]
            c.passed = c.equivalent = False
            break


def _needed_superset(b: _Cand, variants: list[_Cand], g: _Gates, span: "_Span") -> _Cand:
    """The effect's variant that explains what its best-BIC variant ``b`` leaves, when the data need
    it: a passing variant whose design contains b's and whose extra columns lower the χ² beyond the
    scatter it leaves (the nested F-test at F_SIG, the gates' own test of an improvement). BIC's
    ln n per parameter is stricter than that test for many parameters at once: with graduation_error's
    every resolved order (hundreds of small coefficients, each at a few σ) BIC keeps the significant
    orders, whose residual the test after (χ² at P_SIG) then finds not explained — the selection and
    the verdict would read the same data by two rules. For one or a few extra parameters the F-test at
    F_SIG is the stricter one, so this changes nothing there. The best BIC among the needed ones."""
    needed = []
    for c in variants:
        dk = c.fit["k"] - b.fit["k"]
        if c is b or not c.passed or dk <= 0 or not span.contains(c, b):
            continue
        if _improvement_p(b.fit["chi2"], dk, c.fit) < F_SIG:
            needed.append(c)
    return _ordered(needed, lambda c: c.bic, g.tie_tol_chi2, g.order)[0] if needed else b


def _pairs(variants: list[_Cand], g: _Gates) -> list[_Cand]:
    """Stage 3d, pairs of variants of two effects: an effect may earn its place next to one
    variant of another (e.g. a tilt error next to the whirl's quadrature term) and not next to its
    best variant. Only variants with z ≥ Z_PAIR pair up, and not one that lies inside the other's
    span (:class:`_Span`). Each pair is fitted, gated against its members' BIC and the best single
    effect; per effect pair the best-BIC combination among those that pass, else the best."""
    pb, span = g.pb, _Span(g.pb)
    pairs = []
    for a, b in itertools.combinations(variants, 2):
        if a.names[0] == b.names[0] or max(a.z[a.names[0]], b.z[b.names[0]]) < Z_PAIR:
            continue
        if span.inside(a, b) or span.inside(b, a):
            continue
        c = _Cand(a.names + b.names, np.hstack([a.X, b.X]), a.pnames + b.pnames, notes=a.notes + b.notes)
        _evaluate(pb, c, g.mods, g.ctx)
        # the members that explain the residual alone (every gate passed): a member that fails its
        # own gates (e.g. a measured regressor moved beyond its u to imitate the other member's
        # share) is no alternative to the pair, as for ``best_single_bic``
        c.member_bics = [m.bic for m in (a, b) if m.passed]
        _gate(c, g, c.member_bics)
        pairs.append(c)
    _size_from_needed(pairs)
    best_pair: dict[tuple, _Cand] = {}
    for c in pairs:
        key = tuple(sorted(c.names))
        best = best_pair.get(key)
        if best is None or _better(c, best, g.tie_tol_chi2, g.order, flag=lambda x: x.passed or x.equivalent):
            best_pair[key] = c
    return list(best_pair.values())


class _Span:
    """Does one variant's design contain another's? A variant with more columns than the harmonic
    test covers (graduation_error's every resolved order: any function of θ up to the sampling's
    Nyquist) contains every θ-only effect: such a pair is rank-deficient by construction (the gate
    would reject it as not identifiable) and costs a fit of hundreds of columns; it is not formed.
    Other designs have no such variant. The wide designs' orthonormal bases are computed once."""

    def __init__(self, pb: _Problem):
        self.pb = pb
        self.wide = 2 * pb.ev.kmax + 2
        self.basis: dict[int, np.ndarray] = {}

    def inside(self, big: _Cand, small: _Cand) -> bool:
        if big.X.shape[1] <= self.wide:
            return False
        return self.contains(big, small)

    def contains(self, big: _Cand, small: _Cand) -> bool:
        """Is the span of ``small``'s columns inside ``big``'s (weighted, to 1e-6 of its norm)?"""
        w = self.pb.w[:, None]
        if id(big) not in self.basis:
            self.basis[id(big)] = np.linalg.qr(big.X * w)[0]
        B = small.X * w
        Q = self.basis[id(big)]
        return bool(np.linalg.norm(B - Q @ (Q.T @ B)) <= 1e-6 * np.linalg.norm(B))


def _representative(passed: list[_Cand], g: _Gates) -> _Cand | None:
    """Stage 3e, the representative of an ambiguity set: the alternatives within AMBIG_DBIC of the
    best BIC whose predictions are collinear (cos² > COLLINEAR) are ones the data cannot tell apart
    (a BIC difference below AMBIG_DBIC is not "strong" evidence, Kass & Raftery 1995), so the BIC
    does not pick among them: the stated preference does (_prefer: fewer effects, then the library
    order). The set is reported whole either way; what changes is which alternative's fit is the
    model after. E.g. on a bench without X probes the unmeasured tangential motion (always present
    where the Y probes see the axis move) is preferred to an L1 error fitted to the same harmonics."""
    if not passed:
        return None
    pb, chosen = g.pb, passed[0]
    p0 = pb.predict_rows(chosen.X, chosen.fit, nuisance=False)
    alts = [c for c in passed[1:] if c.bic - chosen.bic < AMBIG_DBIC
            and _cos2(pb, pb.predict_rows(c.X, c.fit, nuisance=False), p0) > COLLINEAR]
    return min([chosen] + alts, key=lambda c: _prefer(c, g.order))


class _Reporter:
    """Stage 4, the numbers results.json and the model file report: a candidate's fits, gates and
    CV redone once by the reference solver (the decisions stay the screening's), and its JSON.
    With a chosen candidate, the no-effect CV is the reference's too (:meth:`for_selection`)."""

    def __init__(self, gates: _Gates):
        self.gates = gates
        self._reported: set[int] = set()

    @classmethod
    def for_selection(cls, sel: _Selection) -> "_Reporter":
        g = sel.gates
        if sel.chosen is None:
            return cls(g)
        rep = cls(replace(g, cv0=g.pb.cv(np.zeros((g.pb.n_rows, 0)))))
        rep.report(sel.chosen)
        return rep

    def report(self, c: _Cand) -> _Cand:
        if id(c) not in self._reported:
            self._reported.add(id(c))
            _evaluate(self.gates.pb, c, self.gates.mods, self.gates.ctx)
            _gate(c, self.gates, c.member_bics)
        return c

    def json(self, c: _Cand) -> dict[str, Any]:
        g = self.gates
        scale = chi2_scale(c.fit)
        P, U = _params_u(c, scale)
        return {"names": list(c.names), "params": P, "u": U, "chi2": c.fit["chi2"], "dof": c.fit["dof"], "k": c.fit["k"],
                "bic": c.bic, "aicc": c.aicc, "delta_bic": g.bic0 - c.bic, "delta_aicc": g.aicc0 - c.aicc, "z": c.z,
                "cv_gain": (None if c.cv is None or not g.cv0 else 1.0 - c.cv / g.cv0), "f_test_p": c.f_p,
                "passed": c.passed, "rejected_because": c.reasons, "notes": c.notes}


def _result_head(res: _Residual, cands: _Candidates, sel: _Selection, rep: _Reporter) -> dict[str, Any]:
    """Stage 4, the result's first part, whatever the outcome: the residual before, its signature,
    the skipped effects, the thresholds, every candidate's numbers (best BIC first, at most 30) and
    the three criteria side by side (the choice is BIC among candidates that pass all gates, CV
    included; AICc, which penalises less, is reported so that a disagreement is visible)."""
    g, passed, tol, pb = rep.gates, sel.passed, rep.gates.tie_tol_chi2, sel.gates.pb
    before = res.before if cands.async_motion is None else {**res.before, "async_motion": cands.async_motion}
    ranked = _ordered(sel.singles + sel.pairs, lambda c: c.bic, tol, g.order)
    with_cv = [c for c in passed if c.cv is not None]
    selection = {
        "by_bic": passed[0].key if passed else None,
        "by_aicc": _ordered(passed, lambda c: c.aicc, tol, g.order)[0].key if passed else None,
        "by_cv": (_ordered(with_cv, lambda c: c.cv if c.cv is not None else math.inf, tol, g.order)[0].key
                  if with_cv else None),
        "representative": sel.chosen.key if sel.chosen is not None else None,
        "n_passed": len(passed), "cv_folds": None if pb.folds is None else int(len(np.unique(pb.folds[pb.folds >= 0]))),
    }
    selection["agree"] = len({v for k, v in selection.items() if k.startswith("by_") and v}) <= 1
    return {"residual_before": before, "signature": res.signature, "identified_effects": [], "ambiguous": [],
            "partial_effects": [], "skipped": cands.skipped,
            "thresholds": {"P_SIG": P_SIG, "Z_GATE": Z_GATE, "DBIC_GATE": DBIC_GATE,
                           "AMBIG_DBIC": AMBIG_DBIC, "COLLINEAR": COLLINEAR, "F_SIG": F_SIG,
                           "SIZE_GATE": SIZE_GATE, "DEGENERATE_RATIO": DEGENERATE_RATIO,
                           "SPHERE_FORM_UM": SPHERE_FORM_UM, "TIE_REL": TIE_REL,
                           "tie_tolerance_chi2": tol},
            "candidates": [rep.json(c) for c in ranked][:30], "selection": selection}


def _unexplained(head: dict[str, Any], ev: Evidence, res: _Residual, ctx: dict[str, Any]) -> dict[str, Any]:
    """Stage 6 without a candidate that passes: the residual after is the residual before;
    "unexplained" if it was significant, else nothing to explain."""
    before = res.before
    out = dict(head)
    out["residual_after"] = {k: before[k] for k in ("rms_arcsec", "pv_arcsec", "fraction_of_error", "chi2", "dof", "p_value")}
    out["unexplained"] = res.significant
    out["status"] = "unexplained" if res.significant else "no_significant_residual"
    out["unexplained_signature"] = ({**_short_signature(res.signature),
                                     "left": _significant_parts(res.signature, ev.n, res.noise_floor_arcsec)}
                                    if res.significant else None)
    out["model_file"] = _payload(ev, [], [], out["status"], ctx)
    return out


def _explained(head: dict[str, Any], ev: Evidence, res: _Residual, sel: _Selection, chosen: _Cand,
               rep: _Reporter) -> dict[str, Any]:
    """Stage 6 with a chosen candidate: the residual after it (:func:`_apply`), its effects, the
    ambiguity sets (stage 5, :func:`_ambiguity`), and the verdict: "explained" (or "ambiguous")
    when the residual after shows no signature left (the same tests as "anything to explain?"),
    else "unexplained" with the chosen candidate's effects as partial ones."""
    g = sel.gates
    # the selection's figures (cj, the ambiguity) are the chosen candidate's as gated; its estimate
    # (parameters, u, adjustment, residual after, corrections) the consistent one (_consistent)
    est, eiv_record = _consistent(g.pb, chosen, g.mods, g.ctx)
    after = _apply(ev, res, g, est)
    out = dict(head)
    out["residual_after"] = after.test
    cj = rep.json(chosen)
    effects = _effects_json(est, after, cj)
    if eiv_record is not None:
        for e in effects:
            if e["name"] in eiv_record["params_selection"]:
                e["estimator"] = {**eiv_record, "params_selection": eiv_record["params_selection"][e["name"]],
                                  **({"params_consistent": eiv_record["params_consistent"][e["name"]]}
                                     if "params_consistent" in eiv_record else {})}
    out["ambiguous"] = _ambiguity(sel, rep, chosen, cj)
    sig_after = signature(_replace_alpha(ev, ev.alpha_arcsec - after.pred_arcsec[g.pb.alpha_rows]),
                          time_ks=res.flagged_harmonics)
    left = _significant_parts(sig_after, ev.n, res.noise_floor_arcsec)
    if _chi2_matters(after.test["p_value"], _excess_rms(ev, after.test["chi2"], after.test["dof"]), res.noise_floor_arcsec):
        left.insert(0, f"χ² after: p = {after.test['p_value']:.2g}")
    out["residual_after"] = {**after.test, "signature_left": left}
    if left:
        out["partial_effects"] = effects
        out["unexplained"] = True
        out["status"] = "unexplained"
        out["unexplained_signature"] = {**_short_signature(res.signature),
                                        "after_best_candidate": _short_signature(sig_after), "left": left}
    else:
        out["identified_effects"] = effects
        out["unexplained"] = False
        out["status"] = "ambiguous" if out["ambiguous"] else "explained"
        out["unexplained_signature"] = None
    out["model_file"] = _payload(ev, effects if not out["unexplained"] else [], out["ambiguous"], out["status"], g.ctx)
    scale = chi2_scale(est.fit)
    out["reference_corrections"] = (_reference_corrections(g.pb, est, g.mods, scale)
                                    if not out["unexplained"] else {})
    return out


def _apply(ev: Evidence, res: _Residual, g: _Gates, chosen: _Cand) -> _After:
    """Stage 6a: the chosen candidate's prediction and the residual it leaves. Errors in variables:
    a measured regressor (δX from the X probes, the tilt motion) is adjusted by the joint fit within
    its own uncertainty; the adjustment is part of the effect's estimate (after-residual, model
    file), as Fourier coefficients in θ (the perturbations are harmonics). χ² after: the polygon
    rows without the chosen effect, the model nuisance (and the chosen effect's regressor
    uncertainty) refitted."""
    pb = g.pb
    alpha = pb.alpha_rows
    r0 = pb.y[alpha]
    pred = pb.predict_rows(chosen.X, chosen.fit, nuisance=False)
    adjust = _regressor_adjustments(pb, chosen, g.mods, g.ctx)
    adj_alpha = _sum_rows(list(adjust.values())) if adjust else np.zeros(ev.n)
    groups, w2 = column(ev.closure_group), 1 / column(ev.u_arcsec) ** 2
    adj_alpha = _center(np.asarray(adj_alpha, dtype=float) + np.zeros(ev.n), groups, pb.w[: ev.n] ** 2)
    pred = pred.copy()
    pred[alpha] = pred[alpha] + adj_alpha
    r1 = r0 - pred[alpha]
    pa = res.alpha_problem
    pa_y = pa.y
    pa.y = r1
    f_after = pa.fit(np.zeros((ev.n, 0)))
    pa.y = pa_y
    chi2_a = f_after["chi2"]
    dof_a = max(f_after["dof"] - chosen.fit["k"], 1)
    total_err = _rms(_center(ev.alpha_arcsec, groups, w2))
    test = {"rms_arcsec": _rms(r1), "pv_arcsec": float(np.ptp(r1)),
            "fraction_of_error": _rms(r1) / max(total_err, 1e-300), "chi2": chi2_a, "dof": dof_a,
            "p_value": float(chi2_sf(chi2_a, dof_a))}
    return _After(pred_arcsec=pred, adjust_arcsec=adjust, residual_arcsec=r1, test=test,
                  adjust_coefs=_adjustment_coefs(pb, chosen, g.mods, g.ctx))


def _effects_json(chosen: _Cand, after: _After, cj: dict[str, Any]) -> list[dict[str, Any]]:
    """The chosen candidate's members as effects: parameters with u (× √(χ²/dof) when > 1), the
    regressor adjustment's Fourier coefficients, and the evidence for each."""
    scale = chi2_scale(chosen.fit)
    P, U = _params_u(chosen, scale)
    effects = []
    for member in chosen.names:
        adj_c = after.adjust_coefs.get(member)
        effects.append({"name": member, "params": P[member], "u": U[member],
                        **({"regressor_adjustment_coefs": adj_c} if adj_c else {}),
                        "evidence": {"delta_bic": cj["delta_bic"], "delta_aicc": cj["delta_aicc"], "cv_gain": cj["cv_gain"],
                                     "z": chosen.z[member], "chi2": chosen.fit["chi2"], "dof": chosen.fit["dof"],
                                     "with": [n for n in chosen.names if n != member], "notes": chosen.notes}})
    return effects


def _ambiguity(sel: _Selection, rep: _Reporter, chosen: _Cand, cj: dict[str, Any]) -> list[dict[str, Any]]:
    """Stage 5, the ambiguity set of the chosen candidate: the passing (or equivalent) alternatives
    the data cannot tell apart from it (:func:`_collinear_alternatives`) and those forced by the
    design (:func:`_design_alternatives`), each with its reference fit, and the measurement that
    would separate them. Returns [] or [the set]."""
    amb_cands, amb_fits = _collinear_alternatives(sel, rep, chosen, cj)
    within, forced = _design_alternatives(sel, chosen, amb_cands)
    for alt in within:
        if alt not in amb_cands:
            amb_cands.append(alt)
            for c in sel.singles:
                if set(c.names) == alt:
                    amb_fits[c.key] = rep.json(rep.report(c))
    for other in sorted(forced):
        amb_cands.append({other})
        for c in sel.singles:
            if c.names == (other,):
                amb_fits[c.key] = rep.json(rep.report(c))
    motion = _measured_motion_alternative(sel, chosen)
    if motion is not None and motion[0] not in amb_cands:
        amb_cands.append(motion[0])
        amb_fits["+".join(sorted(motion[0])) + " (exact geometry)"] = motion[1]
    division = _division_error_alternative(sel, chosen)
    if division is not None and set(division.names) not in amb_cands:
        amb_cands.append(set(division.names))
        amb_fits[division.key] = rep.json(rep.report(division))
    # after the design's alternatives: a nested pair that holds a design-forced name (e.g.
    # graduation_error + tangential_motion) does not replace that name's own alternative
    for c in _nested_alternatives(sel, chosen, amb_cands):
        amb_cands.append(set(c.names))
        amb_fits[c.key] = rep.json(rep.report(c))
    # members shared by every alternative are identified whatever the choice: not part of the set,
    # unless the alternatives differ only by one optional member (then the set names both)
    common = set.intersection(*amb_cands)
    amb_names = set.union(*amb_cands) - (common if len(amb_cands) > 1 else set())
    if len(amb_cands) > 1 and len(amb_names) == 1:
        amb_names = set.union(*amb_cands)
    if not (len(amb_cands) > 1 and len(amb_names) > 1):
        return []
    names = sorted(amb_names)
    has_x = sel.gates.pb.ev.radial is not None and sel.gates.pb.ev.radial.has_x
    return [{"names": names, "separating_measurement": _sep_text(names, has_x), "fits": amb_fits,
             "alternatives": ["+".join(sorted(a)) for a in amb_cands], "forced_by_design": sorted(forced)}]


def _division_error_alternative(sel: _Selection, chosen: _Cand) -> _Cand | None:
    """With X probes, the division error that a chosen tangential motion's moved δX could stand for:
    the converse of :func:`_measured_motion_alternative`. graduation_error's best variant, where

    - it passes every gate alone;
    - the motion needed the probes' δX moved beyond its u at the P_DOUBT level, though within the
      P_SIG gate of :func:`_fit_gates`: its :class:`_EivMove`, Σν̂² beyond χ²(p) or one order's χ²₂
      beyond the Šidák bound, at P_DOUBT;
    - next to the division error the motion is not evidenced: in the pair graduation_error +
      tangential_motion (their best variants, :func:`_pairs`) the motion's z < Z_GATE.

    Why: the fitted motion carries the probes' δX with every coefficient free within its type-A u
    (the unit-prior errors-in-variables nuisance, which no information criterion counts), and with
    0.1 µm probes that u is 5–40× the polygon's per harmonic. On a 2-head, one-shift bench (loop
    validation seed 788, graduation_error #0: 23 stops, 3 repetitions, both directions) the motion
    at gains g 0.58, h 1.49 explained a 0.70″ division error down to χ²/dof 1.00 (0.885″ → 0.157″),
    78 % of that reduction carried by the moved δX (Σν̂² 38.3 for 19.0 directions, p ≈ 0.005), and
    won the BIC by 94 over the division error's 18 harmonic parameters; next to the division error
    the motion's z was 0.6. Where the motion explains with δX as measured (Σν̂² within its
    distribution), a saturated division error beside it proves nothing (on 23 stops it spans every
    function of the stop) and the motion stays alone. The data then hold one of the two, not which:
    the set. Nothing is named on the alternative. Returns graduation_error's candidate, else None."""
    ev = sel.gates.pb.ev
    if ("tangential_motion" not in sel.gates.mods or chosen.names != ("tangential_motion",) or ev.radial is None
            or not ev.radial.has_x):
        return None
    grad = [c for c in sel.singles if c.names == ("graduation_error",) and c.passed]
    pair = [c for c in sel.pairs if set(c.names) == {"graduation_error", "tangential_motion"}]
    if not grad or not pair or pair[0].z["tangential_motion"] >= Z_GATE:
        return None
    return grad[0] if chosen.eiv is not None and chosen.eiv.beyond(P_DOUBT) else None


def _measured_motion_alternative(sel: _Selection, chosen: _Cand) -> tuple[set[str], dict[str, Any]] | None:
    """With X probes, a division error the probes' own error in δX could stand for: the chosen
    candidate with graduation_error (and a fitted tangential_motion) replaced by the measured motion
    at its geometric gain, tangential_motion's design at g = 1 (and h = 1 where eq. 5's ∫δY term is
    in the model: the head reads −δX/r, not ∫δY/r; docs/conventions.md), with the probes' δX free
    within its u (the unit-prior errors-in-variables nuisance every fit of the regressor carries).

    Why: the X probes determine each δX Fourier coefficient to a type-A u (0.016 µm = 0.148″ at
    r = 22 mm on the drawn twin benches) that is 5–40× the polygon's u per harmonic (0.004–0.03″), so
    a fitted gain on that regressor is shrunk (0.1–0.3 beside its own nuisance: regression dilution,
    which the errors-in-variables fixed point of :func:`_evaluate` does not undo) and the real motion
    it leaves reads as a division error at the same orders; above the orders the probes resolve
    (``tangential_motion.x_orders``) δX is not measured at all (docs/loop-validation.md, the X-probe
    rounds: spurious graduation_error on null, ac_drift and polygon_pitch_ignored benches). The
    motion at its known gain is an explanation of the same readings that fits nothing: the
    alternative keeps the chosen's other members and graduation_error's columns above those orders
    (an unmeasured motion there reads as a division error, as without X probes:
    ``graduation_error.ambiguous_with``), and drops the division error at the orders the probes
    resolve. The data cannot tell the two apart where

    - no such order is evidenced beside the motion: each order's columns added to the alternative
      (nested) reach z < Z_GATE, their Δχ² in units of the scatter that fit leaves (as a member's z);
    - the motion needs its δX moved within its u: each order's share of the adjustment within the
      Šidák bound of χ²₂ at P_SIG (:func:`_adjustment_by_order`), and the whole within χ²(p) at
      P_SIG (the errors-in-variables gate of :func:`_fit_gates`).

    Returns the alternative's member set (the chosen's other members and tangential_motion) and its
    figures, else None. It is an alternative only: nothing is named on it. On synthetic X-probe
    evidence (probes 0.05 µm, δX u ≈ 0.08″ per order; 15 shifts × 4 start faces, seeds 1–3): a
    motion read as a division error gives the set (z ≤ 0.8); a 1″ division error at order 3 does
    not (z 7.2–8.5); one of 0.5″ (≈ 6 u of δX) is at the edge (z 3.1–4.1)."""
    g = sel.gates
    pb, ev = g.pb, g.pb.ev
    tm = g.mods.get("tangential_motion")
    if tm is None or "graduation_error" not in chosen.names or ev.radial is None or not ev.radial.has_x:
        return None
    Xt, tnames = pb.columns(tm, g.ctx)
    h = 1.0 if ev.radial_term and ev.radial_term in ev.model_terms else 0.0
    p0 = Xt[:, tnames.index("gain")] + h * Xt[:, tnames.index("radial_gain")]
    cols, extras, rest = [], [], []
    i = 0
    grad = g.mods["graduation_error"]
    x_max = max(tm.x_orders(ev), default=0)
    n_unmeasured = 0
    low_orders: dict[int, list[int]] = {}
    for member, names in zip(chosen.names, chosen.pnames):
        if member == "graduation_error":
            # its orders above those the probes resolve stay: there δX is unmeasured, and a motion
            # reads as a division error exactly as without X probes (graduation_error.ambiguous_with)
            keep = [i + j for j, n in enumerate(names) if grad.param_order(n) > x_max]
            cols.append(chosen.X[:, keep])
            n_unmeasured = len(keep)
            for j, n in enumerate(names):
                if i + j not in keep:
                    low_orders.setdefault(grad.param_order(n), []).append(i + j)
        elif member != "tangential_motion":
            rest.append(member)
            cols.append(chosen.X[:, i:i + len(names)])
            if member in chosen.extras:
                extras.append(chosen.extras[member])
        i += len(names)
    E_motion = pb.regressor_nuisance([tm], [{"gain": 1.0}], g.ctx)
    E = np.hstack([E_motion] + extras)
    Xr = np.hstack(cols) if cols else np.zeros((pb.n_rows, 0))
    y0 = pb.y
    try:
        pb.y = y0 - p0
        f = pb.fit(Xr, extra=E)
        m = _eiv_move(g, Xr, f, E, E_motion, slice(0, E_motion.shape[1]))
        # the division error at each order the probes resolve, tested beside the motion: the fit
        # with that order's columns added (nested), Δχ² in units of the scatter that fit leaves
        z_div = {}
        for k, idx in low_orders.items():
            fk = pb.fit(np.hstack([Xr, chosen.X[:, idx]]), extra=E)
            z_div[k] = _z_from_chi2((f["chi2"] - fk["chi2"]) / chi2_scale(fk), max(fk["k"] - f["k"], 1))
    finally:
        pb.y = y0
    z_max = max(z_div.values(), default=0.0)
    members = sorted(set(rest) | {"tangential_motion"})
    figures: dict[str, Any] = {"members": members,
               "meaning": f"tangential_motion at its geometric gain (g = 1, h = {h:g}), the X probes' δX within its u",
               "unmeasured_orders_above": x_max, "unmeasured_columns": n_unmeasured,
               "chi2": float(f["chi2"]), "k": int(f["k"]), "division_error_z_max": float(z_max),
               "division_error_z": {str(k): float(v) for k, v in sorted(z_div.items())},
               "max_order_adjustment_chi2": float(m.d2.max()) if m.d2.size else 0.0,
               "order_bound_chi2": m.order_bound(P_SIG), "sum_nu2": m.sum_nu2, "determined_directions": m.p_eff}
    if z_max >= Z_GATE or m.beyond(P_SIG):
        return None
    return set(members), figures


def _adjustment_by_order(pb: _Problem, E: np.ndarray, nu: np.ndarray, orders: list[int]) -> np.ndarray:
    """Each order's share of a measured regressor's adjustment E·ν̂ at the polygon's readings, as a
    χ²₂ against what the regressor's u allows there: the order's (sin, cos) coefficients c of E·ν̂
    (weighted least squares on the closure-centred harmonics of ``orders``) against their
    covariance C·Cᵀ under ν ~ N(0, I) (C: the same fit of E's columns). A division error the
    probes' δX would have to absorb reads as one order moved by many u, whatever the number of
    columns (per sphere, per coefficient, the form bound) that share it."""
    ev = pb.ev
    n = ev.n
    if not orders or E.shape[1] == 0:
        return np.zeros(0)
    w = pb.w[:n]
    H = _center(harmonic_columns(ev.theta_deg, orders)[0], column(ev.closure_group), w ** 2) * w[:, None]
    B = np.linalg.lstsq(H, np.column_stack([E[:n] @ nu, E[:n]]) * w[:, None], rcond=None)[0]
    c, C = B[:, 0], B[:, 1:]
    out = []
    for i in range(len(orders)):
        ck, Ck = c[2 * i:2 * i + 2], C[2 * i:2 * i + 2]
        out.append(float(ck @ np.linalg.pinv(Ck @ Ck.T, rcond=1e-10, hermitian=True) @ ck))
    return np.asarray(out)


def _collinear_alternatives(sel: _Selection, rep: _Reporter, chosen: _Cand,
                            cj: dict[str, Any]) -> tuple[list[set[str]], dict[str, dict[str, Any]]]:
    """The chosen candidate and the other passing (or equivalent) candidates within AMBIG_DBIC of
    its BIC whose predictions are nearly collinear with its own (cos² > COLLINEAR): (their member
    sets, {key: reference fit JSON}).

    Both predictions are the same kind, columns × fitted parameters (as :func:`_representative`
    compares them): not the chosen one's with its measured regressor's adjustment (errors in
    variables) against the other's without. With the X probes' δX adjusted within its u, a
    tangential motion's prediction moved far enough that three pairs of identical fit (a gain on
    the model — ac_scale, optical_radius, ccd_pixel_scale — next to the same tangential motion)
    had cos² 0.79 with the chosen one and no ambiguity set was reported (loop validation, issue 32)."""
    pb = sel.gates.pb
    pred = pb.predict_rows(chosen.X, chosen.fit, nuisance=False)
    amb_cands, amb_fits = [set(chosen.names)], {chosen.key: cj}
    for c in [c for c in sel.passed if c is not chosen] + sel.equivalents:
        if _delta_bic_scaled(c, chosen) < AMBIG_DBIC and set(c.names) not in amb_cands:
            pc = pb.predict_rows(c.X, c.fit, nuisance=False)
            if _cos2(pb, pc, pred) > COLLINEAR:
                amb_cands.append(set(c.names))
                amb_fits[c.key] = rep.json(rep.report(c))
    return amb_cands, amb_fits


def _nested_alternatives(sel: _Selection, chosen: _Cand, amb_cands: list[set[str]]) -> list[_Cand]:
    """The equivalent pairs (every gate of a pair passed, but not ΔBIC ≥ DBIC_GATE below the best
    single effect) made of the chosen effect's narrower variant and another effect whose columns
    all lie inside the chosen candidate's span (:meth:`_Span.contains`).

    The chosen fit with that other effect added is the same fit — its columns add nothing to the
    chosen span: the same χ², rank and BIC, an exact tie that no criterion separates — and the
    other effect has evidence of its own: next to the chosen effect's narrower variant it passes
    every gate of a pair (z ≥ Z_GATE inside the pair, ΔBIC ≥ DBIC_GATE below each member, the size
    gates, the cross-validation). The data then cannot tell whether that part of the chosen
    prediction is the other effect: it belongs to the ambiguity set. E.g. graduation_error's
    every-order variant (a value per stop position) is needed where an unmeasured tangential motion
    fills many orders; it contains the alias of an interpolation error, which next to the
    significant orders alone took 1232 of the residual's χ² (loop validation seed 71,
    interpolation_error #0: Y probes only, shifts 0/5/10°, named {graduation_error,
    tangential_motion} without it). A pair whose columns the chosen span does not contain was
    judged by the BIC against the chosen one and is not one of these."""
    if len(chosen.names) != 1 or not sel.equivalents:
        return []
    span = _Span(sel.gates.pb)
    out = []
    for c in sel.equivalents:
        if (chosen.names[0] in c.names and set(c.names) not in amb_cands
                and c.X.shape[1] < chosen.X.shape[1] and span.contains(chosen, c)):
            out.append(c)
    return out


def _delta_bic_scaled(c: _Cand, chosen: _Cand) -> float:
    """BIC of ``c`` less the chosen candidate's, its χ² difference in units of the scatter the chosen
    fit leaves (÷ max(1, χ²/dof), as the gates scale each member's z): the evidence the data hold
    for one over the other. Where the chosen fit leaves structure it does not explain (χ²/dof > 1),
    an extra parameter picks up a share of that misfit by chance — unscaled, a quadratic
    autocollimator term took 17 of the χ² an unmeasured motion left (χ²/dof 2.6) and put ac_scale
    10.5 in BIC ahead of the gain on the eccentricity it shares with ccd_pixel_scale and
    optical_radius, so the set named ac_scale alone (loop validation seed 61, ccd_pixel_scale #0).
    Equal to the BIC difference when the chosen fit's χ²/dof ≤ 1."""
    scale = chi2_scale(chosen.fit)
    dk = c.fit["k"] - chosen.fit["k"]
    return (c.fit["chi2"] - chosen.fit["chi2"]) / scale + dk * math.log(chosen.fit["n"])


def _design_alternatives(sel: _Selection, chosen: _Cand, amb_cands: list[set[str]]) -> tuple[list[set[str]], set[str]]:
    """The alternatives the design forces (each module's ``ambiguous_with``): (``within``, ``forced``).
    ``forced``: those of the chosen candidate and of every alternative tied with it (an exact tie
    is a choice by stated preference only: the design's ambiguities of the other candidate hold as
    much), less the names already in ``amb_cands``. ``within``: a member whose design-forced
    alternative is itself a member of the chosen candidate (without X probes: graduation_error +
    tangential_motion) is not told apart from it either: the other member alone (an unmeasured
    motion at the same harmonics) is an alternative of the set."""
    g = sel.gates
    ev = g.pb.ev
    forced: set[str] = set()
    tied = [chosen] + [c for c in sel.passed if c is not chosen and abs(c.bic - chosen.bic) <= g.tie_tol_chi2]
    for c in tied:
        for member in c.names:
            fn = getattr(g.mods[member], "ambiguous_with", None)
            forced |= set(fn(ev)) if fn else set()
    within = []
    for member in chosen.names:
        fn = getattr(g.mods[member], "ambiguous_with", None)
        if len(chosen.names) > 1 and fn and set(fn(ev)) & (set(chosen.names) - {member}):
            within.append(set(chosen.names) - {member})
    forced -= set().union(*amb_cands)
    return within, forced


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


def _regressor_adjustments(pb: _Problem, c: _Cand, mods: dict, ctx: dict, at: Any = None) -> dict[str, np.ndarray]:
    """{member: change of its contribution at the polygon readings (arcsec)} from the joint fit's
    adjustment of its measured regressor (errors in variables): the regressor-perturbation columns
    (uncentred) times their fitted nuisance values. ``at``: the evidence at other angles
    (:class:`~.evidence._AtAngles`) to evaluate the same adjustment there."""
    out: dict[str, np.ndarray] = {}
    if not c.extras:
        return out
    ev = pb.ev if at is None else at
    q = pb.S.shape[1]
    nuis = c.fit["nuis"][q:]
    P = _params(c)
    for member, cols in c.extra_slices().items():
        m = cols.stop - cols.start
        if m:
            R = np.asarray(mods[member].regressor_perturbations(ev, P[member], ctx), dtype=float)
            if R.shape[1] == m:
                out[member] = R @ nuis[cols]
    return out


def _adjustment_coefs(pb: _Problem, c: _Cand, mods: dict, ctx: dict) -> dict[str, dict[str, list[float]]]:
    """{member: {k: [a_k, b_k]}}: each member's regressor adjustment (:func:`_regressor_adjustments`)
    as the function of θ it is, for the model file and the report. The perturbation columns are
    harmonics of the radial motion's series, band-limited to its highest order K (δX to
    X_ORDERS_MAX, beyond the polygon's Nyquist): the adjustment is evaluated on 4K + 4 equally
    spaced angles, where orders 1…K are exactly determined (no aliasing below half the samples), and
    its Fourier coefficients are fitted there. Fitting them on the polygon's own stops instead (as
    before 2026-12-06: orders 1…min(10, kmax)) folded every order above the stops' Nyquist onto lower
    ones and dropped orders 11…K, so the model file's term differed from the fitted one between the
    stops, and on X-probe benches at the stops too."""
    if not c.extras or pb.ev.radial is None:
        return {}
    K = int(pb.ev.radial.highest_order)
    grid = np.arange(4 * K + 4) * (360.0 / (4 * K + 4))
    adjust = _regressor_adjustments(pb, c, mods, ctx, at=_AtAngles(theta_deg=grid, source=pb.ev))
    out = {}
    for member, values in adjust.items():
        coefs = fit_harmonics(grid, np.asarray(values, dtype=float), range(1, K + 1))
        out[member] = {str(k): [float(a), float(b)] for k, (a, b) in coefs.items()}
    return out
