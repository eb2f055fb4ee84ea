"""Library of candidate effects that Jia et al. 2019's model (eq. 5) lacks; one module per effect.

Each module follows the protocol :class:`~benchtwin.analysis.effects.protocol.Effect` (NAME, MEANING,
PARAMS, CHANNELS, SEEN_BY_SELFCAL, SEPARATED_BY, SEPARATES_FROM, available, design, predict, aux,
term; :mod:`benchtwin.analysis.effects.protocol`), which mypy checks each registered module against.
``ALL`` is the registry name → module, in the order used to break ties.
"""

from __future__ import annotations

from . import (ac_drift, ac_scale, ccd_pixel_scale, graduation_error, interpolation_error, optical_radius,
               polygon_pitch_ignored, sphere_form, tangential_motion, tilt_abbe, torsion_hysteresis)
from .protocol import Effect

_MODULES: tuple[Effect, ...] = (graduation_error, optical_radius, ccd_pixel_scale, tangential_motion, tilt_abbe,
                                ac_drift, ac_scale, sphere_form, torsion_hysteresis, polygon_pitch_ignored,
                                interpolation_error)

from ._base import forward  # noqa: E402

ALL: dict[str, Effect] = {m.NAME: m for m in _MODULES}

__all__ = ["ALL", "Effect", "forward"] + [m.NAME for m in _MODULES]
