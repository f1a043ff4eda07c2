"""The registry of robots: one module each, registered here by name.

Adding a robot: write its module (a :class:`calib.robot.Robot` subclass), import it below and add
one line to :data:`ROBOTS`.
"""

from __future__ import annotations

from ..robot import Robot
from .delta import Delta
from .hexapod import Hexapod, paper_hexapod
from .rus import RotaryHexapod, default_rotary_hexapod

__all__ = ["ROBOTS", "robot_class", "default_robot", "robot_from_description", "Hexapod", "Delta", "RotaryHexapod"]

#: name -> (robot class, factory of its default instance).
ROBOTS: dict[str, tuple[type[Robot], object]] = {
    Hexapod.name: (Hexapod, paper_hexapod),
    Delta.name: (Delta, Delta),
    RotaryHexapod.name: (RotaryHexapod, default_rotary_hexapod),
}


def robot_class(name: str) -> type[Robot]:
    """The class registered under ``name``.

    Raises:
        KeyError: unknown name (the message lists the registered ones).
    """
    try:
        return ROBOTS[name][0]
    except KeyError:
        raise KeyError(f"unknown robot {name!r}: registered robots are {', '.join(sorted(ROBOTS))}") from None


def default_robot(name: str) -> Robot:
    """The default machine of a registered robot (e.g. the hexapod paper's Table 2 hexapod)."""
    robot_class(name)
    return ROBOTS[name][1]()


def robot_from_description(name: str, description: dict) -> Robot:
    """The robot ``name`` with the nominal geometry of a :meth:`Robot.description` dict."""
    return robot_class(name).from_description(description)
