"""Orchestration and I/O: the simulated testbed, recordings, Rerun logging, command lines."""

from .delta_testbed import DeltaMeasurements, DeltaTestbed, delta_geometry_si
from .recording import Recording, RecordingError, read_recording, write_recording
from .testbed import HexapodTestbed, MachineEffects, Measurements, SettleError

__all__ = ["DeltaMeasurements", "DeltaTestbed", "delta_geometry_si", "Recording", "RecordingError", "read_recording", "write_recording", "HexapodTestbed",
           "MachineEffects", "Measurements", "SettleError"]
