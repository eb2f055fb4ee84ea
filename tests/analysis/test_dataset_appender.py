"""The incremental table writer (analysis.dataset.TableAppender): same bytes as write_table, rows
on disk after every append, atomic finish, clear errors."""

from __future__ import annotations

import pytest

from benchtwin.analysis.dataset import DatasetError, DatasetWriter, parse_table, table_to_csv

MANIFEST = {"format": "bench-dataset", "version": 1, "source": "hardware",
            "bench": {"optical_radius_mm": 22.0, "L1_mm": 6.81, "L2_mm": 122.96, "grating_period_um": 20.0,
                      "polygon_faces": 23}}


def test_appender_writes_the_same_bytes_as_write_table(tmp_path):
    cols = {"rep": [0, 0, 1], "theta_deg": [0.0, 0.1 + 0.2, 359.99999999999994],
            "probe_top_um": [1.25, -3e-7, 2.0], "probe_bottom_um": [0.0, 1.0, -1.5], "note": ["a", "b,c", 'd"e']}
    w = DatasetWriter(tmp_path / "ds", MANIFEST)
    t = w.open_table("radial_motion", list(cols))
    for k in range(3):
        if k == 1:
            t.append({c: cols[c][k] for c in cols})
        else:
            t.append([cols[c][k] for c in cols])
        # flushed: the rows taken so far are on disk, under the part name, not the final one
        assert t.part.read_text().count("\n") == k + 2
        assert not (tmp_path / "ds" / "radial_motion.csv").exists()
    t.close()
    w.close()
    assert (tmp_path / "ds" / "radial_motion.csv").read_bytes() == table_to_csv(cols)
    assert not t.part.exists()
    # the values read back exactly (the cells' reader: these three rows are no whole revolution, which
    # Dataset.table would refuse, analysis/structure.py)
    text = (tmp_path / "ds" / "radial_motion.csv").read_text()
    assert parse_table(text, "radial_motion", "radial_motion.csv")["theta_deg"].tolist() == cols["theta_deg"]


def test_appender_errors_and_abort(tmp_path):
    w = DatasetWriter(tmp_path / "ds", MANIFEST)
    with pytest.raises(DatasetError, match=r"polygon\.csv: missing required columns \['ac_arcsec'"):
        w.open_table("polygon", ["shift_deg", "start_face", "step", "theta_deg"])
    t = w.open_table("ccd/index", ["k", "theta_deg", "file"])
    with pytest.raises(DatasetError, match=r"index\.csv: row 2: expected 3 values, got 2"):
        t.append([0, 1.0])
    with pytest.raises(DatasetError, match=r"index\.csv: row 2: missing columns \['file'\]"):
        t.append({"k": 0, "theta_deg": 1.0})
    assert t.part == tmp_path / "ds" / "ccd" / ".index.csv.part" and t.part.exists()
    t.abort()
    assert not t.part.exists() and not (tmp_path / "ds" / "ccd" / "index.csv").exists()
