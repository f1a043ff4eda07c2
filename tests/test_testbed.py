"""The one MuJoCo testbed, on the hexapod (the Delta through it: tests/test_mjcf_delta.py)."""

import numpy as np
import pytest

from calib.noise import SensorNoise
from calib.paper import TABLE3_ERRORS
from calib.robots import default_robot, reference_errors
from calib.robots.hexapod import paper_hexapod
from calib.workspace import reachable_poses
from mjcf.machine import MachineEffects, MachineOptions
from mjcf.units import M_PER_MM
from pipeline.simulation import SettleError, Testbed

ROBOT = paper_hexapod()
NOMINAL = ROBOT.table.nominal
ACTUAL = NOMINAL + TABLE3_ERRORS.ravel()


def commands(n: int, seed: int) -> np.ndarray:
    """(n, 6) nominal inverse kinematics of poses drawn in the robot's workspace, mm."""
    b = ROBOT.workspace_bounds()
    poses = b[:, 0] + np.random.default_rng(seed).uniform(size=(n, 6)) * (b[:, 1] - b[:, 0])
    return ROBOT.inverse_kinematics(NOMINAL, poses)


def test_gravity_off_settled_pose_equals_forward_kinematics_on_100_poses():
    commanded = commands(100, 42)
    m = Testbed(ROBOT, ACTUAL).measure(commanded)
    fk = ROBOT.forward_kinematics(ACTUAL, commanded)
    assert np.abs(m.true_poses[:, :3] - fk[:, :3]).max() <= 1e-6  # mm
    assert np.abs(m.true_poses[:, 3:] - fk[:, 3:]).max() <= 1e-9  # rad
    np.testing.assert_array_equal(m.measured, m.true_poses)  # no noise declared
    np.testing.assert_allclose(m.settled_joints, commanded, atol=1e-6)  # unloaded servos sit at their command
    np.testing.assert_array_equal(m.commanded, commanded)
    assert np.all(np.diff(m.t_s) > 0) and m.steps.min() > 5


def test_noise_is_seeded_and_is_the_declared_stream():
    commanded = commands(5, 1)
    noise = SensorNoise(0.001, 1e-6)
    a = Testbed(ROBOT, ACTUAL, noise=noise, seed=7).measure(commanded)
    b = Testbed(ROBOT, ACTUAL, noise=noise, seed=7).measure(commanded)
    c = Testbed(ROBOT, ACTUAL, noise=noise, seed=8).measure(commanded)
    np.testing.assert_array_equal(a.measured, b.measured)
    assert not np.array_equal(a.measured, c.measured)
    # The pose noise is the seed's first draw (as the hexapod testbed has always drawn it).
    np.testing.assert_allclose(a.measured - a.true_poses, noise.sample(5, np.random.default_rng(7), ROBOT.pose_units),
                               rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a.encoders, a.commanded)  # no joint noise declared: none drawn
    # Joint noise comes after the pose noise, from the same stream.
    jn = SensorNoise(0.001, 1e-6, joint=1e-4)
    d = Testbed(ROBOT, ACTUAL, noise=jn, seed=7).measure(commanded)
    rng = np.random.default_rng(7)
    np.testing.assert_allclose(d.measured - d.true_poses, jn.sample(5, rng, ROBOT.pose_units), rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.encoders - commanded, jn.sample_joints(5, 6, rng), rtol=0, atol=1e-12)
    assert 0 < np.abs(d.encoders - commanded).max() <= 1e-4
    np.testing.assert_array_equal(d.settled_joints, a.settled_joints)  # the noise is the encoders', not the machine's


def test_gravity_and_payload_make_the_platform_sag():
    commanded = commands(3, 2)
    m = Testbed(ROBOT, ACTUAL, options=MachineOptions(gravity=True, payload_kg=5.0)).measure(commanded)
    sag = m.true_poses[:, 2] - ROBOT.forward_kinematics(ACTUAL, commanded)[:, 2]
    # 5 kg + 2 kg platform on six legs of 2e5 N/m: of order 0.1 mm down.
    assert np.all(sag < -0.03) and np.all(sag > -0.3)
    # The legs are compressed: they read shorter than commanded.
    assert np.all(m.settled_joints < m.commanded)


def test_friction_leaves_a_dead_band_of_friction_over_stiffness_against_the_last_move():
    friction, stiffness = 1.0, 2e5  # N, N/m: dead band 5 um
    band_mm = friction / stiffness / M_PER_MM
    home = ROBOT.home_lengths
    # Out, further out (same direction), back in, then legs 1-3 out and 4-6 in.
    steps = np.array([[2.0] * 6, [3.0] * 6, [1.0] * 6, [1.5] * 3 + [0.5] * 3])
    direction = np.array([[1.0] * 6, [1.0] * 6, [-1.0] * 6, [1.0] * 3 + [-1.0] * 3])
    bed = Testbed(ROBOT, ACTUAL, options=MachineOptions(actuator_stiffness=stiffness, joint_friction=friction))
    m = bed.measure(home + steps)
    np.testing.assert_allclose(m.commanded - m.settled_joints, direction * band_mm, atol=1e-7)
    # The platform is where the kinematics of the legs' actual lengths put it.
    np.testing.assert_allclose(m.true_poses, ROBOT.forward_kinematics(ACTUAL, m.settled_joints), atol=1e-6)


def test_thermal_drift_and_screw_error_enter_the_servo_reference():
    commanded = commands(4, 5)
    times = np.array([0.0, 10.0, 20.0, 30.0])
    drift = Testbed(ROBOT, ACTUAL, effects=MachineEffects(joint_drift_per_s=1e-4)).measure(commanded, times_s=times)
    np.testing.assert_allclose(drift.settled_joints - commanded, 1e-4 * times[:, None] * np.ones(6), atol=1e-7)
    np.testing.assert_array_equal(drift.t_s, times)
    amp, phase, pitch = np.linspace(1e-3, 6e-3, 6), np.linspace(0, 3, 6), 4.0
    screw = Testbed(ROBOT, ACTUAL, effects=MachineEffects(screw_amplitude=amp, screw_phase_rad=phase,
                                                          screw_pitch=pitch)).measure(commanded)
    expected = amp * np.sin(2 * np.pi * (commanded - ROBOT.home_lengths) / pitch + phase)
    np.testing.assert_allclose(screw.settled_joints - commanded, expected, atol=1e-7)
    # In both, the pose follows the legs' actual lengths.
    for m in (drift, screw):
        np.testing.assert_allclose(m.true_poses, ROBOT.forward_kinematics(ACTUAL, m.settled_joints), atol=1e-6)


def test_transmission_scale_moves_the_legs_1_plus_s_times_the_stroke():
    s = np.array([1e-3, -2e-3, 0.0, 5e-4, 0.0, -1e-3])
    commanded = commands(3, 6)
    m = Testbed(ROBOT, ACTUAL, options=MachineOptions(transmission_scale=tuple(s))).measure(commanded)
    home = ROBOT.home_lengths
    np.testing.assert_allclose(m.settled_joints - home, (1 + s) * (commanded - home), atol=1e-7)
    np.testing.assert_allclose(m.true_poses, ROBOT.forward_kinematics(ACTUAL, m.settled_joints), atol=1e-6)


def test_step_cap_raises_a_clear_error():
    bed = Testbed(ROBOT, ACTUAL, max_steps=20, settle="sequential")
    with pytest.raises(SettleError, match=r"did not settle within 20 steps .* mm: max joint speed"):
        bed.measure(commands(1, 3))
    # The rollout starts at rest but still steps MIN_SETTLE_STEPS before it may call a pose settled.
    with pytest.raises(SettleError, match=r"did not settle within 5 steps .* mm: max joint speed"):
        Testbed(ROBOT, ACTUAL, max_steps=5, settle="rollout").measure(commands(3, 3))


def test_validation():
    with pytest.raises(ValueError, match=r"joints must have shape \(N, 6\), got \(6,\)"):
        Testbed(ROBOT, ACTUAL).measure(np.zeros(6))
    with pytest.raises(ValueError, match=r"times_s must have shape \(2,\), got \(3,\)"):
        Testbed(ROBOT, ACTUAL).measure(commands(2, 0), times_s=np.zeros(3))
    with pytest.raises(ValueError, match=r"effects.screw_amplitude must have 6 values \(one per leg\), got 3"):
        Testbed(ROBOT, ACTUAL, effects=MachineEffects(screw_amplitude=(1, 2, 3), screw_phase_rad=(0, 0, 0)))
    with pytest.raises(ValueError, match="settle_velocity must be > 0"):
        Testbed(ROBOT, ACTUAL, settle_velocity=0.0)
    with pytest.raises(ValueError, match="max_steps must be a positive integer, got 0"):
        Testbed(ROBOT, ACTUAL, max_steps=0)


@pytest.mark.parametrize("robot_name, options", [
    ("hexapod", MachineOptions()),
    ("hexapod", MachineOptions(gravity=True, payload_kg=5.0)),
    ("hexapod", MachineOptions(transmission_scale=(1e-3, -2e-3, 0.0, 5e-4, 0.0, -1e-3))),
    ("delta", MachineOptions()),
    ("delta", MachineOptions(gravity=True, payload_kg=2.0)),
    ("rus", MachineOptions()),
    ("rus", MachineOptions(gravity=True)),
    ("linear_delta", MachineOptions()),
    ("linear_delta", MachineOptions(gravity=True, payload_kg=0.5)),
])
def test_rollout_settles_where_the_sequential_settle_does(robot_name, options):
    robot = default_robot(robot_name)
    theta = robot.table.nominal + reference_errors(robot, 0)
    joints = robot.inverse_kinematics(robot.table.nominal, reachable_poses(robot, 8, 3))
    noise = SensorNoise(0.001, 1e-6 if robot.pose_dim == 6 else 0.0, joint=1e-4)
    seq = Testbed(robot, theta, options=options, noise=noise, seed=5, settle="sequential")
    par = Testbed(robot, theta, options=options, noise=noise, seed=5, settle="rollout", threads=2)
    assert Testbed(robot, theta, options=options).uses_rollout() and not seq.uses_rollout()
    a, b = seq.measure(joints), par.measure(joints)
    # The same rest: the settle velocity (1e-9 m/s, rad/s) leaves nanometres.
    np.testing.assert_allclose(b.true_poses[:, :3], a.true_poses[:, :3], rtol=0, atol=1e-6)  # mm
    np.testing.assert_allclose(b.true_poses[:, 3:], a.true_poses[:, 3:], rtol=0, atol=1e-9)  # rad
    np.testing.assert_allclose(b.settled_joints, a.settled_joints, rtol=0, atol=1e-6)
    # The same noise draws, to the bit.
    np.testing.assert_array_equal(b.measured - b.true_poses, a.measured - a.true_poses)
    np.testing.assert_array_equal(b.encoders, a.encoders)
    # Fewer steps (from the warm start), still at least MIN_SETTLE_STEPS; time runs on.
    assert b.steps.min() >= 6 and b.steps.sum() < a.steps.sum() / 5
    assert np.all(np.diff(b.t_s) > 0)
    # A second measurement continues the noise stream and the clock, as the sequential one does.
    c, d = par.measure(joints[:2]), seq.measure(joints[:2])
    assert c.t_s[0] > b.t_s[-1]
    np.testing.assert_array_equal(c.measured - c.true_poses, d.measured - d.true_poses)


def test_history_effects_settle_one_pose_after_another():
    fric = Testbed(ROBOT, ACTUAL, options=MachineOptions(joint_friction=1.0))
    drift = Testbed(ROBOT, ACTUAL, effects=MachineEffects(joint_drift_per_s=1e-4))
    screw = Testbed(ROBOT, ACTUAL, effects=MachineEffects(screw_amplitude=[1e-3] * 6, screw_phase_rad=[0.0] * 6))
    plain = Testbed(ROBOT, ACTUAL)
    assert not fric.uses_rollout() and not drift.uses_rollout() and not screw.uses_rollout()
    assert plain.uses_rollout() and not plain.uses_rollout(np.zeros(3))
    for kw in (dict(options=MachineOptions(joint_friction=1.0)), dict(effects=MachineEffects(joint_drift_per_s=1e-4))):
        with pytest.raises(ValueError, match="settle='rollout' needs physics without history"):
            Testbed(ROBOT, ACTUAL, settle="rollout", **kw)
    with pytest.raises(ValueError, match="times_s needs the sequential settle"):
        Testbed(ROBOT, ACTUAL, settle="rollout").measure(commands(2, 0), times_s=np.zeros(2))
    with pytest.raises(ValueError, match="settle must be one of auto, rollout, sequential"):
        Testbed(ROBOT, ACTUAL, settle="parallel")
    with pytest.raises(ValueError, match="threads must be a positive integer"):
        Testbed(ROBOT, ACTUAL, threads=0)
    empty = plain.measure(np.zeros((0, 6)))
    assert empty.true_poses.shape == (0, 6) and empty.steps.shape == (0,)


def test_after_a_rollout_the_machine_rests_at_the_last_pose():
    joints = commands(3, 4)
    bed = Testbed(ROBOT, ACTUAL, settle="rollout")
    m = bed.measure(joints)
    np.testing.assert_allclose(bed.simulator.read_pose(), m.true_poses[-1], atol=1e-9)
    assert bed.simulator.time == pytest.approx(m.t_s[-1])
    # A sequential settle of the same command from there is already at rest.
    pose, steps = bed.settle(joints[-1])
    assert steps == 6
    np.testing.assert_allclose(pose, m.true_poses[-1], atol=1e-9)
