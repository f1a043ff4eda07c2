"""Cross-validated prediction error (calib.crossval): a held-out figure without held-out rows.

Measurements are simulated with the kinematic model alone: the joints the true machine needs at
seeded workspace poses (``robot.inverse_kinematics`` under the true parameters, the robot's
reference errors) and the poses plus seeded sensor noise. The independent truth of the
cross-validated figure is the held-out figure the pipeline reports on recorded validation rows:
measured poses at other seeded poses of the same machine, with the same noise, minus the
identified model's prediction at their joints. Both include the sensor noise; both estimate the
prediction error of a model fitted to N rows at rows it was not fitted to.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from calib.crossval import (DEFAULT_CHAINWISE_FOLDS, SUMMARY_STATISTICS, CrossValidation, crossvalidate,
                            crossvalidate_model, error_summary, fold_assignment)
from calib.engine import METHODS, identify, identify_chainwise, identify_forward
from calib.measurement import MeasurementSettings, identify_measured, instrument_measurements
from calib.metrics import pose_error_norms
from calib.noise import SensorNoise
from calib.outliers import find_outliers
from calib.prior import ParameterPrior
from calib.robot import FORWARD_KINEMATICS_TOL_MM
from calib.robots import ROBOTS, default_robot, reference_errors
from calib.workspace import reachable_poses

NAMES = sorted(ROBOTS)
#: Sensor noise of the simulated recordings: 1 um on positions and 1 urad on angles, normal.
NOISE = SensorNoise(1e-3, 1e-6, "normal")
#: The issue's study: 20 seeds, 60 calibration rows, each seed's held-out figure over 200
#: validation rows (its own sampling error, ~1/sqrt(2 * 200 * 3) = 2% on an RMS, is small
#: against the cross-validated figure's, ~1/sqrt(2 * 60 * 3) = 5%).
SEEDS = range(20)
ROWS = 60
HELDOUT_ROWS = 200
#: The issue's requirement: the median over the seeds of cross-validated / held-out within 20%.
#: The median of 20 ratios of spread ~0.07 (measured: 0.88 to 1.16 per seed) is known to ~0.02,
#: and leave-one-out is unbiased to O(1/N); 10-fold fits 90% of the rows, a pessimism of about
#: (p / N) / 9 in the variance (p parameters per residual: < 1% here).
RATIO_BAND = (0.8, 1.2)
#: Rounding of the angle wrap to (-pi, pi] applied to the residuals (a few ulps of pi, rad); the
#: refits are otherwise the same computation, bit for bit.
WRAP_ROUNDING_RAD = 4 * np.pi * np.finfo(float).eps


def _measure(robot, theta, poses, seed, noise: SensorNoise = NOISE):
    """``(joints (N, C), measured (N, D))`` of the machine ``theta`` at ``poses``."""
    return robot.inverse_kinematics(theta, poses), poses + noise.sample(len(poses), seed, robot.pose_units)


def _experiment(robot, method: str, seed: int, rows: int = ROWS):
    """One seed of the study: ``(crossvalidation, held-out position (M,) mm, orientation (M,) rad)``
    of the machine with the robot's reference errors (seed), ``rows`` calibration and
    :data:`HELDOUT_ROWS` validation rows."""
    cal_poses, held_poses, cal_noise, held_noise = np.random.SeedSequence([seed, 7]).spawn(4)
    theta = robot.table.nominal + reference_errors(robot, seed)
    joints, measured = _measure(robot, theta, reachable_poses(robot, rows, cal_poses, theta=theta), cal_noise)
    held_joints, held = _measure(robot, theta, reachable_poses(robot, HELDOUT_ROWS, held_poses, theta=theta),
                                 held_noise)
    fit = identify(robot, joints, measured, NOISE, method=method)
    position, orientation = pose_error_norms(robot, held - robot.forward_kinematics(fit.theta, held_joints,
                                                                                    initial=held))
    return crossvalidate(robot, joints, measured, NOISE, method=method, seed=seed), position, orientation


def _rms(v) -> float:
    return float(np.sqrt(np.mean(np.asarray(v) ** 2)))


@pytest.mark.slow
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", NAMES)
def test_the_crossvalidated_error_is_the_heldout_error(name, method):
    """Median over 20 seeds of cross-validated / held-out RMS (and mean) position error, and RMS
    orientation error where the platform rotates, within 20%."""
    robot = default_robot(name)
    ratios = {"position rms": [], "position mean": [], "orientation rms": []}
    for seed in SEEDS:
        cv, position, orientation = _experiment(robot, method, seed)
        assert cv.success and cv.folds == (ROWS if method == "forward" else DEFAULT_CHAINWISE_FOLDS)
        ratios["position rms"].append(cv.position_summary["rms"] / _rms(position))
        ratios["position mean"].append(cv.position_summary["mean"] / float(position.mean()))
        if robot.angle_pose_mask.any():
            ratios["orientation rms"].append(cv.orientation_summary["rms"] / _rms(orientation))
    medians = {k: float(np.median(v)) for k, v in ratios.items() if v}
    print(name, method, {k: round(v, 3) for k, v in medians.items()})
    for what, median in medians.items():
        assert RATIO_BAND[0] <= median <= RATIO_BAND[1], f"{name} {method}: median {what} ratio {median:.3f}"


def _small_problem(name: str, rows: int, seed: int = 3, noise: SensorNoise = NOISE):
    robot = default_robot(name)
    theta = robot.table.nominal + reference_errors(robot, seed)
    joints, measured = _measure(robot, theta, reachable_poses(robot, rows, seed, theta=theta), seed + 1, noise)
    return robot, joints, measured


@pytest.mark.parametrize("name", NAMES)
def test_each_row_is_predicted_by_the_fit_without_it(name):
    """The leave-one-out residual of a row is the explicit refit's without it; a K-fold's residuals
    those of the chain-wise refit without its fold, with the prior passed through."""
    robot, joints, measured = _small_problem(name, 24)
    cv = crossvalidate(robot, joints, measured, NOISE)
    j = 5
    keep = np.arange(24) != j
    refit = identify_forward(robot, joints[keep], measured[keep], NOISE)
    expected = measured[j] - robot.forward_kinematics(refit.theta, joints[j:j + 1], initial=measured[j:j + 1])[0]
    np.testing.assert_allclose(cv.residuals[j], expected, rtol=0, atol=WRAP_ROUNDING_RAD)
    assert cv.scheme == "leave-one-out" and cv.fits == 24 and np.array_equal(cv.fold_of_row, np.arange(24))

    prior = ParameterPrior.default(robot)
    cw = crossvalidate(robot, joints, measured, NOISE, method="chainwise", folds=4, prior=prior, seed=11)
    test = cw.fold_of_row == 2
    refit = identify_chainwise(robot, joints[~test], measured[~test], NOISE, prior=prior)
    expected = measured[test] - robot.forward_kinematics(refit.theta, joints[test], initial=measured[test])
    np.testing.assert_allclose(cw.residuals[test], expected, rtol=0, atol=WRAP_ROUNDING_RAD)
    plain = crossvalidate(robot, joints, measured, NOISE, method="chainwise", folds=4, seed=11)
    assert not np.array_equal(plain.residuals, cw.residuals)  # the prior reached the fits
    assert cw.scheme == "4-fold" and "seed 11" in cw.message


@pytest.mark.parametrize("name", NAMES)
def test_exact_leave_one_out_agrees_with_the_closed_form_to_second_order(name):
    """calib.outliers' deleted residuals (hat matrix, first order in the parameter change a deleted
    row causes) differ from the exact refits by a second-order term: relative to the residual it
    grows in proportion to the noise, tenfold for tenfold noise (to the next order, ~noise /
    machine size, and the fits' convergence, far below the 5% allowed)."""
    relative = []
    for scale in (1.0, 10.0):
        noise = SensorNoise(NOISE.position_mm * scale, NOISE.orientation_rad * scale, "normal")
        robot, joints, measured = _small_problem(name, 40, noise=noise)
        exact = crossvalidate(robot, joints, measured, noise).residuals
        closed = find_outliers(robot, joints, measured, noise, alpha=1e-12).deleted_residuals
        relative.append(float(np.max(np.linalg.norm(closed - exact, axis=1) / np.linalg.norm(exact, axis=1))))
    assert relative[0] < 1e-3
    assert relative[1] / relative[0] == pytest.approx(10.0, rel=0.05)


def test_fold_assignment():
    """Leave-one-out is row j in fold j; K folds are a seeded partition into near-equal parts."""
    assert np.array_equal(fold_assignment(7, 7), np.arange(7))
    folds = fold_assignment(23, 5, seed=4)
    assert sorted(np.bincount(folds, minlength=5)) == [4, 4, 5, 5, 5]
    assert np.array_equal(folds, fold_assignment(23, 5, seed=4))
    assert not np.array_equal(folds, fold_assignment(23, 5, seed=5))
    for bad in (1, 24, 2.5):
        with pytest.raises(ValueError, match="folds must be an integer from 2 to the number of rows"):
            fold_assignment(23, bad)


def test_a_fold_whose_fit_fails_is_named_not_raised():
    """13 hexapod rows in 2 folds: the fold of 7 leaves 6 rows for 7 unknowns per leg and fails;
    the other fold's 6 rows are predicted; the result says so."""
    robot, joints, measured = _small_problem("hexapod", 13)
    cv = crossvalidate(robot, joints, measured, NOISE, method="chainwise", folds=2)
    failed = cv.fold_of_row == 0
    assert failed.sum() == 7 and cv.failed_folds == (0,) and not cv.success
    assert np.all(np.isnan(cv.position_error[failed])) and np.all(np.isfinite(cv.position_error[~failed]))
    assert cv.rows_predicted == 6 and "7 of 13 rows without a prediction" in cv.message
    assert "1 of 2 fold fits failed: fold 1: the fit failed: measured must have at least 7 rows" in cv.message
    assert cv.position_summary == error_summary(cv.position_error[~failed])


def test_every_fold_failing_still_returns_a_result():
    """7 hexapod rows, leave-one-out: 6 rows cannot identify 42 parameters in any fold."""
    robot, joints, measured = _small_problem("hexapod", 7)
    cv = crossvalidate(robot, joints, measured, NOISE)
    assert cv.failed_folds == tuple(range(7)) and cv.rows_predicted == 0
    summary = json.loads(json.dumps(cv.summary()))
    assert summary["crossvalidated_position_error_mm"] == dict.fromkeys(SUMMARY_STATISTICS)
    assert summary["crossvalidation"]["failed_folds"] == list(range(7))
    assert "7 of 7 fold fits failed" in cv.message and "and 4 more" in cv.message


def test_a_poor_pose_set_is_reported_and_the_prior_rescues_it():
    """Hexapod poses on one level plane leave leg heights undetermined: the plain chain-wise fits
    do not meet their stopping rule (named, kept); with the default prior every fold does."""
    robot = default_robot("hexapod")
    prior = ParameterPrior.default(robot)
    theta = robot.table.nominal + np.random.default_rng(0).uniform(-1.0, 1.0, robot.n_parameters) * prior.std
    b = robot.workspace_bounds()
    g = np.linspace(0.15, 0.85, 6)
    x, y = np.meshgrid(b[0, 0] + g * (b[0, 1] - b[0, 0]), b[1, 0] + g * (b[1, 1] - b[1, 0]))
    poses = np.tile(robot.home_pose, (36, 1))
    poses[:, 0], poses[:, 1] = x.ravel(), y.ravel()
    joints, measured = _measure(robot, theta, poses, 3)
    plain = crossvalidate(robot, joints, measured, NOISE, method="chainwise")
    assert plain.unconverged_folds and "stopped without meeting its stopping rule (kept)" in plain.message
    with_prior = crossvalidate(robot, joints, measured, NOISE, method="chainwise", prior=prior)
    assert with_prior.success and not with_prior.unconverged_folds and not with_prior.failed_folds


def test_summary_and_a_platform_without_angles():
    """The Delta's poses have no angles: no orientation figure; the summary is JSON and names the scheme."""
    robot, joints, measured = _small_problem("delta", 20)
    cv = crossvalidate(robot, joints, measured, NOISE, method="chainwise")
    assert isinstance(cv, CrossValidation) and cv.orientation_error is None and cv.orientation_summary is None
    summary = json.loads(json.dumps(cv.summary()))
    assert summary["crossvalidated_orientation_error_rad"] is None
    assert set(summary["crossvalidated_position_error_mm"]) == set(SUMMARY_STATISTICS)
    block = summary["crossvalidation"]
    assert (block["method"], block["scheme"], block["folds"], block["rows"]) == ("chainwise", "10-fold", 10, 20)
    assert block["message"].startswith("10-fold cross-validation")
    pos = cv.position_error
    assert summary["crossvalidated_position_error_mm"] == pytest.approx(
        {"rms": _rms(pos), "mean": float(pos.mean()), "max": float(pos.max())})


def test_instrument_frame_folds_are_fitted_with_the_frame():
    """Delta poses measured in a tracker's frame: each fold is fitted with the frame
    (identify_measured) and predicted in the tracker's coordinates."""
    robot, joints, _ = _small_problem("delta", 24)
    theta = robot.table.nominal + reference_errors(robot, 3)
    frame = np.array([400.0, -150.0, 80.0, 0.05, -0.1, 0.3])
    measured = instrument_measurements(robot, robot.forward_kinematics(theta, joints), frame) + \
        NOISE.sample(24, 9, robot.pose_units)
    settings = MeasurementSettings(frame="estimate")
    cv = crossvalidate(robot, joints, measured, NOISE, folds=4, measurement=settings, seed=2)
    test = cv.fold_of_row == 1
    refit = identify_measured(robot, joints[~test], measured[~test], NOISE, frame="estimate")
    np.testing.assert_allclose(cv.residuals[test], measured[test] - refit.predict(joints[test]), rtol=0,
                               atol=FORWARD_KINEMATICS_TOL_MM)
    assert cv.success and cv.orientation_error is None and cv.method == "forward"


def test_any_model_can_be_crossvalidated():
    """crossvalidate_model with a model that fits nothing (the nominal geometry): each row's
    residual is its nominal prediction error, whatever the fold; a fold whose fit raises is named."""
    robot, joints, measured = _small_problem("rus", 12)
    nominal = robot.table.nominal
    seen = []

    def fit_fold(train):
        seen.append(int(train.sum()))
        if len(seen) == 2:
            raise ValueError("too few rows for this fold")

        def predict(q, m):
            return robot.forward_kinematics(nominal, q, initial=m)

        return predict, True, "nothing fitted"

    cv = crossvalidate_model(robot, joints, measured, fit_fold, folds=3, seed=1, method="nominal")
    assert seen == [8, 8, 8] and cv.failed_folds == (1,) and cv.method == "nominal"
    ok = cv.fold_of_row != 1
    expected = measured[ok] - robot.forward_kinematics(nominal, joints[ok], initial=measured[ok])
    np.testing.assert_allclose(cv.residuals[ok], expected, rtol=0, atol=WRAP_ROUNDING_RAD)
    assert "fold 2: the fit failed: too few rows for this fold" in cv.message


def test_arguments_are_checked():
    robot, joints, measured = _small_problem("hexapod", 10)
    with pytest.raises(ValueError, match="method must be one of"):
        crossvalidate(robot, joints, measured, NOISE, method="backward")
    with pytest.raises(ValueError, match="fit_kwargs must not set prior"):
        crossvalidate(robot, joints, measured, NOISE, fit_kwargs={"prior": None})
    with pytest.raises(TypeError, match="prior must be a calib.prior.ParameterPrior"):
        crossvalidate(robot, joints, measured, NOISE, prior={"mm": 0.1})
    with pytest.raises(ValueError, match="measured must have shape"):
        crossvalidate(robot, joints, measured[:, :3], NOISE)
    with pytest.raises(ValueError, match="only the forward method"):
        crossvalidate(robot, joints, measured, NOISE, method="chainwise", measurement=MeasurementSettings())
    with pytest.raises(ValueError, match="folds must be an integer"):
        crossvalidate(robot, joints, measured, NOISE, folds=11)


#: Two sessions: calibration rows per session (no validation rows) and, for the truth, held-out rows
#: per session; seeds of the study (the per-seed ratio spreads ~0.07, measured 0.88 to 1.18: the
#: median of 9 is known to ~0.03).
SESSION_ROWS, SESSION_HELDOUT, SESSION_SEEDS = 40, 100, range(9)
SESSION_FOLDS = 10


def _two_session_recording(robot, seed: int):
    """The machine drawn from the default prior (seed), measured in two sessions from
    tests.test_sessions' frames ``F0`` and ``F1`` (50 mm and 0.6 degree apart):
    ``((joints, measured, sessions) of the calibration rows, the same of the held-out rows)``."""
    from tests.test_sessions import F0, F1

    prior = ParameterPrior.default(robot)
    rng = np.random.default_rng(seed)
    theta = robot.table.nominal.copy()
    idx = np.sort(robot.table.indices(robot.free_default))
    theta[idx] += rng.standard_normal(idx.size) * prior.std[idx]
    cal, held = [], []
    for s, frame in enumerate((F0, F1)):
        poses = reachable_poses(robot, SESSION_ROWS + SESSION_HELDOUT, rng, theta=theta)
        q = robot.inverse_kinematics(theta, poses)
        m = instrument_measurements(robot, poses, frame) + NOISE.sample(len(q), rng, robot.pose_units)
        cal.append((q[:SESSION_ROWS], m[:SESSION_ROWS], np.full(SESSION_ROWS, s)))
        held.append((q[SESSION_ROWS:], m[SESSION_ROWS:], np.full(SESSION_HELDOUT, s)))
    return [tuple(np.concatenate(part) for part in zip(*rows)) for rows in (cal, held)]


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_two_sessions_crossvalidated_error_is_the_heldout_error(name):
    """Two sessions, each its own instrument frame, no validation rows: the 10-fold cross-validated
    position RMS (each row predicted in its session's frame) within 20% of the held-out figure of
    the fit to every row, on 100 separate rows of each session, median over 9 seeds."""
    robot = default_robot(name)
    prior = ParameterPrior.default(robot)
    ratios = []
    for seed in SESSION_SEEDS:
        (q, m, s), (qh, mh, sh) = _two_session_recording(robot, seed)
        fit = identify_measured(robot, q, m, NOISE, frame="estimate", prior=prior, sessions=s)
        position, _ = pose_error_norms(robot, mh - fit.predict(qh, sessions=sh))
        cv = crossvalidate(robot, q, m, NOISE, folds=SESSION_FOLDS, prior=prior,
                           measurement=MeasurementSettings(frame="estimate"), sessions=s, seed=seed)
        assert cv.success and cv.rows_predicted == 2 * SESSION_ROWS, cv.message
        ratios.append(cv.position_summary["rms"] / _rms(position))
    median = float(np.median(ratios))
    print(name, "two sessions", round(median, 3), np.round(ratios, 3))
    assert RATIO_BAND[0] <= median <= RATIO_BAND[1], (median, ratios)


def test_each_session_row_is_predicted_in_its_own_frame_by_the_fold_fit():
    """A fold's residuals are the explicit refit's without the fold (identify_measured with the
    training rows' sessions, each session's own settings), predicted in each row's own frame."""
    robot = default_robot("hexapod")
    prior = ParameterPrior.default(robot)
    (q, m, s), _ = _two_session_recording(robot, 4)
    per = [MeasurementSettings(frame="estimate"), MeasurementSettings(frame="auto")]
    cv = crossvalidate(robot, q, m, NOISE, folds=5, prior=prior, measurement=per, sessions=s, seed=1)
    test = cv.fold_of_row == 3
    refit = identify_measured(robot, q[~test], m[~test], NOISE, frame=["estimate", "auto"], initial_frame=[None, None],
                              prior=prior, sessions=s[~test])
    expected = m[test] - refit.predict(q[test], initial=refit.to_base(m[test], sessions=s[test]), sessions=s[test])
    np.testing.assert_allclose(cv.residuals[test], expected, rtol=0, atol=FORWARD_KINEMATICS_TOL_MM)
    assert cv.success and "2 sessions, each row predicted in its own session's instrument frame" in cv.message


def test_a_session_without_training_rows_in_a_fold_is_named_and_the_others_renumbered():
    """Three sessions, session 1 = 6 rows all in fold 2: fold 2's fit has sessions 0 and 2 only
    (renumbered 0, 1); its left-out rows of sessions 0 and 2 are predicted in their own frames,
    as the explicit refit does, and session 1's are NaN, the message says why."""
    robot = default_robot("hexapod")
    prior = ParameterPrior.default(robot)
    (q, m, s), _ = _two_session_recording(robot, 5)
    folds = fold_assignment(len(q), 3, seed=2)
    s = s * 2  # sessions 0 and 2
    lost = np.flatnonzero((folds == 1) & (s == 0))[:6]
    s[lost] = 1  # session 1: the rows of session 0's frame, six of them, all in fold 2
    cv = crossvalidate(robot, q, m, NOISE, folds=3, prior=prior, measurement=MeasurementSettings(frame="estimate"),
                       sessions=s, seed=2)
    assert np.array_equal(cv.fold_of_row, folds) and cv.failed_folds == (1,) and not cv.success
    assert np.all(np.isnan(cv.position_error[lost])) and cv.rows_predicted == len(q) - 6
    assert "fold 2: session 1 kept no training row (no instrument frame fitted): its 6 left-out row(s) cannot be " \
           "predicted" in cv.message and "6 of 80 rows without a prediction" in cv.message
    test = (folds == 1) & (s != 1)
    refit = identify_measured(robot, q[folds != 1], m[folds != 1], NOISE, frame="estimate", prior=prior,
                              sessions=s[folds != 1] // 2)
    own = s[test] // 2
    expected = m[test] - refit.predict(q[test], initial=refit.to_base(m[test], sessions=own), sessions=own)
    np.testing.assert_allclose(cv.residuals[test], expected, rtol=0, atol=FORWARD_KINEMATICS_TOL_MM)


def test_session_arguments_are_checked():
    robot = default_robot("hexapod")
    (q, m, s), _ = _two_session_recording(robot, 6)
    estimate = MeasurementSettings(frame="estimate")
    with pytest.raises(ValueError, match="sessions= needs measurement="):
        crossvalidate(robot, q, m, NOISE, sessions=s)
    with pytest.raises(ValueError, match="needs sessions="):
        crossvalidate(robot, q, m, NOISE, measurement=[estimate, estimate])
    with pytest.raises(ValueError, match="one MeasurementSettings or 2"):
        crossvalidate(robot, q, m, NOISE, measurement=[estimate] * 3, sessions=s)
    with pytest.raises(ValueError, match="session 1's targets differ"):
        crossvalidate(robot, q, m, NOISE, measurement=[estimate, MeasurementSettings(targets=np.zeros((1, 3)))],
                      sessions=s)
    with pytest.raises(ValueError, match="session 1 has no rows"):
        crossvalidate(robot, q, m, NOISE, measurement=estimate, sessions=s * 2)
    with pytest.raises(ValueError, match=r"measurement\[1\].frame must be one of"):
        crossvalidate(robot, q, m, NOISE, measurement=[estimate, MeasurementSettings(frame="tracker")], sessions=s)
    with pytest.raises(ValueError, match="fit_kwargs must not set sessions"):
        crossvalidate(robot, q, m, NOISE, measurement=estimate, fit_kwargs={"sessions": s})
    with pytest.raises(TypeError, match="measurement must be a calib.measurement.MeasurementSettings"):
        crossvalidate(robot, q, m, NOISE, measurement={"frame": "estimate"})


@pytest.mark.parametrize("name", NAMES)
def test_above_the_size_constants_the_default_switches_to_fewer_folds_and_says_why(name, monkeypatch):
    """The forward method's leave-one-out becomes 10-fold above calib.crossval.LOO_MAX_ROWS
    (lowered to 30, 40 rows), and the default becomes FEW_FOLDS-fold above FEW_FOLDS_MIN_ROWS
    (lowered to 100, 200 rows): the scheme names the constant, every row is still predicted, and
    the RMS position error agrees with the exact form's (leave-one-out; the chain-wise 10-fold)
    within the figure's spread. 40 rows of 3 position coordinates know an RMS to
    ~1/sqrt(2 * 40 * 3) = 9 %, 200 rows to 3.6 %, and the two figures share their rows and noise;
    a model fitted to half of 200 rows adds at most P / (100 D) = 11 % (6-RUS: 66 parameters, 6
    coordinates) to the error's variance, 5 % to its RMS: bands of 0.8 to 1.25."""
    import calib.crossval

    robot, joints, measured = _small_problem(name, 40)
    exact = crossvalidate(robot, joints, measured, NOISE)
    assert exact.scheme == "leave-one-out" and "LOO_MAX_ROWS" not in exact.message
    monkeypatch.setattr(calib.crossval, "LOO_MAX_ROWS", 30)
    ten = crossvalidate(robot, joints, measured, NOISE)
    assert ten.scheme == "10-fold (40 rows > LOO_MAX_ROWS = 30)" and ten.fits == 10, ten.scheme
    assert ten.summary()["crossvalidation"]["scheme"] == ten.scheme and ten.message.startswith(ten.scheme)
    assert 0.8 <= ten.position_summary["rms"] / exact.position_summary["rms"] <= 1.25
    assert crossvalidate(robot, joints, measured, NOISE, folds=5).scheme == "5-fold"  # asked: no switch

    robot, joints, measured = _small_problem(name, 200)
    exact = crossvalidate(robot, joints, measured, NOISE, method="chainwise")
    assert exact.scheme == "10-fold"
    monkeypatch.setattr(calib.crossval, "FEW_FOLDS_MIN_ROWS", 100)
    for method in METHODS:
        few = crossvalidate(robot, joints, measured, NOISE, method=method)
        assert few.scheme == "2-fold (200 rows > FEW_FOLDS_MIN_ROWS = 100)" and few.fits == 2, few.scheme
        assert few.success
        ratio = few.position_summary["rms"] / exact.position_summary["rms"]
        assert 0.8 <= ratio <= 1.25, (name, method, ratio)
