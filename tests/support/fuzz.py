"""What the fuzz tests share (tests/benchtwin/test_fuzz_readers.py, tests/app/test_fuzz_app_readers.py): the
bounded, derandomised settings, hostile values of every JSON/TOML type, and a valid parsed file
with a few values replaced, deleted or added."""

from __future__ import annotations

import copy

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

FUZZ = settings(max_examples=60, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

# values a hostile file can hold: every JSON/TOML type, edge numbers, odd strings
_scalar = st.one_of(
    st.none(), st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, -1, 1, 2**63, -(2**63) - 1, 10**30]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.sampled_from(["", "1_000", "1e400", "nan", "inf", "7 mm", "7 kg", "-1 deg", "1e300 deg", "../x", "/etc/passwd",
                     "forward", "sideways", "0 deg", "٣ mm", "\x00", "a" * 300]),
)
any_value = st.recursive(_scalar, lambda c: st.one_of(st.lists(c, max_size=4),
                                                     st.dictionaries(st.text(max_size=6), c, max_size=4)), max_leaves=8)


def _paths(obj, prefix=()):
    """Every (path) into nested dicts/lists of a parsed file."""
    out = [prefix]
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out += _paths(v, prefix + (i,))
    return out


@st.composite
def mutated(draw, base):
    """A valid parsed file with 1-3 values replaced, deleted or added at random paths."""
    obj = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(obj) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = obj
        for k in path[:-1]:
            parent = parent[k]
        op = draw(st.sampled_from(["replace", "replace", "delete", "add"]))
        if op == "delete":
            del parent[path[-1]]
        elif op == "add" and isinstance(parent, dict):
            parent[draw(st.text(min_size=1, max_size=6))] = draw(any_value)
        else:
            parent[path[-1]] = draw(any_value)
    return obj
