"""Microscope cameras (hw.interfaces.Camera): an OpenCV ``VideoCapture`` and a folder replay.

Protocol document: docs/protocols/camera.md. Frames are returned greyscale, 2-D, uint8 or uint16
(``hw.interfaces.check_image``). Colour frames (BGR, BGRA) are converted with OpenCV's luminance
weights; ``dtype`` forces the output depth (uint8 -> uint16 scales by 257, uint16 -> uint8 keeps the
high byte).

- ``OpenCVCamera(name, capture, ...)``: ``capture`` is an open ``cv2.VideoCapture`` (or anything with
  ``read() -> (ok, frame)``); opening it is the caller's business (``OpenCVCamera.open(source)`` does
  it explicitly). A failed grab is retried ``retries`` times, then ``InstrumentError``.
- ``FolderCamera(name, folder, ...)``: replays ``index.csv`` (columns ``file`` and optionally
  ``t_s``) if present, else the folder's ``*.png`` sorted by name; at the end it raises
  ``InstrumentError`` unless ``loop=True``.
- ``WatchFolderCamera(name, folder, ...)``: a "hot folder" camera: the camera's own software (or
  the twin's emulator) saves every frame it takes as a new file whose name sorts after the previous
  ones (a frame counter); ``capture()`` returns the newest frame that appeared after the previous
  capture (or, for the first, after the folder was opened), waiting up to ``timeout_s`` for one.
  Files present at opening are never returned, so a resumed acquisition does not take an old frame.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from benchtwin.hw.drivers.base import InstrumentError
from benchtwin.hw.interfaces import CameraFrame, check_image

__all__ = ["OpenCVCamera", "FolderCamera", "WatchFolderCamera", "WatchFolderSettings", "to_grey"]


def to_grey(frame: np.ndarray, dtype: str | None = None) -> np.ndarray:
    """Greyscale 2-D uint8/uint16 from a grey, BGR or BGRA frame; ``dtype`` forces the depth."""
    arr = np.asarray(frame)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    elif arr.ndim == 3 and arr.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if arr.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        arr = cv2.cvtColor(arr, code)
    if arr.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"frame dtype {arr.dtype} is neither uint8 nor uint16")
    if dtype is not None:
        want = np.dtype(dtype)
        if want == np.uint16 and arr.dtype == np.uint8:
            arr = arr.astype(np.uint16) * 257
        elif want == np.uint8 and arr.dtype == np.uint16:
            arr = (arr >> 8).astype(np.uint8)
        elif want not in (np.uint8, np.uint16):
            raise ValueError(f"dtype must be uint8 or uint16, got {dtype}")
    return check_image(np.ascontiguousarray(arr))


class OpenCVCamera:
    """A ``cv2.VideoCapture`` camera. Arguments: ``name``, ``capture``, ``dtype`` (None: as captured),
    ``pixel_size_um`` (metadata), ``retries`` (2), ``clock`` (``time.monotonic``)."""

    KIND = "camera"

    def __init__(self, name: str, capture: Any, *, dtype: str | None = None, pixel_size_um: float | None = None,
                 retries: int = 2, clock: Callable[[], float] | None = None, model: str = "OpenCV VideoCapture") -> None:
        self.name = str(name)
        self.capture_device = capture
        self.dtype = dtype
        self.pixel_size_um = pixel_size_um
        self.retries = int(retries)
        self.clock = clock if clock is not None else time.monotonic
        self.model = model

    @classmethod
    def open(cls, name: str, source: int | str, **kw: Any) -> "OpenCVCamera":
        """Open ``cv2.VideoCapture(source)`` explicitly (a device index, file or stream URL)."""
        cap = cv2.VideoCapture(source)
        if not cap.isOpened():
            raise InstrumentError(name, "open", f"cv2.VideoCapture({source!r}) did not open", b"")
        return cls(name, cap, **kw)

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.KIND, "model": self.model, "units": {"image": "DN", "t_s": "s"},
                "dtype": self.dtype, "pixel_size_um": self.pixel_size_um}

    def capture(self) -> CameraFrame:
        for _ in range(self.retries + 1):
            ok, frame = self.capture_device.read()
            if ok and frame is not None:
                return {"image": to_grey(frame, self.dtype), "t_s": float(self.clock()), "status": "ok"}
        raise InstrumentError(self.name, "capture", f"no frame after {self.retries + 1} attempt(s)", b"")

    def close(self) -> None:
        release = getattr(self.capture_device, "release", None)
        if release is not None:
            release()


def _read_index(index: Path, folder: Path) -> list[tuple[Path, float | None]]:
    """A camera folder's index.csv by the one reader (benchtwin.schema): a regular file, bounded
    size, ``file`` a relative name inside the folder, ``t_s`` by the number grammar. Errors are
    ValueErrors naming the file and the row (the bench file's reader makes them exit 2)."""
    from benchtwin.schema import check_relative_name, csv_rows, parse_float, read_input_text

    rows = [r for _, r in csv_rows(read_input_text(index, what="camera index"), str(index))]
    header = [h.strip() for h in rows[0]] if rows else []
    if "file" not in header:
        raise ValueError(f"{index}: row 1: needs a 'file' column, has {header}")
    i_file = header.index("file")
    i_t = header.index("t_s") if "t_s" in header else None
    frames: list[tuple[Path, float | None]] = []
    for n, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        if len(row) != len(header):
            raise ValueError(f"{index}: row {n}: expected {len(header)} fields, got {len(row)}")
        name = check_relative_name(row[i_file].strip(), f"{index}: row {n}, column 'file'")
        t = row[i_t].strip() if i_t is not None else ""
        try:
            t_s = parse_float(t) if t else None
        except ValueError as exc:
            raise ValueError(f"{index}: row {n}, column 't_s': {exc}") from None
        frames.append((folder / name, t_s))
    return frames


class FolderCamera:
    """Replays a folder of images. Arguments: ``name``, ``folder``, ``dtype`` (None), ``loop`` (False),
    ``clock`` (used for ``t_s`` when the index has no ``t_s`` column), ``pixel_size_um``."""

    KIND = "camera"

    def __init__(self, name: str, folder: str | Path, *, dtype: str | None = None, loop: bool = False,
                 clock: Callable[[], float] | None = None, pixel_size_um: float | None = None) -> None:
        self.name = str(name)
        self.folder = Path(folder)
        self.dtype = dtype
        self.loop = bool(loop)
        self.clock = clock if clock is not None else time.monotonic
        self.pixel_size_um = pixel_size_um
        index = self.folder / "index.csv"
        self.frames: list[tuple[Path, float | None]] = []
        if index.exists() or index.is_symlink():
            self.frames = _read_index(index, self.folder)
        else:
            self.frames = [(p, None) for p in sorted(self.folder.glob("*.png"))]
        if not self.frames:
            raise ValueError(f"{self.folder}: no index.csv and no *.png images")
        self.pos = 0

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.KIND, "model": "folder replay", "units": {"image": "DN", "t_s": "s"},
                "folder": str(self.folder), "frames": len(self.frames), "dtype": self.dtype,
                "pixel_size_um": self.pixel_size_um}

    def capture(self) -> CameraFrame:
        if self.pos >= len(self.frames):
            if not self.loop:
                raise InstrumentError(self.name, "capture", f"all {len(self.frames)} frames of {self.folder} used", b"")
            self.pos = 0
        path, t_s = self.frames[self.pos]
        self.pos += 1
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise InstrumentError(self.name, "capture", f"cannot read image {path}", b"")
        return {"image": to_grey(img, self.dtype), "t_s": float(t_s if t_s is not None else self.clock()),
                "status": "ok", "file": path.name}


@dataclass(frozen=True)
class WatchFolderSettings:
    """A hot folder's file pattern (names starting with "." are temporary files and ignored), the
    wait for a new frame and the interval of the folder's polls (s), the image dtype (None: as
    read) and the pixel size (µm, metadata)."""

    pattern: str = "*.png"
    timeout_s: float = 5.0
    poll_s: float = 0.01
    dtype: str | None = None
    pixel_size_um: float | None = None


class WatchFolderCamera:
    """A hot-folder camera (see the module docstring). Arguments: ``name``, ``folder``, ``pattern``
    (``"*.png"``; names starting with "." are temporary files and ignored), ``timeout_s`` (5),
    ``poll_s`` (0.01), ``dtype`` (None), ``sleep`` and ``clock`` (injectable, for tests),
    ``pixel_size_um`` (metadata). Only the newest file's name is remembered (flat memory)."""

    KIND = "camera"

    def __init__(self, name: str, folder: str | Path, settings: WatchFolderSettings | None = None, *,
                 sleep: Callable[[float], None] | None = None, clock: Callable[[], float] | None = None,
                 **kw: Any) -> None:
        """``settings`` (a ``WatchFolderSettings``), or its fields as keywords."""
        if settings is not None and kw:
            raise TypeError(f"{name}: give settings or its fields as keywords, not both")
        settings = settings if settings is not None else WatchFolderSettings(**kw)
        self.name = str(name)
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise ValueError(f"{self.folder}: not a folder (the camera's save folder must exist)")
        self.settings = settings
        self.pattern = settings.pattern
        self.timeout_s = float(settings.timeout_s)
        self.poll_s = float(settings.poll_s)
        self.dtype = settings.dtype
        self.sleep = sleep if sleep is not None else time.sleep
        self.clock = clock if clock is not None else time.monotonic
        self.pixel_size_um = settings.pixel_size_um
        self.last = self._newest()

    def _newest(self) -> str | None:
        newest = None
        for p in self.folder.glob(self.pattern):
            if not p.name.startswith(".") and (newest is None or p.name > newest):
                newest = p.name
        return newest

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.KIND, "model": "watched folder", "units": {"image": "DN", "t_s": "s"},
                "folder": str(self.folder), "pattern": self.pattern, "dtype": self.dtype,
                "pixel_size_um": self.pixel_size_um}

    def capture(self) -> CameraFrame:
        t0 = self.clock()
        while True:
            newest = self._newest()
            if newest is not None and (self.last is None or newest > self.last):
                break
            if self.clock() - t0 > self.timeout_s:
                raise InstrumentError(self.name, "capture", f"no new frame in {self.folder} within {self.timeout_s} s "
                                      f"(last taken: {self.last})", b"")
            self.sleep(self.poll_s)
        path = self.folder / newest
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise InstrumentError(self.name, "capture", f"cannot read image {path}", b"")
        self.last = newest
        return {"image": to_grey(img, self.dtype), "t_s": float(self.clock()), "status": "ok", "file": newest}
