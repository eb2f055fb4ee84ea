"""The live view (issue 20): unit checks of the page, and the page of a running emulated acquisition
opened in Debian's headless chromium (a real browser: the DOM it builds shows the numbers)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from benchtwin.app.live import LiveView, live_path
from benchtwin.hw.acquisition.procedures import Mark

# xdist: one at a time on one worker (a headless browser waited for on a deadline; tests/conftest.py)
pytestmark = pytest.mark.xdist_group("serial")

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


class FakeClock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def _row(i, proc, t, **readings):
    return {"i": i, "type": "read", "t_s": t, "tag": {"procedure": proc, "rep": 0, "shift_deg": 0.0, "start_face": 1,
                                                       "target_deg": 15.0 * i},
            "readings": {"encoder": {"angle_deg": [15.0 * i], "status": "ok"}, **readings}}


def test_page_throttled_atomic_and_with_units(tmp_path):
    clock = FakeClock()
    lv = LiveView(tmp_path / "ds.live.html", "acquire demo", 0, min_interval_s=5.0, clock=clock)
    lv.start(100)
    assert lv.writes == 1
    for i in range(10):
        clock.t += 1.0
        lv.on_step(i, Mark(f"polygon clamp {i}"), {"procedure": "polygon"}, False)
        lv.on_row(_row(i, "polygon", 3.0 * i, autocollimator={"x_arcsec": 1.5 + i, "y_arcsec": 0.1, "status": "ok"}))
    assert lv.writes == 3  # 20 callbacks over 10 s of wall time, at most one write per 5 s
    text = (tmp_path / "ds.live.html").read_text()
    assert 'http-equiv="refresh"' in text
    assert not (tmp_path / "ds.live.html.part").exists()
    lv.close("finished")
    text = (tmp_path / "ds.live.html").read_text()
    assert "10 / 100 steps (10.0 %)" in text and "x_arcsec = 10.5" in text and "polyline" in text
    assert "refresh" not in text.split("<title>")[0]  # a finished run's page stops reloading
    assert lv.eta_s() == pytest.approx(90 * 10.0 / 10)


def test_eta_ignores_replayed_steps(tmp_path):
    clock = FakeClock()
    lv = LiveView(tmp_path / "p.html", "t", 0, clock=clock)
    lv.start(200)
    for i in range(100):
        lv.on_step(i, Mark("x"), {}, True)  # resumed from the journal: instantaneous
    for i in range(100, 110):
        clock.t += 2.0
        lv.on_step(i, Mark("x"), {}, False)
    assert lv.eta_s() == pytest.approx(90 * 2.0)


def test_live_path_is_beside_the_dataset(tmp_path):
    assert live_path(tmp_path / "run1") == tmp_path / "run1.live.html"


def _dom(url: str, tmp: Path) -> str:
    out = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                          "--no-first-run", f"--user-data-dir={tmp}", "--dump-dom", url],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed (install.sh installs it)")
@pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")
def test_live_page_in_headless_chromium_while_an_emulated_acquisition_runs(tmp_path):
    from benchtwin.twin.emulators.serve import EmulationSession
    from benchtwin.twin.scenario import load_scenario

    sc = load_scenario().with_overrides({
        "procedure.radial_positions": 36, "procedure.radial_reps": 1, "procedure.polygon_shifts": ["0 deg", "5 deg"],
        "procedure.polygon_reps": 1, "procedure.directions": ["forward"]})
    ds = tmp_path / "ds"
    page = live_path(ds)
    with EmulationSession(sc, camera=None) as session:
        bench = session.start(tmp_path / "emulator")
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        proc = subprocess.Popen([sys.executable, "-c", "import sys; from benchtwin.cli import main; sys.exit(main())", "acquire", str(bench), "-o", str(ds), "--live",
                                 "--live-interval", "0.2", "--quiet"], cwd=ROOT, env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 120
            seen = None
            while time.monotonic() < deadline and proc.poll() is None:
                if page.exists():
                    t = page.read_text(encoding="utf-8")
                    m = re.search(r"(\d+) / (\d+) steps", t)
                    if m and int(m.group(1)) > 20 and "autocollimator" in t:
                        seen = t
                        break
                time.sleep(0.1)
            assert seen is not None, f"no live page with progress while acquiring: {proc.poll()} {proc.stderr.read() if proc.poll() is not None else ''}"
            dom = _dom(page.as_uri(), tmp_path / "chromium")
            running_after = proc.poll() is None
            out, err = proc.communicate(timeout=300)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert proc.returncode == 0, err[-2000:]
    assert running_after, "the acquisition ended before the browser had read the page: nothing was checked live"
    # the browser's DOM: status, step, progress with numbers, readings with units, the running plot
    assert re.search(r'id="status"[^>]*>running<', dom)
    m = re.search(r'id="progress">(\d+) / (\d+) steps \(([\d.]+) %\)', dom)
    assert m and 0 < int(m.group(1)) < int(m.group(2))
    assert re.search(r'id="eta">\d+ (s|min|h)', dom)
    assert re.search(r"x_arcsec = -?\d", dom) and re.search(r"value_um = -?\d", dom)
    assert "<svg" in dom and "polyline" in dom
    final = _dom(page.as_uri(), tmp_path / "chromium2")
    assert re.search(r'id="status"[^>]*>finished<', final)
    n = re.search(r'id="progress">(\d+) / (\d+) steps', final)
    assert n and n.group(1) == n.group(2)
    assert (ds / "manifest.json").is_file()


def test_live_interval_must_be_positive(tmp_path, capsys):
    from benchtwin.cli import main

    assert main(["simulate", "-o", str(tmp_path / "ds"), "--live", "--live-interval", "0", "--json"]) == 2
    cap = capsys.readouterr()
    assert "--live-interval" in (cap.err or cap.out)
    assert not (tmp_path / "ds").exists()


def test_alpha_so_far_converges_to_alpha_when_all_start_faces_are_done(tmp_path):
    """ε_ij = α(θ_i) + Σ_{k=j}^{j+i−1} β_k + U_j (Hsieh eq. 3) with all N start faces: α comes back."""
    import numpy as np

    N = 6
    th = np.arange(N) * 360.0 / N
    alpha = 0.8 * np.sin(np.deg2rad(th)) + 0.3 * np.cos(np.deg2rad(2 * th))
    alpha -= alpha.mean()
    beta = np.array([0.5, -0.2, 0.1, -0.6, 0.3, -0.1])
    lv = LiveView(tmp_path / "a.html", "t", 0, clock=FakeClock())
    lv.start(N * N)
    partial = None
    for j in range(N):
        for i in range(N):
            eps = alpha[i] + sum(beta[(j + k) % N] for k in range(i)) + 0.7 * j  # U_j: a set-up offset per run
            lv.on_row({"type": "read", "t_s": 1.0, "tag": {"procedure": "polygon", "shift_deg": 0.0, "start_face": j + 1,
                                                          "rep": 0, "direction": "forward", "target_deg": th[i]},
                       "readings": {"encoder": {"angle_deg": [th[i]]}, "autocollimator": {"x_arcsec": eps, "status": "ok"}}})
        if j == 1:
            partial = lv.alpha_so_far()
    lv.close()
    (t, a, n), = lv.alpha_so_far().values()
    assert n == N and np.allclose(t, th)
    np.testing.assert_allclose(a, alpha, atol=1e-12)
    (_, a1, n1), = partial.values()
    assert n1 == 1 and np.max(np.abs(np.array(a1) - alpha)) > 0.1  # one run: β not averaged out yet
    assert 'data-kind="alpha"' in (tmp_path / "a.html").read_text()
