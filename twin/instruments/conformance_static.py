"""Static conformance of the twin's simulated instruments to the instrument Protocols (mypy, .ci/lint).

The twin's side of ``hw/conformance_static.py`` (which checks the drivers; hw never imports the
twin): each function is never called; mypy proves that every simulated instrument satisfies its
kind's Protocol of ``hw/interfaces.py``, its reading methods returning the kind's reading type,
so a simulated probe could not stand in for an encoder without a type error.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from benchtwin.hw.interfaces import AngleEncoder, Autocollimator, Camera, DisplacementProbe, RotaryStage
    from benchtwin.twin.instruments.autocollimator import SimAutocollimator
    from benchtwin.twin.instruments.camera import SimCamera
    from benchtwin.twin.instruments.encoder_head import SimEncoder
    from benchtwin.twin.instruments.probe import SimProbe
    from benchtwin.twin.instruments.stage import SimRotaryStage


def _probe(p: SimProbe) -> DisplacementProbe:
    return p


def _encoder(e: SimEncoder) -> AngleEncoder:
    return e


def _autocollimator(a: SimAutocollimator) -> Autocollimator:
    return a


def _stage(s: SimRotaryStage) -> RotaryStage:
    return s


def _camera(c: SimCamera) -> Camera:
    return c


def _probe_not_an_encoder(p: SimProbe) -> AngleEncoder:
    return p  # type: ignore[return-value]  # must stay an error: a probe is not an encoder
