"""The contracts every instrument kind implements: the twin's simulated instruments, the serial
drivers and the emulators' backends alike (bluesky ``protocols.py`` style; ophyd-style conformance
is checked in ``tests/test_conformance.py``).

Return shapes are plain dicts with units in the keys, so a reading can go straight into a journal
line or a dataset row. Every reading carries ``t_s`` (seconds on the runner's clock: simulated for
the twin, monotonic wall time for hardware) and ``status`` ("ok" or a short reason such as
"no_signal", "out_of_range"). Instruments never sleep; a runner owns the clock.

The shapes are written twice on purpose, for two checkers: as ``TypedDict`` reading types
(``ProbeReading``, ``EncoderReading``, ...), which the Protocols' methods return, so that mypy
tells the kinds apart statically (a probe's ``read() -> ProbeReading`` does not satisfy
``AngleEncoder.read() -> EncoderReading``; ``hw/conformance_static.py`` and
``twin/instruments/conformance_static.py`` check every driver and twin instrument that way), and
as the run-time check of ``hw/conformance.py``. ``runtime_checkable`` ``isinstance`` only sees
method names, which several kinds share (``read``): at run time ``is_kind`` adds the kind each
instrument declares (``describe()["kind"]``).
"""

# No `from __future__ import annotations` here: TypedDict computes __required_keys__ (NotRequired)
# from the evaluated annotations at class creation.
from typing import Any, NotRequired, Protocol, TypedDict, runtime_checkable

import numpy as np


class Stamped(TypedDict):
    """What every reading carries: the runner's clock and a status."""

    t_s: float  # seconds on the runner's clock (simulated or monotonic wall time)
    status: str  # "ok" or a short reason ("no_signal", "out_of_range", ...)
    message: NotRequired[str]  # the instrument's own words, when it sent some (e.g. an error text)


class ProbeReading(Stamped):
    value_um: float  # displacement along the probe's measuring axis, µm


class EncoderReading(Stamped):
    heads_deg: list[float]  # azimuth of each reading head, head 1 first (0)
    angle_deg: list[float]  # reading of each head, degrees


class AutocollimatorReading(Stamped):
    x_arcsec: float  # rotation-plane angle (the axis the polygon calibration uses)
    y_arcsec: float  # the other axis


class StagePosition(Stamped):
    angle_deg: float  # the stage's position in encoder degrees
    stage_deg: NotRequired[float]  # the stage's own position, when it differs from the encoder's


class StageMove(Stamped):
    target_deg: float  # the commanded position, encoder degrees
    duration_s: float  # time the move took (>= 0)
    corrections: NotRequired[int]  # closed-loop corrections on the encoder (drivers)
    error_deg: NotRequired[float]  # remaining encoder error after them (drivers)
    iterations: NotRequired[int]  # closed-loop iterations of the twin's servo on the encoder
    held_deg: NotRequired[float]  # status MOVE_NOT_HELD: the reading of the count the servo holds instead


#: A move's status when the stage came to rest but its servo holds another count than the commanded
#: one (outside its in-position window): the stop is where ``held_deg`` says, the move is complete
#: and the runner keeps it (its readings are valid there); any other status but "ok" stops a strict run.
MOVE_NOT_HELD = "not_held"


class CameraFrame(Stamped):
    image: np.ndarray  # 2-D greyscale, uint8 or uint16
    file: NotRequired[str]  # the frame's file name (folder cameras)
    backend: NotRequired[str]  # twin only: the renderer that drew it (a reading never holds a true value)


@runtime_checkable
class Instrument(Protocol):
    """Anything on the bench. ``describe()`` returns at least
    ``{"name": str, "kind": str, "model": str, "units": {field: unit}}`` plus kind-specific
    metadata (range, resolution); it must not talk to the instrument's settings."""

    name: str

    def describe(self) -> dict[str, Any]: ...


@runtime_checkable
class DisplacementProbe(Instrument, Protocol):
    """Inductive/lever probe. ``read()`` -> ``{"value_um": float, "t_s": float, "status": str}``;
    ``value_um`` is the displacement along the probe's measuring axis (see docs/conventions.md)."""

    def read(self) -> ProbeReading: ...


@runtime_checkable
class AngleEncoder(Instrument, Protocol):
    """Encoder counter/display with one or more heads. ``read()`` ->
    ``{"heads_deg": [azimuth of each head], "angle_deg": [reading of each head], "t_s", "status"}``;
    head 1 is the bench's reference reading."""

    def read(self) -> EncoderReading: ...


@runtime_checkable
class Autocollimator(Instrument, Protocol):
    """Two-axis autocollimator. ``read()`` -> ``{"x_arcsec": float, "y_arcsec": float, "t_s", "status"}``;
    X is the rotation plane (the axis the polygon calibration uses)."""

    def read(self) -> AutocollimatorReading: ...


@runtime_checkable
class RotaryStage(Instrument, Protocol):
    """The drive. ``move_to(target_deg)`` commands a position in encoder degrees (the bench stops at
    commanded encoder readings) and returns ``{"target_deg", "t_s", "status", "duration_s"}`` when
    settled, without sleeping (``duration_s``: the time the move took); a stage at rest on another
    count than the commanded one reports ``MOVE_NOT_HELD`` with ``held_deg``. ``position()`` ->
    ``{"angle_deg", "t_s", "status"}``.

    Soft limits, one contract for the twin's stage and the drivers alike (checked by
    ``hw.conformance.check_conformance`` on both):

    - ``describe()["soft_limits_deg"]`` is ``[low, high]`` in degrees (low < high), or None for a
      stage without limits (only the twin's stage may have none: a driver's limits come from the
      bench file and are required);
    - ``move_to`` of a target outside ``[low, high]`` (or not finite) raises ``SoftLimitError``
      before anything happens: nothing is sent to the controller, nothing moves, the clock does not
      advance and ``position()`` is unchanged. It never returns a status for this: a refused move
      is an error a caller cannot overlook (a non-strict runner would otherwise read at the wrong
      stop). A closed-loop correction that would leave the limits is refused the same way.

    Speed limits: a driver refuses to move a stage whose speed exceeds the bench file's
    ``max_speed`` (and never raises the stage's speed itself)."""

    def move_to(self, target_deg: float) -> StageMove: ...

    def position(self) -> StagePosition: ...


class SoftLimitError(ValueError):
    """A stage move refused by the soft limits (``RotaryStage``): nothing was sent, nothing moved."""

    def __init__(self, stage: str, target_deg: float, limits_deg: tuple[float, float] | None):
        self.stage = stage
        self.target_deg = float(target_deg)
        self.limits_deg = None if limits_deg is None else (float(limits_deg[0]), float(limits_deg[1]))
        lim = "" if self.limits_deg is None else f" [{self.limits_deg[0]:g}, {self.limits_deg[1]:g}] deg"
        super().__init__(f"{stage}: move to {target_deg} deg refused: outside the soft limits{lim}; "
                         f"nothing was sent, nothing moved")


@runtime_checkable
class Camera(Instrument, Protocol):
    """Microscope camera. ``capture()`` -> ``{"image": 2-D np.ndarray (uint8 or uint16, greyscale),
    "t_s": float, "status": str}``."""

    def capture(self) -> CameraFrame: ...


INSTRUMENT_KINDS: dict[str, type] = {
    "probe": DisplacementProbe,
    "encoder": AngleEncoder,
    "autocollimator": Autocollimator,
    "stage": RotaryStage,
    "camera": Camera,
}


def is_kind(instrument: object, kind: str) -> bool:
    """Whether ``instrument`` is an instrument of ``kind`` (a key of ``INSTRUMENT_KINDS``): it has
    the kind's methods (the Protocol) and declares that kind (``describe()["kind"]``). The
    Protocol alone cannot tell a probe from an encoder at run time: both have ``read``."""
    proto = INSTRUMENT_KINDS.get(kind)
    if proto is None:
        raise KeyError(f"unknown instrument kind {kind!r}; known: {', '.join(INSTRUMENT_KINDS)}")
    if not isinstance(instrument, proto) or not isinstance(instrument, Instrument):
        return False
    try:
        declared = instrument.describe().get("kind")
    except Exception:  # noqa: BLE001 - an instrument whose describe() fails is of no kind
        return False
    return bool(declared == kind)


def check_image(image: Any) -> np.ndarray:
    """Validate a captured frame: 2-D greyscale uint8/uint16."""
    arr = np.asarray(image)
    if arr.ndim != 2 or arr.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"expected a 2-D uint8/uint16 greyscale image, got shape {arr.shape} dtype {arr.dtype}")
    return arr
