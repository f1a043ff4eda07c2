"""Tests of calib.delta: Model-24 parameters, IK/FK, Jacobians, bad input."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calib.robots.delta import (
    CHAIN_PARAMETER_NAMES,
    NOMINAL_GEOMETRY,
    PARAMETER_NAMES,
    PARAMETER_TABLE,
    PARAMETER_UNITS,
    DeltaParams,
    canonical_params,
    constraint_jacobian_joints,
    constraint_jacobian_params,
    constraint_jacobian_position,
    constraint_residuals,
    elbow_positions,
    fk_jacobian_joints,
    fk_jacobian_params,
    forward_kinematics,
    inverse_kinematics,
    parameter_index,
)
from calib.robots import Delta, uniform_errors
from calib.workspace import reachable_poses

NOM = DeltaParams.nominal()


def _perturbed(seed, e_mm=2.0, e_deg=2.0):
    robot = Delta(NOM)
    return DeltaParams.from_vector(robot.table.nominal + uniform_errors(robot, seed, e_mm, np.deg2rad(e_deg)))


def _configs(params, n, seed):
    x = reachable_poses(Delta(NOM), n, seed, theta=params.to_vector())
    return inverse_kinematics(params, x), x


# --------------------------------------------------------------------------- parameter table


def test_parameter_table_is_consistent():
    assert len(PARAMETER_TABLE) == 24
    for name, idx, unit in PARAMETER_TABLE:
        assert PARAMETER_NAMES[idx] == name
        assert PARAMETER_UNITS[idx] == unit
        assert parameter_index(name) == idx
        assert unit == ("rad" if name.rstrip("123") in ("theta", "alpha") else "mm")
    assert PARAMETER_NAMES[:8] == tuple(f"{n}1" for n in CHAIN_PARAMETER_NAMES)
    assert PARAMETER_NAMES[8 + 3] == "theta2" and PARAMETER_NAMES[23] == "Lb3"


def test_parameter_index_unknown_name():
    with pytest.raises(ValueError, match="name must be one of .* got 'Lc1'"):
        parameter_index("Lc1")


def test_nominal_matches_paper_geometry():
    g = NOMINAL_GEOMETRY
    r = g["Rb_mm"] - g["Rn_mm"]
    th = np.deg2rad(g["theta_deg"])
    np.testing.assert_allclose(NOM.Dx, r * np.cos(th), atol=1e-12)
    np.testing.assert_allclose(NOM.Dy, r * np.sin(th), atol=1e-12)
    np.testing.assert_array_equal(NOM.Dz, 0.0)
    np.testing.assert_allclose(NOM.theta, th)
    np.testing.assert_array_equal(NOM.Lax, g["La_mm"])
    np.testing.assert_array_equal(NOM.Lay, 0.0)
    np.testing.assert_array_equal(NOM.Lb, g["Lb_mm"])
    np.testing.assert_array_equal(NOM.alpha, 0.0)


def test_vector_round_trip_and_frozen():
    p = _perturbed(3)
    v = p.to_vector()
    assert v.shape == (24,) and v.dtype == np.float64
    q = DeltaParams.from_vector(v)
    np.testing.assert_array_equal(q.to_vector(), v)
    np.testing.assert_array_equal(p.chain_vector(1), v[8:16])
    assert list(p.to_dict()) == list(PARAMETER_NAMES)
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.Lb = np.ones(3)
    with pytest.raises(ValueError):
        p.Lb[0] = 1.0  # read-only array


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"Dx": np.zeros(2)}, r"Dx must have shape \(3,\), got \(2,\)"),
        ({"theta": np.zeros((3, 1))}, r"theta must have shape \(3,\), got \(3, 1\)"),
        ({"alpha": np.array([0.0, np.nan, 0.0])}, "alpha must be finite"),
        ({"Lb": np.array([480.0, 0.0, 480.0])}, "Lb must be positive"),
        ({"Lax": np.zeros(3), "Lay": np.zeros(3)}, r"arm vector \(Lax, Lay\) must be non-zero"),
        ({"Dz": "abc"}, "Dz must be a float array"),
    ],
)
def test_params_validation(kwargs, match):
    fields = {f: getattr(NOM, f) for f in DeltaParams.FIELDS}
    fields.update(kwargs)
    with pytest.raises(ValueError, match=match):
        DeltaParams(**fields)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: DeltaParams.from_vector(np.zeros(23)), r"vector must have shape \(24,\), got \(23,\)"),
        (lambda: NOM.chain_vector(3), "i must be 0, 1 or 2, got 3"),
        (lambda: DeltaParams.nominal(la_mm=-1.0), "la_mm must be positive"),
        (lambda: DeltaParams.nominal(theta_deg=(0.0, 120.0)), r"theta_deg must have shape \(3,\)"),
        (lambda: canonical_params("nominal"), "params must be a DeltaParams, got str"),
    ],
)
def test_params_constructor_validation(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_canonical_params_is_kinematically_identical():
    p = dataclasses.replace(_perturbed(5), Lay=np.array([3.0, -2.0, 1.5]))
    c = canonical_params(p)
    np.testing.assert_array_equal(c.Lay, 0.0)
    q, _ = _configs(p, 10, 1)
    np.testing.assert_allclose(elbow_positions(c, q), elbow_positions(p, q), atol=1e-10)
    np.testing.assert_allclose(forward_kinematics(c, q), forward_kinematics(p, q), atol=1e-10)


# --------------------------------------------------------------------------- IK / FK


def test_symmetric_pose_is_on_axis():
    x = forward_kinematics(NOM, np.full((1, 3), 0.5))
    np.testing.assert_allclose(x[0, :2], 0.0, atol=1e-10)
    assert x[0, 2] < 0
    # Every closure holds exactly.
    np.testing.assert_allclose(constraint_residuals(NOM, np.full((1, 3), 0.5), x), 0.0, atol=1e-10)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    r=st.floats(0.0, 200.0),
    a=st.floats(0.0, 2 * np.pi),
    z=st.floats(-550.0, -320.0),
)
def test_ik_fk_round_trip(seed, r, a, z):
    p = _perturbed(seed)
    x = np.array([[r * np.cos(a), r * np.sin(a), z]])
    q = inverse_kinematics(p, x)
    np.testing.assert_allclose(forward_kinematics(p, q), x, atol=1e-8)
    np.testing.assert_allclose(constraint_residuals(p, q, x), 0.0, atol=1e-8)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), q=st.lists(st.floats(-0.2, 1.0), min_size=3, max_size=3))
def test_fk_ik_round_trip(seed, q):
    p = _perturbed(seed)
    q = np.array([q])
    x = forward_kinematics(p, q)
    np.testing.assert_allclose(inverse_kinematics(p, x), q, atol=1e-9)


def test_batch_equals_single():
    q, x = _configs(NOM, 6, 2)
    for k in range(6):
        np.testing.assert_allclose(inverse_kinematics(NOM, x[k : k + 1])[0], q[k], atol=1e-14)
        np.testing.assert_allclose(forward_kinematics(NOM, q[k : k + 1])[0], forward_kinematics(NOM, q)[k], atol=1e-12)


# --------------------------------------------------------------------------- Jacobians vs finite differences


def _fd(f, x0, h):
    cols = []
    for k in range(x0.size):
        xp, xm = x0.copy(), x0.copy()
        xp[k] += h
        xm[k] -= h
        cols.append((f(xp) - f(xm)) / (2 * h))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_constraint_jacobian_params_matches_fd(seed):
    p = dataclasses.replace(_perturbed(seed), Lay=np.array([1.0, -2.0, 0.5]))
    q, _ = _configs(NOM, 5, seed)
    x = forward_kinematics(p, q) + np.random.default_rng(seed).normal(0, 0.5, (5, 3))  # off-closure too
    jac = constraint_jacobian_params(p, q, x)
    for i in range(3):
        def f(v, i=i):
            full = p.to_vector()
            full[8 * i : 8 * i + 8] = v
            return constraint_residuals(DeltaParams.from_vector(full), q, x)[:, i]

        # central differences, h = 1e-6: rounding eps |terms| / h ~ 1e-7 (terms up to ~500 mm),
        # truncation ~h^2 |third derivative|
        np.testing.assert_allclose(jac[:, i, :], _fd(f, p.chain_vector(i), 1e-6), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_constraint_jacobians_position_and_joints_match_fd(seed):
    p = _perturbed(seed)
    q, _ = _configs(NOM, 4, seed)
    x = forward_kinematics(p, q)
    jx = constraint_jacobian_position(p, q, x)
    jq = constraint_jacobian_joints(p, q, x)
    for k in range(4):
        fdx = _fd(lambda xx: constraint_residuals(p, q[k : k + 1], xx[None])[0], x[k].copy(), 1e-5)
        # central differences: rounding eps |terms| / h ~ 1e-8 at h = 1e-5 mm, ~1e-6 at h = 1e-7 rad
        # (terms up to ~500 mm), truncation ~h^2
        np.testing.assert_allclose(jx[k], fdx, atol=1e-7)
        fdq = _fd(lambda qq: constraint_residuals(p, qq[None], x[k : k + 1])[0], q[k].copy(), 1e-7)
        np.testing.assert_allclose(np.diag(jq[k]), fdq, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(fdq - np.diag(np.diag(fdq)), 0.0, atol=1e-7)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fk_jacobian_params_matches_fd(seed):
    p = _perturbed(seed)
    q, _ = _configs(NOM, 4, seed)
    jac = fk_jacobian_params(p, q)
    assert jac.shape == (4, 3, 24)
    fd = _fd(lambda v: forward_kinematics(DeltaParams.from_vector(v), q), p.to_vector(), 1e-6)
    # central differences, h = 1e-6: rounding eps |pose| / h ~ 1e-7 plus the forward kinematics'
    # residual over h, truncation ~h^2
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fk_jacobian_joints_matches_fd(seed):
    p = _perturbed(seed)
    q, _ = _configs(NOM, 4, seed)
    jac = fk_jacobian_joints(p, q)
    for k in range(4):
        fd = _fd(lambda qq: forward_kinematics(p, qq[None])[0], q[k].copy(), 1e-7)
        # central differences, h = 1e-7 rad: rounding eps |pose| / h ~ 1e-6 (the atol's tenth)
        # plus the forward kinematics' residual over h, truncation ~h^2
        np.testing.assert_allclose(jac[k], fd, rtol=1e-6, atol=1e-5)


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: inverse_kinematics(NOM, np.zeros(5)), r"positions must have shape \(N, 3\), got \(5,\)"),
        (lambda: inverse_kinematics(NOM, np.zeros((0, 3))), r"positions must have shape \(N, 3\), got \(0, 3\)"),
        (lambda: inverse_kinematics(NOM, [[0.0, 0.0, np.inf]]), "positions must be finite"),
        (lambda: inverse_kinematics("p", [[0.0, 0.0, -400.0]]), "params must be a DeltaParams, got str"),
        (lambda: forward_kinematics(NOM, np.zeros((4, 2))), r"q must have shape \(N, 3\), got \(4, 2\)"),
        (lambda: elbow_positions(NOM, [0.0, 0.0, 0.0]), r"q must have shape \(N, 3\), got \(3,\)"),
        (
            lambda: constraint_residuals(NOM, np.zeros((2, 3)), np.zeros((3, 3))),
            "q and positions must have the same number of configurations, got 2 and 3",
        ),
        (lambda: fk_jacobian_params(NOM, np.zeros((1, 4))), r"q must have shape \(N, 3\), got \(1, 4\)"),
    ],
)
def test_bad_shapes(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_ik_unreachable_names_configuration():
    x = np.array([[0.0, 0.0, -420.0], [0.0, 0.0, -420.0], [0.0, 0.0, -2000.0]])
    with pytest.raises(ValueError, match="configuration 2: .* outside the workspace"):
        inverse_kinematics(NOM, x)


def test_ik_singular_names_configuration():
    # Chain 1 (just short of) fully stretched: plate at shoulder + (La + Lb) along the arm;
    # long forearms on chains 2 and 3 so that they reach it.
    phi = 0.6
    arm_dir = np.array([np.cos(phi), 0.0, -np.sin(phi)])
    x = NOM.shoulders()[0] + (260.0 + 480.0 - 1e-8) * arm_dir
    elbows = elbow_positions(NOM, np.full((1, 3), 0.3))[0]
    lb = np.linalg.norm(x - elbows, axis=1)
    p = dataclasses.replace(NOM, Lb=np.array([480.0, lb[1], lb[2]]))
    x_ok = x - 1.0 * arm_dir
    inverse_kinematics(p, x_ok[None])  # reachable, not singular
    with pytest.raises(ValueError, match=r"configuration 1: .* singularity \(arm and forearm of chain 1 aligned\)"):
        inverse_kinematics(p, np.array([x_ok, x]))


def test_fk_unreachable_names_configuration():
    # Forearms of 400 mm cannot close on elbows 424 mm from the axis (q = 0).
    p = dataclasses.replace(NOM, Lb=np.full(3, 400.0))
    q = np.array([[0.5, 0.5, 0.5], [0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="configuration 1: .* outside the workspace"):
        forward_kinematics(p, q)


def test_fk_parallel_singularity():
    # Elbows at radius 424 mm in the base plane for q = 0: Lb equal to that radius puts the
    # plate in the elbows' plane with all three forearms coplanar.
    p = dataclasses.replace(NOM, Lb=np.full(3, 424.0 + 1e-10))
    with pytest.raises(ValueError, match="configuration 0: parallel singularity"):
        forward_kinematics(p, np.zeros((1, 3)))
    with pytest.raises(ValueError, match="configuration 0: parallel singularity"):
        fk_jacobian_params(p, np.zeros((1, 3)))


def test_fk_collinear_elbows():
    p = dataclasses.replace(NOM, Dx=np.array([0.0, 10.0, 20.0]), Dy=np.zeros(3), theta=np.zeros(3))
    with pytest.raises(ValueError, match="configuration 0: singular configuration \\(elbows collinear\\)"):
        forward_kinematics(p, np.zeros((1, 3)))


def test_coincident_plate_and_elbow():
    q = np.zeros((1, 3))
    x = elbow_positions(NOM, q)[:, 1, :]
    with pytest.raises(ValueError, match="configuration 0: plate point coincides with elbow 2"):
        constraint_jacobian_params(NOM, q, x)


def test_robot_closure_of_an_impossible_vector_is_a_kinematics_error():
    """A fit's trial step may propose Lb <= 0: the robot reports it as the engine expects
    (KinematicsError), so that the engine ends the fit with success False instead of raising."""
    from calib.robot import KinematicsError

    robot = Delta(NOM)
    theta = robot.table.nominal.copy()
    theta[robot.table.indices(["Lb2"])] = -70.0
    q, x = _configs(NOM, 3, 0)
    for call in (robot.closure, robot.closure_jacobians):
        with pytest.raises(KinematicsError, match="theta: Lb must be positive"):
            call(theta, q, x)


class _CountingDelta(Delta):
    """A Delta that counts the parameter vectors its closure refuses."""

    refused = 0

    def closure(self, theta, joints, poses):
        try:
            return super().closure(theta, joints, poses)
        except Exception:
            type(self).refused += 1
            raise


def test_chainwise_fits_survive_steps_to_impossible_geometry():
    """40 mm / 40 deg errors, 8 poses, noise-free (seed 27): a Gauss-Newton step proposes a
    negative forearm length and the fit ends there with success False (no exception); a
    Levenberg-Marquardt trial step does too, is rejected, and the fit recovers the machine."""
    from calib.engine import gauge_representative, identify_chainwise
    from calib.noise import SensorNoise

    robot = _CountingDelta(NOM)
    nominal = robot.table.nominal
    true = nominal + uniform_errors(robot, 27, 40.0, np.deg2rad(40.0))
    x = reachable_poses(robot, 8, 27, theta=true)
    q = robot.inverse_kinematics(true, x)
    gn = identify_chainwise(robot, q, x, SensorNoise(), solver="gn", weighted=True, max_iter=200)
    assert not gn.success and "step left the workspace" in gn.message
    assert np.all(np.isfinite(gn.theta))
    _CountingDelta.refused = 0
    lm = identify_chainwise(robot, q, x, SensorNoise(), solver="lm", weighted=True, max_iter=200)
    assert _CountingDelta.refused > 0
    assert lm.success
    np.testing.assert_allclose(lm.theta, gauge_representative(robot, true, nominal), atol=1e-8)
