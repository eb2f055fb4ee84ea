"""Which effect of the library (:mod:`benchtwin.analysis.effects`) explains the residual.

Each candidate alone and in pairs: weighted least squares, BIC and AICc, leave-one-group-out
cross-validation, significance gates against over-fitting (``Z_GATE``, ``DBIC_GATE``, ``F_SIG``,
``SIZE_GATE``); ambiguity sets with the separating measurement; "unexplained" when nothing brings the
residual down to the noise. :func:`trace` runs the whole chain (significance, signature, selection)
and returns the tracing result with the model file payload.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchtwin.units import ARCSEC_PER_RAD

from ..distributions import chi2_isf, chi2_sf, f_sf
from ..effects import ALL
from ..fourier import fit_harmonics
from ._blas import _one_blas_thread
from .evidence import Evidence, _replace_alpha
from .problem import _Problem, _center, _rms, _z_from_chi2, noise_floor
from .signature import _short_signature, _significant_parts, signature
from .significance import harmonic_test, residual_test
from .thresholds import (AMBIG_DBIC, COLLINEAR, DBIC_GATE, DEGENERATE_RATIO, F_SIG, P_SIG, SIZE_GATE, SPHERE_FORM_UM,
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
    member_bics: list[float] | None = None    # a pair's members' BIC (its gate compares with them)

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


def _evaluate(pb: _Problem, c: _Cand, mods: dict, ctx: dict):
    c.fit = pb.fit(c.X)
    members = [mods[n] for n in c.names]
    if any(hasattr(m, "regressor_perturbations") for m in members):
        P, _ = _params_u(c, 1.0)
        c.extras = {n: pb.regressor_nuisance([mods[n]], [P[n]], ctx) for n in c.names}
        c.extra = np.hstack(list(c.extras.values()))
        if c.extra.shape[1]:
            c.fit = pb.fit(c.X, extra=c.extra)
            # the nuisance columns are scaled by the parameters (g·δX's u): linearised at the fit
            # without them, whose g the regressor's own noise attenuates; re-linearised at the joint
            # fit's parameters until they settle (the errors-in-variables fixed point)
            for _ in range(EIV_ITER):
                P0 = np.asarray(c.fit["beta"], dtype=float)
                P, _u = _params_u(c, 1.0)
                c.extras = {n: pb.regressor_nuisance([mods[n]], [P[n]], ctx) for n in c.names}
                c.extra = np.hstack(list(c.extras.values()))
                c.fit = pb.fit(c.X, extra=c.extra)
                if np.allclose(np.asarray(c.fit["beta"], dtype=float), P0, rtol=EIV_RTOL, atol=0.0):
                    break
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
    # Screening: every candidate's fits by the block solver (pb.fast, analysis.tracing.blockfit;
    # ~1e-13 from the reference, far below every threshold and tie tolerance). The candidates whose
    # numbers are reported are refitted with the reference afterwards (``report``), so that the
    # results are the reference's to the last bit.
    pb.fast = True
    for c in singles:
        _evaluate(pb, c, cands_mod, ctx)
    variants = list(singles)
    bic0, aicc0 = pb.ic(pb.null)      # pb.null: the reference's (fitted before the screening)
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
        if c.extra is not None and c.extra.shape[1]:
            # errors in variables: the fit may move a measured regressor only within its u; a fit
            # that needs it moved by more (Σν̂² beyond χ²(p) at P_SIG) explains the residual with a
            # motion (or form) the probes did not measure
            adj, p_eff = pb.eiv_adjustment(c.X, c.fit, c.extra)
            if p_eff > 0 and adj > float(chi2_isf(P_SIG, p_eff)):
                c.reasons.append(f"the measured regressor moved beyond its uncertainty: Σν² = {adj:.1f} for "
                                 f"{p_eff:.1f} determined directions (p < {P_SIG:g})")
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
        c.f_p = float(f_sf(F, k_c, c.fit["dof"])) if d_chi2 > 0 else 1.0
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
    # A variant with more columns than the harmonic test covers (graduation_error's every resolved
    # order: any function of θ up to the sampling's Nyquist) contains every θ-only effect: such a
    # pair is rank-deficient by construction (the gate would reject it as not identifiable) and
    # costs a fit of hundreds of columns; it is not formed. Other designs have no such variant.
    wide = 2 * ev.kmax + 2
    basis: dict[int, np.ndarray] = {}

    def inside(big: _Cand, small: _Cand) -> bool:
        if big.X.shape[1] <= wide:
            return False
        if id(big) not in basis:
            basis[id(big)] = np.linalg.qr(big.X * pb.w[:, None])[0]
        B = small.X * pb.w[:, None]
        Q = basis[id(big)]
        return bool(np.linalg.norm(B - Q @ (Q.T @ B)) <= 1e-6 * np.linalg.norm(B))

    for a, b in itertools.combinations(variants, 2):
        if a.names[0] == b.names[0] or max(a.z[a.names[0]], b.z[b.names[0]]) < Z_PAIR:
            continue
        if inside(a, b) or inside(b, a):
            continue
        c = _Cand(a.names + b.names, np.hstack([a.X, b.X]), a.pnames + b.pnames, notes=a.notes + b.notes)
        _evaluate(pb, c, cands_mod, ctx)
        c.member_bics = [a.bic, b.bic]
        gate(c, c.member_bics)
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
    pb.fast = False
    chosen = passed[0] if passed else None
    # The representative of an ambiguity set: the alternatives within AMBIG_DBIC of the best BIC
    # whose predictions are collinear (cos² > COLLINEAR) are ones the data cannot tell apart (a BIC
    # difference below AMBIG_DBIC is not "strong" evidence, Kass & Raftery 1995), so the BIC does not
    # pick among them: the stated preference does (_prefer: fewer effects, then the library order).
    # The set is reported whole either way; what changes is which alternative's fit is the model
    # after. E.g. on a bench without X probes the unmeasured tangential motion (always present where
    # the Y probes see the axis move) is preferred to an L1 error fitted to the same harmonics.
    if chosen is not None:
        p0 = pb.predict_rows(chosen.X, chosen.fit, nuisance=False)
        alts = [c for c in passed[1:] if c.bic - chosen.bic < AMBIG_DBIC
                and _cos2(pb, pb.predict_rows(c.X, c.fit, nuisance=False), p0) > COLLINEAR]
        chosen = min([chosen] + alts, key=lambda c: _prefer(c, order))
    reported: set[int] = set()

    def report(c: _Cand) -> _Cand:
        """c with its fits, gates and CV redone by the reference solver (the decisions stay the
        screening's): the numbers results.json and the model file report."""
        nonlocal cv0
        if not reported:
            cv0 = pb.cv(np.zeros((pb.n_rows, 0)))
        if id(c) not in reported:
            reported.add(id(c))
            _evaluate(pb, c, cands_mod, ctx)
            gate(c, c.member_bics)
        return c

    if chosen is not None:
        report(chosen)

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
    # the three criteria side by side (the choice is BIC among candidates that pass all gates, CV
    # included; AICc, which penalises less, is reported so that a disagreement is visible)
    result["selection"] = {
        "by_bic": passed[0].key if passed else None,
        "by_aicc": _ordered(passed, lambda c: c.aicc, tol, order)[0].key if passed else None,
        "by_cv": (_ordered([c for c in passed if c.cv is not None], lambda c: c.cv, tol, order)[0].key
                  if any(c.cv is not None for c in passed) else None),
        "representative": chosen.key if chosen is not None else None,
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
    p_after = float(chi2_sf(chi2_a, dof_a))
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
    for c in [c for c in passed if c is not chosen] + equivalents:
        if c.bic - chosen.bic < AMBIG_DBIC and set(c.names) not in amb_cands:
            pc = pb.predict_rows(c.X, c.fit, nuisance=False)
            if _cos2(pb, pc, pred) > COLLINEAR:
                amb_cands.append(set(c.names))
                amb_fits[c.key] = cand_json(report(c))
    # sets forced by design: those of the chosen candidate and of every alternative tied with it
    # (an exact tie is a choice by stated preference only: the design's ambiguities of the other
    # candidate hold as much)
    forced = set()
    tied = [chosen] + [c for c in passed if c is not chosen and abs(c.bic - chosen.bic) <= tol]
    for c in tied:
        for member in c.names:
            fn = getattr(cands_mod[member], "ambiguous_with", None)
            forced |= set(fn(ev)) if fn else set()
    # a member whose design-forced alternative is itself a member of the chosen candidate (without X
    # probes: graduation_error + tangential_motion) is not told apart from it either: the other
    # member alone (an unmeasured motion at the same harmonics) is an alternative of the set
    within = []
    for member in chosen.names:
        fn = getattr(cands_mod[member], "ambiguous_with", None)
        if len(chosen.names) > 1 and fn and set(fn(ev)) & (set(chosen.names) - {member}):
            within.append(set(chosen.names) - {member})
    forced -= set().union(*amb_cands)
    for alt in within:
        if alt not in amb_cands:
            amb_cands.append(alt)
            for c in singles:
                if set(c.names) == alt:
                    amb_fits[c.key] = cand_json(report(c))
    for other in sorted(forced):
        amb_cands.append({other})
        for c in singles:
            if c.names == (other,):
                amb_fits[c.key] = cand_json(report(c))
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
    c = fit_harmonics(np.asarray(theta_deg, dtype=float), np.asarray(values, dtype=float), ks)
    return {str(k): [float(a), float(b)] for k, (a, b) in c.items()}
