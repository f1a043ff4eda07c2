"""Klipper's rotary Delta in the workbench's terms: its kinematics, the workbench's Delta robot of a
Klipper config, and the projection of an identified Delta onto Klipper's parameters
(docs/klipper.md).

Klipper (its klippy/kinematics/rotary_delta.py and klippy/chelper/kin_rotary_delta.c) holds a
rotary Delta as ``shoulder_radius`` and ``shoulder_height`` and, per stepper, the shoulder's
``angle`` about z, ``upper_arm_length``, ``lower_arm_length`` and ``position_endstop``. Its frame
(the *Klipper frame*): z up, the bed at ``z = 0``, the shoulders at ``shoulder_height`` on a circle
of ``shoulder_radius`` (both already reduced by the effector: the lower arms meet at the tool
point). Arm ``i``'s angle ``s_i`` turns the upper arm *up* from the horizontal, in the vertical
plane through the z axis at ``angle_i``: the elbow is at ``(shoulder_radius + upper cos s_i)``
along that direction and ``shoulder_height + upper sin s_i`` high. Of the two elbows that reach a
point, Klipper takes the outer one. ``position_endstop`` is a height: the arm's angle at its
endstop is the one that puts the tool at ``(0, 0, position_endstop)`` (the *absolute endstop*);
the steps counted from the endstop turn the arm down from there.

The workbench's :class:`calib.robots.delta.Delta` of those parameters
(:func:`delta_params_of_klipper`): shoulder ``i`` at ``shoulder_radius (cos angle_i, sin
angle_i)``, its chain plane at ``theta_i = angle_i``, ``Lax_i`` the upper arm, ``Lb_i`` the lower
arm, and the joint ``q_i`` the arm's turn *below its endstop* (Klipper's stable position times the
step angle): the joint offset ``alpha_i`` is minus the absolute endstop. The Klipper frame is the
robot's base frame shifted up by the *bed depth* (the bed lies ``bed_depth_mm`` below the base
frame's origin; :func:`bed_depth` takes it from the bottom of the robot's workspace). A converted
config's base frame has its origin at the shoulders (``Dz = 0``, bed depth ``shoulder_height``).

The projection (:func:`project_onto_klipper_rotary`): Klipper's 14 parameters
(:data:`KLIPPER_ROTARY_PARAMETERS`) fitted by least squares of the tool point over a grid of the
print volume: Klipper commanded to each grid point turns the arms to the joints its kinematics
computes; the identified machine puts the tool where its forward kinematics says; the difference is
the error. The joints' zero is taken to be where Klipper homes (the endstop). What the residual
cannot lose, Klipper has no parameter for (:func:`unheld_geometry`): shoulders off the common
circle or off their chain plane, shoulders at different heights.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .robot import KinematicsError
from .robots.delta import Delta, DeltaParams, canonical_params, forward_kinematics
from .validation import as_array

__all__ = ["KLIPPER_ROTARY_PARAMETERS", "ROTARY_GRID_STEP_MM", "WORKSPACE_SCALES", "RotaryProjection", "arm_angles", "unchecked_arm_angles",
           "absolute_endstop_angles", "klipper_rotary_joints", "klipper_rotary_forward", "delta_params_of_klipper",
           "klipper_of_delta_params", "delta_from_klipper_rotary", "bed_depth", "rotary_volume_grid",
           "rotary_tool_errors", "project_onto_klipper_rotary", "unheld_geometry"]

#: Klipper's parameters of a rotary Delta in the projection's order (mm; angles rad).
KLIPPER_ROTARY_PARAMETERS = ("shoulder_radius", "shoulder_height", "angle_a", "angle_b", "angle_c",
                             "upper_arm_length_a", "upper_arm_length_b", "upper_arm_length_c",
                             "lower_arm_length_a", "lower_arm_length_b", "lower_arm_length_c",
                             "position_endstop_a", "position_endstop_b", "position_endstop_c")
#: The projection's grid: points this far apart (mm) in x and y, half of it in z.
ROTARY_GRID_STEP_MM = 20.0


def split(kappa) -> tuple:
    """``(radius, height, angles (3,), upper (3,), lower (3,), endstops (3,))`` of ``kappa`` (14,)."""
    k = as_array(kappa, "kappa", (len(KLIPPER_ROTARY_PARAMETERS),))
    return k[0], k[1], k[2:5], k[5:8], k[8:11], k[11:14]


def unchecked_arm_angles(kappa, points) -> np.ndarray:
    """(N, 3) :func:`arm_angles`, NaN where an arm cannot reach."""
    radius, height, angles, upper, lower, _ = split(kappa)
    p = as_array(points, "points", (-1, 3))
    c, s = np.cos(angles), np.sin(angles)
    radial = p[:, :1] * c + p[:, 1:2] * s - radius  # (N, 3) along each arm's plane, from its shoulder
    tangential = p[:, 1:2] * c - p[:, :1] * s  # out of the plane
    up = p[:, 2:3] - height
    reach2 = lower ** 2 - tangential ** 2  # the lower arm's reach within the plane, squared
    distance = np.hypot(radial, up)
    with np.errstate(invalid="ignore", divide="ignore"):
        cosine = (distance ** 2 + upper ** 2 - reach2) / (2.0 * upper * distance)
        outer = np.where(up > 0.0, -1.0, 1.0)  # the elbow farther out: below the shoulder +, above it -
        return np.where(reach2 > 0.0, np.arctan2(up, radial) + outer * np.arccos(cosine), np.nan)


def arm_angles(kappa, points) -> np.ndarray:
    """(N, 3) Klipper's arm angles (rad, up from the horizontal) that put the tool at ``points``
    (N, 3, Klipper frame, mm): each arm's elbow on the circle of its upper arm meets the sphere of
    its lower arm about the point, the outer of the two elbows.

    Raises:
        KinematicsError: a point an arm cannot reach (naming its row and arm).
    """
    out = unchecked_arm_angles(kappa, points)
    bad = np.isnan(out)
    if np.any(bad):
        row, arm = np.argwhere(bad)[0]
        raise KinematicsError(f"point {row}: {np.asarray(points)[row].tolist()} is out of reach of arm "
                              f"{'abc'[arm]} under Klipper's parameters", int(row))
    return out


def absolute_endstop_angles(kappa) -> np.ndarray:
    """(3,) each arm's angle at its endstop: the one that puts the tool at ``(0, 0,
    position_endstop)``.

    Raises:
        KinematicsError: an endstop height its arm cannot reach at the centre (``index`` the arm).
    """
    endstops = split(kappa)[5]
    out = np.diagonal(unchecked_arm_angles(kappa, np.column_stack([np.zeros((3, 2)), endstops]))).copy()
    bad = np.flatnonzero(np.isnan(out))
    if bad.size:
        i = int(bad[0])
        raise KinematicsError(f"arm {'abc'[i]}: position_endstop {endstops[i]:g} is out of its reach at the centre "
                              "under Klipper's parameters", i)
    return out


def klipper_rotary_joints(kappa, points) -> np.ndarray:
    """(N, 3) the arms' turns below their endstops (rad; Klipper's stable positions times the step
    angles) that Klipper with ``kappa`` commands for the tool at ``points`` (N, 3, Klipper frame)."""
    return absolute_endstop_angles(kappa)[None, :] - arm_angles(kappa, points)


def delta_params_of_klipper(kappa, bed_depth_mm: float) -> DeltaParams:
    """The :class:`DeltaParams` of Klipper's parameters ``kappa`` (14,) in a base frame whose
    origin is ``bed_depth_mm`` above the bed (module docstring)."""
    radius, height, angles, upper, lower, _ = split(kappa)
    return DeltaParams(Dx=radius * np.cos(angles), Dy=radius * np.sin(angles),
                       Dz=np.full(3, height - float(bed_depth_mm)), theta=angles,
                       alpha=-absolute_endstop_angles(kappa), Lax=upper, Lay=np.zeros(3), Lb=lower)


def klipper_rotary_forward(kappa, joints) -> np.ndarray:
    """(N, 3) the tool points (Klipper frame) of the arms turned ``joints`` (N, 3, rad) below their
    endstops: the lower intersection of the lower arms' spheres about the elbows."""
    height = split(kappa)[1]
    return forward_kinematics(delta_params_of_klipper(kappa, height), joints) + [0.0, 0.0, height]


def klipper_of_delta_params(params: DeltaParams, bed_depth_mm: float) -> np.ndarray:
    """(14,) the Klipper parameters nearest ``params`` read one by one (the projection's start):
    the shoulders' mean radius and height, the chain planes' angles, the arms, the endstop heights
    where the arms stand at ``-alpha`` (the joints' zero) with the tool at the centre."""
    p = canonical_params(params)
    radius = float(np.mean(np.hypot(p.Dx, p.Dy)))
    height = float(bed_depth_mm + np.mean(p.Dz))
    up = -p.alpha
    reach = radius + p.Lax * np.cos(up)  # the elbow's distance from the z axis at the endstop
    endstops = height + p.Lax * np.sin(up) - np.sqrt(p.Lb ** 2 - reach ** 2)
    return np.concatenate([[radius, height], p.theta, p.Lax, p.Lb, endstops])


#: The workspace's scales tried, largest first, until every point of its grid is within the joints' ranges.
WORKSPACE_SCALES = np.linspace(1.0, 0.1, 10)


def delta_from_klipper_rotary(shoulder_radius_mm: float, shoulder_height_mm: float, angles_rad, upper_arms_mm,
                              lower_arms_mm, endstops_mm) -> Delta:
    """The workbench's :class:`Delta` whose nominal geometry is Klipper's rotary Delta (module
    docstring): base frame at the shoulders, joints the arms' turns below their endstops, each
    from 0 (the arm does not pass its endstop) to the arm hanging straight down. Its workspace: the
    square inscribed in half of Klipper's reach radius (``min(shoulder_radius + upper, lower -
    shoulder_radius)``), from the bed to half of Klipper's top (the lowest endstop), scaled down
    (:data:`WORKSPACE_SCALES`) until its grid's joints are within their ranges; its home at the
    centre, halfway up.

    Raises:
        KinematicsError: an endstop its arm cannot reach at the centre (``index`` the arm), or no
            workspace within the joints' ranges.
    """
    kappa = np.concatenate([[shoulder_radius_mm, shoulder_height_mm],
                            as_array(angles_rad, "angles_rad", (3,)), as_array(upper_arms_mm, "upper_arms_mm", (3,)),
                            as_array(lower_arms_mm, "lower_arms_mm", (3,)), as_array(endstops_mm, "endstops_mm", (3,))])
    _, height, _, upper, lower, endstops = split(kappa)
    params = delta_params_of_klipper(kappa, height)
    ranges = np.column_stack([np.zeros(3), np.pi / 2 - params.alpha])
    half = 0.5 * min(np.min(shoulder_radius_mm + upper), np.min(lower - shoulder_radius_mm)) / np.sqrt(2.0)
    top = 0.5 * float(np.min(endstops))
    for scale in WORKSPACE_SCALES:
        box = np.array([[-half, half], [-half, half], [0.0, top]]) * scale
        turns = -params.alpha - unchecked_arm_angles(kappa, rotary_volume_grid(box[:, 0], box[:, 1], 0.0))
        if np.all((turns >= ranges[:, 0]) & (turns <= ranges[:, 1])):  # NaN (out of reach) fails too
            workspace = box - [[0.0, 0.0], [0.0, 0.0], [height, height]]
            return Delta(params, rn_mm=0.0, home_position_mm=[0.0, 0.0, 0.5 * box[2, 1] - height],
                         workspace_mm=workspace, joint_ranges=ranges.tolist())
    raise KinematicsError("no workspace above the bed keeps the arms between their endstops and hanging straight down "
                          "under Klipper's parameters", 0)


def bed_depth(robot: Delta) -> float:
    """How far below the base frame's origin the bed lies (mm): the bottom of the robot's workspace."""
    return -float(robot.workspace_bounds()[2, 0])


def rotary_volume_grid(pose_min, pose_max, bed_depth_mm: float) -> np.ndarray:
    """(N, 3) the projection's grid (Klipper frame) over the box ``pose_min``..``pose_max`` (base
    frame, mm): every :data:`ROTARY_GRID_STEP_MM` in x and y, half of it in z, the box's faces
    included."""
    lo = as_array(pose_min, "pose_min", (3,)) + [0.0, 0.0, bed_depth_mm]
    hi = as_array(pose_max, "pose_max", (3,)) + [0.0, 0.0, bed_depth_mm]
    steps = (ROTARY_GRID_STEP_MM, ROTARY_GRID_STEP_MM, ROTARY_GRID_STEP_MM / 2)
    axes = [np.linspace(a, b, max(2, int(np.ceil((b - a) / s)) + 1)) for a, b, s in zip(lo, hi, steps)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def rotary_tool_errors(robot: Delta, theta, kappa, bed_depth_mm: float, targets, bed_tilt=(0.0, 0.0)) -> np.ndarray:
    """(N, 3) where the identified machine (``theta``) puts the tool when Klipper with ``kappa`` is
    commanded to ``targets`` (N, 3, Klipper frame), minus the targets, mm. The Klipper frame's z is
    the height above the bed: ``bed_depth_mm`` below the base frame's origin at x = y = 0, sloped
    by ``bed_tilt`` (``tilt_x``, ``tilt_y``: a probe fit's bed plane) in the base frame."""
    reached = robot.forward_kinematics(theta, klipper_rotary_joints(kappa, targets))
    slope = targets[:, :2] @ np.asarray(bed_tilt, dtype=float)
    return reached + [0.0, 0.0, bed_depth_mm] - targets - np.column_stack([np.zeros((len(slope), 2)), slope])


def unheld_geometry(params: DeltaParams) -> dict:
    """What Klipper has no parameter for, of ``params`` (mm): each shoulder's distance from the
    common circle (``radius_off``, the radius minus the mean), its offset out of its chain plane
    (``plane_offset``: Klipper puts the shoulder on the plane through the z axis at its angle) and
    its height minus the mean (``height_off``)."""
    p = canonical_params(params)
    radii = np.hypot(p.Dx, p.Dy)
    return {"radius_off_mm": (radii - radii.mean()).tolist(),
            "plane_offset_mm": (p.Dy * np.cos(p.theta) - p.Dx * np.sin(p.theta)).tolist(),
            "height_off_mm": (p.Dz - p.Dz.mean()).tolist()}


@dataclass(frozen=True, eq=False)
class RotaryProjection:
    """Klipper's parameters fitted to an identified Delta.

    Attributes:
        kappa: (14,) :data:`KLIPPER_ROTARY_PARAMETERS`, mm and rad.
        targets: (N, 3) the grid, Klipper frame, mm.
        errors: (N, 3) the tool-point errors left there, mm.
        bed_depth_mm: the Klipper frame's bed below the base frame's origin.
        unheld: :func:`unheld_geometry` of the identified parameters.
        start_errors: (N, 3) the errors of :func:`klipper_of_delta_params` (the identified
            parameters read one by one, no fit), mm.
    """

    kappa: np.ndarray
    targets: np.ndarray
    errors: np.ndarray
    bed_depth_mm: float
    unheld: dict
    start_errors: np.ndarray

    @property
    def rms_mm(self) -> float:
        return float(np.sqrt(np.mean(np.sum(self.errors ** 2, axis=1))))

    @property
    def max_mm(self) -> float:
        return float(np.max(np.linalg.norm(self.errors, axis=1)))

    def start_figures(self) -> tuple[float, float]:
        """``(RMS, max)`` (mm) of :attr:`start_errors`."""
        n = np.linalg.norm(self.start_errors, axis=1)
        return float(np.sqrt(np.mean(n ** 2))), float(n.max())

    def parameters(self) -> dict:
        """``{name: value}`` of :data:`KLIPPER_ROTARY_PARAMETERS` (mm, rad)."""
        return dict(zip(KLIPPER_ROTARY_PARAMETERS, map(float, self.kappa)))


def project_onto_klipper_rotary(robot: Delta, theta, pose_min=None, pose_max=None, *,
                                bed=None) -> RotaryProjection:
    """Klipper's parameters that minimise the squared tool-point errors of the identified machine
    (``robot`` with parameters ``theta``) over :func:`rotary_volume_grid` of the box
    ``pose_min``..``pose_max`` (base frame; default the robot's workspace), started from
    :func:`klipper_of_delta_params` (central-difference Gauss-Newton: the errors are smooth), in
    the Klipper frame of the bed plane ``bed`` (``z`` mm, ``tilt_x``, ``tilt_y`` rad, base frame: a
    probe fit's estimated bed; default level at :func:`bed_depth` below the origin)."""
    from scipy.optimize import least_squares

    plane = np.array([-bed_depth(robot), 0.0, 0.0]) if bed is None else as_array(bed, "bed", (3,))
    depth, tilt = -float(plane[0]), plane[1:]
    box = robot.workspace_bounds()
    lo = box[:, 0] if pose_min is None else pose_min
    hi = box[:, 1] if pose_max is None else pose_max
    targets = rotary_volume_grid(lo, hi, depth)
    params = robot.params(theta)
    start = klipper_of_delta_params(params, depth)
    scale = np.array([1.0, 1.0, 1e-3, 1e-3, 1e-3] + [1.0] * 9)
    fit = least_squares(lambda k: rotary_tool_errors(robot, theta, k, depth, targets, tilt).ravel(), start,
                        x_scale=scale, diff_step=1e-8, xtol=1e-14, ftol=1e-14, gtol=1e-14)
    return RotaryProjection(kappa=fit.x, targets=targets, errors=rotary_tool_errors(robot, theta, fit.x, depth, targets, tilt),
                            bed_depth_mm=depth, unheld=unheld_geometry(params),
                            start_errors=rotary_tool_errors(robot, theta, start, depth, targets, tilt))
