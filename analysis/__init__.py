"""The analysis pipeline. Reads datasets only: never imports the twin or hw, never opens the truth folder.

Public API (docs/api.md), imported lazily (``benchtwin._exports``) so that importing the dataset
format (as the twin and hw do) does not load the whole analysis::

    from benchtwin.analysis import open_dataset, analyze
    ds = open_dataset("out/jia/dataset"); ds.validate()
    res = analyze("out/jia/dataset", "out/jia")          # results.json + report.html

The equations live one module each (docs/architecture.md): ``fourier``, ``radial_motion``,
``eccentricity``, ``error_model`` (Jia 2019), ``shift_angle``, ``selfcal``, ``uncertainty``
(Hsieh 2022, GUM), ``effects`` and ``tracing`` (closing the loop).
"""

from typing import TYPE_CHECKING

from benchtwin._exports import lazy_exports

_EXPORTS = {
    "open_dataset": "benchtwin.analysis.dataset",
    "Dataset": "benchtwin.analysis.dataset",
    "DatasetWriter": "benchtwin.analysis.dataset",
    "DatasetError": "benchtwin.analysis.dataset",
    "analyze": "benchtwin.analysis.pipeline",
    "Results": "benchtwin.analysis.results_api",
    "Quantity": "benchtwin.analysis.results_api",
    "figure_error_curve": "benchtwin.analysis.figures",
    "figure_residual": "benchtwin.analysis.figures",
    "figure_radial_motion_polar": "benchtwin.analysis.figures",
    "figure_ccd_frame": "benchtwin.analysis.figures",
    "ErrorModel": "benchtwin.analysis.error_model",
    "error_model_from_results": "benchtwin.analysis.error_model",
    "jia_error_model": "benchtwin.analysis.error_model",
    "eccentricity_from_images": "benchtwin.analysis.eccentricity",
    "analyze_polygon": "benchtwin.analysis.hsieh_pipeline",
    "selfcal_fourier": "benchtwin.analysis.selfcal",
}
__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
__all__ = list(_EXPORTS)

if TYPE_CHECKING:
    from benchtwin.analysis.dataset import Dataset, DatasetError, DatasetWriter, open_dataset
    from benchtwin.analysis.eccentricity import eccentricity_from_images
    from benchtwin.analysis.error_model import ErrorModel, error_model_from_results, jia_error_model
    from benchtwin.analysis.hsieh_pipeline import analyze_polygon
    from benchtwin.analysis.figures import (figure_ccd_frame, figure_error_curve, figure_radial_motion_polar,
                                            figure_residual)
    from benchtwin.analysis.pipeline import analyze
    from benchtwin.analysis.results_api import Quantity, Results
    from benchtwin.analysis.selfcal import selfcal_fourier
