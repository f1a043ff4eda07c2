"""MuJoCo machines of the robots, built from ``calib`` parameter sets (MuJoCo in SI metres)."""

from . import rus
from .machine import Machine, MachineEffects, MachineOptions
from .units import M_PER_MM, m_to_mm, mm_to_m

#: Robot name -> its builder ``build_machine(robot, theta, options) -> Machine`` (see :mod:`mjcf.machine`).
MACHINES = {"rus": rus.build_machine}

__all__ = ["MACHINES", "Machine", "MachineEffects", "MachineOptions", "M_PER_MM", "m_to_mm", "mm_to_m"]
