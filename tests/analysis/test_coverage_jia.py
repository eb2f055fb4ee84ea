"""Issue 5, slow: the Jia pipeline's uncertainties against the twin's truth over several seeds.

A reduced version of ``benchmarks/coverage_jia.py`` (which runs ≥ 50 seeds of the full jia2019
scenario, docs/benchmarks.md "Jia uncertainty coverage"): 6 seeds of jia2019 with 72 radial stops
and 24 CCD frames (the realistic noise of the scenario unchanged), ~15 s per seed. The seeds are
fixed, so the outcome is deterministic; the bounds are those a correct u meets with a wide margin,
and a u three times too small or too large fails. The d_ref fit's u alone (without the asynchronous
motion's share in one sweep's first harmonic) is no longer an example of a too small u on this bench:
the microscope's vibration (twin/vibration.py) dominates u(e) and the fit's residuals carry it.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
REDUCED = {"procedure.radial_positions": 72, "procedure.ccd_step": "15 deg"}


def _bench():
    spec = importlib.util.spec_from_file_location("coverage_jia", ROOT / "benchmarks" / "coverage_jia.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.slow
def test_cut_procedure_gives_the_same_radial_and_ccd_data(tmp_path):
    """The benchmark skips the polygon steps; the radial and CCD data must be byte-identical to those
    of the full simulation (the twin keys its random streams by the step index)."""
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import simulate

    C = _bench()
    sc = load_scenario().with_overrides({**REDUCED, "scenario.seed": 7})
    full = simulate(sc, tmp_path / "full", progress=False, backend="analytic")
    with C._without_polygon():
        cut = simulate(sc, tmp_path / "cut", progress=False, backend="analytic")
    assert (full / "polygon.csv").exists() and not (cut / "polygon.csv").exists()
    for f in ["radial_motion.csv", "ccd/index.csv"] + [f"ccd/img_{k:03d}.png" for k in range(24)]:
        assert (full / f).read_bytes() == (cut / f).read_bytes(), f
    assert (full / "truth" / "ccd.csv").read_bytes() == (cut / "truth" / "ccd.csv").read_bytes()


@pytest.mark.slow
def test_reduced_coverage(tmp_path):
    C = _bench()
    recs = []
    for seed in range(2000, 2006):
        raw = C.run_seed(seed, tmp_path, overrides=REDUCED)
        json.loads(json.dumps(raw))  # the cached record is plain JSON
        recs.append(C.score(raw))
    z = C.normalised_errors(recs)
    summ = C.summarise(recs)
    print(C.markdown(summ, [r["seed"] for r in recs]))
    ze = z["e (synchronous truth; u incl. async 1st harmonic)"]
    zt = z["θ0 (synchronous truth; u incl. async 1st harmonic)"]
    # u incl. the async share: no seed beyond 4 u (a t-distribution with 4 dof: P(|t| > 4) = 1.6 %)
    assert np.all(np.abs(ze) < 4) and np.all(np.abs(zt) < 4), (ze, zt)
    assert np.sqrt(np.mean(ze**2)) < 2 and np.sqrt(np.mean(zt**2)) < 2
    # ... nor overstated: with a correct u, 6 · RMS(z)² is χ² with 6 dof, P(RMS(z) < 0.35) = 0.6 %;
    # seeds 2000…2005 give RMS(z) 0.75 (e), 0.96 (θ0), so a u three times too large fails
    assert np.sqrt(np.mean(ze**2)) > 0.35 and np.sqrt(np.mean(zt**2)) > 0.35, (ze, zt)
    # The d_ref fit's u alone: since the CCD microscope stand's vibration (twin/vibration.py, 927fcb3:
    # 1.21 µm per frame and axis, each frame an independent draw) the fit's residuals hold the sweep's
    # dominant scatter, u_fit = 0.12-0.47 µm at 24 frames, while the ball sets' asynchronous first
    # harmonic is u_h1_async = 0.013-0.025 µm (4aa9eba; the earlier path bearings' async_rms gave
    # ~0.05 µm against a 2-3 nm fit u). With u_fit/u ≥ 0.994 on every seed the fit-only u covers the
    # synchronous truth as u does (seeds 2000…2005: z = -0.0, -0.8, -0.05, 1.2, 1.0, 0.5): the same bounds.
    zf = z["e (synchronous truth; u from the d_ref fit only)"]
    assert np.all(np.abs(zf) < 4) and np.sqrt(np.mean(zf**2)) < 2, zf
    assert np.all(np.abs(z["e (this sweep's truth; u from the fit only)"]) < 3)
    # δY and Δθ at 8 angles × 6 seeds: about the stated level
    for key in ("δY (synchronous truth; u from the revolutions' scatter, per harmonic)",
                "δY (these revolutions' truth; u = GUM fit)",
                "Δθ (eq. 5 on the synchronous truth; u = GUM)"):
        cov = summ["coverage"][key]
        assert 0.45 <= cov["p1"] <= 0.9 and cov["p2"] >= 0.8, (key, cov)
