"""The twin's simulated instruments pass the same conformance check as the drivers
(hw.conformance.check_conformance), including the stage's soft-limit contract."""

from __future__ import annotations

import pytest

from benchtwin.hw.conformance import check_conformance
from benchtwin.hw.interfaces import SoftLimitError

KINDS = {"encoder": "encoder", "probe_top": "probe", "probe_bottom": "probe", "autocollimator": "autocollimator",
         "stage": "stage", "ccd": "camera"}


@pytest.fixture(scope="module")
def twin():
    from benchtwin.twin.scenario import load_scenario
    from benchtwin.twin.simulate import sim_build

    sc = load_scenario().with_overrides({"instruments.ccd.width": "64 px", "instruments.ccd.height": "48 px"})
    bench, state, inst = sim_build(sc, backend="analytic")
    inst["stage"].move_to(10.0)   # the bench is posed (instruments read the posed bodies)
    yield state, inst
    inst["ccd"].close()


def test_every_sim_instrument_conforms(twin):
    state, inst = twin
    assert set(KINDS) <= set(inst)
    for name, kind in KINDS.items():
        assert check_conformance(inst[name], kind) == [], name
    assert check_conformance(inst["stage"], "stage", move_to_deg=12.5) == []


def test_sim_stage_soft_limits_follow_the_driver_contract(twin):
    from benchtwin.twin.instruments.stage import SimRotaryStage, StageSpec

    state, inst = twin
    stage = SimRotaryStage("limited", state, inst["encoder"], StageSpec(soft_limits_deg=(-1.0, 361.0)))
    assert stage.describe()["soft_limits_deg"] == [-1.0, 361.0]
    assert check_conformance(stage, "stage", move_to_deg=30.0) == []
    t0, pos0 = state.clock.now(), stage.position()["angle_deg"]
    with pytest.raises(SoftLimitError, match=r"limited: move to 361.5 deg refused: outside the soft limits \[-1, 361\]"):
        stage.move_to(361.5)
    assert state.clock.now() == t0 and stage.position()["angle_deg"] == pos0   # nothing moved, no time passed
    assert stage.move_to(361.0)["status"] == "ok"                              # the limits themselves are allowed
    with pytest.raises(ValueError, match="low < high"):
        SimRotaryStage("bad", state, inst["encoder"], StageSpec(soft_limits_deg=(10.0, 0.0)))
