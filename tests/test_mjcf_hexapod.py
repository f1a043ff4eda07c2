from operator import attrgetter

import mujoco
import numpy as np
import pytest

from calib.paper import TABLE3_ERRORS
from calib.robots import Delta
from calib.robots.hexapod import paper_hexapod
from mjcf import MACHINES, build_machine
from mjcf.hexapod import DEFAULT_STIFFNESS_N_PER_M, DEFAULT_XML, LEG_MASS_KG, build_spec, integration_step
from mjcf.machine import GRAVITY_M_S2, MachineOptions
from mjcf.units import m_to_mm, mm_to_m

ROBOT = paper_hexapod()
THETA = ROBOT.table.nominal + TABLE3_ERRORS.ravel()


def test_saved_default_model_is_the_builders_machine():
    # The .xml shipped for MuJoCo's viewer is the paper's machine; MuJoCo writes 6 significant
    # digits, so it agrees with the builder to about 1e-6 relative.
    saved = mujoco.MjModel.from_xml_path(str(DEFAULT_XML))
    built = build_machine(ROBOT, THETA).model
    assert (saved.nq, saved.nv, saved.nu, saved.neq, saved.nsensor, saved.nkey) == (25, 24, 6, 6, 2, 1)
    for name in ("body_pos", "body_quat", "body_mass", "site_pos", "actuator_gainprm", "actuator_biasprm",
                 "actuator_gear", "eq_solref", "eq_solimp", "dof_damping", "dof_frictionloss", "key_qpos",
                 "key_ctrl", "qpos0", "opt.timestep", "opt.gravity"):
        a, b = (np.ravel(attrgetter(name)(m)) for m in (saved, built))
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6, err_msg=name)
    for kind, n in (("body", saved.nbody), ("site", saved.nsite), ("actuator", saved.nu), ("sensor", saved.nsensor)):
        assert [getattr(saved, kind)(k).name for k in range(n)] == [getattr(built, kind)(k).name for k in range(n)]


def test_joint_positions_are_the_parameter_vector_in_metres():
    m = build_machine(ROBOT, THETA).model
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    B, dl, P = ROBOT.legs(THETA)
    for i in range(6):
        np.testing.assert_allclose(m_to_mm(d.body(f"leg{i + 1}_lower").xpos), B[i], atol=1e-9)
        # At zero stroke each leg is its home length plus its dl.
        tip = d.site(f"leg{i + 1}_tip").xpos
        np.testing.assert_allclose(m_to_mm(np.linalg.norm(tip - d.body(f"leg{i + 1}_lower").xpos)),
                                   ROBOT.home_lengths[i] + dl[i], atol=1e-9)
        np.testing.assert_allclose(m_to_mm(m.site(f"P{i + 1}").pos), P[i], atol=1e-9)


def test_home_keyframe_is_assembled_at_the_kinematic_home():
    machine = build_machine(ROBOT, THETA)
    d = mujoco.MjData(machine.model)
    machine.reset(d)
    for i in range(6):
        np.testing.assert_allclose(d.site(f"leg{i + 1}_tip").xpos, d.site(f"P{i + 1}").xpos, atol=1e-15)
    np.testing.assert_allclose(machine.read_pose(d), ROBOT.forward_kinematics(THETA, ROBOT.home_lengths[None])[0],
                               atol=1e-10)
    np.testing.assert_allclose(machine.read_joints(d), ROBOT.home_lengths, atol=1e-12)
    # ctrl mapping: joint value (mm) -> slide stroke (m) from the home length, and back.
    lengths = ROBOT.home_lengths + np.arange(6.0)
    np.testing.assert_allclose(machine.ctrl(lengths), 1e-3 * np.arange(6.0))
    assert machine.actuated_joints == tuple(f"leg{i + 1}_slide" for i in range(6))


def test_options_reach_the_model():
    o = MachineOptions(gravity=True, payload_kg=3.0, actuator_stiffness=1e5, joint_friction=0.5,
                       transmission_scale=(0.01, 0, 0, 0, 0, -0.02), platform_mass_kg=1.5)
    m = build_machine(ROBOT, THETA, o).model
    assert m.opt.gravity[2] == pytest.approx(-GRAVITY_M_S2)
    assert m.body("payload").mass[0] == pytest.approx(3.0)
    assert m.body("platform").mass[0] == pytest.approx(1.5)
    # Gear 1 / (1 + s) and kp / g^2: the slide moves (1 + s) times the command, stiffness kept.
    g = m.actuator_gear[:, 0]
    np.testing.assert_allclose(g, 1 / (1 + np.array([0.01, 0, 0, 0, 0, -0.02])))
    np.testing.assert_allclose(m.actuator_gainprm[:, 0] * g**2, 1e5)
    np.testing.assert_allclose(-m.actuator_biasprm[:, 1] * g**2, 1e5)
    assert m.dof_frictionloss[m.joint("leg1_slide").dofadr[0]] == pytest.approx(0.5)
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    off = build_machine(ROBOT, THETA).model
    assert np.all(off.opt.gravity == 0) and off.nbody == m.nbody - 1  # no payload body
    np.testing.assert_allclose(off.actuator_gainprm[:, 0], DEFAULT_STIFFNESS_N_PER_M)


def test_stiff_servo_lowers_the_step_and_the_closure_follows():
    stiff = MachineOptions(actuator_stiffness=1e8)
    omega = np.sqrt(1e8 / LEG_MASS_KG)
    assert integration_step(stiff) == pytest.approx(0.3 / omega)
    m = build_machine(ROBOT, THETA, stiff).model
    assert m.opt.timestep == pytest.approx(0.3 / omega)
    np.testing.assert_allclose(m.eq_solref[:, 0], 2 * 0.3 / omega)
    assert integration_step(MachineOptions()) == 1e-3  # the default is not capped


def test_builder_registry_dispatches_on_the_robot_name():
    assert set(MACHINES) >= {"hexapod", "delta"}
    assert build_machine(ROBOT, THETA).model.nu == 6
    assert build_machine(Delta(), Delta().table.nominal).model.nu == 3

    class Unknown:
        name = "tripod"

    with pytest.raises(KeyError, match="no MuJoCo machine for robot 'tripod': machines exist for .*delta.*hexapod"):
        build_machine(Unknown(), np.zeros(3))


@pytest.mark.parametrize("kw,match", [
    (dict(payload_kg=-1.0), "payload_kg must be >= 0"),
    (dict(actuator_stiffness=0.0), "actuator_stiffness must be > 0"),
    (dict(timestep=-1e-3), "timestep must be > 0"),
])
def test_option_validation(kw, match):
    with pytest.raises(ValueError, match=match):
        MachineOptions(**kw)


def test_builder_validation():
    with pytest.raises(ValueError, match=r"transmission_scale must have 6 values \(one per leg\), got 3"):
        build_spec(ROBOT, THETA, MachineOptions(transmission_scale=(0.0, 0.0, 0.0)))
    with pytest.raises(ValueError, match=r"theta must have shape \(42,\), got \(6, 7\)"):
        build_spec(ROBOT, THETA.reshape(6, 7))


def test_units_round_trip():
    x = np.array([1.0, 250.0])
    np.testing.assert_allclose(m_to_mm(mm_to_m(x)), x)
    assert mm_to_m(1000.0) == pytest.approx(1.0)


def test_the_command_line_writes_only_where_asked_and_replaces_only_with_overwrite(tmp_path, capsys):
    """``python -m mjcf.hexapod``: --out writes the builder's machine there; an existing file (the
    saved default included) is refused without --overwrite, one line, untouched (before: the
    command took no flags, ignored --help and rewrote mjcf/hexapod_paper_actual.xml)."""
    from mjcf.hexapod import main

    out = tmp_path / "h.xml"
    assert main(["--out", str(out)]) == 0 and capsys.readouterr().out.strip() == str(out)
    assert out.read_text() == DEFAULT_XML.read_text()  # the saved default is current, and this is it
    out.write_text("an earlier file")
    for argv in (["--out", str(out)], []):
        before = (out.read_text(), DEFAULT_XML.stat().st_mtime_ns)
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error: --out: ") and "--overwrite" in err[0], err
        assert (out.read_text(), DEFAULT_XML.stat().st_mtime_ns) == before
    assert main(["--out", str(out), "--overwrite"]) == 0
    assert out.read_text() == DEFAULT_XML.read_text()
