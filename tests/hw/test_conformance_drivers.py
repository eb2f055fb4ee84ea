"""hw.conformance.check_conformance on every driver (replayed) and on deliberately broken fakes."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from benchtwin.hw.conformance import check_conformance
from benchtwin.hw.drivers.base import InstrumentError
from benchtwin.hw.drivers.camera import FolderCamera, OpenCVCamera, to_grey
from benchtwin.hw.drivers.elcomat import Elcomat
from benchtwin.hw.drivers.heidenhain import HeidenhainND
from benchtwin.hw.drivers.millimar import MillimarC1202
from benchtwin.hw.drivers.tesa import TesaTT
from benchtwin.hw.drivers.triangle import TriAngle
from benchtwin.hw.drivers.zaber import ZaberRotaryStage
from benchtwin.hw.interfaces import SoftLimitError
from benchtwin.hw.transport import ReplayTransport


def _rt(request: str, response: str) -> ReplayTransport:
    return ReplayTransport([{"request": request, "response": response}])


def _nosleep(s: float) -> None:
    pass


class FakeCapture:
    def __init__(self, frames):
        self.frames = list(frames)

    def read(self):
        if not self.frames:
            return False, None
        return True, self.frames.pop(0)


CASES = {
    "elcomat": ("autocollimator", lambda: Elcomat("ac", _rt("a\r\n", "4 003 1.50 -2.25\r"), sleep=_nosleep)),
    "triangle": ("autocollimator", lambda: TriAngle("tri", _rt("P 1\r\n", "1.0;2.0;0.0;0.9\r\n"), sleep=_nosleep)),
    "tesa": ("probe", lambda: TesaTT("p", _rt("?\r", "+0001.25\r\n"), sleep=_nosleep)),
    "millimar": ("probe", lambda: MillimarC1202("p2", _rt("M2?\r", "2 +001.25 um\r"), channel=2, sleep=_nosleep)),
    "heidenhain": ("encoder", lambda: HeidenhainND("enc", _rt("\x1bA0200\r", "\x02+000012345\r\n+000000010\r\n"),
                                                   heads_deg=[0.0, 180.0], sleep=_nosleep)),
    "opencv_camera": ("camera", lambda: OpenCVCamera("cam", FakeCapture([np.full((4, 6, 3), 200, np.uint8)]))),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_driver_conforms(case):
    kind, make = CASES[case]
    inst = make()
    assert check_conformance(inst, kind) == []
    transport = getattr(inst, "transport", None)
    if transport is not None:
        transport.assert_done()


def test_zaber_conforms_with_and_without_move():
    pos = {"request": "/1 1 get pos\n", "response": "@01 1 OK IDLE -- 1500\r\n"}
    # each conformance call: position(), then two refused moves (above the limit, NaN) that send
    # nothing, each followed by a position() showing the stage did not move
    rt = ReplayTransport([pos, pos, pos,
                          pos, pos, pos,
                          {"request": "/1 1 get maxspeed\n", "response": "@01 1 OK IDLE -- 1638\r\n"},
                          {"request": "/1 1 move abs 2000\n", "response": "@01 1 OK IDLE -- 0\r\n"}])
    stage = ZaberRotaryStage("stage", rt, microsteps_per_deg=1000, soft_limits_deg=(0, 360), max_speed_deg_s=5,
                             sleep=_nosleep)
    assert check_conformance(stage, "stage") == []
    assert check_conformance(stage, "stage", move_to_deg=2.0) == []
    rt.assert_done()


class StatusOnLimitStage:
    """A stage that reports a soft limit as a status (the behaviour the contract forbids)."""

    name = "bad_stage"

    def __init__(self, limits=(0.0, 360.0), moves_anyway=False):
        self.limits, self.moves_anyway, self.pos = limits, moves_anyway, 0.0

    def describe(self):
        return {"name": self.name, "kind": "stage", "model": "fake", "units": {"angle_deg": "deg", "target_deg": "deg"},
                "soft_limits_deg": list(self.limits) if self.limits else self.limits}

    def move_to(self, target_deg):
        if self.moves_anyway:
            self.pos = target_deg
            raise SoftLimitError(self.name, target_deg, self.limits)
        return {"target_deg": target_deg, "t_s": 0.0, "duration_s": 0.0, "status": "soft_limit"}

    def position(self):
        return {"angle_deg": self.pos, "t_s": 0.0, "status": "ok"}


def test_soft_limit_contract_violations_are_reported():
    probs = check_conformance(StatusOnLimitStage(), "stage")
    assert any("returned" in p and "instead of raising SoftLimitError" in p for p in probs), probs
    probs = check_conformance(StatusOnLimitStage(moves_anyway=True), "stage")
    assert any("the stage moved from 0.0 to 363.6 deg" in p for p in probs), probs
    probs = check_conformance(StatusOnLimitStage(limits=(5.0, 1.0)), "stage")
    assert any("low < high" in p for p in probs), probs
    bad = StatusOnLimitStage()
    bad.describe = lambda: {"name": "bad_stage", "kind": "stage", "model": "fake", "units": {}}
    assert any("lacks 'soft_limits_deg'" in p for p in check_conformance(bad, "stage"))


def test_no_signal_reading_still_conforms():
    inst = TriAngle("tri", _rt("P 1\r\n", "1.0;2.0;0.0;0.0\r\n"), sleep=_nosleep)
    assert check_conformance(inst, "autocollimator") == []


def test_folder_camera_png_and_index(tmp_path):
    grey16 = (np.arange(12, dtype=np.uint16).reshape(3, 4) * 5000)
    colour = np.zeros((3, 4, 3), np.uint8)
    colour[..., 2] = 255  # pure red in BGR
    cv2.imwrite(str(tmp_path / "b.png"), colour)
    cv2.imwrite(str(tmp_path / "a.png"), grey16)
    cam = FolderCamera("cam", tmp_path, clock=lambda: 7.0)
    assert check_conformance(cam, "camera") == []  # a.png (sorted first)
    r = cam.capture()
    assert r["file"] == "b.png" and r["image"].dtype == np.uint8 and r["image"].shape == (3, 4)
    assert int(r["image"][0, 0]) == 76  # OpenCV luminance of pure red
    with pytest.raises(InstrumentError, match="frames"):
        cam.capture()
    (tmp_path / "index.csv").write_text("file,t_s\nb.png,1.5\na.png,2.5\n")
    cam = FolderCamera("cam", tmp_path, dtype="uint16", loop=True)
    assert [cam.capture()["t_s"] for _ in range(3)] == [1.5, 2.5, 1.5]
    assert cam.capture()["image"].dtype == np.uint16


def test_to_grey_depths():
    a = np.array([[0, 255]], np.uint8)
    assert to_grey(a, "uint16").tolist() == [[0, 65535]]
    assert to_grey(np.array([[0, 65535]], np.uint16), "uint8").tolist() == [[0, 255]]
    with pytest.raises(ValueError):
        to_grey(np.zeros((2, 2), np.float32))


def test_opencv_camera_retries_then_fails():
    cam = OpenCVCamera("cam", FakeCapture([]), retries=1)
    with pytest.raises(InstrumentError, match="no frame after 2"):
        cam.capture()


class Broken:
    name = "broken"

    def describe(self):
        return {"name": "other", "kind": "probe", "units": {"value_mm": "um"}}

    def read(self):
        return {"value_mm": 1.0, "value_um": "1.0", "status": "", "t_s": math.nan}


def test_conformance_reports_problems():
    problems = check_conformance(Broken(), "probe")
    text = "\n".join(problems)
    for expected in ("differs from .name", "lacks 'model'", "'status' must be", "'t_s' must be",
                     "'value_um' must be a float", "key 'value_um' is not in", "says 'mm'"):
        assert expected in text, (expected, problems)
    assert check_conformance(Broken(), "laser") == ["unknown kind 'laser'; known: "
                                                    "['autocollimator', 'camera', 'encoder', 'probe', 'stage']"]

    class NoRead:
        name = "n"

        def describe(self):
            return {"name": "n", "kind": "stage", "model": "m", "units": {}}

    assert any("does not implement RotaryStage" in p for p in check_conformance(NoRead(), "stage"))


def test_encoder_shape_problems():
    class Enc:
        name = "e"

        def describe(self):
            return {"name": "e", "kind": "encoder", "model": "m", "units": {"angle_deg": "deg", "heads_deg": "deg"}}

        def read(self):
            return {"heads_deg": [90.0, 180.0], "angle_deg": [1.0], "t_s": 0.0, "status": "ok"}

    problems = check_conformance(Enc(), "encoder")
    assert any("heads_deg has 2 entries" in p for p in problems)
    assert any("heads_deg[0] must be 0" in p for p in problems)


def test_watch_folder_camera_takes_only_new_frames(tmp_path):
    from benchtwin.hw.drivers.camera import WatchFolderCamera

    def save(name, value):
        cv2.imwrite(str(tmp_path / name), np.full((4, 6), value, np.uint8))

    save("frame_000001.png", 10)                 # present at opening: never returned
    t = [0.0]
    sleeps = []

    def sleep(s):
        sleeps.append(s)
        t[0] += s

    cam = WatchFolderCamera("ccd", tmp_path, timeout_s=0.05, poll_s=0.01, sleep=sleep, clock=lambda: t[0])
    assert check_conformance(cam, "camera") != []  # nothing new yet: capture() times out...
    assert len(sleeps) >= 5
    with pytest.raises(InstrumentError, match=r"ccd: command 'capture' failed: no new frame in .* within 0.05 s"):
        cam.capture()
    save("frame_000002.png", 20)
    save("frame_000003.png", 30)                 # a re-rendered frame: the newest is taken
    (tmp_path / ".frame_000004.png.tmp").write_bytes(b"half")   # temporary files are ignored
    sleeps.clear()
    r = cam.capture()
    assert r["file"] == "frame_000003.png" and int(r["image"][0, 0]) == 30 and sleeps == []
    save("frame_000004.png", 40)
    assert check_conformance(cam, "camera") == []
    with pytest.raises(ValueError, match="not a folder"):
        WatchFolderCamera("ccd", tmp_path / "missing")
