"""ISO 230-7:2015 polar plots of radial error motion (total, synchronous, asynchronous) and the
spectrum of a continuous rotation with the bearing's kinematic orders marked.

A polar plot draws r(θ) = R0 + S·δ(θ) about the plot's least-squares centre (``analysis.iso230_7``:
the fundamental removed). R0 is chosen so the plot never crosses the centre (R0 = 1.5 × the largest
|δ| of the row); the rings of the grid are labelled in µm of δ, not in r. As spindle analysers do
(Lion Precision SEA), the total plot shows every revolution, the synchronous plot their mean and
the asynchronous plot the deviation of each revolution from that mean around the base circle.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .layout import fixed_margins


def _closed(th_deg: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    o = np.argsort(th_deg)
    t = np.deg2rad(np.asarray(th_deg)[o])
    v = np.asarray(r)[..., o]
    return np.append(t, t[0] + 2 * np.pi), np.concatenate([v, v[..., :1]], axis=-1)


@dataclass(frozen=True)
class _PanelStyle:
    """How one kind of polar panel draws its curves: the kind's name (in the panel's title), the
    line colour and the line width (pt)."""

    kind: str
    colour: str
    line_width_pt: float


#: the three panels of a location's row, left to right
_TOTAL = _PanelStyle("total", "#888", 0.8)
_SYNCHRONOUS = _PanelStyle("synchronous", "#1f4e9a", 1.6)
_ASYNCHRONOUS = _PanelStyle("asynchronous", "#b5401a", 0.8)


def _polar_panel(ax, t: np.ndarray, curves: np.ndarray, R0: float, amax: float, style: _PanelStyle,
                 title: str) -> None:
    """One polar plot drawn on a Cartesian axes (equal aspect): r(θ) = R0 + δ(θ) as x = r cos θ,
    y = r sin θ, θ counter-clockwise from +x (matplotlib's polar default). The grid a polar axes
    would draw is drawn with it — the rings at R0 − amax, R0, R0 + amax labelled in µm of δ at 22.5°
    (over the traces, on a white ground),
    spokes every 45° labelled in degrees, the outer circle at R0 + 1.05·amax — because a polar
    projection costs ~10× as much to lay out and draw (its transforms, tick machinery and the
    extents of every tick label), for the same picture."""
    rmax = R0 + 1.05 * amax
    c, s_ = np.cos(t), np.sin(t)
    ring = np.linspace(0.0, 2 * np.pi, 361)
    cr, sr = np.cos(ring), np.sin(ring)
    ax.plot(rmax * cr, rmax * sr, color="k", lw=0.8)  # the outer circle (a polar axes' spine)
    for dv in (-amax, 0.0, amax):
        ax.plot((R0 + dv) * cr, (R0 + dv) * sr, color="#b0b0b0", lw=0.6)
    for deg in range(0, 360, 45):
        a = np.deg2rad(deg)
        ax.plot([0.0, rmax * np.cos(a)], [0.0, rmax * np.sin(a)], color="#b0b0b0", lw=0.6)
        ax.text(1.13 * rmax * np.cos(a), 1.13 * rmax * np.sin(a), f"{deg}°", fontsize=7, ha="center", va="center")
    for cur in curves:
        r = R0 + cur
        ax.plot(r * c, r * s_, color=style.colour, lw=style.line_width_pt)
    ax.plot(R0 * cr, R0 * sr, color="k", lw=0.5, ls=":")
    # the rings' labels over the traces, on a white ground (issue 34: they were drawn under the
    # traces and unreadable where a trace crossed them)
    a = np.deg2rad(22.5)
    for dv in (-amax, 0.0, amax):
        ax.text((R0 + dv) * np.cos(a), (R0 + dv) * np.sin(a), f"{dv:+.2f}", fontsize=7, ha="left", va="bottom",
                zorder=5, bbox={"boxstyle": "round,pad=0.12", "fc": "white", "ec": "none", "alpha": 0.85})
    lim = 1.22 * rmax
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.set_axis_off()
    # y given: the title stays where matplotlib puts it by default (1.0, above the axes); without it,
    # every draw measures the axes' ticks to move the title above them, which an axes drawn off
    # does not show (a third of the figure's draw; the same pixels)
    ax.set_title(title, fontsize=8.5, y=1.0)


def fig_polar(locations: Sequence[Mapping], title: str = "Radial error motion, ISO 230-7 (fixed sensitive direction, LSC)"):
    """One row per location, columns total / synchronous / asynchronous (fixed layout: no layout
    engine, nothing measured before the one draw)."""
    from matplotlib.figure import Figure

    n = len(locations)
    H = 3.3 * n + 0.6
    fig = Figure(figsize=(10.5, H))
    axes = fig.subplots(n, 3, squeeze=False)
    # a fixed layout: the suptitle and the first row's two-line panel titles in the top 0.95 in
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.15 / H, top=1.0 - 0.95 / H, wspace=0.12, hspace=0.3)
    for row, loc in zip(axes, locations):
        th = np.asarray(loc["theta_deg"], dtype=float)
        tot = np.atleast_2d(loc["total_plot_um"])
        syn = np.asarray(loc["synchronous_plot_um"])
        asy = np.atleast_2d(loc["asynchronous_plot_um"])
        amax = max(float(np.max(np.abs(tot))), float(np.max(np.abs(syn))), float(np.max(np.abs(asy))), 1e-6)
        R0 = 1.5 * amax
        panels = ((tot, _TOTAL, loc["total_um"]), (syn[None, :], _SYNCHRONOUS, loc["synchronous_um"]),
                  (asy, _ASYNCHRONOUS, loc["asynchronous_um"]))
        for ax, (curves, style, value) in zip(row, panels):
            t, c = _closed(th, curves)
            _polar_panel(ax, t, c, R0, amax, style, f"{loc['label']}\n{style.kind}: {value:.3f} µm")
    fig.suptitle(title + "; rings: δ in µm about the base circle", fontsize=10)
    return fig


def fig_spectrum(spec: Mapping, kinematic_orders: Mapping[str, float] | None, label: str):
    """Amplitude per order (cycles/rev) with the bearing's kinematic orders as vertical lines."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 3.4))
    ax = fig.subplots()
    o, a = np.asarray(spec["order"]), np.asarray(spec["amplitude_um"])
    ax.vlines(o, 0, a, color="#1f4e9a", lw=0.8)
    top = float(np.max(a[1:])) if a.size > 1 else 1.0
    for i, (name, k) in enumerate(sorted((kinematic_orders or {}).items(), key=lambda kv: kv[1])):
        for h in (1, 2):
            if h * k <= o[-1]:
                ax.axvline(h * k, color=f"C{i + 1}", ls="--" if h == 1 else ":", lw=0.9,
                           label=f"{name} = {k:.3f}/rev" if h == 1 else None)
    ax.set_xlabel("order (cycles per revolution)")
    ax.set_ylabel("amplitude (µm)")
    ax.set_ylim(0, 1.15 * top)
    ax.set_title(f"Spectrum of the continuous rotation: {label} ({spec['n_revolutions']} revolutions)", fontsize=10)
    if kinematic_orders:
        ax.legend(fontsize=7, loc="upper right")
    return fixed_margins(fig)


def iso_band_label(bw: Mapping) -> str:
    """'orders 2–18/rev' : the short name of a bandwidth (analysis/iso230_7.bandwidth)."""
    hi = bw.get("highest_order")
    return f"orders {bw['lowest_order']}–{hi}/rev" if hi is not None else f"orders ≥ {bw['lowest_order']}/rev"


def add_iso230_7_section(rep, iso: Mapping, ds=None, filtered: Mapping | None = None) -> None:
    """The report's ISO 230-7 subsection: the values with u, the polar plots, and the spectrum of a
    continuous rotation when the dataset has one (table ``radial_continuous``: ``theta_deg``
    unwrapped, the probe columns; the bearing's kinematic orders from the manifest's
    ``bench.bearing_kinematic_orders``, {name: order per revolution})."""
    from benchtwin.analysis.report.html import value_with_u

    locs = iso["locations"]
    rep.heading("Radial error motion values (ISO 230-7:2015)", level=3)
    how = (f"the order-{iso['order']} Fourier series of each revolution (revolutions read at different angles)"
           if iso["filtered"] else "the readings themselves (unfiltered)")
    bw, acq = iso.get("bandwidth"), iso.get("acquisition")
    rep.paragraph(f"Fixed sensitive direction, fundamental removed, about the least-squares centre; "
                  f"{iso['n_revolutions']} revolutions; from {how}."
                  + (f" Bandwidth: {bw['text']}." if bw else "") + (f" Speed: {acq['text']}." if acq else "")
                  + " u: reading noise of the probes (√2·σ for a range, √(2/n)·σ for the synchronous mean), "
                  "standard uncertainties.")
    rows = []
    for loc in locs:
        rows.append([loc["label"]] + [
            value_with_u(loc[f"{k}_um"], loc[f"{k}_u_um"], "µm")
            if np.isfinite(loc[f"{k}_um"]) else "– (one revolution)" for k in ("total", "synchronous", "asynchronous")])
    band = f", {iso_band_label(bw)}" if bw else ""
    rep.table(rows, ["location", f"total{band}", f"synchronous{band}", f"asynchronous{band}"])
    if filtered and not iso["filtered"]:
        f = [(loc["label"], filtered[loc["name"]]) for loc in locs if filtered.get(loc["name"])]

        def vu(v: Mapping, k: str) -> str:
            u = v.get(f"{k}_u_um")
            return value_with_u(v[f"{k}_um"], u if u is not None else float("nan"), "µm")

        rep.paragraph("A different quantity, for comparison: the same values of Jia's order-2…10 Fourier series of "
                      "each revolution (eq. 7, orders 2–10 of the revolution: probe noise and motion above order 10 "
                      "filtered out; u from the probe noise left in the series): "
                      + "; ".join(f"{lab}: {vu(v, 'total')} / {vu(v, 'synchronous')} / {vu(v, 'asynchronous')}"
                                  for lab, v in f) + " (total / synchronous / asynchronous).", note=True)
    y = [loc for loc in locs if not loc["name"].endswith("_x")]
    x = [loc for loc in locs if loc["name"].endswith("_x")]
    rep.figure(fig_polar(y), "ISO 230-7 polar plots along Y (the head direction): total (all revolutions), "
                             "synchronous (their mean), asynchronous (each revolution minus the mean)")
    if x:
        rep.figure(fig_polar(x, "Radial error motion along X, ISO 230-7 (fixed sensitive direction, LSC)"),
                   "ISO 230-7 polar plots along X (the X probes)")
    if ds is not None and ds.has("radial_continuous"):
        from benchtwin.analysis.iso230_7 import spectrum_orders
        from benchtwin.analysis.radial_motion import disk_weights

        t = ds.table("radial_continuous")
        w_top, w_bot = disk_weights(ds.bench["L1_mm"], ds.bench["L2_mm"])
        d = w_top * np.asarray(t["probe_top_um"], dtype=float) + w_bot * np.asarray(t["probe_bottom_um"], dtype=float)
        # the display wraps at 360°: the spectrum needs the unwrapped shaft angle of each sample
        spec = spectrum_orders(np.unwrap(np.asarray(t["theta_deg"], dtype=float), period=360.0), d)
        rep.heading("Spectrum of the continuous rotation", level=3)
        rep.figure(fig_spectrum(spec, ds.bench.get("bearing_kinematic_orders"), "disk plane, Y"),
                   "Amplitude per order of the disk-plane radial motion with the bearing's kinematic orders")
