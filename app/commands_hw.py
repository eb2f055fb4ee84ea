"""Hardware-side subcommands: ``emulate`` (serve a scenario's instruments on pseudo-terminals) and
``acquire`` (run a bench file's procedures on real or emulated instruments -> dataset).

Registered by ``benchtwin.cli._load_commands`` (module name ``benchtwin.app.commands_hw``).
"""

from __future__ import annotations

import argparse
import errno
import signal
import threading
from pathlib import Path
from typing import Any

from benchtwin.cli import InputError, command, force_argument


def _emulate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", type=Path, nargs="?", default=None,
                   help="scenario file (default: the embedded jia2019 scenario)")
    p.add_argument("--faults", type=Path, default=None,
                   help="fault plan (TOML/JSON, [[faults]] port/request/action/seconds; see docs/bench-file.md)")
    p.add_argument("--dir", type=Path, default=None,
                   help="where the port links and bench.toml go (default: a new temporary directory)")
    p.add_argument("--autocollimator", choices=("elcomat", "triangle"), default="elcomat")
    p.add_argument("--probes", choices=("millimar", "tesa"), default="millimar")
    p.add_argument("--camera", choices=("auto", "pyrender", "analytic", "none"), default="auto",
                   help="render backend of the hot-folder CCD camera (frames in DIR/frames; the bench file then "
                        "runs the CCD sweep too, as simulate does); 'none': no camera, no CCD sweep")
    p.add_argument("--tcp", action="store_true",
                   help="serve the instruments on loopback TCP sockets (their Ethernet interfaces) instead of "
                        "pseudo-terminals; the bench file names tcp://127.0.0.1:PORT ports")
    p.add_argument("--tcp-port", type=int, default=0,
                   help="with --tcp: first port (the k-th instrument gets PORT+k); default 0: free ports")
    p.add_argument("--duration", type=float, default=None,
                   help="stop after this many seconds (default: run until Ctrl-C / SIGTERM)")
    force_argument(p, "use a non-empty --dir (deletes its contents; an earlier emulator's own folder is reused "
                   "without it; never the folder of a live emulator)")


@command("emulate", "serve a scenario's instruments on pseudo-terminals; writes a bench file for `acquire`",
         _emulate_args)
def cmd_emulate(ns: argparse.Namespace) -> dict[str, Any]:
    import tempfile

    from benchtwin.twin.emulators.pty import load_fault_plan
    from benchtwin.twin.scenario import ScenarioError, load_scenario

    try:
        sc = load_scenario(ns.scenario)
        faults = load_fault_plan(ns.faults) if ns.faults is not None else None
    except (ScenarioError, ValueError) as exc:
        raise InputError(str(exc)) from None
    directory = ns.dir or Path(tempfile.mkdtemp(prefix="benchtwin-emulate-"))
    from benchtwin.fsio import OutputFolder, locked_output_dir

    # the writing rule (benchtwin.fsio): --dir is held under its lock while the emulator runs; an
    # earlier emulator's own folder (its bench file, port links and frames) is replaced, anything
    # else needs --force; never a folder holding the scenario or the fault plan
    own = {"bench.toml", "ports", "frames", ".benchtwin.lock"}
    earlier = directory.is_dir() and not directory.is_symlink() and (directory / "bench.toml").is_file() and all(
        c.name in own for c in directory.iterdir())
    try:
        with locked_output_dir(directory, OutputFolder("emulator folder (--dir)", "emulate"),
                               force=ns.force or earlier, inputs=[ns.scenario, ns.faults]):
            return _emulate(ns, sc, faults, directory)
    finally:
        if ns.dir is None:  # the temporary folder made above: removed if the run left nothing in it
            try:
                directory.rmdir()
            except OSError:
                pass


def _emulate(ns: argparse.Namespace, sc: Any, faults: Any, directory: Path) -> dict[str, Any]:
    from benchtwin.twin.emulators.serve import EmulationSession

    session = EmulationSession(sc, faults=faults, autocollimator=ns.autocollimator, probes=ns.probes,
                               camera=None if ns.camera == "none" else ns.camera, tcp=ns.tcp,
                               tcp_base_port=ns.tcp_port)
    try:
        bench = session.start(directory)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    stop = threading.Event()
    old = signal.signal(signal.SIGTERM, lambda *a: stop.set())
    if not (ns.quiet or ns.json):
        pts = session.server.pts() if session.server is not None and not ns.tcp else {}
        for name, link in session.ports().items():
            ser = session.emulators[name].SERIAL
            line = "" if ns.tcp else f", {ser['baudrate']} {ser['bytesize']}{ser['parity']}{ser['stopbits']}"
            where = f" -> {pts[name]}" if name in pts else ""
            print(f"{name:16s} {link}{where}  ({session.emulators[name].PROTOCOL}{line})", flush=True)
        if session.camera is not None:
            print(f"{'ccd':16s} {session.camera.folder} (hot folder: numbered PNG frames)", flush=True)
    print(f"bench file: {bench}", flush=True)
    import time

    t_end = None if ns.duration is None else time.monotonic() + ns.duration
    shown: dict[str, int] = {}
    try:
        while not stop.wait(0.2 if t_end is None else max(0.0, min(0.2, t_end - time.monotonic()))):
            if not (ns.quiet or ns.json):
                # a client at the wrong baud rate gets silence, as from the real instrument: say why
                for name, emu in session.emulators.items():
                    for note in emu.framing_notes[shown.get(name, 0):]:
                        print(f"warning: {note}", flush=True)
                    shown[name] = len(emu.framing_notes)
            if t_end is not None and time.monotonic() >= t_end:
                break
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, old)
        session.stop()
    return {"ok": True, "bench_file": str(bench), "ports": session.ports() or {},
            "faults_fired": session.server.fired() if session.server else [],
            "message": f"emulator stopped (bench file was {bench})"}


def _acquire_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("bench", type=Path, help="bench file (TOML, docs/bench-file.md)")
    p.add_argument("-o", "--out", type=Path, required=True, help="dataset directory to write")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run from OUT/journal.jsonl")
    force_argument(p, "start again in a non-empty folder: deletes its contents, journal included (never the "
                   "folder of a live run: its lock is exit 2 naming the pid)")
    from benchtwin.app.live import add_live_argument

    add_live_argument(p)


_DEVICE_GONE = (errno.EIO, errno.ENXIO, errno.ENODEV, errno.EBADF, errno.EPIPE)


def _error_line(exc: BaseException) -> str:
    port = getattr(exc, "port", None) or getattr(exc, "filename", None)
    text = str(exc) or type(exc).__name__
    return f"{port}: {text}" if port and str(port) not in text else text


@command("acquire", "run a bench file's procedures on real or emulated instruments; writes a dataset", _acquire_args)
def cmd_acquire(ns: argparse.Namespace) -> dict[str, Any]:
    import serial

    from benchtwin.app.live import live_for
    from benchtwin.hw.acquisition.acquire import JOURNAL, acquire
    from benchtwin.hw.drivers.base import InstrumentError

    if ns.resume and ns.force:
        raise InputError("acquire: --resume and --force contradict each other (continue the run, or delete it)")
    live = live_for(ns, f"acquire {ns.bench.stem}")
    try:
        out = acquire(ns.bench, ns.out, resume=ns.resume, progress=not (ns.quiet or ns.json), force=ns.force,
                      live=live)
    except BaseException as exc:
        if live is not None:
            live.close(f"failed: {type(exc).__name__}: {exc}")
        if not isinstance(exc, (InstrumentError, serial.SerialException, OSError)):
            raise
        # an instrument that stopped answering (retries exhausted) or a port that vanished (EIO,
        # ENXIO, ENODEV on a pty or USB adapter): the readings taken so far are in the journal; say
        # so and how to continue. Other OSErrors (a folder not writable) take the generic exit 2.
        if isinstance(exc, OSError) and not isinstance(exc, serial.SerialException) and exc.errno not in _DEVICE_GONE:
            raise
        j = ns.out / JOURNAL
        # truthful about --force: it deleted the folder's earlier readings before this run began
        taken = "the readings this run took are" if ns.force else "the readings taken so far are"
        kept = (f"{taken} kept in {j}; continue with `benchtwin acquire {ns.bench} -o {ns.out} --resume`"
                if j.is_file() else "no reading was taken")
        if ns.force:
            kept += " (--force deleted the folder's earlier contents, its journal included, before this run began)"
        raise InputError(f"{ns.bench}: acquisition stopped by an instrument error: {_error_line(exc)}; {kept}") from None
    if live is not None:
        live.close("finished")
    return {"ok": True, "dataset": str(out), **({"live": str(live.path)} if live else {}),
            "message": f"dataset written: {out}"}
