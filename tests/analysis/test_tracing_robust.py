"""Decisions of trace() that must not flip under rounding (issue 16, principle 6).

The same evidence perturbed at 1e-12 relative, its readings permuted (other summation order), the
candidates passed in another order, or the whole trace run under another OpenBLAS kernel
(OPENBLAS_CORETYPE=Prescott / Haswell, in a subprocess: the kernel is chosen when the library
loads) must name the same effects, the same ambiguity sets and the same status. The exact tie of
test_model_file_round_trip (a division error and a sphere form at the same harmonics span the same
columns) is decided by the stated preference (tracing.TIE_REL, docs/effects.md), never by rounding.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from benchtwin.analysis.effects import ALL
from tests.synthetic.evidence import make_evidence
from benchtwin.analysis.tracing import _replace_alpha, trace

#: (seed, make_evidence keywords): the exact tie of the round-trip test, a null, a reference-chain
#: gain, a pair of effects on a rich design
CASES = {
    "tie_graduation_sphere_form": (31, dict(inject={"graduation_error": {2: (0.4, 0.3), 5: (0.2, 1.0)}})),
    "null_shifts": (3, dict(start_faces=range(1, 24, 5), shifts=(0.0, 5.0, 10.0))),
    "ac_scale": (12, dict(inject={"ac_scale": {"gain_pct": 0.3}})),
    # both directions in one mounting, the hysteresis following the approach to each stop (a run's
    # first stop is read where the previous run left the stage: tests/analysis/test_approach.py)
    "torsion_on_approach": (7, dict(start_faces=range(1, 24, 2), directions=(1, -1),
                                    inject={"torsion_hysteresis": {"half_hysteresis_arcsec": 0.4}})),
}


def _decision(res: dict) -> dict:
    """What the trace decided (names only: the numbers may differ at rounding level)."""
    return {"status": res["status"],
            "identified": sorted(e["name"] for e in res["identified_effects"]),
            "partial": sorted(e["name"] for e in res["partial_effects"]),
            "ambiguous": [sorted(a["names"]) for a in res["ambiguous"]],
            "model_file": [e["name"] for e in res["model_file"]["effects"]],
            "by_bic": res["selection"]["by_bic"], "by_aicc": res["selection"]["by_aicc"],
            "by_cv": res["selection"]["by_cv"]}


def _case(name):
    seed, kw = CASES[name]
    ev = make_evidence(np.random.default_rng(seed), **kw)[0]
    if name == "torsion_on_approach":
        from benchtwin.analysis.tracing import approach_direction

        appr = approach_direction(ev.theta_deg, ev.t_s, ev.direction)
        ev.alpha_arcsec = ev.alpha_arcsec + kw["inject"]["torsion_hysteresis"]["half_hysteresis_arcsec"] * (
            appr - ev.direction)
        ev.approach = appr
    return ev


def _perturbed(ev, rel, seed):
    rng = np.random.default_rng(seed)
    e2 = _replace_alpha(ev, ev.alpha_arcsec * (1.0 + rel * rng.standard_normal(ev.n)))
    e2.u_arcsec = ev.u_arcsec * (1.0 + rel * rng.standard_normal(ev.n))
    return e2


@pytest.fixture(scope="module")
def reference():
    return {name: _decision(trace(_case(name))) for name in CASES}


def test_exact_tie_is_decided_by_the_stated_preference(reference):
    d = reference["tie_graduation_sphere_form"]
    assert d["model_file"] == ["graduation_error"], d
    assert d["by_bic"] == d["by_aicc"] == d["by_cv"] == "graduation_error"
    # the tie is reported as what it is: an ambiguity with the effects the data cannot separate
    assert d["ambiguous"] == [["graduation_error", "sphere_form", "tangential_motion"]]
    assert reference["null_shifts"]["status"] == "no_significant_residual"
    # one start face, no self-calibration: a gain on α (ac_scale) is a gain on the model's terms
    # (optical_radius: the same columns, an exact tie) and nearly one on the eccentricity
    assert reference["ac_scale"]["ambiguous"] == [["ac_scale", "ccd_pixel_scale", "optical_radius"]]
    assert reference["torsion_on_approach"]["identified"] == ["torsion_hysteresis"]


@pytest.mark.parametrize("name", list(CASES))
def test_same_decision_under_1e12_perturbation(name, reference):
    ev = _case(name)
    for s in (1, 2):
        assert _decision(trace(_perturbed(ev, 1e-12, s))) == reference[name], s


def test_same_decision_with_the_readings_permuted_and_candidates_reordered(reference):
    ev = _case("tie_graduation_sphere_form")
    res = trace(ev, candidates=dict(reversed(list(ALL.items()))))
    assert _decision(res) == reference["tie_graduation_sphere_form"]
    # the readings in another order: every sum is taken in another order
    from tests.synthetic.evidence import make_evidence as mk
    seed, kw = CASES["tie_graduation_sphere_form"]
    _, truth = mk(np.random.default_rng(seed), **kw)
    p = np.random.default_rng(5).permutation(ev.n)
    from benchtwin.analysis.tracing import Evidence
    e2 = Evidence(theta_deg=ev.theta_deg[p], alpha_arcsec=ev.alpha_arcsec[p], u_arcsec=ev.u_arcsec[p],
                  model_terms={k: v[p] for k, v in ev.model_terms.items()}, t_s=ev.t_s[p], rep=ev.rep[p],
                  direction=ev.direction[p], start_face=ev.start_face[p], shift_deg=ev.shift_deg[p], step=ev.step[p],
                  n_faces=ev.n_faces, radial=ev.radial, ac_arcsec=None if ev.ac_arcsec is None else ev.ac_arcsec[p],
                  model_sensitivity=None if not ev.model_sensitivity else {k: v[p] for k, v in ev.model_sensitivity.items()})
    assert _decision(trace(e2)) == reference["tie_graduation_sphere_form"]


_CHILD = """
import json, sys
import numpy as np
sys.path.insert(0, {here!r})
import test_tracing_robust as t
from benchtwin.analysis.tracing import trace
print(json.dumps({{n: t._decision(trace(t._case(n))) for n in t.CASES}}))
"""


@pytest.mark.parametrize("coretype", ["Prescott", "Haswell"])
def test_same_decision_under_another_blas_kernel(coretype, reference):
    env = {**os.environ, "OPENBLAS_CORETYPE": coretype, "OPENBLAS_NUM_THREADS": "1"}
    code = _CHILD.format(here=os.path.dirname(os.path.abspath(__file__)))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got == reference, coretype


# ---------------------------------------------------------------------------------------------
# cross-validation folds and closure groups valid for every design (issue 16)
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("kw, by", [
    (dict(start_faces=range(1, 24, 4), reps=3, directions=(1, -1)), "rep"),
    (dict(start_faces=range(1, 24, 4)), "start_face"),
    (dict(start_faces=[1], shifts=tuple(float(s) for s in range(15))), "shift_deg"),   # SelfA-like shift set
    (dict(start_faces=[1], directions=(1, -1)), "theta"),                               # one rep, both directions
    (dict(start_faces=[1], selfcal=True, n_heads=12), "theta"),                         # 12 heads, one sweep
])
def test_cv_folds_keep_every_training_set_complete(kw, by):
    from benchtwin.analysis.tracing import MAX_CV_FOLDS, _Problem

    ev, _ = make_evidence(np.random.default_rng(1), **kw)
    pb = _Problem(ev, use_selfcal=True)
    f = pb.folds[: ev.n]
    assert pb.folds is not None and np.all(f >= 0) and np.all(pb.folds[ev.n:] == -1)  # selfcal rows always train
    k = np.unique(f).size
    assert 3 <= k <= MAX_CV_FOLDS
    key = {"rep": ev.rep, "start_face": ev.start_face, "shift_deg": np.round(ev.shift_deg, 6), "theta": ev.theta_bin}[by]
    for g in np.unique(key):  # a fold is made of whole groups of its key
        assert np.unique(f[key == g]).size == 1
    for fold in np.unique(f):  # every training set still has both directions and most stop positions
        train = f != fold
        assert set(ev.direction[train]) == set(ev.direction)
        assert np.unique(ev.theta_bin[train]).size >= 0.5 * np.unique(ev.theta_bin).size


def test_closure_group_is_one_mounting_per_repetition():
    ev, _ = make_evidence(np.random.default_rng(2), start_faces=[1, 5], reps=3, directions=(1, -1))
    g = ev.closure_group
    assert g.max() + 1 == 2 * 3  # (shift, start face, rep)
    for r in range(3):
        for j in (1, 5):
            m = (ev.rep == r) & (ev.start_face == j)
            assert np.unique(g[m]).size == 1 and set(ev.direction[m]) == {1, -1}  # both directions share it
