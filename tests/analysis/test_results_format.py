"""results.json's documented format (analysis/results.py, docs/results-format.md) and its validator.

- the page is the one generated from the typed sections (they cannot drift apart);
- hypothesis: objects drawn from the typed sections themselves are valid and survive a JSON round trip
  unchanged; one key of such an object made wrong (a wrong type, a required key dropped, a
  non-finite number) is rejected with a ResultsError naming exactly that key;
- ``benchtwin validate RESULTS.json`` accepts a valid file and exits 2 on a broken one, naming the key.
The pipeline's own results.json is checked in tests/analysis/test_pipeline.py (test_results_json_follows_the_format).
"""

from __future__ import annotations

import json
import math
import re
import types
import typing
from pathlib import Path
from typing import Any, Literal, Union

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchtwin.analysis import results as R

ROOT = Path(__file__).resolve().parents[2]
SETTINGS = settings(max_examples=40, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def test_docs_page_is_the_generated_one():
    page = (ROOT / "docs" / "results-format.md").read_text(encoding="utf-8")
    assert page == R.results_format_markdown() + "\n", "regenerate: python -c 'from benchtwin.analysis.results " \
                                                       "import results_format_markdown as m; print(m())' > docs/results-format.md"


def test_every_key_has_a_unit_and_a_meaning():
    def walk(td, at):
        for k, tp in R._hints(td).items():
            t_, key = R._strip(tp)
            assert key is not None and key.doc, f"{at}{k}: no Key(unit, doc)"
            inner = typing.get_args(t_)[0] if typing.get_origin(t_) is list and typing.get_args(t_) else t_
            if R._is_typeddict(inner):
                walk(inner, f"{at}{k}.")
    walk(R.BenchResults, "")
    walk(R.ErrorCurveResults, "")


# ---------------------------------------------------------------------------------------------- strategies


_text = st.text(alphabet="abcxyz_ .-", max_size=8)


def _strategy(tp: Any, depth: int = 0) -> st.SearchStrategy:
    """Valid values of a schema type (the writer's JSON types: finite numbers or null where allowed)."""
    tp, _ = R._strip(tp)
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any:
        return st.one_of(st.none(), st.integers(-5, 5), _text)
    if tp is type(None):
        return st.none()
    if tp is float:
        return st.floats(allow_nan=False, allow_infinity=False, width=64)
    if tp is int:
        return st.integers(-(2**40), 2**40)
    if tp is str:
        return _text
    if tp is bool:
        return st.booleans()
    if origin is Literal:
        return st.sampled_from(args)
    if origin in (Union, types.UnionType):  # (a numpy array is the in-memory form of a list: not in a file)
        return st.one_of(*[_strategy(a, depth) for a in args if a is not np.ndarray])
    if origin is list:
        return st.lists(_strategy(args[0], depth + 1), max_size=2 if depth < 2 else 0)
    if origin is dict or tp is dict:
        return st.dictionaries(_text, _strategy(args[1], depth + 1) if args else st.none(), max_size=2 if depth < 2 else 0)
    assert R._is_typeddict(tp), tp
    hints = R._hints(tp)
    req = {k: _strategy(hints[k], depth + 1) for k in tp.__required_keys__}
    opt = {k: _strategy(hints[k], depth + 1) for k in tp.__optional_keys__}
    return st.fixed_dictionaries(req, optional=opt if depth < 3 else {})


RESULTS = st.one_of(_strategy(R.BenchResults), _strategy(R.ErrorCurveResults))


def _described_paths(obj: Any, td: type, at: str = "") -> list[tuple[str, Any, Any, type, str]]:
    """(dotted key, its container, its key in it, its schema type, required?) of every described key present."""
    out = []
    hints = R._hints(td)
    for k, v in obj.items():
        if k not in hints:
            continue
        t_, _ = R._strip(hints[k])
        name = f"{at}.{k}" if at else k
        out.append((name, obj, k, t_, k in td.__required_keys__))
        inner = t_
        if R._is_typeddict(inner) and isinstance(v, dict):
            out += _described_paths(v, inner, name)
        elif typing.get_origin(inner) is list and R._is_typeddict(typing.get_args(inner)[0]):
            for i, x in enumerate(v):
                out += _described_paths(x, typing.get_args(inner)[0], f"{name}[{i}]")
    return out


def _schema_of(obj: dict) -> type:
    return R.ErrorCurveResults if obj.get("kind") == "error-curve" else R.BenchResults


def _accepts(tp: Any, v: Any) -> bool:
    try:
        R._check(v, tp, "x", "t")
        return True
    except R.ResultsError:
        return False


# ---------------------------------------------------------------------------------------------- properties


@SETTINGS
@given(RESULTS)
def test_drawn_results_are_valid_and_round_trip(obj):
    assert R.validate_results(obj) is obj
    text = json.dumps(obj, indent=1, sort_keys=True) + "\n"
    back = json.loads(text)
    assert back == obj
    R.validate_results(back)
    assert json.dumps(back, indent=1, sort_keys=True) + "\n" == text


WRONG = [None, "text", 1.5, 7, True, [], {}, [1.0, "x"], math.inf, math.nan]


@SETTINGS
@given(RESULTS, st.data())
def test_one_wrong_key_is_named(obj, data):
    paths = _described_paths(obj, _schema_of(obj))
    name, holder, key, tp, required = data.draw(st.sampled_from(paths))
    if name in ("format", "version", "kind"):  # they select the schema; checked first, by name
        holder[key] = "other"
        with pytest.raises(R.ResultsError, match=re.escape(f"key '{name}'")):
            R.validate_results(obj)
        return
    if required and data.draw(st.booleans()):
        del holder[key]
        with pytest.raises(R.ResultsError, match=re.escape(f"key '{name}' is missing")):
            R.validate_results(obj)
        return
    bad = [w for w in WRONG if not _accepts(tp, w)]
    if not bad:  # an `any value` key: nothing is wrong for it
        return
    holder[key] = data.draw(st.sampled_from(bad))
    with pytest.raises(R.ResultsError) as ei:
        R.validate_results(obj)
    msg = str(ei.value)
    # the key named is the changed one (or, for a list/object, one of its elements)
    assert f"key '{name}" in msg and "expected" in msg, msg


def test_validator_messages_name_file_key_and_expectation():
    rb = {k: 0.1 for k in ("rms_arcsec", "pv_arcsec", "max_abs_arcsec", "fraction_of_error", "pv_ratio",
                           "measured_pv_arcsec", "measured_rms_arcsec")}
    rb.update(n_points=23, note="", rms_arcsec="0.3")
    obj = {"format": "bench-results", "version": 1, "dataset": "d", "source": "twin", "bench": {}, "notes": [],
           "residual_before": rb}
    with pytest.raises(R.ResultsError, match=r"^f\.json: key 'residual_before\.rms_arcsec': expected a number or "
                                             r"null \(arcsec\), got '0\.3'"):
        R.validate_results(obj, "f.json")
    obj["residual_before"] = {}
    with pytest.raises(R.ResultsError, match="key 'residual_before.fraction_of_error' is missing"):
        R.validate_results(obj, "f.json")
    with pytest.raises(R.ResultsError, match="key 'format'"):
        R.validate_results({"format": "bench-result", "version": 1})


def test_validate_command_exit_codes(tmp_path, capsys):
    from benchtwin.cli import main

    good = {"format": "bench-results", "version": 1, "dataset": "d", "source": "twin", "bench": {"L1_mm": 6.81},
            "notes": [], "eccentricity_um": 7.1}
    p = tmp_path / "results.json"
    p.write_text(json.dumps(good))
    assert main(["validate", str(p)]) == 0
    assert "valid results" in capsys.readouterr().out
    good["bench"]["L1_mm"] = "6.81 mm"
    p.write_text(json.dumps(good))
    assert main(["validate", str(p)]) == 2
    assert "key 'bench.L1_mm': expected a number (mm)" in capsys.readouterr().err


def test_error_curve_results_round_trip(tmp_path):
    """analyze / close-loop on an imported curve (both directions, a full turn) write a results.json
    that reads back valid and re-serialises to the same bytes. (Bench datasets: tests/analysis/test_pipeline.py.)"""
    from benchtwin.cli import main

    th = np.arange(0.0, 360.0, 15.0)
    fwd = 1.2 * np.sin(np.deg2rad(2 * th) + 0.3) + 0.4
    rows = "".join(f"{float(a)!r},{float(f)!r},{float(f) - 0.3!r}\n" for a, f in zip(th, fwd))
    table = tmp_path / "t.csv"
    table.write_text("angle,fwd,rev\n" + rows)
    ds = tmp_path / "ds"
    assert main(["import", str(table), "-o", str(ds), "--angle", "angle", "--error", "fwd", "--reverse", "rev",
                 "--quiet"]) == 0
    for cmd in ("analyze", "close-loop"):
        out = tmp_path / cmd
        assert main([cmd, str(ds), "-o", str(out), "--quiet"]) == 0
        p = out / "results.json"
        res = R.read_results(p)
        assert res["kind"] == "error-curve"
        assert json.dumps(res, indent=1, sort_keys=True) + "\n" == p.read_text(encoding="utf-8")
