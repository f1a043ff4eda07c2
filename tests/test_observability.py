import numpy as np
import pytest

from calib import paper
from calib.hexapod import N_PARAMETERS, paper_hexapod, parameter_index
from calib.kinematics import forward_kinematics, inverse_kinematics
from calib.metrics import evaluate_compensation
from calib.noise import SensorNoise
from calib.observability import (
    analyze_observability,
    describe_combination,
    fisher_information,
    identification_jacobian,
    pose_uncertainty,
)
from calib.workspace import random_poses

NOMINAL = paper_hexapod()
NOISE = SensorNoise(position_mm=1e-3, orientation_rad=1e-6, distribution="normal")
WIDE = np.array([[-20, 20], [-20, 20], [190, 220], [-0.1, 0.1], [-0.1, 0.1], [-0.1, 0.1]])


def machine(seed):
    return NOMINAL.with_errors(np.random.default_rng(seed).uniform(-0.05, 0.05, (6, 7)))


@pytest.mark.parametrize("column", [0, 3, 6, 17, 24, 41])
def test_identification_jacobian_matches_finite_differences(column):
    true = machine(column)
    targets = random_poses(5, column, WIDE)
    lengths = inverse_kinematics(NOMINAL, targets)
    reached = forward_kinematics(true, lengths)
    A = identification_jacobian(true, reached, NOISE)
    h = 1e-5
    e = np.zeros(N_PARAMETERS)
    e[column] = h
    plus = forward_kinematics(true.with_errors(true.vector + e), lengths, initial=reached)
    minus = forward_kinematics(true.with_errors(true.vector - e), lengths, initial=reached)
    fd = ((plus - minus) / (2 * h) * NOISE.weights()).ravel()
    np.testing.assert_allclose(A[:, column], fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_crb_is_inverse_of_fisher_and_indices_consistent():
    poses = random_poses(20, 3, WIDE)
    a = analyze_observability(NOMINAL, poses, NOISE)
    F = fisher_information(NOMINAL, poses, NOISE)
    np.testing.assert_allclose(a.fisher, F)
    np.testing.assert_allclose(a.crb @ F, np.eye(N_PARAMETERS), atol=1e-8)
    np.testing.assert_allclose(a.crb_std, np.sqrt(np.diag(np.linalg.inv(F))), rtol=1e-8)
    s = a.singular_values
    assert a.rank == N_PARAMETERS and np.all(np.diff(s) <= 0)
    np.testing.assert_allclose(s ** 2, np.linalg.eigvalsh(F)[::-1], rtol=1e-7)
    assert a.condition_number == pytest.approx(1.0 / a.o2)
    assert a.o3 == pytest.approx(s[-1])
    assert a.o4 == pytest.approx(a.o3 * a.o2)
    assert a.o1 == pytest.approx(np.exp(np.mean(np.log(s))) / np.sqrt(6 * 20))
    assert a.crb_rms == pytest.approx(np.sqrt(np.trace(a.crb) / N_PARAMETERS))


@pytest.mark.parametrize("factor", [0.5, 2.0, 10.0])
def test_noise_scaling(factor):
    poses = random_poses(12, 4, WIDE)
    a = analyze_observability(NOMINAL, poses, NOISE)
    b = analyze_observability(NOMINAL, poses, SensorNoise(1e-3 * factor, 1e-6 * factor, "normal"))
    np.testing.assert_allclose(b.singular_values, a.singular_values / factor, rtol=1e-9)
    np.testing.assert_allclose(b.crb_std, a.crb_std * factor, rtol=1e-7)
    assert b.o2 == pytest.approx(a.o2) and b.condition_number == pytest.approx(a.condition_number)
    assert b.o1 == pytest.approx(a.o1 / factor) and b.o4 == pytest.approx(a.o4 / factor)
    assert b.scaled_condition_number == pytest.approx(a.scaled_condition_number)


def test_paper_poses_condition_in_the_thousands():
    a = analyze_observability(NOMINAL, paper.TABLE4_NOMINAL_POSES, NOISE)
    assert a.rank == N_PARAMETERS
    assert a.scaled_condition_number > 1e3
    weakest = a.weakest_combinations(3)
    assert [w["std_mm"] for w in weakest] == sorted([w["std_mm"] for w in weakest], reverse=True)
    assert weakest[0]["std_mm"] == pytest.approx(1.0 / a.singular_values[-1])
    assert weakest[0]["std_mm"] > a.crb_std.max() * 0.999


@pytest.mark.parametrize("n_poses, rank", [(1, 6), (4, 24), (6, 36)])
def test_too_few_poses_leave_undetermined_combinations(n_poses, rank):
    a = analyze_observability(NOMINAL, random_poses(n_poses, 5, WIDE), NOISE)
    assert a.rank == rank
    assert a.condition_number == np.inf and a.o3 == 0.0 and a.o1 == 0.0
    assert np.all(np.isinf(a.crb_std))
    w = a.weakest_combinations(1)[0]
    assert not w["determined"] and w["std_mm"] == np.inf
    s = a.summary()
    assert s["condition_number"] is None and s["rank"] == rank


def test_repeated_pose_leaves_rank_six():
    pose = random_poses(1, 6, WIDE)
    a = analyze_observability(NOMINAL, np.repeat(pose, 10, axis=0), NOISE)
    assert a.rank == 6


def test_describe_combination_names_parameters():
    v = np.zeros(N_PARAMETERS)
    v[parameter_index("dZB1")] = 0.71
    v[parameter_index("dl1")] = -0.70
    assert describe_combination(v) == "0.71 dZB1 - 0.70 dl1"
    assert describe_combination(-v) == "0.71 dZB1 - 0.70 dl1"
    w = np.full(N_PARAMETERS, 1 / np.sqrt(N_PARAMETERS))
    assert describe_combination(w, n_terms=2).endswith(" + ...")


def test_results_are_read_only():
    a = analyze_observability(NOMINAL, paper.TABLE4_NOMINAL_POSES, NOISE)
    with pytest.raises(ValueError, match="read-only"):
        a.crb_std[0] = 0.0
    pu = pose_uncertainty(NOMINAL, paper.TABLE4_NOMINAL_POSES[:2], a.crb)
    with pytest.raises(ValueError, match="read-only"):
        pu.covariance[0, 0, 0] = 0.0


def test_summary_is_json_ready():
    import json

    s = analyze_observability(NOMINAL, paper.TABLE4_NOMINAL_POSES, NOISE).summary()
    text = json.dumps(s)
    assert "dZB1" in text and set(s["indices"]) == {"O1", "O2", "O3", "O4"}
    assert len(s["singular_values"]) == N_PARAMETERS


@pytest.mark.parametrize("seed", [0, 1])
def test_pose_uncertainty_is_the_linearised_compensation_error(seed):
    true = machine(seed)
    delta = np.random.default_rng(seed + 10).standard_normal(N_PARAMETERS) * 1e-4
    identified = true.with_errors(true.vector + delta)
    targets = random_poses(6, seed, WIDE)
    ev = evaluate_compensation(true, identified, targets)
    d = ev.reached_after - targets
    pu = pose_uncertainty(true, targets, np.outer(delta, delta))
    np.testing.assert_allclose(pu.position_rms_mm, np.linalg.norm(d[:, :3], axis=1), rtol=1e-3)
    np.testing.assert_allclose(pu.orientation_rms_rad, np.linalg.norm(d[:, 3:], axis=1), rtol=1e-3)
    np.testing.assert_allclose(pu.covariance, np.einsum("ni,nj->nij", d, d), rtol=2e-3,
                               atol=2e-3 * np.abs(pu.covariance).max())


def test_pose_uncertainty_from_crb_matches_sampled_parameters():
    poses = random_poses(15, 8, WIDE)
    a = analyze_observability(NOMINAL, poses, NOISE)
    targets = random_poses(4, 9, WIDE)
    pu = pose_uncertainty(NOMINAL, targets, a.crb)
    from calib.kinematics import forward_parameter_jacobian
    J = forward_parameter_jacobian(NOMINAL, targets)
    np.testing.assert_allclose(pu.covariance, J @ a.crb @ np.swapaxes(J, 1, 2), rtol=1e-9,
                               atol=1e-12 * np.abs(pu.covariance).max())
    assert pu.position_rms_mm.shape == (4,)


@pytest.mark.parametrize("call, exc, match", [
    (lambda: identification_jacobian("hexapod", np.zeros((1, 6)), NOISE), TypeError, "hexapod must be a Hexapod"),
    (lambda: identification_jacobian(NOMINAL, np.zeros((1, 6)), 0.001), TypeError, "noise must be a SensorNoise"),
    (lambda: identification_jacobian(NOMINAL, np.zeros(6), NOISE), ValueError, r"poses must have shape \(N, 6\), got \(6,\)"),
    (lambda: analyze_observability(NOMINAL, paper.TABLE4_NOMINAL_POSES, NOISE, rank_rtol=0.0), ValueError, "rank_rtol"),
    (lambda: describe_combination(np.zeros(5)), ValueError, r"vector must have shape \(42,\), got \(5,\)"),
    (lambda: describe_combination(np.ones(42), n_terms=0), ValueError, "n_terms must be a positive integer"),
    (lambda: analyze_observability(NOMINAL, paper.TABLE4_NOMINAL_POSES, NOISE).weakest_combinations(0), ValueError, "k must be"),
    (lambda: pose_uncertainty(NOMINAL, np.zeros((1, 6)), np.eye(3)), ValueError, r"parameter_covariance must have shape \(42, 42\)"),
    (lambda: pose_uncertainty(NOMINAL, np.zeros((1, 6)), np.triu(np.ones((42, 42)))), ValueError, "must be symmetric"),
    (lambda: pose_uncertainty(NOMINAL, np.zeros((1, 5)), np.eye(42)), ValueError, r"targets must have shape"),
    (lambda: pose_uncertainty(None, np.zeros((1, 6)), np.eye(42)), TypeError, "hexapod must be a Hexapod"),
])
def test_validation(call, exc, match):
    with pytest.raises(exc, match=match):
        call()
