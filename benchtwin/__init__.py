"""benchtwin: digital twin of a rotary-encoder calibration bench, and its analysis.

Subpackages (each a top-level folder of the repository, installed under this one name):
``benchtwin.twin`` (simulation), ``benchtwin.analysis`` (the pipeline, reads datasets only),
``benchtwin.hw`` (hardware adapters), ``benchtwin.models`` (MJCF and assets),
``benchtwin.scenarios`` (embedded scenario files), and ``benchtwin.app`` (the application layer:
commands, studies, scoring).

What a user script needs (docs/api.md)::

    import benchtwin
    sc = benchtwin.load_scenario("scenarios/jia2019.toml")     # or None: the embedded default
    ds = benchtwin.simulate(sc, "out/jia/dataset")             # dataset + truth/
    res = benchtwin.analyze(ds, "out/jia/analysis")            # results.json + report.html
    r = benchtwin.analyze(ds)                                  # in memory: a Results, nothing written
    r.eccentricity, r.to_dataframe(); benchtwin.figure_error_curve(r)   # notebook (docs/examples)
    benchtwin.acquire("bench.toml", "out/real")                # the same format from instruments
    benchtwin.run_study("scenarios/studies/bearing_distance.toml", "out/study")
    benchtwin.score(my_algorithm)                              # against the benchmark suite

Exports are imported lazily (``benchtwin._exports``): ``import benchtwin`` stays cheap.
"""

from typing import TYPE_CHECKING

from benchtwin._exports import lazy_exports

__version__ = "0.1.0"

_EXPORTS = {
    "load_scenario": "benchtwin.twin.scenario",
    "Scenario": "benchtwin.twin.scenario",
    "ScenarioError": "benchtwin.twin.scenario",
    "simulate": "benchtwin.twin.simulate",
    "analyze": "benchtwin.analysis.pipeline",
    "open_dataset": "benchtwin.analysis.dataset",
    "DatasetError": "benchtwin.analysis.dataset",
    "acquire": "benchtwin.hw.acquisition.acquire",
    "run_study": "benchtwin.app.study",
    "simulate_and_analyze": "benchtwin.app.run",
    "SimulatedDataset": "benchtwin.twin.simulate",
    "Results": "benchtwin.analysis.results_api",
    "Quantity": "benchtwin.analysis.results_api",
    "figure_error_curve": "benchtwin.analysis.figures",
    "figure_residual": "benchtwin.analysis.figures",
    "figure_radial_motion_polar": "benchtwin.analysis.figures",
    "figure_ccd_frame": "benchtwin.analysis.figures",
}
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
__all__ = ["__version__", "score", *_EXPORTS]

if TYPE_CHECKING:
    from benchtwin.analysis.dataset import DatasetError, open_dataset
    from benchtwin.analysis.figures import (figure_ccd_frame, figure_error_curve, figure_radial_motion_polar,
                                            figure_residual)
    from benchtwin.analysis.pipeline import analyze
    from benchtwin.analysis.results_api import Quantity, Results
    from benchtwin.app.run import simulate_and_analyze
    from benchtwin.app.study import run_study
    from benchtwin.hw.acquisition.acquire import acquire
    from benchtwin.twin.scenario import Scenario, ScenarioError, load_scenario
    from benchtwin.twin.simulate import SimulatedDataset, simulate


def score(fn, suite=None, *, seed=11, size="small", jobs=1):
    """Score an algorithm written as a Python function (dataset path → results dict) on the
    benchmark suite, without writing results files (issue 19; docs/scoring.md).

    ``suite``: a suite directory (``benchtwin suite -o DIR``), or None / "small" / "full" for a
    blind suite built once in ~/.cache/benchtwin (or $BENCHTWIN_CACHE). Returns a dict with
    ``table`` (Markdown: one row per dataset, one overall figure per criterion), ``overall``,
    ``scores`` (per dataset) and ``errors`` (datasets where ``fn`` raised)."""
    from benchtwin.app.suite import score_callable

    return score_callable(fn, suite, seed=seed, size=size, jobs=jobs)
