"""Checks that a machine can have produced a recording, before anything is fitted to it: reach,
magnitudes, repeated rows, excitation, and units and conventions. Each refusal names the file, row
and column and what the file seems to hold.

Certain refusals (no machine can have produced the file): joint readings beyond the nominal
range by more than the tolerance (:data:`JOINT_LIMIT_TOLERANCE` of the range, or the sidecar's
``meta.joint_limit_tolerance``), values beyond any workspace, copied rows, poses too alike to
identify the parameters. Units and conventions are refused only on evidence
(:func:`calib.diagnosis.diagnose`): the converted file fits the machine to the declared noise and
the file as written does not, even with an instrument frame. Otherwise a suspicion (positions
that look like metres, angles that look like degrees against the nominal model) is a warning with
its figures, and the file is read as written."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.measurement import measurement_settings, target_names

from .recording import Recording, RecordingError, columns, row_frame_groups, sidecar_path

__all__ = ["plausibility", "recording_checks", "RecordingChecks", "REFUSED_CONDITION", "WARNED_CONDITION",
           "EXCITATION_MAX_ROWS", "REACH_FACTOR", "MAX_ANGLE_RAD",
           "ROTATION_CONVENTION", "JOINT_LIMIT_TOLERANCE"]


#: Column-scaled condition number of the identification Jacobian above which the calibration
#: poses are refused (too alike to tell the parameters apart), and above which a warning is given.
#: Poses spread over the workspace give 1e2 to 1e5.
REFUSED_CONDITION = 1e8


WARNED_CONDITION = 1e6

#: Above this many calibration rows the excitation check takes the condition number of a seeded
#: subsample of this many of them (``RecordingChecks.excitation`` says so): the column-scaled
#: condition number is a ratio, which this many rows drawn from the file's estimate to a few per
#: cent (measured: docs/benchmarks.md), against thresholds two decades apart; each row costs its
#: closure Jacobians and a (D, P) block of the Jacobian.
EXCITATION_MAX_ROWS = 5000

#: Joint readings past the nominal range by at most this fraction of the range (a leg's whole
#: stroke, a motor's whole range) are accepted with a warning: a real encoder reads a little past
#: the declared stroke. The sidecar's ``meta.joint_limit_tolerance`` replaces it: a number in the
#: joint unit, or ``{"fraction": f}`` of the range.
JOINT_LIMIT_TOLERANCE = 0.01

#: A recorded position beyond this many times the robot's size (``Robot.length_scale_mm``) is
#: refused: far beyond any workspace.
REACH_FACTOR = 100.0

#: A recorded angle beyond this (rad) is refused: not an angle in rad.
MAX_ANGLE_RAD = 2 * np.pi

#: Rows a warning names before it says "and N more".
LISTED_ROWS = 10


def _row(path: Path, r: int) -> str:
    """How messages name the 0-based data row ``r``: its spreadsheet row number and file line."""
    return f"{path}: row {r + 1} (line {r + 2})"


def _rows_in_words(rows) -> str:
    """``3 (line 4), 17 (line 18)`` of 0-based rows, at most :data:`LISTED_ROWS` of them."""
    rows = [int(r) for r in rows]
    words = ", ".join(f"{r + 1} (line {r + 2})" for r in rows[:LISTED_ROWS])
    return words + (f" and {len(rows) - LISTED_ROWS} more" if len(rows) > LISTED_ROWS else "")


def _condition_in_words(cond: float) -> str:
    if not np.isfinite(cond) or cond > 1e12:
        return "numerically singular"
    if cond > REFUSED_CONDITION:
        return "nearly singular"
    return "poorly conditioned"


#: The rotation convention of recordings (the project's).
ROTATION_CONVENTION = "R = Rz(gamma) Ry(beta) Rx(alpha) (platform to base, angles in the columns alpha, beta, gamma)"


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


def _joint_tolerance(rec: Recording, path: Path, span: np.ndarray) -> np.ndarray:
    """(C,) how far past its range each joint may read (joint unit): :data:`JOINT_LIMIT_TOLERANCE`
    of the range, or the sidecar's ``meta.joint_limit_tolerance`` (a number in the joint unit, or
    ``{"fraction": f}``)."""
    value = rec.meta.get("joint_limit_tolerance")
    if value is None:
        return JOINT_LIMIT_TOLERANCE * span
    where = f"{sidecar_path(path)}: field 'meta.joint_limit_tolerance'"
    if isinstance(value, dict):
        if set(value) != {"fraction"}:
            raise RecordingError(f"{where} must be a number ({rec.robot.joint_unit}) or {{\"fraction\": f}}, got "
                                 f"keys {', '.join(sorted(value)) or 'none'}")
        fraction = value["fraction"]
        if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not 0 <= fraction < 1:
            raise RecordingError(f"{where}: fraction must be a number in [0, 1), got {fraction!r}")
        return float(fraction) * span
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
        raise RecordingError(f"{where} must be a finite number >= 0 ({rec.robot.joint_unit}) or "
                             f"{{\"fraction\": f}}, got {value!r}")
    return np.full(span.shape, float(value))


def _check_joint_range(rec: Recording, path: Path) -> str | None:
    """Refuse joint values outside the nominal geometry's range (:meth:`calib.robot.Robot.joint_limits`:
    its declared ``joint_ranges``, else the robot's default, e.g. a leg's stroke about home) by more than
    the tolerance (:func:`_joint_tolerance`), saying so when the whole file seems to hold metres for
    mm or degrees for rad; a warning naming the rows read past the range within the tolerance."""
    robot = rec.robot
    joint_cols, _ = columns(robot)
    limits = robot.joint_limits()
    q = rec.joints
    out = (q < limits[:, 0]) | (q > limits[:, 1])
    if not out.any():
        return None
    unit = robot.joint_unit
    source = "declared in the nominal geometry's joint_ranges" if robot.joint_ranges is not None \
        else "of the nominal geometry"
    tol = _joint_tolerance(rec, path, limits[:, 1] - limits[:, 0])
    far = (q < limits[:, 0] - tol) | (q > limits[:, 1] + tol)
    if far.any():
        other = "metres" if unit == "mm" else "degrees"
        scaled = q * 1000.0 if unit == "mm" else np.deg2rad(q)
        far_rows = np.flatnonzero(far.any(axis=1))
        # Another unit only where most rows are out and every value fits the range once converted;
        # a few rows far out are those rows' readings, named with them.
        if 2 * far_rows.size > len(q) and not ((scaled < limits[:, 0]) | (scaled > limits[:, 1])).any():
            r, c = np.argwhere(far)[0]
            raise RecordingError(f"{path}: columns {', '.join(joint_cols)}: the joint values seem to be in "
                                 f"{other} ({far_rows.size} of {len(q)} rows are outside the range, e.g. row {r + 1}, "
                                 f"{joint_cols[c]} = {q[r, c]:.6g}), a recording holds {unit}")
        r, c = np.argwhere(far)[0]
        others = "" if far_rows.size == 1 else \
            f"; out of range too: rows {_rows_in_words(far_rows[1:])} ({far_rows.size} of {len(q)} rows)"
        raise RecordingError(f"{_row(path, r)}, column {joint_cols[c]!r}: {q[r, c]:.6g} {unit} is outside the "
                             f"range [{limits[c, 0]:.6g}, {limits[c, 1]:.6g}] {unit} {source} by "
                             f"more than the tolerance {tol[c]:.3g} {unit}: the machine cannot reach it{others}")
    past = np.maximum(limits[:, 0] - q, q - limits[:, 1])
    r, c = np.unravel_index(np.argmax(np.where(out, past, -np.inf)), q.shape)
    cols = [joint_cols[j] for j in np.flatnonzero(out.any(axis=0))]
    return (f"{path}: rows {_rows_in_words(np.flatnonzero(out.any(axis=1)))}, column(s) {', '.join(cols)}: joint "
            f"readings past the range {source} by up to {past[r, c]:.3g} {unit} (row {r + 1}, "
            f"{joint_cols[c]} = {q[r, c]:.6g} {unit}, range [{limits[c, 0]:.6g}, {limits[c, 1]:.6g}] {unit}), within "
            f"the tolerance {tol[c]:.3g} {unit}: accepted as read")


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


def _position_suspicion(rec: Recording, poses: _PoseColumns, path: Path) -> tuple[float, str | None]:
    """``(median |measured - fk| of the positions (mm), a warning or None)``: positions that
    match the nominal forward kinematics (``poses.fk``, not None) ten times better once read as
    metres."""
    m, fk, pos = rec.measured, poses.fk, ~poses.angle
    e1 = float(np.median(np.abs(m[:, pos] - fk[:, pos])))
    e1000 = float(np.median(np.abs(1000.0 * m[:, pos] - fk[:, pos])))
    if e1 > 1.0 and e1000 < 0.1 * e1:
        cols = [c for c, a in zip(poses.names, poses.angle) if not a]
        return e1, (f"{path}: columns {', '.join(cols)}: the positions look like metres: they differ from where "
                    f"the joints put the platform by a median {e1:.4g} mm as written and {e1000:.4g} mm read as "
                    f"metres (e.g. {m[0, pos][-1]:.6g} where the joints put the platform near {fk[0, pos][-1]:.6g} mm)")
    return e1, None


def _angle_suspicion(rec: Recording, poses: _PoseColumns, path: Path, in_base_frame: bool) -> str | None:
    """A warning when the angles, converted from degrees, match the nominal forward kinematics
    closely (in the base frame only: an instrument's frame turns the angles too); None otherwise.
    A capture body mounted a few degrees off on a level platform looks just so."""
    m, fk, angle = rec.measured, poses.fk, poses.angle
    e = float(np.median(np.abs(m[:, angle] - fk[:, angle])))
    edeg = float(np.median(np.abs(np.deg2rad(m[:, angle]) - fk[:, angle])))
    if in_base_frame and e > 0.01 and edeg < 0.1 * e and edeg < 0.01:
        cols = [c for c, a in zip(poses.names, angle) if a]
        return (f"{path}: columns {', '.join(cols)}: the angles look like degrees: they differ from the nominal "
                f"model's by a median {e:.3g} rad as written and {edeg:.3g} rad read as degrees")
    return None


def _suspicions(rec: Recording, poses: _PoseColumns, path: Path) -> list[str]:
    """What the nominal forward kinematics (when there is one) suggests of the pose units, in words."""
    if poses.fk is None:
        return []
    e1, found = _position_suspicion(rec, poses, path)
    out = [] if found is None else [found]
    if poses.angle.any():
        angles = _angle_suspicion(rec, poses, path, e1 < 0.05 * rec.robot.length_scale_mm)
        out += [] if angles is None else [angles]
    return out


def _check_magnitudes(rec: Recording, poses: _PoseColumns, path: Path) -> None:
    """Refuse an angle beyond :data:`MAX_ANGLE_RAD` and a position beyond :data:`REACH_FACTOR`
    times the robot's size (mm)."""
    robot, m, angle = rec.robot, rec.measured, poses.angle
    bound = np.where(angle, MAX_ANGLE_RAD, REACH_FACTOR * robot.length_scale_mm)
    far = np.abs(m) > bound
    if far.any():
        r, c = np.argwhere(far)[0]
        what = "not an angle in rad" if angle[c] else f"far beyond the {robot.name}'s reach"
        raise RecordingError(f"{_row(path, r)}, column {poses.names[c]!r}: {m[r, c]:.6g} is {what}")


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
    from calib.tsqr import triangular_factor

    robot = rec.robot
    free = robot.table.indices(robot.free_default)
    at = poses.fk[cal] if poses.fk is not None else rec.measured[cal]
    std = rec.noise.pose_std(robot.pose_units)
    J = pose_jacobian_of_parameters(robot, robot.table.nominal, rec.joints[cal], at)[:, :, free] / std[None, :, None]
    A = J.reshape(-1, free.size)
    norms = np.linalg.norm(A, axis=0)
    if not np.all(norms > 0):
        return float("inf")
    sv = np.linalg.svd(triangular_factor(A / norms), compute_uv=False)  # A's singular values
    return float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")


def excitation_rows(cal: np.ndarray) -> tuple[np.ndarray, str]:
    """``(rows (N,) bool, form in words)``: the calibration rows ``cal`` (bool (N,)) the excitation
    check judges: every one, or above :data:`EXCITATION_MAX_ROWS` a seeded subsample of that many
    (the seed is the row count: the same file, the same rows)."""
    n = int(np.count_nonzero(cal))
    if n <= EXCITATION_MAX_ROWS:
        return cal, "every calibration row"
    picked = np.flatnonzero(cal)[np.random.default_rng(n).choice(n, size=EXCITATION_MAX_ROWS, replace=False)]
    rows = np.zeros(cal.size, bool)
    rows[picked] = True
    return rows, (f"a seeded subsample of {EXCITATION_MAX_ROWS:,} of the {n:,} calibration rows ({n:,} rows > "
                  f"EXCITATION_MAX_ROWS = {EXCITATION_MAX_ROWS})")


def _excitation(rec: Recording, poses: _PoseColumns, path: Path, prior: bool) -> str | None:
    """Calibration poses too alike to identify the parameters (condition number above
    :data:`REFUSED_CONDITION`): refused for plain least squares (``prior`` False), a warning with
    the tolerances as a prior (they hold what the poses leave; the run names it); a warning above
    :data:`WARNED_CONDITION`, else None. Not for target positions or fewer than two calibration rows."""
    cal = rec.sets == "calibration"
    if cal.sum() < 2 or poses.n_targets:
        return None
    cond = _scaled_condition(rec, poses, excitation_rows(cal)[0])
    if cond > REFUSED_CONDITION and prior:
        return (f"{path}: the calibration poses leave parameter combinations undetermined (the identification "
                f"alone is {_condition_in_words(cond)}, condition number {cond:.2g}): the tolerances hold them "
                "(the summary's left_to_prior names them and suggests poses to measure)")
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


def _diagnosis(rec: Recording):
    """:func:`calib.diagnosis.diagnose` of every row of ``rec``, as its ``meta.measurement`` says
    (instrument frame mode, target offsets); with several instrument frames (sessions), each row
    in its own session's (:func:`~pipeline.formats.recording.row_frame_groups`)."""
    from calib.diagnosis import diagnose

    settings = measurement_settings(rec.meta.get("measurement"))
    sessions, modes = row_frame_groups(rec)
    return diagnose(rec.robot, rec.joints, rec.measured, rec.noise, frame=settings.frame if sessions is None else modes,
                    targets=settings.targets, sessions=sessions,
                    estimate_targets=settings.estimate_targets if settings.targets is not None else None)


def _conversion_columns(rec: Recording, poses: _PoseColumns, conversion) -> list[str]:
    """The columns a :class:`calib.diagnosis.Conversion` changes."""
    if conversion.kind == "joints":
        names = list(columns(rec.robot)[0])
    else:
        pick = poses.angle if conversion.kind == "angles" else ~poses.angle
        names = [c for c, p in zip(poses.names, pick) if p]
        if poses.n_targets and conversion.axes:  # every target's coordinate of those axes
            return [c for c in names if "xyz".index(c.split("_")[1]) in conversion.axes]
    return [names[i] for i in conversion.axes] if conversion.axes else names


def _holds(rec: Recording, kind: str) -> str:
    """What a recording holds in columns of ``kind``, in words."""
    if kind == "angles":
        return f"rad, {ROTATION_CONVENTION}"
    if kind == "joints":
        return f"{rec.robot.joint_unit}, counted as the nominal geometry counts them"
    return "mm, in the base frame or one instrument frame (a rotation and translation of it)"


def _units_and_conventions(rec: Recording, poses: _PoseColumns, path: Path, diagnosis) -> list[str]:
    """Refuse a unit, axis, sign, convention or joint-direction mistake the diagnosis confirms, or
    a column not measured; warnings with their figures for what the nominal model only suggests."""
    suspicions = _suspicions(rec, poses, path)
    if diagnosis.cause == "conversion":
        conv = diagnosis.conversion
        cols = _conversion_columns(rec, poses, conv)
        # The figures quoted support the claim: as written the file misfits (its chi-square beyond
        # the limit) or fits only with a parameter moved far beyond its tolerance (a Delta or a
        # 6-RUS in metres fits a machine a thousand times smaller).
        how = "it does not" if not diagnosis.written.fits else "it fits only implausibly"
        raise RecordingError(f"{path}: column{'s' if len(cols) > 1 else ''} {', '.join(cols)}: {conv.finding}: "
                             f"converted ({conv.fix}) the file fits the {rec.robot.name} at the declared noise "
                             f"({diagnosis.converted.words()}) and as written {how} ({diagnosis.written.words()}); "
                             f"a recording holds {_holds(rec, conv.kind)}")
    if diagnosis.cause == "unmeasured column":
        name = diagnosis.column
        col = poses.names[list(rec.robot.pose_names).index(name)]
        raise RecordingError(f"{path}: column {col!r}: {diagnosis.message}")
    verdict = ("yet the file as written fits the machine" if diagnosis.success else
               "yet no conversion of the file fits the machine better")
    return [f"{w}; {verdict} ({diagnosis.written.words()}): read as written" for w in suspicions]


@dataclass(frozen=True, eq=False)
class RecordingChecks:
    """What :func:`recording_checks` found.

    Attributes:
        warnings: in words, each naming the file (and rows, columns).
        diagnosis: :func:`calib.diagnosis.diagnose` of every row (the verdict whether the file fits
            its machine, and if not the likely cause), or None for fewer than two rows.
        excitation: the rows whose condition number the excitation check took, in words (every
            calibration row, or a seeded subsample above :data:`EXCITATION_MAX_ROWS`).
    """

    warnings: list
    diagnosis: object
    excitation: str = "every calibration row"


def recording_checks(rec: Recording, csv_path: str | Path, *, prior: bool = True) -> RecordingChecks:
    """Check that the machine can have produced ``rec`` before anything is fitted.

    Refuses, in this order: joint values outside the nominal geometry's range by more than the
    tolerance (:data:`JOINT_LIMIT_TOLERANCE`; the whole file in metres or degrees says so);
    values beyond any workspace; rows copied exactly (time included); calibration poses too alike
    to identify the parameters (condition number in words; only for plain least squares, ``prior``
    False: with the tolerances as a prior a warning); then, on the diagnosis' evidence
    only, a unit, axis, sign, rotation-convention or joint-direction mistake (the converted file
    fits the machine to the declared noise, as written it does not) and a pose column not measured.

    Returns:
        Warnings (joint readings past the range within the tolerance, repeated measurements,
        poorly excited poses, units the nominal model only suggests) and the diagnosis.

    Raises:
        RecordingError: naming the file, row and column, and what the file seems to hold.
    """
    path = Path(csv_path)
    warnings = [_check_joint_range(rec, path)]
    poses = _pose_columns(rec)
    _check_magnitudes(rec, poses, path)
    _check_copied_rows(rec, path)
    warnings += [_repeated_measurements(rec, path), _excitation(rec, poses, path, prior)]
    diagnosis = _diagnosis(rec) if len(rec.joints) >= 2 else None
    if diagnosis is not None:
        warnings += _units_and_conventions(rec, poses, path, diagnosis)
    excitation = excitation_rows(rec.sets == "calibration")[1]
    return RecordingChecks([w for w in warnings if w is not None], diagnosis, excitation)


def plausibility(rec: Recording, csv_path: str | Path, *, prior: bool = True) -> list[str]:
    """:func:`recording_checks`' warnings (it raises what it refuses)."""
    return recording_checks(rec, csv_path, prior=prior).warnings
