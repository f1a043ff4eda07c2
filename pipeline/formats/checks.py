"""Checks that a machine can have produced a recording, before anything is fitted to it: units,
reach, rotation convention, repeated rows, excitation. Each refusal names the file, row and
column and what the file seems to hold."""

from __future__ import annotations

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


def plausibility(rec: Recording, csv_path: str | Path) -> list[str]:
    """Check that the machine can have produced ``rec`` before anything is fitted.

    Refuses: joint values outside the nominal geometry's range (the stroke of a leg), with a
    guess when the whole file seems to hold metres for mm or degrees for rad; poses whose
    positions or angles seem to be in metres or degrees; values beyond any workspace; rows copied
    exactly (time included); calibration poses too alike to identify the parameters
    (condition number in words).

    Returns:
        Warnings in words: repeated measurements (same joints and pose at another time), poorly
        excited calibration poses.

    Raises:
        RecordingError: naming the file, row and column, and what the file seems to hold.
    """
    from calib.robot import KinematicsError, pose_jacobian_of_parameters

    path = Path(csv_path)
    robot = rec.robot
    joint_cols, pose_cols = columns(robot)
    limits = robot.joint_limits()
    q = rec.joints
    out = (q < limits[:, 0]) | (q > limits[:, 1])
    warnings: list[str] = []
    if out.any():
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
    m = rec.measured
    nominal = robot.table.nominal
    targets = measurement_settings(rec.meta.get("measurement")).n_targets
    if targets:  # target positions (columns t1_x_mm ...), in the instrument's frame: no pose checks
        angle = np.zeros(m.shape[1], dtype=bool)
        pose_cols = tuple(f"{n}_mm" for n in target_names(targets))
        fk = None
    else:
        angle = robot.angle_pose_mask
        try:
            fk = robot.forward_kinematics(nominal, q, initial=np.repeat(robot.home_pose[None], len(q), axis=0))
        except KinematicsError:
            fk = None
    check_convention = False
    if fk is not None:
        pos = ~angle
        e1 = np.median(np.abs(m[:, pos] - fk[:, pos]))
        e1000 = np.median(np.abs(1000.0 * m[:, pos] - fk[:, pos]))
        if e1 > 1.0 and e1000 < 0.1 * e1:
            cols = [c for c, a in zip(pose_cols, angle) if not a]
            raise RecordingError(f"{path}: columns {', '.join(cols)}: the positions seem to be in metres "
                                 f"(e.g. {m[0, pos][-1]:.6g} where the joints put the platform near "
                                 f"{fk[0, pos][-1]:.6g} mm); a recording holds mm")
        if angle.any():
            e = np.median(np.abs(m[:, angle] - fk[:, angle]))
            edeg = np.median(np.abs(np.deg2rad(m[:, angle]) - fk[:, angle]))
            # Only where the positions say the poses are in the base frame (an instrument's
            # frame turns the angles too), and only for a close match once converted.
            in_base_frame = e1 < 0.05 * robot.length_scale_mm
            if in_base_frame and e > 0.01 and edeg < 0.1 * e and edeg < 0.01:
                cols = [c for c, a in zip(pose_cols, angle) if a]
                raise RecordingError(f"{path}: columns {', '.join(cols)}: the angles seem to be in degrees "
                                     "(they match the joints once converted from degrees); a recording holds rad")
            check_convention = in_base_frame and int(angle.sum()) == 3 and int((rec.sets == "calibration").sum()) >= 2
    bound = np.where(angle, 2 * np.pi, 100.0 * robot.length_scale_mm)
    far = np.abs(m) > bound
    if far.any():
        r, c = np.argwhere(far)[0]
        what = "not an angle in rad" if angle[c] else f"far beyond the {robot.name}'s reach"
        raise RecordingError(f"{_row(path, r)}, column {pose_cols[c]!r}: {m[r, c]:.6g} is {what}")
    if fk is not None and angle.any() and check_convention:  # after the magnitudes: a fit needs sane values
        other = _other_rotation_convention(rec)
        if other is not None:
            cols = [c for c, a in zip(pose_cols, angle) if a]
            raise RecordingError(f"{path}: columns {', '.join(cols)}: the angles seem to follow {other}; "
                                 f"a recording holds {ROTATION_CONVENTION}")
    full = np.column_stack([rec.t_s, q, m])
    body = np.column_stack([q, m])
    first: dict[bytes, int] = {}
    for r in range(len(full)):
        key = full[r].tobytes() + rec.sets[r].encode()
        if key in first:
            raise RecordingError(f"{_row(path, r)}: repeats row {first[key] + 1} exactly (time included): "
                                 "a copied row; delete it")
        first[key] = r
    seen: dict[bytes, int] = {}
    repeats = []
    for r in range(len(body)):
        key = body[r].tobytes()
        if key in seen:
            repeats.append(f"{r + 1} (= {seen[key] + 1})")
        else:
            seen[key] = r
    if repeats:
        warnings.append(f"{path}: rows {', '.join(repeats)} repeat the joints and pose of an earlier row exactly "
                        "(at another time): each counts as a new measurement and shrinks the uncertainty")
    cal = rec.sets == "calibration"
    if cal.sum() >= 2 and not targets:
        free = robot.table.indices(robot.free_default)
        poses = fk[cal] if fk is not None else m[cal]
        std = rec.noise.pose_std(robot.pose_units)
        J = pose_jacobian_of_parameters(robot, nominal, q[cal], poses)[:, :, free] / std[None, :, None]
        A = J.reshape(-1, free.size)
        norms = np.linalg.norm(A, axis=0)
        if np.all(norms > 0):
            sv = np.linalg.svd(A / norms, compute_uv=False)
            cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
        else:
            cond = float("inf")
        distinct = len({b.tobytes() for b in body[cal]})
        if cond > REFUSED_CONDITION:
            raise RecordingError(
                f"{path}: the {int(cal.sum())} calibration poses ({distinct} distinct) are too alike to identify "
                f"the {free.size} parameters: the identification is {_condition_in_words(cond)} (condition "
                f"number {cond:.2g}; poses spread over the workspace give 1e2 to 1e5); measure poses spread "
                "over the workspace")
        if cond > WARNED_CONDITION:
            warnings.append(f"{path}: the calibration poses excite the parameters poorly (condition number "
                            f"{cond:.2g}, {_condition_in_words(cond)}): expect large uncertainties")
    return warnings
