"""Issue 15 item 6: the jia2019 bench's non-repeatability against Jia 2019 sec. 5, and u(e) (slow).

Jia's numbers are ranges of n = 3 repetitions divided by d_3 = 1.69: the radial run's δY "range at
the same position 0.3 µm → σ = 0.18 µm", the eccentricity's "range of e 0.4 µm → u_e = 0.24 µm".
A range of 3 normal values estimates σ to ±52 % (1 sd); its 2.5 % / 97.5 % quantiles are 0.305σ and
3.68σ, so the σ for which Jia's estimate is a 95 % outcome lies in [σ̂·1.693/3.68, σ̂·1.693/0.305]:
δY [0.083, 1.0] µm, e [0.11, 1.33] µm. The tests compare the twin like for like with that band
(the analysis's ``u_dY_range_um`` is Jia's statistic: the largest range over θ / d_n).

The twin (``simulate`` on jia2019 with ``procedure.ccd_reps`` = 6, analytic renderer) is sized from
physical causes only (docs/physics.md, "Non-repeatability of the jia2019 bench"). Monte Carlo over
the twin's own realisations: the six sweeps are six revolutions at six times (another cage path,
thermal state and microscope drift each, and every frame its own draw of the microscope stand's
vibration), so their scatter of e is the twin's σ_e; the u(e) the
analysis states for ONE sweep (the fit ⊕ the probes' asynchronous first harmonic, type B) must cover
it. `pytest -m slow tests/analysis/test_jia_nonrepeatability.py` (~8 min: two simulations, 1080 radial readings and up to 360 frames each,
the polygon run).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from benchtwin.analysis.pipeline import analyze
from benchtwin.twin.scenario import load_scenario
from benchtwin.twin.simulate import simulate

ROOT = Path(__file__).resolve().parents[2]
N_SWEEPS = 6
#: the σ band within which Jia's range-of-3 estimate is a 95 % outcome (module docstring)
R3_LO, R3_HI = 0.305, 3.68
D3 = 1.693


def jia_band(sigma_hat: float) -> tuple[float, float]:
    return sigma_hat * D3 / R3_HI, sigma_hat * D3 / R3_LO


#: the probes held in a stand's 80 mm aluminium arm (docs/physics.md): the arm follows the room
#: control's cycling with its own 12 min (the default stand is compact: 10 mm at 30 min)
ARM = {"thermal.probe_stand_growth": "1.8 um/K", "thermal.probe_stand_time_constant": "12 min"}


def _run(tmp_path_factory, name: str, over: dict) -> dict:
    import json

    out = tmp_path_factory.mktemp(name)
    sc = load_scenario(ROOT / "scenarios" / "jia2019.toml").with_overrides(over)
    ds = simulate(sc, out / "ds", progress=False, backend="analytic")
    analyze(ds, out / "an", progress=False, close_loop=False)
    return json.loads((out / "an" / "results.json").read_text())


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    return _run(tmp_path_factory, "jia_reps", {"procedure.ccd_reps": N_SWEEPS})


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="not met by the default: its compact probe stand gives 0.05 µm, below "
                                       "the band of Jia's 0.18 µm [0.083, 1.0] µm (docs/physics.md)")
def test_default_radial_repeatability_is_jias(results):
    lo, hi = jia_band(0.18)
    assert lo <= results["radial_motion"]["u_dY_range_um"] <= hi


@pytest.mark.slow
def test_radial_repeatability_with_a_stand_arm_is_jias(tmp_path_factory):
    """δY between the three radial reps (Jia's range method, largest over θ): with the probes in an
    80 mm arm inside the band of Jia's 0.18 µm (0.204 µm measured); the default's compact stand
    leaves it at the probes' noise and the ball sets (0.05 µm), below the band."""
    lo, hi = jia_band(0.18)
    rm = _run(tmp_path_factory, "jia_arm", ARM)["radial_motion"]
    # Jia removed no drift: the range method on the readings as taken (analysis/probe_drift.py
    # removes the arm's drift before its own u_dY_range_um, which is then the compact stand's size)
    arm = rm["probe_drift"]["u_dY_range_as_read_um"]
    assert lo <= arm <= hi, (arm, lo, hi)
    assert rm["u_dY_range_um"] < 0.5 * arm, rm["u_dY_range_um"]


@pytest.mark.slow
def test_repeated_sweeps_give_type_a_u(results):
    sw = results["eccentricity_sweeps"]
    assert sw["n_sweeps"] == N_SWEEPS and sw["dof"] == N_SWEEPS - 1
    e = np.asarray(sw["e_sweeps_um"])
    # the stated e is that of the mean first-harmonic vector (analysis/eccentricity.py
    # eccentricity_from_sweeps): below the mean of the magnitudes by ≈ e·s(θ0)²/2 (0.003 µm at 2°)
    t = np.radians(np.asarray(sw["theta0_sweeps_deg"]))
    assert results["eccentricity_um"] == pytest.approx(math.hypot(np.mean(e * np.cos(t)), np.mean(e * np.sin(t))),
                                                       abs=1e-6)
    assert results["eccentricity_um"] == pytest.approx(float(np.mean(e)), abs=0.01)
    s = float(np.std(e, ddof=1))
    assert sw["e_sweep_sd_um"] == pytest.approx(s)
    assert results["eccentricity_u_um"] == pytest.approx(max(s, results["eccentricity_u_fit_um"] * math.sqrt(N_SWEEPS))
                                                         / math.sqrt(N_SWEEPS))
    assert "type A" in results["eccentricity_u_source"]
    assert results["eccentricity_u_async_um"] is None    # the sweeps carry it themselves


@pytest.mark.slow
def test_one_sweep_u_covers_the_twins_sweep_to_sweep_scatter(results):
    """GUM against Monte Carlo over the twin's realisations: the u(e) one sweep would state (its fit
    ⊕ the probes' asynchronous 1st harmonic) is not smaller than the observed σ_e of the six sweeps
    beyond the χ² band (5 dof, 99 %). It may be larger: the probes' first harmonic holds their own
    stand's drift too, which the microscope does not share (docs/physics.md)."""
    sw = results["eccentricity_sweeps"]
    s = sw["e_sweep_sd_um"]
    u_fit_one = results["eccentricity_u_fit_um"] * math.sqrt(N_SWEEPS)   # pooled fit u of one sweep
    u_one = math.hypot(u_fit_one, results["radial_motion"]["u_h1_async_um"])
    k = math.sqrt(stats.chi2.ppf(0.99, N_SWEEPS - 1) / (N_SWEEPS - 1))
    assert s <= k * u_one, (s, u_one)
    assert s >= u_fit_one / k, (s, u_fit_one)   # the sweeps scatter at least by their frames' noise


@pytest.mark.slow
def test_eccentricity_uncertainty_is_jias(results):
    """σ_e between the six sweeps and the u(e) one sweep states are both inside the band of Jia's
    0.24 µm: the microscope stand's floor-borne vibration (twin/vibration.py: a VC-A floor through a
    59 Hz, ζ = 0.03 stand, 5 ms exposure: 1.21 µm per frame and axis) scatters every frame's edge,
    the eq. 10 fit's residual shows it and u_fit(e) states it (the analysis unchanged). Before it:
    nanometres between sweeps, u(e) 0.015 µm."""
    lo, hi = jia_band(0.24)
    u_one = math.hypot(results["eccentricity_u_fit_um"] * math.sqrt(N_SWEEPS), results["radial_motion"]["u_h1_async_um"])
    assert lo <= results["eccentricity_sweeps"]["e_sweep_sd_um"] <= hi
    assert lo <= u_one <= hi
