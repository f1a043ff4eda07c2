"""The identification policy in one call (calib.identification.calibrate), on arrays: no file, no
simulator, no pipeline. Kinematic simulation: a machine with the robot's reference errors
injected, measured at reachable poses with 1 um / 1 urad normal noise; the independent truths are
the injected errors (mapped to the fit's gauge, calib.engine.gauge_representative: the same
kinematics), the row spoiled, the frame the poses were seen from, and the noise declared."""

import numpy as np
import pytest

from calib.calibration import Calibration
from calib.engine import gauge_representative
from calib.identification import (BASE_FRAME, CalibrationOutcome, GrossSearch, Misprediction, UnreachableRows,
                                  calibrate, calibrate_checked, checked_data, checked_options)
from calib.measurement import MeasurementSettings, instrument_measurements
from calib.noise import SensorNoise
from calib.robots import default_robot, reference_errors
from calib.workspace import reachable_poses

NOISE = SensorNoise(1e-3, 1e-6, "normal")
#: Calibration and validation rows of every test machine.
ROWS, VALIDATION = 60, 20
#: The row spoiled: its z 5 mm off (a tracker that lost the target), 5000 noise standard deviations.
GROSS_ROW = 17
#: An instrument frame 300 mm away, turned 0.3 rad about (1, -1, 2) / sqrt(6).
FRAME = np.r_[100.0, 200.0, 200.0, 0.12, -0.15, 0.2]
#: Standard deviations within which an estimate must lie of its truth: a 5-sigma band, a false
#: alarm every 1.7 million parameters for a correct fit and uncertainty.
SIGMAS = 5.0


def machine(name: str, seed: int = 1):
    """``(robot, theta, calibration joints, measured, validation joints, validation measured)``:
    the robot with its reference errors injected (``theta``), measured at ROWS + VALIDATION
    reachable poses with NOISE."""
    robot = default_robot(name)
    theta = robot.table.nominal + reference_errors(robot, seed)
    rng = np.random.default_rng(seed)
    poses = reachable_poses(robot, ROWS + VALIDATION, rng, theta=theta)
    joints = robot.inverse_kinematics(theta, poses)
    measured = poses + NOISE.sample(len(poses), rng, robot.pose_units)
    return robot, theta, joints[:ROWS], measured[:ROWS], joints[ROWS:], measured[ROWS:]


@pytest.fixture(scope="module", params=["hexapod", "delta"])
def spoiled(request):
    """A machine's rows with GROSS_ROW spoiled, calibrated with its validation rows (data rows
    numbered from 100, so that a row's number is not its index)."""
    robot, theta, q, m, qv, mv = machine(request.param)
    m = m.copy()
    m[GROSS_ROW, 2] += 5.0
    outcome = calibrate(robot, q, m, NOISE, validation_joints=qv, validation_measured=mv,
                        rows=np.arange(ROWS) + 100, t_s=np.arange(ROWS) * 0.5)
    return robot, theta, outcome


def test_the_gross_row_is_named_and_left_out(spoiled):
    _, _, outcome = spoiled
    ident = outcome.identification
    assert isinstance(outcome, CalibrationOutcome)
    assert ident.gross_idx == [GROSS_ROW] and ident.flagged_idx == [GROSS_ROW]
    assert GROSS_ROW not in ident.used and ident.used.size == ROWS - 1
    assert outcome.data.rows[ident.gross_idx].tolist() == [100 + GROSS_ROW]


def test_the_injected_errors_are_recovered_within_the_fits_uncertainty(spoiled):
    robot, theta, outcome = spoiled
    result = outcome.result
    truth = gauge_representative(robot, theta, result.start)
    idx = robot.table.indices(result.free_names)
    z = (result.theta - truth)[idx] / result.std[idx]
    assert np.all(np.abs(z) <= SIGMAS), dict(zip(np.array(result.free_names)[np.abs(z) > SIGMAS], z[np.abs(z) > SIGMAS]))
    # the injected errors are beyond the band: the check fails a fit that stayed at the nominal geometry
    moved = np.abs((truth - robot.table.nominal)[idx]) / result.std[idx]
    assert np.max(moved) > 2 * SIGMAS


def test_the_verdict_is_a_success_and_the_validation_rows_are_predicted_to_the_noise(spoiled):
    robot, _, outcome = spoiled
    verdict = outcome.verdict
    assert verdict.success and verdict.cause is None, verdict
    assert verdict.evidence.predictions.what == "validation rows" and verdict.evidence.predictions.agrees
    before, after = outcome.heldout
    assert before.shape == after.shape == (VALIDATION, robot.pose_dim)
    position = ~robot.angle_pose_mask
    rms_after = np.sqrt(np.mean(np.sum(after[:, position] ** 2, axis=1)))
    rms_before = np.sqrt(np.mean(np.sum(before[:, position] ** 2, axis=1)))
    noise_rms = np.sqrt(position.sum()) * 1e-3  # the noise of the position coordinates, mm
    # 20 rows know an RMS to ~1 / sqrt(2 * 20 * 3) = 9 %; the model's own error adds a few per cent
    assert 0.7 * noise_rms <= rms_after <= 1.4 * noise_rms, (rms_after, noise_rms)
    assert rms_before > 20 * rms_after
    assert outcome.crossvalidation is None  # held out: nothing to cross-validate


def test_the_calibration_holds_the_fit_and_the_rows_domain(spoiled):
    robot, _, outcome = spoiled
    cal, result, used = outcome.calibration, outcome.result, outcome.identification.used
    assert isinstance(cal, Calibration) and cal.robot is robot
    np.testing.assert_array_equal(cal.theta, result.theta)
    idx = robot.table.indices(cal.free)
    np.testing.assert_array_equal(cal.covariance, result.covariance[np.ix_(idx, idx)])
    assert cal.frames == {} and cal.targets is None and cal.noise == NOISE
    assert cal.validity["t_s"] == [float(used.min()) * 0.5, float(used.max()) * 0.5]


@pytest.mark.parametrize("name", ["hexapod", "delta"])
def test_noise_declared_ten_times_too_small_is_a_failed_verdict_returned(name):
    """Every row is about 10 times the declared noise off the model: a failure, returned with its
    cause and its figure (the whitened RMS residual about 10): most rows misfit, so the gross-row
    search names none; without the search, physics left out (or noise declared too small)."""
    robot, _, q, m, qv, mv = machine(name, seed=2)
    declared = SensorNoise(1e-4, 1e-7, "normal")
    searched = calibrate(robot, q, m, declared, validation_joints=qv, validation_measured=mv)
    assert not searched.verdict.success and searched.verdict.cause == "model_misfit", searched.verdict
    found = searched.verdict.detail  # typed: the rows beyond the noise of those searched
    assert isinstance(found, GrossSearch) and found.rows == ROWS and 2 * found.beyond > ROWS, found
    assert searched.identification.gross_idx == [] and searched.identification.used.size == ROWS
    plain = calibrate(robot, q, m, declared, validation_joints=qv, validation_measured=mv, search_gross_rows=False)
    verdict = plain.verdict
    assert not verdict.success and verdict.cause == "left_out_physics", verdict
    assert 7.0 <= verdict.evidence.fit_ratio <= 13.0, verdict.evidence
    assert verdict.detail == Misprediction(what="calibration rows", ratio=verdict.evidence.fit_ratio,
                                           where=plain.data.where), verdict.detail
    assert plain.calibration is not None and searched.calibration is not None


def test_without_validation_rows_the_rows_are_crossvalidated():
    robot, _, q, m, _, _ = machine("delta", seed=3)
    outcome = calibrate(robot, q, m, NOISE, method="forward")
    cv = outcome.crossvalidation
    assert cv is not None and outcome.heldout is None
    assert outcome.verdict.success, outcome.verdict
    assert outcome.verdict.evidence.predictions.what == f"cross-validation ({cv.scheme})"
    # the model exact, a row's prediction error is its noise (sqrt(3) um) and the fold model's (a few %)
    ratio = cv.summary()["crossvalidated_position_error_mm"]["rms"] / (np.sqrt(3) * 1e-3)
    assert 0.8 <= ratio <= 1.3, ratio


def test_an_instrument_frame_is_recovered_within_its_uncertainty():
    """The hexapod's rows seen from FRAME, the frame estimated with the geometry: FRAME within its
    standard uncertainty's band, the validation rows predicted in the instrument frame, and the
    calibration names the frame under the session's name."""
    robot, theta, q, m, qv, mv = machine("hexapod", seed=4)
    seen, seen_v = (instrument_measurements(robot, p, FRAME) for p in (m, mv))
    outcome = calibrate(robot, q, seen, NOISE, measurement=MeasurementSettings(frame="estimate"),
                        session_names=["lab"], validation_joints=qv, validation_measured=seen_v)
    fit = outcome.identification.instrument
    assert fit is not None and fit.frame_estimated
    assert np.all(np.abs(fit.frame - FRAME) <= SIGMAS * fit.frame_std + 1e-12), (fit.frame - FRAME) / fit.frame_std
    assert outcome.verdict.success, outcome.verdict
    assert set(outcome.calibration.frames) == {"lab"}
    np.testing.assert_array_equal(outcome.calibration.frames["lab"], fit.frame)


def test_heldout_errors_measured_by_the_caller_are_taken_as_given():
    """A caller that measures held-out errors itself (a simulated machine) gets them back, and no
    prediction check is made of them (they are truths, not predictions of measured rows)."""
    robot, _, q, m, _, _ = machine("delta", seed=5)
    seen = []

    def heldout(theta):
        seen.append(np.array(theta))
        return np.zeros((3, robot.pose_dim)), np.zeros((3, robot.pose_dim))

    outcome = calibrate(robot, q, m, NOISE, heldout=heldout, search_gross_rows=False, cross_validate=False)
    assert len(seen) == 1 and np.array_equal(seen[0], outcome.result.theta)
    assert outcome.heldout[0].shape == (3, robot.pose_dim) and outcome.crossvalidation is None
    assert outcome.verdict.evidence.predictions is None and outcome.identification.gross is None


def test_assess_false_stops_after_the_identification():
    robot, _, q, m, qv, mv = machine("delta", seed=6)
    outcome = calibrate(robot, q, m, NOISE, validation_joints=qv, validation_measured=mv, assess=False)
    assert outcome.identification.result.success
    assert outcome.verdict is None and outcome.calibration is None and outcome.heldout is None


def test_a_row_the_model_cannot_reach_is_named_by_the_callers_number():
    robot, _, q, m, qv, mv = machine("hexapod", seed=7)
    qv = qv.copy()
    qv[4, 0] *= 10.0  # leg 1 ten times its length, the others as measured: no pose
    with pytest.raises(UnreachableRows) as err:
        calibrate(robot, q, m, NOISE, validation_joints=qv, validation_measured=mv,
                  validation_rows=np.arange(VALIDATION) + 500)
    assert int(err.value.rows[err.value.kinematics.index]) == 504 and "row 505" in str(err.value)


#: ``(arguments changed, the name the refusal gives)``: a bad argument of calibrate each.
BAD_ARGUMENTS = [
    ({"joints": np.zeros((5, 2))}, "joints"),
    ({"measured": np.zeros((ROWS, 2))}, "measured"),
    ({"method": "newton"}, "method"),
    ({"solver": "bfgs"}, "solver"),
    ({"validation_joints": np.zeros((3, 3))}, "validation_joints and validation_measured"),
    ({"sessions": np.zeros(ROWS)}, "sessions"),
    ({"measurement": [MeasurementSettings(), MeasurementSettings()], "sessions": np.r_[np.zeros(ROWS - 1), 5]},
     "sessions"),
    ({"session_names": ["a", "b"]}, "session_names"),
    ({"rows": np.arange(ROWS) + 0.5}, "rows"),
    ({"t_s": np.full(ROWS, np.nan)}, "t_s"),
    ({"seed": 1.5}, "seed"),
    ({"validation_joints": np.zeros((3, 3)), "validation_measured": np.zeros((3, 3)),
      "validation_sessions": [0, BASE_FRAME, 0]}, "validation_sessions"),
]


@pytest.mark.parametrize("change, named", BAD_ARGUMENTS)
def test_a_bad_argument_is_refused_by_name(change, named):
    robot, _, q, m, _, _ = machine("delta", seed=8)
    args = {"joints": q, "measured": m} | change
    q, m = args.pop("joints"), args.pop("measured")
    with pytest.raises(ValueError, match=named):
        calibrate(robot, q, m, NOISE, **args)


#: The arguments of calibrate that checked_options takes; the others but heldout, diagnosis and
#: assess are checked_data's.
OPTION_ARGUMENTS = ("method", "solver", "weighted", "keep_outliers", "search_gross_rows", "cross_validate", "seed")


@pytest.mark.parametrize("change, named", BAD_ARGUMENTS)
def test_the_data_and_options_checks_refuse_in_calibrates_words(change, named):
    """A caller that checks the data and the options apart (pipeline, when it reads a recording)
    is refused in the words calibrate uses."""
    robot, _, q, m, _, _ = machine("delta", seed=8)
    args = {"joints": q, "measured": m} | change
    q, m = args.pop("joints"), args.pop("measured")
    with pytest.raises(ValueError) as whole:
        calibrate(robot, q, m, NOISE, **args)
    options = {k: v for k, v in args.items() if k in OPTION_ARGUMENTS}
    with pytest.raises(ValueError) as apart:
        checked_data(robot, q, m, NOISE, **{k: v for k, v in args.items() if k not in OPTION_ARGUMENTS})
        checked_options(**options)
    assert str(apart.value) == str(whole.value) and named in str(apart.value)


def test_data_and_options_checked_apart_calibrate_as_calibrate_does():
    """checked_data and checked_options, given calibrate's arguments, make the fit calibrate makes,
    to the bit (one code path)."""
    robot, _, q, m, qv, mv = machine("hexapod", seed=9)
    rows = np.arange(ROWS) + 100
    whole = calibrate(robot, q, m, NOISE, validation_joints=qv, validation_measured=mv, rows=rows, seed=3,
                      search_gross_rows=False)
    data = checked_data(robot, q, m, NOISE, validation_joints=qv, validation_measured=mv, rows=rows)
    apart = calibrate_checked(data, checked_options(seed=3, search_gross_rows=False))
    assert np.array_equal(apart.result.theta, whole.result.theta)
    assert np.array_equal(apart.heldout[1], whole.heldout[1]) and apart.verdict.success == whole.verdict.success
    np.testing.assert_array_equal(apart.data.validation_rows, whole.data.validation_rows)


def test_a_wrong_type_is_refused_by_name():
    robot, _, q, m, _, _ = machine("delta", seed=8)
    with pytest.raises(TypeError, match="noise"):
        calibrate(robot, q, m, 0.001)
    with pytest.raises(TypeError, match="tolerance"):
        calibrate(robot, q, m, NOISE, tolerance={"mm": 0.1})


def test_above_the_size_the_prediction_check_takes_the_jacobians_chain_factors(monkeypatch):
    """The hexapod's 20 validation rows judged with calib.outliers.STRUCTURED_JACOBIAN_MIN_ROWS
    lowered to 10: ``J Sigma J^T`` through the Jacobian's chain factors (``form`` says so), the
    same verdict, and the whitened ratio that of the check computed here with ``J Sigma J^T`` in
    extended precision (``numpy.longdouble``, independent of both forms), as the dense form's is.
    Bound: 100 P eps relative (9e-13). The noise dominates each row's covariance (``J Sigma
    J^T`` is about P/N of it), so the ratio carries the rounding of the products' sums, P terms
    each, not the ``|J_j|^2 |Sigma|`` of a gauge-like direction the fit's prior holds (Sigma
    large where J nearly cancels it: measured 4e-14 dense, 1e-13 factored; the covariance's
    eigen-factor, as the outlier test's hat blocks take it, measured 4e-8 here and fails).
    """
    import calib.outliers
    from calib.robot import pose_jacobian_of_parameters

    robot, _, q, m, qv, mv = machine("hexapod", seed=4)
    outcome = calibrate(robot, q, m, NOISE, validation_joints=qv, validation_measured=mv)
    dense = outcome.verdict.evidence.predictions
    assert dense.factored_rows is None and "form" not in dense.to_dict()
    monkeypatch.setattr(calib.outliers, "STRUCTURED_JACOBIAN_MIN_ROWS", 10)
    fast = calibrate(robot, q, m, NOISE, validation_joints=qv, validation_measured=mv).verdict.evidence.predictions
    assert fast.to_dict()["form"] == ("J Sigma J^T through the Jacobian's chain factors (20 rows > "
                                      "STRUCTURED_JACOBIAN_MIN_ROWS = 10)")
    assert fast.factored_rows == 20 and fast.agrees == dense.agrees and fast.rows == dense.rows == VALIDATION
    result = outcome.result
    J = pose_jacobian_of_parameters(robot, result.theta, qv, mv)
    Jl, Sl = J.astype(np.longdouble), result.covariance.astype(np.longdouble)
    cov = np.einsum("nip,pq,njq->nij", Jl, Sl, Jl) + np.diag(NOISE.pose_std(robot.pose_units) ** 2).astype(np.longdouble)
    after = outcome.heldout[1]
    chi2 = sum(float(np.asarray(np.linalg.solve(cov[j].astype(float), after[j]) @ after[j])) for j in range(VALIDATION))
    truth = np.sqrt(chi2 / after.size)
    bound = 100 * J.shape[2] * np.finfo(float).eps
    for check in (dense, fast):
        assert abs(check.ratio - truth) <= bound * truth, (check.ratio, truth, bound)
