"""A calibration re-referenced from a handful of poses: the geometry held, the session's shift found.

A machine that re-homes at every power-up is calibrated once; each later session starts with its
joints' zeros moved (and, maybe, the instrument set down elsewhere). :func:`rereference` holds a
calibration's geometry and effects (:class:`calib.calibration.Calibration`) and estimates only
what changes between sessions from the session's calibration rows
(:func:`calib.session_shift.fit_session_shift`: each joint's zero and/or the instrument frame's
motion, chosen by evidence), the held machine's uncertainty carried into its predictions (the
calibration's covariance through the pose Jacobian of its free parameters). It returns a
:class:`Rereference`: the shift, the session's calibration (the joint zero parameters moved, the
instrument frame composed with its motion, the zeros' variance added to the covariance, its
provenance naming the calibration it came from), and the session's validation rows predicted
before (the calibration as it was) and after.

Conventions: mm and rad; a pose error is measured minus predicted in the instrument's frame; the
noise floor of a position error is ``sqrt(3) sigma`` (the RMS length of a 3-D error of
independent coordinates of standard deviation ``sigma``, the instrument's declared position noise),
of an orientation error ``sqrt(3) sigma_rad``: what a perfect prediction leaves.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from .calibration import Calibration
from .measurement import compose, compose_frames, measurement_jacobians
from .metrics import pose_error_norms
from .noise import SensorNoise
from .robot import Robot, pose_jacobian_of_parameters
from .workspace import reachable_poses
from .session_shift import SHIFT_MODELS, SessionShift, fit_session_shift, rereferenced_theta

__all__ = ["Rereference", "ErrorFigures", "rereference", "check_same_machine", "held_machine",
           "held_prediction_covariance", "frame_response", "seen_poses", "SEEN_POSES", "held_frame", "frame_words", "noise_floor", "error_figures_of", "rereferenced_calibration",
           "MIN_REREFERENCE_ROWS", "NOMINAL_MATCH"]

#: Rows below which a re-reference is warned of: six measurements of a pose determine six offsets
#: at best, and a handful of poses spread over the workspace are what separate them.
MIN_REREFERENCE_ROWS = 6
#: Two nominal geometries are the same machine's where no parameter differs by more than this
#: fraction of the robot's size (the files keep ``repr``'s digits: the same description reads back
#: bit for bit; this only forgives a description retyped to nine digits).
NOMINAL_MATCH = 1e-9
#: Poses drawn in a calibration's box of poses on which its frame's response to its geometry is
#: found (:func:`frame_response`; six unknowns, each pose D equations).
SEEN_POSES = 60


@dataclass(frozen=True)
class ErrorFigures:
    """Pose errors of a set of rows (measured minus predicted, the instrument's frame).

    Attributes:
        rows: how many rows.
        position_mm: ``{"mean", "max", "rms"}`` of the position error lengths.
        orientation_rad: the same of the orientation error lengths; None where the robot's pose
            has no angles.
    """

    rows: int
    position_mm: dict
    orientation_rad: dict | None

    def to_dict(self) -> dict:
        return {"rows": self.rows, "position_mm": self.position_mm, "orientation_rad": self.orientation_rad}


def _figures(values: np.ndarray) -> dict:
    return {"mean": float(values.mean()), "max": float(values.max()), "rms": float(np.sqrt(np.mean(values ** 2)))}


def error_figures_of(robot: Robot, errors: np.ndarray) -> ErrorFigures:
    """:class:`ErrorFigures` of (N, D) pose errors (N > 0)."""
    position, orientation = pose_error_norms(robot, errors)
    return ErrorFigures(len(errors), _figures(position),
                        _figures(orientation) if robot.angle_pose_mask.any() else None)


def noise_floor(robot: Robot, noise: SensorNoise) -> dict:
    """``{"position_mm", "orientation_rad"}``: the RMS length of the instrument's noise on a
    position error (``sqrt(3)`` times its declared standard deviation per coordinate) and on an
    orientation error (None without angles); see the module docstring."""
    std = noise.pose_std(robot.pose_units)
    angle = robot.angle_pose_mask
    return {"position_mm": float(np.sqrt(np.sum(std[~angle] ** 2))),
            "orientation_rad": float(np.sqrt(np.sum(std[angle] ** 2))) if angle.any() else None}


def check_same_machine(cal: Calibration, robot: Robot, where: str) -> None:
    """Refuse a calibration of another robot or nominal geometry than ``robot`` (the recording's).

    Raises:
        ValueError: one line naming ``where`` (the calibration file) and the first difference.
    """
    if cal.robot.name != robot.name:
        raise ValueError(f"{where}: a calibration of a {cal.robot.name}, the recording is of a {robot.name}: "
                         "re-reference a calibration of the same machine")
    ours, theirs = cal.robot.table.nominal, robot.table.nominal
    gap = np.abs(ours - theirs)
    k = int(np.argmax(gap))
    if gap[k] > NOMINAL_MATCH * max(robot.length_scale_mm, 1.0):
        unit = robot.table.units[k]
        raise ValueError(f"{where}: key 'nominal_geometry': another geometry than the recording's (nominal "
                         f"{robot.table.names[k]} {ours[k]:.6g} {unit} in the calibration, {theirs[k]:.6g} {unit} in "
                         "the recording's sidecar): re-reference a calibration of the same machine")


def held_machine(cal: Calibration, t_s=None, channels: dict | None = None):
    """``machine(joints (N, C)) -> (N, D)``: where ``cal``'s machine goes (geometry and effects,
    base frame) at the rows' times ``t_s`` and recorded ``channels`` (its effects rebuilt once)."""
    from .compensation import machine_poses

    channels = dict(channels or {})
    effects = cal.fitted_effects(channels)
    return lambda joints: machine_poses(cal.robot, cal.theta, joints, effects, t_s=t_s, channels=channels)


def _free_pose_jacobian(cal: Calibration, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(poses (N, D), d pose / d free parameters (N, D, F))`` of ``cal``'s geometry at ``joints``."""
    robot = cal.robot
    poses = robot.forward_kinematics(cal.theta, joints)
    J = pose_jacobian_of_parameters(robot, cal.theta, joints, poses)[:, :, robot.table.indices(list(cal.free))]
    return poses, J


def seen_poses(cal: Calibration, n: int = SEEN_POSES) -> np.ndarray:
    """(n, D) poses drawn in the box of poses ``cal`` saw (its validity's ``pose_min`` .. ``pose_max``)
    that its machine reaches (the robot's workspace where the box has too few): the poses its fit
    estimated the instrument's frame on, as near as the file says."""
    robot = cal.robot
    box = np.stack([cal.validity["pose_min"], cal.validity["pose_max"]], axis=1).astype(float)
    try:
        return reachable_poses(robot, n, 0, bounds=box, theta=cal.theta)
    except ValueError:
        return reachable_poses(robot, n, 0, theta=cal.theta)


def frame_response(cal: Calibration, frame=None) -> np.ndarray:
    """(6, F) how the instrument's frame ``frame`` (None: base) estimated with ``cal``'s geometry
    moves with its free parameters: the least-squares frame motion that best takes up a parameter
    change on the poses it saw (:func:`seen_poses`, each coordinate over its noise). A change of
    the geometry that moves those poses by one rigid motion (the gauge, or what a level grid
    cannot tell from the frame's height and tilt) is taken up by the frame: the fit's correlation
    between the two, which the file does not keep."""
    robot = cal.robot
    poses = seen_poses(cal)
    _, J = _free_pose_jacobian(cal, robot.inverse_kinematics(cal.theta, poses))
    H, HF, _ = measurement_jacobians(robot, poses, frame)
    w = 1.0 / cal.noise.pose_std(robot.pose_units)
    A = (HF * w[None, :, None]).reshape(-1, 6)
    B = ((H @ J) * w[None, :, None]).reshape(len(A), -1)
    return -np.linalg.lstsq(A, B, rcond=None)[0]


def held_prediction_covariance(cal: Calibration, joints, frame_session: str | None = None) -> np.ndarray:
    """(N, D, D) the covariance of ``cal``'s prediction at ``joints`` seen in its instrument frame of
    ``frame_session`` (None: the base frame), from its free parameters' covariance ``C``: ``M C M'``
    with ``M = H J + H_F L``, ``J`` the pose Jacobian of the free parameters
    (:func:`calib.robot.pose_jacobian_of_parameters`), ``H`` and ``H_F`` the instrument's derivatives
    by the pose and by its frame (:func:`calib.measurement.measurement_jacobians`) and ``L`` the
    frame's response to the parameters (:func:`frame_response`): the geometry and the frame were
    estimated together, and a change of the one is taken up by the other (without ``L`` a 100-pose
    level grid's prediction of its own plane would be said uncertain by 4.4 mm, the gauge's and the
    prior's share). In the base frame (``cal`` has no frame) ``M = J``."""
    robot = cal.robot
    joints = np.asarray(joints, dtype=float)
    poses, J = _free_pose_jacobian(cal, joints)
    if frame_session is None:
        M = J
    else:
        frame = cal.frames[frame_session]
        H, HF, _ = measurement_jacobians(robot, poses, frame)
        M = H @ J + HF @ frame_response(cal, frame)
    return np.einsum("nij,jk,nlk->nil", M, np.asarray(cal.covariance, dtype=float), M)


def _errors(robot: Robot, measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    d = np.asarray(measured, dtype=float) - predicted
    angle = robot.angle_pose_mask
    d[:, angle] = (d[:, angle] + np.pi) % (2 * np.pi) - np.pi
    return d


def rereferenced_calibration(cal: Calibration, shift: SessionShift, session: str, frame_session: str | None, *,
                             noise: SensorNoise, recording: dict, origin: dict, produced_by: str) -> Calibration:
    """The session's calibration: ``cal``'s geometry and effects, the joint zero parameters moved by
    the shift's zeros (their variance added to the covariance, the zero parameters made free where
    they were not), the session's instrument frame (``cal``'s frame of ``frame_session``, None: the
    base frame) composed with the shift's motion (standard deviations added in quadrature), the
    validity's joint ranges moved with the zeros (the same poses are commanded at joints less the
    zeros), ``origin`` as its ``rereferenced_from``."""
    robot = cal.robot
    c = robot.n_chains
    zeros, zeros_cov = shift.zeros, shift.best.covariance[:c, :c]
    free = tuple(cal.free) + tuple(n for n in robot.joint_zero_names if n not in cal.free)
    cov = np.zeros((len(free), len(free)))
    cov[:len(cal.free), :len(cal.free)] = cal.covariance
    at = [free.index(n) for n in robot.joint_zero_names]
    cov[np.ix_(at, at)] += zeros_cov
    std = np.zeros(robot.n_parameters)
    std[robot.table.indices(list(free))] = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    frames, frames_std = {}, {}
    if frame_session is not None or np.any(shift.best.columns >= c):
        known = cal.frames.get(frame_session, np.zeros(6))
        known_std = cal.frames_std.get(frame_session, np.zeros(6))
        frames[session] = compose_frames(shift.frame_motion, known)
        frames_std[session] = np.sqrt(np.asarray(known_std) ** 2 + shift.frame_motion_std ** 2)
    validity = dict(cal.validity)
    if "joint_min" in validity and "joint_max" in validity:
        validity["joint_min"] = (np.asarray(validity["joint_min"], dtype=float) - zeros).tolist()
        validity["joint_max"] = (np.asarray(validity["joint_max"], dtype=float) - zeros).tolist()
    return replace(cal, theta=rereferenced_theta(robot, cal.theta, zeros), std=std, free=free, covariance=cov,
                   frames=frames, frames_std=frames_std, validity=validity, noise=noise, recording=recording,
                   produced_by=produced_by, rereferenced_from=dict(origin), source=None)


@dataclass(frozen=True, eq=False)
class Rereference:
    """A calibration re-referenced to a session (see the module docstring).

    Attributes:
        shift: the session's shift (:class:`calib.session_shift.SessionShift`), chosen by evidence.
        held: the calibration held (its geometry and effects).
        calibration: the session's calibration (:func:`rereferenced_calibration`).
        frame_source: which instrument frame of ``held`` the session's rows were read in, in words.
        calibration_before, calibration_after: the calibration rows' errors with ``held`` as it was
            and re-referenced.
        validation_before, validation_after: the validation rows' (None where there are none).
        noise_floor: :func:`noise_floor` of the session's declared noise.
        warnings: what the user must know (few rows; offsets the rows leave to their prior).
        seconds: the work's wall time, s.
        session: the session's name (its frame's key in ``calibration``).
        frame_session: the session of ``held`` whose frame the rows were read in (None: base).
    """

    shift: SessionShift
    held: Calibration
    calibration: Calibration
    frame_source: str
    calibration_before: ErrorFigures
    calibration_after: ErrorFigures
    validation_before: ErrorFigures | None
    validation_after: ErrorFigures | None
    noise_floor: dict
    warnings: tuple = ()
    seconds: float = 0.0
    session: str = ""
    frame_session: str | None = None

    def errors(self, joints, measured, t_s=None, channels: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(before, after)``: (N, D) the errors of rows of the session (measured minus predicted,
        the instrument's frame) with the held calibration as it was and re-referenced.

        Raises:
            KinematicsError: a row the held geometry cannot assemble at (names the row).
        """
        robot = self.held.robot
        joints = np.asarray(joints, dtype=float).reshape(-1, robot.n_chains)
        out = []
        for cal, frame in ((self.held, self.held.frames.get(self.frame_session, np.zeros(6))),
                           (self.calibration, self.calibration.frames.get(self.session, np.zeros(6)))):
            out.append(_errors(robot, measured, compose(frame, robot, held_machine(cal, t_s, channels)(joints))))
        return out[0], out[1]

    def with_validation(self, joints, measured, t_s=None, channels: dict | None = None) -> "Rereference":
        """This re-reference with the session's validation rows predicted (none: unchanged).

        Raises:
            KinematicsError: a row the held geometry cannot assemble at (names the row).
        """
        if not len(joints):
            return self
        before, after = self.errors(joints, measured, t_s, channels)
        robot = self.held.robot
        return replace(self, validation_before=error_figures_of(robot, before),
                       validation_after=error_figures_of(robot, after))

    def to_dict(self) -> dict:
        """JSON-ready: the shift (:meth:`calib.session_shift.SessionShift.to_dict`), the figures
        before and after, the noise floor, the calibration's provenance."""
        def figures(f):
            return None if f is None else f.to_dict()

        return {"shift": self.shift.to_dict(), "frame_source": self.frame_source,
                "rereferenced_from": self.calibration.rereferenced_from,
                "calibration_rows": {"before": figures(self.calibration_before),
                                     "after": figures(self.calibration_after)},
                "validation_rows": {"before": figures(self.validation_before),
                                    "after": figures(self.validation_after)},
                "noise_floor": {**self.noise_floor, "definition": "RMS length of the declared instrument noise on a "
                                "position (orientation) error: sqrt(3) x its standard deviation per coordinate"},
                "warnings": list(self.warnings), "seconds": self.seconds}


def _shift_warnings(shift: SessionShift, rows: int) -> list[str]:
    out = []
    if rows < MIN_REREFERENCE_ROWS:
        out.append(f"{rows} calibration row(s): at least {MIN_REREFERENCE_ROWS} poses spread over the workspace "
                   "determine each joint's zero and the instrument's motion")
    left = shift.undetermined()
    if left:
        out.append(f"the rows leave {', '.join(left)} near the prior (posterior std over half the prior's): measure "
                   "poses that move them")
    return out


def held_frame(cal: Calibration, session: str) -> str | None:
    """The session of ``cal`` whose instrument frame a session named ``session`` is read in: the
    session of the same name, else ``cal``'s first; None where ``cal`` has none (the base frame)."""
    if session in cal.frames:
        return session
    return next(iter(cal.frames), None)


def frame_words(cal: Calibration, frame_session: str | None) -> str:
    """Which frame of ``cal`` (:func:`held_frame`), in words."""
    if frame_session is None:
        return "the base frame"
    where = f" of {cal.source}" if cal.source is not None else ""
    return f"the instrument frame of session {frame_session!r}{where}"


def rereference(cal: Calibration, joints, measured, noise: SensorNoise, *, session: str,
                frame_session: str | None = None, t_s=None, channels: dict | None = None,
                validation: tuple | None = None, origin: dict | None = None, recording: dict | None = None,
                produced_by: str = "", models=SHIFT_MODELS) -> Rereference:
    """Re-reference ``cal`` to a session from its calibration rows (see the module docstring).

    Args:
        cal: the calibration held.
        joints: (N, C) the session's calibration rows' joints, as read; measured: (N, D) their poses
            as the instrument reported them.
        noise: the session's declared instrument noise.
        session: the session's name (the key of its frame in the new calibration).
        frame_session: the session of ``cal`` whose instrument frame the rows were measured in
            (:func:`held_frame`; None: the base frame).
        t_s, channels: the calibration rows' times (s) and recorded channels, for the effects.
        validation: ``(joints, measured, t_s, channels)`` of the session's validation rows, or None
            (:meth:`Rereference.with_validation` predicts them later).
        origin: the new calibration's ``rereferenced_from`` (the held file's path and SHA-256).
        recording, produced_by: the new calibration's provenance.
        models: the shift's models chosen among (:data:`calib.session_shift.SHIFT_MODELS`).

    Raises:
        ValueError: no calibration rows.
        KinematicsError: a row the held geometry cannot assemble at (names the row).
    """
    t0 = time.perf_counter()
    robot = cal.robot
    joints = np.asarray(joints, dtype=float).reshape(-1, robot.n_chains)
    measured = np.asarray(measured, dtype=float)
    if len(joints) == 0:
        raise ValueError("no calibration rows: the session's shift is estimated from its calibration rows")
    seen = np.asarray(cal.frames.get(frame_session, np.zeros(6)), dtype=float)
    machine = held_machine(cal, t_s, channels)
    shift = fit_session_shift(robot, machine, joints, measured, noise, frame=seen,
                              prediction_covariance=held_prediction_covariance(cal, joints, frame_session), models=models)
    new = rereferenced_calibration(cal, shift, session, frame_session, noise=noise, recording=dict(recording or {}),
                                   origin=dict(origin or {}), produced_by=produced_by)
    rr = Rereference(shift=shift, held=cal, calibration=new, frame_source=frame_words(cal, frame_session),
                     calibration_before=None, calibration_after=None, validation_before=None, validation_after=None,
                     noise_floor=noise_floor(robot, noise), warnings=tuple(_shift_warnings(shift, len(joints))),
                     session=session, frame_session=frame_session)
    before, after = rr.errors(joints, measured, t_s, channels)
    rr = replace(rr, calibration_before=error_figures_of(robot, before), calibration_after=error_figures_of(robot, after))
    if validation is not None:
        rr = rr.with_validation(*validation)
    return replace(rr, seconds=time.perf_counter() - t0)
