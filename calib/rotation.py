"""Rotations in the project's convention: R = Rz(gamma) @ Ry(beta) @ Rx(alpha).

Angles are ``[alpha, beta, gamma]`` in rad (fixed-axis X-Y-Z, "roll-pitch-yaw"). This is the
convention that reproduces the hexapod paper's Table 4 (its printed Eq. 2 does not; see
``shared/reference/README.md``). Quaternions here are scalar-first ``[w, x, y, z]`` as in MuJoCo.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "rotation_matrix",
    "rotation_entries",
    "length_pose_jacobian",
    "rotation_matrix_derivatives",
    "euler_from_matrix",
    "quaternion_from_euler",
    "euler_from_quaternion",
    "matrix_from_quaternion",
    "matrix_from_rotation_vector",
]


def rotation_matrix(angles: np.ndarray) -> np.ndarray:
    """Rotation matrices from angles.

    Args:
        angles: (..., 3) ``[alpha, beta, gamma]`` in rad.

    Returns:
        (..., 3, 3) ``R = Rz(gamma) Ry(beta) Rx(alpha)``, mapping platform-frame vectors to the
        base frame.
    """
    a = np.asarray(angles, dtype=float)
    ca, cb, cg = np.cos(a[..., 0]), np.cos(a[..., 1]), np.cos(a[..., 2])
    sa, sb, sg = np.sin(a[..., 0]), np.sin(a[..., 1]), np.sin(a[..., 2])
    R = np.empty(a.shape[:-1] + (3, 3))
    R[..., 0, 0] = cg * cb
    R[..., 0, 1] = cg * sb * sa - sg * ca
    R[..., 0, 2] = cg * sb * ca + sg * sa
    R[..., 1, 0] = sg * cb
    R[..., 1, 1] = sg * sb * sa + cg * ca
    R[..., 1, 2] = sg * sb * ca - cg * sa
    R[..., 2, 0] = -sb
    R[..., 2, 1] = cb * sa
    R[..., 2, 2] = cb * ca
    return R


def rotation_entries(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Structure-of-arrays rotations, for kinematics vectorised over poses (each entry one
    contiguous row of N values).

    Args:
        angles: (3, N) ``[alpha, beta, gamma]`` rows, rad.

    Returns:
        ``(R, c, s)``: (3, 3, N) ``R[i, k]`` the entries of ``Rz(gamma) Ry(beta) Rx(alpha)``;
        (3, N) the angles' cosines and sines.
    """
    c, s = np.cos(angles), np.sin(angles)
    ca, cb, cg = c
    sa, sb, sg = s
    sbsa, sbca = sb * sa, sb * ca
    R = np.empty((3, 3) + c.shape[1:])
    R[0, 0], R[0, 1], R[0, 2] = cg * cb, cg * sbsa - sg * ca, cg * sbca + sg * sa
    R[1, 0], R[1, 1], R[1, 2] = sg * cb, sg * sbsa + cg * ca, sg * sbca - cg * sa
    R[2, 0], R[2, 1], R[2, 2] = -sb, cb * sa, cb * ca
    return R, c, s


def length_pose_jacobian(u: np.ndarray, w: np.ndarray, R: np.ndarray, cos_gamma: np.ndarray,
                         sin_gamma: np.ndarray) -> np.ndarray:
    """(C, 6, N) the derivative of C lengths with respect to the platform pose, structure-of-arrays.

    Each length runs along the unit vector ``u`` (3, C, N) to a platform point ``R P`` whose
    rotated offset is ``w`` (3, C, N); ``R`` (3, 3, N) and the cosine and sine of gamma (N,) are
    :func:`rotation_entries`'. With ``m = w x u``: ``d/d t = u``, ``d/d alpha = (R e_x) . m``,
    ``d/d beta = (Rz e_y) . m``, ``d/d gamma = e_z . m`` (``dR/d alpha = R [e_x]x``,
    ``dR/d beta = [Rz e_y]x R``, ``dR/d gamma = [e_z]x R``): a hexapod's legs, a 6-RUS's rods.
    """
    u0, u1, u2 = u
    w0, w1, w2 = w
    J = np.empty((u.shape[1], 6, u.shape[2]))
    J[:, 0:3] = u.transpose(1, 0, 2)
    mx = w1 * u2 - w2 * u1
    my = w2 * u0 - w0 * u2
    mz = w0 * u1 - w1 * u0
    J[:, 3] = R[0, 0] * mx + R[1, 0] * my + R[2, 0] * mz
    J[:, 4] = cos_gamma * my - sin_gamma * mx
    J[:, 5] = mz
    return J


def _elementary(axis: int, t: np.ndarray, derivative: bool) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    M = np.zeros(t.shape + (3, 3))
    i, j = [(1, 2), (0, 2), (0, 1)][axis]
    if derivative:
        # d/dt of the elementary rotation: the fixed axis row/column vanishes.
        M[..., i, i] = -s
        M[..., j, j] = -s
        M[..., i, j] = -c
        M[..., j, i] = c
    else:
        M[..., axis, axis] = 1.0
        M[..., i, i] = c
        M[..., j, j] = c
        M[..., i, j] = -s
        M[..., j, i] = s
    if axis == 1:
        # Ry has the sine signs the other way round: [[c, 0, s], [0, 1, 0], [-s, 0, c]].
        M[..., i, j], M[..., j, i] = M[..., j, i].copy(), M[..., i, j].copy()
    return M


def rotation_matrix_derivatives(angles: np.ndarray) -> np.ndarray:
    """Partial derivatives of :func:`rotation_matrix`.

    Args:
        angles: (..., 3) ``[alpha, beta, gamma]`` in rad.

    Returns:
        (..., 3, 3, 3): entry ``[..., k, :, :]`` is dR/d(angle k), in 1/rad.
    """
    a = np.asarray(angles, dtype=float)
    Rx, Ry, Rz = (_elementary(k, a[..., k], False) for k in range(3))
    dRx, dRy, dRz = (_elementary(k, a[..., k], True) for k in range(3))
    out = np.empty(a.shape[:-1] + (3, 3, 3))
    out[..., 0, :, :] = Rz @ Ry @ dRx
    out[..., 1, :, :] = Rz @ dRy @ Rx
    out[..., 2, :, :] = dRz @ Ry @ Rx
    return out


def euler_from_matrix(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotation_matrix` for |beta| < pi/2.

    Args:
        R: (..., 3, 3) rotation matrices.

    Returns:
        (..., 3) ``[alpha, beta, gamma]`` in rad.
    """
    R = np.asarray(R, dtype=float)
    alpha = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    beta = np.arctan2(-R[..., 2, 0], np.hypot(R[..., 0, 0], R[..., 1, 0]))
    gamma = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([alpha, beta, gamma], axis=-1)


def matrix_from_quaternion(q: np.ndarray) -> np.ndarray:
    """Rotation matrices from unit quaternions.

    Args:
        q: (..., 4) scalar-first ``[w, x, y, z]``; normalised here.

    Returns:
        (..., 3, 3) rotation matrices.
    """
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def matrix_from_rotation_vector(v: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of rotation vectors ``v`` (..., 3), rad: the turn by ``|v|``
    about ``v`` (the quaternion ``[cos |v|/2, sin(|v|/2) v/|v|]``, exact at ``v = 0``)."""
    v = np.asarray(v, dtype=float)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half_sinc = 0.5 * np.sinc(angle / (2 * np.pi))  # sin(|v|/2) / |v|
    return matrix_from_quaternion(np.concatenate([np.cos(angle / 2), half_sinc * v], axis=-1))


def euler_from_quaternion(q: np.ndarray) -> np.ndarray:
    """Angles ``[alpha, beta, gamma]`` (rad) from (..., 4) ``[w, x, y, z]`` quaternions."""
    return euler_from_matrix(matrix_from_quaternion(q))


def quaternion_from_euler(angles: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) ``[w, x, y, z]`` of ``Rz(gamma) Ry(beta) Rx(alpha)``."""
    a = np.asarray(angles, dtype=float) / 2.0
    ca, cb, cg = np.cos(a[..., 0]), np.cos(a[..., 1]), np.cos(a[..., 2])
    sa, sb, sg = np.sin(a[..., 0]), np.sin(a[..., 1]), np.sin(a[..., 2])
    w = cg * cb * ca + sg * sb * sa
    x = cg * cb * sa - sg * sb * ca
    y = cg * sb * ca + sg * cb * sa
    z = sg * cb * ca - cg * sb * sa
    return np.stack([w, x, y, z], axis=-1)
