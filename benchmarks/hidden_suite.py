"""Hidden-effect suite (issue 7): can the analysis name what the twin hid?

For every ``scenarios/hidden/*.toml`` and several seeds: simulate the scenario on the twin (its
``[hidden]`` effects change the truth only; the dataset never declares them), run the full analysis
``benchtwin.analysis.pipeline.analyze(dataset, out, progress=False, close_loop=True)`` and score
its outcome against the effect the scenario hid:

- **named**: the hidden effect is in ``results["identified_effects"]``;
- **ambiguous**: it is in one of ``results["ambiguous"]`` sets (named together with others the data
  cannot separate);
- **unexplained**: ``results["unexplained"]`` is true;
- **other**: something else was named (for a null: any named effect is a false identification).

Writes the table to ``docs/hidden-suite.md`` (scenario, expected effect, per-seed outcome, residual
RMS before / after the traced effect) and the raw outcomes to ``<work>/outcomes.json``.

    .venv/bin/python benchmarks/hidden_suite.py [--seeds 5] [--jobs 2] [--only NAME ...]
                                                [--work /tmp/hidden_suite] [--doc docs/hidden-suite.md]

Nothing here reads the truth to decide anything; truth/hidden.json is only quoted in the table.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HIDDEN_DIR = ROOT / "scenarios" / "hidden"
SEEDS = (11, 22, 33, 44, 55, 66, 77, 88, 99, 110)

# What each scenario should come out as (docs/effects.md, docs/hidden-suite.md, twin/hidden.py):
# name → (the library effect that should be reported, what counts as correct, accepted outcomes).
# "named": the effect identified alone; "ambiguous": inside an ambiguity set that the data cannot
# split (the set is the correct answer, with its separating measurement); "ok (nothing)" for nulls
# and absorbed effects; "ok (unexplained)" for the effect outside the library.
EXPECTED = {
    "null_a": ("none", "no effect named", {"ok (nothing)"}),
    "null_b": ("none", "no effect named (X probes, 3 heads, shifts)", {"ok (nothing)"}),
    "null_paper": ("tangential_motion",
                   "named (X probes, as the default jia2019 bench): the paper's waviness whirls leave (1 − 1/k) of "
                   "each lobe, which −δX/r describes and ∫δY does not (notes)", {"named"}),
    "graduation_error": ("graduation_error", "named (X probes rule out a tangential motion)", {"named"}),
    "optical_radius": ("optical_radius", "named or ambiguous with ccd_pixel_scale / ac_scale", {"named", "ambiguous"}),
    "ccd_pixel_scale": ("ccd_pixel_scale", "named or ambiguous with optical_radius / ac_scale", {"named", "ambiguous"}),
    "ccd_pixel_scale_pixel_only": ("none", "absorbed: the image scale is measured from the grating (Jia eq. 13)",
                                   {"ok (nothing)"}),
    "tangential_motion": ("tangential_motion", "named (X probes)", {"named"}),
    "tangential_motion_no_x": ("tangential_motion", "ambiguous with graduation_error (no X probes)", {"ambiguous"}),
    "tilt_abbe": ("tilt_abbe", "named or ambiguous with tangential_motion (one worn bearing: an L1 error only "
                               "rescales the whirl at the disk; a height gauge separates them)", {"named", "ambiguous"}),
    "ac_drift": ("none", "absorbed: the instrument's warm-up after switch-on (1.5″/K × 5 K through a 20-min lag, "
                         "issue 33 item 4) is taken by the per-run setup constants U_j but for 0.04″ RMS, below the "
                         "size gate (the old 20″/h rate·t was named)", {"ok (nothing)"}),
    "ac_scale": ("ac_scale", "named (self-calibration)", {"named"}),
    "sphere_form": ("sphere_form", "named or ambiguous with graduation_error / tangential_motion (only a Donaldson "
                                   "reversal or X probes tell form from motion)", {"named", "ambiguous"}),
    "torsion_hysteresis": ("torsion_hysteresis", "named (both directions in one mounting)", {"named"}),
    "polygon_pitch_ignored": ("none", "absorbed: β from the closure of all start faces", {"ok (nothing)"}),
    "interpolation_error": ("interpolation_error", "named (shifts 0/5/10°)", {"named"}),
    "thermal_growth": ("unexplained", "unexplained (outside the library: the pattern grows with time)",
                       {"ok (unexplained)"}),
    # issue 16
    "ac_nonlinearity": ("none", "nothing to identify: a DESIGN CASE, the largest non-linearity the autocollimator's "
                                "data sheet allows (detector 1° off square, 0.1 % distortion) adds ≤ 0.002″ over "
                                "±70″ (issue 33 item 4; the old 3e-4/″ needed an 88° tilt: "
                                "scenarios/hidden_templates/)", {"ok (nothing)"}),
    "selfa_graduation": ("graduation_error", "named (12-head self-calibration, X probes, shifts 0…14°)", {"named"}),
    "null_y_probes": ("none", "no effect named (Y probes only, both directions, 2 reps)", {"ok (nothing)"}),
}

#: residual after within this factor of the noise floor (issue 7)
FLOOR_FACTOR = 1.5
#: the corrected curve against the true encoder error (issue 16): |corrected − true| ≤ K_COVER·u at
#: ≥ COVER_FRAC of the curve's angles (the coverage a k = 2 interval states), after removing the one
#: constant a polygon calibration cannot know (Hsieh eq. 2: Σα = 0 per run)
K_COVER, COVER_FRAC = 2.0, 0.95


def _true_alpha_at_stops(dataset: Path, theta_deg: np.ndarray) -> np.ndarray | None:
    """The true α at the calibration points: per angle of the curve, the mean of truth/polygon.csv's
    ``alpha_arcsec`` over the polygon readings at that commanded stop (``target_deg`` within
    ``THETA_BIN_DEG``/2) — the same stops the measured curve averages. None without that table."""
    import csv

    from benchtwin.analysis.tracing import THETA_BIN_DEG

    f = dataset / "truth" / "polygon.csv"
    if not f.exists():
        return None
    with open(f, newline="") as fh:
        rows = list(csv.DictReader(fh))
    tg = np.mod(np.array([float(r["target_deg"]) for r in rows]), 360.0)
    a = np.array([float(r["alpha_arcsec"]) for r in rows])
    out = np.full(theta_deg.size, np.nan)
    for k, t in enumerate(np.mod(theta_deg, 360.0)):
        near = np.abs((tg - t + 180.0) % 360.0 - 180.0) <= THETA_BIN_DEG / 2.0
        if near.any():
            out[k] = float(np.mean(a[near]))
    return None if np.any(~np.isfinite(out)) else out


def _true_alpha_on_grid(dataset: Path, theta_deg: np.ndarray) -> np.ndarray | None:
    """truth/encoder_error.csv (the 0.1° grid of the ideal positioner) interpolated at θ."""
    import csv

    f = dataset / "truth" / "encoder_error.csv"
    if not f.exists():
        return None
    with open(f, newline="") as fh:
        rows = list(csv.DictReader(fh))
    g = np.array([float(r["theta_deg"]) for r in rows])
    a = np.array([float(r["alpha_arcsec"]) for r in rows])
    o = np.argsort(np.mod(g, 360.0))
    g, a = np.mod(g, 360.0)[o], a[o]
    return np.interp(np.mod(theta_deg, 360.0), np.concatenate([g, [g[0] + 360.0]]), np.concatenate([a, a[:1]]),
                     period=360.0)


def corrected_vs_truth(res: dict, dataset: Path) -> dict | None:
    """The corrected curve (``encoder_error_corrected_arcsec``) against the true encoder error AT ITS
    CALIBRATION POINTS.

    A calibration certificate states the curve at the angles it measured; between them it states no
    value (docs/effects.md, "The corrected curve"). So the truth compared is the true α at the very
    stops the curve averages (truth/polygon.csv), not truth/encoder_error.csv's 0.1° grid
    interpolated: a sub-division error repeats every grating period (0.051° for 7069 lines), which
    that grid undersamples — interpolated, it is 0.5″ RMS off the true α at the stops (the
    interpolation_error scenario) though the curve is right there. The grid is the fallback for a
    dataset without the polygon truth table. One constant a polygon calibration cannot know
    (Hsieh eq. 2: Σα = 0 per run) is removed (u-weighted mean)."""
    c = res.get("encoder_error_corrected_arcsec")
    if not c:
        return None
    th = np.asarray(c["theta_deg"], dtype=float)
    t = _true_alpha_at_stops(dataset, th)
    basis = "true α at the calibration points (truth/polygon.csv)"
    if t is None:
        t = _true_alpha_on_grid(dataset, th)
        basis = "truth/encoder_error.csv interpolated"
    if t is None:
        return None
    v, u = np.asarray(c["value"], dtype=float), np.asarray(c["u"], dtype=float)
    d = v - t
    w = 1.0 / u ** 2
    d = d - np.sum(w * d) / np.sum(w)
    z = np.abs(d) / u
    frac = float(np.mean(z <= K_COVER))
    return {"within_frac": frac, "max_z": float(np.max(z)), "rms_arcsec": float(np.sqrt(np.mean(d ** 2))),
            "u_rms_arcsec": float(np.sqrt(np.mean(u ** 2))), "ok": frac >= COVER_FRAC, "basis": basis,
            "applied": [x.get("effect") for x in c.get("corrections_applied") or []]}


NOTES = """## Notes: what the expected outcomes are, and why

**The bench of the suite.** The benches run on jia2019's physical ball bearings (issue 33; the
cage at its kinematic speed, `cage_slip = 0`), and the twin poses the shaft exactly. A whirl of the
axis moves the disk along X (tangentially at the head on +Y) as much as along Y. The head reads
−δX/r, while Jia eq. 5's radial term ∫δY dθ / r holds only 1/k of a k-lobed whirl. The ball sets'
own whirls leave 0.58″ RMS of −δX/r at the head (the truth's `floor.tangential_arcsec`; 4.07″ on
`tilt_abbe`'s worn pair), 0.59″ of it unobservable where a bench has no X probes. That is larger
than most hidden effects. So on a Y-probe bench the set {tangential_motion, graduation_error} is
what the data allow, and on a null naming the bearings' own tangential motion (or that set, without
X probes) is no false positive: the rule `benchtwin.app.score.excused_names`, shared with the
scorer and the reference generator ("ok (the bearings' −δX/r named)"). Since 2026-12-07 that covers
every ambiguity set that holds tangential_motion, as a set that holds an expected effect is right on
an effect bench: without X probes a one-parameter rescaling of ∫δY (sphere_form, tilt_abbe) can tie
with the motion (the twin's null of loop-validation seed 779). With X probes the motion is
measured and named; the set is reported there too where the probes' δX, within its u, explains
what a division error would (analysis/tracing/selection.py `_measured_motion_alternative`), and is
then no false positive either. An unexplained residual on a null without X probes, where that
unseen motion is there, is the motion an exact analysis cannot remove ("ok (unexplained: the
bearings' unseen −δX/r)", `benchtwin.app.score.unexplained_by_unseen_motion`, the scorer's rule
too). Only `tilt_abbe` keeps a worn bottom bearing, since ΔL1 needs a tilt motion to
act on.

**The noise floor.** Every scenario shares the declared bench of `null_a` and, for one seed, its
random draws: the spheres' 0.014 µm form (Jia sec. 4.1) read as motion by eq. 7, the
autocollimator's accuracy curve within its class, the reading noise. What the Jia model leaves on
`null_a` (0.04–0.08″ RMS per reading) is therefore the floor of that seed; the analysis itself
judges sizes against Hsieh's u_c of one α (≈ 0.12″, type A and B) and calls nothing below half of it
a finding (docs/effects.md, `SIZE_GATE`).

**`null_paper` (the default bench's layout; decided outcome: tangential_motion named).** One head
on +Y and, like the default `jia2019` bench, X probes, on the same physical ball bearings as the
others (it kept the paper's 2/3/5-lobed path waviness and 0.06 µm non-repeating motion until those
synthetic paths were retired, issue 33; its file's description still says so). The bearings' whirls
leave the tangential motion the model lacks, so "no effect" would be wrong; with the X probes it is
named with its gain. Without X probes the same residual is the set {tangential_motion,
graduation_error} (as `tangential_motion_no_x` shows).

**The encoder's display at the stop (issue 16).** The twin's servo holds the encoder count
nearest to each commanded stop, so the display differs from the stop by up to half the 0.39″
resolution; Hsieh eq. 3 takes it to be the nominal angle. Left in, that offset is a θ-fixed pattern
of ≈ 0.11″ RMS (0.12″ at k = 9 on 23 stops, the same in every seed: `truth/polygon.csv`,
`theta_deg − target_deg`), which on the richer benches (2 reps × 2 directions, 15 shifts) was read
as a division error: `null_y_probes` named {graduation_error, tangential_motion} in 2 of 5 seeds,
`ac_nonlinearity` paired ac_scale with a k = 9 "division error" (blind to 3 heads) in 2 of 5, and
`selfa_graduation` ended "unexplained" (χ² after p = 1e-55, "the θ pattern changes with time":
each shift has its own offsets) in 5 of 5. The analysis now adds the recorded display offset back
(`pipeline.polygon_table`, docs/effects.md). The other 3 `null_y_probes` seeds were "unexplained"
on a direction half-difference of 0.01″ and a drift of 0.01″ RMS, resolved at z ≈ 5 by 1058
readings: the size gate of every candidate (½ u_c) now applies to them too.

**The corrected curve.** Where an effect is identified, `encoder_error_corrected_arcsec` (the
measured curve minus the identified reference-chain artefacts, with their u) is compared with the
twin's true encoder error AT THE CALIBRATION POINTS: at each angle of the curve, the mean true α of
the polygon stops it averages (truth/polygon.csv), the one constant a polygon calibration cannot
know removed; correct when ≥ 95 % of the angles lie within 2u. A certificate states the curve at
the angles it measured and no value between them (docs/effects.md): `interpolation_error`'s
sub-division error repeats every grating period (0.051°), which truth/encoder_error.csv's 0.1° grid
undersamples — interpolated from that grid the "truth" at the stops was 0.50″ RMS off the true α
there (0/5 before), while the curve is 0.10″ from the true α at its own points.

**`torsion_hysteresis` on the physical twin.** The hysteresis follows the approach to each stop
(the last move), not the run's label: a run's first stop is read where the previous run left the
stage, so the two ends of the curve (0°, 344°) carry the other direction's twist. The analysis
takes the approach from the readings' time order (`tracing.approach_direction`, docs/effects.md);
fitted on the label, those 2 of 23 angles were 0.48″ off (91 % within 2u in 5/5 seeds). What the
traced effect leaves (0.56–0.60″) is the servo's stick-slip: the drive holds at rest whatever torque
its settling leaves, so the twist scatters from stop to stop between −T/k and +T/k (truth/polygon.csv
`twist_arcsec`: 0.56″ RMS around ±0.44″, nothing of it fixed to θ or the face). No effect can
remove a scatter that repeats nowhere; the analysis counts it in the readings' repeatability (type
A, 0.59″ vs 0.10″ on `null_a`), and the floor here includes the readings' non-repeating scatter
beyond `null_a`'s, as it includes `null_paper`'s non-repeating spindle motion.

**`selfa_graduation`'s spectrum.** The disk's mounted form (k^−2.5, issue 33 item 4) puts 1.04″ at
k = 2, 0.38″ at k = 3, 0.18″ at k = 4 and less at every higher order, plus a 0.05″ ruling walk.
graduation_error fits the orders its harmonic test passes (2…5 and 11 on seed 11); the many small
orders left each stay below the test's threshold (Bonferroni over 20 orders at 1e-3, z ≈ 4.1, with
a u that is mostly the model's own type B — the spheres' 0.014 µm form bound read as motion by the
∫δY term, ≈ 0.027″ at k = 3). What stays is 0.117″ (median), at worst 1.39× the floor (the old
template-shaped k = 3…8 terms left 1.5–1.9×). A bound of what the model's uncertainty lets the
analysis claim, not a missed effect; a measured sphere form (Donaldson reversal) would lower it.

**Other expected outcomes.** `graduation_error` has X probes (they rule out a tangential motion);
`tangential_motion_no_x` is the same hidden motion without them: the set {graduation_error,
tangential_motion}. `sphere_form` has no X probes: a form and a motion without tangential component
give the same residual, and a division error fits it harmonic by harmonic, so the set containing
sphere_form is correct (a Donaldson reversal separates them). `tilt_abbe`'s tilt motion comes from one
worn bearing, so every point of the shaft moves with the same lobes: a wrong L1 only rescales the
extrapolated motion at the disk, which a whirl that is not quite circular does too — named, or the
set {tilt_abbe, tangential_motion, …} (a height gauge separates them). `thermal_growth` (outside the
library) must be unexplained: its 7th harmonic grows from run to run and the stationarity test
refuses every stationary effect of the library.

**Physical causes (issue 33 item 4): which datasets changed, and why.** Eight scenarios stated their
effect in the analysis's own shape (exactly 0.8″ at k = 4 and 0.5″ at k = 6; c·sin(mLg + φ);
rate·t; a·cos(kθ − φ) on X alone; autocollimator coefficients that needed a detector tilted 84°
and 88°). They now state causes (twin/hidden.py, docs/physics.md), so their datasets changed:
`graduation_error` (the disk's mounted form, orders 2…200 ∝ k^−1.5, 0.7″ rms, + a 0.05″ ruling
walk) and `selfa_graduation` (∝ k^−2.5, 0.8″: 1.04″ at k = 2) have content at every order;
`interpolation_error` is Heydemann's error of the head's signals (offsets 1.1/1.3 %, amplitude
ratio 1.006, quadrature 0.48°: the same 0.50″ / 0.15″ harmonics, which ARE the physics' form);
`tangential_motion` / `_no_x` are an undeclared race waviness (3 and 5 lobes) whirling the axis
through the bearing model, so the Y probes see it too; `ac_scale` is a focal length +1 % and a
detector 1° off square (the data sheet's limits: a scale error, no measurable non-linearity).
Two became design cases whose expected outcome is "nothing": `ac_nonlinearity` (the largest
non-linearity the data sheet allows adds ≤ 0.002″ over the readings' ±70″) and `ac_drift` (the
instrument's warm-up after switch-on, 1.5″/K × 5 K through a 20-min lag: 22″/h at switch-on, but by
the polygon sweeps it has slowed and the per-run constants U_j take all but 0.04″ RMS of it; α's
residual 0.121″ against the floor's 0.104″ on seed 11). The old template-shaped `graduation_error`
and `ac_nonlinearity` are kept as scenarios/hidden_templates/ for the slow tests that exercise
the analysis and calibrate-twin on them. How much of each physical effect its template misses:
docs/effects.md, "Hidden effects against the templates". The other rows were not re-run: their
scenarios and the twin's physics for them did not change (their datasets are byte-identical).
"""


def _names(items) -> list[str]:
    out = []
    for it in items or []:
        if isinstance(it, dict):
            out.append(str(it.get("name")))
        else:
            out.append(str(it))
    return out


def _ambiguous_sets(amb) -> list[list[str]]:
    sets = []
    for a in amb or []:
        if isinstance(a, dict):
            sets.append([str(n) for n in a.get("names", [])])
        elif isinstance(a, (list, tuple)):
            sets.append([str(n) for n in a])
    return sets


#: the truth's −δX/r that a bench without X probes cannot see (app/score.py ``_floor``:
#: ``unattributable_arcsec``, orders 2…10), from which on naming tangential_motion, or the set
#: {tangential_motion, graduation_error} that only X probes separate, is no false positive: the
#: independent reference generator's verdict rule (../shared/reference-generator/score.py), adopted
#: here since the hidden benches run on physical ball bearings (issue 33), whose X motion is real.
#: The rule is the scorer's own (``excused_names``), imported, not a copy kept equal.
from benchtwin.app.score import UNOBSERVABLE_MIN_ARCSEC, excused_names, unexplained_by_unseen_motion  # noqa: E402,F401
OK_UNOBSERVABLE = "ok (the bearings' −δX/r named)"
OK_UNSEEN_UNEXPLAINED = "ok (unexplained: the bearings' unseen −δX/r)"


def classify(expect: str, named: list[str], ambiguous: list[list[str]], unexplained: bool,
             unobservable_arcsec: float | None = None, tangential_arcsec: float | None = None) -> str:
    """The outcome against the expected effect. On a null, tangential_motion is no false positive
    where the truth's axis holds ≥ UNOBSERVABLE_MIN_ARCSEC of −δX/r (``tangential_arcsec``: the
    bearings' real X motion, or ``unobservable_arcsec`` where no X probes see it), nor its set with
    graduation_error where that motion is there: ``benchtwin.app.score.excused_names``, the
    scorer's one rule; nor is an unexplained residual where the unseen motion is there
    (``benchtwin.app.score.unexplained_by_unseen_motion``)."""
    in_amb = any(expect in s for s in ambiguous)
    if expect == "none":
        if named or ambiguous:
            allowed = excused_names(ambiguous, unobservable_arcsec, tangential_arcsec)
            if allowed and set(named) | {n for st in ambiguous for n in st} <= allowed:
                return OK_UNOBSERVABLE
            return "FALSE: " + ",".join(named + [n for s in ambiguous for n in s])
        if unexplained_by_unseen_motion(unexplained, unobservable_arcsec):
            return OK_UNSEEN_UNEXPLAINED
        return "unexplained" if unexplained else "ok (nothing)"
    if expect == "unexplained":
        if unexplained:
            return "ok (unexplained)"
        return ("named " + ",".join(named)) if named else "nothing"
    if expect in named and not in_amb:
        return "named"
    if in_amb or expect in named:
        return "ambiguous"
    if unexplained:
        return "unexplained" + (" (+" + ",".join(named) + ")" if named else "")
    return ("other: " + ",".join(named)) if named else "nothing"


def run_one(path: str, seed: int, work: str, datasets_from: str | None = None) -> dict:
    """Simulate + analyse one (scenario, seed); returns the outcome record (never raises).
    ``datasets_from``: an earlier suite's work folder whose ``NAME/seedS/dataset`` (complete: its
    manifest written last) is analysed instead of simulating again — only valid while twin/,
    scenarios/ and models/ are unchanged since it was written (the caller's responsibility; the
    record says which dataset was used)."""
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import simulate

    name = Path(path).stem
    rec = {"scenario": name, "seed": seed}
    d = Path(work) / name / f"seed{seed}"
    try:
        t0 = time.time()
        old = Path(datasets_from) / name / f"seed{seed}" / "dataset" if datasets_from else None
        if old is not None and (old / "manifest.json").exists():
            ds = old
            rec["dataset_reused"] = str(old)
        else:
            sc = load_scenario(path).with_overrides({"scenario.seed": seed})
            ds = simulate(sc, d / "dataset", progress=False, backend="analytic")
        rec["simulate_s"] = round(time.time() - t0, 1)
    except Exception as exc:  # noqa: BLE001 - recorded in the table
        rec["error"] = f"simulate: {type(exc).__name__}: {exc}"
        rec["traceback"] = traceback.format_exc()
        return rec
    try:
        from benchtwin.analysis.pipeline import analyze
    except Exception as exc:  # noqa: BLE001
        rec["error"] = f"analyze not importable: {type(exc).__name__}: {exc}"
        return rec
    try:
        t0 = time.time()
        res = analyze(ds, d / "analysis", progress=False, close_loop=True)["results"]
        rec["analyze_s"] = round(time.time() - t0, 1)
    except Exception as exc:  # noqa: BLE001
        rec["error"] = f"analyze: {type(exc).__name__}: {exc}"
        rec["traceback"] = traceback.format_exc()
        return rec
    rec["named"] = _names(res.get("identified_effects"))
    rec["ambiguous"] = _ambiguous_sets(res.get("ambiguous"))
    rec["unexplained"] = bool(res.get("unexplained"))
    rec["status"] = (res.get("close_loop") or {}).get("status")
    rb, ra = res.get("residual_before") or {}, res.get("residual_after") or {}
    rec["rms_before"] = rb.get("rms_arcsec")
    rec["rms_after"] = ra.get("rms_arcsec")
    rec["params"] = {e.get("name"): e.get("params") for e in res.get("identified_effects") or [] if isinstance(e, dict)}
    rec["u"] = {e.get("name"): e.get("u") for e in res.get("identified_effects") or [] if isinstance(e, dict)}
    expect = EXPECTED.get(name, ("?", "", set()))[0]
    try:   # the truth's unobservable −δX/r (None with X probes): only for the verdict below
        from benchtwin.app.score import read_truth

        fl = read_truth(Path(ds) / "truth", Path(ds))["floor"]
        rec["unobservable_arcsec"], rec["tangential_arcsec"] = fl.get("unattributable_arcsec"), fl.get("tangential_arcsec")
    except Exception as exc:  # noqa: BLE001 - recorded in the table
        rec["unobservable_arcsec"] = rec["tangential_arcsec"] = None
        rec["unobservable_error"] = f"{type(exc).__name__}: {exc}"
    rec["outcome"] = classify(expect, rec["named"], rec["ambiguous"], rec["unexplained"], rec["unobservable_arcsec"],
                              rec["tangential_arcsec"])
    # the tracing's residual per polygon reading (the basis of the noise floor below)
    rt, rat = res.get("residual_test") or {}, res.get("residual_after_trace") or {}
    rec["trace_rms_before"] = rt.get("rms_arcsec")
    rec["trace_rms_after"] = rat.get("rms_arcsec")
    rec["trace_p_after"] = rat.get("p_value")
    rec["noise_floor_u_c"] = rt.get("noise_floor_arcsec")
    rec["async_arcsec"] = (rt.get("async_motion") or {}).get("per_stop_arcsec") or 0.0
    # the readings' own scatter (type A: residuals of eq. 3 with α per shift and direction, one offset
    # per run-row): what repeats nowhere, the basis of the non-repeating part of the floor below
    rec["s_reading"] = (res.get("repeatability") or {}).get("pooled_sd_eps_arcsec")
    rec["ccd_rejected"] = [r.get("file") for r in res.get("ccd_rejected_frames") or []]
    if rec["named"]:  # where an effect is identified: the corrected curve against the true α
        try:
            rec["corrected"] = corrected_vs_truth(res, Path(ds))
        except Exception as exc:  # noqa: BLE001 - recorded in the table
            rec["corrected"] = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
    return rec


def _fmt(x) -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.3f}"


def _hidden_summary(path: Path) -> str:
    import tomllib

    raw = tomllib.loads(path.read_text(encoding="utf-8"))
    h = raw.get("hidden") or {}
    if not h:
        return "—"
    parts = []
    for eff, params in h.items():
        kv = []
        for k, v in params.items():
            if isinstance(v, list) and v and isinstance(v[0], dict):
                v = "; ".join(f"k{l['order']} {l['amplitude']}" for l in v)
            elif isinstance(v, list):
                v = ", ".join(map(str, v))
            kv.append(f"{k} = {v}")
        parts.append(f"`{eff}`: " + ", ".join(kv))
    return "<br>".join(parts)


def is_correct(name: str, outcome: str) -> bool:
    accepted = EXPECTED.get(name, ("?", "", set()))[2]
    return outcome in accepted or (outcome in (OK_UNOBSERVABLE, OK_UNSEEN_UNEXPLAINED) and "ok (nothing)" in accepted)


def reclassify(rec: dict) -> dict:
    """A stored record's outcome again, by today's rule (``classify``) from what the analysis
    reported (named, ambiguous sets, unexplained) and the truth's −δX/r figures it recorded: a
    rule change then reaches the document without analysing again. Records without an analysis
    (errors) are kept as they are."""
    if "named" not in rec or "error" in rec:
        return rec
    expect = EXPECTED.get(rec["scenario"], ("?", "", set()))[0]
    return {**rec, "outcome": classify(expect, rec["named"], rec["ambiguous"], rec["unexplained"],
                                       rec.get("unobservable_arcsec"), rec.get("tangential_arcsec"))}


def render_stored(doc_input: dict, doc: Path) -> None:
    """The document from its stored input (``--store``): the one renderer of the run and the test."""
    write_doc(doc, doc_input["records"], doc_input["seeds"], doc_input.get("elapsed_s") or float("nan"),
              doc_input.get("previous"),
              doc_input.get("previous_note", ""), doc_input.get("preface", ""), doc_input.get("jobs"))


def previous_rows(old_doc: Path, skip: set[str]) -> list[str]:
    """The table rows of an earlier docs/hidden-suite.md for the scenarios not in ``skip``."""
    out = []
    for line in old_doc.read_text(encoding="utf-8").splitlines():
        if line.startswith("| `"):
            name = line.split("`")[1]
            if name not in skip:
                out.append(line)
    return out


def write_doc(doc: Path, records: list[dict], seeds: list[int], elapsed_s: float,
              previous: list[str] | None = None, previous_note: str = "", preface: str = "",
              jobs: int | None = None) -> None:
    by: dict[str, dict[int, dict]] = {}
    for r in records:
        by.setdefault(r["scenario"], {})[r["seed"]] = r
    # the noise floor of a seed: what the Jia model leaves on the same declared bench with nothing
    # hidden (null_a, same seed → same declared draws: sphere form, autocollimator accuracy, noise)
    floor = {s: (by.get("null_a", {}).get(s) or {}).get("trace_rms_before") for s in seeds}
    lines = [
        "# Hidden-effect suite (issue 7)",
        "",
        *([preface, ""] if preface else []),
        "Generated by `benchmarks/hidden_suite.py` — do not edit by hand. Each scenario of",
        "`scenarios/hidden/` hides one effect in the twin's truth (twin/hidden.py: implemented physically,",
        "never with the analysis's formula; the manifest and tables never declare it). The dataset is",
        "simulated for each seed and analysed with `analysis.pipeline.analyze(..., close_loop=True)`;",
        "the outcome is scored against the hidden effect:",
        "",
        "- **named**: the hidden effect is identified alone; **ambiguous**: it is in an ambiguity set;",
        "  **unexplained**: the analysis reports an unexplained residual; **ok (nothing)**: a null or an",
        "  effect the measurement absorbs gives no identification; **FALSE**: something was named on a",
        "  null / absorbed scenario; **other**: a different effect was named; **nothing**: no finding.",
        "  Which outcomes count as correct is the `expected` column (`EXPECTED` in the script, reasons in",
        "  the notes below).",
        "- RMS before / after: the tracing's residual per polygon reading (α − Jia model, closure-centred),",
        "  before and after the traced effect(s), arcsec, median over seeds.",
        "- floor: the noise floor of each seed = the RMS the Jia model leaves on `null_a` with the same seed",
        "  (same declared bench and draws, nothing hidden), combined with the non-repeating motion the probes",
        "  measured where the bench has one (`null_paper`: its X part at the stops, r·σ_async), and with",
        "  the readings' non-repeating scatter beyond `null_a`'s: √(s² − s_null²), s the analysis's type A",
        "  repeatability of one reading (`repeatability.pooled_sd_eps_arcsec`: residuals of Hsieh eq. 3 with α",
        "  per shift and direction) — on `torsion_hysteresis` the servo's stick-slip leaves a different",
        "  twist at every stop (0.58″ RMS around ±h), which no deterministic effect can remove (notes).",
        "  **after/floor** is the worst seed's ratio, **after/null_a** the same against `null_a`'s floor alone;",
        f"  issue 7 asks after/floor ≤ {FLOOR_FACTOR} where an effect is identified (named or ambiguous).",
        "",
        f"Seeds: {', '.join(map(str, seeds))}."
        + (f" Wall time {elapsed_s / 60:.1f} min" + (f" ({jobs} worker{'s' if jobs != 1 else ''})." if jobs else ".")
           if math.isfinite(elapsed_s) else "")
        + (f" Datasets of {sum(1 for r in records if r.get('dataset_reused'))} of {len(records)} runs reused from "
           "an earlier run on the same twin (`--datasets-from`; analysed anew)."
           if any(r.get("dataset_reused") for r in records) else ""),
        "",
        "| scenario | hidden (truth) | expected | " + " | ".join(f"seed {s}" for s in seeds)
        + " | correct | RMS before ″ | RMS after ″ | after/floor (worst) | after/null_a (worst) | corrected within 2u |",
        "| --- | --- | --- | " + " | ".join("---" for _ in seeds) + " | --- | --- | --- | --- | --- | --- |",
    ]
    s_null = {s: (by.get("null_a", {}).get(s) or {}).get("s_reading") for s in seeds}
    total_ok = total = 0
    floor_fail = []
    floor0_fail = []
    cover_fail = []
    cover_ok = cover_n = 0

    def med(v):
        return v[len(v) // 2] if v else None

    for name in sorted(by):
        rs = by[name]
        why = EXPECTED.get(name, ("?", "", set()))[1]
        cells, ok = [], 0
        ratios, ratios0 = [], []
        for s in seeds:
            r = rs.get(s)
            if r is None:
                cells.append("not run")
                continue
            if "error" in r:
                cells.append("error: " + r["error"][:60].replace("|", "/"))
                continue
            o = r["outcome"]
            good = is_correct(name, o)
            cells.append(o if good else f"**{o}**")
            ok += good
            ra, fl = r.get("trace_rms_after"), floor.get(s)
            if fl and r.get("async_arcsec"):  # the bench's own non-repeating motion (null_paper)
                fl = math.hypot(fl, r["async_arcsec"])
            fl0 = fl
            sr, sn = r.get("s_reading"), s_null.get(s)
            excess = math.sqrt(max(sr ** 2 - sn ** 2, 0.0)) if sr is not None and sn is not None else 0.0
            if fl:  # the readings' own non-repeating scatter beyond the null bench's
                fl = math.hypot(fl, excess)
            if o in ("named", "ambiguous") and ra is not None and fl:
                ratios.append(ra / fl)
                ratios0.append(ra / fl0)
                if ra / fl > FLOOR_FACTOR:
                    floor_fail.append(f"`{name}` seed {s}: {ra:.3f}″ after vs floor {fl:.3f}″ ({ra / fl:.2f}×)")
                if ra / fl0 > FLOOR_FACTOR:
                    floor0_fail.append(f"`{name}` seed {s}: {ra:.3f}″ after vs null_a floor {fl0:.3f}″ "
                                       f"({ra / fl0:.2f}×; non-repeating scatter of its readings beyond null_a's "
                                       f"{excess:.3f}″)")
        n = sum(1 for s in seeds if s in rs and "error" not in rs[s])
        cov = [(s, rs[s]["corrected"]) for s in seeds if s in rs and rs[s].get("corrected")]
        c_ok = sum(1 for _, c in cov if c.get("ok"))
        cover_ok += c_ok
        cover_n += len(cov)
        for s, c in cov:
            if not c.get("ok"):
                cover_fail.append(f"`{name}` seed {s}: " + (c.get("error") or (
                    f"{100 * c['within_frac']:.0f} % of the angles within 2u (worst {c['max_z']:.1f}u; "
                    f"{c['rms_arcsec']:.3f}″ RMS from the true α, u {c['u_rms_arcsec']:.3f}″)")))
        total_ok += ok
        total += n
        rb = sorted(r["trace_rms_before"] for r in rs.values() if r.get("trace_rms_before") is not None)
        ra = sorted(r["trace_rms_after"] for r in rs.values() if r.get("trace_rms_after") is not None)
        lines.append(f"| `{name}` | {_hidden_summary(HIDDEN_DIR / (name + '.toml'))} | {why} | "
                     + " | ".join(cells) + f" | {ok}/{n} | {_fmt(med(rb))} | {_fmt(med(ra))} | "
                     + (f"{max(ratios):.2f}" if ratios else "–") + " | "
                     + (f"{max(ratios0):.2f}" if ratios0 else "–") + " | "
                     + (f"{c_ok}/{len(cov)}" if cov else "–") + " |")
    lines += ["", f"**Correct outcomes: {total_ok}/{total}.** Floors (null_a, per seed): "
              + ", ".join(f"{s}: {_fmt(floor[s])}″" for s in seeds) + ".", ""]
    if floor_fail:
        lines += [f"Residual after above {FLOOR_FACTOR}× the floor:", ""] + [f"- {x}" for x in floor_fail] + [""]
    else:
        lines += [f"Every identified case ends within {FLOOR_FACTOR}× the floor.", ""]
    if floor0_fail:
        lines += [f"Residual after above {FLOOR_FACTOR}× the `null_a` floor alone:", ""] + [f"- {x}" for x in floor0_fail] + [""]
    lines += [f"**Corrected curve within {K_COVER:g}u of the true encoder error** (issue 16; where an effect is "
              f"identified: `encoder_error_corrected_arcsec` against the true α at its calibration points, "
              f"truth/polygon.csv, the one constant a polygon cannot know removed, ≥ {100 * COVER_FRAC:.0f} % of the angles within {K_COVER:g}u): "
              f"{cover_ok}/{cover_n}.", ""]
    if cover_fail:
        lines += [f"- {x}" for x in cover_fail] + [""]
    errs = [r for r in records if "error" in r]
    if errs:
        lines += ["## Errors", ""]
        for r in errs:
            lines.append(f"- `{r['scenario']}` seed {r['seed']}: {r['error']}")
        lines.append("")
    rej = [(r["scenario"], r["seed"], r["ccd_rejected"]) for r in records if r.get("ccd_rejected")]
    if rej:
        lines += ["CCD frames rejected and dropped by the analysis (the others fitted, `ccd_rejected_frames`): "
                  + "; ".join(f"`{n}` seed {s}: {', '.join(f)}" for n, s, f in sorted(rej)) + ".", ""]
    if previous:
        lines += ["## Scenarios not re-run with this analysis", "", previous_note, "",
                  "| scenario | hidden (truth) | expected | " + " | ".join(f"seed {s}" for s in seeds)
                  + " | correct | RMS before ″ | RMS after ″ | after/floor (worst) | after/null_a (worst) "
                  "| corrected within 2u (its scoring) |",
                  "| --- | --- | --- | " + " | ".join("---" for _ in seeds) + " | --- | --- | --- | --- | --- | --- |"]
        lines += previous + [""]
    lines += [NOTES, "## Identified effects and their parameters (first seed; value ± u)", ""]
    for name in sorted(by):
        r = by[name].get(seeds[0]) or {}
        if r.get("params"):
            lines.append(f"- `{name}`: " + "; ".join(
                f"{k}: " + ", ".join(f"{p} = {v:.4g} ± {r.get('u', {}).get(k, {}).get(p, float('nan')):.2g}"
                                     for p, v in (ps or {}).items()) for k, ps in r["params"].items()))
    lines.append("")
    doc.write_text("\n".join(lines), encoding="utf-8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--work", default="/tmp/hidden_suite")
    ap.add_argument("--doc", default=str(ROOT / "docs" / "hidden-suite.md"))
    ap.add_argument("--from-json", nargs="*", default=None,
                    help="rewrite the document from previous outcomes.json files (merged)")
    ap.add_argument("--keep-rows-from", default=None,
                    help="an earlier hidden-suite.md: its rows of the scenarios not run are kept, labelled as such")
    ap.add_argument("--datasets-from", default=None,
                    help="analyse the datasets of an earlier --work folder instead of simulating (same twin only)")
    ap.add_argument("--preface", default="", help="a paragraph under the title (with --from-json)")
    ap.add_argument("--store", default=None,
                    help="write the document's input (records, seeds, preface) to this JSON file (docs/data/hidden-suite.json)")
    ap.add_argument("--keep-note", default="Rows copied from the previous document (an earlier analysis): not re-run.")
    a = ap.parse_args(argv)
    seeds = list(SEEDS[: a.seeds])
    if a.from_json:
        records = [reclassify(r) for f in a.from_json for r in json.loads(Path(f).read_text())]
        prev = (previous_rows(Path(a.keep_rows_from), {r["scenario"] for r in records})
                if a.keep_rows_from else None)
        doc_input = {"records": records, "seeds": sorted({r["seed"] for r in records}), "previous": prev,
                     "previous_note": a.keep_note, "preface": a.preface}
        render_stored(doc_input, Path(a.doc))
        if a.store:   # the document's whole input: tests/app/test_hidden_suite_doc.py renders it again
            Path(a.store).write_text(json.dumps(doc_input, indent=1, default=str) + "\n")
        print(f"wrote {a.doc}" + (f" and {a.store}" if a.store else ""))
        return 0
    paths = sorted(HIDDEN_DIR.glob("*.toml"))
    if a.only:  # in the order given: the run order (the first finish first when time is short)
        by_name = {p.stem: p for p in paths}
        paths = [by_name[n] for n in dict.fromkeys(a.only) if n in by_name]
    try:
        import benchtwin.analysis.pipeline as _p  # noqa: F401

        if not hasattr(_p, "analyze"):
            raise ImportError("benchtwin.analysis.pipeline has no analyze()")
    except Exception as exc:  # noqa: BLE001
        print(f"analysis pipeline not importable ({exc}); nothing run", file=sys.stderr)
        return 2
    jobs = [(str(p), s) for p in paths for s in seeds]
    t0 = time.time()
    records = []
    out_json = Path(a.work) / "outcomes.json"
    out_json.parent.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(max_workers=max(1, a.jobs)) as ex:
        futs = {ex.submit(run_one, p, s, a.work, a.datasets_from): (p, s) for p, s in jobs}
        for f in as_completed(futs):
            r = f.result()
            records.append(r)
            print(f"[{len(records)}/{len(jobs)}] {r['scenario']} seed {r['seed']}: "
                  f"{r.get('outcome', r.get('error'))}", flush=True)
            out_json.write_text(json.dumps(records, indent=1, default=str))
    doc_input = {"records": records, "seeds": seeds, "elapsed_s": time.time() - t0, "preface": a.preface,
                 "jobs": max(1, a.jobs)}
    render_stored(doc_input, Path(a.doc))
    if a.store:
        Path(a.store).write_text(json.dumps(doc_input, indent=1, default=str) + "\n")
    print(f"wrote {a.doc}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
