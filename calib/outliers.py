"""Outlier poses: leave-one-out prediction residuals tested against the declared noise.

A grossly wrong row (the paper's row A2) is partly absorbed by a least-squares fit that
includes it, so its own residual understates the problem. Each pose j is therefore predicted
by the model identified *without* it; the deleted residual ``d_j = QM_j - FK(theta_-j, l_j)``
has covariance ``S_j = Sigma_noise + J_j Sigma_theta J_j^T`` (sensor noise plus the
uncertainty of the prediction, propagated through the paper's estimator), and ``d_j^T S_j^-1 d_j`` is chi-square with 6 degrees of
freedom for a consistent row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from .hexapod import Hexapod
from .identification import _check_inputs, identify_paper
from .kinematics import (
    KinematicsError,
    _parameter_jacobian,
    _pose_jacobian,
    forward_kinematics,
    forward_parameter_jacobian,
)
from .noise import SensorNoise

__all__ = ["OutlierReport", "find_outliers"]


@dataclass(frozen=True, eq=False)
class OutlierReport:
    """Leave-one-out consistency of each measured pose.

    Attributes:
        deleted_residuals: (N, 6) mm and rad, measured minus leave-one-out prediction.
        statistic: (N,) ``d^T S^-1 d``, chi-square(6) for a consistent row.
        threshold: the chi-square(6) quantile at ``1 - alpha``.
        flagged: indices of rows whose statistic exceeds the threshold.
    """

    deleted_residuals: np.ndarray
    statistic: np.ndarray
    threshold: float
    flagged: tuple


def _paper_estimator_covariance(hexapod: Hexapod, measured: np.ndarray, var: np.ndarray) -> np.ndarray:
    """(42, 42) covariance of :func:`identify_paper`'s estimate caused by pose noise of variance
    ``var`` (6,), by linear propagation through the estimator itself.

    Leg i's estimate moves by ``-pinv(J_i) dr_i`` and its residuals by ``dr_ij = Jp_ij . dQ_j``
    (pose Jacobian row of leg i at pose j), so all six legs share each pose's noise.
    """
    m = measured.shape[0]
    Jl = _parameter_jacobian(hexapod, measured)  # (m, 6, 7)
    Jp = _pose_jacobian(hexapod, measured)  # (m, 6, 6)
    G = np.zeros((42, m, 6))
    for leg in range(6):
        pinv = np.linalg.pinv(Jl[:, leg])  # (7, m)
        G[leg * 7:(leg + 1) * 7] = -pinv[:, :, None] * Jp[None, :, leg, :]
    G = G.reshape(42, m * 6)
    return (G * np.tile(var, m)) @ G.T


def find_outliers(nominal: Hexapod, commanded: np.ndarray, measured: np.ndarray, noise: SensorNoise,
                  *, alpha: float = 1e-3) -> OutlierReport:
    """Flag measured poses inconsistent with the rest (leave-one-out, chi-square test).

    Args:
        nominal: nominal parameter set.
        commanded: (N, 6) commanded leg lengths, mm; N >= 8 (each fit leaves one row out).
        measured: (N, 6) measured poses, mm and rad.
        noise: declared sensor noise (zero components floored as in ``SensorNoise.weights``).
        alpha: false-alarm probability per consistent row.
    """
    commanded, measured = _check_inputs(nominal, commanded, measured)
    n = measured.shape[0]
    if n < 8:
        raise ValueError(f"outlier detection needs at least 8 poses (7 per fit plus the one left out), got {n}")
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    w = noise.weights()
    thr = float(chi2.ppf(1 - alpha, 6))
    # Backward search: a gross row also spoils every leave-one-out fit that contains it
    # (swamping), so remove the worst row and test again until all remaining rows pass.
    rows = np.arange(n)
    removed: list[int] = []
    while True:
        res = [_deleted(nominal, commanded, measured, np.delete(rows, k), rows[k], w) for k in range(rows.size)]
        stat = np.array([r[1] for r in res])
        worst = int(np.argmax(stat))
        if stat[worst] <= thr or rows.size <= 8:
            break
        removed.append(int(rows[worst]))
        rows = np.delete(rows, worst)
    d_all = np.zeros((n, 6))
    stat_all = np.zeros(n)
    for k, j in enumerate(rows):
        d_all[j], stat_all[j] = res[k]
    # Removed rows are judged against the model identified from all the rows kept.
    for j in removed:
        d_all[j], stat_all[j] = _deleted(nominal, commanded, measured, rows, j, w)
    flagged = tuple(sorted(int(i) for i in np.flatnonzero(stat_all > thr)))
    return OutlierReport(d_all, stat_all, thr, flagged)


def _deleted(nominal, commanded, measured, keep, j, w) -> tuple[np.ndarray, float]:
    """Residual of row ``j`` predicted by the model identified from rows ``keep``, and its
    chi-square statistic."""
    fit = identify_paper(nominal, commanded[keep], measured[keep])
    try:
        pred = forward_kinematics(fit.hexapod, commanded[j:j + 1], initial=measured[j], stroke_mm=None)
    except KinematicsError:
        return np.full(6, np.nan), np.inf
    d = measured[j] - pred[0]
    cov_theta = _paper_estimator_covariance(fit.hexapod, measured[keep], 1.0 / w**2)
    Jj = forward_parameter_jacobian(fit.hexapod, pred)[0]
    S = np.diag(1.0 / w**2) + Jj @ cov_theta @ Jj.T
    return d, float(d @ np.linalg.solve(S, d))
