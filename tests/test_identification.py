import numpy as np
import pytest

from calib import paper
from calib.hexapod import paper_hexapod
from calib.identification import identify_forward, identify_paper
from calib.kinematics import forward_kinematics, inverse_kinematics
from calib.metrics import evaluate_compensation
from calib.noise import SensorNoise
from calib.workspace import random_poses

NOMINAL = paper_hexapod()
ACTUAL = paper_hexapod(with_table3_errors=True)
PAPER_NOISE = SensorNoise(position_mm=paper.PAPER_NOISE_MM, orientation_rad=0.0)


def measure(actual, targets, noise=None, seed=0):
    commanded = inverse_kinematics(NOMINAL, targets)
    reached = forward_kinematics(actual, commanded)
    if noise is not None:
        reached = reached + noise.sample(len(targets), seed)
    return commanded, reached


def test_paper_method_recovers_table3_noise_free_within_3_iterations():
    commanded, measured = measure(ACTUAL, paper.TABLE4_NOMINAL_POSES)
    res = identify_paper(NOMINAL, commanded, measured, epsilon=paper.PAPER_EPSILON)
    assert res.success and "paper's criterion met" in res.message
    assert res.iterations <= 3
    assert np.abs(res.errors - paper.TABLE3_ERRORS).max() < 1e-8
    assert list(res.history) == sorted(res.history, reverse=True)
    assert res.history[-1] <= paper.PAPER_EPSILON


def test_forward_method_recovers_table3_noise_free():
    commanded, measured = measure(ACTUAL, paper.TABLE4_NOMINAL_POSES)
    res = identify_forward(NOMINAL, commanded, measured, PAPER_NOISE)
    assert res.success, res.message
    assert np.abs(res.errors - paper.TABLE3_ERRORS).max() < 1e-8


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("method", ["paper", "forward"])
def test_random_injected_errors_recovered(seed, method):
    rng = np.random.default_rng(seed)
    injected = rng.uniform(-0.1, 0.1, (6, 7))
    actual = NOMINAL.with_errors(injected)
    commanded, measured = measure(actual, random_poses(30, seed))
    if method == "paper":
        res = identify_paper(NOMINAL, commanded, measured)
    else:
        res = identify_forward(NOMINAL, commanded, measured, SensorNoise(1e-3, 1e-5))
    assert res.success
    np.testing.assert_allclose(res.errors, injected, atol=1e-8)


@pytest.mark.parametrize("method", ["paper", "forward"])
def test_paper_noise_improves_heldout_error_30x(method):
    commanded, measured = measure(ACTUAL, paper.TABLE4_NOMINAL_POSES, PAPER_NOISE, seed=2024)
    if method == "paper":
        res = identify_paper(NOMINAL, commanded, measured)
    else:
        res = identify_forward(NOMINAL, commanded, measured, PAPER_NOISE)
    assert res.success, res.message
    ev = evaluate_compensation(ACTUAL, res.hexapod, random_poses(50, 7))
    assert ev.improvement >= 30
    # ... although the parameters themselves are poorly determined by 10 small poses.
    assert np.sqrt(np.mean((res.errors - paper.TABLE3_ERRORS) ** 2)) > 10 * paper.PAPER_NOISE_MM


def test_noisy_paper_method_reports_that_epsilon_is_unreachable():
    commanded, measured = measure(ACTUAL, paper.TABLE4_NOMINAL_POSES, PAPER_NOISE, seed=5)
    res = identify_paper(NOMINAL, commanded, measured, epsilon=1e-6)
    assert res.success and "not reachable" in res.message
    assert min(res.history) > 1e-6


def test_covariance_predicts_the_scatter_of_the_estimates():
    # Gaussian noise, many poses: the covariance from the residuals of one run must match
    # the spread of estimates over repeated runs (within sampling error).
    noise = SensorNoise(1e-3, 1e-6, "normal")
    targets = random_poses(40, 11)
    estimates, predicted = [], []
    for seed in range(40):
        commanded, measured = measure(ACTUAL, targets, noise, seed=seed)
        res = identify_paper(NOMINAL, commanded, measured)
        estimates.append(res.estimate)
        predicted.append(res.std)
    empirical = np.std(estimates, axis=0)
    ratio = empirical / np.mean(predicted, axis=0)
    assert 0.6 < np.median(ratio) < 1.5


@pytest.mark.parametrize("fn", [identify_paper, lambda n, c, m: identify_forward(n, c, m, PAPER_NOISE)])
@pytest.mark.parametrize("commanded,measured,match", [
    (np.zeros((6, 6)), np.zeros((6, 6)), "at least 7 poses"),
    (np.zeros((8, 6)), np.zeros((7, 6)), "same number of rows, got 8 and 7"),
    (np.zeros((8, 5)), np.zeros((8, 6)), r"commanded must have shape \(N, 6\), got \(8, 5\)"),
    (np.zeros((8, 6)), np.full((8, 6), np.nan), "measured has a non-finite value at index"),
])
def test_bad_input(fn, commanded, measured, match):
    with pytest.raises(ValueError, match=match):
        fn(NOMINAL, commanded, measured)


def test_forward_method_rejects_unknown_solver():
    commanded, measured = measure(ACTUAL, paper.TABLE4_NOMINAL_POSES)
    with pytest.raises(ValueError, match="method must be 'lm' or 'trf'"):
        identify_forward(NOMINAL, commanded, measured, PAPER_NOISE, method="gn")
