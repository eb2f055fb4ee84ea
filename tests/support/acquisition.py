"""Helpers of the emulator and acquisition tests: a fixed reading source, and a table comparison."""

from __future__ import annotations

import numpy as np


class Stub:
    """A reading source: fixed readings per instrument, moves recorded."""

    def __init__(self, **readings):
        self.readings = readings
        self.moves: list[float] = []
        self.position_deg = 0.0
        self.speed_deg_s = 20.0

    def read(self, name):
        return dict(self.readings[name])

    def move(self, target):
        self.moves.append(target)
        return target


def compare_tables(a: dict, b: dict, *, skip=("t_s",)) -> None:
    """Two datasets' tables ({table: {column: values}}) agree: floats bit for bit, the ND display's
    angle to its 6 decimals of a degree, the other columns as text; ``skip`` columns are not compared."""
    assert set(a) == set(b)
    for name in a:
        assert set(a[name]) == set(b[name]), name
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
