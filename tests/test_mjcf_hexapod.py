from operator import attrgetter

import mujoco
import numpy as np
import pytest

from calib.hexapod import paper_hexapod
from mjcf.hexapod import DEFAULT_XML, HexapodModelOptions, build_hexapod, hexapod_xml
from mjcf.units import m_to_mm, mm_to_m


def test_saved_default_model_is_current():
    # The .xml shipped for MuJoCo's viewer must be what the builder makes today: compared by
    # value (the last printed digit of a float may differ between machines), not as text.
    m = mujoco.MjModel.from_xml_path(str(DEFAULT_XML))
    fresh = build_hexapod(paper_hexapod(with_table3_errors=True))
    assert (m.nu, m.neq, m.nsensor) == (fresh.nu, fresh.neq, fresh.nsensor) == (6, 6, 2)
    for field in ("body_pos", "body_quat", "site_pos", "actuator_gainprm", "actuator_biasprm", "eq_solref",
                  "body_mass", "opt.timestep"):
        a, b = (np.asarray(attrgetter(field)(x)) for x in (m, fresh))
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-15, err_msg=field)


def test_joint_positions_are_the_parameter_set_in_metres():
    hx = paper_hexapod(with_table3_errors=True)
    m = build_hexapod(hx)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    for i in range(6):
        np.testing.assert_allclose(m_to_mm(d.body(f"leg{i + 1}_lower").xpos), hx.base_joints[i], atol=1e-9)
        # At zero stroke each leg is the nominal home length plus its dl.
        tip = d.site(f"leg{i + 1}_tip").xpos
        np.testing.assert_allclose(m_to_mm(np.linalg.norm(tip - d.body(f"leg{i + 1}_lower").xpos)),
                                   hx.geometry.home_lengths[i] + hx.leg_offsets[i], atol=1e-9)
    # Platform joints relative to the platform frame.
    for i in range(6):
        np.testing.assert_allclose(m_to_mm(m.site(f"P{i + 1}").pos), hx.platform_joints[i], atol=1e-9)


def test_options_reach_the_model():
    hx = paper_hexapod()
    m = build_hexapod(hx, HexapodModelOptions(gravity=True, payload_kg=3.0, actuator_stiffness=1e5, joint_friction=0.5))
    assert m.opt.gravity[2] == pytest.approx(-9.81)
    assert m.body("payload").mass[0] == pytest.approx(3.0)
    assert m.actuator_gainprm[0, 0] == pytest.approx(1e5)
    assert m.dof_frictionloss[m.joint("leg1_slide").dofadr[0]] == pytest.approx(0.5)
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    off = build_hexapod(hx)
    assert np.all(off.opt.gravity == 0)


@pytest.mark.parametrize("kw,match", [
    (dict(payload_kg=-1.0), "payload_kg must be >= 0"),
    (dict(actuator_stiffness=0.0), "actuator_stiffness must be > 0"),
    (dict(timestep=-1e-3), "timestep must be > 0"),
])
def test_option_validation(kw, match):
    with pytest.raises(ValueError, match=match):
        HexapodModelOptions(**kw)


def test_units_round_trip():
    x = np.array([1.0, 250.0])
    np.testing.assert_allclose(m_to_mm(mm_to_m(x)), x)
    assert mm_to_m(1000.0) == pytest.approx(1.0)
