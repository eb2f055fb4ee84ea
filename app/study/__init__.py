"""Design studies: a parameter sweep × Monte Carlo repetitions on the twin, tabulated and reported.

Four parts, one concern each (docs/studies.md is the user's reference):

- ``spec``: the study file (schema, parameters, target) and its expanded points;
- ``points``: what one point computes, by fidelity (physics statics, or the full
  simulate → analyze pipeline of ``benchtwin.app.run``);
- ``execution``: seeds, cache, the process pool or Dask cluster, the CSV/Parquet tables;
- ``report``: the target verdict, figures, the written summary and ``report.html``.

A user script needs only::

    from benchtwin.app.study import load_study, run_study
"""

from .execution import code_version, rep_seed, run_study
from .spec import Parameter, Point, Study, StudyError, Target, expand_points, load_study

__all__ = ["Parameter", "Point", "Study", "StudyError", "Target", "code_version", "expand_points",
           "load_study", "rep_seed", "run_study"]
