"""Closing the loop (Jia et al. 2019 eq. 5 residual -> the effect the model lacks): the package of the
former analysis/tracing.py. This first step only moves the module to ``selection`` (so its history
follows); the next commit splits it by step (evidence, tests, signature, selection, model file).
"""

from __future__ import annotations

from .selection import (add_to_error_model, AMBIG_DBIC, ASYNC_BAND, ASYNC_NOISE_ORDER, ASYNC_P, _better, _Cand,
                        CCDData, _center, COLLINEAR, _cos2, _cos_signed, DBIC_GATE, DEGENERATE_RATIO, _dummies,
                        _evaluate, Evidence, evidence_from_polygon, F_SIG, _free_of_theta, _harmonic_coefs,
                        harmonic_test, _jsonable, load_model, MAX_CV_FOLDS, _member_predictions,
                        model_terms_from_payload, _nested, noise_floor, _one_blas_thread, _one_column, _openblas,
                        _ordered, P_SIG, _params_u, _payload, _prefer, _prepare, _prior_rank, _Problem, RadialMotion,
                        _read, _reference_corrections, _regressor_adjustments, _replace_alpha, residual_test, _rms,
                        save_model, SelfCal, _selfcal_signature, _sep_text, _short_signature, signature,
                        _significant_parts, SIZE_GATE, SPHERE_FORM_UM, THETA_BIN_DEG, TIE_REL, _time_pattern, trace,
                        _View, _z_from_chi2, Z_GATE, Z_PAIR)
from .selection import __all__ as __all__
