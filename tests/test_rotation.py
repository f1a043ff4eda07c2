import numpy as np
from scipy.spatial.transform import Rotation

from calib.rotation import (
    euler_from_matrix,
    euler_from_quaternion,
    matrix_from_quaternion,
    quaternion_from_euler,
    rotation_matrix,
    rotation_matrix_derivatives,
)


def test_matches_fixed_axis_xyz_of_scipy(rng):
    # Rz(gamma) Ry(beta) Rx(alpha) is scipy's extrinsic "xyz": an independent implementation.
    a = rng.uniform(-1.2, 1.2, (50, 3))
    np.testing.assert_allclose(rotation_matrix(a), Rotation.from_euler("xyz", a).as_matrix(), atol=1e-15)


def test_derivatives_against_finite_differences(rng):
    a = rng.uniform(-1, 1, (20, 3))
    d = rotation_matrix_derivatives(a)
    h = 1e-6
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        fd = (rotation_matrix(a + e) - rotation_matrix(a - e)) / (2 * h)
        np.testing.assert_allclose(d[:, k], fd, atol=1e-9)


def test_round_trips(rng):
    a = rng.uniform(-1.5, 1.5, (100, 3))
    np.testing.assert_allclose(euler_from_matrix(rotation_matrix(a)), a, atol=1e-12)
    q = quaternion_from_euler(a)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(matrix_from_quaternion(q), rotation_matrix(a), atol=1e-15)
    np.testing.assert_allclose(euler_from_quaternion(-q), a, atol=1e-12)  # q and -q: same rotation


def test_scipy_quaternion_agrees(rng):
    a = rng.uniform(-1, 1, (10, 3))
    xyzw = Rotation.from_euler("xyz", a).as_quat()
    q = quaternion_from_euler(a)
    sign = np.sign(q[:, :1] * xyzw[:, 3:4])
    np.testing.assert_allclose(q * sign, np.column_stack([xyzw[:, 3], xyzw[:, :3]]), atol=1e-15)
