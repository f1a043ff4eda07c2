"""calib.batched_lu: the batched factor-once solver against LAPACK (numpy.linalg.solve)."""

import numpy as np
import pytest

from calib.batched_lu import LARGEST_MULTIPLIER, SMALLEST_BATCH_ENTRIES, BatchedLU, solve_stacked
from calib.robots import ROBOTS, default_robot, reference_errors
from calib.workspace import reachable_poses


def lapack(A, b):
    return np.linalg.solve(A, b[..., None])[..., 0]


def relative_error(x, reference):
    return float(np.max(np.abs(x - reference) / np.abs(reference).max(axis=1, keepdims=True)))


@pytest.mark.parametrize("n", [2, 3, 6, 9])
def test_solves_like_lapack_for_many_right_hand_sides(n):
    rng = np.random.default_rng(n)
    m = 2 * SMALLEST_BATCH_ENTRIES // n ** 2  # batched, not the small-stack path
    A = rng.normal(size=(m, n, n)) + 2.0 * n * np.eye(n)  # no pivoting needed
    factors = BatchedLU(A)
    assert factors.fallback.mean() < 0.5  # most of them eliminated here
    for seed in range(3):  # the same factors, new right-hand sides
        b = np.random.default_rng(100 + seed).normal(size=(m, n))
        x = factors.solve(b)
        assert relative_error(x, lapack(A, b)) < 1e-11
        assert np.max(np.abs(np.einsum("mij,mj->mi", A, x) - b)) < 1e-11 * np.abs(b).max()


def test_matrices_that_need_pivoting_go_to_lapack_and_are_solved_right():
    rng = np.random.default_rng(1)
    n, m = 6, 1024
    A = rng.normal(size=(m, n, n)) + 2.0 * n * np.eye(n)  # no pivoting needed
    # Every third matrix with its first column tiny on the shared pivot row: unpivoted
    # elimination in the first matrix's row order would grow without bound.
    order_row = int(np.argmax(np.abs(A[0, :, 0])))
    A[1::3, order_row, 0] = 1e-14
    factors = BatchedLU(A)
    assert factors.fallback[1::3].all()
    b = rng.normal(size=(m, n))
    assert relative_error(factors.solve(b), lapack(A, b)) < 1e-10
    # A permutation matrix in the first place: the shared order is its own pivoting order.
    P = np.eye(n)[rng.permutation(n)]
    A[0] = P
    b = rng.normal(size=(m, n))
    x = BatchedLU(A).solve(b)
    np.testing.assert_allclose(x[0], P.T @ b[0], rtol=0, atol=1e-15)
    assert relative_error(x, lapack(A, b)) < 1e-10


def test_kept_factors_have_small_multipliers():
    rng = np.random.default_rng(2)
    A = rng.normal(size=(2048, 6, 6))
    factors = BatchedLU(A)
    assert 0 < factors.fallback.sum() < 2048  # random matrices: some kept, some not
    b = rng.normal(size=(2048, 6))
    x = factors.solve(b)
    residual = np.abs(np.einsum("mij,mj->mi", A, x) - b).max(axis=1)
    scale = np.abs(A).max(axis=(1, 2)) * np.abs(x).max(axis=1)
    # backward stable: n (1 + m)^n unit round-offs at most
    assert np.all(residual <= 6 * (1 + LARGEST_MULTIPLIER) ** 6 * np.finfo(float).eps * scale)


def test_strided_views_and_the_small_stack_path():
    rng = np.random.default_rng(3)
    T = rng.normal(size=(6, 6, 4096)) + 3.0 * np.eye(6)[:, :, None]
    A = T.transpose(2, 0, 1)  # a view, as the hexapod returns its pose Jacobian
    b = rng.normal(size=(4096, 6))
    before = T.copy()
    assert relative_error(BatchedLU(A).solve(b), lapack(A, b)) < 1e-11
    np.testing.assert_array_equal(T, before)  # not modified
    small = BatchedLU(A[:10])
    assert small.fallback.all()
    np.testing.assert_array_equal(small.solve(b[:10]), lapack(A[:10], b[:10]))


@pytest.mark.parametrize("where", ["first", "later"])
def test_singular_matrix_raises_like_numpy(where):
    rng = np.random.default_rng(4)
    A = rng.normal(size=(1024, 6, 6)) + 3.0 * np.eye(6)
    k = 0 if where == "first" else 700
    A[k, 3] = 0.0  # a zero row: exactly singular
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.solve(A[k], np.ones(6))
    with pytest.raises(np.linalg.LinAlgError):
        BatchedLU(A).solve(rng.normal(size=(1024, 6)))


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_pose_jacobians_of_every_robot(name):
    """The forward kinematics' systems: every robot's pose Jacobians over its workspace."""
    robot = default_robot(name)
    theta = robot.table.nominal + reference_errors(robot, 0)
    d = robot.pose_dim
    poses = reachable_poses(robot, 2 * SMALLEST_BATCH_ENTRIES // d ** 2, 5, theta=theta)
    joints = robot.inverse_kinematics(theta, poses)
    r, J = robot.closure_and_pose_jacobian(theta, joints, poses)
    b = np.random.default_rng(6).normal(size=r.shape)
    assert relative_error(BatchedLU(J).solve(b), lapack(J, b)) < 1e-10


@pytest.mark.parametrize("n", [3, 6])
def test_inverse_columns_are_lapacks_inverse(n):
    """The inverse column by column, structure-of-arrays (X[j, i] = inv(A)[i, j]), against
    numpy.linalg.inv: a batched stack with some matrices handed to LAPACK, a small stack, and a
    small stack asked for its inverse up front (whose solve then multiplies by it)."""
    rng = np.random.default_rng(10 + n)
    m = 2 * SMALLEST_BATCH_ENTRIES // n ** 2
    A = rng.normal(size=(m, n, n)) + 2.0 * n * np.eye(n)
    order_row = int(np.argmax(np.abs(A[0, :, 0])))
    A[1::5, order_row, 0] = 1e-14  # unpivoted elimination in the shared order would fail these
    factors = BatchedLU(A)
    assert factors.fallback[1::5].all() and not factors.fallback.all()
    reference = np.linalg.inv(A)
    X = factors.inverse_columns()
    assert X.shape == (n, n, m)
    scale = np.abs(reference).max(axis=(1, 2))
    assert np.max(np.abs(X.transpose(2, 1, 0) - reference).max(axis=(1, 2)) / scale) < 1e-11
    small = A[:10]
    for f in (BatchedLU(small), BatchedLU(small, inverse=True)):
        np.testing.assert_array_equal(f.inverse_columns().transpose(2, 1, 0), np.linalg.inv(small))
    b = rng.normal(size=(10, n))
    assert relative_error(BatchedLU(small, inverse=True).solve(b), lapack(small, b)) < 1e-11


@pytest.mark.parametrize("k", [1, 6, 42])
def test_stacked_right_hand_sides_solve_like_lapack(k):
    """solve_stacked (the inverse by the kept factors times B) against numpy.linalg.solve, with
    some matrices handed to LAPACK: each solution within cond(A_m) unit round-offs (times a small
    factor for n and the multipliers) of LAPACK's, relative to its largest entry; the small-stack
    path is LAPACK's, bit for bit; a singular matrix raises as numpy does."""
    rng = np.random.default_rng(20 + k)
    n, m = 6, 2 * SMALLEST_BATCH_ENTRIES // 36
    A = rng.normal(size=(m, n, n)) + 2.0 * n * np.eye(n)
    order_row = int(np.argmax(np.abs(A[0, :, 0])))
    A[1::7, order_row, 0] = 1e-14
    B = rng.normal(size=(m, n, k))
    X, reference = solve_stacked(A, B), np.linalg.solve(A, B)
    cond = np.linalg.cond(A)
    bound = 6 * (1 + LARGEST_MULTIPLIER) ** 6 * np.finfo(float).eps * cond
    error = np.abs(X - reference).max(axis=(1, 2)) / np.abs(reference).max(axis=(1, 2))
    assert np.all(error <= bound)
    np.testing.assert_array_equal(solve_stacked(A[:10], B[:10]), np.linalg.solve(A[:10], B[:10]))
    A[500, 2] = 0.0
    with pytest.raises(np.linalg.LinAlgError):
        solve_stacked(A, B)
