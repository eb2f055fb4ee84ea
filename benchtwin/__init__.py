"""benchtwin: digital twin of a rotary-encoder calibration bench, and its analysis.

Subpackages (each a top-level folder of the repository, installed under this one name):
``benchtwin.twin`` (simulation), ``benchtwin.analysis`` (the pipeline, reads datasets only),
``benchtwin.hw`` (hardware adapters), ``benchtwin.models`` (MJCF and assets),
``benchtwin.scenarios`` (embedded scenario files).
"""

__version__ = "0.1.0"
