"""Calibration mathematics for parallel robots (no simulator, no I/O).

Units: mm and rad. Poses are ``[x, y, z, alpha, beta, gamma]`` with
``R = Rz(gamma) Ry(beta) Rx(alpha)``; arrays of poses are (N, 6) float64.
"""

from . import paper
from .hexapod import (
    ERROR_COLUMNS,
    N_PARAMETERS,
    Hexapod,
    HexapodGeometry,
    paper_geometry,
    paper_hexapod,
    parameter_index,
    parameter_table,
)
from .identification import IdentificationResult, identify_forward, identify_paper
from .kinematics import (
    KinematicsError,
    forward_kinematics,
    forward_parameter_jacobian,
    inverse_kinematics,
    leg_vectors,
    parameter_jacobian,
    pose_jacobian,
)
from .outliers import OutlierReport, find_outliers
from .metrics import (
    CompensationEvaluation,
    ConsistencyCheck,
    consistency_check,
    evaluate_compensation,
    integrated_error,
)
from .noise import SensorNoise
from .rotation import (
    euler_from_matrix,
    euler_from_quaternion,
    matrix_from_quaternion,
    quaternion_from_euler,
    rotation_matrix,
)
from .workspace import random_poses
from .design import DesignResult, Workspace, design_poses, full_workspace, paper_workspace
from .effects import EFFECTS, Discovery, EffectData, EffectFit, discover_effect, fit_effect
from .observability import (
    ObservabilityAnalysis,
    PoseUncertainty,
    analyze_observability,
    fisher_information,
    identification_jacobian,
    pose_uncertainty,
)
from . import delta
from .delta import DeltaParams, canonical_params
from .delta_identification import (
    DeltaIdentificationResult,
    GainReport,
    calibration_gain,
    identify_fkm,
    identify_ikm,
)

__all__ = [
    "paper", "ERROR_COLUMNS", "N_PARAMETERS", "Hexapod", "HexapodGeometry", "paper_geometry",
    "paper_hexapod", "parameter_index", "parameter_table", "IdentificationResult",
    "identify_forward", "identify_paper", "KinematicsError", "forward_kinematics",
    "forward_parameter_jacobian", "inverse_kinematics", "leg_vectors", "parameter_jacobian",
    "pose_jacobian", "CompensationEvaluation", "ConsistencyCheck", "consistency_check",
    "evaluate_compensation", "integrated_error", "SensorNoise", "euler_from_matrix",
    "euler_from_quaternion", "matrix_from_quaternion", "quaternion_from_euler",
    "rotation_matrix", "random_poses", "OutlierReport", "find_outliers",
    "delta", "DeltaParams", "canonical_params", "DeltaIdentificationResult", "GainReport",
    "calibration_gain", "identify_fkm", "identify_ikm",
    "DesignResult", "Workspace", "design_poses", "full_workspace", "paper_workspace",
    "EFFECTS", "Discovery", "EffectData", "EffectFit", "discover_effect", "fit_effect",
    "ObservabilityAnalysis", "PoseUncertainty", "analyze_observability", "fisher_information",
    "identification_jacobian", "pose_uncertainty",
]
