"""The report shows the U band (issue 34, "Done when"): the close-loop's report.html opened in Debian's
headless chromium (as the live view's test does, tests/app/test_live.py), a real screenshot of the top
of the page, where the report opens with the calibration figure, and the band ± U found in its pixels
by its colour (figures_calibration.U_BAND_COLOR at U_BAND_ALPHA over white); the table's rows (θ,
error, u, U, k, ν) in the DOM the browser builds.

The check can fail: a copy of the report whose figure is the same figure with the band's two fills
removed is shot too, and shows no band."""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
from io import BytesIO
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_rgb

# xdist: one at a time on one worker (a headless browser waited for on a deadline; tests/conftest.py)
pytestmark = pytest.mark.xdist_group("serial")

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
WINDOW = (1280, 1200)  # CSS px: the body is at most 1100 px wide, the figure 880 × 616 px (8 × 5.6 in at 110 dpi)
_FIRST_IMG = re.compile(r'(<img alt="[^"]*" src="data:image/png;base64,)([A-Za-z0-9+/=]+)(")')


def _chromium(tmp: Path, *args: str) -> str:
    out = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                          "--no-first-run", "--hide-scrollbars", "--force-device-scale-factor=1",
                          f"--user-data-dir={tmp / 'profile'}", *args],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def _screenshot(html: Path, png: Path) -> np.ndarray:
    from PIL import Image

    # the browser's profile beside the screenshot, never in the report's folder (the session's
    # shared analysed run, read-only: tests/conftest.py jia_results)
    _chromium(png.parent / "shot", f"--screenshot={png}", f"--window-size={WINDOW[0]},{WINDOW[1]}", html.as_uri())
    with Image.open(png) as im:
        return np.asarray(im.convert("RGB"), dtype=int)


def _band_rgb() -> np.ndarray:
    """The band's colour on the page: U_BAND_COLOR at opacity U_BAND_ALPHA composited over white."""
    from benchtwin.analysis.report.figures_calibration import U_BAND_ALPHA, U_BAND_COLOR

    return 255.0 * (1.0 - U_BAND_ALPHA) + U_BAND_ALPHA * 255.0 * np.asarray(to_rgb(U_BAND_COLOR))


def _band_pixels(rgb: np.ndarray, tol: int = 4) -> np.ndarray:
    """Mask of the pixels within ±tol (8-bit, per channel) of the band's composited colour."""
    return np.all(np.abs(rgb - np.round(_band_rgb())) <= tol, axis=-1)


def _band_columns(mask: np.ndarray, depth_px: int = 20) -> int:
    """How many columns hold at least depth_px pixels of the band's colour."""
    return int((mask.sum(axis=0) >= depth_px).sum())


def _without_band_png(results: dict) -> tuple[bytes, bytes]:
    """The report's calibration figure drawn again as the report draws it, and once more with the
    band's fills (the fill_between collections of both axes) removed: (with, without)."""
    from matplotlib.collections import PolyCollection

    from benchtwin.analysis.calibration import calibration_curve
    from benchtwin.analysis.report.figures_calibration import fig_calibration_curve
    from benchtwin.analysis.report.html import _png

    c = calibration_curve(results)
    assert c is not None
    with_band = _png(fig_calibration_curve(c))
    fig = fig_calibration_curve(c)
    fills = [coll for ax in fig.axes for coll in ax.collections if isinstance(coll, PolyCollection)]
    assert len(fills) == 2  # the band in the top axes and in the bottom axes
    for coll in fills:
        coll.remove()
    return with_band, _png(fig)


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed (install.sh installs it)")
def test_report_shows_the_U_band_in_a_browser_screenshot(jia_results, tmp_path):
    out = jia_results.parent
    report = out / "report.html"
    html = report.read_text(encoding="utf-8")
    h2 = re.findall(r"<h2>(.*?)</h2>", html)
    assert h2[0].startswith("Calibration result")
    m = _FIRST_IMG.search(html)
    assert m is not None and html.index(h2[0]) < m.start() < html.index(f"<h2>{h2[1]}</h2>")
    fig_png = base64.b64decode(m.group(2))

    # the DOM chromium builds has the table: its heads and every row of calibration.csv
    dom = _chromium(tmp_path, "--dump-dom", report.as_uri())
    assert "<th>θ (°)</th><th>error α (″)</th><th>u (″)</th><th>U (″)</th><th>k</th><th>ν</th>" in dom
    rows = [ln.split(",") for ln in (out / "calibration.csv").read_text(encoding="utf-8").splitlines()
            if ln and not ln.startswith("#")][1:]
    assert len(rows) >= 10
    for r in rows:
        assert "<tr><td>" + "</td><td>".join(r[:5]) + "</td>" in dom

    # the band in the screenshot: the top of the page, where the figure is
    shot = _screenshot(report, tmp_path / "report.png")
    assert shot.shape[:2] == (WINDOW[1], WINDOW[0])
    band = _band_pixels(shot)
    cols = np.flatnonzero(band.any(axis=0))
    # plausible: a region, not the legend's swatches (~20 × 8 px) or anti-aliased edges of the blue
    # lines: at least 20 px of band colour in each of 400+ columns (θ over the turn; the axes are ~740
    # of the figure's 880 px wide) and thousands of pixels (the bottom panel's ± U about zero), inside
    # the figure's width
    assert _band_columns(band) >= 400, _band_columns(band)
    assert band.sum() >= 5000 and cols[-1] - cols[0] <= 880, (band.sum(), cols[:1], cols[-1:])
    # and as many as the figure's own pixels of that colour: the page shows the figure at its size, all of it
    from PIL import Image

    with Image.open(BytesIO(fig_png)) as im:
        own = _band_pixels(np.asarray(im.convert("RGB"), dtype=int)).sum()
    assert abs(int(band.sum()) - int(own)) <= 0.02 * own, (band.sum(), own)

    # the same page with the figure drawn without its band: the check sees no band
    with_band, without_band = _without_band_png(json.loads(jia_results.read_text(encoding="utf-8")))
    assert with_band == fig_png  # the figure redrawn is the report's figure, byte for byte
    bare = tmp_path / "bare" / "report.html"
    bare.parent.mkdir()
    bare.write_text(_FIRST_IMG.sub(lambda g: g.group(1) + base64.b64encode(without_band).decode() + g.group(3),
                                   html, count=1), encoding="utf-8")
    no_band = _band_pixels(_screenshot(bare, tmp_path / "bare.png"))
    assert _band_columns(no_band) <= 10 and no_band.sum() < 1000, (_band_columns(no_band), no_band.sum())
