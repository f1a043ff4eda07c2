import numpy as np
import pytest

from calib.hexapod import paper_hexapod
from calib.kinematics import forward_kinematics, inverse_kinematics
from calib.noise import SensorNoise
from calib.workspace import random_poses
from mjcf.hexapod import HexapodModelOptions
from pipeline.testbed import HexapodTestbed, SettleError

NOMINAL = paper_hexapod()
ACTUAL = paper_hexapod(with_table3_errors=True)


def test_gravity_off_settled_pose_equals_forward_kinematics_on_100_poses():
    commanded = inverse_kinematics(NOMINAL, random_poses(100, 42))
    m = HexapodTestbed(ACTUAL).measure(commanded)
    fk = forward_kinematics(ACTUAL, commanded)
    assert np.abs(m.true_poses[:, :3] - fk[:, :3]).max() < 1e-6  # mm
    assert np.abs(m.true_poses[:, 3:] - fk[:, 3:]).max() < 1e-9  # rad
    np.testing.assert_array_equal(m.measured, m.true_poses)  # no noise declared
    assert np.all(np.diff(m.t_s) > 0)


def test_noise_is_seeded_and_added_to_the_true_pose():
    commanded = inverse_kinematics(NOMINAL, random_poses(5, 1))
    noise = SensorNoise(0.001, 1e-6)
    a = HexapodTestbed(ACTUAL, noise=noise, seed=7).measure(commanded)
    b = HexapodTestbed(ACTUAL, noise=noise, seed=7).measure(commanded)
    c = HexapodTestbed(ACTUAL, noise=noise, seed=8).measure(commanded)
    np.testing.assert_array_equal(a.measured, b.measured)
    assert not np.array_equal(a.measured, c.measured)
    d = a.measured - a.true_poses
    assert np.abs(d[:, :3]).max() <= 0.001 and np.abs(d[:, 3:]).max() <= 1e-6
    assert np.abs(d[:, :3]).max() > 0


def test_gravity_and_payload_make_the_platform_sag():
    commanded = inverse_kinematics(NOMINAL, random_poses(3, 2))
    m = HexapodTestbed(ACTUAL, HexapodModelOptions(gravity=True, payload_kg=5.0)).measure(commanded)
    sag = m.true_poses[:, 2] - forward_kinematics(ACTUAL, commanded)[:, 2]
    # 5 kg + 2 kg platform on six legs of 2e5 N/m: of order 0.1 mm down.
    assert np.all(sag < -0.03) and np.all(sag > -0.3)


def test_step_cap_raises_a_clear_error():
    bed = HexapodTestbed(ACTUAL, max_steps=20)
    commanded = inverse_kinematics(NOMINAL, random_poses(1, 3))
    with pytest.raises(SettleError, match="did not settle within 20 steps"):
        bed.measure(commanded)


def test_bad_commanded_shape():
    with pytest.raises(ValueError, match=r"commanded must have shape \(N, 6\), got \(6,\)"):
        HexapodTestbed(ACTUAL).measure(np.zeros(6))
