"""Layering, enforced: analysis imports neither twin nor hw; hw never imports twin; emulators are
not written from the drivers (contracts in pyproject.toml [tool.importlinter])."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _package_tree(dest: Path) -> Path:
    """The installed layout as one folder tree: import-linter (grimp) walks a package's folder,
    and ours is spread over the client's top-level folders (setup.py maps them)."""
    pkg = dest / "benchtwin"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(ROOT / "benchtwin", pkg, ignore=ignore)
    for folder in ("twin", "analysis", "hw", "models", "scenarios"):
        shutil.copytree(ROOT / folder, pkg / folder, ignore=ignore)
    return dest


def test_import_contracts_hold(tmp_path):
    tree = _package_tree(tmp_path)
    exe = Path(sys.executable).with_name("lint-imports")
    env = {**os.environ, "PYTHONPATH": str(tree)}
    r = subprocess.run([str(exe), "--config", str(ROOT / "pyproject.toml"), "--no-cache"], cwd=tree,
                       capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "3 kept, 0 broken" in r.stdout, r.stdout


def test_analysis_never_mentions_truth_paths():
    """Truth never leaks: no analysis module refers to the truth folder."""
    import re

    offenders = [p for p in (ROOT / "analysis").rglob("*.py") if re.search(r"truth(/|\.json|_dir|\[)", p.read_text())]
    assert not offenders, offenders
