"""Synthetic evidence with known, injected effects (test-only: nothing in benchtwin/, twin/ or analysis/
imports it; it was analysis/effects/synthetic.py). A polygon sweep as in Hsieh et al. 2022 (eq. 3: N faces, start
faces j, shift angles S, repetitions, forward/backward), a Jia-like encoder (eq. 5 with
e = 7.1 µm, θ0 = 192.08°, r = 22 mm; L1 = 6.81 mm, L2 = 122.96 mm, Jia sec. 5), sphere motions
with 2–5 lobes of ~0.1 µm, and the effects of the library injected by their *physics* (true
radius, true L1, true δX, sphere form in the probe reading, drift in time, ...), written here
independently of the effect modules' design matrices, so that the tests check the modules
against the physics and not against themselves.
"""

from __future__ import annotations

import math

import numpy as np

from benchtwin.analysis.tracing import Evidence, RadialMotion, SelfCal
from benchtwin.units import ARCSEC_PER_RAD

E_UM, THETA0_DEG, R_MM, L1_MM, L2_MM = 7.1, 192.08, 22.0, 6.81, 122.96


# The generator's own series (it shares no code with the analysis's Fourier engine, analysis/fourier.py,
# so that the tests compare the analysis against the physics and not against itself).
def fourier_eval(theta_deg, coefs):
    """Σ a_k sin kθ + b_k cos kθ (θ in degrees)."""
    th = np.deg2rad(np.asarray(theta_deg, dtype=float))
    out = np.zeros_like(th)
    for k, (a, b) in coefs.items():
        out += a * np.sin(int(k) * th) + b * np.cos(int(k) * th)
    return out


def fourier_integral(theta_deg, coefs):
    """∫ (a sin kθ + b cos kθ) dθ over θ in radians, without constant: (−a cos kθ + b sin kθ)/k."""
    th = np.deg2rad(np.asarray(theta_deg, dtype=float))
    out = np.zeros_like(th)
    for k, (a, b) in coefs.items():
        out += (-a * np.cos(int(k) * th) + b * np.sin(int(k) * th)) / int(k)
    return out


def quadrature(coefs):
    """A quarter period later in each harmonic: a sin + b cos → b sin − a cos."""
    return {k: (b, -a) for k, (a, b) in coefs.items()}


def _lobes(rng, ks, amp_um):
    return {int(k): (amp_um * math.cos(p), amp_um * math.sin(p)) for k, p in zip(ks, rng.uniform(0, 2 * np.pi, len(ks)))}


def make_evidence(rng: np.random.Generator, *, n_faces: int = 23, start_faces=None, shifts=(0.0,), reps: int = 1,
                  directions=(1,), noise_arcsec: float = 0.07, top_lobes=(2, 3, 4, 5), bottom_lobes=(2, 3, 4, 5),
                  lobe_um: float = 0.1, bottom_lobe_um: float | None = None, x_probes: bool = False,
                  x_whirl: bool = False, selfcal: bool = False, n_heads: int = 3, encoder_lines: int = 36000,
                  jitter_arcsec: float = 2.0, dwell_s: float = 10.0, inject: dict | None = None,
                  extra=None, backward_whirl_um: complex = 0j, probe_noise_um: float = 0.01):
    """Build ``(Evidence, truth)``. ``inject``: {effect name: physical parameters}:

    - ``graduation_error``: {k: (amplitude_arcsec, phase_rad)}, g = A sin(kθ + φ)
    - ``optical_radius``: {"delta_r_mm"} (true radius r + Δr)
    - ``ccd_pixel_scale``: {"scale_error_pct"} (e_true = e_model·(1 + s/100))
    - ``tangential_motion``: {"gain", optional "radial_gain"} (reading error −(g·δX_disk + h·∫δY dθ)/r:
      g = h = 1 is the exact geometry, the head reading −δX/r and not eq. 5's ∫δY/r)
    - ``tilt_abbe``: {"dL1_mm"} (true L1 = nominal + ΔL1)
    - ``ac_drift``: {"drift_arcsec_per_s"}
    - ``ac_scale``: {"gain_pct", "quad_per_arcsec"} (ε_read = (1+k)ε + qε², propagated to α)
    - ``sphere_form``: {"k", "amplitude_um", "phase_rad"} on the top sphere, in its Y probe's reading
      (amplitude·(cos φ, sin φ) as (sin kθ, cos kθ) coefficients) and, with X probes, in its X probe's
      a quarter turn earlier
    - ``torsion_hysteresis``: {"half_hysteresis_arcsec"}
    - ``polygon_pitch_ignored``: {"rms_arcsec"} (leftover pitch Δβ, Σ = 0)
    - ``interpolation_error``: {"c1_arcsec", "phase_rad"} (first order of the grating period)

    ``extra``: optional callable(theta_deg, t_s) -> arcsec added to the measured α (an effect
    outside the library).

    ``backward_whirl_um``: B (µm, complex) of an order-1 motion of the axis, the same at both
    spheres and the disk, c = x + iy = B·e^{−iθ} (against the rotation: no centring makes it). The
    probes read it (X: Re, Y: Im), head 1 reads −c_x/r, and the model's eccentricity is that of a
    CCD opposite the head: it reads c_y's order 1 and takes it for one forward circle.

    ``probe_noise_um``: the probes' noise per reading (σ, µm; each probe, each 6° stop).
    """
    inj = dict(inject or {})
    N = int(n_faces)
    start_faces = list(range(1, N + 1)) if start_faces is None else list(start_faces)
    r_um = R_MM * 1000.0
    # --- shaft motion (true) and probe readings --------------------------------------------
    top = _lobes(rng, top_lobes, lobe_um)
    bot = _lobes(rng, bottom_lobes, lobe_um if bottom_lobe_um is None else bottom_lobe_um)
    if x_whirl:
        top_x, bot_x = quadrature(top), quadrature(bot)
    else:
        top_x = _lobes(rng, top_lobes, lobe_um)
        bot_x = _lobes(rng, bottom_lobes, lobe_um if bottom_lobe_um is None else bottom_lobe_um)
    L1_true = L1_MM + inj.get("tilt_abbe", {}).get("dL1_mm", 0.0)

    def disk(ct, cb, L1):
        wt, wb = (L2_MM - L1) / L2_MM, L1 / L2_MM
        z = (0.0, 0.0)
        return {k: (wt * ct.get(k, z)[0] + wb * cb.get(k, z)[0], wt * ct.get(k, z)[1] + wb * cb.get(k, z)[1])
                for k in sorted(set(ct) | set(cb))}

    dY_true = disk(top, bot, L1_true)
    dX_true = disk(top_x, bot_x, L1_true)
    r_true = r_um + 1000.0 * inj.get("optical_radius", {}).get("delta_r_mm", 0.0)
    e_model = E_UM / (1.0 + inj.get("ccd_pixel_scale", {}).get("scale_error_pct", 0.0) / 100.0)

    def encoder_error(th_deg):
        """True reading error of head 1 (arcsec): Jia eq. 5 with the true quantities + encoder effects."""
        th = np.deg2rad(th_deg)
        a = (E_UM * np.sin(th - math.radians(THETA0_DEG)) + fourier_integral(th_deg, dY_true)) / r_true * ARCSEC_PER_RAD
        a = a - np.real(backward_whirl_um * np.exp(-1j * th)) / r_true * ARCSEC_PER_RAD
        for k, (A, ph) in inj.get("graduation_error", {}).items():
            a = a + A * np.sin(int(k) * th + ph)
        if "tangential_motion" in inj:
            tm = inj["tangential_motion"]
            a = a - (tm["gain"] * fourier_eval(th_deg, dX_true)
                     + tm.get("radial_gain", 0.0) * fourier_integral(th_deg, dY_true)) / r_true * ARCSEC_PER_RAD
        if "interpolation_error" in inj:
            ip = inj["interpolation_error"]
            ph = 2 * np.pi * ((np.asarray(th_deg) * encoder_lines / 360.0) % 1.0)
            a = a + ip["c1_arcsec"] * np.sin(ph + ip.get("phase_rad", 0.0))
        return a

    # probe readings on a 6° grid per rep (what radial_motion.csv holds), with the sphere form
    grid = np.arange(0.0, 360.0, 6.0)
    form = {}
    if "sphere_form" in inj:
        sf = inj["sphere_form"]
        form = {int(sf["k"]): (sf["amplitude_um"] * math.cos(sf["phase_rad"]), sf["amplitude_um"] * math.sin(sf["phase_rad"]))}
    g_all, t_all, b_all, tx_all, bx_all = [], [], [], [], []
    for _ in range(max(reps, 1)):
        g_all.append(grid)
        # each sphere's centring: one forward circle, seen by its Y probe (sin, cos) and X probe (cos, −sin)
        gr = np.deg2rad(grid)
        bw = backward_whirl_um * np.exp(-1j * gr)
        sn = probe_noise_um
        t_all.append(fourier_eval(grid, top) + fourier_eval(grid, form) + 0.5 + 0.3 * np.sin(gr) + bw.imag + rng.normal(0, sn, grid.size))
        b_all.append(fourier_eval(grid, bot) - 0.2 + 0.4 * np.cos(gr) + bw.imag + rng.normal(0, sn, grid.size))
        # the X probe (at 0°, a quarter turn before the Y probe at 90°) reads the same form a quarter
        # turn earlier: X(θ) = Y(θ + 90°)
        tx_all.append(fourier_eval(grid, top_x) + fourier_eval(grid + 90.0, form) + 0.3 * np.cos(gr) + bw.real
                      + rng.normal(0, sn, grid.size))
        bx_all.append(fourier_eval(grid, bot_x) - 0.4 * np.sin(gr) + bw.real + rng.normal(0, sn, grid.size))
    radial = RadialMotion(np.concatenate(g_all), np.concatenate(t_all), np.concatenate(b_all), L1_MM, L2_MM,
                          np.concatenate(tx_all) if x_probes else None, np.concatenate(bx_all) if x_probes else None)

    def model_terms(th_deg):
        th = np.deg2rad(th_deg)
        return {"eccentricity": (e_model * np.sin(th - math.radians(THETA0_DEG))
                                 + np.real(backward_whirl_um * np.exp(-1j * th))) / r_um * ARCSEC_PER_RAD,
                "radial_motion_integral": radial.integral_at(th_deg, "dY_um") / r_um * ARCSEC_PER_RAD}

    # --- polygon sweep ----------------------------------------------------------------------
    beta = rng.normal(0, 0.8, N)
    beta -= beta.mean()
    dbeta = np.zeros(N)
    if "polygon_pitch_ignored" in inj:
        dbeta = rng.normal(0, inj["polygon_pitch_ignored"]["rms_arcsec"], N)
        dbeta -= dbeta.mean()
    cum = np.concatenate([[0.0], np.cumsum(dbeta)])  # cum[f] = C(f), C(0) = C(N) = 0
    rows = []
    t = 0.0
    for S in shifts:
        for j in start_faces:
            U = rng.normal(0, 1.5)
            for rep in range(reps):
                for d in directions:
                    order = range(1, N + 1) if d > 0 else range(N, 0, -1)
                    for i in order:
                        t += dwell_s * (1 + 0.1 * rng.standard_normal())
                        th = ((i - 1) * 360.0 / N + S + rng.normal(0, jitter_arcsec / 3600.0)) % 360.0
                        f = (j + i - 2) % N + 1
                        rows.append((th, S, j, i, f, rep, d, t, U))
    th, S, j, i, f, rep, d, ts, U = (np.array(c) for c in zip(*rows))
    alpha_true = encoder_error(th)
    sumbeta = np.array([beta[(jj - 1 + np.arange(ii)) % N].sum() for jj, ii in zip(j.astype(int), i.astype(int))])
    eps = alpha_true + sumbeta + U  # the true autocollimator reading (Hsieh eq. 3)
    alpha_meas = alpha_true.copy()
    if "ac_scale" in inj:
        a = inj["ac_scale"]
        alpha_meas = (1 + a.get("gain_pct", 0.0) / 100.0) * alpha_meas + a.get("quad_per_arcsec", 0.0) * eps ** 2
        eps = (1 + a.get("gain_pct", 0.0) / 100.0) * eps + a.get("quad_per_arcsec", 0.0) * eps ** 2
    if "ac_drift" in inj:
        alpha_meas = alpha_meas + inj["ac_drift"]["drift_arcsec_per_s"] * ts
    if "torsion_hysteresis" in inj:
        alpha_meas = alpha_meas + inj["torsion_hysteresis"]["half_hysteresis_arcsec"] * d
    alpha_meas = alpha_meas + cum[f.astype(int)] - cum[(j.astype(int) - 1)]
    if extra is not None:
        alpha_meas = alpha_meas + extra(th, ts)
    alpha_meas = alpha_meas + rng.normal(0, noise_arcsec, th.size)
    # the per-run closure (Hsieh eq. 7) leaves an arbitrary offset per (shift, start face): mimic it
    keys = np.unique(np.round(S, 6) * 1000 + j, return_inverse=True)[1]
    alpha_meas = alpha_meas + rng.normal(0, 0.5, keys.max() + 1)[keys]

    sc = None
    if selfcal:
        gsc = np.arange(0.0, 360.0, 1.0)
        mu = encoder_error(gsc) + rng.normal(0, 0.01, gsc.size)
        sc = SelfCal(gsc, mu, 0.01, n_heads, model_terms(gsc))
    ev = Evidence(theta_deg=th, alpha_arcsec=alpha_meas, u_arcsec=noise_arcsec, model_terms=model_terms(th), t_s=ts,
                  rep=rep, direction=d, start_face=j, shift_deg=S, step=i, n_faces=N, optical_radius_mm=R_MM,
                  L1_mm=L1_MM, L2_mm=L2_MM, grating_period_um=20.0, encoder_lines=encoder_lines, radial=radial,
                  ac_arcsec=eps, selfcal=sc)
    truth = {"top": top, "bottom": bot, "top_x": top_x, "bottom_x": bot_x, "dbeta": dbeta, "cum": cum, "inject": inj,
             "encoder_error": encoder_error, "beta": beta, "U": U, "alpha_true": alpha_true,
             "model_terms": model_terms, "grid_deg": np.concatenate(g_all), "top_um": np.concatenate(t_all),
             "bottom_um": np.concatenate(b_all)}
    return ev, truth
