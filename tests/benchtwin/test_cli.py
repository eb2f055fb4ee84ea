"""The command line: exit codes, --json, and messages that name the problem."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from benchtwin.cli import main

ROOT = Path(__file__).resolve().parents[2]


def test_validate_scenario_ok(capsys):
    assert main(["validate", str(ROOT / "scenarios" / "jia2019.toml"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] and out["name"] == "jia2019"


def test_validate_bad_scenario_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text((ROOT / "scenarios" / "jia2019.toml").read_text().replace('L1 = "6.81 mm"', 'L1 = "6.81 kg"'))
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "bench.L1" in err and "length" in err


def test_validate_dataset(tmp_path, capsys):
    from tests.support.fake_dataset import make_dataset

    root = make_dataset(tmp_path / "ds")
    assert main(["validate", str(root)]) == 0
    assert "valid dataset" in capsys.readouterr().out


def test_console_script_installed():
    exe = Path(sys.executable).with_name("benchtwin")
    r = subprocess.run([str(exe), "--version"], capture_output=True, text=True, check=True)
    assert r.stdout.startswith("benchtwin ")


def test_a_bad_tuning_variable_is_exit_2_naming_it(tmp_path, monkeypatch, capsys):
    """The environment variables that tune a run are inputs like options: a bad value is exit 2
    with the variable and what it expects (benchtwin/runtime.py), not an internal error."""
    import pytest

    from benchtwin.runtime import EnvVarError, env_choice, env_whole_number

    for name, value, words in (("BENCHTWIN_SIM_FRAMES", "sometimes", ["serial, pipeline or auto"]),
                               ("BENCHTWIN_SIM_FRAME_WORKERS", "two", ["whole number of frame workers"]),
                               ("BENCHTWIN_SIM_FRAME_WORKERS", "0", ["≥ 1"])):
        monkeypatch.setenv(name, value)
        out = tmp_path / f"{name}-{value}"
        assert main(["simulate", "--quiet", "--json", "-o", str(out)]) == 2
        res = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        assert res["kind"] == "EnvVarError" and name in res["error"], res
        assert all(w in res["error"] for w in words), res
        assert not (out / "manifest.json").exists()
        monkeypatch.delenv(name)
    monkeypatch.setenv("X_BT", " 3 ")
    assert env_whole_number("X_BT", "things") == 3
    monkeypatch.setenv("X_BT", "")
    assert env_whole_number("X_BT", "things") is None and env_choice("X_BT", ("a", "b"), "b") == "b"
    monkeypatch.setenv("X_BT", "A")
    assert env_choice("X_BT", ("a", "b"), "b") == "a"
    monkeypatch.setenv("X_BT", "1.5")
    with pytest.raises(EnvVarError, match="X_BT='1.5'"):
        env_whole_number("X_BT", "things")
