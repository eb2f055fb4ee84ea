"""Issue 15, "Default run": `benchtwin run` on the embedded jia2019 scenario closes its loop.

Residual before the loop 8–16″ P-V over the 23 polygon stops, after ≤ 0.4 × before, and the
verdict not "unexplained" (docs/physics.md, "Why the default run's θ pattern looked
non-stationary"). Slow (the whole default run: ~40 s of simulation, 60 CCD frames, the analysis):
`pytest -m slow tests/test_default_run.py`.

"After" is taken apart (docs/physics.md, "Non-repeatability of the jia2019 bench"): with the CCD
microscope's vibration (twin/vibration.py) one sweep states e to u(e) ≈ 0.24 µm, as Jia's did,
and the model's first harmonic (e/r) is wrong by that much: ~2.3″ per u at r = 22 mm. No traced
effect can take a first harmonic (graduation_error starts at order 2: a first-order division error
is the eccentricity's own), so the residual after the loop is that first harmonic plus what the
loop left: its first harmonic must be within 3 u of the CCD's stated (e, θ0), the rest ≤ 0.4 ×
before. Measured on the default (seed 20190819): 15.55″ → 7.62″ P-V (0.49), all of it the first
harmonic (3.8″ amplitude, 1.7 u); over the vibration's realisations the plain ratio is ≤ 0.4 in
half of them."""

from __future__ import annotations

import json
import math

import numpy as np
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
    ca = r["comparison_after"]
    th = np.radians(np.asarray(ca["theta_deg"], dtype=float))
    res = np.asarray(ca["residual_arcsec"], dtype=float)
    A = np.column_stack([np.sin(th), np.cos(th), np.ones_like(th)])
    c, *_ = np.linalg.lstsq(A, res, rcond=None)
    h1 = math.hypot(c[0], c[1])
    k = 648000 / math.pi / (r["bench"]["optical_radius_mm"] * 1000.0)       # ″ per µm of e
    u_h1 = k * max(r["eccentricity_u_um"], r["eccentricity_um"] * math.radians(r["eccentricity_phase_u_deg"]))
    assert h1 <= 3 * u_h1, (h1, u_h1)
    assert float(np.ptp(res - A[:, :2] @ c[:2])) <= 0.4 * before["pv_arcsec"], after
    assert abs(after["pv_arcsec"] - float(np.ptp(res))) < 1e-9
    assert r["residual_after_trace"]["p_value"] > 0.01, r["residual_after_trace"]   # χ² after: consistent
    assert r["close_loop"]["status"] != "unexplained" and not r["unexplained"], r["close_loop"]["status"]
    assert "graduation_error" in [e["name"] for e in r["identified_effects"]]
    # the cage's creep is in the noise, not a "θ pattern changing with time"
    tp = r["close_loop"]["signature"]["time_pattern"]
    assert not tp["significant"], tp
