"""Both bearings' ball sets as one kernel: forces, stiffness and the shaft-angle rate in one call.

The physics is that of ``twin/bearing.py`` (Hertz contact Q = K_n·delta^1.5 of each ball,
Harris & Kotzalas, *Rolling Bearing Analysis*, 5th ed., vol. 1 ch. 6–7; waviness and ball-diameter
variation after Wardle 1988 / Yhland 1992), term for term:

    delta_j = delta_0 + cos(a)·(u·e_j) + cos(a)·(w_i(psi_j − theta) + w_o(psi_j)) + dD_j
    F       = −cos(a)·sum_j Q_j·e_j,        psi_j = phi_cage + 2·pi·j/Z,  e_j = (cos psi_j, sin psi_j)

What changes is only the cost of evaluating it at every Newton iteration of every pose
(twin/physics.py ``Bench._solve``), where ``BallSet.force_and_stiffness`` spent ~50 µs per set in
NumPy calls on 12-element arrays:

- the four races' lobes (inner and outer, top and bottom) are evaluated at the balls by ONE
  complex exponential and ONE block-diagonal matrix product (the ``BallSet`` identity
  sum_k a_k cos(k·x_j − p_k) = Re(sum_k W[j, k]·c_k·e^(i·k·x_0)), W[j, k] = e^(2·pi·i·j·k/Z)),
  with their derivative along the shaft angle in the same product (a second column i·k·x_0'·c_k·…);
- the per-ball sums (2 × Z balls) run as a scalar loop on Python floats (``math``): at this size
  the interpreter is several times faster than a NumPy call per operation.

Besides F and the stiffness K = −dF/du (the sum over loaded balls of (3/2)·K_n·delta_j^½·cos²a·
e_j·e_jᵀ, as ``force_and_stiffness``), the kernel returns g = ∂F/∂theta at fixed u: the forces'
EXPLICIT dependence on the shaft angle through the cage angle (the balls move: e_j turns, and each
ball meets other points of the races) and through the inner race turning with the shaft. With it
the bench's Newton matrix is the full Jacobian of its residual in the spin coordinate too, so
Newton converges quadratically from the tangent predictor (twin/physics.py). g changes only the
path of the iterations, never the equilibrium they converge to.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .bearing import BallSet


class BallSets:
    """The ball sets of the bench's bearings (top, bottom), evaluated together.

    ``evaluate(u, theta, cages, rates)``: u = (top x, top y, bottom x, bottom y) journal
    displacements relative to the housings (m), theta the shaft angle, cages the cage angles
    (lab frame) and rates d(cage)/d(theta) of each set. Returns (F, K, g): F the four force
    components on the journals (N), K the two 2×2 stiffness blocks as (kxx, kxy, kyy) per set
    (N/m), g = ∂F/∂theta at fixed u (N/rad). Python floats throughout."""

    def __init__(self, sets: Sequence[BallSet]):
        self.sets = tuple(sets)
        self.rho = [float(bs.rho) for bs in self.sets]      # cage ratios (Harris ch. 7)
        # Race terms of all sets in one vector: race r of set s contributes columns with orders
        # k, coefficients c_k = a_k·e^(-i p_k), and its rows in the block-diagonal W.
        ks: list[np.ndarray] = []
        cs: list[np.ndarray] = []
        blocks: list[tuple[int, np.ndarray]] = []
        which: list[int] = []
        rows = 0
        for s, bs in enumerate(self.sets):
            for inner, (c, k, W) in ((True, (bs._ci, bs._ki, bs._Wi)), (False, (bs._co, bs._ko, bs._Wo))):
                if k.size:
                    ks.append(k)
                    cs.append(c)
                    blocks.append((rows, W))
                    which.extend([2 * s + (0 if inner else 1)] * k.size)
            rows += bs.Z
        self._n_rows = rows
        k = np.concatenate(ks) if ks else np.zeros(0)
        self._c = np.concatenate(cs) if cs else np.zeros(0, dtype=complex)
        self._ik = 1j * k
        # Each column's angle x_0 and its rate d(x_0)/dθ, gathered from the eight values
        # (φ_top − θ, φ_top, φ_bottom − θ, φ_bottom, and their rates) in one indexing.
        col_race = np.array(which, dtype=int)
        self._gather = np.stack([col_race, col_race + 4]) if ks else np.zeros((2, 0), dtype=int)
        W = np.zeros((rows, k.size), dtype=complex)
        col = 0
        for r0, Wb in blocks:
            W[r0:r0 + Wb.shape[0], col:col + Wb.shape[1]] = Wb
            col += Wb.shape[1]
        self._WT = np.ascontiguousarray(W.T)
        self._V = np.empty((2, k.size), dtype=complex)
        # Per-set constants as Python floats, and each ball's fixed slot angle.
        self._const = [(bs.Z, bs.delta0_m, bs.cos_a, bs.Kn, [float(v) for v in bs._slots],
                        [float(v) for v in bs._dd]) for bs in self.sets]

    def interference(self, theta: float, cages: Sequence[float], rates: Sequence[float]) -> tuple[list, list]:
        """w_i(psi_j − theta) + w_o(psi_j) of every ball (sets concatenated; without cos(a) and
        dD_j), and its derivative along theta (cage angle moving at ``rates``)."""
        if not self._ik.size:
            z = [0.0] * self._n_rows
            return z, list(z)
        c0, c1 = cages
        r0, r1 = rates
        x = np.array([c0 - theta, c0, c1 - theta, c1, r0 - 1.0, r0, r1 - 1.0, r1])[self._gather]
        V = self._V
        np.multiply(self._c, np.exp(self._ik * x[0]), out=V[0])       # c_k·e^(i·k·x_0)
        np.multiply(V[0], self._ik * x[1], out=V[1])                  # its rate along θ
        w = (V @ self._WT).real.tolist()
        return w[0], w[1]

    def evaluate(self, u: Sequence[float], theta: float, cages: Sequence[float],
                 rates: Sequence[float]) -> tuple[list, list, list]:
        w_all, dw_all = self.interference(theta, cages, rates)
        F: list[float] = []
        K: list[tuple[float, float, float]] = []
        g: list[float] = []
        sqrt, cos, sin = math.sqrt, math.cos, math.sin
        row = 0
        for s, (Z, d0, ca, Kn, slots, dd) in enumerate(self._const):
            ux, uy = float(u[2 * s]), float(u[2 * s + 1])
            cage, rate = float(cages[s]), float(rates[s])
            cux, cuy = ca * ux, ca * uy
            fx = fy = kxx = kxy = kyy = hx = hy = 0.0
            for slot, ddj, wj, dwj in zip(slots, dd, w_all[row:row + Z], dw_all[row:row + Z]):
                psi = cage + slot
                c, sn = cos(psi), sin(psi)
                delta = d0 + (cux * c + cuy * sn) + (ca * wj + ddj)
                if delta <= 0.0:
                    continue          # the ball has lost contact: it carries nothing (no stiffness)
                root = sqrt(delta)
                Q = Kn * delta * root
                dQ = 1.5 * Kn * root                       # dQ/d(delta)
                fx += Q * c
                fy += Q * sn
                kc, ks = dQ * c, dQ * sn
                kxx += kc * c
                kxy += kc * sn
                kyy += ks * sn
                hx += kc * dwj
                hy += ks * dwj
            row += Z
            # g = ∂F/∂θ at fixed u, from the same sums: ball j's approach changes at
            # d(delta_j)/dθ = cos(a)·((u_y·c_j − u_x·s_j)·rate + w_j') (its direction turns with the
            # cage, and it meets the races elsewhere), and its direction e_j turns at ``rate``:
            #   ∂F/∂θ = −cos(a)·sum_j [Q_j'·d(delta_j)/dθ·e_j + Q_j·rate·(−s_j, c_j)]
            gx = ca * (rate * (uy * kxx - ux * kxy) + hx) - rate * fy
            gy = ca * (rate * (uy * kxy - ux * kyy) + hy) + rate * fx
            ca2 = ca * ca
            F += [-ca * fx, -ca * fy]
            K.append((ca2 * kxx, ca2 * kxy, ca2 * kyy))
            g += [-ca * gx, -ca * gy]
        return F, K, g


__all__ = ["BallSets"]
