"""What moves between sessions of one machine: its joints' zeros and the instrument's frame.

A machine that re-homes at power-up (a homing switch's repeatability, an encoder re-zeroed, a spool
re-wound) starts each session with its joints' zeros moved; a motion capture re-calibrated or a
tracker moved sees every pose of a session through a moved frame. Neither changes the geometry.
This module estimates, from the rows of one session and a machine held fixed, the *shift* of that
session against the machine's reference:

* ``joint zeros``: each joint's zero moved by ``d_i`` (joint unit): the machine is at the joints
  ``q + d`` where it reads ``q`` (:attr:`calib.robot.Robot.joint_zero_names` are the parameters
  that carry it);
* ``instrument frame``: the instrument moved by the rigid motion ``D`` (6,): a pose it reported as
  ``m`` it now reports as ``D o m`` (translation mm in the instrument's frame, angles rad);

each with a Gaussian prior of its tolerance (:data:`JOINT_ZERO_SHIFT_STD`,
:data:`FRAME_SHIFT_STD`), and the four models (neither, either, both) chosen against each other
by their evidence (the marginal likelihood of the rows, Laplace's approximation about the
maximum a posteriori: exact for the linearised model). The same linear algebra serves a session
seen through a model's residuals (:func:`shift_of_residuals`: the closure residuals of a
discovery) and a calibration re-referenced from a handful of poses (:func:`fit_session_shift`,
Gauss-Newton on the machine's own prediction).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .measurement import compose, compose_frames, measurement_residuals
from .noise import SensorNoise
from .robot import Robot

__all__ = ["SHIFT_MODELS", "JOINT_ZERO_SHIFT_STD", "FRAME_SHIFT_STD", "FRAME_SHIFT_NAMES", "SessionShift",
           "ShiftModel", "fit_session_shift", "shift_of_residuals", "shift_unknown_names", "frame_shift_std",
           "joint_zero_shift_std", "rereferenced_theta", "UNDETERMINED_FRACTION"]

#: The models a session's shift is chosen among, simplest first.
SHIFT_MODELS = ("none", "joint zeros", "instrument frame", "joint zeros and instrument frame")
#: The prior of a joint zero's move between sessions, one standard deviation per joint unit: a
#: homing switch repeats to hundredths of a millimetre, but a re-zeroed encoder, a re-wound spool
#: or a motor re-seated moves a zero by up to a few millimetres (a degree for a rotary joint).
JOINT_ZERO_SHIFT_STD = {"mm": 2.0, "rad": 0.02}
#: The prior of the instrument's move between sessions, one standard deviation: a tracker set down
#: again or a motion capture re-calibrated, up to centimetres and a degree.
FRAME_SHIFT_STD = {"mm": 10.0, "rad": 0.02}
#: Names of the instrument's motion's six coordinates.
FRAME_SHIFT_NAMES = ("frame.x", "frame.y", "frame.z", "frame.alpha", "frame.beta", "frame.gamma")
#: An unknown is said undetermined by the rows where its posterior standard deviation is above
#: this fraction of its prior's: the rows moved it little from the prior.
UNDETERMINED_FRACTION = 0.5
#: Central-difference steps of the prediction's derivatives, per unit (mm, rad).
DIFFERENCE_STEP = {"mm": 1e-4, "rad": 1e-7}
#: Gauss-Newton iterations of :func:`fit_session_shift` (the model is nearly linear in a shift).
SHIFT_ITERATIONS = 4


def joint_zero_shift_std(robot: Robot) -> np.ndarray:
    """(C,) the prior standard deviation of each joint zero's move, joint unit."""
    return np.full(robot.n_chains, JOINT_ZERO_SHIFT_STD[robot.joint_unit])


def frame_shift_std() -> np.ndarray:
    """(6,) the prior standard deviation of the instrument's move (mm, mm, mm, rad, rad, rad)."""
    return np.repeat([FRAME_SHIFT_STD["mm"], FRAME_SHIFT_STD["rad"]], 3)


def shift_unknown_names(robot: Robot) -> tuple[str, ...]:
    """The joint zeros' names (``d_l1`` ...) then :data:`FRAME_SHIFT_NAMES`."""
    return tuple(f"zero.{j}" for j in robot.joint_names) + FRAME_SHIFT_NAMES


def rereferenced_theta(robot: Robot, theta: np.ndarray, zeros: np.ndarray) -> np.ndarray:
    """(P,) ``theta`` with each joint zero parameter moved by ``zeros`` (C,): the machine that at
    the reading ``q`` is where ``theta`` is at ``q + zeros``."""
    out = np.array(theta, dtype=float)
    out[robot.table.indices(robot.joint_zero_names)] += np.asarray(zeros, dtype=float)
    return out


@dataclass(frozen=True)
class ShiftModel:
    """One model of a session's shift, fitted.

    Attributes:
        name: one of :data:`SHIFT_MODELS`.
        columns: indices of its unknowns in :func:`shift_unknown_names`.
        estimate: (C + 6,) the maximum a posteriori of every unknown (zero where not in the model).
        covariance: (C + 6, C + 6) its posterior covariance (zero outside the model).
        chi2: the rows' whitened residual sum of squares at the estimate.
        log_evidence: the log marginal likelihood of the rows, up to a constant common to the models.
    """

    name: str
    columns: np.ndarray
    estimate: np.ndarray
    covariance: np.ndarray
    chi2: float
    log_evidence: float

    @property
    def std(self) -> np.ndarray:
        """(C + 6,) posterior standard deviations."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))


@dataclass(frozen=True)
class SessionShift:
    """A session's shift, chosen by evidence (see the module docstring).

    Attributes:
        robot: the robot.
        models: every model fitted, by name (:data:`SHIFT_MODELS` order).
        chosen: the name of the model of largest evidence.
        rows: the number of rows that estimated it.
        measurements: the number of whitened residuals (rows times coordinates).
        chi2_none: the rows' whitened residual sum of squares with no shift.
        p_no_shift: the probability of a fall in chi-square at least as large as the full model's
            (joint zeros and frame, without their priors) if nothing moved: chi-square with the
            number of determined unknowns as degrees of freedom.
        mean_position_error_mm: (3,) the mean over the rows of measured minus predicted position
            with no shift (the instrument's frame), the shift as a person sees it.
        prior_std: (C + 6,) the priors' standard deviations.
    """

    robot: Robot
    models: dict
    chosen: str
    rows: int
    measurements: int
    chi2_none: float
    p_no_shift: float
    mean_position_error_mm: np.ndarray
    prior_std: np.ndarray

    @property
    def best(self) -> ShiftModel:
        return self.models[self.chosen]

    @property
    def zeros(self) -> np.ndarray:
        """(C,) each joint zero's move, joint unit (0 unless the chosen model has them)."""
        return self.best.estimate[:self.robot.n_chains]

    @property
    def zeros_std(self) -> np.ndarray:
        return self.best.std[:self.robot.n_chains]

    @property
    def frame_motion(self) -> np.ndarray:
        """(6,) the instrument's motion ``D`` (0 unless the chosen model has it)."""
        return self.best.estimate[self.robot.n_chains:]

    @property
    def frame_motion_std(self) -> np.ndarray:
        return self.best.std[self.robot.n_chains:]

    @property
    def shifted(self) -> bool:
        """Whether a shift is chosen (a model other than ``none``)."""
        return self.chosen != "none"

    def undetermined(self, model: str | None = None) -> tuple[str, ...]:
        """Names of ``model``'s (default the chosen one's) unknowns the rows leave near their prior
        (posterior standard deviation above :data:`UNDETERMINED_FRACTION` of the prior's)."""
        m = self.models[model or self.chosen]
        names = shift_unknown_names(self.robot)
        return tuple(names[j] for j in m.columns if m.std[j] > UNDETERMINED_FRACTION * self.prior_std[j])

    def evidence_against(self, other: str = "none") -> float:
        """Log evidence of the chosen model less ``other``'s (nats)."""
        return self.best.log_evidence - self.models[other].log_evidence

    def to_dict(self) -> dict:
        """JSON-ready: the chosen model, its unknowns with std and unit, the evidence of each model."""
        r = self.robot
        names = shift_unknown_names(r)
        units = (r.joint_unit,) * r.n_chains + ("mm",) * 3 + ("rad",) * 3
        best = self.best
        return {"model": self.chosen, "rows": self.rows,
                "shift": {names[j]: {"value": float(best.estimate[j]), "std": float(best.std[j]), "unit": units[j]}
                          for j in best.columns},
                "undetermined": list(self.undetermined()),
                "log_evidence": {k: float(m.log_evidence) for k, m in self.models.items()},
                "chi2": {k: float(m.chi2) for k, m in self.models.items()}, "measurements": self.measurements,
                "p_no_shift": float(self.p_no_shift),
                "mean_position_error_mm": [float(v) for v in self.mean_position_error_mm]}


def _model_columns(robot: Robot, name: str) -> np.ndarray:
    c = robot.n_chains
    zeros, frame = np.arange(c), c + np.arange(6)
    return {"none": np.zeros(0, int), "joint zeros": zeros, "instrument frame": frame,
            "joint zeros and instrument frame": np.r_[zeros, frame]}[name]


def _linear_model(name: str, cols: np.ndarray, r: np.ndarray, A: np.ndarray, prior_std: np.ndarray) -> ShiftModel:
    """The Gaussian-linear model ``r = A u + e``, ``e ~ N(0, I)``, ``u ~ N(0, diag(prior_std^2))``
    restricted to ``cols``: its maximum a posteriori, covariance, chi-square and log evidence
    (``-(chi2 + u' S^-2 u) / 2 - log det(I + S A'A S) / 2``, constants common to every model
    dropped)."""
    k = A.shape[1]
    est, cov = np.zeros(k), np.zeros((k, k))
    if cols.size == 0:
        chi2 = float(r @ r)
        return ShiftModel(name, cols, est, cov, chi2, -0.5 * chi2)
    S = prior_std[cols]
    As = A[:, cols] * S  # the unknowns scaled by their prior: v = u / S, v ~ N(0, I)
    H = As.T @ As + np.eye(cols.size)
    L = np.linalg.cholesky(H)
    v = np.linalg.solve(L.T, np.linalg.solve(L, As.T @ r))
    Hinv = np.linalg.solve(L.T, np.linalg.solve(L, np.eye(cols.size)))
    est[cols] = S * v
    cov[np.ix_(cols, cols)] = Hinv * np.outer(S, S)
    e = r - As @ v
    chi2 = float(e @ e)
    log_det = 2.0 * float(np.sum(np.log(np.diag(L))))
    return ShiftModel(name, cols, est, cov, chi2, -0.5 * (chi2 + float(v @ v)) - 0.5 * log_det)


def _p_no_shift(r: np.ndarray, A: np.ndarray, prior_std: np.ndarray) -> float:
    """The chi-square fall of the full model without its prior, judged as chi-square with the
    rank of its columns (scaled by the prior, so that units do not set the rank)."""
    from scipy.special import gammaincc

    As = A * prior_std
    U, s, _ = np.linalg.svd(As, full_matrices=False)
    rank = int(np.sum(s > s[0] * max(As.shape) * np.finfo(float).eps)) if s.size and s[0] > 0 else 0
    if rank == 0:
        return 1.0
    fall = float(np.sum((U[:, :rank].T @ r) ** 2))
    return float(gammaincc(rank / 2.0, fall / 2.0))


def _choose(robot: Robot, r: np.ndarray, A: np.ndarray, prior_std: np.ndarray, models) -> tuple[dict, str]:
    fitted = {m: _linear_model(m, _model_columns(robot, m), r, A, prior_std) for m in SHIFT_MODELS if m in models}
    chosen = max(fitted, key=lambda m: fitted[m].log_evidence)
    return fitted, chosen


def shift_of_residuals(robot: Robot, residuals: np.ndarray, zero_jacobian: np.ndarray, frame_jacobian: np.ndarray,
                       whitening: np.ndarray, mean_position_error_mm, *, models=SHIFT_MODELS) -> SessionShift:
    """A session's shift seen in a model's residuals (linear: the residuals are small).

    Args:
        robot: the robot.
        residuals: (N, M) what the model leaves of each row (observed less predicted).
        zero_jacobian: (N, M, C) the residuals' change per unit move of each joint zero
            (observed less predicted: the prediction's derivative with the sign turned).
        frame_jacobian: (N, M, 6) the same per unit instrument motion (mm, rad).
        whitening: (N, M, M) each row's whitening (its noise covariance's inverse Cholesky
            factor, ``W C W' = I``).
        mean_position_error_mm: (3,) the mean position error of the rows with no shift, the
            instrument's frame (said in the words).
        models: the models to choose among (:data:`SHIFT_MODELS`).
    """
    n = residuals.shape[0]
    r = np.einsum("nij,nj->ni", whitening, residuals).ravel()
    J = np.concatenate([zero_jacobian, frame_jacobian], axis=2)
    A = np.einsum("nij,njk->nik", whitening, J).reshape(r.size, -1)
    prior_std = np.r_[joint_zero_shift_std(robot), frame_shift_std()]
    fitted, chosen = _choose(robot, r, A, prior_std, models)
    return SessionShift(robot, fitted, chosen, n, int(r.size), float(r @ r), _p_no_shift(r, A, prior_std),
                        np.asarray(mean_position_error_mm, dtype=float), prior_std)


def _whitening(robot: Robot, noise: SensorNoise, prediction_covariance: np.ndarray | None, n: int) -> np.ndarray:
    """(N, D, D) the rows' whitening: the instrument's noise plus the prediction's covariance."""
    C = np.broadcast_to(np.diag(noise.pose_std(robot.pose_units) ** 2), (n, robot.pose_dim, robot.pose_dim)).copy()
    if prediction_covariance is not None:
        C = C + prediction_covariance
    return np.linalg.inv(np.linalg.cholesky(C))


def _predicted(robot: Robot, machine: Callable, joints: np.ndarray, frame: np.ndarray, u: np.ndarray) -> np.ndarray:
    c = robot.n_chains
    return compose(compose_frames(u[c:], frame), robot, machine(joints + u[:c]))


def _prediction_jacobian(robot: Robot, machine: Callable, joints: np.ndarray, frame: np.ndarray,
                         u: np.ndarray) -> np.ndarray:
    """(N, D, C + 6) the prediction's derivatives at ``u`` (central differences; the machine's
    poses computed once for the frame's columns)."""
    c = robot.n_chains
    seen = compose_frames(u[c:], frame)
    cols = []
    for j in range(c):
        h = np.zeros(c)
        h[j] = DIFFERENCE_STEP[robot.joint_unit]
        cols.append((compose(seen, robot, machine(joints + u[:c] + h))
                     - compose(seen, robot, machine(joints + u[:c] - h))) / (2 * h[j]))
    base = machine(joints + u[:c])
    for j, unit in enumerate(("mm",) * 3 + ("rad",) * 3):
        h = np.zeros(6)
        h[j] = DIFFERENCE_STEP[unit]
        cols.append((compose(compose_frames(u[c:] + h, frame), robot, base)
                     - compose(compose_frames(u[c:] - h, frame), robot, base)) / (2 * h[j]))
    return np.stack(cols, axis=2)


def fit_session_shift(robot: Robot, machine: Callable, joints, measured, noise: SensorNoise, *, frame=None,
                      prediction_covariance=None, models=SHIFT_MODELS) -> SessionShift:
    """Estimate a session's shift from its rows, the machine held (the module docstring's models,
    each by Gauss-Newton on the prediction with its prior, chosen by evidence).

    Args:
        robot: the robot.
        machine: ``machine(joints (N, C)) -> (N, D)`` base-frame poses the held machine reaches
            (a :meth:`calib.calibration.Calibration.predict`, effects included).
        joints: (N, C) the session's joints, as read.
        measured: (N, D) the poses the instrument reported, in its frame.
        noise: the instrument's declared noise.
        frame: (6,) the instrument's frame as the held machine knows it (None: the base frame).
        prediction_covariance: (N, D, D) the held machine's uncertainty at the rows (added to the
            noise), or None.
        models: the models to choose among.
    """
    joints = np.asarray(joints, dtype=float)
    measured = np.asarray(measured, dtype=float)
    frame = np.zeros(6) if frame is None else np.asarray(frame, dtype=float)
    n = joints.shape[0]
    W = _whitening(robot, noise, prediction_covariance, n)
    prior_std = np.r_[joint_zero_shift_std(robot), frame_shift_std()]
    zero = np.zeros(robot.n_chains + 6)
    d0 = measurement_residuals(robot, measured, _predicted(robot, machine, joints, frame, zero))
    r0 = np.einsum("nij,nj->ni", W, d0).ravel()
    # Every model linearised about no shift (a shift of millimetres on a machine of hundreds moves
    # the Jacobian by a part in a thousand), the chosen one then iterated to its own maximum.
    A0 = np.einsum("nij,njk->nik", W, _prediction_jacobian(robot, machine, joints, frame, zero)).reshape(r0.size, -1)
    fitted, chosen = _choose(robot, r0, A0, prior_std, models)
    cols, u = fitted[chosen].columns, fitted[chosen].estimate
    for _ in range(SHIFT_ITERATIONS if cols.size else 0):
        d = measurement_residuals(robot, measured, _predicted(robot, machine, joints, frame, u))
        A = np.einsum("nij,njk->nik", W, _prediction_jacobian(robot, machine, joints, frame, u)).reshape(r0.size, -1)
        # the residual about the current estimate, expressed about no shift: r + A u
        m = _linear_model(chosen, cols, np.einsum("nij,nj->ni", W, d).ravel() + A @ u, A, prior_std)
        step, u = m.estimate - u, m.estimate
        fitted[chosen] = m
        if np.all(np.abs(step) <= 1e-9 * (prior_std + np.abs(u))):
            break
    position = ~robot.angle_pose_mask
    return SessionShift(robot, fitted, chosen, n, int(r0.size), float(r0 @ r0), _p_no_shift(r0, A0, prior_std),
                        d0[:, position].mean(axis=0), prior_std)
