"""Calibration mathematics for parallel robots (no simulator, no I/O).

One robot interface (:mod:`calib.robot`), one module per robot (:mod:`calib.robots`), one engine
over it (:mod:`calib.engine`, :mod:`calib.outliers`, :mod:`calib.metrics`). Units: mm and rad.
Poses are ``(N, D)`` float64 in the robot's pose coordinates (the hexapod's
``[x, y, z, alpha, beta, gamma]`` with ``R = Rz(gamma) Ry(beta) Rx(alpha)``).

The names below are imported from their modules when first used (``import calib.robot`` does
not load SciPy).
"""

from __future__ import annotations

from . import paper
from .lazy import lazy_exports

lazily_exported, __getattr__, __dir__ = lazy_exports(__name__, {
    "engine": ("IdentificationResult", "gauge_representative", "identify", "identify_chainwise",
               "identify_forward", "integrated_error", "noise_verdict"),
    "metrics": ("CompensationEvaluation", "ConsistencyCheck", "GainReport", "calibration_gain", "consistency_check",
                "evaluate_compensation", "pose_error_norms", "PoseRepeatability", "iso9283_position", "repeated_poses"),
    "noise": ("SensorNoise",),
    "outliers": ("OutlierReport", "find_outliers"),
    "robot": ("ClosureJacobians", "KinematicsError", "Parameter", "ParameterTable", "Robot"),
    "robots": ("ROBOTS", "Delta", "Hexapod", "default_robot", "robot_from_description"),
    "rotation": ("euler_from_matrix", "euler_from_quaternion", "matrix_from_quaternion", "quaternion_from_euler",
                 "rotation_matrix"),
    "workspace": ("random_poses", "reachable_poses"),
    "design": ("DesignResult", "Workspace", "design_poses", "robot_workspace"),
    "observability": ("ObservabilityAnalysis", "PoseUncertainty", "analyze_observability", "fisher_information",
                      "identification_jacobian", "pose_uncertainty"),
    "prior": ("ParameterPrior",),
    "crossval": ("CrossValidation", "crossvalidate", "crossvalidate_model"),
    "calibration": ("Calibration", "CalibrationFileError"),
    "identification": ("CalibrationOutcome", "calibrate"),
})
__all__ = ["paper", *lazily_exported]
