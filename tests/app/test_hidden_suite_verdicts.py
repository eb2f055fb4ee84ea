"""The hidden suite's verdict rule (benchmarks/hidden_suite.py ``classify``): where the truth's axis
holds ≥ 0.1″ of −δX/r (unobservable without X probes, or measured by them), tangential_motion, or an
ambiguity set that holds it (such as {tangential_motion, graduation_error}), is no false positive on a
null — without X probes the independent reference generator's rule — and nothing else."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("hidden_suite", ROOT / "benchmarks" / "hidden_suite.py")
hs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(hs)

SET = [["graduation_error", "tangential_motion"]]


def test_the_set_on_a_y_probe_null_is_no_false_positive_above_the_unobservable_floor():
    assert hs.classify("none", [], SET, False, 0.2) == hs.OK_UNOBSERVABLE
    assert hs.classify("none", ["tangential_motion"], [], False, 0.2) == hs.OK_UNOBSERVABLE
    assert hs.is_correct("null_a", hs.OK_UNOBSERVABLE)


def test_below_the_floor_or_with_x_probes_or_another_name_it_stays_false():
    assert hs.classify("none", [], SET, False, 0.05).startswith("FALSE")
    assert hs.classify("none", [], SET, False, None).startswith("FALSE")          # X probes: nothing unobservable
    assert hs.classify("none", ["graduation_error"], [], False, 0.3).startswith("FALSE")   # alone: not the set
    assert hs.classify("none", ["ac_scale"], SET, False, 0.3).startswith("FALSE")
    # a set without the motion excuses nothing, nor does the motion's set-mate below the floor
    assert hs.classify("none", [], [["graduation_error", "sphere_form"]], False, 0.3).startswith("FALSE")
    assert hs.classify("none", [], [["sphere_form", "tangential_motion"]], False, 0.05).startswith("FALSE")
    assert hs.classify("none", [], [], False, 0.3) == "ok (nothing)"
    # an effect that is expected is never satisfied by the rule
    assert not hs.is_correct("graduation_error", hs.OK_UNOBSERVABLE)


def test_every_set_mate_of_the_unseen_motion_is_excused_as_an_expected_effects_are():
    """lv779's null (Y probes, 0.64″ of unseen −δX/r): the set {graduation_error, sphere_form,
    tangential_motion, tilt_abbe}, three one-parameter rescalings of ∫δY tied within 5 BIC. It holds
    the bench's real cause, as a set that holds an expected effect is right on an effect bench; the
    same names outside such a set stay false positives."""
    from benchtwin.app.score import score_identification

    lv779 = [["graduation_error", "sphere_form", "tangential_motion", "tilt_abbe"]]
    assert hs.classify("none", ["graduation_error", "tangential_motion"], lv779, False, 0.64) == hs.OK_UNOBSERVABLE
    null = {"expect": [], "accept": ["nothing"]}
    s = score_identification({"named": ["graduation_error", "tangential_motion"], "ambiguous": lv779,
                              "unexplained": False}, null, unobservable_arcsec=0.64)
    assert s["correct"] and s["spurious"] == [] and s["outcome"] == "nothing", s
    s = score_identification({"named": ["sphere_form"], "ambiguous": [["graduation_error", "tangential_motion"]],
                              "unexplained": False}, null, unobservable_arcsec=0.64)
    assert not s["correct"] and s["spurious"] == ["sphere_form"], s


def test_set_mates_do_not_depend_on_the_order_of_the_sets():
    """One set-mate rule (``app.score.with_set_mates``) for expected effects and the unseen motion:
    a set that shares only a mate with the expected effect's set excuses nothing, in either order
    (the expected effect's loop grew its names set by set, so a second set was excused only when it
    came after the first)."""
    from benchtwin.app.score import score_identification, with_set_mates

    a, b = ["sphere_form", "graduation_error"], ["graduation_error", "ac_scale"]
    exp = {"expect": ["sphere_form"], "accept": ["named", "ambiguous"]}
    for sets in ([a, b], [b, a]):
        assert with_set_mates(["sphere_form"], sets) == {"sphere_form", "graduation_error"}
        s = score_identification({"named": [], "ambiguous": sets, "unexplained": False}, exp)
        assert s["spurious"] == ["ac_scale"] and not s["correct"], s


def test_the_suite_and_the_scorer_share_the_rule():
    from benchtwin.app import score
    from benchtwin.app.score import score_identification

    assert hs.excused_names is score.excused_names   # one rule, not two copies kept equal
    null = {"expect": [], "accept": ["nothing"]}
    res = {"named": [], "ambiguous": SET, "unexplained": False}
    ok = score_identification(res, null, 0.2)
    assert ok["correct"] and ok["spurious"] == [] and ok["unobservable_named"] == ["graduation_error", "tangential_motion"]
    bad = score_identification(res, null, 0.05)
    assert not bad["correct"] and bad["spurious"] == ["graduation_error", "tangential_motion"]
    alone = score_identification({"named": ["graduation_error"], "ambiguous": [], "unexplained": False}, null, 0.2)
    assert not alone["correct"] and alone["spurious"] == ["graduation_error"]


def test_with_x_probes_the_bearings_real_tangential_motion_may_be_named_but_not_a_division_error_alone():
    """With X probes the set {graduation_error, tangential_motion} is reported where the probes' δX,
    within its u, explains what the division error does (analysis/tracing/selection.py
    ``_measured_motion_alternative``); where the truth's axis holds that motion (≥ 0.1″) the set
    holds the bench's real cause and is no false positive. A division error named alone stays one."""
    from benchtwin.app.score import score_identification

    # X probes: nothing unobservable, but the truth's axis holds 0.6″ of −δX/r
    assert hs.classify("none", ["tangential_motion"], [], False, None, 0.6) == hs.OK_UNOBSERVABLE
    assert hs.classify("none", ["tangential_motion"], [], False, None, 0.05).startswith("FALSE")
    assert hs.classify("none", [], SET, False, None, 0.6) == hs.OK_UNOBSERVABLE
    assert hs.classify("none", [], SET, False, None, 0.05).startswith("FALSE")   # no motion to stand for
    assert hs.classify("none", ["graduation_error"], [], False, None, 0.6).startswith("FALSE")   # alone: not the set
    null = {"expect": [], "accept": ["nothing"]}
    assert score_identification({"named": ["tangential_motion"], "ambiguous": [], "unexplained": False},
                                null, None, 0.6)["correct"]
    assert score_identification({"named": ["graduation_error"], "ambiguous": SET, "unexplained": False},
                                null, None, 0.6)["correct"]
    s = score_identification({"named": [], "ambiguous": SET, "unexplained": False}, null, None, 0.05)
    assert not s["correct"] and s["spurious"] == ["graduation_error", "tangential_motion"]
    s = score_identification({"named": ["graduation_error"], "ambiguous": [], "unexplained": False}, null, None, 0.6)
    assert not s["correct"] and s["spurious"] == ["graduation_error"]


def test_an_unexplained_residual_is_not_penalised_where_the_unseen_motion_is_there():
    """Without X probes, where the truth's axis holds ≥ 0.1″ of −δX/r, that motion is the residual
    an exact analysis cannot remove: "unexplained" is not penalised where nothing is expected to be
    named (the reference generator's rule, its score.py docstring). Loop validation seed 794,
    tilt_abbe #0 (Y probes, worn bearings, the effect not observable): 3.84″ unseen, 1.54″ left and
    reported unexplained beside the set {graduation_error, tangential_motion}. Controls: below the
    floor, with X probes (the motion measured), an observable effect, a spurious name."""
    from benchtwin.app.score import score_identification

    not_obs = {"expect": ["tilt_abbe"], "accept": ["named", "ambiguous", "nothing"]}
    lv794 = {"named": [], "ambiguous": SET, "unexplained": True}
    s = score_identification(lv794, not_obs, 3.84)
    assert s["correct"] and s["outcome"] == "nothing" and s["unexplained_by_unseen_motion"], s
    assert not score_identification(lv794, not_obs, 0.05)["correct"]
    assert not score_identification(lv794, not_obs, None, 3.84)["correct"]          # X probes: measured
    assert not score_identification(lv794, {"expect": ["tilt_abbe"], "accept": ["named", "ambiguous"]}, 3.84)["correct"]
    assert not score_identification({**lv794, "named": ["ac_scale"]}, not_obs, 3.84)["correct"]
    null = {"expect": [], "accept": ["nothing"]}
    bare = {"named": [], "ambiguous": [], "unexplained": True}
    assert score_identification(bare, null, 0.64)["correct"]
    assert not score_identification(bare, null, 0.05)["correct"]
    # the hidden suite reads the same rule (one predicate, not a copy)
    from benchtwin.app import score

    assert hs.unexplained_by_unseen_motion is score.unexplained_by_unseen_motion
    assert hs.classify("none", [], [], True, 0.64) == hs.OK_UNSEEN_UNEXPLAINED and hs.is_correct("null_a", hs.OK_UNSEEN_UNEXPLAINED)
    assert hs.classify("none", [], [], True, 0.05) == "unexplained" and not hs.is_correct("null_a", "unexplained")
    assert hs.classify("none", [], [], True, None, 0.64) == "unexplained"          # X probes: the motion is measured
    assert not hs.is_correct("graduation_error", hs.OK_UNSEEN_UNEXPLAINED)
