"""calib.klipper_rotary: Klipper's rotary Delta kinematics against the independent implementation
(tests/klipper_rotary_reference.py), the workbench's Delta of a Klipper config, and the projection
of an identified Delta onto Klipper's parameters (round trip, an error Klipper holds recovered, one
it cannot reported with its residual)."""

import dataclasses

import numpy as np
import pytest

import klipper_rotary_reference as ref
from calib.klipper_rotary import (KLIPPER_ROTARY_PARAMETERS, arm_angles, bed_depth, delta_from_klipper_rotary,
                                  delta_params_of_klipper, klipper_rotary_forward, klipper_rotary_joints,
                                  project_onto_klipper_rotary, rotary_volume_grid)
from calib.robot import KinematicsError

#: Klipper's example rotary Delta (tests/data/klipper/rotary_delta_printer.cfg, its saved values;
#: one lower arm 1.5 mm long) and one of the workbench's paper Delta's size, Klipper's default angles.
CONFIGS = {
    "example": ref.RotaryParams(33.9, 413.212004, (30.0, 150.0, 270.0), (170.0, 170.0, 170.0), (320.0, 320.0, 321.5),
                                (252.14317, 251.902233, 252.308019)),
    "paper_size": ref.RotaryParams(164.0, 500.0, (30.0, 150.0, 270.0), (260.0, 260.0, 260.0), (480.0, 480.0, 480.0),
                                   (300.0, 300.0, 300.0)),
}
#: Two implementations of the same double-precision formulas agree to ~1e-13 relative; the
#: forward kinematics' sphere intersection loses up to ~1e3 of it near the workspace's edge.
SAME_FORMULAS = 1e-9
#: Where the projection stops (xtol, ftol 1e-14 on a problem of condition ~1e4): the parameters
#: within 1e-7 (mm, rad) of the minimum, the residual of an exactly held machine under 1e-8 mm.
FIT_PARAMETER, FIT_RESIDUAL_MM = 1e-7, 1e-8


def kappa_of(p: ref.RotaryParams) -> np.ndarray:
    return np.concatenate([[p.shoulder_radius, p.shoulder_height], np.radians(p.angles), p.upper_arms, p.lower_arms,
                           p.endstops])


def robot_of(p: ref.RotaryParams):
    return delta_from_klipper_rotary(p.shoulder_radius, p.shoulder_height, np.radians(p.angles), p.upper_arms,
                                     p.lower_arms, p.endstops)


def grid_of(robot):
    return rotary_volume_grid(*robot.workspace_bounds().T, bed_depth(robot))


@pytest.mark.parametrize("name", CONFIGS)
def test_the_arm_angles_and_the_tool_point_are_klippers(name):
    p = CONFIGS[name]
    grid = grid_of(robot_of(p))
    np.testing.assert_allclose(arm_angles(kappa_of(p), grid), ref.arm_angles(p, grid), rtol=0, atol=SAME_FORMULAS)
    turns = ref.turns_below_endstops(p, grid)
    np.testing.assert_allclose(klipper_rotary_joints(kappa_of(p), grid), turns, rtol=0, atol=SAME_FORMULAS)
    np.testing.assert_allclose(klipper_rotary_forward(kappa_of(p), turns), grid, rtol=0, atol=SAME_FORMULAS * 1e3)
    np.testing.assert_allclose(ref.position_from_angles(p, ref.arm_angles(p, grid)), grid, rtol=0,
                               atol=SAME_FORMULAS * 1e3)


@pytest.mark.parametrize("name", CONFIGS)
def test_the_delta_of_a_config_moves_as_klipper_does(name):
    """The workbench's Delta of a config, its joints the arms' turns below their endstops and its
    base frame at the shoulders, puts the tool where Klipper does."""
    p = CONFIGS[name]
    robot = robot_of(p)
    grid = grid_of(robot)
    below = grid - [0.0, 0.0, p.shoulder_height]
    turns = ref.turns_below_endstops(p, grid)
    np.testing.assert_allclose(robot.inverse_kinematics(robot.table.nominal, below), turns, rtol=0,
                               atol=SAME_FORMULAS)
    np.testing.assert_allclose(robot.forward_kinematics(robot.table.nominal, turns), below, rtol=0,
                               atol=SAME_FORMULAS * 1e3)
    assert bed_depth(robot) == p.shoulder_height
    assert robot.workspace_bounds()[2, 1] < min(p.endstops) - p.shoulder_height
    # the arms stay between their endstops and hanging straight down over the workspace
    assert np.all((turns >= 0.0) & (turns <= robot.joint_ranges[:, 1]))
    np.testing.assert_allclose(robot.joint_ranges[:, 1], ref.absolute_endstops(p) + np.pi / 2, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", CONFIGS)
def test_above_the_shoulders_the_elbow_is_klippers_too(name):
    p = CONFIGS[name]
    above = p.shoulder_height + max(p.lower_arms) - min(p.upper_arms) + 20.0  # nearer, the lower arm cannot reach
    points = np.array([[0.0, 0.0, above], [30.0, -20.0, above]])
    np.testing.assert_allclose(arm_angles(kappa_of(p), points), ref.arm_angles(p, points), rtol=0, atol=SAME_FORMULAS)


def test_a_point_out_of_reach_is_named():
    p = CONFIGS["example"]
    with pytest.raises(KinematicsError, match=r"point 1: .* out of reach of arm"):
        arm_angles(kappa_of(p), [[0.0, 0.0, 100.0], [900.0, 0.0, 100.0]])


@pytest.mark.parametrize("name", CONFIGS)
def test_the_projection_of_a_configs_delta_gives_back_its_parameters(name):
    p = CONFIGS[name]
    robot = robot_of(p)
    fit = project_onto_klipper_rotary(robot, robot.table.nominal)
    np.testing.assert_allclose(fit.kappa, kappa_of(p), rtol=0, atol=FIT_PARAMETER)
    assert fit.max_mm < FIT_RESIDUAL_MM
    assert set(fit.parameters()) == set(KLIPPER_ROTARY_PARAMETERS)
    assert np.allclose([v for values in fit.unheld.values() for v in values], 0.0, atol=1e-9)


#: An error Klipper holds: every one of its parameters moved (mm; angles rad).
HELD_ERROR = np.array([0.4, -0.3, 2e-3, -1e-3, 3e-3, 0.5, -0.2, 0.3, -0.6, 0.4, 0.2, 0.7, -0.5, 0.3])


@pytest.mark.parametrize("name", CONFIGS)
def test_an_error_klipper_holds_is_recovered(name):
    p = CONFIGS[name]
    robot = robot_of(p)
    actual = kappa_of(p) + HELD_ERROR
    theta = delta_params_of_klipper(actual, p.shoulder_height).to_vector()
    fit = project_onto_klipper_rotary(robot, theta)
    np.testing.assert_allclose(fit.kappa, actual, rtol=0, atol=FIT_PARAMETER)
    assert fit.max_mm < FIT_RESIDUAL_MM


#: A shoulder moved this far (mm) across its arm's plane: Klipper puts it on the plane.
ACROSS_MM = 1.0


@pytest.mark.parametrize("name", CONFIGS)
def test_an_error_klipper_cannot_hold_is_reported_with_its_residual(name):
    p = CONFIGS[name]
    robot = robot_of(p)
    params = robot.params(robot.table.nominal)
    a = params.theta[1]
    moved = dataclasses.replace(params, Dx=params.Dx + ACROSS_MM * np.array([0.0, -np.sin(a), 0.0]),
                                Dy=params.Dy + ACROSS_MM * np.array([0.0, np.cos(a), 0.0]))
    fit = project_onto_klipper_rotary(robot, moved.to_vector())
    np.testing.assert_allclose(fit.unheld["plane_offset_mm"], [0.0, ACROSS_MM, 0.0], atol=1e-9)
    # its radius grows by the second order only: ACROSS^2 / (2 radius)
    assert np.max(np.abs(fit.unheld["radius_off_mm"])) <= ACROSS_MM ** 2 / p.shoulder_radius
    # the fit spreads what it cannot hold over the volume: something is left, less than the shoulder moved
    assert 1e3 * FIT_RESIDUAL_MM < fit.rms_mm < ACROSS_MM
    nearest = project_onto_klipper_rotary(robot, params.to_vector())
    assert nearest.rms_mm < fit.rms_mm * 1e-3
