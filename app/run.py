"""Simulate → analyze in one call, and the scalar outputs a design study collects from it.

Why: a design study's ``full`` fidelity (``app/study/points.py``) asks, per point and repetition,
what the *whole* bench would report — measured encoder error from the polygon, the Jia error model
predicted from the measured eccentricity and radial motion, the residual, the stated uncertainties,
the effects the close-the-loop step identifies — not only what the posed disk does. This module is
that path, built from the two public pieces and nothing else:

1. ``twin.simulate.simulate`` writes the dataset (format v1, rendered CCD images, ``truth/``);
2. ``truth/`` is moved out of the dataset directory *before* the analysis runs, so the analysis
   cannot read it even by accident (one pipeline; truth never leaks into the analysis);
3. ``analysis.pipeline.analyze`` reads the dataset like any other and writes ``results.json``.

::

    simulate_and_analyze(scenario, out_dir, rep_seed, progress=False, *, order=10,
                         close_loop=True, backend="auto") -> dict   # the contents of results.json
    study_outputs(results, out_dir, names) -> dict[str, float]     # FULL_OUTPUTS by name

``out_dir`` receives ``dataset/`` (without ``truth/``), ``truth/`` and ``analysis/``
(``results.json``, ``report.html``).

Seeds: ``rep_seed`` becomes the simulated scenario's ``scenario.seed``: one repetition is one
independent realisation of everything the twin draws from the seed (the bench's seeded
imperfections, the run's non-repeating motion, every instrument's noise). ``rep_seed=None`` keeps
the scenario's own seed.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np

# name -> (needs the close-the-loop step, what it is). Units in the names; docs/studies.md lists them.
FULL_OUTPUTS: dict[str, tuple[bool, str]] = {
    "measured_angle_error_pv_arcsec": (False, "P-V of the encoder error α measured with the polygon and "
                                              "autocollimator (Hsieh shift-angle method), results.json "
                                              "encoder_error_arcsec"),
    "measured_angle_error_rms_arcsec": (False, "RMS about the mean of the same measured α"),
    "measured_angle_error_u_arcsec": (False, "RMS over the measured angles of the standard uncertainty u(α) "
                                             "the analysis states for the measured α"),
    "predicted_angle_error_pv_arcsec": (False, "P-V on a 1° grid of the Jia eq. 5 error model built from the "
                                               "measured eccentricity (CCD) and radial motion (spheres)"),
    "predicted_angle_error_rms_arcsec": (False, "RMS about the mean of the same prediction"),
    "predicted_angle_error_u_arcsec": (False, "RMS over the grid of the model's stated standard uncertainty"),
    "residual_pv_arcsec": (False, "P-V of measured − predicted at the measured angles (means removed), "
                                  "before closing the loop"),
    "residual_rms_arcsec": (False, "RMS of the same residual"),
    "eccentricity_um": (False, "installation eccentricity e measured from the CCD images (Jia eqs. 10–13)"),
    "eccentricity_u_um": (False, "its standard uncertainty as the analysis states it"),
    "true_angle_error_pv_arcsec": (False, "P-V of the twin's true α of head 1 (truth/encoder_error.csv: "
                                          "noise-free, 0.1° grid of readings, run 0, forward); never seen by "
                                          "the analysis"),
    "true_angle_error_rms_arcsec": (False, "RMS about the mean of the same true α"),
    "measurement_error_rms_arcsec": (False, "RMS over the measured angles of (measured α − true α), each with "
                                            "its mean over those angles removed: how well the bench measured "
                                            "the encoder error"),
    "measurement_error_max_arcsec": (False, "largest |measured α − true α| over the same angles"),
    "residual_after_pv_arcsec": (True, "P-V of the residual after the identified effects joined the model"),
    "residual_after_rms_arcsec": (True, "RMS of the residual after the identified effects joined the model"),
    "n_identified_effects": (True, "number of effects the close-the-loop step identified"),
}
# plus "identified.<effect>" (close loop): 1 if that effect of analysis.effects was identified, else 0;
# its mean over the repetitions is the rate at which the bench identifies it.
IDENTIFIED_PREFIX = "identified."
# keys of results.json that only the close-the-loop step writes
CLOSE_LOOP_KEYS = ("close_loop", "identified_effects", "ambiguous", "unexplained", "residual_test",
                   "residual_after_trace", "residual_after", "comparison_after")


class RunOutputError(KeyError):
    """A study output the pipeline's results (or the truth) cannot give; the message says why."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


def effect_names() -> list[str]:
    """Names of the effects the close-the-loop step can identify (analysis.effects)."""
    from benchtwin.analysis.effects import ALL

    return list(ALL)


def is_full_output(name: str) -> bool:
    if name in FULL_OUTPUTS:
        return True
    return name.startswith(IDENTIFIED_PREFIX) and name[len(IDENTIFIED_PREFIX):] in effect_names()


def needs_close_loop(name: str) -> bool:
    """Whether ``name`` (a FULL_OUTPUTS name, ``identified.<effect>`` or ``results.<path>``) needs
    the close-the-loop step; everything else is cheaper without it."""
    if name in FULL_OUTPUTS:
        return FULL_OUTPUTS[name][0]
    if name.startswith(IDENTIFIED_PREFIX):
        return True
    if name.startswith("results."):
        return name.split(".")[1] in CLOSE_LOOP_KEYS
    return False


def move_truth_out(dataset: Path, dest: Path) -> Path | None:
    """Move a simulated dataset's ``truth/`` to ``dest`` before any analysis reads the dataset.

    Why: the analysis must run with the truth absent from the dataset (principle 3), not merely
    unread; a run's output keeps it beside the dataset for `benchtwin score --truth`. Returns
    ``dest`` or ``None`` when the dataset has no truth (a measured bench)."""
    src = Path(dataset) / "truth"
    if not src.is_dir():
        return None
    shutil.move(str(src), str(dest))
    return Path(dest)


def simulate_and_analyze(scenario: Any, out_dir: str | Path, rep_seed: int | None = None, progress: bool = False,
                         *, order: int = 10, close_loop: bool = True, backend: str = "auto") -> dict[str, Any]:
    """Simulate ``scenario`` (with ``scenario.seed = rep_seed``) into ``out_dir/dataset``, move its
    ``truth/`` to ``out_dir/truth``, analyse the dataset into ``out_dir/analysis``; return the
    contents of ``results.json`` as written (read back from the file)."""
    from benchtwin.analysis.pipeline import analyze

    from benchtwin.twin.simulate import simulate

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sc = scenario
    if rep_seed is not None:
        seed = int(rep_seed)
        if not 0 <= seed <= 2**63 - 1:
            raise ValueError(f"rep_seed: expected an integer 0…2^63−1, got {rep_seed!r}")
        if int(scenario.seed) != seed:
            sc = scenario.with_overrides({"scenario.seed": seed})
            sc.path = getattr(scenario, "path", None)
    ds = out / "dataset"
    for d in (ds, out / "truth", out / "analysis"):
        if d.exists():
            shutil.rmtree(d)
    simulate(sc, ds, progress=progress, backend=backend)
    move_truth_out(ds, out / "truth")
    analyze(ds, out / "analysis", order=order, progress=progress, close_loop=close_loop)
    return json.loads((out / "analysis" / "results.json").read_text(encoding="utf-8"))


def _rms0(x: Any) -> float:
    x = np.asarray(x, float)
    return float(np.sqrt(np.mean((x - x.mean()) ** 2)))


def _rms(x: Any) -> float:
    return float(np.sqrt(np.mean(np.square(np.asarray(x, float)))))


class _RunOutputs:
    """The pieces the outputs of one simulate → analyze run are computed from: the results (each
    missing piece an error naming the output) and the twin's truth (read once)."""

    def __init__(self, results: dict[str, Any], out_dir: Path):
        self.results = results
        self.out = out_dir
        self._truth: tuple[np.ndarray, np.ndarray] | None = None

    def need(self, key: str, name: str) -> Any:
        node = self.results.get(key)
        if node is None:
            why = "the close-the-loop step did not run" if key in CLOSE_LOOP_KEYS else \
                "the dataset lacks the data it comes from (see the results' notes)"
            notes = "; ".join(self.results.get("notes", []))
            raise RunOutputError(f"output {name!r}: results.json has no {key!r} ({why}){': ' + notes if notes else ''}")
        return node

    def measured(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        e = self.need("encoder_error_arcsec", name)
        th, v = np.asarray(e["theta_deg"], float), np.asarray(e["value"], float)
        if e.get("u") is None:
            raise RunOutputError(f"output {name!r}: results.json encoder_error_arcsec has no u")
        return th, v, np.asarray(e["u"], float)

    def true_alpha(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        if self._truth is None:
            p = self.out / "truth" / "encoder_error.csv"
            if not p.is_file():
                raise RunOutputError(f"output {name!r}: no twin truth at {p}")
            with p.open(newline="", encoding="utf-8") as f:
                rows = list(csv.DictReader(f))
            col = "alpha_h1_arcsec" if rows and "alpha_h1_arcsec" in rows[0] else "alpha_arcsec"
            self._truth = (np.array([float(r["theta_deg"]) for r in rows]), np.array([float(r[col]) for r in rows]))
        return self._truth

    def meas_minus_true(self, name: str) -> np.ndarray:
        th, v, _ = self.measured(name)
        g, a = self.true_alpha(name)
        t = np.interp(th % 360.0, g, a, period=360.0)
        result: np.ndarray = (v - v.mean()) - (t - t.mean())
        return result


# output name -> how it is computed from one run (FULL_OUTPUTS describes each in words)
_OUTPUTS: dict[str, Callable[[_RunOutputs, str], float]] = {
    "measured_angle_error_pv_arcsec": lambda r, n: float(np.ptp(r.measured(n)[1])),
    "measured_angle_error_rms_arcsec": lambda r, n: _rms0(r.measured(n)[1]),
    "measured_angle_error_u_arcsec": lambda r, n: _rms(r.measured(n)[2]),
    "predicted_angle_error_pv_arcsec": lambda r, n: float(np.ptp(r.need("model_prediction_arcsec", n)["value"])),
    "predicted_angle_error_rms_arcsec": lambda r, n: _rms0(r.need("model_prediction_arcsec", n)["value"]),
    "predicted_angle_error_u_arcsec": lambda r, n: _rms(r.need("model_prediction_arcsec", n)["u"]),
    "residual_pv_arcsec": lambda r, n: float(r.need("residual_before", n)["pv_arcsec"]),
    "residual_rms_arcsec": lambda r, n: float(r.need("residual_before", n)["rms_arcsec"]),
    "eccentricity_um": lambda r, n: float(r.need("eccentricity_um", n)),
    "eccentricity_u_um": lambda r, n: float(r.need("eccentricity_u_um", n)),
    "true_angle_error_pv_arcsec": lambda r, n: float(np.ptp(r.true_alpha(n)[1])),
    "true_angle_error_rms_arcsec": lambda r, n: _rms0(r.true_alpha(n)[1]),
    "measurement_error_rms_arcsec": lambda r, n: _rms(r.meas_minus_true(n)),
    "measurement_error_max_arcsec": lambda r, n: float(np.max(np.abs(r.meas_minus_true(n)))),
    "residual_after_pv_arcsec": lambda r, n: float(r.need("residual_after", n)["pv_arcsec"]),
    "residual_after_rms_arcsec": lambda r, n: float(r.need("residual_after", n)["rms_arcsec"]),
    "n_identified_effects": lambda r, n: float(len(r.need("identified_effects", n))),
}


def study_outputs(results: dict[str, Any], out_dir: str | Path, names: Iterable[str]) -> dict[str, float]:
    """The named outputs (``FULL_OUTPUTS``, ``identified.<effect>``) of one simulate → analyze run.

    ``results`` is what ``simulate_and_analyze`` returned for ``out_dir`` (whose ``truth/`` gives the
    true α). A missing piece raises ``RunOutputError`` naming the output and what is missing."""
    run = _RunOutputs(results, Path(out_dir))
    res: dict[str, float] = {}
    for name in names:
        fn = _OUTPUTS.get(name)
        if fn is not None:
            v = fn(run, name)
        elif name.startswith(IDENTIFIED_PREFIX) and is_full_output(name):
            effect = name[len(IDENTIFIED_PREFIX):]
            v = float(any(e.get("name") == effect for e in run.need("identified_effects", name)))
        else:
            raise RunOutputError(f"output {name!r}: not a full-fidelity output; known: "
                                 f"{', '.join(FULL_OUTPUTS)}, {IDENTIFIED_PREFIX}<effect>")
        if not math.isfinite(v):
            raise RunOutputError(f"output {name!r}: the run gave a non-finite value ({v})")
        res[name] = v
    return res

__all__ = ["simulate_and_analyze", "study_outputs", "FULL_OUTPUTS", "is_full_output", "needs_close_loop",
           "effect_names", "RunOutputError"]
