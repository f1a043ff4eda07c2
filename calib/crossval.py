"""Cross-validated prediction error of an identification: a held-out figure without held-out rows.

A recording without validation rows still says how well the identified model predicts poses it
was not fitted to: each row is predicted by a model fitted without it, and its measured pose
compared with that prediction.

* ``method="forward"`` (:func:`calib.engine.identify_forward`): leave-one-out by default, with
  exact refits (one fit per row, each as the full fit: same start, options and prior). A fit
  costs a few milliseconds (``benchmarks/crossval_speed.py``), so the closed-form one-step
  approximation of :mod:`calib.outliers` (the hat matrix) is not needed. Above
  :data:`LOO_MAX_ROWS` rows (N refits of N rows each: a cost growing as N squared) the default is
  K-fold with :data:`DEFAULT_CHAINWISE_FOLDS` folds, and the scheme says why
  (``"10-fold (5,000 rows > LOO_MAX_ROWS = 2000)"``).
* ``method="chainwise"`` (:func:`calib.engine.identify_chainwise`): K-fold
  (:data:`DEFAULT_CHAINWISE_FOLDS` folds by default): the rows are split at random (seeded) into
  K folds of near-equal size; each fold is predicted by the model fitted to the other K - 1.

Above :data:`FEW_FOLDS_MIN_ROWS` rows either method's default is :data:`FEW_FOLDS` folds: K fits
of (K - 1) N / K rows each cost K - 1 full fits, and a model fitted to half of so many rows
predicts as one fitted to nine tenths (its own error adds about P / (N / 2) of the noise's
variance, P parameters: 0.1 % at 100,000 hexapod rows, below the figure's spread).

The prediction of a left-out row is the forward kinematics of the fold's model at the row's
joints, started from the measured pose (``robot.forward_kinematics(theta, joints,
initial=measured)``); its error is measured minus predicted, as the held-out error of recorded
validation rows (:func:`calib.identification.validation_errors`): it includes the sensor noise. With an
instrument frame or targets (``measurement=``), each fold is fitted by
:func:`calib.measurement.identify_measured` and predicted in the instrument's coordinates.

Sessions. A recording of several sessions, each in its own instrument frame (``sessions=``, with
``measurement=``), is cross-validated as it is fitted: each fold's model is one geometry and a
frame for each session that keeps training rows (the sessions renumbered in order where one keeps
none), and each left-out row is predicted in its own session's frame. A left-out row whose session
kept no training row in its fold has no frame to be predicted in: NaN, and the message says so.

A fold whose fit raises (too few rows left, a start the model cannot reach, a step out of the
workspace) or whose model cannot reach a left-out row leaves those rows without a prediction
(NaN); the result is returned all the same and its message names the folds. A fold fit that
returns without meeting its stopping rule is kept and named.

:func:`crossvalidate_model` runs the same folds for any model a caller fits (a ``fit_fold``
call-back): the geometry with effects of a discovery, for one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .engine import METHODS, identify
from .measurement import (FRAME_MODES, MeasurementSettings, checked_measured_inputs, identify_measured,
                          measurement_residuals)
from .metrics import pose_error_norms
from .noise import SensorNoise
from .prior import ParameterPrior
from .robot import KinematicsError, Robot
from .validation import frozen_array

__all__ = ["CrossValidation", "crossvalidate", "crossvalidate_model", "FIT_FAILURES", "fold_assignment", "error_summary", "DEFAULT_CHAINWISE_FOLDS",
           "SUMMARY_STATISTICS", "LOO_MAX_ROWS", "FEW_FOLDS_MIN_ROWS", "FEW_FOLDS", "default_folds"]

#: Folds of the chain-wise method's K-fold cross-validation when none are asked for.
DEFAULT_CHAINWISE_FOLDS = 10
#: Above this many rows the forward method's default is K-fold (:data:`DEFAULT_CHAINWISE_FOLDS`
#: folds), not leave-one-out: N refits of N rows each grow as N squared (a few seconds at 2,000
#: rows of the hexapod, ``benchmarks/crossval_speed.py``), and with so many rows a model fitted
#: to nine tenths of them predicts as one fitted to all but one (its own error, of order P / N of
#: the noise, is below the spread of the figure).
LOO_MAX_ROWS = 2000
#: Above this many rows the default cross-validation is :data:`FEW_FOLDS`-fold (module doc).
FEW_FOLDS_MIN_ROWS = 20000
#: The folds of a cross-validation of more than :data:`FEW_FOLDS_MIN_ROWS` rows.
FEW_FOLDS = 2
#: The statistics of a cross-validated error over the rows predicted, in the summary's order.
SUMMARY_STATISTICS = ("rms", "mean", "max")
#: What a fit may raise when the rows left to it cannot identify the model.
FIT_FAILURES = (ValueError, KinematicsError, np.linalg.LinAlgError)


@dataclass(frozen=True, eq=False)
class CrossValidation:
    """Each row's prediction error by a model fitted without it.

    Attributes:
        method: ``"forward"`` or ``"chainwise"`` (the identification cross-validated), or the
            name :func:`crossvalidate_model` was given.
        scheme: ``"leave-one-out"`` or ``"K-fold"`` (K the number of folds).
        folds: number of folds (N for leave-one-out).
        fits: fits run (one per fold).
        seed: seed of the fold assignment (unused by leave-one-out).
        fold_of_row: (N,) int, the fold of each row (0-based).
        residuals: (N, M) measured minus the prediction of the model fitted without the row (mm,
            rad; the instrument's coordinates with ``measurement``); NaN where there is none.
        position_error: (N,) mm, position error norm of each row (with targets: the RMS over the
            row's targets of each target's error norm); NaN where there is no prediction.
        orientation_error: (N,) rad, angle error norm of each row; None for a robot whose poses
            have no angles, or for target positions.
        position_summary, orientation_summary: ``{"rms", "mean", "max"}`` over the rows predicted
            (``rms`` the root mean square of the row norms); values None when no row was;
            ``orientation_summary`` None where ``orientation_error`` is.
        failed_folds: 0-based folds whose fit raised or whose model could not reach a left-out row.
        unconverged_folds: 0-based folds whose fit returned without meeting its stopping rule
            (their predictions are kept).
        success: every row has a prediction.
        message: the scheme, and what failed, in words.
    """

    method: str
    scheme: str
    folds: int
    fits: int
    seed: int
    fold_of_row: np.ndarray
    residuals: np.ndarray
    position_error: np.ndarray
    orientation_error: np.ndarray | None
    position_summary: dict
    orientation_summary: dict | None
    failed_folds: tuple
    unconverged_folds: tuple
    success: bool
    message: str

    @property
    def rows_predicted(self) -> int:
        return int(np.count_nonzero(np.isfinite(self.position_error)))

    def summary(self) -> dict:
        """JSON-ready: ``crossvalidated_position_error_mm`` and ``crossvalidated_orientation_error_rad``
        (``{"rms", "mean", "max"}``, the latter None without angles) and ``crossvalidation`` (method,
        scheme, folds, fits, seed, rows, rows predicted, failed and unconverged folds, message)."""
        return {"crossvalidated_position_error_mm": dict(self.position_summary),
                "crossvalidated_orientation_error_rad": None if self.orientation_summary is None
                else dict(self.orientation_summary),
                "crossvalidation": {"method": self.method, "scheme": self.scheme, "folds": self.folds,
                                    "fits": self.fits, "seed": self.seed, "rows": int(self.fold_of_row.size),
                                    "rows_predicted": self.rows_predicted,
                                    "failed_folds": list(self.failed_folds),
                                    "unconverged_folds": list(self.unconverged_folds), "message": self.message}}


def error_summary(values) -> dict:
    """``{"rms", "mean", "max"}`` of the finite entries of ``values`` (N,); None each when none is."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return dict.fromkeys(SUMMARY_STATISTICS)
    return {"rms": float(np.sqrt(np.mean(v ** 2))), "mean": float(v.mean()), "max": float(v.max())}


def fold_assignment(n: int, folds: int, seed: int = 0) -> np.ndarray:
    """(n,) int, the fold (0 .. folds - 1) of each of ``n`` rows: ``folds == n`` is leave-one-out
    (row j in fold j); else a seeded random permutation cut into ``folds`` near-equal parts.

    Raises:
        ValueError: ``folds`` not an integer in 2 .. n.
    """
    if int(folds) != folds or not 2 <= folds <= n:
        raise ValueError(f"folds must be an integer from 2 to the number of rows ({n}), got {folds!r}")
    folds = int(folds)
    if folds == n:
        return np.arange(n)
    out = np.empty(n, dtype=int)
    for k, rows in enumerate(np.array_split(np.random.default_rng(seed).permutation(n), folds)):
        out[rows] = k
    return out


def _checked(robot, joints, measured, noise, method, folds, prior, fit_kwargs, measurement, sessions):
    """The checked arguments: ``(joints (N, C), measured (N, M), folds, fit_kwargs dict, per (S,)
    settings or None, sessions (N,) int or None, why: the size switch of the default folds or "")``;
    the robot, noise, data, free names, start and
    sessions as :func:`calib.measurement.checked_measured_inputs` checks them."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if prior is not None and not isinstance(prior, ParameterPrior):
        raise TypeError(f"prior must be a calib.prior.ParameterPrior or None, got {type(prior).__name__}")
    if measurement is not None and method != "forward":
        raise ValueError("with an instrument frame or targets (measurement=) only the forward method is "
                         "fitted (calib.measurement.identify_measured)")
    if sessions is not None and measurement is None:
        raise ValueError("sessions= needs measurement= (the instrument frame of each session)")
    fit_kwargs = {} if fit_kwargs is None else dict(fit_kwargs)
    clash = sorted(set(fit_kwargs) & {"method", "prior", "frame", "targets", "initial_frame", "estimate_targets",
                                      "sessions"})
    if clash:
        raise ValueError(f"fit_kwargs must not set {', '.join(clash)}: pass them as crossvalidate's own arguments")
    first = MeasurementSettings(frame="base") if measurement is None else _first_settings(measurement)
    data = checked_measured_inputs(robot, joints, measured, noise, first.frame, first.targets,
                                   first.estimate_targets, fit_kwargs.get("free"), fit_kwargs.get("start"),
                                   sessions=sessions)
    n = data["joints"].shape[0]
    why = ""
    if folds is None:
        folds, why = default_folds(method, n)
    per = None if measurement is None else _session_settings(measurement, data["n_sessions"], sessions is not None)
    return (data["joints"], data["measured"], folds, fit_kwargs, per, None if sessions is None else data["sessions"],
            why)


def _first_settings(measurement) -> MeasurementSettings:
    """``measurement`` itself, or the first of a sequence of them (checked to be settings)."""
    if isinstance(measurement, MeasurementSettings):
        return measurement
    if isinstance(measurement, (list, tuple)) and measurement and \
            all(isinstance(m, MeasurementSettings) for m in measurement):
        return measurement[0]
    raise TypeError("measurement must be a calib.measurement.MeasurementSettings, a list of them (one a session) "
                    f"or None, got {type(measurement).__name__}")


def _session_settings(measurement, n_sessions: int, several: bool) -> list:
    """Each session's settings (S,): one for all, or one a session (frame mode and start frame of
    its own, the same targets).

    Raises:
        ValueError: a list without ``sessions=`` or not one a session, a frame mode not in
            :data:`~calib.measurement.FRAME_MODES`, or sessions whose targets differ.
    """
    if isinstance(measurement, MeasurementSettings):
        per = [measurement] * n_sessions
    elif not several:
        raise ValueError("a list of measurement settings (one a session) needs sessions=")
    elif len(measurement) != n_sessions:
        raise ValueError(f"measurement must be one MeasurementSettings or {n_sessions} (one a session), got "
                         f"{len(measurement)}")
    else:
        per = list(measurement)
    for s, ms in enumerate(per):
        if ms.frame not in FRAME_MODES:
            raise ValueError(f"measurement[{s}].frame must be one of {FRAME_MODES}, got {ms.frame!r}")
        same = (ms.targets is None) == (per[0].targets is None) and ms.estimate_targets == per[0].estimate_targets
        if not same or (ms.targets is not None and not np.array_equal(ms.targets, per[0].targets)):
            raise ValueError(f"measurement: session {s}'s targets differ from session 0's (one set of targets "
                             "serves every session)")
    return per


def _fold_model(robot, joints, measured, noise, method, prior, fit_kwargs, per, sessions):
    """``(predict, success, message)`` of the model fitted to the rows given: ``predict(joints,
    measured)`` (M rows) -> (M, W) predicted measurements, or with ``sessions`` (the given rows'
    (n,)) ``predict(joints, measured, sessions)``; raises what the fit raises."""
    if per is None:
        fit = identify(robot, joints, measured, noise, method=method, prior=prior, **fit_kwargs)
        theta = fit.theta

        def predict(q, m):
            return robot.forward_kinematics(theta, q, initial=m)

        return predict, fit.success, fit.message
    if sessions is None:
        ms = per[0]
        fit = identify_measured(robot, joints, measured, noise, frame=ms.frame, initial_frame=ms.initial_frame,
                                targets=ms.targets, estimate_targets=ms.estimate_targets, prior=prior, **fit_kwargs)

        def predict_instrument(q, m):
            return fit.predict(q, initial=fit.to_base(m) if fit.n_targets == 0 else None)

        return predict_instrument, fit.result.success, fit.result.message
    return _sessions_fold_model(robot, joints, measured, noise, prior, fit_kwargs, per, sessions)


def _sessions_fold_model(robot, joints, measured, noise, prior, fit_kwargs, per, sessions):
    """:func:`_fold_model` of rows from several sessions: one frame for each session with rows here
    (renumbered 0.. in order); ``predict(joints, measured, sessions)`` takes the sessions' own
    indices (each one with rows here)."""
    present = np.unique(sessions)
    renumber = np.full(len(per), -1)
    renumber[present] = np.arange(present.size)
    fit = identify_measured(robot, joints, measured, noise, frame=[per[s].frame for s in present],
                            initial_frame=[per[s].initial_frame for s in present], targets=per[0].targets,
                            estimate_targets=per[0].estimate_targets, prior=prior, sessions=renumber[sessions],
                            **fit_kwargs)

    def predict_sessions(q, m, s):
        own = renumber[s]
        return fit.predict(q, initial=fit.to_base(m, sessions=own) if fit.n_targets == 0 else None, sessions=own)

    return predict_sessions, fit.result.success, fit.result.message


def _predicted_rows(predict, joints, measured, sessions=None) -> np.ndarray:
    """(M, W) ``predict``'s measurements of the rows (with ``sessions`` (M,): their sessions passed
    on), row by row where the batch fails; NaN rows where the model cannot reach them."""
    def rows(sl):
        return (joints[sl], measured[sl]) if sessions is None else (joints[sl], measured[sl], sessions[sl])

    try:
        return predict(*rows(slice(None)))
    except KinematicsError:
        out = np.full(measured.shape, np.nan)
        for j in range(len(joints)):
            try:
                out[j] = predict(*rows(slice(j, j + 1)))[0]
            except KinematicsError:
                continue
        return out


def _row_errors(robot: Robot, residuals: np.ndarray, n_targets: int) -> tuple[np.ndarray, np.ndarray | None]:
    """``(position (N,), orientation (N,) or None)`` error norms of (N, W) residuals."""
    if n_targets:
        per_target = np.linalg.norm(residuals.reshape(len(residuals), n_targets, 3), axis=2)
        return np.sqrt(np.mean(per_target ** 2, axis=1)), None
    position, orientation = pose_error_norms(robot, residuals)
    return position, orientation if robot.angle_pose_mask.any() else None


def default_folds(method: str, n: int) -> tuple[int, str]:
    """``(folds, why)`` of a cross-validation of ``n`` rows when none are asked for: leave-one-out
    (``n``) for the forward method up to :data:`LOO_MAX_ROWS` rows, :data:`FEW_FOLDS` above
    :data:`FEW_FOLDS_MIN_ROWS` rows, else :data:`DEFAULT_CHAINWISE_FOLDS` (at most ``n``);
    ``why`` names the size switch made ("" where none was)."""
    if n > FEW_FOLDS_MIN_ROWS:
        return FEW_FOLDS, f"{n:,} rows > FEW_FOLDS_MIN_ROWS = {FEW_FOLDS_MIN_ROWS}"
    if method == "forward":
        return (n, "") if n <= LOO_MAX_ROWS else (min(DEFAULT_CHAINWISE_FOLDS, n),
                                                   f"{n:,} rows > LOO_MAX_ROWS = {LOO_MAX_ROWS}")
    return min(DEFAULT_CHAINWISE_FOLDS, n), ""


def crossvalidate(robot: Robot, joints, measured, noise: SensorNoise, *, method: str = "forward",
                  folds: int | None = None, prior: ParameterPrior | None = None, fit_kwargs: dict | None = None,
                  measurement=None, seed: int = 0, sessions=None) -> CrossValidation:
    """Cross-validated prediction error of an identification (see the module docstring).

    Args:
        robot: the robot.
        joints: (N, C) commanded (or read) joints of the calibration rows.
        measured: (N, D) measured poses (with ``measurement`` and targets: (N, 3K) positions), with
            ``sessions`` each row in its session's instrument frame.
        noise: declared noise (the fits' weights and verdicts).
        method: ``"forward"`` or ``"chainwise"``.
        folds: number of folds, 2 .. N; default (:func:`default_folds`) N (leave-one-out) for the
            forward method up to :data:`LOO_MAX_ROWS` rows, :data:`FEW_FOLDS` above
            :data:`FEW_FOLDS_MIN_ROWS`, else :data:`DEFAULT_CHAINWISE_FOLDS` (at most N); the
            scheme names the switch where one was made.
        prior: a :class:`~calib.prior.ParameterPrior` given to every fit (maximum a posteriori), or None.
        fit_kwargs: options of every fit, as :func:`calib.engine.identify` (``free``, ``start``,
            ``solver``, ``weighted``, ``epsilon``, ...) or, with ``measurement``,
            :func:`calib.measurement.identify_measured` takes them.
        measurement: the recording's instrument settings when its fit estimates a frame or target
            offsets (forward method): a :class:`~calib.measurement.MeasurementSettings` (every
            session's), or with ``sessions`` a list of S of them, each session's frame mode and
            start frame (one set of targets: theirs must agree); None: poses in the base frame.
        seed: seed of the K-fold assignment.
        sessions: (N,) int, each row's session 0..S-1 (every one with rows), each session in its
            own instrument frame (needs ``measurement``); None: one session.

    Returns:
        A :class:`CrossValidation`, also when folds fail (their rows NaN, named in the message).

    Raises:
        TypeError, ValueError: bad arguments (naming them); not a fold that fails.
    """
    joints, measured, folds, fit_kwargs, per, sessions, why = _checked(robot, joints, measured, noise, method, folds,
                                                                       prior, fit_kwargs, measurement, sessions)

    def fit_fold(train: np.ndarray):
        return _fold_model(robot, joints[train], measured[train], noise, method, prior, fit_kwargs, per,
                           None if sessions is None else sessions[train])

    return crossvalidate_model(robot, joints, measured, fit_fold, folds=folds, seed=seed, method=method,
                               n_targets=0 if per is None else per[0].n_targets, sessions=sessions, why=why)


def crossvalidate_model(robot: Robot, joints, measured, fit_fold, *, folds: int, seed: int = 0,
                        method: str = "model", n_targets: int = 0, sessions=None, why: str = "") -> CrossValidation:
    """Cross-validated prediction error of any model fitted to rows (what :func:`crossvalidate` runs
    for the engine's fits; a caller with another model, e.g. the geometry and the effects of
    :mod:`calib.effects.discovery`, passes its own ``fit_fold``).

    Args:
        robot: the robot (which pose coordinates are angles).
        joints: (N, C) joints; measured: (N, W) measurements (poses, or 3 ``n_targets`` positions).
        fit_fold: ``fit_fold(train (N,) bool) -> (predict, success, message)``, the model fitted to
            the rows ``train`` marks; ``predict(joints (M, C), measured (M, W)) -> (M, W)`` its
            prediction of rows (``measured`` only as the start of a forward kinematics), raising
            :class:`~calib.robot.KinematicsError` where it cannot reach one. A ``fit_fold`` that
            raises one of :data:`FIT_FAILURES` fails its fold.
        folds, seed: as :func:`fold_assignment`.
        method: the model's name in the result and its message.
        n_targets: K when the measurements are target positions (position error: the RMS over
            the row's targets), else 0.
        sessions: (N,) int, each row's session (a model with a frame for each), or None. With
            them ``predict(joints, measured, sessions (M,))`` is given the rows' sessions, and only
            rows whose session kept training rows in their fold (the others: NaN, named).
        why: why this scheme (a size switch), appended to ``scheme`` in parentheses; "" none.
    """
    joints, measured = np.asarray(joints, dtype=float), np.asarray(measured, dtype=float)
    n = joints.shape[0]
    sessions = None if sessions is None else np.asarray(sessions, dtype=int)
    fold_of_row = fold_assignment(n, folds, seed)
    fold_of_row.setflags(write=False)
    residuals, failed, unconverged = _run_folds(robot, joints, measured, fold_of_row, folds, fit_fold, n_targets,
                                                sessions)
    position, orientation = _row_errors(robot, residuals, n_targets)
    scheme = ("leave-one-out" if folds == n else f"{folds}-fold") + (f" ({why})" if why else "")
    message = _message(method, scheme, folds, n, int(np.count_nonzero(np.isfinite(position))), seed, failed,
                       unconverged, 1 if sessions is None else int(np.unique(sessions).size))
    return CrossValidation(
        method=method, scheme=scheme, folds=folds, fits=folds, seed=int(seed), fold_of_row=fold_of_row,
        residuals=frozen_array(residuals), position_error=frozen_array(position),
        orientation_error=None if orientation is None else frozen_array(orientation),
        position_summary=error_summary(position),
        orientation_summary=None if orientation is None else error_summary(orientation),
        failed_folds=tuple(sorted(failed)), unconverged_folds=tuple(sorted(unconverged)),
        success=bool(np.all(np.isfinite(position))), message=message)


def _run_folds(robot, joints, measured, fold_of_row, folds, fit_fold, n_targets, sessions=None):
    """Fit each fold's complement and predict the fold (with ``sessions``: the left-out rows of the
    sessions that kept training rows): ``(residuals (N, W) measured - predicted, NaN where none;
    failed {fold: why}; unconverged {fold: the fit's stop message})``."""
    residuals = np.full(measured.shape, np.nan)
    failed, unconverged = {}, {}
    for k in range(folds):
        test = fold_of_row == k
        try:
            predict, ok, msg = fit_fold(~test)
        except FIT_FAILURES as exc:
            failed[k] = f"the fit failed: {exc}"
            continue
        if not ok:
            unconverged[k] = msg.split(";")[0]
        lost = np.zeros_like(test) if sessions is None else test & ~np.isin(sessions, sessions[~test])
        ask = test & ~lost
        predicted = _predicted_rows(predict, joints[ask], measured[ask], None if sessions is None else sessions[ask])
        residuals[ask] = measurement_residuals(robot, measured[ask], predicted, n_targets)
        why = [_lost_words(sessions[lost])] if lost.any() else []
        unreached = int(np.count_nonzero(~np.all(np.isfinite(predicted), axis=1)))
        if unreached:
            why.append(f"its model cannot reach {unreached} of its {int(test.sum())} left-out rows")
        if why:
            failed[k] = "; ".join(why)
    return residuals, failed, unconverged


def _lost_words(lost_sessions: np.ndarray) -> str:
    """Why left-out rows of sessions without training rows have no prediction, in words."""
    gone = np.unique(lost_sessions)
    which = ", ".join(str(int(s)) for s in gone)
    return (f"session{'s' if gone.size > 1 else ''} {which} kept no training row (no instrument frame fitted): "
            f"its {lost_sessions.size} left-out row(s) cannot be predicted")


#: Folds whose reason a message spells out; the others are counted.
REASONS_SPELLED_OUT = 3


def _message(method: str, scheme: str, folds: int, n: int, predicted: int, seed: int, failed: dict,
             unconverged: dict, n_sessions: int = 1) -> str:
    """The cross-validation in words: which it is, which folds failed or did not converge (1-based)."""
    if folds == n:
        how = f"each of the {n} rows predicted by the {method} model fitted without it ({n} fits)"
    else:
        how = (f"the {n} rows split at random (seed {seed}) into {folds} folds, each predicted by the "
               f"{method} model fitted to the others ({folds} fits)")
    if n_sessions > 1:
        how += f"; {n_sessions} sessions, each row predicted in its own session's instrument frame"
    parts = [f"{scheme} cross-validation: {how}; measured minus prediction, includes sensor noise"]
    if predicted < n:
        parts.append(f"{n - predicted} of {n} rows without a prediction")
    for what, folds_with in (("failed", failed), ("stopped without meeting its stopping rule (kept)", unconverged)):
        if folds_with:
            ks = sorted(folds_with)
            spelled = "; ".join(f"fold {k + 1}: {folds_with[k]}" for k in ks[:REASONS_SPELLED_OUT])
            more = f"; and {len(ks) - REASONS_SPELLED_OUT} more" if len(ks) > REASONS_SPELLED_OUT else ""
            parts.append(f"{len(ks)} of {folds} fold fits {what}: {spelled}{more}")
    return "; ".join(parts)
