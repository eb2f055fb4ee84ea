"""The twin behind the emulated instruments: one ``SimBenchState`` shared by every wire protocol,
plus an emulated operator that follows the scenario's procedure.

Why an operator: the wire protocols carry moves and readings only, but the twin also needs the
run context that a real bench gets from people and from the procedure: which revolution (rep) it
is, the approach direction, and above all the polygon re-clamping (start face j at shift S, an
operator action at a ``Mark``). ``EmulatedBench`` therefore holds the scenario's step list
(``sim_procedure(sc)``, the same list ``simulate`` runs) and a cursor in it. Each stage move
that arrives over the wire is matched to the script:

1. the next served ``Move`` of the script has this target: fast-forward to it, executing every
   step in between exactly as ``simulate`` does (Marks apply the context, Waits advance the
   simulated clock, skipped Moves such as the CCD sweep, which has no serial instrument, move the
   simulated stage), so the simulated clock, the context and the step index are those of the
   direct simulation;
2. else the nearest earlier served ``Move`` with this target (a re-issued move: a retried
   ``move abs`` after a lost reply, or a resumed acquisition that stands the bench where its
   journal stopped): jump back to it and restore its context and clock;
3. else any later served ``Move`` with this target (the acquisition skips part of the script);
4. else a free move (no script step: the current context is kept).

A reading request moves the cursor to the next ``Read`` of that instrument before the next
``Move`` (applying the Waits in between). With a camera (``camera_backend``), the CCD sweep's
moves are served too, and an encoder reading at a stop whose next step is a ``Capture`` renders
that frame (keyed by the Capture's step index, as ``simulate`` does) and hands it to ``on_frame``
(the hot-folder camera emulator, ``camera.py``) before the reading is returned. The twin's noise streams are keyed by (seed, stream,
instrument, step index, draw); the draw counter is reset before every reading, so a retried
request at the same stop returns the same value (the display holds its value at a stop) and a
resumed or faulted acquisition reads exactly what the direct simulation of the same scenario and
seed reads.

Limitation (documented in docs/bench-file.md): one emulator session serves one acquisition and its
resumptions; a fresh acquisition from step 0 needs a fresh emulator (a restarted session).
"""

from __future__ import annotations

import math
from array import array
from collections import Counter, deque
from typing import Any

from benchtwin.hw.acquisition import procedures as P

__all__ = ["EmulatedBench"]

EVENTS_KEPT = 1000
SERVED_SKIP_PROCEDURES = ("ccd",)  # no serial instrument serves the camera: those steps are only replayed


class EmulatedBench:
    """The simulated bench of a scenario plus the emulated operator (see the module docstring).

    ``instruments`` are the twin's (``sim_build(sc, camera=False)``); ``script`` the scenario's
    steps. ``microsteps_per_deg`` says how close a wire target must be to a script target to be
    the same stop (half a microstep)."""

    def __init__(self, sc: Any, microsteps_per_deg: float = 1000.0, script: list | None = None,
                 camera_backend: str | None = None):
        from benchtwin.twin.simulate import sim_build, sim_procedure

        self.sc = sc
        self.bench, self.state, self.instruments = sim_build(sc, backend=camera_backend or "auto",
                                                             camera=camera_backend is not None)
        self.stage = self.instruments["stage"]
        self.camera = self.instruments.get("ccd")
        self.on_frame: Any = None   # on_frame(image, capture step index): the camera emulator saves it
        self.script = list(sim_procedure(sc) if script is None else script)
        self.microsteps_per_deg = float(microsteps_per_deg)
        self.ctx_at: list[dict] = []
        ctx: dict[str, Any] = {}
        for step in self.script:
            if isinstance(step, P.Mark):
                ctx = {**ctx, **step.context}
            self.ctx_at.append(ctx)
        skip = SERVED_SKIP_PROCEDURES if self.camera is None else ()
        self.served = [isinstance(s, P.Move) and self.ctx_at[i].get("procedure") not in skip
                       for i, s in enumerate(self.script)]
        self.cursor = -1
        # simulated time after each executed step (NaN: not executed); preallocated, so serving a
        # long acquisition does not grow the emulator's memory
        self.t_after = array("d", [math.nan]) * len(self.script)
        self.free_moves = 0
        self.requests = 0
        # the latest EVENTS_KEPT (kind, step index, target) for tests and logs, and a count per kind
        self.events: deque[tuple[str, int, float]] = deque(maxlen=EVENTS_KEPT)
        self.event_counts: Counter[str] = Counter()

    # ------------------------------------------------------------------ script execution
    def _same(self, a: float, b: float) -> bool:
        return abs(a - b) * self.microsteps_per_deg < 0.5 + 1e-9

    def _exec(self, i: int, dynamics: bool = True) -> None:
        step = self.script[i]
        self.state.on_step(i, step, dict(self.ctx_at[i]), False)
        if isinstance(step, P.Move):
            # (stops passed through on the way to a requested one: no drive-servo simulation)
            self.stage.move_to(step.target_deg, dynamics=dynamics)
        elif isinstance(step, P.Wait):
            self.state.clock.advance(step.seconds)
        self.t_after[i] = self.state.clock.now()

    def _advance_to(self, j: int) -> None:
        for i in range(self.cursor + 1, j + 1):
            self._exec(i, dynamics=(i == j))
        self.cursor = j

    def _jump(self, m: int) -> None:
        st = self.state
        st.step_index = m
        st._draws = {}
        st.apply_context(self.ctx_at[m])
        # Re-do the move from the time it started: the bench's physics is a function of its clock
        # (the cage path, the thermal state), and a pose at a time the bench has already seen
        # refines that stop instead of starting a new one (twin/physics.py), so a re-issued move
        # (a resumed acquisition) finds the bench as the uninterrupted run had it.
        t0 = self.t_after[m - 1] if m > 0 else math.nan
        if not math.isnan(t0):
            st.clock.set(t0)
        self.stage.move_to(self.script[m].target_deg)
        if not math.isnan(self.t_after[m]):
            st.clock.set(self.t_after[m])
        self.cursor = m

    def _next_served_move(self, start: int) -> int | None:
        for i in range(start, len(self.script)):
            if self.served[i]:
                return i
        return None

    def _event(self, kind: str, i: int, target_deg: float) -> None:
        self.events.append((kind, i, target_deg))
        self.event_counts[kind] += 1

    # ------------------------------------------------------------------ wire-level actions
    def move(self, target_deg: float) -> float:
        """A stage move arrived over the wire; returns the angle the stage now stands at (deg)."""
        target_deg = float(target_deg)
        j = self._next_served_move(self.cursor + 1)
        if j is not None and self._same(self.script[j].target_deg, target_deg):
            self._advance_to(j)
            self._event("next", j, target_deg)
            return self.script[j].target_deg
        for m in range(min(self.cursor, len(self.script) - 1), -1, -1):
            if self.served[m] and self._same(self.script[m].target_deg, target_deg):
                self._jump(m)
                self._event("back", m, target_deg)
                return self.script[m].target_deg
        for m in range(self.cursor + 1, len(self.script)):
            if self.served[m] and self._same(self.script[m].target_deg, target_deg):
                self._advance_to(m)
                self._event("ahead", m, target_deg)
                return self.script[m].target_deg
        # free move: no script step; keep the context, key the noise beyond the script
        self.free_moves += 1
        self.state.step_index = len(self.script) + self.free_moves
        self.state._draws = {}
        self.stage.move_to(target_deg)
        self._event("free", -1, target_deg)
        return target_deg

    def read(self, name: str) -> dict[str, Any]:
        """A reading of the twin's instrument ``name`` at the current stop (see module docstring)."""
        c = self.cursor
        cur = self.script[c] if 0 <= c < len(self.script) else None
        if not (isinstance(cur, P.Read) and name in cur.names):
            for i in range(c + 1, len(self.script)):
                s = self.script[i]
                if isinstance(s, P.Move):
                    break
                if isinstance(s, P.Read) and name in s.names:
                    self._advance_to(i)
                    break
        self.state._draws = {}
        if self.state.pose is None:  # nothing moved yet: pose the bench where the stage stands
            self.stage.move_to(self.stage.position_deg)
        reading = self.instruments[name].read()
        c = self.cursor
        if (self.camera is not None and self.on_frame is not None and 0 <= c < len(self.script) - 1
                and isinstance(self.script[c], P.Read) and name in self.script[c].names
                and isinstance(self.script[c + 1], P.Capture)):
            self._render(c + 1)
        return reading

    def _render(self, i: int) -> None:
        """The frame of Capture step ``i``, keyed as ``simulate`` keys it; the cursor stays."""
        st = self.state
        saved = st.step_index
        st.on_step(i, self.script[i], dict(self.ctx_at[i]), False)
        image = self.camera.capture()["image"]   # the renderer's truth is not passed on
        st.step_index, st._draws = saved, {}
        self.on_frame(image, i)

    def close(self) -> None:
        """Release the camera's renderer (idempotent)."""
        cam, self.on_frame = self.camera, None
        if cam is not None and not getattr(self, "_closed", False):
            self._closed = True
            cam.close()

    @property
    def position_deg(self) -> float:
        return float(self.stage.position_deg)

    @property
    def speed_deg_s(self) -> float:
        return float(self.stage.speed_deg_s)

    def describe(self) -> dict[str, Any]:
        return {"scenario": self.sc.name, "seed": int(self.sc.seed), "script_steps": len(self.script),
                "cursor": self.cursor, "free_moves": self.free_moves,
                "sim_time_s": float(self.state.clock.now()), "position_deg": self.position_deg}


def finite(x: Any) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False
