"""Issue #13, one test per example: every bad input gets a clear error (exit 2, file + key/row +
expectation, a JSON object under --json), nothing half-written is taken as complete, acquisition
never discards readings. docs/reliability.md maps each class of the issue to these tests."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchtwin.analysis.dataset import DatasetError, DatasetWriter, open_dataset
from benchtwin.cli import main
from benchtwin.fsio import AtomicDir, DirLock, OutputError, atomic_write_text, check_output_dir
from tests.support.fake_dataset import MANIFEST, make_dataset
from tests.support.bench_file import loop_bench_file

ROOT = Path(__file__).resolve().parents[2]
JIA = ROOT / "scenarios" / "jia2019.toml"


def _cli(args, capsys, code=2):
    """Run the CLI with --json; the one JSON object on stdout, checked for ok/exit code."""
    rc = main([*args, "--json"])
    out = capsys.readouterr().out.strip()
    obj = json.loads(out)  # exactly one JSON object (json.loads fails on anything else)
    assert rc == code, obj
    assert obj["ok"] is (code == 0)
    return obj


def _err(args, capsys, *words):
    obj = _cli(args, capsys, 2)
    for w in words:
        assert w in obj["error"], f"{w!r} not in {obj['error']!r}"
    return obj["error"]


def _rewrite(p: Path, fn) -> None:
    p.write_text(fn(p.read_text()))


def _png(path: Path, img: np.ndarray) -> None:
    import cv2

    ok, buf = cv2.imencode(".png", img)
    assert ok
    path.write_bytes(buf.tobytes())


# ----------------------------------------------------------------------------- A. CCD frames


def test_a_ccd_frame_of_another_size_is_rejected(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds")
    _png(root / "ccd" / "img_001.png", np.full((6, 20), 90, np.uint8))
    _err(["validate", str(root)], capsys, "index.csv", "row 3", "img_001.png", "20×6", "16×12", "one frame size")


def test_a_reference_point_outside_the_frames_is_rejected(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds")
    _rewrite(root / "manifest.json", lambda t: t.replace('"reference_px": [\n   8,\n   6\n  ]', '"reference_px": [1024, 768]'))
    assert json.loads((root / "manifest.json").read_text())["ccd"]["reference_px"] == [1024, 768]
    _err(["validate", str(root)], capsys, "row 2", "reference_px", "outside")


def test_a_duplicated_and_identical_frames_are_rejected(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds")
    _rewrite(root / "ccd" / "index.csv", lambda t: t.replace("img_001.png", "img_000.png"))
    _err(["validate", str(root)], capsys, "index.csv", "rows 2 and 3", "same image file")
    root2 = make_dataset(tmp_path / "ds2")
    shutil.copy(root2 / "ccd" / "img_000.png", root2 / "ccd" / "img_001.png")
    _err(["validate", str(root2)], capsys, "row 3", "identical to the frame of row 2")


def test_a_swapped_angles_are_caught_by_theta_read(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds")
    # the encoder's readings of the two stops (0° and 6°), then the commanded angles swapped
    def with_readings(t: str) -> str:  # every stop's reading next to its angle (0.0001 and 5.9998 for 0° and 6°)
        head, *rows = t.splitlines()
        return "\n".join([head + ",theta_read_deg"] + [r + f",{float(r.split(',')[1]) + (-2e-4 if r.startswith('1,') else 1e-4):.4f}"
                                                        for r in rows]) + "\n"

    _rewrite(root / "ccd" / "index.csv", with_readings)
    assert open_dataset(root).validate()
    _rewrite(root / "ccd" / "index.csv", lambda t: t.replace("0,0.0,img_000", "0,6.0,img_000").replace("1,6.0,img_001", "1,0.0,img_001"))
    _err(["validate", str(root)], capsys, "index.csv", "row 2", "theta_read_deg", "swapped")


def test_a_two_frames_at_one_angle_are_rejected(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds")
    _rewrite(root / "ccd" / "index.csv", lambda t: t.replace("1,6.0,", "1,0.0,"))
    _err(["validate", str(root)], capsys, "rows 2 and 3", "same angle")


# ----------------------------------------------------------------------------- B. outputs written in place


def test_b_simulate_refuses_an_existing_dataset_before_simulating(tmp_path, capsys, monkeypatch):
    import benchtwin.twin.simulate as S

    root = make_dataset(tmp_path / "ds")
    before = {p: p.read_bytes() for p in root.rglob("*") if p.is_file()}
    work: list[str] = []     # the work a refusal must not start: building the bench, running it

    def counted(name):
        run = getattr(S, name)

        def call(*a, **kw):
            work.append(name)
            return run(*a, **kw)
        return call

    for name in ("sim_build", "_simulate"):
        monkeypatch.setattr(S, name, counted(name))
    _err(["simulate", str(JIA), "-o", str(root), "--backend", "analytic"], capsys, str(root), "holds a complete dataset", "--force")
    assert work == []  # refused at once, nothing simulated (a count of work, not a wall-clock bound)
    assert {p: p.read_bytes() for p in root.rglob("*") if p.is_file()} == before


def test_b_force_clears_the_folder_so_a_killed_run_leaves_no_dataset(tmp_path):
    """The old manifest (the completion marker) goes first: a run killed before its own manifest
    leaves nothing validate or analyze accepts, and none of the old run's tables (A's heads.csv
    under scenario B)."""
    root = make_dataset(tmp_path / "ds")
    m = json.loads(json.dumps(MANIFEST))
    w = DatasetWriter(root, m, force=True)
    assert not (root / "heads.csv").exists() and not (root / "manifest.json").exists()
    w.write_table("radial_motion", {"rep": [0], "theta_deg": [0.0], "probe_top_um": [0.0], "probe_bottom_um": [0.0]})
    # killed here: no manifest
    with pytest.raises(DatasetError, match="manifest.json: missing"):
        open_dataset(root)


def test_b_simulate_killed_over_an_old_dataset_leaves_nothing_complete(tmp_path, monkeypatch):
    """issue #13: simulate over an existing dataset, killed during the CCD sweep, left the old
    manifest and tables with new frames (analyze then gave e = 2.37 µm)."""
    from benchtwin.analysis import dataset as dsmod
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import simulate

    root = make_dataset(tmp_path / "ds")
    sc = load_scenario(JIA).with_overrides({"procedure.radial_reps": 1, "procedure.radial_positions": 8,
                                            "procedure.ccd_step": "90 deg", "instruments.ccd.width": "64 px",
                                            "instruments.ccd.height": "48 px", "procedure.polygon_shifts": ["0 deg"]})
    calls = {"n": 0}
    real = dsmod.DatasetWriter.write_image

    def dying(self, relpath, image):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt  # the kill, in the middle of the CCD sweep
        return real(self, relpath, image)

    monkeypatch.setattr(dsmod.DatasetWriter, "write_image", dying)
    with pytest.raises(DatasetError, match="holds a complete dataset"):
        simulate(sc, root, progress=False, backend="analytic")
    with pytest.raises(KeyboardInterrupt):
        simulate(sc, root, progress=False, backend="analytic", force=True)
    assert calls["n"] == 2
    with pytest.raises(DatasetError, match="manifest.json: missing"):
        open_dataset(root)
    assert not (root / "heads.csv").exists() and not (root / ".benchtwin.lock").exists()


def test_b_killed_analyze_never_leaves_a_result_under_the_target(tmp_path, capsys, monkeypatch):
    from benchtwin.analysis import pipeline

    ds = make_dataset(tmp_path / "ds")
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.json").write_text('{"old": true}')
    _err(["analyze", str(ds), "-o", str(out)], capsys, str(out), "not empty", "--force")

    def killed(dataset, out_dir, **kw):
        atomic_write_text(Path(out_dir) / "report.html", "<html>half</html>")
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline, "analyze_into", killed)
    assert main(["analyze", str(ds), "-o", str(out), "--force", "--json"]) == 130
    capsys.readouterr()
    # the previous complete output is untouched (replaced only by a complete new one), and no
    # half output is left beside it
    assert (out / "results.json").read_text() == '{"old": true}' and not (out / "report.html").exists()
    assert [p.name for p in tmp_path.iterdir()] == sorted(["ds", "out"]) or set(p.name for p in tmp_path.iterdir()) == {"ds", "out"}


def test_b_atomic_dir_replaces_only_when_complete(tmp_path):
    t = tmp_path / "t"
    t.mkdir()
    (t / "a").write_text("old")
    with pytest.raises(OutputError, match="not empty"):
        with AtomicDir(t):
            pass
    with AtomicDir(t, force=True) as tmp:
        (tmp / "b").write_text("new")
        assert (t / "a").read_text() == "old"
    assert sorted(p.name for p in t.iterdir()) == ["b"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t"]


def test_b_all_outputs_have_one_file_mode(tmp_path):
    """issue #13: manifest.json and PNGs were 0600 (mkstemp) while CSVs were 0644."""
    old = os.umask(0o022)
    try:
        root = make_dataset(tmp_path / "ds")
    finally:
        os.umask(old)
    modes = {p.relative_to(root).as_posix(): p.stat().st_mode & 0o777 for p in root.rglob("*") if p.is_file()}
    assert set(modes.values()) == {0o644}, modes


# ----------------------------------------------------------------------------- C. acquisition never discards readings


def test_c_acquire_without_resume_keeps_the_journal(tmp_path, capsys):
    bench = loop_bench_file(tmp_path)
    out = tmp_path / "ds"
    out.mkdir()
    journal = out / "journal.jsonl"
    journal.write_text('{"journal": "benchtwin-run", "version": 1}\n{"i": 0, "row": {"x": 1}}\n')
    before = journal.read_bytes()
    _err(["acquire", str(bench), "-o", str(out)], capsys, "journal.jsonl", "--resume", "--force")
    assert journal.read_bytes() == before


def test_c_runner_without_resume_never_deletes_a_journal(tmp_path):
    from benchtwin.hw.acquisition.runner import Runner, RunnerError, SimClock

    j = tmp_path / "j.jsonl"
    j.write_text('{"journal": "benchtwin-run", "version": 1}\n')
    with pytest.raises(RunnerError, match="resume it, or restart"):
        Runner({}, SimClock(), journal=j).run([])
    assert j.exists()


def test_c_a_lock_stops_a_second_acquire_on_one_folder(tmp_path, capsys):
    bench = loop_bench_file(tmp_path)
    out = tmp_path / "ds"
    out.mkdir()
    (out / "journal.jsonl").write_text('{"journal": "benchtwin-run", "version": 1}\n')
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        (out / ".benchtwin.lock").write_text(f"{other.pid}\n")
        _err(["acquire", str(bench), "-o", str(out), "--resume"], capsys, str(out), f"pid {other.pid}")
    finally:
        other.kill()
        other.wait()
    # the owner is gone: its stale lock is taken over (then the run goes on to the instruments)
    with DirLock(out) as lock:
        assert lock.path.read_text().split()[0] == str(os.getpid())  # pid, then its start time
    assert not (out / ".benchtwin.lock").exists()


def test_c_instrument_errors_exit_2_and_say_how_to_resume(tmp_path, capsys, monkeypatch):
    import serial

    from benchtwin.hw.acquisition import acquire as acq
    from benchtwin.hw.drivers.base import InstrumentError

    bench = loop_bench_file(tmp_path)
    out = tmp_path / "ds"
    for exc in (InstrumentError("autocollimator", "read", "no reply", b"", attempts=3),
                serial.SerialException("device reports readiness to read but returned no data (device disconnected?)")):
        def failing(*a, exc=exc, **k):
            out.mkdir(exist_ok=True)
            (out / "journal.jsonl").write_text('{"journal": "benchtwin-run", "version": 1}\n')
            raise exc

        monkeypatch.setattr(acq, "acquire", failing)
        _err(["acquire", str(bench), "-o", str(out)], capsys, str(bench), "instrument error", "journal.jsonl", "--resume")
        shutil.rmtree(out)


def test_c_retries_exhausted_on_a_silent_instrument_is_exit_2(tmp_path, capsys):
    """A real run on loopback ports (the instrument never answers properly): the driver's retries
    run out; exit 2 with the instrument, and the journal is kept for --resume."""
    bench = loop_bench_file(tmp_path)
    out = tmp_path / "ds"
    err = _err(["acquire", str(bench), "-o", str(out)], capsys, str(bench))
    assert "Traceback" not in err


# ----------------------------------------------------------------------------- D. numbers


@pytest.mark.parametrize("cell, words", [
    ("1_000", ["expected a decimal number", "'1_000'"]),                    # float() accepts '_'
    ("12345678901234567890", ["'rep'", "expected an integer"]),              # int64 overflow
    ("1e400", ["expected a finite number"]),
    ("٣", ["expected a decimal number"]),                                     # a non-ASCII digit
])
def test_d_one_number_grammar(tmp_path, capsys, cell, words):
    root = make_dataset(tmp_path / "ds")
    col = "rep" if cell.isdigit() and len(cell) == 20 else "probe_top_um"
    if col == "rep":
        _rewrite(root / "radial_motion.csv", lambda t: t.replace("\n0,0.0,", f"\n{cell},0.0,", 1))
    else:
        _rewrite(root / "radial_motion.csv", lambda t: t.replace("0.49999999999999994", cell, 1))
    _err(["validate", str(root)], capsys, "radial_motion.csv", "row ", *words)


def test_d_theta_range_and_direction_enum(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds")
    _rewrite(root / "radial_motion.csv", lambda t: t.replace("\n0,30.0,", "\n0,7200.0,", 1))
    _err(["validate", str(root)], capsys, "radial_motion.csv", "'theta_deg'", "-360…720", "7200")
    root = make_dataset(tmp_path / "ds2")
    _rewrite(root / "heads.csv", lambda t: t.replace("delta_arcsec\n", "delta_arcsec,direction\n").replace("\n0.0,1,0.0\n", "\n0.0,1,0.0,sideways\n")
             .replace(",0.3\n", ",0.3,forward\n").replace(",0.0\n90", ",0.0,forward\n90").replace(",-0.2\n", ",-0.2,forward\n"))
    _err(["validate", str(root)], capsys, "heads.csv", "'direction'", "forward, backward", "sideways")


def test_d_list_valued_scenario_keys_are_range_checked(tmp_path, capsys):
    p = tmp_path / "s.toml"
    p.write_text(JIA.read_text().replace('heads = ["0 deg"]', 'heads = ["0 deg", "1e300 deg"]'))
    assert "1e300" in p.read_text()
    _err(["validate", str(p)], capsys, "s.toml", "bench.heads", "item 1", "above the maximum")


# ----------------------------------------------------------------------------- E. paths


@pytest.mark.parametrize("name", ["/etc/hostname", "../outside.png", "..\\outside.png"])
def test_e_image_names_stay_inside_the_dataset(tmp_path, capsys, name):
    root = make_dataset(tmp_path / "ds")
    _png(tmp_path / "outside.png", np.zeros((12, 16), np.uint8))
    _rewrite(root / "ccd" / "index.csv", lambda t: t.replace("img_001.png", name))
    _err(["validate", str(root)], capsys, "index.csv", "row 3", "inside the dataset")


def test_e_a_symlinked_image_may_not_leave_the_dataset(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds")
    _png(tmp_path / "outside.png", np.zeros((12, 16), np.uint8))
    (root / "ccd" / "img_001.png").unlink()
    (root / "ccd" / "img_001.png").symlink_to(tmp_path / "outside.png")
    _err(["validate", str(root)], capsys, "row 3", "leaves the dataset")


def test_e_a_table_symlinked_outside_never_echoes_its_content(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds")
    secret = tmp_path / "secret.txt"
    secret.write_text("root:x:0:0:secret-first-line\n")
    (root / "heads.csv").unlink()
    (root / "heads.csv").symlink_to(secret)
    err = _err(["validate", str(root)], capsys, "heads.csv", "leaves the dataset")
    assert "secret-first-line" not in err and "root:x" not in err


# ----------------------------------------------------------------------------- F. a table that is a folder, no tables


def test_f_a_table_that_is_a_folder_is_an_error(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds")
    (root / "polygon.csv").unlink()
    (root / "polygon.csv").mkdir()
    _err(["validate", str(root)], capsys, "polygon.csv", "is a folder")
    _err(["analyze", str(root), "-o", str(tmp_path / "out")], capsys, "polygon.csv", "is a folder")
    assert not (tmp_path / "out").exists()


def test_f_a_dataset_without_tables_is_an_error_for_analyze(tmp_path, capsys):
    root = tmp_path / "ds"
    root.mkdir()
    (root / "manifest.json").write_text(json.dumps(MANIFEST))
    _err(["validate", str(root)], capsys, "no data tables")
    _err(["analyze", str(root), "-o", str(tmp_path / "out")], capsys, "no data tables")
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- G. exit 2 instead of tracebacks


@pytest.mark.parametrize("text, words", [
    ("[study\n", ["not valid TOML"]),
    ('[study]\nname = "x"\n', ["missing key study."]),
    ('[other]\n', ["unknown section [other]"]),
    ('version = 7\n[study]\nname = "x"\n', ["key version", "7"]),
    ("a = " + "[" * 200 + "]" * 200 + "\n", ["nested", "levels"]),
])
def test_g_every_bad_study_file_is_exit_2(tmp_path, capsys, text, words):
    p = tmp_path / "st.toml"
    p.write_text(text)
    _err(["study", str(p), "-o", str(tmp_path / "out")], capsys, "st.toml", *words)
    assert not (tmp_path / "out").exists()


def test_g_a_bad_model_file_fails_before_the_analysis(tmp_path, capsys, monkeypatch):
    from benchtwin.analysis import pipeline

    ds = make_dataset(tmp_path / "ds")
    monkeypatch.setattr(pipeline, "step_radial_motion", lambda *a, **k: pytest.fail("analysis ran before the check"))
    bad = tmp_path / "model.json"
    cases = [
        ("{", ["not valid JSON"]),
        ('{"format": "x", "version": 1, "effects": []}', ["'format'", "benchtwin-traced-effects"]),
        ('{"format": "benchtwin-traced-effects", "version": 1, "effects": [{"name": "nope", "params": {}}]}',
         ["effects[0].name", "expected one of"]),
        ('{"format": "benchtwin-traced-effects", "version": 1, "effects": [{"name": "tangential_motion", '
         '"params": {"gain": 1.0}, "aux": {}}]}', ["effects[0] (tangential_motion)", "missing key 'coefs'"]),
        ('{"format": "benchtwin-traced-effects", "version": 1, "effects": [{"name": "ac_drift", '
         '"params": {"rate": NaN}, "aux": {}}]}', ["not valid JSON", "NaN"]),
    ]
    for text, words in cases:
        bad.write_text(text)
        _err(["analyze", str(ds), "-o", str(tmp_path / "out"), "--model", str(bad)], capsys, "model.json", *words)
    _err(["analyze", str(ds), "-o", str(tmp_path / "out"), "--model", str(tmp_path)], capsys, "is a folder")


def test_g_output_onto_an_existing_file_is_exit_2(tmp_path, capsys):
    ds = make_dataset(tmp_path / "ds")
    f = tmp_path / "file.txt"
    f.write_text("keep")
    _err(["analyze", str(ds), "-o", str(f)], capsys, "file.txt", "found a file")
    _err(["simulate", str(JIA), "-o", str(f)], capsys, "file.txt", "found a file")
    assert f.read_text() == "keep"


def test_g_a_cell_over_128_kib_is_exit_2(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds")
    _rewrite(root / "heads.csv", lambda t: t + '0.0,2,"' + "9" * 200_000 + '"\n')
    _err(["validate", str(root)], capsys, "heads.csv", "row 10", "at most 4096 characters")
    root = make_dataset(tmp_path / "ds2")
    _rewrite(root / "heads.csv", lambda t: t + "0.0,2," + "9" * 5000 + "\n")
    _err(["validate", str(root)], capsys, "heads.csv", "row 10", "'delta_arcsec'")


def test_g_deeply_nested_json_and_toml_are_exit_2(tmp_path, capsys):
    root = make_dataset(tmp_path / "ds")
    m = (root / "manifest.json").read_text()
    (root / "manifest.json").write_text(m[:-2] + ', "deep": ' + "[" * 100_000 + "]" * 100_000 + "}\n")
    _err(["validate", str(root)], capsys, "manifest.json", "nested", "levels")
    p = tmp_path / "s.toml"
    p.write_text(JIA.read_text() + "\n[hidden.x]\ny = " + "[" * 5000 + "]" * 5000 + "\n")
    _err(["validate", str(p)], capsys, "s.toml", "nested")


def test_g_usage_errors_are_json_too(capsys):
    with pytest.raises(SystemExit) as e:
        main(["analyze", "--json"])
    assert e.value.code == 2
    assert json.loads(capsys.readouterr().out)["kind"] == "usage"


def test_g_an_internal_error_is_one_line_and_json(capsys, monkeypatch):
    from benchtwin import cli

    def boom(ns):
        raise ZeroDivisionError("x")

    monkeypatch.setitem(cli._COMMANDS, "validate", (boom, cli._validate_args, "v"))
    obj = _cli(["validate", "x"], capsys, code=1)
    assert obj["kind"] == "internal" and "bug" in obj["error"]


# ----------------------------------------------------------------------------- H. what validate accepts, the next step runs


def _scenario(tmp_path: Path, old: str, new: str, extra: str = "") -> Path:
    p = tmp_path / "s.toml"
    text = JIA.read_text()
    assert old in text
    p.write_text(text.replace(old, new) + extra)
    return p


def test_h_unsorted_motion_table_is_rejected_by_validate(tmp_path, capsys):
    p = _scenario(tmp_path, "[scenario]", "[scenario]",
                  '\n[motion_table]\ntheta = ["0 deg", "240 deg", "120 deg"]\ndx = ["0 um", "0.1 um", "0 um"]\n')
    _err(["validate", str(p)], capsys, "motion_table.theta", "strictly increasing", "item 2")


def test_h_duplicated_polygon_shifts_are_rejected_by_validate(tmp_path, capsys):
    import re

    text = JIA.read_text()
    m = re.search(r"polygon_shifts = \[[^\]]*\]", text)
    p = _scenario(tmp_path, m.group(0), 'polygon_shifts = ["0 deg", "3 deg", "3 deg"]')
    _err(["validate", str(p)], capsys, "procedure.polygon_shifts", "3 deg", "listed twice")


def test_h_radial_reps_beyond_the_d_n_table_are_rejected_and_11_runs(tmp_path, capsys):
    import re

    from benchtwin.analysis.radial_motion import range_method_u

    text = JIA.read_text()
    m = re.search(r"radial_reps = \d+", text)
    p = _scenario(tmp_path, m.group(0), "radial_reps = 26")
    _err(["validate", str(p)], capsys, "procedure.radial_reps", "25")
    u = range_method_u(np.random.default_rng(1).normal(size=(11, 36)))  # 11 repetitions: d_11 is tabulated
    assert np.all(np.isfinite(u))


def test_i_a_ccd_sweep_of_36000_frames_is_rejected(tmp_path, capsys):
    import re

    text = JIA.read_text()
    m = re.search(r'ccd_step = "[^"]*"', text)
    p = _scenario(tmp_path, m.group(0), 'ccd_step = "0.01 deg"')
    _err(["validate", str(p)], capsys, "procedure.ccd_step", "below the minimum")
    root = make_dataset(tmp_path / "ds")
    rows = "".join(f"{k},{k * 0.01},img_{k:05d}.png\n" for k in range(36000))
    (root / "ccd" / "index.csv").write_text("k,theta_deg,file\n" + rows)
    _err(["validate", str(root)], capsys, "index.csv", "36000 CCD frames", "at most 720")


def test_i_fault_plan_seconds_nan_is_rejected(tmp_path):
    from benchtwin.twin.emulators.pty import load_fault_plan

    f = tmp_path / "faults.toml"
    f.write_text('[[faults]]\nport = "stage"\nrequest = 3\naction = "delay"\nseconds = nan\n')
    with pytest.raises(ValueError, match=r"faults\.toml: key faults\[0\]\.seconds: expected a finite number|"
                                         r"faults\.toml: .*seconds.*finite"):
        load_fault_plan(f)
    f.write_text('version = 2\n[[faults]]\nport = "stage"\nrequest = 3\naction = "drop"\n')
    with pytest.raises(ValueError, match="key version: expected one of 1"):
        load_fault_plan(f)


def test_versions_missing_means_1_unknown_is_exit_2(tmp_path, capsys):
    p = tmp_path / "s.toml"
    p.write_text("version = 1\n" + JIA.read_text())
    assert main(["validate", str(p)]) == 0
    capsys.readouterr()
    p.write_text("version = 2\n" + JIA.read_text())
    _err(["validate", str(p)], capsys, "s.toml", "key version", "got 2")


def test_check_output_dir_rules(tmp_path):
    d = tmp_path / "d"
    assert check_output_dir(d) == d and d.is_dir()
    (d / "x").write_text("1")
    with pytest.raises(OutputError, match="not empty"):
        check_output_dir(d)
    check_output_dir(d, force=True)
    assert not any(d.iterdir())
    with pytest.raises(OutputError, match="nothing to resume"):
        check_output_dir(d, resume=True, resume_marker="journal.jsonl")


def test_h_two_heads_with_self_calibration(tmp_path, capsys):
    """issue #13: 2 heads with self-calibration passed validate, then a TypeError in the report.
    Two heads give δ = α(θ) − α(θ+180°): the odd harmonics exactly, with no redundancy, so no u of
    the self-calibration and E_n undefined (tests/hw/test_hil.py runs such a bench). Valid; the
    analysis reports it without E_n, and the close loop does not use it as evidence."""
    import re

    text = JIA.read_text()
    p = tmp_path / "s.toml"
    p.write_text(re.sub(r'heads = \["0 deg"\]', 'heads = ["0 deg", "180 deg"]', text).replace("selfcal = false", "selfcal = true"))
    assert _cli(["validate", str(p)], capsys, code=0)["kind"] == "scenario"
    # a dataset with 2 heads (make_dataset's): analysed, the report written
    root = make_dataset(tmp_path / "ds")
    for f in ("radial_motion.csv", "ccd"):
        shutil.rmtree(root / f) if (root / f).is_dir() else (root / f).unlink()
    th = np.arange(0.0, 360.0, 30.0)
    rows = "".join(f"{float(t)!r},1,0.0\n{float(t)!r},2,{float(0.3 * np.sin(np.radians(t)) + 0.1 * np.cos(3 * np.radians(t)))!r}\n" for t in th)
    (root / "heads.csv").write_text("theta_deg,head,delta_arcsec\n" + rows)
    obj = _cli(["analyze", str(root), "-o", str(tmp_path / "out")], capsys, code=0)
    res = json.loads(Path(obj["results"]).read_text())
    assert res["selfcal_error_arcsec"] is not None and res["en_max"] is None and res["difference_arcsec"]
    assert Path(obj["report"]).stat().st_size > 1000  # the report, with its difference figure (E_n undefined)


def test_validate_reads_study_bench_and_fault_plan_files_as_their_commands_do(tmp_path, capsys):
    """What validate accepts, the next command reads: study files (study), bench files (acquire),
    fault plans (emulate --faults) are checked by those commands' own readers."""
    obj = _cli(["validate", str(ROOT / "scenarios" / "studies" / "bearing_distance.toml")], capsys, code=0)
    assert obj["kind"] == "study"
    obj = _cli(["validate", str(loop_bench_file(tmp_path))], capsys, code=0)
    assert obj["kind"] == "bench" and "stage" in obj["instruments"]
    f = tmp_path / "faults.toml"
    f.write_text('[[faults]]\nport = "stage"\nrequest = 3\naction = "drop"\n')
    assert _cli(["validate", str(f)], capsys, code=0)["kind"] == "fault_plan"
    f.write_text('[[faults]]\nport = "stage"\nrequest = 3\naction = "delay"\nseconds = nan\n')
    _err(["validate", str(f)], capsys, "faults.toml", "faults[0]", "seconds", "finite")
    b = loop_bench_file(tmp_path)
    b.write_text(b.read_text().replace('source = "emulated"', 'source = "twin"'))
    _err(["validate", str(b)], capsys, "b.toml", "bench.source")


def test_a_uniform_blank_frames_are_left_to_the_image_analysis(tmp_path):
    """Two fogged (uniform) frames are alike by nature: not a duplicated file; the analysis rejects
    them with its own note (tests/analysis/test_pipeline.py::test_too_many_bad_ccd_frames_abort_naming_the_threshold)."""
    root = make_dataset(tmp_path / "ds")
    for k in range(2):
        _png(root / "ccd" / f"img_{k:03d}.png", np.full((12, 16), 117, np.uint8))
    assert open_dataset(root).validate()


def test_a_parsed_model_payload_is_checked_like_a_file():
    from benchtwin.analysis.model_file import ModelFileError, read_model_file

    with pytest.raises(ModelFileError, match=r"<model payload>: key 'format'"):
        read_model_file({"format": "x"})
    assert read_model_file({"format": "benchtwin-traced-effects", "version": 1, "effects": []})["effects"] == []


def _fake_run(monkeypatch, fake_simulate, results_of) -> None:
    """`benchtwin run` with the twin and the analysis replaced: ``fake_simulate(sc, out, truth_dir)``
    writes the dataset and returns the function that writes the truth (run in a forked child, as
    ``simulate_apart`` does) or None; the analysis writes ``results_of(dataset)`` and a report
    naming the dataset."""
    import benchtwin.analysis.pipeline as pipeline
    import benchtwin.app.bench_view as bench_view
    import benchtwin.twin.simulate as simulate
    from benchtwin.forkcall import ForkCall

    def fake_apart(sc, out, truth_dir, **kw):
        write_truth = fake_simulate(sc, Path(out), Path(truth_dir))
        return Path(out), ForkCall(write_truth or (lambda: None))

    def fake_analyze(ds, out, **kw):
        (Path(out) / "results.json").write_text(json.dumps(results_of(ds)))
        (Path(out) / "report.html").write_text(f"<html>Dataset {ds}</html>")
        return {"results": {}, "paths": {"results": str(Path(out) / "results.json"),
                                         "report": str(Path(out) / "report.html")}}

    monkeypatch.setattr(simulate, "simulate_apart", fake_apart)
    monkeypatch.setattr(pipeline, "analyze_into", fake_analyze)
    monkeypatch.setattr(bench_view, "bench_preface", lambda sc: [])


def test_run_replaces_its_own_earlier_output_but_nothing_else(tmp_path, monkeypatch):
    """`benchtwin run` twice (the README's first command, repeated) replaces the earlier run's own
    complete output; any other non-empty folder stays refused without --force (exit 2)."""
    from benchtwin.cli import main

    calls = []

    def fake_simulate(sc, out, truth_dir):
        Path(out).mkdir(parents=True)
        (Path(out) / "manifest.json").write_text("{}")
        calls.append("simulate")

    _fake_run(monkeypatch, fake_simulate, lambda ds: {"n": len(calls), "dataset": str(ds)})
    out = tmp_path / "out"
    assert main(["run", "-o", str(out), "--quiet"]) == 0
    assert main(["run", "-o", str(out), "--quiet"]) == 0          # its own output: replaced
    assert json.loads((out / "results.json").read_text())["n"] == 2
    # the report names OUT, not the temporary sibling it was built in
    assert ".partial-" not in (out / "report.html").read_text() + (out / "results.json").read_text()
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("a user's file")
    assert main(["run", "-o", str(other), "--quiet"]) == 2        # someone else's folder: refused
    assert (other / "notes.txt").read_text() == "a user's file"


def test_run_moves_the_truth_out_before_the_analysis_sees_the_dataset(tmp_path, monkeypatch):
    """`benchtwin run`: the analysis runs with truth/ absent from the dataset (principle 3), and the
    run's output keeps it beside the dataset as OUT/truth (for `benchtwin score --truth`), written
    by a forked child while the analysis runs and complete before the run is."""
    seen: list[bool] = []

    def fake_simulate(sc, out, truth_dir):
        Path(out).mkdir(parents=True)
        (Path(out) / "manifest.json").write_text("{}")

        def write_truth():
            import time
            time.sleep(0.3)      # still writing while the analysis runs
            truth_dir.mkdir(parents=True)
            (truth_dir / "encoder_error.csv").write_text("theta_deg,alpha_arcsec\n0,1\n")
        return write_truth

    def results_of(ds):
        seen.append((Path(ds) / "truth").exists())
        return {"dataset": str(ds)}

    _fake_run(monkeypatch, fake_simulate, results_of)
    out = tmp_path / "out"
    assert main(["run", "-o", str(out), "--quiet"]) == 0
    assert seen == [False]
    assert not (out / "dataset" / "truth").exists()
    assert (out / "truth" / "encoder_error.csv").read_text().startswith("theta_deg")


def test_run_fails_whole_when_its_truth_fails(tmp_path, monkeypatch, capsys):
    """The truth is part of a run's output: a truth child that fails (here with a dataset error)
    ends `benchtwin run` with exit 2 and its message, and no output folder is left as complete."""
    from benchtwin.analysis.dataset import DatasetError

    def fake_simulate(sc, out, truth_dir):
        Path(out).mkdir(parents=True)
        (Path(out) / "manifest.json").write_text("{}")

        def write_truth():
            raise DatasetError(f"{truth_dir}/encoder_error.csv: no space left on the device")
        return write_truth

    _fake_run(monkeypatch, fake_simulate, lambda ds: {"dataset": str(ds)})
    out = tmp_path / "out"
    assert main(["run", "-o", str(out), "--quiet"]) == 2
    assert "no space left on the device" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())
