"""Scenario files: the shipped ones load; each broken one is rejected with a message naming
file, key path and what was expected (issue 2: at least 15 distinct broken inputs)."""

from __future__ import annotations

import math

import numpy as np
import tomllib
from pathlib import Path

import pytest

from benchtwin.twin.scenario import ScenarioError, default_scenario_path, load_scenario, validate
from benchtwin.units import ARCSEC, UM

SCEN = Path(__file__).resolve().parents[2] / "scenarios"


def test_default_is_embedded_jia2019():
    sc = load_scenario()
    assert sc.name == "jia2019"
    assert default_scenario_path().name == "jia2019.toml"
    # Jia 2019 sec. 5 values, parsed to SI
    assert sc["bench"]["L1"] == pytest.approx(6.81e-3)
    assert sc["bench"]["L2"] == pytest.approx(122.96e-3)
    assert sc["errors"]["eccentricity"] == pytest.approx(7.1 * UM)
    assert math.degrees(sc["errors"]["theta0"]) == pytest.approx(192.08)
    assert sc["bench"]["polygon_faces"] == 23
    assert sc["bench"]["encoder_resolution"] == pytest.approx(0.39 * ARCSEC)
    assert sc["instruments"]["ccd"]["pixel_pitch"] == pytest.approx(0.667 * UM)


def test_hsieh2022():
    sc = load_scenario(SCEN / "hsieh2022.toml")
    assert sc["bench"]["polygon_faces"] == 24
    assert sc["bench"]["encoder_lines"] == 36000
    assert len(sc["bench"]["heads"]) == 12
    shifts = [round(math.degrees(s)) for s in sc["procedure"]["polygon_shifts"]]
    assert shifts == list(range(15))


# Study files (scenarios/studies/) have their own format, checked by tests/twin/test_study.py.
@pytest.mark.parametrize("path", sorted(p for p in SCEN.rglob("*.toml") if "studies" not in p.parts), ids=lambda p: p.name)
def test_every_shipped_scenario_validates(path):
    load_scenario(path)


def _base() -> dict:
    return tomllib.loads((SCEN / "jia2019.toml").read_text())


def _set(d: dict, dotted: str, value) -> dict:
    *parents, last = dotted.split(".")
    node = d
    for p in parents:
        node = node.setdefault(p, {})
    if value is _DELETE:
        del node[last]
    else:
        node[last] = value
    return d


_DELETE = object()

# (what is broken, dotted key, new value, words the message must contain)
BROKEN = [
    ("unknown key", "bench.L3", "1 mm", ["bench.L3", "unknown key"]),
    ("unknown section", "wheels", {"a": 1}, ["[wheels]", "unknown section"]),
    ("unknown instrument", "instruments.laser", {"power": "1 mm"}, ["instruments.laser"]),
    ("missing section", "bearings", _DELETE, ["missing section [bearings]"]),
    ("missing key", "bench.L1", _DELETE, ["bench.L1", "missing", "length"]),
    ("wrong dimension", "bench.L1", "6.81 deg", ["bench.L1", "angle", "expected a length"]),
    ("bare number for a length", "errors.eccentricity", 7.1, ["errors.eccentricity", "bare number"]),
    ("unknown unit", "errors.eccentricity", "7.1 furlong", ["errors.eccentricity", "unknown unit"]),
    ("not a number", "errors.theta0", "abc deg", ["errors.theta0", "cannot read"]),
    ("out of range", "bench.polygon_faces", 2, ["bench.polygon_faces", "below the minimum"]),
    ("above range", "instruments.ccd.numerical_aperture", 3.0, ["numerical_aperture", "above the maximum"]),
    ("wrong type int", "bench.polygon_faces", "23", ["bench.polygon_faces", "integer"]),
    ("wrong type bool", "instruments.probe.x_probes", "yes", ["x_probes", "true or false"]),
    ("bad choice", "bench.gravity_direction", "down", ["gravity_direction", "not one of"]),
    ("bad bit depth", "instruments.ccd.bit_depth", 10, ["bit_depth", "not one of"]),
    ("lobe missing phase", "bearings.waviness_top", [{"order": 2, "amplitude": "1 um"}], ["waviness_top", "item 0"]),
    ("lobe order zero", "bearings.waviness_top", [{"order": 0, "amplitude": "1 um", "phase": "0 deg"}], ["order"]),
    ("L1 not below L2", "bench.L1", "200 mm", ["bench.L1", "bench.L2"]),
    ("eccentricity huge", "errors.eccentricity", "2 mm", ["errors.eccentricity", "5 %"]),
    ("start face beyond N", "procedure.traditional_start_face", 24, ["traditional_start_face", "1…bench.polygon_faces"]),
    ("unknown hidden effect", "hidden.gremlins", {"amount": "1 um"}, ["hidden.gremlins", "unknown effect"]),
    ("empty head list", "bench.heads", [], ["bench.heads"]),
    ("infinite value", "bench.L2", "inf mm", ["bench.L2"]),
    ("negative seed", "scenario.seed", -1, ["scenario.seed", "minimum"]),
]


@pytest.mark.parametrize("what,key,value,words", BROKEN, ids=[b[0] for b in BROKEN])
def test_broken_scenarios_are_rejected_clearly(what, key, value, words, tmp_path):
    raw = _set(_base(), key, value)
    with pytest.raises(ScenarioError) as err:
        validate(raw, "broken.toml")
    msg = str(err.value)
    assert msg.startswith("broken.toml: "), msg  # names the file
    for w in words:
        assert w in msg, f"{what}: {w!r} not in {msg!r}"


def test_not_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[bench\nL1 = ")
    with pytest.raises(ScenarioError, match="bad.toml: not valid TOML"):
        load_scenario(bad)
    with pytest.raises(ScenarioError, match="no such scenario file"):
        load_scenario(tmp_path / "nope.toml")


def test_overrides_revalidate():
    sc = load_scenario()
    sc2 = sc.with_overrides({"bench.L1": "10 mm"})
    assert sc2["bench"]["L1"] == pytest.approx(0.01)
    assert sc["bench"]["L1"] == pytest.approx(6.81e-3)  # original untouched
    with pytest.raises(ScenarioError, match="bench.L1"):
        sc.with_overrides({"bench.L1": "10 kg"})


def test_scenario_format_doc_matches_schema():
    """docs/scenario-format.md's reference table is generated from the schema; regenerate it with
    `python -c 'from benchtwin.twin.scenario_schema import schema_markdown; print(schema_markdown())'`."""
    from benchtwin.twin.scenario_schema import schema_markdown

    doc = (SCEN.parent / "docs" / "scenario-format.md").read_text()
    assert schema_markdown() in doc


def test_motion_table_section(tmp_path):
    """[motion_table] replays a measured spindle: equal-length unit-carrying lists, validated."""
    raw = _base()
    raw["motion_table"] = {"theta": ["0 deg", "120 deg", "240 deg"], "dx": ["0.1 um", "0 um", "-0.1 um"]}
    sc = validate(raw, "mt.toml")
    assert sc["motion_table"]["dx"][0] == pytest.approx(1e-7)
    assert "dy" not in sc["motion_table"]
    raw["motion_table"]["dy"] = ["0 um"]
    with pytest.raises(ScenarioError, match="motion_table.dy: expected 3 values"):
        validate(raw, "mt.toml")
    raw["motion_table"] = {"dx": ["0 um"]}
    with pytest.raises(ScenarioError, match="missing key motion_table.theta"):
        validate(raw, "mt.toml")


def test_motion_table_drives_the_twin():
    """The physics replays the table: the axis passes through the tabulated motion."""
    from benchtwin.twin.physics import Bench

    raw = _base()
    raw["bearings"]["async_rms"] = "0 um"
    raw["bench"]["gravity_direction"] = "none"
    raw["bearings"]["unbalance"] = "0 g*mm"
    raw["motion_table"] = {"theta": [f"{a} deg" for a in range(0, 360, 10)],
                           "dx": [f"{0.2 * math.cos(math.radians(3 * a)):.6f} um" for a in range(0, 360, 10)]}
    bench = Bench(validate(raw, "mt.toml"))
    dx, dy = bench.disk_plane_motion(np.radians([0.0, 40.0]), rep=0)
    assert dx[0] - dx[1] == pytest.approx(0.2e-6 * (1 - math.cos(math.radians(120))), abs=5e-9)
