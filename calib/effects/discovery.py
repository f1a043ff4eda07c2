"""Discovery of left-out physics, written once over :class:`calib.robot.Robot`.

The joint fit of the geometry and the effects in joint space, whitened by the declared noise
(:mod:`calib.effects.joint_fit`, :mod:`calib.effects.whitening`), linearised for the search of
the searched parameters and the selection (:mod:`calib.effects.search`,
:mod:`calib.effects.selection`), the selection's evidence and aliases (:mod:`calib.effects.evidence`),
the remainder's tests (:mod:`calib.effects.remainder`), where the geometry-only residuals
concentrate (:mod:`calib.effects.located`) and the outlier scan (:mod:`calib.effects.gross_rows`)
are rooms of their own, each returning typed results; this module is the discovery itself, and
re-exports their public names.

:func:`discover_effects` then

1. chooses a subset of the candidates, up to :data:`MAX_EFFECTS`, by stepwise selection on the
   joint fit linearised at the geometry-only solution (every subset fit is then one small
   least-squares problem): each effect must lower the BIC by :data:`MIN_DELTA_BIC` (the
   chi-square divided by the remainder's variance when that exceeds the declared noise, so that
   an underestimated noise does not turn chance into evidence) and lower the cross-validated
   residual (closed form: deleted residuals of each fold through the hat matrix); an effect the
   later ones make redundant is dropped; effects the data cannot tell apart are reported as
   aliases. Nested effects (one generalises the other: :attr:`Effect.generalises`) are never
   named together; the simpler is named unless the general one lowers the BIC by
   :data:`MIN_NESTED_DELTA_BIC` more (its extra parameters must pay), decided during the
   selection and again on the exact joint fits; a general one ahead by less is reported as an
   alias;
2. fits the chosen effects and the geometry jointly (whitened Gauss-Newton) and keeps only
   effects whose coefficients are significantly non-zero (Wald test);
3. tests the remainder (:func:`remainder_tests`): chi-square against the declared noise overall
   and per chain, and structure against time, the direction and size of each joint's last
   move, its stroke, the load it carries and the position in the workspace, and the measured
   pose drifting with time (the same at every pose: a moving measurement frame). ``explained`` is
   true only when every test passes;
4. flags outliers (:func:`outlier_scan`): rows whose studentized deleted residual (closed-form
   leave-one-out) is gross and not shared by their neighbours in time, in the workspace or in
   the direction of motion. When more than :data:`MAX_BAD_FRACTION` of the rows look bad the
   model is wrong, not the data, and nothing is flagged.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..robot import KinematicsError, check_joint_limits
from .base import Effect, EffectData
from .compliance import for_payload
from .evidence import Alias, Evidence, selection_evidence
from .gross_rows import MAX_BAD_FRACTION, OUTLIER_ALPHA, OutlierScan, outlier_scan
from .joint_fit import EffectFit, as_models, check_applies, fit_effect, fit_effects, release_span_bases
from .laws import LawSpace, ProposedLaw, law_effect, search_law
from .registry import effects_for
from .located import Located, locate_mismatch
from .remainder import NOISE_ALPHA, POSE_DRIFT_Z, VERDICT_ALPHA, Remaining, RemainderTests, remainder_tests, root_mean_square
from .search import SEARCH_ROWS_MAX, SEARCH_SUBSAMPLE_ROWS, LinearisedFit, SearchForm, search_subsample
from .selection import (ALIAS_CORRELATION, ALIAS_DELTA_BIC, MIN_DELTA_BIC, MIN_GRANULARITY_DELTA_BIC,
                        MIN_NESTED_DELTA_BIC, SIGNIFICANCE_ALPHA, candidate_forms, choose_effects,
                        regressor_correlation)
from .separability import (HELD_INFORMATION, GeometryBasis, PoseFamilyReach, Separation, UnseparatedForm,
                           pose_families)
from .whitening import (closure_noise_covariance, closure_noise_std, geometry_basis_of, noise_covariance,
                        whiten)

__all__ = ["MIN_DELTA_BIC", "MIN_ROWS", "MAX_EFFECTS", "ALIAS_CORRELATION", "ALIAS_DELTA_BIC",
           "MIN_NESTED_DELTA_BIC", "MIN_GRANULARITY_DELTA_BIC", "VERDICT_ALPHA", "POSE_DRIFT_Z",
           "NOISE_ALPHA", "OUTLIER_ALPHA", "MAX_BAD_FRACTION", "SIGNIFICANCE_ALPHA", "EffectFit", "Discovery", "fit_effect",
           "fit_effects", "discover_effects", "discover_effect", "remainder_tests", "outlier_scan",
           "locate_mismatch", "closure_noise_covariance", "closure_noise_std", "regressor_correlation", "candidate_forms",
           "propose_law", "SEARCH_ROWS_MAX", "SEARCH_SUBSAMPLE_ROWS", "search_subsample"]

#: Fewest measurements a discovery accepts.
MIN_ROWS = 12
#: Most effects named together.
MAX_EFFECTS = 3


@dataclass(frozen=True, eq=False)
class Discovery:
    """The outcome of :func:`discover_effects`.

    Attributes:
        effects: names of the effects named (empty: geometry alone).
        explained: whether the remainder is consistent with the declared noise and shows no
            structure (:func:`remainder_tests`).
        remaining: what is left (:class:`calib.effects.remainder.Remaining`: numbers and
            ``summary`` in words; ``present`` False when explained).
        partial: names of named effects that leave structure behind (all of them when not
            explained).
        chosen: the chosen model's joint fit (on the rows kept).
        geometry: the geometry-only fit (on the rows kept).
        evidence: per candidate alone: chi2, BIC evidence, cross-validated whitened RMS; the
            selection's steps; the geometry-only chi-square test
            (:class:`calib.effects.evidence.Evidence`).
        tests: the remainder's tests (:func:`remainder_tests`, :class:`calib.effects.remainder.RemainderTests`).
        aliases: pairs the data could not tell apart (:class:`calib.effects.evidence.Alias`).
        outliers: the outlier scan (:func:`outlier_scan`, :class:`calib.effects.gross_rows.OutlierScan`)
            of the last round.
        flagged: indices of rows removed as outliers (gross and isolated).
        kept: indices of the rows used.
        located: where the geometry-only residuals concentrate (:func:`locate_mismatch`,
            :class:`calib.effects.remainder.Located`).
        proposed_law: where the library leaves a remainder, the law over joint-space terms that
            explains it (:func:`propose_law`), or None (explained, none found, or not searched).
        separation: with a prior that the rows leave combinations to (:func:`separation`,
            :class:`calib.effects.separability.Separation`): the geometric combinations held at the
            prior mean, the candidate forms that cannot be separated from them on this pose set
            (never named), and the poses that would separate them; None otherwise.
        search: how the searched parameters (a pitch, a time constant, a step time) were
            searched in the last round's selection: on every row, or above ``search_rows_max``
            measurements on a subsample (:class:`calib.effects.search.SearchForm`).
    """

    effects: tuple
    explained: bool
    remaining: Remaining
    partial: tuple
    chosen: EffectFit
    geometry: EffectFit
    evidence: Evidence
    tests: RemainderTests
    aliases: tuple
    outliers: OutlierScan
    flagged: tuple
    kept: np.ndarray
    located: Located
    proposed_law: ProposedLaw | None = None
    separation: Separation | None = None
    search: SearchForm = SearchForm()

    @property
    def effect(self) -> str:
        """``"none"``, the one effect, or the names joined by ``+``."""
        return "+".join(self.effects) or "none"

    @property
    def adequate(self) -> bool:
        return self.explained

    @property
    def model_wrong(self) -> bool:
        """More than :data:`MAX_BAD_FRACTION` of the rows looked bad."""
        return self.outliers.model_wrong


def discover_effects(data: EffectData, *, candidates=None, max_effects: int = MAX_EFFECTS, alpha: float = VERDICT_ALPHA,
                     outlier_alpha: float = OUTLIER_ALPHA, folds: int = 5, seed: int = 0, max_rounds: int = 3,
                     min_delta_bic: float = MIN_DELTA_BIC, per_chain: bool = True, laws: bool = True,
                     channels: dict | None = None, search_rows_max: int | None = None,
                     search_subsample_rows: int | None = None) -> Discovery:
    """Name the left-out physics (up to ``max_effects`` effects together), fit it, test what
    remains, and isolate gross rows (see the module docstring).

    Args:
        data: the measurements.
        candidates: effects to consider, registered names or :class:`Effect` objects (``none``
            is always the reference); default every registered effect that applies to the robot.
        max_effects: most effects named together.
        alpha: significance of the remainder's tests.
        outlier_alpha: family-wise significance of the outlier test.
        folds, seed: cross-validation.
        max_rounds: outlier rounds (each removes the isolated gross rows and redoes the choice).
        per_chain: also consider each candidate's per-chain form
            (:mod:`calib.effects.granularity`), chosen against its shared form by the nested
            rule (False: the shared forms only).
        laws: where the library leaves a remainder (not explained), search a law over joint-space
            terms (:func:`propose_law`, :mod:`calib.effects.laws`).
        channels: extra recorded channels ``{name: (N,) or (N, C)}`` (a temperature) the law's
            terms may use.
        search_rows_max: measurements above which the searched parameters' grids are scanned on
            a subsample and confirmed on every row (default :data:`SEARCH_ROWS_MAX`; the
            discovery's ``search`` says which form ran).
        search_subsample_rows: rows of that subsample (default :data:`SEARCH_SUBSAMPLE_ROWS`).

    Raises:
        ValueError: too few rows, an unknown candidate or one that does not apply to the robot.
    """
    robot = data.robot
    if candidates is None:
        candidates = effects_for(robot)
    # A recording at several payloads: compliance with its payload terms (calib.effects.compliance).
    candidates = [for_payload(m, data) for m in as_models(candidates)]
    models = candidate_forms(candidates, per_chain)
    for m in models.values():
        check_applies(m, robot)
    if data.n < MIN_ROWS:
        raise ValueError(f"effect discovery needs at least {MIN_ROWS} measurements, got {data.n}")

    def choose(rows: EffectData):
        return choose_effects(rows, models, max_effects, min_delta_bic, folds, seed, search_rows_max,
                              search_subsample_rows)

    sub, geo, fit, sel, scan, kept, flagged = _outlier_rounds(data, choose, outlier_alpha, max_rounds)
    tests = remainder_tests(sub, fit, alpha=alpha)
    release_span_bases(fit)  # the outlier scan and the tests are done with its bases
    explained = tests.explained
    separated = separation(sub, fit, models, sel["unseparated"])
    aliases = tuple(Alias(models[a].name, b, gap, corr, nested) for a, b, gap, corr, nested in sel["rivals"]
                    if models[a] in fit.models and (nested or models[b].name not in fit.effects))
    evidence = selection_evidence(geo, sel, models, fit, alpha)
    remaining = tests.remaining
    if scan.model_wrong:
        remaining = replace(remaining, bad_rows=len(scan.bad),
                            summary=remaining.summary + f"; {len(scan.bad)} of {sub.n} rows look bad (more than "
                            f"{100 * MAX_BAD_FRACTION:.0f}%): the model is wrong, not the data, and no row is left out")
    law = _law_left(sub, fit, channels, kept, folds, seed) if laws and not explained else None
    return Discovery(effects=fit.effects, explained=explained, remaining=remaining,
                     partial=() if explained else fit.effects, chosen=fit, geometry=geo, evidence=evidence,
                     tests=tests, aliases=aliases, outliers=scan, flagged=tuple(sorted(flagged)), kept=kept,
                     located=locate_mismatch(sub, geo), proposed_law=law, separation=separated, search=sel["search"])


def _outlier_rounds(data: EffectData, choose, outlier_alpha: float, max_rounds: int) -> tuple:
    """The rounds of :func:`discover_effects`: the choice on the rows kept (``choose(rows)``,
    :func:`calib.effects.selection.choose_effects`) and its outlier scan, the isolated gross rows
    left out and the choice made again, ``max_rounds`` times at most. Returns ``(rows kept as
    data, geometry fit, chosen fit, selection, scan, kept, flagged)``."""
    kept = np.arange(data.n)
    flagged: list[int] = []
    for _ in range(max_rounds):
        sub, geo, fit, sel = choose(data.subset(kept))
        scan = outlier_scan(sub, fit, alpha=outlier_alpha)
        new = list(scan.flagged)
        if scan.model_wrong or not new or kept.size - len(new) < MIN_ROWS \
                or len(flagged) + len(new) > MAX_BAD_FRACTION * data.n:
            if not scan.model_wrong and new and len(flagged) + len(new) > MAX_BAD_FRACTION * data.n:
                scan = scan.cleared(model_wrong=True)
            break
        flagged += [int(kept[j]) for j in new]
        kept = np.delete(kept, new)
    else:  # the last round's removal is not re-checked: re-run the choice on the rows kept
        sub, geo, fit, sel = choose(data.subset(kept))
        scan = outlier_scan(sub, fit, alpha=outlier_alpha).cleared()
    return sub, geo, fit, sel, scan, kept, flagged


def _law_left(sub: EffectData, fit: EffectFit, channels: dict | None, kept: np.ndarray, folds: int,
              seed: int) -> ProposedLaw | None:
    """The law over joint-space terms that explains what the library leaves (:func:`propose_law`
    on the rows kept), or None."""
    try:
        return propose_law(sub, fit, channels=None if channels is None else
                           {k: np.asarray(v)[kept] for k, v in channels.items()}, folds=folds, seed=seed)
    except np.linalg.LinAlgError:
        if fit.basis is None:
            raise
        # With combinations held at the prior a law's terms can resemble them; its exact fit
        # then runs away along them: no law proposed (the pose set cannot tell it from the geometry).
        return None


def separation(data: EffectData, fit: EffectFit, models: dict, unseparated: dict) -> Separation | None:
    """What the rows cannot separate, and the poses that would (:mod:`calib.effects.separability`).

    Args:
        data: the rows; fit: the chosen model's fit on them (its ``basis``).
        models: the candidate forms (key -> effect); unseparated: ``{key: {"extra",
            "combinations"}}`` of the forms the selection set aside (:meth:`LinearisedFit.unseparated`).

    Returns:
        :class:`calib.effects.separability.Separation`, None when every geometric combination is
        determined: ``left_to_prior`` (the held combinations in words, :meth:`GeometryBasis.combinations`),
        ``determined`` and ``free`` (how many geometric combinations are fitted, of how many),
        ``unseparated`` (per form: ``effect``, ``form``, ``combinations`` each with the geometric
        combination that mimics it, ``separated_by`` the pose families that would separate it),
        ``poses`` (per family of added poses, :func:`calib.effects.separability.pose_families`:
        how many of the held combinations it would determine, the forms it would separate, the
        poses reachable of those tried).
    """
    basis = fit.basis
    if basis is None:
        return None
    robot = data.robot
    names = [robot.table.names[i] for i in basis.free]
    separated_by = {k: [] for k in unseparated}
    reach = []
    families = pose_families(data.measured, robot.workspace_bounds(), robot.pose_names, robot.pose_units)
    for family, poses in families.items():
        joints, ok = np.full((len(poses), robot.n_chains), np.nan), np.zeros(len(poses), dtype=bool)
        for k in range(len(poses)):
            try:
                joints[k] = robot.inverse_kinematics(fit.theta, poses[k:k + 1])[0]
                check_joint_limits(robot, joints[k:k + 1])
                ok[k] = True
            except KinematicsError:
                pass
        if not ok.any():
            reach.append(PoseFamilyReach(family, 0, len(poses), 0))
            continue
        added = EffectData(robot, data.theta, joints[ok], poses[ok], data.t_s[-1] + np.arange(1, ok.sum() + 1), data.noise,
                           payload_kg=None if data.payload_kg is None else np.full(ok.sum(), data.payload_kg.mean()))
        both = EffectData(robot, data.theta, np.vstack([data.joints, added.joints]),
                          np.vstack([data.measured, added.measured]), np.concatenate([data.t_s, added.t_s]), data.noise,
                          np.vstack([data.direction, added.direction]), np.vstack([data.last_move, added.last_move]),
                          None if data.payload_kg is None else np.concatenate([data.payload_kg, added.payload_kg]),
                          data.tolerance)
        aug = geometry_basis_of(both)
        info = basis.held.T @ (aug.information if aug is not None else _information(both, basis)) @ basis.held
        determines = int(np.sum(np.linalg.eigvalsh(0.5 * (info + info.T)) > HELD_INFORMATION))
        lin = LinearisedFit(both, _Stub(fit.theta, aug))
        separates = tuple(k for k in unseparated if not lin.unseparated(models[k], unseparated[k]["extra"]))
        for k in separates:
            separated_by[k].append(family)
        reach.append(PoseFamilyReach(family, int(ok.sum()), len(poses), determines, separates))
    return Separation(basis.size, int(basis.free.size), basis.combinations(names, robot.table.chains[basis.free]),
                      tuple(UnseparatedForm(models[k].name, k, tuple(u["combinations"]), tuple(separated_by[k]))
                            for k, u in unseparated.items()), tuple(reach))


@dataclass(frozen=True)
class _Stub:
    """What :class:`LinearisedFit` takes of a geometry fit."""

    theta: np.ndarray
    basis: GeometryBasis | None


def _information(data: EffectData, basis: GeometryBasis) -> np.ndarray:
    """(F, F) the rows' information on ``basis``'s free parameters, tolerance units."""
    robot = data.robot
    jac = robot.closure_jacobians(data.theta, data.joints, data.measured)
    winv = np.linalg.inv(np.linalg.cholesky(noise_covariance(robot, jac, data)))
    G = whiten(winv, jac.parameters[:, :, basis.free]).reshape(-1, basis.free.size) * basis.std
    return G.T @ G


def propose_law(data: EffectData, fit: EffectFit, *, channels: dict | None = None, folds: int = 5,
                seed: int = 0) -> ProposedLaw | None:
    """The law over joint-space terms that explains what ``fit`` (geometry and the library's
    effects) leaves, searched on the fit linearised at its solution (:func:`calib.effects.laws.search_law`)
    and then fitted exactly with it; None when no term earns its place. The library's effects
    are then re-examined (:func:`reexamined`), and the law searched again without those dropped
    and without each effect kept in turn: a trial whose law has no more terms and whose BIC is no
    higher replaces the model (its effects dropped too)."""
    def space(f: EffectFit) -> LawSpace:
        jac = data.robot.closure_jacobians(f.theta, data.joints + f.joint_displacement(data), data.measured)
        winv = np.linalg.inv(np.linalg.cholesky(noise_covariance(data.robot, jac, data)))
        return LawSpace(data, winv, jac.joints, f.span, f.whitened, dict(channels or {}))

    found = search_law(space(fit), folds=folds, seed=seed)
    if not found.terms:
        return None
    eff = law_effect(found.terms, found.granularity, channels)
    extras = {m.name: e for m, e in zip(fit.models, fit.extras) if e is not None}
    exact = fit_effects(data, fit.models + (eff,), extras=extras, start=fit.theta)
    exact, dropped = reexamined(data, exact, eff, extras)
    # The law was searched with the library's effects in: searched again without those dropped,
    # and without each one kept in turn, its form may differ (a dead band named for a friction
    # growing with the load took each joint's mean level, and on three chains the law's
    # per-joint spread no longer paid for two more constants). A trial is kept when its law has
    # no more terms (it does not turn a library effect into a term of its own: on hexapod law
    # seed 900 an actuator scale left out came back as the term `stroke`) and the BIC is no higher.
    def searched_without(names: tuple):
        kept = tuple(m for m in fit.models if m.name not in names)
        ex = {k: v for k, v in extras.items() if k not in names}
        rest = fit_effects(data, kept, extras=ex, start=fit.theta)
        again = search_law(space(rest), folds=folds, seed=seed)
        if not again.terms or len(again.terms) > len(found.terms):
            return None
        e2 = law_effect(again.terms, again.granularity, channels)
        return again, e2, fit_effects(data, kept + (e2,), extras=ex, start=rest.theta)

    for m in (None,) + fit.models:
        if m is not None and m.name in dropped:
            continue
        names = dropped if m is None else dropped + (m.name,)
        if not names:
            continue
        trial = searched_without(names)
        if trial is not None and trial[2].bic() <= exact.bic():
            (found, eff, exact), dropped = trial, names
    floor = float(root_mean_square(closure_noise_std(data.robot, exact.theta, data)))
    cv_w, cv_mm = space(exact).cv([], folds, seed)
    return ProposedLaw(found, eff, exact, remainder_tests(data, exact).remaining, floor, cv_w, cv_mm, dropped)


def reexamined(data: EffectData, exact: EffectFit, law: Effect, extras: dict,
               min_delta_bic: float = MIN_DELTA_BIC) -> tuple[EffectFit, tuple]:
    """The library's effects of ``exact`` re-examined once ``law`` is in: the one whose removal
    costs least is dropped while that cost (the BIC's rise, exact refits) is below
    ``min_delta_bic``, the evidence an effect needs to enter at all; a law that contains an
    effect's physics (a settle lag and a dead band both follow the last move) leaves it nothing to
    explain. Returns the fit kept and the names dropped, in the order dropped."""
    dropped: list[str] = []
    while True:
        trials = []
        for m in exact.models:
            if m is law:
                continue
            rest = tuple(x for x in exact.models if x is not m)
            f = fit_effects(data, rest, extras={k: v for k, v in extras.items() if k != m.name}, start=exact.theta)
            trials.append((f.bic() - exact.bic(), m.name, f))
        cheapest = min(trials, key=lambda t: t[0], default=None)
        if cheapest is None or cheapest[0] >= min_delta_bic:
            return exact, tuple(dropped)
        dropped.append(cheapest[1])
        exact = cheapest[2]


#: The former name (one effect at a time); the same function.
discover_effect = discover_effects
