"""The MuJoCo linear Delta (mjcf.linear_delta) against its kinematics, and against the geometry of
six rods when a pair's rods differ (the effector tilts)."""

import mujoco
import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from calib.robots import default_robot, uniform_errors
from calib.robots.linear_delta import STEP_ERROR_REFERENCE_MM, tower_directions
from calib.workspace import reachable_poses
from mjcf import build_machine
from mjcf.linear_delta import (CARRIAGE_JOINTS, DEFAULT_STIFFNESS_N_PER_M, build_spec, rod_lengths)
from mjcf.machine import GRAVITY_M_S2, SENSOR_POS, MachineOptions
from mjcf.units import M_PER_MM, m_to_mm
from pipeline.simulation import Testbed

ROBOT = default_robot("linear_delta")
NOMINAL = ROBOT.table.nominal
# Every parameter identified by default off by up to 0.5 mm / 0.5 degree (the rods equal).
TRUE = NOMINAL + uniform_errors(ROBOT, 42, 0.5, np.deg2rad(0.5))
#: Settled against the kinematics: at rest means every joint slower than the testbed's 1e-9 m/s,
#: which leaves the carriages and effector within nanometres of their equilibrium (measured
#: 1.8e-10 mm); this bound is 5,000 times that and far below any geometric error.
SETTLED_MM = 1e-6


def commands(n: int, seed: int) -> np.ndarray:
    """(n, 3) the nominal inverse kinematics of tool points drawn in the calibration workspace."""
    return ROBOT.inverse_kinematics(NOMINAL, reachable_poses(ROBOT, n, seed))


@pytest.fixture(scope="module")
def measured():
    """Noise-free MuJoCo measurements of TRUE at 12 nominal-IK commands."""
    return Testbed(ROBOT, TRUE).measure(commands(12, 3))


def test_model_structure():
    m = build_machine(ROBOT, TRUE).model
    # 3 slides + 6 rods x 2 hinges + the effector's free joint (7 qpos, 6 dof); six rod closures
    assert (m.nq, m.nv, m.nu, m.neq) == (22, 21, 3, 6)
    assert all(m.eq_type[k] == mujoco.mjtEq.mjEQ_CONNECT for k in range(m.neq))
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT and np.all(m.opt.gravity == 0.0)
    for k, name in enumerate(CARRIAGE_JOINTS):
        assert m.joint(name).type[0] == mujoco.mjtJoint.mjJNT_SLIDE
        assert m.actuator_trnid[k, 0] == m.joint(name).id  # one actuator per tower, tower order
    assert m.joint("effector_free").type[0] == mujoco.mjtJoint.mjJNT_FREE  # free to tilt
    assert m.sensor(SENSOR_POS).type[0] == mujoco.mjtSensor.mjSENS_FRAMEPOS
    np.testing.assert_allclose(m.actuator_gainprm[:, 0], DEFAULT_STIFFNESS_N_PER_M)


def test_home_keyframe_closes_the_rods_at_the_home_pose():
    machine = build_machine(ROBOT, TRUE)
    d = mujoco.MjData(machine.model)
    machine.reset(d)
    for i in range(3):
        for side in "ab":
            np.testing.assert_allclose(d.site(f"rod{i + 1}{side}_end").xpos, d.site(f"effector_rod{i + 1}{side}").xpos,
                                       atol=1e-14)
    np.testing.assert_allclose(machine.read_pose(d), ROBOT.home_pose, atol=1e-9)
    np.testing.assert_allclose(machine.read_joints(d), ROBOT.inverse_kinematics(TRUE, ROBOT.home_pose[None])[0],
                               atol=1e-10)


def test_the_step_error_is_the_slides_scale():
    """A joint value is counted travel: the slide moves ``1 + step_error/100`` times it."""
    machine = build_machine(ROBOT, TRUE)
    scale = 1.0 + ROBOT.split(TRUE)["step_error"] / STEP_ERROR_REFERENCE_MM
    np.testing.assert_allclose(machine.ctrl(machine.joint_offset + 10.0), 10.0 * scale * M_PER_MM, rtol=1e-14)


def test_settled_tool_is_where_the_kinematics_puts_it(measured):
    np.testing.assert_allclose(measured.settled_joints, measured.commanded, atol=1e-9)
    fk = ROBOT.forward_kinematics(TRUE, measured.settled_joints)
    assert np.abs(measured.true_poses - fk).max() <= SETTLED_MM


def _six_rods(robot, theta, joints):
    """The effector's pose ``(centre (3,) mm, rotation)`` at carriage travels ``joints`` (3,) from
    the six rods alone: each rod's length between its carriage joint and its effector joint
    (effector frame), solved by least squares over the centre and a rotation vector: the
    geometry of the pairs, not the reduced model."""
    reduced, p = robot.carriage_points(theta, joints[None])
    e_r, e_t, _ = tower_directions(robot.split(robot.table.nominal)["angle"], np.zeros(3), np.zeros(3))
    half = robot.rod_spacing_mm / 2
    offset = robot.effector_radius_mm * e_r
    joint = reduced[0] - p["tool"] + offset  # the carriages' joint midpoints
    carriage = np.concatenate([joint - half * e_t, joint + half * e_t])
    effector = np.concatenate([offset - half * e_t, offset + half * e_t])
    lengths = rod_lengths(robot, theta).T.ravel()

    def residual(x):
        ends = x[:3] + Rotation.from_rotvec(x[3:]).apply(effector)
        return np.linalg.norm(ends - carriage, axis=1) - lengths

    start = np.r_[robot.forward_kinematics(theta, joints[None])[0] - p["tool"], np.zeros(3)]
    fit = least_squares(residual, start, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert np.abs(fit.fun).max() < 1e-9
    return fit.x[:3], Rotation.from_rotvec(fit.x[3:])


def _settle_direct(machine, joints, seconds=3.0):
    """(tool (3,) mm, effector rotation, joints (3,) mm, rods (3, 3)) after ``seconds`` of
    simulation commanded to ``joints`` from home; ``rods`` each pair's unit direction, from its
    carriage joints' midpoint to its effector joints' midpoint (MuJoCo's bodies and sites)."""
    m = machine.model
    d = mujoco.MjData(m)
    machine.reset(d)
    d.ctrl[:] = machine.ctrl(joints)
    for _ in range(int(seconds / m.opt.timestep)):
        mujoco.mj_step(m, d)
    w, x, y, z = d.body("effector").xquat
    rods = np.array([(d.site(f"effector_rod{k}a").xpos + d.site(f"effector_rod{k}b").xpos
                      - d.body(f"rod{k}a").xpos - d.body(f"rod{k}b").xpos) / 2 for k in (1, 2, 3)])
    return (machine.read_pose(d), Rotation.from_quat([x, y, z, w]), machine.read_joints(d),
            rods / np.linalg.norm(rods, axis=1, keepdims=True))


def test_one_rod_pair_a_millimetre_long_tilts_the_effector_as_six_rods_say():
    """Pair 1's second rod 1 mm longer than its first (the arm's mean unchanged): the effector
    tilts by about arm_diff / rod spacing (20 mrad), where the six rods' geometry puts it and where
    the kinematics (calib.robots.linear_delta.RodPairs) solves it, and the tool point, 50 mm under
    the effector's joints, goes where the kinematics puts it (measured 2e-11 mm), not where a
    translating effector would (measured 0.24 mm away)."""
    theta = TRUE.copy()
    theta[ROBOT.table.index("arm_diff1")] = 1.0
    machine = build_machine(ROBOT, theta)
    target = commands(1, 7)[0]
    tool, rotation, joints, rods = _settle_direct(machine, target)
    centre, expected = _six_rods(ROBOT, theta, joints)
    tilt = (rotation * expected.inv()).magnitude()
    assert tilt < 1e-8, tilt  # rad
    np.testing.assert_allclose(tool, centre + expected.apply(ROBOT.split(theta)["tool"]), atol=SETTLED_MM)
    # The parallelogram to first order: a tilt w lengthens pair i's second rod over its first by
    # spacing w.(axle_i x rod_i), so spacing (axle_i x rod_i).w = arm_diff_i, three equations;
    # the terms left out are second order, relative to the tilt of the order of the tilt itself
    # (measured 0.85 percent at 20.65 mrad)
    _, axles, _ = tower_directions(ROBOT.split(NOMINAL)["angle"], np.zeros(3), np.zeros(3))
    first_order = np.linalg.solve(ROBOT.rod_spacing_mm * np.cross(axles, rods), ROBOT.split(theta)["arm_diff"])
    omega = rotation.as_rotvec()
    assert np.linalg.norm(omega - first_order) < 2 * np.linalg.norm(omega) ** 2, (omega, first_order)
    # the kinematics holds the tilt: its rotation and tool point are the machine's
    pairs = ROBOT.pairs(theta, joints[None], tool[None])
    assert (Rotation.from_matrix(pairs.rotation[0]) * rotation.inv()).magnitude() < 1e-8
    np.testing.assert_allclose(ROBOT.forward_kinematics(theta, joints[None])[0], tool, atol=SETTLED_MM)
    # a translating effector (the pair's rods equal) would put the tool elsewhere: the tilt moves
    # the tool through its 50 mm offset and the effector's centre through its joints' 30 mm,
    # partly against each other
    level = theta.copy()
    level[ROBOT.table.indices(["arm_diff1", "arm_diff2", "arm_diff3"])] = 0.0
    departure = np.linalg.norm(tool - ROBOT.forward_kinematics(level, joints[None])[0])
    assert departure > 0.1, departure
    # equal rods: no tilt
    _, untilted, _, _ = _settle_direct(build_machine(ROBOT, level), target)
    assert untilted.magnitude() < 1e-9


def test_friction_dead_band_and_transmission_scale_on_the_carriages():
    q = commands(2, 8)
    friction = 1.0  # N against 1e5 N/m: 0.01 mm of counted travel over the step scale
    m = Testbed(ROBOT, TRUE, options=MachineOptions(joint_friction=friction)).measure(q)
    machine = build_machine(ROBOT, TRUE)
    home = machine.joint_offset
    direction = np.sign(np.diff(np.vstack([home, q]), axis=0))
    band = friction / DEFAULT_STIFFNESS_N_PER_M / machine.joint_scale
    np.testing.assert_allclose(q - m.settled_joints, direction * band, atol=1e-7)
    np.testing.assert_allclose(m.true_poses, ROBOT.forward_kinematics(TRUE, m.settled_joints), atol=SETTLED_MM)
    s = np.array([1e-3, -2e-3, 5e-4])
    m = Testbed(ROBOT, TRUE, options=MachineOptions(transmission_scale=tuple(s))).measure(q)
    np.testing.assert_allclose(m.settled_joints - home, (1 + s) * (q - home), atol=1e-9)
    np.testing.assert_allclose(m.true_poses, ROBOT.forward_kinematics(TRUE, m.settled_joints), atol=SETTLED_MM)


def test_gravity_and_payload_pull_the_effector_down():
    q = commands(2, 9)
    m = Testbed(ROBOT, TRUE, options=MachineOptions(gravity=True, payload_kg=0.5)).measure(q)
    assert build_machine(ROBOT, TRUE, MachineOptions(gravity=True)).model.opt.gravity[2] == pytest.approx(-GRAVITY_M_S2)
    sag = m.true_poses[:, 2] - ROBOT.forward_kinematics(TRUE, q)[:, 2]
    # about (effector + payload + carriages + rods) g / 3 per belt over 1e5 N/m: tens of micrometres
    assert np.all(sag < -1e-3) and np.all(sag > -1.0), sag


def test_validation():
    with pytest.raises(ValueError, match=r"theta must have shape \(27,\), got \(26,\)"):
        build_spec(ROBOT, NOMINAL[:26])
    with pytest.raises(ValueError, match=r"transmission_scale must have 3 values \(one per chain\), got 6"):
        build_spec(ROBOT, NOMINAL, MachineOptions(transmission_scale=(0.0,) * 6))


def test_the_tilting_kinematics_derivatives_and_inverse_with_every_pair_unequal():
    """Every pair's rods unequal by up to 0.5 mm (the effector tilts, every chain's closure moves
    with every pair): the closure's derivatives match central differences (h = 1e-6: rounding eps
    |intermediates ~500 mm| / h ~1e-7, as the contract test's), the inverse kinematics returns the
    forward kinematics' joints, and the chains are coupled (an off-chain rod-difference column)."""
    theta = TRUE.copy()
    theta[ROBOT.table.indices(["arm_diff1", "arm_diff2", "arm_diff3"])] = [0.5, -0.3, 0.4]
    poses = reachable_poses(ROBOT, 5, 2, theta=theta)
    joints = ROBOT.inverse_kinematics(theta, poses)
    np.testing.assert_allclose(ROBOT.forward_kinematics(theta, joints), poses, atol=1e-9)
    joints = joints + 1e-3  # off the closure on purpose
    jac = ROBOT.closure_jacobians(theta, joints, poses)
    h = 1e-6
    for analytic, vary, x0 in ((jac.pose, lambda x: ROBOT.closure(theta, joints, x), poses),
                               (jac.joints, lambda q: ROBOT.closure(theta, q, poses), joints),
                               (jac.parameters, lambda th: ROBOT.closure(th, joints, poses), theta)):
        steps = np.eye(x0.shape[-1]) * h
        fd = np.stack([(vary(x0 + d) - vary(x0 - d)) / (2 * h) for d in steps], axis=-1)
        np.testing.assert_allclose(analytic, fd, atol=1e-6)
    arm_diff1 = ROBOT.table.index("arm_diff1")
    assert np.abs(jac.parameters[:, 1:, arm_diff1]).min() > 1e-3  # pair 1's difference moves towers 2, 3
