"""Calibration mathematics for parallel robots (no simulator, no I/O).

One robot interface (:mod:`calib.robot`), one module per robot (:mod:`calib.robots`), one engine
over it (:mod:`calib.engine`, :mod:`calib.outliers`, :mod:`calib.metrics`). Units: mm and rad.
Poses are ``(N, D)`` float64 in the robot's pose coordinates (the hexapod's
``[x, y, z, alpha, beta, gamma]`` with ``R = Rz(gamma) Ry(beta) Rx(alpha)``).
"""

from . import paper
from .engine import (
    IdentificationResult,
    gauge_representative,
    identify,
    identify_chainwise,
    identify_forward,
    integrated_error,
    noise_verdict,
)
from .metrics import (
    CompensationEvaluation,
    ConsistencyCheck,
    GainReport,
    calibration_gain,
    consistency_check,
    evaluate_compensation,
    pose_error_norms,
)
from .noise import SensorNoise
from .outliers import OutlierReport, find_outliers
from .robot import ClosureJacobians, KinematicsError, Parameter, ParameterTable, Robot
from .robots import ROBOTS, Delta, Hexapod, default_robot, robot_from_description
from .rotation import (
    euler_from_matrix,
    euler_from_quaternion,
    matrix_from_quaternion,
    quaternion_from_euler,
    rotation_matrix,
)
from .workspace import random_poses, reachable_poses
from .design import DesignResult, Workspace, design_poses, robot_workspace
from .observability import (
    ObservabilityAnalysis,
    PoseUncertainty,
    analyze_observability,
    fisher_information,
    identification_jacobian,
    pose_uncertainty,
)

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
    "identification_jacobian", "pose_uncertainty",
]
