"""File formats: the recording (CSV + JSON sidecar), the checks a recording passes before
anything is fitted to it, and safe writing of every output (atomic files, sets published
together)."""

from .command_file import command_columns, command_csv, read_command_file, write_command_file
from .checks import (JOINT_LIMIT_TOLERANCE, REFUSED_CONDITION, ROTATION_CONVENTION, WARNED_CONDITION, RecordingChecks,
                     plausibility, recording_checks)
from .outputs import (FileLock, LockHeld, NameReservation, OutputError, ResultSet, atomic_write, check_outputs, one_line, output_folder, publish,
                      remove_stale_temporaries, writing)
from .recording import (FORMAT, FORMAT_VERSION, MIN_ROBOT_SIZE_MM, READABLE_VERSIONS, SETS, SIDECAR_FIELDS,
                        Recording, RecordingError, columns, read_recording, recording_texts, sidecar_path,
                        write_recording)

__all__ = ["command_columns", "command_csv", "read_command_file", "write_command_file", "Recording", "RecordingError", "read_recording", "write_recording", "recording_texts", "columns",
           "sidecar_path", "plausibility", "recording_checks", "RecordingChecks", "JOINT_LIMIT_TOLERANCE", "check_outputs", "one_line", "FileLock", "LockHeld", "NameReservation", "remove_stale_temporaries",
           "OutputError", "ResultSet", "atomic_write", "output_folder", "publish",
           "writing", "FORMAT", "FORMAT_VERSION", "READABLE_VERSIONS", "SETS", "SIDECAR_FIELDS",
           "MIN_ROBOT_SIZE_MM", "REFUSED_CONDITION", "WARNED_CONDITION", "ROTATION_CONVENTION"]
