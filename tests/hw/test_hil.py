"""Hardware-in-the-loop on the twin: the jia2019 bench (reduced procedure) served by the protocol
emulators on pseudo-terminals, acquired through the real drivers with faults active, compared
with the direct simulation of the same scenario and seed; kill-and-resume of an acquisition; the
bench-file loader's errors."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from benchtwin.analysis.dataset import open_dataset
from benchtwin.hw.acquisition.bench import BenchFileError, build_procedure, load_bench, parse_bench

ROOT = Path(__file__).resolve().parents[2]
OVERRIDES = {"procedure.radial_positions": 36, "procedure.radial_reps": 1, "procedure.polygon_shifts": ["0 deg"],
             "procedure.polygon_reps": 1, "procedure.ccd_step": "180 deg",
             "instruments.ccd.width": "64 px", "instruments.ccd.height": "48 px"}
FAULTS = [{"port": "autocollimator", "request": 7, "action": "drop"},
          {"port": "encoder", "request": 11, "action": "garble"},
          {"port": "probes", "request": 5, "action": "partial"},
          {"port": "stage", "request": 40, "action": "disconnect"},
          {"port": "autocollimator", "request": 300, "action": "disconnect"}]

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")


@pytest.fixture(scope="module")
def scenario():
    from benchtwin.twin.scenario import load_scenario

    return load_scenario().with_overrides(OVERRIDES)


@pytest.fixture(scope="module")
def simulated(scenario, tmp_path_factory):
    from benchtwin.twin.simulate import simulate

    return simulate(scenario, tmp_path_factory.mktemp("sim") / "ds", progress=False, backend="analytic")


@pytest.fixture(scope="module")
def emulated(scenario, tmp_path_factory):
    from benchtwin.hw.acquisition.acquire import acquire
    from benchtwin.twin.emulators.serve import EmulationSession

    d = tmp_path_factory.mktemp("emu")
    with EmulationSession(scenario, faults=FAULTS) as session:
        bench = session.start(d / "emulator")
        out = acquire(bench, d / "ds", progress=False)
        fired = session.server.fired()
        errors = list(session.server.errors)
        events = dict(session.backend.event_counts)
    return {"path": out, "fired": fired, "errors": errors, "events": events, "bench": bench}


def _tables(path: Path) -> dict:
    ds = open_dataset(path)
    return {n: ds.table(n) for n in ("radial_motion", "polygon") if ds.has(n)}


def _compare(a: dict, b: dict, *, skip=("t_s",)) -> None:
    for name in a:
        for col, va in a[name].items():
            if col in skip:
                continue
            vb = b[name][col]
            try:  # extra columns (theta_read_deg, ac_y_arcsec) come back as text
                va, vb = np.asarray(va, dtype=float), np.asarray(vb, dtype=float)
            except ValueError:
                pass
            if col == "theta_read_deg":  # the ND display sends 6 decimals of a degree
                np.testing.assert_allclose(va, vb, rtol=0, atol=0.51e-6, err_msg=f"{name}.{col}")
            elif va.dtype.kind in "fc":
                np.testing.assert_array_equal(va, vb, err_msg=f"{name}.{col}")
            else:
                assert list(va) == list(vb), f"{name}.{col}"


def test_emulated_acquisition_with_faults_equals_simulation(simulated, emulated):
    assert emulated["errors"] == []
    assert sorted(f["action"] for f in emulated["fired"]) == ["disconnect", "disconnect", "drop", "garble", "partial"]
    assert set(emulated["events"]) <= {"next", "back"} and emulated["events"]["next"] > 500
    m = json.loads((emulated["path"] / "manifest.json").read_text())
    assert m["source"] == "emulated"
    sim_m = json.loads((simulated / "manifest.json").read_text())
    for k in ("optical_radius_mm", "L1_mm", "L2_mm", "grating_period_um", "polygon_faces", "heads_deg",
              "encoder_lines", "encoder_resolution_arcsec"):
        assert m["bench"][k] == pytest.approx(sim_m["bench"][k], rel=1e-12), k
    a, b = _tables(simulated), _tables(emulated["path"])
    assert set(a) == set(b) == {"radial_motion", "polygon"}
    assert len(b["polygon"]["ac_arcsec"]) == 23 * 23 and len(b["radial_motion"]["rep"]) == 36
    _compare(a, b)   # identical readings: the emulators draw the twin's noise streams of the same steps
    assert np.all(np.diff(b["polygon"]["t_s"]) >= 0)


def _close(x, y, path="") -> None:
    if callable(x):
        return
    if isinstance(x, dict):
        for k in x:
            _close(x[k], y[k], f"{path}.{k}")
    elif isinstance(x, (list, tuple)) and x and not isinstance(x[0], (int, float)):
        for i, (u, v) in enumerate(zip(x, y)):
            _close(u, v, f"{path}[{i}]")
    elif isinstance(x, (int, float, np.ndarray, list, tuple, np.floating, np.integer)):
        xa, ya = np.asarray(x), np.asarray(y)
        if xa.dtype.kind in "fiu":
            np.testing.assert_allclose(xa.astype(float), ya.astype(float), rtol=1e-9, atol=1e-9, err_msg=path)


def test_analysis_of_emulated_and_simulated_datasets_agree(simulated, emulated):
    from benchtwin.analysis.hsieh_pipeline import analyze_polygon
    from benchtwin.analysis.radial_motion import radial_motion

    res = {}
    for label, path in (("sim", simulated), ("emu", emulated["path"])):
        ds = open_dataset(path)
        bench = ds.bench
        poly = analyze_polygon(ds.table("polygon"), bench["polygon_faces"],
                               encoder_resolution_arcsec=bench["encoder_resolution_arcsec"])
        r = ds.table("radial_motion")
        rad = radial_motion(r["rep"], r["theta_deg"], r["probe_top_um"], r["probe_bottom_um"],
                            bench["L1_mm"], bench["L2_mm"])
        res[label] = (poly, rad)
    _close(res["sim"][0], res["emu"][0], "polygon")
    _close(res["sim"][1], res["emu"][1], "radial")
    # and the analysis sees the bench: Jia's eccentricity (7.1 µm on r = 22 mm -> ~66.6″ peak)
    alpha = np.asarray(res["emu"][0]["encoder_error_arcsec"]["value"], dtype=float)
    np.testing.assert_allclose(alpha, np.asarray(res["sim"][0]["encoder_error_arcsec"]["value"], dtype=float),
                               rtol=0, atol=1e-12)
    assert 40 < np.nanmax(np.abs(alpha)) < 100
    np.testing.assert_allclose(res["emu"][1]["dY_um"], res["sim"][1]["dY_um"], rtol=0, atol=1e-12)


def _journal_steps(path: Path) -> int:
    try:
        return sum(1 for line in path.read_text().splitlines() if line.startswith('{"i"'))
    except FileNotFoundError:
        return 0


def test_kill_and_resume_gives_the_uninterrupted_dataset(scenario, emulated, tmp_path):
    from benchtwin.hw.acquisition.acquire import acquire
    from benchtwin.twin.emulators.serve import EmulationSession

    out = tmp_path / "ds"
    code = ("import sys; from benchtwin.hw.acquisition.acquire import acquire; "
            "acquire(sys.argv[1], sys.argv[2], progress=False)")
    # another pair of protocols for the same instruments: TriAngle autocollimator, one TESA per probe
    with EmulationSession(scenario, autocollimator="triangle", probes="tesa") as session:
        bench = session.start(tmp_path / "emulator")
        proc = subprocess.Popen([sys.executable, "-c", code, str(bench), str(out)], cwd=ROOT,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            deadline = time.monotonic() + 60
            while _journal_steps(out / "journal.jsonl") < 400 and proc.poll() is None:
                assert time.monotonic() < deadline, "acquisition did not progress"
                time.sleep(0.02)
            assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait()
        # let the idle ports reset their line speed (twin/emulators/pty.py `_idle`: Linux ptys refuse
        # re-opening 7E2 on a port already at that speed) before the restart opens them again
        time.sleep(0.5)
        n_done = _journal_steps(out / "journal.jsonl")
        assert 400 <= n_done < len(build_procedure(load_bench(bench)))
        assert not (out / "polygon.csv").exists()
        acquire(bench, out, resume=True, progress=False)
        assert session.server.errors == []
    _compare(_tables(emulated["path"]), _tables(out))
    t = _tables(out)["polygon"]["t_s"]
    assert np.all(np.diff(t) >= 0)     # the resumed run continues the journal's time line


# --------------------------------------------------------------------------- bench-file errors

def _bench(**over) -> dict:
    raw = {"bench": {"name": "b", "source": "hardware"},
           "geometry": {"optical_radius": "22 mm", "L1": "6.81 mm", "L2": "122.96 mm", "grating_period": "20 um",
                        "polygon_faces": 23, "heads": ["0 deg"]},
           "instruments": {"encoder": {"driver": "heidenhain", "port": "loop://"},
                           "autocollimator": {"driver": "elcomat", "port": "loop://"},
                           "stage": {"driver": "zaber", "port": "loop://", "soft_limits": ["-1 deg", "361 deg"],
                                     "max_speed": "20 deg/s", "options": {"microsteps_per_deg": 1000}}},
           "procedure": [{"type": "polygon_traditional", "start_face": 2, "dwell": "0.1 s"}]}
    for k, v in over.items():
        sec, key = k.split("__")
        if v is None:
            raw[sec].pop(key)
        else:
            raw[sec][key] = v
    return raw


def test_bench_file_loads_and_builds_the_procedure(tmp_path):
    cfg = parse_bench(_bench(), "b.toml")
    assert cfg.geometry["optical_radius_mm"] == 22.0 and cfg.geometry["heads_deg"] == [0.0]
    assert cfg.instruments["stage"]["soft_limits_deg"] == (-1.0, 361.0)
    assert cfg.instruments["encoder"]["options"]["heads_deg"] == [0.0]
    steps = build_procedure(cfg)
    assert sum(type(s).__name__ == "Read" for s in steps) == 23


@pytest.mark.parametrize("over, match", [
    ({"geometry__L1": "6.81"}, r"b\.toml: key 'geometry\.L1': expected a quantity with a unit of dimension length"),
    ({"geometry__optical_radius": None}, r"b\.toml: \[geometry\]: missing key 'optical_radius'"),
    ({"bench__source": "twin"}, r"b\.toml: key 'bench\.source': expected one of \('hardware', 'emulated'\)"),
    ({"geometry__polygon_faces": 2}, r"key 'geometry\.polygon_faces': expected an integer >= 3"),
    ({"instruments__encoder": {"driver": "nd999", "port": "x"}}, r"key 'instruments\.encoder\.driver': expected one of"),
    ({"instruments__stage": {"driver": "zaber", "port": "x", "soft_limits": ["0 deg", "360 deg"],
                             "options": {"microsteps_per_deg": 1}}}, r"missing key 'max_speed'"),
    ({"instruments__stage": {"driver": "zaber", "port": "x", "soft_limits": ["0 mm", "360 deg"], "max_speed": "1 deg/s",
                             "options": {"microsteps_per_deg": 1}}}, r"key 'instruments\.stage\.soft_limits'"),
    ({"procedure__0": None}, None),
])
def test_bench_file_errors_name_file_key_and_expectation(over, match):
    raw = _bench()
    if "procedure__0" in over:
        raw["procedure"] = [{"type": "radial_motion", "probes": ["probe_top"]}]
        match = r"key 'procedure\[0\]': expected instrument 'probe_top' to be defined"
    else:
        raw = _bench(**over)
    with pytest.raises(BenchFileError, match=match):
        parse_bench(raw, "b.toml")


def test_bench_file_not_toml(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("[bench\n")
    with pytest.raises(BenchFileError, match=r"bad\.toml: not valid TOML"):
        load_bench(p)
    with pytest.raises(BenchFileError, match="no such bench file"):
        load_bench(tmp_path / "missing.toml")


def test_cli_acquire_reports_bench_errors(tmp_path, capsys):
    from benchtwin import cli
    import benchtwin.commands_hw  # noqa: F401 - registers emulate/acquire

    p = tmp_path / "b.toml"
    p.write_text('[bench]\nsource = "twin"\n')
    assert cli.main(["acquire", str(p), "-o", str(tmp_path / "ds")]) == 2
    assert "key 'bench.source'" in capsys.readouterr().err


def test_cli_emulate_serves_and_writes_a_bench_file(tmp_path, capsys):
    from benchtwin import cli
    import benchtwin.commands_hw  # noqa: F401

    faults = tmp_path / "faults.toml"
    faults.write_text('[[faults]]\nport = "encoder"\nrequest = 1\naction = "drop"\n')
    assert cli.main(["emulate", "--faults", str(faults), "--dir", str(tmp_path / "emu"), "--duration", "0.3",
                     "--probes", "tesa", "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert out[0] == f"bench file: {tmp_path / 'emu' / 'bench.toml'}"
    res = json.loads(out[-1])
    cfg = load_bench(res["bench_file"])
    assert cfg.source == "emulated"
    assert {n: s["driver"] for n, s in cfg.instruments.items()} == {
        "encoder": "heidenhain", "autocollimator": "elcomat", "probe_top": "tesa", "probe_bottom": "tesa",
        "stage": "zaber"}
    assert cfg.instruments["encoder"]["port"] == str(tmp_path / "emu" / "ports" / "encoder")
    bad = tmp_path / "bad.toml"
    bad.write_text('[[faults]]\nport = "encoder"\nrequest = 1\naction = "melt"\n')
    assert cli.main(["emulate", "--faults", str(bad), "--duration", "0"]) == 2
