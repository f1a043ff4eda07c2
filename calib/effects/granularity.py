"""Granularity: one coefficient shared by every chain, or one per chain, for any effect.

Real joints differ: each has its own friction, backlash, screw phase, stiffness and thermal
growth. An effect declares which of its coefficients may differ from chain to chain
(:attr:`Effect.per_chain_capable`, coefficient names); its *shared form* is the effect as
registered (one value of each coefficient for every chain), its *per-chain form*
(:func:`per_chain_form`) the same physics with each capable coefficient replaced by one per
chain: the shared form's joint regressor masked chain by chain,

    Xq_pc[n, i, (j, k)] = Xq[n, i, j] [i == k]        (chain k's copy of coefficient j)

so that the shared form is the per-chain form with equal coefficients (nested: the per-chain
form generalises the shared one). Nothing here depends on which effect it is: discovery chooses
between the two forms as between any nested pair (BIC with the nested margin, cross-validated
residual, exact refits: :mod:`calib.effects.discovery`), a later family of terms declaring its
capable coefficients gets the same choice for free.

The per-chain form is an :class:`Effect` with the registered effect's ``name`` (a model holds one
form of an effect at most), ``granularity == "per_chain"``, coefficients named by chain
(``dead_band[leg 3]``), the machine settings of its chains merged field by field
(:func:`merge_chain_settings`), and a scenario drawing a per-joint spread around the shared draw
(each chain 0.3 to 1.0 times it, :data:`SPREAD_RANGE`; random signs where the effect says they
are physical, :attr:`Effect.per_chain_signed`).
"""

from __future__ import annotations

import numpy as np

from .base import Coefficient, Effect, EffectScenario

__all__ = ["SHARED", "PER_CHAIN", "GRANULARITIES", "PerChainForm", "per_chain_form", "shared_form", "form_key",
           "merge_chain_settings", "chain_coefficient_name"]

#: The two granularities.
SHARED, PER_CHAIN = "shared", "per_chain"
GRANULARITIES = (SHARED, PER_CHAIN)

_FORMS: dict = {}


def chain_coefficient_name(name: str, chain_word: str, chain: int) -> str:
    """``dead_band[leg 3]``: coefficient ``name`` of (0-based) ``chain``."""
    return f"{name}[{chain_word} {chain + 1}]"


def form_key(eff: Effect) -> str:
    """The key of an effect's form in a discovery's candidates: its name (shared form, or an
    effect without the choice), ``name[per_chain]`` for a per-chain form."""
    return f"{eff.name}[{PER_CHAIN}]" if isinstance(eff, PerChainForm) else eff.name


def per_chain_form(eff: Effect) -> "PerChainForm | None":
    """The per-chain form of ``eff`` (one object per effect, so that caches keyed on it hold),
    or None when ``eff`` has no capable coefficient or already is a per-chain form."""
    if isinstance(eff, PerChainForm) or not eff.per_chain_capable:
        return None
    key = id(eff)
    if key not in _FORMS:
        _FORMS[key] = (eff, PerChainForm(eff))
    return _FORMS[key][1]


def shared_form(eff: Effect) -> Effect:
    """The registered effect a per-chain form is made of; any other effect itself."""
    return eff.base if isinstance(eff, PerChainForm) else eff


def merge_chain_settings(per_chain: list[dict], n_chains: int) -> dict:
    """One machine's settings from each chain's own (``per_chain[i]``: the settings the shared
    form gives with chain i's coefficients). A field equal in every chain keeps its value; a
    number that differs becomes a tuple, chain i's value in place i; a (C,) tuple takes chain
    i's element i."""
    out = {"options": {}, "effects": {}}
    for section in out:
        fields = dict.fromkeys(f for s in per_chain for f in s.get(section, {}))
        for f in fields:
            vals = [s.get(section, {}).get(f) for s in per_chain]
            if all(_same(v, vals[0]) for v in vals):
                out[section][f] = vals[0]
            elif all(isinstance(v, (tuple, list)) and len(v) == n_chains for v in vals):
                out[section][f] = tuple(float(v[i]) for i, v in enumerate(vals))
            else:
                out[section][f] = tuple(float(v) for v in vals)
    return out


def _same(a, b) -> bool:
    if isinstance(a, (tuple, list)) or isinstance(b, (tuple, list)):
        return np.shape(a) == np.shape(b) and bool(np.all(np.asarray(a) == np.asarray(b)))
    return a == b


class PerChainForm(Effect):
    """The per-chain form of a registered effect ``base`` (see the module docstring)."""

    granularity = PER_CHAIN

    def __init__(self, base: Effect):
        self.base = base
        self.name = base.name
        self.physics = f"{base.physics} (each {PER_CHAIN.replace('_', ' ')} its own)"
        self.searched = base.searched
        self.history_dependent = base.history_dependent
        self.follows = base.follows
        self.refine_search = base.refine_search
        self.generalises = (base.name,)
        self.per_chain_signed = base.per_chain_signed
        self.not_compensable = base.not_compensable

    def compensation_inputs(self):
        return self.base.compensation_inputs()

    def applies_to(self, robot):
        return self.base.applies_to(robot)

    def capable(self, robot) -> np.ndarray:
        """(p,) bool: which of the shared form's coefficients are one per chain here."""
        return np.array([c.name in self.base.per_chain_capable for c in self.base.coefficients(robot)])

    def coefficients(self, robot):
        out = []
        for c, cap in zip(self.base.coefficients(robot), self.capable(robot)):
            out += [Coefficient(chain_coefficient_name(c.name, robot.chain_word, i), c.unit)
                    for i in range(robot.n_chains)] if cap else [c]
        return tuple(out)

    def joint_regressors(self, robot, theta, data, extra=None):
        X = self.base.joint_regressors(robot, theta, data, extra)
        C = robot.n_chains
        blocks = []
        for j, cap in enumerate(self.capable(robot)):
            if cap:
                B = np.zeros((X.shape[0], C, C))
                B[:, np.arange(C), np.arange(C)] = X[:, :, j]
                blocks.append(B)
            else:
                blocks.append(X[:, :, j:j + 1])
        return np.concatenate(blocks, axis=2)

    def chain_coefficients(self, coefficients, robot) -> np.ndarray:
        """(C, p) the shared form's coefficients chain by chain (chain i's own values of the
        capable ones, the shared value of the others)."""
        cap = self.capable(robot)
        C = robot.n_chains
        out = np.empty((C, cap.size))
        k = 0
        for j, c in enumerate(cap):
            width = C if c else 1
            out[:, j] = coefficients[k:k + width]
            k += width
        return out

    def flat_coefficients(self, per_chain: np.ndarray, robot) -> np.ndarray:
        """The inverse of :meth:`chain_coefficients`: (C, p) -> this form's coefficient vector."""
        return np.concatenate([per_chain[:, j] if c else per_chain[:1, j] for j, c in enumerate(self.capable(robot))])

    def search_grid(self, data):
        return self.base.search_grid(data)

    def searched_value(self, u):
        return self.base.searched_value(u)

    def searched_values(self, extra):
        return self.base.searched_values(extra)

    def machine_settings(self, coefficients, robot, context, extra=None):
        rows = self.chain_coefficients(np.asarray(coefficients, dtype=float), robot)
        return merge_chain_settings([self.base.machine_settings(r, robot, context, extra) for r in rows],
                                    robot.n_chains)

    def physical_parameter(self, robot):
        return None  # a vector of machine values: simulated as fitted, not re-fitted one number at a time

    def scenario(self, robot, theta, data, magnitude_mm, rng, context):
        """The shared form's draw, then each chain's capable coefficients spread around it
        (:meth:`Effect.per_chain_draw`), rescaled so that the largest closure contribution is
        the shared draw's (whatever that one was sized on)."""
        sc = self.base.scenario(robot, theta, data, magnitude_mm, rng, context)
        shared = np.asarray(sc.coefficients, dtype=float)
        rows = np.tile(shared, (robot.n_chains, 1))
        cap = self.capable(robot)
        rows[:, cap] = self.base.per_chain_draw(robot, shared, cap, rng)
        coef = self.flat_coefficients(rows, robot)
        raw_shared = np.abs(self.base.regressors(robot, theta, data, sc.extra) @ shared).max()
        raw = np.abs(self.regressors(robot, theta, data, sc.extra) @ coef).max()
        return EffectScenario(coef * (raw_shared / raw), sc.extra, sc.context)

    def __repr__(self) -> str:
        return f"<effect {self.name!r}, {PER_CHAIN}>"
