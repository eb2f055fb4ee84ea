"""Issue 31, the newer readers: every example of the issue (and of the brief that followed it) as a
regression test. Each input below was an internal error (exit 1), a hang, or a silent wrong result
before the readers of ``import``, ``score``/``score-suite``, ``certificate --lab``,
``calibrate-twin``/``compare`` and the study cache went through ``benchtwin.schema``; each must now
be exit 2 naming the file, the row or key and what was expected (docs/reliability.md, "Issue 31").
"""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path

import pytest

from benchtwin.cli import main
from tests.support.known_truth import E_UM
from tests.support.readers import LAB
from tests.support.readers import strict_json as _strict
from tests.support.study import BASIC, counting_point
from tests.support.study import write_study as _write

BIG = "1" + "0" * 400  # a 401-digit number


def _bounded(fn, *args, **kw):
    """``fn(*args, **kw)`` in a thread: a reader that blocks opening a FIFO fails the test instead
    of hanging the suite. The bound is a hang detector, not a timing requirement (a refused FIFO
    returns at once; the bound is generous for a loaded machine)."""
    box: dict = {}

    def run():
        try:
            box["value"] = fn(*args, **kw)
        except BaseException as exc:  # noqa: BLE001 - re-raised in the test's thread
            box["error"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(HANG_S)
    if t.is_alive():
        pytest.fail(f"{getattr(fn, '__name__', fn)}{args!r} blocked for {HANG_S} s (did it open a FIFO?)")
    if "error" in box:
        raise box["error"]
    return box["value"]


HANG_S = 60


def _cli(args: list[str], capsys) -> tuple[int, dict]:
    """Run the CLI with --json (bounded: see ``_bounded``); returns (exit code, the one JSON object
    it printed)."""
    rc = _bounded(main, [*args, "--json"])
    cap = capsys.readouterr()
    return rc, _strict((cap.out or cap.err).strip().splitlines()[-1])


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


# ============================================================================ import


def _table(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "t.csv"
    p.write_text(text, encoding="utf-8")
    return p


def _import(tmp_path, capsys, table: Path, *extra: str):
    return _cli(["import", str(table), "-o", str(tmp_path / "ds"), "--angle", "a", "--error", "e", *extra], capsys)


def test_import_refuses_1_000(tmp_path, capsys):
    """`1_000` became 1000″ (Python's float() takes the separator)."""
    rc, out = _import(tmp_path, capsys, _table(tmp_path, "a,e\n0,1_000\n90,2\n180,3\n"))
    assert rc == 2 and "row 2, column 'e'" in out["error"] and "1_000" in out["error"]
    assert not (tmp_path / "ds").exists()


def test_import_refuses_a_column_named_twice(tmp_path, capsys):
    """A repeated key silently won: the first of two 'e' columns was taken."""
    rc, out = _import(tmp_path, capsys, _table(tmp_path, "a,e,e\n0,1,5\n90,2,5\n180,3,5\n"))
    assert rc == 2 and "column 'e' (--error) appears 2 times" in out["error"]


def test_import_refuses_what_validate_refuses_before_writing(tmp_path, capsys):
    """import wrote angles of 7200.5°, which its own validate then rejected."""
    rc, out = _import(tmp_path, capsys, _table(tmp_path, "a,e\n0,1\n90,2\n7200.5,3\n"))
    assert rc == 2 and "row 4, column 'a': expected -360…720 deg, got 7200.5" in out["error"]
    assert not (tmp_path / "ds").exists()
    # an error of 12° (43 200″) is beyond the ±36 000″ of error_curve.csv: named in the table's unit
    rc, out = _import(tmp_path, capsys, _table(tmp_path, "a,e\n0,1\n90,12\n180,3\n"), "--error-unit", "deg")
    assert rc == 2 and "row 3, column 'e'" in out["error"] and "(-10…10 deg)" in out["error"]
    # at the edge of the ranges: written, and validate accepts it
    rc, out = _import(tmp_path, capsys, _table(tmp_path, "a,e\n-350,10\n90,-10\n720.0,3\n"), "--error-unit", "deg")
    assert rc == 0, out
    rc, out = _cli(["validate", str(tmp_path / "ds")], capsys)
    assert rc == 0, out


def test_import_refuses_a_fifo_without_blocking(tmp_path, capsys):
    rc, out = _import(tmp_path, capsys, _fifo(tmp_path / "t.csv"))
    assert rc == 2 and "not a regular file" in out["error"]


# ============================================================================ score


def _results(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_score_csv_refuses_6_9(truth, tmp_path, capsys):
    """`6_9` in a minimal results CSV scored as e = 69 µm."""
    r = _results(tmp_path, "r.csv", "quantity,key,value,u\ne_um,,6_9,0.1\n")
    rc, out = _cli(["score", str(r), str(truth)], capsys)
    assert rc == 2 and "row 2: column 'value'" in out["error"] and "6_9" in out["error"]


@pytest.mark.parametrize("text, needle", [
    ("quantity,key,value,u\ne_um,,7.1,0.1\ne_um,,9.9,0.1\n", "rows 2 and 3: 'e_um' given twice"),
    ("quantity,key,value,u\nalpha_arcsec,0,1,\nalpha_arcsec,90,1,\nalpha_arcsec,360,2,\n", "rows 2 and 4"),
    ("quantity,key,value,u\nnamed,,graduation_error,\nnamed,,graduation_error,\n", "rows 2 and 3"),
])
def test_score_csv_refuses_a_repeated_key(truth, tmp_path, capsys, text, needle):
    """A repeated key silently won (the last row)."""
    rc, out = _cli(["score", str(_results(tmp_path, "r.csv", text)), str(truth)], capsys)
    assert rc == 2 and needle in out["error"]


def test_score_json_refuses_a_repeated_key(truth, tmp_path, capsys):
    r = _results(tmp_path, "r.json", '{"format": "benchtwin-min-results", "e_um": 7.1, "e_um": 69}')
    rc, out = _cli(["score", str(r), str(truth)], capsys)
    assert rc == 2 and "key 'e_um' appears twice" in out["error"]


@pytest.mark.parametrize("body, needle", [
    (f'{{"format": "benchtwin-min-results", "e_um": {BIG}}}', "outside the 64-bit range"),
    (f'{{"format": "benchtwin-min-results", "e_um": {BIG}.0}}', "overflows a double"),
    ('{"format": "benchtwin-min-results", "e_um": 1e400}', "overflows a double"),
    ('{"format": "benchtwin-min-results", "e_um": 1e30}', "e_um: expected -10000…10000"),
    ('{"format": "benchtwin-min-results", "alpha": {"theta_deg": [], "value_arcsec": []}}', "non-empty list"),
    ('{"format": "benchtwin-min-results", "beta": {"face": [], "value_arcsec": []}}', "non-empty list"),
    ('{"format": "benchtwin-min-results", "beta": {"face": [1, 1.5], "value_arcsec": [0, 0]}}', "face[1]"),
    ('{"format": "benchtwin-min-results", "alpha": {"theta_deg": [0, 360], "value_arcsec": [0, 1]}}',
     "the same point"),
    ('{"format": "benchtwin-min-results", "selfcal": {"theta_deg": [0, 90], "value_arcsec": [0, 1], '
     '"unobservable_harmonics": [2.5]}}', "unobservable_harmonics[0]"),
    ('{"format": "bench-results", "version": 1, "dataset": "d", "source": "twin", "bench": {}, "notes": [], '
     '"eccentricity_um": "7"}', "key 'eccentricity_um': expected"),
])
def test_score_bad_numbers_and_empty_lists_are_exit_2(truth, tmp_path, capsys, body, needle):
    """A 401-digit number or empty lists were exit 1 (OverflowError, max() of an empty array)."""
    rc, out = _cli(["score", str(_results(tmp_path, "r.json", body)), str(truth)], capsys)
    assert rc == 2 and out["kind"] == "input" and needle in out["error"], out


def test_score_json_is_valid_json_with_a_note_for_a_non_finite_number(truth, tmp_path, capsys):
    """`score --json` printed -Infinity (z = error / u with a subnormal u)."""
    r = _results(tmp_path, "r.json", json.dumps({"format": "benchtwin-min-results", "e_um": E_UM - 0.1,
                                                 "e_u_um": 5e-324}))
    rc, out = _cli(["score", str(r), str(truth)], capsys)  # _cli parses strictly: no -Infinity
    assert rc == 0 and out["e_z"] is None and out["e_error_um"] == pytest.approx(-0.1)
    assert any(n.startswith("e_z: -inf") for n in out["notes"])


def test_score_results_fifo_and_truth_fifo_do_not_block(truth, tmp_path, capsys):
    rc, out = _cli(["score", str(_fifo(tmp_path / "r.json")), str(truth)], capsys)
    assert rc == 2 and "not a regular file" in out["error"]
    r = _results(tmp_path, "ok.json", '{"format": "benchtwin-min-results", "e_um": 7.1}')
    (truth / "truth" / "hidden.json").unlink()
    _fifo(truth / "truth" / "hidden.json")
    rc, out = _cli(["score", str(r), str(truth)], capsys)
    assert rc == 2 and "hidden.json" in out["error"] and "not a regular file" in out["error"]


@pytest.mark.parametrize("name, text, needle", [
    ("bench.json", '{"disk_eccentricity_m": "7e-6"}', "disk_eccentricity_m"),
    ("hidden.json", '{"effects": ["graduation_error"]}', "key 'effects'"),
    ("hidden.json", "[]", "expected a JSON object"),
    ("polygon_beta.csv", "face,beta_arcsec\n1,0.5\n2,x\n", "column 'beta_arcsec'"),
    ("encoder_error.csv", "theta_deg\n0\n", "missing column 'alpha_arcsec'"),
])
def test_score_bad_truth_files_are_exit_2(truth, tmp_path, capsys, name, text, needle):
    (truth / "truth" / name).write_text(text, encoding="utf-8")
    r = _results(tmp_path, "ok.json", '{"format": "benchtwin-min-results", "e_um": 7.1}')
    rc, out = _cli(["score", str(r), str(truth)], capsys)
    assert rc == 2 and name in out["error"] and needle in out["error"], out


def test_score_floor_columns_are_checked(truth, tmp_path, capsys):
    """The floor reads the dataset's and the truth's polygon.csv by column: a missing or
    non-numeric one was a KeyError / TypeError (exit 1)."""
    (truth / "polygon.csv").write_text("theta_deg,ac_arcsec\n0,1\n90,x\n", encoding="utf-8")
    r = _results(tmp_path, "ok.json", '{"format": "benchtwin-min-results", "e_um": 7.1}')
    rc, out = _cli(["score", str(r), str(truth)], capsys)
    assert rc == 2 and "truth/polygon.csv" in out["error"] and "'ac_exact_arcsec'" in out["error"], out
    (truth / "truth" / "polygon.csv").write_text("theta_deg,alpha_arcsec,ac_exact_arcsec\n0,1,1\n90,2,2\n",
                                                 encoding="utf-8")
    rc, out = _cli(["score", str(r), str(truth)], capsys)
    assert rc == 2 and "ds/polygon.csv: column 'ac_arcsec'" in out["error"], out


def test_score_suite_refuses_a_suite_file_of_the_wrong_shape(tmp_path, capsys):
    (tmp_path / "suite").mkdir()
    (tmp_path / "res").mkdir()
    sj = tmp_path / "suite" / "suite.json"
    for meta, needle in (({"format": "benchtwin-suite", "datasets": "abc"}, "key 'datasets'"),
                         ({"format": "benchtwin-suite", "datasets": ["../../etc"], "blind": False, "size": "small",
                           "seed": 1}, "a folder name of the suite")):
        sj.write_text(json.dumps(meta), encoding="utf-8")
        rc, out = _cli(["score-suite", str(tmp_path / "res"), str(tmp_path / "suite")], capsys)
        assert rc == 2 and needle in out["error"], out


# ============================================================================ certificate --lab

# the lab file's examples need only a results.json that the certificate can state: a hand-made one
# (the format's reader checks it), so these tests do not simulate


def _results_json(tmp_path: Path, **extra) -> Path:
    th = [0.0, 90.0, 180.0, 270.0]
    res = {"format": "bench-results", "version": 1, "dataset": str(tmp_path / "nowhere"), "source": "external",
           "bench": {}, "notes": [],
           "encoder_error_arcsec": {"theta_deg": th, "value": [0.1, -0.2, 0.3, -0.2], "u": [0.05] * 4}, **extra}
    p = tmp_path / "results.json"
    p.write_text(json.dumps(res), encoding="utf-8")
    return p


def _lab(tmp_path: Path, old: str | None = None, new: str = "") -> Path:
    text = LAB.read_text(encoding="utf-8")
    if old is not None:
        assert old in text
        text = text.replace(old, new, 1)
    p = tmp_path / "lab.toml"
    p.write_text(text, encoding="utf-8")
    return p


def _cert(tmp_path, capsys, lab: Path | None, results: Path | None = None):
    args = ["certificate", str(results or _results_json(tmp_path)), "-o", str(tmp_path / "cert.xml")]
    return _cli(args + (["--lab", str(lab)] if lab is not None else []), capsys)


@pytest.mark.parametrize("old, new, needle", [
    # 9.2·10¹⁸ °C reached a schema-valid certificate
    ("temperature_degC = 20.1", "temperature_degC = 9223372036854775807", "key 'temperature_degC': expected -50…100"),
    ("relative_humidity_percent = 45.0", "relative_humidity_percent = 145.0", "expected 0…100 percent"),
    ("temperature_u_degC = 0.1", "temperature_u_degC = -0.1", "key 'temperature_u_degC'"),
    # a street given as a TOML table printed as a Python dict
    ('street = "Bundesallee"', 'street = { name = "Bundesallee" }', "[laboratory]: key 'street': expected a string"),
    # exit 1 (internal error) before
    ('role = "operator"', "role = 5", "key 'role': expected a string"),
    ('name = "B. Technician"', 'name = "B. Tech\\u0007nician"', "without control characters"),
    ('name = "B. Technician"', 'name = "B. Tech\\u0000nician"', "without control characters"),
    ('serial = "SN 0000-1234"', f'serial = "{"x" * 201}"', "key 'serial': expected 1…200 characters"),
    ("main_signer = true", 'main_signer = "yes"', "key 'main_signer': expected true or false"),
    ('code = "D-K-00000-01"', "code = 7", "key 'code': expected a string"),
    ("temperature_degC = 20.1", '"temp degC" = 20.1', "expected a name of ASCII letters"),
])
def test_certificate_refuses_a_bad_lab_file(tmp_path, capsys, old, new, needle):
    rc, out = _cert(tmp_path, capsys, _lab(tmp_path, old, new))
    assert rc == 2 and out["kind"] == "input" and needle in out["error"] and "lab.toml" in out["error"], out
    assert not (tmp_path / "cert.xml").exists()


def test_certificate_lab_fifo_does_not_hang(tmp_path, capsys):
    rc, out = _cert(tmp_path, capsys, _fifo(tmp_path / "lab.toml"))
    assert rc == 2 and "not a regular file" in out["error"]


def test_certificate_refuses_a_300_mb_lab_file_without_reading_it(tmp_path, capsys):
    lab = tmp_path / "lab.toml"
    with open(lab, "wb") as f:  # sparse: no 300 MB written to disk
        f.truncate(300 * 1024 * 1024)
    rc, out = _cert(tmp_path, capsys, lab)
    assert rc == 2 and "a lab file may have at most 1048576 bytes" in out["error"]


@pytest.mark.parametrize("body, needle", [
    (lambda p: p.read_text().replace('"value": [0.1,', f'"value": [{BIG},'), "outside the 64-bit range"),
    (lambda p: p.read_text().replace('"value": [0.1,', '"value": [1e6,'), "encoder_error_arcsec.value[0]: expected"),
    (lambda p: p.read_text()[:-1] + ', "budget_summary": {"k": 0.5}}', "'budget_summary.k': expected 1…100"),
    (lambda p: p.read_text()[:-1] + ', "version": 1}', "appears twice"),
])
def test_certificate_refuses_bad_results(tmp_path, capsys, body, needle):
    r = _results_json(tmp_path)
    r.write_text(body(r), encoding="utf-8")
    rc, out = _cert(tmp_path, capsys, None, r)
    assert rc == 2 and out["kind"] == "input" and needle in out["error"], out


def test_certificate_refuses_a_bad_environment_in_the_dataset_manifest(tmp_path, capsys):
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "manifest.json").write_text(json.dumps({"environment": {"temperature_degC": 1e9}}), encoding="utf-8")
    r = _results_json(tmp_path, dataset=str(ds))
    rc, out = _cert(tmp_path, capsys, None, r)
    assert rc == 2 and "manifest.json: environment" in out["error"] and "temperature_degC" in out["error"]


# ============================================================================ calibrate-twin, compare


@pytest.mark.parametrize("cmd", ["compare", "calibrate-twin"])
@pytest.mark.parametrize("body, needle", [
    (f'{{"format": "bench-results", "version": 1, "eccentricity_um": {BIG}}}', "outside the 64-bit range"),
    ('{"format": "bench-results", "version": 1, "version": 1}', "appears twice"),
])
def test_compare_and_calibrate_twin_read_results_strictly(tmp_path, capsys, cmd, body, needle):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "results.json").write_text(body, encoding="utf-8")
    args = {"compare": ["compare", str(tmp_path / "a"), str(tmp_path / "a")],
            "calibrate-twin": ["calibrate-twin", str(tmp_path / "a"), "-o", str(tmp_path / "s.toml")]}[cmd]
    rc, out = _cli(args, capsys)
    assert rc == 2 and needle in out["error"], out


# ============================================================================ study cache


def test_a_study_cache_entry_of_braces_is_recomputed_with_a_note(tmp_path, monkeypatch):
    """A cache entry of `{}` was exit 1 (KeyError 'outputs'); a foreign or corrupt entry is now a
    miss: the point is recomputed (the cache is keyed by content), and study.json notes it."""
    from benchtwin.app.study import execution as st

    monkeypatch.setattr(st, "code_version", lambda: "test-fixed")
    p = _write(tmp_path, BASIC.replace('"10 mm", "20 mm"]', '"10 mm"]'))
    out = tmp_path / "out"
    r1 = st.run_study(p, out, workers=0, progress=False, point_fn=counting_point)
    table = (out / "summary.csv").read_text(encoding="utf-8")
    entries = sorted((out / "cache").rglob("*.json"))
    assert len(entries) == 6 and "notes" not in r1
    bad = {entries[0]: "{}", entries[1]: '{"outputs": {"angle_error_pv_arcsec": "x"}, "elapsed_s": 1, "code": "c"}',
           entries[2]: "[1, 2", entries[3]: f'{{"outputs": {{}}, "elapsed_s": {BIG}, "code": "c"}}'}
    for e, text in bad.items():
        e.write_text(text, encoding="utf-8")
    entries[4].unlink()
    _fifo(entries[4])
    r2 = _bounded(st.run_study, p, out, workers=0, progress=False, point_fn=counting_point)
    assert (r2["computed"], r2["cached"]) == (5, 1)
    assert len(r2["notes"]) == 5 and all("recomputed" in n for n in r2["notes"])
    assert str(entries[0]) in " ".join(r2["notes"]) and "see notes" in r2["message"]
    assert json.loads((out / "study.json").read_text())["notes"] == r2["notes"]
    r3 = st.run_study(p, out, workers=0, progress=False, point_fn=counting_point)  # the entries were replaced
    assert (r3["computed"], r3["cached"]) == (0, 6) and "notes" not in r3
    assert (out / "summary.csv").read_text(encoding="utf-8") == table  # recomputed = what was cached


def test_a_study_cache_entry_of_braces_through_the_cli_is_not_exit_1(tmp_path, capsys, monkeypatch):
    from benchtwin.app.study import execution as st

    monkeypatch.setattr(st, "code_version", lambda: "test-fixed")
    p = _write(tmp_path, BASIC.replace('"5 mm", "10 mm", "20 mm"]', '"5 mm"]').replace("repetitions = 2",
                                                                                     "repetitions = 1"))
    out = tmp_path / "out"
    monkeypatch.setattr(st.study_points, "physics_point", _cheap_point)
    rc, res = _cli(["study", str(p), "-o", str(out), "--workers", "0"], capsys)
    assert rc == 0, res
    for e in (out / "cache").rglob("*.json"):
        e.write_text("{}", encoding="utf-8")
    rc, res = _cli(["study", str(p), "-o", str(out), "--workers", "0"], capsys)
    assert rc == 0 and res["computed"] == 2 and len(res["notes"]) == 2, res


def _cheap_point(task: dict) -> list[dict]:
    return [{"angle_error_pv_arcsec": task["scenario"]["bench"]["L1"] * 1e2, "disk_motion_x_pv_um": 0.1}
            for _ in task["rep_seeds"]]


# ============================================================================ other readers (hw, the report)


def test_analyze_with_a_fifo_manifest_does_not_hang(tmp_path, capsys):
    """The report's bench picture read manifest.json with read_text() before the dataset reader
    could refuse it: a FIFO there blocked analyze."""
    (tmp_path / "ds").mkdir()
    _fifo(tmp_path / "ds" / "manifest.json")
    rc, out = _cli(["analyze", str(tmp_path / "ds"), "-o", str(tmp_path / "out")], capsys)
    assert rc == 2 and "not a regular file" in out["error"]


def test_camera_folder_index_by_the_number_grammar_and_inside_the_folder(tmp_path):
    from benchtwin.hw.drivers.camera import FolderCamera

    for text, needle in (("file,t_s\na.png,1_000\n", "row 2, column 't_s'"),
                         ("file,t_s\n/etc/passwd,1\n", "row 2, column 'file'"),
                         ("file,t_s\n../a.png,1\n", "without '..'"),
                         ("file,t_s\na.png\n", "row 2: expected 2 fields")):
        (tmp_path / "index.csv").write_text(text, encoding="utf-8")
        with pytest.raises(ValueError, match=needle.replace("(", r"\(")):
            FolderCamera("cam", tmp_path)
    (tmp_path / "index.csv").unlink()
    _fifo(tmp_path / "index.csv")
    with pytest.raises(ValueError, match="not a regular file"):
        _bounded(FolderCamera, "cam", tmp_path)


def test_transcript_fifo_and_a_line_that_is_not_an_object(tmp_path):
    from benchtwin.hw.transport import load_transcript

    p = tmp_path / "t.jsonl"
    p.write_text('{"comment": "x"}\n5\n', encoding="utf-8")
    with pytest.raises(ValueError, match="t.jsonl:2: expected a JSON object"):
        load_transcript(p)  # was a TypeError (set(5))
    p.write_text('{"request": "a", "request": "b"}\n', encoding="utf-8")
    with pytest.raises(ValueError, match="appears twice"):
        load_transcript(p)
    p.unlink()
    _fifo(p)
    with pytest.raises(ValueError, match="not a regular file"):
        _bounded(load_transcript, p)
