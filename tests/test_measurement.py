"""Instrument frames and position-only targets (calib.measurement): the model, its Jacobians, the
gauge, detection, and the two figures the docs state (docs/measurement.md).

Kinematic simulation: the machine ``nominal + reference_errors(robot, 0)`` moves by its forward
kinematics; noise uniform within +-1 um on every position coordinate and +-1 urad on every angle.
"""

import numpy as np
import pytest

from calib.engine import identify_forward
from calib.measurement import (
    compose,
    detect_frame,
    identify_measured,
    instrument_measurements,
    measurement_jacobians,
    measurement_observability,
    measurement_settings,
    rigid_registration,
    whitened_residuals,
)
from calib.noise import SensorNoise
from calib.robots import ROBOTS, default_robot, reference_errors
from calib.rotation import euler_from_matrix
from calib.workspace import reachable_poses

NOISE = SensorNoise(0.001, 1e-6)
#: 500 mm from the base origin, turned by 0.5 rad on each axis.
FAR_FRAME = np.array([500 / np.sqrt(3)] * 3 + [0.5, -0.5, 0.5])
#: Three reflectors on the platform, mm (platform frame).
TARGETS = np.array([[60.0, 0.0, 20.0], [-30.0, 52.0, 20.0], [-30.0, -52.0, 20.0]])


def _invert(frame):
    from calib.rotation import rotation_matrix
    R = rotation_matrix(frame[3:])
    return np.concatenate([-R.T @ frame[:3], euler_from_matrix(R.T)])


def _experiment(name, n=60, seed=1):
    """Calibration and held-out joints and true poses in the full design workspace."""
    robot = default_robot(name)
    nominal = robot.table.nominal
    true = nominal + reference_errors(robot, 0)
    bounds = robot.full_workspace_bounds()
    cal, val = reachable_poses(robot, n, seed, bounds=bounds), reachable_poses(robot, 50, seed + 1, bounds=bounds)
    q, qv = robot.inverse_kinematics(nominal, cal), robot.inverse_kinematics(nominal, val)
    return (robot, true, q, robot.forward_kinematics(true, q, initial=cal), qv,
            robot.forward_kinematics(true, qv, initial=val))


def _points_error_mm(robot, fit, qv, true_points, targets):
    """Mean held-out distance between predicted and true (noise-free) points (or positions)."""
    pred = instrument_measurements(robot, robot.forward_kinematics(fit.result.theta, qv), fit.frame, targets)
    return float(np.linalg.norm((pred - true_points).reshape(len(qv), -1, 3) if targets is not None else
                                (pred - true_points)[:, :3][:, None, :], axis=2).mean())


# --------------------------------------------------------------------------- model


@pytest.mark.parametrize("name", sorted(ROBOTS))
@pytest.mark.parametrize("targets", [None, TARGETS])
def test_measurement_jacobians_match_finite_differences(name, targets):
    robot = default_robot(name)
    poses = reachable_poses(robot, 4, 0)
    H = measurement_jacobians(robot, poses, FAR_FRAME, targets)
    h = lambda p, f, t: instrument_measurements(robot, p, f, t)  # noqa: E731
    e = 1e-6
    for block, arg in zip(H, ("pose", "frame", "targets")):
        for j in range(block.shape[2]):
            args = {"pose": poses, "frame": FAR_FRAME, "targets": targets}
            shape = np.shape(args[arg])[1:] if arg == "pose" else np.shape(args[arg])  # pose: every row
            d = np.zeros(int(np.prod(shape)))
            d[j] = e
            plus, minus = dict(args), dict(args)
            plus[arg] = args[arg] + d.reshape(shape)
            minus[arg] = args[arg] - d.reshape(shape)
            num = (h(plus["pose"], plus["frame"], plus["targets"]) - h(minus["pose"], minus["frame"], minus["targets"])) / (2 * e)
            np.testing.assert_allclose(block[:, :, j], num, atol=1e-6)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_in_the_base_frame_the_instrument_reports_the_pose_and_its_jacobian_is_the_identity(name):
    """The shortcut taken where the instrument reports the pose itself (no targets, a zero frame):
    the measurements are the poses, and the pose Jacobian asked without its frame columns is the
    identity, which the general formulas (asked with the frame columns) give to rounding: products
    of a few 3 x 3 rotations and one inverse of O(1) entries, a few tens of eps."""
    robot = default_robot(name)
    poses = reachable_poses(robot, 5, 2)
    zero = np.zeros(6)
    np.testing.assert_array_equal(instrument_measurements(robot, poses, zero), poses)
    seen = compose(FAR_FRAME, robot, poses)  # the general formulas, there and back
    np.testing.assert_allclose(compose(_invert(FAR_FRAME), robot, seen), instrument_measurements(robot, poses),
                               atol=1e-10)
    identity, frame_cols, _ = measurement_jacobians(robot, poses, zero, with_frame=False)
    general, _, _ = measurement_jacobians(robot, poses, zero)
    np.testing.assert_array_equal(identity, np.broadcast_to(np.eye(robot.pose_dim), general.shape))
    np.testing.assert_allclose(general, identity, rtol=0, atol=64 * np.finfo(float).eps)
    assert frame_cols.shape == (len(poses), robot.pose_dim, 6)


def test_composition_is_the_frame_applied_to_the_pose():
    robot = default_robot("hexapod")
    pose = reachable_poses(robot, 1, 3)
    seen = compose(FAR_FRAME, robot, pose)
    back = compose(_invert(FAR_FRAME), robot, seen)
    np.testing.assert_allclose(back, pose, atol=1e-10)
    # a target at the platform origin is seen where the pose's position is
    np.testing.assert_allclose(instrument_measurements(robot, pose, FAR_FRAME, np.zeros((1, 3))), seen[:, :3], atol=1e-10)


def test_settings_parse_and_name_the_wrong_key():
    s = measurement_settings({"frame": "estimate", "targets": 3})
    assert s.frame == "estimate" and s.n_targets == 3 and s.estimate_targets
    s = measurement_settings({"targets": TARGETS.tolist()})
    assert s.frame == "auto" and not s.estimate_targets
    assert measurement_settings(None).frame == "auto"
    for bad, word in [({"frame": "tracker"}, "frame"), ({"targets": 4}, "targets"), ({"colour": 1}, "colour"),
                      ({"initial_frame": {"translation_mm": [1, 2]}}, "translation_mm"),
                      ({"estimate_targets": True}, "estimate_targets"), ("auto", "object")]:
        with pytest.raises(ValueError, match=word):
            measurement_settings(bad)


# --------------------------------------------------------------------------- detection


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_base_frame_data_are_not_taken_for_another_frame(name):
    robot, true, q, poses, _, _ = _experiment(name, n=20)
    assert not detect_frame(robot, q, poses + NOISE.sample(len(q), 0, robot.pose_units)).detected
    far = detect_frame(robot, q, instrument_measurements(robot, poses, FAR_FRAME))
    assert far.detected and "not in the robot's base frame" in far.message


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_reference_errors_never_look_like_another_frame(name):
    robot = default_robot(name)
    nominal = robot.table.nominal
    for seed in range(10):
        q = robot.inverse_kinematics(nominal, reachable_poses(robot, 40, seed))
        true = robot.forward_kinematics(nominal + reference_errors(robot, seed), q)
        found = detect_frame(robot, q, true)
        assert not found.detected and found.rms_mm < 0.5 * found.limit_mm and found.rms_rad < 0.5 * found.limit_rad


def test_in_base_frame_the_fit_is_the_forward_method():
    robot, _, q, poses, _, _ = _experiment("hexapod", n=20)
    measured = poses + NOISE.sample(len(q), 0, robot.pose_units)
    fit = identify_measured(robot, q, measured, NOISE)
    assert not fit.frame_estimated and np.all(fit.frame == 0)
    np.testing.assert_allclose(fit.result.theta, identify_forward(robot, q, measured, NOISE).theta, atol=1e-7)


# --------------------------------------------------------------------------- acceptance: instrument frame


def test_hexapod_gauge_is_the_base_frame_best_fitted_to_the_nominal_one():
    """Noise-free: the frame found equals the true frame expressed in the base frame fitted (Kabsch)
    to the nominal base joints: the gauge holds exactly, not to first order."""
    robot, true, q, poses, _, _ = _experiment("hexapod", n=30)
    fit = identify_measured(robot, q, instrument_measurements(robot, poses, FAR_FRAME), NOISE)
    R, t = rigid_registration(true.reshape(6, 7)[:, :3], robot.table.nominal.reshape(6, 7)[:, :3])
    gauge_frame = compose(FAR_FRAME, robot, _invert(np.r_[t, euler_from_matrix(R)])[None])[0]
    np.testing.assert_allclose(fit.frame, gauge_frame, atol=1e-8)
    assert len(fit.gauge) == 6 and fit.frame_estimated


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_far_turned_frame_is_recovered_and_heldout_error_unchanged(name):
    """Acceptance 2: 60 poses, frame 500 mm away turned 0.5 rad on each axis, +-1 um / +-1 urad."""
    robot, true, q, poses, qv, truev = _experiment(name)
    noise = NOISE.sample(len(q), 7, robot.pose_units)
    fit = identify_measured(robot, q, instrument_measurements(robot, poses, FAR_FRAME) + noise, NOISE)
    assert fit.frame_estimated and fit.result.success
    # the true frame in the gauge: the same fit without noise (for the hexapod, the Kabsch test above)
    exact = identify_measured(robot, q, instrument_measurements(robot, poses, FAR_FRAME), NOISE).frame
    assert np.abs(fit.frame[:3] - exact[:3]).max() < 0.1
    assert np.abs(fit.frame[3:] - exact[3:]).max() < 1e-4
    base = identify_measured(robot, q, poses + noise, NOISE, frame="base")
    with_frame = _points_error_mm(robot, fit, qv, instrument_measurements(robot, truev, FAR_FRAME), None)
    without = _points_error_mm(robot, base, qv, truev, None)
    assert with_frame < 1.25 * without


# --------------------------------------------------------------------------- acceptance: position only


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_three_targets_predict_within_1_5x_of_full_poses(name):
    """Acceptance 3: the same 60 poses measured as full poses (+-1 um, +-1 urad) or as three
    target positions (+-1 um each coordinate, offsets estimated); held-out error of the target
    positions predicted by each model."""
    robot, true, q, poses, qv, truev = _experiment(name)
    rng = np.random.default_rng(5)
    full = identify_measured(robot, q, poses + NOISE.sample(len(q), rng, robot.pose_units), NOISE, frame="base")
    points = instrument_measurements(robot, poses, None, TARGETS) + NOISE.sample(len(q), rng, ("mm",) * 9)
    pos = identify_measured(robot, q, points, NOISE, targets=np.zeros((3, 3)))
    assert pos.targets_estimated and not pos.frame_estimated and pos.result.success
    truth = instrument_measurements(robot, truev, None, TARGETS)
    e_full = float(np.linalg.norm((instrument_measurements(robot, robot.forward_kinematics(full.result.theta, qv),
                                                           None, TARGETS) - truth).reshape(-1, 3), axis=1).mean())
    e_pos = _points_error_mm(robot, pos, qv, truth, pos.targets)
    assert e_pos <= 1.5 * e_full


def test_position_only_observability_names_the_platform_gauge():
    robot = default_robot("hexapod")
    q = robot.inverse_kinematics(robot.table.nominal, reachable_poses(robot, 30, 0, bounds=robot.full_workspace_bounds()))
    obs = measurement_observability(robot, robot.table.nominal, q, NOISE, targets=TARGETS, estimate_frame=False)
    # the platform frame moved rigidly with the targets: 6 directions in P and T only
    assert obs.n_unknowns - obs.rank == 6 and all("B" not in g for g in obs.gauge)
    both = measurement_observability(robot, robot.table.nominal, q, NOISE, targets=TARGETS)
    assert both.n_unknowns - both.rank == 12
    full = measurement_observability(robot, robot.table.nominal, q, NOISE, estimate_frame=False)
    assert full.rank == full.n_unknowns == 42


# --------------------------------------------------------------------------- pipeline


@pytest.fixture(scope="module")
def hexapod_recording(tmp_path_factory):
    """A pipeline run's own recording (MuJoCo testbed, 30 poses, +-1 um, +-1 urad) and its forward
    calibration in the base frame."""
    from pipeline.run import run
    out = tmp_path_factory.mktemp("measurement")
    run(["--poses", "30", "--noise-rad", "1e-6", "--out", str(out), "--name", "base", "--quiet"])
    base = run(["--real", str(out / "base.csv"), "--method", "forward", "--out", str(out), "--name", "base_cal", "--quiet"])
    return out, base


def test_real_recording_in_a_far_frame_reports_the_frame(hexapod_recording):
    from dataclasses import replace
    from pipeline.formats import read_recording, write_recording
    from pipeline.run import run
    out, base = hexapod_recording
    rec = read_recording(out / "base.csv")
    write_recording(out / "far.csv", replace(rec, measured=instrument_measurements(rec.robot, rec.measured, FAR_FRAME),
                                             meta=dict(rec.meta, measurement={"frame": "auto"})))
    s = run(["--real", str(out / "far.csv"), "--out", str(out), "--name", "far_cal", "--quiet"]).summary
    assert "not in the robot's base frame" in s["message"]
    frame = np.r_[s["measurement_frame"]["translation_mm"], s["measurement_frame"]["rotation_rad"]]
    # the true frame in the gauge: the base joints of the injected machine fitted to the nominal ones
    robot = rec.robot
    true = robot.table.vector(rec.meta["simulation"]["injected_errors"], base=np.zeros(robot.n_parameters)) + robot.table.nominal
    R, t = rigid_registration(true.reshape(6, 7)[:, :3], robot.table.nominal.reshape(6, 7)[:, :3])
    gauge_frame = compose(FAR_FRAME, robot, _invert(np.r_[t, euler_from_matrix(R)])[None])[0]
    std = np.r_[s["measurement_frame_std"]["translation_mm"], s["measurement_frame_std"]["rotation_rad"]]
    assert np.all(np.abs(frame - gauge_frame) < 5 * std + 1e-9)
    h, hb = s["heldout_position_error_mm"]["after"], base.summary["heldout_position_error_mm"]["after"]
    assert h < 1.1 * hb
    # a sidecar that says "base" keeps the frame out: the fit then cannot explain the data
    write_recording(out / "far_base.csv", replace(rec, measured=instrument_measurements(rec.robot, rec.measured, FAR_FRAME),
                                                  meta=dict(rec.meta, measurement={"frame": "base"})))
    with pytest.raises(ValueError):
        run(["--real", str(out / "far_base.csv"), "--out", str(out), "--name", "far_base_cal", "--quiet"])


def test_real_position_only_recording_round_trips_and_calibrates(hexapod_recording):
    from dataclasses import replace
    from pipeline.formats import read_recording, write_recording
    from pipeline.run import run
    out, base = hexapod_recording
    rec = read_recording(out / "base.csv")
    points = instrument_measurements(rec.robot, rec.measured, None, TARGETS)
    write_recording(out / "targets.csv", replace(rec, measured=points, meta=dict(rec.meta, measurement={"targets": 3})))
    assert (out / "targets.csv").read_text().splitlines()[0].endswith("t3_x_mm,t3_y_mm,t3_z_mm,set")
    back = read_recording(out / "targets.csv")
    np.testing.assert_array_equal(back.measured, points)
    s = run(["--real", str(out / "targets.csv"), "--out", str(out), "--name", "targets_cal", "--quiet"]).summary
    assert s["measurement_targets_estimated"] and "measurement_frame" not in s
    assert s["heldout_position_error_mm"]["after"] < 1.5 * base.summary["heldout_position_error_mm"]["after"]


@pytest.mark.parametrize("targets", [None, np.array([[10.0, 0.0, 5.0], [0.0, 20.0, 3.0]])])
def test_whitened_residuals_without_joint_noise_are_the_residuals_over_the_noise(targets):
    """Without joint noise the whitening is each coordinate over its standard deviation (taken
    without the measurement Jacobians); the independent truth: the covariance path run with a
    joint noise of 1e-30 (its term 1e-60 relative, below rounding), through the Cholesky factor's
    inverse; full poses and targets, in a frame: equal to a few eps relative."""
    robot = default_robot("hexapod")
    theta = robot.table.nominal + reference_errors(robot, 1)
    poses = reachable_poses(robot, 40, 2)
    joints = robot.inverse_kinematics(robot.table.nominal, poses)
    frame = np.array([5.0, -3.0, 2.0, 0.01, -0.02, 0.03])
    measured = instrument_measurements(robot, poses, frame, targets) + 1e-3
    plain, model = whitened_residuals(robot, theta, joints, measured, SensorNoise(1e-3, 1e-6, "normal"), frame=frame,
                                      targets=targets)
    tiny, same = whitened_residuals(robot, theta, joints, measured, SensorNoise(1e-3, 1e-6, "normal", joint=1e-30),
                                    frame=frame, targets=targets)
    np.testing.assert_array_equal(model, same)
    np.testing.assert_allclose(plain, tiny, rtol=1e-13, atol=1e-13 * np.abs(tiny).max())
    assert np.abs(plain).max() > 1.0  # the residuals are not zero: the test could fail
