"""Issue 32 item 6: a named reference-chain effect removes its residual.

A quadratic autocollimator non-linearity acts on the whole reading the instrument measures,
ε = α + Σβ + U (Hsieh 2022 eq. 3), not on α alone: the shown reading is ε = m + c·m². Once the
tracing names it (ac_scale), the pipeline removes c·ε² from every reading and repeats the shift-angle
solution (``pipeline.corrected_polygon``); the corrected curve must then be within 2u of the true α,
and its residual against the model ≤ 0.4× the measured curve's. Without a non-linearity nothing is
named.

The bench is hand-built (no CCD, so no ``analyze`` run): a 24-face polygon read at S = 0 from every
start face and from face 1 at S = 5° and 10° (the reference generator's S = 0 table and a few of its
shifts), setup errors of a few arcseconds, an encoder whose error is its eccentricity term alone
(≈ 70″, the model here: the residual before is the non-linearity's), and 3 heads whose differences
(Hsieh eq. 8) carry no reference-chain error (the self-calibration that rules out encoder causes).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchtwin.analysis.dataset import DatasetWriter, open_dataset
from benchtwin.analysis.pipeline import (_setup_error_lookup, corrected_polygon, polygon_table, reading_response,
                                         step_polygon)
from benchtwin.analysis.steps import TraceOutcome
from benchtwin.analysis.tracing import BenchContext, SelfCalCurve, evidence_from_polygon, trace

N_FACES = 24
HEADS_DEG = [0.0, 120.0, 240.0]
E_ARCSEC, THETA0_DEG = 70.0, 192.0       # the eccentricity term, e/r ≈ 7.5 µm / 22 mm
NOISE_ARCSEC = 0.03                      # per autocollimator reading
HEAD_NOISE_ARCSEC = 0.02
MANIFEST = {
    "format": "bench-dataset", "version": 1, "source": "external",
    "bench": {"optical_radius_mm": 22.0, "L1_mm": 6.81, "L2_mm": 122.96, "grating_period_um": 20.0,
              "polygon_faces": N_FACES, "heads_deg": HEADS_DEG,
              "autocollimator_resolution_arcsec": 0.001, "autocollimator_accuracy_arcsec": 0.05},
}


def alpha_true(theta_deg):
    return E_ARCSEC * np.sin(np.radians(np.asarray(theta_deg, dtype=float) - THETA0_DEG))


class _Model:
    """The error model the tracing compares with: the eccentricity term (exact here)."""

    def predict_terms(self, theta_deg):
        return {"eccentricity": alpha_true(theta_deg)}


def _bench(root: Path, c_per_arcsec: float, seed: int) -> Path:
    rng = np.random.default_rng(seed)
    beta = rng.normal(0.0, 1.0, N_FACES)
    beta -= beta.mean()
    U = {(0.0, j): u for j, u in zip(range(1, N_FACES + 1), rng.normal(0.0, 3.0, N_FACES))}
    U.update({(5.0, 1): 2.0, (10.0, 1): -2.5})
    rows = []
    for shift, faces in ((0.0, range(1, N_FACES + 1)), (5.0, (1,)), (10.0, (1,))):
        for j in faces:
            for i in range(1, N_FACES + 1):
                theta = (i - 1) * 360.0 / N_FACES + shift
                cum = sum(beta[(j - 1 + k) % N_FACES] for k in range(i))
                m = float(alpha_true(theta)) + cum + U[(shift, j)] + rng.normal(0.0, NOISE_ARCSEC)
                rows.append((shift, j, i, theta, m + c_per_arcsec * m * m, 20.0 * len(rows)))
    w = DatasetWriter(root, MANIFEST)
    w.write_table("polygon", dict(zip(["shift_deg", "start_face", "step", "theta_deg", "ac_arcsec", "t_s"],
                                      map(list, zip(*rows)))))
    hrows = [(a, h, float(alpha_true(a) - alpha_true(a - psi)) + rng.normal(0.0, HEAD_NOISE_ARCSEC))
             for a in np.arange(0.0, 360.0, 5.0) for h, psi in enumerate(HEADS_DEG, start=1)]
    w.write_table("heads", dict(zip(["theta_deg", "head", "delta_arcsec"], map(list, zip(*hrows)))))
    w.close()
    return root


def _loop(root: Path):
    """What ``pipeline._close_loop`` does up to the corrected curve: the shift-angle analysis, the
    evidence (α per reading, the exact quadratic column, the self-calibration), trace, correction."""
    ds = open_dataset(root)
    pol = step_polygon(ds)
    poly = polygon_table(ds)
    sc = pol.selfcal_error_arcsec
    ev = evidence_from_polygon(
        poly, pol.pitch_deviation_arcsec, _setup_error_lookup(pol), _Model(),
        BenchContext(n_faces=N_FACES, u_arcsec=NOISE_ARCSEC,
                     selfcal=SelfCalCurve(sc["theta_deg"], sc["value"], np.asarray(sc["u"]), len(HEADS_DEG)),
                     optical_radius_mm=22.0, L1_mm=6.81, L2_mm=122.96, grating_period_um=20.0, u_floor_arcsec=0.05))
    ev.ac_quadratic_response = reading_response(poly, pol, np.asarray(poly["ac_arcsec"], dtype=float) ** 2, N_FACES)
    tr = TraceOutcome.from_trace(trace(ev))
    return pol, tr, corrected_polygon(ds, poly, pol, tr, ev)


def _residual(curve) -> np.ndarray:
    """Curve − model at its angles, the mean removed (the polygon cannot know a constant in α)."""
    d = np.asarray(curve["value"], dtype=float) - alpha_true(curve["theta_deg"])
    return d - d.mean()


@pytest.mark.parametrize("c_per_arcsec", [3e-4, -3e-4])
def test_named_nonlinearity_removes_its_residual(tmp_path, c_per_arcsec):
    pol, tr, corr = _loop(_bench(tmp_path / "ds", c_per_arcsec, seed=7))
    assert [e["name"] for e in tr.identified_effects] == ["ac_scale"], tr.status
    q = tr.identified_effects[0]["params"]["quad_per_arcsec"]
    assert abs(q - c_per_arcsec) < 0.05 * abs(c_per_arcsec), q
    assert [a["effect"] for a in corr["corrections_applied"]] == ["ac_scale"]
    before = np.sqrt(np.mean(_residual(pol.encoder_error_arcsec) ** 2))
    after = np.sqrt(np.mean(_residual(corr) ** 2))
    assert before > 0.3, before                      # the non-linearity is there to remove (≈ 0.6″ RMS)
    assert after <= 0.4 * before, (before, after)
    # the corrected curve against the true α (its mean removed: the model here is the truth)
    assert np.all(np.abs(_residual(corr)) <= 2.0 * np.asarray(corr["u"])), np.max(np.abs(_residual(corr)))


def test_linear_autocollimator_is_not_named(tmp_path):
    pol, tr, corr = _loop(_bench(tmp_path / "ds", 0.0, seed=7))
    assert tr.identified_effects == [] and not tr.ambiguous, tr.status
    assert corr["corrections_applied"] == []
    np.testing.assert_array_equal(corr["value"], pol.encoder_error_arcsec["value"])
