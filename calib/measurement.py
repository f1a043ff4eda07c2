"""What an instrument reports of a robot's pose: its own frame, and targets on the platform.

Measurement model. A robot's pose ``p`` (base frame: position ``t_p``, rotation ``R_p`` from the
angles in the project's convention ``R = Rz(gamma) Ry(beta) Rx(alpha)``; the identity for a
translating platform) is seen by an instrument through

* its frame ``F`` relative to the robot's base, six numbers ``[x, y, z, alpha, beta, gamma]``
  (mm, rad, the same convention): a pose as the instrument sees it is ``F`` composed with the
  pose in the base frame, ``R_m = R_F R_p``, ``t_m = R_F t_p + t_F``;
* either the whole pose (the robot's pose coordinates, ``t_m`` and the angles of ``R_m``), or
  the positions of ``K`` targets (tracker reflectors) fixed on the platform at offsets ``o_k``
  (mm, platform frame): ``m_k = R_F (R_p o_k + t_p) + t_F``, three numbers each, no angles.

Identification (:func:`identify_measured`): the geometry (the robot's free parameters), the
frame and the target offsets at once, by the forward method (pose residuals through the forward
kinematics, whitened by the declared noise, analytic Jacobians). Levenberg-Marquardt is the
engine's (:func:`calib.engine.minimise`).

Gauge. Frame, targets and geometry are partly redundant: moving every base joint of a hexapod
rigidly moves the platform rigidly, which the frame undoes (6 directions); with target offsets
estimated, moving the platform frame rigidly (its joints and the targets together) changes no
measurement (6 more). These directions are found numerically, for any robot, as the null space of
the whitened Jacobian with respect to [geometry | targets | frame], and fixed in that order of
priority: the geometry's errors have no component along them (the robot's geometric errors are
expressed in the base (and platform) frame best fitted to the nominal one), then the targets keep
their start values along what is left, then the frame. The fit runs in the complement of the null
space (a plane through the start); a second pass re-takes the null space at the solution, so that
the gauge holds beyond first order.

Detection (:func:`detect_frame`): the measured poses disagree grossly with the nominal model's
(more than :data:`FRAME_DETECTION_FRACTION` of the machine's size, or
:data:`FRAME_DETECTION_RAD`): the data are not in the base frame; the frame is then registered in
closed form (rotation averaging or Kabsch on the positions, then the target offsets by a rigid
fit) before the joint fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .validation import as_array, frozen_array
from .engine import IdentificationResult, minimise, noise_verdict
from .noise import SensorNoise
from .observability import describe_combination
from .prior import ParameterPrior
from .robot import KinematicsError, Robot, pose_jacobian_of_joints, pose_jacobian_of_parameters
from .rotation import euler_from_matrix, rotation_matrix, rotation_matrix_derivatives

__all__ = ["compose_frames", "FRAME_MODES", "FRAME_NAMES", "FRAME_DETECTION_FRACTION", "FRAME_DETECTION_RAD", "GAUGE_RTOL",
           "MeasurementSettings", "measurement_settings", "frame_from_dict", "frame_to_dict", "compose",
           "instrument_measurements", "measurement_jacobians", "measurement_units", "measurement_names",
           "target_names", "measurement_residuals", "rigid_registration", "Registration", "register_frame",
           "FrameDetection", "detect_frame", "MeasuredFit", "identify_measured", "identify_as_measured",
           "measured_gauge_representative", "gauge_null_space", "invert_frame", "whitened_residuals", "whitened_jacobian",
           "MeasurementObservability", "measurement_observability", "checked_measured_inputs"]

#: ``"auto"``: estimate the frame when the data show it (:func:`detect_frame`); ``"base"``: the
#: poses are in the base frame; ``"estimate"``: always estimate it.
FRAME_MODES = ("auto", "base", "estimate")
#: Names of the frame's six numbers (messages, gauge descriptions).
FRAME_NAMES = ("frame.x", "frame.y", "frame.z", "frame.alpha", "frame.beta", "frame.gamma")
#: Position disagreement (RMS, mm) between measured and nominal poses beyond which the poses are
#: taken as measured in another frame, as a fraction of the machine's size.
FRAME_DETECTION_FRACTION = 0.1
#: The same for the angle disagreement (RMS, rad).
FRAME_DETECTION_RAD = 0.1
#: Singular values of the scaled Jacobian below this times the largest span the gauge.
GAUGE_RTOL = 1e-9
#: Step (mm, rad) of the central differences of :meth:`MeasuredFit.session_motion`.
FRAME_STEP = 1e-6
#: Most targets a position-only recording may name.
MAX_TARGETS = 3


# --------------------------------------------------------------------------- settings


def frame_from_dict(value, what: str = "frame") -> np.ndarray:
    """(6,) ``[x, y, z, alpha, beta, gamma]`` from ``{"translation_mm": [3], "rotation_rad": [3]}``.

    Raises:
        ValueError: naming ``what`` and the key that is wrong.
    """
    if not isinstance(value, dict):
        raise ValueError(f"{what} must be an object with keys translation_mm and rotation_rad, got "
                         f"{type(value).__name__}")
    extra = sorted(set(value) - {"translation_mm", "rotation_rad"})
    if extra:
        raise ValueError(f"{what}: unknown key(s) {', '.join(extra)} (expected translation_mm, rotation_rad)")
    parts = []
    for key in ("translation_mm", "rotation_rad"):
        if key not in value:
            raise ValueError(f"{what}: missing key {key!r}")
        parts.append(as_array(value[key], f"{what}.{key}", (3,)))
    return np.concatenate(parts)


def frame_to_dict(frame) -> dict:
    """``{"translation_mm": [x, y, z], "rotation_rad": [alpha, beta, gamma]}`` of a (6,) frame."""
    f = np.asarray(frame, dtype=float)
    return {"translation_mm": f[:3].tolist(), "rotation_rad": f[3:].tolist()}


@dataclass(frozen=True, eq=False)
class MeasurementSettings:
    """How a recording was measured (the sidecar's ``meta.measurement``).

    Attributes:
        frame: one of :data:`FRAME_MODES`.
        initial_frame: (6,) a known or guessed frame (start of the estimate; with ``"base"``
            ignored), or None.
        targets: (K, 3) target offsets on the platform, mm (given or start values), or None for
            full-pose data.
        estimate_targets: whether the target offsets are estimated (default: when not given).
    """

    frame: str = "auto"
    initial_frame: np.ndarray | None = None
    targets: np.ndarray | None = None
    estimate_targets: bool = False

    @property
    def n_targets(self) -> int:
        """K (0 for full-pose data)."""
        return 0 if self.targets is None else int(self.targets.shape[0])


def measurement_settings(value) -> MeasurementSettings:
    """Parse ``{"frame": "auto"|"base"|"estimate", "initial_frame": {...}, "targets": K or
    [[x, y, z], ...], "estimate_targets": bool}`` (every key optional; None: the defaults).

    Raises:
        ValueError: naming the key that is wrong.
    """
    if value is None:
        return MeasurementSettings()
    where = "meta.measurement"
    if not isinstance(value, dict):
        raise ValueError(f"{where} must be an object, got {type(value).__name__}")
    known = {"frame", "initial_frame", "targets", "estimate_targets"}
    extra = sorted(set(value) - known)
    if extra:
        raise ValueError(f"{where}: unknown key(s) {', '.join(extra)} (expected {', '.join(sorted(known))})")
    mode = value.get("frame", "auto")
    if mode not in FRAME_MODES:
        raise ValueError(f"{where}.frame must be one of {', '.join(FRAME_MODES)}, got {mode!r}")
    initial = value.get("initial_frame")
    initial = None if initial is None else frame_from_dict(initial, f"{where}.initial_frame")
    targets, given = value.get("targets"), True
    if targets is not None:
        if isinstance(targets, bool):
            raise ValueError(f"{where}.targets must be a count 1..{MAX_TARGETS} or a list of [x, y, z] offsets")
        if isinstance(targets, int):
            if not 1 <= targets <= MAX_TARGETS:
                raise ValueError(f"{where}.targets must be between 1 and {MAX_TARGETS}, got {targets}")
            targets, given = np.zeros((targets, 3)), False
        else:
            targets = as_array(targets, f"{where}.targets", (-1, 3))
            if not 1 <= targets.shape[0] <= MAX_TARGETS:
                raise ValueError(f"{where}.targets must list 1 to {MAX_TARGETS} offsets, got {targets.shape[0]}")
    estimate = value.get("estimate_targets", not given)
    if not isinstance(estimate, bool):
        raise ValueError(f"{where}.estimate_targets must be true or false, got {estimate!r}")
    if targets is None and "estimate_targets" in value:
        raise ValueError(f"{where}.estimate_targets needs targets")
    return MeasurementSettings(frame=mode, initial_frame=None if initial is None else frozen_array(initial),
                               targets=None if targets is None else frozen_array(targets),
                               estimate_targets=bool(estimate))


# --------------------------------------------------------------------------- model


def _pose_parts(robot: Robot, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) positions and (N, 3, 3) rotations (identity for a translating platform)."""
    angle = robot.angle_pose_mask
    t = poses[:, ~angle]
    R = rotation_matrix(poses[:, angle]) if angle.any() else np.broadcast_to(np.eye(3), (len(poses), 3, 3))
    return t, R


def compose(frame, robot: Robot, poses) -> np.ndarray:
    """(N, D) the poses ``F o pose`` (a pose in the base frame as the instrument sees it)."""
    return instrument_measurements(robot, poses, frame)


def target_names(n_targets: int) -> tuple[str, ...]:
    """``("t1_x", "t1_y", "t1_z", "t2_x", ...)``."""
    return tuple(f"t{k + 1}_{c}" for k in range(n_targets) for c in "xyz")


def measurement_names(robot: Robot, n_targets: int = 0) -> tuple[str, ...]:
    """Names of the measured coordinates: the robot's pose names, or :func:`target_names`."""
    return robot.pose_names if n_targets == 0 else target_names(n_targets)


def measurement_units(robot: Robot, n_targets: int = 0) -> tuple[str, ...]:
    """Units of the measured coordinates: the robot's pose units, or mm for every target coordinate."""
    return robot.pose_units if n_targets == 0 else ("mm",) * (3 * n_targets)


def _reports_the_pose(robot: Robot, poses: np.ndarray, frame: np.ndarray, targets) -> bool:
    """Whether the instrument reports ``poses`` (N, D) themselves: no targets, the base frame (a
    zero ``frame``) and every angle where :func:`calib.rotation.euler_from_matrix` returns it
    (|alpha|, |gamma| < pi, |beta| < pi / 2); then the measurements are the poses and their pose
    Jacobian the identity (what the general formulas give, to rounding)."""
    if targets is not None or frame.any():
        return False
    angles = poses[:, robot.angle_pose_mask]
    return not angles.size or bool(np.all(np.abs(angles) < np.array([np.pi, np.pi / 2, np.pi])))


def instrument_measurements(robot: Robot, poses, frame=None, targets=None) -> np.ndarray:
    """(N, M) what the instrument reports at base-frame ``poses`` (N, D).

    Args:
        robot: the robot (its pose units say which coordinates are angles).
        poses: (N, D) poses in the base frame.
        frame: (6,) the instrument frame; default the base frame itself.
        targets: (K, 3) target offsets on the platform, mm: report their positions (M = 3K); None:
            report the pose (M = D).
    """
    poses = as_array(poses, "poses", (-1, robot.pose_dim))
    frame = np.zeros(6) if frame is None else as_array(frame, "frame", (6,))
    if _reports_the_pose(robot, poses, frame, targets):
        return poses.copy()
    RF = rotation_matrix(frame[3:])
    t, R = _pose_parts(robot, poses)
    if targets is not None:
        targets = as_array(targets, "targets", (-1, 3))
        pts = np.einsum("nij,kj->nki", R, targets) + t[:, None, :]
        return (np.einsum("ij,nkj->nki", RF, pts) + frame[:3]).reshape(len(poses), -1)
    out = np.empty_like(poses)
    angle = robot.angle_pose_mask
    out[:, ~angle] = t @ RF.T + frame[:3]
    if angle.any():
        out[:, angle] = euler_from_matrix(RF @ R)
    return out


def _angular_rates(angles: np.ndarray) -> np.ndarray:
    """(N, 3, 3) ``E^-1``: angle rates from the world angular velocity, ``R = Rz Ry Rx``
    (``omega = E [da, db, dc]``, columns ``Rz Ry x``, ``Rz y``, ``z``)."""
    b, c = angles[:, 1], angles[:, 2]
    E = np.zeros((len(angles), 3, 3))
    E[:, 0, 0], E[:, 1, 0], E[:, 2, 0] = np.cos(c) * np.cos(b), np.sin(c) * np.cos(b), -np.sin(b)
    E[:, 0, 1], E[:, 1, 1] = -np.sin(c), np.cos(c)
    E[:, 2, 2] = 1.0
    return np.linalg.inv(E)


def _vee(W: np.ndarray) -> np.ndarray:
    return np.stack([W[..., 2, 1], W[..., 0, 2], W[..., 1, 0]], axis=-1)


def measurement_jacobians(robot: Robot, poses, frame=None, targets=None, *,
                          with_frame: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Analytic derivatives of :func:`instrument_measurements`.

    Args:
        with_frame: False: ``H_frame`` is not wanted (zeros are returned where the instrument
            reports the pose itself, the identity ``H_pose`` then taken without the formulas).

    Returns:
        ``(H_pose (N, M, D), H_frame (N, M, 6), H_targets (N, M, 3K))`` (K = 0 without targets).
    """
    poses = as_array(poses, "poses", (-1, robot.pose_dim))
    frame = np.zeros(6) if frame is None else as_array(frame, "frame", (6,))
    n, d = poses.shape
    if not with_frame and _reports_the_pose(robot, poses, frame, targets):
        Hp = np.zeros((n, d, d))
        Hp[:, np.arange(d), np.arange(d)] = 1.0
        return Hp, np.zeros((n, d, 6)), np.zeros((n, d, 0))
    angle = robot.angle_pose_mask
    pos_cols, ang_cols = np.flatnonzero(~angle), np.flatnonzero(angle)
    RF = rotation_matrix(frame[3:])
    dRF = rotation_matrix_derivatives(frame[3:])  # (3, 3, 3)
    t, R = _pose_parts(robot, poses)
    dR = rotation_matrix_derivatives(poses[:, angle]) if angle.any() else np.zeros((n, 0, 3, 3))
    if targets is not None:
        targets = as_array(targets, "targets", (-1, 3))
        k = targets.shape[0]
        Hp, HF, Ho = np.zeros((n, k, 3, d)), np.zeros((n, k, 3, 6)), np.zeros((n, k, 3, k, 3))
        Hp[:, :, :, pos_cols] = RF[None, None]
        if angle.any():
            Hp[:, :, :, ang_cols] = np.einsum("ij,najl,kl->nkia", RF, dR, targets)
        pts = np.einsum("nij,kj->nki", R, targets) + t[:, None, :]
        HF[:, :, :, :3] = np.eye(3)
        HF[:, :, :, 3:] = np.einsum("aij,nkj->nkia", dRF, pts)
        RFR = RF @ R  # (N, 3, 3)
        for j in range(k):
            Ho[:, j, :, j, :] = RFR
        return Hp.reshape(n, 3 * k, d), HF.reshape(n, 3 * k, 6), Ho.reshape(n, 3 * k, 3 * k)
    Hp, HF = np.zeros((n, d, d)), np.zeros((n, d, 6))
    Hp[:, pos_cols[:, None], pos_cols] = RF
    HF[:, pos_cols, :3] = np.eye(3)
    HF[:, pos_cols, 3:] = np.einsum("aij,nj->nia", dRF, t)
    if angle.any():
        Rm = RF @ R
        Einv = _angular_rates(euler_from_matrix(Rm))
        RmT = np.swapaxes(Rm, 1, 2)
        w_pose = _vee(np.einsum("ij,najl,nlm->naim", RF, dR, RmT))  # (N, 3 angles, 3)
        w_frame = _vee(np.einsum("aij,njl,nlm->naim", dRF, R, RmT))
        Hp[:, ang_cols[:, None], ang_cols] = np.einsum("nij,naj->nia", Einv, w_pose)
        HF[:, ang_cols, 3:] = np.einsum("nij,naj->nia", Einv, w_frame)
    return Hp, HF, np.zeros((n, d, 0))


def measurement_residuals(robot: Robot, measured, predicted, n_targets: int = 0) -> np.ndarray:
    """(N, M) ``measured - predicted``, angles wrapped to (-pi, pi]."""
    r = np.asarray(measured, dtype=float) - np.asarray(predicted, dtype=float)
    if n_targets == 0 and robot.angle_pose_mask.any():
        a = robot.angle_pose_mask
        r[:, a] = -((-r[:, a] + np.pi) % (2 * np.pi) - np.pi)
    return r


# --------------------------------------------------------------------------- registration


def rigid_registration(source, target) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` minimising ``sum |R source_i + t - target_i|^2`` (Kabsch), (N, 3) points each."""
    src, dst = np.asarray(source, dtype=float), np.asarray(target, dtype=float)
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    U, _, Vt = np.linalg.svd((dst - cd).T @ (src - cs))
    S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ S @ Vt
    return R, cd - R @ cs


def _nearest_rotation(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    return U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt


@dataclass(frozen=True, eq=False)
class Registration:
    """A closed-form first estimate of the instrument frame from the nominal model.

    Attributes:
        frame: (6,) the frame.
        targets: (K, 3) the target offsets (None for full-pose data).
        poses: (N, D) the nominal model's poses at the joints (base frame).
        rms_mm: RMS position residual after registration, mm.
        rms_rad: RMS angle residual after registration, rad (0 without angles).
    """

    frame: np.ndarray
    targets: np.ndarray | None
    poses: np.ndarray
    rms_mm: float
    rms_rad: float


def _nominal_poses(robot: Robot, theta, joints) -> np.ndarray:
    try:
        return robot.forward_kinematics(theta, joints)
    except KinematicsError as exc:
        raise ValueError(f"joints: the nominal model cannot reach row {exc.index}: {exc}") from None


def _disagreement(robot: Robot, measured, predicted, n_targets) -> tuple[float, float]:
    r = measurement_residuals(robot, measured, predicted, n_targets)
    angle = np.zeros(r.shape[1], bool) if n_targets else robot.angle_pose_mask
    rms = lambda v: float(np.sqrt(np.mean(np.sum(v ** 2, axis=1)))) if v.size else 0.0  # noqa: E731
    pos = r[:, ~angle].reshape(len(r), -1, 3)
    return float(np.sqrt(np.mean(np.sum(pos ** 2, axis=2)))), rms(r[:, angle])


def register_frame(robot: Robot, joints, measured, *, targets=None, estimate_targets: bool = False,
                   theta=None) -> Registration:
    """The instrument frame (and target offsets) that best map the model's poses onto the data.

    Full poses with angles: the rotation is the average (nearest rotation to the sum) of
    ``R_m R_p^T`` over the poses, the translation the mean of ``t_m - R_F t_p``. Positions only
    (a translating platform, or targets): Kabsch on the points, the targets at their start
    values; with ``estimate_targets`` a rigid fit (nominal geometry held) then refines frame and
    targets together.

    Args:
        robot: the robot.
        joints: (N, C) joints.
        measured: (N, M) the instrument's data.
        targets: (K, 3) target offsets (start values when estimated), or None for full poses.
        estimate_targets: refine the target offsets too.
        theta: (P,) the model; default nominal.
    """
    theta = robot.table.nominal if theta is None else as_array(theta, "theta", (robot.n_parameters,))
    k = 0 if targets is None else len(targets)
    joints = as_array(joints, "joints", (-1, robot.n_chains))
    measured = as_array(measured, "measured", (joints.shape[0], robot.pose_dim if k == 0 else 3 * k))
    poses = _nominal_poses(robot, theta, joints)
    t, R = _pose_parts(robot, poses)
    angle = robot.angle_pose_mask
    if k == 0 and angle.any():
        Rm = rotation_matrix(measured[:, angle])
        RF = _nearest_rotation(np.einsum("nij,nkj->ik", Rm, R))
        tF = np.mean(measured[:, ~angle] - t @ RF.T, axis=0)
    else:
        offsets = np.zeros((1, 3)) if k == 0 else np.asarray(targets, dtype=float)
        src = (np.einsum("nij,kj->nki", R, offsets) + t[:, None, :]).reshape(-1, 3)
        RF, tF = rigid_registration(src, measured.reshape(-1, 3))
    frame = np.concatenate([tF, euler_from_matrix(RF)])
    fitted_targets = None if k == 0 else np.array(targets, dtype=float)
    if k and estimate_targets:
        fit = _fit(robot, joints, measured, SensorNoise(1.0, 1.0), theta, np.zeros(0, int), frame[None],
                   fitted_targets, [True], True, poses, "lm", 100, 1e-15, 1e-15, gauge_passes=1)
        frame, fitted_targets = fit["frame"], fit["targets"]
    pred = instrument_measurements(robot, poses, frame, fitted_targets)
    mm, rad = _disagreement(robot, measured, pred, k)
    return Registration(frame=frozen_array(frame), targets=None if k == 0 else frozen_array(fitted_targets),
                        poses=frozen_array(poses), rms_mm=mm, rms_rad=rad)


@dataclass(frozen=True)
class FrameDetection:
    """Whether the data are in the robot's base frame.

    Attributes:
        detected: True when they are not (the frame should be estimated).
        rms_mm, rms_rad: RMS disagreement between the data and the nominal model in the base frame.
        limit_mm, limit_rad: the detection limits.
        message: the finding in words.
    """

    detected: bool
    rms_mm: float
    rms_rad: float
    limit_mm: float
    limit_rad: float
    message: str


def _fit_targets(robot, joints, measured, theta, poses, frame, targets) -> np.ndarray:
    """(K, 3) target offsets fitted with the geometry ``theta`` and the frame held (rigid fit)."""
    fit = _fit(robot, joints, measured, SensorNoise(1.0, 1.0), theta, np.zeros(0, int),
               np.asarray(frame, dtype=float)[None], np.asarray(targets, dtype=float), [False], True, poses,
               "lm", 100, 1e-15, 1e-15, gauge_passes=1)
    return fit["targets"]


def detect_frame(robot: Robot, joints, measured, *, targets=None, estimate_targets: bool = False,
                 theta=None) -> FrameDetection:
    """Compare the data with the nominal model in the base frame (targets at their given offsets,
    or fitted with the frame held when ``estimate_targets``): a disagreement beyond
    :data:`FRAME_DETECTION_FRACTION` of the machine's size (RMS position) or
    :data:`FRAME_DETECTION_RAD` (RMS angle) means another frame. Geometric errors give far less:
    the reference experiments' errors (Delta within 1 mm and 1 degree, rus 0.5 mm and 0.5 degree)
    at most 3.6 % of the size and 0.022 rad over 20 seeds. A smaller offset is not detected; for a
    robot whose base joints can move rigidly (hexapod, rus) the geometry absorbs it, and
    ``"estimate"`` forces the frame in."""
    theta = robot.table.nominal if theta is None else theta
    k = 0 if targets is None else len(targets)
    joints = as_array(joints, "joints", (-1, robot.n_chains))
    measured = as_array(measured, "measured", (joints.shape[0], robot.pose_dim if k == 0 else 3 * k))
    poses = _nominal_poses(robot, theta, joints)
    if k and estimate_targets:
        targets = _fit_targets(robot, joints, measured, theta, poses, np.zeros(6), targets)
    mm, rad = _disagreement(robot, measured, instrument_measurements(robot, poses, None, targets), k)
    lim_mm, lim_rad = FRAME_DETECTION_FRACTION * robot.length_scale_mm, FRAME_DETECTION_RAD
    detected = mm > lim_mm or rad > lim_rad
    what = f"{mm:.4g} mm RMS" + (f", {rad:.3g} rad RMS" if k == 0 and robot.angle_pose_mask.any() else "")
    if detected:
        message = (f"the measured poses are not in the robot's base frame: they differ from the nominal "
                   f"model by {what} (limits {lim_mm:.3g} mm, {lim_rad:g} rad); the instrument frame is "
                   "registered and estimated with the geometry")
    else:
        message = (f"the measured poses are in the robot's base frame: they differ from the nominal "
                   f"model by {what} (limits {lim_mm:.3g} mm, {lim_rad:g} rad)")
    return FrameDetection(detected, mm, rad, lim_mm, lim_rad, message)


# --------------------------------------------------------------------------- joint fit


def _whitening(robot, theta, joints, poses, noise, Hp, n_targets) -> np.ndarray:
    """(N, M, M) whitening of each measurement's covariance: instrument noise plus the joint
    noise through the manipulator Jacobian and the measurement model."""
    std = noise.pose_std(measurement_units(robot, n_targets))
    n, m = Hp.shape[:2]
    if noise.joint_std > 0:
        jq = Hp @ pose_jacobian_of_joints(robot, theta, joints, poses)
        cov = np.broadcast_to(np.diag(std ** 2), (n, m, m)) + noise.joint_std ** 2 * jq @ np.swapaxes(jq, 1, 2)
        return np.linalg.inv(np.linalg.cholesky(cov))
    return np.broadcast_to(np.diag(1.0 / std), (n, m, m)).copy()


def whitened_residuals(robot: Robot, theta, joints, measured, noise: SensorNoise, *, frame=None, targets=None,
                       initial=None) -> tuple[np.ndarray, np.ndarray]:
    """Each row's residual against a model, whitened by the declared noise as the joint fit
    whitens it (instrument noise plus the joint noise through the manipulator Jacobian).

    Args:
        robot, theta: the robot and its (P,) parameter vector.
        joints: (N, C) joints.
        measured: (N, M) the instrument's data (full poses, or K target positions, M = 3K).
        noise: declared noise.
        frame: (6,) the instrument frame; default the base frame.
        targets: (K, 3) target offsets, mm; None for full poses.
        initial: (N, D) start of the forward kinematics; default the robot's home pose.

    Returns:
        ``(whitened (N, M), poses (N, D))``: the whitened residuals (dimensionless; each row's
        squared norm is chi-square with M degrees of freedom for a row at the declared noise) and
        the model's poses at the joints (base frame, mm and rad).

    Raises:
        KinematicsError: the model cannot reach a row.
    """
    joints = as_array(joints, "joints", (-1, robot.n_chains))
    k = 0 if targets is None else len(targets)
    measured = as_array(measured, "measured", (joints.shape[0], robot.pose_dim if k == 0 else 3 * k))
    poses = robot.forward_kinematics(theta, joints, initial=initial)
    r = measurement_residuals(robot, measured, instrument_measurements(robot, poses, frame, targets), k)
    if noise.joint_std == 0:  # a diagonal whitening: each coordinate over its std (the product's numbers)
        return r * (1.0 / noise.pose_std(measurement_units(robot, k))), poses
    Hp, _, _ = measurement_jacobians(robot, poses, frame, targets, with_frame=False)
    winv = _whitening(robot, theta, joints, poses, noise, Hp, k)
    return np.einsum("nij,nj->ni", winv, r), poses


def gauge_null_space(A: np.ndarray, groups, rtol: float = GAUGE_RTOL) -> tuple[np.ndarray, np.ndarray]:
    """The redundant directions of a scaled Jacobian and the constraints that fix them.

    Args:
        A: (R, n) Jacobian in scaled coordinates (every column per mm).
        groups: column index arrays in order of priority (geometry, targets, frame): a direction
            is fixed on the first group it touches.
        rtol: singular values below ``rtol`` times the largest are zero.

    Returns:
        ``(null (n, k), constraints (k, n))``: an orthonormal basis of the null space, and rows
        ``c`` such that ``c . (z - reference) = 0`` fixes it (each row within one group).
    """
    n = A.shape[1]
    # Every right singular vector (the null space's too) without the (M, M) left ones of a tall A.
    _, s, vt = np.linalg.svd(A, full_matrices=A.shape[0] < n)
    s = np.r_[s, np.zeros(n - s.size)]
    null = vt[s <= rtol * s[0]].T
    rows, left = [], null
    for cols in groups:
        if left.shape[1] == 0:
            break
        cols = np.asarray(cols, int)
        if cols.size == 0:
            continue
        U, sv, Vt = np.linalg.svd(left[cols], full_matrices=True)
        r = int(np.count_nonzero(sv > 1e-8))
        for u in U[:, :r].T:
            c = np.zeros(n)
            c[cols] = u
            rows.append(c)
        left = left @ Vt[r:].T
    return null, np.array(rows).reshape(-1, n)


def _complement(constraints: np.ndarray, n: int) -> np.ndarray:
    """(n, n - k) orthonormal basis of the directions the constraints leave free."""
    if constraints.shape[0] == 0:
        return np.eye(n)
    _, s, vt = np.linalg.svd(constraints, full_matrices=True)
    return vt[constraints.shape[0]:].T


def _session_rows(sessions, n_sessions: int) -> list:
    """Each session's rows: ``[slice(None)]`` (every row, as before sessions) for one session,
    else the (N_s,) row indices of sessions 0..S-1."""
    if n_sessions == 1:
        return [slice(None)]
    return [np.flatnonzero(sessions == s) for s in range(n_sessions)]


def _session_measurements(robot, poses, frames, targets, rows) -> np.ndarray:
    """(N, M) :func:`instrument_measurements`, each row in its session's frame (``frames`` (S, 6))."""
    if len(rows) == 1:
        return instrument_measurements(robot, poses, frames[0], targets)
    out = np.empty((len(poses), robot.pose_dim if targets is None else 3 * len(targets)))
    for s, r in enumerate(rows):
        out[r] = instrument_measurements(robot, poses[r], frames[s], targets)
    return out


def _session_jacobians(robot, poses, frames, targets, rows, estimated) -> tuple:
    """``(H_pose, H_frames, H_targets)`` of :func:`measurement_jacobians`, each row in its session's
    frame; ``H_frames`` (N, M, 6E): the E sessions flagged in ``estimated`` (S,), six columns each,
    a row's block in its own session's columns (zero elsewhere)."""
    if len(rows) == 1:
        Hp, HF, Ho = measurement_jacobians(robot, poses, frames[0], targets, with_frame=bool(estimated[0]))
        return Hp, (HF if estimated[0] else HF[:, :, :0]), Ho
    m = robot.pose_dim if targets is None else 3 * len(targets)
    k3 = 0 if targets is None else 3 * len(targets)
    n, column = len(poses), np.cumsum(estimated) - 1
    Hp, HF, Ho = np.empty((n, m, robot.pose_dim)), np.zeros((n, m, 6 * int(np.sum(estimated)))), np.empty((n, m, k3))
    for s, r in enumerate(rows):
        Hp[r], HFs, Ho[r] = measurement_jacobians(robot, poses[r], frames[s], targets, with_frame=bool(estimated[s]))
        if estimated[s]:
            HF[r, :, 6 * column[s]:6 * column[s] + 6] = HFs
    return Hp, HF, Ho


class _JointProblem:
    """The joint fit's unknowns ``z = [geometry idx | targets (when estimated) | the estimated
    sessions' frames, six each]``, its whitened residuals and their Jacobian (the prior's rows after
    the measurements'). The whitening is taken once, at the start."""

    def __init__(self, robot, joints, measured, noise, theta0, idx, frames0, targets0, est_frames, est_targets,
                 poses0, rows, prior):
        self.robot, self.joints, self.measured, self.theta0, self.idx = robot, joints, measured, theta0, idx
        self.frames0, self.targets0, self.rows, self.prior = np.asarray(frames0, dtype=float), targets0, rows, prior
        self.est_frames, self.est_targets = np.asarray(est_frames, bool), est_targets
        self.k = 0 if targets0 is None else targets0.shape[0]
        self.nt, self.nf = (3 * self.k if est_targets else 0), 6 * int(np.sum(self.est_frames))
        frame_scale = np.tile(np.r_[np.ones(3), np.full(3, robot.length_scale_mm)], self.nf // 6)
        self.scale = np.concatenate([np.where(robot.table.angle_mask()[idx], robot.length_scale_mm, 1.0),
                                     np.ones(self.nt), frame_scale])
        self.groups = [np.arange(idx.size), idx.size + np.arange(self.nt), idx.size + self.nt + np.arange(self.nf)]
        tg_start = np.zeros(0) if targets0 is None else np.asarray(targets0, dtype=float).ravel()[:self.nt]
        self.start = np.concatenate([theta0[idx], tg_start, self.frames0[self.est_frames].ravel()])
        self.poses0 = poses0
        self.restart(poses0)
        Hp0, _, _ = _session_jacobians(robot, poses0, self.frames0, targets0, rows, self.est_frames)
        self.winv = _whitening(robot, theta0, joints, poses0, noise, Hp0, self.k)
        self.prior_rows = None if prior is None else np.zeros((idx.size, self.start.size))
        if prior is not None:
            self.prior_rows[:, :idx.size] = np.diag(1.0 / prior.std[idx])

    def unpack(self, z) -> tuple:
        """``(theta (P,), targets (K, 3) or None, frames (S, 6))`` of ``z``."""
        ni, nt = self.idx.size, self.nt
        th = self.theta0.copy()
        th[self.idx] = z[:ni]
        tg = self.targets0 if not self.est_targets else z[ni:ni + nt].reshape(self.k, 3)
        frames = self.frames0.copy()
        frames[self.est_frames] = z[ni + nt:].reshape(-1, 6)
        return th, tg, frames

    def restart(self, poses) -> None:
        """Start the forward kinematics of the next evaluations from ``poses`` (N, D)."""
        self.state = {"poses": poses, "theta": None, "anchor": None}

    def poses_of(self, th) -> np.ndarray:
        """(N, D) the forward kinematics at ``th``: that of the last evaluation when ``th`` is its
        (the Jacobian at a point just evaluated, the figures at the solution), else Newton's from
        the poses at the last Jacobian moved to first order by its pose Jacobian (a trial point
        starts from the point it steps from, never from a rejected trial's poses)."""
        state = self.state
        if not self.idx.size or (state["theta"] is not None and np.array_equal(state["theta"], th)):
            return state["poses"]
        initial = state["poses"]
        if state["anchor"] is not None:
            th_j, poses_j, dpose = state["anchor"]
            initial = poses_j + dpose @ (th - th_j)[self.idx]
        state["poses"] = self.robot.forward_kinematics(th, self.joints, initial=initial)
        state["theta"] = th.copy()
        return state["poses"]

    def residual(self, z) -> np.ndarray:
        th, tg, frames = self.unpack(z)
        pred = _session_measurements(self.robot, self.poses_of(th), frames, tg, self.rows)
        r = np.einsum("nij,nj->ni", self.winv, measurement_residuals(self.robot, self.measured, pred, self.k)).ravel()
        prior, idx = self.prior, self.idx
        return r if prior is None else np.concatenate([r, (th[idx] - prior.mean[idx]) / prior.std[idx]])

    def jacobian(self, z) -> np.ndarray:
        th, tg, frames = self.unpack(z)
        p = self.poses_of(th)
        Hp, HF, Ho = _session_jacobians(self.robot, p, frames, tg, self.rows, self.est_frames)
        blocks = []
        if self.idx.size:
            dpose = pose_jacobian_of_parameters(self.robot, th, self.joints, p)[:, :, self.idx]
            self.state["anchor"] = (th.copy(), p, dpose)
            blocks.append(Hp @ dpose)
        if self.nt:
            blocks.append(Ho)
        if self.nf:
            blocks.append(HF)
        J = np.concatenate(blocks, axis=2)
        J = -np.einsum("nij,njk->nik", self.winv, J).reshape(len(p) * J.shape[1], -1)
        return J if self.prior_rows is None else np.concatenate([J, self.prior_rows])


def _fit(robot, joints, measured, noise, theta0, idx, frames0, targets0, est_frames, est_targets, poses0,
         solver, max_iter, xtol, ftol, gauge_passes=2, reference=None, prior=None, rows=None):
    """The joint fit of geometry ``idx``, the sessions' frames ``frames0`` (S, 6) (those flagged in
    ``est_frames`` (S,) estimated) and the targets; see :func:`identify_measured`. ``rows``: each
    session's rows (:func:`_session_rows`; default one session). With a ``prior``, its whitened rows
    ``(theta[idx] - mean) / std`` follow the measurements' rows. A gauge pass after the first starts
    at its minimum in a gauge plane taken there (combinations the start's plane held exactly may be
    free there, and barely determined): Levenberg-Marquardt then runs ``cautious``
    (:func:`calib.engine.minimise`)."""
    rows = [slice(None)] if rows is None else rows
    pb = _JointProblem(robot, joints, measured, noise, theta0, idx, frames0, targets0, est_frames, est_targets,
                       poses0, rows, prior)
    scale, z = pb.scale, pb.start.copy()
    z_ref = pb.start.copy()
    if reference is not None:
        z_ref[:idx.size] = reference[idx]
    history: list[float] = []
    iters, ok, msg = 0, False, "not run"
    null = np.zeros((z.size, 0))
    for gauge_pass in range(max(1, gauge_passes)):
        null, C = gauge_null_space(pb.jacobian(z) / scale, pb.groups)
        Q = _complement(C, z.size)
        G = Q / scale[:, None]  # y (scaled) -> z
        base = z_ref + G @ (Q.T @ ((z - z_ref) * scale))  # the start, projected onto the gauge plane
        pb.restart(poses0)
        y, it, ok, msg = minimise(lambda y: pb.residual(base + G @ y), lambda y: pb.jacobian(base + G @ y) @ G,
                                  np.zeros(Q.shape[1]), solver=solver, max_iter=max_iter, xtol=xtol,
                                  ftol=ftol, history=history, cautious=gauge_pass > 0)
        iters += it
        z = base + G @ y
        if null.shape[1] == 0:
            break
    out = _fit_outputs(pb, z, G, Q.shape[1])
    out.update({"iterations": iters, "history": tuple(history), "success": ok, "message": msg,
                "null": null / scale[:, None]})
    return out


def _fit_outputs(pb: _JointProblem, z, G, n_free: int) -> dict:
    """The joint fit's solution ``z`` in words of its parts: geometry, targets, ``frames`` (S, 6)
    (``frame`` session 0's), the covariance of ``z`` (gauge plane ``G``), chi-square and degrees of
    freedom (``n_free`` unknowns in the plane, or every measured row with a prior)."""
    r = pb.residual(z)
    Jy = pb.jacobian(z) @ G
    cov = G @ np.linalg.pinv(Jy.T @ Jy, hermitian=True) @ G.T
    th, tg, frames = pb.unpack(z)
    norms = np.linalg.norm(Jy, axis=0)
    cond = float(np.linalg.cond(Jy / norms)) if np.all(norms > 0) and Jy.size else float("inf")
    n_measured = r.size - (0 if pb.prior is None else pb.idx.size)
    return {"theta": th, "targets": None if pb.k == 0 else np.array(tg, dtype=float),
            "frames": np.array(frames, dtype=float), "frame": np.array(frames[0], dtype=float),
            "est_frames": pb.est_frames.copy(), "poses": pb.state["poses"], "chi2": float(r @ r),
            "dof": int(n_measured - n_free) if pb.prior is None else int(n_measured), "cov": cov, "cond": cond,
            "n_theta": pb.idx.size, "nt": pb.nt, "nf": pb.nf}


@dataclass(frozen=True, eq=False)
class MeasuredFit:
    """The geometry, instrument frame(s) and target offsets identified together.

    One machine may be measured in several sessions (:func:`identify_measured`'s ``sessions``),
    each in its own instrument frame; ``frames`` holds them, ``frame`` is session 0's.

    Attributes:
        result: the geometry as an :class:`~calib.engine.IdentificationResult` (method
            ``"forward"``; ``residuals``/``pose_residuals`` in the instrument's coordinates, (N, M);
            ``covariance`` the geometry's, in the gauge).
        frame: (6,) session 0's instrument frame (zeros when the data are in the base frame).
        frame_std: (6,) its standard uncertainty (zeros when not estimated).
        targets: (K, 3) the target offsets (None for full-pose data).
        targets_std: (K, 3) their standard uncertainty (zeros when given).
        frame_estimated, targets_estimated: what was estimated (``frame_estimated``: any session's frame).
        gauge: the redundant directions the gauge fixes, in words (parameter units).
        detection: session 0's frame detection (None when the mode was not ``"auto"``).
        registration: session 0's closed-form start (None when its frame was not estimated).
        notes: what was found and done, in words.
        frames: (S, 6) each session's instrument frame.
        frames_std: (S, 6) their standard uncertainties (zeros where not estimated).
        frames_estimated: (S,) which sessions' frames were estimated.
        session_of_row: (N,) the session of each of the fit's rows (zeros for one session).
        unknown_names: the joint fit's unknowns: free parameters (table order), ``T1.x ...`` when
            the targets are estimated, then the estimated frames (``frame.x ...`` for one session,
            ``frame.x@s ...`` for several).
        unknowns_covariance: (n, n) their covariance, in the gauge (or under the prior).
        registrations: (S,) each session's closed-form start (:class:`Registration`, None where
            its frame was not estimated): the "before" of a session's held-out rows.
    """

    result: IdentificationResult
    frame: np.ndarray
    frame_std: np.ndarray
    targets: np.ndarray | None
    targets_std: np.ndarray | None
    frame_estimated: bool
    targets_estimated: bool
    gauge: tuple
    detection: FrameDetection | None
    registration: Registration | None
    notes: tuple
    frames: np.ndarray
    frames_std: np.ndarray
    frames_estimated: np.ndarray
    session_of_row: np.ndarray
    unknown_names: tuple
    unknowns_covariance: np.ndarray
    registrations: tuple

    @property
    def n_targets(self) -> int:
        return 0 if self.targets is None else int(self.targets.shape[0])

    @property
    def n_sessions(self) -> int:
        """S, the number of sessions (instrument frames)."""
        return int(self.frames.shape[0])

    def frame_dict(self) -> dict:
        """The summary's ``measurement_frame`` (session 0's): ``{"translation_mm": [...], "rotation_rad": [...]}``."""
        return frame_to_dict(self.frame)

    def frames_dict(self) -> dict:
        """``{session index: frame_to_dict(frame)}``, every session."""
        return {s: frame_to_dict(f) for s, f in enumerate(self.frames)}

    def row_sessions(self, n: int, sessions=None) -> np.ndarray:
        """(n,) session indices of ``n`` rows: ``sessions`` (n,) ints, or one int for every row;
        None: session 0, only for a one-session fit (a several-session fit does not guess).

        Raises:
            ValueError: sessions missing for a several-session fit, of the wrong shape or out of range.
        """
        if sessions is None:
            if self.n_sessions > 1:
                raise ValueError(f"this fit has {self.n_sessions} sessions (instrument frames): pass sessions=, "
                                 "each row's session index")
            return np.zeros(n, int)
        s = np.broadcast_to(np.asarray(sessions), (n,)) if np.ndim(sessions) == 0 else np.asarray(sessions)
        return _checked_sessions(s, n, self.n_sessions)

    def predict(self, joints, *, initial=None, sessions=None) -> np.ndarray:
        """(N, M) what the instrument would report at ``joints`` by the identified model, each row in
        its session's frame (``sessions``: see :meth:`row_sessions`)."""
        robot = self.result.robot
        joints = np.asarray(joints, dtype=float)
        s = self.row_sessions(len(joints), sessions)
        poses = robot.forward_kinematics(self.result.theta, joints, initial=initial)
        return _session_measurements(robot, poses, self.frames, self.targets, _session_rows(s, self.n_sessions))

    def base_poses(self, joints, measured, sessions=None) -> np.ndarray:
        """(N, D) the data as poses in the (gauge) base frame: full poses taken out of their
        session's instrument frame; for position-only data the poses the identified model predicts."""
        if self.targets is None:
            return self.to_base(measured, sessions)
        return self.result.robot.forward_kinematics(self.result.theta, np.asarray(joints, dtype=float))

    def to_base(self, measured, sessions=None) -> np.ndarray:
        """(N, D) full poses measured in their session's instrument frame, expressed in the (gauge)
        base frame (``sessions``: see :meth:`row_sessions`)."""
        robot = self.result.robot
        measured = as_array(measured, "measured", (-1, robot.pose_dim))
        s = self.row_sessions(len(measured), sessions)
        inverse = np.array([invert_frame(f) for f in self.frames])
        return _session_measurements(robot, measured, inverse, None, _session_rows(s, self.n_sessions))

    def frame_columns(self, session: int) -> np.ndarray:
        """The six indices of ``session``'s frame in :attr:`unknown_names` (empty when not estimated)."""
        if not self.frames_estimated[session]:
            return np.zeros(0, int)
        first = len(self.unknown_names) - 6 * int(np.sum(self.frames_estimated))
        return first + 6 * (int(np.sum(self.frames_estimated[:session]))) + np.arange(6)

    def session_motion(self, session: int, reference: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """How the instrument moved between sessions: ``(D (6,), std (6,))`` with ``D = F_session o
        F_reference^-1`` (a point seen at ``x`` in the reference session's frame is seen at ``D x`` in
        the other's). ``D`` does not depend on the gauge (a common rigid motion of the base cancels),
        so its uncertainty is the data's whatever holds the gauge; ``std`` from the joint covariance
        of the two frames (linearised, central differences)."""
        pair = np.r_[self.frames[session], self.frames[reference]]
        motion = lambda v: compose_frames(v[:6], invert_frame(v[6:]))  # noqa: E731
        J = np.zeros((6, 12))
        for j in range(12):
            step = np.zeros(12)
            step[j] = FRAME_STEP
            J[:, j] = (motion(pair + step) - motion(pair - step)) / (2 * FRAME_STEP)
        cols = [self.frame_columns(session), self.frame_columns(reference)]
        C = np.zeros((12, 12))
        for a, ca in enumerate(cols):
            for b, cb in enumerate(cols):
                if ca.size and cb.size:
                    C[6 * a:6 * a + 6, 6 * b:6 * b + 6] = self.unknowns_covariance[np.ix_(ca, cb)]
        return motion(pair), np.sqrt(np.clip(np.diag(J @ C @ J.T), 0.0, None))

    def prediction_covariance(self, joints, sessions=None) -> np.ndarray:
        """(N, M, M) the covariance of :meth:`predict` at ``joints`` from the fit's uncertainty
        (geometry, targets and frames together: their correlations through the gauge or the prior
        cancel here). Add the instrument's noise to whiten a held-out row's residual."""
        robot, theta = self.result.robot, self.result.theta
        joints = np.asarray(joints, dtype=float)
        s = self.row_sessions(len(joints), sessions)
        idx = np.sort(robot.table.indices(self.result.free_names))
        poses = robot.forward_kinematics(theta, joints)
        Hp, HF, Ho = _session_jacobians(robot, poses, self.frames, self.targets, _session_rows(s, self.n_sessions),
                                        self.frames_estimated)
        blocks = [Hp @ pose_jacobian_of_parameters(robot, theta, joints, poses)[:, :, idx]]
        blocks += [Ho] if self.targets_estimated else []
        J = np.concatenate(blocks + [HF], axis=2)
        return np.einsum("nij,jk,nlk->nil", J, self.unknowns_covariance, J)


def invert_frame(frame) -> np.ndarray:
    """(6,) the frame F^-1 (a pose seen in frame F taken back: ``compose(invert_frame(F), robot, compose(F, robot, p)) == p``)."""
    frame = as_array(frame, "frame", (6,))
    R = rotation_matrix(frame[3:])
    return np.concatenate([-R.T @ frame[:3], euler_from_matrix(R.T)])


def _read_only(value, dtype) -> np.ndarray:
    """A read-only copy of ``value`` as ``dtype`` (flags and indices; floats take ``frozen_array``)."""
    a = np.array(value, dtype=dtype)
    a.setflags(write=False)
    return a


def compose_frames(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(6,) the frame ``a o b`` (``b`` applied first)."""
    Ra = rotation_matrix(a[3:])
    return np.concatenate([Ra @ b[:3] + a[:3], euler_from_matrix(Ra @ rotation_matrix(b[3:]))])


def _checked_sessions(sessions, n: int, n_sessions: int | None = None) -> np.ndarray:
    """(n,) int session indices 0..S-1 (every one with a row when ``n_sessions`` is None: S is then
    their largest plus one).

    Raises:
        ValueError: not integers, the wrong shape, out of range, or a session without rows.
    """
    s = np.asarray(sessions)
    if s.shape != (n,) or (s.size and not np.issubdtype(s.dtype, np.integer)):
        raise ValueError(f"sessions must be ({n},) integer session indices, got shape {s.shape}, dtype {s.dtype}")
    s = s.astype(int)
    top = (int(s.max()) + 1 if s.size else 1) if n_sessions is None else n_sessions
    if s.size and (s.min() < 0 or s.max() >= top):
        raise ValueError(f"sessions must lie in 0..{top - 1}, got {s.min()}..{s.max()}")
    missing = np.setdiff1d(np.arange(top), s)
    if n_sessions is None and missing.size:
        raise ValueError(f"sessions: session {int(missing[0])} has no rows (number them 0..S-1)")
    return s


def identify_measured(robot: Robot, joints, measured, noise: SensorNoise, *, frame="auto",
                      initial_frame=None, targets=None, estimate_targets: bool | None = None, free=None,
                      start=None, solver: str = "lm", max_iter: int = 100, xtol: float = 1e-15,
                      ftol: float = 1e-15, gauge_passes: int = 2, prior: ParameterPrior | None = None,
                      sessions=None) -> MeasuredFit:
    """Identify the geometry jointly with the instrument frame(s) and the target offsets.

    Three steps: the arguments checked (:func:`checked_measured_inputs`), the start of the frames and
    target offsets (:func:`_sessions_start`: detection, closed-form registration, session by
    session), the joint fit (:func:`_fit`) and its result (:func:`_measured_fit_result`).

    Sessions. With ``sessions`` (N,) (indices 0..S-1, every one with rows), each session has its own
    instrument frame and one geometry (and one set of targets) serves every session. The S frames
    and the base are redundant by one common rigid motion (the base moved, every frame moved back):
    with a ``prior`` the prior on the geometry holds it (the frames' standard deviations then include
    it); without one the gauge fixes it as for one frame (the geometry's errors have no component
    along it). Either way :meth:`MeasuredFit.session_motion` (one frame relative to another) does not
    depend on it. None: one session, bit for bit the fit without sessions.

    Args:
        robot: the robot.
        joints: (N, C) commanded (or read) joints.
        measured: (N, D) full poses or (N, 3K) target positions, each row in its session's frame.
        noise: declared noise (positions of targets take ``position_mm``).
        frame: ``"auto"`` (estimate when :func:`detect_frame` finds the data in another frame),
            ``"base"`` (the data are in the base frame) or ``"estimate"``; or S of them, one a session.
        initial_frame: (6,) start of the frame estimate (every session's); or S of them (each (6,)
            or None); default the closed-form registration of each session's rows.
        targets: (K, 3) target offsets (given, or start values), None for full poses.
        estimate_targets: estimate the offsets; default True when ``targets`` are given.
        free, start, solver, max_iter, xtol, ftol: as :func:`calib.engine.identify_forward`.
        gauge_passes: fits with the null space re-taken at the last solution (2: the gauge holds
            beyond first order).
        prior: the geometry's prior (:class:`calib.prior.ParameterPrior`): maximum a posteriori,
            its rows beside the measurements' (as :func:`calib.engine.identify_forward`). The
            directions the poses cannot separate between geometry, frame and targets are then held
            by the prior, no longer by the gauge; fewer rows than unknowns are accepted.
        sessions: (N,) int, each row's session; None: one session.

    Raises:
        ValueError: bad arguments, a row the start model cannot reach, too few rows (without a prior).
    """
    data = checked_measured_inputs(robot, joints, measured, noise, frame, targets, estimate_targets, free, start,
                                   sessions=sessions)
    joints, measured = data["joints"], data["measured"]
    k, est_targets, idx, theta0 = data["k"], data["est_targets"], data["idx"], data["theta0"]
    modes, initials = _session_modes(frame, initial_frame, data["n_sessions"])
    begin = _sessions_start(robot, joints, measured, modes, initials, data["targets"], est_targets, theta0,
                            data["rows"])
    unknowns = idx.size + (3 * k if est_targets else 0) + 6 * int(np.sum(begin["est_frames"]))
    m = robot.pose_dim if k == 0 else 3 * k
    if joints.shape[0] * m < unknowns and prior is None:
        raise ValueError(f"measured must have at least {-(-unknowns // m)} rows to identify {unknowns} "
                         f"unknowns, got {joints.shape[0]}")
    if prior is not None:
        prior.check(robot)
    fit = _fit(robot, joints, measured, noise, theta0, idx, begin["frames0"], begin["targets0"], begin["est_frames"],
               est_targets, begin["poses0"], solver, max_iter, xtol, ftol, gauge_passes=gauge_passes, prior=prior,
               rows=data["rows"])
    return _measured_fit_result(robot, joints, measured, noise, fit, data, begin, prior)


def _session_modes(frame, initial_frame, n_sessions: int) -> tuple[list, list]:
    """Each session's frame mode and start frame (or None) from :func:`identify_measured`'s
    ``frame`` and ``initial_frame`` (one for all, or one a session).

    Raises:
        ValueError: a mode not in :data:`FRAME_MODES`, or not one per session.
    """
    modes = [frame] * n_sessions if isinstance(frame, str) else list(frame)
    if len(modes) != n_sessions:
        raise ValueError(f"frame must be one of {FRAME_MODES} or {n_sessions} of them, got {frame!r}")
    for mode in modes:
        if mode not in FRAME_MODES:
            raise ValueError(f"frame must be one of {FRAME_MODES}, got {mode!r}")
    if initial_frame is None:
        return modes, [None] * n_sessions
    initials = list(initial_frame)
    if all(f is not None and np.ndim(f) == 0 for f in initials):  # six numbers: one frame for every session
        return modes, [as_array(initial_frame, "initial_frame", (6,))] * n_sessions
    if len(initials) != n_sessions:
        raise ValueError(f"initial_frame must be one (6,) frame or {n_sessions}, got {len(initials)}")
    return modes, [None if f is None else as_array(f, f"initial_frame[{s}]", (6,)) for s, f in enumerate(initials)]


def checked_measured_inputs(robot, joints, measured, noise, frame, targets, estimate_targets, free, start, *,
                            sessions=None) -> dict:
    """The checked arguments of :func:`identify_measured`: ``joints`` (N, C), ``measured``
    (N, M), ``targets`` (K, 3) or None, ``k`` = K, ``est_targets``, the free ``names`` and their
    sorted indices ``idx``, the start vector ``theta0`` (P,), ``sessions`` (N,) int (zeros for one
    session), ``n_sessions`` S and each session's ``rows`` (:func:`_session_rows`).

    Raises:
        TypeError, ValueError: naming the argument that is wrong.
    """
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be a calib.robot.Robot, got {type(robot).__name__}")
    if not isinstance(noise, SensorNoise):
        raise TypeError(f"noise must be a SensorNoise, got {type(noise).__name__}")
    if isinstance(frame, str) and frame not in FRAME_MODES:
        raise ValueError(f"frame must be one of {FRAME_MODES}, got {frame!r}")
    targets = None if targets is None else as_array(targets, "targets", (-1, 3))
    k = 0 if targets is None else targets.shape[0]
    if targets is not None and not 1 <= k <= MAX_TARGETS:
        raise ValueError(f"targets must hold 1 to {MAX_TARGETS} offsets, got {k}")
    est_targets = k > 0 and (True if estimate_targets is None else bool(estimate_targets))
    joints = as_array(joints, "joints", (-1, robot.n_chains))
    measured = as_array(measured, "measured", (joints.shape[0], robot.pose_dim if k == 0 else 3 * k))
    names = robot.free_default if free is None else tuple(free)
    if not names or len(set(names)) != len(names):
        raise ValueError(f"free must be a non-empty list of distinct parameter names, got {names}")
    idx = np.sort(robot.table.indices(names))
    theta0 = robot.table.nominal.copy() if start is None else as_array(start, "start", (robot.n_parameters,)).copy()
    n = joints.shape[0]
    sessions = np.zeros(n, int) if sessions is None else _checked_sessions(sessions, n)
    n_sessions = int(sessions.max()) + 1 if n else 1
    return {"joints": joints, "measured": measured, "targets": targets, "k": k, "est_targets": est_targets,
            "names": names, "idx": idx, "theta0": theta0, "sessions": sessions, "n_sessions": n_sessions,
            "rows": _session_rows(sessions, n_sessions)}


def _measured_start(robot, joints, measured, frame, initial_frame, targets, est_targets, theta0) -> dict:
    """Whether the frame is estimated and where the fit starts: ``detection`` (or None),
    ``est_frame``, ``registration`` (or None), ``frame0`` (6,), ``targets0`` (K, 3) or None,
    ``poses0`` (N, D) the start model's poses, ``notes`` (what was found, in words)."""
    k = 0 if targets is None else targets.shape[0]
    notes, detection = [], None
    if frame == "auto":
        detection = detect_frame(robot, joints, measured, targets=targets, estimate_targets=est_targets,
                                 theta=theta0)
        notes.append(detection.message)
        est_frame = detection.detected
    else:
        est_frame = frame == "estimate"
    poses0 = _nominal_poses(robot, theta0, joints)
    registration = None
    if est_frame:
        registration = register_frame(robot, joints, measured, targets=targets, estimate_targets=est_targets,
                                      theta=theta0)
        frame0 = registration.frame.copy() if initial_frame is None else as_array(initial_frame, "initial_frame", (6,))
        notes.append(f"registered the instrument frame in closed form: {_frame_words(frame0)} (residual "
                     f"{registration.rms_mm:.3g} mm RMS with the nominal geometry)")
        targets0 = None if k == 0 else registration.targets.copy()
    else:
        frame0 = np.zeros(6) if initial_frame is None or frame == "base" else as_array(initial_frame, "initial_frame", (6,))
        targets0 = None if k == 0 else (
            _fit_targets(robot, joints, measured, theta0, poses0, frame0, targets) if est_targets else targets.copy())
    return {"detection": detection, "est_frame": est_frame, "registration": registration, "frame0": frame0,
            "targets0": targets0, "poses0": poses0, "notes": notes}


def _sessions_start(robot, joints, measured, modes, initials, targets, est_targets, theta0, rows) -> dict:
    """:func:`_measured_start` session by session (one session: exactly it), combined:
    ``frames0`` (S, 6), ``est_frames`` (S,), ``est_frame`` (any), ``poses0`` (N, D), ``targets0``
    (session 0's start), ``detection`` and ``registration`` (session 0's), ``registrations`` (each
    session's, None where its frame is not estimated), ``notes`` (each
    session's, named)."""
    if len(rows) == 1:
        begin = _measured_start(robot, joints, measured, modes[0], initials[0], targets, est_targets, theta0)
        begin.update(frames0=begin["frame0"][None], est_frames=np.array([begin["est_frame"]]),
                     registrations=(begin["registration"],))
        return begin
    parts = [_measured_start(robot, joints[r], measured[r], modes[s], initials[s], targets, est_targets, theta0)
             for s, r in enumerate(rows)]
    poses0 = np.empty((joints.shape[0], robot.pose_dim))
    for r, part in zip(rows, parts):
        poses0[r] = part["poses0"]
    est_frames = np.array([part["est_frame"] for part in parts])
    return {"detection": parts[0]["detection"], "registration": parts[0]["registration"],
            "registrations": tuple(part["registration"] for part in parts), "est_frame": bool(est_frames.any()), "est_frames": est_frames,
            "frames0": np.array([part["frame0"] for part in parts]), "targets0": parts[0]["targets0"],
            "poses0": poses0,
            "notes": [f"session {s}: {note}" for s, part in enumerate(parts) for note in part["notes"]]}


def _unknown_names(robot, fit: dict, data: dict) -> list:
    """The joint fit's unknowns (see :attr:`MeasuredFit.unknown_names`)."""
    k, s = data["k"], data["n_sessions"]
    frames = list(FRAME_NAMES) if s == 1 else [f"{name}@{i}" for i in range(s) for name in FRAME_NAMES]
    frames = np.array(frames).reshape(s, 6)[fit["est_frames"]].ravel()
    return list(np.array(robot.table.names)[data["idx"]]) + \
        [f"T{j + 1}.{c}" for j in range(k) for c in "xyz"][:fit["nt"]] + list(frames)


def _measured_fit_result(robot, joints, measured, noise, fit: dict, data: dict, begin: dict,
                         prior: ParameterPrior | None = None) -> MeasuredFit:
    """The :class:`MeasuredFit` of a joint fit (``fit`` from :func:`_fit`; ``data`` from
    :func:`checked_measured_inputs`, ``begin`` from :func:`_sessions_start`): residuals (N, M) at the
    solution, the geometry's covariance (P, P), the frames' and targets' uncertainties, the gauge
    in words, the stop message with the chi-square verdict."""
    k, est_targets, idx, theta0 = data["k"], data["est_targets"], data["idx"], data["theta0"]
    est_frame, detection, notes = begin["est_frame"], begin["detection"], begin["notes"]
    theta, est_frames = fit["theta"], fit["est_frames"]
    # The fit's own forward kinematics at its solution (converged there, and judged regular where
    # the fit evaluated it): Newton's again from them could call a configuration the fit accepted
    # singular (the condition number, near the threshold, taken at a slightly other point).
    res = measurement_residuals(robot, measured, _session_measurements(robot, fit["poses"], fit["frames"],
                                                                       fit["targets"], data["rows"]), k)
    cov = np.zeros((robot.n_parameters,) * 2)
    ni, nt = fit["n_theta"], fit["nt"]
    cov[np.ix_(idx, idx)] = fit["cov"][:ni, :ni]
    std = np.sqrt(np.clip(np.diag(fit["cov"]), 0.0, None))
    frames_std = np.zeros(fit["frames"].shape)
    frames_std[est_frames] = std[ni + nt:].reshape(-1, 6)
    targets_std = None if k == 0 else (std[ni:ni + nt].reshape(k, 3) if est_targets else np.zeros((k, 3)))
    all_names = _unknown_names(robot, fit, data)
    gauge = tuple(describe_combination(v / np.max(np.abs(v)), all_names, n_terms=6, number_format=".3g")
                  for v in fit["null"].T)
    if gauge:
        notes.append(f"{len(gauge)} direction(s) are redundant between geometry, targets and frame; fixed by "
                     "the gauge (geometric errors expressed in the base frame best fitted to the nominal one)")
    msg = fit["message"]
    dof = fit["dof"]
    if fit["success"] and dof > 0 and np.isfinite(fit["chi2"]):
        msg = f"{msg}; {noise_verdict(fit['chi2'], dof)}"
    if est_frame and data["n_sessions"] > 1:
        msg = f"{msg}; the instrument frame(s) of session(s) {', '.join(map(str, np.flatnonzero(est_frames)))} " \
              "estimated with the geometry"
    elif est_frame:
        msg = f"{msg}; " + (detection.message if detection is not None else
                            "the instrument frame is estimated with the geometry")
    result = IdentificationResult(
        method="forward", robot=robot, theta=theta, start=theta0, free_names=data["names"], residuals=res,
        pose_residuals=res, covariance=cov, chi2=fit["chi2"], dof=dof, iterations=fit["iterations"],
        history=fit["history"], success=fit["success"], message=msg, condition_numbers=np.array([fit["cond"]]),
        prior=prior)
    return MeasuredFit(result=result, frame=frozen_array(fit["frame"]), frame_std=frozen_array(frames_std[0]),
                       targets=None if k == 0 else frozen_array(fit["targets"]),
                       targets_std=None if k == 0 else frozen_array(targets_std), frame_estimated=bool(est_frame),
                       targets_estimated=bool(est_targets), gauge=gauge, detection=detection,
                       registration=begin["registration"], notes=tuple(notes), frames=frozen_array(fit["frames"]),
                       frames_std=frozen_array(frames_std), frames_estimated=_read_only(est_frames, bool),
                       session_of_row=_read_only(data["sessions"], int), unknown_names=tuple(all_names),
                       unknowns_covariance=frozen_array(fit["cov"]), registrations=begin["registrations"])


def identify_as_measured(robot: Robot, joints, measured, noise: SensorNoise, settings: MeasurementSettings,
                         **options) -> MeasuredFit | None:
    """:func:`identify_measured` as a recording's ``settings`` say, or None when the data are plain
    full poses in the base frame (``"base"``, or ``"auto"`` and :func:`detect_frame` finds
    nothing): then the caller's own method applies unchanged."""
    if settings.frame != "estimate":
        try:
            found = detect_frame(robot, joints, measured, targets=settings.targets,
                                 estimate_targets=settings.estimate_targets)
        except ValueError:
            if settings.n_targets:
                raise
            return None  # the nominal model cannot start from home here: the caller's method judges
        if settings.frame == "base" and found.detected:
            raise ValueError(f"meta.measurement.frame is 'base', but {found.message.split(': ', 1)[1].split(';')[0]}: "
                             "the poses seem to be measured in another frame; set it to 'auto' or 'estimate'")
        if settings.n_targets == 0 and not found.detected:
            return None
    return identify_measured(robot, joints, measured, noise, frame=settings.frame,
                             initial_frame=settings.initial_frame, targets=settings.targets,
                             estimate_targets=settings.estimate_targets, **options)


def measured_gauge_representative(robot: Robot, theta, *, estimate_frame: bool = True, targets=None,
                                  poses: int = 60, seed: int = 0, start=None) -> np.ndarray:
    """(P,) the parameter vector, in the gauge of :func:`identify_measured` with the frame (and,
    with ``targets``, the target offsets) estimated, that moves like ``theta``: to compare an
    identified vector with a machine's true one (a noise-free fit over ``poses`` workspace poses,
    exact to numerical precision; see :func:`calib.engine.gauge_representative`)."""
    from .workspace import reachable_poses

    theta = as_array(theta, "theta", (robot.n_parameters,))
    start = robot.table.nominal if start is None else start
    targets_at = reachable_poses(robot, poses, seed, theta=theta)
    joints = robot.inverse_kinematics(theta, targets_at)
    data = instrument_measurements(robot, targets_at, None, targets)
    fit = identify_measured(robot, joints, data, SensorNoise(1.0, 1.0), frame="estimate" if estimate_frame else "base",
                            targets=targets, start=start, initial_frame=np.zeros(6))
    return fit.result.theta


def _frame_words(frame) -> str:
    f = np.asarray(frame)
    return (f"translation [{', '.join(f'{v:.4g}' for v in f[:3])}] mm, rotation "
            f"[{', '.join(f'{v:.4g}' for v in f[3:])}] rad")


# --------------------------------------------------------------------------- observability


@dataclass(frozen=True, eq=False)
class MeasurementObservability:
    """What a measurement set determines, frame and targets included.

    Attributes:
        names: the unknowns (free parameters, then ``T1.x ...``, then ``frame.x ...``).
        rank: numerical rank of the whitened, scaled Jacobian.
        n_unknowns: their number.
        gauge: the redundant directions (between geometry, targets and frame), in words.
        condition_number: of the scaled Jacobian restricted to the gauge-free directions.
    """

    names: tuple
    rank: int
    n_unknowns: int
    gauge: tuple
    condition_number: float

    def summary(self) -> dict:
        return {"rank": self.rank, "n_unknowns": self.n_unknowns, "not_identifiable": list(self.gauge),
                "condition_number": self.condition_number if np.isfinite(self.condition_number) else None}


def whitened_jacobian(robot: Robot, theta, joints, poses, noise: SensorNoise, *, frame=None, targets=None,
                      free=None, estimate_frame: bool = False,
                      estimate_targets: bool = False) -> tuple[np.ndarray, np.ndarray, list]:
    """Every row's whitened measurement Jacobian with respect to the unknowns of the joint fit.

    Args:
        robot, theta: the robot and the (P,) parameter vector to linearise at.
        joints: (N, C) joints; poses: (N, D) the model's poses at them (base frame).
        noise: declared noise (whitening, as :func:`whitened_residuals`).
        frame: (6,) the instrument frame; default the base frame.
        targets: (K, 3) target offsets, mm; None for full poses.
        free: the free parameters (default ``robot.free_default``), taken in table order.
        estimate_frame, estimate_targets: whether the frame and the offsets are unknowns.

    Returns:
        ``(J (N, M, n), scale (n,), names)``: the whitened Jacobian (per unit of each unknown:
        mm or rad), each unknown's scale (mm per unit: 1 for lengths, the machine's size for
        angles) and its name (free parameters, then ``T1.x ...``, then ``frame.x ...``).
    """
    frame = np.zeros(6) if frame is None else as_array(frame, "frame", (6,))
    k = 0 if targets is None else len(targets)
    idx = np.sort(robot.table.indices(robot.free_default if free is None else tuple(free)))
    Hp, HF, Ho = measurement_jacobians(robot, poses, frame, targets)
    winv = _whitening(robot, theta, joints, poses, noise, Hp, k)
    blocks = [Hp @ pose_jacobian_of_parameters(robot, theta, joints, poses)[:, :, idx]]
    names = list(np.array(robot.table.names)[idx])
    scale = [np.where(robot.table.angle_mask()[idx], robot.length_scale_mm, 1.0)]
    if estimate_targets and k:
        blocks.append(Ho)
        names += [f"T{j + 1}.{c}" for j in range(k) for c in "xyz"]
        scale.append(np.ones(3 * k))
    if estimate_frame:
        blocks.append(HF)
        names += list(FRAME_NAMES)
        scale.append(np.r_[np.ones(3), np.full(3, robot.length_scale_mm)])
    J = np.concatenate(blocks, axis=2)
    return np.einsum("nij,njk->nik", winv, J), np.concatenate(scale), names


def measurement_observability(robot: Robot, theta, joints, noise: SensorNoise, *, frame=None, targets=None,
                              estimate_frame: bool = True, estimate_targets: bool = True, free=None,
                              rtol: float = GAUGE_RTOL) -> MeasurementObservability:
    """Which combinations of geometry, target offsets and frame a pose set cannot identify.

    Args:
        robot, theta: the robot and the parameter vector to linearise at.
        joints: (N, C) the joints of the measurements.
        noise: declared noise (whitening).
        frame: (6,) the frame to linearise at; default the base frame.
        targets: (K, 3) target offsets (position-only data), None for full poses.
        estimate_frame, estimate_targets: which of them are unknowns.
        free: the free parameters; default ``robot.free_default``.
    """
    theta = as_array(theta, "theta", (robot.n_parameters,))
    joints = as_array(joints, "joints", (-1, robot.n_chains))
    frame = np.zeros(6) if frame is None else as_array(frame, "frame", (6,))
    k = 0 if targets is None else len(targets)
    targets = None if targets is None else as_array(targets, "targets", (-1, 3))
    est_targets = bool(estimate_targets and k)
    idx = np.sort(robot.table.indices(robot.free_default if free is None else tuple(free)))
    poses = _nominal_poses(robot, theta, joints)
    J, scale, names = whitened_jacobian(robot, theta, joints, poses, noise, frame=frame, targets=targets,
                                        free=np.array(robot.table.names)[idx], estimate_frame=estimate_frame,
                                        estimate_targets=est_targets)
    A = J.reshape(-1, J.shape[2])
    ni, nt = idx.size, 3 * k if est_targets else 0
    groups = [np.arange(ni), ni + np.arange(nt), ni + nt + np.arange(6 if estimate_frame else 0)]
    null, C = gauge_null_space(A / scale, groups, rtol)
    Q = _complement(C, A.shape[1])
    s = np.linalg.svd(A / scale @ Q, compute_uv=False) if Q.shape[1] else np.zeros(1)
    natural = null / scale[:, None]
    gauge = tuple(describe_combination(v / np.max(np.abs(v)), names, n_terms=6, number_format=".3g")
                  for v in natural.T)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    return MeasurementObservability(names=tuple(names), rank=A.shape[1] - null.shape[1], n_unknowns=A.shape[1],
                                    gauge=gauge, condition_number=cond)
