"""The MuJoCo Delta (mjcf.delta) and measuring it through the one testbed (pipeline.testbed)."""

import mujoco
import numpy as np
import pytest

from calib.engine import identify_chainwise, identify_forward
from calib.noise import SensorNoise
from calib.robots.delta import Delta, canonical_params
from mjcf import build_machine
from mjcf.delta import ARM_JOINTS, DEFAULT_STIFFNESS_NM_PER_RAD, build_spec
from mjcf.machine import GRAVITY_M_S2, PLATFORM_SITE, SENSOR_POS, MachineOptions
from mjcf.units import m_to_mm
from pipeline.simulation import SettleError, Testbed

ROBOT = Delta()
NOMINAL = ROBOT.table.nominal
# 1 mm / 1 degree uniform errors, seeded (the Delta paper's "1 mm" scenario).
TRUE = NOMINAL + np.random.default_rng(42).uniform(-1, 1, 24) * np.where(ROBOT.table.angle_mask(), np.deg2rad(1.0), 1.0)


def commands(n: int, seed: int) -> np.ndarray:
    """(n, 3) nominal inverse kinematics of plate positions drawn in the workspace box, rad."""
    b = ROBOT.workspace_bounds()
    x = b[:, 0] + np.random.default_rng(seed).uniform(size=(n, 3)) * (b[:, 1] - b[:, 0])
    return ROBOT.inverse_kinematics(NOMINAL, x)


@pytest.fixture(scope="module")
def measured():
    """Noise-free MuJoCo measurements of TRUE at 30 nominal-IK configurations."""
    return Testbed(ROBOT, TRUE).measure(commands(30, 3))


def test_model_structure():
    m = build_machine(ROBOT, TRUE).model
    assert (m.nq, m.nv, m.nu, m.neq) == (12, 12, 3, 3)
    assert all(m.eq_type[k] == mujoco.mjtEq.mjEQ_CONNECT for k in range(m.neq))
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    assert np.all(m.opt.gravity == 0.0)
    for k, name in enumerate(ARM_JOINTS):
        assert m.joint(name).type[0] == mujoco.mjtJoint.mjJNT_HINGE
        assert m.actuator_trnid[k, 0] == m.joint(name).id  # one actuator per chain, chain order
    assert m.sensor(SENSOR_POS).type[0] == mujoco.mjtSensor.mjSENS_FRAMEPOS
    # The plate only translates.
    plate_joints = [m.joint(j) for j in range(m.njnt) if m.jnt_bodyid[j] == m.body("plate").id]
    assert [int(j.type[0]) for j in plate_joints] == [int(mujoco.mjtJoint.mjJNT_SLIDE)] * 3
    np.testing.assert_allclose(m.actuator_gainprm[:, 0], DEFAULT_STIFFNESS_NM_PER_RAD)


def test_geometry_is_the_reduced_model_with_a_physical_plate():
    m = build_machine(ROBOT, TRUE).model
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    p = ROBOT.params(TRUE)
    attach = ROBOT.rn_mm * np.stack([np.cos(p.theta), np.sin(p.theta), np.zeros(3)], axis=1)
    for i in range(3):
        np.testing.assert_allclose(m_to_mm(d.body(f"arm{i + 1}").xpos), p.shoulders()[i] + attach[i], atol=1e-9)
        np.testing.assert_allclose(m_to_mm(m.site(f"plate_c{i + 1}").pos), attach[i], atol=1e-9)
        np.testing.assert_allclose(m_to_mm(m.site(f"fa{i + 1}_end").pos[2]), p.Lb[i], atol=1e-9)
    assert np.linalg.norm(m_to_mm(m.site("plate_c1").pos)) == pytest.approx(30.0)


def test_home_keyframe_closes_the_chains_at_the_home_position():
    machine = build_machine(ROBOT, TRUE)
    d = mujoco.MjData(machine.model)
    machine.reset(d)
    for i in range(3):
        np.testing.assert_allclose(d.site(f"fa{i + 1}_end").xpos, d.site(f"plate_c{i + 1}").xpos, atol=1e-14)
    np.testing.assert_allclose(machine.read_pose(d), ROBOT.home_pose, atol=1e-9)
    np.testing.assert_allclose(machine.read_joints(d), ROBOT.inverse_kinematics(TRUE, ROBOT.home_pose[None])[0],
                               atol=1e-14)
    # The hinge position is the joint reading: offset 0, scale 1.
    np.testing.assert_array_equal(machine.ctrl(np.array([0.1, -0.2, 0.3])), [0.1, -0.2, 0.3])
    assert np.allclose(d.site(PLATFORM_SITE).xpos, d.body("plate").xpos)


def test_settled_plate_matches_the_forward_kinematics(measured):
    """MuJoCo against calib's forward kinematics of the injected parameters (mm)."""
    np.testing.assert_allclose(measured.settled_joints, measured.commanded, atol=1e-10)
    fk = ROBOT.forward_kinematics(TRUE, measured.commanded)
    assert np.abs(measured.true_poses - fk).max() <= 1e-6
    np.testing.assert_array_equal(measured.measured, measured.true_poses)  # noise-free
    assert np.all(np.diff(measured.t_s) > 0) and measured.steps.max() < 20000


@pytest.mark.parametrize("method", ["forward", "chainwise"])
def test_identification_through_mujoco_noise_free(measured, method):
    """Identified = injected (canonical: Lay held at 0) to 1e-5 mm / 1e-7 rad."""
    noise = SensorNoise(position_mm=1e-3, distribution="normal")
    if method == "forward":
        res = identify_forward(ROBOT, measured.encoders, measured.measured, noise)
    else:
        res = identify_chainwise(ROBOT, measured.encoders, measured.measured, noise, solver="lm")
    assert res.success, res.message
    truth = canonical_params(ROBOT.params(TRUE)).to_vector()
    err = np.abs(res.theta - truth)
    angle = ROBOT.table.angle_mask()
    assert err[~angle].max() < 1e-5 and err[angle].max() < 1e-7


def test_noise_is_seeded():
    q = commands(3, 5)
    noise = SensorNoise(position_mm=1e-3, distribution="normal", joint=1e-4)
    a = Testbed(ROBOT, TRUE, noise=noise, seed=9).measure(q)
    b = Testbed(ROBOT, TRUE, noise=noise, seed=9).measure(q)
    c = Testbed(ROBOT, TRUE, noise=noise, seed=10).measure(q)
    np.testing.assert_array_equal(a.measured, b.measured)
    np.testing.assert_array_equal(a.encoders, b.encoders)
    assert not np.array_equal(a.measured, c.measured)
    rng = np.random.default_rng(9)
    np.testing.assert_allclose(a.measured - a.true_poses, noise.sample(3, rng, ROBOT.pose_units), rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.encoders - q, noise.sample_joints(3, 3, rng), rtol=0, atol=1e-12)


def test_friction_dead_band_and_transmission_scale_on_the_arms():
    q = commands(2, 8)
    friction = 0.5  # N m against 2000 N m/rad: 2.5e-4 rad
    m = Testbed(ROBOT, TRUE, options=MachineOptions(joint_friction=friction)).measure(q)
    home = ROBOT.inverse_kinematics(TRUE, ROBOT.home_pose[None])[0]
    direction = np.sign(np.diff(np.vstack([home, q]), axis=0))
    np.testing.assert_allclose(q - m.settled_joints, direction * friction / DEFAULT_STIFFNESS_NM_PER_RAD, atol=1e-9)
    np.testing.assert_allclose(m.true_poses, ROBOT.forward_kinematics(TRUE, m.settled_joints), atol=1e-6)
    s = np.array([1e-3, -2e-3, 5e-4])
    m = Testbed(ROBOT, TRUE, options=MachineOptions(transmission_scale=tuple(s))).measure(q)
    np.testing.assert_allclose(m.settled_joints, (1 + s) * q, atol=1e-10)
    np.testing.assert_allclose(m.true_poses, ROBOT.forward_kinematics(TRUE, m.settled_joints), atol=1e-6)


def test_gravity_and_payload_pull_the_plate_down():
    q = commands(2, 9)
    m = Testbed(ROBOT, TRUE, options=MachineOptions(gravity=True, payload_kg=1.0)).measure(q)
    assert build_machine(ROBOT, TRUE, MachineOptions(gravity=True)).model.opt.gravity[2] == pytest.approx(-GRAVITY_M_S2)
    sag = m.true_poses[:, 2] - ROBOT.forward_kinematics(TRUE, q)[:, 2]
    assert np.all(sag < -1e-3) and np.all(sag > -1.0)  # compliant servos: micrometres to a millimetre


def test_step_cap_raises():
    bed = Testbed(ROBOT, TRUE, max_steps=10, settle="sequential")  # the rollout starts at rest
    with pytest.raises(SettleError, match=r"did not settle within 10 steps .* rad: max joint speed"):
        bed.measure(commands(1, 0))


def test_validation():
    with pytest.raises(ValueError, match=r"joints must have shape \(N, 3\), got \(3,\)"):
        Testbed(ROBOT, NOMINAL).measure(np.zeros(3))
    with pytest.raises(ValueError, match=r"theta must have shape \(24,\), got \(23,\)"):
        build_spec(ROBOT, NOMINAL[:23])
    with pytest.raises(ValueError, match=r"transmission_scale must have 3 values \(one per chain\), got 6"):
        build_spec(ROBOT, NOMINAL, MachineOptions(transmission_scale=(0.0,) * 6))
