"""File formats: the recording (CSV + JSON sidecar), the checks a recording passes before
anything is fitted to it, lab exports turned into recordings, command files, and safe writing of
every output (atomic files, sets published together, locks on names).

The names below are imported from their modules when first used: a command loads the formats
it reads or writes, not every one (the lab exports' TOML reader, the checks of a measured
recording).
"""

from calib.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "checks": ("JOINT_LIMIT_TOLERANCE", "REFUSED_CONDITION", "ROTATION_CONVENTION", "WARNED_CONDITION",
               "RecordingChecks", "plausibility", "recording_checks"),
    "calibration_file": ("CALIBRATION_FORMAT", "CALIBRATION_SUFFIX", "CALIBRATION_VERSION", "Calibration",
                         "CalibrationFileError", "calibration_text", "read_calibration", "recording_source",
                         "validity_domain", "write_calibration"),
    "command_file": ("TIME_COLUMN", "command_columns", "command_csv", "read_command_file", "write_command_file"),
    "lab_export": ("LabExportError", "LabMap", "convert_lab_files", "read_map"),
    "outputs": ("FileLock", "LockHeld", "NameReservation", "OutputError", "ResultSet", "atomic_write",
                "check_outputs", "one_line", "output_folder", "publish", "remove_stale_temporaries", "writing"),
    "targets": ("Targets", "TargetsError", "read_targets"),
    "recording": ("DEFAULT_SESSION", "FORMAT", "FORMAT_VERSION", "MIN_ROBOT_SIZE_MM", "READABLE_VERSIONS",
                  "SESSION_KEYS", "SESSION_TIMES", "SETS", "SIDECAR_FIELDS", "Recording", "RecordingError",
                  "columns", "read_json_file", "read_recording", "recording_texts", "row_message", "row_words",
                  "session_measurement", "sidecar_path", "write_recording"),
})
