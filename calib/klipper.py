"""Klipper's linear Delta in the workbench's terms (docs/klipper.md).

Klipper (its klippy/kinematics/delta.py) holds a linear Delta as ``delta_radius``, each tower's
``angle``, ``arm_length`` and ``position_endstop`` and each stepper's step distance; its towers are
vertical, its carriages' absolute endstop heights ``position_endstop + sqrt(arm^2 - radius^2)`` and
a carriage's height the absolute endstop minus the stable position (steps from the endstop) times
the step distance. :func:`linear_delta_from_klipper` builds the
:class:`calib.robots.linear_delta.LinearDelta` whose nominal geometry is exactly that machine
(radius and angle per tower, no lean, the endstop heights ``H_i`` its absolute endstops, no step
error, joints the stable positions times the step distances: :func:`joints_from_stable`).
"""

from __future__ import annotations

import numpy as np

from .robot import KinematicsError
from .robots.linear_delta import CHAIN_PARAMETERS, DEFAULT_GEOMETRY, LinearDelta
from .validation import as_array

__all__ = ["linear_delta_from_klipper", "joints_from_stable", "absolute_endstops", "touch_height_rms",
           "step_distance_factor", "STEP_MISMATCH_MM", "STEP_FACTOR_RANGE", "STEP_FACTOR_TRIES"]


def absolute_endstops(radius_mm: float, arms_mm, endstops_mm) -> np.ndarray:
    """(3,) the carriages' heights at their endstops, mm: ``position_endstop + sqrt(arm^2 - radius^2)``."""
    return np.asarray(endstops_mm, dtype=float) + np.sqrt(np.asarray(arms_mm, dtype=float) ** 2 - radius_mm ** 2)


def linear_delta_from_klipper(radius_mm: float, angles_rad, arms_mm, endstops_mm, *,
                              print_radius_mm: float | None = None) -> LinearDelta:
    """The :class:`LinearDelta` of Klipper's parameters (module docstring): towers at
    ``radius_mm`` and ``angles_rad`` (3,), arms ``arms_mm`` (3,), endstop heights along the towers
    :func:`absolute_endstops`; the workspace a cylinder of ``print_radius_mm`` (default the
    robot's) from the bed to the default print height, the joints' range down to the bed's edge."""
    angles = as_array(angles_rad, "angles_rad", (3,))
    arms = as_array(arms_mm, "arms_mm", (3,))
    heights = absolute_endstops(radius_mm, arms, as_array(endstops_mm, "endstops_mm", (3,)))
    g = DEFAULT_GEOMETRY
    towers = np.zeros((3, len(CHAIN_PARAMETERS)))
    towers[:, 0], towers[:, 1], towers[:, 4] = radius_mm, angles, arms
    r = g["print_radius_mm"] if print_radius_mm is None else float(print_radius_mm)
    square = r / np.sqrt(2.0)
    return LinearDelta(towers, [0.0, 0.0, g["tool_z_mm"]], heights, travel_mm=float(np.max(heights)),
                       workspace_mm=[[-square, square], [-square, square], [0.0, g["print_height_mm"]]],
                       full_workspace_mm=[[-r, r], [-r, r], [0.0, g["print_height_mm"]]])


def joints_from_stable(steps, step_distances_mm) -> np.ndarray:
    """(..., 3) the robot's joints (mm of counted travel below the endstops) of stable positions
    ``steps`` (..., 3): the steps times each stepper's step distance."""
    return np.asarray(steps, dtype=float) * as_array(step_distances_mm, "step_distances_mm", (3,))


#: Touch heights this far (RMS, mm) from what the nominal machine puts at their stable positions
#: cannot come from the tolerances (a millimetre at most each): the stable positions were counted
#: with another step distance.
STEP_MISMATCH_MM = 5.0
#: The factors of the step distance tried when looking for the one that fits (1/16 to 16: a
#: microstep setting, a pulley or a belt pitch changed).
STEP_FACTOR_RANGE = (1.0 / 16.0, 16.0)
STEP_FACTOR_TRIES = 97


def touch_height_rms(robot: LinearDelta, joints, z_mm, factor: float = 1.0) -> float:
    """RMS (mm) of the nominal machine's tool heights at ``joints`` times ``factor`` minus the
    touches' ``z_mm``; infinite where the arms cannot reach."""
    try:
        X = robot.forward_kinematics(robot.table.nominal, np.asarray(joints, dtype=float) * factor)
    except KinematicsError:
        return float("inf")
    return float(np.sqrt(np.mean((X[:, 2] - np.asarray(z_mm, dtype=float)) ** 2)))


def step_distance_factor(robot: LinearDelta, joints, z_mm) -> tuple[float, float, float]:
    """``(rms, factor, rms_at_factor)``: the touches' height RMS at the step distance given, the
    factor of it that fits them best (scanned over :data:`STEP_FACTOR_RANGE`, then refined by a
    golden-section search of its bracket) and the RMS there."""
    rms = touch_height_rms(robot, joints, z_mm)
    grid = np.geomspace(*STEP_FACTOR_RANGE, STEP_FACTOR_TRIES)
    values = np.array([touch_height_rms(robot, joints, z_mm, f) for f in grid])
    k = int(np.argmin(values))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    for _ in range(40):  # golden-section search on the bracket
        a, b = hi - 0.618 * (hi - lo), lo + 0.618 * (hi - lo)
        if touch_height_rms(robot, joints, z_mm, a) < touch_height_rms(robot, joints, z_mm, b):
            hi = b
        else:
            lo = a
    best = 0.5 * (lo + hi)
    return rms, float(best), touch_height_rms(robot, joints, z_mm, best)
