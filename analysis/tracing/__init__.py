"""Close the loop: trace the residual between Jia's model and the measured encoder error to the effect
the model lacks.

Jia et al. 2019 (Appl. Sci. 9, 3415) validate their model Δθ = [e·sin(θ−θ0) + ∫δY dθ]/r (eq. 5)
against an autocollimator and a 23-face polygon and are left with a residual within ±6″, 9 % of the
encoder error, whose cause they only guess ("imperfect manufacturing of the grating disk and other
minor errors", sec. 6). Hsieh et al. 2022 (Appl. Sci. 12, 5008) give the polygon data's structure
(eq. 3: ε_ij = α((i−1)·360/N + S) + Σβ + U_j, start faces j, shift angles S) and the multi-head
self-calibration (eqs. 8–9) that sees the encoder's own errors but not the reference chain's.

This module takes everything the analysis knows about a dataset, per polygon reading
(:class:`Evidence`), and answers, in order:

1. Is there anything to explain? χ² of the residual against the combined uncertainty of the
   measurement and of the model (model parameter uncertainties enter as nuisance columns with a
   unit Gaussian prior, i.e. the covariance diag(u²) + S·Sᵀ), and a harmonic-by-harmonic test.
2. Its signature: harmonic spectrum, drift with time, repetition (synchronous or not), start face
   and shift (polygon-related or not), direction (hysteresis), self-calibration, correlation with
   the radial motion and with each of the model's own terms.
3. Which effect of the library (:mod:`benchtwin.analysis.effects`) explains it: each candidate alone
   and in pairs, weighted least squares, BIC and AICc, leave-one-group-out cross-validation,
   significance gates against over-fitting; ambiguity sets with the separating measurement;
   "unexplained" when nothing brings the residual down to the noise.

The polygon closure (Hsieh eq. 2: Σα = 0 per run; eq. 7 solves U_j from it) leaves α known only up
to a constant per set of readings that share one setup error U ("closure group", default: one
(shift, start face, repetition) mounting: the twin and Hsieh's six measurements mount the polygon
anew for every repetition; the two directions of one repetition share it). Every fit here therefore removes the weighted mean per closure group
from the residual and from every column (equivalent to free offsets per group); the degrees of
freedom count them.

Thresholds (tuned on the synthetic tests, see docs/effects.md): ``P_SIG`` = 1e-3 for χ² tests,
harmonic flags at a Bonferroni-corrected 1e-3, candidate gates ``Z_GATE`` = 4 and ``DBIC_GATE`` = 10,
ambiguity when ΔBIC < ``AMBIG_DBIC`` = 6 and the predictions' cos² > ``COLLINEAR`` = 0.9.

The package (one module per step; the names of the former single module are all importable from
``benchtwin.analysis.tracing``):

- ``thresholds``: significance thresholds and bench constants (docs/effects.md);
- ``evidence``: :class:`Evidence`, :class:`RadialMotion`, :class:`SelfCal`, :class:`CCDData`,
  :func:`evidence_from_polygon` (with its :class:`BenchContext` and :class:`SelfCalCurve`);
- ``problem``: the weighted least-squares problem (closure groups, nuisance columns, CV folds);
- ``significance``: 1., :func:`residual_test`, :func:`harmonic_test`;
- ``signature``: 2., :func:`signature`;
- ``selection``: 3., :func:`trace`, one stage after the other: evidence → candidates → fit and
  select (screening, gates with the CV folds, pairs, the representative) → report → ambiguity sets
  → outcome;
- ``traced_model``: the model file (:func:`save_model`, :func:`load_model`, :func:`add_to_error_model`).
"""

from __future__ import annotations


# Every name of the former single module, the underscored ones included: tests and the loop figures
# (analysis/report/figures_loop.py) use some of them (_center, _Problem, _replace_alpha).
from .thresholds import (AMBIG_DBIC, ASYNC_BAND, ASYNC_NOISE_ORDER, ASYNC_P, COLLINEAR, DBIC_GATE, DEGENERATE_RATIO,
                         F_SIG, MAX_CV_FOLDS, P_SIG, SIZE_GATE, SPHERE_FORM_UM, THETA_BIN_DEG, TIE_REL, Z_GATE,
                         Z_PAIR)
from ._blas import _one_blas_thread, _openblas
from .evidence import (approach_direction, BenchContext, CCDData, column, Evidence, evidence_from_polygon, RadialMotion,
                       _replace_alpha, SelfCal, SelfCalCurve, _View)
from .problem import _center, noise_floor, _Problem, _rms, _z_from_chi2
from .significance import harmonic_test, _nested, _one_column, residual_test
from .signature import (_dummies, _free_of_theta, _selfcal_signature, _short_signature, signature, _significant_parts,
                        _time_pattern)
from .selection import (_better, _Cand, _cos2, _cos_signed, _adjustment_coefs, _evaluate, _member_predictions, _ordered,
                        _params_u, _prefer, _prepare, _prior_rank, _reference_corrections, _regressor_adjustments,
                        _sep_text, trace)
from .traced_model import (add_to_error_model, _jsonable, load_model, model_terms_from_payload, _payload, _read,
                           save_model)

__all__ = [
    "Evidence", "RadialMotion", "SelfCal", "CCDData", "trace", "signature", "residual_test",
    "save_model", "load_model", "model_terms_from_payload", "add_to_error_model", "evidence_from_polygon",
    "BenchContext", "SelfCalCurve", "approach_direction",
    "P_SIG", "Z_GATE", "DBIC_GATE", "AMBIG_DBIC", "COLLINEAR", "TIE_REL",
]
