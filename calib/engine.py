"""The calibration engine: identification of any registered robot's parameters from measured poses.

Two methods, written once over :class:`calib.robot.Robot`:

* :func:`identify_forward`: all free parameters at once, minimising the pose residuals
  ``QM_j - FK(theta, q_j)`` through the forward kinematics, whitened by the declared noise (pose
  sensor noise plus joint noise propagated through the manipulator Jacobian), with the analytic
  Jacobian of the implicit function theorem. Gauss-Newton with the poses Newton-stepped along
  (Levenberg-Marquardt through the forward kinematics as the fallback), or Gauss-Newton through
  the forward kinematics. The Delta paper's FKM; applied to the hexapod, the "forward method".
* :func:`identify_chainwise`: each chain on its own, from the closure residuals
  ``F_i(theta_i, q_ij, QM_j)`` at the measured poses (joint space). With Gauss-Newton steps and
  the forward kinematics of the corrected model after each, stopped by the integrated pose error
  ``max_j dQint_j <= epsilon`` (hexapod paper, Eqs. 15-17), it is the hexapod paper's per-leg
  least squares with iterative compensation; with Levenberg-Marquardt per chain and residuals
  weighted by the declared noise it is the Delta paper's IKM.

Both validate their arguments (naming them) and return an :class:`IdentificationResult`, also
when they do not converge.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .batched_lu import BatchedLU, solve_stacked
from .tsqr import triangular_update
from .validation import as_array
from .noise import SensorNoise, chi2_quantile
from .prior import ParameterPrior, parameter_sources
from .robot import (
    FORWARD_KINEMATICS_TOL_MM,
    SINGULAR_CONDITION,
    ClosureJacobians,
    KinematicsError,
    Robot,
    pose_whitening,
)
from .workspace import reachable_poses

__all__ = ["IdentificationResult", "identify_forward", "identify_chainwise", "integrated_error",
           "SOLVERS", "METHODS", "identify", "noise_verdict", "gauge_representative",
           "minimise", "newton_offset"]

#: Solvers of both methods.
SOLVERS = ("lm", "gn")
#: The two identification methods by name.
METHODS = ("forward", "chainwise")


@dataclass(frozen=True, eq=False)
class IdentificationResult:
    """Outcome of an identification; returned also when it did not converge.

    Attributes:
        method: ``"forward"`` or ``"chainwise"``.
        robot: the robot identified.
        theta: (P,) identified parameter vector (fixed parameters keep their start value).
        start: (P,) the start (usually the nominal vector).
        free_names: names of the identified parameters.
        residuals: chain-wise: (N, C) closure residuals at the measured poses, mm; forward:
            (N, D) pose residuals ``measured - FK``.
        pose_residuals: (N, D) measured poses minus the poses the identified model predicts at
            the commanded joints (both methods; the paper's ``dQc``); NaN if the forward
            kinematics failed.
        covariance: (P, P) parameter covariance, zero rows/columns for fixed parameters.
            Weighted fits: implied by the declared noise, ``(J^T W J)^-1``. The unweighted
            chain-wise fit (the hexapod paper's): estimated from each chain's residuals,
            ``s^2 (J^T J)^-1``. NaN where no degree of freedom is left.
        chi2: sum of squared whitened residuals (declared noise) at the solution.
        dof: degrees of freedom of ``chi2`` (residuals minus free parameters).
        iterations: outer iterations (Gauss-Newton) or Jacobian evaluations (LM, summed).
        history: max dQint after each iteration (chain-wise GN; from the corrected poses to
            second order, one Newton step of the forward kinematics from the measured ones, and
            exact, from the forward kinematics, where a stopping rule is judged), or cost per
            evaluation (forward Gauss-Newton with the poses solved along: per iteration, at the
            poses one Newton step of the forward kinematics corrects).
        success: whether a stopping criterion was met.
        message: which criterion stopped it, in words.
        condition_numbers: column-scaled condition numbers of the identification Jacobian at
            the solution: (C,) one per chain (chain-wise) or (1,) (forward); with a prior, of the
            system with its prior rows.
        prior: the :class:`~calib.prior.ParameterPrior` of a maximum a posteriori fit, or None
            (plain least squares). With one, ``covariance`` is the posterior covariance
            ``(J^T W J + diag(1 / std^2))^-1``, ``chi2`` counts the prior rows
            ``|(theta - mean) / std|^2`` (free parameters) as observations and ``dof`` is the
            number of measurement residuals.
    """

    method: str
    robot: Robot
    theta: np.ndarray
    start: np.ndarray
    free_names: tuple
    residuals: np.ndarray
    pose_residuals: np.ndarray
    covariance: np.ndarray
    chi2: float
    dof: int
    iterations: int
    history: tuple
    success: bool
    message: str
    condition_numbers: np.ndarray
    prior: ParameterPrior | None = None

    @property
    def errors(self) -> np.ndarray:
        """(P,) identified parameters minus the robot's nominal ones."""
        return self.theta - self.robot.table.nominal

    @property
    def std(self) -> np.ndarray:
        """(P,) standard uncertainty of each parameter (0 for fixed ones)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def reduced_chi2(self) -> float:
        """``chi2 / dof``: about 1 when the model explains the data to the declared noise."""
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    def errors_by_name(self) -> dict[str, float]:
        """``{name: identified - nominal}`` of every parameter."""
        return self.robot.table.to_dict(self.errors)

    @property
    def free_indices(self) -> np.ndarray:
        """(K,) int, flat indices of the identified parameters, table order."""
        return np.sort(self.robot.table.indices(self.free_names))

    def parameter_sources(self) -> dict[str, str]:
        """``{name: source}`` of every parameter: ``"data"`` where the posterior standard deviation
        is below :data:`calib.prior.DATA_SOURCE_RATIO` (one half) of the prior's or the fit moved
        it beyond :data:`calib.prior.MOVED_BY_DATA` prior standard deviations, ``"prior"``
        where it is not (the poses left it to the tolerance), ``"held"`` for a fixed parameter.
        Without a prior every identified parameter's source is ``"data"``."""
        out = dict.fromkeys(self.robot.table.names, "held")
        idx = self.free_indices
        if self.prior is None:
            src = ["data"] * idx.size
        else:
            src = parameter_sources(self.std[idx], self.prior.std[idx], self.theta[idx] - self.prior.mean[idx])
        out.update({self.robot.table.names[i]: str(v) for i, v in zip(idx, src)})
        return out

    def directions_determined(self) -> float | None:
        """How many of the free parameters' directions the rows determine, singly or in
        combinations: MacKay's effective number of parameters ``trace(I - S^-1 Sigma_post)``
        (``S`` the prior's covariance, ``Sigma_post`` the posterior's), between 0 (the prior
        alone) and the number of free parameters. None without a prior."""
        if self.prior is None:
            return None
        idx = self.free_indices
        return float(np.sum(1.0 - np.diag(self.covariance)[idx] / self.prior.std[idx] ** 2))

    def determination(self) -> dict[str, dict]:
        """JSON-ready, per parameter: ``{name: {"value", "error", "posterior_std", "prior_std",
        "source", "unit"}}`` (parameter units; ``prior_std`` None without a prior, both stds 0 for a
        held parameter)."""
        table, std, sources = self.robot.table, self.std, self.parameter_sources()
        out = {}
        for k, name in enumerate(table.names):
            held = sources[name] == "held"
            out[name] = {"value": float(self.theta[k]), "error": float(self.errors[k]), "unit": table.units[k],
                         "posterior_std": 0.0 if held else float(std[k]),
                         "prior_std": None if self.prior is None else (0.0 if held else float(self.prior.std[k])),
                         "source": sources[name]}
        return out

    def left_to_prior(self, n_terms: int = 4) -> tuple[dict, ...]:
        """The parameter combinations the poses left to the prior, in words.

        Those along which the posterior standard deviation is at least
        :data:`calib.prior.DATA_SOURCE_RATIO` of the prior's (the data did not halve the
        tolerance): see :func:`calib.observability.combinations_left_to_prior`. Empty without a
        prior (a plain fit has none; its undetermined directions are
        :func:`calib.observability.analyze_observability`'s ``not_identifiable``)."""
        if self.prior is None:
            return ()
        from .observability import combinations_left_to_prior  # it imports this module

        idx = self.free_indices
        return combinations_left_to_prior(self.robot, self.covariance[np.ix_(idx, idx)], self.prior.std[idx],
                                          idx, n_terms=n_terms)


def integrated_error(robot: Robot, dQ: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The hexapod paper's position, orientation and integrated errors for any robot.

    Args:
        robot: the robot (its pose units say which coordinates are positions and angles).
        dQ: (N, D) pose errors.

    Returns:
        ``(dQ1, dQ2, dQint)``, each (N,): norm of the position errors (mm, Eq. 15), norm of the
        angle errors (rad, Eq. 16, zero for a translating platform) and their plain sum (Eq. 17,
        mixing units as the paper does; used only for its stopping rule).
    """
    angle = robot.angle_pose_mask
    dQ1 = np.linalg.norm(dQ[:, ~angle], axis=1)
    dQ2 = np.linalg.norm(dQ[:, angle], axis=1)
    return dQ1, dQ2, dQ1 + dQ2


# --------------------------------------------------------------------------- front end


def _check(robot, joints, measured, noise, free, start, solver):
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be a calib.robot.Robot, got {type(robot).__name__}")
    if not isinstance(noise, SensorNoise):
        raise TypeError(f"noise must be a SensorNoise, got {type(noise).__name__}")
    joints = as_array(joints, "joints", (-1, robot.n_chains))
    measured = as_array(measured, "measured", (-1, robot.pose_dim))
    if joints.shape[0] != measured.shape[0]:
        raise ValueError(f"joints and measured must have the same number of rows, got "
                         f"{joints.shape[0]} and {measured.shape[0]}")
    free = robot.free_default if free is None else tuple(free)
    if not free or len(set(free)) != len(free):
        raise ValueError(f"free must be a non-empty list of distinct parameter names, got {free}")
    idx = robot.table.indices(free)  # KeyError names an unknown one
    start = robot.table.nominal.copy() if start is None else as_array(start, "start", (robot.n_parameters,)).copy()
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    return joints, measured, free, np.sort(idx), start


def _prior_rows(robot: Robot, prior, idx: np.ndarray):
    """The free parameters' prior rows: ``(mean (K,), 1 / std (K,))`` (the whitened row of
    parameter k is ``(theta_k - mean_k) / std_k``), or None without a prior."""
    if prior is None:
        return None
    if not isinstance(prior, ParameterPrior):
        raise TypeError(f"prior must be a calib.prior.ParameterPrior or None, got {type(prior).__name__}")
    prior.check(robot)
    return prior.mean[idx], 1.0 / prior.std[idx]


def _refuse_empty(n: int) -> None:
    """With a prior any pose set is accepted but none at all: the answer would be the prior alone."""
    if n == 0:
        raise ValueError("measured has no rows: the data determine nothing, and the prior alone is no calibration")


def _closure_std(robot: Robot, jac, noise: SensorNoise) -> np.ndarray:
    """(N, C) standard deviation of each closure residual from the declared noise, given the
    closure's :class:`~calib.robot.ClosureJacobians` at the residuals' configurations."""
    std = noise.pose_std(robot.pose_units)
    var = np.einsum("ncd,ncd,d->nc", jac.pose, jac.pose, std ** 2)
    if noise.joint_std > 0:
        var += noise.joint_std ** 2 * np.einsum("ncq,ncq->nc", jac.joints, jac.joints)
    return np.sqrt(var)


#: Smallest eigenvalue, relative to the largest, of a column-scaled Gram matrix ``As^T As``
#: whose square-root ratio is taken as the condition number of ``As``; below it (a condition
#: number above 1e5, where the Gram matrix's eigenvalues lose their digits) the SVD of ``As`` is used.
GRAM_CONDITION_FLOOR = 1e-10


def _covariance_and_conditions(A, gram: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(pinv(A^T A), cond(A scaled))`` of each matrix of a stack ``A`` (M, N, K): (M, K, K) and (M,).

    The column-scaled Gram matrix ``Gs = D^-1 A^T A D^-1`` (``D`` the column norms; ``gram``
    (M, K, K) is ``A^T A`` when the caller has it) gives both: its eigenvalues the column-scaled
    condition number ``sqrt(lambda_max / lambda_min)``, and ``pinv(A^T A) = D^-1 pinv(Gs) D^-1``
    with eigenvalues below ``1e-15`` of the largest dropped, as ``numpy.linalg.pinv(hermitian=True)``
    does (the plain inverse where none is: the same matrix, without the eigenvectors). The SVD
    of ``A D^-1`` only where the eigenvalue ratio is beyond :data:`GRAM_CONDITION_FLOOR`. A zero
    column: condition number inf, variance 0 for its parameter.

    With ``gram`` given, ``A`` may instead be a callable that takes a boolean mask (M,) and returns
    those matrices of the stack, or any (m, N', K) stack with the same Gram matrices (their
    triangular factors, :func:`triangular_update`): it is called only where the SVD is needed, so
    a fit that accumulated its normal equations block by block never forms the whole ``A``."""
    m, n, k = (gram.shape[0], None, gram.shape[-1]) if callable(A) else A.shape
    if n == 0 or k == 0:
        return np.zeros((m, k, k)), np.full(m, np.inf)
    norms = np.sqrt(np.einsum("mnk,mnk->mk", A, A) if gram is None else np.diagonal(gram, axis1=1, axis2=2))
    zero = np.any(norms == 0, axis=1)
    s = np.where(norms == 0, 1.0, norms)
    if gram is None:
        As = A / s[:, None, :]
        Gs = np.swapaxes(As, 1, 2) @ As
    else:
        Gs = gram / (s[:, :, None] * s[:, None, :])
    lam = np.linalg.eigvalsh(Gs)  # ascending
    top = lam[:, -1]
    full = lam[:, 0] > 1e-15 * top
    cov = np.empty_like(Gs)
    if np.all(full):
        cov[:] = np.linalg.inv(Gs)
    else:
        if np.any(full):
            cov[full] = np.linalg.inv(Gs[full])
        lam_d, V = np.linalg.eigh(Gs[~full])
        keep = lam_d > 1e-15 * lam_d[:, -1:]
        inverse = np.where(keep, 1.0 / np.where(keep, lam_d, 1.0), 0.0)
        cov[~full] = (V * inverse[:, None, :]) @ np.swapaxes(V, 1, 2)
    cov /= s[:, :, None] * s[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = np.sqrt(top / lam[:, 0])
    exact = ~(lam[:, 0] > GRAM_CONDITION_FLOOR * top) & ~zero
    if np.any(exact):
        B = A(exact) if callable(A) else A[exact]
        cond[exact] = np.linalg.cond(B / s[exact][:, None, :])
    return cov, np.where(zero, np.inf, cond)


#: Rows (poses) the identification evaluates at a time. Each Gauss-Newton evaluation runs over
#: the rows block by block: the closure and its Jacobians of one block, its whitened Jacobian and
#: that block's share of the normal equations ``J^T J`` and ``J^T r``, then the next block. The
#: whole Jacobian ((N D, K) for the forward fit, 2 GB at a million hexapod poses) is never held,
#: and a block's temporaries (about 3 MB for the hexapod) stay in cache and in memory already
#: paged in. The results do not depend on it beyond rounding (sums taken in another order).
FIT_BLOCK_ROWS = 2048


def _row_blocks(n: int) -> list[slice]:
    """Slices of :data:`FIT_BLOCK_ROWS` consecutive rows (the last one shorter) covering N rows."""
    step = max(1, int(FIT_BLOCK_ROWS))
    return [slice(a, min(a + step, n)) for a in range(0, n, step)]


def _chain_groups(robot: Robot, idx: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The chains that have free parameters, grouped by how many: ``[(chains (M,), params (M, K))]``,
    so that each group is handled as one stack of M problems of K unknowns."""
    owner = robot.table.chains[idx]
    groups: dict[int, list[tuple[int, np.ndarray]]] = {}
    for c in range(robot.n_chains):
        ix = idx[owner == c]
        if ix.size:
            groups.setdefault(ix.size, []).append((c, ix))
    return [(np.array([c for c, _ in g]), np.array([ix for _, ix in g])) for g in groups.values()]


def _chain_systems(jac: ClosureJacobians, r: np.ndarray, w: np.ndarray | None, chains: np.ndarray,
                   params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The weighted chain-wise systems of one group: ``A`` (M, N, K) C-ordered, one chain's
    ``J[:, c, ix] * w[:, c, None]`` per slice (``J`` the closure's parameter Jacobian, gathered
    from its own entries where the robot gives them), and ``b`` (M, N), ``r[:, c] * w[:, c]``
    (``w`` None: unweighted)."""
    if jac.own is not None and np.array_equal(jac.chains[params], np.broadcast_to(chains[:, None], params.shape)):
        A = jac.own[:, params]  # (N, M, K), a copy: chain m's closure by its own parameters
    else:
        A = jac.parameters[:, chains[:, None], params]  # (N, M, K), a copy
    A = np.ascontiguousarray(np.moveaxis(A, 1, 0) if w is None else np.moveaxis(A * w[:, chains, None], 1, 0))
    b = r[:, chains].T if w is None else (r[:, chains] * w[:, chains]).T
    return A, b


#: Column-scaled condition number of a chain's system beyond which its step is taken by LAPACK's
#: SVD-based least squares (minimum norm on a rank-deficient chain) instead of the normal equations.
NORMAL_EQUATIONS_CONDITION = 1e6


def _chain_steps(gram: np.ndarray, g: np.ndarray, prior=None, factors=None) -> np.ndarray:
    """(M, K) least-squares steps ``argmin |A_m x + b_m|`` of a stack of chain systems, from their
    normal equations (``gram`` (M, K, K) ``A^T A`` and ``g`` (M, K) ``A^T b``, accumulated over the
    rows), in one batched solve of the column-scaled normal equations; a stack with a chain whose
    (Cholesky-estimated) column-scaled condition number exceeds :data:`NORMAL_EQUATIONS_CONDITION`
    (or is rank deficient) is solved chain by chain by ``numpy.linalg.lstsq`` instead (the normal
    equations square the condition number), on the triangular factors ``factors()`` returns
    ((M, *, K + 1): of each ``[A | b]``, :func:`_chain_factors`; the same least-squares
    solutions, minimum norm on a rank-deficient chain).

    ``prior``: ``(inv_std (M, K), e (M, K))``, each chain's prior rows ``diag(inv_std) x + e``
    appended to its system (``e`` the whitened prior residual at the current vector), or None."""
    normal = gram if prior is None else gram + _diagonal_stack(prior[0] ** 2)
    norms = np.sqrt(np.diagonal(normal, axis1=1, axis2=2))
    if np.all(norms > 0):
        G = normal / (norms[:, :, None] * norms[:, None, :])
        if prior is not None:
            g = g + prior[0] * prior[1]
        g = g / norms
        try:
            d = np.diagonal(np.linalg.cholesky(G), axis1=1, axis2=2)
            if np.all(d.max(axis=1) <= NORMAL_EQUATIONS_CONDITION * d.min(axis=1)):
                return -np.linalg.solve(G, g[..., None])[..., 0] / norms
        except np.linalg.LinAlgError:
            pass
    R = factors()
    A, b = R[..., :-1], R[..., -1]
    if prior is not None:
        A, b = _with_prior_rows(A, prior[0]), np.concatenate([b, prior[1]], axis=1)
    return np.array([np.linalg.lstsq(A[k], -b[k], rcond=None)[0] for k in range(A.shape[0])])


@dataclass
class _ChainEvaluation:
    """The chain-wise fit at one vector, evaluated block by block over the rows: the closure ``r``
    (N, C) at the measured poses, ``offset`` (N, D) one Newton step of the forward kinematics
    from them (:func:`newton_offset`), ``systems`` per chain group ``(A^T A (M, K, K), A^T b (M,
    K))`` of the (weighted) chain systems (:func:`_chain_systems`), and ``std`` (N, C) the
    closure residuals' standard deviations from the declared noise (None: none asked for)."""

    r: np.ndarray
    offset: np.ndarray
    systems: list
    std: np.ndarray | None


def _chain_evaluation(robot, theta, joints, measured, groups, w, noise=None) -> _ChainEvaluation:
    """The :class:`_ChainEvaluation` at ``theta``: one closure-and-Jacobians call per block of
    :data:`FIT_BLOCK_ROWS` rows, the blocks' chain systems summed into their normal equations.
    ``w`` (N, C) weights or None; ``noise`` the declared noise whose closure std to keep, or None."""
    n, c = joints.shape
    r, offset = np.empty((n, c)), np.empty(measured.shape)
    std = None if noise is None else np.empty((n, c))
    systems = [(np.zeros((len(chains), params.shape[1], params.shape[1])), np.zeros(params.shape))
               for chains, params in groups]
    for rows in _row_blocks(n):
        rb, jac = robot.closure_with_jacobians(theta, joints[rows], measured[rows])
        r[rows] = rb
        offset[rows] = newton_offset(jac.pose, rb)
        if std is not None:
            std[rows] = _closure_std(robot, jac, noise)
        for (chains, params), (gram, g) in zip(groups, systems):
            A, b = _chain_systems(jac, rb, None if w is None else w[rows], chains, params)
            gram += np.swapaxes(A, 1, 2) @ A
            g += np.einsum("mnk,mn->mk", A, b)
    return _ChainEvaluation(r, offset, systems, std)


def _chain_factors(robot, theta, joints, measured, chains, params, w) -> np.ndarray:
    """(M, K + 1, K + 1) (fewer rows when N <= K) triangular factors of each chain's ``[A | b]``
    of one group at ``theta``, accumulated block by block (:func:`triangular_update`): what the
    least-squares fallback of :func:`_chain_steps` and the exact condition numbers of an
    ill-conditioned chain need, without the (N, K) systems."""
    R = None
    for rows in _row_blocks(joints.shape[0]):
        rb, jac = robot.closure_with_jacobians(theta, joints[rows], measured[rows])
        A, b = _chain_systems(jac, rb, None if w is None else w[rows], chains, params)
        R = triangular_update(R, np.concatenate([A, b[:, :, None]], axis=2))
    return R


def _diagonal_stack(d: np.ndarray) -> np.ndarray:
    """(M, K, K) diagonal matrices of the rows of ``d`` (M, K)."""
    out = np.zeros(d.shape + d.shape[-1:])
    k = np.arange(d.shape[-1])
    out[:, k, k] = d
    return out


def _with_prior_rows(A: np.ndarray, inv_std: np.ndarray) -> np.ndarray:
    """(M, N + K, K) the stack of systems ``A`` (M, N, K) with the prior rows ``diag(inv_std[m])``
    (``inv_std`` (M, K)) below each."""
    return np.concatenate([A, _diagonal_stack(inv_std)], axis=1)


def _gauss_newton(fun, jac, x0, max_iter, xtol):
    """Plain Gauss-Newton with a relative step test; returns (x, iterations, success, message)."""
    x = x0.copy()
    for it in range(1, max_iter + 1):
        step = np.linalg.lstsq(jac(x), -fun(x), rcond=None)[0]
        x = x + step
        if not np.all(np.isfinite(x)):
            return x - step, it, False, "Gauss-Newton diverged (non-finite step)"
        if np.linalg.norm(step) <= max(xtol, 1e-12) * (1e-12 + np.linalg.norm(x)):
            return x, it, True, f"Gauss-Newton step below xtol = {xtol:g}"
    return x, max_iter, False, f"Gauss-Newton: no convergence in {max_iter} iterations"


#: Relative scaled step, taken and well predicted, after which :func:`_levenberg_marquardt` stops.
_CONVERGED_STEP = 1e-9


def _levenberg_marquardt(fun, jac, x0, max_iter, xtol, ftol, fixed_scale=None, max_fev=None):
    """Levenberg-Marquardt (Marquardt's scaling by the diagonal of ``J^T J``, Nielsen's damping
    update, started and kept near Gauss-Newton while steps succeed) on a small dense problem: one Jacobian and one ``(K, K)`` solve per iteration and no
    call-back layer, the fast path of :func:`identify_forward`. Stops when both the actual and
    the predicted reductions of the cost are at most ``ftol`` relative, when the scaled step is
    at most ``xtol`` relative, or when a step the model predicts to help no longer lowers the
    cost at rounding level (``1e-13`` relative: the minimum to machine precision). A trial
    point the robot cannot evaluate (``KinematicsError``) is rejected like a step that raises
    the cost. Returns ``(x, Jacobian evaluations, success, message)``. ``fixed_scale`` (K,): a
    fixed scaling instead of Marquardt's (a prior's inverse standard deviations: the damping is
    then negligible against every direction's curvature, the prior's at least, while steps are
    taken, however ill-conditioned the data leave the columns). ``max_fev``: a budget of residual
    evaluations besides the ``max_iter`` Jacobians (None: none)."""
    x = np.array(x0, dtype=float)
    f = fun(x)
    cost = float(f @ f)
    J = jac(x)
    njev = nfev = 1
    max_fev = np.inf if max_fev is None else max_fev
    A, g = J.T @ J, J.T @ f
    scale = np.sqrt(np.diag(A)).copy() if fixed_scale is None else np.array(fixed_scale, dtype=float)
    scale[scale == 0] = 1.0
    mu, nu = 1e-10, 2.0  # start as Gauss-Newton: these fits are nearly linear
    while True:
        if fixed_scale is None:
            scale = np.maximum(scale, np.sqrt(np.diag(A)))  # MINPACK keeps the largest seen
        D2 = scale ** 2
        try:
            dx = np.linalg.solve(A + mu * np.diag(D2), -g)
        except np.linalg.LinAlgError:
            return x, njev, False, "Levenberg-Marquardt: singular normal equations"
        pred = -float(2.0 * (g @ dx) + dx @ (A @ dx))
        step = float(np.linalg.norm(scale * dx))
        size = float(np.linalg.norm(scale * x))
        if step <= xtol * (size + xtol):
            return x, njev, True, f"the scaled step is below xtol = {xtol:g}"
        if pred <= 0.0:
            return x, njev, True, "no step reduces the cost any further (at the minimum to machine precision)"
        if nfev >= max_fev:
            return x, njev, False, f"Levenberg-Marquardt: {max_fev} residual evaluations reached"
        x_new = x + dx
        nfev += 1
        try:
            f_new = fun(x_new)
            cost_new = float(f_new @ f_new)
        except KinematicsError:
            cost_new = np.inf
        actual = cost - cost_new
        if np.isfinite(cost_new) and actual > 0:
            rho = actual / pred
            x, f, cost_old, cost = x_new, f_new, cost, cost_new
            if actual <= ftol * cost_old and pred <= ftol * cost_old:
                return x, njev, True, f"both actual and predicted relative reductions are below ftol = {ftol:g}"
            if rho > 0.5 and step <= _CONVERGED_STEP * size:
                # A full-size step of 1e-9 relative that the model predicted well: the next
                # would be (quadratically, or at the linear rate of a small-residual fit) at
                # rounding level.
                return x, njev, True, f"converged: the last step was {step / size:.1e} relative"
            if njev >= max_iter:
                return x, njev, False, f"Levenberg-Marquardt: {max_iter} Jacobian evaluations reached"
            J = jac(x)
            njev += 1
            A, g = J.T @ J, J.T @ f
            mu *= max(0.1, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
        else:
            if step <= 1e-13 * size or (np.isfinite(cost_new) and abs(actual) <= 1e-13 * cost):
                return x, njev, True, "the cost is at its minimum to machine precision"
            if nu > 1e12:
                return x, njev, False, "Levenberg-Marquardt: no step lowers the cost"
            mu = max(mu, 1e-4) * nu
            nu *= 2.0


#: Residual entry returned to MINPACK's Levenberg-Marquardt for a trial point the robot cannot
#: evaluate (out of reach, singular, impossible geometry): far above any real residual, so the step
#: is rejected and the trust region shrinks, as for a step that increases the cost.
_REJECTED_RESIDUAL = 1e100


def _least_squares(fun, jac, x0, solver, max_iter, xtol, ftol, history, cautious=False):
    """Run a solver; returns (x, iterations, success, message); never raises on a kinematics
    failure: Levenberg-Marquardt (:func:`_levenberg_marquardt`, or MINPACK's when ``cautious``;
    a budget of ``max_iter`` times the unknowns plus one residual evaluations) rejects a trial
    point the robot cannot evaluate (the start itself failing ends the fit, which returns the
    start), Gauss-Newton stops there."""
    size = {}

    def logged(x):
        f = fun(x)
        history.append(0.5 * float(f @ f))
        size["m"] = f.size
        return f

    def guarded(x):
        try:
            return logged(x)
        except KinematicsError:
            if "m" not in size:  # the start: nothing to fall back on
                raise
            return np.full(size["m"], _REJECTED_RESIDUAL)

    budget = max_iter * (x0.size + 1)
    try:
        if solver == "gn":
            return _gauss_newton(logged, jac, x0, max_iter, xtol)
        if not cautious:
            return _levenberg_marquardt(logged, jac, x0, budget, xtol, ftol, max_fev=budget)
        from scipy.optimize import least_squares  # imported here: ~0.3 s the default run never needs

        sol = least_squares(guarded, x0, jac=jac, method="lm", xtol=xtol, ftol=ftol, gtol=1e-15,
                            max_nfev=budget, x_scale="jac")
        return sol.x, int(sol.njev or sol.nfev), bool(sol.success), str(sol.message)
    except (KinematicsError, np.linalg.LinAlgError) as exc:
        return x0, 0, False, f"the fit left the workspace: {exc}"


def minimise(fun, jac, x0, *, solver: str = "lm", max_iter: int = 100, xtol: float = 1e-15,
             ftol: float = 1e-15, history: list | None = None, cautious: bool = False):
    """The engine's least-squares solver for any residual ``fun(x)`` with Jacobian ``jac(x)``
    (used by :mod:`calib.measurement`): Levenberg-Marquardt or Gauss-Newton.

    Levenberg-Marquardt is :func:`_levenberg_marquardt`, started as Gauss-Newton (a fit from a
    start far from its minimum takes the Gauss-Newton steps at once: 4 to 5 Jacobians where
    MINPACK's trust region, started at 100 in its Jacobian-scaled units, grows for ten); with
    ``cautious``, MINPACK's (scipy.optimize.least_squares): from a start that is already a minimum
    along the well-determined combinations, its small first trust region moves the barely
    determined ones only as far as steps that lower the cost lead, not the whole Gauss-Newton step
    at once. Either has a budget of ``max_iter`` times the unknowns plus one residual evaluations.

    Returns:
        ``(x, iterations, success, message)``; ``history`` (if given) gets the cost of each
        evaluation. A kinematics failure returns the start with ``success`` False.
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    return _least_squares(fun, jac, np.asarray(x0, dtype=float), solver, max_iter, xtol, ftol,
                          [] if history is None else history, cautious)


def _predicted(robot, theta, joints, measured) -> np.ndarray:
    try:
        return robot.forward_kinematics(theta, joints, initial=measured)
    except KinematicsError:
        return np.full(measured.shape, np.nan)


# --------------------------------------------------------------------------- forward


def _start_poses(robot, theta0, joints, measured) -> np.ndarray:
    """(N, D) the start model's forward kinematics from the measured poses; ValueError naming
    the row it cannot reach."""
    try:
        return robot.forward_kinematics(theta0, joints, initial=measured)
    except KinematicsError as exc:
        raise ValueError(f"joints: the start model cannot reach row {exc.index}: {exc}") from None


#: Relative scaled parameter step (as :data:`_CONVERGED_STEP` measures it) above which the next
#: iteration of :func:`_simultaneous_newton` first predicts its poses at the new parameters (a
#: chord step from the poses the last Jacobian was taken at, with that iteration's inverse pose
#: Jacobians: the closure alone is evaluated again). Below it the last iteration's poses are as good a start:
#: they are off by the step's effect, about this fraction, and so is a Jacobian taken there.
#: Measured (hexapod, Delta, 6-RUS at 100 to 10,000 poses, with and without joint noise): the
#: iteration counts of the Gauss-Newton that stored its Jacobian and predicted the poses to first
#: order from it; at 1e-5, one more iteration in a few of those fits.
POSE_PREDICTION_STEP = 1e-7

#: Steps of :func:`_simultaneous_newton` before it gives the fit over to Levenberg-Marquardt.
SIMULTANEOUS_NEWTON_STEPS = 12


#: Rows of the first block on which :func:`_chain_owners` looks for a closure moved by another
#: chain's parameter (a structural dependence shows at any generic configuration).
OWNERS_CHECK_ROWS = 256


def _chain_owners(robot, jac: ClosureJacobians, idx: np.ndarray) -> np.ndarray | None:
    """(K,) the chain each free parameter ``idx`` belongs to (``robot.table.chains``), where the
    closure Jacobians ``jac`` of some rows declare (``own``) or show (the dense (B, C, P)
    ``parameters``) each chain's closure moved by its own parameters alone (every other entry
    exactly zero: what the chain-wise fit assumes); else None (a robot whose closures share
    parameters: the forward fit then takes the dense product)."""
    owners = np.asarray(robot.table.chains)[idx]
    if jac.own_for(robot.table.chains) is not None:
        return owners
    parameters = jac.parameters
    others = np.ones((parameters.shape[1], idx.size), dtype=bool)
    others[owners, np.arange(idx.size)] = False
    chains, columns = np.nonzero(others)
    return None if np.any(parameters[:OWNERS_CHECK_ROWS, chains, idx[columns]]) else owners


#: Rows of a block from which :func:`_forward_normal_equations` takes the chain-by-chain products
#: (fewer calls pay below it: the (D B, K) rows of the block and one Gram product).
CHAIN_PRODUCT_ROWS = 512


def _forward_normal_equations(columns: np.ndarray, jac: ClosureJacobians, e: np.ndarray, idx: np.ndarray,
                              owners: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """``(J^T J (K, K), J^T e (K,))`` of a block of B rows of the whitened forward residual, its
    Jacobian ``J = W M dF/dtheta`` not formed: ``columns`` (C, D, B) the whitened inverse pose
    Jacobians column by column (``columns[c, :, n]`` column c of ``W_n M_n``), ``jac`` the
    block's closure Jacobians (``dF/dtheta`` (B, C, P) its ``parameters``, or its ``own`` entries),
    ``e`` (B, D) the whitened residual.

    With ``owners`` (:func:`_chain_owners`) parameter k moves closure ``owners[k]`` alone, by
    ``v[n, k]``: row n's share of ``J^T J`` is ``(v v^T) * S[owners][:, owners]`` with ``S =
    (W M)^T (W M)`` (C, C), so ``J^T J`` is, chain by chain, ``V_a^T (S[a, owners] * V)`` (one (7,
    B) by (B, K) product per chain: a third of the (D B, K) Gram product's work), and ``J^T e``
    is ``v`` times ``(W M)^T e`` (C,) at the owner (blocks of :data:`CHAIN_PRODUCT_ROWS` rows
    or more; a smaller one forms its (D B, K) rows, one gathered column of ``W M`` times ``v``
    each). None: the (D B, K) Jacobian of the block, formed densely."""
    k = idx.size
    if owners is None:
        jt = np.einsum("cin,nck->kin", columns, jac.parameters[:, :, idx]).reshape(k, -1)
        return jt @ jt.T, jt @ e.T.ravel()
    # (K, B): each free parameter's entry in its own chain's closure
    vt = np.ascontiguousarray((jac.parameters[:, owners, idx] if jac.own is None else jac.own[:, idx]).T)
    if columns.shape[2] < CHAIN_PRODUCT_ROWS:  # few rows: the Jacobian's rows, three calls
        jt = np.take(columns, owners, axis=0)  # (K, D, B)
        jt *= vt[:, None, :]
        jt = jt.reshape(k, -1)
        return jt @ jt.T, jt @ e.T.ravel()
    S = np.einsum("ain,bin->abn", columns, columns)  # (C, C, B)
    g = np.einsum("cin,ni->cn", columns, e)  # (C, B): (W M)^T e
    gram = np.empty((k, k))
    scaled = np.empty_like(vt)
    for a in np.unique(owners):
        mine = owners == a
        np.take(S[a], owners, axis=0, out=scaled, mode="clip")  # owners are in range: no buffered copy
        scaled *= vt
        gram[mine] = vt[mine] @ scaled.T
    return gram, np.einsum("kn,kn->k", vt, g[owners])


def _newton_pass(robot, theta, joints, measured, p, idx, white, white_columns, newton, structure, inverses,
                 predict, final):
    """One evaluation of :func:`_simultaneous_newton` at ``theta``, block by block over the rows
    (:data:`FIT_BLOCK_ROWS`), from the poses ``p`` (N, D): with ``predict``, first a chord step
    of the poses at ``theta`` (the closure alone, with the last pass's inverse pose Jacobians
    ``inverses``; ``p`` is overwritten with its result); then the closure and its Jacobians at
    ``p`` (one call), the pose Jacobians factored once (:class:`~calib.batched_lu.BatchedLU`,
    ``M = (dF/dpose)^-1``) and a Newton step, written to ``newton`` (N, D); ``inverses`` (a
    list, one (C, D, B) array a block) then holds this pass's ``M``. Returns ``(J^T J (K, K), J^T e (K,), |e|^2, largest,
    regular)``: the normal equations of the whitened residual ``e`` of the ``newton`` poses and
    its Jacobian ``J = W M dF/dtheta`` at ``p`` (:func:`_forward_normal_equations`, block by
    block; never formed), the largest closure residual at ``p`` (mm, before the Newton step),
    and whether every pose Jacobian's Frobenius condition bound is below
    :data:`SINGULAR_CONDITION` (looked at only where ``final``, the pass where the fit may stop;
    else True).
    ``structure``: a list, empty on the first pass of a fit (then the first block's
    :func:`_chain_owners` is put in it)."""
    k = idx.size
    column_scale = 1.0 / robot.pose_scale()
    gram, gradient = np.zeros((k, k)), np.zeros(k)
    squares, largest, regular = 0.0, 0.0, True
    for block, rows in enumerate(_row_blocks(p.shape[0])):
        q = joints[rows]
        if predict:  # a chord step at theta with the last pass's inverse pose Jacobians
            r = robot.closure(theta, q, p[rows])
            p[rows] -= np.einsum("cin,nc->ni", inverses[block], r)
        r, jac = robot.closure_with_jacobians(theta, q, p[rows])
        if not structure:
            structure.append(_chain_owners(robot, jac, idx))
        factors = BatchedLU(jac.pose, inverse=True)
        np.subtract(p[rows], factors.solve(r), out=newton[rows])
        largest = max(largest, float(np.max(np.abs(r))))
        e = white(measured[rows] - newton[rows], rows)  # (B, D)
        inverse = factors.inverse_columns()  # (C, D, B): inverse[c, i] entry (i, c) of each M
        if block < len(inverses):
            inverses[block] = inverse
        else:
            inverses.append(inverse)
        if final:
            condition_bound = np.sqrt(np.einsum("nij,nij,j->n", jac.pose, jac.pose, column_scale ** 2)
                                      * np.einsum("jin,jin,i->n", inverse, inverse, column_scale ** -2))  # >= cond_2
            regular = regular and bool(np.all(condition_bound < SINGULAR_CONDITION))
        block_gram, block_gradient = _forward_normal_equations(white_columns(inverse, rows), jac, e,
                                                               idx, structure[0])
        gram += block_gram
        gradient += block_gradient
        squares += float(np.vdot(e, e))
    return gram, gradient, squares, largest, regular


def _simultaneous_newton(robot, joints, measured, theta0, idx, white, white_columns, poses0, prior_rows=None):
    """Gauss-Newton on the parameters with the forward kinematics solved along (the fast path of
    :func:`identify_forward`).

    At ``(theta, p)`` one call gives the closure ``F`` and its Jacobians; with ``M = (dF/dpose)^-1``
    the poses the model reaches are, to first order in the closure and the parameter step,
    ``p - M F - M (dF/dtheta) dtheta``: the Gauss-Newton step of the forward residual takes that
    linearisation (the residual of the Newton poses ``p - M F``, the Jacobian ``-M dF/dtheta``),
    and the next poses are that prediction. The prediction is not taken from a stored Jacobian
    (it would be the whole (N D, K) one): after a step above :data:`POSE_PREDICTION_STEP` the
    next iteration re-evaluates it, a chord step at the new parameters from the same ``p`` with
    the same ``M`` (``p - M F(theta + dtheta, p)``, the same to first order; the (N, C, D)
    inverses are kept from pass to pass, a seventh of the Jacobian); after a smaller one it
    starts from the Newton poses, except where it may stop (the last step at most ``1e-9`` of the
    scaled parameters): it predicts them then too, so that its Jacobian and normal equations
    are those at the forward kinematics to second order. Each iteration is one pass over the
    rows (:func:`_newton_pass`, block by block: the normal equations ``J^T J``, ``J^T e`` are
    accumulated, the (N D, K) Jacobian is never held). It stops where the last step taken was at
    most ``1e-9`` of the scaled parameters, every closure residual at the predicted poses is at
    most :data:`FORWARD_KINEMATICS_TOL_MM` (the Newton poses are then the forward kinematics to
    its own tolerance) and the pose Jacobians are well conditioned (Frobenius bound below
    :data:`SINGULAR_CONDITION`); the step it computed there is not taken.
    ``prior_rows`` (:func:`_prior_rows`, or None) adds the prior's rows to the cost and the
    normal equations.

    Returns ``(theta (P,), poses (N, D), J^T J (K, K) of the whitened residual Jacobian at them
    (measurement rows alone), iterations, costs (0.5 |whitened residual of the Newton-corrected
    poses|^2 per iteration), message)``, or, where it cannot vouch for the answer (a step that
    raised the cost, a singular or non-finite evaluation, no convergence in
    :data:`SIMULTANEOUS_NEWTON_STEPS`), why, in words: the caller then runs Levenberg-Marquardt
    through the forward kinematics.
    """
    theta, p = theta0.copy(), np.array(poses0, dtype=float)
    newton = np.empty_like(p)
    structure: list = []  # the parameters' chains, from the first block (_chain_owners)
    inverses: list = []  # the last pass's inverse pose Jacobians, block by block ((C, D, B) each)
    # The cost's rounding level: each whitened residual is a difference of poses of the size of
    # the measured ones, so it carries an error of about eps |measured| w; a rise below this is no rise.
    rounding = 0.5 * measured.size * (np.finfo(float).eps * float(np.max(np.abs(white(np.abs(measured)))))) ** 2
    history: list[float] = []
    converged, relative = False, np.inf
    with np.errstate(all="ignore"):
        for it in range(SIMULTANEOUS_NEWTON_STEPS + 1):
            try:
                gram, gradient, squares, largest, regular = _newton_pass(
                    robot, theta, joints, measured, p, idx, white, white_columns, newton, structure, inverses,
                    converged or POSE_PREDICTION_STEP < relative < np.inf, converged)
            except (KinematicsError, np.linalg.LinAlgError) as exc:
                return f"a singular or impossible configuration at iteration {it}: {exc}"
            cost = 0.5 * squares
            if prior_rows is not None:
                e_prior = (theta[idx] - prior_rows[0]) * prior_rows[1]
                cost += 0.5 * float(e_prior @ e_prior)
            if not np.isfinite(cost):
                return f"a non-finite residual at iteration {it}"
            if history and cost > history[-1] * (1.0 + 1e-8) + rounding:
                return f"the step of iteration {it} raised the cost"
            history.append(cost)
            normal = gram
            if prior_rows is not None:
                normal = gram + np.diag(prior_rows[1] ** 2)
                gradient = gradient + prior_rows[1] * e_prior
            scale = np.sqrt(np.diag(normal))
            scale[scale == 0] = 1.0
            try:
                dx = -np.linalg.solve(normal / scale / scale[:, None], gradient / scale) / scale
            except np.linalg.LinAlgError:
                return "singular normal equations"
            if converged and largest <= FORWARD_KINEMATICS_TOL_MM:
                if not regular:
                    return "a near-singular configuration at the solution"
                return theta, newton, gram, it, history, f"converged: the last step was {relative:.1e} relative"
            if it == SIMULTANEOUS_NEWTON_STEPS:
                return f"no convergence in {it} iterations"
            theta[idx] += dx
            relative = float(np.linalg.norm(scale * dx) / np.linalg.norm(scale * theta[idx]))
            if not POSE_PREDICTION_STEP < relative:  # else the next pass predicts from p
                p, newton = newton, p  # the next iteration starts from this one's Newton poses
            converged = relative <= _CONVERGED_STEP
    return "no convergence"


def _forward_factor(robot, theta, joints, poses, idx, white_jac) -> np.ndarray:
    """(K, K) triangular factor of the whitened forward residual Jacobian at ``(theta, poses)``
    (poses the model reaches), accumulated block by block (:func:`triangular_update`): for the
    exact condition number of an ill-conditioned fit without the (N D, K) Jacobian."""
    R = None
    for rows in _row_blocks(poses.shape[0]):
        jac = robot.closure_jacobians(theta, joints[rows], poses[rows])
        R = triangular_update(R, white_jac(solve_stacked(jac.pose, jac.parameters[:, :, idx]), rows))
    return R


def identify_forward(robot: Robot, joints, measured, noise: SensorNoise, *, free=None, start=None,
                     solver: str = "lm", max_iter: int = 100, xtol: float = 1e-15,
                     ftol: float = 1e-15, prior: ParameterPrior | None = None) -> IdentificationResult:
    """Forward identification: all free parameters at once through the forward kinematics.

    Minimises ``sum_j |W_j (QM_j - FK(theta, q_j))|^2``, ``W_j`` the whitening of pose j's
    declared measurement covariance (pose noise, plus joint noise through the manipulator
    Jacobian), evaluated once at the start. The Jacobian is analytic:
    ``d FK / d theta = -(dF/dpose)^-1 dF/dtheta``.

    Args:
        robot: the robot; its nominal vector is the default start.
        joints: (N, C) commanded (or read) joint values.
        measured: (N, D) measured poses.
        noise: declared noise (weights; a declared zero is floored, see :class:`SensorNoise`).
        free: names to identify; default ``robot.free_default``.
        start: (P,) start vector; default the nominal one. Fixed parameters keep its values.
        solver: ``"lm"``: Gauss-Newton with the forward kinematics solved along
            (:func:`_simultaneous_newton`: one closure-and-Jacobians call an iteration, and the
            closure alone where it predicts the poses), and
            where it cannot vouch for its answer (a step that raises the cost, a singular
            configuration, no convergence; ``message`` says so) Levenberg-Marquardt through the
            forward kinematics (Marquardt's scaling, MINPACK's rules); ``"gn"``: Gauss-Newton
            through the forward kinematics. All reach the same minimum.
        max_iter, xtol, ftol: stopping controls (of the solvers through the forward kinematics).
        prior: a :class:`~calib.prior.ParameterPrior`: maximum a posteriori (its whitened rows
            ``(theta_k - mean_k) / std_k`` of the free parameters join the system; any pose set
            but an empty one is accepted). None: plain (weighted) least squares.
    """
    joints, measured, free, idx, theta0 = _check(robot, joints, measured, noise, free, start, solver)
    prior_rows = _prior_rows(robot, prior, idx)
    n, d = measured.shape
    if prior_rows is not None:
        _refuse_empty(n)
    elif n * d < idx.size:
        raise ValueError(f"measured must have at least {-(-idx.size // d)} rows to identify "
                         f"{idx.size} parameters, got {n}")
    white, white_jac, white_columns, start_poses = _forward_whitening(robot, theta0, joints, measured, noise)
    simultaneous = _simultaneous_newton(robot, joints, measured, theta0, idx, white, white_columns,
                                        measured if start_poses is None else start_poses, prior_rows) \
        if solver == "lm" else "not asked for"
    if not isinstance(simultaneous, str):
        theta, predicted, gram, iters, history, msg = simultaneous
        factor = lambda: _forward_factor(robot, theta, joints, predicted, idx, white_jac)  # noqa: E731
        return _forward_result(robot, free, idx, theta0, theta, measured, predicted, white, factor, gram,
                               iters, history, True, msg, prior)
    if start_poses is None:
        start_poses = _start_poses(robot, theta0, joints, measured)
    theta, predicted, J, iters, history, ok, msg = _forward_through_kinematics(
        robot, joints, measured, theta0, idx, white, white_jac, start_poses, solver, max_iter, xtol, ftol,
        simultaneous, prior_rows)
    return _forward_result(robot, free, idx, theta0, theta, measured, predicted, white,
                           None if J is None else (lambda: J), None if J is None else J.T @ J, iters,
                           history, ok, msg, prior)


def _forward_whitening(robot, theta0, joints, measured, noise):
    """The forward fit's whitening: ``(white, white_jac, start_poses)``, ``white`` (N, D) -> (N, D)
    whitened residuals, ``white_jac`` (N, D, K) -> (N D, K) whitened Jacobian, ``start_poses``
    (N, D) the start model's forward kinematics where the whitening needed it (joint noise is
    propagated through the manipulator Jacobian there), else None: without joint noise the
    whitening is the same diagonal for every pose (a product) and needs no poses."""
    n, d = measured.shape
    start_poses = None
    if noise.joint_std > 0:
        start_poses = _start_poses(robot, theta0, joints, measured)
        winv = pose_whitening(robot, theta0, joints, start_poses, noise)
    diagonal = not noise.joint_std > 0
    w = 1.0 / noise.pose_std(robot.pose_units)

    def white(v, rows=slice(None)):  # (N, D) -> whitened (v of the rows ``rows``)
        return v * w if diagonal else np.einsum("nij,nj->ni", winv[rows], v)

    def white_jac(jp, rows=slice(None)):  # (N, D, K) -> whitened, flattened to (N D, K)
        jw = jp * w[:, None] if diagonal else np.einsum("nij,njk->nik", winv[rows], jp)
        return jw.reshape(-1, jp.shape[2])

    def white_columns(x, rows=slice(None)):  # (K, D, N) columns of (D, K) matrices of the rows ``rows``
        if diagonal:  # -> whitened, W x
            return x * w[None, :, None]
        return np.einsum("nil,kln->kin", winv[rows], x)

    return white, white_jac, white_columns, start_poses


def _forward_through_kinematics(robot, joints, measured, theta0, idx, white, white_jac, start_poses, solver,
                                max_iter, xtol, ftol, simultaneous, prior_rows=None):
    """The forward fit through the exact forward kinematics (Levenberg-Marquardt, where
    ``simultaneous`` says why :func:`_simultaneous_newton` could not vouch for its answer, or
    Gauss-Newton). Returns ``(theta (P,), predicted (N, D) its forward kinematics (NaN where it
    failed), J (N D, K) the whitened residual Jacobian there (measurement rows) or None,
    iterations, history, success, message)``; ``prior_rows`` (or None) join the residual."""
    # The last forward kinematics: each evaluation starts from it (a small perturbation),
    # moved to first order by the last Jacobian (Newton then has one step less to go), and the
    # Jacobian at a point just evaluated (as the solvers ask for it) reuses its poses.
    state = {"poses": start_poses, "x": theta0[idx].copy(), "dpose": None}
    history: list[float] = []

    def full(x):
        th = theta0.copy()
        th[idx] = x
        return th

    def reached(x):
        if not np.array_equal(state["x"], x):
            initial = state["poses"]
            if state["dpose"] is not None:
                x_j, poses_j, dpose = state["dpose"]
                initial = poses_j + dpose @ (x - x_j)
            state["poses"] = robot.forward_kinematics(full(x), joints, initial=initial)
            state["x"] = np.array(x)
        return state["poses"]

    def fun(x):
        f = white(measured - reached(x)).ravel()
        if prior_rows is not None:
            f = np.concatenate([f, (x - prior_rows[0]) * prior_rows[1]])
        history.append(0.5 * float(f @ f))
        return f

    def residual_jac(th, poses):  # (N, D, K) d (measured - FK) / d theta_free = (dF/dpose)^-1 dF/dtheta
        jac_c = robot.closure_jacobians(th, joints, poses)
        return np.linalg.inv(jac_c.pose) @ jac_c.parameters[:, :, idx]

    def jac(x):
        poses = reached(x)
        rj = residual_jac(full(x), poses)
        state["dpose"] = (np.array(x), poses, -rj)
        return white_jac(rj) if prior_rows is None else np.vstack([white_jac(rj), np.diag(prior_rows[1])])

    if solver == "lm":
        # With a prior, in offsets from its mean scaled by its standard deviations: the relative
        # step tests then measure the errors in tolerances, not the absolute values, and the
        # damping is negligible along the combinations only the prior holds (curvature 1e-12 of
        # the data's in Marquardt's column scaling).
        origin = None if prior_rows is None else prior_rows[0]
        try:
            if origin is None:
                x, iters, ok, msg = _levenberg_marquardt(fun, jac, theta0[idx], max_iter, xtol, ftol)
            else:
                x, iters, ok, msg = _levenberg_marquardt(lambda v: fun(origin + v), lambda v: jac(origin + v),
                                                         theta0[idx] - origin, max_iter, xtol, ftol, prior_rows[1])
                x = origin + x
        except (KinematicsError, np.linalg.LinAlgError) as exc:
            x, iters, ok, msg = theta0[idx], 0, False, f"the fit left the workspace: {exc}"
        msg = f"Levenberg-Marquardt through the forward kinematics (Gauss-Newton met {simultaneous}): {msg}"
    else:
        x, iters, ok, msg = _least_squares(fun, jac, theta0[idx], solver, max_iter, xtol, ftol, [])
    theta = full(x)
    if state["x"] is not None and np.array_equal(state["x"], x):
        predicted = state["poses"]  # the forward kinematics at the solution, already done
    else:
        predicted = _predicted(robot, theta, joints, measured)
    J = white_jac(residual_jac(theta, predicted)) if np.all(np.isfinite(predicted)) else None
    return theta, predicted, J, iters, history, ok, msg


def _forward_result(robot, free, idx, theta0, theta, measured, predicted, white, factor, gram, iterations,
                    history, success, message, prior=None) -> IdentificationResult:
    """The forward identification's result at ``theta``: ``predicted`` (N, D) its forward
    kinematics (NaN where it failed), ``gram`` (K, K) the ``J^T J`` of the whitened residual
    Jacobian there and ``factor`` a callable returning ``J`` or any matrix with that Gram matrix
    (its triangular factor), called only where the exact condition number is needed (both None
    if the forward kinematics failed); with a ``prior`` its rows join the covariance (posterior)
    and the chi-square."""
    n, d = measured.shape
    res = measured - predicted
    cov = np.zeros((robot.n_parameters,) * 2)
    dof = n * d - idx.size if prior is None else n * d  # the prior rows count as observations
    if gram is not None and np.all(np.isfinite(res)):
        r = white(res).ravel()
        rows = factor
        if prior is not None:
            mean, inv_std = _prior_rows(robot, prior, idx)
            r = np.concatenate([r, (theta[idx] - mean) * inv_std])
            gram = gram + np.diag(inv_std ** 2)
            rows = lambda: np.vstack([factor(), np.diag(inv_std)])  # noqa: E731
        block, cond = _covariance_and_conditions(lambda mask: rows()[None], gram[None])
        chi2 = float(r @ r)
        cov[np.ix_(idx, idx)] = block[0]
    else:
        chi2, cond = float("nan"), np.array([np.nan])
        cov[np.ix_(idx, idx)] = np.nan
    if dof > 0 and np.isfinite(chi2):  # converged or not, say where the residual stands
        message = f"{message}; {noise_verdict(chi2, dof)}"
    return IdentificationResult(
        method="forward", robot=robot, theta=theta, start=theta0, free_names=free, residuals=res,
        pose_residuals=res, covariance=cov, chi2=chi2, dof=dof, iterations=iterations,
        history=tuple(history), success=success, message=message, condition_numbers=cond, prior=prior)


# --------------------------------------------------------------------------- chain-wise


def identify_chainwise(robot: Robot, joints, measured, noise: SensorNoise | None = None, *, free=None,
                       start=None, solver: str = "gn", weighted: bool = False, epsilon: float = 1e-6,
                       step_tol: float = 1e-10, max_iter: int = 20, xtol: float = 1e-12,
                       ftol: float = 1e-14, prior: ParameterPrior | None = None) -> IdentificationResult:
    """Chain-wise identification from the closure residuals at the measured poses.

    ``solver="gn"`` (the hexapod paper's method, Sections 2, 3 and 5): each iteration solves, for
    every chain i, ``J_i d(theta_i) = -r_i`` by linear least squares (``r_i`` (N,) the closure
    residual at the measured poses, ``J_i`` its derivative with respect to chain i's free
    parameters; the paper writes the right-hand side to first order as ``(df/dQ) dQ``, Eq. 9,
    we evaluate it exactly: the same to first order, fewer iterations), corrects the parameters,
    computes the corrected poses ``QC`` by forward kinematics and stops when
    ``max_j dQint_j <= epsilon``. With noisy data ``dQint`` never falls below the noise and the
    iteration stops when the next update's largest entry is below ``step_tol`` (that update is
    not taken: the closure and its Jacobians stay those of the returned vector, one evaluation
    fewer); ``message`` says which rule stopped it and whether the residual is at the declared
    noise.

    ``solver="lm"`` (the Delta paper's IKM): each chain fitted to convergence by
    Levenberg-Marquardt.

    Args:
        robot, joints, measured, free, start: as :func:`identify_forward`.
        noise: declared noise; weights the residuals when ``weighted`` and judges the final
            residual (chi-square) always. Default: none declared (no judgement).
        solver: ``"gn"`` or ``"lm"``.
        weighted: whiten each closure residual by its declared standard deviation (pose and joint
            noise propagated); the paper's hexapod method is unweighted.
        epsilon: the paper's tolerance on max dQint (mm + rad, Eq. 17).
        step_tol: tolerance on the largest parameter update (GN): a smaller one is not taken.
        max_iter: outer iterations (GN) or iterations per chain (LM).
        prior: a :class:`~calib.prior.ParameterPrior`: maximum a posteriori, each chain's free
            parameters' whitened prior rows ``(theta_k - mean_k) / std_k`` in that chain's
            system; the closure residuals are then whitened by the declared noise (``weighted``
            implied: the prior needs the data's scale, so ``noise`` is required), and any pose set
            but an empty one is accepted. None: plain least squares.
    """
    if prior is not None and noise is None:
        raise ValueError("a prior needs the declared noise: pass noise (the closure residuals are "
                         "weighted by it against the prior)")
    noise_given = noise is not None
    noise = SensorNoise() if noise is None else noise
    joints, measured, free, idx, theta0 = _check(robot, joints, measured, noise, free, start, solver)
    prior_rows = _prior_rows(robot, prior, idx)
    n = measured.shape[0]
    # Chains with free parameters, grouped by their number: each group is one stack of problems
    # (the hexapod's six legs of seven parameters are one stack), gathered from the Jacobian,
    # conditioned and turned into covariances in one batched call each.
    groups = _chain_groups(robot, idx)
    most = max(p.shape[1] for _, p in groups)
    if prior is not None:
        _refuse_empty(n)
        weighted = True
    elif n < most:
        raise ValueError(f"measured must have at least {most} rows ({most} unknowns in one "
                         f"{robot.chain_word}), got {n}")
    if weighted:
        sigma = np.empty((n, robot.n_chains))
        for rows in _row_blocks(n):
            sigma[rows] = _closure_std(robot, robot.closure_jacobians(theta0, joints[rows], measured[rows]), noise)
        w = 1.0 / np.maximum(sigma, 1e-12)
    else:
        w = None  # unit weights, not multiplied in
    # Each chain's prior: the free parameters' (mean, 1 / std) in the robot's flat layout.
    chain_prior = None
    if prior is not None:
        chain_prior = (np.zeros(robot.n_parameters), np.zeros(robot.n_parameters))
        chain_prior[0][idx], chain_prior[1][idx] = prior_rows
    judged = noise if noise_given else None
    if solver == "gn":
        fit = _chainwise_gauss_newton(robot, joints, measured, theta0, groups, w, epsilon, step_tol, max_iter,
                                      chain_prior, judged)
    else:
        fit = _chainwise_levenberg_marquardt(robot, joints, measured, theta0, groups, w, max_iter, xtol, ftol,
                                             chain_prior, judged)
    return _chainwise_result(robot, free, idx, theta0, joints, measured, groups, w, judged, fit, prior,
                             chain_prior)


@dataclass
class _ChainwiseFit:
    """Where a chain-wise solver stopped: ``theta`` (P,), its :class:`_ChainEvaluation` at the
    measured poses ``evaluation`` (closure, normal equations of its chain systems, closure std),
    the ``corrected`` (N, D) poses (its forward kinematics, NaN where it failed), ``history``,
    ``iterations``, ``success`` and ``message``."""

    theta: np.ndarray
    evaluation: _ChainEvaluation
    corrected: np.ndarray
    history: list
    iterations: int
    success: bool
    message: str


def _chainwise_gauss_newton(robot, joints, measured, theta0, groups, w, epsilon, step_tol,
                            max_iter, chain_prior=None, noise=None) -> _ChainwiseFit:
    """The hexapod paper's iteration (see :func:`identify_chainwise`): a Gauss-Newton step per
    chain, the integrated error of the corrected model after each, judged on the exact forward
    kinematics where a stopping rule holds (:func:`_chainwise_stop`). ``chain_prior``: ``(mean
    (P,), 1 / std (P,))`` whose entries at each chain's parameters join its system, or None;
    ``noise``: the declared noise whose closure std the evaluations keep (for the result), or None."""
    theta = theta0.copy()
    history: list[float] = []
    iterations, success = 0, False
    message = f"no stopping rule met in {max_iter} iterations"
    # The closure, its chain systems' normal equations and one Newton step of the forward
    # kinematics at the measured poses, for the current vector: evaluated once per vector, block
    # by block, they serve its Gauss-Newton step, the integrated error of the corrected model
    # and, for the final vector, the result.
    ev = _chain_evaluation(robot, theta, joints, measured, groups, w, noise)
    dQ = None  # the corrected poses' offset from the measured ones, to second order
    corrected = None
    for it in range(1, max_iter + 1):
        step = np.zeros_like(theta)
        for (chains, params), (gram, g) in zip(groups, ev.systems):
            rows = None
            if chain_prior is not None:
                inv_std = chain_prior[1][params]
                rows = (inv_std, (theta[params] - chain_prior[0][params]) * inv_std)
            step[params] = _chain_steps(gram, g, rows, lambda th=theta, c=chains, p=params: _chain_factors(
                robot, th, joints, measured, c, p, w))
        update = float(np.max(np.abs(step)))
        small_step = update <= step_tol
        if not small_step:
            try:  # a step may leave the robot's parameter domain (a Delta forearm of negative length)
                ev_new = _chain_evaluation(robot, theta + step, joints, measured, groups, w, noise)
            except KinematicsError as exc:
                message = f"the Gauss-Newton step left the workspace at iteration {it}: {exc}"
                break
            theta, ev = theta + step, ev_new
            iterations = it
            dQ = ev.offset
            history.append(float(integrated_error(robot, dQ)[2].max()) if np.all(np.isfinite(dQ)) else np.inf)
            if not history[-1] <= epsilon:
                continue
        # A stopping rule holds (the paper's to second order, or the next update is negligible
        # and not taken): decide on the exact forward kinematics.
        if dQ is None:  # the start is the answer
            dQ = ev.offset
        corrected, stop = _chainwise_stop(robot, theta, joints, measured, dQ, history, epsilon,
                                          update if small_step else None, step_tol)
        if stop is not None:
            success, message = stop
            break
    if corrected is None:
        corrected = _predicted(robot, theta, joints, measured)
    return _ChainwiseFit(theta, ev, corrected, history, iterations, success, message)


def _chainwise_stop(robot, theta, joints, measured, dQ, history, epsilon, update, step_tol):
    """Judge a stopping rule of the chain-wise Gauss-Newton on the exact forward kinematics,
    started from the measured poses less ``dQ`` (N, D); ``update`` is the largest entry of the
    next update when it is below ``step_tol`` (not taken), else None. The exact max dQint
    replaces (or, at the start, becomes) the last entry of ``history``. Returns ``(corrected
    (N, D) or None, (success, message) or None to go on)``."""
    try:
        corrected = robot.forward_kinematics(
            theta, joints, initial=measured - dQ if np.all(np.isfinite(dQ)) else measured)
    except KinematicsError as exc:
        return None, (False, f"forward kinematics of the corrected model failed: {exc}")
    exact = float(integrated_error(robot, measured - corrected)[2].max())
    if history:
        history[-1] = exact
    else:
        history.append(exact)
    if exact <= epsilon:
        return corrected, (True, f"paper's criterion met: max dQint = {exact:.3g} <= epsilon = {epsilon:g}")
    if update is not None:
        return corrected, (True, f"the next parameter update, {update:.3g}, is below step_tol = {step_tol:g} "
                                 f"and not taken; the paper's criterion is not reachable: max dQint stays at "
                                 f"{exact:.3g} (> epsilon = {epsilon:g})")
    return None, None


def _chainwise_levenberg_marquardt(robot, joints, measured, theta0, groups, w, max_iter, xtol,
                                   ftol, chain_prior=None, noise=None) -> _ChainwiseFit:
    """Each chain fitted to convergence by Levenberg-Marquardt (the Delta paper's IKM), in chain
    order; ``chain_prior`` and ``noise`` as :func:`_chainwise_gauss_newton`'s. Where a chain's
    closure moves with other chains' free parameters too (:func:`_chains_coupled`: the linear
    Delta's rod-pair differences, :attr:`calib.robot.Robot.chain_coupled`, where a caller frees
    them, or any of its parameters where its effector is tilted), the chains are swept again, each
    fitted with the others' latest values, until a sweep moves no parameter by more than ``xtol``
    relative (at most ``max_iter`` sweeps)."""
    theta = theta0.copy()
    history: list[float] = []
    iterations = 0
    in_order = sorted((int(c), ix) for chains, params in groups for c, ix in zip(chains, params))
    free = np.sort(np.concatenate([ix for _, ix in in_order]))
    sweeps = max_iter if _chains_coupled(robot, theta, joints[:1], measured[:1], free) else 1
    for _ in range(sweeps):
        before = theta.copy()
        messages, oks = [], []
        for c, ix in in_order:
            x, it, ok, msg = _chain_levenberg_marquardt(robot, joints, measured, theta, c, ix, w, max_iter, xtol,
                                                        ftol, chain_prior, history)
            theta[ix] = x
            iterations += it
            oks.append(ok)
            messages.append(f"{robot.chain_word} {c + 1}: {msg}")
        if np.all(np.abs(theta - before) <= xtol * np.maximum(1.0, np.abs(theta))):
            break
    corrected = _predicted(robot, theta, joints, measured)
    ev = _chain_evaluation(robot, theta, joints, measured, groups, w, noise)
    return _ChainwiseFit(theta, ev, corrected, history, iterations, all(oks), "; ".join(messages))


def _chains_coupled(robot, theta, joints, poses, free) -> bool:
    """Whether some chain's closure moves with another chain's ``free`` parameters (a nonzero
    entry of the parameter Jacobian off each parameter's own chain, at the first row)."""
    jac = robot.closure_jacobians(theta, joints, poses)
    if jac.own_for(robot.table.chains) is not None:
        return False
    off = np.arange(robot.n_chains)[:, None] != robot.table.chains[None, free]
    return bool(np.any(jac.parameters[:, :, free][:, off] != 0))


def _chain_levenberg_marquardt(robot, joints, measured, theta, c, ix, w, max_iter, xtol, ftol, chain_prior,
                               history) -> tuple:
    """Chain ``c``'s parameters ``ix`` fitted by Levenberg-Marquardt, the others held at ``theta``:
    ``(x, iterations, ok, message)``."""

    def full(x):
        th = theta.copy()
        th[ix] = x
        return th

    def fun(x):
        r = robot.closure(full(x), joints, measured)[:, c]
        r = r if w is None else r * w[:, c]
        if chain_prior is None:
            return r
        return np.concatenate([r, (x - chain_prior[0][ix]) * chain_prior[1][ix]])

    def jac(x):
        A = robot.closure_jacobians(full(x), joints, measured).parameters[:, c, ix]
        A = A if w is None else A * w[:, c, None]
        return A if chain_prior is None else np.vstack([A, np.diag(chain_prior[1][ix])])

    if chain_prior is None:
        return _least_squares(fun, jac, theta[ix], "lm", max_iter, xtol, ftol, history)
    # in offsets from the prior's mean, as the forward fit (its relative step test)
    origin = chain_prior[0][ix]
    x, it, ok, msg = _least_squares(lambda v: fun(origin + v), lambda v: jac(origin + v), theta[ix] - origin, "lm",
                                    max_iter, xtol, ftol, history)
    return origin + x, it, ok, msg


def _chainwise_result(robot, free, idx, theta0, joints, measured, groups, w, noise, fit: _ChainwiseFit,
                      prior=None, chain_prior=None) -> IdentificationResult:
    """The chain-wise identification's result: per-chain covariances and condition numbers from
    the normal equations of the fit's evaluation at the returned vector (the exact condition
    number of an ill-conditioned chain from its triangular factor, one more pass over the rows),
    chi-square against ``noise`` (None: none declared, no judgement); with a ``prior``
    (``chain_prior`` its rows as :func:`_chainwise_gauss_newton` takes them) the posterior
    covariance and its rows in the chi-square."""
    n = measured.shape[0]
    ev = fit.evaluation
    r = ev.r
    cond = np.full(robot.n_chains, np.nan)
    cov = np.zeros((robot.n_parameters,) * 2)
    for k, (chains, params) in enumerate(groups):
        gram = ev.systems[k][0]
        inv_std = None if chain_prior is None else chain_prior[1][params]

        def factors(mask, chains=chains, params=params, inv_std=inv_std):
            R = _chain_factors(robot, fit.theta, joints, measured, chains[mask], params[mask], w)[..., :-1]
            return R if inv_std is None else _with_prior_rows(R, inv_std[mask])

        if inv_std is not None:
            gram = gram + _diagonal_stack(inv_std ** 2)
        block, cond[chains] = _covariance_and_conditions(factors, gram)  # (M, K, K) and (M,), per chain
        dof = n - params.shape[1]
        if w is None:  # the residuals' own variance, s^2 = |r_c|^2 / dof, per chain
            rc = r[:, chains]
            block = block * (np.einsum("nm,nm->m", rc, rc) / dof)[:, None, None] if dof > 0 else \
                np.full_like(block, np.nan)
        cov[params[:, :, None], params[:, None, :]] = block
    message = fit.message
    if noise is not None:
        white = r / np.maximum(ev.std, 1e-12)
        chi2 = float(np.sum(white ** 2))
        if chain_prior is not None:
            e_prior = (fit.theta[idx] - chain_prior[0][idx]) * chain_prior[1][idx]
            chi2 += float(e_prior @ e_prior)
    else:
        chi2 = float("nan")
    dof_total = n * robot.n_chains - (idx.size if prior is None else 0)  # prior rows count as observations
    if noise is not None and dof_total > 0 and np.isfinite(chi2):  # converged or not
        message += "; " + noise_verdict(chi2, dof_total)
    return IdentificationResult(
        method="chainwise", robot=robot, theta=fit.theta, start=theta0, free_names=free, residuals=r,
        pose_residuals=measured - fit.corrected, covariance=cov, chi2=chi2, dof=dof_total,
        iterations=fit.iterations, history=tuple(fit.history), success=fit.success, message=message,
        condition_numbers=cond, prior=prior)


def newton_offset(pose_jacobian: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(N, D) one Newton step of the forward kinematics from the measured poses, ``(dF/dpose)^-1
    F`` (``pose_jacobian`` (N, C, D) at those poses, ``r`` (N, C) the closure there): the measured
    poses minus the corrected ones, exact to ``|dQ|^2 / machine size`` (``inf`` where the pose
    Jacobian is singular)."""
    try:
        return BatchedLU(pose_jacobian).solve(r)
    except np.linalg.LinAlgError:
        return np.full(r.shape[:1] + pose_jacobian.shape[2:], np.inf)


def noise_verdict(chi2: float, dof: int, alpha: float = 0.01) -> str:
    """Whether a chi-square of whitened residuals is at the declared noise, in words."""
    limit = chi2_quantile(1.0 - alpha, dof)
    ratio = np.sqrt(chi2 / dof)
    if chi2 <= limit:
        return (f"the residual is at the declared noise (chi-square {chi2:.4g} on {dof} degrees of "
                f"freedom, {ratio:.2f} times the declared noise)")
    return (f"the model does not fit to the declared noise: the residual is {ratio:.3g} times the "
            f"declared noise (chi-square {chi2:.4g} on {dof} degrees of freedom, limit {limit:.4g}): an "
            "unmodelled effect, outlying rows, or noise declared too small")


def identify(robot: Robot, joints, measured, noise: SensorNoise, *, method: str = "forward",
             prior: ParameterPrior | None = None, **options) -> IdentificationResult:
    """Either method by name: ``"forward"`` or ``"chainwise"`` (options passed on); ``prior``
    (a :class:`~calib.prior.ParameterPrior`, e.g. ``ParameterPrior.default(robot)``): maximum a
    posteriori; None: plain least squares."""
    if method == "forward":
        return identify_forward(robot, joints, measured, noise, prior=prior, **options)
    if method == "chainwise":
        return identify_chainwise(robot, joints, measured, noise, prior=prior, **options)
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


def gauge_representative(robot: Robot, theta: np.ndarray, start: np.ndarray | None = None, *,
                         poses: int = 60, seed: int = 0) -> np.ndarray:
    """The parameter vector, in the identification's gauge, that moves exactly like ``theta``.

    Pose data cannot tell apart parameter vectors that differ along an unidentifiable direction
    (the Delta's joint offset and arm direction); the identification holds the robot's
    ``gauge_fixed`` parameters at their start values. To compare an identified vector with a
    machine's true one, the true one is first mapped to that gauge: the vector with the gauge
    parameters of ``start`` whose kinematics match ``theta``'s over ``poses`` workspace poses
    (a noise-free forward fit, exact to numerical precision).

    Args:
        robot: the robot.
        theta: (P,) the machine's parameters.
        start: (P,) whose gauge parameters to take; default the nominal vector.
        poses, seed: the workspace poses of the fit.

    Returns:
        (P,) ``theta`` itself when the robot has no gauge parameters.
    """
    if not robot.gauge_fixed:
        return np.array(theta, dtype=float)
    start = robot.table.nominal if start is None else start
    gauge = robot.table.indices(robot.gauge_fixed)
    begin = np.array(theta, dtype=float)
    begin[gauge] = start[gauge]
    targets = reachable_poses(robot, poses, seed, theta=theta)
    joints = robot.inverse_kinematics(theta, targets)
    fit = identify_forward(robot, joints, targets, SensorNoise(1.0, 1.0), start=begin)
    return fit.theta
