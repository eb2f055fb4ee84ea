"""The one CSV row reader (benchtwin.schema.csv_rows) that every table reader uses: rows numbered as
in a text editor, and text csv cannot parse or that holds NUL bytes is the caller's error type,
naming the file and the row."""

from __future__ import annotations

import pytest

from benchtwin.schema import csv_rows


class TableError(ValueError):
    pass


def test_rows_are_numbered_from_the_header():
    assert list(csv_rows("a,b\n1,2\n\n3,4\n", "t.csv")) == [(1, ["a", "b"]), (2, ["1", "2"]), (3, []),
                                                             (4, ["3", "4"])]


def test_a_cell_over_csvs_field_limit_names_the_row():
    text = "a,b\n1,2\n" + "x" * 200_000 + ",3\n"
    with pytest.raises(TableError, match=r"t\.csv: row 3: not valid CSV"):
        list(csv_rows(text, "t.csv", TableError))


def test_nul_bytes_are_refused_before_any_row():
    rows = csv_rows("a,b\n1,\x002\n", "t.csv", TableError)
    with pytest.raises(TableError, match=r"t\.csv: contains NUL bytes"):
        next(rows)
