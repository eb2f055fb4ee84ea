"""Radial error motion of the shaft and of the grating disk from two test spheres (Jia 2019, sec. 4.1).

Jia et al., Appl. Sci. 9 (2019) 3415, sec. 4.1 and sec. 5:

- each probe's readings, per repetition, are fitted with a Fourier series of order 10 (eq. 6);
- the 0th harmonic (probe position) and the 1st (test-sphere centring) are removed (eq. 7):
  ``δ(θ) = Σ_{i=2}^{10} (a_i sin iθ + b_i cos iθ)``;
- tilt (eq. 8): ``ε_X(θ) = (δ_{Y,L1}(θ) − δ_{Y,L2}(θ)) / L2``;
- radial motion of the disk along the head direction (eq. 9):
  ``δ_Y(θ) = ((L2 − L1)/L2) δ_{Y,L1}(θ) + (L1/L2) δ_{Y,L2}(θ)``;
  L1: top sphere → disk, L2: top sphere → bottom sphere (docs/conventions.md, "Spheres and probes");
- repeatability (sec. 5): range over the n repetitions at each θ divided by d_n (d_3 = 1.69).

ISO 230-7:2015 decomposition (fixed sensitive direction): the synchronous error motion is the
average over the repetitions at each angle, the asynchronous error motion the deviation of each
repetition from it. Error-motion values (all P-V type for a fixed sensitive direction):

- ``total_um``: range of all repetitions' δ(θ) together;
- ``synchronous_um``: range of the synchronous δ(θ);
- ``asynchronous_um``: maximum over θ of the range over repetitions at that θ (ISO 230-7 value);
  ``asynchronous_pv_um``: range of all asynchronous values together (reported as well).

Signs: probe readings are the displacement of the sphere surface along lab +Y (+X for ``_x_um``).
``tilt_x_urad`` is eq. 8 as printed, positive when the top sphere moves further toward +Y than the
bottom one (this is a right-handed rotation about −X); ``tilt_y_urad = (δ_{X,L1} − δ_{X,L2})/L2``
is a right-handed rotation about +Y. µm/mm = mrad, reported in µrad.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchtwin.analysis.fourier import (FourierFit, design_matrix, evaluate, evaluate_harmonics, fit_fourier,
                                        fit_harmonics, harmonic_columns, integrate_harmonics, perturbation_columns)

__all__ = ["D_N", "range_method_u", "error_motion_values", "radial_motion", "disk_weights", "RadialMotion",
           "RADIAL_ORDERS", "ASYNC_P", "ASYNC_NOISE_ORDER", "ASYNC_BAND",
           "ProbeReadings", "SphereSpacing", "RadialOptions"]

#: Harmonic order set of the radial-motion series (eq. 7: orders 2…10; 0 = probe position and
#: 1 = sphere centring are removed).
RADIAL_ORDERS = tuple(range(2, 11))

#: Non-repeating (asynchronous) motion of the axis (:meth:`RadialMotion.async_rms`): its part along
#: X at the time of the polygon readings is unmeasured (the probes run in other revolutions) and
#: reads −δX_async/r. Its size is known from the probes' rep-to-rep scatter (isotropic: the same
#: along X as along Y) in the band of orders 1…ASYNC_BAND (eq. 7's series and the order 1), with
#: the probes' noise from each rep's residual about a series of order ASYNC_NOISE_ORDER (white
#: noise, smooth motion); counted only if the scatter exceeds that noise at p < ASYNC_P (F test).
ASYNC_P = 0.01
ASYNC_NOISE_ORDER = 40
ASYNC_BAND = 10

#: δX at the disk (channel ``dX_um``, the tangential-motion regressor: a head on +Y reads −δX/r at
#: every order, not only eq. 7's 2…10) is fitted at orders 2…X_ORDERS_MAX, capped by the probe grid
#: as the asynchronous estimate is (a rep of n angles: order ≤ (n − 1)/3). A ball bearing's δX has
#: orders near the ball-pass orders (z·(1 ∓ d/D)/2 per revolution: 4…8 and 13…15 for 12 balls) that
#: a truncation at 10 leaves to the polygon residual (hidden benches, seed 11: 0.26″ RMS of −δX/r
#: above order 10, of 0.63″). The single X probes' channels (``top_x_um``, ``bottom_x_um``) and the
#: Y channels stay at eq. 7's orders.
X_ORDERS_MAX = ASYNC_NOISE_ORDER

#: The order-1 backward whirl (RadialMotion.order1_model_error) enters the tangential regressor
#: only where the probes resolve it: |B| ≥ 3 u(|B|), the z ≥ 3 of ``significant_orders`` (the orders
#: of δX "the X probes resolve", docs/effects.md); below, its noise (≈ 0.1″ per component at 0.17 µm
#: repeatability) would enter α's model for nothing.
BACKWARD_WHIRL_Z_MIN = 3.0

# d_n of the range method (mean range of n normal samples / σ), n = 2…25 (the d2 constants of
# control-chart tables, e.g. Montgomery, Introduction to Statistical Quality Control, app. VI).
# Jia uses 1.69 for n = 3. The scenario schema allows radial_reps ≤ 25 to match (issue #13).
D_N: dict[int, float] = {2: 1.128, 3: 1.693, 4: 2.059, 5: 2.326, 6: 2.534, 7: 2.704, 8: 2.847, 9: 2.970, 10: 3.078,
                         11: 3.173, 12: 3.258, 13: 3.336, 14: 3.407, 15: 3.472, 16: 3.532, 17: 3.588, 18: 3.640,
                         19: 3.689, 20: 3.735, 21: 3.778, 22: 3.819, 23: 3.858, 24: 3.895, 25: 3.931}


def disk_weights(L1_mm: float, L2_mm: float) -> tuple[float, float]:
    """Weights (w_top, w_bottom) of eq. 9: ((L2 − L1)/L2, L1/L2)."""
    if not (L2_mm > 0 and math.isfinite(L1_mm) and math.isfinite(L2_mm)):
        raise ValueError(f"need L2 > 0 and finite L1, got L1={L1_mm}, L2={L2_mm}")
    return (L2_mm - L1_mm) / L2_mm, L1_mm / L2_mm


def range_method_u(values_reps: np.ndarray, d_n: float | None = None) -> np.ndarray:
    """Range method (Jia sec. 5): (max − min over repetitions, axis 0) / d_n, at each θ.

    The result estimates the standard deviation of one repetition; Jia takes it as the
    uncertainty of δY. ``d_n`` defaults to :data:`D_N` [n] (1.693 for n = 3; the paper rounds 1.69).
    """
    v = np.asarray(values_reps, dtype=float)
    n = v.shape[0]
    if d_n is None:
        if n not in D_N:
            raise ValueError(f"no d_n tabulated for n = {n} repetitions (2…25); pass d_n")
        d_n = D_N[n]
    return (v.max(axis=0) - v.min(axis=0)) / d_n


def error_motion_values(values_reps: np.ndarray) -> dict[str, float]:
    """ISO 230-7 error-motion values (fixed sensitive direction) of δ(θ) given per repetition
    (shape n_reps × n_theta, common grid): total, synchronous, asynchronous (max range at one θ)
    and asynchronous P-V."""
    v = np.asarray(values_reps, dtype=float)
    sync = v.mean(axis=0)
    asyn = v - sync
    return {
        "total_um": float(np.ptp(v)),
        "synchronous_um": float(np.ptp(sync)),
        "asynchronous_um": float(np.max(np.ptp(v, axis=0))) if v.shape[0] > 1 else 0.0,
        "asynchronous_pv_um": float(np.ptp(asyn)),
    }


def _with_u(values: dict[str, float], point_var_um2: float, n_reps: int) -> dict[str, float]:
    """The error-motion values with their standard uncertainties from the probe noise (GUM, first
    order, as analysis/iso230_7.py): a range is the difference of two points of the curves, each
    with variance ``point_var_um2``, so u(total) = u(asynchronous) = √(2·var) and u(synchronous) =
    √(2·var/n) for the mean of n revolutions; the asynchronous value of one revolution has none."""
    s2 = point_var_um2 if math.isfinite(point_var_um2) else float("nan")
    return {**values, "total_u_um": math.sqrt(2.0 * s2), "synchronous_u_um": math.sqrt(2.0 * s2 / n_reps),
            "asynchronous_u_um": math.sqrt(2.0 * s2) if n_reps > 1 else float("nan")}


@dataclass
class RadialMotion:
    """Sphere probe readings on a θ grid (radial_motion.csv), µm, all reps pooled: the motion as a
    series the tracing (analysis/tracing/) evaluates at any θ, with the uncertainty of each of its
    coefficients (:func:`radial_motion` is the per-repetition reduction the results report).

    Each channel is reduced to its Fourier series of orders 2…10 (Jia eq. 7: orders 0 and 1 are
    probe position and sphere centring); δY at the disk by eq. 9, δX likewise from the X probes.
    Channels: ``top_um``, ``bottom_um``, ``dY_um`` and, with X probes, ``top_x_um``,
    ``bottom_x_um``, ``dX_um``. ``at``/``integral_at`` evaluate a channel or its antiderivative in θ
    (radians; µm·rad) anywhere.
    """

    theta_deg: np.ndarray
    top_um: np.ndarray
    bottom_um: np.ndarray
    L1_mm: float
    L2_mm: float
    top_x_um: np.ndarray | None = None
    bottom_x_um: np.ndarray | None = None
    orders: tuple = RADIAL_ORDERS
    rep: np.ndarray | None = None
    _coefs: dict = field(default_factory=dict, init=False, repr=False)
    _u: dict = field(default_factory=dict, init=False, repr=False)
    _o1: dict = field(default_factory=dict, init=False, repr=False)
    _bw: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self):
        th = np.asarray(self.theta_deg, dtype=float)
        wt, wb = disk_weights(self.L1_mm, self.L2_mm)  # eq. 9
        raw = {"top_um": self.top_um, "bottom_um": self.bottom_um}
        if self.top_x_um is not None and self.bottom_x_um is not None:  # has_x
            raw.update(top_x_um=self.top_x_um, bottom_x_um=self.bottom_x_um)
        for name, y in raw.items():
            # orders 0 and 1 fitted and dropped (eq. 7), orders 2…10 kept, with their type-A u
            self._coefs[name], self._u[name] = fit_harmonics(th, y, self.orders, nuisance_ks=(1,), return_u=True)
        self.combos = {n: {n: 1.0} for n in raw}
        self.combos["dY_um"] = {"top_um": wt, "bottom_um": wb}
        if self.has_x:
            xks = self._x_orders(th)
            if xks == tuple(self.orders):
                self.combos["dX_um"] = {"top_x_um": wt, "bottom_x_um": wb}
            else:  # δX over every order the X probes' grid determines (X_ORDERS_MAX)
                for name in ("top_x_um", "bottom_x_um"):
                    self._coefs[name + "@x"], self._u[name + "@x"] = fit_harmonics(
                        th, raw[name], xks, nuisance_ks=(1,), return_u=True)
                self.combos["dX_um"] = {"top_x_um@x": wt, "bottom_x_um@x": wb}
            # order 1 of each sphere's X and Y readings (eq. 7 drops it as the centring), for the
            # backward whirl (``order1_model_error``): the same orders as δX, type-A u
            for name in ("top_um", "bottom_um", "top_x_um", "bottom_x_um"):
                c1, u1 = fit_harmonics(th, raw[name], (1,) + xks, return_u=True)
                self._o1[name] = (c1[1], u1[1])
        self.combos["bottom_minus_top_um"] = {"bottom_um": 1.0, "top_um": -1.0}
        for out, combo in self.combos.items():
            if out not in self._coefs:
                ks = self._combo_orders(combo)
                self._coefs[out] = {k: (sum(w * self._coefs[c][k][0] for c, w in combo.items()),
                                        sum(w * self._coefs[c][k][1] for c, w in combo.items())) for k in ks}

    def _x_orders(self, th: np.ndarray) -> tuple:
        """Orders of δX at the disk: 2…X_ORDERS_MAX, at most (n − 1)/3 for the rep with fewest angles
        (all readings as one rep without ``rep``), never fewer than eq. 7's."""
        if self.rep is not None:
            n = min(int(np.count_nonzero(np.asarray(self.rep) == r)) for r in np.unique(np.asarray(self.rep)))
        else:
            n = int(np.unique(np.round(np.mod(th, 360.0), 9)).size)
        kmax = int(min(X_ORDERS_MAX, (n - 1) // 3))
        top = max(self.orders) if len(self.orders) else 0
        return tuple(self.orders) + tuple(range(top + 1, kmax + 1)) if kmax > top else tuple(self.orders)

    #: the order of the four sphere channels in the order-1 maps below
    _O1_NAMES = ("top_x_um", "top_um", "bottom_x_um", "bottom_um")

    def _backward_whirl_map(self) -> np.ndarray:
        """(2 × 8) map from the order-1 coefficients [a, b] (a sin θ + b cos θ) of the four sphere
        channels (:data:`_O1_NAMES`) to (Re B, Im B) of the disk's backward whirl: per sphere
        B = ((b_x − a_y) + i(b_y + a_x))/2, carried to the disk plane by eq. 9's weights."""
        wt, wb = disk_weights(self.L1_mm, self.L2_mm)
        M = np.zeros((2, 8))
        for i, w in enumerate((wt, wb)):  # [a_x, b_x, a_y, b_y] of the sphere
            M[0, 4 * i:4 * i + 4] = w * np.array([0.0, 0.5, -0.5, 0.0])
            M[1, 4 * i:4 * i + 4] = w * np.array([0.5, 0.0, 0.0, 0.5])
        return M

    def _order1_values(self, which: int) -> np.ndarray:
        """The order-1 coefficients (``which`` = 0) or their type-A u (1) of the four channels."""
        return np.array([x for n in self._O1_NAMES for x in self._o1[n][which]])

    def _order1_map(self, camera_azimuth_deg: float) -> np.ndarray:
        """(2 × 8) map from the four channels' order-1 coefficients to (a₁, b₁) of
        :meth:`order1_model_error`: G = B·(1 + e^{−2iψ}), a₁ = Im G, b₁ = Re G."""
        re, im = self._backward_whirl_map()
        G = (re + 1j * im) * (1.0 + np.exp(-2j * math.radians(camera_azimuth_deg)))
        return np.vstack([G.imag, G.real])

    def backward_whirl_z(self) -> float:
        """|B| / u(|B|) of the disk's order-1 backward whirl (:meth:`order1_model_error`), u from
        the order-1 coefficients' type-A u (first order, as :meth:`significant_orders`); 0 without
        X probes."""
        if not self._o1:
            return 0.0
        if "z" not in self._bw:   # the order-1 coefficients are fixed at construction: once per instance
            self._bw["z"] = self._backward_whirl_z()
        return self._bw["z"]

    def _backward_whirl_z(self) -> float:
        re, im = self._backward_whirl_map()
        v, u = self._order1_values(0), self._order1_values(1)
        br, bi = float(re @ v), float(im @ v)
        ur, ui = float(np.sqrt(np.sum((re * u) ** 2))), float(np.sqrt(np.sum((im * u) ** 2)))
        amp = math.hypot(br, bi)
        ua = math.hypot(br * ur, bi * ui) / amp if amp > 0 else 0.0
        return amp / ua if ua > 0 else (math.inf if amp > 0 else 0.0)

    def resolves_backward_whirl(self) -> bool:
        """Whether the probes resolve the backward whirl (X probes, |B| ≥ BACKWARD_WHIRL_Z_MIN·u):
        the one gate of :meth:`order1_model_error` and its perturbations."""
        return bool(self._o1) and self.backward_whirl_z() >= BACKWARD_WHIRL_Z_MIN

    def order1_model_error(self, camera_azimuth_deg: float = 180.0) -> dict[int, tuple[float, float]]:
        """{1: (a₁, b₁)} µm: the order-1 error, in δX at the disk, of a model that takes the disk
        centre's order-1 motion as one forward circle measured by a CCD at ``camera_azimuth_deg``
        from the head (Jia eqs. 3, 10–12: e and θ0), for a head on +Y reading −c_x/r. The lab-fixed
        order-1 motion c = F e^{iθ} + B e^{−iθ} (c = x + iy) has a forward part F (eccentricity,
        sphere centring, an orbit with the shaft: one circle, which the CCD measures) and a backward
        part B, which no centring produces; only the X and Y probes of one sphere together separate
        them (B = ((b_x − a_y) + i(b_y + a_x))/2 of their order-1 coefficients), at the disk by
        eq. 9. The CCD reads c's radial component at its azimuth ψ and takes all of it as forward,
        F' = F + conj(B)·e^{2iφ_c}, so the head's error less the model's is
        −Re(B e^{−iθ}(1 + e^{−2iψ}))/r: −2B_x/r with the camera opposite the head (Jia's set-up),
        0 at ψ = 90°. Empty without X probes (B is then unmeasured)."""
        if not self.resolves_backward_whirl():
            return {}
        a1, b1 = self._order1_map(camera_azimuth_deg) @ self._order1_values(0)
        return {1: (float(a1), float(b1))}

    def order1_model_error_perturbations(self, theta_deg, camera_azimuth_deg: float = 180.0) -> np.ndarray:
        """(n × 8) change of :meth:`order1_model_error` at θ for a 1-u change of each order-1
        coefficient of the four sphere channels (type A); (n × 0) without X probes."""
        th = np.asarray(theta_deg, dtype=float)
        if not self.resolves_backward_whirl():
            return np.zeros((th.size, 0))
        Mu = self._order1_map(camera_azimuth_deg) * self._order1_values(1)
        sc, _ = harmonic_columns(th, (1,))  # [sin θ, cos θ]
        return np.outer(sc[:, 0], Mu[0]) + np.outer(sc[:, 1], Mu[1])

    def _combo_orders(self, combo: dict) -> list:
        return [k for k in self._coefs[next(iter(combo))] if all(k in self._coefs[c] for c in combo)]

    def perturbations(self, theta_deg, name: str, kind: str = "value", orders=None) -> np.ndarray:
        """(n × m) change of channel ``name`` (value, integral or quadrature) at θ for a 1-u change of
        each raw Fourier coefficient it is made of (the probe data's own uncertainty); ``orders``:
        only those harmonics."""
        key = ("p", name, kind, None if orders is None else tuple(orders))
        return self._cached(key, theta_deg, lambda: self._perturbations(theta_deg, name, kind, orders))

    def _perturbations(self, theta_deg, name, kind, orders) -> np.ndarray:
        sel = (lambda u: u) if orders is None else (lambda u: {k: v for k, v in u.items() if k in orders})
        return np.hstack([perturbation_columns(theta_deg, sel(self._u[c]), w, kind) for c, w in self.combos[name].items()])

    def _cached(self, key, theta_deg, make):
        """The columns for ``key`` at these θ, computed once (the tracing asks for the same ones for
        every candidate that scales them by its parameters); read-only, the same bytes every time."""
        th = np.ascontiguousarray(theta_deg, dtype=float)
        cache = self.__dict__.setdefault("_columns_cache", {})
        k = (key, th.shape, th.tobytes())
        if k not in cache:
            out = np.asarray(make())
            out.flags.writeable = False
            cache[k] = out
        return cache[k]

    def form_perturbations(self, theta_deg, name: str, u_um: float, kind: str = "integral", orders=None) -> np.ndarray:
        """(n × m) change of channel ``name`` at θ for a change of u_um (µm) in each Fourier coefficient
        (orders 2…10, or ``orders``) of the spheres' readings it is made of: the unmeasured sphere
        form (type B)."""
        if not u_um or u_um <= 0:
            return np.zeros((np.size(theta_deg), 0))
        u = {k: (float(u_um), float(u_um)) for k in (self.orders if orders is None else orders)}
        return self._cached(("f", name, kind, float(u_um), tuple(u)), theta_deg,
                            lambda: np.hstack([perturbation_columns(theta_deg, u, w, kind) for c, w in self.combos[name].items()]))

    def async_rms(self, name: str = "dY_um", p: float = ASYNC_P) -> dict:
        """The non-repeating (asynchronous) motion of channel ``name`` (µm RMS over θ), in the band of
        orders 1…``ASYNC_BAND`` (eq. 7's series and the order 1 that a sphere's centring hides only
        when it repeats): the scatter of each rep's Fourier coefficients about their mean over the
        reps (ISO 230-7's asynchronous error, band-limited), minus the probes' own noise in that band
        (the noise from each rep's residual about a series of order ``ASYNC_NOISE_ORDER``: white
        noise, smooth motion). ``sigma_um`` = 0 unless the scatter exceeds the noise at
        significance ``p`` (F test). Needs ``rep`` with ≥ 3 reps; {} otherwise."""
        # computed once per (channel, p): the tracing asks for it with every problem it builds
        cache = self.__dict__.setdefault("_async_cache", {})
        if (name, p) not in cache:
            cache[(name, p)] = self._async_rms(name, p)
        return dict(cache[(name, p)])

    def _async_rms(self, name: str, p: float) -> dict:
        if self.rep is None:
            return {}
        rep = np.asarray(self.rep).astype(int)
        reps = np.unique(rep)
        R = reps.size
        if R < 3:
            return {}
        th = np.asarray(self.theta_deg, dtype=float)
        raw = {"top_um": self.top_um, "bottom_um": self.bottom_um, "top_x_um": self.top_x_um, "bottom_x_um": self.bottom_x_um}
        y = np.asarray(sum(w * np.asarray(raw[c.split("@")[0]], dtype=float) for c, w in self.combos[name].items()), dtype=float)
        KB = ASYNC_BAND
        coefs, d2, nd, v = [], 0.0, 0, []
        for r in reps:
            m = rep == r
            n_r = int(m.sum())
            K = int(min(ASYNC_NOISE_ORDER, (n_r - 1) // 3))
            if K < KB:
                return {}
            try:  # eq. 6 per revolution, order K
                f = fit_fourier(th[m], y[m], K)
            except ValueError:  # the revolution's angles do not determine the series: no estimate
                return {}
            d2 += float(np.sum(f.residual ** 2))
            nd += f.dof
            coefs.append(f.params[1:2 * KB + 1])
            v.append(2.0 / n_r)   # a sine/cosine coefficient's variance per unit noise variance
        n2 = d2 / max(nd, 1)
        C = np.array(coefs)
        dev = C - C.mean(axis=0)
        s2 = float(np.sum(dev ** 2)) / 2.0 / (R - 1)        # band RMS² of a rep's deviation
        noise_band = KB * n2 * float(np.mean(v))             # the noise's share of it
        from benchtwin.analysis.distributions import f_isf

        f_crit = float(f_isf(p, 2 * KB * (R - 1), max(nd, 1)))
        sig = s2 > f_crit * noise_band
        return {"sigma_um": math.sqrt(max(s2 - noise_band, 0.0)) if sig else 0.0, "scatter_um": math.sqrt(s2),
                "noise_in_band_um": math.sqrt(noise_band), "noise_um": math.sqrt(n2), "band_orders": KB,
                "significant": bool(sig), "n_reps": int(R)}

    def coef_u(self, name: str) -> dict[int, tuple[float, float]]:
        """Type-A standard uncertainties of channel ``name``'s coefficients {k: (u(a_k), u(b_k))}."""
        combo = self.combos[name]
        return {k: (math.sqrt(sum((w * self._u[c][k][0]) ** 2 for c, w in combo.items())),
                    math.sqrt(sum((w * self._u[c][k][1]) ** 2 for c, w in combo.items()))) for k in self._combo_orders(combo)}

    def significant_orders(self, name: str, z_min: float = 3.0) -> list[int]:
        """Orders whose amplitude in channel ``name`` is ≥ z_min standard uncertainties (type A):
        the motion the probes resolve, as opposed to their noise."""
        c, u = self.coefs(name), self.coef_u(name)
        out = []
        for k in c:
            a, b = c[k]
            amp = math.hypot(a, b)
            ua = math.sqrt((a * u[k][0]) ** 2 + (b * u[k][1]) ** 2) / amp if amp > 0 else 0.0
            if amp > 0 and (ua == 0 or amp / ua >= z_min):
                out.append(k)
        return out

    @property
    def has_x(self) -> bool:
        return self.top_x_um is not None and self.bottom_x_um is not None

    @property
    def channels(self) -> list[str]:
        return [c for c in self._coefs if c != "bottom_minus_top_um" and not c.endswith("@x")]

    def coefs(self, name: str) -> dict[int, tuple[float, float]]:
        return self._coefs[name]

    @property
    def highest_order(self) -> int:
        """The highest harmonic order of any series the channels and their perturbations are made
        of (eq. 7's 2…10, δX's up to X_ORDERS_MAX, the order 1 of the backward whirl): every
        function of θ built from this motion (value, integral, quadrature) is band-limited to it."""
        return max([1] + [max(c) for c in self._coefs.values() if c])

    def at(self, theta_deg, name: str, orders=None) -> np.ndarray:
        c = self._coefs[name]
        return evaluate_harmonics(theta_deg, c if orders is None else {k: c[k] for k in orders if k in c})

    def integral_at(self, theta_deg, name: str) -> np.ndarray:
        return integrate_harmonics(theta_deg, self._coefs[name])


def _check(name: str, a: np.ndarray | None, n: int) -> np.ndarray | None:
    if a is None:
        return None
    x = np.asarray(a, dtype=float).ravel()
    if x.size != n:
        raise ValueError(f"{name}: expected {n} values (as many as rep), got {x.size}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name}: non-finite value at index {int(np.flatnonzero(~np.isfinite(x))[0])}")
    return x


@dataclass(frozen=True)
class ProbeReadings:
    """The columns of ``radial_motion.csv`` (one row per reading): repetition label, θ (deg) and the
    sphere probes' readings (µm; the X probes optional, both or neither)."""

    rep: np.ndarray
    theta_deg: np.ndarray
    probe_top_um: np.ndarray
    probe_bottom_um: np.ndarray
    probe_top_x_um: np.ndarray | None = None
    probe_bottom_x_um: np.ndarray | None = None

    @classmethod
    def from_table(cls, table: Mapping[str, np.ndarray]) -> ProbeReadings:
        """The readings from a dataset's radial_motion table (its column names are the field names)."""
        return cls(table["rep"], table["theta_deg"], table["probe_top_um"], table["probe_bottom_um"],
                   probe_top_x_um=table.get("probe_top_x_um"), probe_bottom_x_um=table.get("probe_bottom_x_um"))


@dataclass(frozen=True)
class SphereSpacing:
    """The lengths of eqs. 8-9 (mm): L1 top sphere → disk, L2 top sphere → bottom sphere, with their
    standard uncertainties (propagated through eq. 9)."""

    L1_mm: float
    L2_mm: float
    u_L1_mm: float = 0.0
    u_L2_mm: float = 0.0


@dataclass(frozen=True)
class RadialOptions:
    """How :func:`radial_motion` reduces the readings.

    ``order``: Fourier order of eq. 6; ``u_probe_um``: standard uncertainty of one probe reading (µm;
    None: the residual scatter of each fit); ``grid_deg``: the evaluation grid when the repetitions'
    angles differ; ``d_n``: the range method's constant (None: :data:`D_N`); ``keep_residual``: keep
    the readings minus orders 0 and 1 instead of eq. 7's series."""

    order: int = 10
    u_probe_um: float | None = None
    grid_deg: np.ndarray | None = None
    d_n: float | None = None
    keep_residual: bool = False


@dataclass(frozen=True)
class _Checked:
    """The validated readings (flat float arrays; the X probes None or both given)."""

    rep: np.ndarray
    theta_deg: np.ndarray
    top_um: np.ndarray
    bottom_um: np.ndarray
    top_x_um: np.ndarray | None
    bottom_x_um: np.ndarray | None


@dataclass(frozen=True)
class _Reduction:
    """What every stage of :func:`radial_motion` shares: the readings' repetitions and angles, the
    common grid, eq. 7's design matrix on it and the options."""

    rep: np.ndarray            # label of each reading
    theta_deg: np.ndarray      # angle of each reading
    reps: np.ndarray           # the distinct labels
    grid_deg: np.ndarray       # the common evaluation grid
    G: np.ndarray              # harmonics 2…order on the grid (eq. 7)
    order: int
    u_probe_um: float | None
    keep_residual: bool


def _checked_readings(readings: ProbeReadings) -> _Checked:
    """The readings as flat finite float arrays of one length (ValueError naming the column otherwise)."""
    rep_a = np.asarray(readings.rep).ravel()
    n = rep_a.size
    th = _check("theta_deg", readings.theta_deg, n)
    top = _check("probe_top_um", readings.probe_top_um, n)
    bot = _check("probe_bottom_um", readings.probe_bottom_um, n)
    topx = _check("probe_top_x_um", readings.probe_top_x_um, n)
    botx = _check("probe_bottom_x_um", readings.probe_bottom_x_um, n)
    if (topx is None) != (botx is None):
        raise ValueError("probe_top_x_um and probe_bottom_x_um must be given together")
    assert th is not None and top is not None and bot is not None
    return _Checked(rep_a, th, top, bot, topx, botx)


def _common_grid(rep_a: np.ndarray, th: np.ndarray, reps: np.ndarray, options: RadialOptions) -> np.ndarray:
    """The evaluation grid: the measured angles when every repetition has the same set, otherwise
    ``grid_deg`` or 360 points at 1°. ``keep_residual`` needs the first case."""
    sets = [np.unique(np.round(th[rep_a == r] % 360.0, 9)) for r in reps]
    same = all(s.size == sets[0].size and np.allclose(s, sets[0]) for s in sets)
    if options.grid_deg is not None:
        grid = np.asarray(options.grid_deg, dtype=float).ravel()
    elif same:
        grid = sets[0]
    else:
        grid = np.arange(360) * 1.0
    if options.keep_residual and (options.grid_deg is not None or not same):
        raise ValueError("keep_residual=True needs every repetition at the same angles (no grid_deg)")
    return grid


def _channel(ctx: _Reduction, values: np.ndarray, label: str) -> tuple[list[FourierFit], np.ndarray]:
    """One probe's eq. 6 fit per repetition and its curve on the grid (n_reps × n_grid): eq. 7's
    series, or with ``keep_residual`` the readings minus the fitted orders 0 and 1."""
    fits: list[FourierFit] = []
    curves = []
    th, order = ctx.theta_deg, ctx.order
    for r in ctx.reps:
        m = ctx.rep == r
        try:
            f = fit_fourier(th[m], values[m], order, ctx.u_probe_um)
        except ValueError as exc:
            raise ValueError(f"{label}, repetition {r}: {exc}") from None
        fits.append(f)
        if ctx.keep_residual:
            # data minus the 0th and 1st harmonics, at the measured angles (sorted onto the grid)
            tm = np.round(th[m] % 360.0, 9)
            o = np.argsort(tm, kind="stable")
            tm, vm = tm[o], values[m][o] - (design_matrix(th[m], order, harmonics=(0, 1)) @ f.params)[o]
            _, first = np.unique(tm, return_index=True)
            curves.append(vm[first])
        else:
            curves.append(ctx.G @ f.params)
    return fits, np.array(curves)


def _point_var(ctx: _Reduction, fl: list[FourierFit], w: float = 1.0) -> float:
    """w²·(variance of one revolution's curve at a point from the probe noise), mean over θ and reps:
    gᵀ·cov·g of the series (harmonics 2…order), or σ² itself for the kept residual."""
    if ctx.keep_residual:
        return float(np.mean([w**2 * (ctx.u_probe_um if ctx.u_probe_um is not None else f.sigma) ** 2 for f in fl]))
    return float(np.mean([w**2 * np.mean(np.einsum("ij,jk,ik->i", ctx.G, f.cov, ctx.G)) for f in fl]))


def _summary(ctx: _Reduction, fa: list[FourierFit], fb: list[FourierFit], curves: tuple[np.ndarray, ...],
             weights: tuple[float, float]) -> tuple[dict[str, float], ...]:
    """ISO 230-7 values with u (:func:`_with_u`) of a probe pair and its disk-plane combination:
    ``curves`` = (top, bottom, disk) per repetition, ``weights`` = eq. 9's (w_top, w_bottom)."""
    n = ctx.reps.size
    w_top, w_bot = weights
    return (_with_u(error_motion_values(curves[0]), _point_var(ctx, fa), n),
            _with_u(error_motion_values(curves[1]), _point_var(ctx, fb), n),
            _with_u(error_motion_values(curves[2]), _point_var(ctx, fa, w_top) + _point_var(ctx, fb, w_bot), n))


def _bandwidth(order: int, keep_residual: bool) -> dict[str, Any]:
    """The orders per revolution the curves hold (2…order, or 2 and up unfiltered), with words."""
    if keep_residual:
        return {"lowest_order": 2, "highest_order": None, "filter": "none",
                "text": "orders 2 and up of the revolution (the readings minus orders 0 and 1, unfiltered)"}
    return {"lowest_order": 2, "highest_order": int(order), "filter": f"Fourier series of order {order} (Jia eq. 7)",
            "text": f"orders 2–{order} of the revolution (Jia eq. 7's series of each revolution: motion and "
                    f"probe noise above order {order} filtered out)"}


def _mean_series(fa: list[FourierFit], fb: list[FourierFit], weights: tuple[float, float],
                 order: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean over reps of w_top·(top series) + w_bot·(bottom series), harmonics 2…order: its
    parameters (µm) and their GUM covariance."""
    w_top, w_bot = weights
    keep = np.zeros(2 * order + 1)
    keep[3:] = 1.0
    k = len(fa)
    p = sum(w_top * f.params + w_bot * g.params for f, g in zip(fa, fb)) / k * keep
    cov = sum(w_top**2 * f.cov + w_bot**2 * g.cov for f, g in zip(fa, fb)) / k**2
    cov = cov * np.outer(keep, keep)
    return p, cov


def _pair(ctx: _Reduction, top: np.ndarray, bot: np.ndarray, names: tuple[str, str],
          spacing: SphereSpacing) -> dict[str, Any]:
    """Both probes of one direction reduced: per-rep fits and curves, their eq. 9 disk-plane
    combination and eq. 8 tilt (µrad), and the mean series of the combination."""
    wts = disk_weights(spacing.L1_mm, spacing.L2_mm)
    fa, top_r = _channel(ctx, top, names[0])
    fb, bot_r = _channel(ctx, bot, names[1])
    disk_r = wts[0] * top_r + wts[1] * bot_r
    tilt_r = (top_r - bot_r) / spacing.L2_mm * 1e3  # µm/mm = mrad → µrad
    params, cov = _mean_series(fa, fb, wts, ctx.order)
    mean = disk_r.mean(axis=0)
    fn = _interp_fn(ctx.grid_deg, mean) if ctx.keep_residual else _series_fn(params, ctx.order)
    return {"fits": (fa, fb), "top_r": top_r, "bot_r": bot_r, "disk_r": disk_r, "tilt_r": tilt_r,
            "params": params, "cov": cov, "mean": mean, "fn": fn,
            "summary": _summary(ctx, fa, fb, (top_r, bot_r, disk_r), wts)}


def _gum_u(ctx: _Reduction, y: dict[str, Any],
           spacing: SphereSpacing) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """GUM variance of the synchronous δY at each θ from the fit covariances (probe noise) and
    u(L1), u(L2) (and the reading noise the kept residual carries): (var, var_fit, (the L1 term,
    the L2 term))."""
    L1, L2 = spacing.L1_mm, spacing.L2_mm
    w_top, w_bot = disk_weights(L1, L2)
    var_fit = np.einsum("ij,jk,ik->i", ctx.G, y["cov"], ctx.G)
    dtop, dbot = y["top_r"].mean(axis=0), y["bot_r"].mean(axis=0)
    dd_dL1 = (dbot - dtop) / L2  # ∂δY/∂L1
    dd_dL2 = L1 * (dtop - dbot) / L2**2  # ∂δY/∂L2
    var_L = ((dd_dL1 * spacing.u_L1_mm) ** 2, (dd_dL2 * spacing.u_L2_mm) ** 2)
    var = np.nan_to_num(var_fit, nan=0.0) + var_L[0] + var_L[1]
    if ctx.keep_residual:
        # the kept residual carries the reading noise itself (σ of each fit, or u_probe_um)
        def s2(fl: list[FourierFit]) -> float:
            return float(np.mean([(ctx.u_probe_um if ctx.u_probe_um is not None else f.sigma) ** 2 for f in fl]))

        fa, fb = y["fits"]
        var = var + (w_top**2 * s2(fa) + w_bot**2 * s2(fb)) / ctx.reps.size
    if np.all(np.isnan(var_fit)):
        var = var + np.nan  # no residual dof and no u given: unknown
    return var, var_fit, var_L


def _sync_u(ctx: _Reduction, y: dict[str, Any], var_fit: np.ndarray, var_L: tuple[np.ndarray, np.ndarray],
            weights: tuple[float, float]) -> dict[str, Any]:
    """δY as the spindle's synchronous motion (see :func:`_rep_scatter`): the covariance of the mean
    of n revolutions from the repetitions' scatter, harmonic by harmonic; one revolution: the fit's.
    Keys ``dY_cov_sync``, ``u_dY_theta_um``, ``u_dY_um`` and :func:`_rep_scatter`'s."""
    n = ctx.reps.size
    fa, fb = y["fits"]
    sc = _rep_scatter(fa, fb, weights[0], weights[1])
    out: dict[str, Any] = {k: v for k, v in sc.items() if k != "cov_mean"}
    cov_sync = sc["cov_mean"] if n >= 2 else y["cov"]
    out["dY_cov_sync"] = cov_sync * np.outer(keep_mask(ctx.order), keep_mask(ctx.order))
    var_sync = np.nan_to_num(np.einsum("ij,jk,ik->i", ctx.G, out["dY_cov_sync"], ctx.G), nan=np.nan if n < 2 and
                             np.all(np.isnan(var_fit)) else 0.0)
    out["u_dY_theta_um"] = np.sqrt(var_sync + var_L[0] + var_L[1])
    out["u_dY_um"] = float(np.max(out["u_dY_theta_um"]))
    return out


def _range_u(ctx: _Reduction, dY_r: np.ndarray, d_n: float | None) -> dict[str, Any]:
    """Jia sec. 5's range method on δY per θ (NaN for one revolution): ``u_dY_range_theta_um``,
    ``u_dY_range_um`` (its maximum) and ``d_n``."""
    n = int(ctx.reps.size)
    if n < 2:
        return {"u_dY_range_theta_um": np.full(ctx.grid_deg.size, np.nan), "u_dY_range_um": float("nan"),
                "d_n": float("nan")}
    dn = d_n if d_n is not None else D_N.get(n)
    if dn is None:
        raise ValueError(f"no d_n tabulated for {ctx.reps.size} repetitions; pass d_n")
    u = range_method_u(dY_r, dn)
    return {"u_dY_range_theta_um": u, "u_dY_range_um": float(np.max(u)), "d_n": dn}


def _x_outputs(ctx: _Reduction, x: dict[str, Any], d_n: float) -> dict[str, Any]:
    """The X probes' keys of :func:`radial_motion` (δX, tilt about Y, the range method on δX)."""
    topx_r, botx_r, dX_r, tilty_r = x["top_r"], x["bot_r"], x["disk_r"], x["tilt_r"]
    return dict(
        delta_top_x_reps_um=topx_r, delta_bottom_x_reps_um=botx_r,
        delta_top_x_um=topx_r.mean(axis=0), delta_bottom_x_um=botx_r.mean(axis=0),
        dX_reps_um=dX_r, dX_um=x["mean"], dX_async_um=dX_r - x["mean"],
        tilt_y_reps_urad=tilty_r, tilt_y_urad=tilty_r.mean(axis=0),
        dX_params=x["params"], dX_cov=x["cov"], dX_fn=x["fn"],
        u_dX_range_theta_um=(range_method_u(dX_r, d_n) if ctx.reps.size >= 2 else np.full(ctx.grid_deg.size, np.nan)),
    )


def radial_motion(readings: ProbeReadings, spacing: SphereSpacing, options: RadialOptions | None = None) -> dict:
    """Radial error motion of the spheres and the disk (Jia eqs. 6-9), per repetition and averaged.

    ``readings`` are the columns of ``radial_motion.csv`` (one row per reading). Each repetition is
    fitted separately (order ``options.order``, eq. 6) and its harmonics 2…order kept (eq. 7). Everything
    is then evaluated on a common grid: the measured angles when every repetition has the same set
    (the usual case), otherwise ``options.grid_deg`` or, if not given, 360 points at 1°.

    ``options.u_probe_um``: standard uncertainty of one probe reading; when given it weights the fit and
    the GUM covariance is absolute, otherwise the residual scatter of each fit is used.
    ``spacing.u_L1_mm``, ``spacing.u_L2_mm``: uncertainty of the lengths (propagated through eq. 9).
    ``options.keep_residual``: instead of eq. 7's series (harmonics 2…order: content above the order and
    probe noise are filtered out), keep the data minus the fitted 0th and 1st harmonics (ISO 230-7
    evaluates asynchronous motion unfiltered); needs every repetition at the same angles. ``dY_fn``
    is then the periodic linear interpolant of ``dY_um`` and ``dY_params`` the series part only.

    Returns a dict (arrays on the grid ``theta_deg``; ``*_reps_*`` are n_reps × n_theta):

    - ``theta_deg``, ``reps`` (repetition labels), ``n_reps``, ``order``
    - ``delta_top_um``, ``delta_bottom_um``: synchronous (mean) sphere motion; ``*_reps_um`` per rep
    - ``dY_um``: synchronous disk motion δY (eq. 9); ``dY_reps_um``; ``dY_async_um`` (reps − mean)
    - ``tilt_x_urad`` (eq. 8, synchronous) and ``tilt_x_reps_urad``
    - ``dY_fn``: callable θ[deg] → δY[µm] (the mean Fourier series, exact between grid points)
    - ``dY_params``: [0, 0, 0, a2, b2, ...] of that mean series (µm), ``dY_cov``: its GUM covariance
    - ``summary``: {"top"|"bottom"|"disk" [|"top_x"|"bottom_x"|"disk_x"]: error_motion_values with
      ``total_u_um``, ``synchronous_u_um``, ``asynchronous_u_um`` (:func:`_with_u`)}; ``bandwidth``: the
      orders per revolution the curves hold (2…order; ``text`` in words)
    - ``u_dY_range_theta_um``: range method per θ (σ of one repetition); ``u_dY_range_um``: its
      maximum over θ (the single number Jia quotes, 0.18 µm); ``d_n``
    - ``u_dY_gum_theta_um``: GUM standard uncertainty of the synchronous δY at each θ from the fit
      covariances (probe noise) and u(L1), u(L2) — it does not contain the asynchronous motion, which
      is a real motion and is reported by the range method; ``u_dY_gum_um``: its maximum
    - ``u_dY_theta_um``: standard uncertainty of ``dY_um`` as the spindle's SYNCHRONOUS motion (the
      mean of n revolutions carries 1/n of the asynchronous variance): from ``dY_cov_sync``, the
      covariance of the mean from the repetitions' scatter harmonic by harmonic (:func:`_rep_scatter`,
      type A, ν = 2(n − 1) per harmonic; the fit covariance for one revolution), + u(L) terms;
      ``u_dY_um``: its maximum; ``s2_harmonics_um2``: the per-revolution variance of each harmonic
    - ``h1_reps_um`` (n_reps × 2: the (a1, b1) of the disk-plane combination per repetition),
      ``u_h1_async_um``, ``u_h1_async_dof``: their rep-to-rep scatter, the asynchronous motion's
      share in the 1st harmonic of one revolution (see :func:`_rep_scatter`; the eccentricity from
      one CCD sweep carries it, :func:`benchtwin.analysis.eccentricity.with_async_motion`)
    - ``fits``: {"top": [FourierFit per rep], "bottom": [...]} (and x)
    - with X probes: ``delta_top_x_um``, ``delta_bottom_x_um``, ``dX_um``, ``dX_reps_um``,
      ``dX_async_um``, ``tilt_y_urad``, ``dX_fn``, ``u_dX_range_theta_um``
    """
    opt = options if options is not None else RadialOptions()
    c = _checked_readings(readings)
    weights = disk_weights(spacing.L1_mm, spacing.L2_mm)
    reps = np.unique(c.rep)
    if reps.size == 0:
        raise ValueError("no readings")
    grid = _common_grid(c.rep, c.theta_deg, reps, opt)
    G = design_matrix(grid, opt.order, harmonics=range(2, opt.order + 1))  # eq. 7 on the grid
    ctx = _Reduction(c.rep, c.theta_deg, reps, grid, G, opt.order, opt.u_probe_um, opt.keep_residual)

    y = _pair(ctx, c.top_um, c.bottom_um, ("probe_top_um", "probe_bottom_um"), spacing)
    top_r, bot_r, dY_r, tilt_r = y["top_r"], y["bot_r"], y["disk_r"], y["tilt_r"]
    out: dict[str, Any] = {"theta_deg": grid, "reps": reps, "n_reps": int(reps.size), "order": opt.order}
    out.update(
        delta_top_reps_um=top_r, delta_bottom_reps_um=bot_r,
        delta_top_um=top_r.mean(axis=0), delta_bottom_um=bot_r.mean(axis=0),
        dY_reps_um=dY_r, dY_um=y["mean"], dY_async_um=dY_r - y["mean"],
        tilt_x_reps_urad=tilt_r, tilt_x_urad=tilt_r.mean(axis=0),
    )
    summary = dict(zip(("top", "bottom", "disk"), y["summary"]))
    out["bandwidth"] = _bandwidth(opt.order, opt.keep_residual)
    out["dY_params"], out["dY_cov"], out["dY_fn"] = y["params"], y["cov"], y["fn"]
    var, var_fit, var_L = _gum_u(ctx, y, spacing)
    out["u_dY_gum_theta_um"] = np.sqrt(var)
    out["u_dY_gum_um"] = float(np.max(out["u_dY_gum_theta_um"]))
    out.update(_sync_u(ctx, y, var_fit, var_L, weights))
    out.update(_range_u(ctx, dY_r, opt.d_n))
    fits: dict[str, list[FourierFit]] = {"top": y["fits"][0], "bottom": y["fits"][1]}
    if c.top_x_um is not None and c.bottom_x_um is not None:
        x = _pair(ctx, c.top_x_um, c.bottom_x_um, ("probe_top_x_um", "probe_bottom_x_um"), spacing)
        fits["top_x"], fits["bottom_x"] = x["fits"]
        out.update(_x_outputs(ctx, x, out["d_n"]))
        summary.update(zip(("top_x", "bottom_x", "disk_x"), x["summary"]))
    out["summary"] = summary
    out["fits"] = fits
    return out


def keep_mask(order: int) -> np.ndarray:
    """1 for the parameters of harmonics 2…order (eq. 7), 0 for a0, a1, b1."""
    m = np.zeros(2 * order + 1)
    m[3:] = 1.0
    return m


def _rep_scatter(fa: list[FourierFit], fb: list[FourierFit], w_top: float, w_bot: float) -> dict:
    """Rep-to-rep scatter of the disk-plane motion's Fourier coefficients (eq. 9 weights on the
    probes' eq. 6 coefficients), harmonic by harmonic (GUM type A).

    Each revolution's coefficients are the synchronous ones plus the non-repeating (asynchronous)
    motion's share in that revolution plus the fit's noise. Pooled over the sin and cos coefficient
    of each harmonic i (an isotropic, stationary process: over a full revolution its harmonic
    coefficients are uncorrelated): s_i² = Σ_reps Σ_{a,b} (x − x̄)² / (2(n − 1)), ν = 2(n − 1).
    The covariance of the MEAN of the n revolutions is diag(s_i²)/n: it contains the fit noise and
    the asynchronous motion together (adding the fit covariance to it would count the noise twice).

    The 1st harmonic is the sphere centring (removed by eq. 7) in every revolution alike, so its
    scatter s_1 is the asynchronous motion's share in the 1st harmonic of ONE revolution — what adds
    to the eccentricity fitted from one CCD sweep (eq. 11), which cannot tell it from e
    (:func:`benchtwin.analysis.eccentricity.with_async_motion`).

    Keys: ``s2_harmonics_um2`` (s_i², i = 1…order), ``h1_reps_um`` (n × 2), ``u_h1_async_um`` (s_1),
    ``u_h1_async_dof`` (2(n − 1)), ``cov_mean`` ((2·order+1)², all harmonics). NaN for one revolution.
    """
    P = np.array([w_top * f.params + w_bot * g.params for f, g in zip(fa, fb)])
    n, p = P.shape
    order = (p - 1) // 2
    h1 = P[:, 1:3].copy()
    if n < 2:
        nan = np.full(order, np.nan)
        return {"s2_harmonics_um2": nan, "h1_reps_um": h1, "u_h1_async_um": float("nan"), "u_h1_async_dof": 0,
                "cov_mean": np.full((p, p), np.nan)}
    dev = P - P.mean(axis=0)
    ss = np.sum(dev**2, axis=0)
    s2 = np.array([(ss[2 * i - 1] + ss[2 * i]) / (2 * (n - 1)) for i in range(1, order + 1)])
    diag = np.concatenate([[np.sum(dev[:, 0] ** 2) / (n - 1)], np.repeat(s2, 2)]) / n
    return {"s2_harmonics_um2": s2, "h1_reps_um": h1, "u_h1_async_um": float(math.sqrt(s2[0])),
            "u_h1_async_dof": 2 * (n - 1), "cov_mean": np.diag(diag)}


def _series_fn(params: np.ndarray, order: int) -> Callable[[np.ndarray], np.ndarray]:
    p = np.array(params, dtype=float)

    def fn(theta_deg: np.ndarray) -> np.ndarray:
        """δ(θ) in µm at θ in degrees (mean Fourier series, harmonics 2…order)."""
        return evaluate(p, theta_deg, order=order)

    return fn


def _interp_fn(grid_deg: np.ndarray, values: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    g = np.asarray(grid_deg, dtype=float)
    v = np.asarray(values, dtype=float)

    def fn(theta_deg: np.ndarray) -> np.ndarray:
        """δ(θ) in µm at θ in degrees (periodic linear interpolation of the grid values)."""
        return np.interp(np.asarray(theta_deg, dtype=float) % 360.0, g, v, period=360.0)

    return fn
