"""The identified machine in MuJoCo (pipeline.simulation.mjcf_export, ``--export-mjcf``): loaded by
plain ``mujoco.MjModel.from_xml_path``, commanded with joint values, it settles where the identified
model (calib's forward kinematics of the identified parameters, the effects it holds applied to the
joints) puts the platform; the effects MuJoCo cannot hold are named in the file."""

import mujoco
import numpy as np
import pytest

from calib.effects import EFFECTS
from calib.effects.granularity import per_chain_form
from calib.effects.records import EffectRecord, FittedEffect
from calib.robots import default_robot
from calib.robots.rus import RotaryHexapod
from calib.rotation import euler_from_quaternion
from pipeline.discover import main as discover_main
from pipeline.formats import Calibration, read_calibration, validity_domain, write_calibration
from pipeline.run import main as run_main
from pipeline.simulation.mjcf_export import export_mjcf, mjcf_text

ROBOTS = ("hexapod", "delta", "rus")
#: At rest when every joint speed is below this (m/s or rad/s): the testbed's default.
SETTLE_SPEED = 1e-9
MAX_STEPS = 20000
#: The acceptance: 1e-6 mm noise-free; on angles the same at a 100 mm lever (1e-8 rad).
POSITION_TOL_MM, ANGLE_TOL_RAD = 1e-6, 1e-8


def calibration(robot, theta, fitted=()):
    """A calibration of ``robot`` identifying ``theta`` with the fitted effects ``fitted``."""
    free = tuple(robot.free_default)
    home = robot.home_pose[None]
    validity = validity_domain(robot, home, robot.inverse_kinematics(robot.table.nominal, home), [0.0])
    return Calibration(validity=validity, robot=robot, theta=np.asarray(theta, dtype=float), std=np.zeros(robot.n_parameters), free=free,
                       covariance=np.eye(len(free)) * 1e-6, effects=tuple(EffectRecord.from_fitted(fe, robot) for fe in fitted),
                       recording={"name": "test.csv"}, produced_by="tests")


def identified_theta(robot, seed=0):
    """Nominal plus errors drawn here (0.05 mm, 5e-4 rad on the default free parameters)."""
    theta = robot.table.nominal.copy()
    free = robot.table.indices(robot.free_default)
    size = np.where(robot.table.angle_mask()[free], 5e-4, 0.05)
    theta[free] += np.random.default_rng(seed).uniform(-1.0, 1.0, free.size) * size
    return theta


def commanded_joints(robot, n=5, seed=1):
    """(n, C) joint commands: the nominal inverse kinematics of poses drawn in the workspace."""
    ws = robot.workspace_bounds()
    poses = ws[:, 0] + np.random.default_rng(seed).uniform(size=(n, robot.pose_dim)) * np.ptp(ws, axis=1)
    return robot.inverse_kinematics(robot.table.nominal, poses)


def settle_file(path, robot, joints):
    """(N, D) where the machine in ``path`` comes to rest for each row of ``joints``, one after
    another from its home keyframe, commanded as the file's comment says (ctrl = joint in SI)."""
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    si = 1e-3 if robot.joint_unit == "mm" else 1.0
    pos = m.sensor("platform_pos").adr[0]
    quat = m.sensor("platform_quat").adr[0] if robot.pose_dim == 6 else None
    out = []
    for q in joints:
        d.ctrl[:] = q * si
        for step in range(MAX_STEPS):
            mujoco.mj_step(m, d)
            if step > 5 and np.max(np.abs(d.qvel)) < SETTLE_SPEED:
                break
        else:
            raise AssertionError(f"not at rest after {MAX_STEPS} steps")
        p = d.sensordata[pos:pos + 3] * 1e3
        out.append(p if quat is None else np.r_[p, euler_from_quaternion(d.sensordata[quat:quat + 4])])
    return np.array(out)


def assert_lands(robot, got, want):
    np.testing.assert_array_less(np.linalg.norm(got[:, :3] - want[:, :3], axis=1), POSITION_TOL_MM)
    if robot.pose_dim == 6:
        np.testing.assert_array_less(np.abs(got[:, 3:] - want[:, 3:]), ANGLE_TOL_RAD)


@pytest.mark.parametrize("name", ROBOTS)
def test_the_identified_machine_settles_where_the_identified_model_predicts(name, tmp_path):
    robot = default_robot(name)
    theta = identified_theta(robot)
    c = robot.n_chains
    scale = np.random.default_rng(2).uniform(-2e-3, 2e-3, c)
    cal = calibration(robot, theta, [FittedEffect(EFFECTS["actuator_scale"], scale, np.zeros(c))])
    path = export_mjcf(cal, tmp_path / "identified.xml")
    joints = commanded_joints(robot)
    # The identified model: the joints sit (1 + s) times their stroke from the centre of travel.
    centre = robot.joint_limits().mean(axis=1)
    want = robot.forward_kinematics(theta, joints + scale * (joints - centre))
    got = settle_file(path, robot, joints)
    assert_lands(robot, got, want)
    # The scale matters: without it the machine would land elsewhere.
    assert np.max(np.linalg.norm(got[:, :3] - robot.forward_kinematics(theta, joints)[:, :3], axis=1)) > 1e-3


def test_geometry_alone_settles_at_the_forward_kinematics(tmp_path):
    robot = default_robot("delta")
    theta = identified_theta(robot, seed=5)
    path = export_mjcf(calibration(robot, theta), tmp_path / "delta.xml")
    joints = commanded_joints(robot, n=3, seed=6)
    assert_lands(robot, settle_file(path, robot, joints), robot.forward_kinematics(theta, joints))
    assert "Effects held: none (the calibration found none)." in path.read_text()


def test_the_actuator_scale_is_about_the_centre_of_travel(tmp_path):
    """A motor range off centre: the scale's reference (the centre of travel) is not the
    builder's joint zero, and the file still puts the platform where the model does."""
    nominal = default_robot("rus")
    robot = RotaryHexapod.from_description({**nominal.description(), "joint_range_rad": [-1.0, 1.6]})
    centre = robot.joint_limits().mean(axis=1)
    np.testing.assert_allclose(centre, 0.3)
    theta = identified_theta(robot, seed=3)
    scale = np.full(6, 1.5e-3)
    cal = calibration(robot, theta, [FittedEffect(EFFECTS["actuator_scale"], scale, np.zeros(6))])
    path = export_mjcf(cal, tmp_path / "rus.xml")
    joints = commanded_joints(robot, n=3, seed=4)
    want = robot.forward_kinematics(theta, joints + scale * (joints - centre))
    got = settle_file(path, robot, joints)
    assert_lands(robot, got, want)
    about_zero = robot.forward_kinematics(theta, joints + scale * joints)
    assert np.min(np.linalg.norm(about_zero[:, :3] - want[:, :3], axis=1)) > 1e-3  # the reference matters


@pytest.mark.parametrize("name", ROBOTS)
def test_each_joints_dead_band_is_its_friction_loss(name, tmp_path):
    robot = default_robot(name)
    c = robot.n_chains
    band = np.linspace(1.0, 2.0, c) * (2e-3 if robot.joint_unit == "mm" else 2e-5)
    fe = FittedEffect(per_chain_form(EFFECTS["joint_friction"]), band, np.zeros(c))
    path = export_mjcf(calibration(robot, robot.table.nominal, [fe]), tmp_path / "friction.xml")
    m = mujoco.MjModel.from_xml_path(str(path))
    dofs = m.jnt_dofadr[m.actuator_trnid[:, 0]]
    stiffness = m.actuator_gainprm[:, 0] * m.actuator_gear[:, 0] ** 2
    si = 1e-3 if robot.joint_unit == "mm" else 1.0
    np.testing.assert_allclose(m.dof_frictionloss[dofs], band * si * stiffness, rtol=1e-12)
    assert np.count_nonzero(m.dof_frictionloss) == c  # the actuated joints only
    text = path.read_text()
    assert "Effects held: joint_friction" in text and "leaves no dead band at rest" in text


def test_compliance_is_the_servo_stiffness_under_gravity(tmp_path):
    robot = default_robot("hexapod")
    eff = EFFECTS["compliance"]
    c0 = 0.02  # mm: the platform's weight over the servo stiffness
    coef = np.array([c0, 0.0])
    path = export_mjcf(calibration(robot, robot.table.nominal, [FittedEffect(eff, coef, np.zeros(2))]),
                       tmp_path / "compliance.xml")
    m = mujoco.MjModel.from_xml_path(str(path))
    np.testing.assert_allclose(m.opt.gravity, [0.0, 0.0, -9.81])
    weight_n = m.body("platform").mass[0] * 9.81
    stiffness = m.actuator_gainprm[:, 0] * m.actuator_gear[:, 0] ** 2  # N/m
    np.testing.assert_allclose(stiffness, weight_n / (c0 * 1e-3), rtol=1e-12)


def test_the_effects_mujoco_cannot_hold_are_named_in_the_file(tmp_path):
    robot = default_robot("hexapod")
    fitted = [FittedEffect(EFFECTS["thermal_drift"], np.array([1e-5]), np.zeros(1)),
              FittedEffect(EFFECTS["periodic_screw_error"], np.array([1e-3, 2e-3]), np.zeros(2), 5.0)]
    path = export_mjcf(calibration(robot, robot.table.nominal, fitted), tmp_path / "drift.xml")
    text = path.read_text()
    comment = text[text.index("<!--"):text.index("-->")]
    assert "Effects MuJoCo cannot hold, left out of this model: thermal_drift" in comment
    assert "periodic_screw_error" in comment and "Effects held: none." in comment
    m = mujoco.MjModel.from_xml_path(str(path))
    assert not np.any(m.dof_frictionloss) and not np.any(m.opt.gravity)


def test_the_file_round_trips_through_the_calibration_file(tmp_path):
    robot = default_robot("rus")
    fe = FittedEffect(EFFECTS["actuator_scale"], np.full(6, 1e-3), np.zeros(6))
    cal = calibration(robot, identified_theta(robot), [fe])
    read = read_calibration(write_calibration(tmp_path / "r.calibration.json", cal))
    assert mjcf_text(read) == mjcf_text(cal)


def test_an_existing_file_is_refused_and_overwrite_replaces_it(tmp_path):
    robot = default_robot("delta")
    path = tmp_path / "m.xml"
    path.write_text("keep me")
    with pytest.raises(FileExistsError, match="exists; pass --overwrite"):
        export_mjcf(calibration(robot, robot.table.nominal), path)
    assert path.read_text() == "keep me"
    export_mjcf(calibration(robot, robot.table.nominal), path, overwrite=True)
    assert mujoco.MjModel.from_xml_path(str(path)).nu == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.xml"]  # no temporary file left


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0]
    return err[0]


def test_pipeline_run_writes_the_identified_machine(tmp_path, capsys):
    xml = tmp_path / "machine.xml"
    assert run_main(["--heldout", "0", "--out", str(tmp_path), "--export-mjcf", str(xml), "--quiet"]) == 0
    cal = read_calibration(tmp_path / "hexapod_paper.calibration.json")
    assert xml.read_text() == mjcf_text(cal)
    joints = cal.robot.home_lengths[None] + np.array([[1.0, -1.0, 2.0, 0.5, -0.5, 1.5]])
    assert_lands(cal.robot, settle_file(xml, cal.robot, joints), cal.robot.forward_kinematics(cal.theta, joints))


def test_pipeline_run_refuses_an_existing_or_unwritable_path_before_any_work(tmp_path, capsys):
    xml = tmp_path / "machine.xml"
    xml.write_text("keep me")
    assert run_main(["--heldout", "0", "--out", str(tmp_path), "--export-mjcf", str(xml), "--quiet"]) == 2
    assert "--export-mjcf" in one_error_line(capsys) and xml.read_text() == "keep me"
    assert not list(tmp_path.glob("hexapod_paper*"))
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    assert run_main(["--heldout", "0", "--out", str(tmp_path), "--export-mjcf", str(blocker / "m.xml"),
                     "--quiet"]) == 2
    assert "--export-mjcf" in one_error_line(capsys)


def test_pipeline_discover_writes_the_machine_with_its_effects(tmp_path, capsys):
    xml = tmp_path / "found.xml"
    args = ["--scenario", "joint_friction", "--no-resim", "--out", str(tmp_path), "--export-mjcf", str(xml)]
    assert discover_main(args) == 0
    assert f"wrote {xml}" in capsys.readouterr().out
    cal = read_calibration(tmp_path / "hexapod_joint_friction_0_discover.calibration.json")
    assert xml.read_text() == mjcf_text(cal)
    held = [e.name for e in cal.effects]
    assert held and f"Effects held: {', '.join(held)}" in xml.read_text()
    again = ["--scenario", "joint_friction", "--no-resim", "--out", str(tmp_path / "again"), "--export-mjcf", str(xml)]
    assert discover_main(again) == 2  # the file exists: refused before the analysis, nothing written
    assert "--export-mjcf" in one_error_line(capsys)
    assert not list((tmp_path / "again").glob("*"))


def test_pipeline_export_to_mjcf_writes_a_loadable_identified_machine(tmp_path, capsys):
    """``pipeline.export --to mjcf`` from a run's calibration file: plain MuJoCo loads it, and it
    is the file ``--export-mjcf`` writes for the same calibration."""
    import mujoco

    from pipeline.export import main as export_main
    from pipeline.run import run as run_main

    run_main(["--heldout", "0", "--out", str(tmp_path), "--quiet", "--export-mjcf", str(tmp_path / "run.xml")])
    cal = tmp_path / "hexapod_paper.calibration.json"
    assert export_main(["--calibration", str(cal), "--to", "mjcf", "--out", str(tmp_path / "export.xml")]) == 0
    assert (tmp_path / "export.xml").read_text() == (tmp_path / "run.xml").read_text()
    assert mujoco.MjModel.from_xml_path(str(tmp_path / "export.xml")).nu == 6
    capsys.readouterr()
    assert export_main(["--calibration", str(cal), "--to", "mjcf", "--out", str(tmp_path / "export.xml")]) == 2
    assert "exists" in capsys.readouterr().err
