"""A time-smooth drift of the sphere probes' readings, separated from the θ-synchronous motion.

The two-sphere run (Jia 2019 sec. 4.1) reads the same θ grid on several revolutions at different
times. A drift of the probes' holding stand (its thermal growth along the probe axis, docs/physics.md
"The probes' holding arm") is smooth in TIME and common to every angle; the spindle's synchronous
motion repeats in θ. So each probe's readings are

    y(θ_i, t_i) = m(θ_i) + d(t_i) + c_r + a_r·sin θ_i + b_r·cos θ_i + ε_i

with m a Fourier series of orders 2…K common to the revolutions, c_r, a_r, b_r each revolution's
probe position and sphere centring (eq. 7 removes them per revolution), d a Legendre series of
orders 1…P in the reading time over the run and ε the rest (probe noise and the non-repeating
motion). d is identifiable up to its part that is periodic at the revolution period (which m and
the per-revolution terms take); a polynomial of order P has P zeros over the run, so P ≤ 2·R
(R revolutions) keeps it below one cycle per revolution (:data:`DRIFT_MAX_ORDER_PER_REV`).

Order selection (stated before any data): first whether there is a drift at all, by the F test
of the full model (all identifiable orders up to P_max) against none at significance
:data:`DRIFT_P`; without drift no order is admitted with probability 1 − DRIFT_P per channel, and
then the readings are left untouched (bit for bit). With a drift, its order P (the first P
identifiable Legendre orders) by the smallest BIC (Schwarz 1978: ln n per order, a consistent
criterion that does not admit orders the drift does not have) among 1…P_max. u(d̂) is the fit's
(the joint fit's covariance) and, in quadrature, the truncation: d̂ of all P_max orders less d̂.
Identifiable: a Legendre order is fitted only if its column keeps ≥ :data:`DRIFT_IDENT_MIN` of its
norm once the θ model and the lower orders are projected out. The linear order does not: over evenly
timed revolutions a drift linear in t is a step per revolution (eq. 7's order 0) plus the same
sawtooth in θ every revolution — synchronous motion for any analysis of these readings. So the
drift's linear part over the run stays in the synchronous δY (as before this fit), and the stated
u(d̂) is that of the identifiable part.

What is removed from the readings is d̂ less its part common to the revolutions (its projection on
the θ series of orders 0…K): the synchronous estimate (the mean over revolutions of each harmonic)
is then the readings' own, unchanged, and only the revolutions' deviations from it — the
asynchronous estimate, the 1st harmonic's scatter included — lose the drift. d̂'s common part (a
drift's average shape over the revolutions, e.g. the sawtooth of its linear part) cannot be told
from synchronous motion by these readings; it stays in the synchronous δY, as it did without this
fit, rather than being replaced by the Legendre model's extrapolation. d̂'s per-revolution orders 0
and 1 (nuisance terms of the joint fit) are the Legendre model's: the model decides them.

What the drift MEANS is stated, not decided here: the probes alone cannot tell a common, time-smooth
drift of their stand from a slow drift of the axis. The analysis takes it as the stand's (the
synchronous δY and the asynchronous scatter are formed after removing it); :func:`fit_probe_drift`'s
summary states its size and u, so a reader can see what the choice moved.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchtwin.analysis.fourier import design_matrix
from benchtwin.units import ARCSEC_PER_RAD

__all__ = ["theta_model_basis", "common_theta_basis", "DRIFT_P", "DRIFT_IDENT_MIN", "DRIFT_MAX_ORDER_PER_REV", "DRIFT_MAX_ORDER", "DRIFT_SYNC_ORDER", "ChannelDrift",
           "fit_channel_drift", "fit_probe_drift", "drift_summary"]

#: significance of the nested F test that admits drift orders (per channel)
DRIFT_P = 0.01
#: P_max = DRIFT_MAX_ORDER_PER_REV · R (a Legendre polynomial of order P has P zeros over the run:
#: at most one cycle per revolution), capped by DRIFT_MAX_ORDER
DRIFT_MAX_ORDER_PER_REV = 2
DRIFT_MAX_ORDER = 12
#: a Legendre order is fitted only if its column keeps ≥ this fraction of its norm once the θ model
#: (and the orders kept before it) are projected out; below, the readings cannot tell it from
#: synchronous motion (module docstring)
DRIFT_IDENT_MIN = 0.1
#: order K of the common synchronous series m(θ) in the drift fit (capped at (n − 1)/3 of the
#: revolution with fewest angles, as the asynchronous estimate's noise fit is)
DRIFT_SYNC_ORDER = 40


@dataclass(frozen=True)
class ChannelDrift:
    """One probe's fitted drift: the order P chosen, d̂ at every reading (µm, its mean over the
    readings removed) with its standard uncertainty, and the F tests."""

    order: int
    max_order: int
    drift_um: np.ndarray
    u_drift_um: np.ndarray
    p_value_none: float      # F test of P = 0 against P_max
    p_value_chosen: float    # F test of the chosen P against P_max (1 when P = P_max)
    sigma_um: float          # residual σ of the full fit (noise and non-repeating motion)
    legendre_orders: tuple[int, ...]  # the Legendre orders of d̂ (the first ``order`` identifiable ones)
    #: d̂ less its projection on the θ series common to the revolutions (orders 0…K): what
    #: :meth:`RadialMotionTable.drift_corrected` removes from the readings (µm)
    removed_um: np.ndarray

    def summary(self) -> dict[str, Any]:
        d, u = self.drift_um, self.u_drift_um
        return {"order": int(self.order), "max_order": int(self.max_order),
                "legendre_orders": [int(k) for k in self.legendre_orders],
                "pv_um": float(np.ptp(d)) if d.size else 0.0,
                "rms_um": float(np.sqrt(np.mean(d ** 2))) if d.size else 0.0,
                "u_um": float(np.max(u)) if u.size else 0.0,
                "u_rms_um": float(np.sqrt(np.mean(u ** 2))) if u.size else 0.0,
                "removed_rms_um": float(np.sqrt(np.mean(self.removed_um ** 2))) if self.removed_um.size else 0.0,
                "p_value_none": float(self.p_value_none), "p_value_chosen": float(self.p_value_chosen),
                "residual_sigma_um": float(self.sigma_um)}


def _legendre(t_s: np.ndarray, P: int) -> np.ndarray:
    """Legendre columns P_1…P_P of the reading time mapped onto [−1, 1] over the run."""
    t0, t1 = float(np.min(t_s)), float(np.max(t_s))
    x = (2.0 * (t_s - t0) / (t1 - t0) - 1.0) if t1 > t0 else np.zeros_like(t_s)
    return np.polynomial.legendre.legvander(x, P)[:, 1:]


def theta_model_basis(rep: np.ndarray, theta_deg: np.ndarray, K: int) -> np.ndarray:
    """An orthonormal basis (n × rank) of the θ model: each revolution's orders 0 and 1 (probe
    position, sphere centring; eq. 7 removes them per revolution) and the orders 2…K common to the
    revolutions (the synchronous motion)."""
    rep = np.asarray(rep).ravel()
    th = np.asarray(theta_deg, dtype=float).ravel()
    reps = np.unique(rep)
    F = design_matrix(th, K)
    per_rep = np.zeros((th.size, 3 * reps.size))
    for j, r in enumerate(reps):
        m = rep == r
        per_rep[m, 3 * j:3 * j + 3] = F[m, :3]
    base = np.hstack([per_rep, F[:, 3:]])
    U, sv, _ = np.linalg.svd(base, full_matrices=False)
    return U[:, sv > sv[0] * max(base.shape) * np.finfo(float).eps]


def common_theta_basis(theta_deg: np.ndarray, K: int) -> np.ndarray:
    """An orthonormal basis of the θ series of orders 0…K common to every revolution."""
    F = design_matrix(np.asarray(theta_deg, dtype=float).ravel(), K)
    U, sv, _ = np.linalg.svd(F, full_matrices=False)
    return U[:, sv > sv[0] * max(F.shape) * np.finfo(float).eps]


@dataclass(frozen=True)
class _DriftDesign:
    """What the probes of one run share: the θ model's basis, the identifiable Legendre orders of the
    reading time (raw and with the θ model projected out) and the common θ basis. Built once per run
    (:func:`fit_probe_drift`), not once per probe."""

    K: int
    Pmax: int
    Q: np.ndarray
    L: np.ndarray
    Lp: np.ndarray
    orders: tuple[int, ...]
    th: np.ndarray


def _drift_design(rep: np.ndarray, theta_deg: np.ndarray, t_s: np.ndarray) -> _DriftDesign | None:
    """The run's shared design (:class:`_DriftDesign`); None when the readings cannot carry a
    drift: fewer than 2 revolutions, no spread of the reading times, too few readings per
    revolution, or no identifiable order."""
    rep = np.asarray(rep).ravel()
    th = np.asarray(theta_deg, dtype=float).ravel()
    t = np.asarray(t_s, dtype=float).ravel()
    reps = np.unique(rep)
    R = reps.size
    if R < 2 or not np.all(np.isfinite(t)) or np.ptp(t) <= 0:
        return None
    n_min = min(int(np.count_nonzero(rep == r)) for r in reps)
    K = int(min(DRIFT_SYNC_ORDER, (n_min - 1) // 3))
    if K < 2:
        return None
    Pmax = int(min(DRIFT_MAX_ORDER, DRIFT_MAX_ORDER_PER_REV * R))
    # Frisch–Waugh: the drift terms and the readings with the θ model projected out
    Q = theta_model_basis(rep, th, K)
    L_all = _legendre(t, Pmax)
    Lp_all = L_all - Q @ (Q.T @ L_all)
    # identifiability: an order whose column the θ model (with the orders kept before it) mimics to
    # within DRIFT_IDENT_MIN of its norm is not fitted (a drift linear in t over evenly timed
    # revolutions is a per-revolution step plus the same sawtooth in θ every revolution: ratio ≈ 0.04)
    kept: list[int] = []
    for j in range(Pmax):
        c = Lp_all[:, j]
        if kept:
            Kc = Lp_all[:, kept]
            c = c - Kc @ np.linalg.lstsq(Kc, c, rcond=None)[0]
        ref = float(np.linalg.norm(L_all[:, j] - L_all[:, j].mean()))
        if ref > 0 and float(np.linalg.norm(c)) >= DRIFT_IDENT_MIN * ref:
            kept.append(j)
    if not kept:
        return None
    return _DriftDesign(K, Pmax, Q, L_all[:, kept], Lp_all[:, kept], tuple(j + 1 for j in kept), th)


def fit_channel_drift(rep: np.ndarray, theta_deg: np.ndarray, t_s: np.ndarray, y: np.ndarray,
                      p: float = DRIFT_P) -> ChannelDrift | None:
    """The drift of one probe's readings (module docstring). None when the readings cannot carry
    it: fewer than 2 revolutions, no spread of the reading times, or too few readings."""
    dz = _drift_design(rep, theta_deg, t_s)
    return None if dz is None else _fit_channel(dz, y, p)


def _fit_channel(dz: _DriftDesign, y: np.ndarray, p: float) -> ChannelDrift | None:
    """:func:`fit_channel_drift` on the run's shared design."""
    from benchtwin.analysis.distributions import f_sf

    yy = np.asarray(y, dtype=float).ravel()
    Q, L, Lp, orders, th, K, Pmax = dz.Q, dz.L, dz.Lp, dz.orders, dz.th, dz.K, dz.Pmax
    Pn = len(orders)   # the nested models: the first P of the identifiable orders, P = 0…Pn
    yp = yy - Q @ (Q.T @ yy)
    dof_full = th.size - Q.shape[1] - Pn
    if dof_full < 1:
        return None
    fits = [np.linalg.lstsq(Lp[:, :P], yp, rcond=None)[0] if P else np.zeros(0) for P in range(Pn + 1)]
    rss = [float(np.sum((yp - Lp[:, :P] @ c) ** 2)) for P, c in enumerate(fits)]
    s2 = rss[Pn] / dof_full

    def p_of(P: int) -> float:
        if s2 <= 0:
            return 1.0
        return float(f_sf(max(rss[P] - rss[Pn], 0.0) / (Pn - P) / s2, Pn - P, dof_full))

    p_none = p_of(0)
    if p_none >= p:   # no drift: the readings stay as they are
        order = 0
    else:             # a drift: its order by BIC among 1…Pn (n readings; the θ model's parameters are common)
        n_obs = th.size

        def bic(P: int) -> float:
            return n_obs * math.log(max(rss[P], 1e-300) / n_obs) + P * math.log(n_obs)

        order = min(range(1, Pn + 1), key=lambda P: (bic(P), P))
    p_chosen = p_of(order) if order < Pn else 1.0
    if order == 0:
        z = np.zeros_like(yy)
        return ChannelDrift(0, Pmax, z, z, p_none, p_none, math.sqrt(s2), (), z)
    sig2 = rss[order] / max(th.size - Q.shape[1] - order, 1)
    Lo = Lp[:, :order]
    cov = sig2 * np.linalg.inv(Lo.T @ Lo)  # the drift coefficients' covariance in the joint fit
    # d̂ with its mean over the readings removed (a constant is every revolution's probe position)
    Lc = L[:, :order] - L[:, :order].mean(axis=0)
    d = Lc @ fits[order]
    u2 = np.maximum(np.einsum("ij,jk,ik->i", Lc, cov, Lc), 0.0)
    if order < Pn:  # the truncation: what the full order's drift differs by (model uncertainty, in quadrature)
        Lf = L - L.mean(axis=0)
        u2 = u2 + (Lf @ fits[Pn] - d) ** 2
    u = np.sqrt(u2)
    # what is removed from the readings: d̂ less its part common to the revolutions (its projection on
    # the θ series of orders 0…K): the synchronous estimate (the mean over the revolutions) stays the
    # readings' own, the revolutions' deviations from it (orders 0 and 1 included) lose the drift
    Qc = common_theta_basis(th, K)
    seen = d - Qc @ (Qc.T @ d)
    return ChannelDrift(order, Pmax, d, u, p_none, p_chosen, math.sqrt(s2), orders[:order], seen)


def fit_probe_drift(rep: np.ndarray, theta_deg: np.ndarray, t_s: np.ndarray | None,
                    channels: Mapping[str, np.ndarray | None], p: float = DRIFT_P) -> dict[str, ChannelDrift]:
    """:func:`fit_channel_drift` for each probe column given (None columns skipped); {} without
    reading times."""
    if t_s is None:
        return {}
    dz = _drift_design(rep, theta_deg, t_s)
    out: dict[str, ChannelDrift] = {}
    if dz is None:
        return out
    for name, y in channels.items():
        if y is None:
            continue
        f = _fit_channel(dz, y, p)
        if f is not None:
            out[name] = f
    return out


def drift_summary(fits: Mapping[str, ChannelDrift], t_s: np.ndarray, disk_weights: tuple[float, float],
                  optical_radius_mm: float | None = None) -> dict[str, Any]:
    """results.json's ``radial_motion.probe_drift``: the model, each probe's fit, and the drift carried
    to the disk plane (``disk_weights``: the top and bottom probes' weights of the Abbe extrapolation,
    analysis.radial_motion.disk_weights), µm, with its u from the two probes' independent fits."""
    out: dict[str, Any] = {
        "model": "y(θ, t) = m(θ) + d(t) + per-revolution orders 0, 1 + noise; d: Legendre orders 1…P in the "
                 "reading time over the run, P by a nested F test against P_max = 2·revolutions (≤ 12)",
        "test_p": DRIFT_P, "duration_s": float(np.ptp(np.asarray(t_s, dtype=float))),
        "channels": {c: f.summary() for c, f in fits.items()},
        "treated_as": "the probes' stand (a drift in time, not axis motion): removed from the readings less its "
                      "part common to the revolutions, so the revolutions' asynchronous scatter loses it and the "
                      "synchronous δY (the mean over revolutions) is unchanged; the common part (e.g. the "
                      "sawtooth of a drift linear over the run) cannot be told from synchronous motion",
    }
    wt, wb = disk_weights
    for key, (a, b) in (("disk_y", ("probe_top_um", "probe_bottom_um")),
                        ("disk_x", ("probe_top_x_um", "probe_bottom_x_um"))):
        if a not in fits or b not in fits:
            continue
        d = wt * fits[a].drift_um + wb * fits[b].drift_um
        # u: the two probes' fits are independent (their noise is)
        u = np.hypot(wt * fits[a].u_drift_um, wb * fits[b].u_drift_um)
        out[key] = {"pv_um": float(np.ptp(d)), "rms_um": float(np.sqrt(np.mean(d ** 2))),
                    "u_um": float(np.max(u)), "u_rms_um": float(np.sqrt(np.mean(u ** 2)))}
        if key == "disk_x" and optical_radius_mm:
            # if it were the axis's motion along X: α reads −δX/r (not added to any u; see the note)
            out["as_axis_alpha_pv_arcsec"] = float(np.ptp(d)) / (optical_radius_mm * 1e3) * ARCSEC_PER_RAD
            out["as_axis_note"] = (
                "were the drift the axis's along X, α would move by as_axis_alpha_pv_arcsec over the radial "
                "run's duration_s; a drift in time during the polygon run is what the loop's ac_drift effect "
                "(autocollimator or bench drift ∝ reading time) tests, so it is not added to each reading's u")
    return out
