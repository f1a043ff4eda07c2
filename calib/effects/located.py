"""Where the residuals of the geometry-only fit concentrate: per chain, per pose coordinate, in
the workspace, in time and with the direction of motion (a room of :mod:`calib.effects.discovery`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robot import KinematicsError
from .base import EffectData
from .joint_fit import EffectFit
from .remainder import root_mean_square
from .whitening import closure_noise_std

__all__ = ["WorkspaceThirds", "Located", "locate_mismatch"]


@dataclass(frozen=True)
class WorkspaceThirds:
    """The per-pose residual RMS (noise standard deviations) in the lower and upper thirds of one
    pose coordinate."""

    coordinate: str
    low_third_rms: float
    high_third_rms: float


@dataclass(frozen=True, eq=False)
class Located:
    """Where the geometry-only residuals concentrate (:func:`locate_mismatch`); RMS in noise
    standard deviations.

    Attributes:
        joint_space_rms_per_chain: (C,) each chain's standardised closure residual RMS.
        pose_names: the pose coordinates; task_space_rms_per_dof: (D,) the forward-kinematics
            residual's RMS per coordinate (NaN where the forward kinematics fails).
        workspace_thirds: per pose coordinate (:class:`WorkspaceThirds`).
        time_thirds_rms: in the first, middle and last thirds of the record.
        time_correlation: of the mean residual with time.
        direction_contrast_se: chains whose joint last increased minus those whose joint last
            decreased, standard errors.
        worst_poses: the five rows (0-based, of the rows analysed) with the largest residual.
        summary: the findings in words.
    """

    joint_space_rms_per_chain: np.ndarray
    pose_names: tuple
    task_space_rms_per_dof: np.ndarray
    workspace_thirds: tuple
    time_thirds_rms: tuple
    time_correlation: float
    direction_contrast_se: float
    worst_poses: tuple
    summary: tuple

    def to_dict(self) -> dict:
        """JSON-ready (the summary's ``located``)."""
        return {"joint_space_rms_per_chain": self.joint_space_rms_per_chain.tolist(),
                "task_space_rms_per_dof": dict(zip(self.pose_names, self.task_space_rms_per_dof.tolist())),
                "workspace_thirds": {w.coordinate: {"low_third_rms": w.low_third_rms, "high_third_rms": w.high_third_rms}
                                     for w in self.workspace_thirds},
                "time_thirds_rms": list(self.time_thirds_rms), "time_correlation": self.time_correlation,
                "direction_contrast_se": self.direction_contrast_se, "worst_poses": list(self.worst_poses),
                "summary": list(self.summary)}


def locate_mismatch(data: EffectData, geometry_fit: EffectFit) -> Located:
    """Where the residuals of the geometry-only fit concentrate.

    Joint space: RMS of the standardised closure residuals per chain. Task space: RMS of
    ``measured - FK(identified, q_cmd)`` per pose coordinate over its declared standard
    deviation (NaN where the forward kinematics fails). Workspace: for each pose coordinate,
    the per-pose residual RMS in its lower and upper thirds. Time: in the first, middle and last
    thirds of the record. Direction of motion: the mean residual of chains whose joint last
    increased minus that of chains whose joint last decreased, in standard errors (hysteresis
    shows here).

    Returns:
        :class:`Located`; its ``summary`` holds the findings in words.
    """
    robot, theta = data.robot, geometry_fit.theta
    z = geometry_fit.residuals / closure_noise_std(robot, theta, data)  # standardised closure residuals
    per_chain = root_mean_square(z, axis=0)
    try:
        pred = robot.forward_kinematics(theta, data.joints, initial=data.measured)
        per_dof = root_mean_square((data.measured - pred) / data.noise.pose_std(robot.pose_units), axis=0)
    except KinematicsError:
        per_dof = np.full(robot.pose_dim, np.nan)
    per_pose = root_mean_square(z, axis=1)
    region = []
    for k, name in enumerate(robot.pose_names):
        q = np.quantile(data.measured[:, k], [1 / 3, 2 / 3])
        lo, hi = data.measured[:, k] <= q[0], data.measured[:, k] >= q[1]
        region.append(WorkspaceThirds(name, float(root_mean_square(per_pose[lo])), float(root_mean_square(per_pose[hi]))))
    thirds = np.array_split(np.argsort(data.t_s), 3)
    time_rms = [float(root_mean_square(per_pose[s])) for s in thirds]
    tc = np.corrcoef(data.t_s, z.mean(axis=1))[0, 1] if np.ptp(data.t_s) > 0 else 0.0
    up, down = z[data.direction > 0], z[data.direction < 0]
    if up.size > 1 and down.size > 1:
        hyst = float((up.mean() - down.mean()) / np.sqrt(up.var() / up.size + down.var() / down.size))
    else:
        hyst = 0.0
    worst = int(np.argmax(per_chain))
    reg = max(region, key=lambda w: abs(w.high_third_rms - w.low_third_rms))
    chain = robot.chain_word
    summary = [
        f"joint space: residual RMS per {chain} {', '.join(f'{v:.2f}' for v in per_chain)} (in noise standard "
        f"deviations); largest on {chain} {worst + 1}",
        f"task space: RMS per coordinate {' '.join(robot.pose_names)} {', '.join(f'{v:.2f}' for v in per_dof)} "
        f"(noise standard deviations)",
        f"workspace: largest contrast along {reg.coordinate}: low third {reg.low_third_rms:.2f}, "
        f"high third {reg.high_third_rms:.2f}",
        f"time: RMS in first/middle/last third {', '.join(f'{v:.2f}' for v in time_rms)}; correlation of the "
        f"mean residual with time {tc:+.2f}",
        f"direction of motion: {chain}s whose joint last increased minus those whose joint last decreased: "
        f"{hyst:+.1f} standard errors",
    ]
    return Located(per_chain, tuple(robot.pose_names), per_dof, tuple(region), tuple(time_rms), float(tc), hyst,
                   tuple(int(i) for i in np.argsort(per_pose)[::-1][:5]), tuple(summary))
