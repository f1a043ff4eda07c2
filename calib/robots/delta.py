"""The Delta robot on the robot interface: Model 24 of the Delta calibration paper.

The kinematics (:class:`calib.delta.DeltaParams`, closed-form IK and FK, closure Jacobians) live
in :mod:`calib.delta`; this module presents them as a :class:`calib.robot.Robot`.
"""

from __future__ import annotations

import numpy as np

from ..delta import (
    CHAIN_PARAMETER_UNITS,
    NOMINAL_GEOMETRY,
    DeltaParams,
    constraint_jacobian_joints,
    constraint_jacobian_params,
    constraint_jacobian_position,
    constraint_residuals,
    elbow_positions,
    forward_kinematics,
    inverse_kinematics,
)
from .._validate import as_array
from ..robot import ClosureJacobians, KinematicsError, Parameter, ParameterTable, Robot

__all__ = ["Delta", "CHAIN_TABLE_NAMES", "HOME_POSITION_MM", "WORKSPACE_BOUNDS_MM", "JOINT_RANGE_RAD"]


# --------------------------------------------------------------------------- robot interface

#: Names of a chain's eight parameters in the robot's table (``D.x`` -> ``D2.x``).
CHAIN_TABLE_NAMES: tuple[str, ...] = ("D.x", "D.y", "D.z", "theta", "alpha", "Lax", "Lay", "Lb")
#: Plate-centre home position of the default Delta, mm, base frame.
HOME_POSITION_MM = (0.0, 0.0, -420.0)
#: Default calibration workspace of the paper's Delta: a box in x, y and z, mm.
WORKSPACE_BOUNDS_MM = ((-150.0, 150.0), (-150.0, 150.0), (-500.0, -330.0))
#: Range of the actuated joints, rad.
JOINT_RANGE_RAD = (-np.pi / 2, np.pi / 2)


def _chain_name(template: str, chain: int) -> str:
    head, _, tail = template.partition(".")
    return f"{head}{chain + 1}" + (f".{tail}" if tail else "")


class Delta(Robot):
    """A Delta robot (three rotary-actuated parallelogram chains, translating plate), Model 24.

    Pose: the plate centre ``(x, y, z)`` in mm (the parallelograms hold the plate's orientation).
    Joints: the arm angles ``q1..q3`` read by the motors (rad). Parameters: the 24 of
    :class:`DeltaParams` named ``D{i}.x D{i}.y D{i}.z theta{i} alpha{i} Lax{i} Lay{i} Lb{i}``;
    ``Lay1..3`` are held by default (gauge: with the joint offset they form one unidentifiable
    direction per chain, see :func:`canonical_params`).

    Args:
        nominal: nominal parameters (default the paper's Delta).
        rn_mm: plate radius (centre to forearm attachment), mm: physical size of the machine
            built in MuJoCo; the kinematics use the reduced model.
        home_position_mm: (3,) home plate position, start of iterations.
        workspace_mm: (3, 2) calibration workspace box, mm.
    """

    name = "delta"
    pose_names = ("x", "y", "z")
    pose_units = ("mm", "mm", "mm")
    joint_unit = "rad"
    joint_symbol = "q"
    chain_word = "chain"
    gauge_fixed = ("Lay1", "Lay2", "Lay3")

    def __init__(self, nominal: DeltaParams | None = None, *, rn_mm: float = NOMINAL_GEOMETRY["Rn_mm"],
                 home_position_mm=HOME_POSITION_MM, workspace_mm=WORKSPACE_BOUNDS_MM):
        self.nominal_params = DeltaParams.nominal() if nominal is None else nominal
        if not isinstance(self.nominal_params, DeltaParams):
            raise TypeError(f"nominal must be a DeltaParams, got {type(self.nominal_params).__name__}")
        if not (np.isfinite(rn_mm) and rn_mm >= 0):
            raise ValueError(f"rn_mm must be finite and >= 0, got {rn_mm!r}")
        self.rn_mm = float(rn_mm)
        self._home = as_array(home_position_mm, "home_position_mm", (3,))
        self._workspace = as_array(workspace_mm, "workspace_mm", (3, 2))
        v = self.nominal_params.to_vector()
        self.table = ParameterTable([
            Parameter(_chain_name(t, c), CHAIN_PARAMETER_UNITS[k], float(v[8 * c + k]), c)
            for c in range(3) for k, t in enumerate(CHAIN_TABLE_NAMES)])

    @property
    def home_pose(self) -> np.ndarray:
        return self._home.copy()

    @property
    def length_scale_mm(self) -> float:
        return float(np.mean(np.hypot(self.nominal_params.Lax, self.nominal_params.Lay)))

    def workspace_bounds(self) -> np.ndarray:
        return self._workspace.copy()

    def joint_limits(self) -> np.ndarray:
        return np.tile(JOINT_RANGE_RAD, (3, 1))

    def description(self) -> dict:
        return {"parameters": self.table.to_dict(self.table.nominal), "rn_mm": self.rn_mm,
                "home_position_mm": self._home.tolist(), "workspace_mm": self._workspace.tolist()}

    @classmethod
    def from_description(cls, description: dict) -> "Delta":
        names = [_chain_name(t, c) for c in range(3) for t in CHAIN_TABLE_NAMES]
        values = description["parameters"]
        missing = [n for n in names if n not in values]
        if missing:
            raise KeyError(f"parameters: missing {', '.join(missing)}")
        return cls(DeltaParams.from_vector([values[n] for n in names]),
                   rn_mm=description.get("rn_mm", NOMINAL_GEOMETRY["Rn_mm"]),
                   home_position_mm=description.get("home_position_mm", HOME_POSITION_MM),
                   workspace_mm=description.get("workspace_mm", WORKSPACE_BOUNDS_MM))

    @staticmethod
    def params(theta: np.ndarray) -> DeltaParams:
        """The structured :class:`DeltaParams` view of a flat parameter vector."""
        return DeltaParams.from_vector(theta)

    def chain_points(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """Physical points: actuated joint, elbow, plate attachment (the reduced model shifted by
        each chain's plate attachment of radius ``rn_mm``)."""
        p = self.params(theta)
        attach = self.rn_mm * np.stack([np.cos(p.theta), np.sin(p.theta), np.zeros(3)], axis=1)
        elbow = elbow_positions(p, joints) + attach[None]
        shoulder = np.broadcast_to(p.shoulders() + attach, elbow.shape)
        plate = poses[:, None, :] + attach[None]
        return np.stack([shoulder, elbow, plate], axis=2)

    def inverse_kinematics(self, theta: np.ndarray, poses: np.ndarray) -> np.ndarray:
        try:
            return inverse_kinematics(self.params(theta), poses)
        except ValueError as exc:
            raise KinematicsError(str(exc), _row_of(exc)) from None

    def forward_kinematics(self, theta: np.ndarray, joints: np.ndarray, *, initial=None) -> np.ndarray:
        try:
            return forward_kinematics(self.params(theta), joints)
        except ValueError as exc:
            raise KinematicsError(str(exc), _row_of(exc)) from None

    def closure(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        return constraint_residuals(self.params(theta), joints, poses)

    def closure_jacobians(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> ClosureJacobians:
        p = self.params(theta)
        n = joints.shape[0]
        jp = np.zeros((n, 3, 3, 8))
        idx = np.arange(3)
        jp[:, idx, idx] = constraint_jacobian_params(p, joints, poses)
        return ClosureJacobians(pose=constraint_jacobian_position(p, joints, poses),
                                joints=constraint_jacobian_joints(p, joints, poses)[:, :, None] * np.eye(3)[None],
                                parameters=jp.reshape(n, 3, 24))


def _row_of(exc: ValueError) -> int:
    """The configuration index named by a kinematics message (``configuration 12: ...``)."""
    text = str(exc)
    if text.startswith("configuration "):
        head = text[len("configuration "):].split(":", 1)[0]
        if head.isdigit():
            return int(head)
    return 0
