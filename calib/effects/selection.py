"""The choice of the effects: stepwise selection on the linearised joint fit, nested forms
decided again on the exact fits, insignificant effects dropped (a room of
:mod:`calib.effects.discovery`, whose docstring says the rules).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .base import Effect, EffectData, orthonormal_columns
from .granularity import PerChainForm, form_key, per_chain_form, shared_form
from .joint_fit import EffectFit, as_models, fit_effects, model_poses
from .registry import effect_family, effects_for, nested_in
from .search import LinearisedFit

__all__ = ["MIN_DELTA_BIC", "MIN_NESTED_DELTA_BIC", "MIN_GRANULARITY_DELTA_BIC", "ALIAS_CORRELATION",
           "ALIAS_DELTA_BIC", "SIGNIFICANCE_ALPHA", "regressor_correlation", "candidate_forms", "choose_effects"]

#: Evidence an effect needs to enter the model: BIC lower by at least this ("very strong" on
#: the Kass-Raftery scale; a chance reduction of a one-parameter effect's chi-square by 16 has
#: probability 5e-5).
MIN_DELTA_BIC = 10.0
#: Evidence a general effect needs over one it contains (:attr:`Effect.generalises`) to be named
#: in its place: BIC lower by at least this, on top of the BIC's own charge for the extra
#: parameters (as much as an effect needs to enter at all: :data:`MIN_DELTA_BIC`).
MIN_NESTED_DELTA_BIC = MIN_DELTA_BIC
#: Evidence a per-chain form needs over its own shared form (:mod:`calib.effects.granularity`)
#: on top of the BIC's charge of ``ln(n)`` for each of its ``C - 1`` extra coefficients: none more.
#: That charge alone keeps a shared machine shared (a chance gain of ``(C - 1) ln n``, 31 for
#: six chains and 500 residuals, has probability 1e-5 under chi-square(5)), while a per-joint
#: spread the shared form cannot fit leaves structure the remainder tests would call unexplained.
MIN_GRANULARITY_DELTA_BIC = 0.0
#: Largest canonical correlation of two effects' whitened regressors (geometry projected out)
#: above which this recording cannot tell them apart.
ALIAS_CORRELATION = 0.95
#: Two effects whose evidence at the same step differs by less than this BIC ("positive" on the
#: Kass-Raftery scale), and of which only one enters, are reported as aliases.
ALIAS_DELTA_BIC = 6.0
#: A named effect's coefficients must differ from zero at this significance (Wald test).
SIGNIFICANCE_ALPHA = 1e-3


def _canonical_correlation(A: np.ndarray, B: np.ndarray) -> float:
    Qa, Qb = orthonormal_columns(A), orthonormal_columns(B)
    if Qa.shape[1] == 0 or Qb.shape[1] == 0:
        return 0.0
    return float(np.clip(np.linalg.svd(Qa.T @ Qb, compute_uv=False)[0], 0.0, 1.0))


def regressor_correlation(data: EffectData, candidates=None, extras=None) -> dict:
    """``{(a, b): c}``: the largest canonical correlation between the whitened regressors of
    each pair of effects, with the geometry projected out (1: the data cannot tell them apart).

    Args:
        data: the measurements (the linearisation point is the geometry-only fit).
        candidates: effects (default every one that applies to the robot).
        extras: ``{name: value}`` for searched parameters (default searched on ``data``).
    """
    models = as_models(effects_for(data.robot) if candidates is None else candidates)
    lin = LinearisedFit(data, fit_effects(data, ()))
    extras = dict(extras or {})
    cols = {m.name: lin.columns(m, extras.get(m.name) if m.searched is None or m.name in extras
                                else lin.search(m, [])) for m in models}
    names = list(cols)
    return {(a, b): _canonical_correlation(cols[a], cols[b]) for i, a in enumerate(names) for b in names[i + 1:]}


def candidate_forms(candidates, per_chain: bool = True) -> dict:
    """``{key: effect}``: every candidate effect (its shared form, under its name) and, with
    ``per_chain``, the per-chain form of each that has one (under ``name[per_chain]``,
    :func:`calib.effects.granularity.form_key`); ``none`` dropped."""
    out = {}
    for m in as_models(candidates):
        out[form_key(m)] = m
        pc = per_chain_form(m) if per_chain else None
        if pc is not None:
            out[form_key(pc)] = pc
    return out


def _relations(models: dict) -> tuple[dict, dict]:
    """``(family, nested)`` over the candidate forms ``models`` (key -> effect): ``family[k]``
    the keys of every form of every effect nested with ``k``'s (one of them in a model at
    most); ``nested[k]`` ``{key: margin}`` of the keys ``k`` generalises: the other forms of its
    own effect (margin :data:`MIN_GRANULARITY_DELTA_BIC`) or of an effect it generalises
    (:attr:`Effect.generalises`; margin :data:`MIN_NESTED_DELTA_BIC`) whose granularity is no
    finer (a per-chain form contains its shared form; a shared warm-up a shared drift, not a
    per-chain one)."""
    family, nested = {}, {}
    for k, m in models.items():
        fam = set(effect_family(shared_form(m)))
        inner = set(nested_in(shared_form(m))) | {m.name}
        fine = isinstance(m, PerChainForm)
        family[k] = {k2 for k2, m2 in models.items() if m2.name in fam}
        nested[k] = {k2: MIN_GRANULARITY_DELTA_BIC if models[k2].name == m.name else MIN_NESTED_DELTA_BIC
                     for k2 in family[k] if k2 != k and models[k2].name in inner
                     and (fine or not isinstance(models[k2], PerChainForm))}
    return family, nested


def _simplest(trials: dict, names, nested: dict) -> str:
    """Among ``names`` (one family of nested effects, each with its ``delta_bic`` in ``trials``;
    ``nested[name]``: ``{effect it generalises: margin}``), the one selection names: the best by
    BIC, then, as long as an effect it generalises is within the margin of it
    (:data:`MIN_NESTED_DELTA_BIC`, :data:`MIN_GRANULARITY_DELTA_BIC`), that simpler one (the
    extra parameters must pay)."""
    names = [n for n in names if n in trials]
    best = max(names, key=lambda n: trials[n]["delta_bic"])
    while True:
        simpler = [n for n in nested[best] if n in names
                   and trials[best]["delta_bic"] - trials[n]["delta_bic"] < nested[best][n]]
        if not simpler:
            return best
        best = max(simpler, key=lambda n: trials[n]["delta_bic"])


def _trial(lin: LinearisedFit, eff: Effect, blocks: list, chi2_ref: float, p_ref: int, log_n: float) -> dict:
    """``eff`` fitted with ``blocks``: its columns, chi-square and BIC evidence against
    ``blocks`` alone (chi-square ``chi2_ref``, ``p_ref`` parameters)."""
    extra = lin.search(eff, blocks) if eff.searched is not None else None
    X = lin.columns(eff, extra)
    chi2_new = lin.chi2(blocks + [X])
    k = X.shape[1] + (eff.searched is not None)
    s2 = max(1.0, chi2_new / max(lin.dof0 - p_ref - k, 1))
    return {"extra": extra, "X": X, "k": k, "chi2": chi2_new, "scale": s2,
            "delta_bic": (chi2_ref - chi2_new) / s2 - k * log_n}


@dataclass
class _Model:
    """The selection's current model: ``chosen`` the effects in it (key -> ``{"extra", "X",
    "k"}``), ``excluded`` those a later effect made redundant (never tried again), its
    chi-square, parameters and cross-validated whitened RMS."""

    chosen: dict
    excluded: set
    chi2: float
    p: int
    cv: float

    def blocks(self) -> list:
        return [c["X"] for c in self.chosen.values()]


def _tried(lin: LinearisedFit, models: dict, cur: _Model, family: dict, unseparated: dict, log_n: float) -> dict:
    """Every candidate that may join ``cur`` fitted with it (:func:`_trial`): not in it, not
    excluded, no member of its family in it, and separable from the geometry's held combinations
    (those that are not go to ``unseparated``, updated here)."""
    blocks = cur.blocks()
    trials = {}
    for name, eff in models.items():
        if name in cur.chosen or name in cur.excluded or (family[name] - {name}) & set(cur.chosen):
            continue
        if eff.searched is None and unseparated.get(name):
            continue
        t = _trial(lin, eff, blocks, cur.chi2, cur.p, log_n)
        if eff.searched is not None or name not in unseparated:
            unseparated[name] = lin.unseparated(eff, t["extra"])
        if unseparated[name]:
            unseparated[name] = {"extra": t["extra"], "combinations": unseparated[name]}
            continue
        trials[name] = t
    return trials


def _entering(lin: LinearisedFit, trials: dict, order: list, cur: _Model, min_delta_bic: float, folds: int,
              seed: int) -> tuple:
    """``(name, its cross-validated RMS)`` of the first of ``order`` that lowers the BIC by
    ``min_delta_bic`` and the cross-validated residual, or ``(None, None)``."""
    blocks = cur.blocks()
    for name in order:
        t = trials[name]
        if t["delta_bic"] < min_delta_bic:
            break
        cv_try = lin.cv_rms(blocks + [t["X"]], folds, seed)
        if cv_try < cur.cv:
            return name, cv_try
    return None, None


def _rivals(added: str, trials: dict, order: list, min_delta_bic: float) -> list:
    """The candidates of the step whose evidence is within :data:`ALIAS_DELTA_BIC` of the one
    ``added``: ``(added, rival, gap, canonical correlation, False)``."""
    t = trials[added]
    return [(added, other, t["delta_bic"] - trials[other]["delta_bic"],
             _canonical_correlation(t["X"], trials[other]["X"]), False)
            for other in order if other != added and trials[other]["delta_bic"] >= min_delta_bic
            and t["delta_bic"] - trials[other]["delta_bic"] < ALIAS_DELTA_BIC]


def _review_nested(lin: LinearisedFit, models: dict, cur: _Model, added: str, family: dict, nested: dict,
                   unseparated: dict, step: dict, log_n: float, folds: int, seed: int) -> None:
    """Nested review: with the others fitted, each family's simplest member that the evidence
    allows takes the place of the one in ``cur`` (said in ``step["replaced"]``)."""
    for name in [n for n in cur.chosen if n != added and len(family[n]) > 1]:
        rest = {n: c for n, c in cur.chosen.items() if n != name}
        blocks_rest = [c["X"] for c in rest.values()]
        chi2_rest, p_rest = lin.chi2(blocks_rest), cur.p - cur.chosen[name]["k"]
        review = {f: _trial(lin, models[f], blocks_rest, chi2_rest, p_rest, log_n)
                  for f in family[name] if f not in cur.excluded and not unseparated.get(f)}
        better = _simplest(review, review, nested)
        if better != name:
            r = review[better]
            cur.chosen = {(better if n == name else n): ({"extra": r["extra"], "X": r["X"], "k": r["k"]} if n == name
                                                         else c) for n, c in cur.chosen.items()}
            cur.chi2, cur.p = r["chi2"], p_rest + r["k"]
            cur.cv = lin.cv_rms(cur.blocks(), folds, seed)
            step.setdefault("replaced", []).append((name, better))


def _drop_redundant(lin: LinearisedFit, cur: _Model, added: str, step: dict, min_delta_bic: float, log_n: float,
                    folds: int, seed: int) -> None:
    """Backward: an earlier effect the later ones make redundant leaves ``cur`` (and is
    excluded; said in ``step["dropped"]``)."""
    for name in [n for n in cur.chosen if n != added]:
        rest = [c["X"] for n, c in cur.chosen.items() if n != name]
        chi2_wo = lin.chi2(rest)
        s2 = max(1.0, cur.chi2 / max(lin.dof0 - cur.p, 1))
        if (chi2_wo - cur.chi2) / s2 - cur.chosen[name]["k"] * log_n < min_delta_bic:
            cur.p -= cur.chosen[name]["k"]
            del cur.chosen[name]
            cur.excluded.add(name)
            cur.chi2 = chi2_wo
            cur.cv = lin.cv_rms(rest, folds, seed)
            step["dropped"].append(name)


def _select(lin: LinearisedFit, models: dict, max_effects: int, min_delta_bic: float, folds: int, seed: int) -> dict:
    """Stepwise selection (forward, with a backward check after each addition).

    Nested effects (:attr:`Effect.generalises`) are one family: at most one of a family is in
    the model, the simplest unless a more general one gains :data:`MIN_NESTED_DELTA_BIC` over it
    (:func:`_simplest`), and after each step the family's member in the model is reviewed with
    the other effects fitted (a warm-up's curvature can show only once another effect is in).
    A form the rows cannot separate from the geometry's held combinations (:meth:`LinearisedFit.unseparated`)
    is no candidate; it is returned under ``"unseparated"``."""
    log_n = np.log(lin.n)
    unseparated: dict = {}
    family, nested = _relations(models)
    cur = _Model({}, set(), lin.chi2([]), 0, lin.cv_rms([], folds, seed))
    steps, rivals, first = [], [], None
    while len(cur.chosen) < max_effects:
        trials = _tried(lin, models, cur, family, unseparated, log_n)
        if first is None:
            first = {n: {"chi2": t["chi2"], "delta_bic_vs_none": t["delta_bic"], "n_params": t["k"],
                         "extra": t["extra"],
                         "cv_whitened_rms": lin.cv_rms([t["X"]], folds, seed)} for n, t in trials.items()}
        # One member per family competes: the simplest that the evidence allows.
        winners = {n: _simplest(trials, family[n], nested) for n in trials}
        order = sorted((n for n in trials if winners[n] == n), key=lambda c: -trials[c]["delta_bic"])
        added, cv_new = _entering(lin, trials, order, cur, min_delta_bic, folds, seed)
        step = {"trials": {n: {"delta_bic": t["delta_bic"], "chi2": t["chi2"]} for n, t in trials.items()},
                "added": added, "dropped": []}
        steps.append(step)
        if added is None:
            break
        rivals += _rivals(added, trials, order, min_delta_bic)
        t = trials[added]
        cur.chosen[added] = {"extra": t["extra"], "X": t["X"], "k": t["k"]}
        cur.chi2, cur.p, cur.cv = t["chi2"], cur.p + t["k"], cv_new
        _review_nested(lin, models, cur, added, family, nested, unseparated, step, log_n, folds, seed)
        _drop_redundant(lin, cur, added, step, min_delta_bic, log_n, folds, seed)
    return {"chosen": {n: c["extra"] for n, c in cur.chosen.items()}, "steps": steps, "rivals": rivals,
            "single": first or {}, "cv_geometry": lin.cv_rms([], folds, seed), "cv_chosen": cur.cv,
            "unseparated": {n: u for n, u in unseparated.items() if u}}


def _nested_check(sub: EffectData, lin: LinearisedFit, geo: EffectFit, models: dict, sel: dict) -> None:
    """The chosen member of each family of nested effects decided again on the exact joint fits
    (the other chosen effects fitted too): the linearised evidence of two nested effects can
    differ by a few units of BIC from the exact one, as much as the margin the general one needs.
    Updates ``sel["chosen"]`` and appends nested aliases to ``sel["rivals"]``."""
    chosen = dict(sel["chosen"])
    log_n = np.log(lin.n)
    family, nested = _relations(models)
    for name in list(chosen):
        fam = [f for f in models if f in family[name] and f not in sel["unseparated"]]
        if len(fam) < 2:
            continue
        others = {n: e for n, e in chosen.items() if n != name}
        fits = {f: fit_effects(sub, [models[n] for n in others] + [models[f]], start=geo.theta,
                               extras={models[n].name: e for n, e in others.items()}) for f in fam}
        s2 = max(1.0, min(f.chi2 / max(f.dof, 1) for f in fits.values()))
        trials = {f: {"delta_bic": -(fit.chi2 / s2 + fit.n_params * log_n)} for f, fit in fits.items()}
        better = _simplest(trials, fam, nested)
        extra = fits[better].extras[-1]
        for g in fam:
            gap = trials[g]["delta_bic"] - trials[better]["delta_bic"]
            if better in nested[g] and 0 < gap < nested[g][better]:
                corr = _canonical_correlation(lin.columns(models[better], extra),
                                              lin.columns(models[g], fits[g].extras[-1]))
                sel["rivals"].append((better, g, float(gap), corr, True))
        if better != name:
            chosen = {(better if n == name else n): (extra if n == name else e) for n, e in chosen.items()}
            sel.setdefault("nested_replaced", []).append((name, better))
    sel["chosen"] = chosen


def choose_effects(sub: EffectData, models: dict, max_effects: int, min_delta_bic: float, folds: int, seed: int,
            search_rows_max: int | None = None, search_subsample_rows: int | None = None):
    geo = fit_effects(sub, ())
    poses = model_poses(sub.robot, geo.theta, sub.joints, sub.measured, geo.basis)
    if poses is not sub.measured:  # combinations held: the effects' regressors at the model's poses
        sub = replace(sub, model_poses=poses)
    lin = LinearisedFit(sub, geo, search_rows_max=search_rows_max, search_subsample_rows=search_subsample_rows, seed=seed)
    sel = _select(lin, models, max_effects, min_delta_bic, folds, seed)
    _nested_check(sub, lin, geo, models, sel)
    names = list(sel["chosen"])
    fit = geo
    while names:
        fit = fit_effects(sub, [models[n] for n in names], start=geo.theta,
                          extras={models[n].name: sel["chosen"][n] for n in names})
        p_value = {n: fit.significance(models[n].name)["p_value"] for n in names}
        weak = [n for n in names if p_value[n] > SIGNIFICANCE_ALPHA]
        if not weak:
            break
        names.remove(max(weak, key=lambda n: p_value[n]))
        sel.setdefault("insignificant", []).append(weak)
        fit = geo
    sel["search"] = lin.search_form()
    return sub, geo, fit, sel
