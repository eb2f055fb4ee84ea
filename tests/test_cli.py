"""The command line: exit codes, --json, and messages that name the problem."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from benchtwin.cli import main

ROOT = Path(__file__).resolve().parents[1]


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
    from tests.test_dataset import make_dataset

    root = make_dataset(tmp_path / "ds")
    assert main(["validate", str(root)]) == 0
    assert "valid dataset" in capsys.readouterr().out


def test_console_script_installed():
    exe = Path(sys.executable).with_name("benchtwin")
    r = subprocess.run([str(exe), "--version"], capture_output=True, text=True, check=True)
    assert r.stdout.startswith("benchtwin ")
