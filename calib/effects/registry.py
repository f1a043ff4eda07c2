"""The registry of effects: every effect module of :mod:`calib.effects` by name, and the
relations between them (which one generalises which).

Adding an effect: write its module (a subclass of :class:`calib.effects.base.Effect` in an
instance named ``EFFECT``) and append the module's name to :data:`EFFECT_MODULES`.
"""

from __future__ import annotations

import importlib

from ..robot import Robot
from .base import Effect

__all__ = ["EFFECT_MODULES", "EFFECTS", "effect", "effects_for", "nested_in", "effect_family"]

#: The effect modules of this package, in the order of the registry (``none`` first).
EFFECT_MODULES = ("none", "compliance", "joint_friction", "thermal_drift", "actuator_scale", "periodic_screw_error",
                  "instrument_drift", "lost_count", "thermal_warmup")

#: name -> effect, in the order of :data:`EFFECT_MODULES`.
EFFECTS: dict[str, Effect] = {
    e.name: e for e in (importlib.import_module(f"{__package__}.{m}").EFFECT for m in EFFECT_MODULES)}


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
