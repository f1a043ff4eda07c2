"""The tools' library functions, one module each: settings in, a result object out, usable from
Python with the commands' defaults (:func:`run_calibration`, ...). The commands
(``python -m pipeline.<tool>``) parse their flags, call one of these and print its result."""

from calib.lazy import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "calibration": ("RunSettings", "RunResult", "run_calibration"),
    "discovery": ("DiscoverySettings", "DiscoveryReport", "run_discovery", "discover", "resimulate"),
    "design": ("DesignSettings", "DesignOutcome", "run_design", "optimal_poses", "design_search", "load_robot",
               "DEFAULT_NOISE"),
    "study": ("StudySettings", "StudyOutcome", "run_study", "monte_carlo", "true_errors", "compensation_errors"),
    "blind": ("run_blind_suite", "blind_cases", "blind_case", "rates_table", "failure_lines", "KINDS"),
    "convert": ("ConvertSettings", "ConvertResult", "run_convert"),
    "compensate": ("CompensateSettings", "CompensationReport", "run_compensation"),
    "rereference": ("RereferenceSettings", "RereferenceResult", "run_rereference"),
    "export": ("ExportSettings", "ExportReport", "run_export"),
    "fleet": ("run_fleet", "FleetReport", "calibrate_machine", "fleet_inputs", "input_hash"),
})
