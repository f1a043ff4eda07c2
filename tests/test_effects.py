"""The effect registry and the discovery engine on exact synthetic data, for every robot an
effect applies to."""

import numpy as np
import pytest

from calib import paper
from calib.effects.base import unabsorbed
from calib.effects.discovery import MIN_NESTED_DELTA_BIC
from calib.effects.compliance import interior_points
from calib.effects.granularity import per_chain_form
from calib.effects import (EFFECT_MODULES, EFFECTS, FOLLOWED_QUANTITIES, Effect, EffectData, MachineContext,
                           discover_effect, discover_effects, effect_family, effects_for, fit_effect, fit_effects,
                           nested_in,
                           regressor_correlation)
from calib.noise import SensorNoise
from calib.robot import pose_jacobian_of_joints
from calib.robots import ROBOTS, default_robot
from calib.rotation import rotation_matrix

NOISE = SensorNoise(0.001, 1e-6, "normal")
#: A wider workspace than the hexapod paper's, where effects and geometry separate.
HEXAPOD_WORKSPACE = np.array([[-25, 25], [-25, 25], [190, 215], [-0.1, 0.1], [-0.1, 0.1], [-0.15, 0.15]], dtype=float)
CONTEXT = MachineContext(moving_mass_kg=3.0, platform_mass_kg=2.0, payload_height_m=0.05, gravity_m_s2=9.81,
                         m_per_mm=1e-3, servo_stiffness=2e5)


def machine(name):
    """(robot, true theta, workspace): the hexapod with the paper's Table 3 errors; other robots
    with seeded errors of 0.05 mm / 0.5 mrad on their free parameters."""
    robot = default_robot(name)
    if name == "hexapod":
        return robot, robot.table.nominal + paper.TABLE3_ERRORS.ravel(), HEXAPOD_WORKSPACE
    theta = robot.table.nominal.copy()
    free = robot.table.indices(robot.free_default)
    rng = np.random.default_rng(99)
    theta[free] += rng.uniform(-1, 1, free.size) * np.where(robot.table.angle_mask()[free], 5e-4, 0.05)
    return robot, theta, robot.workspace_bounds()


def synthetic(name, effect, coef, seed=0, n=80, extra=None, noise=None):
    """Measurements of the calib machine whose joints are moved by Xq(effect) . coef (exact truth:
    the poses are the forward kinematics at the displaced joints, not a linearisation)."""
    robot, theta, workspace = machine(name)
    rng = np.random.default_rng(seed)
    targets = workspace[:, 0] + rng.uniform(size=(n, robot.pose_dim)) * np.ptp(workspace, axis=1)
    joints = robot.inverse_kinematics(robot.table.nominal, targets)
    t = np.cumsum(rng.uniform(0.5, 1.5, n))
    eff = EFFECTS[effect] if isinstance(effect, str) else effect
    reached = targets
    for _ in range(6):  # fixed point: the load regressor depends on the pose reached
        Xq = eff.joint_regressors(robot, theta, EffectData(robot, robot.table.nominal, joints, reached, t, NOISE), extra)
        reached = robot.forward_kinematics(theta, joints + Xq @ np.asarray(coef, dtype=float), initial=reached)
    if noise is not None:
        reached = reached + noise.sample(n, seed + 1, robot.pose_units)
    return EffectData(robot, robot.table.nominal, joints, reached, t, NOISE)


# -------------------------------------------------------------------------- registry


def test_registry_is_ordered_with_none_first_and_every_effect_declares_itself():
    assert list(EFFECTS) == ["none", "compliance", "joint_friction", "thermal_drift", "actuator_scale",
                             "periodic_screw_error", "instrument_drift", "lost_count", "thermal_warmup"]
    assert len(EFFECT_MODULES) == len(EFFECTS)
    for name, eff in EFFECTS.items():
        assert isinstance(eff, Effect) and eff.name == name and eff.physics
        assert name == "none" or eff.follows in FOLLOWED_QUANTITIES
        assert type(eff).applies_to.__doc__ or type(eff).__doc__  # the reason is written down


def test_which_effects_apply_to_which_robot():
    assert effects_for(default_robot("hexapod")) == tuple(EFFECTS)
    # Rotary motors: no leg grows, no lead screw.
    assert effects_for(default_robot("delta")) == ("none", "compliance", "joint_friction", "actuator_scale",
                                                     "instrument_drift", "lost_count")
    for name in ROBOTS:
        assert effects_for(default_robot(name))[0] == "none"


CASES = [(r, e) for r in ROBOTS for e in EFFECTS if EFFECTS[e].applies_to(default_robot(r))]


@pytest.mark.parametrize("robot_name,effect", CASES)
def test_coefficients_match_the_regressors_and_the_machine_settings_are_plain_data(robot_name, effect):
    data = synthetic(robot_name, "none", [], n=12)
    eff = EFFECTS[effect]
    extra = eff.searched_value(eff.search_grid(data)[len(eff.search_grid(data)) // 2]) if eff.searched else None
    X = eff.regressors(data.robot, data.theta, data, extra)
    Xq = eff.joint_regressors(data.robot, data.theta, data, extra)
    p = len(eff.coefficients(data.robot))
    assert X.shape == Xq.shape == (12, data.robot.n_chains, p)
    s = eff.machine_settings(np.full(p, 1e-4), data.robot, CONTEXT, extra)
    assert set(s) == {"options", "effects"}
    from mjcf.machine import MachineEffects, MachineOptions  # the field names are the builder's
    MachineOptions(**s["options"])
    MachineEffects(**s["effects"])


def test_robot_without_a_lead_screw_is_refused_with_the_reason():
    data = synthetic("delta", "none", [], n=12)
    with pytest.raises(ValueError, match="does not apply to the delta.*lead screws"):
        fit_effect(data, "periodic_screw_error", extra=4.0)
    with pytest.raises(ValueError, match="does not apply"):
        discover_effect(data, candidates=("thermal_drift",))


# -------------------------------------------------------------------------- physics of the regressors


def test_direction_is_the_last_motion_of_each_chain():
    robot = default_robot("hexapod")
    c = np.array([[1.0] * 6, [2.0] * 6, [2.0] * 6, [0.5] * 6]) + 233.23808
    d = EffectData(robot, robot.table.nominal, c, np.tile([0, 0, 200, 0, 0, 0.0], (4, 1)), np.arange(4.0),
                   NOISE).direction
    np.testing.assert_array_equal(d[:, 0], [1, 1, 1, -1])  # an unchanged command keeps the last direction


def test_hexapod_compliance_regressors_are_the_static_equilibrium_of_the_legs():
    """Independent truth: the leg forces of the old hexapod statics (force and moment balance of
    the platform with forces along the legs)."""
    robot, theta, workspace = machine("hexapod")
    poses = workspace[:, 0] + np.random.default_rng(3).uniform(size=(10, 6)) * np.ptp(workspace, axis=1)
    data = EffectData(robot, robot.table.nominal, robot.inverse_kinematics(theta, poses), poses, np.arange(10.0), NOISE)
    X = EFFECTS["compliance"].regressors(robot, theta, data)
    f = -X[..., 0]  # compressive leg forces for a unit weight at the platform origin
    B, _, P = robot.legs(theta)
    a = np.einsum("nij,lj->nli", rotation_matrix(poses[:, 3:]), P) + poses[:, None, :3]
    u = a - B
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    force = np.einsum("nl,nli->ni", f, u)
    moment = np.einsum("nl,nli->ni", f, np.cross(a, u)) + np.cross(poses[:, :3], [0, 0, -1.0])
    np.testing.assert_allclose(force, np.tile([0, 0, 1.0], (10, 1)), atol=1e-12)  # legs carry the weight
    np.testing.assert_allclose(moment, 0, atol=1e-9)
    assert np.all(f > 0)  # a hanging weight compresses every leg of this layout


@pytest.mark.parametrize("robot_name", [r for r in ROBOTS if EFFECTS["compliance"].applies_to(default_robot(r))])
def test_compliance_is_the_gradient_of_the_potential_energy_by_finite_differences(robot_name):
    """Independent truth for every robot: the servo deflection is ``-dV/dq / k`` with
    ``V(q) = m g z_com(FK(q))``, differentiated numerically through the forward kinematics."""
    robot, theta, workspace = machine(robot_name)
    rng = np.random.default_rng(5)
    poses = workspace[:, 0] + rng.uniform(size=(6, robot.pose_dim)) * np.ptp(workspace, axis=1)
    q = robot.inverse_kinematics(theta, poses)
    data = EffectData(robot, robot.table.nominal, q, poses, np.arange(6.0), NOISE)
    eff = EFFECTS["compliance"]
    Xq = eff.joint_regressors(robot, theta, data)
    h = 1e-5 if robot.joint_unit == "mm" else 1e-7
    rotates = "gamma" in robot.pose_names

    def z_com(qq, com_height_mm):
        pose = robot.forward_kinematics(theta, qq, initial=poses)
        z = pose[:, robot.pose_names.index("z")]
        if rotates:
            z = z + com_height_mm * rotation_matrix(pose[:, 3:6])[:, 2, 2]
        return z

    for c in range(robot.n_chains):
        dq = np.zeros_like(q)
        dq[:, c] = h
        grad0 = (z_com(q + dq, 0.0) - z_com(q - dq, 0.0)) / (2 * h)
        # central differences through the forward kinematics (h 1e-5 mm / 1e-7 rad): truncation
        # ~h^2 and rounding eps |z| / h relative to a gradient of order 1; the second-order term
        # with a 100 mm lever, a difference of two such gradients, gets 1e-5
        np.testing.assert_allclose(Xq[:, c, 0], -grad0, rtol=1e-6, atol=1e-9)
        if rotates:
            grad1 = (z_com(q + dq, 100.0) - z_com(q - dq, 100.0)) / (2 * h) - grad0
            np.testing.assert_allclose(Xq[:, c, 1], -grad1, rtol=1e-5, atol=1e-9)
    # The generic statics use the pose Jacobian of the closure (implicit function theorem).
    J = pose_jacobian_of_joints(robot, theta, q, poses)
    # the same function on the same inputs (calib/effects/compliance.py): equal to the last bits
    np.testing.assert_allclose(Xq[:, :, 0], -J[:, robot.pose_names.index("z"), :], rtol=1e-12)
    # The chains' own weight, lumped at their interior points (a Delta's elbows, a 6-RUS's crank
    # tips; none on a hexapod): V = m g sum_i z(point_i(q, FK(q))).
    k = interior_points(robot)
    assert Xq.shape[2] == (2 if rotates else 1) + k
    assert k == (0 if robot_name == "hexapod" else 1)

    def z_points(qq):
        pose = robot.forward_kinematics(theta, qq, initial=poses)
        return robot.chain_points(theta, qq, pose)[:, :, 1:-1, 2].sum(axis=1)

    for c in range(robot.n_chains):
        dq = np.zeros_like(q)
        dq[:, c] = h * 100
        grad = (z_points(q + dq) - z_points(q - dq)) / (200 * h)
        # central differences with a 100 times larger step: truncation ~(100 h)^2 dominates
        np.testing.assert_allclose(Xq[:, c, Xq.shape[2] - k:], -grad, rtol=1e-5, atol=1e-7)


# -------------------------------------------------------------------------- mapping to the MuJoCo machine


def test_machine_settings_map_coefficients_to_physical_parameters():
    hexapod, delta = default_robot("hexapod"), default_robot("delta")
    weight = CONTEXT.moving_mass_kg * CONTEXT.gravity_m_s2
    s = EFFECTS["compliance"].machine_settings(np.array([0.01, 0.002]), hexapod, CONTEXT)["options"]
    assert s["actuator_stiffness"] == pytest.approx(weight / 0.01e-3)  # N over m of deflection per unit
    assert s["gravity"] and s["payload_kg"] == pytest.approx(1.0)
    s = EFFECTS["compliance"].machine_settings(np.array([1e-4]), delta, CONTEXT)["options"]
    assert s["actuator_stiffness"] == pytest.approx(weight * 1e-3 / 1e-4)  # N m/rad from rad/mm
    s = EFFECTS["joint_friction"].machine_settings(np.array([0.004]), hexapod, CONTEXT)["options"]
    assert s["joint_friction"] == pytest.approx(0.004e-3 * 2e5)  # dead band x stiffness
    s = EFFECTS["joint_friction"].machine_settings(np.array([2e-5]), delta, CONTEXT)["options"]
    assert s["joint_friction"] == pytest.approx(2e-5 * 2e5)  # rad x N m/rad
    s = EFFECTS["periodic_screw_error"].machine_settings(np.array([3.0, 4.0]), hexapod, CONTEXT, 4.3)["effects"]
    assert s["screw_amplitude"] == pytest.approx((5.0,) * 6) and s["screw_pitch"] == 4.3
    assert 3.0 * np.sin(0.7) + 4.0 * np.cos(0.7) == pytest.approx(5.0 * np.sin(0.7 + s["screw_phase_rad"][0]))
    assert EFFECTS["thermal_drift"].machine_settings(np.array([5e-5]), hexapod, CONTEXT)["effects"] == \
        {"joint_drift_per_s": 5e-5}


@pytest.mark.parametrize("robot_name,effect", [c for c in CASES if c[1] != "none"])
def test_scenario_draws_the_requested_largest_contribution(robot_name, effect):
    robot, theta, _ = machine(robot_name)
    data = synthetic(robot_name, "none", [], n=30)
    eff = EFFECTS[effect]
    sc = eff.scenario(robot, theta, data, 0.005, np.random.default_rng(1), CONTEXT)
    X = eff.regressors(robot, theta, data, sc.extra)
    if effect == "actuator_scale" and robot.joint_unit == "rad":
        X = unabsorbed(robot, theta, data, X)  # a revolute scale is nearly a crank length: sized by what is left
        assert np.abs(eff.regressors(robot, theta, data) @ sc.coefficients).max() > 10 * 0.005
    if effect == "thermal_warmup":  # sized by the part neither the geometry nor a drift absorbs
        D = unabsorbed(robot, theta, data, EFFECTS["thermal_drift"].regressors(robot, theta, data)).ravel()
        X = unabsorbed(robot, theta, data, X).ravel()
        X = (X - D * (D @ X) / (D @ D)).reshape(data.n, robot.n_chains, 1)
        assert 0.2 * data.t_s.max() < sc.extra < 0.4 * data.t_s.max()
        assert np.abs(eff.regressors(robot, theta, data, sc.extra) @ sc.coefficients).max() > 3 * 0.005
        assert np.abs(X @ sc.coefficients).max() == pytest.approx(0.005, rel=1e-9)
        return
    largest = np.abs(X @ sc.coefficients).max()
    assert largest == pytest.approx(0.005, rel=1e-9) if not eff.searched else 0.0025 < largest <= 0.005 + 1e-12


# -------------------------------------------------------------------------- joint fits

INJECTED = {
    "hexapod": {"joint_friction": [0.004], "thermal_drift": [5e-5],
                "actuator_scale": [1e-4, -2e-4, 3e-4, -1e-4, 2e-4, 5e-5], "compliance": [0.01, 0.002]},
    "delta": {"joint_friction": [2e-5], "actuator_scale": [1e-4, -2e-4, 3e-4], "compliance": [2e-6, 1e-6]},
}
FIT_CASES = [(r, e, c) for r, d in INJECTED.items() for e, c in d.items()]


@pytest.mark.parametrize("robot_name,effect,coef", FIT_CASES)
def test_joint_fit_recovers_injected_effect_and_geometry_noise_free(robot_name, effect, coef):
    data = synthetic(robot_name, effect, coef)
    _, theta, _ = machine(robot_name)
    fit = fit_effect(data, effect, iterations=4)
    np.testing.assert_allclose(fit.coefficients, coef, rtol=1e-5, atol=1e-10)
    free = data.robot.table.indices(data.robot.free_default)
    np.testing.assert_allclose(fit.theta[free], theta[free], atol=1e-7)
    assert fit.chi2 < 1e-6


def test_pitch_search_finds_the_screw_pitch_through_noise():
    coef = np.array([0.004, -0.002, 0.001, 0.003, -0.003, 0.002, 0.0, 0.004, 0.002, 0.002, -0.001, -0.004])
    screws = per_chain_form(EFFECTS["periodic_screw_error"])  # each screw its own amplitude and phase
    data = synthetic("hexapod", screws, coef[np.r_[0:12:2, 1:12:2]], extra=4.3, noise=NOISE)
    fit = fit_effect(data, screws)
    assert fit.extra == pytest.approx(4.3, rel=2e-3)
    assert fit.named_coefficients()["pitch"]["value"] == fit.extra
    np.testing.assert_allclose(fit.coefficients, coef[np.r_[0:12:2, 1:12:2]], atol=5 * fit.coefficient_std.max())


# -------------------------------------------------------------------------- discovery

DISCOVERY_CASES = [
    ("hexapod", "none", []), ("hexapod", "joint_friction", [0.004]), ("hexapod", "thermal_drift", [5e-5]),
    ("hexapod", "actuator_scale", [5e-5, -5e-5, 5e-5, -5e-5, 5e-5, 5e-5]),
    ("delta", "none", []), ("delta", "joint_friction", [1e-5]),
    # 97% of the Delta's scale regressor lies in the span of its geometry (the joint offsets and
    # arm lengths absorb it): only a large scale error is told apart.
    ("delta", "actuator_scale", [2e-4, -2e-4, 2e-4]),
    ("delta", "compliance", [2e-7, 1e-7]),
]


@pytest.mark.parametrize("robot_name,effect,coef", DISCOVERY_CASES)
def test_discovery_names_the_synthetic_effect(robot_name, effect, coef):
    d = discover_effect(synthetic(robot_name, effect, coef, seed=4, noise=NOISE))
    assert d.effect == effect
    assert d.effects == (() if effect == "none" else (effect,))
    assert d.explained and not d.remaining.present
    assert d.flagged == ()
    assert set(effects_for(default_robot(robot_name))) <= set(d.evidence.forms)


@pytest.mark.parametrize("robot_name", ["hexapod", "delta"])
def test_a_gross_row_is_flagged_not_explained(robot_name):
    data = synthetic(robot_name, "none", [], seed=5, noise=NOISE)
    measured = data.measured.copy()
    measured[17, :3] += [0.02, -0.02, 0.0]
    d = discover_effect(data.with_measured(measured))
    assert d.flagged == (17,) and d.effect == "none" and d.explained


def test_located_mismatch_points_at_time_for_a_drift():
    d = discover_effect(synthetic("hexapod", "thermal_drift", [1e-4], seed=6, noise=NOISE))
    assert d.located.time_correlation > 0.5
    assert abs(d.located.direction_contrast_se) < 4


def test_located_mismatch_points_at_the_direction_of_motion_for_friction_on_the_delta():
    d = discover_effect(synthetic("delta", "joint_friction", [1e-5], seed=6, noise=NOISE))
    assert abs(d.located.direction_contrast_se) > 4
    assert d.located.pose_names == ("x", "y", "z") and d.located.task_space_rms_per_dof.shape == (3,)


@pytest.mark.parametrize("kw,match", [
    (dict(effect="magic"), "unknown effect 'magic'"),
])
def test_fit_effect_validation(kw, match):
    with pytest.raises(ValueError, match=match):
        fit_effect(synthetic("hexapod", "none", [], n=12), **kw)


def test_effect_data_validation():
    robot = default_robot("hexapod")
    c = np.zeros((5, 6))
    with pytest.raises(ValueError, match="same length, got 5, 4 and 5"):
        EffectData(robot, robot.table.nominal, c, np.zeros((4, 6)), np.arange(5.0), NOISE)
    with pytest.raises(ValueError, match=r"measured must have shape \(N, 6\)"):
        EffectData(robot, robot.table.nominal, c, np.zeros((5, 3)), np.arange(5.0), NOISE)
    with pytest.raises(ValueError, match="at least 12 measurements"):
        discover_effect(synthetic("hexapod", "none", [], n=10))
    with pytest.raises(ValueError, match="unknown effect 'x'"):
        discover_effect(synthetic("hexapod", "none", []), candidates=("x",))


class SquaredStrokeError(Effect):
    """A made-up effect written in one place (here): ``dq_i = b (q_i - q_centre_i)^2``, one
    coefficient shared by every chain. Applies to every robot."""

    name = "squared_stroke"
    physics = "a stroke error growing with the square of the stroke"

    def coefficients(self, robot):
        from calib.effects import Coefficient
        return (Coefficient("b", f"1/{robot.joint_unit}"),)

    def joint_regressors(self, robot, theta, data, extra=None):
        return (data.stroke ** 2)[..., None]


def test_an_effect_written_in_one_place_is_discovered_without_touching_the_engine():
    new = SquaredStrokeError()
    robot, theta, workspace = machine("hexapod")
    rng = np.random.default_rng(8)
    targets = workspace[:, 0] + rng.uniform(size=(80, 6)) * np.ptp(workspace, axis=1)
    joints = robot.inverse_kinematics(robot.table.nominal, targets)
    data = EffectData(robot, robot.table.nominal, joints, targets, np.arange(80.0), NOISE)
    reached = robot.forward_kinematics(theta, joints + new.joint_regressors(robot, theta, data) @ [1e-5])
    data = data.with_measured(reached + NOISE.sample(80, 9, robot.pose_units))
    d = discover_effect(data, candidates=tuple(effects_for(robot)) + (new,))
    assert d.effect == "squared_stroke"
    assert d.chosen.named_coefficients()["b"]["value"] == pytest.approx(1e-5, abs=5 * d.chosen.coefficient_std[0])


# -------------------------------------------------------------------------- several effects, the verdict, rows


def two_effects(seed=11, n=100):
    """Friction and a thermal drift at once on the hexapod (exact truth through the forward
    kinematics at the displaced joints), 1 um noise."""
    robot, theta, workspace = machine("hexapod")
    rng = np.random.default_rng(seed)
    targets = workspace[:, 0] + rng.uniform(size=(n, 6)) * np.ptp(workspace, axis=1)
    joints = robot.inverse_kinematics(robot.table.nominal, targets)
    data = EffectData(robot, robot.table.nominal, joints, targets, np.cumsum(rng.uniform(0.5, 1.5, n)), NOISE)
    dq = -0.004 * data.direction + 5e-5 * data.t_s[:, None]
    reached = robot.forward_kinematics(theta, joints + dq, initial=targets)
    return data.with_measured(reached + NOISE.sample(n, seed + 1, robot.pose_units))


def test_two_effects_at_once_are_both_named_with_units_and_uncertainties():
    d = discover_effects(two_effects())
    assert set(d.effects) == {"joint_friction", "thermal_drift"} and d.explained
    p = d.chosen.parameters()
    assert p["joint_friction"]["dead_band"]["unit"] == "mm"
    assert abs(p["joint_friction"]["dead_band"]["value"] - 0.004) < 5 * p["joint_friction"]["dead_band"]["std"]
    assert abs(p["thermal_drift"]["growth_rate"]["value"] - 5e-5) < 5 * p["thermal_drift"]["growth_rate"]["std"]
    assert all(v["significance"]["p_value"] < 1e-3 for v in p.values())
    # The joint fit of both is the same with the multi-effect fit called directly.
    f = fit_effects(two_effects(), ["joint_friction", "thermal_drift"])
    np.testing.assert_allclose(f.coefficients, d.chosen.coefficients, rtol=1e-6)


def test_an_effect_left_out_of_the_candidates_is_said_to_be_unknown_and_what_it_follows():
    d = discover_effects(two_effects(), candidates=("compliance", "joint_friction", "actuator_scale"))
    assert not d.explained and d.remaining.present
    assert d.remaining.follows[0] == "time"
    assert "thermal_drift" not in d.effects and d.partial == d.effects
    assert "following time" in d.remaining.summary
    assert d.remaining.pose_drift == ()  # growing legs, not a drifting pose: said in joint space
    assert d.flagged == ()  # the rows that carry the drift are evidence, not outliers


def test_a_frame_drift_left_out_is_not_explained_by_growing_legs_and_is_said_to_drift_in_pose_space():
    # The measurement frame moving up at 0.1 um/s: growing legs (thermal_drift, the only
    # candidate) raise the platform too, and take most of it; what they leave follows time in
    # pose space (the same displacement at every pose), which no per-leg statistic sees.
    d = discover_effects(synthetic("hexapod", "instrument_drift", [0, 0, 1e-4], seed=0, noise=NOISE),
                         candidates=("thermal_drift",))
    assert d.effects == ("thermal_drift",) and not d.explained
    assert d.remaining.follows[0] == "time" and d.remaining.pose_drift == ("z",)
    time = d.tests.quantity("time")
    assert time.p_value_pose_drift < time.p_value_proportional
    assert "the measured pose drifts with time, alike at every pose: z" in d.remaining.summary


def test_noise_larger_than_declared_is_not_explained_and_names_nothing_insignificant():
    data = synthetic("hexapod", "none", [], seed=12, n=80)
    big = data.with_measured(data.measured + SensorNoise(0.01, 1e-5, "normal").sample(80, 3, data.robot.pose_units))
    d = discover_effects(big)
    assert not d.explained and not d.tests.noise.consistent
    assert d.remaining.follows == ()  # white: it follows nothing
    for name in d.effects:
        assert d.chosen.significance(name)["p_value"] < 1e-3
    assert d.flagged == ()  # gross means gross against the remainder's own spread


def test_three_gross_rows_are_flagged_and_nothing_else():
    data = synthetic("hexapod", "joint_friction", [0.004], seed=13, n=90, noise=NOISE)
    m = data.measured.copy()
    for row, sign in ((5, 1), (40, -1), (41, 1)):
        m[row, :3] += sign * np.array([0.02, -0.02, 0.0])
    d = discover_effects(data.with_measured(m))
    assert d.flagged == (5, 40, 41) and d.effects == ("joint_friction",) and d.explained


def test_aliased_regressors_are_measured():
    corr = regressor_correlation(synthetic("delta", "none", [], seed=4, n=60))
    names = effects_for(default_robot("delta"))[1:]
    assert set(corr) == {(a, b) for i, a in enumerate(names) for b in names[i + 1:]}
    assert all(0.0 <= c <= 1.0 for c in corr.values())
    assert corr[("compliance", "actuator_scale")] > corr[("compliance", "joint_friction")]


# -------------------------------------------------------------------------- instrument drift


@pytest.mark.parametrize("robot_name", ["hexapod", "delta", "rus"])
def test_instrument_drift_is_a_moving_frame_not_moving_joints(robot_name):
    """Independent truth: the machine at its commanded joints, every measured position off by
    ``v t``; the joint regressors reproduce it to first order and discovery names it."""
    robot, theta, workspace = machine(robot_name)
    rng = np.random.default_rng(8)
    n = 80
    targets = workspace[:, 0] + rng.uniform(size=(n, robot.pose_dim)) * np.ptp(workspace, axis=1)
    joints = robot.inverse_kinematics(robot.table.nominal, targets)
    t = np.cumsum(rng.uniform(0.5, 1.5, n))
    true = robot.forward_kinematics(theta, joints, initial=targets)
    v = np.array([4e-5, -3e-5, 5e-5])  # mm/s: up to 6 um over the recording
    measured = true.copy()
    measured[:, :3] += t[:, None] * v
    eff = EFFECTS["instrument_drift"]
    # First order: the joints that would put the machine at the measured pose.
    data = EffectData(robot, robot.table.nominal, joints, measured, t, NOISE)
    dq = eff.joint_regressors(robot, theta, data) @ v
    moved = robot.forward_kinematics(theta, joints + dq, initial=measured)
    assert np.abs(moved - measured)[:, :3].max() < 1e-6
    noisy = data.with_measured(measured + NOISE.sample(n, 3, robot.pose_units))
    d = discover_effects(noisy)
    assert list(d.effects) == ["instrument_drift"] and d.explained, d.verdict
    fit = d.chosen
    np.testing.assert_allclose(fit.coefficients, v, atol=5 * fit.coefficient_std.max() + 1e-7)


def test_the_testbed_moves_the_measured_positions_only():
    from mjcf.machine import MachineEffects
    from pipeline.simulation import Testbed

    robot = default_robot("delta")
    q = robot.inverse_kinematics(robot.table.nominal, robot.workspace_bounds().mean(axis=1)[None] + [[0, 0, 0], [20, 0, 0]])
    v = (1e-3, -2e-3, 3e-3)
    plain = Testbed(robot, robot.table.nominal).measure(q, times_s=np.array([10.0, 20.0]))
    drift = Testbed(robot, robot.table.nominal, effects=MachineEffects(instrument_drift_mm_per_s=v)).measure(
        q, times_s=np.array([10.0, 20.0]))
    np.testing.assert_allclose(drift.settled_joints, plain.settled_joints, atol=1e-12)
    np.testing.assert_allclose(drift.measured - plain.measured, np.outer([10.0, 20.0], v), atol=1e-12)


# -------------------------------------------------------------------------- lost count, thermal warm-up


def test_lost_count_regressor_is_a_step_of_one_joint_at_the_step_time():
    """Independent truth: the one joint reads ``s`` off from ``t0`` on, nothing before, and no
    other joint moves."""
    from calib.effects.lost_count import JointStep

    data = synthetic("hexapod", "none", [], n=20)
    t0 = float((data.t_s[9] + data.t_s[10]) / 2)
    eff = EFFECTS["lost_count"]
    Xq = eff.joint_regressors(data.robot, data.theta, data, JointStep(2, t0))
    expected = np.zeros((20, 6))
    expected[10:, 2] = 0.003
    np.testing.assert_array_equal(Xq @ [0.003], expected)
    grid = eff.search_grid(data)
    assert {g.chain for g in grid} == set(range(6))  # every joint is a candidate
    t = data.t_s
    times = np.array([g.time_s for g in grid])
    assert np.all([np.any((t[:-1] < g) & (g < t[1:])) for g in times])  # never on a measurement
    assert np.isclose(times[:, None], (t[:-1] + t[1:]) / 2).any(axis=1).all()
    assert eff.searched_values(JointStep(2, t0)) == {"step_time": (t0, "s"), "joint": (3.0, "")}
    settings = eff.machine_settings(np.array([0.003]), data.robot, CONTEXT, JointStep(2, t0))["effects"]
    assert settings == {"joint_offset_step": (0.0, 0.0, 0.003, 0.0, 0.0, 0.0), "joint_offset_step_time_s": t0}


def test_thermal_warmup_regressor_is_the_exponential_approach_and_becomes_the_drift():
    data = synthetic("hexapod", "none", [], n=20)
    eff, tau = EFFECTS["thermal_warmup"], 7.0
    Xq = eff.joint_regressors(data.robot, data.theta, data, tau)
    t = data.t_s
    growth = np.array([5e-5 * tau * (1 - np.exp(-ti / tau)) for ti in t])  # g tau (1 - e^{-t/tau})
    np.testing.assert_allclose(Xq[:, :, 0] * 5e-5, np.repeat(growth[:, None], 6, axis=1), rtol=1e-12)
    slow = eff.joint_regressors(data.robot, data.theta, data, 1e7)
    np.testing.assert_allclose(slow, EFFECTS["thermal_drift"].joint_regressors(data.robot, data.theta, data), rtol=1e-5)
    assert eff.applies_to(default_robot("hexapod")) and not eff.applies_to(default_robot("delta"))



@pytest.mark.parametrize("robot_name", list(ROBOTS))
def test_lost_count_is_named_with_its_joint_step_and_time_on_noisy_data(robot_name):
    from calib.effects.lost_count import JointStep

    robot = default_robot(robot_name)
    probe = synthetic(robot_name, "none", [], seed=11)
    truth = JointStep(1, float((probe.t_s[44] + probe.t_s[45]) / 2))
    step = [0.004 if robot.joint_unit == "mm" else 4e-5]
    d = discover_effects(synthetic(robot_name, "lost_count", step, seed=11, extra=truth, noise=NOISE))
    assert list(d.effects) == ["lost_count"] and d.explained, d.verdict
    fit = d.chosen
    assert fit.extra == truth
    assert fit.parameters()["lost_count"]["joint"]["value"] == 2
    np.testing.assert_allclose(fit.coefficients, step, atol=5 * fit.coefficient_std.max())


def test_a_trend_every_chain_shares_is_no_lost_count():
    """A warm-up common to every leg, analysed without its family: one joint's step cannot
    stand in for it, and the remainder says what is left follows time."""
    data = synthetic("hexapod", "thermal_warmup", [3e-4], seed=12, extra=15.0, noise=NOISE)
    d = discover_effects(data, candidates=[e for e in effects_for(data.robot) if e not in effect_family("thermal_warmup")])
    assert not d.explained and d.remaining.follows[0] == "time", d.remaining.summary


def test_thermal_warmup_is_named_with_its_rate_and_time_constant_on_noisy_data():
    for robot_name in [r for r in ROBOTS if EFFECTS["thermal_warmup"].applies_to(default_robot(r))]:
        d = discover_effects(synthetic(robot_name, "thermal_warmup", [3e-4], seed=12, extra=15.0, noise=NOISE))
        assert list(d.effects) == ["thermal_warmup"] and d.explained, d.verdict
        fit = d.chosen
        assert fit.coefficients[0] == pytest.approx(3e-4, abs=5 * fit.coefficient_std[0])
        assert fit.extra == pytest.approx(15.0, rel=0.25)


def test_effect_families_are_the_nested_effects_either_way():
    assert EFFECTS["thermal_warmup"].generalises == ("thermal_drift",)
    assert nested_in("thermal_warmup") == ("thermal_drift",) and nested_in("thermal_drift") == ()
    assert effect_family("thermal_drift") == effect_family("thermal_warmup") == ("thermal_drift", "thermal_warmup")
    assert effect_family("lost_count") == ("lost_count",) and effect_family("instrument_drift") == ("instrument_drift",)


@pytest.mark.parametrize("seed", [3, 7])
def test_a_pure_drift_is_named_thermal_drift_not_the_warmup_that_contains_it(seed):
    data = synthetic("hexapod", "thermal_drift", [8e-5], seed=seed, noise=NOISE)
    d = discover_effects(data)
    assert "thermal_warmup" in d.evidence.forms  # it was a candidate
    assert d.effects == ("thermal_drift",) and d.explained, d.verdict


def test_a_warmup_the_data_cannot_tell_from_a_drift_is_named_drift_and_reported_as_nested():
    """tau longer than the recording: the warm-up fits better than the drift by more than its
    extra parameter costs (BIC alone would name it), but not by the nested margin."""
    data = synthetic("hexapod", "thermal_warmup", [1.2e-4], seed=31, extra=100.0, noise=NOISE)
    gain = fit_effects(data, ["thermal_drift"]).chi2 - fit_effects(data, ["thermal_warmup"]).chi2
    log_n = np.log(data.n * data.robot.n_chains)
    assert log_n < gain < log_n + MIN_NESTED_DELTA_BIC
    d = discover_effects(data)
    assert d.effects == ("thermal_drift",) and d.explained, d.verdict
    assert [(a.named, a.rival, a.nested) for a in d.aliases] == [("thermal_drift", "thermal_warmup", True)]
    assert 0 < d.aliases[0].delta_bic < MIN_NESTED_DELTA_BIC


def test_a_warmup_well_inside_the_recording_is_named_warmup_over_the_drift():
    data = synthetic("hexapod", "thermal_warmup", [2e-4], seed=31, extra=25.0, noise=NOISE)  # tau about 0.3 of it
    gain = fit_effects(data, ["thermal_drift"]).chi2 - fit_effects(data, ["thermal_warmup"]).chi2
    assert gain > np.log(data.n * data.robot.n_chains) + MIN_NESTED_DELTA_BIC
    d = discover_effects(data)
    assert d.effects == ("thermal_warmup",) and d.explained and d.aliases == (), d.verdict
    assert d.chosen.extra == pytest.approx(25.0, rel=0.3)


def test_the_testbed_steps_one_joint_and_warms_the_legs_up():
    from mjcf.machine import MachineEffects
    from pipeline.simulation import Testbed

    robot = default_robot("hexapod")
    q = robot.inverse_kinematics(robot.table.nominal, np.tile(robot.home_pose, (3, 1)))
    times = np.array([1.0, 2.0, 3.0])
    plain = Testbed(robot, robot.table.nominal).measure(q, times_s=times).settled_joints
    step = (0.0, 0.0, 0.01, 0.0, 0.0, 0.0)
    lost = Testbed(robot, robot.table.nominal, effects=MachineEffects(joint_offset_step=step, joint_offset_step_time_s=1.5))
    assert not lost.history_free
    moved = lost.measure(q, times_s=times).settled_joints - plain
    np.testing.assert_allclose(moved, [[0] * 6, step, step], atol=1e-6)
    warm = Testbed(robot, robot.table.nominal, effects=MachineEffects(joint_warmup_per_s=0.01, joint_warmup_tau_s=2.0))
    moved = warm.measure(q, times_s=times).settled_joints - plain
    np.testing.assert_allclose(moved, np.repeat((0.01 * 2.0 * (1 - np.exp(-times / 2.0)))[:, None], 6, axis=1), atol=1e-6)


def test_large_folds_of_the_closed_form_crossvalidation_take_the_woodbury_form(monkeypatch):
    """With calib.effects.search.DENSE_FOLD_MAX lowered to 0 every fold of the closed-form
    cross-validation is solved through the Woodbury identity (a P x P system) instead of the
    dense fold-sized one: the same effects are chosen and the same cross-validated figures to
    rounding (the two forms are the same algebra; 1e-9 is far above the rounding of a fold's
    systems and far below any difference between candidates)."""
    import calib.effects.search

    exact = discover_effects(two_effects())
    monkeypatch.setattr(calib.effects.search, "DENSE_FOLD_MAX", 0)
    woodbury = discover_effects(two_effects())
    assert woodbury.effects == exact.effects
    assert woodbury.evidence.cv_whitened_rms_chosen == pytest.approx(exact.evidence.cv_whitened_rms_chosen, rel=1e-9)
    assert woodbury.evidence.geometry.cv_whitened_rms == pytest.approx(exact.evidence.geometry.cv_whitened_rms,
                                                                       rel=1e-9)


@pytest.mark.parametrize("robot_name", list(ROBOTS))
def test_a_long_step_time_grid_is_searched_coarse_to_fine_to_the_same_step(robot_name, monkeypatch):
    """The lost count's step-time grid (one point per row and chain: 6 x 79 for the hexapod) is
    longer than calib.effects.search.SEARCH_GRID_MAX lowered to 12: the coarse-to-fine search
    finds the same joint and time as every point tried (the independent truth: the step made)."""
    import calib.effects.search
    from calib.effects.lost_count import JointStep

    robot = default_robot(robot_name)
    probe = synthetic(robot_name, "none", [], seed=11)
    truth = JointStep(1, float((probe.t_s[44] + probe.t_s[45]) / 2))
    step = [0.004 if robot.joint_unit == "mm" else 4e-5]
    data = synthetic(robot_name, "lost_count", step, seed=11, extra=truth, noise=NOISE)
    assert len(EFFECTS["lost_count"].search_grid(data)) > 12
    monkeypatch.setattr(calib.effects.search, "SEARCH_GRID_MAX", 12)
    d = discover_effects(data)
    assert list(d.effects) == ["lost_count"] and d.explained, d.verdict
    assert d.chosen.extra == truth
