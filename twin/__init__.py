"""The twin: scenario -> MuJoCo model -> posed bodies -> instruments -> procedures -> dataset + truth/.

Public API (docs/api.md), imported lazily (``benchtwin._exports``)::

    from benchtwin.twin import load_scenario, Bench, sim_build
    sc = load_scenario(None).with_overrides({"bench.L1": "5 mm"})
    bench = Bench(sc)                                     # MuJoCo statics: posed bodies per angle
    bench_, state, instruments = sim_build(sc, backend="analytic")   # instruments of hw/interfaces

``benchtwin.simulate`` (the package root) writes a whole dataset; ``scenario_procedures`` gives
the scenario's procedures in the procedure language of ``benchtwin.hw.acquisition.procedures``.
"""

from typing import TYPE_CHECKING

from benchtwin._exports import lazy_exports

_EXPORTS = {
    "load_scenario": "benchtwin.twin.scenario",
    "Scenario": "benchtwin.twin.scenario",
    "ScenarioError": "benchtwin.twin.scenario",
    "Bench": "benchtwin.twin.physics",
    "sim_build": "benchtwin.twin.simulate",
    "sim_procedure": "benchtwin.twin.simulate",
    "scenario_procedures": "benchtwin.twin.simulate",
    "BenchPose": "benchtwin.twin.pose",
}
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
__all__ = list(_EXPORTS)

if TYPE_CHECKING:
    from benchtwin.twin.physics import Bench
    from benchtwin.twin.pose import BenchPose
    from benchtwin.twin.scenario import Scenario, ScenarioError, load_scenario
    from benchtwin.twin.simulate import scenario_procedures, sim_build, sim_procedure
