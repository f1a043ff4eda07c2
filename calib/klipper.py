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

from .robots.linear_delta import DEFAULT_GEOMETRY, CHAIN_PARAMETERS, LinearDelta
from .validation import as_array

__all__ = ["linear_delta_from_klipper", "joints_from_stable", "absolute_endstops"]


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
