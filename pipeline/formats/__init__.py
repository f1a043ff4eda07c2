"""File formats: the recording (CSV + JSON sidecar), the checks a recording passes before
anything is fitted to it, lab exports turned into recordings, command files, the LinuxCNC files,
Klipper's printer.cfg, and safe writing of every output (atomic files, sets published together,
locks on names). The report is :mod:`pipeline.report`.

The names below are imported from their modules when first used: a command loads the formats
it reads or writes, not every one (the lab exports' TOML reader, the checks of a measured
recording).
"""

from calib.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "checks": ("EXCITATION_MAX_ROWS", "JOINT_LIMIT_TOLERANCE", "MAX_ANGLE_RAD", "REACH_FACTOR", "REFUSED_CONDITION",
               "ROTATION_CONVENTION", "WARNED_CONDITION", "RecordingChecks", "plausibility", "recording_checks"),
    "calibration_file": ("ABSURD_TOLERANCES", "CALIBRATION_FORMAT", "CALIBRATION_SUFFIX", "CALIBRATION_VERSION",
                         "Calibration", "CalibrationFileError", "calibration_text", "check_plausible_parameters",
                         "read_calibration", "recording_source", "validity_domain", "write_calibration"),
    "command_file": ("TIME_COLUMN", "command_columns", "command_csv", "read_command_file", "write_command_file",
                     "write_command_rows"),
    "linuxcnc": ("HAL_NAME", "INI_NAME", "NOTES_NAME", "RECORD_NAME", "check_export_folder", "comp_file_name",
                 "comp_text", "genhex_hal_text", "kins_ini_text", "rotarydelta_hal_text", "write_export_folder"),
    "lab_export": ("LabExportError", "LabMap", "import_lab_files", "joint_readings", "read_map",
                   "session_joint_mapping"),
    "lab_checks": ("MapReading", "lab_checks", "map_readings"),
    "klipper": ("KlipperConfig", "KlipperDelta", "KlipperError", "KlipperPrinter", "KlipperRotaryDelta", "ProbeData",
                "klipper_printer", "parse_klipper_text", "read_klipper_config", "read_klipper_printer"),
    "outputs": ("FileLock", "LockHeld", "NameReservation", "OutputError", "ResultSet", "atomic_write",
                "check_outputs", "forget_created_folders", "make_folder", "one_line", "output_folder", "publish",
                "remove_dead_writers_temporaries", "remove_stale_temporaries", "take_back_created_folders",
                "temporary_file", "writing"),
    "targets": ("Targets", "TargetsError", "read_targets"),
    "recording": ("DEFAULT_SESSION", "FORMAT", "FORMAT_VERSION", "MIN_ROBOT_SIZE_MM", "READABLE_VERSIONS",
                  "SESSION_KEYS", "SESSION_TIMES", "SETS", "SIDECAR_FIELDS", "Recording", "RecordingError",
                  "columns", "frame_session", "read_json_file", "read_recording", "read_sidecar_geometry",
                  "recording_texts", "row_message", "recording_header", "sidecar_text", "write_recording_rows",
                  "row_words", "session_measurement", "sidecar_path", "write_recording"),
})
