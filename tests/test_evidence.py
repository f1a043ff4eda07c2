"""Tolerances learnt from the data (calib.evidence): the prior's scale that maximises the evidence.

Independent truths: the exact log evidence of a linear-Gaussian model written here in the rows'
space (``log N(y; 0, I + J S J^T)``, n x n, no parameter-space shortcut), maximised over a fine
grid; fits under a prior made by calib.engine on rows simulated with the kinematic model and
injected errors of a known spread; the evidence's invariance to the prior the fit was made under
(the data's information read back from its posterior is the same whichever prior was used).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from calib.engine import identify_forward
from calib.evidence import CONTRADICTION_NATS, MIN_DETERMINED, tolerance_from_data
from calib.noise import SensorNoise
from calib.prior import ParameterPrior
from calib.robots import ROBOTS, default_robot
from calib.workspace import reachable_poses


def _linear_result(robot, J, y, prior_std, mean=None):
    """A result object of a linear-Gaussian MAP fit ``y = J d + e`` under N(mean, prior_std^2):
    what tolerance_from_data reads (robot, prior, theta, covariance, free_indices)."""
    p = robot.n_parameters
    mean = robot.table.nominal if mean is None else mean
    A = J.T @ J + np.diag(1.0 / prior_std ** 2)
    cov = np.linalg.inv(A)
    d = cov @ (J.T @ y)
    return SimpleNamespace(robot=robot, prior=ParameterPrior(mean=mean, std=prior_std), theta=mean + d,
                           covariance=cov, free_indices=np.arange(p))


def _exact_log_evidence(J, y, std):
    """log N(y; 0, I + J diag(std^2) J^T), in the rows' space."""
    C = np.eye(len(y)) + (J * std ** 2) @ J.T
    sign, logdet = np.linalg.slogdet(C)
    return -0.5 * (y @ np.linalg.solve(C, y) + logdet + len(y) * np.log(2 * np.pi))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_single_unit_scale_is_the_exact_evidence_maximum(seed):
    """Hexapod (every parameter in mm): a random rank-deficient design (a third of the directions
    unseen, as on a plane of poses), errors drawn at 2 mm: the learnt tolerance is the grid maximum
    of the exact evidence, whichever prior the fit was made under."""
    robot = default_robot("hexapod")
    rng = np.random.default_rng(seed)
    p = robot.n_parameters
    J = rng.normal(size=(150, p)) @ np.diag(np.r_[np.full(28, 3.0), np.zeros(p - 28)])
    J = J @ np.linalg.qr(rng.normal(size=(p, p)))[0]  # the unseen directions mix every parameter
    truth = 2.0 * rng.normal(size=p)
    y = J @ truth + rng.normal(size=150)
    grid = np.exp(np.linspace(np.log(0.05), np.log(50.0), 4001))
    exact = np.array([_exact_log_evidence(J, y, np.full(p, t)) for t in grid[::40]])
    best = grid[::40][np.argmax(exact)]
    fine = grid[(grid > best / 1.2) & (grid < best * 1.2)]
    best = fine[np.argmax([_exact_log_evidence(J, y, np.full(p, t)) for t in fine])]
    for prior_mm in (0.1, 1.0, 10.0):
        est = tolerance_from_data(_linear_result(robot, J, y, np.full(p, prior_mm)))
        assert est.tolerance["mm"] == pytest.approx(best, rel=2e-3)   # the grid's step is 0.17%
        assert est.determined["mm"] <= 28 + 1e-9
    gain = _exact_log_evidence(J, y, np.full(p, best)) - _exact_log_evidence(J, y, np.full(p, 0.1))
    est = tolerance_from_data(_linear_result(robot, J, y, np.full(p, 0.1)))
    assert est.log_evidence_gain == pytest.approx(gain, rel=1e-3)
    assert est.contradicted and est.far, "2 mm errors under a 0.1 mm tolerance are contradicted, with names"


def _exact_log_evidence_svd(J, y, s, beta=1.0):
    """log N(y; 0, I / beta + s^2 J J^T) up to the constant, through J's singular values: every
    term a sum of positives (the rows' part outside J's range subtracted as a vector, not as
    squares), so it holds its precision where ``y^T y`` is 1e16 and the answer a few thousand."""
    U, sv, _ = np.linalg.svd(J, full_matrices=False)
    c = U.T @ y
    outside = y - U @ c
    var = 1.0 / beta + s * s * sv * sv
    return -0.5 * (np.sum(c * c / var) + beta * (outside @ outside) + np.sum(np.log(var))
                   - (len(y) - len(sv)) * np.log(beta))


def _exact_with_noise_scale(J, y, s):
    """The exact log evidence at its best noise scale beta (1-D search on log beta)."""
    from scipy.optimize import minimize_scalar

    best = minimize_scalar(lambda lb: -_exact_log_evidence_svd(J, y, s, np.exp(lb)), bounds=(-10, 10),
                           method="bounded", options={"xatol": 1e-10})
    return -best.fun


@pytest.mark.parametrize("noise", ["declared", "estimated"])
def test_evidence_gain_holds_its_precision_on_millimetre_errors_at_micrometre_noise(noise):
    """A hand-built machine seen by a precise instrument: errors of 2 mm, rows whose information is
    1e14 per mm^2 (``b^T A^-1 b`` of order 1e16, the gain a few thousand nats), the noise scale
    declared or estimated with the tolerance (the fit's chi-square given). The gain is the exact
    one (SVD in the rows' space) within 1e-4 nats: the textbook form's rounding, ``eps |H| |m|^2``,
    is a few nats here (it lost thousands on a 6-RUS fit under another BLAS kernel), the form
    written as a change from the fit rounds to second order."""
    robot = default_robot("hexapod")
    rng = np.random.default_rng(7)
    p, n = robot.n_parameters, 150
    J = 1e6 * rng.normal(size=(n, p))
    y = J @ (2.0 * rng.normal(size=p)) + 1.3 * rng.normal(size=n)
    fit = _linear_result(robot, J, y, np.full(p, 0.1))
    exact = _exact_log_evidence_svd
    if noise == "estimated":
        d = fit.theta - robot.table.nominal
        fit.chi2, fit.dof = float(np.sum((y - J @ d) ** 2) + np.sum((d / 0.1) ** 2)), n
        exact = _exact_with_noise_scale
    est = tolerance_from_data(fit)
    gain = exact(J, y, est.tolerance["mm"]) - exact(J, y, 0.1)
    assert gain > 1e3
    assert est.log_evidence_gain == pytest.approx(gain, abs=1e-4)
    assert est.contradicted
    if noise == "estimated":
        assert est.noise_scale == pytest.approx(1.3, rel=0.2)


def test_two_units_each_scaled_by_its_own_evidence():
    """Delta (mm and rad parameters): each unit's factor maximises the exact evidence over a 2-D
    grid about the estimate (no grid point beats it)."""
    robot = default_robot("delta")
    rng = np.random.default_rng(5)
    units = np.array(robot.table.units)
    p = robot.n_parameters
    ref = ParameterPrior.default(robot).std
    truth = np.where(units == "mm", 1.5, 0.004) * rng.normal(size=p)
    J = rng.normal(size=(200, p)) / ref  # every parameter seen, in its reference's scale
    y = J @ truth + rng.normal(size=200)
    est = tolerance_from_data(_linear_result(robot, J, y, ref))
    f_mm, f_rad = est.factor["mm"], est.factor["rad"]
    at = lambda a, b: _exact_log_evidence(J, y, ref * np.where(units == "mm", a, b))  # noqa: E731
    top = at(f_mm, f_rad)
    for da in (0.97, 1.03):
        for db in (0.97, 1.0, 1.03):
            assert at(f_mm * da, f_rad * db) <= top + 1e-9
    assert 1.0 < est.tolerance["mm"] < 2.5 and 0.002 < est.tolerance["rad"] < 0.008


def test_rows_that_see_nothing_keep_the_reference():
    robot = default_robot("hexapod")
    p = robot.n_parameters
    J = np.zeros((10, p))
    J[:, 0] = 1e-3  # barely one parameter, far below one determined
    y = np.random.default_rng(0).normal(size=10)
    est = tolerance_from_data(_linear_result(robot, J, y, np.full(p, 0.1)))
    assert est.determined["mm"] < MIN_DETERMINED
    assert est.factor == {"mm": 1.0} and not est.contradicted


def test_a_tolerance_that_fits_is_not_contradicted():
    robot = default_robot("hexapod")
    rng = np.random.default_rng(3)
    p = robot.n_parameters
    J = rng.normal(size=(300, p)) * 20.0
    truth = 0.1 * rng.normal(size=p)
    y = J @ truth + rng.normal(size=300)
    est = tolerance_from_data(_linear_result(robot, J, y, np.full(p, 0.1)))
    assert 0.07 < est.tolerance["mm"] < 0.14
    assert est.log_evidence_gain < CONTRADICTION_NATS and not est.contradicted and not est.far


def test_without_a_prior_nothing_is_learnt():
    robot = default_robot("hexapod")
    res = SimpleNamespace(robot=robot, prior=None)
    with pytest.raises(ValueError, match="under a prior"):
        tolerance_from_data(res)


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_learnt_from_a_nonlinear_fit_matches_the_spread_of_the_injected_errors(name):
    """Every robot, kinematic model: errors drawn with a spread 20 times the default tolerance,
    rows at a noise far below it: the learnt scale of each unit's tolerances is the errors' RMS in
    reference tolerances within the sampling spread of an RMS over the parameters (a factor 1.5)
    (where a unit's tolerances are one value, the learnt tolerance is the errors' RMS)."""
    robot = default_robot(name)
    rng = np.random.default_rng(11)
    ref = ParameterPrior.default(robot).std
    free = robot.table.indices(robot.free_default)
    errors = np.zeros(robot.n_parameters)
    errors[free] = 20.0 * ref[free] * rng.normal(size=free.size)
    theta = robot.table.nominal + errors
    poses = reachable_poses(robot, 120, rng, theta=theta)
    noise = SensorNoise(1e-3, 1e-6, "normal")
    joints = robot.inverse_kinematics(theta, poses)
    measured = poses + rng.normal(size=poses.shape) * noise.pose_std(robot.pose_units)
    fit = identify_forward(robot, joints, measured, noise, prior=ParameterPrior.default(robot))
    est = tolerance_from_data(fit)
    units = np.array(robot.table.units)
    for u, factor in est.factor.items():
        k = free[units[free] == u]
        rms = float(np.sqrt(np.mean((errors[k] / ref[k]) ** 2)))
        assert rms / 1.5 < factor < 1.5 * rms, (u, factor, rms)
    assert est.contradicted


def test_a_direction_pinned_to_zero_variance_is_read_as_exact():
    """A fit whose covariance lost a direction (the rows pin it far below the prior: angles declared
    exact, a pseudo-inverse dropping it): the estimate stays finite and equals the one where that
    direction is pinned at a millionth of the prior's standard deviation."""
    robot = default_robot("hexapod")
    rng = np.random.default_rng(9)
    p = robot.n_parameters
    J = rng.normal(size=(200, p)) * 10.0
    J[:, 0] *= 1e9  # one direction known to 1e-10 of the prior
    y = J @ (2.0 * rng.normal(size=p)) + rng.normal(size=200)
    res = _linear_result(robot, J, y, np.full(p, 0.1))
    est = tolerance_from_data(res)
    pinned = res.covariance.copy()
    pinned[0, :] = pinned[:, 0] = 0.0
    res.covariance = pinned
    est0 = tolerance_from_data(res)
    assert np.isfinite(est0.tolerance["mm"]) and est0.tolerance["mm"] == pytest.approx(est.tolerance["mm"], rel=1e-3)


def test_noise_wider_than_declared_goes_to_the_noise_scale_not_the_tolerance():
    """Rows whose scatter is 4 times the declared noise (physics left out, or noise declared too
    small): the scale and the noise are estimated together, each at the exact evidence's maximum
    over a grid of both (the rows' space, written here)."""
    robot = default_robot("hexapod")
    rng = np.random.default_rng(21)
    p, n = robot.n_parameters, 300
    J = rng.normal(size=(n, p)) * 3.0
    y = J @ (0.5 * rng.normal(size=p)) + 4.0 * rng.normal(size=n)
    res = _linear_result(robot, J, y, np.full(p, 0.1))
    d = res.theta - res.prior.mean
    res.chi2 = float(np.sum((y - J @ d) ** 2) + np.sum((d / 0.1) ** 2))  # the rows' and the prior's, as a fit's
    res.dof = n
    est = tolerance_from_data(res)

    def exact(tau, noise_sd):
        C = noise_sd ** 2 * np.eye(n) + tau ** 2 * J @ J.T
        return -0.5 * (y @ np.linalg.solve(C, y) + np.linalg.slogdet(C)[1])

    taus, sds = np.linspace(0.3, 0.8, 26), np.linspace(3.0, 5.0, 21)
    grid = np.array([[exact(t, sd) for sd in sds] for t in taus])
    i, j = np.unravel_index(np.argmax(grid), grid.shape)
    assert est.tolerance["mm"] == pytest.approx(taus[i], abs=0.02)   # the grid's step
    assert est.noise_scale == pytest.approx(sds[j], abs=0.1)
    assert 3.5 < est.noise_scale < 4.5
