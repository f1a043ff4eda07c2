"""MuJoCo machines of the robots, composed with ``mujoco.MjSpec`` from ``calib`` parameter vectors
(MuJoCo in SI metres; the conversion lives in :mod:`mjcf.units`).

Adding a robot: write its builder module (``build_machine(robot, theta, options) -> Machine``, the
contract of :mod:`mjcf.machine`) and add one line to :data:`MACHINES`.
"""

from calib.robot import Robot

from . import delta, hexapod, rus
from .machine import GRAVITY_M_S2, Machine, MachineEffects, MachineOptions
from .units import M_PER_MM, m_to_mm, mm_to_m

__all__ = ["MACHINES", "build_machine", "Machine", "MachineOptions", "MachineEffects", "GRAVITY_M_S2",
           "M_PER_MM", "m_to_mm", "mm_to_m"]

#: robot name -> its builder ``build_machine(robot, theta, options) -> Machine``.
MACHINES = {
    "hexapod": hexapod.build_machine,
    "delta": delta.build_machine,
    "rus": rus.build_machine,
}


def build_machine(robot: Robot, theta, options: MachineOptions = MachineOptions()) -> Machine:
    """The compiled machine of ``robot`` (a :class:`calib.robot.Robot`) with parameters ``theta``
    ((P,), mm and rad), built by the builder registered under ``robot.name``.

    Raises:
        KeyError: no builder for this robot (the message lists the registered ones).
    """
    try:
        builder = MACHINES[robot.name]
    except KeyError:
        raise KeyError(f"no MuJoCo machine for robot {robot.name!r}: machines exist for "
                       f"{', '.join(sorted(MACHINES))}") from None
    return builder(robot, theta, options)
