import numpy as np
import pytest

from calib import paper
from calib.engine import integrated_error
from calib.metrics import calibration_gain, evaluate_compensation
from calib.noise import SensorNoise
from calib.robots import Delta, paper_hexapod
from calib.workspace import reachable_poses

ROBOT = paper_hexapod()


def test_integrated_error_is_eqs_15_to_17():
    dQ = np.array([[3.0, 4.0, 0.0, 0.0, 0.6, 0.8]])
    dQ1, dQ2, dQint = integrated_error(ROBOT, dQ)
    assert dQ1[0] == 5.0 and dQ2[0] == pytest.approx(1.0) and dQint[0] == pytest.approx(6.0)


def test_calibration_gain_mean_and_norm():
    robot = Delta()
    nominal = robot.table.nominal
    true = nominal.copy()
    true[robot.table.index("D1.x")] += 1.0
    true[robot.table.index("theta2")] += np.deg2rad(1.0)
    half = nominal + 0.5 * (true - nominal)
    gain = calibration_gain(robot, true, nominal, half, names=["D1.x", "theta2", "Lb3"])
    assert gain.per_parameter[:2] == pytest.approx([50.0, 50.0])
    assert np.isnan(gain.per_parameter[2])  # no initial error on Lb3
    assert gain.mean == pytest.approx(50.0) and gain.norm == pytest.approx(50.0)


def test_perfect_identification_leaves_no_error():
    actual = ROBOT.table.nominal + paper.TABLE3_ERRORS.ravel()
    ev = evaluate_compensation(ROBOT, actual, actual, reachable_poses(ROBOT, 20, 0))
    assert ev.position_after.max() < 1e-9 and ev.orientation_after.max() < 1e-12
    assert ev.position_before.mean() > 0.02  # Table 3 errors are tens of micrometres


@pytest.mark.parametrize("distribution,expected_std", [("uniform", 1 / np.sqrt(3)), ("normal", 1.0)])
def test_noise_is_seeded_and_has_the_declared_std(distribution, expected_std):
    n = SensorNoise(1.0, 2.0, distribution)
    a, b = n.sample(20000, 3), n.sample(20000, 3)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(a.std(axis=0), n.std, rtol=0.03)
    assert n.std[0] == pytest.approx(expected_std)


@pytest.mark.parametrize("kw,match", [
    (dict(position_mm=-1.0), "position_mm must be finite and >= 0"),
    (dict(orientation_rad=np.nan), "orientation_rad must be finite and >= 0"),
    (dict(distribution="cauchy"), "distribution must be one of"),
])
def test_noise_validation(kw, match):
    with pytest.raises(ValueError, match=match):
        SensorNoise(**kw)
