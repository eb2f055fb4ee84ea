"""A scenario's bench as emulated serial instruments on pseudo-terminals, plus the bench file that
talks to them.

    session = EmulationSession(sc, faults=plan)     # builds the twin and one emulator per port
    bench_path = session.start(directory)            # ports up; writes directory/bench.toml
    ...                                              # benchtwin acquire bench.toml -o DATASET
    session.stop()

Ports are pseudo-terminals (``PtyServer``), or with ``tcp=True`` loopback TCP sockets
(``TcpServer``: the same protocols, as the instruments' Ethernet interfaces carry them; the bench
file then names ``tcp://127.0.0.1:PORT`` ports). Ports (one protocol each, docs/protocols/*.md): ``encoder`` (Heidenhain ND), ``stage`` (Zaber
ASCII), ``autocollimator`` (ELCOMAT 3000 by default, or TriAngle), and the probes: one Millimar
C1202 port with ``probe_top`` on feature 1 and ``probe_bottom`` on feature 2 (by default), or one
TESA TT display per probe. X probes, when the scenario has them, go to features 3/… of a second
amplifier, or to their own TESA displays.

The CCD camera is not a serial instrument: with ``camera`` (a render backend: "auto",
"pyrender", "analytic") it is a hot-folder camera (``camera.FolderCameraEmulator``: the twin
renders each frame at its stop into ``DIRECTORY/frames``; the bench file reads it with the
``watch_folder`` driver) and the bench file runs all four procedures in ``simulate``'s order
(radial motion, CCD sweep, polygon shift-angle, self-calibration), with the ``[ccd]`` geometry
for the manifest. Without (``camera=None``) the bench file has no CCD sweep and the emulated
operator only replays it, to keep the twin's clock and noise keys those of ``simulate``.
"""

from __future__ import annotations

import math
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from benchtwin.fsio import atomic_write_text
from benchtwin.hw.acquisition.procedures import specs_toml
from benchtwin.schema import toml_value
from benchtwin.units import ARCSEC

from ._base import decimals_for
from .backend import EmulatedBench
from .camera import FolderCameraEmulator
from .elcomat import ElcomatEmulator
from .heidenhain import HeidenhainEmulator
from .millimar import MillimarEmulator
from .pty import PtyServer
from .tcp import TcpServer
from .tesa import TesaEmulator
from .triangle import TriAngleEmulator
from .zaber import ZaberDeviceSpec, ZaberEmulator

__all__ = ["EmulationSession", "SessionOptions", "build_emulators", "bench_file_text"]

MICROSTEPS_PER_DEG = 1000.0


def _deg(rad: float) -> float:
    return float(f"{math.degrees(float(rad)):.12g}")


def build_emulators(sc: Any, backend: EmulatedBench, autocollimator: str = "elcomat",
                    probes: str = "millimar") -> dict[str, Any]:
    """``{port name: emulator}`` for a scenario (see the module docstring)."""
    ins = sc["instruments"]
    ac_dec = decimals_for(float(ins["autocollimator"]["resolution"]) / ARCSEC, 2, 4)
    pr_dec = decimals_for(float(ins["probe"]["resolution"]) * 1e6, 2, 4)
    emus: dict[str, Any] = {
        "encoder": HeidenhainEmulator("encoder", backend, "encoder", decimals=6),
        "stage": ZaberEmulator("stage", backend, ZaberDeviceSpec(microsteps_per_deg=MICROSTEPS_PER_DEG)),
    }
    if autocollimator == "elcomat":
        emus["autocollimator"] = ElcomatEmulator("autocollimator", backend, "autocollimator", ac_dec)
    elif autocollimator == "triangle":
        emus["autocollimator"] = TriAngleEmulator("autocollimator", backend, "autocollimator", ac_dec)
    else:
        raise ValueError(f"autocollimator protocol must be 'elcomat' or 'triangle', got {autocollimator!r}")
    names = ["probe_top", "probe_bottom"] + (["probe_top_x", "probe_bottom_x"] if ins["probe"]["x_probes"] else [])
    if probes == "millimar":
        emus["probes"] = MillimarEmulator("probes", backend, {1: names[0], 2: names[1]}, pr_dec)
        if len(names) > 2:
            emus["probes_x"] = MillimarEmulator("probes_x", backend, {1: names[2], 2: names[3]}, pr_dec)
    elif probes == "tesa":
        for n in names:
            emus[n] = TesaEmulator(n, backend, n, pr_dec)
    else:
        raise ValueError(f"probe protocol must be 'millimar' or 'tesa', got {probes!r}")
    return emus


def bench_file_text(sc: Any, ports: dict[str, str], emulators: dict[str, Any], timeout_s: float = 0.25,
                    camera: Any = None, frames_dir: str | Path | None = None, session: str | None = None) -> str:
    """A ready-to-use bench file for the emulated instruments (docs/bench-file.md). ``camera``:
    the twin's ``SimCamera`` (its nominal geometry goes to ``[ccd]``), served from ``frames_dir``.
    ``session``: the serving session's id (``[bench] session``; ``acquire`` journals it and a resume
    against another session is refused)."""
    b = sc["bench"]
    from benchtwin.twin.instruments.encoder_head import sim_lines_from_bench

    heads = ", ".join(toml_value(_deg(h), "deg") for h in b["heads"])
    lines = [
        f"# Written by `benchtwin emulate` for scenario {sc.name!r} (seed {sc.seed}).",
        ("# The ports are loopback TCP sockets served by the emulator; they exist while it runs."
         if any(str(v).startswith("tcp://") for v in ports.values()) else
         "# The ports are links to pseudo-terminals served by the emulator; they exist while it runs."),
        "", "[bench]", f"name = {toml_value(sc.name + '-emulated')}", 'source = "emulated"',
        "description = " + toml_value(f"emulated instruments of scenario {sc.name} (benchtwin emulate)"),
        *([f"session = {toml_value(session)}           # this emulator session: a resume against another is refused"]
          if session is not None else []),
        "", "[geometry]",
        f"optical_radius = {toml_value(float(b['optical_radius']) * 1e3, 'mm')}",
        f"L1 = {toml_value(float(b['L1']) * 1e3, 'mm')}",
        f"L2 = {toml_value(float(b['L2']) * 1e3, 'mm')}",
        f"grating_period = {toml_value(float(b['grating_period']) * 1e6, 'um')}",
        f"polygon_faces = {int(b['polygon_faces'])}",
        f"heads = [{heads}]",
        f"encoder_lines = {sim_lines_from_bench(b)}",
        f"encoder_resolution = {toml_value(float(b['encoder_resolution']) / ARCSEC, 'arcsec')}",
        f"scale_edge_radius = {toml_value(float(b['scale_edge_radius']) * 1e3, 'mm')}",
    ]
    ac = sc["instruments"]["autocollimator"]
    lines += [f"autocollimator_resolution = {toml_value(float(ac['resolution']) / ARCSEC, 'arcsec')}",
              f"autocollimator_accuracy = {toml_value(float(ac['accuracy']) / ARCSEC, 'arcsec')}"]
    if camera is not None:
        c = camera.camera
        ref = ", ".join(f"{float(v):.12g}" for v in c.reference_px)
        lines += ["", "[ccd]                          # the camera's nominal geometry (dataset manifest 'ccd')",
                  f"position = {toml_value(_deg(c.azimuth_rad), 'deg')}", f"tangential = {toml_value(c.tangential)}",
                  f"reference_px = [{ref}]", f"pixel_size = {toml_value(c.pixel_pitch_m * 1e6, 'um')}"]
    lines += [
        "", "[run]", 'waits = "skip"                # emulated instruments: nothing to settle',
        "driver_sleep_scale = 0.0      # no retry backoff / poll waits against an emulator",
        'theta = "target"', "fsync = true", "",
    ]
    ser = f"serial = {{ timeout = {timeout_s:g} }}"

    def inst(name: str, driver: str, port: str, options: str = "", extra: tuple[str, ...] = ()) -> None:
        lines.extend([f"[instruments.{name}]", f"driver = {toml_value(driver)}", f"port = {toml_value(port)}", ser,
                      "retries = 3",
                      "reconnect = true", *extra])
        if options:
            lines.append(f"options = {{ {options} }}")
        lines.append("")

    enc = emulators["encoder"]
    inst("encoder", "heidenhain", ports["encoder"], f"decimals = {enc.decimals}")
    ac = emulators["autocollimator"]
    inst("autocollimator", ac.DRIVER, ports["autocollimator"])
    probe_names = ["probe_top", "probe_bottom"]
    if "probes" in emulators:
        for port in ("probes", "probes_x"):
            if port in emulators:
                for ch, n in emulators[port].channels.items():
                    probe_names = probe_names if n in probe_names else probe_names + [n]
                    inst(n, "millimar", ports[port], f"channel = {ch}")
    else:
        for n, e in emulators.items():
            if isinstance(e, TesaEmulator):
                probe_names = probe_names if n in probe_names else probe_names + [n]
                inst(n, "tesa", ports[n])
    st = emulators["stage"]
    # message ids and checksums on (zaber.md): a corrupted or stale reply is detected, not parsed
    inst("stage", "zaber", ports["stage"], f"microsteps_per_deg = {st.microsteps_per_deg:g}, poll_interval_s = 0.0, "
         "message_ids = true, checksums = true",
         ('soft_limits = ["-1 deg", "361 deg"]', f'max_speed = "{st.speed_deg_s * 1.25:g} deg/s"'))
    if camera is not None:
        lines += ["[instruments.ccd]", 'driver = "watch_folder"', f"port = {toml_value(str(frames_dir))}",
                  "options = { timeout_s = 30.0 }", ""]
    # the procedures simulate runs, in the one procedure language (faces and heads: from [geometry])
    from benchtwin.twin.simulate import scenario_procedures

    lines += specs_toml(scenario_procedures(sc, probes=probe_names, ccd=camera is not None), omit=("faces", "heads"))
    return "\n".join(lines)


@dataclass(frozen=True)
class SessionOptions:
    """An emulation session's instruments and ports: the autocollimator's protocol ("elcomat" or
    "triangle"), the probes' ("millimar" or "tesa"), the emulators' read timeout (s), the CCD
    camera's renderer (None: no camera), and TCP sockets instead of pseudo-terminals (from
    ``tcp_base_port``; 0: any free port)."""

    autocollimator: str = "elcomat"
    probes: str = "millimar"
    timeout_s: float = 0.25
    camera: str | None = None
    tcp: bool = False
    tcp_base_port: int = 0


class EmulationSession:
    """Twin + emulators + pseudo-terminals + bench file for one acquisition (and its resumptions)."""

    def __init__(self, sc: Any, faults: Any = None, options: SessionOptions | None = None, **kw: Any):
        """``faults``: the fault plan; ``options`` (a ``SessionOptions``), or its fields as keywords."""
        if options is not None and kw:
            raise TypeError("EmulationSession: give options or its fields as keywords, not both")
        options = options if options is not None else SessionOptions(**kw)
        autocollimator, probes, camera = options.autocollimator, options.probes, options.camera
        timeout_s, tcp, tcp_base_port = options.timeout_s, options.tcp, options.tcp_base_port
        self.options = options
        self.sc = sc
        self.backend = EmulatedBench(sc, MICROSTEPS_PER_DEG, camera_backend=camera)
        self.camera = FolderCameraEmulator("ccd") if camera is not None else None
        if self.camera is not None:
            self.backend.on_frame = self.camera.save
        self.emulators = build_emulators(sc, self.backend, autocollimator, probes)
        self.faults = faults
        self.timeout_s = float(timeout_s)
        self.tcp, self.tcp_base_port = bool(tcp), int(tcp_base_port)
        self.server: Any = None
        self.bench_path: Path | None = None
        # the session's identity, in its bench file: the emulators' state (the operator's place in
        # the procedure, the clock, the noise streams) lives only here, so a journal of this
        # session is resumed against this session only (issue #31)
        self.session_id = uuid.uuid4().hex

    def start(self, directory: str | Path) -> Path:
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        if self.tcp:
            self.server = TcpServer(self.emulators, self.faults, base_port=self.tcp_base_port)
        else:
            self.server = PtyServer(self.emulators, self.faults, link_dir=d / "ports")
        ports = self.server.start()
        frames = self.camera.start(d / "frames") if self.camera is not None else None
        self.bench_path = d / "bench.toml"
        # atomic (benchtwin.fsio): a client polling for the bench file never reads half of it
        atomic_write_text(self.bench_path, bench_file_text(self.sc, ports, self.emulators, self.timeout_s,
                                                           self.backend.camera, frames, self.session_id))
        return self.bench_path

    def ports(self) -> dict[str, str]:
        return self.server.paths() if self.server else {}

    def stop(self) -> None:
        if self.server is not None:
            self.server.stop()
        self.backend.close()

    def __enter__(self) -> "EmulationSession":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()
