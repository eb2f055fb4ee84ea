"""Figures of the "close the loop" analysis (:mod:`benchtwin.analysis.tracing`).

Jia et al. 2019, fig. 16 compares the polygon-measured encoder error with eq. 5's prediction and
leaves a ±6″ residual; these figures show what happened to that residual here:

- :func:`plot_residual_before_after`: the (closure-centred) residual vs θ before, the identified
  effect's contribution, and the residual after;
- :func:`plot_harmonic_spectrum`: the residual's harmonic amplitudes with their standard
  uncertainties and the significance threshold;
- :func:`plot_signature`: residual vs reading time (drift), vs start face (spread per run), vs the
  polygon face under the autocollimator (a pattern that moves with the start face), and by
  direction of rotation.

Object-oriented matplotlib on the Agg canvas (no pyplot, no global backend switch). Each function
returns the Figure and writes it to ``path`` when given.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..effects import ALL
from ..effects._base import fourier_eval
from ..tracing import Z_GATE, Evidence, _center
from .layout import fixed_margins

__all__ = ["effect_contribution", "plot_residual_before_after", "plot_harmonic_spectrum", "plot_signature",
           "figures_loop"]


def _fig(w: float = 8.0, h: float = 4.5, nrows: int = 1, ncols: int = 1) -> tuple[Figure, np.ndarray]:
    """A figure of w × h inches on the Agg canvas and its nrows × ncols array of Axes."""
    fig = Figure(figsize=(w, h))     # margins set by _save (fixed_margins) when the figure is complete
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, axes


def _save(fig: Figure, path: str | Path | None) -> Figure:
    fixed_margins(fig)
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=110)
    return fig


def _column(values: np.ndarray | float | None) -> np.ndarray:
    """A per-reading column of ``ev``: an array once ``Evidence.__post_init__`` has run (the
    dataclass types its fields as the constructor takes them, where None or a scalar may stand)."""
    if not isinstance(values, np.ndarray):
        raise TypeError(f"Evidence column not filled in by Evidence.__post_init__: {type(values).__name__}")
    return values


def _weights(ev: Evidence) -> np.ndarray:
    """w² = 1/u² per reading, 1/arcsec²."""
    return 1.0 / _column(ev.u_arcsec) ** 2


def _closure_centred(ev: Evidence, x: np.ndarray) -> np.ndarray:
    """``x`` less its w²-weighted mean over each closure group (what one setup error U absorbs)."""
    return _center(x, _column(ev.closure_group), _weights(ev))


def _centred_residual(ev: Evidence) -> np.ndarray:
    return _closure_centred(ev, ev.residual_arcsec)


def effect_contribution(ev: Evidence, result: dict) -> np.ndarray:
    """Sum of the identified (else the best partial / ambiguous) effects' predictions at the
    readings, closure-centred like the residual."""
    effects = result.get("identified_effects") or result.get("partial_effects") or []
    ctx = {"harmonics": result["signature"]["significant_harmonics"]}
    total = np.zeros(ev.n)
    for e in effects:
        total += ALL[e["name"]].predict(ev, e["params"], ctx)
        adj = e.get("regressor_adjustment_coefs")
        if adj:  # the measured regressor as adjusted by the joint fit (errors in variables)
            total += fourier_eval(ev.theta_deg, {int(k): (float(v[0]), float(v[1])) for k, v in adj.items()})
    return _closure_centred(ev, total)


def plot_residual_before_after(ev: Evidence, result: dict, path: str | Path | None = None) -> Figure:
    fig, ax = _fig(9, 5, 2, 1)
    th = ev.theta_deg % 360
    r0 = _centred_residual(ev)
    c = effect_contribution(ev, result)
    o = np.argsort(th)
    names = [e["name"] for e in (result.get("identified_effects") or result.get("partial_effects") or [])]
    a = ax[0, 0]
    a.plot(th, r0, ".", ms=3, color="0.4", label=f"residual before (rms {result['residual_before']['rms_arcsec']:.3f}″)")
    if names:
        a.plot(th[o], c[o], "-", lw=1, color="C3", label="contribution of " + " + ".join(names))
    a.set_ylabel("α − model [arcsec]")
    a.legend(loc="upper right", fontsize=8)
    a.set_title(f"status: {result['status']}", fontsize=10)
    b = ax[1, 0]
    b.plot(th, r0 - c, ".", ms=3, color="C0", label=f"residual after (rms {result['residual_after']['rms_arcsec']:.3f}″)")
    u = float(np.sqrt(np.mean(ev.u_arcsec ** 2)))
    b.axhspan(-2 * u, 2 * u, color="C2", alpha=0.15, label="±2u (measurement)")
    b.set_xlabel("θ [deg]")
    b.set_ylabel("arcsec")
    b.legend(loc="upper right", fontsize=8)
    return _save(fig, path)


def plot_harmonic_spectrum(result: dict, path: str | Path | None = None) -> Figure:
    fig, ax = _fig(8, 4)
    a = ax[0, 0]
    h = result["signature"]["harmonics"]
    k = np.array([x["k"] for x in h])
    amp = np.array([x["amplitude_arcsec"] for x in h])
    u = np.array([x["u_arcsec"] if x["u_arcsec"] is not None else np.nan for x in h])
    sig = np.array([x["significant"] for x in h])
    if np.any(~sig):
        a.bar(k[~sig], amp[~sig], color="0.6", label="not significant")
    if np.any(sig):
        a.bar(k[sig], amp[sig], color="C3", label="significant (Bonferroni p·K < 1e-3)")
    a.errorbar(k, amp, yerr=u, fmt="none", ecolor="k", capsize=2, lw=0.8, label="± u")
    a.plot(k, Z_GATE * u, "_", color="C0", ms=12, mew=1.5, label=f"{Z_GATE:g}·u")
    a.set_xlabel("harmonic k (per turn)")
    a.set_ylabel("amplitude [arcsec]")
    a.set_xticks(k)
    a.legend(fontsize=8)
    return _save(fig, path)


def plot_signature(ev: Evidence, result: dict, path: str | Path | None = None) -> Figure:
    fig, ax = _fig(15, 4, 1, 4)
    r = _centred_residual(ev)
    w2 = _weights(ev)
    t_s, group = _column(ev.t_s), _column(ev.closure_group)
    start_face, face, direction = _column(ev.start_face), _column(ev.face), _column(ev.direction)
    # vs time
    a = ax[0, 0]
    a.plot(t_s, r, ".", ms=3, color="0.4")
    d = result["signature"]["drift"]
    if d.get("slope_arcsec_per_s") is not None:
        tc = t_s - np.bincount(group, w2 * t_s)[group] / np.bincount(group, w2)[group]
        o = np.argsort(t_s)
        a.plot(t_s[o], (d["slope_arcsec_per_s"] * tc)[o], "-", color="C3", lw=0.8,
               label=f"drift {d['slope_arcsec_per_s']:.2e} ± {d['u']:.1e} ″/s")
        a.legend(fontsize=8)
    a.set_xlabel("t [s]")
    a.set_ylabel("residual [arcsec]")
    a.set_title("vs reading time", fontsize=10)
    # vs start face: the closure removes each run's mean, so what is left to see is the spread
    e = ax[0, 1]
    sfs = np.unique(start_face)
    e.plot(start_face + 0.15 * (np.random.default_rng(0).random(ev.n) - 0.5), r, ".", ms=2, color="0.6")
    e.plot(sfs, [np.sqrt(np.mean(r[start_face == j] ** 2)) for j in sfs], "o-", ms=3, color="C3", label="rms per start face")
    e.set_xlabel("start face j")
    e.set_title("vs start face", fontsize=10)
    e.legend(fontsize=8)
    # vs face under the autocollimator
    b = ax[0, 2]
    faces = np.unique(face)
    sf = result["signature"]["start_face"]
    if sfs.size < 2:
        # one start face: the face under the autocollimator is a function of θ, so this panel would
        # redraw the θ panel in another order (issue 34: a degenerate panel); say why it is empty
        b.text(0.5, 0.5, "one start face:\nthe face under the autocollimator\nfollows θ, so a face pattern\n"
               "cannot be told from a θ pattern\n(several start faces can)", ha="center", va="center",
               fontsize=8, color="0.3", transform=b.transAxes)
        b.set_xticks([])
        b.set_yticks([])
        b.set_title("vs polygon face", fontsize=10)
    else:
        m = np.array([np.average(r[face == f], weights=w2[face == f]) for f in faces])
        s = np.array([1.0 / np.sqrt(np.sum(w2[face == f])) for f in faces])
        b.errorbar(faces, m, yerr=s, fmt="o", ms=3, color="C0")
        b.set_title("vs polygon face" + (f" (p = {sf['p_value']:.2g})" if sf.get("p_value") is not None else ""),
                    fontsize=10)
        b.set_xlabel("face under the autocollimator")
    # by direction
    c = ax[0, 3]
    th = ev.theta_deg % 360
    for dval, col, lab in ((1, "C0", "forward"), (-1, "C1", "backward")):
        sel = direction == dval
        if np.any(sel):
            c.plot(th[sel], r[sel], ".", ms=3, color=col, label=lab)
    dd = result["signature"]["direction"]
    c.set_title("by direction" + (f" (half diff. {dd['half_difference_arcsec']:.3f}″)" if dd.get("half_difference_arcsec") is not None else ""),
                fontsize=10)
    c.set_xlabel("θ [deg]")
    c.legend(fontsize=8)
    return _save(fig, path)


def figures_loop(ev: Evidence, result: dict, outdir: str | Path) -> list[Path]:
    """All three figures as PNG files in ``outdir``; returns their paths."""
    outdir = Path(outdir)
    paths = [outdir / "loop_residual.png", outdir / "loop_spectrum.png", outdir / "loop_signature.png"]
    plot_residual_before_after(ev, result, paths[0])
    plot_harmonic_spectrum(result, paths[1])
    plot_signature(ev, result, paths[2])
    return paths
