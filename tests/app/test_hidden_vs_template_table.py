"""docs/effects.md's hidden-effect table (issue 33 item 4, benchmarks/hidden_vs_template.py) covers
every scenario of scenarios/hidden/: a new hidden scenario without a row (or without a comparison in
the script) fails here. Fast: reads the TOML files and the doc, simulates nothing."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("hidden_vs_template", ROOT / "benchmarks" / "hidden_vs_template.py")
hvt = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(hvt)

SECTION = "## Hidden effects against the templates (issue 33 item 4)"


def table_rows(text: str) -> dict[str, str]:
    """Scenario name → its table row, from the section's table (a row may name several: the nulls)."""
    sec = text.split(SECTION, 1)[1]
    sec = re.split(r"\n## ", sec, maxsplit=1)[0]
    out: dict[str, str] = {}
    for line in sec.splitlines():
        if not line.startswith("| `"):
            continue
        first = line.split("|")[1]
        for name in re.findall(r"`([a-z0-9_]+)`", first):
            out[name] = line
    return out


def test_every_hidden_scenario_has_a_row_and_the_nulls_are_checked_identical():
    effects, nulls = hvt.hidden_names()
    assert len(effects) + len(nulls) == len(list((ROOT / "scenarios" / "hidden").glob("*.toml")))
    rows = table_rows((ROOT / "docs" / "effects.md").read_text(encoding="utf-8"))
    missing = sorted(n for n in set(effects) | set(nulls) if n not in rows)
    assert not missing, f"docs/effects.md's hidden-effect table has no row for {missing} (run benchmarks/hidden_vs_template.py)"
    for n in nulls:
        assert "identical" in rows[n] and "DIFFER" not in rows[n], rows[n]
    for n in effects:   # a row of numbers, or the library's "no template" with the difference's RMS
        cells = [c.strip() for c in rows[n].split("|")[1:-1]]
        assert len(cells) == 7, rows[n]
        assert re.fullmatch(r"\d+\.\d{4}", cells[4]), rows[n]
        assert re.fullmatch(r"\d+\.\d{4}", cells[5]) or "no template" in cells[3], rows[n]


def test_the_script_compares_every_effect_scenario():
    effects, nulls = hvt.hidden_names()
    assert set(effects) <= set(hvt.CASES), sorted(set(effects) - set(hvt.CASES))
    assert not set(nulls) & set(hvt.CASES)
    assert effects and nulls


def test_the_table_check_fails_without_a_row():
    """The check can fail: a doc missing one scenario's row (or a null's) is caught."""
    text = (ROOT / "docs" / "effects.md").read_text(encoding="utf-8")
    rows = table_rows(text)
    effects, nulls = hvt.hidden_names()
    gone = text.replace(rows[effects[0]] + "\n", "")
    assert effects[0] not in table_rows(gone)
    gone = text.replace(rows[nulls[0]] + "\n", "")
    assert not set(nulls) & set(table_rows(gone))
