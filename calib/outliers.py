"""Outlier test for any robot: leave-one-out in closed form on the forward identification.

At the forward-method estimate from the rows kept, the whitened pose residuals ``r`` (N D,) and
the whitened Jacobian ``A`` (N D, p) give the hat matrix ``H = A (A^T A)^-1 A^T``. The residual of
row j predicted by the model identified WITHOUT row j is, to first order,
``d_j = (I - H_jj)^-1 r_j`` (H_jj the D x D block of row j), with covariance
``(I - H_jj)^-1``, so ``t_j = r_j^T (I - H_jj)^-1 r_j`` is chi-square with D degrees of freedom for
a consistent row (studentized deleted residual). A gross row also spoils the fit that contains
it (swamping), so the worst row is removed and the model re-identified until every kept row
passes; removed rows are judged against the model of the rows kept. One fit per removed row, no
refit per row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from .engine import identify_forward
from .noise import SensorNoise
from .robot import Robot, pose_jacobian_of_parameters

__all__ = ["OutlierReport", "find_outliers"]


@dataclass(frozen=True, eq=False)
class OutlierReport:
    """Leave-one-out consistency of each measured pose.

    Attributes:
        deleted_residuals: (N, D) measured minus the leave-one-out prediction (mm, rad).
        statistic: (N,) chi-square(D) statistic of each row.
        threshold: the chi-square(D) quantile at ``1 - alpha``.
        flagged: 0-based indices of the rows whose statistic exceeds the threshold.
    """

    deleted_residuals: np.ndarray
    statistic: np.ndarray
    threshold: float
    flagged: tuple


def _whitened(robot: Robot, theta, joints, measured, noise):
    std = noise.pose_std(robot.pose_units)
    pred = robot.forward_kinematics(theta, joints, initial=measured)
    r = (measured - pred) / std
    J = pose_jacobian_of_parameters(robot, theta, joints, pred) / std[None, :, None]
    return r, J


def find_outliers(robot: Robot, joints, measured, noise: SensorNoise, *, free=None,
                  alpha: float = 1e-3) -> OutlierReport:
    """Flag measured poses inconsistent with the rest (closed-form leave-one-out, chi-square).

    Args:
        robot: the robot (its nominal vector starts the fits).
        joints: (N, C) commanded joints.
        measured: (N, D) measured poses.
        noise: declared noise (its pose part; zero components floored).
        free: identified parameters (default ``robot.free_default``).
        alpha: false-alarm probability per consistent row.
    """
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    joints = np.asarray(joints, dtype=float)
    measured = np.asarray(measured, dtype=float)
    n, d = measured.shape
    free = robot.free_default if free is None else tuple(free)
    idx = robot.table.indices(free)
    p = idx.size
    if n * d <= p + d:
        raise ValueError(f"outlier detection needs more than {(p + d) // d} poses for {p} parameters "
                         f"(one left out), got {n}")
    thr = float(chi2.ppf(1 - alpha, d))
    rows = np.arange(n)
    removed: list[int] = []
    while True:
        fit = identify_forward(robot, joints[rows], measured[rows], noise, free=free)
        r, J = _whitened(robot, fit.theta, joints[rows], measured[rows], noise)
        A = J[:, :, idx].reshape(-1, p)
        cov = np.linalg.pinv(A.T @ A, hermitian=True)
        Jr = J[:, :, idx]
        H = np.einsum("nip,pq,njq->nij", Jr, cov, Jr)  # (m, D, D) diagonal blocks of the hat matrix
        M = np.eye(d)[None] - H
        dw = np.linalg.solve(M, r[..., None])[..., 0]  # whitened deleted residuals
        stat = np.einsum("ni,ni->n", r, dw)
        worst = int(np.argmax(stat))
        if stat[worst] <= thr or (rows.size - 1) * d <= p + d:
            break
        removed.append(int(rows[worst]))
        rows = np.delete(rows, worst)
    std = noise.pose_std(robot.pose_units)
    deleted = np.zeros((n, d))
    stat_all = np.zeros(n)
    deleted[rows] = dw * std
    stat_all[rows] = stat
    if removed:
        # Removed rows are judged against the model identified from all the rows kept.
        out = np.array(removed)
        r_out, J_out = _whitened(robot, fit.theta, joints[out], measured[out], noise)
        Jo = J_out[:, :, idx]
        S = np.eye(d)[None] + np.einsum("nip,pq,njq->nij", Jo, cov, Jo)
        deleted[out] = r_out * std
        stat_all[out] = np.einsum("ni,ni->n", r_out, np.linalg.solve(S, r_out[..., None])[..., 0])
    flagged = tuple(sorted(int(i) for i in np.flatnonzero(stat_all > thr)))
    return OutlierReport(deleted, stat_all, thr, flagged)
