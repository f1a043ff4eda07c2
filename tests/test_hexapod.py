"""The hexapod and its paper: tables, Table 4 reproduced, Table 3 recovered by both methods."""

import numpy as np
import pytest

from calib import paper
from calib.engine import identify_chainwise, identify_forward
from calib.metrics import consistency_check
from calib.noise import SensorNoise
from calib.outliers import find_outliers
from calib.robots import paper_hexapod
from calib.robots.hexapod import LEG_PARAMETERS

ROBOT = paper_hexapod()
NOMINAL = ROBOT.table.nominal
ACTUAL = NOMINAL + paper.TABLE3_ERRORS.ravel()


def test_builtin_tables_match_reference_transcription(reference_tables):
    t2 = reference_tables["table2_nominal"]
    np.testing.assert_array_equal(paper.TABLE2_BASE_JOINTS_MM, t2["B"])
    np.testing.assert_array_equal(paper.TABLE2_PLATFORM_JOINTS_MM, t2["P"])
    np.testing.assert_array_equal(paper.TABLE2_HOME_LENGTHS_MM, t2["l"])
    t3 = reference_tables["table3_injected_errors"]
    assert len(t3["columns"]) == len(LEG_PARAMETERS)
    np.testing.assert_array_equal(paper.TABLE3_ERRORS, t3["rows"])
    t4 = reference_tables["table4_poses"]
    np.testing.assert_array_equal(paper.TABLE4_NOMINAL_POSES, t4["nominal_PT"])
    np.testing.assert_array_equal(paper.TABLE4_MEASURED_POSES, t4["measured_PP"])


def test_home_lengths_are_the_inverse_kinematics_of_the_home_pose():
    lengths = ROBOT.inverse_kinematics(NOMINAL, ROBOT.home_pose[None])[0]
    np.testing.assert_allclose(lengths, ROBOT.home_lengths, atol=1e-5)  # Table 2 prints 8 digits


@pytest.mark.parametrize("name,leg,column", [("B1.x", 0, 0), ("dl5", 4, 3), ("P6.z", 5, 6), ("B3.y", 2, 1)])
def test_parameter_names_address_the_paper_table3_layout(name, leg, column):
    assert ROBOT.table.index(name) == leg * 7 + column
    assert (ACTUAL - NOMINAL)[ROBOT.table.index(name)] == pytest.approx(paper.TABLE3_ERRORS[leg, column], abs=1e-12)


def test_leg_offset_is_additive():
    """Commanding length l makes leg i l + dl_i long."""
    theta = NOMINAL.copy()
    theta[ROBOT.table.index("dl2")] = 0.5
    lengths = ROBOT.inverse_kinematics(theta, ROBOT.home_pose[None])[0]
    np.testing.assert_allclose(ROBOT.home_lengths - lengths, [0, 0.5, 0, 0, 0, 0], atol=1e-5)


def test_table4_reproduced_and_row_a2_flagged():
    """Table 4: actual poses = FK(Table 2 + Table 3) at the nominal IK lengths of the targets."""
    commanded = ROBOT.inverse_kinematics(NOMINAL, paper.TABLE4_NOMINAL_POSES)
    check = consistency_check(ROBOT, ACTUAL, commanded, paper.TABLE4_MEASURED_POSES, tol_mm=1e-4, tol_rad=3e-5)
    assert check.flagged == [1]  # row A2 (index 1) is inconsistent with the model
    ok = np.delete(np.arange(10), 1)
    assert check.position_deviation[ok].max() < 1e-4
    assert check.orientation_deviation[ok].max() < 3e-5
    assert check.position_deviation[1] > 0.01 and check.orientation_deviation[1] > 1e-4


def test_find_outliers_flags_a2_alone_at_the_print_resolution():
    commanded = ROBOT.inverse_kinematics(NOMINAL, paper.TABLE4_NOMINAL_POSES)
    report = find_outliers(ROBOT, commanded, paper.TABLE4_MEASURED_POSES, SensorNoise(1e-4, 3e-5))
    assert report.flagged == (1,)


def _paper_data():
    commanded = ROBOT.inverse_kinematics(NOMINAL, paper.TABLE4_NOMINAL_POSES)
    return commanded, ROBOT.forward_kinematics(ACTUAL, commanded, initial=paper.TABLE4_NOMINAL_POSES)


def test_paper_method_recovers_table3_noise_free_in_two_iterations():
    commanded, measured = _paper_data()
    fit = identify_chainwise(ROBOT, commanded, measured, SensorNoise(paper.PAPER_NOISE_MM), epsilon=paper.PAPER_EPSILON)
    assert fit.success and "paper's criterion met" in fit.message
    assert fit.iterations == 2
    assert np.abs(fit.errors - paper.TABLE3_ERRORS.ravel()).max() < 1e-9
    assert fit.condition_numbers.shape == (6,)


def test_forward_method_recovers_table3_noise_free():
    commanded, measured = _paper_data()
    fit = identify_forward(ROBOT, commanded, measured, SensorNoise(paper.PAPER_NOISE_MM))
    assert fit.success
    assert np.abs(fit.errors - paper.TABLE3_ERRORS.ravel()).max() < 1e-9


def test_noisy_stop_message_tells_whether_the_residual_is_at_the_noise():
    commanded, measured = _paper_data()
    noise = SensorNoise(paper.PAPER_NOISE_MM)
    noisy = measured + noise.sample(10, 0)
    fit = identify_chainwise(ROBOT, commanded, noisy, noise)
    assert "step_tol" in fit.message and "at the declared noise" in fit.message
    bad = measured + SensorNoise(100 * paper.PAPER_NOISE_MM).sample(10, 0)
    fit = identify_forward(ROBOT, commanded, bad, noise)
    assert "does not fit" in fit.message


def test_identification_validates_its_arguments():
    commanded, measured = _paper_data()
    noise = SensorNoise(paper.PAPER_NOISE_MM)
    with pytest.raises(ValueError, match=r"measured must have shape \(N, 6\)"):
        identify_forward(ROBOT, commanded, measured[:, :5], noise)
    with pytest.raises(ValueError, match="same number of rows"):
        identify_forward(ROBOT, commanded[:9], measured, noise)
    with pytest.raises(ValueError, match="at least 7 rows"):
        identify_chainwise(ROBOT, commanded[:6], measured[:6], noise)
    with pytest.raises(KeyError, match="unknown parameter"):
        identify_forward(ROBOT, commanded, measured, noise, free=["B9.q"])
    with pytest.raises(TypeError, match="noise must be a SensorNoise"):
        identify_forward(ROBOT, commanded, measured, 0.001)


def test_chainwise_corrected_poses_are_the_forward_kinematics_from_the_measured_poses():
    """The Gauss-Newton loop starts the forward kinematics one Newton step ahead (reusing the
    closure Jacobians it has computed): the corrected poses must be those from the measured poses."""
    commanded, measured = _paper_data()
    noise = SensorNoise(paper.PAPER_NOISE_MM)
    noisy = measured + noise.sample(10, 0)
    fit = identify_chainwise(ROBOT, commanded, noisy, noise)
    direct = ROBOT.forward_kinematics(fit.theta, commanded, initial=noisy)
    np.testing.assert_allclose(fit.pose_residuals, noisy - direct, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fit.residuals, ROBOT.closure(fit.theta, commanded, noisy), rtol=0, atol=0)


def test_chainwise_noisy_stop_leaves_the_negligible_update_untaken():
    """With noisy data the loop stops when the next update is below step_tol, without taking it:
    restarted from its answer, the fit takes no step and returns the same vector and residuals."""
    commanded, measured = _paper_data()
    noise = SensorNoise(paper.PAPER_NOISE_MM)
    noisy = measured + noise.sample(10, 0)
    fit = identify_chainwise(ROBOT, commanded, noisy, noise)
    assert fit.success and "not taken" in fit.message
    again = identify_chainwise(ROBOT, commanded, noisy, noise, start=fit.theta)
    assert again.success and again.iterations == 0 and "not taken" in again.message
    np.testing.assert_array_equal(again.theta, fit.theta)
    np.testing.assert_array_equal(again.residuals, fit.residuals)
    assert again.history == (fit.history[-1],)
    # one more iteration with a tighter step_tol moves the answer by less than step_tol
    tighter = identify_chainwise(ROBOT, commanded, noisy, noise, start=fit.theta, step_tol=0.0, max_iter=1)
    assert tighter.iterations == 1
    assert 0 < np.abs(tighter.theta - fit.theta).max() <= 1e-10


def test_chainwise_history_is_the_integrated_error_and_its_last_entry_exact():
    """Each iteration's max dQint comes from one Newton step of the forward kinematics (second
    order); the entry on which the loop stops is the corrected model's forward kinematics."""
    commanded, measured = _paper_data()
    noise = SensorNoise(paper.PAPER_NOISE_MM)
    noisy = measured + noise.sample(10, 0)
    fit = identify_chainwise(ROBOT, commanded, noisy, noise)
    from calib.engine import integrated_error

    exact = integrated_error(ROBOT, fit.pose_residuals)[2].max()
    assert fit.history[-1] == exact
    # the second-order entries: within (1 um)^2 / 100 mm of the exact ones
    steps = [identify_chainwise(ROBOT, commanded, noisy, noise, max_iter=k) for k in range(1, fit.iterations)]
    for k, partial in enumerate(steps):
        exact_k = integrated_error(ROBOT, partial.pose_residuals)[2].max()
        assert abs(fit.history[k] - exact_k) < 1e-6 * max(exact_k, 1e-3)


def test_chainwise_rank_deficient_chain_gets_the_minimum_norm_step():
    """At constant orientation a leg's B and P enter only as P - B: each chain's system is rank
    deficient; the step is LAPACK's minimum-norm least squares, not a blown-up normal equation."""
    from calib.workspace import reachable_poses

    targets = reachable_poses(ROBOT, 30, np.random.default_rng(5))
    targets[:, 3:] = 0.0
    joints = ROBOT.inverse_kinematics(ACTUAL, targets)
    fit = identify_chainwise(ROBOT, joints, targets, SensorNoise(paper.PAPER_NOISE_MM), max_iter=3)
    assert np.all(np.isfinite(fit.theta))
    assert np.abs(fit.residuals).max() < 1e-9
    t, tn = fit.theta.reshape(6, 7), NOMINAL.reshape(6, 7)
    # P - B and the offsets' combination are identified; the minimum-norm step splits the rest evenly
    true = ACTUAL.reshape(6, 7)
    np.testing.assert_allclose(t[:, 4:7] - t[:, 0:3], true[:, 4:7] - true[:, 0:3], atol=1e-6)
    np.testing.assert_allclose((t - tn)[:, 4:7], -(t - tn)[:, 0:3], atol=1e-6)


def _two_hundred_poses(seed=3):
    from calib.workspace import reachable_poses

    targets = reachable_poses(ROBOT, 200, np.random.default_rng(seed))
    joints = ROBOT.inverse_kinematics(NOMINAL, targets)
    return targets, joints, ROBOT.forward_kinematics(ACTUAL, joints, initial=targets)


def test_outlier_test_is_closed_form_fast_and_finds_gross_rows_among_200():
    import time

    targets, joints, measured = _two_hundred_poses()
    noise = SensorNoise(0.001, 1e-6, "normal")
    noisy = measured + noise.sample(200, 1)
    noisy[[5, 50, 150], :3] += [0.02, -0.02, 0.0]
    t = time.perf_counter()
    report = find_outliers(ROBOT, joints, noisy, noise)
    elapsed = time.perf_counter() - t
    assert report.flagged == (5, 50, 150) and not report.misfit
    assert elapsed < 1.0, elapsed


def test_real_model_misfit_is_reported_as_misfit_not_a_list_of_rows():
    """An unmodelled effect 20 times the noise (a sag growing with the distance from the axis)."""
    import time

    targets, joints, measured = _two_hundred_poses()
    noise = SensorNoise(0.001, 1e-6, "normal")
    r2 = targets[:, 0] ** 2 + targets[:, 1] ** 2
    sag = 20 * 0.001 * (2 * r2 / r2.max() - 1)
    data = measured + noise.sample(200, 1)
    data[:, 2] += sag
    t = time.perf_counter()
    report = find_outliers(ROBOT, joints, data, noise)
    elapsed = time.perf_counter() - t
    assert report.misfit and len(report.flagged) <= 10  # at most 5% of the rows: none
    assert "model misfit" in report.verdict and "no row is left out" in report.verdict
    assert elapsed < 1.0, elapsed


@pytest.mark.parametrize("method,options", [("chainwise", {}), ("chainwise", {"solver": "lm"}),
                                            ("chainwise", {"weighted": True}), ("forward", {}),
                                            ("forward", {"solver": "gn", "max_iter": 2}),
                                            ("chainwise", {"max_iter": 1})])
def test_every_method_says_when_the_residual_is_far_above_the_declared_noise(method, options):
    """Noise 100 times the declared: every method, converged or not, says the model does not fit."""
    from calib.engine import identify

    commanded, measured = _paper_data()
    bad = measured + SensorNoise(100 * paper.PAPER_NOISE_MM).sample(10, 0)
    fit = identify(ROBOT, commanded, bad, SensorNoise(paper.PAPER_NOISE_MM), method=method, **options)
    assert "does not fit to the declared noise" in fit.message and "at the declared noise" not in fit.message
    good = identify(ROBOT, commanded, measured + SensorNoise(paper.PAPER_NOISE_MM).sample(10, 0),
                    SensorNoise(paper.PAPER_NOISE_MM), method=method, **options)
    assert "does not fit" not in good.message or not good.success
