"""Checks that a machine can have produced a recording, before anything is fitted to it: units,
reach, rotation convention, repeated rows, excitation. Each refusal names the file, row and
column and what the file seems to hold."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.measurement import measurement_settings, target_names
from calib.rotation import rotation_matrix

from .recording import Recording, RecordingError, columns

__all__ = ["plausibility", "REFUSED_CONDITION", "WARNED_CONDITION", "ROTATION_CONVENTION"]


#: Column-scaled condition number of the identification Jacobian above which the calibration
#: poses are refused (too alike to tell the parameters apart), and above which a warning is given.
#: Poses spread over the workspace give 1e2 to 1e5.
REFUSED_CONDITION = 1e8


WARNED_CONDITION = 1e6


def _row(path: Path, r: int) -> str:
    """How messages name the 0-based data row ``r``: its spreadsheet row number and file line."""
    return f"{path}: row {r + 1} (line {r + 2})"


def _condition_in_words(cond: float) -> str:
    if not np.isfinite(cond) or cond > 1e12:
        return "numerically singular"
    if cond > REFUSED_CONDITION:
        return "nearly singular"
    return "poorly conditioned"


#: The rotation convention of recordings (the project's).
ROTATION_CONVENTION = "R = Rz(gamma) Ry(beta) Rx(alpha) (platform to base, angles in the columns alpha, beta, gamma)"


def _other_rotation_convention(rec: Recording) -> str | None:
    """The convention the recording's angles seem to follow when it is not the project's: the
    geometry identified (forward method) with the angles read in another convention explains the
    calibration rows at least ten times better (chi-square) than with the project's, which
    misfits (chi-square above 4 per degree of freedom); None otherwise. Only then: for small
    angles the conventions differ at second order, like a geometric error, so only a fit tells
    them apart."""
    from scipy.spatial.transform import Rotation

    from calib.engine import identify_forward
    from calib.rotation import euler_from_matrix

    joints, measured = rec.subset("calibration")
    robot = rec.robot
    angle = robot.angle_pose_mask
    angles = measured[:, angle]

    def chi2(converted_angles) -> float:
        poses = measured.copy()
        poses[:, angle] = converted_angles
        try:
            fit = identify_forward(robot, joints, poses, rec.noise)
        except (ValueError, ArithmeticError):  # KinematicsError is a ValueError
            return float("inf")
        value = fit.chi2 / max(fit.dof, 1)
        return value if np.isfinite(value) else float("inf")

    declared = chi2(angles)
    if not declared > 4.0:
        return None
    candidates = {
        "R = Rx(alpha) Ry(beta) Rz(gamma)": lambda: euler_from_matrix(Rotation.from_euler("XYZ", angles).as_matrix()),
        "the inverse rotation (base to platform)": lambda: euler_from_matrix(np.swapaxes(rotation_matrix(angles), 1, 2)),
        "the columns in the order gamma, beta, alpha": lambda: angles[:, ::-1],
    }
    misfit = {name: chi2(convert()) for name, convert in candidates.items()}
    best = min(misfit, key=misfit.get)
    return best if misfit[best] < 0.1 * declared else None


@dataclass(frozen=True)
class _PoseColumns:
    """How a recording's pose columns are checked.

    Attributes:
        names: (D,) the columns' names.
        angle: (D,) bool, the columns holding angles (rad).
        fk: (N, D) where the nominal geometry puts the platform at the recorded joints (mm, rad),
            or None: target positions in an instrument's frame, or the forward kinematics failed.
        n_targets: targets measured per row (0: poses).
    """

    names: tuple[str, ...]
    angle: np.ndarray
    fk: np.ndarray | None
    n_targets: int


def _check_joint_range(rec: Recording, path: Path) -> None:
    """Refuse joint values outside the nominal geometry's range (the stroke of a leg), saying so
    when the whole file seems to hold metres for mm or degrees for rad."""
    robot = rec.robot
    joint_cols, _ = columns(robot)
    limits = robot.joint_limits()
    q = rec.joints
    out = (q < limits[:, 0]) | (q > limits[:, 1])
    if not out.any():
        return
    unit = robot.joint_unit
    factor = 1000.0 if unit == "mm" else 180.0 / np.pi
    other = "metres" if unit == "mm" else "degrees"
    scaled = q * factor if unit == "mm" else np.deg2rad(q)
    if out.all(axis=1).any() and not ((scaled < limits[:, 0]) | (scaled > limits[:, 1])).any():
        raise RecordingError(f"{path}: columns {', '.join(joint_cols)}: the joint values seem to be in "
                             f"{other} (e.g. {q[0, 0]:.6g}), a recording holds {unit}")
    r, c = np.argwhere(out)[0]
    raise RecordingError(f"{_row(path, r)}, column {joint_cols[c]!r}: {q[r, c]:.6g} {unit} is outside the "
                         f"range [{limits[c, 0]:.6g}, {limits[c, 1]:.6g}] {unit} of the nominal geometry: "
                         "the machine cannot reach it")


def _pose_columns(rec: Recording) -> _PoseColumns:
    """The recording's pose columns, which hold angles, and the poses the nominal geometry gives."""
    from calib.robot import KinematicsError

    robot = rec.robot
    n_targets = measurement_settings(rec.meta.get("measurement")).n_targets
    if n_targets:  # target positions (columns t1_x_mm ...), in the instrument's frame: no pose checks
        return _PoseColumns(names=tuple(f"{n}_mm" for n in target_names(n_targets)),
                            angle=np.zeros(rec.measured.shape[1], dtype=bool), fk=None, n_targets=n_targets)
    try:
        fk = robot.forward_kinematics(robot.table.nominal, rec.joints,
                                      initial=np.repeat(robot.home_pose[None], len(rec.joints), axis=0))
    except KinematicsError:
        fk = None
    return _PoseColumns(names=columns(robot)[1], angle=robot.angle_pose_mask, fk=fk, n_targets=0)


def _check_position_units(rec: Recording, poses: _PoseColumns, path: Path) -> float:
    """Refuse positions in metres: read as metres they match the nominal forward kinematics
    (``poses.fk``, not None) ten times better than read as mm. Returns the median
    |measured - fk| of the position columns (mm)."""
    m, fk, pos = rec.measured, poses.fk, ~poses.angle
    e1 = np.median(np.abs(m[:, pos] - fk[:, pos]))
    e1000 = np.median(np.abs(1000.0 * m[:, pos] - fk[:, pos]))
    if e1 > 1.0 and e1000 < 0.1 * e1:
        cols = [c for c, a in zip(poses.names, poses.angle) if not a]
        raise RecordingError(f"{path}: columns {', '.join(cols)}: the positions seem to be in metres "
                             f"(e.g. {m[0, pos][-1]:.6g} where the joints put the platform near "
                             f"{fk[0, pos][-1]:.6g} mm); a recording holds mm")
    return e1


def _check_angle_units(rec: Recording, poses: _PoseColumns, path: Path, in_base_frame: bool) -> None:
    """Refuse angles in degrees: converted from degrees they match the nominal forward kinematics
    closely. Only where the positions say the poses are in the base frame (an instrument's frame
    turns the angles too)."""
    m, fk, angle = rec.measured, poses.fk, poses.angle
    e = np.median(np.abs(m[:, angle] - fk[:, angle]))
    edeg = np.median(np.abs(np.deg2rad(m[:, angle]) - fk[:, angle]))
    if in_base_frame and e > 0.01 and edeg < 0.1 * e and edeg < 0.01:
        cols = [c for c, a in zip(poses.names, angle) if a]
        raise RecordingError(f"{path}: columns {', '.join(cols)}: the angles seem to be in degrees "
                             "(they match the joints once converted from degrees); a recording holds rad")


def _check_pose_units(rec: Recording, poses: _PoseColumns, path: Path) -> bool:
    """Refuse positions in metres and angles in degrees (against the nominal forward kinematics,
    when there is one). Returns whether the rotation convention can be checked: the poses in the
    base frame, three angles, at least two calibration rows."""
    if poses.fk is None:
        return False
    e1 = _check_position_units(rec, poses, path)
    if not poses.angle.any():
        return False
    in_base_frame = e1 < 0.05 * rec.robot.length_scale_mm
    _check_angle_units(rec, poses, path, in_base_frame)
    return in_base_frame and int(poses.angle.sum()) == 3 and int((rec.sets == "calibration").sum()) >= 2


def _check_magnitudes(rec: Recording, poses: _PoseColumns, path: Path) -> None:
    """Refuse an angle beyond 2 pi rad and a position beyond 100 times the robot's size (mm)."""
    robot, m, angle = rec.robot, rec.measured, poses.angle
    bound = np.where(angle, 2 * np.pi, 100.0 * robot.length_scale_mm)
    far = np.abs(m) > bound
    if far.any():
        r, c = np.argwhere(far)[0]
        what = "not an angle in rad" if angle[c] else f"far beyond the {robot.name}'s reach"
        raise RecordingError(f"{_row(path, r)}, column {poses.names[c]!r}: {m[r, c]:.6g} is {what}")


def _check_rotation_convention(rec: Recording, poses: _PoseColumns, path: Path) -> None:
    """Refuse angles that follow another rotation convention (:func:`_other_rotation_convention`)."""
    other = _other_rotation_convention(rec)
    if other is not None:
        cols = [c for c, a in zip(poses.names, poses.angle) if a]
        raise RecordingError(f"{path}: columns {', '.join(cols)}: the angles seem to follow {other}; "
                             f"a recording holds {ROTATION_CONVENTION}")


def _check_copied_rows(rec: Recording, path: Path) -> None:
    """Refuse a row that repeats an earlier one exactly, time and set included."""
    full = np.column_stack([rec.t_s, rec.joints, rec.measured])
    first: dict[bytes, int] = {}
    for r in range(len(full)):
        key = full[r].tobytes() + rec.sets[r].encode()
        if key in first:
            raise RecordingError(f"{_row(path, r)}: repeats row {first[key] + 1} exactly (time included): "
                                 "a copied row; delete it")
        first[key] = r


def _repeated_measurements(rec: Recording, path: Path) -> str | None:
    """A warning naming the rows that repeat the joints and pose of an earlier row (at another
    time), or None."""
    body = np.column_stack([rec.joints, rec.measured])
    seen: dict[bytes, int] = {}
    repeats = []
    for r in range(len(body)):
        key = body[r].tobytes()
        if key in seen:
            repeats.append(f"{r + 1} (= {seen[key] + 1})")
        else:
            seen[key] = r
    if not repeats:
        return None
    return (f"{path}: rows {', '.join(repeats)} repeat the joints and pose of an earlier row exactly "
            "(at another time): each counts as a new measurement and shrinks the uncertainty")


def _scaled_condition(rec: Recording, poses: _PoseColumns, cal: np.ndarray) -> float:
    """Condition number of the identification Jacobian of the ``cal`` rows (bool (N,)), rows
    scaled by the declared noise and columns to unit norm (inf when a parameter has no effect)."""
    from calib.robot import pose_jacobian_of_parameters

    robot = rec.robot
    free = robot.table.indices(robot.free_default)
    at = poses.fk[cal] if poses.fk is not None else rec.measured[cal]
    std = rec.noise.pose_std(robot.pose_units)
    J = pose_jacobian_of_parameters(robot, robot.table.nominal, rec.joints[cal], at)[:, :, free] / std[None, :, None]
    A = J.reshape(-1, free.size)
    norms = np.linalg.norm(A, axis=0)
    if not np.all(norms > 0):
        return float("inf")
    sv = np.linalg.svd(A / norms, compute_uv=False)
    return float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")


def _excitation(rec: Recording, poses: _PoseColumns, path: Path) -> str | None:
    """Refuse calibration poses too alike to identify the parameters (condition number above
    :data:`REFUSED_CONDITION`); a warning above :data:`WARNED_CONDITION`, else None. Not for
    target positions or fewer than two calibration rows."""
    cal = rec.sets == "calibration"
    if cal.sum() < 2 or poses.n_targets:
        return None
    cond = _scaled_condition(rec, poses, cal)
    if cond > REFUSED_CONDITION:
        free = rec.robot.table.indices(rec.robot.free_default)
        distinct = len({b.tobytes() for b in np.column_stack([rec.joints, rec.measured])[cal]})
        raise RecordingError(
            f"{path}: the {int(cal.sum())} calibration poses ({distinct} distinct) are too alike to identify "
            f"the {free.size} parameters: the identification is {_condition_in_words(cond)} (condition "
            f"number {cond:.2g}; poses spread over the workspace give 1e2 to 1e5); measure poses spread "
            "over the workspace")
    if cond > WARNED_CONDITION:
        return (f"{path}: the calibration poses excite the parameters poorly (condition number "
                f"{cond:.2g}, {_condition_in_words(cond)}): expect large uncertainties")
    return None


def plausibility(rec: Recording, csv_path: str | Path) -> list[str]:
    """Check that the machine can have produced ``rec`` before anything is fitted.

    Refuses: joint values outside the nominal geometry's range (the stroke of a leg), with a
    guess when the whole file seems to hold metres for mm or degrees for rad; poses whose
    positions or angles seem to be in metres or degrees; values beyond any workspace; angles in
    another rotation convention; rows copied exactly (time included); calibration poses too
    alike to identify the parameters (condition number in words). The checks run in that order.

    Returns:
        Warnings in words: repeated measurements (same joints and pose at another time), poorly
        excited calibration poses.

    Raises:
        RecordingError: naming the file, row and column, and what the file seems to hold.
    """
    path = Path(csv_path)
    _check_joint_range(rec, path)
    poses = _pose_columns(rec)
    check_convention = _check_pose_units(rec, poses, path)
    _check_magnitudes(rec, poses, path)
    if check_convention:  # after the magnitudes: a fit needs sane values
        _check_rotation_convention(rec, poses, path)
    _check_copied_rows(rec, path)
    return [w for w in (_repeated_measurements(rec, path), _excitation(rec, poses, path)) if w is not None]
