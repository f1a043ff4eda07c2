"""An independent implementation of Klipper's rotary Delta kinematics, in plain numpy, in Klipper's
units (mm, shoulder angles in degrees), written from its formulas (klippy/kinematics/rotary_delta.py
``RotaryDeltaCalibration``, klippy/chelper/kin_rotary_delta.c ``rotary_two_arm_calc``; GPLv3: the
formulas re-derived and written here, no code copied): what calib/klipper_rotary.py and the export
are checked against.

- Inverse kinematics (``arm_angle``): in each shoulder's frame (x along its angle from the shoulder,
  y up, z across), the elbow lies on the line ``elbow_y = c1 - c2 elbow_x`` (the difference of the
  upper arm's circle and the lower arm's sphere cut by the arm's plane), and on the upper arm's
  circle; of the two, the one with the larger ``elbow_x`` (the elbow out).
- Forward kinematics (``position_from_angles``): the elbows at ``((radius + upper cos s) cos a,
  (radius + upper cos s) sin a, height + upper sin s)``; the tool the lower intersection of the
  lower arms' spheres about them (tests/klipper_reference.py's trilateration).
- Stable positions: the arm's angle is the absolute endstop (the angle that puts the tool at
  ``(0, 0, position_endstop)``) minus the steps times the step angle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from klipper_reference import lower_sphere_intersection


@dataclass(frozen=True)
class RotaryParams:
    """Klipper's rotary Delta as its config holds it: angles in degrees, lengths mm."""

    shoulder_radius: float
    shoulder_height: float
    angles: tuple
    upper_arms: tuple
    lower_arms: tuple
    endstops: tuple


def arm_angle(p: RotaryParams, i: int, xyz: np.ndarray) -> np.ndarray:
    """(...,) arm ``i``'s angle (rad, up) that puts the tool at ``xyz`` (..., 3)."""
    xyz = np.asarray(xyz, dtype=float)
    a = np.radians(p.angles[i])
    across = xyz[..., 1] * np.cos(a) - xyz[..., 0] * np.sin(a)
    dx = xyz[..., 0] * np.cos(a) + xyz[..., 1] * np.sin(a) - p.shoulder_radius
    dy = xyz[..., 2] - p.shoulder_height
    upper2, lower2 = p.upper_arms[i] ** 2, p.lower_arms[i] ** 2 - across ** 2
    c1 = 0.5 / dy * (dx * dx + dy * dy + upper2 - lower2)
    c2 = dx / dy
    scale = c2 * c2 + 1.0
    elbow_x = c1 * c2 + np.sqrt(scale * upper2 - c1 * c1)
    elbow_y = c1 * scale - c2 * elbow_x
    return np.arctan2(elbow_y, elbow_x)


def arm_angles(p: RotaryParams, xyz: np.ndarray) -> np.ndarray:
    """(..., 3) the three arms' angles of the tool points ``xyz`` (..., 3)."""
    return np.stack([arm_angle(p, i, xyz) for i in range(3)], axis=-1)


def absolute_endstops(p: RotaryParams) -> np.ndarray:
    """(3,) the arms' angles at their endstops."""
    return np.array([arm_angle(p, i, np.array([0.0, 0.0, p.endstops[i]])) for i in range(3)])


def elbows(p: RotaryParams, angles: np.ndarray) -> np.ndarray:
    """(..., 3, 3) the elbows at arm angles ``angles`` (..., 3)."""
    a = np.radians(np.asarray(p.angles))
    out = p.shoulder_radius + np.asarray(p.upper_arms) * np.cos(angles)
    return np.stack([out * np.cos(a), out * np.sin(a), p.shoulder_height + np.asarray(p.upper_arms) * np.sin(angles)],
                    axis=-1)


def position_from_angles(p: RotaryParams, angles: np.ndarray) -> np.ndarray:
    """(..., 3) the tool point at arm angles ``angles`` (..., 3)."""
    return lower_sphere_intersection(elbows(p, angles), np.asarray(p.lower_arms, dtype=float) ** 2)


def turns_below_endstops(p: RotaryParams, xyz: np.ndarray) -> np.ndarray:
    """(..., 3) the arms' turns below their endstops (stable positions x step angles) for ``xyz``."""
    return absolute_endstops(p) - arm_angles(p, xyz)


def read_params(cfg) -> RotaryParams:
    """The :class:`RotaryParams` of a parsed config (``pipeline.formats.klipper.KlipperConfig``):
    the keys as Klipper reads them, defaults included."""
    steppers = ("stepper_a", "stepper_b", "stepper_c")

    def per(key, defaults=None):
        first = cfg.value(steppers[0], key, defaults[0]) if defaults else cfg.value(steppers[0], key)
        return tuple(float(cfg.value(s, key, defaults[k] if defaults else first)) for k, s in enumerate(steppers))

    return RotaryParams(float(cfg.value("printer", "shoulder_radius")), float(cfg.value("printer", "shoulder_height")),
                        per("angle", (30.0, 150.0, 270.0)), per("upper_arm_length"), per("lower_arm_length"),
                        per("position_endstop"))
