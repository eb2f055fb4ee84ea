"""The structure of a dataset's tables that the analysis assumes (issue 31): checked when a table is
read (``Dataset.table``: :func:`check_structure`) and, for the analysis' Fourier order, by the one
check ``validate`` and ``analyze`` both run first (``Dataset.check_tables``: :func:`check_order`), so
that they accept exactly the same datasets.

The cell-level checks (number grammar, ranges, duplicated keys) are in :mod:`.dataset`; these are
the checks across rows, each the assumption of an analysis step:

- every table has at least one row (a header-only table is an error, not a missing section);
- ``radial_motion.csv`` (Jia 2019 sec. 4.1, :mod:`.radial_motion`, :mod:`.iso230_7`): repetitions
  numbered without a gap and at most ``max(D_N)`` of them (the range method's d_n); every repetition
  reads the same angles of the turn (within a quarter of their closest spacing), each once (Jia
  sec. 5's range and ISO 230-7's asynchronous motion compare the revolutions angle by angle); for
  order K (:func:`check_order`) those angles cover the turn: no gap of 180°/K or more between
  neighbours (the maximal-gap condition under which a trigonometric polynomial of degree K is stably
  determined by its samples, Gröchenig, Math. Comp. 59 (1992) 181-194; it implies the 2K+1 angles
  of eq. 6). A table cut inside a revolution (issue 31: ``head -n 541`` gave a disk motion of
  327 388 µm) fails here; X probes come in pairs (eq. 9 needs both spheres);
- ``ccd/index.csv`` (Jia sec. 4.2), for order K: every sweep has the frames eq. 10 needs
  (:func:`benchtwin.analysis.pipeline.ccd_frame_limits`) and covers the turn like a repetition;
- ``polygon.csv`` (Hsieh 2022, :mod:`.shift_angle`): every run of a start face (shift, rep,
  direction, start face) reads all N steps (eq. 7 needs the whole turn); repetitions numbered without
  a gap, each repeating the design of the first; the reference shift's N×N table complete unless the
  manifest gives a certificate (eqs. 5-6, :func:`.shift_angle.require_reference_table`); then the
  analysis' own tabulation (:func:`.shift_angle.tabulate_polygon`);
- ``heads.csv`` (Hsieh sec. 2.3, :mod:`.selfcal`): at least 2 heads in the manifest, head 1 at 0°;
  every run (rep, direction) reads every head of the table at every angle, each once; the angles an
  equally spaced full-circle grid (eq. 9's Fourier solution); repetitions numbered without a gap,
  each with the same directions;
- ``error_curve.csv`` (:mod:`.error_curve`): at least 3 distinct angles, each once per direction. An
  arc is legitimate (an imported lab table may cover part of a turn): no coverage is required.

Each function raises :class:`.dataset.DatasetError` naming the file, the row or key and what was
expected. ``order`` is the Fourier order the analysis will use (``analyze --order``, default 10).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from benchtwin.analysis.dataset import DatasetError

__all__ = ["check_structure", "check_order", "turn_gap_limit_deg"]

_DECIMALS = 9  # angles are matched after rounding to 1e-9° (as the analysis does)


def turn_gap_limit_deg(order: int) -> float:
    """The largest gap between neighbouring angles (exclusive) for a Fourier series of ``order``."""
    return 180.0 / max(int(order), 1)


def check_structure(name: str, cols: Mapping[str, np.ndarray], where: str, bench: Mapping[str, Any]) -> None:
    """The structural checks of table ``name`` that hold whatever the order (see the module
    docstring); run on every read of a table (``Dataset.table``)."""
    n = len(next(iter(cols.values()))) if cols else 0
    if n == 0:
        raise DatasetError(f"{where}: a header and no rows (expected at least one reading; delete the file if "
                           "this measurement was not made)")
    if name == "radial_motion":
        _radial(cols, where)
    elif name == "polygon":
        _polygon(cols, where, bench)
    elif name == "heads":
        _heads(cols, where, bench)
    elif name == "error_curve":
        _error_curve(cols, where)


def check_order(name: str, cols: Mapping[str, np.ndarray], where: str, order: int) -> None:
    """What the analysis at Fourier ``order`` needs of table ``name`` (already read and checked by
    :func:`check_structure`): a revolution's angles and each CCD sweep's frames cover the turn, and
    a sweep has the frames eq. 10 needs. Run by ``Dataset.check_tables`` (validate and analyze);
    a reader that only compares tables (the emulators' tests) does not need it."""
    if name == "radial_motion":
        rep = np.asarray(cols["rep"], dtype=np.int64)
        grid = np.unique(_turn(cols["theta_deg"])[rep == rep.min()])
        _covers_turn(grid, where, "each repetition's", order)
        if grid.size < 4:   # at order 1 three angles cover the turn
            raise DatasetError(f"{where}: each repetition reads {grid.size} angles; ISO 230-7's least-squares "
                               "circle (the fundamental's 3 parameters) needs at least 4")
    elif name == "ccd/index":
        _ccd_index(cols, where, order)


def _turn(theta_deg: np.ndarray) -> np.ndarray:
    """Angles as positions on the turn: mod 360, rounded (0° and 360° are the same position)."""
    a = np.round(np.mod(np.asarray(theta_deg, dtype=float), 360.0), _DECIMALS)
    return np.where(a >= 360.0, 0.0, a)


def _reps_consecutive(rep: np.ndarray, where: str, what: str = "repetitions") -> np.ndarray:
    reps = np.unique(np.asarray(rep, dtype=np.int64))
    expect = np.arange(reps[0], reps[0] + reps.size)
    if not np.array_equal(reps, expect):
        gap = int(expect[np.flatnonzero(reps != expect)[0]])
        raise DatasetError(f"{where}: column 'rep': rep {gap} is missing between {int(reps[0])} and {int(reps[-1])} "
                           f"(expected {what} numbered without a gap: a deleted or lost repetition?)")
    return reps


def _once_per_group(keys: list[np.ndarray], where: str, what: str) -> None:
    """No two rows with the same key (several columns, already mapped to positions on the turn)."""
    arr = np.rec.fromarrays(keys) if len(keys) > 1 else keys[0]
    order = np.argsort(arr, kind="stable")
    s = arr[order]
    same = np.flatnonzero(s[1:] == s[:-1])
    if same.size:
        a, b = sorted((int(order[same[0]]), int(order[same[0] + 1])))
        raise DatasetError(f"{where}: rows {a + 2} and {b + 2}: {what} read twice (0° and 360° are the same "
                           "position of the turn)")


def _covers_turn(grid: np.ndarray, where: str, what: str, order: int) -> None:
    """The angles ``grid`` (sorted, distinct, on the turn) leave no gap of 180°/order or more."""
    g = np.sort(grid)
    gaps = np.diff(np.concatenate([g, g[:1] + 360.0]))
    i = int(np.argmax(gaps))
    limit = turn_gap_limit_deg(order)
    if gaps[i] >= limit:
        nxt = g[(i + 1) % g.size]
        raise DatasetError(
            f"{where}: {what} {g.size} angle{'s' if g.size != 1 else ''} leave a gap of {gaps[i]:g}° "
            f"(theta_deg {g[i]:g} → {nxt:g}); a Fourier series of order {order} (analyze --order) needs every "
            f"gap below 180°/{order} = {limit:g}°: expected a whole turn (a table cut short?)")


def _radial(cols: Mapping[str, np.ndarray], where: str) -> None:
    from benchtwin.analysis.radial_motion import D_N

    if ("probe_top_x_um" in cols) != ("probe_bottom_x_um" in cols):
        have = "probe_top_x_um" if "probe_top_x_um" in cols else "probe_bottom_x_um"
        raise DatasetError(f"{where}: row 1: column {have!r} without its pair (expected both probe_top_x_um and "
                           "probe_bottom_x_um: eq. 9 combines the two spheres)")
    rep = np.asarray(cols["rep"], dtype=np.int64)
    reps = _reps_consecutive(rep, where)
    if reps.size > max(D_N):
        raise DatasetError(f"{where}: column 'rep': {reps.size} repetitions; at most {max(D_N)} (the range method's "
                           "d_n is tabulated for n ≤ 25, Jia sec. 5)")
    turn = _turn(cols["theta_deg"])
    _once_per_group([rep, turn], where, "a repetition's angle")
    first = rep == reps[0]
    grid = np.unique(turn[first])
    # an angle of the grid is matched within a quarter of the grid's closest spacing: with `acquire`'s
    # [run] theta = "encoder", theta_deg is the encoder's display, one count (0.39″) apart between
    # revolutions at the same stop (as polygon.csv's theta_deg may be a quarter pitch off its step)
    spacing = np.diff(np.concatenate([grid, grid[:1] + 360.0])).min() if grid.size > 1 else 360.0
    tol = 0.25 * float(spacing)
    for r in reps[1:]:
        m = rep == r
        got = np.unique(turn[m])
        k, d = _nearest(grid, got)
        ok = d <= tol
        if got.size == grid.size and bool(ok.all()) and np.unique(k).size == grid.size:
            continue
        missing = np.delete(grid, np.unique(k[ok]))
        extra = got[~ok]
        rows = np.flatnonzero(m)
        desc = (f"missing theta_deg {_list(missing)}" if missing.size else "") + \
               ("; " if missing.size and extra.size else "") + \
               (f"theta_deg {_list(extra)} not read in rep {int(reps[0])}" if extra.size else "")
        raise DatasetError(
            f"{where}: rows {rows[0] + 2}…{rows[-1] + 2}: rep {int(r)} reads {got.size} angles, rep {int(reps[0])} "
            f"{grid.size}: {desc} (expected every repetition at the same angles of the turn: Jia sec. 5's range "
            "and ISO 230-7 compare the revolutions angle by angle)")


def _nearest(grid: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each angle of ``a``: the index of the nearest angle of the sorted ``grid`` on the circle,
    and the distance (°)."""
    n = grid.size
    j = np.searchsorted(grid, a) % n
    i = (j - 1) % n
    dj = np.abs((a - grid[j] + 180.0) % 360.0 - 180.0)
    di = np.abs((a - grid[i] + 180.0) % 360.0 - 180.0)
    return np.where(dj <= di, j, i), np.minimum(dj, di)


def _ccd_index(cols: Mapping[str, np.ndarray], where: str, order: int) -> None:
    from benchtwin.analysis.pipeline import ccd_frame_limits

    n = len(cols["k"])
    sweeps = np.asarray(cols["sweep"], dtype=np.int64) if "sweep" in cols else np.zeros(n, dtype=np.int64)
    turn = _turn(cols["theta_deg"])
    for sw in np.unique(sweeps):
        m = sweeps == sw
        name = f"sweep {int(sw)}'s" if "sweep" in cols else "the sweep's"
        need = ccd_frame_limits(int(m.sum()), order)["by_fit"]
        if int(m.sum()) < need:
            raise DatasetError(f"{where}: {name} {int(m.sum())} frames; the eccentricity fit (Jia eq. 10) at order "
                               f"{order} needs at least {need} (2·order + 1 coefficients + 3 residual dof)")
        _covers_turn(np.unique(turn[m]), where, name, order)


def _list(a: np.ndarray, n: int = 5) -> str:
    s = ", ".join(f"{float(x):g}" for x in a[:n])
    return s + (f", … ({a.size - n} more)" if a.size > n else "")


def _codes(values: np.ndarray) -> np.ndarray:
    return np.unique(np.asarray(values), return_inverse=True)[1].ravel().astype(np.int64)


def _polygon(cols: Mapping[str, np.ndarray], where: str, bench: Mapping[str, Any]) -> None:
    from benchtwin.analysis import shift_angle as sa

    N = int(bench["polygon_faces"])
    n = len(cols["shift_deg"])
    shift = np.round(np.asarray(cols["shift_deg"], dtype=float), _DECIMALS) + 0.0
    face = np.asarray(cols["start_face"], dtype=np.int64)
    step = np.asarray(cols["step"], dtype=np.int64)
    rep = np.asarray(cols["rep"], dtype=np.int64) if "rep" in cols else np.zeros(n, dtype=np.int64)
    dirn = np.asarray(cols["direction"]).astype(str) if "direction" in cols else np.full(n, "forward")
    reps = _reps_consecutive(rep, where) if "rep" in cols else np.zeros(1, dtype=np.int64)
    # a run of a start face: (shift, rep, direction, start face) reads steps 1…N (eq. 7)
    run = np.column_stack([_codes(shift), rep - reps[0], _codes(dirn), face])
    uniq, inv, cnt = np.unique(run, axis=0, return_inverse=True, return_counts=True)
    short = np.flatnonzero(cnt != N)
    if short.size:
        rows = np.flatnonzero(inv.ravel() == short[0])
        have = np.unique(step[rows])
        missing = np.setdiff1d(np.arange(1, N + 1), have)
        r0 = int(rows[0])
        key = f"shift_deg={shift[r0]:g}, start_face={int(face[r0])}" + \
              (f", rep={int(rep[r0])}" if "rep" in cols else "") + \
              (f", direction={dirn[r0]}" if "direction" in cols else "")
        what = (f"steps {_list(missing.astype(float))} missing" if missing.size
                else f"{int(cnt[short[0]])} readings of {N} steps")
        raise DatasetError(f"{where}: rows {rows[0] + 2}…{rows[-1] + 2} ({key}): {what}; expected steps 1…{N} "
                           "(a start face is read over the whole turn, Hsieh eq. 7; a table cut short?)")
    # every repetition repeats the design of the first: the same (shift, direction, start face) runs
    if reps.size > 1:
        design = np.column_stack([run[:, 0], run[:, 2], run[:, 3]])
        base = {tuple(x) for x in design[rep == reps[0]].tolist()}
        for r in reps[1:]:
            m = rep == r
            got = {tuple(x) for x in design[m].tolist()}
            if got != base:
                diff = sorted(base - got) or sorted(got - base)
                i = int(np.flatnonzero((design == np.asarray(diff[0])).all(axis=1))[0])
                rows = np.flatnonzero(m)
                miss = "missing" if base - got else "not in rep " + str(int(reps[0]))
                raise DatasetError(
                    f"{where}: rows {rows[0] + 2}…{rows[-1] + 2}: rep {int(r)}: the run shift_deg={shift[i]:g}, "
                    f"start_face={int(face[i])}" + (f", direction={dirn[i]}" if "direction" in cols else "")
                    + f" is {miss} (expected every repetition to repeat the design of rep {int(reps[0])})")
    # the analysis' own tabulation and its reference table (eqs. 5-6), named by file row
    cert = bench.get("polygon_certificate_arcsec")
    try:
        table = sa.tabulate_polygon(cols, N)
        sa.require_reference_table(table, certificate=cert is not None)
    except sa.PolygonDataError as exc:
        raise DatasetError(f"{where}: {exc} (array index i is file row i + 2)") from None


def _heads(cols: Mapping[str, np.ndarray], where: str, bench: Mapping[str, Any]) -> None:
    from benchtwin.analysis.selfcal import _check_grid

    heads_deg = list(bench.get("heads_deg", []))
    if len(heads_deg) < 2 or heads_deg[0] != 0.0:
        raise DatasetError(f"{where}: the manifest's bench.heads_deg = {heads_deg}; the self-calibration (Hsieh "
                           "eq. 9) needs at least 2 heads, head 1 at 0° (azimuths from head 1)")
    n = len(cols["head"])
    head = np.asarray(cols["head"], dtype=np.int64)
    rep = np.asarray(cols["rep"], dtype=np.int64) if "rep" in cols else np.zeros(n, dtype=np.int64)
    dirn = np.asarray(cols["direction"]).astype(str) if "direction" in cols else np.full(n, "forward")
    turn = _turn(cols["theta_deg"])
    _once_per_group([turn, head, rep, dirn], where, "a head's angle of one run (rep, direction)")
    if "rep" in cols:
        reps = _reps_consecutive(rep, where)
        base = set(dirn[rep == reps[0]].tolist())
        for r in reps[1:]:
            got = set(dirn[rep == r].tolist())
            if got != base:
                raise DatasetError(f"{where}: rep {int(r)} reads directions {sorted(got)}, rep {int(reps[0])} "
                                   f"{sorted(base)} (expected every repetition in the same directions)")
    grid = np.unique(turn)
    present = np.unique(head)
    full = grid.size * present.size
    run = np.column_stack([rep, _codes(dirn)])
    uniq, inv, cnt = np.unique(run, axis=0, return_inverse=True, return_counts=True)
    short = np.flatnonzero(cnt != full)
    if short.size:
        rows = np.flatnonzero(inv.ravel() == short[0])
        have = set(zip(turn[rows].tolist(), head[rows].tolist()))
        miss = next((float(t), int(h)) for t in grid for h in present if (float(t), int(h)) not in have)
        r0 = int(rows[0])
        key = ", ".join(([f"rep={int(rep[r0])}"] if "rep" in cols else [])
                        + ([f"direction={dirn[r0]}"] if "direction" in cols else []))
        raise DatasetError(
            f"{where}: rows {rows[0] + 2}…{rows[-1] + 2}{' (' + key + ')' if key else ''}: no reading of head "
            f"{miss[1]} at theta_deg {miss[0]:g}; expected every head of the table ({_list(present.astype(float))}) "
            f"at each of the {grid.size} angles (a table cut short?)")
    try:
        _check_grid(grid)
    except ValueError:
        d = np.diff(np.concatenate([grid, grid[:1] + 360.0]))
        raise DatasetError(
            f"{where}: column 'theta_deg': {grid.size} angles, spaced {float(d.min()):g}°…{float(d.max()):g}°; the "
            "self-calibration (Hsieh eq. 9) needs an equally spaced full-circle grid") from None


def _error_curve(cols: Mapping[str, np.ndarray], where: str) -> None:
    n = len(cols["theta_deg"])
    turn = _turn(cols["theta_deg"])
    dirn = np.asarray(cols["direction"]).astype(str) if "direction" in cols else np.full(n, "forward")
    _once_per_group([turn, dirn], where, "an angle of one direction")
    k = np.unique(turn).size
    if k < 3:
        raise DatasetError(f"{where}: {k} distinct angle{'s' if k != 1 else ''}; an error curve needs at least 3")
