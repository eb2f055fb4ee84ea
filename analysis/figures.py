"""The report's main figures as public functions that return matplotlib figures (issue 34: a notebook API).

Each returns a ``matplotlib.figure.Figure`` (not attached to pyplot: a notebook shows it as the
cell's value, ``fig.savefig(...)`` writes it); the drawing is the report's own
(analysis/report/figures_*.py), fed from the results or the dataset:

- :func:`figure_error_curve` (results): the encoder error α(θ) with its band ± U (the report's opening figure);
- :func:`figure_residual` (results): measured − Jia model (eq. 5) at the calibrated angles, before and after
  the loop's traced effects, with ± 2u of the measured curve;
- :func:`figure_radial_motion_polar` (dataset): the ISO 230-7 polar plots, total / synchronous / asynchronous;
- :func:`figure_ccd_frame` (dataset): one CCD frame with its line ends, the fitted edge circle and R (Jia fig. 12).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from .dataset import Dataset, open_dataset

__all__ = ["figure_error_curve", "figure_residual", "figure_radial_motion_polar", "figure_ccd_frame"]


def _dataset(dataset: str | Path | Dataset) -> Dataset:
    return dataset if isinstance(dataset, Dataset) else open_dataset(dataset)


def figure_error_curve(results: Mapping[str, Any]) -> Figure:
    """The encoder error a certificate states at each calibrated angle, with the band ± U (U = k·u;
    analysis/calibration.py) and, below, ± U and ± u on a scale of their own. ValueError without
    an encoder error curve."""
    from .calibration import calibration_curve
    from .report.figures_calibration import fig_calibration_curve

    c = calibration_curve(results)
    if c is None or not c.theta_deg:
        raise ValueError("no encoder error curve in these results (the dataset has no polygon or imported curve)")
    return fig_calibration_curve(c)


def figure_residual(results: Mapping[str, Any]) -> Figure:
    """Measured encoder error − the Jia model (eq. 5) at the calibrated angles: before the loop
    (``comparison``) and, when the loop added effects, after (``comparison_after``), with the band
    ± 2u of the measured curve. ValueError without the comparison (no CCD or no polygon)."""
    from .report.layout import fixed_margins

    cmp = results.get("comparison")
    if not isinstance(cmp, Mapping):
        raise ValueError("no comparison of the measured curve with the Jia model in these results (it needs the "
                         "CCD's eccentricity and the polygon's curve)")
    th = np.asarray(cmp["theta_deg"], dtype=float) % 360.0
    o = np.argsort(th)
    fig = Figure(figsize=(8, 4.2))
    ax = fig.subplots()
    rb = results.get("residual_before") or {}
    ax.plot(th[o], np.asarray(cmp["residual_arcsec"], dtype=float)[o], "o-", ms=3, lw=1, color="0.45",
            label=f"before the loop (RMS {float(rb.get('rms_arcsec', np.nan)):.3f}″)")
    after = results.get("comparison_after")
    if isinstance(after, Mapping):
        ra = results.get("residual_after") or {}
        added = ", ".join(ra.get("added_terms") or []) or "the traced effects"
        ax.plot(th[o], np.asarray(after["residual_arcsec"], dtype=float)[o], "o-", ms=3, lw=1, color="C0",
                label=f"after adding {added} (RMS {float(ra.get('rms_arcsec', np.nan)):.3f}″)")
    enc = results.get("encoder_error_arcsec")
    if isinstance(enc, Mapping) and enc.get("u") is not None:
        u = np.asarray([np.nan if v is None else v for v in enc["u"]], dtype=float)
        te = np.asarray(enc["theta_deg"], dtype=float) % 360.0
        oe = np.argsort(te)
        ax.fill_between(te[oe], -2 * u[oe], 2 * u[oe], color="C2", alpha=0.15, lw=0, label="± 2u (measured curve)")
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel("θ (deg)")
    ax.set_ylabel("measured − model (″)")
    ax.set_xlim(0, 360)
    ax.set_title("Residual of the Jia error model (eq. 5) at the calibrated angles", fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    return fixed_margins(fig)


def figure_radial_motion_polar(dataset: str | Path | Dataset, axis: str = "y", order: int = 10) -> Figure:
    """The ISO 230-7 polar plots of the dataset's radial motion (radial_motion.csv): one row per
    location (spheres, disk), total (every revolution) / synchronous (their mean) / asynchronous,
    along ``axis`` "y" (the head direction) or "x" (the X probes). The analysis's own computation
    (Jia eqs. 6–9, analysis/iso230_7.py)."""
    from .pipeline import step_radial_motion
    from .report.figures_iso import fig_polar

    ds = _dataset(dataset)
    if not ds.has("radial_motion"):
        raise ValueError(f"{ds.path}: no radial_motion.csv: no radial motion to plot")
    locs = step_radial_motion(ds, order).iso230_7["locations"]
    chosen = [loc for loc in locs if loc["name"].endswith("_x") == (axis == "x")]
    if axis not in ("x", "y") or not chosen:
        raise ValueError(f"axis {axis!r}: expected 'y', or 'x' when the dataset has X probes")
    if axis == "x":
        return fig_polar(chosen, "Radial error motion along X, ISO 230-7 (fixed sensitive direction, LSC)")
    return fig_polar(chosen)


def figure_ccd_frame(dataset: str | Path | Dataset, frame: int = 0, results: Mapping[str, Any] | None = None) -> Figure:
    """CCD frame number ``frame`` (row of ccd/index.csv) with the detected line ends, the fitted edge
    circle and the reference point R (Jia fig. 12): the analysis's fit of that frame
    (analysis/eccentricity.py ``d_ref_px``), with the edge radius fixed from the results' pixel scale
    when ``results`` are given (as the pipeline fits it), else fitted too."""
    from . import eccentricity as E
    from .report.figures_ccd import fig_ccd_overlay

    ds = _dataset(dataset)
    if not ds.has("ccd/index"):
        raise ValueError(f"{ds.path}: no ccd/index.csv: no CCD frames")
    idx = ds.table("ccd/index")
    n = len(idx["file"])
    if not 0 <= frame < n:
        raise ValueError(f"frame {frame}: expected 0…{n - 1} (rows of {ds.path / 'ccd' / 'index.csv'})")
    f = str(idx["file"][frame]).strip()
    img = ds.read_image(f, row=frame + 2)
    radius_px = None
    ccd = (results or {}).get("ccd")
    edge_mm = ds.bench.get("scale_edge_radius_mm")
    if isinstance(ccd, Mapping) and ccd.get("pixel_um") and edge_mm:
        radius_px = float(edge_mm) * 1000.0 / float(ccd["pixel_um"])
    fit = E.d_ref_px(img, tuple(ds.manifest["ccd"]["reference_px"]), radius_px=radius_px, name=f)
    return fig_ccd_overlay(img, fit, f, float(idx["theta_deg"][frame]))
