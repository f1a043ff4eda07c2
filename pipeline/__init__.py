"""Orchestration and I/O: the simulated testbed, recordings, Rerun logging, command lines."""

from .recording import Recording, RecordingError, read_recording, write_recording
from .testbed import Measurements, SettleError, Testbed

__all__ = ["Recording", "RecordingError", "read_recording", "write_recording", "Testbed", "Measurements", "SettleError"]
