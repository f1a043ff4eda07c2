"""Held-out rows judge what discovery names, and find the shift between sessions.

A model chosen on the calibration rows (its BIC lower, its remainder white) can still predict
other rows worse: an effect that the pose set cannot tell from the geometry takes whatever the
rows happen to hold. Here the geometry alone and the geometry with the effects named are each
fitted on the training rows and asked to predict the held-out rows (closure residuals, mm); an
effect stays named only where the prediction improves or stays within what the noise allows
(:func:`judge_effects`); one that worsens it is reported, not named.

The held-out rows are the recording's validation rows, or, without any, rows held out in folds:
at random, in contiguous blocks of time, and session by session (:func:`heldout_folds`).

A validation session that shifted as a whole (the machine re-homed, the instrument moved) would
make every model look wrong, and could make an effect look right: a session made only of held-out
rows is tested for a shift (:func:`session_shifts`, :mod:`calib.session_shift`: each joint's zero
and the instrument frame, by evidence) and the comparison is made with that session's shift taken
out of both predictions, so that a shift neither hides nor fakes an effect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..session_shift import shift_of_residuals
from ..measurement import compose
from ..robot import KinematicsError
from .base import EffectData
from .session_zeros import session_codes
from .granularity import form_key
from .joint_fit import EffectFit, fit_effects
from .whitening import closure_noise_covariance

__all__ = ["HeldoutFold", "HeldoutFigures", "HeldoutJudgement", "RejectedEffect", "heldout_folds", "session_shifts",
           "judge_effects", "MIN_SESSION_ROWS", "TIME_BLOCKS", "WORSE_STANDARD_ERRORS", "FRAME_STEP"]

#: Held-out rows a session needs at least for its shift to be tested.
MIN_SESSION_ROWS = 3
#: Contiguous blocks of time the rows are cut into when none are held out for validation.
TIME_BLOCKS = 4
#: A model predicts worse when its held-out mean square exceeds the geometry's by more than this
#: many standard errors of a mean square of pure noise (``floor^2 sqrt(2 / n)`` for ``n``
#: residuals): a difference the noise alone would make about once in forty comparisons.
WORSE_STANDARD_ERRORS = 2.0
#: Central-difference step of the instrument motion's derivatives (mm, rad alike: the motion is
#: linear in its translation and nearly so in its small rotation).
FRAME_STEP = 1e-6


@dataclass(frozen=True)
class HeldoutFold:
    """Rows held out and the rows fitted: ``kind`` (``validation``, ``random``, ``time block``,
    ``session``), ``held`` and ``train`` (indices into the data)."""

    kind: str
    held: np.ndarray
    train: np.ndarray


def heldout_folds(t_s: np.ndarray, sessions: np.ndarray, rows: np.ndarray, validation: np.ndarray, *,
                  random_fraction: float, seed: int) -> list[HeldoutFold]:
    """The folds that judge a model.

    Args:
        t_s: (N,) each row's time (its order within a session).
        sessions: (N,) each row's session.
        rows: the rows analysed (indices).
        validation: the recording's validation rows (indices); when there are any they are the
            one fold, the rows analysed its training rows.
        random_fraction, seed: the random fold's share of the rows and its seed.
    """
    rows = np.asarray(rows, dtype=int)
    if validation.size:
        return [HeldoutFold("validation", np.asarray(validation, dtype=int), rows)]
    order = np.random.default_rng(seed).permutation(rows.size)
    n_held = max(1, int(round(random_fraction * rows.size)))
    folds = [HeldoutFold("random", np.sort(rows[order[:n_held]]), np.sort(rows[order[n_held:]]))]
    # contiguous blocks in time, session by session in their order (a session's rows are together)
    timeline = rows[np.lexsort((t_s[rows], session_codes(sessions)[0][rows]))]
    for block in np.array_split(timeline, TIME_BLOCKS):
        if block.size:
            folds.append(HeldoutFold("time block", np.sort(block), np.setdiff1d(rows, block)))
    names = list(dict.fromkeys(sessions[rows].tolist()))
    if len(names) > 1:
        for s in names:
            held = rows[sessions[rows] == s]
            folds.append(HeldoutFold("session", held, np.setdiff1d(rows, held)))
    return folds


def _shift_jacobians(data: EffectData, theta: np.ndarray):
    """``(-dF/dq (N, C, C), dF/dE (N, C, 6), whitening (N, C, C))``: the closure's change per unit
    joint zero moved (with the sign of observed less predicted) and per unit rigid motion ``E`` of
    the measured poses (base frame), and each row's closure whitening."""
    robot = data.robot
    jac = robot.closure_jacobians(theta, data.joints, data.measured)
    dP = np.zeros((data.n, robot.pose_dim, 6))
    for j in range(6):
        h = np.zeros(6)
        h[j] = FRAME_STEP
        dP[:, :, j] = (compose(h, robot, data.measured) - compose(-h, robot, data.measured)) / (2 * FRAME_STEP)
    W = np.linalg.inv(np.linalg.cholesky(closure_noise_covariance(robot, theta, data)))
    # the machine at q + d closes: F(q, p) ~ -dF/dq d; the poses seen moved by E: F ~ dF/dp dP/dE E
    return -jac.joints, jac.pose @ dP, W


def _mean_position_error(data: EffectData, theta: np.ndarray) -> np.ndarray:
    """(3,) mean of measured less predicted position over the rows (base frame), mm."""
    robot = data.robot
    pred = robot.forward_kinematics(theta, data.joints, initial=data.measured)
    position = ~robot.angle_pose_mask
    return (data.measured - pred)[:, position].mean(axis=0)


def _session_jacobians(data: EffectData, theta: np.ndarray, session, rows: np.ndarray, cache: dict) -> tuple:
    """:func:`_shift_jacobians` of ``session``'s ``rows`` at ``theta``, made once (``cache``)."""
    key = (session, theta.tobytes())
    if key not in cache:
        cache[key] = _shift_jacobians(data.subset(rows), theta)
    return cache[key]


def session_shifts(data: EffectData, theta: np.ndarray, residuals: np.ndarray, candidates: dict,
                   cache: dict | None = None) -> dict:
    """``{session: SessionShift}`` of each session in ``candidates`` (``{session: rows}``, indices
    into ``data``, ``residuals`` (len(data), C) the model's closure residuals there), with at
    least :data:`MIN_SESSION_ROWS` rows: the shift the rows show against the model ``theta`` (a
    session with a row the model cannot assemble at is left out: its figures say it); ``cache``
    keeps each session's shift Jacobians for :func:`_unshifted` at the same model."""
    cache = {} if cache is None else cache
    out = {}
    for s, rows in candidates.items():
        if rows.size < MIN_SESSION_ROWS:
            continue
        sub = data.subset(rows)
        try:
            mean_error = _mean_position_error(sub, theta)
        except KinematicsError:  # a row the model cannot assemble at: the session is not tested for a shift
            continue
        Jz, Jf, W = _session_jacobians(data, theta, s, rows, cache)
        out[s] = shift_of_residuals(data.robot, residuals[rows], Jz, Jf, W, mean_error)
    return out


def _unshifted(data: EffectData, theta: np.ndarray, residuals: np.ndarray, shifts: dict, session_rows: dict,
               cache: dict) -> np.ndarray:
    """``residuals`` with each shifted session's shift (of its chosen model, fitted again to these
    residuals) taken out."""
    out = residuals.copy()
    for s, shift in shifts.items():
        if not shift.shifted:
            continue
        rows = session_rows[s]
        Jz, Jf, W = _session_jacobians(data, theta, s, rows, cache)
        again = shift_of_residuals(data.robot, residuals[rows], Jz, Jf, W, np.zeros(3), models=(shift.chosen,))
        u = again.best.estimate
        out[rows] = residuals[rows] - np.concatenate([Jz, Jf], axis=2) @ u
    return out


@dataclass(frozen=True)
class HeldoutFigures:
    """One model's held-out prediction: closure residual RMS (mm) over the held-out rows, as
    predicted and with the shifted sessions' shifts taken out; ``per_row`` (n,) each row's RMS
    over the joints (shifts taken out)."""

    rms_mm: float
    unshifted_rms_mm: float
    per_row_mm: np.ndarray


@dataclass(frozen=True)
class RejectedEffect:
    """An effect the calibration rows chose and the held-out rows did not confirm.

    Attributes:
        name: the effect.
        delta_bic: its BIC gain on the calibration rows when it entered (negative: lower), or None.
        geometry_mm, with_effect_mm: held-out RMS (shifts taken out) of the geometry alone and of
            the model with it, mm.
        fold: the held-out rows that judged it (``validation``, ``random``, ...).
        why: ``"worse held-out"`` or ``"not separable"`` or ``"worse re-simulated"``.
    """

    name: str
    delta_bic: float | None
    geometry_mm: float
    with_effect_mm: float
    fold: str
    why: str


@dataclass(frozen=True)
class HeldoutJudgement:
    """What the held-out rows said (:func:`judge_effects`).

    Attributes:
        named: the effects that hold (a subset of those the calibration rows chose, in order).
        rejected: the ones that did not, with their figures.
        fold: the first fold (validation rows, or the random one): the figures reported.
        geometry, model: :class:`HeldoutFigures` of the geometry alone and of the effects named,
            on ``fold``.
        floor_mm: RMS of the closure noise on ``fold``'s rows, mm.
        shifts: ``{session: SessionShift}`` of the held-out sessions with no training rows.
        folds: per fold ``(kind, rows held, geometry RMS, model RMS)`` (shifts taken out).
        fit: the named effects' fit on ``fold``'s training rows (the geometry's when none).
    """

    named: tuple
    rejected: tuple
    fold: HeldoutFold
    geometry: HeldoutFigures
    model: HeldoutFigures
    floor_mm: float
    shifts: dict
    folds: tuple
    fit: EffectFit


def _figures(data, theta, residuals, shifts, session_rows, cache: dict) -> HeldoutFigures:
    unshifted = _unshifted(data, theta, residuals, shifts, session_rows, cache)
    return HeldoutFigures(float(np.sqrt(np.mean(residuals ** 2))), float(np.sqrt(np.mean(unshifted ** 2))),
                          np.sqrt(np.mean(unshifted ** 2, axis=1)))


def _worse(model_ms: float, geometry_ms: float, floor_mm: float, n: int) -> bool:
    return model_ms - geometry_ms > WORSE_STANDARD_ERRORS * floor_mm ** 2 * np.sqrt(2.0 / n)


class _Fold:
    """One fold's data, geometry fit and shifts, and the mean squares of the models tried on it."""

    def __init__(self, data: EffectData, fold: HeldoutFold, sessions: np.ndarray, start, shift_sessions: bool):
        self.data, self.fold = data, fold
        self.train, self.test = data.subset(fold.train), data.subset(fold.held)
        self.geo = fit_effects(self.train, (), start=start)
        r0 = self.geo.predict(self.test)[0]
        trained = set(sessions[fold.train].tolist())
        held_sessions = sessions[fold.held]
        self.session_rows = {s: np.flatnonzero(held_sessions == s) for s in dict.fromkeys(held_sessions.tolist())
                             if s not in trained}
        self.jacobians: dict = {}  # each shifted session's at each model tried
        self.shifts = session_shifts(self.test, self.geo.theta, r0, self.session_rows, self.jacobians) \
            if shift_sessions else {}
        self.floor = float(np.sqrt(np.mean(np.diagonal(closure_noise_covariance(
            data.robot, data.theta, self.test), axis1=1, axis2=2))))
        self.geometry = _figures(self.test, self.geo.theta, r0, self.shifts, self.session_rows, self.jacobians)
        self.tried: dict = {}

    def figures(self, models: tuple, extras: dict) -> tuple[HeldoutFigures, EffectFit] | None:
        """The held-out figures of ``models`` fitted on the training rows (None: the training rows
        do not determine them, e.g. a step in time outside them)."""
        key = tuple(m.name for m in models)
        if key not in self.tried:
            if not models:
                self.tried[key] = (self.geometry, self.geo)
            else:
                try:
                    fit = fit_effects(self.train, models, extras=extras, start=self.geo.theta)
                    r = fit.predict(self.test)[0]
                    ok = bool(np.all(np.isfinite(r)))
                except (np.linalg.LinAlgError, ValueError):
                    ok = False
                got = _figures(self.test, fit.theta, r, self.shifts, self.session_rows, self.jacobians) if ok else None
                self.tried[key] = None if got is None else (got, fit)
        return self.tried[key]

    def worse(self, models: tuple, extras: dict) -> bool | None:
        got = self.figures(models, extras)
        if got is None:
            return None
        n = self.geometry.per_row_mm.size * self.data.robot.n_chains
        return _worse(got[0].unshifted_rms_mm ** 2, self.geometry.unshifted_rms_mm ** 2, self.floor, n)


def judge_effects(data: EffectData, chosen: EffectFit, folds: list[HeldoutFold], sessions: np.ndarray, *,
                  unseparated=(), delta_bic: dict | None = None, start=None) -> HeldoutJudgement:
    """Keep the effects of ``chosen`` that the held-out rows confirm.

    Every effect the separability screen set aside (``unseparated``, effect names) is dropped
    first. Then, while the model predicts some fold's held-out rows worse than the geometry alone
    (mean square beyond :data:`WORSE_STANDARD_ERRORS` standard errors of the noise's, shifts taken
    out), the effect whose removal predicts best is dropped and reported.

    Args:
        data: every row (the motion history of the recording's order), the folds index it.
        chosen: the model the calibration rows chose (its effects and searched parameters).
        folds: :func:`heldout_folds`.
        sessions: (N,) each row's session.
        unseparated: the forms (:func:`calib.effects.granularity.form_key`: ``name`` or
            ``name[per_chain]``) the rows cannot separate from the geometry.
        delta_bic: ``{effect: BIC gain when it entered}`` for the words.
        start: (P,) the geometry the training fits start from (default ``data.theta``).
    """
    delta_bic = dict(delta_bic or {})
    extras = {m.name: e for m, e in zip(chosen.models, chosen.extras) if e is not None}
    judged = [_Fold(data, f, sessions, start, shift_sessions=f.kind == "validation") for f in folds]
    first = judged[0]
    rejected: list[RejectedEffect] = []
    models = tuple(chosen.models)

    def reject(m, why, fold: _Fold):
        got = fold.figures((m,), extras)
        after = got[0].unshifted_rms_mm if got is not None else float("nan")
        rejected.append(RejectedEffect(m.name, delta_bic.get(m.name), fold.geometry.unshifted_rms_mm, after,
                                       fold.fold.kind, why))

    for m in [m for m in models if form_key(m) in set(unseparated)]:
        reject(m, "not separable", first)
        models = tuple(x for x in models if x is not m)
    while models:
        worse = next((f for f in judged if f.worse(models, extras)), None)
        if worse is None:
            break
        scores = []
        for m in models:
            rest = tuple(x for x in models if x is not m)
            got = worse.figures(rest, extras)
            scores.append(np.inf if got is None else got[0].unshifted_rms_mm)
        m = models[int(np.argmin(scores))]
        reject(m, "worse held-out", worse)
        models = tuple(x for x in models if x is not m)
    got = first.figures(models, extras)
    if got is None:  # the first fold cannot fit what the others confirmed: its figures are the geometry's
        got = (first.geometry, first.geo)
    fold_rows = tuple((f.fold.kind, int(f.fold.held.size), f.geometry.unshifted_rms_mm,
                       (f.figures(models, extras) or (f.geometry,))[0].unshifted_rms_mm) for f in judged)
    return HeldoutJudgement(tuple(m.name for m in models), tuple(rejected), first.fold, first.geometry, got[0],
                            first.floor, first.shifts, fold_rows, got[1])

