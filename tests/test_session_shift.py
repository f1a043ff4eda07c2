"""calib.session_shift: a session's joint zeros and instrument motion, chosen by evidence.

Independent truths: the shifts injected into a machine held fixed (its forward kinematics at the
joints moved, seen through the frame moved), the closure's own identity for the joint zero
parameters, and the chi-square law of an estimate's error under its covariance.
"""

from __future__ import annotations

import numpy as np
import pytest

from calib.measurement import compose, compose_frames
from calib.noise import SensorNoise, chi2_quantile
from calib.robots import ROBOTS
from calib.session_shift import SHIFT_MODELS, fit_session_shift, rereferenced_theta, shift_unknown_names
from calib.workspace import random_poses

#: The instrument's frame as the held machine knows it.
FRAME = np.array([3.0, -2.0, -500.0, 0.03, 0.0, 0.01])
#: The probability below which an estimate's error is called inconsistent with its covariance.
CONSISTENT = 0.999


def _machine(name, rows=8, seed=2):
    robot = ROBOTS[name].default()
    rng = np.random.default_rng(seed)
    theta = robot.table.nominal + rng.normal(0, 0.05, robot.n_parameters) * np.where(
        np.array(robot.table.units) == "mm", 1.0, 1e-3)
    poses = random_poses(rows, seed, robot.workspace_bounds())
    return robot, theta, robot.inverse_kinematics(theta, poses), poses, rng


def _noise(robot):
    return SensorNoise(0.01, 1e-5, "normal")


def _consistent(error, covariance):
    """The estimate's error is a draw of its covariance: its squared Mahalanobis length below the
    chi-square quantile."""
    return float(error @ np.linalg.solve(covariance, error)) < chi2_quantile(CONSISTENT, error.size)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_a_joint_zero_parameter_adds_to_the_joint_reading(name):
    robot, theta, q, poses, rng = _machine(name)
    d = rng.normal(0, 0.5, robot.n_chains) * (1.0 if robot.joint_unit == "mm" else 1e-2)
    moved = rereferenced_theta(robot, theta, d)
    a, b = robot.closure(theta, q + d, poses), robot.closure(moved, q, poses)
    assert np.max(np.abs(a - b)) <= 64 * np.finfo(float).eps * max(1.0, np.max(np.abs(poses)))
    assert len(robot.joint_zero_names) == robot.n_chains


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_a_rehoming_is_found_as_joint_zeros_from_eight_rows(name):
    robot, theta, q, _, rng = _machine(name)
    scale = 1.0 if robot.joint_unit == "mm" else 1e-3
    d = rng.uniform(0.3, 1.5, robot.n_chains) * rng.choice([-1.0, 1.0], robot.n_chains) * scale
    noise = _noise(robot)
    measured = compose(FRAME, robot, robot.forward_kinematics(theta, q + d)) + noise.sample(len(q), 3, robot.pose_units)
    s = fit_session_shift(robot, lambda j: robot.forward_kinematics(theta, j), q, measured, noise, frame=FRAME)
    assert s.chosen == "joint zeros", s.to_dict()["log_evidence"]
    c = robot.n_chains
    assert _consistent(s.zeros - d, s.best.covariance[:c, :c])
    assert s.p_no_shift < 1e-6 and not s.undetermined()


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_an_instrument_moved_is_found_as_the_frames_motion(name):
    robot, theta, q, _, _ = _machine(name)
    motion = np.array([0.5, -0.3, 0.8, 1e-3, -2e-3, 5e-4])
    noise = _noise(robot)
    true = robot.forward_kinematics(theta, q)
    measured = compose(compose_frames(motion, FRAME), robot, true) + noise.sample(len(q), 4, robot.pose_units)
    s = fit_session_shift(robot, lambda j: robot.forward_kinematics(theta, j), q, measured, noise, frame=FRAME)
    assert s.chosen == "instrument frame", s.to_dict()["log_evidence"]
    c = robot.n_chains
    assert _consistent(s.frame_motion - motion, s.best.covariance[c:, c:])


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_nothing_moved_is_said_so(name):
    robot, theta, q, _, _ = _machine(name, rows=12)
    noise = _noise(robot)
    measured = compose(FRAME, robot, robot.forward_kinematics(theta, q)) + noise.sample(len(q), 5, robot.pose_units)
    s = fit_session_shift(robot, lambda j: robot.forward_kinematics(theta, j), q, measured, noise, frame=FRAME)
    assert s.chosen == "none" and not s.shifted
    assert s.p_no_shift > 1 - CONSISTENT
    assert set(s.models) == set(SHIFT_MODELS)
    assert len(shift_unknown_names(robot)) == robot.n_chains + 6


def test_rows_that_do_not_determine_an_offset_say_which():
    """One pose, every joint zero and the frame together: twelve unknowns, six measurements; the
    rows leave some near their priors, and say which."""
    robot, theta, q, _, _ = _machine("hexapod", rows=1)
    noise = _noise(robot)
    measured = compose(FRAME, robot, robot.forward_kinematics(theta, q))
    s = fit_session_shift(robot, lambda j: robot.forward_kinematics(theta, j), q, measured, noise, frame=FRAME,
                          models=("joint zeros and instrument frame",))
    assert s.undetermined(), s.to_dict()
