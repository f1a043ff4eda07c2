"""calib.engine: the fits evaluated block by block over the rows (FIT_BLOCK_ROWS) give the answers
of one pass over all rows, to what the conditioning allows; the triangular factors accumulated
block by block (the least-squares fallback, the exact condition numbers) are those of the whole
system. Parametrised over the robot registry."""

from __future__ import annotations

import numpy as np
import pytest

import calib.engine as engine
from calib.robot import ClosureJacobians
from calib.engine import identify_chainwise, identify_forward
from calib.noise import SensorNoise
from calib.observability import identification_jacobian
from calib.robots import ROBOTS, default_robot, uniform_errors
from calib.workspace import reachable_poses

from linalg_tolerance import EPS, column_norms, gram_inverse_tolerance, scaled_relative_gap

NAMES = sorted(ROBOTS)
#: Rows of a block in the tests: a prime, so that the last block is a short one.
SMALL_BLOCK = 7
#: A block holding every row: the unblocked computation.
WHOLE = 10 ** 9


def _data(name: str, n: int = 120, joint: float = 0.0):
    robot = default_robot(name)
    theta = robot.table.nominal + uniform_errors(robot, 1, 0.5, np.deg2rad(0.5))
    poses = reachable_poses(robot, n, np.random.default_rng(3), theta=theta)
    noise = SensorNoise(1e-3, 1e-6, joint=joint)
    joints = robot.inverse_kinematics(theta, poses) + noise.sample_joints(n, robot.n_chains, 4)
    measured = poses + noise.sample(n, 5, robot.pose_units)
    return robot, joints, measured, noise


def _fit(monkeypatch, rows: int, fit, *args, **kwargs):
    monkeypatch.setattr(engine, "FIT_BLOCK_ROWS", rows)
    return fit(*args, **kwargs)


def _scaled_gap(a: np.ndarray, b: np.ndarray, norms: np.ndarray) -> float:
    """``|D (a - b)| / |D b|``: the difference of two parameter vectors in the coordinates of the
    column-scaled system (``D`` its column norms), where K eps cond^2 bounds what rounding does."""
    return float(np.linalg.norm(norms * (a - b)) / np.linalg.norm(norms * b))


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("joint", [0.0, 1e-3])
def test_forward_fit_in_blocks_is_the_fit_in_one_pass(monkeypatch, name, joint):
    """Blocks of 7 rows and one block of all rows: the same iterations, theta, covariance, chi2 and
    predicted poses, to K eps cond^2 (tests/linalg_tolerance.py; cond of the column-scaled
    whitened Jacobian): the two sum the normal equations in another order, nothing else."""
    robot, joints, measured, noise = _data(name, joint=joint)
    one = _fit(monkeypatch, WHOLE, identify_forward, robot, joints, measured, noise)
    blocks = _fit(monkeypatch, SMALL_BLOCK, identify_forward, robot, joints, measured, noise)
    assert one.success and blocks.success and one.message.startswith("converged")
    assert blocks.iterations == one.iterations
    idx = robot.table.indices(one.free_names)
    J = identification_jacobian(robot, one.theta, measured - one.pose_residuals, noise, joints=joints)
    J = J.reshape(-1, J.shape[-1])
    norms = column_norms(J)
    tol = gram_inverse_tolerance(one.condition_numbers[0], idx.size)
    assert _scaled_gap(blocks.theta[idx], one.theta[idx], norms) <= tol
    assert scaled_relative_gap(blocks.covariance[np.ix_(idx, idx)], one.covariance[np.ix_(idx, idx)], norms) <= tol
    assert blocks.condition_numbers[0] == pytest.approx(one.condition_numbers[0], rel=tol)
    # chi2 ~ N D at the minimum is first-order insensitive to theta; the two stop within their
    # last steps (at most 1e-9 relative) of it, as in test_robot_contract's comparison of two fits
    assert blocks.chi2 == pytest.approx(one.chi2, rel=1e-9)
    assert np.max(np.abs(blocks.pose_residuals - one.pose_residuals)) <= 1e-9  # the poses' Newton tolerance


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("solver,weighted", [("gn", False), ("gn", True), ("lm", True)])
def test_chainwise_fit_in_blocks_is_the_fit_in_one_pass(monkeypatch, name, solver, weighted):
    """The chain-wise fit, blocks of 7 rows against one block: the same theta and covariance chain
    by chain, to K eps cond^2 of that chain's column-scaled system."""
    robot, joints, measured, noise = _data(name, joint=1e-3 if weighted else 0.0)
    kw = dict(solver=solver, weighted=weighted)
    one = _fit(monkeypatch, WHOLE, identify_chainwise, robot, joints, measured, noise, **kw)
    blocks = _fit(monkeypatch, SMALL_BLOCK, identify_chainwise, robot, joints, measured, noise, **kw)
    assert one.success and blocks.success
    idx = robot.table.indices(one.free_names)
    P = robot.closure_jacobians(one.theta, joints, measured).parameters
    for c in range(robot.n_chains):
        ix = np.intersect1d(robot.table.chain_indices(c), idx)
        norms = column_norms(P[:, c, ix])
        tol = gram_inverse_tolerance(one.condition_numbers[c], ix.size)
        assert _scaled_gap(blocks.theta[ix], one.theta[ix], norms) <= tol
        assert scaled_relative_gap(blocks.covariance[np.ix_(ix, ix)], one.covariance[np.ix_(ix, ix)], norms) <= tol
    np.testing.assert_allclose(blocks.residuals, one.residuals, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", NAMES)
def test_condition_numbers_from_block_factors_are_the_svds(monkeypatch, name):
    """Every condition number taken the exact way (GRAM_CONDITION_FLOOR raised to 1: the SVD of the
    triangular factor accumulated over blocks of 7 rows): that of the whole column-scaled system
    by numpy's SVD, to m K eps cond (m rows, K columns: Householder QR's backward error, gamma_{mK}
    (Higham Thm 19.4), which a singular value's relative error amplifies by at most cond; the
    factor's SVD does not square it as the Gram matrix's eigenvalues would)."""
    monkeypatch.setattr(engine, "GRAM_CONDITION_FLOOR", 1.0)
    robot, joints, measured, noise = _data(name)
    fwd = _fit(monkeypatch, SMALL_BLOCK, identify_forward, robot, joints, measured, noise)
    idx = robot.table.indices(fwd.free_names)
    J = identification_jacobian(robot, fwd.theta, measured - fwd.pose_residuals, noise, joints=joints)
    J = J.reshape(-1, J.shape[-1])
    cond = np.linalg.cond(J / column_norms(J))
    assert fwd.condition_numbers[0] == pytest.approx(cond, rel=idx.size * EPS * cond * len(J))
    chain = _fit(monkeypatch, SMALL_BLOCK, identify_chainwise, robot, joints, measured, noise)
    P = robot.closure_jacobians(chain.theta, joints, measured).parameters
    for c in range(robot.n_chains):
        ix = np.intersect1d(robot.table.chain_indices(c), idx)
        A = P[:, c, ix]
        cond = np.linalg.cond(A / column_norms(A))
        assert chain.condition_numbers[c] == pytest.approx(cond, rel=ix.size * EPS * cond * len(A))


@pytest.mark.parametrize("name", NAMES)
def test_chainwise_least_squares_fallback_on_block_factors_is_the_normal_equations_step(monkeypatch, name):
    """Every chain's step by the least-squares fallback (NORMAL_EQUATIONS_CONDITION 0: lstsq on the
    triangular factors of [A | b] accumulated over blocks of 7 rows) reaches the theta the normal
    equations reach, to K eps cond^2."""
    robot, joints, measured, noise = _data(name)
    normal = _fit(monkeypatch, WHOLE, identify_chainwise, robot, joints, measured, noise)
    monkeypatch.setattr(engine, "NORMAL_EQUATIONS_CONDITION", 0.0)
    fallback = _fit(monkeypatch, SMALL_BLOCK, identify_chainwise, robot, joints, measured, noise)
    assert normal.success and fallback.success
    idx = robot.table.indices(normal.free_names)
    P = robot.closure_jacobians(normal.theta, joints, measured).parameters
    for c in range(robot.n_chains):
        ix = np.intersect1d(robot.table.chain_indices(c), idx)
        tol = gram_inverse_tolerance(normal.condition_numbers[c], ix.size)
        assert _scaled_gap(fallback.theta[ix], normal.theta[ix], column_norms(P[:, c, ix])) <= tol


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("joint", [0.0, 1e-3])
def test_forward_normal_equations_three_ways_are_one_fit(monkeypatch, name, joint):
    """The forward fit's normal equations per block from the chains' ownership of their parameters
    (chain by chain products, CHAIN_PRODUCT_ROWS 0), from the block's gathered Jacobian rows
    (CHAIN_PRODUCT_ROWS above every block) and from the dense product (no ownership assumed):
    the same iterations, theta and covariance to K eps cond^2 (they sum the same products in
    another order)."""
    robot, joints, measured, noise = _data(name, joint=joint)
    monkeypatch.setattr(engine, "FIT_BLOCK_ROWS", 50)
    monkeypatch.setattr(engine, "CHAIN_PRODUCT_ROWS", 0)
    chains = identify_forward(robot, joints, measured, noise)
    monkeypatch.setattr(engine, "CHAIN_PRODUCT_ROWS", WHOLE)
    rows = identify_forward(robot, joints, measured, noise)
    monkeypatch.setattr(engine, "_chain_owners", lambda *args: None)
    dense = identify_forward(robot, joints, measured, noise)
    assert chains.message.startswith("converged")
    idx = robot.table.indices(chains.free_names)
    J = identification_jacobian(robot, chains.theta, measured - chains.pose_residuals, noise, joints=joints)
    norms = column_norms(J.reshape(-1, J.shape[-1]))
    tol = gram_inverse_tolerance(chains.condition_numbers[0], idx.size)
    for other in (rows, dense):
        assert other.iterations == chains.iterations and other.message.startswith("converged")
        assert _scaled_gap(other.theta[idx], chains.theta[idx], norms) <= tol
        assert scaled_relative_gap(other.covariance[np.ix_(idx, idx)], chains.covariance[np.ix_(idx, idx)],
                                   norms) <= tol


@pytest.mark.parametrize("name", NAMES)
def test_chain_owners_are_the_parameter_tables_chains(name):
    """Every robot's closure of chain c moves with chain c's parameters alone (what the chain-wise
    fit and the forward fit's chain products assume), those it identifies by default
    (``free_default``, all but the chain-coupled: the linear Delta's rod differences tilt the
    effector all its chains hold, and with them free the owners are None): the owners are the
    table's chains; a parameter Jacobian with one entry of another chain's parameter set gives None."""
    robot, joints, measured, _ = _data(name, n=30)
    idx = np.sort(robot.table.indices(robot.free_default + robot.gauge_fixed))
    jac = robot.closure_jacobians(robot.table.nominal, joints, measured)
    np.testing.assert_array_equal(engine._chain_owners(robot, jac, idx), robot.table.chains[idx])
    every = np.arange(robot.n_parameters)
    assert (engine._chain_owners(robot, jac, every) is None) == bool(robot.chain_coupled)
    # The dense Jacobian alone (no declared structure) shows the same owners...
    dense = ClosureJacobians(jac.pose, jac.joints, jac.parameters.copy())
    np.testing.assert_array_equal(engine._chain_owners(robot, dense, idx), robot.table.chains[idx])
    # ... and one entry of another chain's parameter set breaks them.
    other = (int(robot.table.chains[0]) + 1) % robot.n_chains
    dense.parameters[3, other, 0] = 1e-300
    assert engine._chain_owners(robot, dense, idx) is None


def test_declared_own_entries_make_the_dense_parameter_jacobian():
    """The hexapod and the 6-RUS give their closures' own entries (``ClosureJacobians.own``, the
    dense Jacobian built on first use): the own entry on each parameter's chain, zero elsewhere,
    and the fits that read ``own`` give what they give from the dense Jacobian alone (the finite
    differences of the dense Jacobian are tests/test_robot_contract.py's)."""
    for name in ("hexapod", "rus"):
        robot, joints, measured, noise = _data(name, n=30)
        jac = robot.closure_jacobians(robot.table.nominal, joints, measured)
        assert jac.own is not None, name
        np.testing.assert_array_equal(jac.chains, robot.table.chains)
        P, k = jac.parameters, np.arange(robot.n_parameters)
        np.testing.assert_array_equal(P[:, robot.table.chains, k], jac.own)
        off = np.ones(P.shape[1:], dtype=bool)
        off[robot.table.chains, k] = False
        assert not np.any(P[:, off])


@pytest.mark.parametrize("name", ("hexapod", "rus"))
def test_fits_reading_the_own_entries_equal_the_fits_on_the_dense_jacobian(name, monkeypatch):
    """The forward and chain-wise fits (and the pose Jacobians of the parameters) read the
    closures' own entries where the robot gives them: the same numbers, to the bit, as from the
    dense parameter Jacobian alone (the same entries, gathered from another array)."""
    robot, joints, measured, noise = _data(name)
    own = (identify_forward(robot, joints, measured, noise), identify_chainwise(robot, joints, measured, noise))
    original = type(robot).closure_with_jacobians

    def dense_only(self, theta, q, poses):
        r, jac = original(self, theta, q, poses)
        return r, ClosureJacobians(jac.pose, jac.joints, jac.parameters)

    monkeypatch.setattr(type(robot), "closure_with_jacobians", dense_only)
    assert robot.closure_jacobians(robot.table.nominal, joints[:3], measured[:3]).own is None
    dense = (identify_forward(robot, joints, measured, noise), identify_chainwise(robot, joints, measured, noise))
    for a, b in zip(own, dense):
        assert a.iterations == b.iterations
        np.testing.assert_array_equal(a.theta, b.theta)
        np.testing.assert_array_equal(a.covariance, b.covariance)


def test_minimise_started_as_gauss_newton_finds_minpacks_minimum():
    """calib.engine.minimise's Levenberg-Marquardt (started as Gauss-Newton) and MINPACK's
    (``cautious``) end at one minimum of a nonlinear least-squares problem started far from it
    (a decaying exponential and offset, noisy): the costs equal to rounding, the minimisers within
    what their stopping rules leave: each stops where the cost left to gain is at most ftol (1e-15)
    of it, |J dx|^2 <= ftol cost, so the two differ by at most 2 sqrt(ftol cost) / sigma_min(J)."""
    from calib.engine import minimise

    t = np.linspace(0.0, 4.0, 40)
    rng = np.random.default_rng(3)
    y = 3.0 * np.exp(-1.3 * t) + 0.5 + rng.normal(0.0, 1e-3, t.size)

    def fun(x):
        return x[0] * np.exp(-x[1] * t) + x[2] - y

    def jac(x):
        e = np.exp(-x[1] * t)
        return np.column_stack([e, -x[0] * t * e, np.ones_like(t)])

    x0 = np.array([1.0, 0.2, 0.0])
    ours, n_ours, ok_ours, _ = minimise(fun, jac, x0)
    theirs, _, ok_theirs, _ = minimise(fun, jac, x0, cautious=True)
    assert ok_ours and ok_theirs
    cost = lambda x: float(fun(x) @ fun(x))  # noqa: E731
    sigma_min = np.linalg.svd(jac(theirs), compute_uv=False)[-1]
    assert np.linalg.norm(ours - theirs) <= 2 * np.sqrt(1e-15 * cost(theirs)) / sigma_min
    # each residual rounded to eps of the values it subtracts (|y|, ~1), its square to twice that
    rounding = 8 * np.finfo(float).eps * float(np.abs(fun(theirs)) @ (np.abs(y) + 1.0))
    assert abs(cost(ours) - cost(theirs)) <= 2e-15 * cost(theirs) + rounding
    assert n_ours < 3 * 100  # within the budget: max_iter (100) times the unknowns plus one
