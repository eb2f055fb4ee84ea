"""Each hidden effect against the analysis's template (issue 33 item 4): what the template misses.

For every effect scenario of ``scenarios/hidden/`` whose cause the twin computes (twin/hidden.py),
simulate the scenario and the same scenario without ``[hidden]`` (same seed, so every declared
draw is the same), take the difference in the channel the effect lives in, from the TRUTH where the
effect changes the encoder (truth/), and fit the matching template of the analysis's effect module
(analysis/effects/*.py: its columns) to it by least squares. The table states the difference's RMS
before and after the fit and the fraction that remains (after/before):

- graduation_error: Δα on truth/encoder_error.csv's 0.1° grid (3600 points), template
  ``harmonic_columns(θ, ORDERS)`` of analysis/effects/graduation_error.py (orders 2…20) plus the
  first harmonic (the Jia model's eccentricity); nuisance: a constant;
- interpolation_error: Δα at the polygon stops (truth/polygon.csv), template sin/cos(m·L·θ),
  m = 1, 2 (analysis/effects/interpolation_error.py, L the twin's line count); nuisance: a constant;
- tangential_motion: Δα on the 0.1° grid, template [−δX/r, −∫δY dθ/r] (analysis/effects/
  tangential_motion.py's gain and radial_gain; δX, δY the true axis motion's difference,
  truth/encoder_error.csv); without X probes (tangential_motion_no_x) its δY-only basis
  [−δY/r, −H[δY]/r, −∫δY dθ/r] (H the quadrature); nuisance: a constant;
- ac_drift: Δ of the autocollimator's readings (polygon.csv: the same seed draws the same noise),
  template d·t_s (analysis/effects/ac_drift.py); nuisance: one constant per run (U_j of Hsieh
  eq. 3, which the measurement model removes anyway);
- ac_scale: Δ of the autocollimator's readings, template [v, v²] (analysis/effects/ac_scale.py's
  gain and quadratic columns, v the reading without the effect); nuisance: one constant per run;
- optical_radius: Δα on the 0.1° grid, template a gain on Jia eq. 5's model e/r·sin(θ−θ0) + ∫δY dθ/r
  (analysis/effects/optical_radius.py), the model from the run without the effect; nuisance: a constant;
- ccd_pixel_scale (and _pixel_only): Δ of the CCD's d_ref as the analysis measures it from the
  images (pipeline.step_eccentricity, Jia eqs. 10–13), template a gain s·d_ref (ccd_pixel_scale.py's
  ccd channel); nuisance: a constant; a frame every 30° at 512 × 384 px (EXTRA);
- tilt_abbe: Δ of eq. 9's δY at the disk from the probe readings (declared L1), template
  ΔL1·(δ_bottom − δ_top)/L2 (tilt_abbe.py's radial channel, the spheres' true motion); nuisance:
  orders 0 and 1 (eq. 7); 120 radial positions;
- sphere_form: Δ of the top probe's reading, template its harmonics 2…10 (sphere_form.py: a form
  harmonic of the reading, eq. 7's RADIAL_ORDERS); nuisance: orders 0 and 1; 120 radial positions;
- torsion_hysteresis: Δ of the AC readings, template h·approach direction (torsion_hysteresis.py);
  nuisance: one U_j per setup (shift, start face), shared by both directions;
- polygon_pitch_ignored: Δ of the AC readings, template the cumulative pitch C(f) of the face under
  the autocollimator, f = 1…N−1 (polygon_pitch_ignored.py); nuisance: one constant per run;
- thermal_growth: no effect module describes it ("no template: out of the library"): the RMS of Δα
  at the polygon readings (their times), a constant removed; a note says what a static error of θ
  would leave;
- the nulls (``[hidden]`` empty): nothing to fit; one row checks that the run without ``[hidden]``
  is byte for byte the same run (NULL_FILES).

A hidden scenario without an entry here makes the script exit 2 (tests/benchmarks: the table in
docs/effects.md lists every scenario of scenarios/hidden/).

"before" is the RMS left after the nuisance columns alone, "after" with the template's columns too,
in ″, or in µm where the difference column says so.

A remainder near 0 says the template has the physics' shape (Heydemann's sub-division error is
that case: its first and second harmonics ARE the physics); a large remainder says the analysis's
template misses part of the effect (what the loop must then call unexplained or leave in its
residual). Small settings (one radial rep, 24 radial positions, CCD frames every 180°, except where
a case's channel is the CCD or the probes: EXTRA); the polygon procedure is the scenario's own.

    .venv/bin/python benchmarks/hidden_vs_template.py [--work /tmp/hidden_vs_template] [--only NAME ...] [--no-nulls]

Prints a markdown table (docs/effects.md quotes it). Imports both twin and analysis: a benchmark
is outside the package layers (pyproject's import-linter contracts cover benchtwin.* only).
"""

from __future__ import annotations

import argparse
import csv
import math
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from benchtwin.analysis.effects import graduation_error as grad_mod
from benchtwin.analysis.fourier import harmonic_columns
from benchtwin.analysis.radial_motion import RADIAL_ORDERS
from benchtwin.twin.scenario import load_scenario, validate
from benchtwin.twin.simulate import sim_build, simulate
from benchtwin.units import ARCSEC

ROOT = Path(__file__).resolve().parents[1]
SMALL = {"procedure.radial_reps": 1, "procedure.radial_positions": 24, "procedure.ccd_step": "180 deg",
         "instruments.ccd.width": "128 px", "instruments.ccd.height": "96 px"}


def rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def col(rs: list[dict[str, str]], name: str) -> np.ndarray:
    return np.array([float(r[name]) for r in rs])


def run_columns(rs: list[dict[str, str]]) -> np.ndarray:
    """One indicator column per run (shift, start face, rep, direction): Hsieh's U_j."""
    keys = [(r["shift_deg"], r["start_face"], r["rep"], r["direction"]) for r in rs]
    idx = {k: i for i, k in enumerate(dict.fromkeys(keys))}
    X = np.zeros((len(rs), len(idx)))
    X[np.arange(len(rs)), [idx[k] for k in keys]] = 1.0
    return X


def _rms_residual(y: np.ndarray, X: np.ndarray) -> float:
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    return float(np.sqrt(np.mean((y - X @ beta) ** 2)))


def remains(y: np.ndarray, X0: np.ndarray, X: np.ndarray) -> tuple[float, float]:
    """RMS of y's least-squares residual on the nuisance columns X0 alone (a constant; the per-run
    U_j for the autocollimator: what the measurement model removes anyway), and on X0 with the
    template's columns X."""
    y = np.asarray(y, dtype=float)
    return _rms_residual(y, X0), _rms_residual(y, np.column_stack([X0, X]))


def periodic_integral(theta_deg: np.ndarray, y: np.ndarray) -> np.ndarray:
    """∫y dθ (θ in rad) over a uniform full-turn grid, zero-mean (the Fourier integral of eq. 5)."""
    n = y.size
    c = np.fft.rfft(y - y.mean())
    k = np.arange(c.size)
    ci = np.zeros_like(c)
    ci[1:] = c[1:] / (1j * k[1:])
    return np.fft.irfft(ci, n=n)


def fit_graduation(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    a, b = rows(h / "truth" / "encoder_error.csv"), rows(p / "truth" / "encoder_error.csv")
    th = col(a, "theta_deg")
    y = col(a, "alpha_arcsec") - col(b, "alpha_arcsec")
    X = harmonic_columns(th, (1, *grad_mod.ORDERS))[0]
    return "Δα, 0.1° grid", "harmonics 1, 2…20", *remains(y, np.ones((th.size, 1)), X)


def fit_interpolation(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    a, b = rows(h / "truth" / "polygon.csv"), rows(p / "truth" / "polygon.csv")
    th = col(a, "theta_deg")
    y = col(a, "alpha_arcsec") - col(b, "alpha_arcsec")
    _, _, inst = sim_build(sc, camera=False)
    L = int(inst["encoder"].n_lines)
    ph = np.deg2rad(th) * L
    X = np.column_stack([f(m * ph) for m in (1, 2) for f in (np.sin, np.cos)])
    return f"Δα, {th.size} polygon readings", f"sin/cos(m·L·θ), m = 1, 2, L = {L}", *remains(y, np.ones((th.size, 1)), X)


def fit_tangential(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    a, b = rows(h / "truth" / "encoder_error.csv"), rows(p / "truth" / "encoder_error.csv")
    th = col(a, "theta_deg")
    y = col(a, "alpha_arcsec") - col(b, "alpha_arcsec")
    r_um = float(sc["bench"]["optical_radius"]) * 1e6
    dx = col(a, "axis_dx_um") - col(b, "axis_dx_um")
    dy = col(a, "axis_dy_um") - col(b, "axis_dy_um")
    k = 1.0 / (r_um * ARCSEC)
    X = np.column_stack([-dx * k, -periodic_integral(th, dy) * k])
    return "Δα, 0.1° grid", "[−δX/r, −∫δY dθ/r]", *remains(y, np.ones((th.size, 1)), X)


def fit_tangential_no_x(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    """Without X probes the template is built from δY alone: its in-phase and quadrature (Hilbert)
    parts and ∫δY (tangential_motion.design's inphase_gain, quadrature_gain, radial_gain)."""
    a, b = rows(h / "truth" / "encoder_error.csv"), rows(p / "truth" / "encoder_error.csv")
    th = col(a, "theta_deg")
    y = col(a, "alpha_arcsec") - col(b, "alpha_arcsec")
    r_um = float(sc["bench"]["optical_radius"]) * 1e6
    dy = col(a, "axis_dy_um") - col(b, "axis_dy_um")
    c = np.fft.rfft(dy - dy.mean())
    hil = np.fft.irfft(-1j * c, n=dy.size)
    k = 1.0 / (r_um * ARCSEC)
    X = np.column_stack([-(dy - dy.mean()) * k, -hil * k, -periodic_integral(th, dy) * k])
    return "Δα, 0.1° grid", "[−δY/r, −H[δY]/r, −∫δY dθ/r] (no X probes)", *remains(y, np.ones((th.size, 1)), X)


def fit_ac_drift(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    a, b = rows(h / "polygon.csv"), rows(p / "polygon.csv")
    y = col(a, "ac_arcsec") - col(b, "ac_arcsec")
    return f"Δ AC reading, {len(a)} readings", "d·t_s", *remains(y, run_columns(a), col(a, "t_s")[:, None])


def fit_ac_scale(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    a, b = rows(h / "polygon.csv"), rows(p / "polygon.csv")
    v = col(b, "ac_arcsec")
    y = col(a, "ac_arcsec") - v
    return f"Δ AC reading, {len(a)} readings", "[v, v²]", *remains(y, run_columns(a), np.column_stack([v, v * v]))


def fit_optical_radius(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    """A head radius r(1 + s): the template is a gain on the analysis's model (analysis/effects/
    optical_radius.py: −(Δr/r)·Σ model terms), the model being Jia eq. 5, e/r·sin(θ−θ0) + ∫δY dθ/r.
    Built from the truth of the run without the effect: its eccentricity term is α + δX/r (the head
    reads the grating's tangential displacement, −δX/r for the axis' part, exactly: the
    tangential_motion row) and ∫δY dθ/r replaces −δX/r, as eq. 5 does."""
    a, b = rows(h / "truth" / "encoder_error.csv"), rows(p / "truth" / "encoder_error.csv")
    th = col(a, "theta_deg")
    y = col(a, "alpha_arcsec") - col(b, "alpha_arcsec")
    k = 1.0 / (float(sc["bench"]["optical_radius"]) * 1e6 * ARCSEC)
    ecc = col(b, "alpha_arcsec") + col(b, "axis_dx_um") * k
    model = ecc + periodic_integral(th, col(b, "axis_dy_um")) * k
    return "Δα, 0.1° grid", "−(Δr/r)·[e/r·sin(θ−θ0) + ∫δY dθ/r] (Jia eq. 5 model)", *remains(y, np.ones((th.size, 1)),
                                                                                         model[:, None])


def _d_ref(d: Path) -> dict[float, float]:
    """θ (deg, 6 decimals) → d_ref (µm) of the frames the analysis's CCD step keeps (Jia eqs. 10–13:
    the image scale from the grating lines with the datasheet period)."""
    from benchtwin.analysis.dataset import open_dataset
    from benchtwin.analysis.pipeline import step_eccentricity
    r = step_eccentricity(open_dataset(d, order=1), 1, False, workers=1)
    return {round(float(t), 6): float(v) for t, v in zip(r.theta_deg, r.d_ref_um)}


def fit_ccd_scale(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    """The CCD's d_ref as the analysis measures it from the images (pipeline.step_eccentricity), on
    the frames both runs keep; template: a gain s on d_ref (analysis/effects/ccd_pixel_scale.py's
    ccd channel: e, hence d_ref, scaled by 1/(1 + s)); nuisance: a constant (eq. 10's offset)."""
    dh, dp = _d_ref(h), _d_ref(p)
    keys = sorted(set(dh) & set(dp))
    v = np.array([dp[t] for t in keys])
    y = np.array([dh[t] for t in keys]) - v
    return (f"Δ d_ref (µm), {len(keys)} CCD frames", "s·d_ref (Jia eq. 13 scale)",
            *remains(y, np.ones((len(keys), 1)), v[:, None]))


def _probes(d: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rs = rows(d / "radial_motion.csv")
    return col(rs, "theta_deg"), col(rs, "probe_top_um"), col(rs, "probe_bottom_um")


def _orders01(th: np.ndarray) -> np.ndarray:
    """Jia eq. 7's removed orders: 0 (probe position) and 1 (sphere centring)."""
    return np.column_stack([np.ones(th.size), harmonic_columns(th, (1,))[0]])


def fit_tilt_abbe(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    """The spheres sit ΔL1 off their declared heights: the probe readings change, α does not. The
    channel is eq. 9's δY at the disk from the probe readings with the DECLARED L1, L2 (what the
    analysis computes); template: ΔL1·(δ_bottom − δ_top)/L2 (analysis/effects/tilt_abbe.py's radial
    channel), δ the spheres' TRUE motion with the effect (truth/radial_motion.csv: the template's
    shape, as the tangential rows use the true axis motion; built from the readings it would carry
    their repeatability too, errors in variables); nuisance: orders 0 and 1 (eq. 7 removes them)."""
    L1 = float(sc["bench"]["L1"]) * 1e3
    L2 = float(sc["bench"]["L2"]) * 1e3
    th, th_, bh = _probes(h)
    _, tp, bp = _probes(p)
    y = ((L2 - L1) * (th_ - tp) + L1 * (bh - bp)) / L2
    t = rows(h / "truth" / "radial_motion.csv")
    tilt = (col(t, "sphere_bottom_y_um") - col(t, "sphere_top_y_um")) / L2
    return (f"Δ δY at the disk (eq. 9, µm), {th.size} probe positions", "ΔL1·(δ_bottom − δ_top)/L2",
            *remains(y, _orders01(th), tilt[:, None]))


def fit_sphere_form(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    """Lobes of the top sphere's form: the top probe's reading changes, α does not. Template: the
    sphere's reading harmonics 2…10 (analysis/effects/sphere_form.py: a form harmonic of the reading,
    eq. 7's orders RADIAL_ORDERS); nuisance: orders 0 and 1 (eq. 7 removes them)."""
    th, th_, _ = _probes(h)
    _, tp, _ = _probes(p)
    X = harmonic_columns(th, RADIAL_ORDERS)[0]
    return (f"Δ top probe reading (µm), {th.size} positions", "harmonics 2…10 of the reading",
            *remains(th_ - tp, _orders01(th), X))


def setup_columns(rs: list[dict[str, str]]) -> np.ndarray:
    """One indicator column per polygon setup (shift, start face): Hsieh's U_j as the measurement
    model has it (evidence_from_polygon: one U per (shift, start face), shared by directions and reps)."""
    keys = [(r["shift_deg"], r["start_face"]) for r in rs]
    idx = {k: i for i, k in enumerate(dict.fromkeys(keys))}
    X = np.zeros((len(rs), len(idx)))
    X[np.arange(len(rs)), [idx[k] for k in keys]] = 1.0
    return X


def fit_torsion(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    """Friction torque twisting the shaft between disk and polygon: the AC readings change. Template:
    h·approach direction (analysis/effects/torsion_hysteresis.py, the approach from the readings' time
    order, tracing.evidence.approach_direction); nuisance: one U_j per setup (shift, start face),
    shared by both directions as in the measurement model."""
    from benchtwin.analysis.tracing.evidence import approach_direction
    a, b = rows(h / "polygon.csv"), rows(p / "polygon.csv")
    y = col(a, "ac_arcsec") - col(b, "ac_arcsec")
    d = np.array([-1.0 if r["direction"].startswith("b") else 1.0 for r in a])
    app = approach_direction(col(a, "theta_deg"), col(a, "t_s"), d).astype(float)
    return f"Δ AC reading, {len(a)} readings", "h·approach direction", *remains(y, setup_columns(a), app[:, None])


def fit_polygon_pitch(h: Path, p: Path, sc) -> tuple[str, str, float, float]:
    """The true polygon's faces differ from the certificate: the AC readings change. Template: the
    cumulative pitch C(f) of the face under the autocollimator, f = (j + i − 2) mod N + 1, f = 1…N−1
    (analysis/effects/polygon_pitch_ignored.py); nuisance: one constant per run (U_j)."""
    a, b = rows(h / "polygon.csv"), rows(p / "polygon.csv")
    y = col(a, "ac_arcsec") - col(b, "ac_arcsec")
    N = int(sc["bench"]["polygon_faces"])
    f = (col(a, "start_face").astype(int) + col(a, "step").astype(int) - 2) % N + 1
    X = np.column_stack([(f == c).astype(float) for c in range(1, N)])
    return f"Δ AC reading, {len(a)} readings", f"C(f), f = 1…{N - 1}", *remains(y, run_columns(a), X)


def fit_none_polygon(h: Path, p: Path, sc) -> tuple[str, str, float, float | None]:
    """No effect module describes it (thermal_growth): the RMS of the true α's difference at the
    polygon readings (their times: the lobes follow the hub's temperature), a constant removed."""
    a, b = rows(h / "truth" / "polygon.csv"), rows(p / "truth" / "polygon.csv")
    y = col(a, "alpha_arcsec") - col(b, "alpha_arcsec")
    th = np.round(col(a, "target_deg"), 6)
    angles = np.unique(th)
    static = _rms_residual(y, (th[:, None] == angles[None, :]).astype(float))
    NOTES.append(f"thermal_growth: a static error of θ (one value per polygon angle, {angles.size} "
                 f"angles: whatever graduation_error's harmonics could take on these stops) leaves {static:.4f}″")
    return (f"Δα, {len(a)} polygon readings", "no template: out of the library",
            _rms_residual(y, np.ones((y.size, 1))), None)


#: lines printed under the table (what a case measured beside its row)
NOTES: list[str] = []

CASES: dict[str, Callable] = {
    "graduation_error": fit_graduation,
    "selfa_graduation": fit_graduation,
    "interpolation_error": fit_interpolation,
    "tangential_motion": fit_tangential,
    "tangential_motion_no_x": fit_tangential_no_x,
    "ac_drift": fit_ac_drift,
    "ac_scale": fit_ac_scale,
    "ac_nonlinearity": fit_ac_scale,
    "optical_radius": fit_optical_radius,
    "ccd_pixel_scale": fit_ccd_scale,
    "ccd_pixel_scale_pixel_only": fit_ccd_scale,
    "tilt_abbe": fit_tilt_abbe,
    "sphere_form": fit_sphere_form,
    "torsion_hysteresis": fit_torsion,
    "polygon_pitch_ignored": fit_polygon_pitch,
    "thermal_growth": fit_none_polygon,
}

#: settings beyond SMALL where a case's channel needs them: the CCD cases a frame every 30° at
#: 512 × 384 px (Jia eq. 13's line count needs several periods in the field; the order-1 fit of
#: eq. 10 needs ≥ 6 frames), the probe cases the scenario's 120 radial positions (eq. 7's orders
#: 0…10 are 21 columns)
EXTRA: dict[str, dict[str, str | int]] = {
    "ccd_pixel_scale": {"procedure.ccd_step": "30 deg", "instruments.ccd.width": "512 px",
                        "instruments.ccd.height": "384 px"},
    "ccd_pixel_scale_pixel_only": {"procedure.ccd_step": "30 deg", "instruments.ccd.width": "512 px",
                                   "instruments.ccd.height": "384 px"},
    "tilt_abbe": {"procedure.radial_positions": 120},
    "sphere_form": {"procedure.radial_positions": 120},
}


#: the files a null scenario's two runs must share byte for byte (every channel and its truth)
NULL_FILES = ("polygon.csv", "radial_motion.csv", "ccd/index.csv", "truth/encoder_error.csv", "truth/polygon.csv",
              "truth/radial_motion.csv", "truth/ccd.csv", "truth/polygon_beta.csv", "truth/polygon_setup.csv")


def hidden_names() -> tuple[list[str], list[str]]:
    """(effect scenarios, nulls) of scenarios/hidden/: a null's ``[hidden]`` table is empty."""
    effects, nulls = [], []
    for f in sorted((ROOT / "scenarios" / "hidden").glob("*.toml")):
        (effects if load_scenario(f).raw.get("hidden") else nulls).append(f.stem)
    return effects, nulls


def simulate_pair(name: str, work: Path, overrides: dict) -> tuple[Path, Path, object, dict]:
    """The scenario (small settings) and the same without its ``[hidden]`` table, same seed."""
    sc = load_scenario(ROOT / "scenarios" / "hidden" / f"{name}.toml").with_overrides(overrides)
    raw = dict(sc.raw)
    hidden = raw.pop("hidden")
    plain = validate(raw, f"{name} without [hidden]")
    d = work / name
    shutil.rmtree(d, ignore_errors=True)
    simulate(sc, d / "hidden", progress=False, backend="analytic")
    simulate(plain, d / "plain", progress=False, backend="analytic")
    return d / "hidden", d / "plain", sc, hidden


def null_row(nulls: list[str], work: Path) -> str:
    """One row for the nulls: nothing hidden, so the run without ``[hidden]`` is the same run; checked
    (every channel's and every truth file's bytes equal)."""
    same = []
    for name in nulls:
        h, p, _, hidden = simulate_pair(name, work, SMALL)
        assert not hidden, name
        diff = [f for f in NULL_FILES if not ((h / f).exists() and (p / f).exists())
                or (h / f).read_bytes() != (p / f).read_bytes()]   # a missing file is no evidence: it differs
        same.append(f"{'identical' if not diff else 'DIFFER: ' + ', '.join(diff)}")
    verdict = "identical" if all(x == "identical" for x in same) else "; ".join(f"{n}: {x}" for n, x in zip(nulls, same))
    names = ", ".join(f"`{n}`" for n in nulls)
    return (f"| {names} | nothing: `[hidden]` empty | with = without ({len(NULL_FILES)} files: the channels and "
            f"truth/): {verdict} | — (nothing to fit) | — | — | — |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", default="/tmp/hidden_vs_template")
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--no-nulls", action="store_true", help="skip the nulls' with = without check")
    args = ap.parse_args(argv)
    work = Path(args.work)
    effects, nulls = hidden_names()
    missing = [n for n in effects if n not in CASES]
    if missing:
        print(f"scenarios/hidden/: no template comparison for {missing} (add them to CASES)")
        return 2
    names = [n for n in CASES if not args.only or n in args.only]
    out = ["| scenario | cause (twin/hidden.py) | difference (nuisance removed) | template (analysis columns) | "
           "RMS before | RMS after | remains |", "| --- | --- | --- | --- | --- | --- | --- |"]
    t0 = time.time()
    for name in names:
        h, p, sc, hidden = simulate_pair(name, work, {**SMALL, **EXTRA.get(name, {})})
        what, template, before, after = CASES[name](h, p, sc)
        cause = "; ".join(f"{e}: " + ", ".join(sorted(k for k, v in ps.items() if v not in (None, [], 0, 0.0)))
                          for e, ps in hidden.items())
        if after is None:
            out.append(f"| `{name}` | {cause} | {what} | {template} | {before:.4f} | — | — |")
        else:
            frac = after / before if before > 0 else math.nan
            out.append(f"| `{name}` | {cause} | {what} | {template} | {before:.4f} | {after:.4f} | {frac:.1%} |")
        print(out[-1], flush=True)
    todo = [n for n in nulls if not args.only or n in args.only]
    if todo and not args.no_nulls:
        out.append(null_row(todo, work))
        print(out[-1], flush=True)
    print(f"\nwall time {time.time() - t0:.0f} s\n")
    print("\n".join(out))
    for n in NOTES:
        print(f"\n- {n}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
