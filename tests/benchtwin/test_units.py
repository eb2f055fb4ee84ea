"""Units parser: round trips, dimension checks, and garbage never parses silently."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from benchtwin.units import _QUANTITY, _UNITS, ARCSEC, UnitError, format_quantity, parse_quantity


def test_known_values():
    assert parse_quantity("7.1 um", "length") == pytest.approx(7.1e-6)
    assert parse_quantity("192.08 deg", "angle") == pytest.approx(math.radians(192.08))
    assert parse_quantity("0.005 arcsec", "angle") == pytest.approx(0.005 * math.pi / 648000)
    assert parse_quantity("150 N/um", "stiffness") == pytest.approx(1.5e8)
    assert parse_quantity("1e-3 mm", "length") == pytest.approx(1e-6)
    assert parse_quantity(0.5, "dimensionless") == 0.5
    assert ARCSEC == pytest.approx(math.pi / 648000)


@pytest.mark.parametrize("text,dim,words", [
    ("7.1", "length", "bare number"),
    ("7.1 deg", "length", "is a angle"),
    ("7.1 parsec", "length", "unknown unit"),
    ("um 7", "length", "cannot read"),
    ("nan um", "length", "cannot read"),
    ("1e999 um", "length", "not a finite"),
])
def test_rejects(text, dim, words):
    with pytest.raises(UnitError, match=words):
        parse_quantity(text, dim)


unit_names = st.sampled_from([u for u in _UNITS if u])


@given(x=st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False), unit=unit_names)
def test_format_parse_round_trip(x, unit):
    factor, dim = _UNITS[unit]
    si = x * factor
    assert parse_quantity(format_quantity(si, unit), dim) == pytest.approx(si, rel=1e-12, abs=1e-300)


@given(st.text(max_size=30))
def test_garbage_never_parses_silently(text):
    try:
        v = parse_quantity(text, "length")
    except UnitError:
        return
    # whatever parsed is a finite number followed by a length unit, nothing else
    m = _QUANTITY.match(text)
    assert m is not None and _UNITS[m.group(2)][1] == "length"
    assert math.isfinite(v)


def test_quantise_to_a_display_step():
    from benchtwin.units import quantise

    assert quantise(0.123456, 0.01) == 0.12              # a decimal step: the correctly rounded decimal
    assert repr(quantise(1.005001, 0.005)) == "1.005"
    assert quantise(1.0, 0.39) == 3 * 0.39               # any other step: the nearest multiple
    assert quantise(0.123456, 0.0) == 0.123456           # no step: unchanged


def test_unit_constants_live_only_in_the_units_module():
    """One place for unit factors: no module of the package defines its own arcsecond, degree or
    micrometre constant (they once were defined in 7 places); they import benchtwin.units."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    pattern = re.compile(r"^(ARCSEC|ARCSEC_PER_RAD|ARCSEC_RAD|DEG|UM|MM|NM)\s*=|648000|206264", re.M)
    offenders = []
    for folder in ("benchtwin", "twin", "analysis", "hw"):
        for p in (root / folder).rglob("*.py"):
            if p.name == "units.py" and p.parent.name == "benchtwin":
                continue
            offenders += [f"{p.relative_to(root)}: {m.group(0)}" for m in pattern.finditer(p.read_text())]
    assert not offenders, offenders
