"""Identification of the 42 hexapod errors from commanded leg lengths and measured poses.

Two methods:

* :func:`identify_paper`: the hexapod paper's method (Sections 2, 3 and 5). Built on the
  inverse kinematics: for each leg, n equations in that leg's 7 errors, solved by linear
  least squares; parameters corrected; corrected poses computed by forward kinematics;
  repeated until ``max_j dQint_j <= epsilon`` (Eqs. 15-17).
* :func:`identify_forward`: the forward method of the Delta paper applied to the hexapod:
  all 42 errors at once, minimising noise-weighted pose residuals through the forward
  kinematics with Levenberg-Marquardt.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ._validate import as_array, as_poses
from .hexapod import N_PARAMETERS, Hexapod
from .kinematics import (
    KinematicsError,
    _commanded,
    _parameter_jacobian,
    forward_kinematics,
    forward_parameter_jacobian,
)
from .metrics import integrated_error
from .noise import SensorNoise

__all__ = ["IdentificationResult", "identify_paper", "identify_forward", "MIN_POSES"]

#: Each leg has 7 unknowns, so at least 7 poses are needed (the paper's n >= 7).
MIN_POSES = 7


@dataclass(frozen=True, eq=False)
class IdentificationResult:
    """Outcome of an identification; returned also when it did not converge.

    Attributes:
        method: ``"paper"`` or ``"forward"``.
        hexapod: the identified parameter set (nominal geometry + ``errors``).
        errors: (6, 7) mm, identified errors in Table 3's column order.
        estimate: (42,) mm, the same as a flat vector (``parameter_table`` order).
        residuals: for ``"paper"`` (N, 6) mm, leg-length residuals ``l(measured pose) - l_cmd``;
            for ``"forward"`` (N, 6) mm and rad, ``measured - forward kinematics``.
        pose_residuals: (N, 6) mm and rad, measured poses minus the poses the identified model
            predicts (both methods; the paper's ``dQc``).
        covariance: (42, 42) mm^2, parameter covariance estimated from the residuals
            (``s^2 (J^T J)^-1``); NaN where the residuals leave no degree of freedom.
        iterations: outer iterations (paper) or Jacobian evaluations (forward).
        history: max dQint after each iteration (paper) or cost per evaluation (forward).
        success: whether a stopping criterion was met.
        message: which criterion stopped it, in words.
        condition_numbers: condition numbers of the identification Jacobian(s): (6,) per leg
            for ``"paper"``, (1,) for ``"forward"`` (noise-weighted, column-scaled).
    """

    method: str
    hexapod: Hexapod
    errors: np.ndarray
    estimate: np.ndarray
    residuals: np.ndarray
    pose_residuals: np.ndarray
    covariance: np.ndarray
    iterations: int
    history: tuple
    success: bool
    message: str
    condition_numbers: np.ndarray

    @property
    def std(self) -> np.ndarray:
        """(42,) mm, standard uncertainty of each parameter (sqrt of covariance diagonal)."""
        return np.sqrt(np.diag(self.covariance))


def _check_inputs(nominal: Hexapod, commanded, measured):
    if not isinstance(nominal, Hexapod):
        raise TypeError(f"nominal must be a Hexapod, got {type(nominal).__name__}")
    commanded = as_array(commanded, "commanded", (-1, 6))
    measured = as_poses(measured, "measured")
    if commanded.shape[0] != measured.shape[0]:
        raise ValueError(
            f"commanded and measured must have the same number of rows, got "
            f"{commanded.shape[0]} and {measured.shape[0]}")
    if measured.shape[0] < MIN_POSES:
        raise ValueError(
            f"identification needs at least {MIN_POSES} poses (7 unknowns per leg), "
            f"got {measured.shape[0]}")
    return commanded, measured


def identify_paper(
    nominal: Hexapod,
    commanded: np.ndarray,
    measured: np.ndarray,
    *,
    epsilon: float = 1e-6,
    step_tol: float = 1e-10,
    max_iter: int = 20,
) -> IdentificationResult:
    """The paper's per-leg least-squares identification with iterative compensation.

    Step 5 solves, for each leg i, ``J_i d(theta_i) = -r_i`` by linear least squares, where
    ``r_i`` (n,) is the leg-length residual ``|R P_i + OP - B_i| - dl_i - l_cmd`` at the
    measured poses and ``J_i`` (n, 7) its derivative with respect to that leg's errors. The
    paper writes the right-hand side to first order as ``(d f / d Q) dQ`` (Eq. 9); we evaluate
    the residual exactly, which is the same to first order and converges in fewer iterations.
    Steps 6-8 correct the parameters and compute the corrected poses ``QC`` by forward
    kinematics at the commanded lengths and ``dQc = QM - QC``; step 9 stops when
    ``max_j dQint_j <= epsilon``.

    With noisy measurements ``dQc`` never falls below the noise, so the paper's rule cannot
    be met; the iteration then stops when the largest parameter update falls below
    ``step_tol`` mm (``success`` is still True and ``message`` says which rule stopped it).

    Args:
        nominal: nominal parameter set (its errors are the starting estimate, usually 0).
        commanded: (N, 6) commanded leg lengths, mm.
        measured: (N, 6) measured poses, mm and rad, N >= 7.
        epsilon: the paper's tolerance on max dQint (mm + rad, as in Eq. 17).
        step_tol: tolerance on the largest parameter update, mm.
        max_iter: iterations before giving up (``success`` False).
    """
    commanded, measured = _check_inputs(nominal, commanded, measured)
    n = measured.shape[0]
    theta = nominal.errors.copy()
    history: list[float] = []
    success, message = False, f"no stopping rule met in {max_iter} iterations"
    cond = np.full(6, np.nan)
    corrected = measured.copy()
    it = 0
    for it in range(1, max_iter + 1):
        hx = nominal.with_errors(theta)
        r = _commanded(hx, measured) - commanded  # (n, 6)
        J = _parameter_jacobian(hx, measured)  # (n, 6, 7)
        step = np.empty((6, 7))
        for leg in range(6):
            step[leg] = np.linalg.lstsq(J[:, leg], -r[:, leg], rcond=None)[0]
            cond[leg] = np.linalg.cond(J[:, leg])
        theta = theta + step
        hx = nominal.with_errors(theta)
        try:
            corrected = forward_kinematics(hx, commanded, initial=measured, stroke_mm=None)
        except KinematicsError as exc:
            message = f"forward kinematics of the corrected model failed: {exc}"
            break
        dQint = integrated_error(measured - corrected)[2]
        history.append(float(dQint.max()))
        if history[-1] <= epsilon:
            success, message = True, (
                f"paper's criterion met: max dQint = {history[-1]:.3g} <= epsilon = {epsilon:g}")
            break
        if np.max(np.abs(step)) <= step_tol:
            success, message = True, (
                f"parameter update {np.max(np.abs(step)):.3g} mm <= step_tol = {step_tol:g}; "
                f"the paper's criterion is not reachable: max dQint stays at {history[-1]:.3g} "
                f"(> epsilon = {epsilon:g}), the level of the measurement noise")
            break

    hx = nominal.with_errors(theta)
    r = _commanded(hx, measured) - commanded
    J = _parameter_jacobian(hx, measured)
    cov = np.full((N_PARAMETERS, N_PARAMETERS), np.nan)
    dof = n - 7
    for leg in range(6):
        blk = slice(leg * 7, (leg + 1) * 7)
        cov[blk, :] = 0.0
        cov[:, blk] = 0.0
        if dof > 0:
            s2 = float(r[:, leg] @ r[:, leg]) / dof
            cov[blk, blk] = s2 * np.linalg.pinv(J[:, leg].T @ J[:, leg])
        else:
            cov[blk, blk] = np.nan
    return IdentificationResult(
        method="paper", hexapod=hx, errors=theta.copy(), estimate=theta.ravel().copy(),
        residuals=r, pose_residuals=measured - corrected, covariance=cov, iterations=it,
        history=tuple(history), success=success, message=message, condition_numbers=cond.copy(),
    )


def identify_forward(
    nominal: Hexapod,
    commanded: np.ndarray,
    measured: np.ndarray,
    noise: SensorNoise,
    *,
    method: str = "lm",
    xtol: float = 1e-15,
    ftol: float = 1e-15,
    max_nfev: int = 200,
) -> IdentificationResult:
    """The forward method: all 42 errors at once through the forward kinematics.

    Minimises ``sum_j || W (QM_j - FK(theta, l_cmd_j)) ||^2`` with ``W = diag(1/std)`` from the
    declared sensor noise (mm and rad weighted explicitly, never a raw norm), with an analytic
    Jacobian from the implicit function theorem
    (:func:`~calib.kinematics.forward_parameter_jacobian`).

    Args:
        nominal: nominal parameter set (its errors are the starting estimate).
        commanded: (N, 6) commanded leg lengths, mm.
        measured: (N, 6) measured poses, mm and rad, N >= 7.
        noise: declared sensor noise; zero components are floored (see ``SensorNoise.weights``).
        method: ``"lm"`` (Levenberg-Marquardt, MINPACK) or ``"trf"``.
        xtol, ftol, max_nfev: passed to :func:`scipy.optimize.least_squares`.
    """
    commanded, measured = _check_inputs(nominal, commanded, measured)
    if method not in ("lm", "trf"):
        raise ValueError(f"method must be 'lm' or 'trf', got {method!r}")
    w = noise.weights()
    n = measured.shape[0]
    state = {"poses": measured.copy()}

    def reached(x):
        hx = nominal.with_errors(x)
        # Warm start from the last solution: each evaluation is a small perturbation.
        state["poses"] = forward_kinematics(hx, commanded, initial=state["poses"], stroke_mm=None)
        return hx, state["poses"]

    def fun(x):
        _, p = reached(x)
        return ((measured - p) * w).ravel()

    def jac(x):
        hx, p = reached(x)
        return -(forward_parameter_jacobian(hx, p) * w[None, :, None]).reshape(6 * n, N_PARAMETERS)

    history: list[float] = []

    def fun_logged(x):
        f = fun(x)
        history.append(0.5 * float(f @ f))
        return f

    x0 = nominal.vector
    try:
        sol = least_squares(fun_logged, x0, jac=jac, method=method, xtol=xtol, ftol=ftol,
                            gtol=1e-15, max_nfev=max_nfev, x_scale="jac")
        x, ok, msg, nj = sol.x, bool(sol.success), str(sol.message), int(sol.njev or sol.nfev)
    except KinematicsError as exc:
        x, ok, msg, nj = x0, False, f"forward kinematics failed during the fit: {exc}", 0
    hx = nominal.with_errors(x)
    p = forward_kinematics(hx, commanded, initial=measured, stroke_mm=None)
    res = measured - p
    J = -(forward_parameter_jacobian(hx, p) * w[None, :, None]).reshape(6 * n, N_PARAMETERS)
    dof = 6 * n - N_PARAMETERS
    fw = (res * w).ravel()
    # Column-scaled condition number: invariant to the units of the parameters.
    Js = J / np.linalg.norm(J, axis=0)
    cond = np.array([np.linalg.cond(Js)])
    if dof > 0:
        s2 = float(fw @ fw) / dof
        cov = s2 * np.linalg.pinv(J.T @ J)
    else:
        cov = np.full((N_PARAMETERS, N_PARAMETERS), np.nan)
    return IdentificationResult(
        method="forward", hexapod=hx, errors=hx.errors.copy(), estimate=x.copy(), residuals=res,
        pose_residuals=res, covariance=cov, iterations=nj, history=tuple(history), success=ok,
        message=msg, condition_numbers=cond,
    )
