"""The report's opening section: the encoder's calibration curve with its expanded uncertainty.

What a lab reads first (issue 34): the error α(θ) at each calibrated angle with the band ±U
(U = k·u, analysis/calibration.py), the table of angle, error, u, U, k, ν as calibration.csv states
them (the same rounded numbers), and what U includes and excludes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ..calibration import CalibrationCurve, calibration_rows
from .layout import fixed_margins

__all__ = ["fig_calibration_curve", "add_calibration_section", "U_BAND_COLOR", "U_BAND_ALPHA"]

#: the band ± U: this colour at this opacity, drawn over the axes' white (so on the page it is the
#: composite 255 − α·(255 − c) per channel, a light blue no other element of the figure fills a region with;
#: tests/app/test_report_u_band_browser.py finds the band by it in a browser screenshot)
U_BAND_COLOR = "tab:blue"
U_BAND_ALPHA = 0.3


def fig_calibration_curve(c: CalibrationCurve) -> Figure:
    """Top: α(θ) with the band α ± U at the calibrated angles (the band joins the points: nothing
    is claimed between them, see the caption). Bottom: the band ± U and ± u about zero on a scale of
    its own, so U stays readable beside an error many times larger."""
    th = np.asarray(c.theta_deg)
    o = np.argsort(th)
    th, e, u, U = th[o], np.asarray(c.error_arcsec)[o], np.asarray(c.u_arcsec)[o], np.asarray(c.U_arcsec)[o]
    fig = Figure(figsize=(8, 5.6))
    top, bot = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [2.2, 1]})
    band = f"± U (k = {c.k:.2f}, p = {c.p:.2f})"
    top.fill_between(th, e - U, e + U, color=U_BAND_COLOR, alpha=U_BAND_ALPHA, lw=0, label=band)
    top.errorbar(th, e, yerr=U, fmt="o-", color="tab:blue", ms=3, lw=1, capsize=2, label="encoder error α")
    top.axhline(0.0, color="0.6", lw=0.8)
    top.set_ylabel("α = reading − reference (″)")
    top.legend(fontsize="small")
    top.set_title("Encoder error with its expanded uncertainty U")
    bot.fill_between(th, -U, U, color=U_BAND_COLOR, alpha=U_BAND_ALPHA, lw=0, label=band)
    bot.plot(th, U, "o-", color="tab:blue", ms=2, lw=0.8)
    bot.plot(th, -U, "o-", color="tab:blue", ms=2, lw=0.8)
    bot.plot(th, u, "--", color="0.3", lw=0.8, label="± u (k = 1)")
    bot.plot(th, -u, "--", color="0.3", lw=0.8)
    bot.axhline(0.0, color="0.6", lw=0.8)
    bot.set_ylabel("± U, ± u (″)")
    bot.set_xlabel("θ (encoder reading, deg)")
    bot.legend(fontsize="small", ncols=2)
    if c.full_turn:
        bot.set_xlim(0, 360)
    return fixed_margins(fig)


def add_calibration_section(rep: Any, c: CalibrationCurve | None) -> None:
    """Heading, figure, what U includes and excludes, and the table (the numbers of calibration.csv)."""
    if c is None or not c.theta_deg:
        return
    rep.heading("Calibration result: the encoder error with its expanded uncertainty")
    nu = f"ν = {math.floor(c.nu)}" if c.nu else "ν = ∞"
    rep.paragraph(f"Curve: {c.label}, at {len(c.theta_deg)} calibrated angles. U = k·u with k = {c.k:.2f} "
                  f"({c.distribution} distribution, {nu}, p = {c.p:.2f}; {c.k_source}). "
                  f"Written beside results.json as calibration.csv and compensation.csv (correction = −error).")
    rep.figure(fig_calibration_curve(c), "Encoder error α at the calibrated angles with the band ± U; the lines "
               "join the points, no value is stated between them")
    rep.paragraph(f"u includes: {c.u_includes}.")
    rep.paragraph(f"u and U do not include: {c.u_excludes}.", note=True)
    rep.paragraph(f"Constant: {c.constant}.")
    if c.left_out_deg:
        rep.paragraph("Not stated (no finite value or u) at θ = " + ", ".join(f"{t:g}°" for t in c.left_out_deg),
                      note=True)
    nu_s = str(math.floor(c.nu)) if c.nu else "∞"
    rep.table([[th, e, u, U, k, nu_s] for th, e, u, U, k in calibration_rows(c)],
              ["θ (°)", "error α (″)", "u (″)", "U (″)", "k", "ν"])
