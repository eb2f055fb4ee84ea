"""Issue 15, "Default run", and issue 32: `benchtwin run` on the embedded jia2019 scenario closes its
loop and tells one story in results.json, the score and the certificate.

What the default bench hides from Jia's model is its declared graduation error (the Mercury 3000's
3″ RMS, scenarios/jia2019.toml): the loop names graduation_error and `benchtwin score` calls that
right. Residual before the loop 8–16″ P-V over the 23 polygon stops. After it, the model is one
fit on the stops: the graduation orders the tracing resolved, the first harmonic and α's constant.
With the probes in their 80 mm arm (the default since 2026-12-06; the analysis separates the arm's
drift, analysis/probe_drift.py) the tracing resolves orders 2…4, 6…9 and 11 (seed 20190819): 19
parameters on 23 stops, dof 4, so the residual at the stops is a test (χ² and p stated) and each
stop is predicted by the fit made without it (leave-one-out 1.69″ against 4.00″ RMS before: ≤ 0.6 ×,
issue 32's bar). Where a sampling leaves dof < 3, results.json says it cannot test the model
(`sampling_note`, tests/analysis/test_fit_statistics.py). The check per
reading: after ≤ 0.4 × before (measured: 4.07″ → 0.76″) with the χ² of the tracing consistent. The
refined e (CCD ⊕ the comparison's first harmonic, with the prior on a first-order graduation term)
is within 2u of the truth (7.123 ± 0.093 µm against 7.100 µm).
Slow (the whole default run: ~40 s of simulation, 60 CCD frames, the analysis):
`pytest -m slow tests/app/test_default_run.py`."""

from __future__ import annotations

import json
import math

import pytest

from benchtwin.cli import main


@pytest.mark.slow
def test_default_run_closes_its_loop(tmp_path):
    from benchtwin.app.score import score_files

    out = tmp_path / "run"
    assert main(["run", "-o", str(out), "--quiet"]) == 0
    r = json.loads((out / "results.json").read_text())
    before, after = r["residual_before"], r["residual_after"]
    assert before["n_points"] == 23 and before["n_params"] == 1 and before["dof"] == 22
    assert 8.0 <= before["pv_arcsec"] <= 16.0, before
    # the model after leaves degrees of freedom at the stops: a test, and a prediction of each stop
    assert after["n_points"] == 23 and after["n_params"] + after["dof"] == 23, after
    assert after["dof"] >= 3 and after["p_value"] is not None and "sampling_note" not in after, after
    assert after["loo_rms_arcsec"] <= 0.6 * before["rms_arcsec"], (after["loo_rms_arcsec"], before["rms_arcsec"])
    # per reading, the same model after the loop
    assert after["per_reading_rms_arcsec"] <= 0.4 * r["residual_test"]["rms_arcsec"], after
    ref = r["eccentricity_refined"]
    assert ref["p_value"] > 0.01, ref                 # the CCD's e, θ0 and the comparison's agree
    assert ref["u_e_um"] < ref["ccd"]["u_e_um"] and ref["u_e_um"] == pytest.approx(
        1 / math.sqrt(ref["ccd"]["u_e_um"] ** -2 + ref["comparison"]["u_e_um"] ** -2), rel=0.05)
    assert ref["k1_prior"]["u_arcsec"] > 0
    # e about the axis of rotation (installed ⊕ the inner races' synchronous run-out; docs/scoring.md):
    # the refined e is 0.01 u from it (0.25 u from the installed 7.1 µm), θ0 0.34 u (−1.57 u)
    tb = json.loads((out / "truth" / "bench.json").read_text())
    e_true = tb["disk_eccentricity_axis_m"] * 1e6
    assert abs(ref["e_um"] - e_true) <= 2 * ref["u_e_um"], (ref["e_um"], ref["u_e_um"], e_true)
    d_theta0 = (ref["theta0_deg"] - math.degrees(tb["theta0_axis_rad"]) + 180.0) % 360.0 - 180.0
    assert abs(d_theta0) <= 2 * ref["u_theta0_deg"], (ref["theta0_deg"], ref["u_theta0_deg"], d_theta0)
    assert r["residual_after_trace"]["p_value"] > 0.01, r["residual_after_trace"]   # χ² after: consistent
    assert r["close_loop"]["status"] != "unexplained" and not r["unexplained"], r["close_loop"]["status"]
    assert "graduation_error" in [e["name"] for e in r["identified_effects"]]
    # the cage's creep is in the noise, not a "θ pattern changing with time"
    tp = r["close_loop"]["signature"]["time_pattern"]
    assert not tp["significant"], tp
    # the score tells the same story: the declared graduation error named, e within 2u
    s = score_files(out / "results.json", out / "dataset", out / "truth")
    assert s["identification_correct"] is True and not s["spurious"], s["identification"]
    assert abs(s["e_z"]) <= 2.0
