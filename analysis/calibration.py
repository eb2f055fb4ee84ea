"""The calibration result a lab hands on: the encoder error at each calibrated angle with u, U, k, ν.

One source for the report's opening section, ``calibration.csv``, ``compensation.csv`` and the
certificate (app/certificate.py): :func:`calibration_curve` reads results.json (as
written, or the pipeline's dict before it is written) and says, for the curve it states,

- which curve it is: the loop's corrected curve when a correction of the reference chain was
  applied (``encoder_error_corrected_arcsec``), else the measured one (``encoder_error_arcsec``:
  Hsieh 2022 eq. 3 on a bench dataset, the direction mean of an imported table);
- u at each angle (GUM, k = 1) and what it includes and excludes;
- the coverage factor k with its distribution: on a bench dataset the GUM budget's
  (t-distribution at the Welch–Satterthwaite ν_eff, Hsieh Table 3, JCGM 100 G.4); on an imported
  table with a type A u of ν degrees of freedom, t_{(1+p)/2}(ν) (GUM G.3); with no degrees of freedom,
  k = 2 (normal distribution, p ≈ 95 %);
- U = k·u at each angle;
- how the additive constant is fixed (a full turn determines the error only up to a constant).

:func:`calibration_csv` / :func:`compensation_csv` render it (docs/calibration-files.md);
:func:`write_calibration_files` writes both beside results.json through the one atomic writer
(benchtwin/fsio.py).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .distributions import t_ppf

__all__ = ["CalibrationCurve", "calibration_curve", "ambiguities", "LONE_CURVE_CAUSES", "LONE_CURVE_SEPARATION", "calibration_csv", "compensation_csv", "write_calibration_files",
           "calibration_rows", "CALIBRATION_COLUMNS", "COMPENSATION_COLUMNS", "K_NORMAL", "P_DEFAULT"]

#: the columns of calibration.csv, in this order
CALIBRATION_COLUMNS = ("theta_deg", "error_arcsec", "u_arcsec", "U_arcsec", "k")
#: the columns of compensation.csv, in this order
COMPENSATION_COLUMNS = ("theta_deg", "correction_arcsec", "U_arcsec")
#: coverage factor without degrees of freedom (normal distribution, p ≈ 95 %, GUM 6.3.3)
K_NORMAL = 2.0
P_DEFAULT = 0.95
#: decimals written: angles to 1e-6° (3.6 mas, what an encoder display transmits), arcsec values
#: to 1e-4″, k to 1e-3; u, U and k are rounded UP (a rounded uncertainty never understates)
THETA_DECIMALS, ARCSEC_DECIMALS, K_DECIMALS = 6, 4, 3
#: |mean| below this (arcsec) is a zero mean: the closure (Σα = 0) was applied
ZERO_MEAN_ARCSEC = 1e-9

#: the two repeatability rows of the shift-angle budget: per angle they are the propagated u_A(θ)
_TYPE_A_ROWS = ("Repeatability of angle error measurement", "Repeatability of the pitch angle deviation measurement")


#: the causes a lone curve cannot tell apart (analysis/error_curve.py), in words that assume no
#: reference instrument: an imported table names none
LONE_CURVE_CAUSES = {"graduation_error": "a division error of the scale",
                     "tangential_motion": "a synchronous tangential motion of the axis",
                     "polygon_pitch_ignored": "an error of the (unknown) reference"}
#: what would separate them, in the same words
LONE_CURVE_SEPARATION = ("measuring the axis's tangential motion, re-mounting the scale rotated on the shaft, or a "
                         "calibration in which the reference's own error cancels (a self-calibration with several "
                         "reading heads)")


def ambiguities(res: Mapping[str, Any]) -> list[str]:
    """The ambiguity sets the analysis reported, each in words (an imported curve's in the words of
    :data:`LONE_CURVE_CAUSES`), with the harmonic orders they concern."""
    lone = res.get("kind") == "error-curve"
    out = []
    for a in res.get("ambiguous") or []:
        names = [LONE_CURVE_CAUSES.get(str(n), str(n)) if lone else str(n) for n in a.get("names", [])]
        h = a.get("harmonics")
        out.append(", ".join(names) + (" at harmonic order " + ", ".join(str(x) for x in h) if h else ""))
    return out


@dataclass(frozen=True)
class CalibrationCurve:
    """The encoder error a certificate and the calibration files state (see the module docstring)."""

    key: str                          #: results.json key of the curve
    label: str                        #: what the curve is, in words
    imported: bool                    #: an imported measured table (its reference unknown)
    theta_deg: tuple[float, ...]      #: calibrated angles (encoder reading), deg
    error_arcsec: tuple[float, ...]   #: encoder error α = reading − reference angle, arcsec
    u_arcsec: tuple[float, ...]       #: standard uncertainty (k = 1), arcsec
    U_arcsec: tuple[float, ...]       #: expanded uncertainty k·u, arcsec
    k: float                          #: coverage factor
    p: float                          #: coverage probability
    nu: float | None                  #: degrees of freedom k was taken with (None: normal)
    distribution: str                 #: "t" or "normal"
    k_source: str                     #: where k comes from, in words
    u_includes: str                   #: what u includes
    u_excludes: str                   #: what u (hence U) does not include
    constant: str                     #: how the additive constant of the curve is fixed
    mean_arcsec: float                #: mean of the stated values over the angles
    full_turn: bool                   #: the angles cover a full turn (else an arc)
    step_deg: float | None            #: median spacing of the angles
    left_out_deg: tuple[float, ...]   #: angles of the curve without a finite value or u (not stated)


def _floats(x: Any) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in (x if x is not None else [])], dtype=float)


def _step(theta: np.ndarray) -> float | None:
    th = np.unique(np.mod(theta, 360.0))
    if th.size < 2:
        return None
    gaps = np.diff(np.concatenate([th, [th[0] + 360.0]]))
    return float(np.median(gaps))


def _k_for(nu: float | None, p: float) -> tuple[float, float | None, str]:
    """(k, ν, distribution): t_{(1+p)/2}(⌊ν⌋) (GUM G.3, G.4.1) for finite ν ≥ 1, else k = 2 (normal)."""
    if nu is not None and math.isfinite(nu) and nu >= 1:
        return float(t_ppf(0.5 + p / 2.0, math.floor(nu))), float(nu), "t"
    return K_NORMAL, None, "normal"


def _num(x: Any) -> float | None:
    return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) else None


def _shift_angle_u(res: Mapping[str, Any], corrections: Sequence[Mapping[str, Any]]) -> tuple[str, str]:
    """What u of the shift-angle curve includes (from the budget rows of results.json) and excludes."""
    rep = res.get("repeatability") or {}
    dof = _num(rep.get("dof"))
    bs = res.get("budget_summary") or {}
    typeb = [f"{r['name'].lower()} {float(r['contribution']):.3f}″"
             for r in res.get("budget") or []
             if r.get("kind") in ("member", "contribution") and r.get("name") not in _TYPE_A_ROWS
             and _num(r.get("contribution")) and float(r["contribution"]) >= 5e-4]
    assumed = [k.removesuffix("_arcsec").replace("_", " ") for k, v in (res.get("budget_inputs") or {}).items()
               if isinstance(v, Mapping) and str(v.get("source", "")).startswith("assumed")]
    ac = res.get("autocollimator_declared") or {}
    if ac and ac.get("source") != "manifest":
        assumed.append("autocollimator resolution and maximum error")
    inc = ("u(θ) = √(u_A(θ)² + u_B²): u_A(θ) is the repeatability of the autocollimator readings and of the "
           "polygon's pitch deviations propagated through Hsieh 2022 eqs. 5-7 at each angle (type A"
           + (f", ν = {dof:.0f}" if dof else "") + ")")
    ub = _num(bs.get("u_type_b"))
    if ub is not None:
        inc += f"; u_B = {ub:.3f}″ is the budget's type B part (Hsieh Table 3): " + (", ".join(typeb) or "none")
    if assumed:
        inc += f" (assumed, not declared by the dataset: {', '.join(assumed)})"
    if corrections:
        inc += "; the standard uncertainty of the corrections applied (" + ", ".join(
            str(c.get("effect")) for c in corrections) + ")"
    exc = ("values between the calibrated angles (periods shorter than twice the step, e.g. the sub-division "
           "error, are not sampled); another mounting of the encoder (eccentricity and axis motion differ); "
           "temperature and drift after the calibration; the additive constant of the curve")
    amb = ambiguities(res)
    if amb:
        exc += ("; the effects the analysis could not tell apart (" + "; ".join(amb) + "): they are in the stated "
                "values, uncorrected")
    return inc, exc


def _imported_u(res: Mapping[str, Any]) -> tuple[str, str]:
    up = res.get("u_point") or {}
    src = str(up.get("source") or "not stated")
    dof = _num(up.get("dof"))
    r = _num((res.get("bench") or {}).get("encoder_resolution_arcsec"))
    inc = f"{src}" + (f", ν = {math.floor(dof)}" if dof else "")
    exc = ("the reference instrument's own error and its traceability (the imported table names no reference: "
           "unknown); anything " + ("both directions share" if res.get("hysteresis") else "smooth across the points")
           + " (a systematic error of the reference or of the setup enters every run alike and does not show in "
           "the scatter u is taken from); "
           + (f"the encoder's resolution ({r:g}″ declared, not included); " if r is not None else
              "the encoder's resolution (not declared); ")
           + "values between the calibrated angles; the additive constant of the curve")
    if "given per point" in src:
        exc = "what the table's own u includes is not stated by the import; " + exc
    amb = ambiguities(res)
    if amb:
        exc += ("; the causes the curve cannot tell apart (" + "; ".join(amb) + "): they are in the stated values, "
                "uncorrected")
    return inc, exc


def calibration_curve(res: Mapping[str, Any]) -> CalibrationCurve | None:
    """The curve results.json states, with u, U, k, ν and what u includes; None without an encoder curve."""
    enc = res.get("encoder_error_arcsec")
    if not isinstance(enc, Mapping) or enc.get("value") is None:
        return None
    imported = res.get("kind") == "error-curve"
    key, curve = "encoder_error_arcsec", enc
    corrected = res.get("encoder_error_corrected_arcsec")
    corrections: list[Mapping[str, Any]] = []
    if isinstance(corrected, Mapping) and corrected.get("value") is not None and corrected.get("corrections_applied"):
        key, curve = "encoder_error_corrected_arcsec", corrected
        corrections = list(corrected["corrections_applied"])
    theta = _floats(curve.get("theta_deg"))
    value = _floats(curve.get("value"))
    u = _floats(curve.get("u"))
    if not (theta.size == value.size == u.size) or theta.size == 0:
        raise ValueError(f"results.json: {key}: theta_deg, value and u must be lists of one length")
    bs = res.get("budget_summary") or {}
    p = _num(bs.get("p")) or P_DEFAULT
    if imported:
        k, nu, dist = _k_for(_num((res.get("u_point") or {}).get("dof")), p)
        k_src = (f"t-distribution with the ν = {math.floor(nu)} degrees of freedom of the type A u (GUM G.3)" if nu else
                 "normal distribution (u without degrees of freedom)")
        inc, exc = _imported_u(res)
        imp = res.get("imported_from") or {}
        table = Path(str(imp.get("table"))).name if imp.get("table") else "not stated"
        ndir = "two directions" if res.get("hysteresis") else "one direction"
        label = f"imported measured error curve (table {table}, {ndir}; the mean of the directions at each angle)"
    else:
        k_b, nu_b = _num(bs.get("k")), _num(bs.get("nu_eff"))
        if k_b is not None:   # the budget's k = t_{(1+p)/2}(ν_eff); without ν_eff it is stated as normal
            k, nu, dist = k_b, nu_b, "t" if nu_b is not None else "normal"
            k_src = ("t-distribution at the effective degrees of freedom of the GUM budget (Welch-Satterthwaite"
                     + (f", ν_eff = {math.floor(nu_b)}" if nu_b else "") + "; Hsieh 2022 Table 3, JCGM 100 G.4)")
        else:
            k, nu, dist = K_NORMAL, None, "normal"
            k_src = "normal distribution (no budget with degrees of freedom)"
        inc, exc = _shift_angle_u(res, corrections)
        shifts = sorted((float(s) for s in (res.get("setup_error_arcsec") or {})), key=float)
        faces = (res.get("bench") or {}).get("polygon_faces")
        label = (f"measured against {f'a {faces}-face' if faces else 'an'} optical polygon read by an autocollimator "
                 "(Hsieh 2022 eq. 3"
                 + (f", {len(shifts)} shift angles" if len(shifts) > 1 else ", one shift angle" if shifts else "")
                 + ")")
        if corrections:
            label += ", corrected by the artefacts of the reference chain the loop identified (" + ", ".join(
                str(c.get("effect")) for c in corrections) + ")"
    U_given = _floats(curve.get("U")) if key == "encoder_error_arcsec" and curve.get("U") is not None else None
    U = k * u
    if U_given is not None and U_given.size == U.size:
        U = np.fmax(U, U_given)  # never below k·u
    ok = np.isfinite(theta) & np.isfinite(value) & np.isfinite(u) & (u > 0) & np.isfinite(U)
    mean = float(np.mean(value[ok])) if ok.any() else float("nan")
    cov = res.get("coverage") or {}
    full = bool(cov.get("full_turn", True)) if imported else True
    if imported:
        clo = res.get("closure") or {}
        if clo.get("state") == "not applicable":
            constant = "an arc: no closure; the values as imported"
        else:
            constant = (f"the values as imported ({clo.get('state', 'not stated')}); their mean over the turn is "
                        f"{mean:.3f}″" + (f" ± {float(clo['u_mean_arcsec']):.2f}″" if _num(clo.get("u_mean_arcsec"))
                                          else "") + ", not removed: a full turn determines the error only up to a "
                        "constant")
    elif abs(mean) <= ZERO_MEAN_ARCSEC:
        constant = ("the mean over the calibrated angles is zero (circle closure, Hsieh 2022 eq. 2): the error is "
                    "determined up to a constant")
    else:
        constant = f"the mean over the calibrated angles is {mean:.4f}″ (not removed)"
    return CalibrationCurve(
        key=key, label=label, imported=imported,
        theta_deg=tuple(theta[ok].tolist()), error_arcsec=tuple(value[ok].tolist()), u_arcsec=tuple(u[ok].tolist()),
        U_arcsec=tuple(U[ok].tolist()), k=float(k), p=float(p), nu=nu, distribution=dist, k_source=k_src,
        u_includes=inc, u_excludes=exc, constant=constant, mean_arcsec=mean, full_turn=full,
        step_deg=_step(theta[ok]) if ok.any() else None, left_out_deg=tuple(theta[~ok].tolist()))


# ----------------------------------------------------------------------------- the files


def _fixed(x: float, d: int) -> str:
    s = f"{x:.{d}f}"
    return s[1:] if s.startswith("-") and float(s) == 0.0 else s   # no "-0.0000"


def _up(x: float, d: int) -> str:
    """x rounded up to ``d`` decimals (an uncertainty or a coverage factor: never understated)."""
    s = f"{math.ceil(x * 10 ** d) / 10 ** d:.{d}f}"
    while float(s) < x:  # the product x·10^d rounded down by one unit in the last place
        s = f"{float(s) + 10 ** -d:.{d}f}"
    return s


def calibration_rows(c: CalibrationCurve) -> list[tuple[str, str, str, str, str]]:
    """The rows of calibration.csv as written: U ≥ k·u holds for the written numbers themselves."""
    k_s = _up(c.k, K_DECIMALS)
    out = []
    for th, e, u, U in zip(c.theta_deg, c.error_arcsec, c.u_arcsec, c.U_arcsec):
        u_s = _up(u, ARCSEC_DECIMALS)
        U_s = _up(max(U, float(k_s) * float(u_s)), ARCSEC_DECIMALS)
        while float(U_s) < float(k_s) * float(u_s):
            U_s = f"{float(U_s) + 10 ** -ARCSEC_DECIMALS:.{ARCSEC_DECIMALS}f}"
        out.append((_fixed(th, THETA_DECIMALS), _fixed(e, ARCSEC_DECIMALS), u_s, U_s, k_s))
    return out


def _coverage_words(c: CalibrationCurve) -> str:
    nu = f", ν = {math.floor(c.nu)}" if c.nu else ""
    return f"k = {_up(c.k, K_DECIMALS)} ({c.distribution} distribution{nu}, p = {c.p:.2f}): {c.k_source}"


def _comment(text: str) -> str:
    return "".join(f"# {line}\n" for line in text.splitlines())


def calibration_csv(c: CalibrationCurve) -> str:
    """calibration.csv: ``#`` comment lines (what the numbers are), then the columns of
    :data:`CALIBRATION_COLUMNS`, one row per calibrated angle."""
    head = [
        "benchtwin calibration: the encoder error at each calibrated angle",
        "error_arcsec = encoder reading - reference angle, in arcsec (docs/conventions.md); theta_deg = the encoder "
        "reading, deg",
        f"curve: {c.label} (results.json: {c.key})",
        f"u_arcsec: standard uncertainty (k = 1). It includes: {c.u_includes}.",
        f"It does not include: {c.u_excludes}.",
        f"U_arcsec = k * u_arcsec; {_coverage_words(c)}",
        f"constant: {c.constant}",
        f"rounding: theta to {THETA_DECIMALS} decimals, error to {ARCSEC_DECIMALS}; u and U rounded up to "
        f"{ARCSEC_DECIMALS} decimals, k up to {K_DECIMALS}",
    ]
    if c.left_out_deg:
        head.append("not stated (no finite value or u): theta_deg = " + ", ".join(f"{t:g}" for t in c.left_out_deg))
    body = ",".join(CALIBRATION_COLUMNS) + "\n" + "".join(",".join(r) + "\n" for r in calibration_rows(c))
    return _comment("\n".join(head)) + body


def compensation_csv(c: CalibrationCurve) -> str:
    """compensation.csv: the correction to add to a reading at each calibrated angle (−error), with
    its U; the header states the sign convention and how to interpolate."""
    if c.full_turn:
        interp = ("between the calibrated angles interpolate linearly in theta_deg, periodic over 360 deg (the last "
                  "row's neighbour is the first row + 360 deg)")
    else:
        interp = (f"an arc ({c.theta_deg[0]:g} to {c.theta_deg[-1]:g} deg as listed): interpolate linearly between "
                  "neighbouring rows inside the arc only; no correction is known outside it (do not extrapolate)")
    head = [
        "benchtwin compensation table: the correction to add to an encoder reading",
        "correction_arcsec = -error_arcsec of calibration.csv at each calibrated angle theta_deg (the reading)",
        "sign: error = reading - reference angle, so reference angle = reading + correction_arcsec / 3600 (deg)",
        f"interpolation: {interp}; periods shorter than twice the step"
        + (f" ({2 * c.step_deg:g} deg)" if c.step_deg else "") + " (e.g. the sub-division error) are not sampled: "
        "interpolation does not correct them and U does not include them",
        f"U_arcsec: expanded uncertainty of the correction at the calibrated angle (that of the error, "
        f"{_coverage_words(c)}); u and what it includes: calibration.csv",
        f"constant: {c.constant}",
    ]
    rows = calibration_rows(c)
    body = ",".join(COMPENSATION_COLUMNS) + "\n" + "".join(
        f"{th},{_fixed(-float(e), ARCSEC_DECIMALS)},{U}\n" for th, e, _u, U, _k in rows)
    return _comment("\n".join(head)) + body


def write_calibration_files(out: str | Path, res: Mapping[str, Any]) -> dict[str, str]:
    """calibration.csv and compensation.csv in ``out`` (atomically, benchtwin/fsio.py); {} when the
    results carry no encoder curve. Returns their paths by name ("calibration", "compensation")."""
    from benchtwin.fsio import atomic_write_text

    c = calibration_curve(res)
    if c is None or not c.theta_deg:
        return {}
    out = Path(out)
    return {"calibration": str(atomic_write_text(out / "calibration.csv", calibration_csv(c))),
            "compensation": str(atomic_write_text(out / "compensation.csv", compensation_csv(c)))}
