"""The declared noise of the closure residuals, and the whitening every fit of the discovery
takes (a room of :mod:`calib.effects.discovery`).

The noise of ``r_j`` (C chains) comes from the pose sensor and the joint readings through the
closure Jacobians, ``S_j = dF/dpose Sigma_pose dF/dpose^T + dF/dq Sigma_q dF/dq^T``; every fit
is whitened by it (mm and rad never mixed by a raw norm), so that the sum of squares is
chi-square distributed when the model is right.
"""

from __future__ import annotations

import weakref

import numpy as np

from ..robot import Robot
from .base import EffectData
from .separability import GRAM_MIN_RESIDUALS, GeometryBasis, geometry_basis

__all__ = ["noise_covariance", "closure_noise_covariance", "closure_noise_std", "whitening_matrices", "whiten",
           "free_indices", "geometry_basis_of", "scaled_least_squares"]


def noise_covariance(robot: Robot, jac, data: EffectData) -> np.ndarray:
    """(N, C, C) mm^2, the covariance of each measurement's closure residuals caused by
    the declared noise, through the closure Jacobians ``jac`` (:meth:`Robot.closure_jacobians`)."""
    var = data.noise.pose_std(robot.pose_units) ** 2
    S = np.einsum("nik,k,njk->nij", jac.pose, var, jac.pose)
    if data.noise.joint_std > 0:
        S += data.noise.joint_std ** 2 * jac.joints @ np.swapaxes(jac.joints, 1, 2)
    return S


def closure_noise_covariance(robot: Robot, theta: np.ndarray, data: EffectData) -> np.ndarray:
    """(N, C, C) covariance of each measurement's closure residuals caused by the declared
    noise: pose sensor noise and joint-reading noise through the closure Jacobians, mm^2."""
    return noise_covariance(robot, robot.closure_jacobians(theta, data.joints, data.measured), data)


def closure_noise_std(robot: Robot, theta: np.ndarray, data: EffectData) -> np.ndarray:
    """(N, C) mm, standard deviation of each closure residual caused by the declared noise."""
    return np.sqrt(np.diagonal(closure_noise_covariance(robot, theta, data), axis1=1, axis2=2))


def whitening_matrices(robot: Robot, theta: np.ndarray, data: EffectData) -> np.ndarray:
    """(N, C, C) ``L^-1``, ``L`` the Cholesky factor of each measurement's closure noise
    covariance: ``L^-1 r`` has unit covariance."""
    return np.linalg.inv(np.linalg.cholesky(closure_noise_covariance(robot, theta, data)))


def whiten(winv: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``L^-1 v`` measurement by measurement; ``v`` is (N, C) or (N, C, k)."""
    if v.ndim == 2:
        return np.einsum("nij,nj->ni", winv, v)
    return winv @ v


def free_indices(robot: Robot) -> np.ndarray:
    return np.sort(robot.table.indices(robot.free_default))


_BASES: "weakref.WeakKeyDictionary[EffectData, GeometryBasis | None]" = weakref.WeakKeyDictionary()


def geometry_basis_of(data: EffectData) -> GeometryBasis | None:
    """The determined and held geometric combinations of ``data`` (at ``data.theta``;
    :mod:`calib.effects.separability`), or None: no prior, or every combination determined
    (the fits are then those without a prior, unchanged)."""
    if data.tolerance is None:
        return None
    if data not in _BASES:
        robot = data.robot
        free = free_indices(robot)
        jac = robot.closure_jacobians(data.theta, data.joints, data.measured)
        winv = np.linalg.inv(np.linalg.cholesky(noise_covariance(robot, jac, data)))
        G = whiten(winv, jac.parameters[:, :, free]).reshape(-1, free.size)
        basis = geometry_basis(G, data.tolerance[free], free)
        _BASES[data] = basis if basis.held.shape[1] else None
    return _BASES[data]


def scaled_least_squares(A: np.ndarray, b: np.ndarray, gram: bool | None = None) -> np.ndarray:
    """Least squares ``A x ~ b``, columns scaled; through the Gram matrix with ``gram`` (default:
    above :data:`GRAM_MIN_RESIDUALS` rows)."""
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    As = A / scale
    if (A.shape[0] > GRAM_MIN_RESIDUALS) if gram is None else gram:
        return np.linalg.pinv(As.T @ As, hermitian=True) @ (As.T @ b) / scale
    x, *_ = np.linalg.lstsq(As, b, rcond=None)
    return x / scale
