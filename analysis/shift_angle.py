"""Shift-angle method and polygon cross-calibration (Hsieh, Watanabe, Hsu 2022).

T.-H. Hsieh, T. Watanabe, P.-E. Hsu, "Calibration of Rotary Encoders Using a Shift-Angle Method",
Appl. Sci. 12 (2022) 5008. Signs and frames: docs/conventions.md ("Polygon and autocollimator").

Model (eq. 3), step ``i`` and start face ``j`` in 1…N, shift ``S``::

    ε_ij(S) = α((i−1)·360/N + S) + Σ_{k=j}^{j+i−1 (mod N)} β_k + U_j(S)

- eq. 1: Σβ = 0 (circle closure of the polygon);
- eq. 2: Σ_i α((i−1)·360/N + S) = 0 for every shift (circle closure of the encoder);
- Table 1: the N×N readings at one shift. **Layout here: ``table[j−1, i−1]``** (start face = row,
  step = column, as in the paper's Table 1);
- eqs. 5–6 / Table 2: δ_{l,l−1,n} = ε_{l,n} − ε_{l−1,n} with ε_{N+1,n} ≡ ε_{1,n}; the row of Table 2
  whose differences all contain β_p has n = p − l + 1 (mod N); the row average is β_p because the
  α differences telescope over the full circle (:func:`table2_arcsec`, :func:`pitch_deviation_arcsec`);
- eq. 7: Σ_i ε_ij = Σ_i α + Σ_i B_ij + N·U_j, with eq. 2 → U_j = mean_i(ε_ij − B_ij), generalised
  from j = 1 (the paper) to any start face (:func:`setup_error_arcsec`);
- eq. 3 again: α(θ_i + S) = ε_ij − B_ij − U_j; with several start faces at one shift (always at
  S = 0, the full table) the estimates of the start faces are averaged (:func:`encoder_error_arcsec`);
- sec. 3.1: the curve-fit check of U, α = A·sin(2θ + B) + U (:func:`fit_sine2_offset`), and a
  general K-harmonic version (:func:`fit_harmonic_offset`, :func:`setup_error_by_curve_fit`).

Traditional cross-calibration: (a) with a calibrated polygon, one start face and the certificate β
(:func:`cross_calibrate_with_certificate`); (b) without one, the N×N closure over all start faces
(:func:`cross_calibrate_closure`), which is the S = 0 part of the shift-angle method.

Estimators and their uncertainty
--------------------------------
For one observation per cell, the paper's row averages are the ordinary least-squares estimates of
the three-way additive (Latin-square) model ε_ij = α_i + φ_{j+i−1} + V_j with φ the cumulative β.
All estimators are linear in the readings, so their standard uncertainties are propagated exactly
through the Jacobians (GUM, linear model) from ``u(ε)`` of each cell (e.g. the standard deviation
of the mean of its repetitions) and ``u(β)`` / cov(β) of a certificate. At S = 0 the correlation
between α and β (same readings) is taken into account.

What the method cannot see (not stated in the paper)
----------------------------------------------------
Harmonics of α whose order is a multiple of N sum to N·(their value at S) over the N steps; eq. 2
assumes that sum is zero, so such a harmonic is absorbed into U_j(S) and lost (it changes with S, so
every shift loses it). The combined shift-angle curve therefore lacks the harmonics k·N of α; compare
with self-calibration after removing those harmonics from the latter as well.

Decisions where the paper is silent
-----------------------------------
- θ of a reading is the nominal (i−1)·360/N + S (mod 360). A ``theta_deg`` column is only checked:
  a reading further than a quarter pitch from its nominal angle is a data error (usually a wrong N).
- Repetitions (``rep``; and ``direction`` forward/backward) of the same (shift, start_face, step)
  are averaged; their sample standard deviation is the repeatability; u(ε) of a cell is the pooled
  repeatability over all cells divided by √n (or, optionally, the cell's own sd/√n).
  Without a ``rep``/``direction`` column a repeated (shift, start_face, step) is an error.
- Shifts are matched after rounding to 1e-9 deg.
- A certificate β that does not sum to zero is made to (its mean is subtracted, eq. 1); the removed
  mean is reported.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchtwin.analysis.fourier import harmonic_columns

__all__ = [
    "PolygonDataError",
    "BetaSource",
    "PolygonTable",
    "tabulate_polygon",
    "nominal_theta_deg",
    "cumulative_pitch_sum_arcsec",
    "table2_arcsec",
    "pitch_deviation_operator",
    "pitch_deviation_arcsec",
    "setup_error_arcsec",
    "encoder_error_arcsec",
    "cross_calibrate_closure",
    "cross_calibrate_with_certificate",
    "closure_residual_sd_arcsec",
    "Repeatability",
    "reading_repeatability",
    "direction_difference",
    "alpha_scatter_by_rep",
    "ShiftResult",
    "ShiftAngleResult",
    "reference_shift",
    "require_reference_table",
    "shift_angle_analysis",
    "combined_curve",
    "fit_sine2_offset",
    "fit_harmonic_offset",
    "setup_error_by_curve_fit",
]

_SHIFT_DECIMALS = 9
_MAX_LISTED = 10


class PolygonDataError(ValueError):
    """Polygon readings that cannot be analysed; the message names the rows (0-based index) and column."""


def _rows(idx: Sequence[int] | np.ndarray) -> str:
    idx = [int(i) for i in np.asarray(idx).ravel()]
    s = ", ".join(str(i) for i in idx[:_MAX_LISTED])
    if len(idx) > _MAX_LISTED:
        s += f", … ({len(idx) - _MAX_LISTED} more)"
    return ("row " if len(idx) == 1 else "rows ") + s


def _cells(cells: Sequence[tuple[int, int]]) -> str:
    s = ", ".join(f"(start_face={j}, step={i})" for j, i in cells[:_MAX_LISTED])
    if len(cells) > _MAX_LISTED:
        s += f", … ({len(cells) - _MAX_LISTED} more)"
    return s


def _shift_key(s: float) -> float:
    return float(np.round(float(s), _SHIFT_DECIMALS)) + 0.0


def nominal_theta_deg(n_faces: int, shift_deg: float = 0.0) -> np.ndarray:
    """Encoder angles of steps i = 1…N at shift S: (i−1)·360/N + S, wrapped into [0, 360)."""
    return np.mod(np.arange(n_faces) * 360.0 / n_faces + shift_deg, 360.0)


# --------------------------------------------------------------------------- Table 1 from columns


@dataclass(frozen=True)
class PolygonTable:
    """Table 1 for every shift: ``eps_arcsec[S][j−1, i−1]`` (NaN where not measured).

    ``sd_arcsec``: sample standard deviation of the repetitions of a cell (NaN with < 2);
    ``n_rep``: number of repetitions averaged; ``u_arcsec``: sd/√n (NaN with < 2 repetitions).
    """

    n_faces: int
    shifts_deg: np.ndarray
    eps_arcsec: dict[float, np.ndarray]
    sd_arcsec: dict[float, np.ndarray]
    n_rep: dict[float, np.ndarray]
    theta_offset_max_deg: float = float("nan")
    #: the single runs: ``runs[S][(rep, direction)]`` is that run's Table 1 (NaN where not read);
    #: ``rep`` is 0 and ``direction`` "" where the columns are absent.
    runs: dict[float, dict[tuple, np.ndarray]] = field(default_factory=dict)

    @property
    def u_arcsec(self) -> dict[float, np.ndarray]:
        """Per-cell sd/√n (NaN with < 2 repetitions)."""
        return {s: self.sd_arcsec[s] / np.sqrt(np.maximum(self.n_rep[s], 1)) for s in self.shifts_deg}

    def pooled_sd(self) -> tuple[float, int]:
        """Pooled repeatability s_p = √(Σ(n−1)·s² / Σ(n−1)) over all cells of all shifts, and its dof."""
        num, dof = 0.0, 0
        for s in self.shifts_deg:
            ok = self.n_rep[s] > 1
            num += float(np.sum((self.n_rep[s][ok] - 1) * self.sd_arcsec[s][ok] ** 2))
            dof += int(np.sum(self.n_rep[s][ok] - 1))
        return (float(np.sqrt(num / dof)) if dof else float("nan")), dof

    def u_pooled_arcsec(self) -> dict[float, np.ndarray]:
        """s_p/√n per cell (NaN where the cell has no reading or no repetitions exist anywhere)."""
        sp, _ = self.pooled_sd()
        return {s: np.where(self.n_rep[s] > 0, sp / np.sqrt(np.maximum(self.n_rep[s], 1)), np.nan)
                for s in self.shifts_deg}

    def start_faces(self, shift_deg: float) -> np.ndarray:
        """1-based start faces that have at least one reading at this shift."""
        e = self.eps_arcsec[_shift_key(shift_deg)]
        return np.flatnonzero(np.any(np.isfinite(e), axis=1)) + 1

    def is_complete(self, shift_deg: float) -> bool:
        return bool(np.all(np.isfinite(self.eps_arcsec[_shift_key(shift_deg)])))


#: The polygon table's columns :func:`tabulate_polygon` needs; and those it uses when present.
POLYGON_COLUMNS = ("shift_deg", "start_face", "step", "ac_arcsec")
POLYGON_OPTIONAL_COLUMNS = ("theta_deg", "rep", "direction")


def _polygon_columns(columns: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """The columns as flat arrays of one length, the numeric ones finite floats (PolygonDataError
    naming the rows and the column otherwise); theta_deg, rep, direction when present (None: absent);
    other columns are not used."""
    missing = [c for c in POLYGON_COLUMNS if c not in columns]
    if missing:
        raise PolygonDataError(f"polygon columns missing: {missing} (has {sorted(columns)})")
    cols: dict[str, np.ndarray] = {
        "shift_deg": np.asarray(columns["shift_deg"], dtype=float).ravel(),
        "start_face": np.asarray(columns["start_face"]).ravel(),
        "step": np.asarray(columns["step"]).ravel(),
        "ac_arcsec": np.asarray(columns["ac_arcsec"], dtype=float).ravel(),
    }
    for name in POLYGON_OPTIONAL_COLUMNS:
        v = columns.get(name)
        if v is not None:
            cols[name] = np.asarray(v, dtype=float).ravel() if name == "theta_deg" else np.asarray(v).ravel()
    n = cols["shift_deg"].size
    bad_len = {k: v.size for k, v in cols.items() if v.size != n}
    if bad_len:
        raise PolygonDataError(f"columns of different lengths: shift_deg has {n} rows, {bad_len}")
    if n == 0:
        raise PolygonDataError("no polygon readings (0 rows)")
    for name in ("shift_deg", "start_face", "step", "ac_arcsec", "theta_deg", "rep"):
        if name not in cols:
            continue
        try:
            v = cols[name].astype(float)
        except (TypeError, ValueError):
            raise PolygonDataError(f"column {name!r}: non-numeric values") from None
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise PolygonDataError(f"{_rows(bad)}, column {name!r}: not a finite number (NaN or inf)")
        cols[name] = v
    return cols


def _check_faces_and_steps(cols: Mapping[str, np.ndarray], N: int) -> None:
    """Start face and step must be integers in 1…N."""
    for name in ("start_face", "step"):
        v = cols[name]
        bad = np.flatnonzero((v != np.round(v)) | (v < 1) | (v > N))
        if bad.size:
            raise PolygonDataError(f"{_rows(bad)}, column {name!r}: expected an integer in 1…{N} (n_faces={N}), "
                                   f"got {v[bad[:_MAX_LISTED]].tolist()}")


def _check_repeats(cols: Mapping[str, np.ndarray], shifts: np.ndarray, face: np.ndarray, stp: np.ndarray) -> None:
    """No reading twice: (shift, start face, step) plus rep and direction where those columns exist."""
    key_cols = ["rep"] if "rep" in cols else []
    key_cols += ["direction"] if "direction" in cols else []
    seen: dict[tuple, int] = {}
    for r in range(shifts.size):
        key = (shifts[r], face[r], stp[r]) + tuple(cols[c][r] for c in key_cols)
        if key in seen:
            what = f"shift_deg={shifts[r]:g}, start_face={face[r]}, step={stp[r]}"
            what += "".join(f", {c}={cols[c][r]}" for c in key_cols)
            hint = "" if key_cols else " (no 'rep' column, so repetitions are not expected)"
            raise PolygonDataError(f"rows {seen[key]} and {r}, columns shift_deg/start_face/step"
                                   f"{'/' + '/'.join(key_cols) if key_cols else ''}: duplicated reading ({what}){hint}")
        seen[key] = r


def _theta_offset_max(cols: Mapping[str, np.ndarray], shifts: np.ndarray, stp: np.ndarray, N: int) -> float:
    """The largest |θ − ((step − 1)·360/N + S)| in deg (NaN without θ); PolygonDataError beyond a
    quarter pitch."""
    if "theta_deg" not in cols:
        return float("nan")
    nominal = (stp - 1) * 360.0 / N + shifts
    off = np.abs(np.mod(cols["theta_deg"] - nominal + 180.0, 360.0) - 180.0)
    bad = np.flatnonzero(off > 0.25 * 360.0 / N)
    if bad.size:
        raise PolygonDataError(
            f"{_rows(bad)}, column 'theta_deg': more than a quarter pitch from (step−1)·360/N + shift_deg "
            f"with N={N} (offsets up to {off[bad].max():.4g} deg): wrong face count or step numbering?")
    return float(off.max())


def _check_full_rows(s: float, cnt: np.ndarray) -> None:
    """Every start face present at a shift must have its full row (eq. 7); the message suggests a
    wrong face count when every row stops at the same step."""
    N = cnt.shape[0]
    present = np.flatnonzero(cnt.sum(axis=1) > 0)
    missing = [(int(j) + 1, int(k) + 1) for j in present for k in range(N) if cnt[j, k] == 0]
    if missing:
        last = {int(j) + 1: int(np.flatnonzero(cnt[j] > 0).max()) + 1 for j in present}
        hint = ""
        if len(set(last.values())) == 1 and next(iter(last.values())) < N:
            hint = (f"; every start face stops at step {next(iter(last.values()))}: "
                    f"wrong face count (n_faces={N})?")
        raise PolygonDataError(f"shift_deg={s:g}: columns start_face/step: missing readings {_cells(missing)} "
                               f"(each start face needs steps 1…{N}){hint}")


def _shift_table(N: int, f: np.ndarray, i: np.ndarray, a: np.ndarray, runs_by: tuple[np.ndarray, np.ndarray]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[tuple, np.ndarray]]:
    """One shift's Table 1 from its readings (0-based start face ``f``, step ``i``, reading ``a``):
    the mean over repeats per cell, their sd (NaN below 2), the count, and each run's own table keyed
    by (rep, direction) (``runs_by``: those columns)."""
    rk, dk = runs_by
    runs_s: dict[tuple, np.ndarray] = {}
    for key in sorted(set(zip(rk.tolist(), dk.tolist()))):
        mm = (rk == key[0]) & (dk == key[1])
        t = np.full((N, N), np.nan)
        t[f[mm], i[mm]] = a[mm]
        runs_s[key] = t
    cnt = np.zeros((N, N), dtype=int)
    sm = np.zeros((N, N))
    np.add.at(cnt, (f, i), 1)
    np.add.at(sm, (f, i), a)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(cnt > 0, sm / np.maximum(cnt, 1), np.nan)
    ss = np.zeros((N, N))
    np.add.at(ss, (f, i), (a - mean[f, i]) ** 2)
    sdev = np.where(cnt > 1, np.sqrt(ss / np.maximum(cnt - 1, 1)), np.nan)
    return mean, sdev, cnt, runs_s


def tabulate_polygon(columns: Mapping[str, Any], n_faces: int) -> PolygonTable:
    """Build Table 1 (eq. 3 layout) per shift from the dataset's columns; validate them.

    ``columns``: the polygon table, ``shift_deg, start_face, step, ac_arcsec`` and, when present,
    ``theta_deg``, ``rep``, ``direction`` (a column that is None counts as absent; others are not
    used). Raises :class:`PolygonDataError` naming rows (0-based index into the arrays) and the
    column for: a wrong ``n_faces`` (< 3 or not an integer), a missing column, columns of different
    lengths, NaN/inf, start face or
    step not an integer in 1…N, repeated readings without a ``rep``/``direction`` column (or repeated
    (shift, start_face, step, rep, direction)), a ``theta_deg`` more than a quarter pitch away from
    (i−1)·360/N + S, and a start face whose row at a shift misses steps (eq. 7 needs all N; the message
    suggests a wrong face count when every row stops at the same step).

    Stages: :func:`_polygon_columns`, :func:`_check_faces_and_steps`, :func:`_check_repeats`,
    :func:`_theta_offset_max`, then per shift :func:`_shift_table` and :func:`_check_full_rows`.
    """
    if isinstance(n_faces, bool) or int(n_faces) != n_faces or n_faces < 3:
        raise PolygonDataError(f"n_faces: expected an integer >= 3, got {n_faces!r}")
    N = int(n_faces)
    cols = _polygon_columns(columns)
    n = cols["shift_deg"].size
    _check_faces_and_steps(cols, N)
    face = cols["start_face"].astype(int)
    stp = cols["step"].astype(int)
    shifts = np.array([_shift_key(s) for s in cols["shift_deg"]])
    _check_repeats(cols, shifts, face, stp)
    off_max = _theta_offset_max(cols, shifts, stp, N)
    # aggregate
    uniq = np.unique(shifts)
    eps, sd, nrep, runs = {}, {}, {}, {}
    rep_col = cols["rep"] if "rep" in cols else np.zeros(n)
    dir_col = cols["direction"].astype(str) if "direction" in cols else np.full(n, "", dtype=object)
    for s in uniq:
        m = shifts == s
        mean, sdev, cnt, runs_s = _shift_table(N, face[m] - 1, stp[m] - 1, cols["ac_arcsec"][m], (rep_col[m], dir_col[m]))
        _check_full_rows(s, cnt)
        eps[float(s)], sd[float(s)], nrep[float(s)], runs[float(s)] = mean, sdev, cnt, runs_s
    return PolygonTable(N, uniq.astype(float), eps, sd, nrep, off_max, runs)


# --------------------------------------------------------------------------- eq. 3, Table 2, eq. 5-7


def _cumsum_indicator(N: int, faces: np.ndarray) -> np.ndarray:
    """C[r, i−1, k−1] = 1 if β_k is in Σ_{k=j}^{j+i−1 mod N} (i terms from face j = faces[r])."""
    i = np.arange(N)[:, None]
    k = np.arange(N)[None, :]
    C = np.empty((len(faces), N, N))
    for r, j in enumerate(np.asarray(faces, dtype=int)):
        C[r] = ((k - (j - 1)) % N <= i).astype(float)
    return C


def cumulative_pitch_sum_arcsec(beta_arcsec: np.ndarray) -> np.ndarray:
    """B[j−1, i−1] = Σ_{k=j}^{j+i−1 (mod N)} β_k of eq. 3 (i terms, starting at face j)."""
    b = np.asarray(beta_arcsec, dtype=float).ravel()
    N = b.size
    ext = np.concatenate([[0.0], np.cumsum(np.concatenate([b, b]))])  # ext[m] = Σ_{k<m} b2[k]
    j = np.arange(N)[:, None]
    i = np.arange(N)[None, :]
    return ext[j + i + 1] - ext[j]


def _check_square(table: np.ndarray, what: str = "table") -> np.ndarray:
    t = np.asarray(table, dtype=float)
    if t.ndim != 2 or t.shape[0] != t.shape[1] or t.shape[0] < 3:
        raise PolygonDataError(f"{what}: expected an N×N Table 1 (N >= 3), got shape {t.shape}")
    bad = np.argwhere(~np.isfinite(t))
    if bad.size:
        raise PolygonDataError(f"{what}: missing readings {_cells([(int(j) + 1, int(i) + 1) for j, i in bad])} "
                               f"(the closure needs all N×N = {t.size} cells)")
    return t


def table2_arcsec(table1_arcsec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Table 2 (eqs. 5-6): ``delta[p−1, l−2] = δ_{l,l−1,n}`` = ε_{l,n} − ε_{l−1,n} for l = 2…N+1.

    Row p collects the N differences that contain β_p: n = p − l + 1 (mod N), and ε_{N+1,n} ≡ ε_{1,n}.
    Returns ``(delta, n)`` with ``n[p−1, l−2]`` the 1-based start face of each entry.
    """
    t = _check_square(table1_arcsec, "table1_arcsec")
    N = t.shape[0]
    p = np.arange(N)[:, None]  # 0-based p−1
    lm2 = np.arange(N)[None, :]  # l−2, l = 2…N+1
    n0 = (p - lm2 - 1) % N  # 0-based n: n = p − l + 1 → (p−1) − (l−2) − 1
    l0 = (lm2 + 1) % N  # 0-based l−1 (wraps N+1 → 1)
    lm0 = lm2  # 0-based (l−1)−1
    delta = t[n0, l0] - t[n0, lm0]
    return delta, n0 + 1


def pitch_deviation_operator(n_faces: int) -> np.ndarray:
    """L (N × N²) with β̂ = L @ table1.ravel() (row-major ``[j−1, i−1]``): the row averages of Table 2."""
    N = int(n_faces)
    L = np.zeros((N, N * N))
    for p in range(N):
        for lm2 in range(N):
            n0 = (p - lm2 - 1) % N
            L[p, n0 * N + (lm2 + 1) % N] += 1.0 / N
            L[p, n0 * N + lm2] -= 1.0 / N
    return L


def pitch_deviation_arcsec(table1_arcsec: np.ndarray, u_table1_arcsec: np.ndarray | float | None = None
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """β from the row averages of Table 2 (eqs. 5-6); Σβ = 0 (eq. 1) holds identically.

    Returns ``(beta, u_beta, cov_beta)``; u from ``u_table1_arcsec`` (per cell or scalar, independent
    cells), NaN if not given.
    """
    t = _check_square(table1_arcsec, "table1_arcsec")
    N = t.shape[0]
    delta, _ = table2_arcsec(t)
    beta = delta.mean(axis=1)
    if u_table1_arcsec is None:
        cov = np.full((N, N), np.nan)
    else:
        u = np.broadcast_to(np.asarray(u_table1_arcsec, dtype=float), (N, N)).ravel()
        L = pitch_deviation_operator(N)
        cov = (L * u**2) @ L.T
    return beta, np.sqrt(np.diag(cov)), cov


def _prep_rows(eps_rows: np.ndarray, start_faces: Sequence[int] | np.ndarray, N: int) -> tuple[np.ndarray, np.ndarray]:
    e = np.atleast_2d(np.asarray(eps_rows, dtype=float))
    f = np.atleast_1d(np.asarray(start_faces)).astype(int).ravel()
    if e.shape[1] != N:
        raise PolygonDataError(f"eps rows have {e.shape[1]} steps, expected N = {N} (length of beta)")
    if e.shape[0] != f.size:
        raise PolygonDataError(f"{e.shape[0]} rows of readings but {f.size} start faces")
    if np.any((f < 1) | (f > N)):
        raise PolygonDataError(f"start faces {f.tolist()}: expected 1…{N}")
    bad = np.argwhere(~np.isfinite(e))
    if bad.size:
        raise PolygonDataError(f"missing readings {_cells([(int(f[r]), int(c) + 1) for r, c in bad])}")
    return e, f


def setup_error_arcsec(eps_rows_arcsec: np.ndarray, start_faces: Sequence[int] | np.ndarray,
                       beta_arcsec: np.ndarray) -> np.ndarray:
    """U_j of eq. 7 for each given start face: U_j = mean_i(ε_ij − Σ_{k=j}^{j+i−1} β_k), using eq. 2.

    ``eps_rows_arcsec``: (m, N) readings, row r for start face ``start_faces[r]``, steps 1…N.
    """
    b = np.asarray(beta_arcsec, dtype=float).ravel()
    e, f = _prep_rows(eps_rows_arcsec, start_faces, b.size)
    B = cumulative_pitch_sum_arcsec(b)[f - 1]
    return (e - B).mean(axis=1)


def _alpha_jacobians(f: np.ndarray, N: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Linear maps of :func:`encoder_error_arcsec`: α = Je @ eps.ravel() + Jb @ β, U = Ke @ eps.ravel() + Kb @ β."""
    m = f.size
    C = _cumsum_indicator(N, f)  # (m, N, N)
    Je = np.zeros((N, m * N))
    Ke = np.zeros((m, m * N))
    center = np.eye(N) - 1.0 / N
    for r in range(m):
        Je[:, r * N:(r + 1) * N] = center / m
        Ke[r, r * N:(r + 1) * N] = 1.0 / N
    Cbar = C.mean(axis=1)  # (m, N): mean over steps
    Kb = -Cbar
    Jb = (-(C - Cbar[:, None, :])).mean(axis=0)  # (N, N)
    return Je, Jb, Ke, Kb


def encoder_error_arcsec(eps_rows_arcsec: np.ndarray, start_faces: Sequence[int] | np.ndarray, beta_arcsec: np.ndarray,
                         shift_deg: float = 0.0, *, u_eps_arcsec: np.ndarray | float | None = None,
                         cov_beta_arcsec2: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """α at θ_i = (i−1)·360/N + S from eq. 3 with U_j from eq. 7; averaged over the start faces given.

    Returns a dict: ``theta_deg`` (N, nominal, wrapped), ``alpha`` (N), ``u_alpha`` (N), ``U`` (m),
    ``u_U`` (m), ``alpha_by_face`` (m, N), ``cov_alpha`` (N, N). Uncertainties propagate ``u_eps``
    (per reading or scalar, independent) and ``cov_beta`` (β treated as independent of these readings;
    see :func:`shift_angle_analysis` for the S = 0 case where they are not).
    """
    b = np.asarray(beta_arcsec, dtype=float).ravel()
    N = b.size
    e, f = _prep_rows(eps_rows_arcsec, start_faces, N)
    B = cumulative_pitch_sum_arcsec(b)[f - 1]
    r = e - B
    U = r.mean(axis=1)
    by_face = r - U[:, None]
    alpha = by_face.mean(axis=0)
    Je, Jb, Ke, Kb = _alpha_jacobians(f, N)
    cov = np.zeros((N, N))
    covU = np.zeros((f.size, f.size))
    if u_eps_arcsec is not None:
        u2 = np.broadcast_to(np.asarray(u_eps_arcsec, dtype=float), e.shape).ravel() ** 2
        cov += (Je * u2) @ Je.T
        covU += (Ke * u2) @ Ke.T
    if cov_beta_arcsec2 is not None:
        cb = np.asarray(cov_beta_arcsec2, dtype=float)
        cov += Jb @ cb @ Jb.T
        covU += Kb @ cb @ Kb.T
    if u_eps_arcsec is None and cov_beta_arcsec2 is None:
        cov[:] = np.nan
        covU[:] = np.nan
    return {"theta_deg": nominal_theta_deg(N, shift_deg), "alpha": alpha, "u_alpha": np.sqrt(np.diag(cov)),
            "U": U, "u_U": np.sqrt(np.diag(covU)), "alpha_by_face": by_face, "cov_alpha": cov}


def cross_calibrate_closure(table1_arcsec: np.ndarray, u_table1_arcsec: np.ndarray | float | None = None
                            ) -> dict[str, np.ndarray]:
    """Traditional cross-calibration without a calibrated polygon: N×N closure over all start faces.

    β from Table 2 (eqs. 5-6), U_j of every start face (eq. 7), α at 0, 360/N, … averaged over the N
    start faces (eq. 3). u propagated from ``u_table1_arcsec`` including the α-β correlation.
    Returns ``beta, u_beta, cov_beta, U, u_U, theta_deg, alpha, u_alpha, cov_alpha``.
    """
    t = _check_square(table1_arcsec, "table1_arcsec")
    N = t.shape[0]
    beta, u_beta, cov_beta = pitch_deviation_arcsec(t, u_table1_arcsec)
    faces = np.arange(1, N + 1)
    res = encoder_error_arcsec(t, faces, beta, 0.0)
    if u_table1_arcsec is not None:
        u2 = np.broadcast_to(np.asarray(u_table1_arcsec, dtype=float), (N, N)).ravel() ** 2
        L = pitch_deviation_operator(N)
        Je, Jb, Ke, Kb = _alpha_jacobians(faces, N)
        Ja, Ju = Je + Jb @ L, Ke + Kb @ L
        cov_a, cov_u = (Ja * u2) @ Ja.T, (Ju * u2) @ Ju.T
    else:
        cov_a, cov_u = np.full((N, N), np.nan), np.full((N, N), np.nan)
    return {"beta": beta, "u_beta": u_beta, "cov_beta": cov_beta, "U": res["U"], "u_U": np.sqrt(np.diag(cov_u)),
            "theta_deg": res["theta_deg"], "alpha": res["alpha"], "u_alpha": np.sqrt(np.diag(cov_a)),
            "cov_alpha": cov_a, "alpha_by_face": res["alpha_by_face"]}


def closure_residual_sd_arcsec(table1_arcsec: np.ndarray) -> tuple[float, int]:
    """Pooled standard deviation of one reading from the residuals of the N×N closure (S = 0).

    Residual r_ij = ε_ij − (α̂_i + B̂_ij + Û_j); ν = N² − (N−1) − (N−1) − N = (N−1)(N−2) (α and β each
    closed, eqs. 1-2; one U per start face). Used as u(ε) when the readings have no repetitions.
    Returns ``(s, nu)``.
    """
    t = _check_square(table1_arcsec, "table1_arcsec")
    N = t.shape[0]
    r = cross_calibrate_closure(t)
    B = cumulative_pitch_sum_arcsec(r["beta"])
    res = t - (r["alpha"][None, :] + B + r["U"][:, None])
    nu = (N - 1) * (N - 2)
    return float(np.sqrt(np.sum(res**2) / nu)), nu


def _certificate(beta_cert: np.ndarray, N: int, u_cert: np.ndarray | float | None) -> tuple[np.ndarray, np.ndarray, float]:
    b = np.asarray(beta_cert, dtype=float).ravel()
    if b.size != N:
        raise PolygonDataError(f"certificate_beta_arcsec: {b.size} pitch deviations, expected N = {N} faces")
    bad = np.flatnonzero(~np.isfinite(b))
    if bad.size:
        raise PolygonDataError(f"certificate_beta_arcsec: entries {bad.tolist()} (0-based faces) not finite")
    mean = float(b.mean())
    b = b - mean
    if u_cert is None:
        cov = np.zeros((N, N))
    else:
        u = np.broadcast_to(np.asarray(u_cert, dtype=float), (N,))
        P = np.eye(N) - 1.0 / N  # the mean removal is part of the estimator
        cov = P @ np.diag(u**2) @ P.T
    return b, cov, mean


def cross_calibrate_with_certificate(eps_row_arcsec: np.ndarray, certificate_beta_arcsec: np.ndarray,
                                     start_face: int = 1, shift_deg: float = 0.0, *,
                                     u_eps_arcsec: np.ndarray | float | None = None,
                                     u_certificate_arcsec: np.ndarray | float | None = None) -> dict[str, Any]:
    """Traditional cross-calibration with a calibrated polygon: one start face, β from a certificate.

    eq. 3 with known β and U from eq. 7. The certificate is made to close (Σβ = 0, eq. 1) by subtracting
    its mean, returned as ``certificate_mean_arcsec``.
    """
    e = np.atleast_2d(np.asarray(eps_row_arcsec, dtype=float))
    N = e.shape[1]
    b, cov, mean = _certificate(certificate_beta_arcsec, N, u_certificate_arcsec)
    res: dict[str, Any] = encoder_error_arcsec(e, [start_face] * e.shape[0], b, shift_deg,
                                               u_eps_arcsec=u_eps_arcsec, cov_beta_arcsec2=cov)
    res["certificate_mean_arcsec"] = mean
    res["beta"] = b
    return res


# --------------------------------------------------------------------------- all shifts


@dataclass(frozen=True)
class ShiftResult:
    """α at one shift: ``theta_deg`` (N), ``alpha_arcsec``, ``u_alpha_arcsec`` (from u(ε), u(β)),
    ``start_faces`` used, their setup errors ``U_arcsec`` and ``u_U_arcsec``."""

    shift_deg: float
    theta_deg: np.ndarray
    alpha_arcsec: np.ndarray
    u_alpha_arcsec: np.ndarray
    start_faces: np.ndarray
    U_arcsec: np.ndarray
    u_U_arcsec: np.ndarray
    alpha_by_face_arcsec: np.ndarray
    #: the parts of u_alpha from this shift's readings and from β (at the closure's reference shift,
    #: where the same readings give β, everything is in the first and the second is 0)
    u_alpha_eps_arcsec: np.ndarray | None = None
    u_alpha_beta_arcsec: np.ndarray | None = None


@dataclass(frozen=True)
class ShiftAngleResult:
    n_faces: int
    beta_arcsec: np.ndarray
    u_beta_arcsec: np.ndarray
    cov_beta_arcsec2: np.ndarray
    beta_source: str  # "closure" or "certificate"
    shifts: list[ShiftResult]
    table: PolygonTable
    beta_closure_arcsec: np.ndarray | None = None  # closure β when the certificate was used but S=0 is full
    notes: list[str] = field(default_factory=list)
    reference_shift_deg: float = 0.0  # the shift whose full table gave the closure β


def reference_shift(table: PolygonTable, reference_shift_deg: float | None = None) -> float:
    """The shift whose full N×N table gives the closure β (eqs. 5-6): ``reference_shift_deg`` if given,
    else S = 0 when there are readings at 0 (the paper), else the smallest shift with a complete table."""
    if reference_shift_deg is not None:
        return _shift_key(reference_shift_deg)
    complete = [float(x) for x in table.shifts_deg if table.is_complete(float(x))]
    return 0.0 if (0.0 in table.eps_arcsec or not complete) else complete[0]


def require_reference_table(table: PolygonTable, *, certificate: bool,
                            reference_shift_deg: float | None = None) -> float:
    """The reference shift (:func:`reference_shift`); without a certificate β comes from its closure,
    so its N×N table must be complete, else :class:`PolygonDataError` names the missing cells. The
    dataset reader applies the same rule (analysis/structure.py), so validate accepts what this runs."""
    s0 = reference_shift(table, reference_shift_deg)
    if certificate or (s0 in table.eps_arcsec and table.is_complete(s0)):
        return s0
    N = table.n_faces
    if s0 not in table.eps_arcsec:
        raise PolygonDataError(f"no readings at shift_deg={s0:g}: the closure (eqs. 5-6) needs the full "
                               f"N×N table at one shift (N={N}), or pass certificate_beta_arcsec")
    missing = [(int(j) + 1, int(i) + 1) for j, i in np.argwhere(~np.isfinite(table.eps_arcsec[s0]))]
    raise PolygonDataError(f"shift_deg={s0:g}, columns start_face/step: incomplete Table 1, missing readings "
                           f"{_cells(missing)} (the closure needs all N×N = {N * N})")


@dataclass(frozen=True)
class BetaSource:
    """Where the polygon's pitch deviations β come from (:func:`shift_angle_analysis`): ``source``
    "auto", "closure" or "certificate", and a calibrated polygon's certificate (arcsec, N values) with
    its standard uncertainty (arcsec, one number or N; None: unknown)."""

    source: str = "auto"
    certificate_arcsec: np.ndarray | None = None
    u_certificate_arcsec: np.ndarray | float | None = None


def shift_angle_analysis(table: PolygonTable, *, beta_from: BetaSource | None = None, u_eps_arcsec: float | None = None,
                         pool_repeatability: bool = True, reference_shift_deg: float | None = None,
                         s_reading_arcsec: float | None = None) -> ShiftAngleResult:
    """The shift-angle method over every shift of a :class:`PolygonTable` (sec. 2.1-2.2, 3.1).

    β (``beta_from``, :class:`BetaSource`): from the full N×N table at the reference shift (eqs. 5-6;
    ``source="closure"``) or from a certificate (``"certificate"``); ``"auto"`` uses the closure when the reference table is complete,
    else the certificate, else raises :class:`PolygonDataError` naming the missing cells. The reference
    shift is ``reference_shift_deg``, by default S = 0 when there are readings at 0 (the paper), else the
    smallest shift with a complete N×N table (eqs. 5-6 hold at any S). Then, at every shift,
    every start face measured gets its own setup error (eq. 7) and α is averaged over those faces.

    u(ε) of a cell: s/√n with s the repeatability pooled over all cells (``pool_repeatability=True``,
    default: a sample sd from 2-3 repetitions is too uncertain to weigh a single cell — a cell whose
    few readings agree by chance would get a tiny u) or the cell's own sd (``False``); where that is
    not available (no repetitions), ``u_eps_arcsec``; if neither, uncertainties are NaN.
    ``s_reading_arcsec`` (the standard deviation of ONE reading, e.g. from :func:`reading_repeatability`)
    overrides both: u(ε) of a cell is s/√n with n the readings averaged in it.
    """
    bs = beta_from if beta_from is not None else BetaSource()
    beta_source, certificate_beta_arcsec, u_certificate_arcsec = bs.source, bs.certificate_arcsec, bs.u_certificate_arcsec
    N = table.n_faces
    notes: list[str] = []
    s0 = reference_shift(table, reference_shift_deg)
    have_full0 = s0 in table.eps_arcsec and table.is_complete(s0)
    if beta_source not in ("auto", "closure", "certificate"):
        raise ValueError(f"beta_source must be auto/closure/certificate, got {beta_source!r}")
    src = beta_source
    if src == "auto":
        src = "closure" if (have_full0 or certificate_beta_arcsec is None) else "certificate"
    if src == "certificate" and certificate_beta_arcsec is None:
        raise PolygonDataError("beta_source='certificate' but no certificate_beta_arcsec given")

    def u_cells(s: float) -> np.ndarray | None:
        if s_reading_arcsec is not None:
            n = table.n_rep[s]
            return np.where(n > 0, float(s_reading_arcsec) / np.sqrt(np.maximum(n, 1)), 0.0)
        u = (table.u_pooled_arcsec() if pool_repeatability else table.u_arcsec)[s].copy()
        if u_eps_arcsec is not None:
            u = np.where(np.isfinite(u), u, float(u_eps_arcsec))
        return None if np.all(np.isnan(u)) else np.where(np.isfinite(u), u, 0.0)

    beta_closure = None
    L = pitch_deviation_operator(N)
    if have_full0:
        u0 = u_cells(s0)
        beta_closure, ub, cb = pitch_deviation_arcsec(table.eps_arcsec[s0], u0)
    if src == "closure":
        require_reference_table(table, certificate=False, reference_shift_deg=reference_shift_deg)
        assert beta_closure is not None  # the complete reference table gave it (required just above)
        beta, u_beta, cov_beta = beta_closure, ub, cb
    else:
        assert certificate_beta_arcsec is not None  # src == "certificate" requires it (checked above)
        beta, cov_beta, mean = _certificate(certificate_beta_arcsec, N, u_certificate_arcsec)
        u_beta = np.sqrt(np.diag(cov_beta)) if u_certificate_arcsec is not None else np.full(N, np.nan)
        if abs(mean) > 0:
            notes.append(f"certificate β summed to {N * mean:.6g} arcsec; its mean was removed (eq. 1)")
    results = []
    for s in table.shifts_deg:
        s = float(s)
        faces = table.start_faces(s)
        e = table.eps_arcsec[s][faces - 1]
        uc = u_cells(s)
        u_rows = None if uc is None else uc[faces - 1]
        res = encoder_error_arcsec(e, faces, beta, s)
        Je, Jb, Ke, Kb = _alpha_jacobians(faces, N)
        cov_b = cov_beta if np.all(np.isfinite(cov_beta)) else None
        if src == "closure" and s == s0 and u_rows is not None:
            # same readings give β and α: total Jacobian w.r.t. the full table
            u2 = u_rows.ravel() ** 2  # faces == 1…N here (full table)
            Ja, Ju = Je + Jb @ L, Ke + Kb @ L
            cov_a, cov_u = (Ja * u2) @ Ja.T, (Ju * u2) @ Ju.T
            u_e, u_b = np.sqrt(np.diag(cov_a)), np.zeros(N)
        else:
            cov_a = np.zeros((N, N))
            cov_u = np.zeros((faces.size, faces.size))
            u_e = u_b = np.full(N, np.nan)
            ok = False
            if u_rows is not None:
                u2 = u_rows.ravel() ** 2
                ce = (Je * u2) @ Je.T
                cov_a += ce
                cov_u += (Ke * u2) @ Ke.T
                u_e = np.sqrt(np.diag(ce))
                ok = True
            if cov_b is not None:
                cbb = Jb @ cov_b @ Jb.T
                cov_a += cbb
                cov_u += Kb @ cov_b @ Kb.T
                u_b = np.sqrt(np.maximum(np.diag(cbb), 0.0))
                ok = True
            if not ok:
                cov_a[:] = np.nan
                cov_u[:] = np.nan
        results.append(ShiftResult(s, res["theta_deg"], res["alpha"], np.sqrt(np.diag(cov_a)), faces, res["U"],
                                   np.sqrt(np.diag(cov_u)), res["alpha_by_face"], u_e, u_b))
    return ShiftAngleResult(N, beta, u_beta, cov_beta, src, results, table,
                            beta_closure if src == "certificate" else None, notes, s0)


# --------------------------------------------------------------------------- repeatability, directions


@dataclass(frozen=True)
class Repeatability:
    """Repeatability of ONE autocollimator reading from the residuals of the Table-1 model.

    ``s_arcsec`` with ``dof`` degrees of freedom, from ``n_readings`` readings in ``n_rows`` run-rows
    (one start face swept once in one direction); ``dropped`` lists run-rows not used because a reading
    is missing in that run: ``(shift_deg, rep, direction, start_face)``.
    """

    s_arcsec: float
    dof: int
    n_readings: int
    n_rows: int
    rss_arcsec2: float
    dropped: list[tuple] = field(default_factory=list)


def reading_repeatability(table: PolygonTable) -> Repeatability:
    """s of one reading from the residuals of eq. 3 fitted to every single reading (every run).

    Model, for the reading of step i, start face j, run r (a repetition in one direction d), shift S::

        ε = α_{S,d}(i) + Φ((j + i − 1) mod N) + V_{S,r,j} + e

    Φ is the cumulative pitch deviation (B_ij = Φ(j+i−1) − Φ(j−1), the −Φ(j−1) goes into V); one α
    per shift AND direction, so that a hysteresis that depends on θ is not counted as scatter (it is
    the direction-difference term, :func:`direction_difference`); one offset V per run-row, so that
    the setup error of each clamping and a constant hysteresis are not counted either. What remains
    is the scatter of a reading about the model: the repeatability of ε. Forward and backward
    readings are NOT taken as repetitions of one value (with hysteresis they are not).

    Degrees of freedom: readings − Σ_blocks (run-rows + N − 1) − rank(Φ part), a block being one
    (shift, direction). With all N start faces at S = 0, one run per direction, and one start face at
    the other shifts, ν = 2·N² − 2·(N + N − 1) − (N − 1): for N = 24, 1035 — the (N − 1)(N − 2) of the
    N×N closure per direction, plus the information linking the two directions through the common Φ.
    Single-face shifts add no dof with one run (α absorbs the row), (runs − 1)(N − 1) with more.

    Computed by Frisch–Waugh: within each block, readings and the Φ design are centred per run-row
    and then per step (the projection off V and α for complete rows); Φ is then a small least
    squares problem. Run-rows with a missing reading are dropped (listed).
    """
    N = table.n_faces
    zs: list[np.ndarray] = []
    Ps: list[np.ndarray] = []
    n_obs = n_rows = n_par = 0
    dropped: list[tuple] = []
    for S in table.shifts_deg:
        S = float(S)
        runs = table.runs.get(S, {})
        for d in sorted({k[1] for k in runs}):
            rows_y, rows_j = [], []
            for key, t in runs.items():
                if key[1] != d:
                    continue
                for j0 in range(N):
                    y = t[j0]
                    if np.all(np.isnan(y)):
                        continue
                    if np.any(np.isnan(y)):
                        dropped.append((S, key[0], d, j0 + 1))
                        continue
                    rows_y.append(y)
                    rows_j.append(j0)
            if not rows_y:
                continue
            Y = np.asarray(rows_y)
            Yc = Y - Y.mean(axis=1, keepdims=True)
            Z = Yc - Yc.mean(axis=0, keepdims=True)
            i0 = np.arange(N)
            M = np.zeros((len(rows_j), N, N))
            for r, j0 in enumerate(rows_j):
                M[r, i0, (j0 + i0 + 1) % N] = 1.0
            Mc = M - M.mean(axis=1, keepdims=True)
            Mc = Mc - Mc.mean(axis=0, keepdims=True)
            zs.append(Z.ravel())
            Ps.append(Mc.reshape(-1, N))
            n_obs += Y.size
            n_rows += Y.shape[0]
            n_par += Y.shape[0] + N - 1
    if not zs:
        return Repeatability(float("nan"), 0, 0, 0, float("nan"), dropped)
    z = np.concatenate(zs)
    P = np.concatenate(Ps)
    phi, *_ = np.linalg.lstsq(P, z, rcond=None)
    rank = int(np.linalg.matrix_rank(P)) if P.size else 0
    res = z - P @ phi
    dof = int(n_obs - n_par - rank)
    rss = float(res @ res)
    s = math.sqrt(rss / dof) if dof > 0 else float("nan")
    return Repeatability(s, dof, n_obs, n_rows, rss, dropped)


def _direction_tables(table: PolygonTable, S: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per direction at shift S: (mean over its runs of Table 1, number of readings per cell)."""
    out = {}
    runs = table.runs.get(S, {})
    for d in sorted({k[1] for k in runs}):
        ts = np.stack([t for k, t in runs.items() if k[1] == d])
        cnt = np.sum(np.isfinite(ts), axis=0)
        with np.errstate(invalid="ignore"):
            mean = np.where(cnt > 0, np.nansum(ts, axis=0) / np.maximum(cnt, 1), np.nan)
        out[d] = (mean, cnt)
    return out


def direction_difference(table: PolygonTable, beta_arcsec: np.ndarray, s_reading_arcsec: float
                         ) -> dict[str, object] | None:
    """α(θ) of one direction minus the other's (forward − backward), with the β of the whole data.

    At every shift, α is computed per direction from that direction's readings (eqs. 3, 7; faces whose
    row is complete in that direction). ``u`` is the standard uncertainty of the difference from the
    reading repeatability alone (s/√n per cell; β is common and cancels), i.e. what the difference
    would scatter by without hysteresis. Returns ``theta_deg, value, u`` (sorted by θ; several shifts
    at one θ are kept separately), ``chi2`` = Σ(value/u)², its ``dof`` (points) and ``p_value`` (the
    test "no θ-dependent hysteresis"), ``rms``, ``rms_systematic`` = √max(0, mean(value²) − mean(u²))
    (the part of the difference that the repeatability does not explain), and ``offset_arcsec``: the
    mean difference of the setup errors U (forward − backward), a constant hysteresis, which eq. 7
    puts into U and which therefore does not bias α. None with fewer than two directions.
    """
    b = np.asarray(beta_arcsec, dtype=float)
    dirs = sorted({k[1] for S in table.shifts_deg for k in table.runs.get(float(S), {})})
    if len(dirs) < 2:
        return None
    d1, d2 = ("forward", "backward") if {"forward", "backward"} <= set(dirs) else (dirs[0], dirs[1])
    th, val, uu, offs = [], [], [], []
    for S in table.shifts_deg:
        S = float(S)
        per = _direction_tables(table, S)
        if d1 not in per or d2 not in per:
            continue
        got = {}
        for d in (d1, d2):
            mean, cnt = per[d]
            faces = np.flatnonzero(np.all(np.isfinite(mean), axis=1)) + 1
            if faces.size == 0:
                break
            r = encoder_error_arcsec(mean[faces - 1], faces, b, S,
                                     u_eps_arcsec=s_reading_arcsec / np.sqrt(cnt[faces - 1]))
            got[d] = (faces, r)
        if len(got) < 2:
            continue
        (f1, r1), (f2, r2) = got[d1], got[d2]
        th.append(r1["theta_deg"])
        val.append(r1["alpha"] - r2["alpha"])
        uu.append(np.sqrt(r1["u_alpha"] ** 2 + r2["u_alpha"] ** 2))
        common = np.intersect1d(f1, f2)
        offs += [float(r1["U"][np.searchsorted(f1, j)] - r2["U"][np.searchsorted(f2, j)]) for j in common]
    if not th:
        return None
    th_a, v, u = np.concatenate(th), np.concatenate(val), np.concatenate(uu)
    order = np.argsort(th_a, kind="stable")
    th_a, v, u = th_a[order], v[order], u[order]
    ok = u > 0
    chi2 = float(np.sum((v[ok] / u[ok]) ** 2))
    dof = int(np.count_nonzero(ok))
    from benchtwin.analysis.distributions import chi2_sf

    p = float(chi2_sf(chi2, dof)) if dof else float("nan")
    rms = float(np.sqrt(np.mean(v**2)))
    rms_sys = float(np.sqrt(max(0.0, float(np.mean(v**2) - np.mean(u**2)))))
    return {"directions": [d1, d2], "theta_deg": th_a, "value": v, "u": u, "chi2": chi2, "dof": dof, "p_value": p,
            "rms": rms, "rms_systematic": rms_sys, "max_abs": float(np.max(np.abs(v))),
            "offset_arcsec": float(np.mean(offs)) if offs else float("nan"), "n_offset_rows": len(offs)}


def alpha_scatter_by_rep(table: PolygonTable, beta_arcsec: np.ndarray) -> dict[str, object] | None:
    """Hsieh sec. 3.3 (1): the standard deviation over the repetitions of the whole method of α(θ),
    each repetition's α from its own readings (directions averaged) and the common β. Returns
    ``theta_deg``, ``sd`` (per θ, shifts kept separately), ``n_reps``, ``max_sd``, and (7) the sd over
    the repetitions of β from each one's full table (``beta_sd``, ``max_sd_beta``, ``n_reps_beta``; NaN
    without two full tables); None with < 2 reps."""
    b = np.asarray(beta_arcsec, dtype=float)
    reps = sorted({k[0] for S in table.shifts_deg for k in table.runs.get(float(S), {})})
    if len(reps) < 2:
        return None
    th_all, sd_all = [], []
    for S in table.shifts_deg:
        S = float(S)
        runs = table.runs.get(S, {})
        alphas = []
        faces_ref = None
        for rp in reps:
            ts = [t for k, t in runs.items() if k[0] == rp]
            if not ts:
                continue
            st_ = np.stack(ts)
            cnt = np.sum(np.isfinite(st_), axis=0)
            mean = np.where(cnt > 0, np.nansum(st_, axis=0) / np.maximum(cnt, 1), np.nan)
            faces = np.flatnonzero(np.all(np.isfinite(mean), axis=1)) + 1
            if faces.size == 0:
                continue
            faces_ref = faces if faces_ref is None else faces_ref
            alphas.append(encoder_error_arcsec(mean[faces - 1], faces, b, S)["alpha"])
        if len(alphas) >= 2:
            th_all.append(nominal_theta_deg(table.n_faces, S))
            sd_all.append(np.std(np.stack(alphas), axis=0, ddof=1))
    if not th_all:
        return None
    th, sd = np.concatenate(th_all), np.concatenate(sd_all)
    order = np.argsort(th, kind="stable")
    # sec. 3.3 (7): β of each repetition from its own full table, where it has one
    betas = []
    for S in table.shifts_deg:
        runs = table.runs.get(float(S), {})
        for rp in reps:
            ts = [t for k, t in runs.items() if k[0] == rp]
            if ts:
                m = np.mean(np.stack(ts), axis=0)
                if np.all(np.isfinite(m)):
                    betas.append(pitch_deviation_arcsec(m)[0])
        if len(betas) >= 2:
            break
        betas = []
    sd_b = np.std(np.stack(betas), axis=0, ddof=1) if len(betas) >= 2 else None
    return {"theta_deg": th[order], "sd": sd[order], "n_reps": len(reps), "max_sd": float(np.max(sd)),
            "beta_sd": sd_b, "max_sd_beta": float(np.max(sd_b)) if sd_b is not None else float("nan"),
            "n_reps_beta": len(betas)}


def combined_curve(result: ShiftAngleResult | Sequence[ShiftResult], *, decimals: int = 9
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The encoder error curve over all shifts, sorted by θ in [0, 360): ``(theta_deg, alpha, u_alpha)``.

    Points of different shifts at the same θ (e.g. S = 0 and S = 360/N) are averaged; their u is the
    root-mean-square u divided by √m (treated as independent, which ignores the common β).
    """
    shifts = result.shifts if isinstance(result, ShiftAngleResult) else list(result)
    th = np.concatenate([np.round(s.theta_deg, decimals) % 360.0 for s in shifts])
    a = np.concatenate([s.alpha_arcsec for s in shifts])
    u = np.concatenate([s.u_alpha_arcsec for s in shifts])
    uth, inv, cnt = np.unique(th, return_inverse=True, return_counts=True)
    am = np.bincount(inv, weights=a) / cnt
    um = np.sqrt(np.bincount(inv, weights=u**2) / cnt) / np.sqrt(cnt)
    return uth, am, um


# --------------------------------------------------------------------------- sec. 3.1 curve fits


def _harmonic_design(theta_deg: np.ndarray, harmonics: Sequence[int]) -> np.ndarray:
    """Columns [sin kθ, cos kθ] of the harmonics (θ in degrees): :func:`.fourier.harmonic_columns`."""
    return harmonic_columns(theta_deg, harmonics)[0]


def fit_harmonic_offset(theta_deg: np.ndarray, y_arcsec: np.ndarray, harmonics: Sequence[int] = (2,), *,
                        fixed_coef: np.ndarray | None = None) -> dict[str, Any]:
    """Least squares y(θ) = U + Σ_k (a_k sin kθ + b_k cos kθ) (sec. 3.1, generalised to K harmonics).

    With ``fixed_coef`` (the ``coef`` of an earlier fit, ``[a_k1, b_k1, a_k2, …]``) only U is fitted,
    as the paper does at S = 5° and 10°. Returns ``U``, ``coef``, ``harmonics``, ``residual`` and
    ``rms``. Raises ValueError if the design is rank deficient (e.g. a harmonic that is a multiple of
    the number of equally spaced points, indistinguishable from U).
    """
    y = np.asarray(y_arcsec, dtype=float).ravel()
    hs = [int(k) for k in harmonics]
    if any(k < 1 for k in hs):
        raise ValueError(f"harmonics must be >= 1, got {hs}")
    A = _harmonic_design(theta_deg, hs)
    if A.shape[0] != y.size:
        raise ValueError(f"theta_deg has {A.shape[0]} points, y_arcsec {y.size}")
    if fixed_coef is not None:
        c = np.asarray(fixed_coef, dtype=float).ravel()
        if c.size != A.shape[1]:
            raise ValueError(f"fixed_coef has {c.size} entries, expected {A.shape[1]}")
        U = float(np.mean(y - A @ c))
    else:
        M = np.column_stack([np.ones(y.size), A])
        if np.linalg.matrix_rank(M) < M.shape[1]:
            raise ValueError(f"harmonics {hs} with offset are not identifiable from {y.size} points "
                             f"(a harmonic aliases onto the offset or another harmonic)")
        sol, *_ = np.linalg.lstsq(M, y, rcond=None)
        U, c = float(sol[0]), sol[1:]
    res = y - U - A @ c
    return {"U": U, "coef": c, "harmonics": hs, "residual": res, "rms": float(np.sqrt(np.mean(res**2)))}


def fit_sine2_offset(theta_deg: np.ndarray, y_arcsec: np.ndarray, *, A_arcsec: float | None = None,
                     B_rad: float | None = None) -> dict[str, float]:
    """Sec. 3.1: y(θ) = A·sin(2θ + B) + U by least squares; with A and B given, only U is fitted.

    Returns ``A_arcsec``, ``B_rad`` (B in radians, as the paper's B = −2.4233), ``U_arcsec``, ``rms_arcsec``.
    """
    if (A_arcsec is None) != (B_rad is None):
        raise ValueError("give both A_arcsec and B_rad, or neither")
    fixed = None if A_arcsec is None or B_rad is None else np.array([A_arcsec * math.cos(B_rad),
                                                                     A_arcsec * math.sin(B_rad)])
    f = fit_harmonic_offset(theta_deg, y_arcsec, (2,), fixed_coef=fixed)
    a, b = f["coef"]
    return {"A_arcsec": float(math.hypot(a, b)), "B_rad": float(math.atan2(b, a)), "U_arcsec": f["U"],
            "rms_arcsec": f["rms"]}


def setup_error_by_curve_fit(result: ShiftAngleResult, harmonics: Sequence[int] = (2,), *,
                             reference_shift_deg: float | None = None) -> list[dict[str, Any]]:
    """Cross-check of U (sec. 3.1): fit U + harmonics to y_i = ε_ij − B_ij = α(θ_i) + U_j at the reference
    shift (start face = the first measured there), then at every shift and start face fit only U with the
    shape fixed (reference: the result's reference shift). Returns rows ``shift_deg, start_face, U_fit_arcsec, U_eq7_arcsec, diff_arcsec`` (+ the
    reference fit's ``A_arcsec, B_rad`` when ``harmonics == (2,)``).

    With N equally spaced steps and no harmonic a multiple of N, the fitted offset equals the mean,
    i.e. eq. 7 to rounding: the check verifies the computation, as in the paper (< 1e-4″).
    """
    tab = result.table
    N = result.n_faces
    B = cumulative_pitch_sum_arcsec(result.beta_arcsec)
    by_shift = {s.shift_deg: s for s in result.shifts}
    if reference_shift_deg is None:
        reference_shift_deg = result.reference_shift_deg if result.reference_shift_deg in by_shift \
            else result.shifts[0].shift_deg
    ref = _shift_key(reference_shift_deg)
    if ref not in by_shift:
        raise PolygonDataError(f"reference_shift_deg={reference_shift_deg:g}: no readings at that shift")
    sr = by_shift[ref]
    j0 = int(sr.start_faces[0])
    y0 = tab.eps_arcsec[ref][j0 - 1] - B[j0 - 1]
    f0 = fit_harmonic_offset(sr.theta_deg, y0, harmonics)
    extra = {}
    if tuple(harmonics) == (2,):
        a, b = f0["coef"]
        extra = {"A_arcsec": float(math.hypot(a, b)), "B_rad": float(math.atan2(b, a))}
    rows = []
    for s in result.shifts:
        for r, j in enumerate(s.start_faces):
            y = tab.eps_arcsec[s.shift_deg][j - 1] - B[j - 1]
            if s.shift_deg == ref and j == j0:
                U_fit = f0["U"]
            else:
                U_fit = fit_harmonic_offset(s.theta_deg, y, harmonics, fixed_coef=f0["coef"])["U"]
            rows.append({"shift_deg": s.shift_deg, "start_face": int(j), "U_fit_arcsec": U_fit,
                         "U_eq7_arcsec": float(s.U_arcsec[r]), "diff_arcsec": U_fit - float(s.U_arcsec[r]), **extra})
    del N
    return rows
