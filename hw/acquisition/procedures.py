"""Measurement procedures as generators of steps (bluesky-plan style).

A procedure never talks to an instrument and never sleeps: it yields steps, and a runner
(``hw.acquisition.runner``) executes them against real instruments (wall clock) or the twin
(simulated clock). A dry run (``list(procedure)``) lists the steps, and ``estimate_duration``
prices them, without any instrument.

Step types
----------
- ``Move(target_deg)``: command the stage to an ENCODER reading (head 1), in degrees. The bench
  stops at commanded encoder readings; the approach direction is the run's direction (context).
- ``Read(instrument, tag)``: read one instrument, or several at the same stop (a tuple of names:
  one row holding every reading, e.g. encoder + autocollimator).
- ``Capture(camera, tag)``: one camera frame.
- ``Wait(seconds)``: settle / dwell (the runner's clock advances; hardware waits).
- ``Mark(label, context)``: a boundary of the run; ``context`` (rep, direction, polygon start face,
  shift, procedure) is merged into the tag of every later row until the next Mark replaces keys.
  A context key ``polygon_start_face`` means the polygon is re-clamped (operator action on the
  bench; the twin re-mounts its polygon with a new setup error).

The procedure language
----------------------
One language names a bench's procedures, whoever runs them: a list of *procedure specs*, plain
dicts ``{"type": <one of PROCEDURE_TYPES>, <parameter>: <value>, ...}`` with angles in degrees and
times in seconds, the parameters of the generator of that type (``PROCEDURE_PARAMS``). The bench
file's ``[[procedure]]`` tables are this language written in TOML (``hw/acquisition/bench.py``
parses and writes them); the twin turns a scenario's ``[procedure]`` into it
(``twin.simulate.scenario_procedures``); ``steps_from_specs`` is the one place where specs become
steps, for ``simulate``, ``emulate`` (its operator and its bench file) and ``acquire`` alike.

Polygon numbering (Hsieh 2022 eq. 3): with start face j at step i (1…N) the autocollimator sees
face j+i−1 (mod N), the encoder stands at (i−1)·360°/N + S. Start face j is set at S: the
polygon is clamped so that face j faces the autocollimator when the encoder reads S.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from benchtwin.schema import toml_value

__all__ = [
    "Move", "Read", "Capture", "Wait", "Mark", "Step",
    "radial_motion_run", "ccd_sweep", "PolygonSetup", "polygon_traditional", "polygon_shift_angle", "selfcal_sweep",
    "count_steps", "estimate_duration", "describe_step",
    "PROCEDURE_TYPES", "PROCEDURE_PARAMS", "steps_from_specs", "specs_toml",
]


@dataclass(frozen=True)
class Move:
    target_deg: float


@dataclass(frozen=True)
class Read:
    instrument: str | tuple[str, ...]
    tag: dict = field(default_factory=dict)

    @property
    def names(self) -> tuple[str, ...]:
        return (self.instrument,) if isinstance(self.instrument, str) else tuple(self.instrument)


@dataclass(frozen=True)
class Capture:
    camera: str
    tag: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Wait:
    seconds: float


@dataclass(frozen=True)
class Mark:
    label: str
    context: dict = field(default_factory=dict)


Step = Move | Read | Capture | Wait | Mark


def describe_step(step: Step) -> dict[str, Any]:
    """A JSON-ready description of a step (journal lines, dry runs, resume checks)."""
    if isinstance(step, Move):
        return {"type": "move", "target_deg": float(step.target_deg)}
    if isinstance(step, Read):
        return {"type": "read", "instrument": list(step.names), "tag": dict(step.tag)}
    if isinstance(step, Capture):
        return {"type": "capture", "camera": step.camera, "tag": dict(step.tag)}
    if isinstance(step, Wait):
        return {"type": "wait", "seconds": float(step.seconds)}
    if isinstance(step, Mark):
        return {"type": "mark", "label": step.label, "context": dict(step.context)}
    raise TypeError(f"not a procedure step: {step!r}")


# --------------------------------------------------------------------------- procedures

def _dir_name(direction: str | int) -> str:
    if direction in ("forward", +1, 1):
        return "forward"
    if direction in ("backward", -1):
        return "backward"
    raise ValueError(f"direction must be 'forward' or 'backward', got {direction!r}")


def radial_motion_run(reps: int = 3, positions: int = 360, dwell_s: float = 0.5,
                      probes: Sequence[str] = ("probe_top", "probe_bottom"),
                      encoder: str = "encoder", rep0: int = 0) -> Iterator[Step]:
    """Jia 2019 sec. 4.1: ``reps`` revolutions, ``positions`` stops per revolution (every
    360/positions degrees, forward); at each stop the encoder and both (or four) probes are read
    together. Rows carry ``rep`` and ``k`` (stop index)."""
    if reps < 1 or positions < 1:
        raise ValueError("reps and positions must be >= 1")
    for r in range(rep0, rep0 + reps):
        yield Mark(f"radial_motion rep {r}", {"procedure": "radial_motion", "rep": r, "direction": "forward"})
        for k in range(positions):
            th = 360.0 * k / positions
            yield Move(th)
            yield Wait(dwell_s)
            yield Read((encoder, *probes), {"k": k, "target_deg": th})


def ccd_sweep(step_deg: float = 6.0, dwell_s: float = 0.5, camera: str = "ccd", encoder: str = "encoder",
              rep: int = 0, reps: int = 1) -> Iterator[Step]:
    """Jia 2019 sec. 4.2: one image every ``step_deg`` over a revolution (60 images at 6°).

    ``reps`` > 1: the sweep repeated (Jia sec. 5 gives the range of e over repeated sweeps): the
    shaft returns to 0° between sweeps; frames are numbered on (``k`` = sweep·n + j, unique in the
    dataset) and their tags carry ``sweep`` (0…reps−1), which ``ccd/index.csv`` keeps. One sweep
    (the default) has no ``sweep`` tag: its rows are those of the single-sweep format."""
    n = int(round(360.0 / step_deg))
    if n < 1 or abs(n * step_deg - 360.0) > 1e-9:
        raise ValueError(f"ccd step {step_deg}° must divide 360°")
    if reps < 1:
        raise ValueError(f"ccd sweep reps must be >= 1, got {reps}")
    for s in range(reps):
        yield Mark("ccd sweep", {"procedure": "ccd", "rep": rep + s, "direction": "forward"})
        for j in range(n):
            th = j * step_deg
            k = s * n + j
            tag: dict[str, Any] = {"k": k, "target_deg": th}
            if reps > 1:
                tag["sweep"] = s
            yield Move(th)
            yield Wait(dwell_s)
            yield Read(encoder, dict(tag))
            yield Capture(camera, tag)


@dataclass(frozen=True)
class PolygonSetup:
    """What both polygon procedures share: the polygon (``faces``: N), the directions of each sweep
    (``"forward"``: i = 1…N; ``"backward"``: i = N…1, same mounting), the dwell at each face (s) and
    the instruments read at each stop (an encoder and the autocollimator)."""

    faces: int
    directions: tuple[str, ...] = ("forward",)
    dwell_s: float = 0.5
    encoder: str = "encoder"
    autocollimator: str = "autocollimator"


def polygon_traditional(polygon: PolygonSetup, start_face: int = 1, shift_deg: float = 0.0,
                        rep: int = 0) -> Iterator[Step]:
    """Cross-calibration with polygon and autocollimator (Hsieh 2022 sec. 2.1): clamp the polygon
    with ``start_face`` at the encoder angle S (a Mark: operator action), then read at
    θ_i = (i−1)·360/N + S, i = 1…N, in each direction (backward: i = N…1, same mounting)."""
    N = polygon.faces
    if N < 3:
        raise ValueError("a polygon has at least 3 faces")
    if not 1 <= start_face <= N:
        raise ValueError(f"start_face must be in 1…{N}")
    yield Mark(f"polygon clamp: face {start_face} at S={shift_deg:g}°, rep {rep}",
               {"procedure": "polygon", "polygon_start_face": int(start_face), "shift_deg": float(shift_deg),
                "rep": int(rep)})
    for d in polygon.directions:
        d = _dir_name(d)
        yield Mark(f"polygon {d}", {"direction": d})
        steps = range(1, N + 1) if d == "forward" else range(N, 0, -1)
        for i in steps:
            th = (i - 1) * 360.0 / N + shift_deg
            yield Move(th)
            yield Wait(polygon.dwell_s)
            yield Read((polygon.encoder, polygon.autocollimator),
                       {"shift_deg": float(shift_deg), "start_face": int(start_face), "step": int(i), "target_deg": th})


def polygon_shift_angle(polygon: PolygonSetup, shifts_deg: Sequence[float] = (0.0,), reps: int = 1,
                        all_faces_each_shift: bool = False) -> Iterator[Step]:
    """Hsieh 2022 shift-angle method: at the first shift (the reference, normally S = 0) every face
    is the start face once (N·N readings per direction: 576 for N = 24), which gives the pitch
    deviations β and U_1 (eqs. 4–7); at every further shift S start face 1 is clamped at S and
    swept (N readings), as in Hsieh sec. 3 (``all_faces_each_shift`` repeats all N start faces)."""
    shifts = list(shifts_deg)
    if not shifts:
        raise ValueError("at least one shift angle")
    for rep in range(reps):
        for si, s in enumerate(shifts):
            faces = range(1, polygon.faces + 1) if (si == 0 or all_faces_each_shift) else (1,)
            for j in faces:
                yield from polygon_traditional(polygon, j, s, rep)


def selfcal_sweep(heads: Sequence[float], step_deg: float = 1.0, directions: Sequence[str] = ("forward", "backward"),
                  dwell_s: float = 0.5, encoder: str = "encoder", rep: int = 0) -> Iterator[Step]:
    """Multi-head self-calibration sweep (Hsieh 2022 sec. 2.3, eq. 8): read every head at
    θ = k·step over a revolution, in each direction. ``heads`` (deg from head 1) is recorded in the
    context (the encoder reads all its heads at once)."""
    n = int(round(360.0 / step_deg))
    if n < 1 or abs(n * step_deg - 360.0) > 1e-9:
        raise ValueError(f"self-calibration step {step_deg}° must divide 360°")
    for d in directions:
        d = _dir_name(d)
        yield Mark(f"selfcal {d}", {"procedure": "selfcal", "direction": d, "rep": rep,
                                    "heads_deg": [float(h) for h in heads]})
        ks = range(n) if d == "forward" else range(n - 1, -1, -1)
        for k in ks:
            th = k * step_deg
            yield Move(th)
            yield Wait(dwell_s)
            yield Read(encoder, {"k": k, "target_deg": th})


# --------------------------------------------------------------------------- dry run helpers

# --------------------------------------------------------------------------- the procedure language

PROCEDURE_TYPES = ("radial_motion", "ccd_sweep", "polygon_shift_angle", "polygon_traditional", "selfcal")

# type -> parameter -> kind: int, bool, str (an instrument name), list (of strings), "angle" (deg),
# "angles" (list of deg), "time" (s). The bench file's schema is this table (hw/acquisition/bench.py).
PROCEDURE_PARAMS: dict[str, dict[str, Any]] = {
    "radial_motion": {"reps": int, "positions": int, "dwell": "time", "probes": list, "encoder": str},
    "polygon_shift_angle": {"faces": int, "shifts": "angles", "reps": int, "directions": list, "dwell": "time",
                            "all_faces_each_shift": bool, "encoder": str, "autocollimator": str},
    "polygon_traditional": {"faces": int, "start_face": int, "shift": "angle", "rep": int, "directions": list,
                            "dwell": "time", "encoder": str, "autocollimator": str},
    "selfcal": {"step": "angle", "directions": list, "dwell": "time", "encoder": str, "heads": "angles"},
    "ccd_sweep": {"step": "angle", "dwell": "time", "encoder": str, "camera": str, "reps": int},
}


def steps_from_specs(specs: Iterable[Mapping[str, Any]]) -> Iterator[Step]:
    """The steps of every procedure spec, in order, generated lazily (flat memory). Defaults of
    absent parameters are the generators' (dwell 0.5 s, instrument names "encoder", "ccd",
    "autocollimator", "probe_top"/"probe_bottom"); ``polygon_*`` need ``faces``, ``selfcal``
    needs ``heads``."""
    for p in specs:
        typ = p["type"]
        dwell = p.get("dwell", 0.5)
        enc = p.get("encoder", "encoder")
        dirs = p.get("directions", ["forward"])
        if typ == "radial_motion":
            yield from radial_motion_run(p.get("reps", 3), p.get("positions", 360), dwell,
                                         p.get("probes", ["probe_top", "probe_bottom"]), enc)
        elif typ in ("polygon_shift_angle", "polygon_traditional"):
            polygon = PolygonSetup(p["faces"], tuple(dirs), dwell, enc, p.get("autocollimator", "autocollimator"))
            if typ == "polygon_shift_angle":
                yield from polygon_shift_angle(polygon, p.get("shifts", [0.0]), p.get("reps", 1),
                                               p.get("all_faces_each_shift", False))
            else:
                yield from polygon_traditional(polygon, p.get("start_face", 1), p.get("shift", 0.0), p.get("rep", 0))
        elif typ == "ccd_sweep":
            yield from ccd_sweep(p.get("step", 6.0), dwell, p.get("camera", "ccd"), enc, reps=p.get("reps", 1))
        elif typ == "selfcal":
            yield from selfcal_sweep(p["heads"], p.get("step", 1.0), p.get("directions", ["forward", "backward"]),
                                     dwell, enc)
        else:
            raise ValueError(f"unknown procedure type {typ!r}; expected one of {', '.join(PROCEDURE_TYPES)}")


_UNITS = {"angle": "deg", "angles": "deg", "time": "s"}   # the parameter kinds written as quantities


def _toml_value(v: Any, kind: Any) -> str:
    return toml_value(kind(v) if kind in (bool, int) else v, _UNITS.get(kind))  # the one TOML writer


def specs_toml(specs: Sequence[Mapping[str, Any]], omit: Sequence[str] = ()) -> list[str]:
    """Procedure specs as the bench file's ``[[procedure]]`` tables (lines; what
    ``hw.acquisition.bench`` parses back into the same specs). ``omit``: parameters left to the bench file's defaults
    (``faces``, ``heads`` come from ``[geometry]``)."""
    lines: list[str] = []
    for p in specs:
        kinds = PROCEDURE_PARAMS[p["type"]]
        lines += ["[[procedure]]", f'type = "{p["type"]}"']
        lines += [f"{k} = {_toml_value(v, kinds[k])}" for k, v in p.items() if k != "type" and k not in omit]
        lines.append("")
    return lines


def count_steps(procedure: Iterable[Step]) -> dict[str, int]:
    """Numbers of steps of each type (``readings`` = Read + Capture rows)."""
    out = {"move": 0, "read": 0, "capture": 0, "wait": 0, "mark": 0}
    for s in procedure:
        out[describe_step(s)["type"]] += 1
    out["readings"] = out["read"] + out["capture"]
    return out


def estimate_duration(procedure: Iterable[Step], speed_deg_s: float = 20.0, accel_deg_s2: float = 40.0,
                      settle_s: float = 0.0, read_s: float = 0.0, capture_s: float = 0.0,
                      start_deg: float = 0.0) -> float:
    """Duration in seconds of a procedure (trapezoidal moves at ``speed``/``accel``, plus waits,
    plus fixed times per reading), from its steps alone: no instrument needed."""
    t, pos = 0.0, start_deg
    for s in procedure:
        if isinstance(s, Move):
            t += move_time_s(abs(s.target_deg - pos), speed_deg_s, accel_deg_s2) + settle_s
            pos = s.target_deg
        elif isinstance(s, Wait):
            t += s.seconds
        elif isinstance(s, Read):
            t += read_s
        elif isinstance(s, Capture):
            t += capture_s
    return t


def move_time_s(distance_deg: float, speed_deg_s: float, accel_deg_s2: float) -> float:
    """Time of a trapezoidal (or triangular, for short moves) velocity profile."""
    d = abs(float(distance_deg))
    if d == 0.0:
        return 0.0
    if accel_deg_s2 <= 0:
        return d / speed_deg_s
    d_acc = speed_deg_s**2 / accel_deg_s2  # accelerate + decelerate distance
    if d >= d_acc:
        return d / speed_deg_s + speed_deg_s / accel_deg_s2
    return 2.0 * (d / accel_deg_s2) ** 0.5
