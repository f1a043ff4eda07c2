"""Tests of mjcf.delta (the MJCF Delta) and pipeline.delta_testbed (measuring it)."""

import dataclasses

import mujoco
import numpy as np
import pytest

from calib.delta import PARAMETER_NAMES, PARAMETER_UNITS, DeltaParams, canonical_params, forward_kinematics, inverse_kinematics
from calib.delta_identification import DEFAULT_FREE, calibration_gain, identify_fkm, identify_ikm, perturb_params, random_workspace_positions
from mjcf.delta import ACTUATORS, ARM_JOINTS, PLATE_SENSOR, DeltaMjcfGeometry, build_delta_model, build_delta_xml
from pipeline.delta_testbed import M_PER_MM, DeltaTestbed, delta_geometry_si

NOM = DeltaParams.nominal()
TRUE = perturb_params(NOM, 1.0, np.deg2rad(1.0), 42)
FREE_IDX = np.array([PARAMETER_NAMES.index(n) for n in DEFAULT_FREE])
IS_MM = np.array([u == "mm" for u in PARAMETER_UNITS])[FREE_IDX]


@pytest.fixture(scope="module")
def measured():
    """Noise-free MuJoCo measurements of TRUE at 12 nominal-IK configurations."""
    q = inverse_kinematics(NOM, random_workspace_positions(12, 3))
    return DeltaTestbed(TRUE).measure(q)


def test_geometry_conversion_is_metres():
    g = delta_geometry_si(TRUE, rn_mm=30.0)
    np.testing.assert_allclose(g.shoulder, TRUE.shoulders() * 1e-3)
    np.testing.assert_allclose(g.forearm, TRUE.Lb * M_PER_MM)
    np.testing.assert_allclose(g.arm[:, 0], TRUE.Lax * 1e-3)
    np.testing.assert_allclose(np.linalg.norm(g.plate_attach, axis=1), 0.030)
    np.testing.assert_allclose(g.home_plate * 1e3, forward_kinematics(TRUE, g.home_q[None])[0])


def test_model_structure():
    m = build_delta_model(delta_geometry_si(TRUE))
    assert (m.nq, m.nv, m.nu, m.neq) == (12, 12, 3, 3)
    assert all(m.eq_type[k] == mujoco.mjtEq.mjEQ_CONNECT for k in range(m.neq))
    assert np.all(m.geom_contype == 0) and np.all(m.geom_conaffinity == 0)
    assert np.all(m.opt.gravity == 0.0)
    for name in ARM_JOINTS:
        assert m.joint(name).type[0] == mujoco.mjtJoint.mjJNT_HINGE
    for name in ACTUATORS:
        assert m.actuator(name).id >= 0
    assert m.sensor(PLATE_SENSOR).type[0] == mujoco.mjtSensor.mjSENS_FRAMEPOS
    # The plate only translates.
    plate_joints = [m.joint(j) for j in range(m.njnt) if m.jnt_bodyid[j] == m.body("plate").id]
    assert [int(j.type[0]) for j in plate_joints] == [int(mujoco.mjtJoint.mjJNT_SLIDE)] * 3


def test_home_keyframe_closes_the_chains():
    g = delta_geometry_si(TRUE)
    m = build_delta_model(g)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mujoco.mj_forward(m, d)
    for i in range(3):
        np.testing.assert_allclose(d.site(f"fa{i + 1}_end").xpos, d.site(f"plate_c{i + 1}").xpos, atol=1e-12)
    np.testing.assert_allclose(d.sensor(PLATE_SENSOR).data, g.home_plate, atol=1e-12)
    np.testing.assert_allclose(d.qpos[[m.joint(n).qposadr[0] for n in ARM_JOINTS]], g.home_q)


def test_settled_plate_matches_kinematics(measured):
    """MuJoCo vs calib forward kinematics of the injected parameters (mm)."""
    np.testing.assert_allclose(measured.q_true, measured.q_cmd, atol=1e-10)
    np.testing.assert_allclose(measured.positions_true, forward_kinematics(TRUE, measured.q_true), atol=1e-8)
    np.testing.assert_array_equal(measured.positions_meas, measured.positions_true)  # noise-free
    assert np.all(np.diff(measured.t_s) > 0) and measured.steps.max() < 20000


@pytest.mark.parametrize("fn", [identify_fkm, identify_ikm])
def test_identification_through_mujoco_noise_free(measured, fn):
    """Acceptance 4: identified = injected (canonical, Lay fixed) to 1e-5 mm / 1e-7 rad."""
    res = fn(NOM, measured.q_meas, measured.positions_meas)
    assert res.success, res.message
    err = np.abs(res.estimate.to_vector() - canonical_params(TRUE).to_vector())[FREE_IDX]
    assert err[IS_MM].max() < 1e-5
    assert err[~IS_MM].max() < 1e-7
    assert calibration_gain(TRUE, NOM, res.estimate).mean > 99.99


def test_noise_is_seeded():
    q = inverse_kinematics(NOM, random_workspace_positions(3, 5))
    a = DeltaTestbed(TRUE, noise_mm=1e-3, noise_rad=1e-4, seed=9).measure(q)
    b = DeltaTestbed(TRUE, noise_mm=1e-3, noise_rad=1e-4, seed=9).measure(q)
    c = DeltaTestbed(TRUE, noise_mm=1e-3, noise_rad=1e-4, seed=10).measure(q)
    np.testing.assert_array_equal(a.positions_meas, b.positions_meas)
    np.testing.assert_array_equal(a.q_meas, b.q_meas)
    assert not np.array_equal(a.positions_meas, c.positions_meas)
    assert 0 < np.abs(a.positions_meas - a.positions_true).max() < 1e-2
    assert 0 < np.abs(a.q_meas - a.q_true).max() < 1e-3


def test_step_cap_raises():
    bed = DeltaTestbed(TRUE, max_steps=10)
    q = inverse_kinematics(NOM, np.array([[50.0, 0.0, -400.0]]))
    with pytest.raises(RuntimeError, match="configuration 0: the Delta did not settle within max_steps=10 steps"):
        bed.measure(q)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"noise_mm": -1.0}, "noise_mm must be finite and >= 0, got -1.0"),
        ({"noise_rad": np.nan}, "noise_rad must be finite and >= 0"),
        ({"max_steps": 0}, "max_steps must be a positive integer, got 0"),
        ({"vel_tol": 0.0}, "vel_tol must be positive, got 0.0"),
        ({"rn_mm": -3.0}, "rn_mm must be finite and >= 0, got -3.0"),
    ],
)
def test_testbed_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DeltaTestbed(TRUE, **kwargs)


def test_measure_validation():
    bed = DeltaTestbed(NOM)
    with pytest.raises(ValueError, match=r"q_cmd must have shape \(N, 3\), got \(3,\)"):
        bed.measure(np.zeros(3))


def test_geometry_validation():
    g = delta_geometry_si(NOM)
    with pytest.raises(ValueError, match=r"theta must have shape \(3,\), got \(2,\)"):
        dataclasses.replace(g, theta=np.zeros(2))
    with pytest.raises(ValueError, match="forearm must be in metres"):
        dataclasses.replace(g, forearm=np.full(3, 480.0))
    with pytest.raises(ValueError, match="forearm must be positive"):
        dataclasses.replace(g, forearm=np.zeros(3))
    with pytest.raises(ValueError, match="shoulder must be finite"):
        dataclasses.replace(g, shoulder=np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match="timestep must be positive, got 0.0"):
        build_delta_xml(g, timestep=0.0)
    with pytest.raises(ValueError, match="geom must be a DeltaMjcfGeometry, got DeltaParams"):
        build_delta_xml(NOM)
    with pytest.raises(ValueError, match="params must be a DeltaParams, got DeltaMjcfGeometry"):
        delta_geometry_si(g)
    assert isinstance(g, DeltaMjcfGeometry)
