"""docs/physics.md's "Sources of motion and drift, bench by bench" table is the one the scenarios give.

benchmarks/motion_sources.py loads every shipped scenario through the project's loader and writes
each source of motion and drift with its resolved size; the doc's block between the markers must
equal a fresh one, so the table cannot drift from the scenarios (issue 33, first "Done when" item).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _module():
    spec = importlib.util.spec_from_file_location("motion_sources", ROOT / "benchmarks" / "motion_sources.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod          # its dataclass looks its module up there
    spec.loader.exec_module(mod)
    return mod


def test_doc_table_equals_a_fresh_one():
    ms = _module()
    fresh = ms.table()
    doc = ms.doc_block(ms.DOC.read_text(encoding="utf-8"))
    assert doc == fresh, ("docs/physics.md's motion-sources table differs from the scenarios: "
                          "run .venv/bin/python benchmarks/motion_sources.py --write")


def test_every_shipped_bench_is_in_the_table():
    ms = _module()
    block = ms.table()
    names = [ms.bench_name(p) for p in ms.scenario_files()]
    assert len(names) == 3 + len(list((ROOT / "scenarios" / "hidden").glob("*.toml"))) + len(
        list((ROOT / "scenarios" / "hidden_templates").glob("*.toml")))
    headers = [line for line in block.splitlines() if line.startswith("**")]
    listed = [n for h in headers for n in h.strip("*").split(", ")]
    assert sorted(listed) == sorted(names)


def test_rows_follow_the_resolved_values(tmp_path):
    """A changed value changes its row, and a reference lapses with the value it was read for."""
    ms = _module()
    src = (ROOT / "scenarios" / "jia2019.toml").read_text(encoding="utf-8")
    assert 'cage_slip = 0.02' in src and 'hvac_amplitude = "0.5 K"' in src
    changed = src.replace("cage_slip = 0.02", "cage_slip = 0.05").replace(
        'hvac_amplitude = "0.5 K"', 'hvac_amplitude = "0.7 K"')
    p = tmp_path / "scenarios" / "jia2019.toml"      # named "jia2019" like the shipped bench
    p.parent.mkdir()
    p.write_text(changed, encoding="utf-8")
    rows = {r.source: r for r in ms.bench_rows(p)}
    slip = rows["ball bearings: cage slip (sets the asynchronous motion)"]
    assert slip.size == "σ = 0.05 of the move's rolling"
    temps = rows["temperatures (drive every thermal row below)"]
    assert "room control ±0.7 K" in temps.size
    assert ms.bench_name(p) == "jia2019"
    # the reference was read for "0.5 K": it lapses with the value
    assert "Bryan 1990" not in temps.size_source
    # the shipped file keeps its reference
    shipped = {r.source: r for r in ms.bench_rows(ROOT / "scenarios" / "jia2019.toml")}
    assert "Bryan 1990" in shipped["temperatures (drive every thermal row below)"].size_source


def test_path_bearing_rows_say_the_whirl_is_imposed(tmp_path):
    """A path bearing (a replay) still says what the code imposes: built from the old null_paper
    bearing block, since no shipped bench uses one any more."""
    ms = _module()
    src = (ROOT / "scenarios" / "hidden" / "null_paper.toml").read_text(encoding="utf-8")
    i, j = src.index("[bearings]"), src.index("[errors]")
    block = """[bearings]
type = "path"
radial_stiffness = "150 N/um"
waviness_top = [ { order = 2, amplitude = "0.15 um", phase = "30 deg" },
                 { order = 3, amplitude = "0.10 um", phase = "110 deg" },
                 { order = 5, amplitude = "0.05 um", phase = "200 deg" } ]
waviness_bottom = [ { order = 2, amplitude = "0.10 um", phase = "250 deg" },
                    { order = 4, amplitude = "0.06 um", phase = "80 deg" } ]
async_rms = "0.06 um"               # non-repeating motion, rep to rep (fig. 13: 0.3 µm range over 3 reps)

"""
    p = tmp_path / "hidden" / "null_paper.toml"
    p.parent.mkdir()
    p.write_text(src[:i] + block + src[j:], encoding="utf-8")
    rows = {r.source: r for r in ms.bench_rows(p)}
    wav = rows["path bearing: race waviness"]
    assert "FORWARD whirl" in wav.mechanism
    assert wav.size == "top: k=2 0.15 µm, k=3 0.1 µm, k=5 0.05 µm; bottom: k=2 0.1 µm, k=4 0.06 µm"
    assert rows["path bearing: random non-repeating motion"].keyed_by.endswith("not time")
    assert rows["path bearing: cage lobing"].size_source.startswith(
        "`bearings.async_rms`: Jia 2019 fig. 13")
    replay = rows["path bearing: the REPLAY of a given rolling path (not a bearing model)"]
    assert "none stated" in replay.size_source


def test_no_shipped_bench_imposes_a_whirl_and_air_motion_is_keyed_by_time():
    """Issue 33 item 1: every bench in scenarios/ runs on a bearing model (ball or air); the only
    path bearings are the template stress cases' ideal (zero) paths, with their provenance."""
    ms = _module()
    for path in ms.scenario_files():
        rows = ms.bench_rows(path)
        assert not any("FORWARD whirl" in r.mechanism for r in rows), path
        replay = [r for r in rows if r.source.startswith("path bearing")]
        if replay:
            assert path.parent.name == "hidden_templates"
            assert "synthetic: an ideal rolling path" in replay[0].size_source
    rows = {r.source: r for r in ms.bench_rows(ROOT / "scenarios" / "hsieh2022.toml")}
    assert rows["air bearings: supply-pressure fluctuation (asynchronous)"].keyed_by == ms.KEY_TIME
    assert "backward at qN−1" in rows["air bearings: journal form through the film"].mechanism
    assert "K = 116 N/µm" in rows["air bearings: film stiffness"].size


def test_time_keyed_cage_slip_row(tmp_path):
    """cage_slip_time > 0 (the time-keyed slip process) is said as such, keyed by bench time, with
    its correlation time and the sources of all three numbers."""
    ms = _module()
    src = (ROOT / "scenarios" / "jia2019.toml").read_text(encoding="utf-8")
    changed = src.replace("radial_stiffness = ", 'cage_slip_time = "60 s"\nradial_stiffness = ', 1)
    p = tmp_path / "scenarios" / "jia2019.toml"
    p.parent.mkdir()
    p.write_text(changed, encoding="utf-8")
    slip = {r.source: r for r in ms.bench_rows(p)}["ball bearings: cage slip (sets the asynchronous motion)"]
    assert slip.size == "σ = 0.02, τ = 1 min, s̄ = 0"
    assert slip.keyed_by.startswith("bench time t")
    assert "`bearings.cage_slip`: ASSUMPTION, no source" in slip.size_source
    assert "`bearings.cage_slip_time`: no source" in slip.size_source
    assert "`bearings.cage_slip_mean`: schema default, no source" in slip.size_source


def test_shared_and_default_references_lapse_with_the_value(tmp_path):
    """A reference found by the sourcing pass (SHARED_REFS: any bench stating the same value;
    DEFAULT_REFS: a schema default) applies only to the value it was read for; a derivation that
    disagrees with the value leaves it unsourced."""
    ms = _module()
    src = (ROOT / "scenarios" / "jia2019.toml").read_text(encoding="utf-8")
    assert 'microscope_stand_growth = "2.3 um/K"' in src and 'axis_drift = "0.1 um/K"' in src
    assert 'probe_stand_time_constant = "12 min"' in src
    changed = src.replace('microscope_stand_growth = "2.3 um/K"', 'microscope_stand_growth = "3 um/K"').replace(
        'probe_stand_time_constant = "12 min"', 'probe_stand_time_constant = "20 min"')
    p = tmp_path / "scenarios" / "jia2019.toml"
    p.parent.mkdir()
    p.write_text(changed, encoding="utf-8")
    rows = {r.source: r for r in ms.bench_rows(p)}
    micro = rows["thermal: microscope_stand_growth"].size_source
    assert "Callister" not in micro and "`thermal.microscope_stand_growth`: ASSUMPTION, no source" in micro
    probe = rows["thermal: probe_stand_growth"].size_source
    assert "`thermal.probe_stand_time_constant`: no source" in probe and "Incropera" not in probe
    shipped = {r.source: r for r in ms.bench_rows(ROOT / "scenarios" / "jia2019.toml")}
    assert "Callister" in shipped["thermal: microscope_stand_growth"].size_source
    assert "`thermal.probe_stand_time_constant`: derived: lumped capacitance" in (
        shipped["thermal: probe_stand_growth"].size_source)
    # a schema default carries its reference (hsieh2022 states no probe stand time constant)
    hsieh = {r.source: r for r in ms.bench_rows(ROOT / "scenarios" / "hsieh2022.toml")}
    assert "`thermal.probe_stand_time_constant`: schema default: within [12 min, 2.5 h]" in (
        hsieh["thermal: probe_stand_growth"].size_source)
    twist = shipped["bearing friction: twist"].size_source
    assert "`bearings.friction_torque`: ASSUMPTION, no source for the value" in twist
    assert "`bearings.shaft_torsional_stiffness`: ASSUMPTION; within [3.6e3, 9.7e3] N·m/rad" in twist
    # the same value on another bench carries the same reference
    hidden = {r.source: r for r in ms.bench_rows(ROOT / "scenarios" / "hidden" / "torsion_hysteresis.toml")}
    assert "within [3.6e3, 9.7e3] N·m/rad" in hidden["bearing friction: twist (hidden torsion_hysteresis)"].size_source
