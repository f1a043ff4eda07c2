"""A found effect as data: what a calibration file keeps of each effect discovery named (or law
it proposed), and the effect rebuilt from it, ready to act on new commands.

A record is JSON-ready::

    {"name": "joint_friction", "granularity": "per_chain",
     "coefficients": {"dead_band[leg 1]": 0.0041, ...}, "std": {...}, "units": {...},
     "searched": 12.7 | {"joint": 3, "step_time_s": 41.2} | null,
     "law": {"terms": [...]} (a proposed or kept law only),
     "reference_payload_kg": 2.4 (a compliance fitted at several payloads only: the payload its
                                  weight terms stand for, the mean of its recording's)}

``coefficients`` are in the order of the effect's own (:meth:`Effect.coefficients`), and
:func:`effect_from_record` checks that the rebuilt effect names the same ones: a record of a
form, robot or law other than the one rebuilt is refused, not misread.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robot import Robot
from .base import Effect
from .compliance import LoadedCompliance
from .granularity import PER_CHAIN, SHARED, PerChainForm, per_chain_form
from .laws import LAW_NAME, Law, law_effect, law_from_dict, law_to_dict
from .lost_count import JointStep

__all__ = ["FittedEffect", "fitted_effects", "effect_record", "effect_from_record", "RECORD_KEYS"]

#: The keys every effect record has.
RECORD_KEYS = ("name", "granularity", "coefficients", "std", "units", "searched")


@dataclass(frozen=True, eq=False)
class FittedEffect:
    """An effect with the values fitted for it.

    Attributes:
        effect: the effect (a registered one, its per-chain form, or a law).
        coefficients: (p,) its coefficients, in the order of ``effect.coefficients(robot)``.
        std: (p,) their standard uncertainties (NaN where unknown).
        extra: its searched parameter (a pitch, a time constant, a :class:`JointStep`), or None.
    """

    effect: Effect
    coefficients: np.ndarray
    std: np.ndarray
    extra: object = None

    @property
    def name(self) -> str:
        return self.effect.name


def fitted_effects(fit) -> list[FittedEffect]:
    """The effects of a :class:`calib.effects.EffectFit` with their fitted values."""
    out = []
    for m, extra in zip(fit.models, fit.extras):
        s = fit.slices()[m.name]
        out.append(FittedEffect(m, np.array(fit.coefficients[s], dtype=float),
                                np.array(fit.coefficient_std[s], dtype=float), extra))
    return out


def _law_of(eff: Effect) -> Law | None:
    base = eff.base if isinstance(eff, PerChainForm) else eff
    return base if isinstance(base, Law) else None


def _searched_data(extra):
    if extra is None:
        return None
    if isinstance(extra, JointStep):
        return {"joint": int(extra.chain) + 1, "step_time_s": float(extra.time_s)}
    return float(extra)


def effect_record(fe: FittedEffect, robot: Robot, reference_payload_kg: float | None = None) -> dict:
    """The JSON-ready record of a fitted effect on ``robot`` (see the module docstring);
    ``reference_payload_kg``: the mean payload of the rows a payload-aware compliance was fitted on
    (needed for one, unless it already holds its reference)."""
    coefs = fe.effect.coefficients(robot)
    d = {"name": fe.name, "granularity": fe.effect.granularity,
         "coefficients": {c.name: float(v) for c, v in zip(coefs, fe.coefficients)},
         "std": {c.name: float(v) for c, v in zip(coefs, fe.std)},
         "units": {c.name: c.unit for c in coefs},
         "searched": _searched_data(fe.extra)}
    base = fe.effect.base if isinstance(fe.effect, PerChainForm) else fe.effect
    if isinstance(base, LoadedCompliance):
        reference = base.reference_payload_kg if base.reference_payload_kg is not None else reference_payload_kg
        if reference is None:
            raise ValueError("a compliance fitted at several payloads needs the mean payload of its rows")
        d["reference_payload_kg"] = float(reference)
    law = _law_of(fe.effect)
    if law is not None:
        gran = {t.name: PER_CHAIN if set(t.column_names()) & set(law.per_chain_capable) else SHARED
                for t in law.terms}
        d["law"] = law_to_dict(law.terms, gran)
    return d


def _searched(value, where: str, robot: Robot):
    if value is None:
        return None
    if isinstance(value, dict):
        try:
            joint, t = int(value["joint"]), float(value["step_time_s"])
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"{where}.searched: expected a number or {{'joint', 'step_time_s'}}") from None
        if not 1 <= joint <= robot.n_chains:
            raise ValueError(f"{where}.searched.joint: {joint} is not a joint of the {robot.name} (1..{robot.n_chains})")
        return JointStep(joint - 1, t)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise ValueError(f"{where}.searched: {value!r} is not a finite number")
    return float(value)


def effect_from_record(d: dict, robot: Robot, *, channels: dict | None = None,
                       where: str = "effect") -> FittedEffect:
    """The fitted effect a record holds, on ``robot`` (its coefficients checked against the
    effect's own names). ``channels``: recorded channels a law uses, one value per row of the
    data it will act on.

    Raises:
        ValueError: naming ``where`` and the key: not a record, an unknown effect or granularity,
            coefficients other than the effect's, a value that is not a finite number.
    """
    from .registry import EFFECTS

    if not isinstance(d, dict):
        raise ValueError(f"{where}: expected an object with keys {', '.join(RECORD_KEYS)}")
    for key in RECORD_KEYS:
        if key not in d:
            raise ValueError(f"{where}: key {key!r} missing")
    name, gran = d["name"], d["granularity"]
    if gran not in (SHARED, PER_CHAIN):
        raise ValueError(f"{where}.granularity: {gran!r} is neither {SHARED!r} nor {PER_CHAIN!r}")
    if "law" in d:
        try:
            terms, term_gran = law_from_dict(d["law"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{where}.law: not a law's terms ({exc!r})") from None
        eff = law_effect(terms, term_gran, channels, name=str(name))
    elif name in EFFECTS and name not in ("none", LAW_NAME):
        eff = EFFECTS[name]
        if "reference_payload_kg" in d:  # compliance at several payloads: its payload terms
            reference = d["reference_payload_kg"]
            if name != EFFECTS["compliance"].name or isinstance(reference, bool) or \
                    not isinstance(reference, (int, float)) or not np.isfinite(reference):
                raise ValueError(f"{where}.reference_payload_kg: {reference!r} is not a compliance's payload (a "
                                 "finite number of kg)")
            eff = LoadedCompliance(reference)
        if not eff.applies_to(robot):
            raise ValueError(f"{where}.name: {name!r} does not apply to the {robot.name}")
        if gran == PER_CHAIN and eff.granularity != PER_CHAIN:
            eff = per_chain_form(eff)
            if eff is None:
                raise ValueError(f"{where}.granularity: {name!r} has no per-chain form")
    else:
        raise ValueError(f"{where}.name: {name!r} is no registered effect (expected one of "
                         f"{', '.join(n for n in EFFECTS if n != 'none')}, or a law with key 'law')")
    if eff.granularity != gran:
        raise ValueError(f"{where}.granularity: {gran!r}, but the effect rebuilt is {eff.granularity!r}")
    names = [c.name for c in eff.coefficients(robot)]
    values = []
    for key in ("coefficients", "std"):
        block = d[key]
        if not isinstance(block, dict) or list(block) != names:
            got = list(block) if isinstance(block, dict) else block
            raise ValueError(f"{where}.{key}: expected the coefficients {names}, got {got}")
        for c, v in block.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or (key == "coefficients" and not np.isfinite(v)):
                raise ValueError(f"{where}.{key}.{c}: {v!r} is not a finite number")
        values.append(np.array(list(block.values()), dtype=float))
    return FittedEffect(eff, values[0], values[1], _searched(d["searched"], where, robot))
