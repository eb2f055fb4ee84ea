"""Issue 5: "a dataset from another source with the same format works".

A dataset written without the twin — numbers made up here, written with the format's own writer
(``DatasetWriter``; source ``external``; no truth/, no twin extras such as ``theta_read_deg`` or a
journal): two-sphere probe readings (Jia sec. 4.1), CCD frames of the scale edge drawn by the
tests' own grating renderer (small 480×360 frames at 2 µm/px, 24 angles), and a polygon table
(Hsieh eq. 3 with 8 faces). ``benchtwin analyze`` must read it and recover what was put in: e, θ0
(within their stated uncertainty), δY (eq. 9) and the error model (eq. 5) against the encoder error
the polygon table carries.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchtwin.analysis.dataset import DatasetWriter
from benchtwin.analysis.pipeline import analyze
from benchtwin.units import ARCSEC

E_UM, TH0_DEG, R_OPT_MM, R_EDGE_MM = 6.0, 123.4, 22.0, 22.5
L1, L2 = 6.81, 122.96
PX_UM, W, H = 2.0, 480, 360
N_FACES = 8


def _dY(th_deg):
    t = np.radians(th_deg)
    return 0.20 * np.cos(2 * t - 0.4) + 0.08 * np.cos(3 * t - 2.0) + 0.05 * np.cos(5 * t - 1.0)  # µm


def _int_dY(th_deg):
    """∫_0^θ δY dθ' (µm·rad), analytic."""
    t = np.radians(th_deg)
    out = 0.0
    for a, k, p in ((0.20, 2, 0.4), (0.08, 3, 2.0), (0.05, 5, 1.0)):
        out = out + a * (np.sin(k * t - p) + math.sin(p)) / k
    return out


def _alpha_arcsec(th_deg):
    """Jia eq. 5 with the values put in (the encoder error this bench would show)."""
    return (E_UM * np.sin(np.radians(th_deg - TH0_DEG)) + _int_dY(th_deg)) / (R_OPT_MM * 1e3) / ARCSEC


@pytest.fixture(scope="module")
def external_dataset(tmp_path_factory):
    from tests.support.grating import lab_to_image_centre, render_grating

    rng = np.random.default_rng(2024)
    path = tmp_path_factory.mktemp("ext") / "bench_2024-05-01"
    manifest = {
        "format": "bench-dataset", "version": 1, "source": "external",
        "bench": {"optical_radius_mm": R_OPT_MM, "L1_mm": L1, "L2_mm": L2, "grating_period_um": 20.0,
                  "polygon_faces": N_FACES, "scale_edge_radius_mm": R_EDGE_MM},
        "ccd": {"position_deg": 180.0, "outward": "+x", "tangential": "+x", "reference_px": [W / 2, H / 2]},
    }
    with DatasetWriter(path, manifest) as w:
        # radial motion: 3 revolutions × 72 stops; sphere = offset + centring + δY (+ tilt) + noise
        th = np.arange(72) * 5.0
        t = np.radians(th)
        eps = 0.6e-3 * np.cos(2 * t - 1.0)  # µm/mm
        cols = {"rep": [], "theta_deg": [], "probe_top_um": [], "probe_bottom_um": []}
        for r in range(3):
            cols["rep"] += [r] * th.size
            cols["theta_deg"] += th.tolist()
            cols["probe_top_um"] += (4 + 3 * np.cos(t - 0.7) + _dY(th) + L1 * eps + rng.normal(0, 0.005, th.size)).tolist()
            cols["probe_bottom_um"] += (-2 + 4 * np.cos(t - 5.2) + _dY(th) - (L2 - L1) * eps
                                        + rng.normal(0, 0.005, th.size)).tolist()
        w.write_table("radial_motion", cols)
        # CCD: 24 frames every 15°, the disk centre from docs/conventions.md
        thc = np.arange(24) * 15.0
        files = []
        for k, tc in enumerate(thc):
            c = lab_to_image_centre(tc, E_UM, TH0_DEG, R_EDGE_MM * 1e3, PX_UM, (W / 2, H / 2))
            img = render_grating(W, H, c, R_EDGE_MM * 1e3 / PX_UM, 20.0 / PX_UM, line_length_px=600.0,
                                 ss_end=16, ss_side=4, noise=1.0, seed=k, to_uint8=True)
            files.append(f"frame_{k:02d}.png")
            w.write_image(f"ccd/{files[-1]}", img)
        w.write_table("ccd/index", {"k": list(range(thc.size)), "theta_deg": thc.tolist(), "file": files})
        # polygon (Hsieh eq. 3): ε_ij = α(θ_i) + Σ_{k=j}^{j+i−1} β_k + U_j, all start faces at S = 0
        beta = rng.normal(0, 0.8, N_FACES)
        beta -= beta.mean()
        U = rng.normal(0, 3.0, N_FACES)
        pc = {k: [] for k in ("shift_deg", "start_face", "step", "theta_deg", "ac_arcsec", "t_s")}
        for j in range(1, N_FACES + 1):
            for i in range(1, N_FACES + 1):
                thi = (i - 1) * 360.0 / N_FACES
                bsum = sum(beta[(j - 1 + m) % N_FACES] for m in range(i))
                pc["shift_deg"].append(0.0), pc["start_face"].append(j), pc["step"].append(i)
                pc["theta_deg"].append(thi), pc["t_s"].append(float(len(pc["t_s"])))
                pc["ac_arcsec"].append(float(_alpha_arcsec(thi) + bsum + U[j - 1] + rng.normal(0, 0.01)))
        w.write_table("polygon", pc)
    return path


def test_external_dataset_is_analysed(external_dataset, tmp_path):
    assert not (external_dataset / "truth").exists()
    assert json.loads((external_dataset / "manifest.json").read_text())["source"] == "external"
    r = analyze(external_dataset, tmp_path / "out", progress=False, close_loop=False)["results"]
    res = json.loads((tmp_path / "out" / "results.json").read_text())
    assert res["source"] == "external"
    # e, θ0 from the images (Jia eqs. 10-12)
    assert abs(r["eccentricity_um"] - E_UM) < max(3 * r["eccentricity_u_um"], 0.01)
    assert abs((r["eccentricity_phase_deg"] - TH0_DEG + 180) % 360 - 180) < max(3 * r["eccentricity_phase_u_deg"], 0.1)
    # δY (eq. 9) and the synchronous/asynchronous summary
    rm = r["radial_motion"]
    err = np.asarray(rm["dY_um"]) - _dY(np.asarray(rm["theta_deg"]))
    assert np.sqrt(np.mean(err**2)) < 0.005
    assert {"synchronous_um", "asynchronous_um", "total_um"} <= set(rm["summary"]["disk"])
    assert rm["u_dY_um"] > 0 and math.isfinite(rm["u_h1_async_um"])
    # eq. 5 against the encoder error of the polygon table: the residual is the noise only
    rb = r["residual_before"]
    assert rb["rms_arcsec"] < 0.1 and rb["fraction_of_error"] < 0.01
    pred = r["model_prediction_arcsec"]
    want = _alpha_arcsec(np.asarray(pred["theta_deg"]))
    got = np.asarray(pred["value"])
    assert np.max(np.abs((got - got.mean()) - (want - want.mean()))) < 0.1
    assert (tmp_path / "out" / "report.html").read_text().count("<img") >= 4
