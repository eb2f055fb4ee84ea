"""Twin against bench: ``benchtwin compare A B`` (issue 16, item 3).

Two measurements of "the same" bench — a bench dataset and a twin's (before calibration: the
base scenario; after: the scenario of ``calibrate-twin``) — compared through what the analysis
measures on each, never through truth/ (principle 3), so the comparison works for real data too:

- the encoder error α(θ) (results.json ``encoder_error_arcsec``, Hsieh 2022 eq. 7): the difference
  B − A interpolated (periodic, linear) onto A's angles, each curve's mean removed first (α is
  known up to a constant, closure); its RMS and P-V, and the RMS of A's u for scale;
- the synchronous radial error motion of the disk plane (``radial_motion.dY_um``, Jia eq. 9): the
  RMS and P-V of the difference on A's angles;
- the eccentricity and its phase (Jia eqs. 10-13): the difference and its normalised error
  E_n = |Δ| / √(u_A² + u_B²) (ISO 13528 with standard uncertainties, k = 1);
- the residuals: the Jia model's residual before and after close-loop on each (``residual_before``,
  ``residual_after_trace``), and the effects each names.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.analysis.results import ResultsError
from benchtwin.analysis.results_api import Results

__all__ = ["CompareInputError", "compare", "compare_results", "format_comparison"]


class CompareInputError(ValueError):
    """An input compare cannot read (exit 2)."""


def _results_of(path: Path, workdir: Path) -> Results:
    path = Path(path)
    if (path / "results.json").is_file() and not (path / "manifest.json").is_file():
        f = path / "results.json"
    elif path.is_file() and path.name.endswith(".json"):
        f = path
    elif (path / "manifest.json").is_file():
        from benchtwin.analysis.pipeline import analyze

        return analyze(path, workdir, progress=False, close_loop=True)["results"]
    else:
        raise CompareInputError(f"{path}: neither a dataset (manifest.json) nor a results folder (results.json)")
    try:
        return Results.read(f)  # the format's one reader: its error names the file and the key (exit 2)
    except ResultsError as exc:
        raise CompareInputError(str(exc)) from None


def _curve_diff(tha: Any, va: Any, thb: Any, vb: Any, remove_mean: bool) -> dict[str, float] | None:
    try:
        ta, a = np.asarray(tha, dtype=float) % 360.0, np.asarray(va, dtype=float)
        tb, b = np.asarray(thb, dtype=float) % 360.0, np.asarray(vb, dtype=float)
    except (TypeError, ValueError):
        return None
    if a.size < 2 or b.size < 2 or a.shape != ta.shape or b.shape != tb.shape:
        return None
    o = np.argsort(tb)
    bi = np.interp(ta, tb[o], b[o], period=360.0)
    if remove_mean:
        a, bi = a - a.mean(), bi - bi.mean()
    d = bi - a
    return {"rms": float(np.sqrt(np.mean(d ** 2))), "pv": float(np.ptp(d)), "n": int(a.size),
            "rms_a": float(np.sqrt(np.mean(a ** 2))), "rms_b": float(np.sqrt(np.mean(bi ** 2)))}


def _en(a: float | None, ua: float | None, b: float | None, ub: float | None, period: float | None = None) -> dict:
    if a is None or b is None:
        return {"available": False}
    d = float(b) - float(a)
    if period:
        d = (d + period / 2) % period - period / 2
    u = math.hypot(float(ua or 0.0), float(ub or 0.0))
    return {"available": True, "a": float(a), "b": float(b), "difference": d, "u_a": ua, "u_b": ub,
            "E_n": abs(d) / u if u > 0 else float("inf")}


def compare_results(ra: Mapping[str, Any], rb: Mapping[str, Any]) -> dict[str, Any]:
    """The comparison of two results.json (A the reference, usually the bench)."""
    out: dict[str, Any] = {}
    for key, label in (("encoder_error_arcsec", "alpha"), ("encoder_error_corrected_arcsec", "alpha_corrected")):
        ca, cb = ra.get(key), rb.get(key)
        d = None
        if isinstance(ca, dict) and isinstance(cb, dict):
            d = _curve_diff(ca.get("theta_deg"), ca.get("value"), cb.get("theta_deg"), cb.get("value"), True)
            if d is not None and ca.get("u") is not None:
                d["u_rms_a"] = float(np.sqrt(np.mean(np.asarray(ca["u"], dtype=float) ** 2)))
        out[f"{label}_arcsec"] = d or {"available": False}
    ma, mb = ra.get("radial_motion"), rb.get("radial_motion")
    d = None
    if isinstance(ma, dict) and isinstance(mb, dict):
        d = _curve_diff(ma.get("theta_deg"), ma.get("dY_um"), mb.get("theta_deg"), mb.get("dY_um"), False)
    out["radial_motion_dY_um"] = d or {"available": False}
    out["eccentricity_um"] = _en(ra.get("eccentricity_um"), ra.get("eccentricity_u_um"),
                                 rb.get("eccentricity_um"), rb.get("eccentricity_u_um"))
    out["eccentricity_phase_deg"] = _en(ra.get("eccentricity_phase_deg"), ra.get("eccentricity_phase_u_deg"),
                                        rb.get("eccentricity_phase_deg"), rb.get("eccentricity_phase_u_deg"), 360.0)
    res: dict[str, Any] = {}
    for tag, r in (("a", ra), ("b", rb)):
        res[tag] = {
            "before_rms_arcsec": (r.get("residual_before") or {}).get("rms_arcsec"),
            "before_pv_arcsec": (r.get("residual_before") or {}).get("pv_arcsec"),
            "after_trace_rms_arcsec": (r.get("residual_after_trace") or {}).get("rms_arcsec"),
            "identified_effects": [e.get("name") for e in r.get("identified_effects") or []],
            "unexplained": r.get("unexplained"),
        }
    out["residuals"] = res
    return out


def compare(a: Path, b: Path) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="benchtwin-compare-") as tmp:
        ra = _results_of(Path(a), Path(tmp) / "a")
        rb = _results_of(Path(b), Path(tmp) / "b")
    c = compare_results(ra, rb)
    c["a"], c["b"] = str(a), str(b)
    return c


def _f(x: Any, fmt: str = ".3g") -> str:
    return "n/a" if x is None else format(float(x), fmt)


def format_comparison(c: dict[str, Any]) -> str:
    lines = [f"compare A = {c.get('a')}  B = {c.get('b')}  (B − A)"]
    for key, name, unit in (("alpha_arcsec", "encoder error α", "″"), ("alpha_corrected_arcsec", "corrected α", "″"),
                            ("radial_motion_dY_um", "radial motion δY (disk)", " µm")):
        d = c[key]
        if d.get("available") is False:
            lines.append(f"  {name}: not in both")
        else:
            extra = f", u(A) rms {_f(d['u_rms_a'])}{unit}" if "u_rms_a" in d else ""
            lines.append(f"  {name}: difference RMS {_f(d['rms'])}{unit}, P-V {_f(d['pv'])}{unit} over {d['n']} angles "
                         f"(A rms {_f(d['rms_a'])}{unit}{extra})")
    for key, name, unit in (("eccentricity_um", "eccentricity e", " µm"), ("eccentricity_phase_deg", "phase θ0", "°")):
        d = c[key]
        if not d.get("available"):
            lines.append(f"  {name}: not in both")
        else:
            lines.append(f"  {name}: A {_f(d['a'], '.4g')}{unit}, B {_f(d['b'], '.4g')}{unit}, Δ {_f(d['difference'])}{unit}, "
                         f"E_n {_f(d['E_n'], '.2f')}")
    for tag in ("a", "b"):
        r = c["residuals"][tag]
        lines.append(f"  residual {tag.upper()}: Jia model {_f(r['before_rms_arcsec'])}″ RMS / {_f(r['before_pv_arcsec'])}″ P-V,"
                     f" after trace {_f(r['after_trace_rms_arcsec'])}″ RMS; identified: "
                     f"{', '.join(r['identified_effects']) or 'none'}{' (unexplained)' if r['unexplained'] else ''}")
    return "\n".join(lines)
