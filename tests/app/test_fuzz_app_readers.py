"""Bounded fuzzing of the newer readers (issue 31), as tests/benchtwin/test_fuzz_readers.py does for the dataset,
scenario, study, bench file, fault plan and model file: ``import``'s table, ``score``'s results
(minimal CSV and JSON, the project's results.json) and truth files, ``score-suite``'s suite.json,
``certificate``'s lab file and results.json, ``compare``'s results, and the study cache. Hostile
input may only raise the reader's own error type (exit 2 through the CLI), never anything else;
and what a reader accepts, the next step runs: an imported dataset passes ``validate``, an accepted
lab file gives a certificate that validates against the DCC schema, a score prints strict JSON.

Derandomised and small (60 examples each, a few seconds together), like the dataset's fuzzers."""

from __future__ import annotations

import copy
import json
import math
import string
import tomllib
import uuid
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.support.fuzz import FUZZ, mutated
from tests.support.fuzz import any_value as _value  # the tests' source, hence hypothesis' derandomised seeds, unchanged
from tests.support.known_truth import write_truth
from tests.support.readers import LAB
from tests.support.readers import strict_json as _strict

ROOT = Path(__file__).resolve().parents[2]

_cells = st.one_of(st.sampled_from(["0", "1", "-1", "0.5", "90", "180", "270", "360", "720", "720.5", "-360",
                                    "7200.5", "1_000", "6_9", "1e400", "nan", "inf", "", " ", "36000", "1e30",
                                    "12345678901234567890", "1" + "0" * 400, "0x10", "١", "−3", "\"", "a,b",
                                    "\x00", "true"]),
                   st.text(alphabet=string.printable, max_size=8))


# ============================================================================ import


#: mostly numbers, so that many tables parse and reach the ranges and the writer
_numbers = st.one_of(st.sampled_from(["0", "90", "180", "270", "360", "-360", "720", "720.5", "7200.5", "0.5", "-3",
                                      "1_000", "36000", "36001", "1e30", "1e-30", "-0", "\u22123"]),
                     st.floats(min_value=-1e5, max_value=1e5, allow_nan=False).map(repr),
                     st.floats(min_value=-400, max_value=800, allow_nan=False).map(repr))


@st.composite
def import_table(draw):
    cols = draw(st.permutations(["a", "e"] + draw(st.lists(st.sampled_from(["a", "e", "r", "u", "x"]), max_size=3))))
    rows = draw(st.lists(st.lists(_numbers, min_size=len(cols), max_size=len(cols)), min_size=3, max_size=6))
    # then, sometimes, a hostile cell, a short or long row, or junk before the header
    for _ in range(draw(st.integers(0, 2))):
        r = draw(st.sampled_from(rows))
        op = draw(st.sampled_from(["cell", "cell", "short", "long"]))
        if op == "cell":
            r[draw(st.integers(0, len(r) - 1))] = draw(_cells)
        elif op == "short":
            r.pop()
        else:
            r.append(draw(_cells))
    text = ",".join(cols) + "\n" + "".join(",".join(r) + "\n" for r in rows)
    return text if draw(st.integers(0, 4)) else draw(st.text(max_size=30)) + text


@FUZZ
@given(text=import_table(), reverse=st.sampled_from([None, "r"]), u=st.sampled_from([None, "u"]),
       unit=st.sampled_from(["arcsec", "urad", "deg", "turns"]))
def test_import_raises_only_import_error_and_validate_accepts_what_it_writes(tmp_path_factory, text, reverse, u,
                                                                               unit):
    from benchtwin.analysis.dataset import open_dataset
    from benchtwin.app.curve_import import ImportError_, TableColumns, import_table as imp

    d = tmp_path_factory.getbasetemp() / f"imp-{uuid.uuid4().hex}"
    d.mkdir()
    (d / "t.csv").write_text(text, encoding="utf-8")
    try:
        imp(d / "t.csv", d / "ds", TableColumns("a", "e", reverse=reverse, u=u, error_unit=unit))
    except ImportError_:
        assert not (d / "ds" / "manifest.json").exists()
        return
    open_dataset(d / "ds").validate()  # raises DatasetError (a failure here) if import wrote what validate refuses


# ============================================================================ score: results


@FUZZ
@given(rows=st.lists(st.tuples(st.sampled_from(["e_um", "theta0_deg", "alpha_arcsec", "beta_arcsec", "selfcal_arcsec",
                                                "named", "ambiguous", "unexplained", "residual_after_arcsec",
                                                "residual_before_arcsec", "ecc", ""]),
                               _cells, _cells, _cells), max_size=8),
       junk=st.text(max_size=20))
def test_score_csv_raises_only_input_error(rows, junk):
    from benchtwin.app.score import results_from_csv
    from benchtwin.cli import InputError

    text = "quantity,key,value,u\n" + "".join(",".join(r) + "\n" for r in rows) + junk
    try:
        results_from_csv(text, "r.csv")
    except InputError:
        pass


_MIN = {"format": "benchtwin-min-results", "version": 1, "algorithm": "x", "e_um": 7.0, "e_u_um": 0.1,
        "theta0_deg": 10.0, "theta0_u_deg": 0.5,
        "alpha": {"theta_deg": [0.0, 90.0, 180.0, 270.0], "value_arcsec": [1.0, -1.0, 0.5, -0.5],
                  "u_arcsec": [0.1, 0.1, 0.1, 0.1]},
        "beta": {"face": [1, 2, 3, 4], "value_arcsec": [0.5, -0.2, -0.6, 0.3]},
        "selfcal": {"theta_deg": [0.0, 90.0, 180.0, 270.0], "value_arcsec": [1.0, -1.0, 0.5, -0.5],
                    "unobservable_harmonics": [2]},
        "named": ["graduation_error"], "ambiguous": [["a", "b"]], "unexplained": False,
        "residual_before_arcsec": 0.5, "residual_after_arcsec": 0.1}
_PROJECT = {"format": "bench-results", "version": 1, "dataset": "d", "source": "twin", "bench": {}, "notes": [],
            "eccentricity_um": 7.0, "eccentricity_u_um": 0.1, "eccentricity_phase_deg": 10.0,
            "eccentricity_phase_u_deg": 0.5,
            "encoder_error_arcsec": {"theta_deg": [0.0, 90.0, 180.0, 270.0], "value": [1.0, -1.0, 0.5, -0.5],
                                     "u": [0.1, 0.1, 0.1, 0.1]},
            "polygon_pitch_deviation_arcsec": [0.5, -0.2, -0.6, 0.3],
            "polygon_pitch_deviation_u_arcsec": [0.1, 0.1, 0.1, 0.1],
            "identified_effects": [{"name": "graduation_error"}], "ambiguous": [], "unexplained": False,
            "residual_before": {"rms_arcsec": 0.7}, "residual_after": {"rms_arcsec": 0.06}}


@FUZZ
@given(data=st.data())
def test_score_results_raise_only_input_error_and_print_strict_json(truth, tmp_path_factory, data):
    """A mutated results file (minimal or project format), read as ``score`` reads it and scored
    against the hand-made truth: InputError or a score whose --json is strict JSON."""
    from benchtwin.app.score import public, read_results, read_truth, score_results
    from benchtwin.cli import InputError, _json_line

    raw = data.draw(st.one_of(mutated(_MIN), mutated(_PROJECT), _value))
    p = tmp_path_factory.getbasetemp() / f"r-{uuid.uuid4().hex}.json"
    try:
        text = json.dumps(raw)
    except ValueError:
        return
    if data.draw(st.booleans()):  # a number as a hostile file may spell it
        text = text.replace("7.0", data.draw(st.sampled_from(["1" + "0" * 400, "1e400", "7_0", "NaN", "-Infinity",
                                                                "7.0, \"e_um\": 8"])), 1)
    p.write_text(text, encoding="utf-8")
    try:
        res = read_results(p)
        s = score_results(res, read_truth(truth / "truth", truth))
    except InputError:
        return
    _strict(_json_line(public(s)))


@pytest.fixture(scope="module")
def truth(tmp_path_factory):
    return write_truth(tmp_path_factory.mktemp("truth"))


@FUZZ
@given(data=st.data())
def test_score_truth_files_raise_only_input_error(tmp_path_factory, data):
    """A truth folder with a mutated bench.json / hidden.json / expected.json or a fuzzed table."""
    from benchtwin.app.score import read_truth
    from benchtwin.cli import InputError

    ds = write_truth(tmp_path_factory.getbasetemp() / f"t-{uuid.uuid4().hex}")
    name = data.draw(st.sampled_from(["bench.json", "hidden.json", "expected.json", "polygon_beta.csv", "polygon.csv",
                                      "encoder_error.csv"]))
    p = ds / "truth" / name
    if name.endswith(".json"):
        base = json.loads(p.read_text()) if p.exists() else {"expect": ["x"], "accept": ["named"], "why": "w"}
        obj = data.draw(st.one_of(mutated(base), _value))
        try:
            p.write_text(json.dumps(obj), encoding="utf-8")
        except ValueError:
            return
    else:
        lines = p.read_text().splitlines()
        head = data.draw(st.sampled_from([lines[0], "face,face", "theta_deg", "x,y"]))
        rows = data.draw(st.lists(st.lists(_cells, min_size=1, max_size=3), max_size=4))
        p.write_text(head + "\n" + "\n".join(lines[1:3] + [",".join(r) for r in rows]) + "\n", encoding="utf-8")
    try:
        read_truth(ds / "truth", ds)
    except InputError:
        pass


@FUZZ
@given(meta=mutated({"format": "benchtwin-suite", "suite_version": 1, "size": "small", "seed": 11, "blind": False,
                     "datasets": ["jia2019", "graduation_error"],
                     "entries": [{"name": "jia2019", "category": "paper"},
                                 {"name": "graduation_error", "category": "hidden"}]}))
def test_suite_file_raises_only_input_error(tmp_path_factory, meta):
    from benchtwin.app.suite import SUITE_FORMAT, SUITE_VERSION, open_suite
    from benchtwin.cli import InputError

    d = tmp_path_factory.getbasetemp() / f"suite-{uuid.uuid4().hex}"
    for n in ("jia2019", "graduation_error"):
        (d / n).mkdir(parents=True)
    meta = {**meta, "format": SUITE_FORMAT} if meta.get("format") == "benchtwin-suite" else meta
    if meta.get("suite_version") == 1:
        meta["suite_version"] = SUITE_VERSION
    try:
        (d / "suite.json").write_text(json.dumps(meta), encoding="utf-8")
    except ValueError:
        return
    try:
        open_suite(d)
    except InputError:
        pass


# ============================================================================ certificate


_RES = {"format": "bench-results", "version": 1, "dataset": "nowhere", "source": "external", "bench": {}, "notes": [],
        "encoder_error_arcsec": {"theta_deg": [0.0, 90.0, 180.0, 270.0], "value": [0.1, -0.2, 0.3, -0.2],
                                 "u": [0.05] * 4}}


@FUZZ
@given(data=st.data())
def test_lab_file_raises_only_certificate_input_error_and_gives_a_valid_certificate(data):
    """A mutated lab file: CertificateInputError, or a certificate that validates (a lab file that
    passes but breaks the DCC schema would be an internal error, exit 1)."""
    from benchtwin.app.certificate import CertificateInputError, build_certificate, parse_lab, validation_errors

    base = tomllib.loads(LAB.read_text(encoding="utf-8"))
    raw = data.draw(mutated(base))
    if data.draw(st.booleans()):  # a control character or an over-long text somewhere
        raw["item"]["serial"] = data.draw(st.sampled_from(["SN\x07", "SN\x1b[31m", "x" * 500, "", " ", "\u00e9"]))
    try:
        lab = parse_lab(raw, "lab.toml", "2026-12-05")
    except CertificateInputError:
        return
    assert validation_errors(build_certificate(copy.deepcopy(_RES), lab, None)) == []
    env = lab.environment
    assert all(math.isfinite(v) for v in env.values())


_TOML_VALUES = ["5", "-1", "9223372036854775807", "9223372036854775808", "1e400", "inf", "nan", "true", "[1, 2]",
                "{ a = 1 }", '"\\u0007"', '"\\u0000x"', '"\\u001b[31m"', '""', "2026-13-01", "1979-05-27T07:32:00Z",
                '"x"', '"' + "y" * 300 + '"', "[[1]]", "{}"]


@FUZZ
@given(data=st.data())
def test_lab_file_text_raises_only_certificate_input_error_and_gives_a_valid_certificate(tmp_path_factory, data):
    """The example lab file with one to three values replaced as a user might type them (or the text
    cut or garbled): CertificateInputError, or a certificate that validates."""
    from benchtwin.app.certificate import CertificateInputError, build_certificate, load_lab, validation_errors

    lines = LAB.read_text(encoding="utf-8").splitlines()
    keyed = [i for i, line in enumerate(lines) if "=" in line and not line.lstrip().startswith("#")]
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.sampled_from(keyed))
        key = lines[i].split("=", 1)[0]
        lines[i] = f"{key}= {data.draw(st.one_of(st.sampled_from(_TOML_VALUES), st.text(max_size=8)))}"
    text = "\n".join(lines)
    if data.draw(st.integers(0, 4)) == 0:
        text = text[: data.draw(st.integers(0, len(text)))]
    p = tmp_path_factory.getbasetemp() / "fuzz_lab.toml"
    p.write_text(text, encoding="utf-8")
    try:
        lab = load_lab(p, "2026-12-05")
    except CertificateInputError:
        return
    assert validation_errors(build_certificate(copy.deepcopy(_RES), lab, None)) == []


def _spell(data, text: str) -> str:
    """A number of ``text`` as a hostile file may spell it (a 401-digit integer, an overflow, a
    separator, a constant JSON does not have, a key given twice), sometimes."""
    how = data.draw(st.sampled_from(["as is", "u", "en_max"]))
    spelling = data.draw(st.sampled_from(["1" + "0" * 400, "1e400", "0_05", "NaN", "-Infinity", "1e-320",
                                          "0.05, \"u\": [1]"]))
    if how == "u" and "0.05" in text:  # a standard uncertainty of the encoder error
        return text.replace("0.05", spelling, 1)
    if how == "en_max" and text.startswith("{") and text.endswith("}") and text != "{}":
        return text[:-1] + f', "en_max": {spelling}}}'  # a number the format types (analysis.results)
    return text


@FUZZ
@given(res=mutated({**_RES, "budget_summary": {"k": 2.0, "p": 0.95}}), data=st.data())
def test_certificate_results_raise_only_certificate_input_error(tmp_path_factory, res, data):
    from benchtwin.app.certificate import CertificateInputError, build_certificate, load_lab, load_results

    p = tmp_path_factory.getbasetemp() / "fuzz_results.json"
    try:
        p.write_text(_spell(data, json.dumps(res)), encoding="utf-8")
    except ValueError:
        return
    try:
        r = load_results(p)
        build_certificate(r, load_lab(None, "2026-12-05"), None)
    except CertificateInputError:
        pass


# ============================================================================ compare


@FUZZ
@given(res=mutated({**{k: v for k, v in _PROJECT.items()  # a results.json the format's reader accepts
                        if k not in ("residual_before", "residual_after", "identified_effects")},
                     "encoder_error_arcsec": {"theta_deg": [0.0, 90.0, 180.0, 270.0], "value": [1.0, -1.0, 0.5, -0.5],
                                              "u": [0.05] * 4}}),
       data=st.data())
def test_compare_results_raise_only_its_error(tmp_path_factory, res, data):
    from benchtwin.app.compare import CompareInputError, _results_of, compare_results

    d = tmp_path_factory.getbasetemp() / f"cmp-{uuid.uuid4().hex}"
    d.mkdir()
    try:
        (d / "results.json").write_text(_spell(data, json.dumps(res)), encoding="utf-8")
    except ValueError:
        return
    try:
        r = _results_of(d, d / "work")
    except CompareInputError:
        return
    compare_results(r, copy.deepcopy(_PROJECT))


# ============================================================================ study cache


@FUZZ
@given(entry=st.one_of(mutated({"outputs": {"a": 1.0, "b": float("nan")}, "elapsed_s": 0.1, "code": "v"}), _value),
       junk=st.sampled_from([None, "", "{", "[1, 2", "\x00", "{}", "1" + "0" * 400, "NaN"]))
def test_study_cache_entry_is_a_hit_or_a_miss_never_an_error(tmp_path_factory, entry, junk):
    from benchtwin.app.study.execution import _Cache, _entry_problem

    c = _Cache(tmp_path_factory.getbasetemp() / f"cache-{uuid.uuid4().hex}")
    key = uuid.uuid4().hex
    p = c.path(key)
    p.parent.mkdir(parents=True)
    try:
        p.write_text(junk if junk is not None else json.dumps(entry), encoding="utf-8")
    except ValueError:
        return
    got = c.get(key)
    assert got is None and len(c.notes) == 1 or got is not None and _entry_problem(got) is None and not c.notes
