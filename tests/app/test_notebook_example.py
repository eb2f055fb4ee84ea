"""The example notebook (docs/examples/notebook.py, `# %%` cells) runs in the suite (issue 34 item 5):
executed as the plain script it is (nbclient is not installed: README, dependencies), it simulates a
small bench, analyses it in memory, and leaves the results' table and a figure; it writes nothing
but the temporary dataset it removes."""

from __future__ import annotations

import runpy
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "docs" / "examples" / "notebook.py"


def test_the_example_notebook_runs_and_shows_a_table_and_a_figure(tmp_path, monkeypatch, capsys):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    monkeypatch.chdir(tmp_path)                          # anything written to the working folder would show
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    ns = runpy.run_path(str(EXAMPLE), run_name="__main__")
    out = capsys.readouterr().out
    df, r, fig = ns["df"], ns["r"], ns["fig"]
    assert list(df.columns) == ["theta_deg", "error_arcsec", "u_arcsec", "U_arcsec", "k"]
    assert len(df) == 8 and np.all(df["U_arcsec"] >= df["k"] * df["u_arcsec"] - 1e-12)
    assert 5.0 < r.eccentricity.value < 9.0                       # the scenario's 7.1 µm, at its u
    assert abs(r.eccentricity.value - 7.1) < 4 * r.eccentricity.u
    assert isinstance(fig, Figure) and fig.axes
    assert "eccentricity e =" in out and "theta_deg" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tmp"]    # nothing in the working folder
    assert list((tmp_path / "tmp").iterdir()) == []                 # the temporary dataset is gone
