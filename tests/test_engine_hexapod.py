"""The engine on the hexapod paper's data: Table 3 recovered by both methods, truthful stop messages."""

import numpy as np
import pytest

from calib import paper
from calib.engine import identify_chainwise, identify_forward
from calib.noise import SensorNoise
from calib.robots import paper_hexapod
from calib.robots.hexapod import LEG_PARAMETERS

ROBOT = paper_hexapod()
NOMINAL = ROBOT.table.nominal
ACTUAL = NOMINAL + paper.TABLE3_ERRORS.ravel()


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
