"""Per-joint values of the MuJoCo machine: each joint its own friction, stiffness, drift and
warm-up, through the MjSpec (every builder) and the testbed; a number still means every joint alike."""

import numpy as np
import pytest

from calib.paper import TABLE3_ERRORS
from calib.robots import default_robot
from calib.robots.hexapod import paper_hexapod
from calib.effects.thermal_warmup import warmup_growth
from mjcf import build_machine
from mjcf.machine import MachineEffects, MachineOptions, chain_values
from mjcf.units import M_PER_MM
from pipeline.simulation import Testbed

ROBOT = paper_hexapod()
ACTUAL = ROBOT.table.nominal + TABLE3_ERRORS.ravel()
FRICTION = (0.4, 0.6, 0.8, 1.0, 0.5, 0.7)  # N
STIFFNESS = (1e5, 2e5, 1.5e5, 2.5e5, 1.2e5, 3e5)  # N/m


@pytest.mark.parametrize("name", ["hexapod", "delta", "rus", "linear_delta"])
def test_every_builder_writes_each_joints_friction_and_stiffness_into_the_spec(name):
    robot = default_robot(name)
    c = robot.n_chains
    friction, stiffness = np.linspace(0.1, 0.6, c), np.linspace(100.0, 300.0, c)
    scale = tuple(np.linspace(-2e-3, 2e-3, c))
    m = build_machine(robot, robot.table.nominal,
                      MachineOptions(joint_friction=tuple(friction), actuator_stiffness=tuple(stiffness),
                                     transmission_scale=scale))
    np.testing.assert_allclose(m.model.dof_frictionloss[m.dof_index], friction, rtol=1e-12)
    # The servo's stiffness at the joint is the gain times the gear squared, whatever the gear.
    np.testing.assert_allclose(m.servo_stiffness, stiffness, rtol=1e-12)
    np.testing.assert_allclose(m.model.actuator_gear[:, 0], 1 / (1 + np.asarray(scale)), rtol=1e-12)


def test_a_number_means_every_joint_alike():
    shared = build_machine(ROBOT, ACTUAL, MachineOptions(joint_friction=0.5, actuator_stiffness=1e5))
    tupled = build_machine(ROBOT, ACTUAL, MachineOptions(joint_friction=(0.5,) * 6, actuator_stiffness=(1e5,) * 6))
    np.testing.assert_array_equal(shared.model.dof_frictionloss, tupled.model.dof_frictionloss)
    np.testing.assert_array_equal(shared.model.actuator_gainprm, tupled.model.actuator_gainprm)
    np.testing.assert_array_equal(chain_values(0.5, 6), np.full(6, 0.5))


def test_per_joint_options_are_checked():
    with pytest.raises(ValueError, match="joint_friction must be >= 0"):
        MachineOptions(joint_friction=(0.1, -0.1, 0.1, 0.1, 0.1, 0.1))
    with pytest.raises(ValueError, match="actuator_stiffness must be > 0"):
        MachineOptions(actuator_stiffness=(1.0, 0.0))
    with pytest.raises(ValueError, match="one number or 6 values"):
        build_machine(ROBOT, ACTUAL, MachineOptions(joint_friction=(0.1, 0.2)))
    assert MachineEffects(joint_drift_per_s=[1e-5] * 6).to_dict()["joint_drift_per_s"] == [1e-5] * 6


def test_each_joint_stops_short_by_its_own_friction_over_its_own_stiffness():
    band_mm = np.asarray(FRICTION) / np.asarray(STIFFNESS) / M_PER_MM  # 1.9-6 um
    steps = np.array([[2.0] * 6, [3.0] * 6, [1.0] * 6, [1.5] * 3 + [0.5] * 3])
    direction = np.array([[1.0] * 6, [1.0] * 6, [-1.0] * 6, [1.0] * 3 + [-1.0] * 3])
    bed = Testbed(ROBOT, ACTUAL, options=MachineOptions(actuator_stiffness=STIFFNESS, joint_friction=FRICTION))
    m = bed.measure(ROBOT.home_lengths + steps)
    np.testing.assert_allclose(m.commanded - m.settled_joints, direction * band_mm, atol=1e-7)
    np.testing.assert_allclose(m.true_poses, ROBOT.forward_kinematics(ACTUAL, m.settled_joints), atol=1e-6)


def test_each_joint_drifts_and_warms_up_at_its_own_rate():
    rng = np.random.default_rng(3)
    commanded = ROBOT.home_lengths + rng.uniform(-2, 2, (4, 6))
    times = np.array([0.0, 10.0, 20.0, 30.0])
    rate = np.linspace(2e-5, 1e-4, 6)
    drift = Testbed(ROBOT, ACTUAL, effects=MachineEffects(joint_drift_per_s=tuple(rate))).measure(commanded, times_s=times)
    np.testing.assert_allclose(drift.settled_joints - commanded, times[:, None] * rate, atol=1e-7)
    warm = Testbed(ROBOT, ACTUAL, effects=MachineEffects(joint_warmup_per_s=tuple(rate), joint_warmup_tau_s=15.0))
    m = warm.measure(commanded, times_s=times)
    np.testing.assert_allclose(m.settled_joints - commanded, warmup_growth(times, 15.0)[:, None] * rate, atol=1e-7)
