"""The actuated joints' end stops as built (a description's ``joint_ranges``) in every robot's
MuJoCo machine: where they are, and that a servo commanded past one stops at it."""

import mujoco
import numpy as np
import pytest

from calib.robots import default_robot
from mjcf import build_machine
from mjcf.machine import END_STOP_SOLIMP, HOME_KEY

#: Half-width of the declared range about the home joint value, and how far past its stop the
#: first joint is commanded, per joint unit (mm for the hexapod's legs, rad for the hinges).
HALF_RANGE = {"mm": 5.0, "rad": 0.05}
OVERRUN = {"mm": 10.0, "rad": 0.1}
SETTLE_S = 2.0
#: The stop at least this many times as stiff as the servo pushing against it: a joint commanded
#: past its stop by an overrun settles within the overrun / this (plus the impedance's width,
#: where the stop stiffens) of it.
STIFFER_THAN_SERVO = 50.0


def robot_with_ranges(name):
    robot = default_robot(name)
    home = robot.inverse_kinematics(robot.table.nominal, robot.home_pose[None])[0]
    half = HALF_RANGE[robot.joint_unit]
    description = dict(robot.description(), joint_ranges=np.stack([home - half, home + half], axis=1).tolist())
    return type(robot).from_description(description), home


def settle(machine, values):
    """``(joints, spread)``: the actuated joints' values (joint unit) after ``SETTLE_S`` s commanded
    to ``values``, and how far each moved over the last quarter of that time (peak to peak)."""
    m = machine.model
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key(HOME_KEY).id)
    d.ctrl[:] = (values - machine.joint_offset) * machine.joint_scale
    adr = [m.jnt_qposadr[m.joint(j).id] for j in machine.actuated_joints]
    steps = int(SETTLE_S / m.opt.timestep)
    tail = []
    for k in range(steps):
        mujoco.mj_step(m, d)
        if k >= 3 * steps // 4:
            tail.append(d.qpos[adr] / machine.joint_scale + machine.joint_offset)
    return tail[-1], np.ptp(tail, axis=0)


@pytest.mark.parametrize("name", ["hexapod", "delta", "rus", "linear_delta"])
def test_the_declared_ranges_are_the_joints_limits_in_the_machines_units(name):
    robot, _ = robot_with_ranges(name)
    machine = build_machine(robot, robot.table.nominal)
    m = machine.model
    ids = [m.joint(j).id for j in machine.actuated_joints]
    assert np.all(m.jnt_limited[ids] == 1)
    expected = (robot.joint_ranges - machine.joint_offset[:, None]) * machine.joint_scale[:, None]
    np.testing.assert_allclose(m.jnt_range[ids], expected, rtol=0, atol=8 * np.finfo(float).eps * np.abs(expected).max())
    # Without declared ranges nothing is limited: the default limits are not a machine's stops.
    plain = build_machine(default_robot(name), robot.table.nominal)
    assert not np.any(plain.model.jnt_limited[[plain.model.joint(j).id for j in plain.actuated_joints]])


@pytest.mark.parametrize("name", ["hexapod", "delta", "rus", "linear_delta"])
def test_a_servo_commanded_past_its_stop_stops_there(name):
    robot, home = robot_with_ranges(name)
    machine = build_machine(robot, robot.table.nominal)
    stop = robot.joint_ranges[0, 1]
    commanded = home.copy()
    commanded[0] = stop + OVERRUN[robot.joint_unit]
    reached, spread = settle(machine, commanded)
    # Pushed by its servo (stiffness k) an overrun X past the stop, the joint settles where the
    # stop's force balances k X: within X / STIFFER_THAN_SERVO of it once the stop's impedance has
    # reached its full value, which it does within its width (END_STOP_SOLIMP[2], SI). Measured:
    # 0.11 mm for the hexapod's leg 10 mm past, 0.24 and 0.30 mrad for the Delta's and the 6-RUS's
    # 0.1 rad past; MuJoCo's default limit (a 20 ms spring) let the leg settle 4.2 mm past a stop
    # it was commanded 5 mm past.
    width = END_STOP_SOLIMP[2] / machine.joint_scale[0]
    overrun = OVERRUN[robot.joint_unit]
    assert stop - width < reached[0] <= stop + width + overrun / STIFFER_THAN_SERVO, (reached[0] - stop, width)
    # Settled, not chattering on the stop (a critically damped stop let the Delta's arm cycle 3 mrad).
    assert spread[0] <= 1e-3 * width, spread
    # Inside the range the stop is not felt: the same machine reaches a command short of it as the
    # machine without stops does.
    inside = home.copy()
    inside[0] = stop - 0.5 * HALF_RANGE[robot.joint_unit]
    free = build_machine(default_robot(name), robot.table.nominal)
    np.testing.assert_allclose(settle(machine, inside)[0], settle(free, inside)[0], rtol=0, atol=1e-3 * width)
