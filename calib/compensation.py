"""Compensated commands: the joint commands that put the identified machine at target poses,
geometry and found physics together.

The machine model discovery fits (:mod:`calib.effects`): commanded ``q``, the joints sit at
``q + dq(q)`` with ``dq = Xq(q) phi`` (each effect's joint regressors, which follow the command
sequence: the direction and size of each joint's last move, its stroke, the time, the load at
the pose), and the pose is the forward kinematics of the identified geometry ``theta`` there.
To reach target ``x_j`` the joints must sit at ``q*_j = IK(theta, x_j)``; the commands solve

    q_j + dq_j(q_1..q_j) = q*_j          for every target j, in order,

by fixed-point iteration ``q <- q* - dq(q)`` from ``q = q*``: ``dq`` is a small fraction of a
move (a dead band, a scale of the stroke, a compliance under load), so the map contracts; a dead
band's direction is the direction of the *commanded* move, which the iteration settles with the
commands. The machine starts from its home pose (as :class:`calib.effects.EffectData` assumes),
or from the commands already given (``previous``: the command history a dead band follows goes
on from them), and ``t_s`` is the time since the machine started, as in the recordings.

:func:`machine_poses` is the model the other way round: where the identified machine goes when
joints are commanded (the forward kinematics of ``theta`` at ``q + dq(q)``), so that
``machine_poses(compensated_commands(targets).commands) == targets`` to the fixed point's
tolerance.

An effect the commands cannot compensate is left out, with why (:attr:`Effect.not_compensable`:
an instrument's drift, a one-off lost count; an effect that needs the targets' times or a
recorded channel the targets lack); the commands are then geometric for it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .effects.base import PAYLOAD_CHANNEL, EffectData, motion_history
from .effects.records import FittedEffect
from .noise import SensorNoise
from .robot import Robot, check_joint_limits
from .validation import as_array

__all__ = ["Compensation", "compensated_commands", "machine_poses", "effect_displacement", "COMPENSATION_TOLERANCE",
           "MAX_COMPENSATION_ITERATIONS"]

#: The fixed point is reached when no command changes by more than this fraction of the joints'
#: travel in an iteration (1e-12 of a 300 mm stroke is 3e-10 mm).
COMPENSATION_TOLERANCE = 1e-12
#: Iterations of the fixed point before it is said not to converge.
MAX_COMPENSATION_ITERATIONS = 100


@dataclass(frozen=True, eq=False)
class Compensation:
    """Commands for a sequence of targets.

    Attributes:
        commands: (N, C) joint commands, the robot's joint unit.
        geometric: (N, C) the joints the identified geometry needs at the targets (the commands
            with no physics compensated).
        displacement: (N, C) the compensated effects' joint displacement at ``commands``
            (``commands + displacement == geometric`` at convergence).
        compensated: names of the effects compensated.
        left_out: ``{effect name: why}`` of those that are not.
        iterations: fixed-point iterations taken; converged: whether the last step was below
            :data:`COMPENSATION_TOLERANCE` of the travel.
        largest_step: the last iteration's largest change of a command, joint unit.
    """

    commands: np.ndarray
    geometric: np.ndarray
    displacement: np.ndarray
    compensated: tuple = ()
    left_out: dict = field(default_factory=dict)
    iterations: int = 0
    converged: bool = True
    largest_step: float = 0.0


def _why_not(fe: FittedEffect, t_s, channels: dict) -> str:
    eff = fe.effect
    if eff.not_compensable:
        return eff.not_compensable
    missing = [k for k in eff.compensation_inputs() if (k == "t_s" and t_s is None) or (k != "t_s" and k not in channels)]
    if missing:
        what = ["the targets' times (column t_s)" if k == "t_s" else f"the recorded channel {k!r}" for k in missing]
        return f"it follows {' and '.join(what)}, which the targets do not give"
    return ""


def effect_displacement(robot: Robot, theta: np.ndarray, effects, joints: np.ndarray, poses: np.ndarray,
                        t_s: np.ndarray, payload_kg: np.ndarray | None = None,
                        previous: np.ndarray | None = None) -> np.ndarray:
    """(N, C) the joint displacement ``sum Xq phi`` of fitted ``effects`` when ``joints`` are
    commanded in this order towards ``poses`` at times ``t_s`` (from the home pose, or after the
    commands ``previous`` (M, C) given since the machine started), the platform carrying
    ``payload_kg`` (N,) where a compliance fitted at several payloads needs it."""
    if not effects:
        return np.zeros_like(joints)
    home = robot.inverse_kinematics(theta, robot.home_pose[None])[0]
    if previous is None or len(previous) == 0:
        direction, last_move = motion_history(home, joints)
    else:
        direction, last_move = (a[len(previous):] for a in motion_history(home, np.vstack([previous, joints])))
    data = EffectData(robot, theta, joints, poses, t_s, SensorNoise(), direction=direction, last_move=last_move,
                      payload_kg=payload_kg)
    return sum(fe.effect.joint_regressors(robot, theta, data, fe.extra) @ fe.coefficients for fe in effects)


def _history(robot: Robot, theta, previous) -> np.ndarray | None:
    """(2, C) commands with the history of ``previous`` (M, C), or None: the last command, after
    a unit step in each joint's direction of its last move (no step for a joint that never moved
    from home). What the effects follow of the past is the last command and each joint's direction
    (:func:`calib.effects.base.motion_history`), so a long past costs two rows."""
    if previous is None:
        return None
    previous = as_array(previous, "previous", (-1, robot.n_chains))
    if len(previous) == 0:
        return None
    direction, _ = motion_history(robot.inverse_kinematics(theta, robot.home_pose[None])[0], previous)
    return np.vstack([previous[-1] - direction[-1], previous[-1]])


def _compensable(effects, t_s, channels: dict) -> tuple[list, dict]:
    """``(the effects the commands invert, {name: why not} of the others)``."""
    used, left = [], {}
    for fe in effects:
        why = _why_not(fe, t_s, channels)
        if why:
            left[fe.name] = why
        else:
            used.append(fe)
    return used, left


def _inputs(robot: Robot, theta, rows, what: str, width: int, t_s, channels, previous, effects) -> tuple:
    """The checked inputs of :func:`compensated_commands` and :func:`machine_poses`: ``(theta (P,),
    rows (N, width), times (N,) or None, channels, the command history, the effects used, {name:
    why not} of the others)``."""
    theta = as_array(theta, "theta", (robot.n_parameters,))
    rows = as_array(rows, what, (-1, width))
    times = None if t_s is None else as_array(t_s, "t_s", (rows.shape[0],))
    channels = dict(channels or {})
    used, left = _compensable(effects, times, channels)
    return theta, rows, times, channels, _history(robot, theta, previous), used, left


def compensated_commands(robot: Robot, theta, targets, effects=(), *, t_s=None, channels: dict | None = None,
                         previous=None, tolerance: float = COMPENSATION_TOLERANCE,
                         max_iterations: int = MAX_COMPENSATION_ITERATIONS) -> Compensation:
    """The commands that put the machine ``theta`` with fitted ``effects`` at ``targets``.

    Args:
        robot: the robot; theta: (P,) its identified parameters.
        targets: (N, D) target poses in the base frame, in the order they will be commanded.
        effects: :class:`calib.effects.records.FittedEffect` s (laws built with ``channels``).
        t_s: (N,) time of each target since the machine started, s; None: effects that follow
            time are left out.
        channels: recorded channels a law follows, ``{name: (N,)}``; ``payload_kg`` (the payload
            at each target) for a compliance fitted at several payloads.
        previous: (M, C) the commands given before these since the machine started (the history
            a dead band or a law of the last move follows); None: the machine starts at home.

    Raises:
        KinematicsError: a target the identified geometry cannot reach, or a command past a
            joint's stroke (names the row).
        ValueError: arrays of the wrong shape.
    """
    theta, targets, times, channels, previous, used, left = _inputs(robot, theta, targets, "targets", robot.pose_dim,
                                                                    t_s, channels, previous, effects)
    n = targets.shape[0]
    geometric = robot.inverse_kinematics(theta, targets)
    clock = np.zeros(n) if times is None else times  # no effect used follows it when it is None
    travel = float(np.max(np.ptp(robot.joint_limits(), axis=1)))
    q, step, k = geometric.copy(), 0.0, 0
    payload = channels.get(PAYLOAD_CHANNEL)
    for k in range(1, max_iterations + 1):
        new = geometric - effect_displacement(robot, theta, used, q, targets, clock, payload, previous)
        step = float(np.max(np.abs(new - q))) if n else 0.0
        q = new
        if step <= tolerance * travel:
            break
    d = effect_displacement(robot, theta, used, q, targets, clock, payload, previous)
    check_joint_limits(robot, q, "row")  # a command past a joint's stroke is none the machine can take
    return Compensation(commands=q, geometric=geometric, displacement=d, compensated=tuple(fe.name for fe in used),
                        left_out=left, iterations=k if used else 0, converged=step <= tolerance * travel,
                        largest_step=step)


def machine_poses(robot: Robot, theta, joints, effects=(), *, t_s=None, channels: dict | None = None, previous=None,
                  tolerance: float = COMPENSATION_TOLERANCE, max_iterations: int = MAX_COMPENSATION_ITERATIONS
                  ) -> np.ndarray:
    """(N, D) where the machine ``theta`` with fitted ``effects`` goes when ``joints`` are
    commanded in this order: the forward kinematics at ``q + dq(q)``, base frame.

    The effects acted on are those :func:`compensated_commands` inverts with the same ``t_s`` and
    ``channels`` (the others act on the instrument, happen once, or need what is not given), so
    the poses of its commands are its targets. An effect that follows the pose (a compliance)
    is settled by fixed-point iteration on the pose, to :data:`COMPENSATION_TOLERANCE` of the
    travel in the joints' displacement.

    Args:
        joints: (N, C) commanded joints, joint unit, in the order commanded.
        t_s, channels, previous: as :func:`compensated_commands`.

    Raises:
        KinematicsError: joints the identified geometry cannot assemble at (names the row).
        ValueError: arrays of the wrong shape.
    """
    theta, joints, times, channels, previous, used, _ = _inputs(robot, theta, joints, "joints", robot.n_chains,
                                                                 t_s, channels, previous, effects)
    n = joints.shape[0]
    poses = robot.forward_kinematics(theta, joints)
    if not used or n == 0:
        return poses
    clock = np.zeros(n) if times is None else times
    travel = float(np.max(np.ptp(robot.joint_limits(), axis=1)))
    payload = channels.get(PAYLOAD_CHANNEL)
    shift = None
    for _ in range(max_iterations):
        new = effect_displacement(robot, theta, used, joints, poses, clock, payload, previous)
        poses = robot.forward_kinematics(theta, joints + new, initial=poses)
        if shift is not None and float(np.max(np.abs(new - shift))) <= tolerance * travel:
            break
        shift = new
    return poses
