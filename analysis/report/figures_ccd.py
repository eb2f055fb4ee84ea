"""Pictures of the CCD image analysis (Jia et al. 2019 sec. 4.2, figs. 10–12): one raw frame with
the detected line ends, the fitted edge circle and the reference point R drawn on it, and a frame
the analysis rejected with the reason.

The overlay is the pipeline's own fit of that frame (``first_frame_fit`` of the eccentricity
step: ``analysis.eccentricity.d_ref_px`` with the reference point of the manifest and the edge radius
fixed from the pixel scale), so what is drawn is what was fitted, and the frame's edges are not
found a second time (issue #17); without it (a step result from elsewhere) the fit is recomputed
with the same function and arguments.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np


#: the frame is shown at most this many pixels wide (the figure's width at the report's dpi is
#: ~1000 px): reduced once by pixel-area averaging instead of resampled by matplotlib at draw time
SHOW_WIDTH_PX = 1024


def _grey8(image: np.ndarray) -> np.ndarray:
    """The frame for display: reduced to ≤ SHOW_WIDTH_PX columns (pixel-area mean, cv2.INTER_AREA)
    and stretched between its 0.5 and 99.5 percentiles. Drawn with ``imshow(..., extent=_extent)``
    so that plotted points stay in the full frame's pixel coordinates."""
    import cv2

    g: np.ndarray = np.asarray(image, dtype=np.float32)
    if g.ndim == 3:
        g = g.mean(axis=2, dtype=np.float32)
    H, W = g.shape
    if W > SHOW_WIDTH_PX:
        f = SHOW_WIDTH_PX / W
        g = np.asarray(cv2.resize(g, (SHOW_WIDTH_PX, max(1, round(H * f))), interpolation=cv2.INTER_AREA))
    lo, hi = np.percentile(g, [0.5, 99.5])
    return np.clip((g - lo) / max(float(hi - lo), 1e-9), 0, 1)


def _extent(image: np.ndarray) -> tuple[float, float, float, float]:
    """imshow extent of the whole frame in its own pixel coordinates (pixel centres at integers)."""
    H, W = image.shape[:2]
    return (-0.5, W - 0.5, H - 0.5, -0.5)


def fig_ccd_overlay(image: np.ndarray, fit: Mapping, name: str, theta_deg: float):
    """The frame with line ends (points), rejected ends (crosses), the fitted circle and R."""
    from matplotlib.figure import Figure

    H, W = image.shape[:2]
    fig = Figure(figsize=(9, 9 * H / W))
    ax = fig.subplots()
    # fixed layout (no layout engine): room for the title above and the axis labels left and below
    fig.subplots_adjust(left=0.075, right=0.99, bottom=0.075, top=0.95)
    ax.imshow(_grey8(image), cmap="gray", interpolation="nearest", extent=_extent(image))
    P = np.asarray(fit["points_px"])
    ax.plot(P[:, 0], P[:, 1], "o", ms=3.5, mfc="none", mec="#00c0ff", mew=1.0, label=f"line ends ({P.shape[0]})")
    rej = np.asarray(fit.get("rejected_points_px", np.empty((0, 2)))).reshape(-1, 2)
    if rej.size:
        ax.plot(rej[:, 0], rej[:, 1], "x", ms=7, color="#ff3030", mew=1.5, label=f"rejected ends ({rej.shape[0]})")
    cx, cy = fit["centre_px"]
    r = fit["radius_px"]
    a0 = np.arctan2(-cy, W - cx)
    a1 = np.arctan2(H - cy, W - cx)
    a = np.linspace(min(a0, a1) - 0.05, max(a0, a1) + 0.05, 400)
    ax.plot(cx + r * np.cos(a), cy + r * np.sin(a), "-", color="#ffb000", lw=1.2, label=f"fitted edge (r = {r:.0f} px)")
    rx, ry = fit["reference_px"]
    ax.plot([rx], [ry], "+", ms=16, mew=2, color="#ff40ff", label="reference point R")
    # l: distance from the fitted centre to R, along the radius through R (d_ref = l − r)
    ang = np.arctan2(ry - cy, rx - cx)
    ex, ey = cx + r * np.cos(ang), cy + r * np.sin(ang)
    ax.plot([rx, ex], [ry, ey], "-", color="#ff40ff", lw=1.5)
    ax.set_xlim(0, W)
    ax.set_ylim(H, 0)
    ax.set_xlabel("x (px, radially outward)")
    ax.set_ylabel("y (px)")
    ax.set_title(f"{name} at θ = {theta_deg:.1f}°: d_ref = l − r = {fit['d_ref_px']:.2f} px "
                 f"(residual {fit['residual_rms_px']:.3f} px RMS)", fontsize=10)
    ax.legend(loc="lower left", fontsize=8, framealpha=0.8)
    return fig


def fig_rejected(image: np.ndarray, info: Mapping):
    from matplotlib.figure import Figure

    H, W = image.shape[:2]
    fig = Figure(figsize=(7, 7 * H / W + 0.35))
    ax = fig.subplots()
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=1.0 - 0.35 / (7 * H / W + 0.35))  # the title's 0.35 in
    ax.imshow(_grey8(image), cmap="gray", interpolation="nearest", extent=_extent(image))
    ax.set_title(f"rejected: {info['file']} at θ = {info['theta_deg']:.1f}° ({info['stage']})", fontsize=10)
    ax.text(0.01, 0.01, _wrap(str(info["reason"]), 90), transform=ax.transAxes, fontsize=8, color="#ff3030",
            va="bottom", bbox={"facecolor": "white", "alpha": 0.85, "edgecolor": "none"})
    ax.set_axis_off()
    return fig


def _wrap(s: str, n: int) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(s, n)[:6])


def add_ccd_pictures(rep, ds, ecc: Mapping) -> None:
    """Report: the first analysed frame with its overlay, and the first rejected frame (if any)."""
    from benchtwin.analysis import eccentricity as E

    files: Sequence[str] = ecc.get("files") or []
    thetas = ecc.get("theta_deg") or []
    if not files:
        return
    idx = ds.table("ccd/index")
    row = {str(f): i for i, f in enumerate(idx["file"])}
    f0 = files[0]
    img = ds.read_image(f0, row=row.get(f0, 0) + 2)
    ref = tuple(ds.manifest["ccd"]["reference_px"])
    own = ecc.get("first_frame_fit")
    if own is not None and own.get("file") == f0:
        fit = own["fit"]
    else:
        fit = E.d_ref_px(img, ref, radius_px=ecc.get("radius_fixed_px"), name=f0)
    rep.figure(fig_ccd_overlay(img, fit, f0, float(thetas[0])),
               "A raw CCD frame with the detected line ends, the fitted edge circle and the reference point R (Jia fig. 12)")
    rej = ecc.get("rejected_frames") or []
    if rej:
        r0 = rej[0]
        try:
            img_r = ds.read_image(r0["file"], row=row.get(r0["file"], 0) + 2)
        except Exception:  # noqa: BLE001 - a frame that cannot even be read is stated, not drawn
            rep.paragraph(f"Rejected frame {r0['file']}: {r0['reason']} (the image itself cannot be shown)", note=True)
            return
        rep.figure(fig_rejected(img_r, r0), f"A frame the analysis rejected, with the reason: {r0['reason']}")
