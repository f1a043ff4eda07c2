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
           "step_distance_factor", "STEP_MISMATCH_MM", "STEP_FACTOR_RANGE", "STEP_FACTOR_TRIES", "KLIPPER_PARAMETERS",
           "VOLUME_STEP_MM", "VOLUME_HEIGHT_MM", "klipper_vector", "klipper_joints", "volume_grid", "bed_to_base",
           "klipper_tool_errors", "fit_klipper", "mesh_points"]


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


#: Klipper's parameters of a linear Delta in the projection's order: ``delta_radius`` (mm), each
#: tower's ``angle`` (rad), ``arm_length`` and ``position_endstop`` (mm), and each stepper's step
#: distance as a factor of the one the joints were counted with.
KLIPPER_PARAMETERS = ("delta_radius", "angle_a", "angle_b", "angle_c", "arm_length_a", "arm_length_b",
                      "arm_length_c", "position_endstop_a", "position_endstop_b", "position_endstop_c",
                      "step_factor_a", "step_factor_b", "step_factor_c")
#: The projection's grid over the print volume: points this far apart (mm) in x, y (inside the
#: print radius) and in z, from the bed to :data:`VOLUME_HEIGHT_MM` above it.
VOLUME_STEP_MM, VOLUME_HEIGHT_MM = 20.0, 150.0


def klipper_vector(robot: LinearDelta) -> np.ndarray:
    """(13,) :data:`KLIPPER_PARAMETERS` of the machine Klipper would hold for ``robot``'s nominal
    geometry (mean radius, its angles and arms, endstops from its endstop heights, factors 1)."""
    t = robot.towers
    radius = float(np.mean(t[:, 0]))
    return np.concatenate([[radius], t[:, 1], t[:, 4],
                           robot.endstop_height_mm - np.sqrt(t[:, 4] ** 2 - radius ** 2), np.ones(3)])


def klipper_joints(kappa, targets) -> np.ndarray:
    """(N, 3) the joints (travel counted below the endstops at the joints' step distance, mm) that
    Klipper's kinematics with parameters ``kappa`` (13,) commands for the tool points ``targets``
    (N, 3): the carriage heights ``z + sqrt(arm^2 - |xy - tower|^2)`` below the absolute endstops,
    divided by the step factors."""
    kappa = np.asarray(kappa, dtype=float)
    radius, angles, arms, endstops, factors = kappa[0], kappa[1:4], kappa[4:7], kappa[7:10], kappa[10:13]
    towers = radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    targets = np.asarray(targets, dtype=float)
    horizontal2 = np.sum((towers - targets[:, None, :2]) ** 2, axis=-1)
    heights = targets[:, 2:3] + np.sqrt(arms ** 2 - horizontal2)
    return (absolute_endstops(radius, arms, endstops) - heights) / factors


def volume_grid(print_radius_mm: float) -> np.ndarray:
    """(N, 3) the projection's grid above the bed (:data:`VOLUME_STEP_MM`, :data:`VOLUME_HEIGHT_MM`)."""
    s = np.arange(-print_radius_mm, print_radius_mm + 1e-9, VOLUME_STEP_MM)
    xy = np.array([(x, y) for x in s for y in s if x * x + y * y <= print_radius_mm ** 2])
    z = np.arange(0.0, VOLUME_HEIGHT_MM + 1e-9, VOLUME_STEP_MM / 2)
    return np.concatenate([np.column_stack([xy, np.full(len(xy), h)]) for h in z])


def bed_to_base(targets, bed) -> np.ndarray:
    """(N, 3) points given above the bed plane ``bed`` (``z``, ``tilt_x``, ``tilt_y``) in the
    robot's base frame (the plane's height added to z)."""
    out = np.array(targets, dtype=float)
    out[:, 2] += bed[0] + out[:, :2] @ np.asarray(bed[1:], dtype=float)
    return out


def klipper_tool_errors(robot: LinearDelta, theta, bed, kappa, targets) -> np.ndarray:
    """(N, 3) where the identified machine (``theta``, on the bed plane ``bed``) puts the tool when
    Klipper with ``kappa`` is commanded to ``targets`` (above the bed), minus the targets, mm."""
    reached = robot.forward_kinematics(theta, klipper_joints(kappa, targets),
                                       initial=bed_to_base(targets, bed))
    return reached - bed_to_base(targets, bed)


def fit_klipper(robot: LinearDelta, theta, bed, targets, *, free_shift: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(kappa, errors)``: Klipper's parameters (13,) that minimise the squared tool-point errors
    of the identified machine over ``targets`` (N, 3, above the bed), and the (N, 3) errors left.
    With ``free_shift`` the errors are taken after the best shift of the whole print in x, y (fitted
    along, removed from the errors returned): where the data fix no such shift (probe touches and
    distances do not), the projection spends none of Klipper's parameters on it. Gauss-Newton with
    central-difference columns (the errors are smooth in kappa)."""
    from scipy.optimize import least_squares

    shifts = 2 if free_shift else 0
    start = np.concatenate([klipper_vector(robot), np.zeros(shifts)])
    scale = np.concatenate([[1.0], np.full(3, 1e-3), np.ones(6), np.full(3, 1e-3), np.ones(shifts)])

    def errors(x):
        e = klipper_tool_errors(robot, theta, bed, x[:len(KLIPPER_PARAMETERS)], targets)
        if shifts:
            e[:, :2] -= x[len(KLIPPER_PARAMETERS):]
        return e

    fit = least_squares(lambda x: errors(x).ravel(), start, x_scale=scale, diff_step=1e-7, xtol=1e-12, ftol=1e-12)
    return fit.x[:len(KLIPPER_PARAMETERS)], errors(fit.x)


def mesh_points(robot: LinearDelta, theta, bed, kappa, radius_mm: float, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``(axis, points)``: the mesh's node coordinates (count,) from ``-radius_mm`` to
    ``radius_mm`` and (count, count) its points, row ``j`` at ``y = axis[j]``: the height at which
    the tool meets the bed there under Klipper with ``kappa`` (minus the z error at the bed); a
    node outside the circle of ``radius_mm`` (a round bed's corner, out of the arms' reach) takes
    the value at the nearest point of the circle."""
    axis = np.linspace(-radius_mm, radius_mm, count)
    xx, yy = np.meshgrid(axis, axis)
    nodes = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)])
    r = np.hypot(nodes[:, 0], nodes[:, 1])
    nodes[:, :2] *= np.minimum(1.0, radius_mm / np.where(r > 0, r, 1.0))[:, None]
    return axis, -klipper_tool_errors(robot, theta, bed, kappa, nodes)[:, 2].reshape(count, count)
