"""A continuous-rotation radial error motion run (ISO 230-7:2015 sec. 5.4, "dynamic" measurement).

The spindle turns at a constant stated speed and the displacement probes are sampled in TIME
(``samples_per_rev`` a revolution, for ``revolutions`` >= 20 revolutions): the asynchronous error
motion of ball bearings is not periodic in the shaft angle (cage at rho, ball pass at Z·rho and
Z·(1 − rho) ± 1 cycles per revolution, twin/bearing.py), so ISO 230-7 asks for many revolutions and
separates the synchronous part (the average over revolutions) from the asynchronous remainder.
It sits beside Jia's stop-and-go run (``radial_motion.csv``), only where a scenario asks for it
(``procedure.continuous_revolutions`` > 0; off in the defaults so the default run stays fast).

Physics while turning: quasi-static poses along the path (the rotation frequency, a fraction of a
hertz to a few hertz, is three orders below the bearings' radial modes at ~1.6 kHz), with the cages
rolling steadily (no start/stop slip while turning), the unbalance's centrifugal force U·ω² at the
stated speed turning with the shaft, and the bearing friction opposing the rotation. The drive
turns at ω (its command is θ = θ_start + ω·t); the encoder is read at every sample like the probes.

Output rows (one per sample): ``t_s`` (bench clock), ``theta_deg`` (head 1's displayed reading),
``probe_*_um``. Table ``radial_continuous.csv`` (docs/dataset-format.md).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: the axial / face probes only where the scenario's [axial] section builds them (twin/axial.py)
PROBES = ("probe_top", "probe_bottom", "probe_top_x", "probe_bottom_x", "probe_axial", "probe_face")


def continuous_run(bench: Any, state: Any, inst: dict, speed_rad_s: float, revolutions: int,
                   samples_per_rev: int) -> dict[str, list]:
    """Sample the probes (and the encoder) at a constant speed from the bench's current time and
    angle; advances the bench clock by the run's duration. Returns the table's columns."""
    if speed_rad_s <= 0:
        raise ValueError("continuous run: the speed must be > 0")
    if revolutions < 1 or samples_per_rev < 8:
        raise ValueError("continuous run: at least 1 revolution and 8 samples per revolution")
    enc = inst["encoder"]
    stage = inst["stage"]
    probes = [p for p in PROBES if p in inst]
    cols: dict[str, list] = {"t_s": [], "theta_deg": [], **{f"{p}_um": [] for p in probes}}
    t0 = float(state.clock.now())
    th0 = float(stage.command_rad)
    dt = 2.0 * math.pi / (speed_rad_s * samples_per_rev)
    saved = bench._centrifugal_N
    bench._centrifugal_N = float(bench.sc["bearings"]["unbalance"]) * speed_rad_s**2
    state.direction = 1
    try:
        for i in range(int(revolutions) * int(samples_per_rev)):
            t = t0 + i * dt
            state.clock.set(t)
            state.pose = bench.pose_at(th0 + speed_rad_s * (t - t0), rep=state.rep, t_s=t, direction=+1,
                                       rolling=True)
            enc.sim_last_exact = None
            r = enc.read()
            cols["t_s"].append(t)
            cols["theta_deg"].append(float(r["angle_deg"][0]))
            for p in probes:
                cols[f"{p}_um"].append(float(inst[p].read()["value_um"]))
    finally:
        bench._centrifugal_N = saved
    state.clock.set(t0 + int(revolutions) * int(samples_per_rev) * dt)
    return cols


def spectrum_per_rev(x: np.ndarray, samples_per_rev: int) -> tuple[np.ndarray, np.ndarray]:
    """One-sided amplitude spectrum of a signal sampled ``samples_per_rev`` times a revolution:
    (frequencies in cycles per revolution, amplitudes in the signal's unit), mean removed."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    a = np.abs(np.fft.rfft(x)) * 2.0 / x.size
    f = np.fft.rfftfreq(x.size, d=1.0 / samples_per_rev)
    return f, a


__all__ = ["continuous_run", "spectrum_per_rev"]
