"""Orchestration and I/O: the simulated testbed, recordings, Rerun logging, command lines."""

from .recording import Recording, RecordingError, read_recording, write_recording
from .testbed import HexapodTestbed, Measurements, SettleError

__all__ = ["Recording", "RecordingError", "read_recording", "write_recording", "HexapodTestbed",
           "Measurements", "SettleError"]
