"""Gross rows found before anything is fitted to them: least trimmed squares over whole rows.

A recording may hold rows that are not measurements of the pose at their joints (a tracker that
lost its reflector, a row copied from elsewhere, a wrong unit): a fit over every row bends to
them, and a frame test over every row may take a few far rows for an instrument frame. This
module finds such rows with a fit that never sees them (:func:`find_gross_rows`):

1. **Frame, robustly** (``frame="auto"``). Each row's disagreement with the nominal model in the
   base frame (position in units of :data:`calib.measurement.FRAME_DETECTION_FRACTION` of the
   machine's size, angle in units of :data:`calib.measurement.FRAME_DETECTION_RAD`); the
   instrument frame test (:func:`calib.measurement.detect_frame`, the same limits) runs on the
   ``h`` rows that agree best, not on every row: a frame is inferred only when it is needed to
   make a majority of the rows consistent, never to absorb a few far rows. Where the frame is
   estimated, its closed-form start is a *trimmed* registration: register on every row, keep the
   ``h`` rows the registered nominal model explains best, register again, until the rows repeat.
2. **Least trimmed squares** (FAST-LTS, Rousseeuw and Van Driessen 2006, over rows). Each row's
   statistic is the squared norm of its whitened residual (the joint fit's whitening: declared
   instrument noise plus joint noise through the Jacobians), chi-square with M degrees of
   freedom (M = D pose coordinates, or 3 per target) for a row at the declared noise. The
   objective is the sum of the ``h`` smallest statistics, ``h = ceil(KEPT_FRACTION N)`` (at
   least twice the fewest rows that identify the unknowns). Starts: the ``h`` rows the (frame-
   registered) nominal model explains best, and :data:`RANDOM_STARTS` seeded random subsets of
   :data:`SUBSET_FACTOR` times the fewest rows that identify the unknowns. Each start is fitted
   (geometry, and the frame and target offsets where estimated:
   :func:`calib.measurement.identify_measured`, :data:`STEP_ITERATIONS` Gauss-Newton iterations
   warm-started) and improved by :data:`TRIAL_C_STEPS` C-steps (refit on the ``h`` rows with the
   smallest statistic: the objective never rises); the best start is iterated to convergence
   (the rows repeat). A subset whose fit fails (a row out of reach, a diverging or singular fit,
   condition number beyond :data:`SUBSET_CONDITION`) is replaced by another draw.
3. **Reweighting.** Rows whose statistic (leverage-corrected, below) against the best trimmed
   fit exceeds the chi-square(M) quantile ``1 - alpha`` (:data:`GROSS_ALPHA`: 0.999, false-alarm
   probability 0.001 per consistent row, the outlier test's) are gross; the fit is repeated on
   the rest, and the rows re-judged against it, until they repeat. The last fit is the full one
   (Levenberg-Marquardt from the nominal geometry, the frame from the trimmed fit), whose gauge
   is :func:`calib.measurement.identify_measured`'s.

Fewer than ``h`` rows consistent with the best trimmed fit is not a matter of gross rows: the
model does not fit the data at the declared noise (an unmodelled effect, noise declared too
small, or more than ``1 - KEPT_FRACTION`` of the rows gross): no row is named and the result
says so (``success`` False).

Rows are judged by the leverage-corrected statistic, as the outlier test judges them
(:mod:`calib.outliers`): a row in the fit by ``r^T (I - H_jj)^-1 r`` (its residual predicted by
the fit without it), a row left out by ``r^T (I + H_jj)^-1 r`` (the fit's prediction error
added), ``H_jj`` its block of the hat matrix: both chi-square(M) to first order at the declared
noise. Without it a consistent row left out of a fit with many parameters (the 6-RUS: 66) can
exceed the cutoff by its prediction error alone. The search itself ranks rows by the plain
statistic (least trimmed squares' objective).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .batched_lu import BatchedLU
from .measurement import (FRAME_DETECTION_FRACTION, FRAME_DETECTION_RAD, GAUGE_RTOL, MeasuredFit,
                          checked_measured_inputs, detect_frame, identify_measured, instrument_measurements,
                          measurement_residuals, register_frame, whitened_jacobian, whitened_residuals)
from .noise import SensorNoise, chi2_quantile
from .tsqr import triangular_factor
from .robot import KinematicsError, Robot

__all__ = ["GrossRowResult", "find_gross_rows", "GROSS_ALPHA", "KEPT_FRACTION", "RANDOM_STARTS",
           "SUBSET_FACTOR", "TRIAL_C_STEPS", "STEP_ITERATIONS", "SUBSET_CONDITION", "SEARCH_MAX_ROWS"]

#: False-alarm probability per consistent row: the cutoff is the chi-square(M) 0.999 quantile.
GROSS_ALPHA = 1e-3
#: The trimmed fit keeps this fraction of the rows (it tolerates up to 1 - this fraction gross).
KEPT_FRACTION = 0.6
#: Seeded random subsets tried besides the deterministic start.
RANDOM_STARTS = 4
#: A random subset holds this many times the fewest rows that identify the unknowns.
SUBSET_FACTOR = 2
#: C-steps given to every start before the best one is iterated to convergence.
TRIAL_C_STEPS = 2
#: Most C-steps (and reweighting rounds) of one fit.
MAX_C_STEPS = 20
#: Gauss-Newton iterations of each warm-started fit in the search (the last fit runs to convergence).
STEP_ITERATIONS = 3
#: A subset fit whose scaled condition number exceeds this is singular (about 1 / sqrt(machine eps)).
SUBSET_CONDITION = 1e8
#: Extra subsets drawn, in all, to replace subsets whose fit fails.
REDRAWS = 10
#: Above this many rows the search (frame test, starts, C-steps, reweighting) runs on a seeded
#: subsample of this many rows, and every row is then judged against the subsample's fit: each
#: fit of the search costs in proportion to its rows, and a few thousand rows determine the
#: geometry far beyond what a gross row (many times the noise) needs to stand out.
SEARCH_MAX_ROWS = 1000


@dataclass(frozen=True, eq=False)
class GrossRowResult:
    """Which rows are gross errors, and the fit on the others.

    Attributes:
        gross: 0-based indices (into the input arrays) of the rows named gross, ascending.
        kept: (N,) bool, the rows the fit used (False for gross rows).
        statistic: (N,) each row's leverage-corrected statistic against ``fit`` (dimensionless,
            chi-square(M) at the declared noise: module doc); NaN where not computed. Above
            :data:`SEARCH_MAX_ROWS` rows, a row outside the subsample's fit whose plain statistic
            is within the cutoff keeps the plain one (the correction of a row left out can only
            lower it: the judgement is the same; its Jacobian is not computed).
        residuals: (N, M) each row's whitened residual against ``fit`` (dimensionless).
        cutoff: the chi-square(M) ``1 - alpha`` quantile a gross row exceeds.
        dof: M, the coordinates of a row.
        fit: the identification on the kept rows (geometry, and frame and target offsets where
            estimated); on failure the best fit found, or None.
        frame_estimated: whether an instrument frame was estimated.
        trimmed_rows: 0-based indices of the ``h`` rows of the best trimmed fit.
        fits: fits run in all.
        failed_subsets: subset fits that failed and were replaced.
        success: whether the search ended with a judgement of every row.
        message: the finding in words (no row numbers: the caller numbers rows for the user).
        search: which form of the search ran, in words: ``"every row"``, or the subsample's size
            with the constant it exceeds (:data:`SEARCH_MAX_ROWS`).
    """

    gross: tuple
    kept: np.ndarray
    statistic: np.ndarray
    residuals: np.ndarray
    cutoff: float
    dof: int
    fit: MeasuredFit | None
    frame_estimated: bool
    trimmed_rows: tuple
    fits: int
    failed_subsets: int
    success: bool
    message: str
    search: str = "every row"


@dataclass(frozen=True, eq=False)
class _Problem:
    """The data and what is estimated; ``h`` rows are kept by the trimmed fit."""

    robot: Robot
    joints: np.ndarray
    measured: np.ndarray
    noise: SensorNoise
    targets: np.ndarray | None
    estimate_targets: bool
    free: tuple
    theta0: np.ndarray
    h: int
    min_rows: int


@dataclass(frozen=True, eq=False)
class _State:
    """A fit on ``rows`` and every row's whitened residual against it."""

    rows: np.ndarray
    fit: MeasuredFit
    white: np.ndarray
    stat: np.ndarray
    poses: np.ndarray

    def objective(self, h: int) -> float:
        return float(np.sum(np.sort(self.stat)[:h]))


class _Counter:
    """Fits run, subset fits failed, and why the last one failed."""

    def __init__(self):
        self.fits, self.failed, self.last_failure = 0, 0, ""


def find_gross_rows(robot: Robot, joints, measured, noise: SensorNoise, *, frame: str = "auto", targets=None,
                    estimate_targets: bool | None = None, free=None, start=None, alpha: float = GROSS_ALPHA,
                    kept_fraction: float = KEPT_FRACTION, random_starts: int = RANDOM_STARTS,
                    seed: int = 0) -> GrossRowResult:
    """Name the rows no consistent fit explains, with a fit that never used them (module doc).

    Args:
        robot: the robot (its nominal vector, or ``start``, starts the fits).
        joints: (N, C) commanded (or read) joints, the robot's joint unit.
        measured: (N, D) full poses (mm, rad) or (N, 3K) target positions (mm), instrument frame.
        noise: declared noise (whitening).
        frame: ``"auto"`` (estimate the instrument frame when the rows that agree best with the
            nominal model need it), ``"base"`` or ``"estimate"``.
        targets: (K, 3) target offsets on the platform, mm (given, or start values); None for
            full poses.
        estimate_targets: estimate the offsets; default True when ``targets`` are given.
        free: identified parameters (default ``robot.free_default``).
        start: (P,) start of the geometry, and the reference of its gauge; default nominal.
        alpha: false-alarm probability per consistent row (the cutoff's quantile is ``1 - alpha``).
        kept_fraction: the trimmed fit keeps ``ceil(kept_fraction N)`` rows (in [0.5, 1)).
        random_starts: seeded random subsets tried besides the deterministic start.
        seed: the random subsets' seed (the same seed gives the same result).

    Above :data:`SEARCH_MAX_ROWS` rows the whole search runs on a seeded subsample of that many
    rows, and every row is then judged against its final fit (leverage-corrected as a row in that
    fit or left out of it); ``search`` says which form ran.

    Returns:
        A :class:`GrossRowResult`, also when the search fails (``success`` False, ``message``).

    Raises:
        TypeError, ValueError: bad arguments (not a failing fit).
    """
    problem, mode = _problem(robot, joints, measured, noise, frame, targets, estimate_targets, free, start,
                             alpha, kept_fraction, random_starts)
    n = len(problem.joints)
    if n > SEARCH_MAX_ROWS:
        return _subsampled(problem, mode, alpha, random_starts, seed)
    return _search(problem, mode, alpha, random_starts, seed)


def _search(problem: _Problem, mode: str, alpha: float, random_starts: int, seed: int) -> GrossRowResult:
    """The search over every row of ``problem`` (module doc)."""
    m = problem.measured.shape[1]
    cutoff = chi2_quantile(1.0 - alpha, m)
    counter = _Counter()
    n = len(problem.joints)
    if n < problem.min_rows + 1:
        return _failure(problem, cutoff, mode == "estimate", None, None, counter,
                        f"too few rows to judge any: {n}, and {problem.min_rows} rows are needed to identify the "
                        f"unknowns, {problem.min_rows + 1} to judge one row against the others")
    est_frame, words = False, ""
    try:
        est_frame, words = _frame_needed(problem, mode)
        begin = _start_state(problem, est_frame)
        best = _trimmed_fit(problem, est_frame, begin, np.random.default_rng(seed), random_starts, counter)
    except (_SearchFailed, ValueError, np.linalg.LinAlgError) as exc:  # KinematicsError is a ValueError
        return _failure(problem, cutoff, est_frame, None, None, counter, f"{words}{exc}")
    return _reweighted(problem, est_frame, best, cutoff, alpha, counter, words)


def _subsampled(problem: _Problem, mode: str, alpha: float, random_starts: int, seed: int) -> GrossRowResult:
    """The search on a seeded subsample of :data:`SEARCH_MAX_ROWS` rows, then every row judged
    against its final fit (the count of consistent rows checked against ``h`` of every row)."""
    n, size = len(problem.joints), SEARCH_MAX_ROWS
    sub = np.sort(np.random.default_rng([int(seed), n]).choice(n, size=size, replace=False))
    h_sub = min(size, max(math.ceil(problem.h / n * size), 2 * problem.min_rows))
    part = _Problem(problem.robot, problem.joints[sub], problem.measured[sub], problem.noise, problem.targets,
                    problem.estimate_targets, problem.free, problem.theta0, h_sub, problem.min_rows)
    form = (f"least trimmed squares on a seeded subsample of {size:,} of the {n:,} rows ({n:,} rows > "
            f"SEARCH_MAX_ROWS = {SEARCH_MAX_ROWS}), every row judged against its fit")
    found = _search(part, mode, alpha, random_starts, seed)
    if found.fit is None:
        return _widened(found, n, sub, form)
    counter = _Counter()
    counter.fits, counter.failed = found.fits, found.failed_subsets
    fit = found.fit
    # Full poses in the base frame: the measured poses start the forward kinematics (a few Newton
    # steps where the home pose needs many); the same poses to its tolerance.
    start = problem.measured if problem.targets is None and not found.frame_estimated else None
    try:
        white, poses = whitened_residuals(problem.robot, fit.result.theta, problem.joints, problem.measured,
                                          problem.noise, frame=fit.frame, targets=fit.targets, initial=start)
    except (ValueError, np.linalg.LinAlgError) as exc:  # a row the subsample's model cannot reach
        return _widened(found, n, sub, form, success=False,
                        message=f"{found.message}; the rows outside the subsample could not be judged: {exc}")
    stat = np.sum(white ** 2, axis=1)
    state = _State(rows=sub[found.kept], fit=fit, white=white, stat=stat, poses=poses)
    # The leverage correction of a row left out of the fit, r^T (I + H_jj)^-1 r, is at most its
    # plain statistic (H_jj is positive semi-definite): a row outside the fit whose plain statistic
    # is within the cutoff is kept whatever its leverage, and only the fit's rows and the others
    # above the cutoff need their hat-matrix blocks (the Jacobian of those rows alone).
    inside = np.zeros(n, bool)
    inside[state.rows] = True
    judge = np.flatnonzero(inside | (stat > found.cutoff))
    judged = _judged(problem, found.frame_estimated, state, judge) if np.all(np.isfinite(stat)) else stat
    kept = judged <= found.cutoff
    trimmed = tuple(int(sub[i]) for i in found.trimmed_rows)
    common = dict(statistic=judged, residuals=white, cutoff=found.cutoff, dof=found.dof, fit=fit,
                  frame_estimated=found.frame_estimated, trimmed_rows=trimmed, fits=counter.fits,
                  failed_subsets=counter.failed, search=form)
    if not found.success or np.count_nonzero(kept) < problem.h:
        reason = found.message if not found.success else (
            f"model misfit, not gross rows: {n - np.count_nonzero(kept)} of {n} rows exceed the chi-square cutoff "
            f"{found.cutoff:.3g} against the subsample's fit (more than {n - problem.h}): the geometric model does not "
            "explain the data at the declared noise (an unmodelled effect, or noise declared too small); no row is named")
        return GrossRowResult(gross=(), kept=np.ones(n, bool), success=False, message=reason, **common)
    gross = tuple(int(i) for i in np.flatnonzero(~kept))
    what = (f"{len(gross)} of {n} rows are gross errors" if gross else f"no gross row among the {n} rows")
    message = (f"{what} (whitened residual above the chi-square({found.dof}) quantile {1 - alpha:g}, "
               f"{found.cutoff:.3g}, against the fit of a least-trimmed-squares search on {size} rows drawn at random "
               f"(seed {seed}); the search: {found.message})")
    return GrossRowResult(gross=gross, kept=kept, success=True, message=message, **common)


def _widened(found: GrossRowResult, n: int, sub: np.ndarray, form: str, *, success: bool | None = None,
             message: str | None = None) -> GrossRowResult:
    """A subsample's failed result over all ``n`` rows (no row named; figures NaN off the subsample)."""
    stat = np.full(n, np.nan)
    stat[sub] = found.statistic
    res = np.full((n, found.residuals.shape[1]), np.nan)
    res[sub] = found.residuals
    return GrossRowResult(gross=(), kept=np.ones(n, bool), statistic=stat, residuals=res, cutoff=found.cutoff,
                          dof=found.dof, fit=found.fit, frame_estimated=found.frame_estimated,
                          trimmed_rows=tuple(int(sub[i]) for i in found.trimmed_rows), fits=found.fits,
                          failed_subsets=found.failed_subsets, success=False if success is None else success,
                          message=found.message if message is None else message, search=form)


class _SearchFailed(Exception):
    """No start could be fitted, or the data cannot be judged."""


def _problem(robot, joints, measured, noise, frame, targets, estimate_targets, free, start, alpha, kept_fraction,
             random_starts) -> tuple[_Problem, str]:
    """The checked arguments of :func:`find_gross_rows` (raises TypeError / ValueError)."""
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    if not 0.5 <= kept_fraction < 1:
        raise ValueError(f"kept_fraction must be in [0.5, 1), got {kept_fraction!r}")
    if int(random_starts) != random_starts or random_starts < 0:
        raise ValueError(f"random_starts must be a whole number >= 0, got {random_starts!r}")
    args = checked_measured_inputs(robot, joints, measured, noise, frame, targets, estimate_targets, free, start)
    joints, measured, targets, k = args["joints"], args["measured"], args["targets"], args["k"]
    est_targets, free, theta0 = args["est_targets"], args["names"], args["theta0"]
    m = measured.shape[1]
    unknowns = len(free) + 6 * (frame != "base") + (3 * k if est_targets else 0)
    min_rows = -(-unknowns // m)
    n = joints.shape[0]
    h = min(n, max(math.ceil(kept_fraction * n), 2 * min_rows))
    return _Problem(robot, joints, measured, noise, targets, est_targets, free, theta0, h, min_rows), frame


def _row_disagreement(robot: Robot, residual: np.ndarray, n_targets: int) -> np.ndarray:
    """(N,) each row's disagreement (N, M residual, mm and rad) in units of the frame test's
    limits: the larger of the position norm over ``FRAME_DETECTION_FRACTION`` times the
    machine's size and the angle norm over ``FRAME_DETECTION_RAD``."""
    angle = np.zeros(residual.shape[1], bool) if n_targets else robot.angle_pose_mask
    pos = np.linalg.norm(residual[:, ~angle], axis=1) / (FRAME_DETECTION_FRACTION * robot.length_scale_mm)
    ang = np.linalg.norm(residual[:, angle], axis=1) / FRAME_DETECTION_RAD
    return np.maximum(pos, ang)


def _nominal_poses(problem: _Problem) -> np.ndarray:
    try:
        return problem.robot.forward_kinematics(problem.theta0, problem.joints)
    except KinematicsError as exc:
        raise _SearchFailed(f"the start model cannot reach row index {exc.index} (0-based): {exc}") from None


def _frame_needed(problem: _Problem, mode: str) -> tuple[bool, str]:
    """Whether the frame is estimated, and the frame test's finding in words (``"auto"``: the
    test over the ``h`` rows that agree best with the nominal model in the base frame)."""
    if mode != "auto":
        return mode == "estimate", ""
    robot, k = problem.robot, 0 if problem.targets is None else len(problem.targets)
    pred = instrument_measurements(robot, _nominal_poses(problem), None, problem.targets)
    score = _row_disagreement(robot, measurement_residuals(robot, problem.measured, pred, k), k)
    best = np.sort(np.argsort(score, kind="stable")[:problem.h])
    found = detect_frame(robot, problem.joints[best], problem.measured[best], targets=problem.targets,
                         estimate_targets=problem.estimate_targets, theta=problem.theta0)
    return found.detected, f"frame test over the {problem.h} rows that agree best with the nominal model: {found.message}; "


def _start_state(problem: _Problem, est_frame: bool) -> dict:
    """The nominal model's frame (trimmed registration where estimated) and target offsets:
    ``{"frame": (6,), "targets": (K, 3) or None, "poses": (N, D), "order": (N,) rows by their
    whitened disagreement with it, best first}``."""
    robot, k = problem.robot, 0 if problem.targets is None else len(problem.targets)
    poses0 = _nominal_poses(problem)
    frame0, targets0 = np.zeros(6), problem.targets
    if est_frame:
        rows = np.arange(len(problem.joints))
        for _ in range(MAX_C_STEPS):
            reg = register_frame(robot, problem.joints[rows], problem.measured[rows], targets=problem.targets,
                                 estimate_targets=problem.estimate_targets, theta=problem.theta0)
            frame0, targets0 = np.array(reg.frame), None if k == 0 else np.array(reg.targets)
            pred = instrument_measurements(robot, poses0, frame0, targets0)
            score = _row_disagreement(robot, measurement_residuals(robot, problem.measured, pred, k), k)
            new = np.sort(np.argsort(score, kind="stable")[:problem.h])
            if new.size == rows.size and np.array_equal(new, rows):
                break
            rows = new
    white, _ = whitened_residuals(robot, problem.theta0, problem.joints, problem.measured, problem.noise,
                                  frame=frame0, targets=targets0, initial=poses0)
    order = np.argsort(np.sum(white ** 2, axis=1), kind="stable")
    return {"frame": frame0, "targets": targets0, "poses": poses0, "order": order}


def _fit_rows(problem: _Problem, est_frame: bool, rows, warm: dict, counter: _Counter, *,
              final: bool = False) -> _State:
    """Fit ``rows`` (warm-started at ``warm``: ``theta``, ``frame``, ``targets``, ``poses``) and
    judge every row against the fit. The search's fits take :data:`STEP_ITERATIONS` Gauss-
    Newton iterations; ``final`` runs Levenberg-Marquardt to convergence from ``problem.theta0``.

    Raises:
        _SearchFailed: the fit fails (out of reach, singular, diverging).
    """
    rows = np.sort(np.asarray(rows, int))
    robot, counter.fits = problem.robot, counter.fits + 1
    options = {} if final else {"solver": "gn", "max_iter": STEP_ITERATIONS, "gauge_passes": 1}
    try:
        fit = identify_measured(robot, problem.joints[rows], problem.measured[rows], problem.noise,
                                frame="estimate" if est_frame else "base",
                                initial_frame=warm["frame"] if est_frame else None,
                                targets=warm["targets"], estimate_targets=problem.estimate_targets,
                                free=problem.free, start=problem.theta0 if final else warm["theta"], **options)
        res = fit.result
        if not res.success and res.iterations == 0:
            raise _SearchFailed(res.message)
        if not np.isfinite(res.condition_numbers[0]) or res.condition_numbers[0] > SUBSET_CONDITION:
            raise _SearchFailed(f"the fit is singular (condition number {res.condition_numbers[0]:.3g})")
        white, poses = whitened_residuals(robot, res.theta, problem.joints, problem.measured, problem.noise,
                                          frame=fit.frame, targets=fit.targets, initial=warm["poses"])
    except (ValueError, np.linalg.LinAlgError) as exc:  # KinematicsError is a ValueError
        raise _SearchFailed(str(exc)) from None
    stat = np.sum(white ** 2, axis=1)
    if not np.all(np.isfinite(stat)):
        raise _SearchFailed("the fit's residuals are not finite")
    return _State(rows=rows, fit=fit, white=white, stat=stat, poses=poses)


def _warm(state: _State) -> dict:
    return {"theta": state.fit.result.theta, "frame": np.array(state.fit.frame),
            "targets": None if state.fit.targets is None else np.array(state.fit.targets), "poses": state.poses}


def _c_steps(problem: _Problem, est_frame: bool, state: _State, steps: int, counter: _Counter) -> _State:
    """Refit on the ``h`` rows with the smallest statistic, at most ``steps`` times, while the
    rows change and the objective falls."""
    for _ in range(steps):
        rows = np.sort(np.argsort(state.stat, kind="stable")[:problem.h])
        if np.array_equal(rows, state.rows):
            break
        try:
            new = _fit_rows(problem, est_frame, rows, _warm(state), counter)
        except _SearchFailed:
            break
        if new.objective(problem.h) >= state.objective(problem.h):
            break
        state = new
    return state


def _trimmed_fit(problem: _Problem, est_frame: bool, begin: dict, rng: np.random.Generator, random_starts: int,
                 counter: _Counter) -> _State:
    """The best least-trimmed-squares fit over the deterministic start and the random subsets."""
    n = len(problem.joints)
    nominal = {"theta": problem.theta0, "frame": begin["frame"], "targets": begin["targets"], "poses": begin["poses"]}
    size = min(problem.h, SUBSET_FACTOR * problem.min_rows)
    deterministic, trials, draws = [begin["order"][:problem.h]], [], 0
    while len(trials) < 1 + random_starts:
        if deterministic:
            rows = deterministic.pop()
        elif draws < random_starts + REDRAWS:
            rows, draws = rng.choice(n, size=size, replace=False), draws + 1
        else:
            break
        try:
            state = _fit_rows(problem, est_frame, rows, nominal, counter)
        except _SearchFailed as exc:
            counter.failed, counter.last_failure = counter.failed + 1, str(exc)
            continue
        trials.append(_c_steps(problem, est_frame, state, TRIAL_C_STEPS, counter))
    if not trials:
        raise _SearchFailed(f"no subset of the rows could be fitted ({counter.failed} tried; the last: "
                            f"{counter.last_failure})")
    best = min(trials, key=lambda s: s.objective(problem.h))
    return _c_steps(problem, est_frame, best, MAX_C_STEPS, counter)


def _judged(problem: _Problem, est_frame: bool, state: _State, rows: np.ndarray | None = None) -> np.ndarray:
    """(N,) each row's statistic corrected for leverage, chi-square(M) to first order for a row
    at the declared noise: ``r^T (I - H_jj)^-1 r`` for a row in the fit (its residual predicted
    by the fit without it), ``r^T (I + H_jj)^-1 r`` for a row left out (the fit's prediction
    error added), ``H_jj`` (M, M) the row's block of the hat matrix of the fitted rows' whitened
    Jacobian (geometry, targets, frame; the gauge's null directions dropped).

    ``rows``: (R,) ascending 0-based indices, every row of the fit (``state.rows``) among them:
    only these are corrected (the Jacobian of these rows alone), the others keep their plain
    statistic ``state.stat``; None: every row."""
    fit = state.fit
    at = slice(None) if rows is None else rows
    J, scale, _ = whitened_jacobian(problem.robot, fit.result.theta, problem.joints[at], state.poses[at],
                                    problem.noise, frame=fit.frame, targets=fit.targets, free=problem.free,
                                    estimate_frame=est_frame, estimate_targets=problem.estimate_targets)
    J = J / scale
    fitted = state.rows if rows is None else np.searchsorted(rows, state.rows)
    _, s, vt = np.linalg.svd(triangular_factor(J[fitted].reshape(-1, J.shape[2])), full_matrices=False)
    keep = s > GAUGE_RTOL * s[0]
    B = J @ (vt[keep].T / s[keep])  # (R, M, r): H_jj = B_j B_j^T
    H = B @ np.swapaxes(B, 1, 2)
    inside = np.zeros(len(J), bool)
    inside[fitted] = True
    sign = np.where(inside, -1.0, 1.0)[:, None, None]
    white = state.white[at]
    try:
        solved = BatchedLU(np.eye(J.shape[1])[None] + sign * H).solve(white)
    except np.linalg.LinAlgError:  # a row alone determines a direction: no leave-one-out residual
        return state.stat
    if rows is None:
        return np.sum(white * solved, axis=1)
    out = state.stat.copy()
    out[rows] = np.sum(white * solved, axis=1)
    return out


def _reweighted(problem: _Problem, est_frame: bool, best: _State, cutoff: float, alpha: float, counter: _Counter,
                words: str) -> GrossRowResult:
    """Rows above the cutoff against the best trimmed fit are gross; refit on the others and
    re-judge until the rows repeat; the last fit is the full one."""
    n, h = len(problem.joints), problem.h
    state, final = best, False
    judged = _judged(problem, est_frame, state)
    for _ in range(MAX_C_STEPS):
        kept = judged <= cutoff
        if np.count_nonzero(kept) < h:
            ratio = math.sqrt(float(np.median(judged)) / problem.measured.shape[1])
            return _failure(problem, cutoff, est_frame, state, judged, counter, (
                f"{words}model misfit, not gross rows: {n - np.count_nonzero(kept)} of {n} rows exceed the chi-square "
                f"cutoff {cutoff:.3g} against the best trimmed fit (more than {n - h}; typical row {ratio:.3g} times "
                "the declared noise): the geometric model does not explain the data at the declared noise (an "
                "unmodelled effect, or noise declared too small); no row is named"), best)
        try:
            state = _fit_rows(problem, est_frame, np.flatnonzero(kept), _warm(state), counter, final=final)
        except _SearchFailed as exc:
            return _failure(problem, cutoff, est_frame, state, judged, counter,
                            f"{words}the fit on the kept rows failed: {exc}", best)
        judged = _judged(problem, est_frame, state)
        if np.array_equal(judged <= cutoff, kept):
            if final:
                break
            final = True  # the rows repeat: once more with the full fit, and re-judged against it
    gross = tuple(int(i) for i in np.flatnonzero(~kept))
    what = (f"{len(gross)} of {n} rows are gross errors" if gross else f"no gross row among the {n} rows")
    message = (f"{words}{what} (whitened residual above the chi-square({problem.measured.shape[1]}) quantile "
               f"{1 - alpha:g}, {cutoff:.3g}, against the fit on the other rows; least trimmed squares over "
               f"{h} rows)")
    return GrossRowResult(gross=gross, kept=kept, statistic=judged, residuals=state.white, cutoff=cutoff,
                          dof=problem.measured.shape[1], fit=state.fit, frame_estimated=bool(est_frame),
                          trimmed_rows=tuple(int(i) for i in best.rows), fits=counter.fits,
                          failed_subsets=counter.failed, success=True, message=message)


def _failure(problem: _Problem, cutoff: float, est_frame: bool, state: _State | None, judged: np.ndarray | None,
             counter: _Counter, message: str, best: _State | None = None) -> GrossRowResult:
    """The result of a search that names no row (``state``: the best fit found, if any)."""
    n, m = problem.measured.shape
    return GrossRowResult(gross=(), kept=np.ones(n, bool),
                          statistic=np.full(n, np.nan) if judged is None else judged,
                          residuals=np.full((n, m), np.nan) if state is None else state.white, cutoff=cutoff, dof=m,
                          fit=None if state is None else state.fit, frame_estimated=bool(est_frame),
                          trimmed_rows=() if best is None else tuple(int(i) for i in best.rows), fits=counter.fits,
                          failed_subsets=counter.failed, success=False, message=message)
