"""What the strict-reader tests share (tests/app/test_readers_strict.py, tests/app/test_fuzz_app_readers.py):
the shipped example lab file and JSON as a strict parser reads it."""

from __future__ import annotations

import json
from pathlib import Path

LAB = Path(__file__).resolve().parents[2] / "docs" / "lab.example.toml"


def strict_json(text: str):
    """JSON as a strict parser reads it: NaN / Infinity are not JSON."""
    def bad(name):
        raise ValueError(f"{name} is not JSON")
    return json.loads(text, parse_constant=bad)
