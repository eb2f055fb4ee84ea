"""Hardware adapters: instrument protocols, transports, serial drivers, acquisition runner.

Public API (docs/api.md), imported lazily (``benchtwin._exports``)::

    from benchtwin.hw import acquire, load_bench, check_conformance, is_kind, open_transport
    acquire("bench.toml", "out/dataset")                  # procedures on real or emulated ports
    problems = check_conformance(my_driver, "probe")      # [] = conforms to hw/interfaces.py

The contracts (Protocols and reading TypedDicts) are ``benchtwin.hw.interfaces``; the procedure
language is ``benchtwin.hw.acquisition.procedures``.
"""

from typing import TYPE_CHECKING

from benchtwin._exports import lazy_exports

_EXPORTS = {
    **{n: "benchtwin.hw.interfaces" for n in (
        "Instrument", "DisplacementProbe", "AngleEncoder", "Autocollimator", "RotaryStage", "Camera",
        "ProbeReading", "EncoderReading", "AutocollimatorReading", "StagePosition", "StageMove", "CameraFrame",
        "INSTRUMENT_KINDS", "SoftLimitError", "is_kind")},
    "check_conformance": "benchtwin.hw.conformance",
    "open_transport": "benchtwin.hw.transport",
    "ReplayTransport": "benchtwin.hw.transport",
    "RecordingTransport": "benchtwin.hw.transport",
    "Runner": "benchtwin.hw.acquisition.runner",
    "SimClock": "benchtwin.hw.acquisition.runner",
    "WallClock": "benchtwin.hw.acquisition.runner",
    "steps_from_specs": "benchtwin.hw.acquisition.procedures",
    "load_bench": "benchtwin.hw.acquisition.bench",
    "acquire": "benchtwin.hw.acquisition.acquire",
}
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
__all__ = list(_EXPORTS)

if TYPE_CHECKING:
    from benchtwin.hw.acquisition.acquire import acquire
    from benchtwin.hw.acquisition.bench import load_bench
    from benchtwin.hw.acquisition.procedures import steps_from_specs
    from benchtwin.hw.acquisition.runner import Runner, SimClock, WallClock
    from benchtwin.hw.conformance import check_conformance
    from benchtwin.hw.interfaces import (INSTRUMENT_KINDS, AngleEncoder, Autocollimator, AutocollimatorReading,
                                         Camera, CameraFrame, DisplacementProbe, EncoderReading, Instrument,
                                         ProbeReading, RotaryStage, SoftLimitError, StageMove, StagePosition,
                                         is_kind)
    from benchtwin.hw.transport import RecordingTransport, ReplayTransport, open_transport
