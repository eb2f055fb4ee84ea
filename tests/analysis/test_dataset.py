"""Dataset format v1: round trips of every table (hypothesis), and broken datasets rejected with
messages naming file, row and column (issue 2)."""

from __future__ import annotations

import json
import math
import string
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchtwin.analysis.dataset import (
    TABLES,
    DatasetError,
    DatasetWriter,
    open_dataset,
    column_range,
    parse_table,
    table_to_csv,
)

from tests.support.fake_dataset import MANIFEST, make_dataset

def test_valid_dataset_round_trip(tmp_path):
    ds = open_dataset(make_dataset(tmp_path / "ds"))
    checked = ds.validate()
    assert "60 CCD images" in checked
    assert ds.table("polygon")["start_face"].dtype == np.int64
    assert ds.table("radial_motion")["probe_top_um"][6] == math.sin(math.radians(90.0))
    frames = list(ds.ccd_frames())
    assert frames[1][0] == 1 and frames[1][2].shape == (12, 16)


def test_analysis_runs_without_truth_folder(tmp_path):
    """Truth is never needed to read a dataset (the twin writes it; the reader never opens it)."""
    root = make_dataset(tmp_path / "ds")
    w = DatasetWriter(root, MANIFEST, prepared=True)  # adds truth/ to a finished dataset (the folder is not empty)
    w.write_truth_json("params.json", {"e_um": 7.1})
    import shutil

    shutil.rmtree(root / "truth")
    assert open_dataset(root).validate()


def _rewrite(root: Path, name: str, fn) -> None:
    p = root / name
    p.write_text(fn(p.read_text()))


def _manifest_edit(fn):
    def edit(text):
        m = json.loads(text)
        fn(m)
        return json.dumps(m)
    return edit


# (what is broken, file, edit, words the message must contain)
BROKEN = [
    ("missing manifest", "manifest.json", None, ["manifest.json", "missing"]),
    ("manifest not json", "manifest.json", lambda t: t[:-5], ["manifest.json", "not valid JSON"]),
    ("wrong format", "manifest.json", _manifest_edit(lambda m: m.update(format="csv")), ["'format'", "bench-dataset"]),
    ("wrong version", "manifest.json", _manifest_edit(lambda m: m.update(version=2)), ["'version'"]),
    ("bad source", "manifest.json", _manifest_edit(lambda m: m.update(source="guess")), ["'source'"]),
    ("missing bench key", "manifest.json", _manifest_edit(lambda m: m["bench"].pop("L2_mm")), ["bench.L2_mm", "missing"]),
    ("bench key wrong type", "manifest.json", _manifest_edit(lambda m: m["bench"].update(polygon_faces="four")), ["bench.polygon_faces", "int"]),
    ("ccd tangential", "manifest.json", _manifest_edit(lambda m: m["ccd"].update(tangential="+z")), ["ccd.tangential"]),
    ("missing column", "radial_motion.csv", lambda t: t.replace("probe_bottom_um", "probe_bot_um"), ["radial_motion.csv", "row 1", "probe_bottom_um"]),
    ("not a number", "radial_motion.csv", lambda t: t.replace("0.49999999999999994", "abc", 1), ["radial_motion.csv", "row ", "probe_top_um", "abc"]),
    ("nan", "radial_motion.csv", lambda t: t.replace("0.49999999999999994", "nan", 1), ["radial_motion.csv", "finite", "nan"]),
    ("inf", "polygon.csv", lambda t: t.replace(",5.0\n", ",inf\n", 1), ["polygon.csv", "row 2", "'t_s'", "finite"]),
    ("short row", "polygon.csv", lambda t: t.replace(",5.0\n", "\n", 1), ["polygon.csv", "row 2", "expected 6 fields"]),
    ("face out of range", "polygon.csv", lambda t: t.replace("0.0,4,4,", "0.0,5,4,", 1), ["polygon.csv", "start_face", "1…4"]),
    ("step zero", "polygon.csv", lambda t: t.replace("0.0,1,1,", "0.0,1,0,", 1), ["polygon.csv", "'step'", "got 0"]),
    ("step not int", "polygon.csv", lambda t: t.replace("0.0,1,1,", "0.0,1,1.5,", 1), ["polygon.csv", "'step'", "integer"]),
    ("duplicated reading", "polygon.csv", lambda t: t + t.splitlines()[1] + "\n", ["polygon.csv", "rows 2 and 18", "duplicated"]),
    ("head out of range", "heads.csv", lambda t: t.replace("0.0,2,0.3", "0.0,3,0.3"), ["heads.csv", "'head'", "1…2"]),
    ("image missing", "ccd/img_001.png", None, ["index.csv", "row 3", "img_001.png", "missing"]),
    ("image unreadable", "ccd/img_001.png", "garbage", ["img_001.png", "not a readable image"]),
    ("image colour", "ccd/img_001.png", "colour", ["img_001.png", "greyscale"]),
    ("empty table", "heads.csv", lambda t: "", ["heads.csv", "empty"]),
]


@pytest.mark.parametrize("what,name,edit,words", BROKEN, ids=[b[0] for b in BROKEN])
def test_broken_datasets_are_rejected_clearly(what, name, edit, words, tmp_path):
    root = make_dataset(tmp_path / "ds")
    p = root / name
    if edit is None:
        p.unlink()
    elif edit == "garbage":
        p.write_bytes(b"not a png")
    elif edit == "colour":
        import cv2

        cv2.imwrite(str(p), np.zeros((12, 16, 3), np.uint8))
    else:
        _rewrite(root, name, edit)
    with pytest.raises(DatasetError) as err:
        open_dataset(root).validate()
    msg = str(err.value)
    for w in words:
        assert w in msg, f"{what}: {w!r} not in {msg!r}"


# ----------------------------------------------------------------- property-based round trips

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
_strats = {int: st.integers(min_value=-(2**62), max_value=2**62), float: finite,
           str: st.text(alphabet=string.ascii_letters + string.digits + "_-. ,\"", min_size=1, max_size=12).map(str.strip).filter(bool)}


@st.composite
def table_columns(draw, name):
    spec = TABLES[name]
    n = draw(st.integers(min_value=0, max_value=20))
    cols = {}
    for col, typ in {**spec.required, **{k: v for k, v in spec.optional.items() if draw(st.booleans())}}.items():
        # values within the column's range or enumeration (the reader enforces them, issue #13)
        rng = column_range(spec, col)
        if col in spec.choices:
            strat = st.sampled_from(spec.choices[col])
        elif rng is not None and typ is int:
            strat = st.integers(min_value=int(rng[0]), max_value=int(rng[1]))
        elif rng is not None:
            strat = st.floats(min_value=rng[0], max_value=rng[1], allow_nan=False, width=64)
        else:
            strat = _strats[typ]
        cols[col] = draw(st.lists(strat, min_size=n, max_size=n))
    return cols


@pytest.mark.parametrize("name", sorted(TABLES))
@settings(max_examples=60, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(data=st.data())
def test_every_table_round_trips(name, data):
    cols = data.draw(table_columns(name))
    text = table_to_csv(cols).decode()
    spec = TABLES[name]
    # duplicates are legitimately rejected; the round trip is about values
    keys = [k for k in spec.key if k in cols]
    rows = list(zip(*(cols[k] for k in keys)))
    if len(set(rows)) != len(rows):
        with pytest.raises(DatasetError, match="duplicated"):
            parse_table(text, name, f"{name}.csv")
        return
    back = parse_table(text, name, f"{name}.csv")
    assert list(back) == list(cols)
    for c, vals in cols.items():
        assert list(back[c]) == list(vals), c  # exact: floats are written with repr


def test_truth_and_extra_columns_are_allowed(tmp_path):
    root = make_dataset(tmp_path / "ds")
    _rewrite(root, "heads.csv", lambda t: t.replace("delta_arcsec", "delta_arcsec,note").replace("\n", ",x\n").replace("note,x", "note"))
    assert open_dataset(root).table("heads")["note"][0] == "x"


def test_repeated_ccd_sweeps_share_angles_not_within_a_sweep(tmp_path):
    """ccd/index.csv's optional ``sweep`` column (procedure.ccd_reps): the same angle once per sweep."""
    root = make_dataset(tmp_path / "ds")
    th = [12.0 * (k % 30) for k in range(60)]   # two sweeps of 30 frames over the turn (the 60 images)
    idx = {"k": list(range(60)), "theta_deg": th, "file": [f"img_{k:03d}.png" for k in range(60)],
           "theta_read_deg": [t + 0.0001 for t in th]}
    (root / "ccd" / "index.csv").write_bytes(table_to_csv(dict(idx, sweep=[k // 30 for k in range(60)])))
    ds = open_dataset(root)
    assert "60 CCD images" in ds.validate()
    assert list(ds.table("ccd/index")["sweep"]) == [k // 30 for k in range(60)]
    (root / "ccd" / "index.csv").write_bytes(table_to_csv(dict(idx, sweep=[0] * 60)))
    with pytest.raises(DatasetError, match="rows 2 and 32: two frames of sweep 0 at the same angle"):
        open_dataset(root).validate()
    (root / "ccd" / "index.csv").write_bytes(table_to_csv(idx))   # no sweep column: one sweep
    with pytest.raises(DatasetError, match="rows 2 and 32: two frames at the same angle"):
        open_dataset(root).validate()
