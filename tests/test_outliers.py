"""The outlier test's backward search (calib.outliers): one row at a time, or every row above the
threshold at once above ONE_AT_A_TIME_MAX_ROWS. Kinematic simulation as tests/test_crossval.py
(the robot's reference errors, 1 um / 1 urad normal noise); the independent truth is the rows
spoiled."""

import numpy as np
import pytest

import calib.outliers
from calib.noise import SensorNoise
from calib.outliers import find_outliers
from calib.robots import ROBOTS, default_robot, reference_errors
from calib.workspace import reachable_poses

NOISE = SensorNoise(1e-3, 1e-6, "normal")
#: Rows moved 50 um along x: 29 standard deviations of a 3-coordinate row's position.
SPOILED = (3, 20, 41)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_above_the_size_every_row_above_the_threshold_goes_at_once(name, monkeypatch):
    """60 rows, three of them 50 um off: the one-at-a-time search (the default at this size) and
    the at-once search (the constant lowered to 40) flag the same rows, the three, and agree on
    every row's statistic to the linearisation's order (both end at a fit without the three);
    ``search`` says which ran."""
    robot = default_robot(name)
    theta = robot.table.nominal + reference_errors(robot, 2)
    poses = reachable_poses(robot, 60, 4, theta=theta)
    joints = robot.inverse_kinematics(theta, poses)
    measured = poses + NOISE.sample(60, 5, robot.pose_units)
    measured[list(SPOILED), 0] += 0.05
    exact = find_outliers(robot, joints, measured, NOISE)
    assert exact.search == "one row at a time" and exact.flagged == SPOILED, exact.verdict
    monkeypatch.setattr(calib.outliers, "ONE_AT_A_TIME_MAX_ROWS", 40)
    fast = find_outliers(robot, joints, measured, NOISE)
    assert fast.search == "every row above the threshold at once (60 rows > ONE_AT_A_TIME_MAX_ROWS = 40)"
    assert fast.flagged == exact.flagged and not fast.misfit, fast.verdict
    clean = np.setdiff1d(np.arange(60), SPOILED)
    np.testing.assert_allclose(fast.statistic[clean], exact.statistic[clean], rtol=1e-3, atol=1e-3)
