"""The protocol every effect module follows, stated once with types (see ``docs/effects.md``).

An effect of the library is a module, not a class: its constants describe it and its functions fit
it. :class:`Effect` states what such a module provides, so that the registry
(:data:`benchtwin.analysis.effects.ALL`) is typed as a collection of ``Effect`` and mypy checks every
registered module against it (PEP 544: a module can implement a protocol). :func:`problems` checks
the same at run time, with each function's arity (tests/analysis/test_effects.py).

Required (:class:`Effect`, each member documented there): the description ``NAME``, ``MEANING``,
``PARAMS``, ``CHANNELS``, ``SEEN_BY_SELFCAL``, ``SEPARATED_BY``, ``SEPARATES_FROM``; the functions
``available``, ``design``, ``predict``, ``aux``, ``term``. All effects here are linear in their
parameters: the residual is ``X @ params`` with ``X`` from ``design``.

Optional (:class:`EffectOptions`; the callers test for them with ``hasattr``/``getattr``, so a
module that does not need one leaves it out): ``plausible``, ``heads``, ``regressor_perturbations``,
``ambiguous_with``, ``variants``, ``SUBSETS`` and ``SEPARATES_WITH_X_PROBES``.

The shared implementations (the linear ``predict``, the empty ``aux``, the absent ``term`` of a
reference-chain effect, the ``CHANNELS`` builder) are in :mod:`benchtwin.analysis.effects._base`.

``ev`` is a :class:`benchtwin.analysis.tracing.Evidence` (or its self-calibration view, which has
the same θ-related attributes); the modules use its attributes only (duck typing), so they do not
import ``tracing`` (which imports them): here it is typed :data:`Evidence` = ``Any``.
"""

from __future__ import annotations

import inspect
import typing
from collections.abc import Callable, Mapping
from typing import Any, Protocol

import numpy as np

#: the evidence an effect reads (duck-typed, see the module docstring)
Evidence = Any
#: the tracing's context (e.g. ``{"harmonics": [2, 5]}``: the harmonics the residual test flagged), or None
Context = Mapping[str, Any] | None
#: an ErrorModel term: θ (rad, array) → the encoder error (arcsec)
ThetaFunction = Callable[[Any], Any]

#: the measured channels every module's CHANNELS describes, in this order
CHANNEL_NAMES = ("alpha", "selfcal", "radial", "ccd", "heads")


class Effect(Protocol):
    """What every effect module provides (the module docstring says what each member means)."""

    NAME: str
    """the registry's key (``ALL[NAME]``), also the module's name"""
    MEANING: str
    """one paragraph: what is physically wrong and how it shows"""
    PARAMS: dict[str, str]
    """parameter name → unit (``{k}`` in a name marks a family, e.g. ``a{k}_arcsec``)"""
    CHANNELS: dict[str, str]
    """measured channel (every one of :data:`CHANNEL_NAMES`, in that order) → how the effect shows up there"""
    SEEN_BY_SELFCAL: bool
    """an error of the encoder/model, hence present identically in the multi-head self-calibration
    residual (True), or of the polygon/autocollimator reference chain, hence absent there (False)"""
    SEPARATED_BY: str
    """which data tell it apart"""
    SEPARATES_FROM: dict[str, str]
    """other effect → the measurement that would separate the two"""

    def available(self, ev: Evidence, ctx: Context = None) -> tuple[bool, str]:
        """(can these data show it, why not / a note)"""
        ...

    def design(self, ev: Evidence, ctx: Context = None) -> tuple[np.ndarray, list[str]]:
        """(X, names): X of shape (n_readings, n_params), the residual being ``X @ params``"""
        ...

    def predict(self, ev: Evidence, params: Mapping[str, float], ctx: Context = None) -> np.ndarray:
        """the residual at the readings for ``params`` (arcsec; names not given count as 0)"""
        ...

    def aux(self, ev: Evidence, ctx: Context = None) -> dict[str, Any]:
        """JSON-ready data the θ-function needs (stored in the model file beside the parameters)"""
        ...

    def term(self, params: Mapping[str, float], aux: Mapping[str, Any],
             base_terms: Any = None) -> ThetaFunction | None:
        """the ErrorModel term θ (rad) → arcsec, or None: not an encoder error (no term)"""
        ...


class EffectOptions(Protocol):
    """Members a module may add (each with this signature where present):

    - ``plausible(ev, params, u, ctx) -> (bool, reason)``: the fitted values are physically possible;
    - ``heads(ev, params, heads_deg, ctx)``: δ_(1,j) at the readings, (n, n_heads) arcsec (Hsieh eq. 8), or None;
    - ``regressor_perturbations(ev, params, ctx)``: the regressors' own uncertainty as columns
      (errors in variables);
    - ``ambiguous_with(ev) -> [names]``: effects it cannot be told from with these data;
    - ``variants(names, ev, ctx) -> [[names]]`` or ``SUBSETS``: the parameter subsets tried;
    - ``SEPARATES_WITH_X_PROBES``: other effect → the separating measurement on a bench that has X
      probes, where ``SEPARATES_FROM``'s would advise the probes it already has.
    """

    SUBSETS: list[list[str]]
    SEPARATES_WITH_X_PROBES: dict[str, str]

    def plausible(self, ev: Evidence, params: Mapping[str, float], u: Mapping[str, float],
                  ctx: Context = None) -> tuple[bool, str]: ...
    def heads(self, ev: Evidence, params: Mapping[str, float], heads_deg: Any,
              ctx: Context = None) -> np.ndarray | None: ...
    def regressor_perturbations(self, ev: Evidence, params: Mapping[str, float], ctx: Context = None) -> np.ndarray: ...
    def ambiguous_with(self, ev: Evidence) -> list[str]: ...
    def variants(self, names: list[str], ev: Evidence = None, ctx: Context = None) -> list[list[str]]: ...


def _members(proto: type) -> tuple[dict[str, type], dict[str, inspect.Signature]]:
    """(data member → runtime type, function member → signature without ``self``) of a protocol."""
    data = {name: typing.get_origin(t) or t for name, t in typing.get_type_hints(proto).items()}
    funcs = {}
    for name, v in vars(proto).items():
        if inspect.isfunction(v) and not name.startswith("_"):
            sig = inspect.signature(v)
            funcs[name] = sig.replace(parameters=list(sig.parameters.values())[1:])
    return data, funcs


def _arity_problem(fn: Any, want: inspect.Signature) -> str | None:
    """Why ``fn`` cannot be called positionally as ``want`` is (with only its required arguments and
    with all of them), or None."""
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return "no signature"
    n_all = len(want.parameters)
    n_req = sum(p.default is inspect.Parameter.empty for p in want.parameters.values())
    for n in sorted({n_req, n_all}):
        try:
            sig.bind(*range(n))
        except TypeError:
            return f"takes {sig}, cannot be called with {n} positional arguments as {want}"
    return None


def problems(module: Any) -> list[str]:
    """What keeps ``module`` from being an :class:`Effect` (missing members, wrong types, functions
    that cannot be called with the protocol's arguments; optional members checked where present);
    [] when it is one."""
    out = []
    for proto, required in ((Effect, True), (EffectOptions, False)):
        data, funcs = _members(proto)
        for name, t in data.items():
            if not hasattr(module, name):
                if required:
                    out.append(f"{name}: missing")
            elif not isinstance(getattr(module, name), t):
                out.append(f"{name}: expected {t.__name__}, got {type(getattr(module, name)).__name__}")
        for name, want in funcs.items():
            if not hasattr(module, name):
                if required:
                    out.append(f"{name}(): missing")
            elif not callable(getattr(module, name)):
                out.append(f"{name}(): not callable")
            elif (why := _arity_problem(getattr(module, name), want)) is not None:
                out.append(f"{name}(): {why}")
    channels = getattr(module, "CHANNELS", None)
    if isinstance(channels, Mapping) and tuple(channels) != CHANNEL_NAMES:
        out.append(f"CHANNELS: expected the channels {', '.join(CHANNEL_NAMES)} in that order, got {', '.join(channels)}")
    return out
