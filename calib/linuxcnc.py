"""A calibration projected onto LinuxCNC: its kinematics' parameters and its joints'
compensation tables (the mathematics; the files are written by ``pipeline.formats.linuxcnc``).

LinuxCNC runs a parallel robot through a kinematics module (``genhexkins`` for a hexapod) that
turns a pose into *joint values* ``J``, then adds to each joint a *trim* read from the joint's
compensation table (``motion/control.c``, ``compute_screw_comp``):

    motor = J + trim(J, direction)

``trim`` is interpolated linearly between the table's entries (nominals strictly increasing, at
most :data:`COMP_TABLE_SIZE`), held at the end entries' values beyond the table, and taken from
the "up" or the "down" column by the sign of the joint's commanded velocity (kept while the joint
stands still). A type-0 table line is ``nominal actual_up actual_down`` with ``trim = nominal -
actual`` (``usrmotLoadComp``); LinuxCNC stores the trims and slopes as single-precision floats.

A joint's table can hold what depends on that joint's own position and direction of motion
only: its offset and, of the effects a calibration finds, those that follow the joint's stroke
or the direction of its last move (:data:`JOINT_TABLE_FOLLOWS`: an actuator scale, a dead band,
a periodic screw error). The rest (drifts with time, compliance under load, an instrument's
drift, laws of recorded channels) it cannot: :func:`accuracy_given_up` sizes what leaving each
out costs on the identified model.

The joint a table serves is mapped affinely (:class:`JointMap`): LinuxCNC's joint value is
``J = scale (q + dq(q)) + offset`` for the command ``q`` (the project's joint unit) that makes the
joint sit at ``q + dq(q)`` (the effects' displacement, :mod:`calib.compensation`), and the
motor's position LinuxCNC outputs is ``scale q + motor_offset``. For the hexapod (``genhexkins``:
``J`` is the leg's length ``|R P_i + t - B_i|``, the project's command ``q`` makes the leg ``q +
dl_i`` long): ``scale = 1``, ``offset = dl_i``, ``motor_offset = 0``, so the table carries the
leg's length offset as well (``trim = -dl_i - dq_i``). For the Delta (``rotarydeltakins``: ``J``
is the hip angle in degrees, 0 horizontal, positive down, as the project's arm angle ``q +
alpha``): ``scale = 180/pi``, ``offset`` the joint's angle offset of the fit (degrees),
``motor_offset = 0``, so the motor positions are the project's commands in degrees.

A Delta's identified geometry (24 parameters, three chains each its own) is *projected* onto
``rotarydeltakins`` (four lengths, three identical chains at 120 degrees):
:func:`rotarydelta_fit` finds by least squares the lengths, each joint's angle offset and the
rigid transform from the calibration's base frame to LinuxCNC's world that bring the identified
machine, commanded through them, closest to its targets over the calibrated workspace;
:func:`projection_errors` is what is left (what LinuxCNC, with its tables, will leave).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .compensation import compensated_commands, effect_displacement
from .effects.base import PAYLOAD_CHANNEL, EffectData
from .effects.granularity import PerChainForm
from .effects.laws import Law
from .noise import SensorNoise
from .robot import KinematicsError, Robot
from .robots.delta import DeltaParams, canonical_params
from .robots.delta import inverse_kinematics as delta_inverse
from .rotation import rotation_matrix
from .validation import as_array
from .workspace import random_poses

__all__ = ["COMP_TABLE_SIZE", "JOINT_TABLE_FOLLOWS", "JointMap", "CompTable", "GenhexGeometry", "LeftOut",
           "joint_table_effects", "joint_displacement", "comp_tables", "genhex_geometry", "genhex_joints",
           "accuracy_given_up", "GivenUp", "workspace_sample", "WORKSPACE_SAMPLE", "FINE_FACTOR", "motor_positions",
           "ROTARYDELTA_PARAMETERS", "ROTARYDELTA_HIP_AZIMUTH_DEG", "RotaryDeltaGeometry", "rotarydelta_fit",
           "rotarydelta_joints", "projection_errors", "FIT_SAMPLE", "FIT_SEED"]

#: Entries a LinuxCNC compensation table holds at most (``EMCMOT_COMP_SIZE``, motion.h).
COMP_TABLE_SIZE = 256
#: What a joint's table can follow: the quantities of :data:`calib.effects.base.FOLLOWED_QUANTITIES`
#: that are the joint's own position and direction of motion.
JOINT_TABLE_FOLLOWS = ("stroke", "direction of the last move")
#: The interpolation error is measured on a grid this many times finer than the table's.
FINE_FACTOR = 16
#: Poses of the calibrated workspace on which the accuracy given up is measured.
WORKSPACE_SAMPLE = 200
#: The fixed point of a table entry's command stops when no command changes by more than this
#: fraction of the table's span (as :data:`calib.compensation.COMPENSATION_TOLERANCE`).
TABLE_TOLERANCE = 1e-12
#: Iterations of that fixed point at most.
TABLE_ITERATIONS = 100


@dataclass(frozen=True)
class JointMap:
    """How LinuxCNC's joint values and motor positions relate to the project's joints.

    Attributes:
        scale: (C,) LinuxCNC joint unit per project joint unit (1 for mm to mm, 180/pi for rad
            to degrees; negative where LinuxCNC counts the other way).
        offset: (C,) LinuxCNC's joint value where the joint sits at 0 (project unit), LinuxCNC
            joint unit: ``J = scale * (q + dq) + offset``.
        motor_offset: (C,) LinuxCNC's motor position for the command 0: ``motor = scale * q +
            motor_offset``.
    """

    scale: np.ndarray
    offset: np.ndarray
    motor_offset: np.ndarray

    def motor_to_command(self, motor: np.ndarray) -> np.ndarray:
        """(N, C) the project's commands of LinuxCNC's motor positions ``motor`` (N, C)."""
        return (np.asarray(motor, dtype=float) - self.motor_offset) / self.scale


@dataclass(frozen=True, eq=False)
class CompTable:
    """One joint's compensation table (type 0).

    Attributes:
        joint: the joint, 0-based (LinuxCNC's numbering).
        nominal: (K,) LinuxCNC joint values, strictly increasing, K <= :data:`COMP_TABLE_SIZE`.
        up: (K,) the ``actual`` column moving up (``nominal - trim_up``).
        down: (K,) the ``actual`` column moving down.
        trim_up: (K,) motor minus joint value moving up, LinuxCNC joint unit.
        trim_down: (K,) the same moving down.
        interpolation_error: the largest difference between the table's trim (linear
            interpolation of single-precision trims, as LinuxCNC does) and the exact one, over
            the table's span on a grid :data:`FINE_FACTOR` times finer, LinuxCNC joint unit.
    """

    joint: int
    nominal: np.ndarray
    up: np.ndarray
    down: np.ndarray
    trim_up: np.ndarray
    trim_down: np.ndarray
    interpolation_error: float


@dataclass(frozen=True)
class LeftOut:
    """An effect LinuxCNC cannot hold, and the accuracy given up by leaving it out.

    Attributes:
        name: the effect's name.
        why: why a joint's table cannot hold it.
        rms_mm, max_mm: position error over the calibrated workspace of the identified model
            commanded with everything compensated but this effect (NaN where it cannot be
            evaluated: ``note`` says why).
        note: empty, or why the figures are not given.
    """

    name: str
    why: str
    rms_mm: float = float("nan")
    max_mm: float = float("nan")
    note: str = ""


def _base_effect(eff):
    return eff.base if isinstance(eff, PerChainForm) else eff


def joint_table_effects(effects) -> tuple[list, dict]:
    """Split fitted effects (:class:`calib.effects.records.FittedEffect`) into those the joints'
    tables hold and the others, ``{name: why}``."""
    held, left = [], {}
    for fe in effects:
        eff = fe.effect
        if eff.not_compensable:
            left[fe.name] = eff.not_compensable
        elif isinstance(_base_effect(eff), Law):
            left[fe.name] = ("a law of the recorded quantities (time, channels, other joints): a joint's table is a "
                             "function of its own position and direction only")
        elif eff.follows in JOINT_TABLE_FOLLOWS:
            held.append(fe)
        else:
            left[fe.name] = (f"it follows the {eff.follows}: a joint's table is a function of its own position and "
                             "direction only")
    return held, left


def joint_displacement(robot: Robot, theta: np.ndarray, held, joints: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(K, C) the displacement ``dq`` of joint-local effects ``held`` at commands ``joints``
    (K, C) reached moving in ``direction`` (K, C) (+1 up, -1 down), joint unit."""
    k = joints.shape[0]
    data = EffectData(robot, theta, joints, np.tile(robot.home_pose, (k, 1)), np.zeros(k), SensorNoise(),
                      direction=direction, last_move=np.zeros_like(joints))
    if not held:
        return np.zeros_like(joints)
    return sum(fe.effect.joint_regressors(robot, theta, data, fe.extra) @ fe.coefficients for fe in held)


def _commands_for(robot, theta, held, actual: np.ndarray, direction: np.ndarray, span: float) -> np.ndarray:
    """(K, C) the commands ``q`` with ``q + dq(q) == actual`` moving in ``direction`` (fixed point)."""
    q = actual.copy()
    for _ in range(TABLE_ITERATIONS):
        new = actual - joint_displacement(robot, theta, held, q, direction)
        step = float(np.max(np.abs(new - q)))
        q = new
        if step <= TABLE_TOLERANCE * span:
            return q
    raise ValueError(f"the joints' effects do not converge to a command in {TABLE_ITERATIONS} iterations: too "
                     "large to hold in a table")


def _trims(robot, theta, held, jmap: JointMap, nominal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, C) trims moving up and down at LinuxCNC joint values ``nominal`` (K, C)."""
    actual = (nominal - jmap.offset) / jmap.scale
    span = float(np.max(np.ptp(actual, axis=0))) or 1.0
    out = []
    for sense in (1.0, -1.0):
        direction = np.broadcast_to(sense * np.sign(jmap.scale), actual.shape).copy()
        q = _commands_for(robot, theta, held, actual, direction, span)
        out.append(jmap.scale * q + jmap.motor_offset - nominal)
    return out[0], out[1]


def _interpolated(nominal: np.ndarray, trims: np.ndarray, at: np.ndarray) -> np.ndarray:
    """LinuxCNC's trim at ``at``: single-precision trims and slopes, linear between entries, the
    end entries held beyond."""
    t = trims.astype(np.float32)
    slope = (np.diff(t.astype(float)) / np.diff(nominal)).astype(np.float32)
    k = np.clip(np.searchsorted(nominal, at, side="right") - 1, 0, len(nominal) - 1)
    inner = k < len(nominal) - 1
    value = t[k].astype(float)
    value[inner] += slope[k[inner]].astype(float) * (at[inner] - nominal[k[inner]])
    return np.where(at < nominal[0], float(t[0]), value)


def comp_tables(robot: Robot, theta, held, joint_min, joint_max, jmap: JointMap,
                entries: int = COMP_TABLE_SIZE) -> list[CompTable]:
    """Each joint's compensation table over the commands ``joint_min .. joint_max`` (the range
    the calibration saw).

    Args:
        robot: the robot; theta: (P,) identified parameters.
        held: the fitted effects the tables hold (:func:`joint_table_effects`).
        joint_min, joint_max: (C,) the commanded range, the project's joint unit.
        jmap: the joints' map to LinuxCNC's.
        entries: entries a table (2 .. :data:`COMP_TABLE_SIZE`), evenly spaced over the joint
            values the range reaches in either direction.
    """
    theta = as_array(theta, "theta", (robot.n_parameters,))
    lo, hi = (as_array(v, name, (robot.n_chains,)) for v, name in ((joint_min, "joint_min"), (joint_max, "joint_max")))
    if not 2 <= entries <= COMP_TABLE_SIZE:
        raise ValueError(f"entries must be in 2..{COMP_TABLE_SIZE}, got {entries}")
    if np.any(hi <= lo):
        raise ValueError("joint_max must exceed joint_min for every joint")
    # The joint values the commanded range reaches, either way: the table's span.
    q = np.linspace(lo, hi, FINE_FACTOR * entries)
    reach = [jmap.scale * (q + joint_displacement(robot, theta, held, q, np.full_like(q, s))) + jmap.offset
             for s in (1.0, -1.0)]
    start, stop = np.minimum(*(r.min(axis=0) for r in reach)), np.maximum(*(r.max(axis=0) for r in reach))
    nominal = np.linspace(start, stop, entries)
    up, down = _trims(robot, theta, held, jmap, nominal)
    fine = np.linspace(start, stop, FINE_FACTOR * (entries - 1) + 1)
    fine_up, fine_down = _trims(robot, theta, held, jmap, fine)
    tables = []
    for j in range(robot.n_chains):
        err = max(float(np.max(np.abs(_interpolated(nominal[:, j], trims[:, j], fine[:, j]) - exact[:, j])))
                  for trims, exact in ((up, fine_up), (down, fine_down)))
        tables.append(CompTable(j, nominal[:, j], nominal[:, j] - up[:, j], nominal[:, j] - down[:, j], up[:, j],
                                down[:, j], err))
    return tables


# ----------------------------------------------------------------------------- genhexkins


@dataclass(frozen=True)
class GenhexGeometry:
    """``genhexkins``' parameters of an identified hexapod.

    Attributes:
        base: (6, 3) ``genhexkins.base.N.{x,y,z}``: the base joints, base frame (LinuxCNC's
            world), mm.
        platform: (6, 3) ``genhexkins.platform.N.{x,y,z}``: the platform joints, platform frame, mm.
        jmap: the legs' map to LinuxCNC's joint values (genhexkins' joint value is the leg's
            length; the project's command is that length less the leg's offset ``dl``).
    """

    base: np.ndarray
    platform: np.ndarray
    jmap: JointMap


def genhex_geometry(robot: Robot, theta) -> GenhexGeometry:
    """The ``genhexkins`` parameters of the hexapod ``theta`` (its joint centres as identified;
    its legs' offsets go to the compensation tables, :class:`JointMap`)."""
    if robot.name != "hexapod":
        raise ValueError(f"genhexkins is the hexapod's kinematics, not the {robot.name}'s")
    B, dl, P = robot.legs(as_array(theta, "theta", (robot.n_parameters,)))
    c = robot.n_chains
    return GenhexGeometry(base=B.copy(), platform=P.copy(),
                          jmap=JointMap(scale=np.ones(c), offset=dl.copy(), motor_offset=np.zeros(c)))


def genhex_joints(geometry: GenhexGeometry, poses: np.ndarray) -> np.ndarray:
    """(N, 6) genhexkins' joint values (leg lengths, mm) at ``poses`` (N, 6) (the project's pose
    coordinates: mm and rad, base frame)."""
    R = rotation_matrix(poses[:, 3:6])
    legs = np.einsum("nij,lj->nli", R, geometry.platform) + poses[:, None, 0:3] - geometry.base[None]
    return np.linalg.norm(legs, axis=-1)


def motor_positions(tables, joint_values: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(N, C) the motor positions LinuxCNC outputs for the joint values ``joint_values`` (N, C),
    visited in order from ``start`` (C,) (LinuxCNC's joint unit; ``tables[c]`` serves column
    ``c``): each joint value plus its table's trim (single-precision, linear between entries, the
    end entries held beyond), the up column where the joint's commanded velocity is positive, the
    down column where negative, the last one kept while the joint stands (up before any move)."""
    J = np.asarray(joint_values, dtype=float)
    step = np.sign(np.diff(np.vstack([np.asarray(start, dtype=float)[None], J]), axis=0))
    out = np.empty_like(J)
    for c, t in enumerate(tables):
        direction, last = step[:, c].copy(), 1.0
        for k in range(len(direction)):
            last = direction[k] = direction[k] or last
        up, down = (_interpolated(t.nominal, trims, J[:, c]) for trims in (t.trim_up, t.trim_down))
        out[:, c] = J[:, c] + np.where(direction > 0, up, down)
    return out


# ----------------------------------------------------------------------------- rotarydeltakins

#: rotarydeltakins' HAL pins of its four lengths (``rotarydeltakins.<name>``, mm), its order.
ROTARYDELTA_PARAMETERS = ("platformradius", "thighlength", "shinlength", "footradius")
#: The azimuths of rotarydeltakins' hips in its world (degrees from +x about +z), joints 0, 1, 2:
#: joint 0's thigh swings in the YZ plane with its hip on -y; its inverse finds joint 1 by
#: turning the point -120 degrees onto joint 0's plane, joint 2 by +120 degrees.
ROTARYDELTA_HIP_AZIMUTH_DEG = (-90.0, 30.0, 150.0)
#: How far (degrees) a chain's azimuth, turned with chain 1 onto joint 0, may lie from a hip of
#: rotarydeltakins for the chain to be numbered as that joint.
AZIMUTH_MATCH_DEG = 15.0
#: Poses of the calibrated workspace the rotarydeltakins fit is made on, and their seed (the
#: projection's residual is stated on the :data:`WORKSPACE_SAMPLE` poses of seed 0).
FIT_SAMPLE, FIT_SEED = 400, 1
#: The fit's stopping tolerances (scipy.optimize.least_squares' xtol, ftol, gtol).
FIT_TOLERANCE = 1e-15


@dataclass(frozen=True)
class RotaryDeltaGeometry:
    """``rotarydeltakins``' parameters of an identified Delta and where LinuxCNC's world lies.

    rotarydeltakins' world: origin at the centre of the hips' plane, z up, joint 0's hip on -y,
    joints 1 and 2 at +-120 degrees from it (:data:`ROTARYDELTA_HIP_AZIMUTH_DEG`); its joint value
    is the hip angle in degrees, 0 with the thigh horizontal, positive turning the knee down.

    Attributes:
        platformradius, thighlength, shinlength, footradius: the HAL pins
            ``rotarydeltakins.<name>``, mm (its kinematics depend on ``platformradius -
            footradius`` only: ``footradius`` is the robot's plate radius ``rn_mm``).
        rotation: (3, 3) LinuxCNC's world from the calibration's base frame: a pose's position
            ``p`` (mm, base frame) is ``rotation @ p + translation`` in LinuxCNC's X Y Z.
        translation: (3,) mm.
        chain_of_joint: (3,) the calibration's chain (0-based) that LinuxCNC's joint N drives.
        jmap: the chains' map to LinuxCNC's joint values (indexed by the calibration's chains):
            ``scale`` 180/pi, ``offset`` each joint's angle offset (degrees), so ``J = degrees(q +
            dq) + offset``.
        fit_rms_mm, fit_max_mm: position error of the identified geometry commanded through
            these over the fit's poses (exact offsets, no table), mm.
        fit_poses: how many poses the fit was made on.
    """

    platformradius: float
    thighlength: float
    shinlength: float
    footradius: float
    rotation: np.ndarray
    translation: np.ndarray
    chain_of_joint: np.ndarray
    jmap: JointMap
    fit_rms_mm: float = float("nan")
    fit_max_mm: float = float("nan")
    fit_poses: int = 0

    def values(self) -> dict:
        """``{pin name: value}`` of :data:`ROTARYDELTA_PARAMETERS`, mm."""
        return {name: float(getattr(self, name)) for name in ROTARYDELTA_PARAMETERS}

    def world(self, positions: np.ndarray) -> np.ndarray:
        """(N, 3) LinuxCNC's X Y Z (mm) of positions (N, 3) in the base frame."""
        return np.asarray(positions, dtype=float) @ self.rotation.T + self.translation

    def rotation_about_z_deg(self) -> float:
        """The rotation's turn about z, degrees (the whole turn where it is about z alone)."""
        return float(np.degrees(np.arctan2(self.rotation[1, 0], self.rotation[0, 0])))


def _rotarydelta_model(reach: float, thigh: float, shin: float) -> DeltaParams:
    """rotarydeltakins' machine in its own world as the project's Delta model (its joints in
    LinuxCNC's order): hips ``reach = platformradius - footradius`` from the centre at the azimuths
    of :data:`ROTARYDELTA_HIP_AZIMUTH_DEG`, arm ``thigh`` with no offset, forearm ``shin``."""
    az = np.radians(ROTARYDELTA_HIP_AZIMUTH_DEG)
    return DeltaParams(Dx=reach * np.cos(az), Dy=reach * np.sin(az), Dz=np.zeros(3), theta=az, alpha=np.zeros(3),
                       Lax=np.full(3, thigh), Lay=np.zeros(3), Lb=np.full(3, shin))


def rotarydelta_joints(geometry: RotaryDeltaGeometry, world: np.ndarray) -> np.ndarray:
    """(N, 3) rotarydeltakins' joint values (hip angles, degrees, LinuxCNC's joint order) at the
    points ``world`` (N, 3) of LinuxCNC's world (mm).

    Raises:
        ValueError: a point rotarydeltakins cannot reach (names it).
    """
    model = _rotarydelta_model(geometry.platformradius - geometry.footradius, geometry.thighlength,
                               geometry.shinlength)
    return np.degrees(delta_inverse(model, world))


def _wrap(angle: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * np.asarray(angle, dtype=float)))


def _numbering(azimuth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(chain_of_joint, turn)``: the chain each of rotarydeltakins' joints drives (chain 1 is
    joint 0) and the turns about z (rad, per joint) that bring each chain onto its hip."""
    hips = np.radians(ROTARYDELTA_HIP_AZIMUTH_DEG)
    turned = _wrap(azimuth + hips[0] - azimuth[0])
    gap = np.abs(_wrap(turned[:, None] - hips[None, :]))  # [chain, joint]
    joint_of_chain = np.argmin(gap, axis=1)
    if sorted(joint_of_chain.tolist()) != [0, 1, 2] or np.any(gap.min(axis=1) > np.radians(AZIMUTH_MATCH_DEG)):
        raise ValueError(f"the Delta's chains at {np.degrees(azimuth).round(3).tolist()} degrees are not three chains "
                         "120 degrees apart: rotarydeltakins cannot hold them")
    chain_of_joint = np.argsort(joint_of_chain)
    return chain_of_joint, _wrap(hips - azimuth[chain_of_joint])


def _fit_geometry(x: np.ndarray, rot0: np.ndarray, chain_of_joint, footradius: float) -> RotaryDeltaGeometry:
    from scipy.spatial.transform import Rotation

    reach, thigh, shin = x[0:3]
    offset = np.empty(3)
    offset[chain_of_joint] = np.degrees(x[3:6])
    return RotaryDeltaGeometry(platformradius=float(reach + footradius), thighlength=float(thigh),
                               shinlength=float(shin), footradius=footradius,
                               rotation=Rotation.from_rotvec(x[6:9]).as_matrix() @ rot0, translation=x[9:12].copy(),
                               chain_of_joint=np.asarray(chain_of_joint),
                               jmap=JointMap(scale=np.full(3, 180.0 / np.pi), offset=offset, motor_offset=np.zeros(3)))


def _geometry_errors(robot: Robot, theta: np.ndarray, geometry: RotaryDeltaGeometry, poses: np.ndarray) -> np.ndarray:
    """(N, 3) where the identified geometry goes less ``poses`` (N, 3), commanded through
    rotarydeltakins ``geometry`` with exact joint offsets, mm."""
    J = rotarydelta_joints(geometry, geometry.world(poses))
    q = np.empty_like(J)
    q[:, geometry.chain_of_joint] = J
    q = (q - geometry.jmap.offset) / geometry.jmap.scale
    return robot.forward_kinematics(theta, q) - poses


def rotarydelta_fit(robot: Robot, theta, poses) -> RotaryDeltaGeometry:
    """rotarydeltakins fitted to the identified Delta ``theta`` over ``poses`` (N, 3) (base frame,
    mm: the calibrated workspace, :func:`workspace_sample`).

    Least squares (``scipy.optimize.least_squares``, Levenberg-Marquardt) over rotarydeltakins'
    three lengths (its kinematics hold ``platformradius - footradius``, the thigh and the shin),
    each joint's angle offset and the rigid transform from the base frame to LinuxCNC's world
    (rotation and translation) of the position errors ``FK(theta, q) - p``, ``q`` the commands
    rotarydeltakins with these gives for ``p``. It starts from the identified chains' means (the
    centroid of the shoulders, their mean radius, arm and forearm, each joint's offset, the turn
    bringing chain 1 onto joint 0's hip: -90 degrees for the project's Delta), exact for a Delta
    of rotarydeltakins' shape. ``footradius`` is the robot's plate radius (``rn_mm``).

    Raises:
        ValueError: not a Delta, or chains not 120 degrees apart.
    """
    from scipy.optimize import least_squares  # imported here, as calib.engine does

    if robot.name != "delta":
        raise ValueError(f"rotarydeltakins is the Delta's kinematics, not the {robot.name}'s")
    theta = as_array(theta, "theta", (robot.n_parameters,))
    poses = as_array(poses, "poses", (-1, 3))
    p = canonical_params(robot.params(theta))
    chain_of_joint, turns = _numbering(p.theta)
    centre = p.shoulders().mean(axis=0)
    turn = float(np.angle(np.mean(np.exp(1j * turns))))
    c, s = np.cos(turn), np.sin(turn)
    rot0 = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    reach = float(np.mean(np.linalg.norm((p.shoulders() - centre)[:, :2], axis=1)))
    x0 = np.concatenate([[reach, np.mean(p.Lax), np.mean(p.Lb)], p.alpha[chain_of_joint], np.zeros(3), -rot0 @ centre])
    footradius = float(robot.rn_mm)

    def residual(x):
        return _geometry_errors(robot, theta, _fit_geometry(x, rot0, chain_of_joint, footradius), poses).ravel()

    sol = least_squares(residual, x0, method="lm", x_scale="jac", xtol=FIT_TOLERANCE, ftol=FIT_TOLERANCE,
                        gtol=FIT_TOLERANCE)
    x = sol.x if np.sum(sol.fun ** 2) <= np.sum(residual(x0) ** 2) else x0
    geometry = _fit_geometry(x, rot0, chain_of_joint, footradius)
    e = np.linalg.norm(_geometry_errors(robot, theta, geometry, poses), axis=1)
    return replace(geometry, fit_rms_mm=float(np.sqrt(np.mean(e ** 2))), fit_max_mm=float(np.max(e)),
                   fit_poses=len(poses))


def projection_errors(robot: Robot, theta, held, geometry: RotaryDeltaGeometry, tables, poses, t_s) -> np.ndarray:
    """(N,) position error (mm) of the identified Delta (geometry ``theta`` and the ``held``
    effects) commanded as LinuxCNC will command it for ``poses`` (N, 3) visited in order from the
    home pose at times ``t_s``: rotarydeltakins ``geometry`` (in its world) then the joints'
    compensation ``tables`` (LinuxCNC's joint order, :func:`motor_positions`)."""
    joints = rotarydelta_joints(geometry, geometry.world(poses))
    start = rotarydelta_joints(geometry, geometry.world(robot.home_pose[None]))[0]
    motor = np.empty_like(joints)
    motor[:, geometry.chain_of_joint] = motor_positions(tables, joints, start)
    return _position_errors(robot, theta, held, geometry.jmap.motor_to_command(motor), poses, t_s, None)


# ----------------------------------------------------------------------------- what is left out


def workspace_sample(robot: Robot, theta, pose_min, pose_max, n: int = WORKSPACE_SAMPLE, seed: int = 0) -> np.ndarray:
    """(M, D) poses drawn uniformly in the box ``pose_min .. pose_max`` (the calibrated workspace,
    base frame) that the identified machine ``theta`` reaches within its joint limits (M <= n)."""
    bounds = np.stack([as_array(pose_min, "pose_min", (robot.pose_dim,)),
                       as_array(pose_max, "pose_max", (robot.pose_dim,))], axis=1)
    limits = robot.joint_limits()
    reach = []
    for pose in random_poses(n, seed, bounds):
        try:
            q = robot.inverse_kinematics(theta, pose[None])[0]
        except KinematicsError:
            continue
        if np.all((q >= limits[:, 0]) & (q <= limits[:, 1])):
            reach.append(pose)
    return np.array(reach).reshape(-1, robot.pose_dim)


@dataclass(frozen=True)
class GivenUp:
    """The accuracy given up by what LinuxCNC cannot hold, on the identified model.

    Attributes:
        poses: how many poses of the calibrated workspace it was measured on (visited in order).
        rms_mm, max_mm: position error of the identified model (geometry and every effect it
            can be commanded with) under the commands LinuxCNC gives (the geometry and the
            effects its tables hold); 0 when everything is held.
        left: one :class:`LeftOut` per effect not held.
    """

    poses: int
    rms_mm: float
    max_mm: float
    left: tuple


def _position_errors(robot: Robot, theta, used, commands, poses, t_s, payload) -> np.ndarray:
    """(N,) position error (mm) of the identified machine commanded with ``commands`` in order."""
    joints = commands + effect_displacement(robot, theta, used, commands, poses, t_s, payload)
    reached = robot.forward_kinematics(theta, joints, initial=poses)
    position = ~robot.angle_pose_mask
    return np.linalg.norm((reached - poses)[:, position], axis=1)


def accuracy_given_up(robot: Robot, theta, effects, held, poses, t_s, channels: dict | None = None) -> GivenUp:
    """What leaving out the effects LinuxCNC cannot hold costs, on the identified model.

    The identified model is the geometry ``theta`` with every effect of ``effects`` the commands
    can act on (:func:`calib.compensation.compensated_commands`); LinuxCNC commands it with the
    geometry and the ``held`` effects compensated. Each effect not held is measured alone too:
    the model commanded with everything compensated but it.

    Args:
        robot, theta: the identified robot.
        effects: every fitted effect; held: those the joints' tables hold.
        poses: (N, D) poses of the calibrated workspace, visited in this order.
        t_s: (N,) their times, s (an effect that follows time acts at them).
        channels: recorded channels a law or a compliance at several payloads follows, ``{name: (N,)}``.
    """
    poses = as_array(poses, "poses", (-1, robot.pose_dim))
    payload = (channels or {}).get(PAYLOAD_CHANNEL)
    held_names = {fe.name for fe in held}
    _, why = joint_table_effects(effects)
    full = compensated_commands(robot, theta, poses, effects, t_s=t_s, channels=channels)
    used = [fe for fe in effects if fe.name in full.compensated]

    def errors(compensated):
        q = compensated_commands(robot, theta, poses, compensated, t_s=t_s, channels=channels).commands
        return _position_errors(robot, theta, used, q, poses, t_s, payload)

    left = []
    for fe in effects:
        if fe.name in held_names:
            continue
        if fe.effect.not_compensable:
            left.append(LeftOut(fe.name, why[fe.name], note="not the machine's physics under the commands: no "
                                                            "controller compensates it"))
        elif fe.name in full.left_out:
            left.append(LeftOut(fe.name, why[fe.name], note=f"not evaluated: {full.left_out[fe.name]}"))
        else:
            e = errors([u for u in used if u.name != fe.name])
            left.append(LeftOut(fe.name, why[fe.name], float(np.sqrt(np.mean(e ** 2))), float(np.max(e))))
    e = errors([u for u in used if u.name in held_names]) if len(poses) else np.zeros(0)
    return GivenUp(len(poses), float(np.sqrt(np.mean(e ** 2))) if len(e) else 0.0,
                   float(np.max(e)) if len(e) else 0.0, tuple(left))
