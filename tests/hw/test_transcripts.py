"""Record/replay for every serial driver against the twin's protocol emulators (written from the
protocol documents, not from the drivers): each driver talks to its emulator on a pseudo-terminal
through a ``RecordingTransport``; a fresh driver on a ``ReplayTransport`` of that transcript then
returns the same results (strict order, nothing left over). The hand-written transcripts of
tests/hw/transcripts/ (vendor examples, faults) are replayed in test_drivers.py."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from benchtwin.hw.drivers.elcomat import Elcomat
from benchtwin.hw.drivers.heidenhain import HeidenhainND
from benchtwin.hw.drivers.millimar import MillimarC1202
from benchtwin.hw.drivers.tesa import TesaTT
from benchtwin.hw.drivers.triangle import TriAngle
from benchtwin.hw.drivers.zaber import ZaberRotaryStage
from benchtwin.hw.transport import RecordingTransport, ReplayTransport, open_transport

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")


FACE_3 = round(3 * 360.0 / 23, 3)   # the polygon's 4th face (of 23) faces the autocollimator here


def _nosleep(s: float) -> None:
    pass


def _session(ports: dict, directory: Path, uses: dict) -> dict:
    """Record each port's drivers in use (the Millimar channels share their amplifier's port), then
    replay the port's transcript with fresh drivers; returns {name: (live, replayed)}."""
    by_port: dict[str, list] = {}
    for name, (cls, port, kw, use) in uses.items():
        by_port.setdefault(port, []).append((name, cls, kw, use))
    out = {}
    for port, drivers in by_port.items():
        path = directory / f"{port}.jsonl"
        rec = RecordingTransport(open_transport(ports[port], **drivers[0][1].serial_settings(timeout=1.0)), path)
        try:
            live = {name: use(cls(name, rec, sleep=_nosleep, **kw)) for name, cls, kw, use in drivers}
        finally:
            rec.close()
        rt = ReplayTransport(path)
        replayed = {name: use(cls(name, rt, sleep=_nosleep, **kw)) for name, cls, kw, use in drivers}
        rt.assert_done()
        assert path.read_text().count('"request"') >= sum(1 if n == "probe_bottom" else 2 for n, *_ in drivers)
        out.update({n: (live[n], replayed[n]) for n in live})
    return out


def _strip(r):
    if isinstance(r, dict):
        return {k: v for k, v in r.items() if k not in ("t_s", "duration_s")}
    return [_strip(x) for x in r]


@pytest.mark.parametrize("protocols", [("elcomat", "millimar"), ("triangle", "tesa")])
def test_every_driver_records_and_replays_its_emulated_session(tmp_path, protocols):
    from benchtwin.twin.emulators.serve import EmulationSession
    from benchtwin.twin.scenario import load_scenario

    ac, probes = protocols
    sc = load_scenario().with_overrides({"bench.heads": ["0 deg", "120 deg", "240 deg"]})
    # the TriAngle/TESA session also runs the stage with Zaber message ids and checksums (zaber.md)
    stage_kw = dict(microsteps_per_deg=1000.0, soft_limits_deg=(-1.0, 361.0), max_speed_deg_s=50.0,
                    poll_interval_s=0.0, message_ids=ac == "triangle", checksums=ac == "triangle")
    uses = {
        "stage": (ZaberRotaryStage, "stage", stage_kw, lambda d: [d.move_to(12.5), d.position(), d.move_to(FACE_3)]),
        "encoder": (HeidenhainND, "encoder", {"heads_deg": [0.0, 120.0, 240.0], "decimals": 6},
                    lambda d: [d.read(), d.read()]),
        "autocollimator": ({"elcomat": Elcomat, "triangle": TriAngle}[ac], "autocollimator", {},
                           lambda d: [d.read(), d.read()]),
    }
    if probes == "millimar":
        uses["probe_top"] = (MillimarC1202, "probes", {"channel": 1}, lambda d: [d.read(), d.read()])
        uses["probe_bottom"] = (MillimarC1202, "probes", {"channel": 2}, lambda d: [d.read()])
    else:
        uses["probe_top"] = (TesaTT, "probe_top", {}, lambda d: [d.read(), d.read()])
        uses["probe_bottom"] = (TesaTT, "probe_bottom", {}, lambda d: [d.read()])
    with EmulationSession(sc, autocollimator=ac, probes=probes) as session:
        session.start(tmp_path / "emu")
        got = _session(session.ports(), tmp_path, uses)
        assert session.server.errors == []
    for name, (live, replayed) in got.items():
        assert _strip(live) == _strip(replayed), name
        assert all(r["status"] == "ok" for r in live), name
    enc = got["encoder"][0][0]
    assert len(enc["angle_deg"]) == 3 and abs(enc["angle_deg"][0] - FACE_3) < 0.01   # where the stage stands
