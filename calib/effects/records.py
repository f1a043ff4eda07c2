"""A found effect as a typed record: what a calibration keeps of each effect discovery named (or
law it proposed), and the effect rebuilt from it, ready to act on new commands.

:class:`EffectRecord` (frozen) holds an effect's name and granularity, its coefficients
(:class:`CoefficientRecord`: name, value, standard uncertainty, unit), its searched parameter (a
float, or a :class:`~calib.effects.lost_count.JointStep`), a proposed or kept law's terms
(:class:`LawTerms`) and the reference payload of a compliance fitted at several payloads.
:meth:`EffectRecord.fitted` rebuilds the effect (a law binds the recorded channels it is given
then, so the record, not the bound effect, is what a calibration keeps).

JSON is for the file edge only (:meth:`EffectRecord.to_dict`, :meth:`EffectRecord.from_dict`)::

    {"name": "joint_friction", "granularity": "per_chain",
     "coefficients": {"dead_band[leg 1]": 0.0041, ...}, "std": {...}, "units": {...},
     "searched": 12.7 | {"joint": 3, "step_time_s": 41.2} | null,
     "reference_payload_kg": 2.4 (a compliance fitted at several payloads only: the payload its
                                  weight terms stand for, the mean of its recording's),
     "law": {"terms": [...]} (a proposed or kept law only)}

``coefficients`` are in the order of the effect's own (:meth:`Effect.coefficients`), and
:meth:`EffectRecord.fitted` checks that the rebuilt effect names the same ones: a record of a
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

__all__ = ["FittedEffect", "fitted_effects", "CoefficientRecord", "LawTerms", "EffectRecord", "RECORD_KEYS"]

#: The keys every effect record has.
RECORD_KEYS = ("name", "granularity", "coefficients", "std", "units", "searched")
#: The granularities an effect or a law's term has.
GRANULARITIES = (SHARED, PER_CHAIN)


@dataclass(frozen=True, eq=False)
class FittedEffect:
    """An effect with the values fitted for it.

    Attributes:
        effect: the effect (a registered one, its per-chain form, or a law).
        coefficients: (p,) its coefficients, in the order of ``effect.coefficients(robot)``, each
            in its coefficient's unit.
        std: (p,) their standard uncertainties, same units (NaN where unknown).
        extra: its searched parameter (a pitch in the joint unit, a time constant in s, a
            :class:`JointStep`), or None.
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


def is_number(value, finite: bool = True) -> bool:
    """Whether ``value`` (read from JSON) is a number (not a bool), finite when ``finite``."""
    return not isinstance(value, bool) and isinstance(value, (int, float)) and (not finite or bool(np.isfinite(value)))


@dataclass(frozen=True)
class CoefficientRecord:
    """A fitted coefficient of an effect.

    Attributes:
        name: its name (``dead_band[leg 1]``, ``pitch_sin``), the effect's own.
        value: its value, in ``unit``.
        std: its standard uncertainty, in ``unit`` (NaN where unknown).
        unit: its unit (``mm``, ``rad``, ``mm/kg``, ``1``).
    """

    name: str
    value: float
    std: float
    unit: str


@dataclass(frozen=True)
class LawTerms:
    """A proposed or kept law as a calibration keeps it: its terms and whether each term's
    constants are shared by every joint or each joint's own.

    Attributes:
        terms: the law's terms (:class:`calib.effects.laws.Term`), in its coefficients' order.
        granularity: one per term, ``shared`` or ``per_chain``.
    """

    terms: tuple
    granularity: tuple

    @classmethod
    def of(cls, law: Law) -> "LawTerms":
        """The terms of ``law`` (a term is per joint where its columns are the law's per-chain ones)."""
        capable = set(law.per_chain_capable)
        return cls(tuple(law.terms), tuple(PER_CHAIN if set(t.column_names()) & capable else SHARED
                                           for t in law.terms))

    def by_term(self) -> dict:
        """``{term name: granularity}`` (:func:`calib.effects.laws.law_effect`'s argument)."""
        return {t.name: g for t, g in zip(self.terms, self.granularity)}

    def effect(self, channels: dict | None = None, name: str = LAW_NAME) -> Effect:
        """The law as an effect called ``name``, bound to the recorded ``channels`` it uses (one
        value per row of the data it acts on): a :class:`Law`, or its per-chain form."""
        return law_effect(self.terms, self.by_term(), channels, name=name)

    def to_dict(self) -> dict:
        """The law's JSON object (:func:`calib.effects.laws.law_to_dict`)."""
        return law_to_dict(self.terms, self.by_term())

    @classmethod
    def from_dict(cls, d, where: str = "law") -> "LawTerms":
        """The terms of :meth:`to_dict`'s object.

        Raises:
            ValueError: naming ``where``: not a law's terms, or a term's granularity neither
                ``shared`` nor ``per_chain``.
        """
        try:
            terms, _ = law_from_dict(d)
            grans = tuple(e["granularity"] for e in d["terms"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{where}: not a law's terms ({exc!r})") from None
        for k, g in enumerate(grans):
            if g not in GRANULARITIES:
                raise ValueError(f"{where}.terms[{k}].granularity: {g!r} is neither {SHARED!r} nor {PER_CHAIN!r}")
        return cls(terms, grans)


@dataclass(frozen=True)
class EffectRecord:
    """A found effect as a calibration keeps it (see the module docstring).

    Attributes:
        name: the effect's name (a registered effect's, or a law's).
        granularity: ``shared`` or ``per_chain`` (the effect's form).
        coefficients: its coefficients (:class:`CoefficientRecord`), in the effect's own order.
        searched: its searched parameter: a number (a screw's pitch in the joint unit, a warm-up's
            time constant in s), a :class:`JointStep` (a lost count's joint, 0-based, and step
            time, s), or None.
        law: a proposed or kept law's terms, None for a registered effect.
        reference_payload_kg: a compliance fitted at several payloads: the payload its weight
            terms stand for (kg, the mean of its rows'); None otherwise.
    """

    name: str
    granularity: str
    coefficients: tuple
    searched: float | JointStep | None = None
    law: LawTerms | None = None
    reference_payload_kg: float | None = None

    @property
    def values(self) -> np.ndarray:
        """(p,) the coefficients' values, each in its unit."""
        return np.array([c.value for c in self.coefficients], dtype=float)

    @property
    def stds(self) -> np.ndarray:
        """(p,) the coefficients' standard uncertainties, each in its unit."""
        return np.array([c.std for c in self.coefficients], dtype=float)

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        """The coefficients' names, in the effect's own order."""
        return tuple(c.name for c in self.coefficients)

    @classmethod
    def from_fitted(cls, fe: FittedEffect, robot: Robot, reference_payload_kg: float | None = None) -> "EffectRecord":
        """The record of a fitted effect on ``robot``. ``reference_payload_kg``: the mean payload
        (kg) of the rows a payload-aware compliance was fitted on (needed for one, unless it
        already holds its reference).

        Raises:
            ValueError: a compliance fitted at several payloads without its reference payload.
        """
        coefs = tuple(CoefficientRecord(c.name, float(v), float(s), c.unit)
                      for c, v, s in zip(fe.effect.coefficients(robot), fe.coefficients, fe.std))
        extra = fe.extra
        searched = None if extra is None else JointStep(int(extra.chain), float(extra.time_s)) \
            if isinstance(extra, JointStep) else float(extra)
        base = fe.effect.base if isinstance(fe.effect, PerChainForm) else fe.effect
        reference = None
        if isinstance(base, LoadedCompliance):
            reference = base.reference_payload_kg if base.reference_payload_kg is not None else reference_payload_kg
            if reference is None:
                raise ValueError("a compliance fitted at several payloads needs the mean payload of its rows")
            reference = float(reference)
        law = LawTerms.of(base) if isinstance(base, Law) else None
        return cls(fe.name, fe.effect.granularity, coefs, searched, law, reference)

    def fitted(self, robot: Robot, channels: dict | None = None, where: str = "effect") -> FittedEffect:
        """The effect this record holds, on ``robot``, with its fitted values (its coefficients
        checked against the effect's own names). ``channels``: ``{name: (N,)}`` recorded channels a
        law uses, one value per row of the data it will act on.

        Raises:
            ValueError: naming ``where`` and the key: an effect that does not apply to ``robot``,
                a form it does not have, coefficients other than the effect's, a joint the robot
                does not have.
        """
        from .registry import EFFECTS

        if self.law is not None:
            eff = self.law.effect(channels, self.name)
        else:
            eff = EFFECTS[self.name]
            if self.reference_payload_kg is not None:  # compliance at several payloads: its payload terms
                eff = LoadedCompliance(self.reference_payload_kg)
            if not eff.applies_to(robot):
                raise ValueError(f"{where}.name: {self.name!r} does not apply to the {robot.name}")
            if self.granularity == PER_CHAIN and eff.granularity != PER_CHAIN:
                eff = per_chain_form(eff)
                if eff is None:
                    raise ValueError(f"{where}.granularity: {self.name!r} has no per-chain form")
        if eff.granularity != self.granularity:
            raise ValueError(f"{where}.granularity: {self.granularity!r}, but the effect rebuilt is "
                             f"{eff.granularity!r}")
        names = [c.name for c in eff.coefficients(robot)]
        if list(self.coefficient_names) != names:
            raise ValueError(f"{where}.coefficients: expected the coefficients {names}, got "
                             f"{list(self.coefficient_names)}")
        if isinstance(self.searched, JointStep) and not 0 <= self.searched.chain < robot.n_chains:
            raise ValueError(f"{where}.searched.joint: {self.searched.chain + 1} is not a joint of the {robot.name} "
                             f"(1..{robot.n_chains})")
        return FittedEffect(eff, self.values, self.stds, self.searched)

    def to_dict(self) -> dict:
        """The record's JSON object (see the module docstring): for the file edge only."""
        s = self.searched
        d = {"name": self.name, "granularity": self.granularity,
             "coefficients": {c.name: c.value for c in self.coefficients},
             "std": {c.name: c.std for c in self.coefficients},
             "units": {c.name: c.unit for c in self.coefficients},
             "searched": None if s is None else {"joint": int(s.chain) + 1, "step_time_s": float(s.time_s)}
             if isinstance(s, JointStep) else float(s)}
        if self.reference_payload_kg is not None:
            d["reference_payload_kg"] = self.reference_payload_kg
        if self.law is not None:
            d["law"] = self.law.to_dict()
        return d

    @classmethod
    def from_dict(cls, d, where: str = "effect") -> "EffectRecord":
        """The record of :meth:`to_dict`'s object (a calibration file's ``effects[k]``). What it
        can check without a robot is checked here; :meth:`fitted` checks the rest.

        Raises:
            ValueError: naming ``where`` and the key: not an object, a key missing, an unknown
                effect or granularity, coefficients, std and units not naming the same
                coefficients, a value that is not a number (a coefficient not finite), a searched
                parameter that is neither a finite number nor a joint and step time, a reference
                payload on another effect than a compliance, a law's terms unreadable.
        """
        from .registry import EFFECTS

        if not isinstance(d, dict):
            raise ValueError(f"{where}: expected an object with keys {', '.join(RECORD_KEYS)}")
        for key in RECORD_KEYS:
            if key not in d:
                raise ValueError(f"{where}: key {key!r} missing")
        name, gran = d["name"], d["granularity"]
        if gran not in GRANULARITIES:
            raise ValueError(f"{where}.granularity: {gran!r} is neither {SHARED!r} nor {PER_CHAIN!r}")
        law = None
        if "law" in d:
            law = LawTerms.from_dict(d["law"], f"{where}.law")
        elif name not in EFFECTS or name in ("none", LAW_NAME):
            raise ValueError(f"{where}.name: {name!r} is no registered effect (expected one of "
                             f"{', '.join(n for n in EFFECTS if n != 'none')}, or a law with key 'law')")
        reference = d.get("reference_payload_kg")
        if "reference_payload_kg" in d and (law is not None or name != EFFECTS["compliance"].name
                                            or not is_number(reference)):
            raise ValueError(f"{where}.reference_payload_kg: {reference!r} is not a compliance's payload (a "
                             "finite number of kg)")
        block = d["coefficients"]
        if not isinstance(block, dict):
            raise ValueError(f"{where}.coefficients: expected an object of coefficients by name, got {block!r}")
        names = list(block)
        for key in ("std", "units"):
            if not isinstance(d[key], dict) or list(d[key]) != names:
                got = list(d[key]) if isinstance(d[key], dict) else d[key]
                raise ValueError(f"{where}.{key}: expected the coefficients {names}, got {got}")
        for c in names:
            if not is_number(block[c]):
                raise ValueError(f"{where}.coefficients.{c}: {block[c]!r} is not a finite number")
            if not is_number(d["std"][c], finite=False):
                raise ValueError(f"{where}.std.{c}: {d['std'][c]!r} is not a number")
            if not isinstance(d["units"][c], str):
                raise ValueError(f"{where}.units.{c}: {d['units'][c]!r} is not a unit's name")
        coefs = tuple(CoefficientRecord(str(c), float(block[c]), float(d["std"][c]), d["units"][c]) for c in names)
        return cls(str(name), gran, coefs, searched_from_dict(d["searched"], where), law,
                   None if reference is None else float(reference))


def searched_from_dict(value, where: str) -> float | JointStep | None:
    """A record's searched parameter from its JSON value (``where.searched`` named when refused)."""
    if value is None:
        return None
    if isinstance(value, dict):
        joint, t = value.get("joint"), value.get("step_time_s")
        if isinstance(joint, bool) or not isinstance(joint, int) or not is_number(t):
            raise ValueError(f"{where}.searched: expected a number or {{'joint', 'step_time_s'}} (an integer "
                             f"joint from 1 and a finite time in s), got {value!r}")
        if joint < 1:
            raise ValueError(f"{where}.searched.joint: {joint} is not a joint (they count from 1)")
        return JointStep(joint - 1, float(t))
    if not is_number(value):
        raise ValueError(f"{where}.searched: {value!r} is not a finite number")
    return float(value)
