"""Static conformance of the serial drivers to the instrument Protocols (checked by mypy, .ci/lint).

Why: ``runtime_checkable`` Protocols only see method names, and several kinds share ``read``; the
reading ``TypedDict``s of ``hw/interfaces.py`` are what tell the kinds apart, and only a type checker
sees them. Each function below is never called: it exists so that mypy proves, for every driver
class, that it satisfies its kind's Protocol (its methods return the kind's reading type), and that
a probe does not pass for an encoder or an autocollimator (``_not_*``: the ``type: ignore`` there
must stay needed; with ``warn_unused_ignores`` mypy fails the day a probe would pass as one).

The twin's simulated instruments get the same check in ``twin/instruments/conformance_static.py``
(hw never imports the twin). The run-time check is ``hw/conformance.py``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from benchtwin.hw.drivers.camera import FolderCamera, OpenCVCamera, WatchFolderCamera
    from benchtwin.hw.drivers.elcomat import Elcomat
    from benchtwin.hw.drivers.heidenhain import HeidenhainND
    from benchtwin.hw.drivers.millimar import MillimarC1202
    from benchtwin.hw.drivers.tesa import TesaTT
    from benchtwin.hw.drivers.triangle import TriAngle
    from benchtwin.hw.drivers.zaber import ZaberRotaryStage
    from benchtwin.hw.interfaces import AngleEncoder, Autocollimator, Camera, DisplacementProbe, RotaryStage


def _probes(a: MillimarC1202, b: TesaTT) -> list[DisplacementProbe]:
    return [a, b]


def _encoders(a: HeidenhainND) -> list[AngleEncoder]:
    return [a]


def _autocollimators(a: Elcomat, b: TriAngle) -> list[Autocollimator]:
    return [a, b]


def _stages(a: ZaberRotaryStage) -> list[RotaryStage]:
    return [a]


def _cameras(a: OpenCVCamera, b: FolderCamera, c: WatchFolderCamera) -> list[Camera]:
    return [a, b, c]


def _not_an_encoder(p: DisplacementProbe) -> AngleEncoder:
    return p  # type: ignore[return-value]  # must stay an error: a probe is not an encoder


def _not_an_autocollimator(p: DisplacementProbe) -> Autocollimator:
    return p  # type: ignore[return-value]  # must stay an error: a probe is not an autocollimator


def _encoder_not_a_probe(e: AngleEncoder) -> DisplacementProbe:
    return e  # type: ignore[return-value]  # must stay an error: an encoder is not a probe
