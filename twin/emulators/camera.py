"""The CCD microscope as a hot-folder camera (docs/protocols/camera.md): the twin's camera renders
a frame when the bench stands at a CCD stop and saves it as the next numbered file of a folder,
as a camera's acquisition software does; the acquisition takes it with the ``watch_folder``
driver (``hw.drivers.camera.WatchFolderCamera``).

Trigger: the emulated operator (``backend.EmulatedBench``) renders the frame of a ``Capture``
step when the encoder is read at the stop just before it (the CCD sweep reads the encoder, then
captures), keyed by the Capture's step index exactly as ``simulate`` renders it, and before the
encoder's reply goes out, so the file exists when the acquisition asks for it. A repeated read
(a retry, a resumed run) renders the same frame again under a new number. Files are written
atomically (``.name.tmp`` + rename; the driver ignores dot-files). Only the image is saved: the
renderer's truth stays in the twin.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from benchtwin.fsio import atomic_write_bytes

__all__ = ["FolderCameraEmulator"]


class FolderCameraEmulator:
    """Saves frames as ``frame_NNNNNN.png`` in ``folder`` (created); ``frames`` counts them."""

    DRIVER = "watch_folder"

    def __init__(self, name: str, folder: str | Path | None = None):
        self.name = str(name)
        self.folder = Path(folder) if folder is not None else None
        self.frames = 0

    def start(self, folder: str | Path) -> Path:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        return self.folder

    def save(self, image: np.ndarray, step: int) -> Path:
        import cv2

        if self.folder is None:
            raise RuntimeError(f"{self.name}: the camera emulator has no folder (start() it first)")
        ok, png = cv2.imencode(".png", np.asarray(image))
        if not ok:
            raise RuntimeError(f"{self.name}: PNG encoding failed for step {step}")
        self.frames += 1
        p = self.folder / f"frame_{self.frames:06d}.png"
        # atomic (benchtwin.fsio: a dot-named temporary sibling the driver ignores, then rename)
        return atomic_write_bytes(p, png.tobytes(), fsync=False)

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "protocol": "hot folder (numbered PNG frames)", "driver": self.DRIVER,
                "protocol_doc": "docs/protocols/camera.md", "folder": str(self.folder), "frames": self.frames}
