"""Issue 31, "one writing rule for every command" (benchtwin/fsio.py; docs/reliability.md):

1. ``--force`` never breaks a live lock (a real process holds it), and a dead owner's lock (or a
   reused pid's) is taken over; acquire's message says what ``--force`` deleted;
2. no existing file or folder is replaced without ``--force`` (certificate, calibrate-twin,
   import, suite, emulate --dir, the live page, the API ``analyze``);
3. an input is never an output, even with ``--force`` (same path, symlink, hard link, a folder that
   contains the input);
4. abandoned ``.OUT.partial-*`` folders of dead owners are removed by the next run into OUT;
5. a second analyze/run into a folder a live run holds is refused, naming the pid;
6. the Python ``analyze()`` has the CLI's rule (``force=``).

Fast: small hand-made error-curve datasets (``benchtwin import`` of a 36-row table, analysed in
about a second); the twin's simulation is replaced where a command would start one. Processes
that hold a lock are real, killed at the end of each test.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from benchtwin.cli import main
from benchtwin.fsio import LOCK_NAME, DirLock, OutputError
from tests.support.bench_file import loop_bench_file

ROOT = Path(__file__).resolve().parents[2]
JIA = ROOT / "scenarios" / "jia2019.toml"


def _cli(args, capsys, code):
    rc = main([*args, "--json"])
    obj = json.loads(capsys.readouterr().out.strip())
    assert rc == code, obj
    return obj


def _err(args, capsys, *words):
    obj = _cli(args, capsys, 2)
    for w in words:
        assert w in obj["error"], f"{w!r} not in {obj['error']!r}"
    return obj["error"]


def _start_time(pid: int) -> int | None:
    """The process's start time in clock ticks (proc(5): field 22 of /proc/PID/stat), or None."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return int(stat[stat.rindex(")") + 2:].split()[19])


def _table(path: Path) -> Path:
    rows = [f"{10.0 * i},{0.5 * math.sin(math.radians(10 * i)) + 0.2 * math.cos(math.radians(20 * i)):.4f}"
            for i in range(36)]
    path.write_text("angle,err\n" + "\n".join(rows) + "\n")
    return path


def _import(table: Path, out: Path, capsys, *extra, code=0):
    return _cli(["import", str(table), "-o", str(out), "--angle", "angle", "--error", "err", *extra], capsys, code)


@pytest.fixture
def curve(tmp_path, capsys):
    """An error-curve dataset and its analysis folder (results.json, report.html)."""
    ds = tmp_path / "ds"
    _import(_table(tmp_path / "t.csv"), ds, capsys)
    out = tmp_path / "out"
    _cli(["analyze", str(ds), "-o", str(out)], capsys, 0)
    return ds, out


class Holder:
    """A real process that takes ``folder``'s lock (benchtwin.fsio.DirLock) and sleeps."""

    def __init__(self, folder: Path):
        code = ("import sys, time\nfrom benchtwin.fsio import DirLock\nDirLock(sys.argv[1], 'acquire').acquire()\n"
                "print('locked', flush=True)\ntime.sleep(120)\n")
        self.p = subprocess.Popen([sys.executable, "-c", code, str(folder)], stdout=subprocess.PIPE, text=True,
                                  cwd=ROOT)
        assert self.p.stdout is not None
        line = self.p.stdout.readline()  # returns at once if the child dies
        assert line.strip() == "locked", f"lock holder did not start (exit {self.p.poll()})"
        self.pid = self.p.pid

    def stop(self) -> None:
        self.p.kill()
        self.p.wait(timeout=30)
        if self.p.stdout is not None:
            self.p.stdout.close()


@pytest.fixture
def holder():
    started: list[Holder] = []

    def start(folder: Path) -> Holder:
        h = Holder(folder)
        started.append(h)
        return h

    yield start
    for h in started:
        h.stop()


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait(timeout=30)
    return p.pid


def _no_simulation(monkeypatch):
    """Any simulation a command would start fails at once (a refused command never gets there)."""
    import benchtwin.twin.simulate as simulate

    def fail(*a, **k):
        raise AssertionError("the simulation started")

    monkeypatch.setattr(simulate, "_simulate", fail)


def _journal(folder: Path, steps: int) -> str:
    folder.mkdir(parents=True, exist_ok=True)
    text = '{"journal": "benchtwin-run", "version": 1}\n' + "".join(f'{{"i": {i}}}\n' for i in range(steps))
    (folder / "journal.jsonl").write_text(text)
    return text


# ----------------------------------------------------------------------------- 1. --force and live locks


class TestForceNeverBreaksALiveLock:
    def test_acquire_force_onto_a_running_acquisition_keeps_its_journal(self, tmp_path, capsys, holder):
        out = tmp_path / "run"
        journal = _journal(out, 310)
        h = holder(out)
        _err(["acquire", str(loop_bench_file(tmp_path)), "-o", str(out), "--force"], capsys, str(out), f"pid {h.pid}",
             "--force never breaks a live lock")
        assert (out / "journal.jsonl").read_text() == journal
        assert (out / LOCK_NAME).read_text().split()[0] == str(h.pid)

    def test_simulate_force_onto_a_running_simulate_keeps_its_folder(self, tmp_path, capsys, holder, monkeypatch):
        _no_simulation(monkeypatch)
        out = tmp_path / "ds"
        journal = _journal(out, 40)
        h = holder(out)
        _err(["simulate", str(JIA), "-o", str(out), "--force"], capsys, f"pid {h.pid}")
        assert (out / "journal.jsonl").read_text() == journal

    def test_a_dead_owners_lock_and_a_reused_pids_lock_are_taken_over(self, tmp_path, holder):
        d = tmp_path / "d"
        d.mkdir()
        (d / LOCK_NAME).write_text(f"{_dead_pid()}\n")  # the owner was killed -9
        with DirLock(d):
            assert (d / LOCK_NAME).read_text().split()[0] == str(os.getpid())
        # a lock naming a live pid whose process started at another time: the pid was reused
        other = holder(tmp_path / "elsewhere")
        start = _start_time(other.pid)
        if start is None:
            pytest.skip("no /proc start times on this system")
        (d / LOCK_NAME).write_text(f"{other.pid} {start + 1}\n")
        with DirLock(d):
            assert (d / LOCK_NAME).read_text().split()[0] == str(os.getpid())
        # the same pid with its true start time is a live owner
        (d / LOCK_NAME).write_text(f"{other.pid} {start}\n")
        with pytest.raises(OutputError, match=f"pid {other.pid}"):
            DirLock(d).acquire()

    def test_acquire_force_says_that_it_deleted_the_earlier_readings(self, tmp_path, capsys, monkeypatch):
        from benchtwin.hw.acquisition import acquire as acq
        from benchtwin.hw.drivers.base import InstrumentError

        out = tmp_path / "run"
        _journal(out, 310)

        def failing(cfg, out_, *a, **k):
            _journal(out_, 1)  # this run's first step, then the instrument stops answering
            raise InstrumentError("autocollimator", "read", "no reply", b"", attempts=3)

        monkeypatch.setattr(acq, "_acquire", failing)
        msg = _err(["acquire", str(loop_bench_file(tmp_path)), "-o", str(out), "--force"], capsys,
                   "the readings this run took are kept", "--force deleted the folder's earlier contents")
        assert "the readings taken so far" not in msg


# ----------------------------------------------------------------------------- 2. nothing replaced without --force


class TestNothingReplacedWithoutForce:
    def test_certificate(self, tmp_path, capsys, curve):
        _, out = curve
        c = tmp_path / "c.xml"
        c.write_text("a file of the user")
        _err(["certificate", str(out / "results.json"), "-o", str(c)], capsys, "c.xml", "exists", "--force")
        assert c.read_text() == "a file of the user"
        _cli(["certificate", str(out / "results.json"), "-o", str(c), "--force"], capsys, 0)
        assert c.read_text().startswith("<?xml")

    def test_calibrate_twin(self, tmp_path, capsys, curve):
        ds, out = curve
        s = tmp_path / "s.toml"
        s.write_text("a file of the user")
        _err(["calibrate-twin", str(ds), "-o", str(s), "--results", str(out / "results.json")], capsys,
             "s.toml", "exists", "--force")
        assert s.read_text() == "a file of the user"

    def test_import_needs_force_for_a_non_empty_folder(self, tmp_path, capsys):
        t = _table(tmp_path / "t.csv")
        ds = tmp_path / "ds"
        ds.mkdir()
        (ds / "notes.txt").write_text("a file of the user")
        _err(["import", str(t), "-o", str(ds), "--angle", "angle", "--error", "err"], capsys, "not empty", "--force")
        assert (ds / "notes.txt").is_file()
        _import(t, ds, capsys, "--force")
        assert not (ds / "notes.txt").exists() and (ds / "error_curve.csv").is_file()

    def test_suite_needs_force_for_a_non_empty_folder(self, tmp_path, capsys, monkeypatch):
        import benchtwin.app.suite as suite

        monkeypatch.setattr(suite, "_simulate_one", lambda *a: pytest.fail("the suite started simulating"))
        out = tmp_path / "suite"
        out.mkdir()
        (out / "graduation_error").mkdir()
        (out / "graduation_error" / "notes.txt").write_text("a file of the user")
        _err(["suite", "-o", str(out), "--size", "small"], capsys, "not empty", "--force")
        assert (out / "graduation_error" / "notes.txt").is_file()

    def test_the_live_page_is_not_replaced(self, tmp_path, capsys, monkeypatch):
        _no_simulation(monkeypatch)
        page = tmp_path / "ds.live.html"
        page.write_text("a file of the user")
        _err(["simulate", str(JIA), "-o", str(tmp_path / "ds"), "--live"], capsys, "ds.live.html", "exists", "--force")
        assert page.read_text() == "a file of the user"

    def test_emulate_dir_of_the_user_is_not_used(self, tmp_path, capsys):
        d = tmp_path / "emu"
        d.mkdir()
        (d / "notes.txt").write_text("a file of the user")
        _err(["emulate", "--camera", "none", "--dir", str(d), "--duration", "0.1"], capsys, "not empty", "--force")
        assert [p.name for p in d.iterdir()] == ["notes.txt"]

    def test_api_analyze_has_the_cli_rule(self, tmp_path, curve):
        from benchtwin import analyze

        ds, _ = curve
        out = tmp_path / "api"
        out.mkdir()
        (out / "notes.txt").write_text("a file of the user")
        with pytest.raises(OutputError, match="not empty.*--force"):
            analyze(ds, out, progress=False)
        assert [p.name for p in out.iterdir()] == ["notes.txt"]
        res = analyze(ds, out, force=True, progress=False)
        assert sorted(p.name for p in out.iterdir()) == ["calibration.csv", "compensation.csv", "report.html", "results.json"]
        assert res["paths"]["results"] == str(out / "results.json")
        assert str(tmp_path / ".api.partial") not in (out / "report.html").read_text()


# ----------------------------------------------------------------------------- 3. an input is never an output


class TestAnInputIsNeverAnOutput:
    def test_certificate_onto_its_results_by_name_symlink_or_hard_link(self, tmp_path, capsys, curve):
        _, out = curve
        r = out / "results.json"
        before = r.read_bytes()
        (tmp_path / "link.xml").symlink_to(r)
        os.link(r, tmp_path / "hard.xml")
        for target in (r, tmp_path / "link.xml", tmp_path / "hard.xml"):
            _err(["certificate", str(r), "-o", str(target), "--force"], capsys, "is the input", "even with --force")
        assert r.read_bytes() == before

    def test_certificate_onto_its_lab_file(self, tmp_path, capsys, curve):
        _, out = curve
        lab = tmp_path / "lab.toml"
        lab.write_text("")
        _err(["certificate", str(out / "results.json"), "--lab", str(lab), "-o", str(lab), "--force"], capsys,
             "is the input")
        assert lab.read_text() == ""

    def test_calibrate_twin_into_its_dataset(self, tmp_path, capsys, curve):
        ds, out = curve
        m = (ds / "manifest.json").read_bytes()
        _err(["calibrate-twin", str(ds), "-o", str(ds / "manifest.json"), "--results", str(out / "results.json"),
              "--force"], capsys, "lies inside the input")
        assert (ds / "manifest.json").read_bytes() == m

    def test_analyze_onto_or_around_its_dataset(self, tmp_path, capsys, curve):
        ds, _ = curve
        files = sorted(p.name for p in ds.iterdir())
        _err(["analyze", str(ds), "-o", str(ds), "--force"], capsys, "is the input")
        _err(["analyze", str(ds), "-o", str(tmp_path), "--force"], capsys, "contains the input")
        (tmp_path / "alias").symlink_to(ds)
        _err(["analyze", str(ds), "-o", str(tmp_path / "alias"), "--force"], capsys, "is the input")
        assert sorted(p.name for p in ds.iterdir()) == files

    def test_import_and_simulate_into_a_folder_holding_their_input(self, tmp_path, capsys, monkeypatch):
        _no_simulation(monkeypatch)
        d = tmp_path / "d"
        d.mkdir()
        t = _table(d / "t.csv")
        _err(["import", str(t), "-o", str(d), "--angle", "angle", "--error", "err", "--force"], capsys,
             "contains the input")
        s = d / "s.toml"
        s.write_text(JIA.read_text())
        _err(["simulate", str(s), "-o", str(d), "--force"], capsys, "contains the input")
        assert sorted(p.name for p in d.iterdir()) == ["s.toml", "t.csv"]


# ----------------------------------------------------------------------------- 4. abandoned partial folders


class TestAbandonedPartialFoldersAreCleaned:
    def test_the_next_analyze_removes_dead_owners_partials_only(self, tmp_path, capsys, curve, holder):
        ds, _ = curve
        out = tmp_path / "res"
        live = holder(tmp_path / "elsewhere")
        start = _start_time(live.pid) or 0
        dead_old = tmp_path / f".res.partial-{_dead_pid()}-abcd1234"               # killed, earlier naming
        dead_new = tmp_path / f".res.partial-{_dead_pid()}-77-abcd1234"
        old_aside = tmp_path / f".res.old-{_dead_pid()}-77-abcd1234"                # killed while swapping
        reused = tmp_path / f".res.partial-{live.pid}-{start + 1}-abcd1234"         # its pid now another process
        running = tmp_path / f".res.partial-{live.pid}-{start}-abcd1234"            # its owner still runs
        other = tmp_path / f".other.partial-{_dead_pid()}-abcd1234"                 # another target's
        for p in (dead_old, dead_new, old_aside, reused, running, other):
            p.mkdir()
            (p / "results.json").write_text("{}")
        _cli(["analyze", str(ds), "-o", str(out)], capsys, 0)
        left = {p.name for p in tmp_path.iterdir()}
        assert not {dead_old.name, dead_new.name, old_aside.name} & left
        assert running.name in left and other.name in left
        if _start_time(live.pid) is not None:
            assert reused.name not in left


# ----------------------------------------------------------------------------- 5. two runs into one folder


class TestTwoRunsIntoOneFolder:
    def test_analyze_into_a_folder_a_live_run_holds_is_refused(self, tmp_path, capsys, curve, holder):
        ds, _ = curve
        out = tmp_path / "res"
        h = holder(out)
        for flags in ([], ["--force"]):
            _err(["analyze", str(ds), "-o", str(out), *flags], capsys, f"pid {h.pid}")
            _err(["close-loop", str(ds), "-o", str(out), *flags], capsys, f"pid {h.pid}")
        assert [p.name for p in out.iterdir()] == [LOCK_NAME]

    def test_run_into_a_folder_a_live_run_holds_is_refused(self, tmp_path, capsys, holder, monkeypatch):
        import benchtwin.twin.simulate as simulate

        monkeypatch.setattr(simulate, "simulate_apart", lambda *a, **k: pytest.fail("the run started"))
        out = tmp_path / "out"
        h = holder(out)
        _err(["run", str(JIA), "-o", str(out), "--force"], capsys, f"pid {h.pid}")

    def test_the_lock_is_held_until_the_output_is_in_place(self, tmp_path, curve):
        from benchtwin.fsio import AtomicDir

        out = tmp_path / "res"
        with AtomicDir(out) as tmp:
            assert (out / LOCK_NAME).read_text().split()[0] == str(os.getpid())
            (tmp / "results.json").write_text("{}")
            with pytest.raises(OutputError, match="already holds the lock"):
                AtomicDir(out, force=True).__enter__()
        assert sorted(p.name for p in out.iterdir()) == ["results.json"]
        assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".res")) == []

    def test_api_analyze_refuses_a_live_run_even_with_force(self, tmp_path, curve, holder):
        from benchtwin import analyze

        ds, _ = curve
        out = tmp_path / "res"
        h = holder(out)
        with pytest.raises(OutputError, match=f"pid {h.pid}"):
            analyze(ds, out, force=True, progress=False)
