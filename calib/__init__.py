"""Calibration mathematics for parallel robots (no simulator, no I/O).

One robot interface (:mod:`calib.robot`), one module per robot (:mod:`calib.robots`), one engine
over it (:mod:`calib.engine`, :mod:`calib.outliers`, :mod:`calib.metrics`). Units: mm and rad.
Poses are ``(N, D)`` float64 in the robot's pose coordinates (the hexapod's
``[x, y, z, alpha, beta, gamma]`` with ``R = Rz(gamma) Ry(beta) Rx(alpha)``).

The names below are imported from their modules when first used (``import calib.robot`` does
not load SciPy).
"""

from __future__ import annotations

import importlib

from . import paper

__all__ = [
    "paper", "IdentificationResult", "gauge_representative", "identify", "identify_chainwise",
    "identify_forward", "integrated_error", "noise_verdict", "CompensationEvaluation",
    "ConsistencyCheck", "GainReport", "calibration_gain", "consistency_check", "evaluate_compensation",
    "pose_error_norms", "SensorNoise", "OutlierReport", "find_outliers", "ClosureJacobians",
    "KinematicsError", "Parameter", "ParameterTable", "Robot", "ROBOTS", "Delta", "Hexapod",
    "default_robot", "robot_from_description", "euler_from_matrix", "euler_from_quaternion",
    "matrix_from_quaternion", "quaternion_from_euler", "rotation_matrix", "random_poses",
    "reachable_poses", "DesignResult", "Workspace", "design_poses", "robot_workspace",
    "ObservabilityAnalysis", "PoseUncertainty", "analyze_observability", "fisher_information",
    "identification_jacobian", "pose_uncertainty", "ParameterPrior",
]

#: submodule -> the names this package re-exports from it (imported on first use).
_EXPORTS = {
    "engine": ("IdentificationResult", "gauge_representative", "identify", "identify_chainwise",
               "identify_forward", "integrated_error", "noise_verdict"),
    "metrics": ("CompensationEvaluation", "ConsistencyCheck", "GainReport", "calibration_gain", "consistency_check",
                "evaluate_compensation", "pose_error_norms"),
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
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}


def __getattr__(name: str):
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'calib' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_MODULE_OF))
