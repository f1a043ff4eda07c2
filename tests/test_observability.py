import json

import numpy as np
import pytest

import calib.robots
from calib import paper
from calib.design import minimum_poses, robot_workspace, sample_feasible_poses
from calib.noise import SensorNoise
from calib.observability import (
    analyze_observability,
    describe_combination,
    fisher_information,
    free_indices,
    identification_jacobian,
    parameter_scale,
    pose_uncertainty,
)
from calib.robot import pose_jacobian_of_joints
from calib.robots import default_robot

from linalg_tolerance import EPS, gram_inverse_tolerance

NOISE = SensorNoise(position_mm=1e-3, orientation_rad=1e-6, distribution="normal")
ROBOTS = sorted(calib.robots.ROBOTS)
HEXAPOD = default_robot("hexapod")


def perturbed(robot, seed, size_mm=0.05, size_rad=1e-3):
    """Nominal parameters plus uniform errors on the free ones."""
    half = np.where(robot.table.angle_mask(), size_rad, size_mm)
    _, idx = free_indices(robot)
    theta = robot.table.nominal.copy()
    theta[idx] += np.random.default_rng(seed).uniform(-1, 1, idx.size) * half[idx]
    return theta


def inversion_accuracy(F):
    """Relative accuracy of two float64 computations of ``inv(F)``, ``F = A^T A`` (K, K):
    ``K eps cond(F with unit diagonal)`` (tests/linalg_tolerance.py; that condition number is the
    column-scaled ``cond(A)^2``). The rus's free parameters include weak combinations,
    docs/rus.md: its scaled Fisher matrix has cond ~ 3e9, the hexapod's ~2e6, the Delta's ~1e5."""
    d = np.sqrt(np.diag(F))
    return gram_inverse_tolerance(np.sqrt(np.linalg.cond(F / np.outer(d, d))), len(F))


def enough(robot, n):
    """At least n poses, and more than the robot needs to determine its free parameters."""
    return max(n, minimum_poses(robot) + 2)


def poses_of(robot, n, seed, workspace="full"):
    return sample_feasible_poses(robot, robot.table.nominal, robot_workspace(robot, workspace), n, seed)


def reached(robot, theta, targets):
    """(joints, poses): the nominal controller's joints and the poses the machine theta reaches."""
    q = robot.inverse_kinematics(robot.table.nominal, targets)
    return q, robot.forward_kinematics(theta, q, initial=targets)


@pytest.mark.parametrize("name", ROBOTS)
def test_identification_jacobian_matches_finite_differences(name):
    robot = default_robot(name)
    theta = perturbed(robot, 1)
    q, poses = reached(robot, theta, poses_of(robot, 5, 1))
    A = identification_jacobian(robot, theta, poses, NOISE, joints=q)
    names, idx = free_indices(robot)
    assert A.shape == (5 * robot.pose_dim, len(names))
    w = 1.0 / NOISE.pose_std(robot.pose_units)
    for col, k in enumerate(idx):
        h = 1e-7 if robot.table.units[k] == "rad" else 1e-5
        e = np.zeros(robot.n_parameters)
        e[k] = h
        plus = robot.forward_kinematics(theta + e, q, initial=poses)
        minus = robot.forward_kinematics(theta - e, q, initial=poses)
        fd = ((plus - minus) / (2 * h) * w).ravel()
        # central differences of the forward kinematics: truncation ~h^2, rounding eps |pose| / h
        # ~1e-9 relative to a column (h 1e-5 mm, 1e-7 rad) plus the solver's residual over h
        np.testing.assert_allclose(A[:, col], fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max(), err_msg=names[col])


@pytest.mark.parametrize("name", ROBOTS)
def test_joint_noise_whitening_is_the_pose_covariance(name):
    """With joint noise the Fisher information is J^T (S_pose + Jq S_q Jq^T)^-1 J, Jq by finite
    differences of the forward kinematics."""
    robot = default_robot(name)
    noise = SensorNoise(1e-3, 1e-6, "normal", joint=2e-3 if robot.joint_unit == "mm" else 1e-5)
    theta = perturbed(robot, 2)
    q, poses = reached(robot, theta, poses_of(robot, 4, 2))
    F = fisher_information(robot, theta, poses, noise, joints=q)
    J = identification_jacobian(robot, theta, poses, SensorNoise(1.0, 1.0, "normal"), joints=q) \
        .reshape(4, robot.pose_dim, -1)
    # central differences, h = 1e-6 rad or 1e-4 mm: rounding eps |pose| / h ~ 1e-8 absolute (atol;
    # a step of 1e-6 mm on poses of 250 mm, the linear Delta's, rounded to 9e-8, and F's cancelling
    # entries to 8e-4 relative), truncation ~h^2 plus the forward kinematics' Newton residual over
    # h, below 1e-5 relative
    h = 1e-4 if robot.joint_unit == "mm" else 1e-6
    jq = np.stack([(robot.forward_kinematics(theta, q + h * np.eye(robot.n_chains)[c], initial=poses)
                    - robot.forward_kinematics(theta, q - h * np.eye(robot.n_chains)[c], initial=poses)) / (2 * h)
                   for c in range(robot.n_chains)], axis=-1)
    np.testing.assert_allclose(jq, pose_jacobian_of_joints(robot, theta, q, poses), rtol=1e-5, atol=1e-8)
    S = np.diag(NOISE.pose_std(robot.pose_units) ** 2) + noise.joint_std ** 2 * jq @ np.swapaxes(jq, 1, 2)
    expected = sum(J[j].T @ np.linalg.solve(S[j], J[j]) for j in range(4))
    np.testing.assert_allclose(F, expected, rtol=1e-5)  # expected is built from jq, 1e-5 as above
    assert np.all(np.diag(F) < np.diag(fisher_information(robot, theta, poses, NOISE, joints=q)))


@pytest.mark.parametrize("name", ROBOTS)
def test_crb_is_inverse_of_fisher_and_indices_consistent(name):
    robot = default_robot(name)
    poses = poses_of(robot, enough(robot, 20), 3)
    a = analyze_observability(robot, robot.table.nominal, poses, NOISE)
    F = fisher_information(robot, robot.table.nominal, poses, NOISE)
    n = len(robot.free_default)
    np.testing.assert_allclose(a.fisher, F)
    d = np.sqrt(np.diag(F))  # in the basis where F has a unit diagonal
    # the residual of an inverse is bounded norm-wise (hence element-wise) by its accuracy; the
    # diagonal of an SPD inverse is accurate relative to itself: |d C_ii| <= ||C|| C_ii ||dF||
    np.testing.assert_allclose(d[:, None] * (a.crb @ F) / d, np.eye(n), atol=inversion_accuracy(F))
    np.testing.assert_allclose(a.crb_std, np.sqrt(np.diag(np.linalg.inv(F))), rtol=inversion_accuracy(F))
    s = a.singular_values
    assert a.rank == n and np.all(np.diff(s) <= 0)
    S = parameter_scale(robot)[a.indices]
    # eigenvalues of a symmetric matrix: absolute error ~K eps lambda_max (Weyl), not relative
    lam = np.linalg.eigvalsh(F / np.outer(S, S))[::-1]
    np.testing.assert_allclose(s ** 2, lam, rtol=0, atol=n * EPS * lam[0])
    # the same computed numbers rearranged: a few ulps apart, pytest.approx's 1e-6 is ample
    assert a.condition_number == pytest.approx(1.0 / a.o2)
    assert a.o3 == pytest.approx(s[-1])
    assert a.o4 == pytest.approx(a.o3 * a.o2)
    assert a.o1 == pytest.approx(np.exp(np.mean(np.log(s))) / np.sqrt(robot.pose_dim * len(poses)))
    assert a.crb_rms == pytest.approx(np.sqrt(np.trace(a.crb * np.outer(S, S)) / n))
    assert a.not_identifiable == ()
    cov = a.parameter_covariance()
    np.testing.assert_array_equal(cov[np.ix_(a.indices, a.indices)], a.crb)
    assert np.count_nonzero(cov) == np.count_nonzero(a.crb)


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("factor", [0.5, 10.0])
def test_noise_scaling(name, factor):
    robot = default_robot(name)
    poses = poses_of(robot, enough(robot, 12), 4)
    a = analyze_observability(robot, robot.table.nominal, poses, NOISE)
    b = analyze_observability(robot, robot.table.nominal, poses, SensorNoise(1e-3 * factor, 1e-6 * factor, "normal"))
    # The whitened Jacobian is scaled by 1 / factor, up to a rounding of each element: every
    # singular value moves by ~K eps sigma_1 (Weyl), relative to itself K eps cond; a variance,
    # the diagonal of an inverse, by K eps cond^2 (tests/linalg_tolerance.py).
    sv = a.n_free * EPS * a.condition_number
    np.testing.assert_allclose(b.singular_values, a.singular_values / factor, rtol=sv)
    np.testing.assert_allclose(b.crb_std, a.crb_std * factor, rtol=gram_inverse_tolerance(a.condition_number, a.n_free))
    assert b.o2 == pytest.approx(a.o2, rel=2 * sv) and b.condition_number == pytest.approx(a.condition_number, rel=2 * sv)
    assert b.o1 == pytest.approx(a.o1 / factor, rel=sv) and b.o4 == pytest.approx(a.o4 / factor, rel=3 * sv)
    sv_scaled = a.n_free * EPS * a.scaled_condition_number
    assert b.scaled_condition_number == pytest.approx(a.scaled_condition_number, rel=2 * sv_scaled)


def test_paper_poses_condition_in_the_thousands():
    a = analyze_observability(HEXAPOD, HEXAPOD.table.nominal, paper.TABLE4_NOMINAL_POSES, NOISE)
    assert a.rank == 42
    assert a.scaled_condition_number > 1e3
    weakest = a.weakest_combinations(3)
    assert [w["std_mm"] for w in weakest] == sorted([w["std_mm"] for w in weakest], reverse=True)
    assert weakest[0]["std_mm"] == pytest.approx(1.0 / a.singular_values[-1])
    assert weakest[0]["std_mm"] > a.crb_std.max() * 0.999
    # the leg offsets against the vertical joint coordinates (docs/observability.md)
    assert set(weakest[0]["coefficients"]) == {"dl1", "dl6", "B1.z", "B6.z"}


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("n_poses", [1, 2])
def test_too_few_poses_leave_undetermined_combinations(name, n_poses):
    robot = default_robot(name)
    n = len(robot.free_default)
    rank = n_poses * robot.pose_dim
    assert rank < n
    a = analyze_observability(robot, robot.table.nominal, poses_of(robot, n_poses, 5), NOISE)
    assert a.rank == rank
    assert a.condition_number == np.inf and a.o3 == 0.0 and a.o1 == 0.0
    assert np.all(np.isinf(a.crb_std))
    w = a.weakest_combinations(1)[0]
    assert not w["determined"] and w["std_mm"] == np.inf
    assert len(a.not_identifiable) == n - rank
    s = a.summary()
    assert s["condition_number"] is None and s["rank"] == rank
    np.testing.assert_allclose(a.right_singular_vectors @ a.right_singular_vectors.T, np.eye(n), atol=1e-10)


@pytest.mark.parametrize("name", ROBOTS)
def test_repeated_pose_leaves_rank_of_one_pose(name):
    robot = default_robot(name)
    pose = poses_of(robot, 1, 6)
    a = analyze_observability(robot, robot.table.nominal, np.repeat(pose, 10, axis=0), NOISE)
    assert a.rank == robot.pose_dim


@pytest.mark.parametrize("name", ROBOTS)
def test_not_identifiable_combinations_leave_every_pose_unchanged(name):
    """With every parameter free, each reported combination moves no pose (to first order),
    and the others are determined."""
    robot = default_robot(name)
    theta = perturbed(robot, 7)
    q, poses = reached(robot, theta, poses_of(robot, enough(robot, 30), 7))
    a = analyze_observability(robot, theta, poses, NOISE, joints=q, free=robot.table.names)
    assert a.rank + len(a.not_identifiable) == robot.n_parameters
    for c in a.not_identifiable:
        assert max(abs(v) for v in c["coefficients"].values()) == pytest.approx(1.0)
        d = robot.table.vector(c["coefficients"], base=np.zeros(robot.n_parameters))
        step = 1e-4 / np.max(np.abs(d * parameter_scale(robot)))
        moved = robot.forward_kinematics(theta + step * d, q, initial=poses) - poses
        assert np.abs(moved).max() < 1e-9, c["combination"]
    # what the analysis calls identifiable is: the free default set has full rank
    b = analyze_observability(robot, theta, poses, NOISE, joints=q)
    assert b.rank == len(robot.free_default) and b.not_identifiable == ()


def test_delta_null_directions_are_the_arm_direction_against_the_joint_offset():
    """Per chain one null direction: (dalpha, dLax, dLay) = (1/Lax, -Lay/Lax, 1) (turning the arm
    vector in the chain plane and adding the angle to the joint offset)."""
    robot = default_robot("delta")
    theta = perturbed(robot, 4, size_mm=1.0, size_rad=np.deg2rad(1.0))
    theta[robot.table.indices(["Lay1", "Lay2", "Lay3"])] += [0.7, -0.4, 0.2]
    q, poses = reached(robot, theta, poses_of(robot, 30, 5))
    a = analyze_observability(robot, theta, poses, NOISE, joints=q, free=robot.table.names)
    assert a.rank == 21 and [c["chain"] for c in a.not_identifiable] == [0, 1, 2]
    values = robot.table.to_dict(theta)
    for i, c in enumerate(a.not_identifiable, start=1):
        assert set(c["coefficients"]) == {f"alpha{i}", f"Lax{i}", f"Lay{i}"}
        co = {k: v / c["coefficients"][f"Lay{i}"] for k, v in c["coefficients"].items()}
        lax, lay = values[f"Lax{i}"], values[f"Lay{i}"]
        assert co[f"alpha{i}"] == pytest.approx(1.0 / lax, rel=1e-8)
        assert co[f"Lax{i}"] == pytest.approx(-lay / lax, rel=1e-6)
        assert f"Lay{i}" in c["combination"] and f"alpha{i}" in c["combination"]
    # at the nominal geometry (Lay = 0) the arm length does not enter: alpha and Lay only
    n = analyze_observability(robot, robot.table.nominal, poses, NOISE, free=robot.table.names).not_identifiable
    for i, c in enumerate(n, start=1):
        assert set(c["coefficients"]) == {f"alpha{i}", f"Lay{i}"}
        assert c["coefficients"][f"Lay{i}"] == pytest.approx(1.0)
        assert c["coefficients"][f"alpha{i}"] == pytest.approx(1.0 / 260.0, rel=1e-9)
    # the weakest combinations are the same directions, one chain each, in scaled coordinates
    weakest = analyze_observability(robot, robot.table.nominal, poses, NOISE, free=robot.table.names) \
        .weakest_combinations(3)
    supports = sorted(sorted(k for k, v in w["coefficients"].items() if abs(v) > 1e-9) for w in weakest)
    assert supports == [sorted([f"Lay{i}", f"alpha{i}"]) for i in (1, 2, 3)]
    assert all(not w["determined"] and abs(w["coefficients"][f"Lay{i}"]) == pytest.approx(np.sqrt(0.5))
               for i, w in zip((1, 2, 3), sorted(weakest, key=lambda w: w["combination"][-1])))


def test_describe_combination_names_parameters():
    names = HEXAPOD.table.names
    v = np.zeros(42)
    v[HEXAPOD.table.index("B1.z")] = 0.71
    v[HEXAPOD.table.index("dl1")] = -0.70
    assert describe_combination(v, names) == "0.71 B1.z - 0.70 dl1"
    assert describe_combination(-v, names) == "0.71 B1.z - 0.70 dl1"
    w = np.full(42, 1 / np.sqrt(42))
    assert describe_combination(w, names, n_terms=2).endswith(" + ...")
    assert describe_combination([1.0, 1 / 260], ["Lay1", "alpha1"], min_coefficient=1e-6,
                                number_format=".3g") == "1 Lay1 + 0.00385 alpha1"


@pytest.mark.parametrize("name", ROBOTS)
def test_results_are_read_only(name):
    robot = default_robot(name)
    poses = poses_of(robot, 10, 8)
    a = analyze_observability(robot, robot.table.nominal, poses, NOISE)
    with pytest.raises(ValueError, match="read-only"):
        a.crb_std[0] = 0.0
    pu = pose_uncertainty(robot, robot.table.nominal, poses[:2], a.parameter_covariance())
    with pytest.raises(ValueError, match="read-only"):
        pu.covariance[0, 0, 0] = 0.0


@pytest.mark.parametrize("name", ROBOTS)
def test_summary_is_json_ready_and_names_parameters(name):
    robot = default_robot(name)
    s = analyze_observability(robot, robot.table.nominal, poses_of(robot, 10, 9), NOISE).summary()
    back = json.loads(json.dumps(s))
    assert back["parameters"] == list(robot.free_default)
    assert set(back["crb_std"]) == set(robot.free_default) == set(back["crb_std_mm"])
    assert set(back["indices"]) == {"O1", "O2", "O3", "O4"}
    assert len(back["singular_values"]) == len(robot.free_default)
    assert all(back["parameter_units"][n] == robot.table.units[robot.table.index(n)] for n in back["parameters"])


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.parametrize("seed", [0, 1])
def test_pose_uncertainty_is_the_linearised_compensation_error(name, seed):
    robot = default_robot(name)
    theta = perturbed(robot, seed)
    _, idx = free_indices(robot)
    delta = np.zeros(robot.n_parameters)
    delta[idx] = np.random.default_rng(seed + 10).standard_normal(idx.size) * 1e-4 / parameter_scale(robot)[idx]
    targets = poses_of(robot, 6, seed)
    # the identified model theta + delta commands the targets; the machine theta reaches them
    q = robot.inverse_kinematics(theta + delta, targets)
    d = robot.forward_kinematics(theta, q, initial=targets) - targets
    pu = pose_uncertainty(robot, theta, targets, np.outer(delta, delta))
    angle = robot.angle_pose_mask
    # first order against the exact kinematics, a modelling (not a rounding) tolerance: the
    # neglected second-order term relative to the first is ~|delta| / the machine's size (1e-4 mm
    # on ~100 mm, measured <= 2e-6); 1e-3 and 2e-3 are a wide margin on it
    np.testing.assert_allclose(pu.position_rms_mm, np.linalg.norm(d[:, ~angle], axis=1), rtol=1e-3)
    np.testing.assert_allclose(pu.orientation_rms_rad, np.linalg.norm(d[:, angle], axis=1), rtol=1e-3, atol=1e-15)
    np.testing.assert_allclose(pu.covariance, np.einsum("ni,nj->nij", d, d), rtol=2e-3,
                               atol=2e-3 * np.abs(pu.covariance).max())


@pytest.mark.parametrize("name", ROBOTS)
def test_pose_uncertainty_from_crb_matches_the_jacobian(name):
    robot = default_robot(name)
    theta = robot.table.nominal
    a = analyze_observability(robot, theta, poses_of(robot, enough(robot, 15), 8), NOISE)
    targets = poses_of(robot, 4, 9)
    pu = pose_uncertainty(robot, theta, targets, a.parameter_covariance())
    # the whitened Jacobian with unit noise is d pose / d theta_free
    J = identification_jacobian(robot, theta, targets, SensorNoise(1.0, 1.0, "normal")).reshape(4, robot.pose_dim, -1)
    # The same crb through two computations of the same Jacobian and product: each pose's
    # covariance to ~K eps ||J_k / S||^2 ||S crb S|| norm-wise (S the scale a.crb was computed
    # in; an element-wise bound fails on near-cancelling entries)
    expected = J @ a.crb @ np.swapaxes(J, 1, 2)
    js = np.linalg.norm(J / a.scale, 2, axis=(1, 2)) ** 2
    bound = 2 * a.n_free * EPS * js * np.linalg.norm(a.crb * np.outer(a.scale, a.scale), 2)
    assert np.all(np.linalg.norm(pu.covariance - expected, 2, axis=(1, 2)) <= bound)
    assert pu.position_rms_mm.shape == (4,) and np.all(pu.position_rms_mm > 0)


DELTA = default_robot("delta")


@pytest.mark.parametrize("call, exc, match", [
    (lambda: identification_jacobian("hexapod", HEXAPOD.table.nominal, np.zeros((1, 6)), NOISE), TypeError,
     "robot must be a calib.robot.Robot"),
    (lambda: identification_jacobian(HEXAPOD, HEXAPOD.table.nominal, np.zeros((1, 6)), 0.001), TypeError,
     "noise must be a SensorNoise"),
    (lambda: identification_jacobian(HEXAPOD, HEXAPOD.table.nominal, np.zeros(6), NOISE), ValueError,
     r"poses must have shape \(N, 6\), got \(6,\)"),
    (lambda: identification_jacobian(DELTA, DELTA.table.nominal, paper.TABLE4_NOMINAL_POSES, NOISE), ValueError,
     r"poses must have shape \(N, 3\), got \(10, 6\)"),
    (lambda: identification_jacobian(DELTA, np.zeros(42), np.zeros((1, 3)), NOISE), ValueError,
     r"theta must have shape \(24,\), got \(42,\)"),
    (lambda: identification_jacobian(HEXAPOD, HEXAPOD.table.nominal, paper.TABLE4_NOMINAL_POSES, NOISE,
                                     free=["B1.x", "nope"]), KeyError, "unknown parameter 'nope'"),
    (lambda: identification_jacobian(HEXAPOD, HEXAPOD.table.nominal, paper.TABLE4_NOMINAL_POSES, NOISE,
                                     free=[]), ValueError, "free must be a non-empty list"),
    (lambda: analyze_observability(HEXAPOD, HEXAPOD.table.nominal, paper.TABLE4_NOMINAL_POSES, NOISE,
                                   rank_rtol=0.0), ValueError, "rank_rtol"),
    (lambda: describe_combination(np.zeros(5), HEXAPOD.table.names), ValueError,
     r"vector must have shape \(42,\), got \(5,\)"),
    (lambda: describe_combination(np.ones(42), HEXAPOD.table.names, n_terms=0), ValueError,
     "n_terms must be a positive integer"),
    (lambda: analyze_observability(HEXAPOD, HEXAPOD.table.nominal, paper.TABLE4_NOMINAL_POSES, NOISE)
     .weakest_combinations(0), ValueError, "k must be"),
    (lambda: pose_uncertainty(HEXAPOD, HEXAPOD.table.nominal, np.zeros((1, 6)), np.eye(3)), ValueError,
     r"parameter_covariance must have shape \(42, 42\)"),
    (lambda: pose_uncertainty(HEXAPOD, HEXAPOD.table.nominal, paper.TABLE4_NOMINAL_POSES,
                              np.triu(np.ones((42, 42)))), ValueError, "must be symmetric"),
    (lambda: pose_uncertainty(HEXAPOD, HEXAPOD.table.nominal, np.zeros((1, 5)), np.eye(42)), ValueError,
     r"targets must have shape"),
    (lambda: pose_uncertainty(None, HEXAPOD.table.nominal, np.zeros((1, 6)), np.eye(42)), TypeError,
     "robot must be a calib.robot.Robot"),
])
def test_validation(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


@pytest.mark.parametrize("name", ROBOTS)
def test_above_the_qr_size_the_figures_are_the_direct_ones(name, monkeypatch):
    """With calib.observability.QR_FIRST_ROWS lowered below the poses, the singular values come
    from the QR triangle: the same singular values (absolute error ~K eps s_1, both backward
    stable), scaled condition number and bound (as the inverse of the Fisher matrix,
    :func:`inversion_accuracy`) as the direct SVDs."""
    import calib.observability

    robot = default_robot(name)
    poses = poses_of(robot, enough(robot, 30), 5)
    exact = analyze_observability(robot, robot.table.nominal, poses, NOISE)
    monkeypatch.setattr(calib.observability, "QR_FIRST_ROWS", 10)
    qr = analyze_observability(robot, robot.table.nominal, poses, NOISE)
    n = exact.singular_values.size
    s0 = exact.singular_values[0]
    np.testing.assert_allclose(qr.singular_values, exact.singular_values, rtol=0, atol=4 * n * EPS * s0)
    assert qr.rank == exact.rank == n
    tol = inversion_accuracy(exact.fisher)
    np.testing.assert_allclose(qr.crb_std, exact.crb_std, rtol=tol)
    assert qr.condition_number == pytest.approx(exact.condition_number, rel=tol)
    assert qr.scaled_condition_number == pytest.approx(exact.scaled_condition_number, rel=tol)
