"""The registry of robots: one module each, registered here by name.

Adding a robot: write its module (a :class:`calib.robot.Robot` subclass), import it below and add
one line to :data:`ROBOTS`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .. import paper
from ..robot import Robot
from .delta import Delta
from .hexapod import Hexapod, paper_hexapod
from .linear_delta import LinearDelta
from .rus import RotaryHexapod, default_rotary_hexapod

__all__ = ["ROBOTS", "RobotEntry", "robot_class", "default_robot", "robot_from_description",
           "reference_errors", "reference_poses", "uniform_errors", "Hexapod", "Delta", "RotaryHexapod",
           "LinearDelta"]


def uniform_errors(robot: Robot, seed, error_mm: float, error_rad: float) -> np.ndarray:
    """(P,) seeded errors uniform within +-``error_mm`` on lengths and +-``error_rad`` on angles;
    zero on the robot's :attr:`~calib.robot.Robot.machine_only` parameters (no pose data tell
    them from the others) and :attr:`~calib.robot.Robot.chain_coupled` ones (not identified by
    default)."""
    half = np.where(robot.table.angle_mask(), error_rad, error_mm)
    half[robot.table.indices(robot.machine_only + robot.chain_coupled)] = 0.0
    return np.random.default_rng(seed).uniform(-1.0, 1.0, robot.n_parameters) * half


@dataclass(frozen=True)
class RobotEntry:
    """A registered robot.

    Attributes:
        cls: the robot class.
        default: factory of its default machine (nominal geometry).
        errors: ``errors(robot, seed) -> (P,)``: the errors of its reference experiment.
        poses: the reference experiment's (N, D) poses, or None for seeded workspace poses.
    """

    cls: type
    default: Callable[[], Robot]
    errors: Callable[[Robot, int], np.ndarray]
    poses: np.ndarray | None = None


#: name -> entry. The hexapod's reference experiment is its paper's (Table 2 machine, Table 3
#: errors, Table 4 poses); the Delta's its paper's primary study (errors within 1 mm / 1 deg); the
#: linear Delta's errors within 0.3 mm / 0.3 deg (tenths of a millimetre and degree, step
#: distances within 0.3 percent) on what it identifies by default, its rods equal.
ROBOTS: dict[str, RobotEntry] = {
    Hexapod.name: RobotEntry(Hexapod, paper_hexapod, lambda r, s: paper.TABLE3_ERRORS.ravel().copy(),
                             paper.TABLE4_NOMINAL_POSES),
    Delta.name: RobotEntry(Delta, Delta, lambda r, s: uniform_errors(r, s, 1.0, np.deg2rad(1.0))),
    RotaryHexapod.name: RobotEntry(RotaryHexapod, default_rotary_hexapod,
                                   lambda r, s: uniform_errors(r, s, 0.5, np.deg2rad(0.5))),
    LinearDelta.name: RobotEntry(LinearDelta, LinearDelta.default,
                                 lambda r, s: uniform_errors(r, s, 0.3, np.deg2rad(0.3))),
}


def _entry(name: str) -> RobotEntry:
    try:
        return ROBOTS[name]
    except KeyError:
        raise KeyError(f"unknown robot {name!r}: registered robots are {', '.join(sorted(ROBOTS))}") from None


def robot_class(name: str) -> type:
    """The class registered under ``name`` (KeyError listing the registered names)."""
    return _entry(name).cls


def default_robot(name: str) -> Robot:
    """The default machine of a registered robot (e.g. the hexapod paper's Table 2 hexapod)."""
    return _entry(name).default()


def reference_errors(robot: Robot, seed: int = 0) -> np.ndarray:
    """(P,) the errors injected in the robot's reference experiment."""
    return np.asarray(_entry(robot.name).errors(robot, seed), dtype=float)


def reference_poses(robot: Robot) -> np.ndarray | None:
    """(N, D) the reference experiment's poses, or None."""
    poses = _entry(robot.name).poses
    return None if poses is None else np.array(poses, dtype=float)


def robot_from_description(name: str, description: dict) -> Robot:
    """The robot ``name`` with the nominal geometry of a :meth:`Robot.description` dict."""
    return robot_class(name).from_description(description)
