"""The application layer: what runs the twin, the hardware and the analysis together.

Commands, the run of a scenario end to end, design studies, scoring, certificates. It sits on top
of ``benchtwin.twin``, ``benchtwin.hw`` and ``benchtwin.analysis`` and nothing below imports it
(import-linter contract in pyproject.toml).
"""
