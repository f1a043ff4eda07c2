"""MJCF models of the robots, built from ``calib`` parameter sets (MuJoCo in SI metres)."""

from .hexapod import DEFAULT_XML, HexapodModelOptions, build_hexapod, hexapod_xml
from .units import M_PER_MM, m_to_mm, mm_to_m

__all__ = ["DEFAULT_XML", "HexapodModelOptions", "build_hexapod", "hexapod_xml", "M_PER_MM",
           "m_to_mm", "mm_to_m"]
