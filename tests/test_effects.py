import numpy as np
import pytest

from calib.effects import EFFECTS, EffectData, discover_effect, effect_regressors, fit_effect
from calib.hexapod import paper_hexapod
from calib.kinematics import forward_kinematics, inverse_kinematics
from calib.noise import SensorNoise
from calib.rotation import rotation_matrix
from calib.workspace import random_poses

NOMINAL = paper_hexapod()
ACTUAL = paper_hexapod(with_table3_errors=True)
WORKSPACE = np.array([[-25, 25], [-25, 25], [190, 215], [-0.1, 0.1], [-0.1, 0.1], [-0.15, 0.15]], dtype=float)
NOISE = SensorNoise(0.001, 1e-6, "normal")


def synthetic(effect, coef, seed=0, n=80, pitch=None, noise=None):
    """Measurements of the calib machine whose legs carry X(effect) . coef (exact truth)."""
    rng = np.random.default_rng(seed)
    targets = random_poses(n, rng, WORKSPACE)
    commanded = inverse_kinematics(NOMINAL, targets)
    t = np.cumsum(rng.uniform(0.5, 1.5, n))
    reached = targets
    for _ in range(4):  # fixed point: the load regressor depends on the pose reached
        X = effect_regressors(effect, ACTUAL, EffectData(NOMINAL, commanded, reached, t, NOISE), pitch)
        reached = forward_kinematics(ACTUAL, commanded + X @ np.asarray(coef, dtype=float))
    if noise is not None:
        reached = reached + noise.sample(n, seed + 1)
    return EffectData(NOMINAL, commanded, reached, t, NOISE)


def test_direction_is_the_last_motion_of_each_leg():
    c = np.array([[1.0] * 6, [2.0] * 6, [2.0] * 6, [0.5] * 6]) + 233.23808
    d = EffectData(NOMINAL, c, np.tile([0, 0, 200, 0, 0, 0.0], (4, 1)), np.arange(4.0), NOISE).direction
    np.testing.assert_array_equal(d[:, 0], [1, 1, 1, -1])  # an unchanged command keeps the last direction


def test_compliance_regressors_are_static_equilibrium():
    poses = random_poses(10, 3, WORKSPACE)
    data = EffectData(NOMINAL, inverse_kinematics(NOMINAL, poses), poses, np.arange(10.0), NOISE)
    X = effect_regressors("leg_compliance", ACTUAL, data)
    f = -X[..., 0]  # compressive leg forces for a unit weight at the platform origin
    R = rotation_matrix(poses[:, 3:])
    a = np.einsum("nij,lj->nli", R, ACTUAL.platform_joints) + poses[:, None, :3]
    u = a - ACTUAL.base_joints
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    force = np.einsum("nl,nli->ni", f, u)
    moment = np.einsum("nl,nli->ni", f, np.cross(a, u)) + np.cross(poses[:, :3], [0, 0, -1.0])
    np.testing.assert_allclose(force, np.tile([0, 0, 1.0], (10, 1)), atol=1e-12)  # legs carry the weight
    np.testing.assert_allclose(moment, 0, atol=1e-9)
    assert np.all(f > 0)  # a hanging weight compresses every leg of this layout


@pytest.mark.parametrize("effect,coef", [
    ("joint_friction", [0.004]),
    ("thermal_drift", [5e-5]),
    ("actuator_scale", [1e-4, -2e-4, 3e-4, -1e-4, 2e-4, 5e-5]),
    ("leg_compliance", [0.01, 0.002]),
])
def test_joint_fit_recovers_injected_effect_and_geometry_noise_free(effect, coef):
    data = synthetic(effect, coef)
    fit = fit_effect(data, effect, iterations=4)
    np.testing.assert_allclose(fit.coefficients, coef, rtol=1e-5, atol=1e-10)
    np.testing.assert_allclose(fit.hexapod.errors, ACTUAL.errors, atol=1e-7)
    assert fit.chi2 < 1e-6


def test_pitch_search_finds_the_screw_pitch_through_noise():
    coef = np.array([0.004, -0.002, 0.001, 0.003, -0.003, 0.002, 0.0, 0.004, 0.002, 0.002, -0.001, -0.004])
    data = synthetic("periodic_screw_error", coef, pitch=4.3, noise=NOISE)
    fit = fit_effect(data, "periodic_screw_error")
    assert fit.pitch_mm == pytest.approx(4.3, rel=2e-3)
    np.testing.assert_allclose(fit.coefficients, coef, atol=5 * fit.coefficient_std.max())


@pytest.mark.parametrize("effect", ["none", "joint_friction", "thermal_drift", "actuator_scale"])
def test_discovery_names_the_synthetic_effect(effect):
    coef = {"none": [], "joint_friction": [0.004], "thermal_drift": [5e-5],
            "actuator_scale": [5e-5, -5e-5, 5e-5, -5e-5, 5e-5, 5e-5]}[effect]
    d = discover_effect(synthetic(effect, coef, seed=4, noise=NOISE))
    assert d.effect == effect
    assert d.flagged == ()
    assert set(d.evidence) == set(EFFECTS) | {"geometry_chi2_test"}


def test_a_gross_row_is_flagged_not_explained():
    data = synthetic("none", [], seed=5, noise=NOISE)
    measured = data.measured.copy()
    measured[17, :3] += [0.02, -0.02, 0.0]
    d = discover_effect(EffectData(NOMINAL, data.commanded, measured, data.t_s, NOISE))
    assert d.flagged == (17,) and d.effect == "none"


def test_located_mismatch_points_at_time_for_a_drift():
    d = discover_effect(synthetic("thermal_drift", [1e-4], seed=6, noise=NOISE))
    assert d.located["time_correlation"] > 0.5
    assert abs(d.located["direction_contrast_se"]) < 4


@pytest.mark.parametrize("kw,match", [
    (dict(effect="magic"), "unknown effect 'magic'"),
])
def test_fit_effect_validation(kw, match):
    with pytest.raises(ValueError, match=match):
        fit_effect(synthetic("none", []), **kw)


def test_effect_data_validation():
    c = np.zeros((5, 6))
    with pytest.raises(ValueError, match="same length, got 5, 4 and 5"):
        EffectData(NOMINAL, c, np.zeros((4, 6)), np.arange(5.0), NOISE)
    with pytest.raises(ValueError, match=r"measured must have shape \(N, 6\)"):
        EffectData(NOMINAL, c, np.zeros((5, 3)), np.arange(5.0), NOISE)
    with pytest.raises(ValueError, match="at least 12 measurements"):
        discover_effect(synthetic("none", [], n=10))
    with pytest.raises(ValueError, match="unknown effect 'x'"):
        discover_effect(synthetic("none", []), candidates=("x",))
