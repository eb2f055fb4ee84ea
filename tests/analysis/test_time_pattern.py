"""The stationarity test of the close-the-loop signature (analysis/tracing/signature.py, ``_time_pattern``)
against the asynchronous motion of a ball-bearing shaft.

The cage of a preloaded ball bearing creeps: its slip accumulates over the moves between polygon
sweeps, so the non-repeating motion at the kinematic orders (outer-race lobes at q·Z·ρ cycles/rev,
4.81 for jia2019's bearings) reaches the stops as a pattern near the 5th harmonic of θ whose phase
wanders from sweep to sweep like a random walk (docs/physics.md, "Why the default run's θ pattern
looked non-stationary"). That is noise of the size the 23 visits show, not a change of a
disk-fixed pattern; a pattern that really grows during the session must still be refused."""

from __future__ import annotations

import numpy as np

from tests.synthetic.evidence import make_evidence
from benchtwin.analysis.tracing import trace


def _creeping_cage(seed: int, amplitude_arcsec: float = 0.5, step_deg: float = 35.0):
    """A 4.81-cycles/rev motion read at the stops: phase = random walk in time (one step of
    ``step_deg`` per sweep-length of time on average, continuous inside a sweep)."""
    rng = np.random.default_rng(seed)

    def extra(theta_deg, t_s):
        t = np.asarray(t_s, dtype=float)
        grid = np.linspace(t.min() - 1.0, t.max() + 1.0, 400)
        sweep_s = np.ptp(t) / 23.0
        walk = np.cumsum(rng.normal(0.0, np.deg2rad(step_deg) * np.sqrt(np.diff(grid, prepend=grid[0]) / sweep_s)))
        phase = np.interp(t, grid, walk)
        return amplitude_arcsec * np.sin(4.81 * np.deg2rad(theta_deg) + phase)
    return extra


def test_creeping_cage_is_noise_not_a_changing_pattern():
    """A division error (k = 3 and 5, 0.5″ each) under a wandering 0.5″ asynchronous pattern: the sweeps'
    deviations are serially correlated and the test takes the walk for what it is: it is not
    reported as a θ pattern changing with time."""
    ev, _ = make_evidence(np.random.default_rng(151), inject={"graduation_error": {3: (0.5, 0.7), 5: (0.5, 0.2)}},
                          extra=_creeping_cage(152))
    res = trace(ev)
    tp = res["signature"]["time_pattern"]
    assert 5 in tp["harmonics"] and tp["n_sweeps"] == 23 and tp["random_walk"] and not tp["significant"], tp
    assert not any("changes with time" in x for x in (res.get("unexplained_signature") or {}).get("left", []))
    # (whether the division error is then named depends on the noise model: here u is the 0.07″
    # white noise alone, so the wandering 0.5″ is left in χ²; the twin's u is the closure
    # scatter, which holds it — docs/physics.md)


def test_independent_sweeps_keep_the_level_test():
    """Without the walk (white noise only) the sweeps are independent and the test is the
    regression of each sweep's coefficients on time against their scatter (no random-walk form)."""
    ev, _ = make_evidence(np.random.default_rng(153), inject={"graduation_error": {3: (0.5, 0.7)}})
    tp = trace(ev)["signature"]["time_pattern"]
    assert tp["n_sweeps"] == 23 and not tp["random_walk"] and not tp["significant"], tp



def test_a_change_below_practical_size_is_not_left_unexplained():
    """A 7th harmonic that changes sign during the session (0.05″ at the ends, RMS of the change
    ≈ 0.02″) on 552 readings of 0.02″ noise: the stationarity test resolves it (z ≥ 4), but it is
    below ``SIZE_GATE`` × a 0.07″ noise floor, so it changes no calibrated value beyond its
    uncertainty and is not a part "left" to explain — the same practical gate as a drift or a
    direction offset (the hsieh2022 default's 0.015″ change at z = 7 is such a case). Ten times
    larger, it is left."""
    from benchtwin.analysis.tracing.selection import noise_floor
    from benchtwin.analysis.tracing.signature import _significant_parts, signature
    from benchtwin.analysis.tracing.thresholds import SIZE_GATE

    def flip(amplitude):
        def extra(th, t):
            tt = (t - t.mean()) / np.ptp(t)
            return amplitude * 2.0 * tt * np.sin(7 * np.deg2rad(th) + 0.3)
        return extra

    for amplitude, left_expected in ((0.05, False), (0.5, True)):
        ev, _ = make_evidence(np.random.default_rng(161), extra=flip(amplitude), noise_arcsec=0.02)
        ev.u_arcsec = np.full(ev.n, 0.07)     # the floor: 0.07″ per reading
        sig = signature(ev, time_ks=[7])
        tp = sig["time_pattern"]
        assert tp["significant"] and tp["z"] >= 4, tp
        assert (tp["rms_arcsec"] >= SIZE_GATE * noise_floor(ev)) == left_expected, (tp["rms_arcsec"], noise_floor(ev))
        parts = _significant_parts(sig, ev.n, noise_floor(ev))
        assert any("changes with time" in x for x in parts) == left_expected, parts


def _shift_sweeps(reps: int, alpha, seed: int = 181, noise: float = 0.07):
    """23 faces × shifts 0…14° (one start face each), ``reps`` repetitions as the outer loop (the
    twin's order: every shift of rep 0, then every shift of rep 1), 10 s a stop; α = alpha(θ, t) +
    white noise. Too few readings per sweep for 12 harmonics: the reading-by-reading form."""
    from benchtwin.analysis.tracing import Evidence

    th, sh, rp, ts = [], [], [], []
    t = 0.0
    for r in range(reps):
        for s in range(15):
            for i in range(23):
                t += 10.0
                th.append((i * 360.0 / 23 + s) % 360.0)
                sh.append(float(s))
                rp.append(r)
                ts.append(t)
    th, ts = np.array(th), np.array(ts)
    a = alpha(th, ts) + np.random.default_rng(seed).normal(0.0, noise, th.size)
    return Evidence(theta_deg=th, alpha_arcsec=a, u_arcsec=noise, model_terms={}, t_s=ts, rep=np.array(rp),
                    shift_deg=np.array(sh), radial=None)


def _high_orders(th, t):
    """A stationary pattern above the tested harmonics 2…20 (orders 21…31, 0.3″ RMS: a ball
    bearing's −δX/r there on the twin's benches)."""
    g = np.deg2rad(th)
    return sum(a * np.sin(k * g + p) for k, a, p in ((21, 0.2, 0.3), (22, 0.15, 1.0), (24, 0.15, 0.4), (27, 0.12, 1.1),
                                                   (31, 0.1, 2.0)))


def _k7_flip(th, t):
    tt = (t - t.mean()) / np.ptp(t)
    return 0.5 * 2.0 * tt * np.sin(7 * np.deg2rad(th) + 0.3)


def test_a_stationary_pattern_above_the_tested_orders_is_no_change_with_time():
    """Shift-angle sweeps read once per position, the shifts in time order: a stationary pattern at
    orders the test does not hold (21…31) reads, sweep by sweep, as orders 23 − k (2, 1, 1, 4, 8)
    with a phase that turns with the shift, i.e. with time. Nested over the tested harmonics alone
    that was "the θ pattern changes with time" (z = 5.2, 0.22″: the twin's base benches, seeds
    660-663, the bearings' −δX/r above order 20); nested over every function of θ, a single reading
    per position leaves no change to see, and two repetitions see none."""
    from benchtwin.analysis.tracing.signature import signature

    ks = list(range(2, 21))
    tp = signature(_shift_sweeps(1, _high_orders), time_ks=ks)["time_pattern"]
    assert not tp["available"] and "different times" in tp["reason"], tp
    tp = signature(_shift_sweeps(2, _high_orders), time_ks=ks)["time_pattern"]
    assert tp["available"] and not tp["significant"], tp


def test_a_pattern_that_changes_between_repetitions_is_still_seen():
    """The same design with two repetitions (each position read twice, half a session apart) and a
    7th harmonic that changes sign during the session (0.5″ at the ends): the revisits see it."""
    from benchtwin.analysis.tracing.selection import noise_floor
    from benchtwin.analysis.tracing.signature import _significant_parts, signature

    ev = _shift_sweeps(2, _k7_flip)
    sig = signature(ev, time_ks=list(range(2, 14)))
    tp = sig["time_pattern"]
    assert tp["available"] and tp["significant"] and tp["z"] >= 4, tp
    assert any("changes with time" in x for x in _significant_parts(sig, ev.n, noise_floor(ev)))


def test_removing_every_function_of_theta_is_linear():
    """signature._time_pattern projects the fitted combination of its harmonics × (t − t̄)/T once
    (it projected each column): the removal of every function of θ is a linear projection, so both
    give the same part beyond θ, to rounding, and none of a function of θ alone is left."""
    from benchtwin.analysis.tracing import _Problem
    from benchtwin.analysis.tracing.signature import _free_of_theta

    ev = _shift_sweeps(2, _k7_flip)
    pb = _Problem(ev)
    th, tt = np.deg2rad(ev.theta_deg), (ev.t_s - ev.t_s.mean()) / np.ptp(ev.t_s)
    X = np.column_stack([f(k * th) * tt for k in (3, 7, 11) for f in (np.sin, np.cos)])
    b = np.random.default_rng(4).normal(size=X.shape[1])
    each = np.column_stack([_free_of_theta(pb, X[:, j]) for j in range(X.shape[1])]) @ b
    once = _free_of_theta(pb, X @ b)
    assert np.ptp(once) > 0.1 and np.max(np.abs(once - each)) <= 1e-12 * np.max(np.abs(each))
    assert np.max(np.abs(_free_of_theta(pb, np.cos(5 * th)))) <= 1e-9


def _warm_up(amplitude_arcsec: float, k: int = 7, tau_of_session: float = 0.25, phase: float = 0.4):
    """A k-lobed pattern that follows a warm-up: amplitude·(1 − exp(−x/τ)) with x the fraction of
    the session (the hub's temperature rise of the twin's thermal_growth; no straight line)."""
    def extra(theta_deg, t_s):
        x = (np.asarray(t_s, dtype=float) - np.min(t_s)) / np.ptp(t_s)
        return amplitude_arcsec * (1.0 - np.exp(-x / tau_of_session)) * np.sin(k * np.deg2rad(theta_deg) + phase)
    return extra


def test_a_warm_up_is_not_taken_for_a_random_walk():
    """A 1″ 7-lobe pattern that grows with a warm-up (τ a quarter of the session) over 23 sweeps of
    0.07″ readings: a straight line leaves its curvature in the sweeps' deviations, which look serial.
    Tested as a pure random walk with drift (first differences) it was z 2.1–2.8 on these five seeds;
    within the local-level model (a walk plus the sweeps' own scatter, the curved drift tested) it is
    seen (z ≥ 4, 4.3–5.1) with about its size. (0.6″ was seen on all five at the walk share's point
    estimate, z 4.4–6.0, and on two of them at the conservative end of its interval, z 3.2–4.3.)"""
    from benchtwin.analysis.tracing.signature import signature

    for seed in range(201, 206):
        ev, _ = make_evidence(np.random.default_rng(seed), inject={"graduation_error": {3: (0.5, 0.7), 7: (0.3, 0.1)}},
                              extra=_warm_up(1.0))
        tp = signature(ev, time_ks=[3, 5, 7])["time_pattern"]
        assert tp["n_sweeps"] == 23 and tp["random_walk"] and tp["significant"] and tp["z"] >= 4, (seed, tp)
        # the change from the first sweep to the last: 1.0·(1 − e^(−x/τ)) between the sweeps' mean times
        assert 0.75 <= tp["change_over_session_arcsec"][2] <= 1.05, (seed, tp)
        assert max(tp["change_over_session_arcsec"][:2]) < 0.15, (seed, tp)


def test_the_local_level_test_keeps_its_false_alarm_rate_under_a_walk():
    """Monte Carlo of the null: 23 sweeps × 6 coefficients, each a random walk plus the sweep's own
    scatter (walk share ρ = 0.3, 0.5 and 1; scales 0.5…2 per coefficient), no drift, kept where the
    sweeps look serial (the case that reaches the test). z ≥ 3 has probability 0.00135 for a
    calibrated test: ≤ 3 of the 816 series here. With ρ at its point estimate (not the upper end of
    its 95 % interval) it was 17 of them, 2.1 %."""
    import math

    from benchtwin.analysis.distributions import norm_isf
    from benchtwin.analysis.tracing.problem import _z_from_chi2
    from benchtwin.analysis.tracing.signature import _local_level_trend
    from benchtwin.analysis.tracing.thresholds import P_SIG

    G, m = 23, 6
    tg = (np.arange(G) - (G - 1) / 2) / G
    rng = np.random.default_rng(7)
    zs = []
    for rho in (0.3, 0.5, 1.0):
        sw, se = (math.sqrt(rho / (1 - rho)), 1.0) if rho < 1 else (1.0, 0.0)
        for _ in range(400):
            C = (np.cumsum(rng.normal(0, sw, (G, m)), axis=0) + rng.normal(0, se, (G, m))) * rng.uniform(0.5, 2.0, m)
            res = C - C.mean(0) - np.outer(tg, (tg @ (C - C.mean(0))) / (tg @ tg))
            if np.sum(res[1:] * res[:-1]) / np.sum(res ** 2) * math.sqrt(res.size) <= norm_isf(P_SIG):
                continue
            _, q, k2, _, _ = _local_level_trend(C, tg)
            zs.append(_z_from_chi2(q, k2))
    assert len(zs) >= 800 and sum(z >= 3 for z in zs) <= 3, (len(zs), sorted(zs)[-5:])


def test_the_creeping_cage_stays_noise_over_seeds():
    """The creeping cage of the first test on five more seeds: the curved drift within the
    local-level model does not take its walk for a change of the pattern (with each coefficient's
    own walk share it did on two of these seeds, z 3.6–3.8; with a cubic drift on one, z 6.2)."""
    from benchtwin.analysis.tracing.signature import signature

    for seed in range(151, 156):
        ev, _ = make_evidence(np.random.default_rng(seed), inject={"graduation_error": {3: (0.5, 0.7), 7: (0.3, 0.1)}},
                              extra=_creeping_cage(seed + 1))
        tp = signature(ev, time_ks=[3, 5, 7])["time_pattern"]
        assert tp["n_sweeps"] == 23 and not tp["significant"] and tp["z"] < 2.5, (seed, tp)
