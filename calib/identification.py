"""The identification policy: from measured rows to a :class:`~calib.calibration.Calibration` and
its verdict, in one call (:func:`calibrate`).

The steps, in order (each a function of this module; :func:`calibrate` checks the arguments once
and runs them):

1. **Gross rows** (:func:`gross_row_search`): the rows no consistent fit explains are named before
   anything is fitted to them (:func:`calib.robust.find_gross_rows`: trimmed fits, each frame
   group in its own instrument frame, the frame inferred from the rows it makes consistent); they
   are left out of every fit unless ``keep_outliers``.
2. **Frames and fit** (:func:`first_fit`): on the rows kept, the geometry with the instrument
   frame(s) and target offsets where the measurement needs them
   (:func:`calib.measurement.identify_measured`, one geometry and a frame per frame group), else
   the chosen identification of base-frame poses (:func:`calib.engine.identify`).
3. **Tolerance** (:func:`learn_tolerance`): the tolerance the rows support
   (:func:`calib.evidence.tolerance_from_data`); where none was declared and the rows show the
   default too tight, the learnt one becomes the prior and the fit of step 2 is made again.
4. **Outliers** (:func:`identify_rows`): the closed-form leave-one-out test
   (:func:`calib.outliers.find_outliers`, forward model, poses in the base frame) on the rows
   kept; without an instrument fit the geometry is fitted again without the rows it flags (both
   fits kept for the comparison).
5. **Held-out errors** (:func:`validation_errors`): the validation rows predicted by the nominal
   and the identified model (in their instrument frame where one was fitted), or the errors a
   caller measures itself (``heldout``: a simulated machine commanded with the compensation).
6. **Cross-validation** (:func:`crossvalidation_of`) where nothing is held out.
7. **Verdict** (:func:`verdict_of`): a success only where the fit converged, its rows fit within
   the declared noise and the rows it did not use are predicted as well as it says they can be;
   otherwise the likely cause with its evidence.
8. **Calibration** (:func:`calibration_of`): geometry with covariance, instrument frames,
   targets, validity domain, declared noise.

Units: mm and rad (the robot's pose and joint units). Rows are numbered as the caller gives them
(``rows``, ``validation_rows``: 0-based; a message names row ``r`` as ``r + 1``). Nothing here
reads or writes a file, simulates a machine or draws.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable, Mapping, Sequence

import numpy as np

from . import paper
from .calibration import Calibration, validity_domain
from .crossval import CrossValidation, crossvalidate
from .diagnosis import chi2_limit
from .engine import METHODS, IdentificationResult, identify
from .evidence import MIN_DETERMINED, ToleranceEstimate, tolerance_from_data
from .measurement import (MeasuredFit, MeasurementSettings, identify_as_measured, identify_measured,
                          instrument_measurements, measurement_residuals)
from .noise import SensorNoise
from . import outliers
from .outliers import OutlierReport, find_outliers
from .prior import ParameterPrior
from .robot import KinematicsError, Robot, chain_jacobian_factors, pose_jacobian_of_parameters
from .robust import GrossRowResult, find_gross_rows
from .validation import as_array

__all__ = ["calibrate", "calibrate_checked", "checked_arguments", "checked_data", "checked_options",
           "CalibrationOutcome", "CalibrationData", "IdentificationOptions", "Identification",
           "Verdict", "VerdictEvidence", "PredictionCheck", "NoMotion", "NoInformation", "DescriptionPattern", "NoConvergence",
           "GrossSearch", "Misprediction", "SessionSearch", "UnreachableRows", "BASE_FRAME", "INSTRUMENT_FOLDS",
           "SOLVERS", "PRODUCED_BY", "VERDICT_CAUSES", "DIAGNOSED_CAUSES",
           "identify_rows", "gross_row_search", "first_fit", "learn_tolerance", "validation_errors", "instrument_heldout",
           "crossvalidation_of", "crossvalidation_settings", "prediction_check", "verdict_of", "information_verdict",
           "description_verdict", "likely_cause", "calibration_of", "instrument_frames"]

#: The recording diagnosis' causes a failed :class:`Verdict` adopts (the diagnosis says them).
DIAGNOSED_CAUSES = ("conversion", "unmeasured column")
#: Every cause of a failed :class:`Verdict`: its own, then the diagnosis' it adopts.
VERDICT_CAUSES = ("no_motion", "no_information", "description", "no_convergence", "gross_search_failed",
                  "model_misfit", "unpredictable_rows", "left_out_physics") + DIAGNOSED_CAUSES
#: A validation row's frame group when it is predicted in the base frame (a session without
#: calibration rows declared in the base frame).
BASE_FRAME = -1
#: Folds of the cross-validation of an instrument-frame fit (each fold refits geometry and frame).
INSTRUMENT_FOLDS = 10
#: The solvers a caller may name (default: Gauss-Newton for the chain-wise method, Levenberg-Marquardt
#: for the forward one).
SOLVERS = ("gn", "lm")
#: The ``produced_by`` of a calibration this module makes (a command that writes it says its own).
PRODUCED_BY = "calib.identification.calibrate"


class UnreachableRows(ValueError):
    """The model cannot reach a row's joints.

    Attributes:
        kinematics: the :class:`~calib.robot.KinematicsError` (its ``index`` into the rows the model
            was given).
        rows: (n,) int, those rows' numbers as the caller gave them (0-based).
        what: which rows, and what it means, in words.
        where: how the caller names its data.
    """

    def __init__(self, kinematics: KinematicsError, rows, what: str, where: str):
        self.kinematics, self.rows, self.what, self.where = kinematics, np.asarray(rows), what, where
        index = getattr(kinematics, "index", None)
        at = f"row {int(self.rows[index]) + 1}: " if index is not None and 0 <= index < len(self.rows) else ""
        super().__init__(f"{where}: {at}{kinematics} ({what})")


@dataclass(frozen=True, eq=False)
class CalibrationData:
    """The checked data of :func:`calibrate` (the back end trusts it): N calibration rows, M
    validation rows, S frame groups.

    Attributes:
        robot, noise: the robot and the declared noise.
        joints: (N, C) calibration joints (the robot's joint unit).
        measured: (N, W) what the instrument measured: poses (W = D, mm and rad) or the positions
            of K targets (W = 3K, mm), in the frame group's instrument frame.
        rows: (N,) int, each calibration row's number in the caller's data (0-based).
        t_s: (N,) each calibration row's time, s.
        measurement: (S,) how each frame group was measured, or None: poses in the base frame
            (no instrument fit).
        sessions: (N,) int, each calibration row's frame group 0..S-1.
        session_names: (S,) each frame group's name.
        session_frames: ``{session name: frame group}`` of every session the calibration names a
            frame for (a session captured in another's frame too; :data:`BASE_FRAME`: none).
        validation_joints: (M, C); validation_measured: (M, W); validation_sessions: (M,) int, each
            validation row's frame group (or :data:`BASE_FRAME`); validation_rows: (M,) their numbers.
        tolerance: (P,) each parameter's tolerance as a prior (one standard deviation): the
            yardstick of the verdicts, and the prior unless ``prior`` is None; after
            :func:`learn_tolerance` the one the run used.
        prior: ``tolerance`` when the fits are maximum a posteriori, else None (plain least squares).
        tolerance_declared: the caller declared ``tolerance`` (else the robot's default).
        tolerance_source: where the tolerance came from, in words (what :func:`learn_tolerance` found added).
        tolerance_estimate: the tolerance the rows support (None before :func:`learn_tolerance` or
            without a prior).
        where: how messages name the data.
        geometry_source: where the nominal geometry is described (named by a verdict that finds it
            another machine's), or None.
    """

    robot: Robot
    noise: SensorNoise
    joints: np.ndarray
    measured: np.ndarray
    rows: np.ndarray
    t_s: np.ndarray
    measurement: tuple | None
    sessions: np.ndarray
    session_names: tuple
    session_frames: dict
    validation_joints: np.ndarray
    validation_measured: np.ndarray
    validation_sessions: np.ndarray
    validation_rows: np.ndarray
    tolerance: ParameterPrior
    prior: ParameterPrior | None
    tolerance_declared: bool
    tolerance_source: str
    tolerance_estimate: ToleranceEstimate | None = None
    where: str = "the calibration rows"
    geometry_source: str | None = None

    @property
    def n_sessions(self) -> int:
        """S, the instrument frames fitted (1 for poses in the base frame)."""
        return 1 if self.measurement is None else len(self.session_names)

    def measurement_of(self, s: int = 0) -> MeasurementSettings:
        """How frame group ``s`` was measured (base-frame poses where ``measurement`` is None)."""
        return MeasurementSettings(frame="base") if self.measurement is None else self.measurement[s]


@dataclass(frozen=True)
class IdentificationOptions:
    """How :func:`calibrate` identifies (see its arguments)."""

    method: str = "chainwise"
    solver: str | None = None
    weighted: bool = False
    keep_outliers: bool = False
    search_gross_rows: bool = True
    cross_validate: bool = True
    seed: int = 0


@dataclass
class Identification:
    """What the identification steps found (indices are 0-based into the calibration rows).

    Attributes:
        result: the fit used (without the flagged rows where they were left out).
        result_all: the fit of every row kept by the gross-row stage; result_kept: the fit without
            the rows the leave-one-out test flags (None where none was flagged or with an instrument fit).
        solver: ``"gn"`` or ``"lm"``.
        report: the leave-one-out test (:class:`calib.outliers.OutlierReport`), or None where it
            could not run; outlier_verdict: its verdict in words (or why it did not run).
        flagged_idx: the rows named, gross or flagged, ascending.
        keep: the rows kept by both tests; kept: the rows kept by the gross-row stage.
        left_out: the flagged rows were left out of ``result``.
        used: the rows ``result`` was fitted to.
        instrument: the instrument fit (:class:`calib.measurement.MeasuredFit`), or None: base-frame poses.
        measured: (N, D) the calibration poses in the base frame (the instrument frame taken out).
        gross: the gross-row search (:class:`calib.robust.GrossRowResult` or
            :class:`SessionSearch`), or None where it did not run; gross_idx: the gross rows.
    """

    result: IdentificationResult
    result_all: IdentificationResult
    result_kept: IdentificationResult | None
    solver: str
    report: OutlierReport | None
    outlier_verdict: str
    flagged_idx: list
    keep: np.ndarray
    left_out: bool
    used: np.ndarray
    instrument: MeasuredFit | None
    measured: np.ndarray
    gross: GrossRowResult | SessionSearch | None = None
    gross_idx: list = field(default_factory=list)
    kept: np.ndarray | None = None


@dataclass(frozen=True)
class PredictionCheck:
    """Whether the predictions of rows the fit did not use agree with what the fit says they can be
    (:func:`prediction_check`).

    Attributes:
        what: the rows predicted: ``"validation rows"`` or ``"cross-validation (<scheme>)"``.
        agrees: their whitened chi-square is within its limit.
        ratio: their RMS whitened residual, or None where no row could be predicted.
        rows: the rows predicted.
        limit_ratio: the ratio's limit (chi-square at :data:`calib.diagnosis.FIT_ALPHA`); None
            where no row could be predicted.
        factored_rows: the base-frame rows whose ``J Sigma J^T`` was taken through the Jacobian's
            chain factors (above :data:`calib.outliers.STRUCTURED_JACOBIAN_MIN_ROWS`), or None
            where it was formed densely.
    """

    what: str
    agrees: bool
    ratio: float | None
    rows: int
    limit_ratio: float | None = None
    factored_rows: int | None = None

    def to_dict(self) -> dict:
        """The figures under the names the summary JSON gives them (``limit_ratio`` where there is
        one; ``form`` where the factored form ran)."""
        out = {"what": self.what, "agrees": self.agrees, "ratio": self.ratio}
        if self.limit_ratio is not None:
            out["limit_ratio"] = self.limit_ratio
        out["rows"] = self.rows
        if self.factored_rows is not None:
            out["form"] = (f"J Sigma J^T through the Jacobian's chain factors ({self.factored_rows:,} rows > "
                           f"STRUCTURED_JACOBIAN_MIN_ROWS = {outliers.STRUCTURED_JACOBIAN_MIN_ROWS})")
        return out


@dataclass(frozen=True)
class VerdictEvidence:
    """The figures every verdict rests on (the summary's ``verdict.evidence``: :meth:`to_dict`).

    Attributes:
        converged: the fit converged.
        fit_ratio: the fit's RMS whitened residual (the rows' misfit over the declared noise).
        fit_limit_ratio: its limit (chi-square at :data:`calib.diagnosis.FIT_ALPHA`).
        fit_at_noise: the fit is within that limit.
        predictions: :func:`prediction_check` of rows the fit did not use, or None.
    """

    converged: bool
    fit_ratio: float
    fit_limit_ratio: float
    fit_at_noise: bool
    predictions: PredictionCheck | None

    def to_dict(self) -> dict:
        """The figures under the names the summary JSON gives them."""
        return {"converged": self.converged, "fit_ratio": self.fit_ratio, "fit_limit_ratio": self.fit_limit_ratio,
                "fit_at_noise": self.fit_at_noise,
                "predictions": None if self.predictions is None else self.predictions.to_dict()}


@dataclass(frozen=True)
class NoMotion:
    """Cause ``"no_motion"``: every calibration row used is at one pose (:func:`calib.diagnosis.motionless_rows`).
    ``rows``: how many; ``robot``: the robot's name."""

    rows: int
    robot: str


@dataclass(frozen=True)
class NoInformation:
    """Cause ``"no_information"``: the rows determine nothing beyond the tolerance.

    Attributes:
        free: the parameters not held.
        determined: the directions the rows determine, singly or in combinations.
        same_pose_rows: rows at one pose (:func:`calib.diagnosis.same_pose_rows`), of ``rows``.
        noise: the declared pose noise's first standard deviation, in ``noise_unit``.
        tolerances: ``(median tolerance, unit)`` of the free parameters, one per unit.
    """

    free: int
    determined: float
    same_pose_rows: int
    rows: int
    noise: float
    noise_unit: str
    tolerances: tuple


@dataclass(frozen=True)
class DescriptionPattern:
    """Cause ``"description"``: the fitted errors are a scale of the nominal geometry described.
    ``patterns``: :func:`calib.diagnosis.description_pattern`'s groups; ``geometry_source``: the
    description's file, or None."""

    patterns: tuple
    geometry_source: str | None


@dataclass(frozen=True)
class NoConvergence:
    """Cause ``"no_convergence"``: the solver's own ``message``."""

    message: str


@dataclass(frozen=True)
class GrossSearch:
    """Causes ``"gross_search_failed"`` and ``"model_misfit"``: the gross-row search could not judge.

    Attributes:
        message: the search's own reason.
        beyond: rows beyond the declared noise after the trimmed fits, of ``rows`` searched.
        where: the recording (``CalibrationData.where``).
    """

    message: str
    beyond: int
    rows: int
    where: str


@dataclass(frozen=True)
class Misprediction:
    """Causes ``"unpredictable_rows"`` and ``"left_out_physics"``: rows off the model.

    Attributes:
        what: the rows off (``"calibration rows"``, or the prediction check's ``what``).
        ratio: their RMS whitened residual (None: the model cannot predict them at all).
        where: the recording (``CalibrationData.where``).
    """

    what: str
    ratio: float | None
    where: str


@dataclass(frozen=True)
class Verdict:
    """Whether the calibration is a success, and if not its likely cause: a code and typed
    evidence, no sentence (the words, one table per cause, are pipeline's:
    :mod:`pipeline.report.verdict_words`).

    Attributes:
        success: the fit converged, its rows fit within the declared noise and the predictions of
            rows it did not use agree with what it says they can be (and the rows determine
            something, and the errors are not a description's pattern).
        cause: None on success, else one of :data:`VERDICT_CAUSES`: ``"no_motion"``,
            ``"no_information"``, ``"description"``, ``"no_convergence"``,
            ``"gross_search_failed"``, ``"model_misfit"``, ``"unpredictable_rows"``,
            ``"left_out_physics"``, or the diagnosis' cause (``"conversion"``, ``"unmeasured column"``).
        evidence: the :class:`VerdictEvidence` every verdict rests on.
        detail: the cause's own evidence: :class:`NoMotion`, :class:`NoInformation`,
            :class:`DescriptionPattern`, :class:`NoConvergence`, :class:`GrossSearch` (both its
            causes), :class:`Misprediction` (both its causes); None on success and for the
            diagnosis' causes (the diagnosis says them).
        diagnosis: the recording's diagnosis given to :func:`calibrate`, or None.
    """

    success: bool
    cause: str | None
    evidence: VerdictEvidence
    detail: object | None = None
    diagnosis: object | None = None


@dataclass(frozen=True, eq=False)
class CalibrationOutcome:
    """What :func:`calibrate` found, returned also when the verdict is a failure.

    Attributes:
        calibration: the :class:`~calib.calibration.Calibration` (``produced_by`` :data:`PRODUCED_BY`;
            no recording named); None with ``assess=False``.
        identification: the fits, gross and flagged rows, instrument fit (:class:`Identification`).
        data: the data as the run used them (:class:`CalibrationData`: the tolerance learnt, its source).
        heldout: ``(before, after)`` (M, W) held-out errors of the fit used (measured minus
            predicted for validation rows, with their frame group's frame; or what ``heldout``
            returned), or None.
        heldout_with_flagged, heldout_without_flagged: the same of ``result_all`` and ``result_kept``
            where both were fitted (else None).
        crossvalidation: the cross-validated prediction error where nothing was held out
            (:class:`calib.crossval.CrossValidation`), or None.
        verdict: the :class:`Verdict` (None with ``assess=False``).
        warnings: what the caller should be told, in words.
        seconds: wall time of the steps, s: ``identify`` (steps 1-4), ``gross_rows``,
            ``outlier_test``, ``heldout``, ``crossvalidation`` (where run), ``verdict``.
    """

    calibration: Calibration | None
    identification: Identification
    data: CalibrationData
    heldout: tuple | None
    heldout_with_flagged: tuple | None
    heldout_without_flagged: tuple | None
    crossvalidation: CrossValidation | None
    verdict: Verdict | None
    warnings: tuple
    seconds: dict

    @property
    def result(self) -> IdentificationResult:
        """The fit used (:attr:`Identification.result`)."""
        return self.identification.result


# --------------------------------------------------------------------------- front end


def calibrate(robot: Robot, joints, measured, noise: SensorNoise, *, measurement=None, sessions=None,
              session_names: Sequence[str] | None = None, session_frames: Mapping[str, int] | None = None,
              validation_joints=None, validation_measured=None, validation_sessions=None, validation_rows=None,
              heldout: Callable | None = None, tolerance: ParameterPrior | None = None,
              tolerance_declared: bool | None = None, tolerance_source: str | None = None, prior: bool = True,
              method: str = "chainwise", solver: str | None = None, weighted: bool = False,
              keep_outliers: bool = False, search_gross_rows: bool = True, cross_validate: bool = True,
              assess: bool = True, rows=None, t_s=None, diagnosis=None, where: str = "the calibration rows",
              geometry_source: str | None = None, seed: int = 0) -> CalibrationOutcome:
    """Calibrate ``robot`` from measured rows: gross rows, instrument frames, fit, learnt
    tolerance, outlier test, held-out errors or cross-validation, verdict (module docstring).

    Args:
        robot: the robot (its nominal geometry starts every fit).
        joints: (N, C) the calibration rows' joints (commanded or read), the robot's joint unit.
        measured: (N, D) measured poses (mm, rad) or, with targets in ``measurement``, (N, 3K)
            target positions (mm), each row in its frame group's instrument frame.
        noise: the declared noise (weights, tests, verdict).
        measurement: how the rows were measured: a :class:`~calib.measurement.MeasurementSettings`
            (one frame group) or a sequence of S of them (one per frame group: its frame mode and
            start; the targets the first's); None: poses in the base frame, fitted by ``method``
            (no instrument fit).
        sessions: (N,) int, each row's frame group 0..S-1, every group with rows (needs
            ``measurement``); None: one group.
        session_names: (S,) the frame groups' names (default ``"1"``, ``"2"``, ...).
        session_frames: ``{session name: frame group}`` of the sessions whose frame the
            calibration gives (a session captured in another's frame too; :data:`BASE_FRAME`:
            none); default each name of ``session_names`` its own group.
        validation_joints, validation_measured: (M, C) and (M, W) validation rows, measured as
            the calibration rows (None: none).
        validation_sessions: (M,) int, each validation row's frame group, or :data:`BASE_FRAME`
            for rows measured in the base frame (default: group 0).
        validation_rows: (M,) int, their numbers in the caller's data (default M after the
            calibration rows' last).
        heldout: ``heldout(theta (P,)) -> (before, after)``, the (M, D) held-out errors of the
            model ``theta`` the caller measures itself (a simulated machine commanded with the
            compensation: noise-free, no prediction check); not with validation rows.
        tolerance: each parameter's tolerance (:class:`~calib.prior.ParameterPrior`); default the
            robot's (:meth:`ParameterPrior.default`).
        tolerance_declared: the tolerance is the machine's declared one (kept, and checked against
            the rows); default: whether ``tolerance`` is given.
        tolerance_source: where the tolerance came from, in words (default: said from the above).
        prior: fit maximum a posteriori under the tolerance (False: plain least squares; the
            tolerance stays the verdicts' yardstick).
        method: ``"chainwise"`` or ``"forward"`` (:func:`calib.engine.identify`; an instrument fit is
            always forward).
        solver: one of :data:`SOLVERS`, or None: ``"gn"`` for chainwise, ``"lm"`` for forward.
        weighted: chainwise: weight the closure residuals by the declared noise.
        keep_outliers: name the gross and flagged rows but fit every row.
        search_gross_rows: run the gross-row search (False: every row is fitted; data known clean,
            e.g. simulated).
        cross_validate: cross-validate where nothing is held out.
        assess: False: stop after the identification (steps 1-4): no held-out errors,
            cross-validation, verdict or calibration (those fields None).
        rows: (N,) int, the calibration rows' numbers in the caller's data, 0-based (default 0..N-1).
        t_s: (N,) their times, s (the calibration's validity span; default 0).
        diagnosis: the data's diagnosis made before any fit (:func:`calib.diagnosis.diagnose`), or
            None: its cause (a conversion, an unmeasured column) becomes a failed verdict's.
        where: how messages name the data (a file name).
        geometry_source: where the nominal geometry is described, or None (named by the verdict
            that finds the errors a description's pattern).
        seed: seed of the gross-row search and of the cross-validation's folds.

    Returns:
        A :class:`CalibrationOutcome`, also when the verdict is a failure.

    Raises:
        TypeError: ``robot``, ``noise``, ``measurement``, ``tolerance`` or ``heldout`` of the wrong type.
        ValueError: a bad argument (named), or rows that cannot be calibrated (too few, unusable:
            the message says why; :class:`UnreachableRows` where the model cannot reach a row).
    """
    data, options = checked_arguments(
        robot, joints, measured, noise, measurement=measurement, sessions=sessions, session_names=session_names,
        session_frames=session_frames, validation_joints=validation_joints, validation_measured=validation_measured,
        validation_sessions=validation_sessions, validation_rows=validation_rows, heldout=heldout,
        tolerance=tolerance, tolerance_declared=tolerance_declared, tolerance_source=tolerance_source, prior=prior,
        method=method, solver=solver, weighted=weighted, keep_outliers=keep_outliers,
        search_gross_rows=search_gross_rows, cross_validate=cross_validate, rows=rows, t_s=t_s, where=where,
        geometry_source=geometry_source, seed=seed)
    return calibrate_checked(data, options, heldout=heldout, diagnosis=diagnosis, assess=assess)


def calibrate_checked(data: CalibrationData, options: IdentificationOptions, *, heldout: Callable | None = None,
                      diagnosis=None, assess: bool = True) -> CalibrationOutcome:
    """:func:`calibrate`'s back end: trusts its input, ``data`` and ``options`` as
    :func:`checked_arguments` (or :func:`checked_data` and :func:`checked_options`) returns them
    (``heldout``, ``diagnosis``, ``assess`` as :func:`calibrate` takes them)."""
    warnings: list[str] = []
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    ident, data = identify_rows(data, options, warnings, seconds)
    seconds["identify"] = time.perf_counter() - t0
    if not assess:
        return CalibrationOutcome(calibration=None, identification=ident, data=data, heldout=None,
                                  heldout_with_flagged=None, heldout_without_flagged=None, crossvalidation=None,
                                  verdict=None, warnings=tuple(warnings), seconds=seconds)
    return assessed(data, ident, options, heldout, diagnosis, warnings, seconds)


def assessed(data: CalibrationData, ident: Identification, options: IdentificationOptions, heldout: Callable | None,
             diagnosis, warnings: list, seconds: dict) -> CalibrationOutcome:
    """:func:`calibrate`'s steps after the identification: the held-out errors (of the fit used, and
    of the fits with and without the flagged rows), the cross-validation where nothing is held out,
    the verdict and the calibration; ``seconds`` gets each step's wall time."""
    t1 = time.perf_counter()
    errors = heldout if heldout is not None else (lambda theta: validation_errors(data, ident, theta))
    held = errors(ident.result.theta)
    with_flagged = without_flagged = None
    if ident.result_kept is not None:
        other = ident.result_all if ident.left_out else ident.result_kept
        by_fit = {id(ident.result): held, id(other): errors(other.theta)}
        with_flagged, without_flagged = by_fit[id(ident.result_all)], by_fit[id(ident.result_kept)]
    seconds["heldout"] = time.perf_counter() - t1
    cv = None
    if options.cross_validate and held is None:
        t_cv = time.perf_counter()
        cv = crossvalidation_of(data, ident, options)
        seconds["crossvalidation"] = time.perf_counter() - t_cv
    t_v = time.perf_counter()
    verdict = verdict_of(data, ident, held if heldout is None else None, cv, diagnosis)
    seconds["verdict"] = time.perf_counter() - t_v
    return CalibrationOutcome(calibration=calibration_of(data, ident), identification=ident, data=data, heldout=held,
                              heldout_with_flagged=with_flagged, heldout_without_flagged=without_flagged,
                              crossvalidation=cv, verdict=verdict, warnings=tuple(warnings), seconds=seconds)


def _int_array(value, name: str, n: int) -> np.ndarray:
    a = as_array(value, name, (n,))
    if not np.all(a == np.round(a)):
        raise ValueError(f"{name} must hold integers, got {a[a != np.round(a)][0]!r}")
    return a.astype(int)


def checked_arguments(robot, joints, measured, noise, *, measurement, sessions, session_names, session_frames,
                      validation_joints, validation_measured, validation_sessions, validation_rows, heldout,
                      tolerance, tolerance_declared, tolerance_source, prior, method, solver, weighted,
                      keep_outliers, search_gross_rows, cross_validate, rows, t_s, where, geometry_source,
                      seed) -> tuple[CalibrationData, IdentificationOptions]:
    """The arguments of :func:`calibrate`, checked, as its back end takes them: the scalars first (in
    the signature's order), then :func:`checked_data` and :func:`checked_options`.

    Raises:
        TypeError, ValueError: naming the argument that is wrong.
    """
    _check_types(robot, noise)
    _check_method(method, solver)
    _check_heldout(heldout)
    _check_seed(seed)
    _check_where(where)
    data = checked_data(robot, joints, measured, noise, measurement=measurement, sessions=sessions,
                        session_names=session_names, session_frames=session_frames,
                        validation_joints=validation_joints, validation_measured=validation_measured,
                        validation_sessions=validation_sessions, validation_rows=validation_rows, heldout=heldout,
                        tolerance=tolerance, tolerance_declared=tolerance_declared,
                        tolerance_source=tolerance_source, prior=prior, rows=rows, t_s=t_s, where=where,
                        geometry_source=geometry_source)
    options = checked_options(method=method, solver=solver, weighted=weighted, keep_outliers=keep_outliers,
                              search_gross_rows=search_gross_rows, cross_validate=cross_validate, seed=seed)
    return data, options


def checked_data(robot, joints, measured, noise, *, measurement=None, sessions=None, session_names=None,
                 session_frames=None, validation_joints=None, validation_measured=None, validation_sessions=None,
                 validation_rows=None, heldout: Callable | None = None, tolerance=None, tolerance_declared=None,
                 tolerance_source=None, prior: bool = True, rows=None, t_s=None, where: str = "the calibration rows",
                 geometry_source: str | None = None) -> CalibrationData:
    """The data of :func:`calibrate` (its arguments of the same names, their defaults), checked:
    the :class:`CalibrationData` :func:`calibrate_checked` takes. ``heldout``: the held-out errors
    the caller will give :func:`calibrate_checked` (checked against validation rows), or None.

    Raises:
        TypeError, ValueError: naming the argument that is wrong.
    """
    _check_types(robot, noise)
    _check_heldout(heldout)
    _check_where(where)
    per, joints, measured, sessions, names, frames_of = _checked_groups(robot, joints, measured, measurement, sessions,
                                                                        session_names, session_frames)
    n = joints.shape[0]
    rows = np.arange(n) if rows is None else _int_array(rows, "rows", n)
    t_s = np.zeros(n) if t_s is None else as_array(t_s, "t_s", (n,))
    v_joints, v_measured, v_sessions, v_rows = _checked_validation(robot, per, measured.shape[1], len(names), rows,
                                                                   validation_joints, validation_measured,
                                                                   validation_sessions, validation_rows, heldout)
    tolerance, declared, tolerance_source = _checked_tolerance(robot, tolerance, tolerance_declared, tolerance_source)
    return CalibrationData(robot=robot, noise=noise, joints=joints, measured=measured, rows=rows, t_s=t_s,
                           measurement=per, sessions=sessions, session_names=names, session_frames=frames_of,
                           validation_joints=v_joints, validation_measured=v_measured, validation_sessions=v_sessions,
                           validation_rows=v_rows, tolerance=tolerance, prior=tolerance if prior else None,
                           tolerance_declared=declared, tolerance_source=str(tolerance_source), where=where,
                           geometry_source=geometry_source)


def checked_options(*, method: str = "chainwise", solver: str | None = None, weighted: bool = False,
                    keep_outliers: bool = False, search_gross_rows: bool = True, cross_validate: bool = True,
                    seed: int = 0) -> IdentificationOptions:
    """The identification options of :func:`calibrate` (its arguments of the same names, their
    defaults), checked.

    Raises:
        ValueError: naming the argument that is wrong.
    """
    _check_method(method, solver)
    _check_seed(seed)
    return IdentificationOptions(method=method, solver=solver, weighted=bool(weighted),
                                 keep_outliers=bool(keep_outliers), search_gross_rows=bool(search_gross_rows),
                                 cross_validate=bool(cross_validate), seed=int(seed))


def _check_types(robot, noise) -> None:
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be a calib.robot.Robot, got {type(robot).__name__}")
    if not isinstance(noise, SensorNoise):
        raise TypeError(f"noise must be a calib.noise.SensorNoise, got {type(noise).__name__}")


def _check_method(method, solver) -> None:
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if solver is not None and solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS} or None, got {solver!r}")


def _check_heldout(heldout) -> None:
    if heldout is not None and not callable(heldout):
        raise TypeError(f"heldout must be callable (theta -> (before, after)), got {type(heldout).__name__}")


def _check_seed(seed) -> None:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f"seed must be an integer, got {seed!r}")


def _check_where(where) -> None:
    if not isinstance(where, str):
        raise ValueError(f"where must be a string, got {type(where).__name__}")


def _checked_groups(robot, joints, measured, measurement, sessions, session_names, session_frames) -> tuple:
    """``(per-group settings or None, joints, measured, sessions, names, session frames)`` checked."""
    per = None
    if measurement is not None:
        per = (measurement,) if isinstance(measurement, MeasurementSettings) else tuple(measurement)
        if not per or not all(isinstance(m, MeasurementSettings) for m in per):
            raise TypeError("measurement must be a calib.measurement.MeasurementSettings or a non-empty sequence of "
                            f"them, got {measurement!r}")
    n_groups = 1 if per is None else len(per)
    width = robot.pose_dim if per is None or per[0].targets is None else 3 * per[0].n_targets
    joints = as_array(joints, "joints", (-1, robot.n_chains))
    n = joints.shape[0]
    measured = as_array(measured, "measured", (n, width))
    if n == 0:
        raise ValueError("joints and measured must hold at least one calibration row, got 0")
    if sessions is None:
        if n_groups > 1:
            raise ValueError(f"sessions must give each row's frame group: measurement names {n_groups} groups")
        sessions = np.zeros(n, dtype=int)
    else:
        if per is None:
            raise ValueError("sessions needs measurement (each frame group's instrument settings)")
        sessions = _int_array(sessions, "sessions", n)
        missing = sorted(set(range(n_groups)) - set(sessions.tolist()))
        if sessions.min() < 0 or sessions.max() >= n_groups or missing:
            raise ValueError(f"sessions must number the {n_groups} frame group(s) of measurement 0..{n_groups - 1}, "
                             f"each with rows, got values {sorted(set(sessions.tolist()))}")
    names = tuple(str(s + 1) for s in range(n_groups)) if session_names is None else tuple(session_names)
    if len(names) != n_groups or len(set(names)) != n_groups or not all(isinstance(s, str) for s in names):
        raise ValueError(f"session_names must be {n_groups} distinct strings, got {session_names!r}")
    frames_of = {name: s for s, name in enumerate(names)} if session_frames is None else dict(session_frames)
    bad = {k: v for k, v in frames_of.items() if not isinstance(k, str) or v not in (BASE_FRAME, *range(n_groups))}
    if bad:
        raise ValueError(f"session_frames must map session names to a frame group 0..{n_groups - 1} or BASE_FRAME "
                         f"({BASE_FRAME}), got {bad}")
    return per, joints, measured, sessions, names, frames_of


def _checked_validation(robot, per, width: int, n_groups: int, rows, validation_joints, validation_measured,
                        validation_sessions, validation_rows, heldout) -> tuple:
    """``(joints, measured, frame groups, row numbers)`` of the validation rows, checked."""
    if (validation_joints is None) != (validation_measured is None):
        raise ValueError("validation_joints and validation_measured must be given together")
    if validation_joints is None:
        v_joints, v_measured = np.zeros((0, robot.n_chains)), np.zeros((0, width))
    else:
        v_joints = as_array(validation_joints, "validation_joints", (-1, robot.n_chains))
        v_measured = as_array(validation_measured, "validation_measured", (v_joints.shape[0], width))
    m = v_joints.shape[0]
    if m and heldout is not None:
        raise ValueError("heldout and validation rows exclude each other: give the held-out errors one way")
    v_sessions = np.zeros(m, dtype=int) if validation_sessions is None else \
        _int_array(validation_sessions, "validation_sessions", m)
    if m and not set(v_sessions.tolist()) <= {BASE_FRAME, *range(n_groups)}:
        raise ValueError(f"validation_sessions must be frame groups 0..{n_groups - 1} or BASE_FRAME ({BASE_FRAME}), "
                         f"got values {sorted(set(v_sessions.tolist()))}")
    if m and per is None and np.any(v_sessions == BASE_FRAME):
        raise ValueError("validation_sessions: BASE_FRAME needs measurement (every row is in the base frame without)")
    v_rows = np.arange(m) + int(rows.max()) + 1 if validation_rows is None else \
        _int_array(validation_rows, "validation_rows", m)
    return v_joints, v_measured, v_sessions, v_rows


def _checked_tolerance(robot, tolerance, tolerance_declared, tolerance_source) -> tuple:
    """``(tolerance, declared, its source in words)`` checked (default the robot's)."""
    declared = tolerance is not None if tolerance_declared is None else bool(tolerance_declared)
    if tolerance is None:
        tolerance = ParameterPrior.default(robot)
    elif not isinstance(tolerance, ParameterPrior):
        raise TypeError(f"tolerance must be a calib.prior.ParameterPrior, got {type(tolerance).__name__}")
    elif tolerance.std.shape != (robot.n_parameters,):
        raise ValueError(f"tolerance must hold the {robot.n_parameters} parameters of the {robot.name}, got "
                         f"{tolerance.std.shape[0]}")
    if tolerance_source is None:
        tolerance_source = "the tolerance declared" if declared else f"the {robot.name}'s default tolerance"
    return tolerance, declared, tolerance_source


# --------------------------------------------------------------------------- identification


def fit_rows(data: CalibrationData, options: IdentificationOptions, joints, measured, prior, rows):
    """``(result, solver)``: the identification of base-frame poses ``measured`` at ``joints``
    (the calibration rows numbered ``rows``) by ``options.method``.

    Raises:
        UnreachableRows: the nominal model cannot reach a row.
        ValueError: too few or unusable rows (``data.where`` named).
    """
    robot = data.robot
    solver = options.solver or ("gn" if options.method == "chainwise" else "lm")
    kw = {"solver": solver}
    if options.method == "chainwise":
        kw.update(weighted=options.weighted, epsilon=paper.PAPER_EPSILON)
    try:
        return identify(robot, joints, measured, data.noise, method=options.method, prior=prior, **kw), solver
    except KinematicsError as exc:
        raise UnreachableRows(exc, rows, f"the {robot.name} cannot reach the recorded joints", data.where) from None
    except ValueError as exc:
        raise ValueError(f"{data.where}: {len(measured)} calibration rows are too few or unusable: {exc}") from None


class SessionSearch:
    """The gross-row searches of the frame groups (one instrument frame each) read as one:
    ``gross``, ``kept``, ``statistic`` over the calibration rows; ``success`` where every group's
    search judged its rows; ``frame_estimated`` where any estimated a frame; ``searches`` each."""

    def __init__(self, searches: list, sessions: np.ndarray):
        self.searches, self.sessions = searches, sessions
        n = sessions.size
        self.kept, self.statistic = np.ones(n, dtype=bool), np.full(n, np.nan)
        for s, search in enumerate(searches):
            rows = np.flatnonzero(sessions == s)
            self.kept[rows] = search.kept
            self.statistic[rows] = search.statistic
        self.gross = tuple(int(i) for i in np.flatnonzero(~self.kept))
        self.success = all(search.success for search in searches)
        self.frame_estimated = any(search.frame_estimated for search in searches)
        self.cutoff = searches[0].cutoff
        self.fit = None
        self.message = "; ".join(f"session {s + 1}: {search.message}" for s, search in enumerate(searches))


def session_gross_rows(data: CalibrationData, options: IdentificationOptions, s: int) -> GrossRowResult:
    """The gross-row search of frame group ``s``'s rows, in its own instrument frame."""
    ms = data.measurement_of(s)
    rows = np.flatnonzero(data.sessions == s)
    return find_gross_rows(data.robot, data.joints[rows], data.measured[rows], data.noise, frame=ms.frame,
                           targets=ms.targets, estimate_targets=ms.estimate_targets if ms.targets is not None else None,
                           seed=options.seed)


def gross_row_search(data: CalibrationData, options: IdentificationOptions):
    """``(search, kept rows)``: the gross rows found before anything is fitted to them
    (:func:`calib.robust.find_gross_rows`: trimmed fits, a row named only when no consistent fit
    explains it; the instrument frame inferred from the rows it makes consistent); ``(None, every
    row)`` without ``search_gross_rows``. With ``keep_outliers`` the rows are named, not left out."""
    n = len(data.measured)
    if not options.search_gross_rows:
        return None, np.arange(n)
    if data.n_sessions > 1:
        search = SessionSearch([session_gross_rows(data, options, s) for s in range(data.n_sessions)], data.sessions)
    else:
        search = session_gross_rows(data, options, 0)
    if not search.success or options.keep_outliers:
        return search, np.arange(n)
    return search, np.flatnonzero(search.kept)


def instrument_fit(data: CalibrationData, search, kept: np.ndarray) -> MeasuredFit | None:
    """The geometry fitted with the instrument frame(s) and target offsets on the rows ``kept``,
    where the measurement needs them (None: poses in the base frame)."""
    if data.measurement is None:
        return None
    if data.n_sessions > 1:
        return sessions_fit(data, search, kept)
    ms = data.measurement_of(0)
    joints, measured = data.joints[kept], data.measured[kept]
    if search is None or not search.success:  # the search could not judge: the frame test on every row
        return identify_as_measured(data.robot, joints, measured, data.noise, ms, prior=data.prior)
    if not search.frame_estimated and ms.n_targets == 0:
        return None
    start = search.fit.frame if search.frame_estimated and search.fit is not None else ms.initial_frame
    # "auto" on the rows kept: the frame test of every run, now on rows the frame makes consistent.
    return identify_measured(data.robot, joints, measured, data.noise,
                             frame="auto" if search.frame_estimated else "base", initial_frame=start,
                             targets=ms.targets, estimate_targets=ms.estimate_targets if ms.n_targets else None,
                             prior=data.prior)


def sessions_fit(data: CalibrationData, search, kept: np.ndarray) -> MeasuredFit:
    """One geometry, an instrument frame for each frame group (estimated where its own search found
    one or its settings ask for it), fitted together on the rows ``kept``
    (:func:`calib.measurement.identify_measured` with ``sessions``)."""
    per = [data.measurement_of(s) for s in range(data.n_sessions)]
    searches = search.searches if isinstance(search, SessionSearch) else [None] * len(per)
    frames, starts = [], []
    for ms, found in zip(per, searches):
        estimated = (found.frame_estimated if found is not None and found.success else ms.frame == "estimate")
        frames.append("auto" if estimated and ms.frame != "estimate" else ("estimate" if estimated else "base"))
        starts.append(found.fit.frame if estimated and found is not None and found.fit is not None
                      else ms.initial_frame)
    ms0 = per[0]
    return identify_measured(data.robot, data.joints[kept], data.measured[kept], data.noise, frame=frames,
                             initial_frame=starts, targets=ms0.targets,
                             estimate_targets=ms0.estimate_targets if ms0.n_targets else None, prior=data.prior,
                             sessions=data.sessions[kept])


def first_fit(data: CalibrationData, options: IdentificationOptions, search, kept: np.ndarray):
    """``(instrument, measured, (result, solver))`` of the rows ``kept`` under ``data.prior``: the
    instrument fit where the measurement needs one (then ``measured`` (N, D) the poses in the base
    frame and the pair None), else the identification of the base-frame poses."""
    instrument = instrument_fit(data, search, kept)
    measured = data.measured if instrument is None else instrument.base_poses(
        data.joints, data.measured, sessions=data.sessions if data.n_sessions > 1 else None)
    if instrument is not None:
        return instrument, measured, None
    return None, measured, fit_rows(data, options, data.joints[kept], measured[kept], data.prior, data.rows[kept])


def learn_tolerance(data: CalibrationData, fit) -> tuple[CalibrationData, bool]:
    """``(data, refit)``: ``data`` with the tolerance the rows support
    (:func:`calib.evidence.tolerance_from_data`, from ``fit``: an identification result, or the
    ``(result, solver)`` pair, made under ``data.prior``). Where no tolerance was declared and the
    rows show the robot's default too tight (the units of
    :attr:`calib.evidence.ToleranceEstimate.wider`), the learnt tolerance becomes the prior and the
    yardstick (``tolerance_source`` says so) and ``refit`` is True (fit again under it); a default
    the rows do not contradict stays, with the estimate said; a declared one is kept and checked
    (``tolerance_estimate`` says whether the rows contradict it). Without a prior nothing is learnt."""
    result = fit[0] if isinstance(fit, tuple) else fit
    if data.prior is None or result is None or result.prior is None:
        return data, False
    try:
        estimate = tolerance_from_data(result, reference=data.prior)
    except (ValueError, np.linalg.LinAlgError) as exc:
        return replace(data, tolerance_source=data.tolerance_source +
                       f" (no tolerance could be learnt from the rows: {exc})"), False
    data = replace(data, tolerance_estimate=estimate)
    if data.tolerance_declared:
        return data, False
    robot = data.robot
    default = estimate.tolerance_words("reference")
    if all(f == 1.0 for f in estimate.factor.values()):
        return replace(data, tolerance_source=f"the {robot.name}'s default tolerance ({default}, one standard "
                                              "deviation): the rows determine too few parameters to learn one"), False
    if not estimate.wider:
        return replace(data, tolerance_source=(
            f"the {robot.name}'s default tolerance ({default}, one standard deviation), consistent with the rows or "
            f"wider than they show (estimated from the data: {estimate.tolerance_words()}); a default wider than the "
            "machine costs nothing where the rows determine the parameters")), False
    learnt = estimate.widened_prior()
    kept = [u for u in estimate.factor if u not in estimate.wider]
    source = (f"tolerance estimated from the data: "
              f"{', '.join(f'{estimate.tolerance[u]:.3g} {u}' for u in estimate.wider)} (the "
              f"{robot.name}'s default {default} is contradicted: {estimate.evidence_words()})"
              + (f"; the default kept for {', '.join(kept)}" if kept else ""))
    return replace(data, prior=learnt, tolerance=learnt, tolerance_source=source), True


def identify_rows(data: CalibrationData, options: IdentificationOptions, warnings: list,
                  seconds: dict | None = None) -> tuple[Identification, CalibrationData]:
    """Steps 1-4 of the module docstring: gross rows first (:func:`gross_row_search`), then, on the
    rows kept, the instrument frame where the measurement needs one (:func:`instrument_fit`), the
    tolerance (:func:`learn_tolerance`), the outlier test (closed-form leave-one-out, forward
    model, poses in the base frame) and the identification from the rows it keeps; the one with
    its flagged rows is kept for the comparison. Returns the identification and ``data`` with the
    tolerance learnt; ``warnings`` and ``seconds`` (``gross_rows``, ``outlier_test``) are added to."""
    robot, joints, noise = data.robot, data.joints, data.noise
    seconds = {} if seconds is None else seconds
    t0 = time.perf_counter()
    search, kept = gross_row_search(data, options)
    seconds["gross_rows"] = time.perf_counter() - t0
    gross_idx = [] if search is None or not search.success else [int(i) for i in search.gross]
    instrument, measured, first = first_fit(data, options, search, kept)
    data, refit = learn_tolerance(data, instrument.result if instrument is not None else first)
    if refit:
        instrument, measured, first = first_fit(data, options, search, kept)  # under the learnt tolerance
    est = data.tolerance_estimate
    if data.tolerance_declared and est is not None and est.contradicted:
        warnings.append(f"the declared tolerance ({est.tolerance_words('reference')}) is contradicted by the rows: "
                        f"{est.evidence_words()}; the rows support {est.tolerance_words()} (declared, so obeyed)")
    t1 = time.perf_counter()
    try:
        report = find_outliers(robot, joints[kept], measured[kept], noise)
    except (ValueError, KinematicsError) as exc:
        report, outlier_verdict = None, f"outlier test not run: {exc}"
    else:
        outlier_verdict = report.verdict
    seconds["outlier_test"] = time.perf_counter() - t1
    loo_idx = [int(kept[i]) for i in report.flagged] if report is not None else []
    flagged_idx = sorted(set(gross_idx) | set(loo_idx))
    result_all, solver = (instrument.result, "lm") if instrument is not None else first
    keep = np.setdiff1d(kept, loo_idx)
    left_out = bool(loo_idx) and not options.keep_outliers and instrument is None
    if loo_idx and instrument is not None:
        warnings.append("the rows the leave-one-out test flags are kept: leaving them out is not done with an "
                        "instrument frame or targets estimated (gross rows are left out before the frame is fitted)")
    result_kept = None
    if loo_idx and instrument is None:
        try:
            result_kept, _ = fit_rows(data, options, joints[keep], measured[keep], data.prior, data.rows[keep])
        except ValueError as exc:
            warnings.append(f"the flagged rows are kept: without them {exc}")
            left_out = False
    ident = Identification(result=result_kept if left_out else result_all, result_all=result_all,
                           result_kept=result_kept, solver=solver, report=report, outlier_verdict=outlier_verdict,
                           flagged_idx=flagged_idx, keep=keep, left_out=left_out, used=keep if left_out else kept,
                           instrument=instrument, measured=measured, gross=search, gross_idx=gross_idx, kept=kept)
    return ident, data


# --------------------------------------------------------------------------- held-out errors


def instrument_heldout(robot: Robot, fit: MeasuredFit, joints, measured, sessions=None):
    """``(before, after)`` (M, W) held-out errors of rows in an instrument frame or of targets:
    measured minus the prediction, before (nominal geometry, the registered frame, the start
    offsets) and after (the fit); ``sessions``: (M,) each row's frame group (None: one;
    :data:`BASE_FRAME`: the base frame, the fit's targets)."""
    k = fit.n_targets
    nominal = robot.forward_kinematics(robot.table.nominal, joints)
    groups = np.zeros(len(joints), dtype=int) if sessions is None else np.asarray(sessions)
    several = fit.n_sessions > 1
    before = np.empty_like(np.asarray(measured, dtype=float))
    after = np.empty_like(before)
    for s in np.unique(groups):
        at = groups == s
        if s == BASE_FRAME:
            frame, targets = np.zeros(6), fit.targets
            predicted = instrument_measurements(robot, robot.forward_kinematics(fit.result.theta, joints[at]),
                                                None, fit.targets)
        else:
            reg = fit.registrations[s] if several else fit.registration
            estimated = fit.frames_estimated[s] if several else fit.frame_estimated
            frame = reg.frame if estimated and reg is not None else fit.frames[s]
            targets = None if k == 0 else (reg.targets if reg is not None and estimated else fit.targets)
            predicted = fit.predict(joints[at], sessions=s if several else None)
        before[at] = measurement_residuals(robot, measured[at], instrument_measurements(robot, nominal[at], frame,
                                                                                       targets), k)
        after[at] = measurement_residuals(robot, measured[at], predicted, k)
    return before, after


def validation_errors(data: CalibrationData, ident: Identification, theta) -> tuple | None:
    """``(before, after)`` (M, W) the validation rows' errors, measured minus predicted by the
    nominal model and by ``theta`` (in their frame group's instrument frame where one was fitted;
    they include the sensor noise), or None without validation rows.

    Raises:
        UnreachableRows: a model cannot reach a validation row.
    """
    if not len(data.validation_joints):
        return None
    robot = data.robot
    if ident.instrument is not None:
        return instrument_heldout(robot, ident.instrument, data.validation_joints, data.validation_measured,
                                  data.validation_sessions)
    # The validation poses measured under nominal commands: the identified model's prediction error
    # there stands for the compensated error (equal to first order), and includes the sensor noise.
    joints, measured = data.validation_joints, data.validation_measured
    try:
        before = measured - robot.forward_kinematics(robot.table.nominal, joints, initial=measured)
        after = measured - robot.forward_kinematics(theta, joints, initial=measured)
    except KinematicsError as exc:
        raise UnreachableRows(exc, data.validation_rows, "a validation row the model cannot reach",
                              data.where) from None
    return before, after


# --------------------------------------------------------------------------- cross-validation


def crossvalidation_of(data: CalibrationData, ident: Identification, options: IdentificationOptions) -> CrossValidation:
    """The cross-validated prediction error of the rows the fit used
    (:func:`calib.crossval.crossvalidate`, fitted as the run fits them: leave-one-out for the forward
    method, 10-fold for the chain-wise one and with an instrument frame, each frame group's own
    with several).

    Raises:
        ValueError: one row left (nothing to predict a row from; said in words).
    """
    rows = ident.used
    if rows.size < 2:  # nothing to predict a row from: said in words, not as the folds' bounds
        total = len(data.measured)
        what = "the recording holds one data row" if total == 1 else \
            f"of its {total} rows one calibration row is left to fit once the gross rows are out"
        raise ValueError(f"{data.where}: {what}: a calibration is judged by predicting rows it did not use, and one "
                         "row leaves none (add validation rows, or measure more poses spread over the workspace)")
    if ident.instrument is not None:
        several = data.n_sessions > 1
        return crossvalidate(data.robot, data.joints[rows], data.measured[rows], data.noise, method="forward",
                             folds=min(INSTRUMENT_FOLDS, rows.size), prior=data.prior,
                             measurement=crossvalidation_settings(data, ident.instrument), seed=options.seed,
                             sessions=data.sessions[rows] if several else None)
    kw = {"solver": ident.solver}
    if options.method == "chainwise":
        kw.update(weighted=options.weighted, epsilon=paper.PAPER_EPSILON)
    return crossvalidate(data.robot, data.joints[rows], ident.measured[rows], data.noise, method=options.method,
                         prior=data.prior, fit_kwargs=kw, seed=options.seed)


def crossvalidation_settings(data: CalibrationData, instrument: MeasuredFit):
    """How each fold fits the instrument: the frame estimated (from the run's) where the run
    estimated it, else the base frame; with several frame groups one settings a group (its frame),
    the targets group 0's (as :func:`sessions_fit`)."""
    ms = data.measurement_of(0)
    if data.n_sessions == 1:
        return replace(ms, frame="estimate" if instrument.frame_estimated else "base",
                       initial_frame=instrument.frame if instrument.frame_estimated else None)
    per = [data.measurement_of(s) for s in range(data.n_sessions)]
    return [replace(one, frame="estimate" if estimated else "base", initial_frame=frame if estimated else None,
                    targets=per[0].targets, estimate_targets=per[0].estimate_targets)
            for one, frame, estimated in zip(per, instrument.frames, instrument.frames_estimated)]


# --------------------------------------------------------------------------- verdict


def prediction_check(data: CalibrationData, ident: Identification, held, cv) -> PredictionCheck | None:
    """Whether the predictions of rows the fit did not use agree with what the fit says they can be:
    each row's prediction residual (the validation rows' ``held``, or the cross-validation's)
    whitened by its covariance, the declared noise plus the identified parameters' uncertainty
    carried to the pose (``S + J Sigma J^T``), summed against the chi-square on their coordinates.
    None where there is nothing to test (no measured rows held out; target data).

    Above :data:`calib.outliers.STRUCTURED_JACOBIAN_MIN_ROWS` rows in the base frame ``J Sigma
    J^T`` is taken through the Jacobian's chain factors where the robot's closures give them
    (:func:`calib.robot.chain_jacobian_factors`; equal to rounding), and ``factored_rows`` says so.
    """
    if ident.instrument is not None and ident.instrument.targets is not None:
        return None
    robot, result = data.robot, ident.result
    if held is not None:
        joints, poses, residuals, what = data.validation_joints, data.validation_measured, held[1], "validation rows"
    elif cv is not None:
        joints, poses = data.joints[ident.used], ident.measured[ident.used]
        residuals, what = cv.residuals, f"cross-validation ({cv.scheme})"
    else:
        return None
    ok = np.all(np.isfinite(residuals), axis=1)
    if not ok.any():
        return PredictionCheck(what, agrees=False, ratio=None, rows=0)
    joints, poses, residuals = joints[ok], poses[ok], residuals[ok]
    std = data.noise.pose_std(robot.pose_units)
    try:
        groups = data.validation_sessions[ok] if ident.instrument is not None and held is not None else \
            np.full(len(joints), BASE_FRAME)
        cov = np.empty((len(joints), robot.pose_dim, robot.pose_dim))
        base = groups == BASE_FRAME  # in the base frame: the geometry's uncertainty alone
        factors = None
        if base.any():
            if np.count_nonzero(base) > outliers.STRUCTURED_JACOBIAN_MIN_ROWS:  # the chain factors, where given
                factors = chain_jacobian_factors(robot, result.theta, joints[base], poses[base])
            if factors is not None:
                cov[base] = factors.sandwich(result.covariance)
            else:
                jac = pose_jacobian_of_parameters(robot, result.theta, joints[base], poses[base])
                # J Sigma J^T row by row: one (N D, P) x (P, P) product, then (D, P) x (P, D) per row
                # (a three-operand einsum without a contraction order loops over N D P P D terms)
                js = (jac.reshape(-1, jac.shape[2]) @ result.covariance).reshape(jac.shape)
                cov[base] = js @ np.swapaxes(jac, 1, 2)
        if (~base).any():  # geometry and frames' uncertainty together
            cov[~base] = ident.instrument.prediction_covariance(
                joints[~base], sessions=groups[~base] if data.n_sessions > 1 else None)
        cov += np.diag(std ** 2)
    except KinematicsError:
        return PredictionCheck(what, agrees=False, ratio=None, rows=0)
    w = np.linalg.solve(np.linalg.cholesky(cov), residuals[:, :, None])[:, :, 0]
    chi2, dof = float(np.sum(w ** 2)), int(w.size)
    limit = chi2_limit(dof)
    return PredictionCheck(what, agrees=bool(chi2 <= limit), ratio=float(np.sqrt(chi2 / dof)), rows=int(ok.sum()),
                           limit_ratio=float(np.sqrt(limit / dof)), factored_rows=None if factors is None else factors.n)


def verdict_of(data: CalibrationData, ident: Identification, held, cv, diagnosis=None) -> Verdict:
    """The :class:`Verdict`: success only where the fit converged, the rows it used (less the gross
    rows) fit within the declared noise (chi-square at :data:`calib.diagnosis.FIT_ALPHA`) and the
    predictions of rows it did not use agree (:func:`prediction_check` of the validation rows'
    errors ``held`` or of ``cv``); never where the rows determine nothing or the errors are a
    description's pattern; otherwise the likely cause with its evidence: ``diagnosis``'s where it
    names a conversion or an unmeasured column, else :func:`likely_cause`."""
    result = ident.result
    dof = max(int(result.dof), 1)
    fit_ok = bool(np.isfinite(result.chi2) and result.chi2 <= chi2_limit(dof))
    check = prediction_check(data, ident, held, cv)
    success = bool(result.success and fit_ok and (check is None or check.agrees))
    evidence = VerdictEvidence(converged=bool(result.success), fit_ratio=float(np.sqrt(result.chi2 / dof)),
                               fit_limit_ratio=float(np.sqrt(chi2_limit(dof) / dof)), fit_at_noise=fit_ok,
                               predictions=check)
    uninformed = information_verdict(data, ident) or description_verdict(data, ident)
    if uninformed is not None:
        cause, detail = uninformed
        return Verdict(False, cause, evidence, detail, diagnosis)
    if success:
        return Verdict(True, None, evidence, None, diagnosis)
    if diagnosis is not None and diagnosis.cause in DIAGNOSED_CAUSES:
        return Verdict(False, diagnosis.cause, evidence, None, diagnosis)
    cause, detail = likely_cause(data, ident, evidence)
    return Verdict(False, cause, evidence, detail, diagnosis)


def information_verdict(data: CalibrationData, ident: Identification) -> tuple[str, object] | None:
    """``(cause, detail)`` of a fit that learnt nothing from its rows, else None: rows that do not
    move the machine (every calibration row used at one pose, :func:`calib.diagnosis.motionless_rows`:
    ``"no_motion"``, :class:`NoMotion`), or, with the tolerances as a prior, no parameter determined
    by the data (:meth:`calib.engine.IdentificationResult.parameter_sources`: none whose posterior
    standard deviation fell below half the prior's, none moved beyond 3 prior standard deviations:
    ``"no_information"``, :class:`NoInformation`), and fewer than one direction determined singly or
    in combinations (:meth:`calib.engine.IdentificationResult.directions_determined`: a plane of
    poses determines combinations, not single parameters). Such a fit is never a success, however
    well the rows fit."""
    from .diagnosis import motionless_rows, same_pose_rows

    robot, result = data.robot, ident.result
    joints = data.joints[ident.used]
    still = motionless_rows(robot, joints, data.noise.joint_std)
    if still is not None:
        return "no_motion", NoMotion(rows=still, robot=robot.name)
    sources = result.parameter_sources()
    seen = result.directions_determined()
    if seen is None or seen >= MIN_DETERMINED or any(v == "data" for v in sources.values()):
        return None
    free = [n for n, v in sources.items() if v != "held"]
    noise = data.noise.pose_std(robot.pose_units)
    idx = robot.table.indices(free)
    units = np.array(robot.table.units)[idx]
    tolerances = tuple((float(np.median(result.prior.std[idx][units == u])), str(u)) for u in dict.fromkeys(units))
    return "no_information", NoInformation(
        free=len(free), determined=float(seen), same_pose_rows=len(same_pose_rows(robot, joints, data.noise.joint_std)),
        rows=len(joints), noise=float(noise[0]), noise_unit=robot.pose_units[0], tolerances=tolerances)


def description_verdict(data: CalibrationData, ident: Identification) -> tuple[str, DescriptionPattern] | None:
    """``("description", DescriptionPattern)`` where the fitted errors are a scale of the nominal
    geometry described (:func:`calib.diagnosis.description_pattern`, against the declared tolerance
    or the robot's default, not one learnt from these rows: the learnt one grows to hold the
    pattern): the description is another machine's (``data.geometry_source`` named); else None."""
    from .diagnosis import description_pattern

    robot, result = data.robot, ident.result
    reference = data.tolerance if data.tolerance_declared else ParameterPrior.default(robot)
    pattern = description_pattern(robot, result.errors, reference.std, result.free_names)
    if not pattern:
        return None
    return "description", DescriptionPattern(patterns=tuple(pattern), geometry_source=data.geometry_source or None)


def likely_cause(data, ident, evidence: VerdictEvidence) -> tuple[str, object]:
    """``(cause, detail)`` of a calibration that is no success: no convergence
    (:class:`NoConvergence`), a gross-row search that could not judge or a model that misfits most
    rows (:class:`GrossSearch`), rows it cannot predict or physics the geometric model leaves out
    (:class:`Misprediction`). Reads ``data.where``, ``ident.result.message``, ``ident.gross`` (its
    ``success``, ``statistic``, ``cutoff``, ``message``) and the verdict's ``evidence``."""
    where = data.where
    if not evidence.converged:
        return "no_convergence", NoConvergence(message=ident.result.message)
    search = ident.gross
    if search is not None and not search.success:
        beyond = int(np.sum(search.statistic > search.cutoff))
        found = GrossSearch(message=search.message, beyond=beyond, rows=int(search.statistic.size), where=where)
        # most rows beyond the noise: the model misfits them; else the search failed for another reason
        return ("gross_search_failed" if 2 * beyond <= search.statistic.size else "model_misfit"), found
    predictions = evidence.predictions
    if evidence.fit_at_noise and predictions.ratio is None:
        return "unpredictable_rows", Misprediction(what=predictions.what, ratio=None, where=where)
    if evidence.fit_at_noise:
        return "left_out_physics", Misprediction(what=predictions.what, ratio=predictions.ratio, where=where)
    return "left_out_physics", Misprediction(what="calibration rows", ratio=evidence.fit_ratio, where=where)


# --------------------------------------------------------------------------- calibration


def instrument_frames(data: CalibrationData, instrument: MeasuredFit | None) -> tuple[dict, dict]:
    """``({session: (6,) frame}, {session: (6,) std})`` of a fit's instrument frames, one per
    session of ``data.session_frames`` in a frame group; empty when the data were in the base frame."""
    if instrument is None or not np.any(instrument.frames):
        return {}, {}
    return ({n: np.array(instrument.frames[g]) for n, g in data.session_frames.items() if g != BASE_FRAME},
            {n: np.array(instrument.frames_std[g]) for n, g in data.session_frames.items() if g != BASE_FRAME})


def calibration_of(data: CalibrationData, ident: Identification) -> Calibration:
    """What the identification found, as a :class:`~calib.calibration.Calibration`: the identified
    geometry with its covariance, the instrument frames, the targets, no effect, the domain of the
    rows used (:func:`calib.calibration.validity_domain`), the declared noise; ``produced_by``
    :data:`PRODUCED_BY`, no recording (the caller names its own)."""
    robot, result, used = data.robot, ident.result, ident.used
    idx = robot.table.indices(result.free_names)
    frames, frames_std = instrument_frames(data, ident.instrument)
    return Calibration(robot=robot, theta=result.theta, std=result.std, free=tuple(result.free_names),
                       covariance=result.covariance[np.ix_(idx, idx)], frames=frames, frames_std=frames_std,
                       targets=None if ident.instrument is None else ident.instrument.targets,
                       validity=validity_domain(robot, ident.measured[used], data.joints[used], data.t_s[used],
                                                result.theta),
                       noise=data.noise, produced_by=PRODUCED_BY)
