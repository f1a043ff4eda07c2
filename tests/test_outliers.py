"""The outlier test's backward search (calib.outliers): one row at a time, or every row above the
threshold at once above ONE_AT_A_TIME_MAX_ROWS. Kinematic simulation as tests/test_crossval.py
(the robot's reference errors, 1 um / 1 urad normal noise); the independent truth is the rows
spoiled."""

import numpy as np
import pytest

import calib.outliers
from calib.noise import SensorNoise
from calib.outliers import find_outliers
from calib.robot import pose_jacobian_of_parameters
from calib.robots import ROBOTS, default_robot, reference_errors
from calib.workspace import reachable_poses

NOISE = SensorNoise(1e-3, 1e-6, "normal")
#: Rows moved 50 um along x: 29 standard deviations of a 3-coordinate row's position.
SPOILED = (3, 20, 41)


def spoiled(name: str):
    """``(robot, theta, poses, joints, measured)``: 60 reachable poses of the robot with its
    reference errors, measured with NOISE, the rows SPOILED moved 50 um along x."""
    robot = default_robot(name)
    theta = robot.table.nominal + reference_errors(robot, 2)
    poses = reachable_poses(robot, 60, 4, theta=theta)
    joints = robot.inverse_kinematics(theta, poses)
    measured = poses + NOISE.sample(60, 5, robot.pose_units)
    measured[list(SPOILED), 0] += 0.05
    return robot, theta, poses, joints, measured


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_above_the_size_every_row_above_the_threshold_goes_at_once(name, monkeypatch):
    """60 rows, three of them 50 um off: the one-at-a-time search (the default at this size) and
    the at-once search (the constant lowered to 40) flag the same rows, the three, and agree on
    every row's statistic to the linearisation's order (both end at a fit without the three);
    ``search`` says which ran."""
    robot, theta, poses, joints, measured = spoiled(name)
    exact = find_outliers(robot, joints, measured, NOISE)
    assert exact.search == "one row at a time" and exact.flagged == SPOILED, exact.verdict
    monkeypatch.setattr(calib.outliers, "ONE_AT_A_TIME_MAX_ROWS", 40)
    fast = find_outliers(robot, joints, measured, NOISE)
    assert fast.search == "every row above the threshold at once (60 rows > ONE_AT_A_TIME_MAX_ROWS = 40)"
    assert fast.flagged == exact.flagged and not fast.misfit, fast.verdict
    clean = np.setdiff1d(np.arange(60), SPOILED)
    np.testing.assert_allclose(fast.statistic[clean], exact.statistic[clean], rtol=1e-3, atol=1e-3)


def test_hat_blocks_are_the_diagonal_blocks_of_the_hat_matrix():
    """calib.outliers.hat_blocks against the blocks of ``J cov J^T`` formed whole (independent:
    one dense product), for a positive definite ``cov`` and a rank-deficient one (a gauge-like
    null direction). The two computations of each block differ by rounding: relative to
    ``|J_j|^2 |cov|`` a few times p eps (bound 100 p eps)."""
    rng = np.random.default_rng(7)
    n, d, p = 30, 6, 12
    J = rng.normal(size=(n, d, p))
    M = rng.normal(size=(3 * p, p))
    for cov in (np.linalg.inv(M.T @ M), np.linalg.pinv(M[:, :-1].T @ M[:, :-1])):
        if cov.shape[0] < p:  # rank deficient: the last parameter not seen
            cov = np.pad(cov, ((0, 1), (0, 1)))
        whole = J.reshape(-1, p) @ cov @ J.reshape(-1, p).T
        blocks = calib.outliers.hat_blocks(J, cov)
        bound = 100 * p * np.finfo(float).eps * np.linalg.norm(cov, 2)
        for j in range(n):
            expected = whole[d * j:d * (j + 1), d * j:d * (j + 1)]
            assert np.abs(blocks[j] - expected).max() <= bound * np.sum(J[j] ** 2)


@pytest.mark.parametrize("name", ["hexapod", "delta"])
def test_above_the_size_the_checking_refit_keeps_the_first_jacobian(name, monkeypatch):
    """60 rows, three 50 um off, the at-once search (ONE_AT_A_TIME_MAX_ROWS lowered to 40): with
    REUSED_JACOBIAN_MIN_ROWS lowered to 40 as well the checking refit keeps the first fit's
    Jacobian; ``search`` says so, the rows flagged are the same, and every row's statistic agrees
    with the recomputed Jacobian's to the Jacobian's change over the refit's step (the refit moves
    the estimate by the three rows' pull, about 50 um over a machine of hundreds of mm: 1e-3
    relative bounds it)."""
    robot, theta, poses, joints, measured = spoiled(name)
    monkeypatch.setattr(calib.outliers, "ONE_AT_A_TIME_MAX_ROWS", 40)
    recomputed = find_outliers(robot, joints, measured, NOISE)
    assert "REUSED_JACOBIAN_MIN_ROWS" not in recomputed.search
    monkeypatch.setattr(calib.outliers, "REUSED_JACOBIAN_MIN_ROWS", 40)
    reused = find_outliers(robot, joints, measured, NOISE)
    assert reused.search.endswith("(60 rows > REUSED_JACOBIAN_MIN_ROWS = 40)"), reused.search
    assert reused.flagged == recomputed.flagged == SPOILED, reused.verdict
    np.testing.assert_allclose(reused.statistic, recomputed.statistic, rtol=1e-3, atol=1e-3)
    assert not np.array_equal(reused.statistic, recomputed.statistic)  # the other form ran


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_above_the_size_the_jacobian_kept_as_its_chain_factors_gives_the_same_statistics(name, monkeypatch):
    """60 rows, three 50 um off, the at-once search and the reused Jacobian (their constants lowered
    to 40): with STRUCTURED_JACOBIAN_MIN_ROWS lowered to 40 as well the hexapod's and the 6-RUS's
    Jacobian is kept as its chain factors (``search`` says so; the Delta's closures give no own
    entries: the dense form runs and ``search`` does not say it). The two forms compute the same
    numbers in another order (the kept rows' Gram product as every row's less the left-out rows'),
    so every statistic agrees to rounding carried through the normal equations: relative to
    ``1 + t``, below ``100 kappa eps`` with ``kappa`` the column-scaled condition number of the
    whitened Gram product of the free parameters (measured here from the dense Jacobian of the
    flagged-free fit, independent of the factored form)."""
    robot, theta, poses, joints, measured = spoiled(name)
    for constant in ("ONE_AT_A_TIME_MAX_ROWS", "REUSED_JACOBIAN_MIN_ROWS"):
        monkeypatch.setattr(calib.outliers, constant, 40)
    dense = find_outliers(robot, joints, measured, NOISE)
    assert "STRUCTURED_JACOBIAN_MIN_ROWS" not in dense.search
    monkeypatch.setattr(calib.outliers, "STRUCTURED_JACOBIAN_MIN_ROWS", 40)
    factored = find_outliers(robot, joints, measured, NOISE)
    own = robot.closure_jacobians(theta, joints, poses).own is not None
    assert factored.search.endswith("(60 rows > STRUCTURED_JACOBIAN_MIN_ROWS = 40)") == own, factored.search
    assert factored.flagged == dense.flagged == SPOILED, factored.verdict
    if not own:
        np.testing.assert_array_equal(factored.statistic, dense.statistic)
        return
    assert not np.array_equal(factored.statistic, dense.statistic)  # the other form ran
    std = NOISE.pose_std(robot.pose_units)
    free = robot.table.indices(robot.free_default)  # the fitted columns (a held one may be zero)
    J = pose_jacobian_of_parameters(robot, theta, joints, poses)[:, :, free].reshape(-1, free.size) \
        / np.tile(std, 60)[:, None]
    scale = np.linalg.norm(J, axis=0)
    kappa = np.linalg.cond(J / scale) ** 2
    bound = 100 * kappa * np.finfo(float).eps
    err = np.abs(factored.statistic - dense.statistic) / (1 + dense.statistic)
    assert err.max() <= bound, (err.max(), bound)
    np.testing.assert_allclose(factored.deleted_residuals, dense.deleted_residuals,
                               atol=bound * np.abs(dense.deleted_residuals).max())
