"""MJCF models of the robots, built from ``calib`` parameter sets (MuJoCo in SI metres)."""

from .hexapod import DEFAULT_XML, HexapodModelOptions, build_hexapod, hexapod_xml
from .delta import DeltaMjcfGeometry, build_delta_model, build_delta_xml
from .units import M_PER_MM, m_to_mm, mm_to_m
from . import rus
from .machine import Machine, MachineEffects, MachineOptions

#: Robot name -> its builder ``build_machine(robot, theta, options) -> Machine`` (see :mod:`mjcf.machine`).
#: The hexapod and the Delta still use their own builders above until they move onto this contract.
MACHINES = {"rus": rus.build_machine}

__all__ = ["MACHINES", "Machine", "MachineEffects", "MachineOptions", "DeltaMjcfGeometry", "build_delta_model", "build_delta_xml", "DEFAULT_XML", "HexapodModelOptions", "build_hexapod", "hexapod_xml", "M_PER_MM",
           "m_to_mm", "mm_to_m"]
