"""One procedure language: simulate, emulate and acquire make their steps from the same specs.

The scenario's procedures as specs (``twin.simulate.scenario_procedures``) are what ``simulate``
runs (``sim_procedure``), what the emulator writes into its bench file (``serve.bench_file_text``)
and, parsed back by the bench-file reader, what ``acquire`` runs (``bench.build_procedure``): the
three step lists are equal, step for step."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from benchtwin.hw.acquisition import procedures as P
from benchtwin.hw.acquisition.bench import _procedure, build_procedure, parse_bench
from benchtwin.twin.emulators.serve import bench_file_text
from benchtwin.twin.scenario import load_scenario
from benchtwin.twin.simulate import scenario_procedures, sim_procedure


ROOT = Path(__file__).resolve().parents[2]


class _Enc:
    decimals = 4


class _Ac:
    DRIVER = "elcomat"


class _Stage:
    microsteps_per_deg = 1000.0
    speed_deg_s = 20.0


class _Probes:
    channels = {1: "probe_top", 2: "probe_bottom"}


class _ProbesX:
    channels = {1: "probe_top_x", 2: "probe_bottom_x"}


class _Cam:
    class camera:
        reference_px = (1024.0, 768.0)
        azimuth_rad = 3.141592653589793
        tangential = "+x"
        pixel_pitch_m = 0.667e-6


@pytest.mark.parametrize("name", ["jia2019", "hsieh2022"])
def test_simulate_emulate_and_acquire_make_the_same_steps(name):
    sc = load_scenario(ROOT / "scenarios" / f"{name}.toml")
    emus = {"encoder": _Enc(), "autocollimator": _Ac(), "stage": _Stage(), "probes": _Probes()}
    ports = {"encoder": "/dev/e", "autocollimator": "/dev/a", "stage": "/dev/s", "probes": "/dev/p"}
    if sc["instruments"]["probe"]["x_probes"]:
        emus["probes_x"], ports["probes_x"] = _ProbesX(), "/dev/px"
    text = bench_file_text(sc, ports, emus, camera=_Cam(), frames_dir="/tmp/frames")
    cfg = parse_bench(tomllib.loads(text), "<emulated bench file>")
    simulated = sim_procedure(sc)
    assert build_procedure(cfg) == simulated
    assert list(P.steps_from_specs(scenario_procedures(sc))) == simulated
    types = [p["type"] for p in cfg.procedures]
    assert types[:3] == ["radial_motion", "ccd_sweep", "polygon_shift_angle"]


def test_specs_round_trip_through_the_bench_file_form():
    """specs_toml writes what the bench-file reader parses back into the same specs."""
    specs = [{"type": "polygon_traditional", "faces": 12, "start_face": 3, "shift": 15.0, "rep": 1,
              "directions": ["forward", "backward"], "dwell": 0.25, "encoder": "enc", "autocollimator": "ac"},
             {"type": "selfcal", "step": 2.5, "directions": ["forward"], "dwell": 0.1, "heads": [0.0, 90.0, 180.0]},
             {"type": "radial_motion", "reps": 2, "positions": 36, "dwell": 0.5, "probes": ["a", "b"]}]
    raw = tomllib.loads("\n".join(P.specs_toml(specs)))
    geo = {"polygon_faces": 12, "heads_deg": [0.0]}
    parsed = [_procedure(k, p, "<specs>", geo) for k, p in enumerate(raw["procedure"])]
    assert parsed == specs
    assert list(P.steps_from_specs(parsed)) == list(P.steps_from_specs(specs))
    with pytest.raises(ValueError, match="unknown procedure type"):
        list(P.steps_from_specs([{"type": "warm_up"}]))
