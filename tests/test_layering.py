"""Layering, enforced: app (and the CLI) over twin over hw over analysis over units; the twin takes
of the analysis only the dataset format; analysis imports neither twin nor hw; hw never imports
twin; emulators are not written from the drivers (contracts in pyproject.toml [tool.importlinter])."""

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
    for folder in ("app", "twin", "analysis", "hw", "models", "scenarios"):
        shutil.copytree(ROOT / folder, pkg / folder, ignore=ignore)
    return dest


def _lint(tree: Path) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("lint-imports")
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run([str(exe), "--config", str(ROOT / "pyproject.toml"), "--no-cache"], cwd=tree,
                          capture_output=True, text=True, env=env)


def test_import_contracts_hold(tmp_path):
    r = _lint(_package_tree(tmp_path))
    assert r.returncode == 0, r.stdout + r.stderr
    assert "5 kept, 0 broken" in r.stdout, r.stdout


def test_import_contracts_catch_a_twin_running_the_analysis_and_hw_using_the_app(tmp_path):
    """The contracts can fail: a twin module importing the pipeline and an hw module importing the
    application layer are reported, while the twin's import of the dataset format stays allowed."""
    tree = _package_tree(tmp_path)
    (tree / "benchtwin" / "twin" / "_leak.py").write_text(
        "from benchtwin.analysis import dataset, fourier  # noqa: F401\n")
    (tree / "benchtwin" / "hw" / "_up.py").write_text("from benchtwin.app import run  # noqa: F401\n")
    r = _lint(tree)
    assert r.returncode != 0
    assert "2 kept, 3 broken" in r.stdout, r.stdout  # layers, twin->analysis, hw->twin (via app)
    assert "benchtwin.twin._leak -> benchtwin.analysis.fourier" in r.stdout, r.stdout
    assert "benchtwin.hw._up -> benchtwin.app.run" in r.stdout, r.stdout
    assert "benchtwin.twin._leak -> benchtwin.analysis.dataset" not in r.stdout, r.stdout


def test_analysis_never_mentions_truth_paths():
    """Truth never leaks: no analysis module refers to the truth folder."""
    import re

    offenders = [p for p in (ROOT / "analysis").rglob("*.py") if re.search(r"truth(/|\.json|_dir|\[)", p.read_text())]
    assert not offenders, offenders


def test_the_package_never_imports_the_test_generators():
    """The synthetic-data generators are test-only (tests/synthetic/, issue 16): no module of the package
    (benchtwin/, twin/, analysis/, hw/, models/, scenarios/) imports them or anything else of tests/."""
    import re

    pat = re.compile(r"^\s*(from|import)\s+tests(\.|\s|$)|synthesize_readings|effects\.synthetic", re.M)
    offenders = [str(p.relative_to(ROOT)) for d in ("benchtwin", "twin", "analysis", "hw", "models", "scenarios")
                 for p in (ROOT / d).rglob("*.py") if pat.search(p.read_text(encoding="utf-8"))]
    assert not offenders, offenders
    assert not (ROOT / "analysis" / "effects" / "synthetic.py").exists()


def test_tracing_uses_the_one_fourier_engine_directly():
    """One implementation per concern (issue 16, item 5): the tracing package fits and evaluates its
    series with analysis/fourier.py and takes unit constants from benchtwin.units, not through the
    effect modules' helper names (analysis/effects/_base.py's fourier_fit / fourier_eval aliases)."""
    import re

    pat = re.compile(r"effects\._base|effects\s+import\s+_base|\bfourier_(fit|eval|integral)\b")
    offenders = [p.name for p in (ROOT / "analysis" / "tracing").glob("*.py") if pat.search(p.read_text(encoding="utf-8"))]
    assert not offenders, offenders
    uses = "".join(p.read_text(encoding="utf-8") for p in (ROOT / "analysis" / "tracing").glob("*.py"))
    assert "from ..fourier import" in uses


def test_the_floor_is_under_the_contract(tmp_path):
    """The floor modules of benchtwin/ (fsio, schema, runtime, ...) are in the layers contract: one
    of them importing the analysis is reported (issue 35: the floor under a contract)."""
    tree = _package_tree(tmp_path)
    schema = tree / "benchtwin" / "schema.py"
    schema.write_text(schema.read_text() + "\nfrom benchtwin.analysis import fourier  # noqa: E402,F401\n")
    r = _lint(tree)
    assert r.returncode != 0
    assert "over the floor BROKEN" in r.stdout, r.stdout  # the layers contract itself, not only the twin's
    assert "benchtwin.schema -> benchtwin.analysis.fourier" in r.stdout, r.stdout
