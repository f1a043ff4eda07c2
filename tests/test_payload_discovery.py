"""Recordings at two payloads (a recorded ``payload_kg`` channel): compliance with its payload
terms (calib.effects.compliance.LoadedCompliance), the MuJoCo machine driven run by run at each
payload, and discovery on the Delta, whose geometry absorbs most of a one-payload load pattern."""

import numpy as np
import pytest

from calib.effects import EFFECTS, EffectData
from calib.effects.base import PAYLOAD_CHANNEL
from calib.effects.compliance import LOADED, TWO_PAYLOADS_KG, for_payload, payload_varies
from calib.effects.granularity import per_chain_form
from calib.robots import default_robot
from pipeline.simulation import effect_recording
from pipeline.simulation.scenarios import DISCOVERY_NOISE, machine_context, simulate
from pipeline.workflows.discovery import discover

DELTA = default_robot("delta")


def _data(robot, n=30, payload=None, seed=0):
    rng = np.random.default_rng(seed)
    ws = robot.workspace_bounds()
    poses = ws[:, 0] + rng.uniform(size=(n, robot.pose_dim)) * np.ptp(ws, axis=1)
    joints = robot.inverse_kinematics(robot.table.nominal, poses)
    return EffectData(robot, robot.table.nominal, joints, poses, np.arange(n, dtype=float), DISCOVERY_NOISE,
                      payload_kg=payload)


def test_the_payload_form_is_used_only_where_the_payload_varies():
    comp = EFFECTS["compliance"]
    assert for_payload(comp, _data(DELTA)) is comp
    assert for_payload(comp, _data(DELTA, payload=np.full(30, 2.0))) is comp
    varying = _data(DELTA, payload=np.r_[np.zeros(15), np.full(15, 4.0)])
    assert payload_varies(varying) and for_payload(comp, varying) is LOADED
    assert for_payload(EFFECTS["joint_friction"], varying) is EFFECTS["joint_friction"]
    assert LOADED.name == "compliance"
    assert varying.subset(np.arange(10, 20)).payload_kg.tolist() == [0.0] * 5 + [4.0] * 5
    with pytest.raises(ValueError, match="payload_kg"):
        _data(DELTA, payload=np.full(30, -1.0))


@pytest.mark.parametrize("robot", ["delta", "hexapod", "rus"])
def test_the_payload_terms_are_the_load_of_each_row_over_the_stiffness(robot):
    """One machine (platform M, stiffness k) at payloads p_n: the loaded form with its payload
    coefficient g/k reproduces, row by row, the one-payload compliance of a machine carrying p_n."""
    r = default_robot(robot)
    p = np.r_[np.full(10, 0.5), np.full(10, 4.0), np.full(10, 0.5)]
    data = _data(r, payload=p)
    ctx = machine_context(r)
    base = EFFECTS["compliance"]
    g_over_k = 1e-7
    loaded_ctx = ctx.with_payload(p.mean())
    shape = LOADED._shape(r, loaded_ctx)  # ratios of the one-payload coefficients at the mean payload
    from calib.effects.compliance import _platform_load_kg
    load = _platform_load_kg(r, loaded_ctx)
    coef = np.concatenate([shape * load * g_over_k, [g_over_k], [g_over_k * ctx.payload_height_m / ctx.m_per_mm / 100.0]
                           if len(LOADED.coefficients(r)) > len(shape) + 1 else []])
    got = LOADED.joint_regressors(r, r.table.nominal, data) @ coef
    for level in (0.5, 4.0):
        rows = np.flatnonzero(p == level)
        c = ctx.with_payload(level)
        want = base.joint_regressors(r, r.table.nominal, data.subset(rows)) @ (
            LOADED._shape(r, c) * _platform_load_kg(r, c) * g_over_k)
        np.testing.assert_allclose(got[rows], want, rtol=1e-9, atol=1e-15)


def test_the_stiffness_comes_from_the_payload_term_per_chain_too():
    ctx = machine_context(DELTA).with_payload(2.0)
    n = len(LOADED.coefficients(DELTA))
    coef = np.full(n, 1e-7)
    coef[-1] = 2e-8
    k = LOADED.machine_settings(coef, DELTA, ctx)["options"]["actuator_stiffness"]
    assert k == pytest.approx(ctx.gravity_m_s2 * ctx.m_per_mm / 2e-8)
    pc = per_chain_form(LOADED)
    assert [c.name for c in pc.coefficients(DELTA)][-3:] == [f"payload_over_stiffness[chain {i}]" for i in (1, 2, 3)]
    rows = np.tile(coef, (3, 1))
    rows[:, -1] = [1e-8, 2e-8, 4e-8]
    ks = pc.machine_settings(pc.flat_coefficients(rows, DELTA), DELTA, ctx)["options"]["actuator_stiffness"]
    assert ks == pytest.approx(tuple(ctx.gravity_m_s2 * ctx.m_per_mm / rows[:, -1]))


def test_one_payload_given_row_by_row_is_the_machine_carrying_it():
    joints = DELTA.inverse_kinematics(DELTA.table.nominal, _data(DELTA, n=6).measured)
    settings = {"options": {"payload_kg": 2.0}, "effects": {}}
    a = simulate(DELTA, DELTA.table.nominal, joints, settings, DISCOVERY_NOISE, seed=3)
    b = simulate(DELTA, DELTA.table.nominal, joints, {"options": {}, "effects": {}}, DISCOVERY_NOISE, seed=3,
                 payload_kg=np.full(6, 2.0))
    np.testing.assert_array_equal(a.measured, b.measured)


def test_a_two_payload_recording_moves_the_machine_by_the_loaded_compliance_and_records_the_payload():
    rec = effect_recording("compliance", 3, robot="delta", n_poses=40, payloads=2, magnitude_noise=10)
    p = rec.extras[PAYLOAD_CHANNEL]
    light, heavy = sorted(set(p.tolist()))
    assert TWO_PAYLOADS_KG[0][0] <= light <= TWO_PAYLOADS_KG[0][1] and TWO_PAYLOADS_KG[1][0] <= heavy <= TWO_PAYLOADS_KG[1][1]
    assert np.count_nonzero(np.diff(p)) == 3  # light, heavy, light, heavy
    assert np.all(np.diff(rec.t_s) > 0)
    sim = rec.meta["simulation"]
    coef = np.array(list(sim["coefficients"].values()))
    assert list(sim["coefficients"]) == [c.name for c in LOADED.coefficients(DELTA)]
    theta = DELTA.table.nominal + np.array(sim["injected_errors"])
    data = EffectData(DELTA, theta, rec.joints, rec.measured, rec.t_s, rec.noise, payload_kg=p)
    dq = LOADED.joint_regressors(DELTA, theta, data) @ coef
    noise = rec.noise.position_mm
    moved = DELTA.forward_kinematics(theta, rec.joints + dq, initial=rec.measured)
    still = DELTA.forward_kinematics(theta, rec.joints, initial=rec.measured)
    z = (rec.measured - moved) / noise
    assert 0.6 < np.sqrt(np.mean(z ** 2)) < 1.4  # 120 values: +-4 sd
    assert np.sqrt(np.mean(((rec.measured - still) / noise) ** 2)) > 3  # the compliance is there


def test_on_the_delta_two_payloads_name_the_compliance_the_geometry_hides_at_one():
    """Seed 101 (per joint, 78 poses): at one payload the geometry absorbs the load pattern and
    nothing is named; at two the compliance is named and explains the recording."""
    one = discover(effect_recording("compliance", 101, robot="delta", granularity="per_chain"), resim=False).summary
    two = discover(effect_recording("compliance", 101, robot="delta", granularity="per_chain", payloads=2),
                   resim=False).summary
    assert one["effects"] == []
    assert two["effects"] == ["compliance"] and two["explained"]
    coefficients = two["effect_parameters"]["compliance"]
    assert "payload_over_stiffness[chain 1]" in coefficients or "payload_over_stiffness" in coefficients


def test_left_out_at_two_payloads_the_compliance_is_unknown_and_the_remainder_follows_the_load():
    rec = effect_recording("compliance", 102, robot="delta", granularity="per_chain", payloads=2)
    s = discover(rec, resim=False, candidates=["joint_friction", "actuator_scale", "instrument_drift",
                                               "lost_count"]).summary
    assert not s["explained"]
    assert s["remaining"]["follows"][0] == "load"
