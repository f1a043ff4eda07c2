"""The contract every registered robot keeps (one module, parametrised over the registry)."""

from __future__ import annotations

import numpy as np
import pytest

from calib.engine import gauge_representative, identify_chainwise, identify_forward
from calib.noise import SensorNoise
from calib.robot import KinematicsError, check_joint_limits, pose_jacobian_of_parameters
from calib.robots import ROBOTS, default_robot, robot_from_description, uniform_errors
from calib.workspace import reachable_poses

NAMES = sorted(ROBOTS)


def _machine(name: str, seed: int = 1):
    robot = default_robot(name)
    theta = robot.table.nominal + uniform_errors(robot, seed, 0.5, np.deg2rad(0.5))
    return robot, theta


@pytest.mark.parametrize("name", NAMES)
def test_ik_then_fk_returns_the_pose(name):
    robot, theta = _machine(name)
    poses = reachable_poses(robot, 200, 0, theta=theta)
    joints = robot.inverse_kinematics(theta, poses)
    back = robot.forward_kinematics(theta, joints)  # from the home pose
    assert np.abs(back - poses)[:, ~robot.angle_pose_mask].max() < 1e-9
    assert np.abs(back - poses)[:, robot.angle_pose_mask].max(initial=0.0) < 1e-11
    assert np.abs(robot.closure(theta, joints, poses)).max() < 1e-9


@pytest.mark.parametrize("name", NAMES)
def test_closure_jacobians_match_finite_differences(name):
    robot, theta = _machine(name)
    poses = reachable_poses(robot, 5, 2, theta=theta)
    joints = robot.inverse_kinematics(theta, poses) + 1e-3  # off the closure on purpose
    jac = robot.closure_jacobians(theta, joints, poses)
    f = lambda th, q, x: robot.closure(th, q, x)  # noqa: E731

    def fd(vary, x0, h):
        cols = []
        for k in range(x0.shape[-1]):
            dx = np.zeros_like(x0)
            dx[..., k] = h
            cols.append((vary(x0 + dx) - vary(x0 - dx)) / (2 * h))
        return np.stack(cols, axis=-1)

    np.testing.assert_allclose(jac.pose, fd(lambda x: f(theta, joints, x), poses, 1e-6), atol=1e-6)
    np.testing.assert_allclose(jac.joints, fd(lambda q: f(theta, q, poses), joints, 1e-6), atol=1e-6)
    jp = np.stack([(f(theta + d, joints, poses) - f(theta - d, joints, poses)) / 2e-6
                   for d in np.eye(theta.size) * 1e-6], axis=-1)
    np.testing.assert_allclose(jac.parameters, jp, atol=1e-6)


@pytest.mark.parametrize("name", NAMES)
def test_forward_parameter_jacobian_matches_finite_differences_of_fk(name):
    robot, theta = _machine(name)
    poses = reachable_poses(robot, 4, 3, theta=theta)
    joints = robot.inverse_kinematics(theta, poses)
    analytic = pose_jacobian_of_parameters(robot, theta, joints, poses)
    h = 1e-6
    numeric = np.stack([(robot.forward_kinematics(theta + d, joints, initial=poses)
                         - robot.forward_kinematics(theta - d, joints, initial=poses)) / (2 * h)
                        for d in np.eye(theta.size) * h], axis=-1)
    np.testing.assert_allclose(analytic, numeric, atol=1e-6)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("method", ["forward", "chainwise"])
def test_noise_free_kinematic_identification_recovers_the_identifiable_part(name, method):
    robot, theta = _machine(name, seed=4)
    poses = reachable_poses(robot, 40, 5, theta=theta)
    joints = robot.inverse_kinematics(robot.table.nominal, poses)
    measured = robot.forward_kinematics(theta, joints, initial=poses)
    noise = SensorNoise(1e-3, 1e-6, "normal")
    fit = identify_forward(robot, joints, measured, noise) if method == "forward" else \
        identify_chainwise(robot, joints, measured, noise, solver="lm")
    truth = gauge_representative(robot, theta)
    size = np.abs(truth - robot.table.nominal).max()
    assert fit.success, fit.message
    assert np.abs(fit.theta - truth).max() < 1e-6 * size


@pytest.mark.parametrize("name", NAMES)
def test_description_round_trip_and_unreachable_pose_named(name):
    robot = default_robot(name)
    again = robot_from_description(name, robot.description())
    np.testing.assert_array_equal(again.table.nominal, robot.table.nominal)
    assert again.table.names == robot.table.names
    far = robot.workspace_bounds()[:, 1] + 5 * robot.length_scale_mm * (~robot.angle_pose_mask)
    # A pose out of reach is refused naming its row, by the kinematics or by the joint limits.
    with pytest.raises(KinematicsError) as info:
        joints = robot.inverse_kinematics(robot.table.nominal, np.vstack([robot.home_pose, far]))
        check_joint_limits(robot, joints, "pose")
    assert info.value.index == 1


@pytest.mark.parametrize("name", NAMES)
def test_parameter_table_addresses_by_name(name):
    robot = default_robot(name)
    t = robot.table
    assert len(set(t.names)) == len(t) == robot.n_parameters
    for k, n in enumerate(t.names):
        assert t.index(n) == k
    with pytest.raises(KeyError, match="unknown parameter"):
        t.index("no_such_parameter")
    assert set(np.unique(t.chains)) == set(range(robot.n_chains))
