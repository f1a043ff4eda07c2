"""File formats: the recording (CSV + JSON sidecar), the checks a recording passes before
anything is fitted to it, lab exports turned into recordings, command files, the HTML report, and
safe writing of every output (atomic files, sets published together, locks on names)."""

from .checks import (JOINT_LIMIT_TOLERANCE, REFUSED_CONDITION, ROTATION_CONVENTION, WARNED_CONDITION,
                     RecordingChecks, plausibility, recording_checks)
from .calibration_file import (ABSURD_TOLERANCES, CALIBRATION_FORMAT, CALIBRATION_SUFFIX, CALIBRATION_VERSION,
                               Calibration, CalibrationFileError, calibration_text, check_plausible_parameters,
                               read_calibration, recording_source, validity_domain, write_calibration)
from .command_file import TIME_COLUMN, command_columns, command_csv, read_command_file, write_command_file
from .linuxcnc import (HAL_NAME, INI_NAME, NOTES_NAME, RECORD_NAME, check_export_folder, comp_file_name, comp_text, genhex_hal_text, kins_ini_text,
                       rotarydelta_hal_text, write_export_folder)
from .lab_export import LabExportError, LabMap, convert_lab_files, joint_readings, read_map, session_joint_mapping
from .lab_checks import MapReading, lab_checks, map_readings
from .outputs import (FileLock, LockHeld, NameReservation, OutputError, ResultSet, atomic_write, check_outputs,
                      forget_created_folders, make_folder, one_line, output_folder, publish,
                      remove_dead_writers_temporaries, remove_stale_temporaries, take_back_created_folders,
                      temporary_file, writing)
from .targets import Targets, TargetsError, read_targets
from .report import Report, build_report
from .report_html import render_html, write_report
from .recording import (DEFAULT_SESSION, FORMAT, FORMAT_VERSION, MIN_ROBOT_SIZE_MM, READABLE_VERSIONS, SESSION_KEYS,
                        SESSION_TIMES, SETS, SIDECAR_FIELDS, Recording, RecordingError, columns, read_json_file,
                        read_recording,
                        recording_texts, row_message, row_words, session_measurement, frame_session, sidecar_path,
                        write_recording)

__all__ = ["Recording", "RecordingError", "read_recording", "write_recording", "recording_texts", "columns",
           "sidecar_path", "read_json_file", "session_measurement", "frame_session", "joint_readings",
           "session_joint_mapping", "row_words", "row_message", "plausibility", "recording_checks", "RecordingChecks",
           "LabExportError", "LabMap", "convert_lab_files", "read_map", "lab_checks", "map_readings", "MapReading", "command_columns", "command_csv",
           "read_command_file", "write_command_file", "check_outputs", "one_line", "FileLock", "LockHeld",
           "NameReservation", "remove_stale_temporaries", "remove_dead_writers_temporaries", "temporary_file",
           "make_folder", "forget_created_folders", "take_back_created_folders", "OutputError", "ResultSet", "atomic_write",
           "output_folder", "publish", "writing", "FORMAT", "FORMAT_VERSION", "READABLE_VERSIONS", "SETS",
           "SIDECAR_FIELDS", "MIN_ROBOT_SIZE_MM", "DEFAULT_SESSION", "SESSION_KEYS", "SESSION_TIMES",
           "Calibration", "CalibrationFileError", "read_calibration", "check_plausible_parameters", "ABSURD_TOLERANCES", "write_calibration", "calibration_text",
           "recording_source", "validity_domain", "CALIBRATION_FORMAT", "CALIBRATION_VERSION", "CALIBRATION_SUFFIX",
           "Targets", "TargetsError", "read_targets", "TIME_COLUMN", "Report", "build_report", "render_html",
           "write_report",
           "HAL_NAME", "INI_NAME", "NOTES_NAME", "RECORD_NAME", "check_export_folder", "comp_file_name", "comp_text", "genhex_hal_text", "kins_ini_text",
           "rotarydelta_hal_text", "write_export_folder", "JOINT_LIMIT_TOLERANCE", "REFUSED_CONDITION", "WARNED_CONDITION", "ROTATION_CONVENTION"]
