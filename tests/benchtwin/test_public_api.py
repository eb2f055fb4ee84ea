"""The curated public API (docs/api.md): every exported name resolves, docs/api.md names each one,
and the exports are lazy (importing the package or the dataset format loads nothing heavy)."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ["benchtwin", "benchtwin.analysis", "benchtwin.twin", "benchtwin.hw"]


@pytest.mark.parametrize("package", PACKAGES)
def test_every_export_resolves_and_is_documented(package):
    mod = importlib.import_module(package)
    doc = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    assert mod.__all__, package
    for name in mod.__all__:
        assert getattr(mod, name) is not None, f"{package}.{name}"
        assert f"`{name}`" in doc, f"docs/api.md does not name {package}.{name}"
        assert name in dir(mod)
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        _ = mod.no_such_name


def test_exports_are_lazy():
    code = ("import sys, benchtwin, benchtwin.analysis.dataset, benchtwin.hw, benchtwin.twin; "
            "heavy = [m for m in ('mujoco', 'matplotlib', 'benchtwin.analysis.pipeline', 'benchtwin.hw.drivers.base', "
            "'benchtwin.twin.physics') if m in sys.modules]; print(heavy)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "[]", r.stdout + r.stderr
