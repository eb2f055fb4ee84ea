"""Issue 15, "Default run": `benchtwin run` on the embedded jia2019 scenario closes its loop.

Residual before the loop 8–16″ P-V over the 23 polygon stops, after ≤ 0.4 × before, and the
verdict not "unexplained" (docs/physics.md, "Why the default run's θ pattern looked
non-stationary"). Slow (the whole default run: ~40 s of simulation, 60 CCD frames, the analysis):
`pytest -m slow tests/test_default_run.py`.

The model after the loop takes (e, θ0) from the CCD combined with the comparison's first harmonic
(analysis/error_model.py ``refine_eccentricity``; docs/effects.md): with the CCD microscope's
vibration (twin/vibration.py) one sweep states e to u(e) ≈ 0.24 µm, as Jia's did, ≈ 2.3″ of first
harmonic at r = 22 mm, which no traced effect may take (graduation_error starts at order 2). The
two measurements of the first harmonic must agree within their u (χ², 2 dof), and with the CCD's
own (e, θ0) the residual after is reported too (measured on the default, seed 20190819: 15.55″
before, 7.62″ after with the CCD's e, 0.007″ with the refined e: with the mean, order 1 and graduation_error's orders 2…11 the
23 stops are interpolated, so the ratio is met trivially; the per-reading χ² after is the check)."""

from __future__ import annotations

import json
import math

import pytest

from benchtwin.cli import main


@pytest.mark.slow
def test_default_run_closes_its_loop(tmp_path):
    out = tmp_path / "run"
    assert main(["run", "-o", str(out), "--quiet"]) == 0
    r = json.loads((out / "results.json").read_text())
    before, after = r["residual_before"], r["residual_after"]
    assert before["n_points"] == 23
    assert 8.0 <= before["pv_arcsec"] <= 16.0, before
    assert after["pv_arcsec"] <= 0.4 * before["pv_arcsec"], after
    ref = r["eccentricity_refined"]
    assert ref["p_value"] > 0.01, ref                 # the CCD's e, θ0 and the comparison's agree
    assert ref["u_e_um"] < ref["ccd"]["u_e_um"] and ref["u_e_um"] == pytest.approx(
        1 / math.sqrt(ref["ccd"]["u_e_um"] ** -2 + ref["comparison"]["u_e_um"] ** -2), rel=0.05)
    assert ref["residual_after_ccd_e_pv_arcsec"] >= after["pv_arcsec"]
    assert "refined:eccentricity (CCD ⊕ comparison)" in after["added_terms"]
    assert r["residual_after_trace"]["p_value"] > 0.01, r["residual_after_trace"]   # χ² after: consistent
    assert r["close_loop"]["status"] != "unexplained" and not r["unexplained"], r["close_loop"]["status"]
    assert "graduation_error" in [e["name"] for e in r["identified_effects"]]
    # the cage's creep is in the noise, not a "θ pattern changing with time"
    tp = r["close_loop"]["signature"]["time_pattern"]
    assert not tp["significant"], tp
