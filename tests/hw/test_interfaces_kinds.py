"""The instrument kinds are told apart: by their reading types (statically, mypy on
hw/conformance_static.py and twin/instruments/conformance_static.py in .ci/lint) and at run time by
``is_kind`` and ``check_conformance``, where a runtime_checkable Protocol alone cannot (``read``
is shared by probe, encoder and autocollimator)."""

from __future__ import annotations

from typing import get_type_hints

import pytest

from benchtwin.hw import interfaces as I
from benchtwin.hw.conformance import _REQUIRED, check_conformance
from benchtwin.hw.drivers.elcomat import Elcomat
from benchtwin.hw.drivers.heidenhain import HeidenhainND
from benchtwin.hw.drivers.millimar import MillimarC1202
from benchtwin.hw.transport import ReplayTransport


class ProbeLike:
    """A probe as the Protocols see it: name, describe(), read() -> value_um."""

    name = "p"
    kind = "probe"

    def describe(self):
        return {"name": "p", "kind": "probe", "model": "stand-in", "units": {"value_um": "um"}}

    def read(self):
        return {"value_um": 1.5, "t_s": 0.0, "status": "ok"}


def test_a_probe_passes_the_bare_protocols_of_other_kinds_but_not_is_kind():
    p = ProbeLike()
    # the weakness the reading types fix: isinstance sees only method names
    assert isinstance(p, I.AngleEncoder) and isinstance(p, I.Autocollimator)
    assert I.is_kind(p, "probe")
    assert not I.is_kind(p, "encoder") and not I.is_kind(p, "autocollimator")
    assert not I.is_kind(p, "stage") and not I.is_kind(p, "camera")
    with pytest.raises(KeyError, match="unknown instrument kind"):
        I.is_kind(p, "thermometer")


def test_the_conformance_check_rejects_a_probe_as_encoder_or_autocollimator():
    p = ProbeLike()
    assert check_conformance(p, "probe") == []
    as_encoder = check_conformance(p, "encoder")
    assert any("heads_deg" in m for m in as_encoder) and any("angle_deg" in m for m in as_encoder)
    assert any("x_arcsec" in m for m in check_conformance(p, "autocollimator"))


def test_drivers_are_of_their_kind_only():
    drivers = {"autocollimator": Elcomat("ac", ReplayTransport([])),
               "encoder": HeidenhainND("enc", ReplayTransport([])),
               "probe": MillimarC1202("pr", ReplayTransport([]))}
    for kind, drv in drivers.items():
        assert [k for k in I.INSTRUMENT_KINDS if I.is_kind(drv, k)] == [kind], kind


def test_reading_types_and_the_runtime_check_name_the_same_keys():
    """The TypedDicts and hw/conformance.py's required keys are one contract written twice."""
    reading = {"probe": I.ProbeReading, "encoder": I.EncoderReading, "autocollimator": I.AutocollimatorReading,
               "stage": I.StagePosition, "camera": I.CameraFrame}
    for kind, td in reading.items():
        assert set(td.__required_keys__) - {"t_s", "status"} == set(_REQUIRED[kind]), kind
        assert {"t_s", "status"} <= td.__required_keys__
    assert get_type_hints(I.Stamped)["t_s"] is float
    assert get_type_hints(I.DisplacementProbe.read)["return"] is I.ProbeReading
    assert get_type_hints(I.AngleEncoder.read)["return"] is I.EncoderReading
    assert get_type_hints(I.RotaryStage.move_to)["return"] is I.StageMove
