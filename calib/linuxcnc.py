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
leg's length offset as well (``trim = -dl_i - dq_i``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .compensation import compensated_commands, effect_displacement
from .effects.base import PAYLOAD_CHANNEL, EffectData
from .effects.granularity import PerChainForm
from .effects.laws import Law
from .noise import SensorNoise
from .robot import KinematicsError, Robot
from .rotation import rotation_matrix
from .validation import as_array
from .workspace import random_poses

__all__ = ["COMP_TABLE_SIZE", "JOINT_TABLE_FOLLOWS", "JointMap", "CompTable", "GenhexGeometry", "LeftOut",
           "joint_table_effects", "joint_displacement", "comp_tables", "genhex_geometry", "genhex_joints",
           "accuracy_given_up", "GivenUp", "workspace_sample", "WORKSPACE_SAMPLE", "FINE_FACTOR"]

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
