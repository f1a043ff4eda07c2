"""Hexapod inverse and forward kinematics and their analytic Jacobians.

Pure functions of a :class:`~calib.hexapod.Hexapod` parameter set and (N, 6) pose arrays
``[x, y, z, alpha, beta, gamma]`` (mm, rad; platform frame relative to the base frame,
``R = Rz(gamma) Ry(beta) Rx(alpha)``). A *commanded* leg length is the number the controller
sends; the leg of the machine is then ``commanded + dl`` long (see :mod:`calib.hexapod`).
"""

from __future__ import annotations

import numpy as np

from ._validate import as_array, as_poses
from .hexapod import Hexapod
from .rotation import rotation_matrix, rotation_matrix_derivatives

__all__ = [
    "KinematicsError",
    "leg_vectors",
    "inverse_kinematics",
    "pose_jacobian",
    "parameter_jacobian",
    "forward_kinematics",
    "forward_parameter_jacobian",
]

#: Default stroke of each leg about its home length, mm (documented workspace limit).
DEFAULT_STROKE_MM = 50.0
# Condition number beyond which the 6x6 pose Jacobian is treated as singular.
_SINGULAR_COND = 1e5


class KinematicsError(ValueError):
    """A pose or set of leg lengths the machine cannot reach, or a singular configuration.

    Attributes:
        index: index of the first offending pose / row of leg lengths.
    """

    def __init__(self, message: str, index: int):
        super().__init__(message)
        self.index = index


def _leg_vectors(hexapod: Hexapod, poses: np.ndarray):
    R = rotation_matrix(poses[:, 3:6])
    P_base = np.einsum("nij,lj->nli", R, hexapod.platform_joints)
    L = P_base + poses[:, None, 0:3] - hexapod.base_joints[None]
    return L, R


def leg_vectors(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    """Leg vectors from base joint to platform joint, ``L_i = R P_i + OP - B_i`` (Eq. 1).

    Args:
        hexapod: parameter set (its actual, error-carrying joints are used).
        poses: (N, 6) platform poses, mm and rad.

    Returns:
        (N, 6, 3) mm, in the base frame.
    """
    return _leg_vectors(hexapod, as_poses(poses))[0]


def _commanded(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    L, _ = _leg_vectors(hexapod, poses)
    return np.linalg.norm(L, axis=-1) - hexapod.leg_offsets[None]


def _check_stroke(hexapod: Hexapod, lengths: np.ndarray, stroke: float | None, what: str) -> None:
    if stroke is None:
        return
    dev = np.abs(lengths - hexapod.geometry.home_lengths[None])
    bad = np.argwhere(dev > stroke)
    if bad.size:
        n, leg = (int(v) for v in bad[0])
        raise KinematicsError(
            f"{what} {n} is unreachable: leg {leg + 1} needs {lengths[n, leg]:.6f} mm, outside "
            f"the stroke {hexapod.geometry.home_lengths[leg]:.3f} +- {stroke:g} mm",
            n,
        )


def inverse_kinematics(
    hexapod: Hexapod, poses: np.ndarray, *, stroke_mm: float | None = DEFAULT_STROKE_MM
) -> np.ndarray:
    """Commanded leg lengths that bring the machine to the given poses.

    Args:
        hexapod: parameter set believed by the controller.
        poses: (N, 6) target poses, mm and rad.
        stroke_mm: legs must stay within ``home length +- stroke_mm``; None disables the check.

    Returns:
        (N, 6) commanded leg lengths, mm: ``|R P_i + OP - B_i| - dl_i``.

    Raises:
        KinematicsError: a pose needs a leg outside its stroke (names the pose and the leg).
    """
    poses = as_poses(poses)
    lengths = _commanded(hexapod, poses)
    _check_stroke(hexapod, lengths, stroke_mm, "pose")
    return lengths


def _unit_legs(hexapod: Hexapod, poses: np.ndarray):
    L, R = _leg_vectors(hexapod, poses)
    norm = np.linalg.norm(L, axis=-1, keepdims=True)
    return L / norm, R, norm[..., 0]


def _pose_jacobian(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    u, _, _ = _unit_legs(hexapod, poses)
    dR = rotation_matrix_derivatives(poses[:, 3:6])  # (N, 3, 3, 3)
    dP = np.einsum("nkij,lj->nlki", dR, hexapod.platform_joints)  # (N, 6 legs, 3 angles, 3)
    J = np.empty(poses.shape[:1] + (6, 6))
    J[:, :, 0:3] = u
    J[:, :, 3:6] = np.einsum("nli,nlki->nlk", u, dP)
    return J


def pose_jacobian(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    """Jacobian of commanded leg lengths with respect to the pose.

    Args:
        hexapod: parameter set.
        poses: (N, 6) poses, mm and rad.

    Returns:
        (N, 6, 6): ``[n, i, k] = d l_i / d pose_k``; columns 0-2 dimensionless (mm/mm),
        columns 3-5 in mm/rad.
    """
    return _pose_jacobian(hexapod, as_poses(poses))


def _parameter_jacobian(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    u, R, _ = _unit_legs(hexapod, poses)
    J = np.empty(poses.shape[:1] + (6, 7))
    J[:, :, 0:3] = -u
    J[:, :, 3] = -1.0
    J[:, :, 4:7] = np.einsum("nji,nlj->nli", R, u)  # R^T u
    return J


def parameter_jacobian(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    """Jacobian of each commanded leg length with respect to that leg's 7 errors.

    This is the per-leg identification matrix of the paper's Section 3: leg i depends only
    on its own ``dXB dYB dZB dl dXP dYP dZP``.

    Args:
        hexapod: parameter set at which to linearise.
        poses: (N, 6) poses, mm and rad.

    Returns:
        (N, 6, 7) dimensionless (mm/mm): ``[n, i, k] = d l_i / d errors[i, k]``.
    """
    return _parameter_jacobian(hexapod, as_poses(poses))


def forward_kinematics(
    hexapod: Hexapod,
    lengths: np.ndarray,
    *,
    initial: np.ndarray | None = None,
    tol: float = 1e-11,
    max_iter: int = 50,
    stroke_mm: float | None = DEFAULT_STROKE_MM,
) -> np.ndarray:
    """Poses reached when the given leg lengths are commanded (Newton, analytic Jacobian).

    Args:
        hexapod: parameter set of the machine (actual or believed).
        lengths: (N, 6) commanded leg lengths, mm.
        initial: (N, 6) or (6,) starting poses; default the geometry's home pose. Newton's
            method finds the assembly mode nearest the start.
        tol: convergence when every leg-length residual is below ``tol`` mm.
        max_iter: Newton iterations before giving up.
        stroke_mm: reject lengths outside ``home +- stroke_mm``; None disables the check.

    Returns:
        (N, 6) poses, mm and rad.

    Raises:
        KinematicsError: lengths outside the stroke, a singular configuration met, or no
            convergence; the message names the first offending row.
    """
    lengths = as_array(lengths, "lengths", (-1, 6))
    _check_stroke(hexapod, lengths, stroke_mm, "row of leg lengths")
    n = lengths.shape[0]
    if initial is None:
        poses = np.tile(hexapod.geometry.home_pose, (n, 1))
    else:
        init = np.asarray(initial, dtype=float)
        poses = np.tile(as_array(init, "initial", (6,)), (n, 1)) if init.ndim == 1 else \
            as_array(init, "initial", (n, 6)).copy()
    # Singularity is judged on the Jacobian with its angle columns scaled by the platform
    # radius, so that the threshold does not depend on the units of the pose coordinates.
    scale = np.r_[np.ones(3), np.full(3, 1.0 / np.linalg.norm(hexapod.platform_joints, axis=1).mean())]
    active = np.arange(n)
    for _ in range(max_iter):
        p = poses[active]
        r = _commanded(hexapod, p) - lengths[active]
        J = _pose_jacobian(hexapod, p)
        done = np.max(np.abs(r), axis=1) <= tol
        # Singularity is checked where a row converges (an SVD per row, so only once); on the
        # way there a near-singular Jacobian shows up as divergence or non-convergence.
        if np.any(done):
            cond = np.linalg.cond(J[done] * scale)
            singular = ~(cond < _SINGULAR_COND)
            if np.any(singular):
                k = int(active[done][np.argmax(singular)])
                raise KinematicsError(
                    f"forward kinematics met a singular configuration at row {k} (scaled condition "
                    f"number of the pose Jacobian {cond[np.argmax(singular)]:.3g})", k)
        active, p, r, J = active[~done], p[~done], r[~done], J[~done]
        if active.size == 0:
            return poses
        try:
            poses[active] = p - np.linalg.solve(J, r[..., None])[..., 0]
        except np.linalg.LinAlgError:
            bad = np.linalg.matrix_rank(J * scale) < 6
            k = int(active[np.argmax(bad)])
            raise KinematicsError(f"forward kinematics met a singular configuration at row {k}", k) from None
        if not np.all(np.isfinite(poses[active])):
            k = int(active[np.argmax(~np.all(np.isfinite(poses[active]), axis=1))])
            raise KinematicsError(f"forward kinematics diverged at row {k}", k)
    k = int(active[0])
    raise KinematicsError(
        f"forward kinematics did not converge for row {k} in {max_iter} iterations "
        f"(lengths {np.array2string(lengths[k], precision=4)} mm): no assembly near the start pose",
        k,
    )


def forward_parameter_jacobian(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    """Sensitivity of the reached pose to the 42 errors at fixed commanded lengths.

    By the implicit function theorem on ``l(pose, errors) = const``:
    ``d pose / d errors = -(d l / d pose)^-1 (d l / d errors)``.

    Args:
        hexapod: parameter set.
        poses: (N, 6) poses the machine reached (its forward kinematics), mm and rad.

    Returns:
        (N, 6, 42): rows 0-2 in mm/mm, rows 3-5 in rad/mm, columns in
        :func:`~calib.hexapod.parameter_table` order.
    """
    poses = as_poses(poses)
    Jp = _pose_jacobian(hexapod, poses)
    Jl = _parameter_jacobian(hexapod, poses)
    n = poses.shape[0]
    Jt = np.zeros((n, 6, 42))
    for leg in range(6):
        Jt[:, leg, leg * 7:(leg + 1) * 7] = Jl[:, leg]
    return -np.linalg.solve(Jp, Jt)
