"""Radial error motion values and polar plots of ISO 230-7:2015 (axes of rotation), fixed sensitive
direction, from the test-sphere probes of Jia et al. 2019 sec. 4.1.

ISO 230-7:2015 (sec. 3 terms, 5.2 / 5.4 radial error motion, annex on polar plots):

- the *error motion polar plot* is r(θ) = R0 + S·δ(θ) around the *polar chart centre* (PC): R0 a
  base circle, S a scale, δ the probe's displacement along the fixed sensitive direction;
- for a fixed sensitive direction the *fundamental* (the once-per-revolution component, the
  centring of the test sphere on the axis) is not part of the error motion and is removed; its
  removal puts the plot about the *least-squares circle centre* (LSC). For δ ≪ R0 the LSC of the
  plot is, to first order, the centre shift a·cos θ + b·sin θ of the least-squares fit (the
  limaçon approximation, exact in the limit ISO 230-7 uses for small errors), so here:
  δ_LSC(θ) = δ(θ) − (c0 + a1 cos θ + b1 sin θ), fitted by least squares;
- **total** error motion: all revolutions together, one LSC; value = the radial difference of the
  two circles about the LSC that just contain the plot = max − min of δ_LSC;
- **synchronous** error motion: the mean over the revolutions at each angle, its own LSC; value =
  max − min;
- **asynchronous** error motion: each revolution's deviation from the synchronous plot; value = the
  maximum over θ of the radial width of the band (max − min over the revolutions at that angle),
  which does not depend on the centre; not defined (NaN, null in results.json) for one revolution.

The disk plane (Jia eq. 9) is the combination w_top·δ_top + w_bot·δ_bot of the two spheres'
readings at the same angle of the same revolution, so its plots follow from the same steps.

Unfiltered: the values use the readings themselves minus the fundamental (ISO 230-7 states the
frequency response; the measured angles are the only low-pass here), unlike Jia's eq. 7 series of
orders 2…10 that ``radial_motion`` reports. When the revolutions do not share their angles (then a
per-angle mean does not exist) the Fourier series of order ``order`` of each revolution is used on a
1° grid instead, and ``filtered`` says so.

Uncertainty (GUM, first order): a range value is the difference of two readings, each with the
probe's reading noise σ (the residual scatter of the order-``order`` Fourier fit of each revolution,
an upper estimate: it also holds motion above that order), so u(total) = u(async) = √2·σ and
u(sync) = √2·σ/√n for the mean of n revolutions. The bias of an extreme value by noise (of order σ)
is within that u.

Spectrum of a continuous rotation (for a run that turns the shaft without stopping): the amplitude
of each order (cycles per revolution) by an FFT over whole revolutions, with the bearing's
kinematic orders (cage, ball pass inner/outer, ball spin; ISO 15243 / Harris & Kotzalas ch. 7)
marked; ``spectrum_orders``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from .fourier import fit_fourier, harmonic_columns

__all__ = ["remove_fundamental", "error_motion", "axial_error_motion", "axial_face_error_motion", "radial_error_motion",
           "spectrum_orders", "bandwidth", "acquisition"]


def _design01(theta_deg: np.ndarray) -> np.ndarray:
    """Columns [1, cos θ, sin θ] (the fundamental of ISO 230-7; analysis/fourier.py builds them)."""
    X = harmonic_columns(theta_deg, [1], cos_first=True)[0]
    return np.column_stack([np.ones(X.shape[0]), X])


def remove_fundamental(theta_deg: np.ndarray, delta_um: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """δ minus its least-squares c0 + a1 cos θ + b1 sin θ (the plot about its LSC); returns (δ_LSC, [c0, a1, b1])."""
    th = np.asarray(theta_deg, dtype=float).ravel()
    d = np.asarray(delta_um, dtype=float).ravel()
    if th.size != d.size:
        raise ValueError(f"theta_deg and delta_um differ in length ({th.size} vs {d.size})")
    if th.size < 4:
        raise ValueError(f"need at least 4 readings to remove the fundamental, got {th.size}")
    A = _design01(th)
    coef, *_ = np.linalg.lstsq(A, d, rcond=None)
    return d - A @ coef, coef


def error_motion(theta_deg: np.ndarray, revs_um: np.ndarray, sigma_um: float | None = None) -> dict:
    """ISO 230-7 total / synchronous / asynchronous error motion of one location.

    ``theta_deg``: the n_θ angles every revolution was read at; ``revs_um``: n_rev × n_θ readings
    along the sensitive direction (µm); ``sigma_um``: a reading's noise (for u). Returns values
    (µm), their u, and the plots (µm about the LSC, on ``theta_deg``)."""
    th = np.asarray(theta_deg, dtype=float).ravel()
    R = np.atleast_2d(np.asarray(revs_um, dtype=float))
    if R.shape[1] != th.size:
        raise ValueError(f"revs_um has {R.shape[1]} angles per revolution, theta_deg {th.size}")
    if not np.all(np.isfinite(R)):
        raise ValueError("revs_um contains non-finite readings")
    n = R.shape[0]
    total, _ = remove_fundamental(np.tile(th, n), R.ravel())
    total = total.reshape(R.shape)
    sync, _ = remove_fundamental(th, R.mean(axis=0))
    asyn = R - R.mean(axis=0)
    s = float(sigma_um) if sigma_um is not None and math.isfinite(sigma_um) else float("nan")
    return {
        "total_um": float(np.ptp(total)),
        "synchronous_um": float(np.ptp(sync)),
        # one revolution has no asynchronous motion to show: not defined (NaN), not zero
        "asynchronous_um": float(np.max(np.ptp(asyn, axis=0))) if n > 1 else float("nan"),
        "total_u_um": math.sqrt(2.0) * s,
        "synchronous_u_um": math.sqrt(2.0 / n) * s,
        "asynchronous_u_um": math.sqrt(2.0) * s if n > 1 else float("nan"),
        "n_revolutions": int(n),
        "theta_deg": th, "total_plot_um": total, "synchronous_plot_um": sync, "asynchronous_plot_um": asyn,
    }


def axial_error_motion(theta_deg: np.ndarray, revs_um: np.ndarray, sigma_um: float | None = None) -> dict:
    """ISO 230-7 axial (or face) error motion of one probe parallel to the axis.

    Unlike the radial case the fundamental is PART of the error motion (ISO 230-7:2015 3.x / ASME
    B89.3.4: a once-per-revolution axial motion at the axis is the axis moving, not a centring of the
    target; at a radius R it holds the tilt motion times R, and the face target's squareness): the
    values are about the polar chart centre (PC): total = max − min of all readings, synchronous =
    max − min of the mean revolution, asynchronous = the largest width over the revolutions at one
    angle (as the radial case). The ``residual_*`` values are the same with the fundamental removed
    (:func:`error_motion`, about the LSC), and ``fundamental_um`` the amplitude of the mean
    revolution's once-per-revolution term. u as :func:`error_motion` (a range is two readings)."""
    th = np.asarray(theta_deg, dtype=float).ravel()
    R = np.atleast_2d(np.asarray(revs_um, dtype=float))
    res = error_motion(th, R, sigma_um)
    n = R.shape[0]
    sync = R.mean(axis=0)
    _, coef = remove_fundamental(th, sync)
    out = {
        "total_um": float(np.ptp(R)),
        "synchronous_um": float(np.ptp(sync)),
        "asynchronous_um": res["asynchronous_um"],
        "total_u_um": res["total_u_um"], "synchronous_u_um": res["synchronous_u_um"],
        "asynchronous_u_um": res["asynchronous_u_um"],
        "residual_total_um": res["total_um"], "residual_synchronous_um": res["synchronous_um"],
        "fundamental_um": float(math.hypot(coef[1], coef[2])),
        "fundamental_u_um": (math.sqrt(2.0 / (n * th.size)) * float(sigma_um)
                             if sigma_um is not None and math.isfinite(sigma_um) else float("nan")),
        "n_revolutions": int(n),
        "theta_deg": th.tolist(), "synchronous_plot_um": (sync - sync.mean()).tolist(),
    }
    return out


def _fourier_sigma(theta_deg: np.ndarray, R: np.ndarray, order: int) -> float | None:
    """A reading's noise: the residual σ of each revolution's Fourier series of order ``order``
    (analysis/fourier.py, as the radial case's fits; an upper estimate: it holds motion above that
    order too), pooled as :func:`radial_error_motion` pools them (RMS over the revolutions)."""
    th = np.asarray(theta_deg, dtype=float)
    if th.size <= 2 * order + 1:
        return None
    s = [fit_fourier(th, row, order).sigma for row in np.atleast_2d(R)]
    return float(np.sqrt(np.mean(np.square(s))))


def axial_face_error_motion(rep: np.ndarray, theta_deg: np.ndarray, axial_um: np.ndarray | None,
                            face_um: np.ndarray | None, face_radius_mm: float | None, order: int = 10) -> dict | None:
    """ISO 230-7 axial error motion (probe on the top sphere's pole, on the axis) and face error motion
    (probe parallel to the axis on the disk's face at ``face_radius_mm``) from ``radial_motion.csv``'s
    optional columns ``probe_axial_um`` / ``probe_face_um``; None when neither was read. JSON-ready."""
    cols = {k: np.asarray(v, dtype=float).ravel() for k, v in (("probe_axial_um", axial_um), ("probe_face_um", face_um))
            if v is not None}
    if not cols:
        return None
    got = _revolutions(np.asarray(rep).ravel(), theta_deg, cols)
    if got is None:
        return {"standard": "ISO 230-7:2015", "locations": [],
                "note": "revolutions read at different angles: no axial/face values (no per-angle mean)"}
    th, revs = got
    locs = []
    for col, name, label in (("probe_axial_um", "axial", "axial, top sphere pole (on the axis)"),
                             ("probe_face_um", "face", "face, disk at radius R")):
        if col not in revs:
            continue
        em = axial_error_motion(th, revs[col], _fourier_sigma(th, revs[col], order))
        d = {"name": name, "label": label, **em}
        if name == "face":
            d["radius_mm"] = None if face_radius_mm is None else float(face_radius_mm)
        locs.append(d)
    return {"standard": "ISO 230-7:2015", "fundamental_removed": False, "centre": "polar chart centre (PC)",
            "sigma_from": f"residual of each revolution's Fourier series of order {order}",
            "bandwidth": bandwidth(th, None), "locations": locs}


#: locations: (name, label, probe column(s), combination)
_LOCATIONS = (
    ("top", "top sphere, Y", "probe_top_um"),
    ("bottom", "bottom sphere, Y", "probe_bottom_um"),
    ("disk", "disk plane, Y (head direction; Jia eq. 9)", None),
    ("top_x", "top sphere, X", "probe_top_x_um"),
    ("bottom_x", "bottom sphere, X", "probe_bottom_x_um"),
    ("disk_x", "disk plane, X (Jia eq. 9)", "x"),
)


def _revolutions(rep: np.ndarray, theta_deg: np.ndarray, cols: Mapping[str, np.ndarray]):
    """Readings per revolution on the common angles: (θ, {col: n_rev × n_θ}) or None if they differ."""
    reps = np.unique(rep)
    grid = None
    out: dict[str, list[np.ndarray]] = {c: [] for c in cols}
    for r in reps:
        m = rep == r
        t = np.round(np.asarray(theta_deg, dtype=float)[m] % 360.0, 9)
        o = np.argsort(t, kind="stable")
        t_sorted = t[o]
        if np.unique(t_sorted).size != t_sorted.size:
            return None  # an angle read twice in one revolution: no single reading per angle
        if grid is None:
            grid = t_sorted
        elif grid.size != t_sorted.size or not np.allclose(grid, t_sorted, atol=1e-6):
            return None
        for c, v in cols.items():
            out[c].append(np.asarray(v, dtype=float)[m][o])
    return grid, {c: np.array(v) for c, v in out.items()}


def radial_error_motion(rep: np.ndarray, theta_deg: np.ndarray, probes: Mapping[str, np.ndarray | None],
                        L1_mm: float, L2_mm: float, rm: Mapping | None = None, order: int = 10) -> dict:
    """ISO 230-7 values and plots at each sphere and the disk plane from ``radial_motion.csv``.

    ``probes``: columns ``probe_top_um``, ``probe_bottom_um`` (and ``probe_top_x_um``,
    ``probe_bottom_x_um`` when the X probes were read). ``rm``: the result of
    :func:`benchtwin.analysis.radial_motion.radial_motion` on the same table (its per-revolution
    fits give σ; its eq. 7 series are the fallback when revolutions differ in their angles)."""
    from benchtwin.analysis.radial_motion import disk_weights

    w_top, w_bot = disk_weights(L1_mm, L2_mm)
    rep_a = np.asarray(rep).ravel()
    cols = {k: np.asarray(v, dtype=float).ravel() for k, v in probes.items() if v is not None}
    got = _revolutions(rep_a, theta_deg, cols)
    filtered = got is None
    if filtered:
        if rm is None:
            raise ValueError("revolutions read at different angles: pass rm (the eq. 7 series) for the filtered values")
        th = np.asarray(rm["theta_deg"], dtype=float)
        revs = {"probe_top_um": np.asarray(rm["delta_top_reps_um"]), "probe_bottom_um": np.asarray(rm["delta_bottom_reps_um"])}
        if "delta_top_x_reps_um" in rm:
            revs["probe_top_x_um"] = np.asarray(rm["delta_top_x_reps_um"])
            revs["probe_bottom_x_um"] = np.asarray(rm["delta_bottom_x_reps_um"])
    else:
        th, revs = got

    def sigma(fit_key: str) -> float | None:
        if rm is None or fit_key not in rm.get("fits", {}):
            return None
        s = [f.sigma for f in rm["fits"][fit_key] if f.sigma is not None and math.isfinite(f.sigma)]
        return float(np.sqrt(np.mean(np.square(s)))) if s else None

    locs = []
    for name, label, col in _LOCATIONS:
        if name in ("disk", "disk_x"):
            a, b = ("probe_top_um", "probe_bottom_um") if name == "disk" else ("probe_top_x_um", "probe_bottom_x_um")
            if a not in revs or b not in revs:
                continue
            R = w_top * revs[a] + w_bot * revs[b]
            sa, sb = sigma(a.replace("probe_", "").replace("_um", "")), sigma(b.replace("probe_", "").replace("_um", ""))
            s = math.hypot(w_top * sa, w_bot * sb) if sa is not None and sb is not None else None
        else:
            if col not in revs:
                continue
            R = revs[col]
            s = sigma(col.replace("probe_", "").replace("_um", ""))
        em = error_motion(th, R, s)
        locs.append({"name": name, "label": label, **em})
    n = locs[0]["n_revolutions"] if locs else 0
    per_turn = min(int(np.unique(np.round(np.asarray(theta_deg, dtype=float)[rep_a == r] % 360.0, 9)).size)
                   for r in np.unique(rep_a))
    return {"standard": "ISO 230-7:2015", "sensitive_direction": "fixed", "centre": "least-squares circle (LSC)",
            "fundamental_removed": True, "filtered": filtered, "order": order if filtered else None,
            "n_revolutions": n, "bandwidth": bandwidth(None if filtered else th, order if filtered else None),
            "acquisition": acquisition(per_turn, n), "locations": locs}


def bandwidth(theta_deg: np.ndarray | None, order: int | None) -> dict:
    """The orders per revolution an error motion value contains, in numbers and words.

    The fundamental removed, the lowest order is 2. Unfiltered (``order`` None), the readings at the
    angles ``theta_deg`` of a turn resolve the orders up to their Nyquist: N/2 for N equally spaced
    positions, 180°/(the largest step) otherwise; motion of higher orders is not removed but aliases
    into the values (stop-and-go readings have no anti-alias filter). Filtered: the Fourier series
    of order ``order`` keeps orders 2…order (Jia eq. 7)."""
    if order is not None:
        return {"lowest_order": 2, "highest_order": int(order), "filter": f"Fourier series of order {order}",
                "text": f"orders 2–{order} of the revolution (the order-{order} Fourier series of each revolution: "
                        f"motion and probe noise above order {order} filtered out)"}
    t = np.sort(np.unique(np.round(np.asarray(theta_deg, dtype=float) % 360.0, 9)))
    steps = np.diff(np.append(t, t[0] + 360.0))
    n = int(t.size)
    equal = bool(np.ptp(steps) <= 1e-6 * 360.0)
    top = n // 2 if equal else int(math.floor(180.0 / float(np.max(steps)) + 1e-9))
    how = (f"the Nyquist order of {n} equally spaced positions per turn" if equal else
           f"the Nyquist order of the largest step between the {n} positions per turn, {float(np.max(steps)):g}°")
    return {"lowest_order": 2, "highest_order": top, "filter": "none",
            "text": f"orders 2–{top} of the revolution (unfiltered: all orders up to {how}; motion of higher "
                    "orders is not filtered out but aliases into the values)"}


def acquisition(positions_per_turn: int, n_revolutions: int) -> dict:
    """How the readings of radial_motion.csv were taken, in numbers and words: the table holds one
    reading per probe at each stop of each revolution (docs/dataset-format.md: stop-and-go
    revolutions), so the values describe the axis at rest at each position, not at a spindle
    speed (a run turning without stopping is the table radial_continuous, its spectrum only)."""
    return {"mode": "step-and-settle", "positions_per_turn": int(positions_per_turn),
            "text": f"step-and-settle: one reading per probe at each of {positions_per_turn} positions per turn "
                    f"with the spindle at rest (no spindle speed), {n_revolutions} revolution"
                    + ("s" if n_revolutions != 1 else "")}


def summary(rem: Mapping) -> dict:
    """The JSON part of :func:`radial_error_motion` for results.json (values, u, plots on θ)."""
    keep = ("name", "label", "total_um", "synchronous_um", "asynchronous_um", "total_u_um", "synchronous_u_um",
            "asynchronous_u_um", "n_revolutions")
    locs = []
    for loc in rem["locations"]:
        d = {k: loc[k] for k in keep}
        d["theta_deg"] = np.asarray(loc["theta_deg"]).tolist()
        d["synchronous_plot_um"] = np.asarray(loc["synchronous_plot_um"]).tolist()
        locs.append(d)
    return {**{k: v for k, v in rem.items() if k != "locations"}, "locations": locs}


def spectrum_orders(theta_deg: np.ndarray, delta_um: np.ndarray, max_order: float = 60.0) -> dict:
    """Amplitude spectrum (µm) of a continuous rotation over whole revolutions, in orders (cycles
    per revolution). ``theta_deg`` is the unwrapped shaft angle at equally spaced samples; the
    record is cut to a whole number of revolutions (no leakage for the shaft's own orders) and
    the fundamental (order 1) is kept: the caller marks what it needs."""
    th = np.asarray(theta_deg, dtype=float).ravel()
    d = np.asarray(delta_um, dtype=float).ravel()
    if th.size != d.size or th.size < 16:
        raise ValueError("need ≥ 16 samples of theta_deg and delta_um of equal length")
    step = float(np.median(np.diff(th)))  # each sample stands for one step of angle
    revs = math.floor((th[-1] - th[0] + step) / 360.0 + 1e-9)
    if revs < 1:
        raise ValueError("the record covers less than one revolution")
    m = th - th[0] < revs * 360.0 - 1e-9
    th, d = th[m], d[m] - np.mean(d[m])
    dt = np.diff(th)
    if np.ptp(dt) > 1e-3 * np.mean(dt):
        # not equally spaced in angle: resample onto an even angle grid (linear, periodic record)
        grid = th[0] + np.arange(th.size) * (revs * 360.0 / th.size)
        d = np.interp(grid, th, d)
    amp = 2.0 * np.abs(np.fft.rfft(d)) / d.size
    orders = np.arange(amp.size) / revs
    keep = orders <= max_order
    return {"order": orders[keep], "amplitude_um": amp[keep], "n_revolutions": int(revs)}
