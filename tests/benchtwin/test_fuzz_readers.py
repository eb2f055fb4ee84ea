"""Bounded fuzzing of every reader (issue #13): tables, manifest, scenario, study, bench file, fault
plan, model file, and the shared grammar of benchtwin.schema. Hostile input may only raise the
project's own error type of that reader, never anything else (no TypeError, KeyError,
OverflowError, RecursionError...). Kept small (max_examples) so that all of them together take
well under 30 s; each is seeded by hypothesis' database-free derandomised run so CI is stable."""

from __future__ import annotations

import copy
import json
import string
import tomllib
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from benchtwin.analysis.dataset import TABLES, DatasetError, open_dataset, parse_table, validate_manifest
from tests.support.fake_dataset import MANIFEST, make_dataset
from tests.support.fuzz import FUZZ, mutated
from tests.support.fuzz import any_value as _value  # the tests' source, hence hypothesis' derandomised seeds, unchanged

ROOT = Path(__file__).resolve().parents[2]


# ----------------------------------------------------------------------------- grammar


@FUZZ
@given(st.text(max_size=40))
def test_number_grammar_raises_only_value_error(text):
    from benchtwin.schema import parse_float, parse_int

    for fn in (parse_float, parse_int):
        try:
            x = fn(text)
        except ValueError:
            continue
        assert text.isascii() and "_" not in text and x == x and abs(x) != float("inf")


@FUZZ
@given(st.text(alphabet="[]{}\"'#=,.:ab1 \n\\", max_size=200))
def test_json_and_toml_loaders_raise_only_schema_error(text):
    from benchtwin.schema import SchemaError, loads_json, loads_toml

    for fn in (loads_json, loads_toml):
        try:
            fn(text, "f")
        except SchemaError:
            pass


# ----------------------------------------------------------------------------- tables and manifest

_cells = st.one_of(st.sampled_from(["0", "1", "-1", "0.5", "1_000", "1e400", "nan", "inf", "", " ", "7200", "forward",
                                    "backward", "sideways", "12345678901234567890", "1e-400", "0x10", "١", "\"", "a,b"]),
                   st.text(alphabet=string.printable, max_size=8))


@st.composite
def csv_text(draw, name):
    spec = TABLES[name]
    cols = list(spec.required) + draw(st.lists(st.sampled_from(list(spec.optional) + ["extra"]), max_size=2, unique=True))
    if draw(st.booleans()):
        cols = draw(st.permutations(cols))
    rows = draw(st.lists(st.lists(_cells, min_size=len(cols) - 1, max_size=len(cols) + 1), max_size=6))
    text = ",".join(cols) + "\n" + "".join(",".join(r) + "\n" for r in rows)
    return text if not draw(st.booleans()) else draw(st.text(max_size=60)) + text


@pytest.mark.parametrize("name", sorted(TABLES))
@FUZZ
@given(data=st.data())
def test_tables_raise_only_dataset_error(name, data):
    text = data.draw(csv_text(name))
    try:
        parse_table(text, name, f"{name}.csv")
    except DatasetError:
        pass


@FUZZ
@given(mutated(json.loads(json.dumps(MANIFEST))))
def test_manifest_raises_only_dataset_error(m):
    try:
        validate_manifest(m)
    except DatasetError:
        pass


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("fuzz") / "ds")


@FUZZ
@given(m=mutated(json.loads(json.dumps(MANIFEST))), table=st.sampled_from(sorted(TABLES)), data=st.data())
def test_whole_dataset_raises_only_dataset_error(dataset_dir, tmp_path_factory, m, table, data):
    """A dataset with a mutated manifest and one fuzzed table, read and validated as validate does."""
    import shutil

    d = tmp_path_factory.mktemp("fz") / "ds"
    shutil.copytree(dataset_dir, d)
    (d / "manifest.json").write_text(json.dumps(m))
    (d / f"{table}.csv").write_text(data.draw(csv_text(table)))
    try:
        open_dataset(d).validate()
    except DatasetError:
        pass


# ----------------------------------------------------------------------------- scenario, study, bench, fault plan


@pytest.fixture(scope="module")
def jia_raw():
    return tomllib.loads((ROOT / "scenarios" / "jia2019.toml").read_text())


@FUZZ
@given(data=st.data())
def test_scenario_raises_only_scenario_error(jia_raw, data):
    from benchtwin.twin.scenario import ScenarioError, validate

    raw = data.draw(mutated(jia_raw))
    try:
        validate(raw, "s.toml")
    except ScenarioError:
        pass


@FUZZ
@given(data=st.data())
def test_study_raises_only_study_error(tmp_path_factory, monkeypatch_module, data):
    from benchtwin.app.study import spec as st_mod

    base = tomllib.loads((ROOT / "scenarios" / "studies" / "bearing_distance.toml").read_text())
    raw = data.draw(mutated(base))
    p = tmp_path_factory.getbasetemp() / "fuzz_study.toml"
    p.write_text("# the reader's parse is replaced by the fuzzed table\n")
    monkeypatch_module.setattr(st_mod, "load_toml_file", lambda path, what="": copy.deepcopy(raw))
    try:
        st_mod.load_study(p)
    except st_mod.StudyError:
        pass


@pytest.fixture(scope="module")
def monkeypatch_module():
    mp = pytest.MonkeyPatch()
    yield mp
    mp.undo()


@FUZZ
@given(data=st.data())
def test_bench_file_raises_only_bench_file_error(data):
    from benchtwin.hw.acquisition.bench import BenchFileError, parse_bench
    from tests.support.bench_file import bench_raw as _bench

    raw = data.draw(mutated(_bench()))
    try:
        parse_bench(raw, "b.toml")
    except BenchFileError:
        pass


@FUZZ
@given(data=st.data())
def test_fault_plan_raises_only_value_error(data):
    from benchtwin.twin.emulators.pty import load_fault_plan

    base = {"faults": [{"port": "stage", "request": 3, "action": "delay", "seconds": 0.5},
                       {"port": "encoder", "request": 1, "action": "drop"}]}
    raw = data.draw(st.one_of(mutated(base), _value))
    try:
        load_fault_plan(raw)
    except ValueError:  # the fault plan's own error type (ValueError, as load_fault_plan documents)
        pass


# ----------------------------------------------------------------------------- model file

_MODEL = {"format": "benchtwin-traced-effects", "version": 1, "status": "explained", "effects": [
    {"name": "tangential_motion", "params": {"gain": 0.7}, "u": {"gain": 0.1},
     "aux": {"r_um": 22000.0, "coefs": {"2": [0.1, 0.1]}, "coefs_dY": {"2": [0.1, -0.1]}, "x_probes": True},
     "encoder_error": True},
    {"name": "graduation_error", "params": {"a3_arcsec": 0.2}, "u": {}, "aux": {"orders": [3]}, "encoder_error": True},
]}


@FUZZ
@given(m=mutated(_MODEL))
def test_model_file_raises_only_model_file_error(tmp_path_factory, m):
    from benchtwin.analysis.model_file import ModelFileError, read_model_file

    p = tmp_path_factory.getbasetemp() / "fuzz_model.json"
    try:
        p.write_text(json.dumps(m))
    except ValueError:
        return
    try:
        read_model_file(p)
    except ModelFileError:
        pass


def test_the_unmutated_model_file_is_valid(tmp_path):
    from benchtwin.analysis.model_file import read_model_file

    p = tmp_path / "m.json"
    p.write_text(json.dumps(_MODEL))
    assert read_model_file(p)["effects"][0]["name"] == "tangential_motion"
