"""Polygon readings generated from Hsieh et al. 2022 eq. 3 (test-only; it was
analysis.shift_angle.synthesize_readings): ε_ij = α((i−1)·360/N + S) + Σ_{k=j}^{j+i−1} β_k + U_j.

The cumulative pitch sums are computed here, not with the analysis's own
(``shift_angle.cumulative_pitch_sum_arcsec``), so the tests check eq. 3 against an independent sum.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np


def _pitch_sums(beta: np.ndarray) -> np.ndarray:
    """B[j−1, i−1] = Σ of the i pitch deviations from face j on (cyclic), eq. 3."""
    N = beta.size
    B = np.zeros((N, N))
    for j in range(N):
        acc = 0.0
        for i in range(N):
            acc += beta[(j + i) % N]
            B[j, i] = acc
    return B


def synthesize_readings(alpha_fn, beta_arcsec: np.ndarray, setup_error_fn, shifts_deg: Sequence[float], *,
                        start_faces_at: Mapping[float, Sequence[int]] | None = None, n_rep: int = 1,
                        noise_arcsec: float = 0.0, rng: np.random.Generator | None = None) -> dict[str, np.ndarray]:
    """Columns of a polygon table generated from eq. 3 (pure given ``rng``).

    ``alpha_fn(theta_deg) -> arcsec``; ``setup_error_fn(shift_deg, start_face) -> arcsec``. At S = 0 all
    N start faces are measured; at other shifts the faces in ``start_faces_at[S]`` (default: face 1).
    Returns ``shift_deg, start_face, step, theta_deg, ac_arcsec, t_s`` and ``rep`` when ``n_rep > 1``.
    """
    beta = np.asarray(beta_arcsec, dtype=float).ravel()
    N = beta.size
    B = _pitch_sums(beta)
    if noise_arcsec > 0 and rng is None:
        raise ValueError("noise needs an explicit rng (np.random.default_rng(seed))")
    out: dict[str, list] = {k: [] for k in ("shift_deg", "start_face", "step", "theta_deg", "ac_arcsec", "t_s", "rep")}
    t = 0.0
    for S in shifts_deg:
        faces = range(1, N + 1) if round(float(S), 9) == 0.0 else (start_faces_at or {}).get(S, [1])
        for rep in range(n_rep):
            for j in faces:
                U = setup_error_fn(S, j)
                for i in range(1, N + 1):
                    th = ((i - 1) * 360.0 / N + S) % 360.0
                    val = float(alpha_fn(np.array([th]))[0]) + B[j - 1, i - 1] + U
                    if noise_arcsec > 0:
                        val += float(rng.normal(0.0, noise_arcsec))
                    for k, v in zip(("shift_deg", "start_face", "step", "theta_deg", "ac_arcsec", "t_s", "rep"),
                                    (float(S), j, i, th, val, t, rep)):
                        out[k].append(v)
                    t += 1.0
    cols = {k: np.asarray(v) for k, v in out.items()}
    if n_rep == 1:
        del cols["rep"]
    return cols
