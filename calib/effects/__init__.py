"""Physics the geometric model leaves out: a registry of effects, one module each, and their
discovery (joint fits with the geometry, model choice, outliers, localisation) written once
over :class:`calib.robot.Robot`.

Adding an effect: write its module (a subclass of :class:`Effect` in an instance named
``EFFECT``, see :mod:`calib.effects.base`) and append the module's name to
:data:`EFFECT_MODULES` (:mod:`calib.effects.registry`, the registry's own module). Coefficients that may differ from chain to chain are named in
:attr:`Effect.per_chain_capable`: the effect then also has a per-chain form
(:mod:`calib.effects.granularity`), which discovery weighs against the shared one.
"""

from __future__ import annotations

from ..lazy import lazy_exports
from .base import (FOLLOWED_QUANTITIES, Coefficient, Effect, EffectData, EffectScenario, MachineContext, PhysicalParameter,
                   SearchedParameter)
from .registry import EFFECT_MODULES, EFFECTS, effect, effect_family, effects_for, nested_in

__all__ = ["EFFECT_MODULES", "EFFECTS", "effect", "effects_for", "effect_family", "nested_in", "Effect", "EffectData", "Coefficient",
           "SearchedParameter", "PhysicalParameter", "MachineContext", "EffectScenario", "FOLLOWED_QUANTITIES",
           "MIN_DELTA_BIC", "MAX_EFFECTS", "EffectFit", "Discovery", "fit_effect", "fit_effects", "discover_effects",
           "discover_effect", "remainder_tests", "outlier_scan", "regressor_correlation", "locate_mismatch",
           "closure_noise_std", "candidate_forms", "PerChainForm", "per_chain_form", "SHARED", "PER_CHAIN",
           "propose_law", "ProposedLaw", "Law", "law_effect", "search_law", "LAW_WORDS", "law_to_dict", "law_from_dict"]

# Discovery's names are imported from their rooms when first read: they load scipy.stats (half a
# second), which a command that only reads or writes found effects (the calibration file) does not need.
_discovery_names, __getattr__, __dir__ = lazy_exports(__name__, {
    "discovery": ("MAX_EFFECTS", "Discovery", "discover_effect", "discover_effects", "propose_law"),
    "joint_fit": ("EffectFit", "fit_effect", "fit_effects"),
    "whitening": ("closure_noise_std",),
    "selection": ("MIN_DELTA_BIC", "candidate_forms", "regressor_correlation"),
    "remainder": ("remainder_tests",),
    "located": ("locate_mismatch",),
    "gross_rows": ("outlier_scan",)})
from .laws import LAW_WORDS, Law, ProposedLaw, law_effect, law_from_dict, law_to_dict, search_law  # noqa: E402
from .granularity import PER_CHAIN, SHARED, PerChainForm, per_chain_form  # noqa: E402
