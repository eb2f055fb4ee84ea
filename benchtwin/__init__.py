"""benchtwin: digital twin of a rotary-encoder calibration bench, and its analysis.

Subpackages (each a top-level folder of the repository, installed under this one name):
``benchtwin.twin`` (simulation), ``benchtwin.analysis`` (the pipeline, reads datasets only),
``benchtwin.hw`` (hardware adapters), ``benchtwin.models`` (MJCF and assets),
``benchtwin.scenarios`` (embedded scenario files).
"""

__version__ = "0.1.0"


def score(fn, suite=None, *, seed=11, size="small", jobs=1):
    """Score an algorithm written as a Python function (dataset path → results dict) on the
    benchmark suite, without writing results files (issue 19; docs/scoring.md).

    ``suite``: a suite directory (``benchtwin suite -o DIR``), or None / "small" / "full" for a
    blind suite built once in ~/.cache/benchtwin (or $BENCHTWIN_CACHE). Returns a dict with
    ``table`` (Markdown: one row per dataset, one overall figure per criterion), ``overall``,
    ``scores`` (per dataset) and ``errors`` (datasets where ``fn`` raised)."""
    from benchtwin.app.suite import score_callable

    return score_callable(fn, suite, seed=seed, size=size, jobs=jobs)
