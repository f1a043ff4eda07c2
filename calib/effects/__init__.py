"""Physics the geometric model leaves out: a registry of effects, one module each, and their
discovery (joint fits with the geometry, model choice, outliers, localisation) written once
over :class:`calib.robot.Robot`.

Adding an effect: write its module (a subclass of :class:`Effect` in an instance named
``EFFECT``, see :mod:`calib.effects.base`) and append the module's name to
:data:`EFFECT_MODULES`. Coefficients that may differ from chain to chain are named in
:attr:`Effect.per_chain_capable`: the effect then also has a per-chain form
(:mod:`calib.effects.granularity`), which discovery weighs against the shared one.
"""

from __future__ import annotations

import importlib

from ..lazy import lazy_exports
from ..robot import Robot
from .base import (FOLLOWED_QUANTITIES, Coefficient, Effect, EffectData, EffectScenario, MachineContext, PhysicalParameter,
                   SearchedParameter)

__all__ = ["EFFECT_MODULES", "EFFECTS", "effect", "effects_for", "effect_family", "nested_in", "Effect", "EffectData", "Coefficient",
           "SearchedParameter", "PhysicalParameter", "MachineContext", "EffectScenario", "FOLLOWED_QUANTITIES",
           "MIN_DELTA_BIC", "MAX_EFFECTS", "EffectFit", "Discovery", "fit_effect", "fit_effects", "discover_effects",
           "discover_effect", "remainder_tests", "outlier_scan", "regressor_correlation", "locate_mismatch",
           "closure_noise_std", "candidate_forms", "PerChainForm", "per_chain_form", "SHARED", "PER_CHAIN",
           "propose_law", "ProposedLaw", "Law", "law_effect", "search_law", "LAW_WORDS", "law_to_dict", "law_from_dict"]

#: The effect modules of this package, in the order of the registry (``none`` first).
EFFECT_MODULES = ("none", "compliance", "joint_friction", "thermal_drift", "actuator_scale", "periodic_screw_error",
                  "instrument_drift", "lost_count", "thermal_warmup")

#: name -> effect, in the order of :data:`EFFECT_MODULES`.
EFFECTS: dict[str, Effect] = {
    e.name: e for e in (importlib.import_module(f"{__name__}.{m}").EFFECT for m in EFFECT_MODULES)}


def effect(name: str | Effect) -> Effect:
    """The effect registered under ``name`` (an :class:`Effect` is returned as is).

    Raises:
        ValueError: unknown name (the message lists the registered ones).
    """
    if isinstance(name, Effect):
        return name
    try:
        return EFFECTS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown effect {name!r}: expected one of {', '.join(EFFECTS)}") from None


def effects_for(robot: Robot) -> tuple[str, ...]:
    """Names of the effects that apply to ``robot``, registry order (``none`` first)."""
    return tuple(n for n, e in EFFECTS.items() if e.applies_to(robot))


def nested_in(name: str | Effect) -> tuple[str, ...]:
    """Names of the registered effects that ``name`` (a registered name or an :class:`Effect`)
    generalises, directly or through another (:attr:`Effect.generalises`), registry order."""
    seen: set = set()
    todo = list(effect(name).generalises)
    while todo:
        n = todo.pop()
        if n not in seen:
            seen.add(n)
            todo += list(effect(n).generalises)
    return tuple(n for n in EFFECTS if n in seen)


def effect_family(name: str | Effect) -> tuple[str, ...]:
    """``name`` and every registered effect nested with it, either way (those it generalises
    and those that generalise it, transitively), registry order with ``name`` first if it is not
    registered: the effects a recording of ``name`` is also correctly explained by, and that
    leave-one-out removes together."""
    first = effect(name)
    family, todo = {first.name}, [first]
    while todo:  # the effects nested with one already found, either way, until none is new
        e = effect(todo.pop())
        found = set(nested_in(e)) | {g for g in EFFECTS if e.name in nested_in(g)}
        todo += list(found - family)
        family |= found
    return tuple(([] if first.name in EFFECTS else [first.name]) + [n for n in EFFECTS if n in family])


# Discovery's names are imported from it when first read: it loads scipy.stats (half a second), which
# a command that only reads or writes found effects (the calibration file) does not need.
_discovery_names, __getattr__, __dir__ = lazy_exports(__name__, {"discovery": (
    "MAX_EFFECTS", "MIN_DELTA_BIC", "Discovery", "EffectFit", "candidate_forms", "closure_noise_std", "discover_effect",
    "discover_effects", "fit_effect", "fit_effects", "locate_mismatch", "outlier_scan", "propose_law",
    "regressor_correlation", "remainder_tests")})
from .laws import LAW_WORDS, Law, ProposedLaw, law_effect, law_from_dict, law_to_dict, search_law  # noqa: E402
from .granularity import PER_CHAIN, SHARED, PerChainForm, per_chain_form  # noqa: E402
