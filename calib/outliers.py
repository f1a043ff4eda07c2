"""Outlier test for any robot: leave-one-out in closed form on the forward identification.

At the forward-method estimate from the rows kept, the whitened pose residuals ``r`` (N D,) and
the whitened Jacobian ``A`` (N D, p) give the hat matrix ``H = A (A^T A)^-1 A^T``. The residual of
row j predicted by the model identified WITHOUT row j is, to first order,
``d_j = (I - H_jj)^-1 r_j`` (H_jj the D x D block of row j), with covariance
``(I - H_jj)^-1``, so ``t_j = r_j^T (I - H_jj)^-1 r_j`` is chi-square with D degrees of freedom for
a consistent row (studentized deleted residual). A gross row also spoils the fit that contains
it (swamping), so the worst row is removed until every kept row passes; removed rows are judged
against the model of the rows kept (``r_j^T (I + H_jj)^-1 r_j``). The search runs on the model
linearised at the fit (removing rows moves the estimate by a closed-form update), then the kept
rows are re-identified once to check it: two or three fits in all, whatever the number of rows.
Above :data:`ONE_AT_A_TIME_MAX_ROWS` rows each step of the search removes every kept row above
the threshold at once (the worst first, no more than ``max_fraction`` allows in all), not the
worst alone: each step costs a pass over every row, and a clean file has ``alpha N`` rows above
it by chance (100 at 100,000 rows). A row removed only because a worse one bent the fit is
judged again at the end against the fit without the removed rows, as every removed row is, and
is flagged only if it still fails (``search`` says which form ran). Above
:data:`REUSED_JACOBIAN_MIN_ROWS` rows the checking refits take their residuals at their own
estimate (the forward kinematics from the measured poses) but keep the first fit's Jacobian (a
pass over every row's closure Jacobians saved a refit): the refit moves the estimate by the
removed rows' pull, a few times the noise over the square root of the rows, which changes the
Jacobian by that over the machine's size (below 1e-6 relative at 10,000 rows of a 1 um
instrument on a machine of 100 mm), and the statistics by as much relative. Such a refit keeps
the kept rows and the Jacobian of the last pass, hence its covariance and hat-matrix blocks: they
are reused (the same numbers), only the residuals are new.

Above :data:`STRUCTURED_JACOBIAN_MIN_ROWS` rows, where each chain's closure moves with its own
parameters alone (:attr:`calib.robot.ClosureJacobians.own`: the hexapod, the 6-RUS) and the free
parameters come chain by chain, as many per chain, the (N, D, P) Jacobian is never formed: row
j's is ``M_j S_j``, ``M_j`` (D, C) the whitened inverse pose Jacobian and ``S_j`` (C, P) its
parameters' own entries, one chain's block per row; the Gram products, the residual updates and
the hat-matrix blocks ``M_j (S_j cov S_j^T) M_j^T`` are taken through the factors (about a fifth
of the flops, no 200 MB array at 100,000 rows of 42 parameters), equal to the dense ones to
rounding; the Gram product of the kept rows is every row's less the few left out.

A few bad rows are outliers; many are not: when more than ``max_fraction`` of the rows would
have to go, the model does not fit the data at the declared noise (an unmodelled effect, or noise
declared too small), and the report says so (``misfit``) instead of listing rows to delete.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .batched_lu import BatchedLU
from .engine import identify_forward
from .noise import SensorNoise, chi2_quantile
from .robot import ChainJacobianFactors, Robot, chain_jacobian_factors, pose_jacobian_of_parameters

__all__ = ["OutlierReport", "find_outliers", "hat_blocks", "MISFIT_FRACTION", "ONE_AT_A_TIME_MAX_ROWS",
           "REUSED_JACOBIAN_MIN_ROWS", "STRUCTURED_JACOBIAN_MIN_ROWS"]

#: More rows than this fraction failing the test is model misfit, not outliers.
MISFIT_FRACTION = 0.05
#: Above this many rows the backward search removes every row above the threshold at once (module doc).
ONE_AT_A_TIME_MAX_ROWS = 2000
#: Above this many rows the checking refits keep the first fit's Jacobian (module doc).
REUSED_JACOBIAN_MIN_ROWS = 10000
#: Above this many rows a chain-structured robot's Jacobian is kept as its factors (module doc).
STRUCTURED_JACOBIAN_MIN_ROWS = 10000


@dataclass(frozen=True, eq=False)
class OutlierReport:
    """Leave-one-out consistency of each measured pose.

    Attributes:
        deleted_residuals: (N, D) measured minus the leave-one-out prediction (mm, rad).
        statistic: (N,) chi-square(D) statistic of each row.
        threshold: the chi-square(D) quantile at ``1 - alpha``.
        flagged: 0-based indices of the rows whose statistic exceeds the threshold; empty when
            ``misfit`` (no row is singled out then).
        misfit: more than ``max_fraction`` of the rows fail: the model does not fit the data at
            the declared noise.
        exceeding: rows whose statistic exceeds the threshold (in the last fit).
        verdict: the outcome in words.
        search: the backward search's form, in words (one row at a time, or all rows above the
            threshold at once above :data:`ONE_AT_A_TIME_MAX_ROWS` rows; the checking refits'
            Jacobian and the Jacobian's factored form where they apply).
    """

    deleted_residuals: np.ndarray
    statistic: np.ndarray
    threshold: float
    flagged: tuple
    misfit: bool = False
    exceeding: int = 0
    verdict: str = ""
    search: str = "one row at a time"


def hat_blocks(J: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(N, D, D) the diagonal blocks ``J_j cov J_j^T`` of ``J cov J^T``: ``J`` (N, D, p) the rows'
    Jacobians, ``cov`` (p, p) symmetric positive semi-definite (units: those of ``J`` squared
    times ``cov``'s). Through a factor ``cov = L L^T`` (its eigenvectors scaled by the square
    roots of its eigenvalues, negative rounding ones taken as zero): one (N D, p) by (p, p)
    product, then each row's (D, p) block times its transpose; ``J_j cov J_j^T`` to rounding
    (relative to ``|J_j|^2 |cov|``)."""
    n, d, p = J.shape
    w, v = np.linalg.eigh(cov)
    B = (J.reshape(-1, p) @ (v * np.sqrt(np.clip(w, 0.0, None)))).reshape(n, d, p)
    return B @ np.swapaxes(B, 1, 2)


def _whitened(robot: Robot, theta, joints, measured, noise, idx=None, structured=False):
    """``(r (N, D), J)``: the whitened residuals at ``theta`` (forward kinematics from the measured
    poses) and their Jacobian by the free parameters ``idx`` (all: None): a (N, D, P) array, or,
    with ``structured`` where the robot's closures allow it, its
    :class:`~calib.robot.ChainJacobianFactors`."""
    std = noise.pose_std(robot.pose_units)
    pred = robot.forward_kinematics(theta, joints, initial=measured)
    r = (measured - pred) / std
    if structured:
        factors = chain_jacobian_factors(robot, theta, joints, pred, idx, 1.0 / std)
        if factors is not None:
            return r, factors
    J = pose_jacobian_of_parameters(robot, theta, joints, pred) / std[None, :, None]
    return r, J


def _leave_one_out(Jr, gram_all, r0: np.ndarray, kept: np.ndarray, last):
    """One pass of the backward search on the model linearised at a fit: the estimate moved by
    leaving the rows not ``kept`` out, ``delta = (sum_kept Jr^T Jr)^-1 sum_kept Jr^T r0``, in
    closed form. ``Jr`` the whitened Jacobian of every row, (N, D, p) or its
    :class:`~calib.robot.ChainJacobianFactors` (with ``gram_all`` its Gram product over every row:
    the kept rows' is that less the left-out rows'); ``r0`` (N, D) the whitened residuals at the
    fit; ``last`` ``(kept, cov, factors)`` of the pass before on the same Jacobian, or None: reused
    when the same rows are kept. Returns ``(r, dw, last)``: ``r`` (N, D) the residuals after the
    step, ``dw = (I -+ H_jj)^-1 r_j`` (a kept row's predicted without it, a left-out row's with the
    fit's prediction error added; ``H_jj`` the hat matrix's diagonal block), and this pass's
    ``last``."""
    same = last is not None and np.array_equal(last[0], kept)
    if same:  # the same Jacobian and rows kept: the same covariance, blocks and factors
        cov, factors = last[1:]
    if isinstance(Jr, ChainJacobianFactors):
        out = np.flatnonzero(~kept)
        if not same:
            cov = np.linalg.pinv(gram_all - Jr.gram(out) if out.size else gram_all, hermitian=True)
        delta = cov @ Jr.rmatvec(r0 if out.size == 0 else np.where(kept[:, None], r0, 0.0))
        r = r0 - Jr.matvec(delta)
    else:
        p = Jr.shape[2]
        A = Jr.reshape(-1, p) if kept.all() else Jr[kept].reshape(-1, p)  # a view while every row is kept
        if not same:
            cov = np.linalg.pinv(A.T @ A, hermitian=True)
        delta = cov @ (A.T @ (r0.ravel() if kept.all() else r0[kept].ravel()))
        r = r0 - Jr @ delta
    if not same:
        # (N, D, D) diagonal blocks of the hat matrix
        H = Jr.hat(cov) if isinstance(Jr, ChainJacobianFactors) else hat_blocks(Jr, cov)
        sign = np.where(kept, -1.0, 1.0)[:, None, None]  # kept: I - H; left out: I + H
        factors = BatchedLU(np.eye(r0.shape[1])[None] + sign * H)
        last = (kept.copy(), cov, factors)
    return r, factors.solve(r), last


def _backward_search(Jr, gram_all, r0, kept: np.ndarray, last, removed: list, most: int, thr: float, d: int, p: int,
                     at_once: bool) -> tuple:
    """The backward search of :func:`find_outliers` on the model linearised at one fit: rows above
    the threshold removed (the worst first, one at a time or all at once), ``kept`` and ``removed``
    updated in place; ``(r, dw, stat, last, grown, misfit)`` of the last pass."""
    grown = misfit = False
    while True:
        r, dw, last = _leave_one_out(Jr, gram_all, r0, kept, last)
        stat = np.sum(r * dw, axis=1)
        cand = np.flatnonzero(kept)
        if at_once:
            over = cand[stat[cand] > thr]
            if over.size == 0:
                break
            if len(removed) == most:
                misfit = True
                break
            over = over[np.argsort(-stat[over], kind="stable")][:most - len(removed)]  # the worst first
            if (cand.size - over.size) * d <= p + d:
                break
            removed.extend(int(i) for i in over)
            kept[over] = False
            grown = True
            continue
        worst = int(cand[np.argmax(stat[cand])])
        if stat[worst] <= thr:
            break
        if len(removed) == most:
            misfit = True
            break
        if (cand.size - 1) * d <= p + d:
            break
        removed.append(worst)
        kept[worst] = False
        grown = True
    return r, dw, stat, last, grown, misfit


def find_outliers(robot: Robot, joints, measured, noise: SensorNoise, *, free=None,
                  alpha: float = 1e-3, max_fraction: float = MISFIT_FRACTION) -> OutlierReport:
    """Flag measured poses inconsistent with the rest (closed-form leave-one-out, chi-square).

    Args:
        robot: the robot (its nominal vector starts the fits).
        joints: (N, C) commanded joints.
        measured: (N, D) measured poses.
        noise: declared noise (its pose part; zero components floored).
        free: identified parameters (default ``robot.free_default``).
        alpha: false-alarm probability per consistent row.
        max_fraction: at most this fraction of the rows (at least one row) is left out as
            outliers; more failing rows are reported as model misfit.
    """
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    if not 0 <= max_fraction < 1:
        raise ValueError(f"max_fraction must be in [0, 1), got {max_fraction!r}")
    joints = np.asarray(joints, dtype=float)
    measured = np.asarray(measured, dtype=float)
    n, d = measured.shape
    free = robot.free_default if free is None else tuple(free)
    idx = robot.table.indices(free)
    p = idx.size
    if n * d <= p + d:
        raise ValueError(f"outlier detection needs more than {(p + d) // d} poses for {p} parameters "
                         f"(one left out), got {n}")
    thr = chi2_quantile(1 - alpha, d)
    most = max(1, math.floor(max_fraction * n))
    std = noise.pose_std(robot.pose_units)
    kept = np.ones(n, dtype=bool)
    removed: list[int] = []
    misfit = False
    theta = None
    at_once = n > ONE_AT_A_TIME_MAX_ROWS
    search = (f"every row above the threshold at once ({n:,} rows > ONE_AT_A_TIME_MAX_ROWS = "
              f"{ONE_AT_A_TIME_MAX_ROWS})" if at_once else "one row at a time")
    reuse = n > REUSED_JACOBIAN_MIN_ROWS
    if reuse:
        search += (f"; the checking refits' residuals against the first fit's Jacobian ({n:,} rows > "
                   f"REUSED_JACOBIAN_MIN_ROWS = {REUSED_JACOBIAN_MIN_ROWS})")
    Jr = gram_all = None
    structured = n > STRUCTURED_JACOBIAN_MIN_ROWS
    last = None  # (kept, cov, factors) of the last pass: reused while the Jacobian and the rows kept stay
    for _ in range(3):  # nonlinear refits: the first, and one check per linearised search
        fit = identify_forward(robot, joints[kept], measured[kept], noise, free=free, start=theta)
        theta = fit.theta
        if reuse and Jr is not None:  # the refit's residuals; its Jacobian is the last one's (module doc)
            r0 = (measured - robot.forward_kinematics(theta, joints, initial=measured)) / std
        else:
            r0, J = _whitened(robot, theta, joints, measured, noise, idx, structured)
            last = None
            if isinstance(J, ChainJacobianFactors):
                Jr, gram_all = J, J.gram()
                if "STRUCTURED_JACOBIAN_MIN_ROWS" not in search:
                    search += (f"; the Jacobian kept as its chains' factors ({n:,} rows > "
                               f"STRUCTURED_JACOBIAN_MIN_ROWS = {STRUCTURED_JACOBIAN_MIN_ROWS})")
            else:
                Jr = J if np.array_equal(idx, np.arange(J.shape[2])) else np.take(J, idx, axis=2)
        # Backward search on the model linearised at this fit (_leave_one_out).
        r, dw, stat, last, grown, misfit = _backward_search(Jr, gram_all, r0, kept, last, removed, most, thr, d, p,
                                                            at_once)
        if misfit or not grown:
            break
    deleted = np.where(kept[:, None], dw, r) * std
    stat_all = stat
    exceeding = int(np.count_nonzero(stat_all > thr))
    if misfit:
        ratio = math.sqrt(float(np.median(stat)) / d)
        verdict = (f"model misfit, not outliers: {exceeding} of {n} rows fail the leave-one-out test "
                   f"(more than {100 * max_fraction:g}% of the rows; typical row {ratio:.3g} times the "
                   "declared noise): the geometric model does not explain the data at the declared noise "
                   "(an unmodelled effect, or noise declared too small); no row is left out")
        return OutlierReport(deleted, stat_all, thr, (), True, exceeding, verdict, search)
    flagged = tuple(sorted(int(i) for i in np.flatnonzero(stat_all > thr)))
    verdict = (f"{len(flagged)} of {n} rows inconsistent with the others (leave-one-out chi-square "
               f"above {thr:.3g}, false-alarm rate {alpha:g} per row)" if flagged else
               f"every row consistent with the others (leave-one-out chi-square <= {thr:.3g})")
    return OutlierReport(deleted, stat_all, thr, flagged, False, exceeding, verdict, search)
