"""Manufacturing tolerances as priors (calib.prior, the ``prior=`` of calib.engine's fits).

Measurements are simulated with the kinematic model alone: the joints the true machine needs at
each pose (``robot.inverse_kinematics`` under the true parameters) and the poses plus seeded
sensor noise at the pipeline's defaults (the hexapod paper's +-1 um, uniform; angles exact to
the weights' floor). The independent truth of the maximum a posteriori fits is a fit written
here: Gauss-Newton on the whitened pose residuals and prior rows, with a central-difference
Jacobian of the forward kinematics and a dense ``numpy.linalg.lstsq`` step.
"""

from __future__ import annotations

import numpy as np
import pytest

from calib import paper
from calib.engine import METHODS, gauge_representative, identify, identify_chainwise, identify_forward
from calib.noise import SensorNoise
from calib.observability import analyze_observability
from calib.prior import DATA_SOURCE_RATIO, ParameterPrior
from calib.robots import ROBOTS, default_robot, reference_errors, uniform_errors
from calib.workspace import reachable_poses

NAMES = sorted(ROBOTS)
#: Sensor noise of the simulated recordings: 1 um on positions and 1 urad on angles, normal (the
#: defaults of pipeline.design and of the contract tests). The run's default declares the angles
#: exact (floored at 1e-9 rad), under which the forward fit draws on closure residuals that are
#: nearly noise-free combinations across chains and the chain-wise fit, blind to them, predicts
#: the 6-RUS off the plane 2.5 times worse: see docs/observability.md.
NOISE = SensorNoise(1e-3, 1e-6, "normal")
#: The pipeline's default run noise (python -m pipeline.run): +-1 um uniform, angles exact.
RUN_NOISE = SensorNoise(paper.PAPER_NOISE_MM)
#: Largest tilt (rad) and height offset (mm) of the poses predicted off the calibration plane.
OFF_PLANE_TILT_RAD = np.deg2rad(3.0)
OFF_PLANE_HEIGHT_MM = 10.0
#: Central-difference step of the reference fit's Jacobian, per parameter unit (mm or rad): its
#: truncation error (h^2 times the third derivative over the machine size, ~1e-10 relative) and
#: its rounding (the forward kinematics' 1e-11 mm over h, ~1e-7 relative) are both far below
#: the noise-level differences the tests compare.
FD_STEP = 1e-4


def _tolerance_errors(robot, seed: int) -> np.ndarray:
    """(P,) errors drawn uniformly within the robot's declared default tolerance; none on what is
    not identified by default and seeded errors leave at nominal (``machine_only``,
    ``chain_coupled``: the linear Delta's tool offset and rod differences)."""
    tol = ParameterPrior.default(robot).std.copy()
    tol[robot.table.indices(robot.machine_only + robot.chain_coupled)] = 0.0
    return np.random.default_rng(seed).uniform(-1.0, 1.0, robot.n_parameters) * tol


def _plane_poses(robot, side: int = 10) -> np.ndarray:
    """(side^2, D) a level grid at the home height over the middle 70% of the workspace's x and y."""
    b = robot.workspace_bounds()
    g = np.linspace(0.15, 0.85, side)
    x, y = np.meshgrid(b[0, 0] + g * (b[0, 1] - b[0, 0]), b[1, 0] + g * (b[1, 1] - b[1, 0]))
    poses = np.tile(robot.home_pose, (side * side, 1))
    poses[:, 0], poses[:, 1] = x.ravel(), y.ravel()
    return poses


def _off_plane_poses(robot, n: int, seed: int) -> np.ndarray:
    """(n, D) poses over the same x, y, heights within +-10 mm of the plane, tilts (alpha, beta)
    within +-3 degrees where the platform rotates."""
    rng = np.random.default_rng(seed)
    b = robot.workspace_bounds()
    poses = np.tile(robot.home_pose, (n, 1))
    for k in (0, 1):
        poses[:, k] = rng.uniform(b[k, 0] + 0.15 * (b[k, 1] - b[k, 0]), b[k, 0] + 0.85 * (b[k, 1] - b[k, 0]), n)
    poses[:, 2] += rng.uniform(-OFF_PLANE_HEIGHT_MM, OFF_PLANE_HEIGHT_MM, n)
    if robot.pose_dim == 6:
        poses[:, 3:5] += rng.uniform(-OFF_PLANE_TILT_RAD, OFF_PLANE_TILT_RAD, (n, 2))
    return poses


def _measure(robot, theta, poses, seed: int, noise: SensorNoise = NOISE):
    """``(joints (N, C), measured (N, D))`` of the machine ``theta`` at ``poses``."""
    joints = robot.inverse_kinematics(theta, poses)
    return joints, poses + noise.sample(len(poses), seed, robot.pose_units)


def _prediction_rms(robot, theta_hat, theta, targets) -> float:
    """mm, RMS over ``targets`` of the error of the poses ``theta_hat`` predicts at the joints
    the machine ``theta`` needs there (angles as the length they move at the machine's size)."""
    joints = robot.inverse_kinematics(theta, targets)
    err = robot.forward_kinematics(theta_hat, joints, initial=targets) - targets
    err = np.where(robot.angle_pose_mask, robot.length_scale_mm, 1.0) * err
    return float(np.sqrt(np.mean(np.sum(err ** 2, axis=1))))


def _reference_map(robot, joints, measured, prior, iterations: int = 8):
    """``(theta (P,), posterior covariance (K, K) of the free parameters)``, the maximum a
    posteriori fit written independently of the engine: Gauss-Newton on ``[(measured - FK(theta,
    q)) / noise std; (theta - mean) / std]`` over the free parameters, central-difference
    Jacobian of the forward kinematics, dense lstsq steps; the covariance ``(J^T J)^-1`` of the
    last Jacobian."""
    free = robot.table.indices(robot.free_default)
    w = 1.0 / NOISE.pose_std(robot.pose_units)
    theta = prior.mean.copy()

    def residual(th):
        pose = robot.forward_kinematics(th, joints, initial=measured)
        return np.concatenate([((measured - pose) * w).ravel(), (th[free] - prior.mean[free]) / prior.std[free]])

    for _ in range(iterations):
        r = residual(theta)
        J = np.empty((r.size, free.size))
        for j, k in enumerate(free):
            e = np.zeros_like(theta)
            e[k] = FD_STEP
            J[:, j] = (residual(theta + e) - residual(theta - e)) / (2 * FD_STEP)
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        theta[free] += step
        if np.max(np.abs(step / prior.std[free])) < 1e-9:
            break
    return theta, np.linalg.inv(J.T @ J)


# --------------------------------------------------------------------------- one plane


@pytest.fixture(scope="module")
def one_plane():
    """Per robot, computed once: the machine (errors within the declared tolerance), its 8 x 8
    level grid at one height measured, the reference fit, 200 poses off the plane and the
    uncalibrated prediction error there."""
    cache = {}

    def get(name):
        if name not in cache:
            robot = default_robot(name)
            prior = ParameterPrior.default(robot)
            theta = robot.table.nominal + _tolerance_errors(robot, 1)
            joints, measured = _measure(robot, theta, _plane_poses(robot, 8), 2)
            ref, ref_cov = _reference_map(robot, joints, measured, prior)
            off = _off_plane_poses(robot, 200, 3)
            cache[name] = dict(robot=robot, prior=prior, theta=theta, joints=joints, measured=measured, ref=ref,
                               ref_cov=ref_cov, off=off, ref_error=_prediction_rms(robot, ref, theta, off),
                               uncalibrated=_prediction_rms(robot, robot.table.nominal, theta, off))
        return cache[name]

    return get


#: Robots whose chain-wise fit is no maximum a posteriori fit on one plane, and why (measured).
CHAINWISE_NOT_MAP = {
    "linear_delta": "its three rods lean alike, so one pose's noise moves their closures together (mean "
                    "|n_i . n_j| 0.52 over the plane, the rotary Delta's 0.08), which the chain-wise fit "
                    "takes as independent: off the plane it predicts 1.6-2.9 times the reference over five "
                    "noise draws (the rotary Delta's 0.99-1.1)",
}


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("method", METHODS)
def test_one_plane_predicts_off_the_plane_as_the_reference_fit(one_plane, name, method):
    """Calibrated on one level plane at one height, each method predicts poses tilted up to 3
    degrees and 10 mm off it within 1.5x of the independent maximum a posteriori fit, and far
    below the uncalibrated error (the plain fit is refused or lost on such a pose set); the
    chain-wise fit of a robot of :data:`CHAINWISE_NOT_MAP` to the second claim alone."""
    c = one_plane(name)
    robot = c["robot"]
    fit = identify(robot, c["joints"], c["measured"], NOISE, method=method, prior=c["prior"])
    assert fit.success, fit.message
    error = _prediction_rms(robot, fit.theta, c["theta"], c["off"])
    print(f"{name} {method}: off-plane prediction {1e3 * error:.2f} um, reference {1e3 * c['ref_error']:.2f} um, "
          f"uncalibrated {1e3 * c['uncalibrated']:.1f} um")
    if method == "forward" or name not in CHAINWISE_NOT_MAP:
        assert error <= 1.5 * c["ref_error"]
    else:
        assert error < 0.01 * c["uncalibrated"]
    assert c["ref_error"] < 0.1 * c["uncalibrated"]
    # A level plane leaves a 6-DOF platform's combinations to the prior (a Delta's arms still
    # swing through the plane: it determines them all).
    assert bool(fit.left_to_prior()) == (robot.pose_dim == 6)


@pytest.mark.parametrize("name", NAMES)
def test_forward_map_fit_is_the_reference_fit(one_plane, name):
    """A second method for the forward fit with a prior: the same minimum as the reference fit
    (parameters to 1e-4 of their prior standard deviation: the reference's Gauss-Newton with a
    finite-difference Jacobian, 1e-7 relative error, converges linearly at that error times the
    condition number, and stops after 8 steps) and the same posterior standard deviations (to
    1e-4 relative: the inverse of that Jacobian's Gram matrix)."""
    c = one_plane(name)
    robot = c["robot"]
    fit = identify_forward(robot, c["joints"], c["measured"], NOISE, prior=c["prior"])
    free = fit.free_indices
    assert np.max(np.abs(fit.theta - c["ref"])[free] / c["prior"].std[free]) < 1e-4
    ref_std = np.sqrt(np.diag(c["ref_cov"]))
    assert np.max(np.abs(fit.std[free] / ref_std - 1.0)) < 1e-4


def test_left_to_prior_spans_what_the_plane_cannot_identify(one_plane):
    """Independent truth: every combination calib.observability finds unidentifiable from the
    plane (plain Fisher information) lies, in tolerance units, within the span of the
    combinations the maximum a posteriori fit reports left to the prior."""
    c = one_plane("hexapod")
    robot = c["robot"]
    fit = identify_forward(robot, c["joints"], c["measured"], NOISE, prior=c["prior"])
    left = fit.left_to_prior(n_terms=robot.n_parameters)
    names = [robot.table.names[i] for i in fit.free_indices]
    basis = np.array([[d["coefficients"].get(n, 0.0) for n in names] for d in left])
    q, _ = np.linalg.qr(basis.T)
    a = analyze_observability(robot, robot.table.nominal, _plane_poses(robot, 8), NOISE)
    assert a.not_identifiable
    std = dict(zip(names, c["prior"].std[fit.free_indices]))
    for comb in a.not_identifiable:
        v = np.array([comb["coefficients"].get(n, 0.0) / std[n] for n in names])
        v /= np.linalg.norm(v)
        assert np.linalg.norm(v - q @ (q.T @ v)) < 1e-3, comb["combination"]
    sources = fit.parameter_sources()
    assert set(sources.values()) <= {"data", "prior"} and "prior" in sources.values()
    post, tol = fit.std[fit.free_indices], c["prior"].std[fit.free_indices]
    assert [sources[n] for n in names] == ["data" if p < DATA_SOURCE_RATIO * t else "prior" for p, t in zip(post, tol)]


@pytest.mark.parametrize("name", NAMES)
def test_no_method_fails_on_a_subset_of_the_plane(one_plane, name):
    """Subsets of the grid, down to two poses (fewer measurements than parameters): every
    method and solver returns a converged answer that predicts better than the uncalibrated model."""
    c = one_plane(name)
    robot = c["robot"]
    rng = np.random.default_rng(11)
    for size in (2, 7, 20, 40):
        rows = np.sort(rng.choice(len(c["joints"]), size, replace=False))
        for method in METHODS:
            for solver in ("lm", "gn"):
                fit = identify(robot, c["joints"][rows], c["measured"][rows], NOISE, method=method,
                               prior=c["prior"], solver=solver)
                assert fit.success or method == "forward" and solver == "gn", (size, method, solver, fit.message)
                assert np.all(np.isfinite(fit.theta)) and np.all(np.isfinite(fit.std))
                assert _prediction_rms(robot, fit.theta, c["theta"], c["off"]) < c["uncalibrated"], (size, method)


# --------------------------------------------------------------------------- well-spread poses


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("method", METHODS)
def test_prior_changes_nothing_that_matters_on_well_spread_poses(name, method):
    """The default run's machine and noise (reference errors, +-1 um), 100 poses spread over the
    workspace (the engine benchmark's), 50 held-out poses. Forward fit: the parameter RMS error
    (against the gauge representative of the truth, angles as lengths at the machine's size) and
    the held-out prediction error with the default prior are within 2% of the plain fit's. The
    chain-wise fit, whose per-chain data leave combinations weaker than the tolerance even
    there (the hexapod's leg-wise B-P combinations), is changed by the prior, for the better on
    the hexapod: its held-out error is at most 2% above the plain fit's (figures printed)."""
    robot = default_robot(name)
    theta = robot.table.nominal + reference_errors(robot, 0)
    poses = reachable_poses(robot, 100, 0, theta=theta)
    joints, measured = _measure(robot, theta, poses, 1, RUN_NOISE)
    heldout = reachable_poses(robot, 50, 2, theta=theta)
    truth = gauge_representative(robot, theta)
    scale = np.where(robot.table.angle_mask(), robot.length_scale_mm, 1.0)
    figures = []
    for prior in (None, ParameterPrior.default(robot)):
        fit = identify(robot, joints, measured, RUN_NOISE, method=method, prior=prior)
        assert fit.success, fit.message
        free = fit.free_indices
        rms = float(np.sqrt(np.mean(((fit.theta - truth) * scale)[free] ** 2)))
        figures.append((rms, _prediction_rms(robot, fit.theta, theta, heldout)))
    (rms0, held0), (rms1, held1) = figures
    print(f"{name} {method}: parameter RMS {rms0:.4g} -> {rms1:.4g} mm, held-out {held0:.4g} -> {held1:.4g} mm")
    if method == "forward":
        assert abs(rms1 / rms0 - 1.0) <= 0.02
        assert abs(held1 / held0 - 1.0) <= 0.02
    else:
        assert held1 <= 1.02 * held0


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("method", METHODS)
def test_no_prior_is_the_plain_fit_and_a_wide_prior_tends_to_it(name, method):
    """``prior=None`` is the plain fit (the same arrays, no sources but data, nothing left to a
    prior); a prior 1e6 times wider moves no parameter by more than 1e-2 of the plain fit's
    standard uncertainty: its own pull is (data std / prior std)^2, below 1e-12, but both fits
    stop by their step rules (relative steps of 1e-9 of parameters of hundreds of mm, an
    absolute update of 1e-10), which leave each up to ~1e-3 of a standard uncertainty from the
    exact minimum."""
    robot = default_robot(name)
    theta = robot.table.nominal + uniform_errors(robot, 4, 0.05, 5e-4)
    joints, measured = _measure(robot, theta, reachable_poses(robot, 40, 5, theta=theta), 6)
    plain = identify(robot, joints, measured, NOISE, method=method)
    none = identify(robot, joints, measured, NOISE, method=method, prior=None)
    for a, b in ((plain.theta, none.theta), (plain.covariance, none.covariance), (plain.residuals, none.residuals)):
        assert np.array_equal(a, b)
    assert none.prior is None and none.left_to_prior() == ()
    assert set(none.parameter_sources().values()) <= {"data", "held"}
    wide = ParameterPrior(robot.table.nominal, 1e6 * ParameterPrior.default(robot).std)
    fit = identify(robot, joints, measured, NOISE, method=method, prior=wide)
    free = fit.free_indices
    assert np.max(np.abs(fit.theta - plain.theta)[free] / plain.std[free]) < 1e-2


@pytest.mark.parametrize("method", METHODS)
def test_with_a_prior_only_an_empty_pose_set_is_refused(method):
    robot = default_robot("hexapod")
    prior = ParameterPrior.default(robot)
    joints, measured = _measure(robot, robot.table.nominal, robot.home_pose[None], 1)
    with pytest.raises(ValueError, match="at least"):
        identify(robot, joints, measured, NOISE, method=method)
    fit = identify(robot, joints, measured, NOISE, method=method, prior=prior)
    assert fit.success and fit.dof == robot.pose_dim
    with pytest.raises(ValueError, match="determine nothing"):
        identify(robot, joints[:0], measured[:0], NOISE, method=method, prior=prior)
    with pytest.raises(ValueError, match="declared noise"):
        identify_chainwise(robot, joints, measured, prior=prior)


# --------------------------------------------------------------------------- the prior itself


def test_prior_from_tolerance_names_units_and_defaults():
    robot = default_robot("rus")
    default = ParameterPrior.default(robot)
    angle = robot.table.angle_mask()
    assert np.array_equal(default.mean, robot.table.nominal)
    assert np.all(default.std[~angle] == robot.default_parameter_tolerance["mm"])
    assert np.all(default.std[angle] == robot.default_parameter_tolerance["rad"])
    p = ParameterPrior.from_tolerance(robot, {"mm": 0.05, "s3": 0.3})
    expected = np.where(angle, robot.default_parameter_tolerance["rad"], 0.05)
    expected[robot.table.index("s3")] = 0.3  # a name overrides its unit
    assert np.array_equal(p.std, expected)
    assert p.tolerance_by_name(robot)["s3"] == 0.3


@pytest.mark.parametrize("tolerance, match", [
    ({"B9.x": 0.1}, "'B9.x'"), ({"deg": 0.1}, "'deg'"), ({"mm": 0.0}, "'mm'"), ({"B1.x": -1.0}, "'B1.x'"),
    ({"mm": float("nan")}, "'mm'"), ({"mm": "a lot"}, "'mm'")])
def test_prior_from_tolerance_refuses_bad_keys_and_values(tolerance, match):
    with pytest.raises(ValueError, match=match):
        ParameterPrior.from_tolerance(default_robot("hexapod"), tolerance)


def test_prior_refuses_bad_arrays_and_a_foreign_robot():
    with pytest.raises(ValueError, match="std"):
        ParameterPrior(np.zeros(3), np.array([1.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match="std"):
        ParameterPrior(np.zeros(3), np.ones(2))
    hexapod, delta = default_robot("hexapod"), default_robot("delta")
    joints, measured = _measure(hexapod, hexapod.table.nominal, hexapod.home_pose[None], 1)
    with pytest.raises(ValueError, match="parameters"):
        identify_forward(hexapod, joints, measured, NOISE, prior=ParameterPrior.default(delta))


@pytest.mark.parametrize("name", NAMES)
def test_implausible_errors_are_those_beyond_three_tolerances_farthest_first(name):
    """Errors at 2.9, 3.1 and 5 tolerances on three free parameters: the last two named, 5 first,
    each with its error, tolerance and unit; the parameters not asked about never named."""
    from calib.prior import IMPLAUSIBLE_TOLERANCES, implausible_errors

    robot = default_robot(name)
    prior = ParameterPrior.default(robot)
    names = list(robot.free_default)[:3]
    errors = np.zeros(robot.n_parameters)
    for name_, times in zip(names, (2.9, 3.1, 5.0)):
        k = robot.table.index(name_)
        errors[k] = -times * prior.std[k]
    other = robot.table.index(robot.table.names[-1]) if robot.table.names[-1] not in names else None
    if other is not None:
        errors[other] = 10 * prior.std[other]
    found = implausible_errors(robot, errors, prior, names)
    assert [e.name for e in found] == [names[2], names[1]]
    for e in found:
        k = robot.table.index(e.name)
        assert (e.error, e.tolerance, e.unit) == (errors[k], prior.std[k], robot.table.units[k])
        assert abs(e.error) > IMPLAUSIBLE_TOLERANCES * e.tolerance
