import numpy as np
import pytest

from calib.hexapod import paper_hexapod
from calib.metrics import evaluate_compensation, integrated_error
from calib.noise import SensorNoise
from calib.workspace import random_poses


def test_integrated_error_is_eqs_15_to_17():
    dQ = np.array([[3.0, 4.0, 0.0, 0.0, 0.6, 0.8]])
    dQ1, dQ2, dQint = integrated_error(dQ)
    assert dQ1[0] == 5.0 and dQ2[0] == pytest.approx(1.0) and dQint[0] == pytest.approx(6.0)


def test_perfect_identification_leaves_no_error():
    actual = paper_hexapod(with_table3_errors=True)
    ev = evaluate_compensation(actual, actual, random_poses(20, 0))
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
