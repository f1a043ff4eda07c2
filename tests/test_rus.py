"""Tests specific to the rotary hexapod (6-RUS): its IK branch and errors, its observability, its
MuJoCo machine. The contract tests over all registered robots cover IK/FK, Jacobians and
identification."""

import mujoco
import numpy as np
import pytest

from calib.robot import KinematicsError, pose_jacobian_of_parameters
from calib.robots import default_robot
from calib.robots.rus import crank_frames
from mjcf import MACHINES
from mjcf.machine import MachineOptions


@pytest.fixture(scope="module")
def robot():
    return default_robot("rus")


def perturbed(robot, seed):
    """A machine 0.5 mm / 0.5 degree (uniform) off the nominal one."""
    rng = np.random.default_rng(seed)
    half = np.where(robot.table.angle_mask(), np.deg2rad(0.5), 0.5)
    return robot.table.nominal + rng.uniform(-1.0, 1.0, robot.n_parameters) * half


def workspace_poses(robot, n, seed):
    b = robot.workspace_bounds()
    return b[:, 0] + (b[:, 1] - b[:, 0]) * np.random.default_rng(seed).random((n, 6))


def settle(machine, joints, max_steps=20000):
    """MjData of the machine settled (max |qvel| < 1e-9) from its home keyframe at ``joints``."""
    data = mujoco.MjData(machine.model)
    machine.reset(data)
    data.ctrl[:] = machine.ctrl(joints)
    for _ in range(max_steps):
        mujoco.mj_step(machine.model, data)
        if np.abs(data.qvel).max() < 1e-9:
            return data
    raise AssertionError(f"the machine did not settle in {max_steps} steps")


def test_default_machine_homes_with_level_cranks(robot):
    q = robot.inverse_kinematics(robot.table.nominal, robot.home_pose[None])
    np.testing.assert_allclose(q, 0.0, atol=1e-12)
    tips = robot.chain_points(robot.table.nominal, q, robot.home_pose[None])[0, :, 1]
    np.testing.assert_allclose(tips[:, 2], robot.table.nominal[robot.table.indices([f"M{i}.z" for i in range(1, 7)])],
                               atol=1e-12)


def test_ik_takes_the_documented_branch(robot):
    theta = perturbed(robot, 1)
    poses = workspace_poses(robot, 50, 2)
    q = robot.inverse_kinematics(theta, poses)
    np.testing.assert_allclose(robot.closure(theta, q, poses), 0.0, atol=1e-9)
    M, C, X = np.moveaxis(robot.chain_points(theta, q, poses), 2, 0)
    p = robot.split(theta)
    _, _, a = crank_frames(p["az"], p["el"])
    # The crank is turned negatively about a from the direction of the platform joint.
    turn = np.einsum("nli,li->nl", np.cross(C - M, X - M), a)
    assert np.all(turn > 0.0)
    # The other root of K cos + L sin = N closes the chain as well, elsewhere.
    p_other = p["q0"][None] + q
    u, v, _ = crank_frames(p["az"], p["el"])
    d = X - M
    psi = np.arctan2(np.einsum("nli,li->nl", d, v), np.einsum("nli,li->nl", d, u))
    other = 2.0 * psi - p_other - p["q0"][None]
    assert np.abs(np.angle(np.exp(1j * (other - q)))).min() > 0.1
    np.testing.assert_allclose(robot.closure(theta, other, poses), 0.0, atol=1e-9)


def test_ik_names_the_row_and_chain_it_cannot_reach(robot):
    poses = np.tile(robot.home_pose, (4, 1))
    poses[2, 2] += 80.0  # beyond crank + rod
    with pytest.raises(KinematicsError, match=r"row 2 is unreachable: the rod of chain \d") as info:
        robot.inverse_kinematics(robot.table.nominal, poses)
    assert info.value.index == 2


def test_pose_data_identify_every_parameter(robot):
    """No gauge: the stacked identification Jacobian over 40 workspace poses has full rank."""
    theta = robot.table.nominal
    poses = workspace_poses(robot, 40, 3)
    q = robot.inverse_kinematics(theta, poses)
    J = pose_jacobian_of_parameters(robot, theta, q, poses) * robot.pose_scale()[None, :, None]
    J = J.reshape(-1, robot.n_parameters)
    sv = np.linalg.svd(J / np.linalg.norm(J, axis=0), compute_uv=False)
    assert robot.gauge_fixed == ()
    assert sv[-1] / sv[0] > 1e-5  # measured 4.8e-5 (condition number 2.1e4, docs/rus.md)


def test_settled_machine_matches_forward_kinematics(robot):
    theta = perturbed(robot, 4)
    machine = MACHINES["rus"](robot, theta, MachineOptions())
    assert np.all(machine.joint_offset == 0.0) and np.all(machine.joint_scale == 1.0)
    data = mujoco.MjData(machine.model)
    machine.reset(data)
    np.testing.assert_allclose(machine.read_pose(data), robot.home_pose, atol=1e-9)
    targets = workspace_poses(robot, 3, 5)
    q = robot.inverse_kinematics(robot.table.nominal, targets)
    expected = robot.forward_kinematics(theta, q, initial=targets)
    assert np.abs(expected - targets)[:, :3].max() > 0.1  # the errors move the platform
    for j in range(3):
        data = settle(machine, q[j])
        np.testing.assert_allclose(machine.read_joints(data), q[j], atol=1e-9)
        np.testing.assert_allclose(machine.read_pose(data)[:3], expected[j, :3], atol=1e-6)
        np.testing.assert_allclose(machine.read_pose(data)[3:], expected[j, 3:], atol=1e-9)


def test_transmission_scale_turns_the_motor_further(robot):
    theta = robot.table.nominal
    scale = (0.01, -0.02, 0.0, 0.03, 0.0, -0.01)
    machine = MACHINES["rus"](robot, theta, MachineOptions(transmission_scale=scale))
    q = robot.inverse_kinematics(theta, workspace_poses(robot, 1, 6))[0]
    data = settle(machine, q)
    turned = q * (1.0 + np.array(scale))
    np.testing.assert_allclose(machine.read_joints(data), turned, atol=1e-9)
    np.testing.assert_allclose(machine.read_pose(data)[:3], robot.forward_kinematics(theta, turned[None])[0, :3],
                               atol=1e-6)


def test_gravity_sags_the_platform(robot):
    theta = robot.table.nominal
    machine = MACHINES["rus"](robot, theta, MachineOptions(gravity=True, payload_kg=2.0))
    data = settle(machine, np.zeros(6))
    sag = machine.read_pose(data)[2] - robot.home_pose[2]
    assert -1.0 < sag < -1e-3
