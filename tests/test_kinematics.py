import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calib import paper
from calib.hexapod import paper_hexapod
from calib.kinematics import (
    KinematicsError,
    forward_kinematics,
    forward_parameter_jacobian,
    inverse_kinematics,
    leg_vectors,
    parameter_jacobian,
    pose_jacobian,
)
from calib.metrics import consistency_check
from calib.workspace import random_poses

ACTUAL = paper_hexapod(with_table3_errors=True)
NOMINAL = paper_hexapod()
# A larger workspace than the paper's to exercise the kinematics away from small angles.
WIDE = np.array([[-25, 25], [-25, 25], [190, 215], [-0.1, 0.1], [-0.1, 0.1], [-0.15, 0.15]], dtype=float)


def test_leg_vectors_close_the_loop():
    poses = random_poses(5, 0)
    L = leg_vectors(ACTUAL, poses)
    from calib.rotation import rotation_matrix
    R = rotation_matrix(poses[:, 3:])
    expected = np.einsum("nij,lj->nli", R, ACTUAL.platform_joints) + poses[:, None, :3] - ACTUAL.base_joints
    np.testing.assert_allclose(L, expected)
    np.testing.assert_allclose(inverse_kinematics(ACTUAL, poses), np.linalg.norm(L, axis=2) - ACTUAL.leg_offsets)


def test_pose_jacobian_against_finite_differences():
    poses = random_poses(20, 1, WIDE)
    J = pose_jacobian(ACTUAL, poses)
    for k in range(6):
        h = 1e-5 if k < 3 else 1e-7
        e = np.zeros(6)
        e[k] = h
        fd = (inverse_kinematics(ACTUAL, poses + e) - inverse_kinematics(ACTUAL, poses - e)) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, rtol=1e-6, atol=1e-7)


def test_parameter_jacobian_against_finite_differences():
    poses = random_poses(15, 2, WIDE)
    J = parameter_jacobian(ACTUAL, poses)
    h = 1e-5
    for p in range(42):
        e = np.zeros(42)
        e[p] = h
        fd = (inverse_kinematics(ACTUAL.with_errors(ACTUAL.vector + e), poses)
              - inverse_kinematics(ACTUAL.with_errors(ACTUAL.vector - e), poses)) / (2 * h)
        leg, k = divmod(p, 7)
        np.testing.assert_allclose(J[:, leg, k], fd[:, leg], atol=1e-8)
        others = np.delete(fd, leg, axis=1)
        assert np.abs(others).max() < 1e-12  # each leg depends on its own 7 errors only


def test_forward_parameter_jacobian_against_finite_differences_through_fk():
    lengths = inverse_kinematics(NOMINAL, random_poses(6, 3, WIDE))
    poses = forward_kinematics(ACTUAL, lengths)
    J = forward_parameter_jacobian(ACTUAL, poses)
    h = 1e-5
    for p in range(0, 42, 5):
        e = np.zeros(42)
        e[p] = h
        fd = (forward_kinematics(ACTUAL.with_errors(ACTUAL.vector + e), lengths)
              - forward_kinematics(ACTUAL.with_errors(ACTUAL.vector - e), lengths)) / (2 * h)
        np.testing.assert_allclose(J[:, :, p], fd, atol=1e-8)


pose_strategy = st.tuples(*[st.floats(lo, hi, allow_nan=False) for lo, hi in WIDE])


@settings(max_examples=200, deadline=None)
@given(pose=pose_strategy)
def test_ik_fk_round_trip_property(pose):
    pose = np.array([pose])
    lengths = inverse_kinematics(ACTUAL, pose)
    back = forward_kinematics(ACTUAL, lengths)
    np.testing.assert_allclose(back[:, :3], pose[:, :3], atol=1e-9)
    np.testing.assert_allclose(back[:, 3:], pose[:, 3:], atol=1e-11)


def test_fk_ik_round_trip_vectorised():
    lengths = inverse_kinematics(NOMINAL, random_poses(500, 4, WIDE))
    poses = forward_kinematics(ACTUAL, lengths)
    np.testing.assert_allclose(inverse_kinematics(ACTUAL, poses), lengths, atol=1e-10)


def test_table4_reproduced_and_row_a2_flagged():
    """Table 4: actual poses = FK(Table 2 + Table 3) at the nominal IK lengths of the targets."""
    commanded = inverse_kinematics(NOMINAL, paper.TABLE4_NOMINAL_POSES)
    check = consistency_check(ACTUAL, commanded, paper.TABLE4_MEASURED_POSES, tol_mm=1e-4, tol_rad=3e-5)
    assert check.flagged == [1]  # row A2 (index 1) is inconsistent with the model
    ok = np.delete(np.arange(10), 1)
    assert check.position_deviation[ok].max() < 1e-4
    assert check.orientation_deviation[ok].max() < 3e-5
    assert check.position_deviation[1] > 0.01 and check.orientation_deviation[1] > 1e-4


@pytest.mark.parametrize("poses,match", [
    (np.zeros(6), r"poses must have shape \(N, 6\), got \(6,\)"),
    (np.zeros((3, 5)), r"poses must have shape \(N, 6\), got \(3, 5\)"),
    (np.array([[0, 0, 200, 0, 0, np.nan]]), r"poses has a non-finite value at index \(0, 5\)"),
    ([["a"] * 6], "poses must be a numeric array"),
])
def test_ik_bad_input(poses, match):
    with pytest.raises(ValueError, match=match):
        inverse_kinematics(NOMINAL, poses)


def test_ik_unreachable_pose_names_pose_and_leg():
    poses = random_poses(4, 5)
    poses[2, 2] = 400.0  # legs would need ~430 mm, far beyond the stroke
    with pytest.raises(KinematicsError, match=r"pose 2 is unreachable: leg \d needs") as exc:
        inverse_kinematics(NOMINAL, poses)
    assert exc.value.index == 2


def test_fk_lengths_out_of_stroke():
    lengths = np.full((3, 6), 233.23808)
    lengths[1, 4] = 300.0
    with pytest.raises(KinematicsError, match="row of leg lengths 1 is unreachable: leg 5"):
        forward_kinematics(NOMINAL, lengths)


def test_fk_no_assembly_raises_naming_the_row():
    lengths = np.full((2, 6), 233.23808)
    # |B1 B2| = 280 mm > l1 + l2 + |P1 P2| = 240 mm: no assembly exists at all.
    lengths[1, :2] = 100.0
    with pytest.raises(KinematicsError, match="row 1") as exc:
        forward_kinematics(NOMINAL, lengths, stroke_mm=None, max_iter=30)
    assert exc.value.index == 1


def test_fk_singular_configuration_raises():
    # Platform in the plane of the base (z = 0) with all joints coplanar: the legs cannot resist
    # a vertical force, the pose Jacobian loses rank.
    pose = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    lengths = inverse_kinematics(NOMINAL, pose, stroke_mm=None)
    with pytest.raises(KinematicsError, match="singular"):
        forward_kinematics(NOMINAL, lengths, initial=pose[0], stroke_mm=None)


@pytest.mark.parametrize("lengths,match", [
    (np.zeros((2, 5)), r"lengths must have shape \(N, 6\), got \(2, 5\)"),
    (np.full((1, 6), np.inf), "lengths has a non-finite value"),
])
def test_fk_bad_input(lengths, match):
    with pytest.raises(ValueError, match=match):
        forward_kinematics(NOMINAL, lengths)
