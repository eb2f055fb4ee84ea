"""Figures in the style of Jia et al. 2019 (Appl. Sci. 9, 3415), figs. 13-16.

- :func:`fig_radial_motion` (fig. 13): radial error motion of the two test spheres and of the disk
  along the reading head (eq. 7, eq. 9), synchronous curve with the repetitions behind it;
- :func:`fig_dref` (fig. 14): d_ref(θ) without its constant term (eq. 10) and its first harmonic
  (the eccentricity, eqs. 11-12);
- :func:`fig_predicted_error` (fig. 15): Δθ(θ) of eq. 5 and its named terms, with ±u band;
- :func:`fig_comparison` (fig. 16): measured α(θ) vs the model (means removed) and the residual.

Every function returns a ``matplotlib.figure.Figure`` built with the object API (no pyplot state,
Agg canvas), so it is safe in tests and in worker processes. Inputs are the dicts returned by
:mod:`benchtwin.analysis.radial_motion`, :mod:`benchtwin.analysis.eccentricity` and
:mod:`benchtwin.analysis.error_model`.
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .layout import fixed_margins

__all__ = ["fig_radial_motion", "fig_dref", "fig_predicted_error", "fig_comparison"]


def _figure(nrows: int = 1, figsize=(7.0, 4.2)):
    fig = Figure(figsize=figsize)     # margins set by fixed_margins when the figure is complete
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, 1, sharex=True, squeeze=False)[:, 0]
    return fig, axes


def _deg_axis(ax):
    ax.set_xlim(0, 360)
    ax.set_xticks(np.arange(0, 361, 60))
    ax.grid(True, alpha=0.3)


def fig_radial_motion(rm: dict, show_reps: bool = True) -> Figure:
    """Fig. 13: δ of the top and bottom spheres and δY of the disk (µm) over θ."""
    fig, (ax,) = _figure()
    th = np.asarray(rm["theta_deg"])
    o = np.argsort(th)
    series = [("delta_top", "top sphere (L1)", "C0"), ("delta_bottom", "bottom sphere (L2)", "C1"),
              ("dY", "grating disk δY (eq. 9)", "C3")]
    for key, label, col in series:
        if show_reps and f"{key}_reps_um" in rm and rm["n_reps"] > 1:
            for rep in np.asarray(rm[f"{key}_reps_um"]):
                ax.plot(th[o], rep[o], color=col, lw=0.6, alpha=0.35)
        ax.plot(th[o], np.asarray(rm[f"{key}_um"])[o], color=col, lw=1.6, label=label)
    s = rm.get("summary", {}).get("disk")
    title = f"Radial error motion (harmonics 2…{rm.get('order', 10)}, eq. 7)"
    if s:
        title += f"\ndisk: total {s['total_um']:.3f} µm, sync {s['synchronous_um']:.3f} µm, async {s['asynchronous_um']:.3f} µm"
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("θ (deg)")
    ax.set_ylabel("radial error motion (µm)")
    _deg_axis(ax)
    ax.legend(fontsize=8, loc="upper right")
    return fixed_margins(fig)


def fig_dref(ecc: dict, theta_deg: np.ndarray | None = None, dref_um: np.ndarray | None = None) -> Figure:
    """Fig. 14: d_ref − c0 (measured points and the order-n series) and its first harmonic."""
    fit = ecc["coefficients"]
    th = np.asarray(theta_deg if theta_deg is not None else ecc["theta_deg"], dtype=float)
    d = np.asarray(dref_um if dref_um is not None else ecc["dref_um"], dtype=float)
    fig, (ax,) = _figure()
    q = np.linspace(0, 360, 721)
    ax.plot(th % 360, d - fit.a0, "o", ms=3.5, color="C0", label="d_ref − c0 (images)")
    ax.plot(q, fit(q, harmonics=range(1, fit.order + 1)), color="C0", lw=1.2, label=f"Fourier series, order {fit.order}")
    ax.plot(q, fit(q, harmonics=[1]), color="C3", lw=1.6, ls="--", label="first harmonic (eccentricity)")
    ax.set_title(f"e = {ecc['e_um']:.2f} ± {ecc['e_u_um']:.2f} µm, θ0 = {ecc['theta0_deg']:.2f} ± "
                 f"{ecc['theta0_u_deg']:.2f}° (eqs. 11-12)", fontsize=10)
    ax.set_xlabel("θ (deg)")
    ax.set_ylabel("d_ref (µm)")
    _deg_axis(ax)
    ax.legend(fontsize=8, loc="upper right")
    return fixed_margins(fig)


def fig_predicted_error(model, theta_deg: np.ndarray | None = None, band: bool = True) -> Figure:
    """Fig. 15: Δθ(θ) of eq. 5 (arcsec) and its named terms; ±u(Δθ) band."""
    th = np.linspace(0, 360, 721) if theta_deg is None else np.asarray(theta_deg, dtype=float)
    fig, (ax,) = _figure()
    total = model.predict(th)
    if band:
        u = model.uncertainty(th)
        if np.any(u > 0):
            ax.fill_between(th, total - u, total + u, color="k", alpha=0.12, lw=0, label="± u(Δθ)")
    for k, (name, v) in enumerate(model.predict_terms(th).items()):
        ax.plot(th, v, lw=1.0, color=f"C{k}", label=name)
    ax.plot(th, total, color="k", lw=1.6, label="Δθ (eq. 5)")
    ax.set_title(f"Predicted angle error, P-V {np.ptp(total):.2f}″", fontsize=10)
    ax.set_xlabel("θ (deg)")
    ax.set_ylabel("Δθ (arcsec)")
    _deg_axis(ax)
    ax.legend(fontsize=8, loc="upper right")
    return fixed_margins(fig)


def fig_comparison(comparison: dict) -> Figure:
    """Fig. 16: measured α and model (means removed) and the residual (arcsec)."""
    c = comparison
    th = np.asarray(c["theta_deg"], dtype=float)
    o = np.argsort(th % 360)
    fig, (ax, axr) = _figure(2, figsize=(7.0, 5.6))
    ax.plot(th[o] % 360, c["measured_arcsec"][o], "o-", ms=3.5, lw=1.0, color="C0", label="measured α (mean removed)")
    ax.plot(th[o] % 360, c["model_arcsec"][o], "s--", ms=3.0, lw=1.0, color="C3", label="model Δθ (mean removed)")
    ax.set_ylabel("angle error (arcsec)")
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(f"Residual P-V {c['residual_pv_arcsec']:.2f}″, RMS {c['residual_rms_arcsec']:.2f}″, "
                 f"{100 * c['fraction_of_error']:.1f} % of the error (RMS), P-V ratio {100 * c['pv_ratio']:.1f} %",
                 fontsize=10)
    _deg_axis(ax)
    axr.plot(th[o] % 360, c["residual_arcsec"][o], "o-", ms=3.0, lw=1.0, color="C2", label="residual = measured − model")
    axr.axhline(0, color="k", lw=0.6)
    axr.set_xlabel("θ (deg)")
    axr.set_ylabel("residual (arcsec)")
    axr.legend(fontsize=8, loc="upper right")
    _deg_axis(axr)
    return fixed_margins(fig, row_gap_in=0.2)     # shared x: the upper axes has no tick labels
