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
  gain and quadratic columns, v the reading without the effect); nuisance: one constant per run.

"before" is the RMS left after the nuisance columns alone, "after" with the template's columns too.

A remainder near 0 says the template has the physics' shape (Heydemann's sub-division error is
that case: its first and second harmonics ARE the physics); a large remainder says the analysis's
template misses part of the effect (what the loop must then call unexplained or leave in its
residual). Small settings (one radial rep, 24 radial positions, CCD frames every 180°: the CCD and
probes do not enter these channels); the polygon procedure is the scenario's own.

    .venv/bin/python benchmarks/hidden_vs_template.py [--work /tmp/hidden_vs_template] [--only NAME ...]

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


CASES: dict[str, Callable] = {
    "graduation_error": fit_graduation,
    "selfa_graduation": fit_graduation,
    "interpolation_error": fit_interpolation,
    "tangential_motion": fit_tangential,
    "tangential_motion_no_x": fit_tangential_no_x,
    "ac_drift": fit_ac_drift,
    "ac_scale": fit_ac_scale,
    "ac_nonlinearity": fit_ac_scale,
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", default="/tmp/hidden_vs_template")
    ap.add_argument("--only", nargs="*", default=None)
    args = ap.parse_args(argv)
    work = Path(args.work)
    names = [n for n in CASES if not args.only or n in args.only]
    out = ["| scenario | cause (twin/hidden.py) | difference (nuisance removed) | template (analysis columns) | "
           "RMS before ″ | RMS after ″ | remains |", "| --- | --- | --- | --- | --- | --- | --- |"]
    t0 = time.time()
    for name in names:
        sc = load_scenario(ROOT / "scenarios" / "hidden" / f"{name}.toml").with_overrides(SMALL)
        raw = dict(sc.raw)
        hidden = raw.pop("hidden")
        plain = validate(raw, f"{name} without [hidden]")
        d = work / name
        shutil.rmtree(d, ignore_errors=True)
        simulate(sc, d / "hidden", progress=False, backend="analytic")
        simulate(plain, d / "plain", progress=False, backend="analytic")
        what, template, before, after = CASES[name](d / "hidden", d / "plain", sc)
        cause = "; ".join(f"{e}: " + ", ".join(sorted(k for k, v in ps.items() if v not in (None, [], 0, 0.0)))
                          for e, ps in hidden.items())
        frac = after / before if before > 0 else math.nan
        out.append(f"| `{name}` | {cause} | {what} | {template} | {before:.4f} | {after:.4f} | {frac:.1%} |")
        print(out[-1], flush=True)
    print(f"\nwall time {time.time() - t0:.0f} s\n")
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
