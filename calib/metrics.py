"""Error metrics for any robot: compensation on held-out targets, model consistency, and the
Delta paper's calibration gain G (Eq. 4.1)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .robot import Robot
from .validation import as_array

__all__ = ["CompensationEvaluation", "evaluate_compensation", "ConsistencyCheck", "consistency_check",
           "GainReport", "calibration_gain", "pose_error_norms", "PoseRepeatability", "iso9283_position",
           "repeated_poses", "ISO9283_MIN_REPEATS", "REPEAT_JOINT_TOLERANCE"]


def pose_error_norms(robot: Robot, dQ: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(position, orientation)`` (N,) norms of (N, D) pose errors: mm and rad (0 without angles)."""
    angle = robot.angle_pose_mask
    return np.linalg.norm(dQ[:, ~angle], axis=1), np.linalg.norm(dQ[:, angle], axis=1)


@dataclass(frozen=True, eq=False)
class CompensationEvaluation:
    """Pose errors a controller makes on target poses, before and after compensation.

    Attributes:
        targets: (N, D) target poses.
        reached_before / reached_after: (N, D) poses the machine reaches when the nominal /
            identified model commands it.
        position_before / position_after: (N,) mm, position error norms.
        orientation_before / orientation_after: (N,) rad, angle error norms (0 without angles).
    """

    targets: np.ndarray
    reached_before: np.ndarray
    reached_after: np.ndarray
    position_before: np.ndarray
    position_after: np.ndarray
    orientation_before: np.ndarray
    orientation_after: np.ndarray

    @property
    def improvement(self) -> float:
        """Ratio of mean position error before to after compensation."""
        return float(self.position_before.mean() / self.position_after.mean())

    def summary(self) -> dict:
        """Mean before/after and max after, position (mm) and orientation (rad)."""
        return {
            "position_mm": {"before": float(self.position_before.mean()),
                            "after": float(self.position_after.mean()),
                            "max_after": float(self.position_after.max())},
            "orientation_rad": {"before": float(self.orientation_before.mean()),
                                "after": float(self.orientation_after.mean()),
                                "max_after": float(self.orientation_after.max())},
        }


def evaluate_compensation(robot: Robot, true: np.ndarray, identified: np.ndarray, targets: np.ndarray,
                          nominal: np.ndarray | None = None) -> CompensationEvaluation:
    """Errors on target poses of the machine ``true`` commanded by the nominal and identified models.

    Args:
        robot: the robot.
        true: (P,) the machine's parameters (it moves by their forward kinematics).
        identified: (P,) the parameters found by calibration.
        targets: (N, D) target poses.
        nominal: (P,) the controller's model before calibration; default the robot's nominal.
    """
    nominal = robot.table.nominal if nominal is None else nominal
    before = robot.forward_kinematics(true, robot.inverse_kinematics(nominal, targets), initial=targets)
    after = robot.forward_kinematics(true, robot.inverse_kinematics(identified, targets), initial=targets)
    pb, ob = pose_error_norms(robot, before - targets)
    pa, oa = pose_error_norms(robot, after - targets)
    return CompensationEvaluation(targets, before, after, pb, pa, ob, oa)


@dataclass(frozen=True, eq=False)
class ConsistencyCheck:
    """Measured poses compared with what a model of the machine predicts.

    Attributes:
        predicted: (N, D) predicted poses.
        position_deviation: (N,) mm, max abs deviation of the position coordinates.
        orientation_deviation: (N,) rad, max abs deviation of the angles (0 without angles).
        consistent: (N,) bool, both deviations within the tolerances.
    """

    predicted: np.ndarray
    position_deviation: np.ndarray
    orientation_deviation: np.ndarray
    consistent: np.ndarray

    @property
    def flagged(self) -> list[int]:
        """0-based indices of inconsistent rows."""
        return [int(i) for i in np.flatnonzero(~self.consistent)]


def consistency_check(robot: Robot, theta: np.ndarray, joints: np.ndarray, measured: np.ndarray, *,
                      tol_mm: float, tol_rad: float) -> ConsistencyCheck:
    """Which measured rows the model ``theta`` of the machine cannot reproduce.

    Used to reproduce Table 4 of the hexapod paper (model Table 2 + Table 3, joints the nominal
    inverse kinematics of the targets).
    """
    predicted = robot.forward_kinematics(theta, joints, initial=measured)
    dev = np.abs(predicted - measured)
    angle = robot.angle_pose_mask
    pos = dev[:, ~angle].max(axis=1)
    ang = dev[:, angle].max(axis=1) if angle.any() else np.zeros(len(dev))
    return ConsistencyCheck(predicted, pos, ang, (pos <= tol_mm) & (ang <= tol_rad))


@dataclass(frozen=True)
class GainReport:
    """Calibration gain G of the Delta paper's Eq. (4.1), in percent.

    Attributes:
        names: parameter names the gains refer to.
        per_parameter: ``100 (|Pr-Pn| - |Pr-Pc|) / |Pr-Pn|`` per parameter, (K,); NaN where the
            initial error is exactly zero.
        mean: mean of ``per_parameter`` over the parameters: the paper's figure ("percentage
            average of the gain on all parameters"), NaN entries ignored.
        norm: Eq. (4.1) applied to the norm of the error vector over all listed parameters,
            lengths in mm and angles in degrees (the paper states errors in "mm/degrees").
    """

    names: tuple
    per_parameter: np.ndarray
    mean: float
    norm: float

    def as_dict(self) -> dict:
        """JSON-ready: per-parameter gains by name, mean and norm (percent)."""
        return {"per_parameter": {n: (None if not np.isfinite(g) else float(g))
                                  for n, g in zip(self.names, self.per_parameter)},
                "mean": float(self.mean), "norm": float(self.norm)}


def calibration_gain(robot: Robot, true: np.ndarray, nominal: np.ndarray, calibrated: np.ndarray,
                     names=None) -> GainReport:
    """Calibration gain G per parameter, averaged (the paper's figure) and on the error norm.

    Args:
        robot: the robot (units of its parameters).
        true, nominal, calibrated: (P,) the machine's parameters ``Pr`` (in the gauge of the
            identification, see :func:`calib.identifiability.gauge_representative`), the start
            ``Pn`` and the identified ``Pc``.
        names: parameters to score; default the robot's identifiable ones (``free_default``).
    """
    names = tuple(robot.free_default if names is None else names)
    idx = robot.table.indices(names)
    pr, pn, pc = (np.asarray(v, dtype=float)[idx] for v in (true, nominal, calibrated))
    e0, e1 = np.abs(pr - pn), np.abs(pr - pc)
    with np.errstate(divide="ignore", invalid="ignore"):
        per = np.where(e0 > 0, 100.0 * (e0 - e1) / e0, np.nan)
    scale = np.where(robot.table.angle_mask()[idx], 180.0 / np.pi, 1.0)
    n0, n1 = np.linalg.norm(scale * (pr - pn)), np.linalg.norm(scale * (pr - pc))
    norm = 100.0 * (n0 - n1) / n0 if n0 > 0 else float("nan")
    mean = float(np.nanmean(per)) if np.any(np.isfinite(per)) else float("nan")
    return GainReport(names=names, per_parameter=per, mean=mean, norm=float(norm))


#: Visits of one commanded pose needed for its ISO 9283 figures (a spread needs three to mean much).
ISO9283_MIN_REPEATS = 3
#: Rows whose joints agree within this (the robot's joint unit, mm or rad) plus five declared
#: joint-noise standard deviations are visits of one commanded pose (:func:`repeated_poses`).
REPEAT_JOINT_TOLERANCE = 1e-6


def repeated_poses(joints: np.ndarray, joint_noise_std: float = 0.0) -> np.ndarray:
    """Which rows visit the same commanded pose: (N,) int labels, rows sharing one label repeat a
    pose (labels 0, 1, ... in the order of their first row).

    Args:
        joints: (N, C) joint commands or readings, the robot's joint unit.
        joint_noise_std: the readings' noise (standard deviation, joint unit); rows whose every
            joint agrees within :data:`REPEAT_JOINT_TOLERANCE` plus five of it with a group's first
            row join that group.
    """
    joints = as_array(joints, "joints", (-1, -1))
    tol = REPEAT_JOINT_TOLERANCE + 5.0 * float(joint_noise_std)
    labels = np.full(len(joints), -1, dtype=int)
    k = 0
    for i in range(len(joints)):
        if labels[i] >= 0:
            continue
        same = (labels < 0) & np.all(np.abs(joints - joints[i]) <= tol, axis=1)
        labels[same] = k
        k += 1
    return labels


@dataclass(frozen=True, eq=False)
class PoseRepeatability:
    """ISO 9283 positional accuracy and repeatability of each commanded pose visited at least
    :data:`ISO9283_MIN_REPEATS` times.

    Attributes:
        rows: one (n_j,) int array per pose, the 0-based rows visiting it.
        accuracy: (J,) mm, AP_j: distance from the barycentre of the attained positions to the
            commanded position.
        repeatability: (J,) mm, RP_j = l_bar + 3 S_l, l the distances of the attained positions
            to their barycentre, S_l their sample standard deviation (n_j - 1).
        barycentre_offset: (J, 3) mm, barycentre minus command (x, y, z).
    """

    rows: tuple
    accuracy: np.ndarray
    repeatability: np.ndarray
    barycentre_offset: np.ndarray

    def as_dict(self) -> dict:
        """JSON-ready: per pose its rows (0-based), number of visits, AP and RP (mm)."""
        return {"poses": [{"rows": [int(r) for r in rows], "repeats": int(len(rows)), "AP_mm": float(ap),
                           "RP_mm": float(rp)} for rows, ap, rp in zip(self.rows, self.accuracy, self.repeatability)]}


def iso9283_position(attained: np.ndarray, commanded: np.ndarray, groups: np.ndarray,
                     min_repeats: int = ISO9283_MIN_REPEATS) -> PoseRepeatability:
    """ISO 9283 (7.2.1, 7.2.2) positional accuracy AP and repeatability RP of repeated poses.

    Args:
        attained: (N, 3) mm, the positions reached (measured), any frame.
        commanded: (N, 3) mm, the positions commanded, the same frame (one command per group: the
            group's rows carry the same command; their mean is taken).
        groups: (N,) int, rows sharing a label visit one commanded pose (:func:`repeated_poses`).
        min_repeats: poses visited fewer times are left out.

    Since only ``attained - commanded`` enters, errors (attained minus command) can be passed with
    a zero command.
    """
    attained = as_array(attained, "attained", (-1, 3))
    commanded = as_array(commanded, "commanded", (len(attained), 3))
    groups = np.asarray(groups, dtype=int)
    if groups.shape != (len(attained),):
        raise ValueError(f"groups must have shape ({len(attained)},), got {groups.shape}")
    rows, ap, rp, off = [], [], [], []
    for g in np.unique(groups):
        at = np.flatnonzero(groups == g)
        if at.size < min_repeats:
            continue
        bary = attained[at].mean(axis=0)
        l = np.linalg.norm(attained[at] - bary, axis=1)
        offset = bary - commanded[at].mean(axis=0)
        rows.append(at)
        off.append(offset)
        ap.append(float(np.linalg.norm(offset)))
        rp.append(float(l.mean() + 3.0 * l.std(ddof=1)))
    return PoseRepeatability(tuple(rows), np.array(ap), np.array(rp), np.array(off).reshape(-1, 3))
