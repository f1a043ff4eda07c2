"""Identification of the Delta's Model-24 parameters: the forward (FKM) and inverse (IKM)
methods of the Delta calibration paper (Section 3), and the calibration gain G (Eq. 4.1).

* FKM (paper Eq. 3.4-3.7, 3.13 first line): residual ``X_meas_k - FK(P, q_meas_k)``, three
  per configuration (mm), all free parameters at once, Jacobian Eq. 3.17-3.18.
* IKM (paper Eq. 3.8-3.10, 3.13 second line): closure residual
  ``||X_meas_k - B_i(P_i, q_meas_ik)|| - Lb_i`` (mm), one per configuration and chain,
  solved chain by chain (eight parameters per chain), Jacobian Eq. 3.19-3.21.

Both weight residuals by the *declared* measurement noise: a position noise ``sigma_mm``
(per coordinate) and a joint noise ``sigma_rad`` (per joint) are propagated to each residual
at the initial estimate (FKM: 3x3 covariance ``sigma_mm^2 I + sigma_rad^2 Jq Jq^T`` whitened by
its Cholesky factor; IKM: variance ``sigma_mm^2 + sigma_rad^2 (dF/dq)^2``). The weights are
held fixed during the iterations, so the solvers minimise one fixed quadratic criterion.

Identifiability: with position measurements the arm vector direction ``(Lax_i, Lay_i)`` and
the joint offset ``alpha_i`` are coupled (one exact null direction of the identification
Jacobian per chain, found by SVD), so by default ``Lay1..3`` are held at their value in the
initial estimate (zero for the nominal) and the 21 others are identified: the estimate is
the canonical representative of :func:`calib.delta.canonical_params`.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from calib.delta import (
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    DeltaParams,
    canonical_params,
    constraint_jacobian_joints,
    constraint_jacobian_params,
    constraint_residuals,
    fk_jacobian_joints,
    fk_jacobian_params,
    forward_kinematics,
    inverse_kinematics,
    _as_array,
    _check_params,
)

__all__ = [
    "DEFAULT_FREE",
    "DeltaDataset",
    "DeltaIdentificationResult",
    "GainReport",
    "calibration_gain",
    "identify_fkm",
    "identify_ikm",
    "make_dataset",
    "null_space_combinations",
    "perturb_params",
    "random_workspace_positions",
]

#: Default identified set: all parameters except ``Lay1..3`` (see module docstring).
DEFAULT_FREE: tuple[str, ...] = tuple(n for n in PARAMETER_NAMES if not n.startswith("Lay"))

_METHODS = ("lm", "gn")


# --------------------------------------------------------------------------- results


@dataclasses.dataclass(frozen=True)
class DeltaIdentificationResult:
    """Outcome of an identification (never raised on non-convergence).

    Attributes:
        estimate: Identified parameters (fixed ones keep their initial value).
        free_names: Names of the identified parameters, in the covariance's order.
        residuals: Final unweighted residuals, shape (N, 3), mm. FKM: position error
            ``X_meas - FK`` (base frame); IKM: closure residual of each chain.
        weighted_residuals: Final residuals divided by their declared standard deviation
            (whitened), flat, dimensionless.
        covariance: Covariance of the identified parameters implied by the declared noise,
            shape (len(free_names), len(free_names)), units mm^2, mm.rad, rad^2.
        iterations: Number of accepted solver iterations (IKM: summed over the chains).
        success: Whether the solver met its convergence test.
        message: Human-readable reason for stopping.
        method: ``"fkm"`` or ``"ikm"``.
        solver: ``"lm"`` or ``"gn"``.
        cost: Final sum of squared weighted residuals.
    """

    estimate: DeltaParams
    free_names: tuple[str, ...]
    residuals: np.ndarray
    weighted_residuals: np.ndarray
    covariance: np.ndarray
    iterations: int
    success: bool
    message: str
    method: str
    solver: str
    cost: float


@dataclasses.dataclass(frozen=True)
class _SolveOut:
    x: np.ndarray
    r: np.ndarray
    jac: np.ndarray
    iterations: int
    success: bool
    message: str


# --------------------------------------------------------------------------- solvers


def _solve(
    fun: Callable[[np.ndarray], np.ndarray],
    jac: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    solver: str,
    max_iter: int,
    xtol: float,
    ftol: float,
) -> _SolveOut:
    """Levenberg-Marquardt or Gauss-Newton on ``min ||fun(x)||^2``.

    Column scaling ``d_j = max(||J_:,j||)`` (Marquardt/More) makes mm and rad columns
    comparable. ``fun``/``jac`` may raise ValueError (unreachable configuration): LM then
    rejects the trial step, GN stops with ``success=False``.
    """
    x = x0.copy()
    try:
        r = fun(x)
        j = jac(x)
    except ValueError as exc:
        return _SolveOut(x, np.full(1, np.nan), np.zeros((1, x.size)), 0, False, f"initial estimate invalid: {exc}")
    cost = float(r @ r)
    d = np.maximum(np.linalg.norm(j, axis=0), 1e-12)
    lam = 1e-3
    it = 0
    trials = 0
    while it < max_iter and trials < 20 * max_iter:
        trials += 1
        d = np.maximum(d, np.linalg.norm(j, axis=0))
        js = j / d
        if solver == "gn":
            step_s = np.linalg.lstsq(js, -r, rcond=None)[0]
        else:
            a = js.T @ js
            g = js.T @ r
            step_s = np.linalg.solve(a + lam * np.diag(np.maximum(np.diag(a), 1e-12)), -g)
        step = step_s / d
        x_new = x + step
        err = "non-finite residuals"
        try:
            r_new = fun(x_new)
            ok = bool(np.all(np.isfinite(r_new)))
        except ValueError as exc:
            ok = False
            err = str(exc)
        if not ok:
            if solver == "gn":
                return _SolveOut(x, r, j, it, False, f"Gauss-Newton step left the workspace at iteration {it + 1}: {err}")
            lam *= 10.0
            if lam > 1e16:
                return _SolveOut(x, r, j, it, False, "Levenberg-Marquardt damping exhausted (steps leave the workspace)")
            continue
        cost_new = float(r_new @ r_new)
        if solver == "lm" and cost_new > cost:
            lam *= 4.0
            if lam > 1e16:
                return _SolveOut(x, r, j, it, True, "converged: no decreasing step left (damping exhausted)")
            continue
        it += 1
        small_step = np.linalg.norm(step_s) <= xtol * (np.linalg.norm(d * x) + xtol)
        small_cost = abs(cost - cost_new) <= ftol * max(cost, 1e-300)
        x, r, cost = x_new, r_new, cost_new
        if solver == "lm":
            lam = max(lam / 3.0, 1e-12)
        try:
            j = jac(x)
        except ValueError as exc:
            return _SolveOut(x, r, j, it, False, f"Jacobian failed at iteration {it}: {exc}")
        if solver == "gn" and not np.isfinite(cost):
            return _SolveOut(x, r, j, it, False, "Gauss-Newton diverged (non-finite cost)")
        if small_step:
            return _SolveOut(x, r, j, it, True, f"converged: relative step below {xtol:g}")
        if small_cost and solver == "lm":
            return _SolveOut(x, r, j, it, True, f"converged: relative cost change below {ftol:g}")
        if cost == 0.0:
            return _SolveOut(x, r, j, it, True, "converged: zero residual")
    return _SolveOut(x, r, j, it, False, f"did not converge in {max_iter} iterations")


def _covariance(j: np.ndarray) -> np.ndarray:
    """``(J^T J)^+`` of whitened residuals, symmetrised."""
    c = np.linalg.pinv(j.T @ j, hermitian=True)
    return 0.5 * (c + c.T)


# --------------------------------------------------------------------------- validation


def _check_common(params, q, positions, free, solver, sigma_mm, sigma_rad, max_iter):
    _check_params(params)
    q = _as_array(q, "q", (-1, 3))
    positions = _as_array(positions, "positions", (-1, 3))
    if q.shape[0] != positions.shape[0]:
        raise ValueError(
            f"q and positions must have the same number of configurations, got {q.shape[0]} and {positions.shape[0]}"
        )
    if solver not in _METHODS:
        raise ValueError(f"solver must be one of {_METHODS}, got {solver!r}")
    free = tuple(free)
    unknown = [n for n in free if n not in PARAMETER_NAMES]
    if unknown:
        raise ValueError(f"free must name parameters of PARAMETER_NAMES, got unknown {unknown}")
    if len(set(free)) != len(free) or not free:
        raise ValueError(f"free must be a non-empty list of distinct names, got {free}")
    for name, val in (("sigma_mm", sigma_mm), ("sigma_rad", sigma_rad)):
        if not (np.isfinite(val) and val > 0):
            raise ValueError(f"{name} must be positive (declared noise used as weight), got {val}")
    if not (isinstance(max_iter, (int, np.integer)) and max_iter >= 1):
        raise ValueError(f"max_iter must be a positive integer, got {max_iter!r}")
    return q, positions, free


# --------------------------------------------------------------------------- FKM


def identify_fkm(
    initial: DeltaParams,
    q,
    positions,
    *,
    solver: str = "lm",
    free=DEFAULT_FREE,
    sigma_mm: float = 1e-3,
    sigma_rad: float = float(np.deg2rad(0.01)),
    max_iter: int = 100,
    xtol: float = 1e-12,
    ftol: float = 1e-14,
) -> DeltaIdentificationResult:
    """Forward-kinematics method: fit all free parameters to measured plate positions.

    Args:
        initial: Initial estimate (usually the nominal parameters); also supplies fixed ones.
        q: Measured joint readings, shape (N, 3), rad.
        positions: Measured plate-centre positions, shape (N, 3), mm, base frame.
        solver: ``"lm"`` (Levenberg-Marquardt) or ``"gn"`` (Gauss-Newton).
        free: Names of the parameters to identify (default :data:`DEFAULT_FREE`).
        sigma_mm: Declared position noise per coordinate, mm (> 0; weights only).
        sigma_rad: Declared joint noise per joint, rad (> 0; weights only).
        max_iter: Maximum accepted iterations.
        xtol: Relative (column-scaled) step tolerance.
        ftol: Relative cost-change tolerance (LM only).

    Returns:
        A :class:`DeltaIdentificationResult` (``success=False`` rather than raising when the
        solver fails, e.g. when a step leaves the workspace).

    Raises:
        ValueError: On malformed input, or when the initial estimate cannot reach the
            measured configurations.
    """
    q, positions, free = _check_common(initial, q, positions, free, solver, sigma_mm, sigma_rad, max_iter)
    n = q.shape[0]
    if 3 * n < len(free):
        raise ValueError(f"q must have at least {-(-len(free) // 3)} configurations for {len(free)} free parameters, got {n}")
    idx = np.array([PARAMETER_NAMES.index(nm) for nm in free])
    base = initial.to_vector()
    jq = fk_jacobian_joints(initial, q)  # raises with configuration index if unreachable
    cov = sigma_mm**2 * np.eye(3)[None] + sigma_rad**2 * jq @ np.swapaxes(jq, 1, 2)
    winv = np.linalg.inv(np.linalg.cholesky(cov))  # (N,3,3): whitening L^-1

    def full(x):
        v = base.copy()
        v[idx] = x
        return DeltaParams.from_vector(v)

    def raw(x):
        return positions - forward_kinematics(full(x), q)

    def fun(x):
        return np.einsum("nrc,nc->nr", winv, raw(x)).ravel()

    def jac(x):
        jp = fk_jacobian_params(full(x), q)[:, :, idx]
        return -np.einsum("nrc,nck->nrk", winv, jp).reshape(3 * n, idx.size)

    out = _solve(fun, jac, base[idx], solver, max_iter, xtol, ftol)
    est = full(out.x)
    try:
        res = raw(out.x)
    except ValueError:
        res = np.full((n, 3), np.nan)
    return DeltaIdentificationResult(
        estimate=est,
        free_names=free,
        residuals=res,
        weighted_residuals=out.r,
        covariance=_covariance(out.jac),
        iterations=out.iterations,
        success=out.success,
        message=out.message,
        method="fkm",
        solver=solver,
        cost=float(out.r @ out.r),
    )


# --------------------------------------------------------------------------- IKM


def identify_ikm(
    initial: DeltaParams,
    q,
    positions,
    *,
    solver: str = "lm",
    free=DEFAULT_FREE,
    sigma_mm: float = 1e-3,
    sigma_rad: float = float(np.deg2rad(0.01)),
    max_iter: int = 100,
    xtol: float = 1e-12,
    ftol: float = 1e-14,
) -> DeltaIdentificationResult:
    """Inverse method: identify each chain separately from its closure residual (Eq. 3.8).

    Args:
        initial: Initial estimate (usually the nominal parameters); also supplies fixed ones.
        q: Measured joint readings, shape (N, 3), rad.
        positions: Measured plate-centre positions, shape (N, 3), mm, base frame.
        solver: ``"lm"`` (Levenberg-Marquardt) or ``"gn"`` (Gauss-Newton).
        free: Names of the parameters to identify (default :data:`DEFAULT_FREE`).
        sigma_mm: Declared position noise per coordinate, mm (> 0; weights only).
        sigma_rad: Declared joint noise per joint, rad (> 0; weights only).
        max_iter: Maximum accepted iterations per chain.
        xtol: Relative (column-scaled) step tolerance.
        ftol: Relative cost-change tolerance (LM only).

    Returns:
        A :class:`DeltaIdentificationResult`; ``iterations`` summed over chains, ``success``
        only if every chain converged, ``message`` per chain. ``covariance`` is block
        diagonal (chains are independent).

    Raises:
        ValueError: On malformed input.
    """
    q, positions, free = _check_common(initial, q, positions, free, solver, sigma_mm, sigma_rad, max_iter)
    n = q.shape[0]
    base = initial.to_vector()
    est = base.copy()
    dfdq = constraint_jacobian_joints(initial, q, positions)
    sigma = np.sqrt(sigma_mm**2 + (sigma_rad * dfdq) ** 2)  # (N, 3) mm
    cov = np.zeros((len(free), len(free)))
    wres = []
    iters, oks, msgs = 0, [], []
    for i in range(3):
        names_i = [nm for nm in free if nm.endswith(str(i + 1))]
        if not names_i:
            continue
        if n < len(names_i):
            raise ValueError(f"q must have at least {len(names_i)} configurations for chain {i + 1}, got {n}")
        idx = np.array([PARAMETER_NAMES.index(nm) for nm in names_i])
        local = idx - 8 * i

        def full(x, idx=idx):
            v = est.copy()
            v[idx] = x
            return DeltaParams.from_vector(v)

        def fun(x, i=i, full=full):
            return constraint_residuals(full(x), q, positions)[:, i] / sigma[:, i]

        def jac(x, i=i, full=full, local=local):
            return constraint_jacobian_params(full(x), q, positions)[:, i, :][:, local] / sigma[:, i, None]

        out = _solve(fun, jac, base[idx], solver, max_iter, xtol, ftol)
        est[idx] = out.x
        pos = [free.index(nm) for nm in names_i]
        cov[np.ix_(pos, pos)] = _covariance(out.jac)
        wres.append(out.r)
        iters += out.iterations
        oks.append(out.success)
        msgs.append(f"chain {i + 1}: {out.message}")
    estimate = DeltaParams.from_vector(est)
    res = constraint_residuals(estimate, q, positions)
    w = np.concatenate(wres) if wres else np.zeros(0)
    return DeltaIdentificationResult(
        estimate=estimate,
        free_names=free,
        residuals=res,
        weighted_residuals=w,
        covariance=cov,
        iterations=iters,
        success=all(oks),
        message="; ".join(msgs),
        method="ikm",
        solver=solver,
        cost=float(w @ w),
    )


# --------------------------------------------------------------------------- identifiability


def null_space_combinations(params: DeltaParams, q, *, rel_tol: float = 1e-9) -> list[dict[str, float]]:
    """Parameter combinations that position measurements cannot identify (FKM Jacobian SVD).

    The 24 columns are made comparable first (angles scaled by the nominal arm length, i.e.
    expressed as mm at the arm tip); singular values below ``rel_tol`` times the largest
    give the null space.

    Args:
        params: Parameters at which the Jacobian is evaluated.
        q: Joint readings of the configurations, shape (N, 3), rad (N >= 8).
        rel_tol: Relative singular-value threshold.

    Returns:
        One ``{name: coefficient}`` dict per chain whose parameters appear in the null space
        (each chain's closure involves only its own parameters, so the null space splits
        chain by chain; the dominant direction of each chain's block is returned),
        coefficients below 1e-6 dropped, normalised so that the largest is +1; units: mm
        for lengths, rad for angles.
    """
    _check_params(params)
    q = _as_array(q, "q", (-1, 3))
    if q.shape[0] < 8:
        raise ValueError(f"q must have at least 8 configurations, got {q.shape[0]}")
    if not (np.isfinite(rel_tol) and 0 < rel_tol < 1):
        raise ValueError(f"rel_tol must be in (0, 1), got {rel_tol}")
    scale = np.array([1.0 if u == "mm" else float(np.mean(np.hypot(params.Lax, params.Lay))) for u in PARAMETER_UNITS])
    jac = fk_jacobian_params(params, q).reshape(-1, 24) / scale
    _, s, vt = np.linalg.svd(jac)
    null = vt[s < rel_tol * s[0]] / scale  # back to mm / rad coordinates
    out = []
    for i in range(3):  # one basis vector per chain: project the null space onto each chain
        block = null[:, 8 * i : 8 * i + 8]
        if not np.any(np.abs(block) > 1e-9):
            continue
        u, _, _ = np.linalg.svd(block.T, full_matrices=False)
        v = u[:, 0]
        v = v / v[np.argmax(np.abs(v))]
        out.append({PARAMETER_NAMES[8 * i + k]: float(c) for k, c in enumerate(v) if abs(c) > 1e-6})
    return out


# --------------------------------------------------------------------------- gain G


@dataclasses.dataclass(frozen=True)
class GainReport:
    """Calibration gain G of paper Eq. (4.1), in percent.

    Attributes:
        names: Parameter names the gains refer to.
        per_parameter: ``100 (|Pr-Pn| - |Pr-Pc|) / |Pr-Pn|`` per parameter, shape (K,);
            NaN where the initial error ``|Pr-Pn|`` is exactly zero.
        mean: Mean of ``per_parameter`` (the paper's "percentage average of the gain on all
            parameters"), NaN entries ignored.
        norm: Eq. (4.1) with the vector norm over all listed parameters, lengths in mm and
            angles in degrees (the paper states errors as "mm/degrees").
    """

    names: tuple[str, ...]
    per_parameter: np.ndarray
    mean: float
    norm: float

    def as_dict(self) -> dict:
        """JSON-friendly dict: per-parameter gains by name, mean and norm (percent)."""
        return {
            "per_parameter": {n: (None if not np.isfinite(g) else float(g)) for n, g in zip(self.names, self.per_parameter)},
            "mean": float(self.mean),
            "norm": float(self.norm),
        }


def calibration_gain(
    true: DeltaParams,
    nominal: DeltaParams,
    calibrated: DeltaParams,
    names=DEFAULT_FREE,
    *,
    canonical: bool = True,
) -> GainReport:
    """Calibration gain G (paper Eq. 4.1) per parameter, averaged, and as a norm.

    Args:
        true: Real parameters ``Pr``.
        nominal: Initial (nominal) parameters ``Pn``.
        calibrated: Identified parameters ``Pc``.
        names: Parameters to score (default: the 21 identifiable ones).
        canonical: Compare the canonical (``Lay = 0``) representatives of the three sets,
            so that the unidentifiable arm-direction/offset combination does not count.

    Returns:
        A :class:`GainReport`.
    """
    for nm, p in (("true", true), ("nominal", nominal), ("calibrated", calibrated)):
        if not isinstance(p, DeltaParams):
            raise ValueError(f"{nm} must be a DeltaParams, got {type(p).__name__}")
    names = tuple(names)
    bad = [n for n in names if n not in PARAMETER_NAMES]
    if bad or not names:
        raise ValueError(f"names must be a non-empty subset of PARAMETER_NAMES, got unknown {bad}")
    sets = [true, nominal, calibrated]
    if canonical:
        sets = [canonical_params(p) for p in sets]
    idx = np.array([PARAMETER_NAMES.index(n) for n in names])
    pr, pn, pc = (p.to_vector()[idx] for p in sets)
    e0, e1 = np.abs(pr - pn), np.abs(pr - pc)
    with np.errstate(divide="ignore", invalid="ignore"):
        per = np.where(e0 > 0, 100.0 * (e0 - e1) / e0, np.nan)
    scale = np.array([1.0 if PARAMETER_UNITS[k] == "mm" else 180.0 / np.pi for k in idx])
    n0 = np.linalg.norm(scale * (pr - pn))
    n1 = np.linalg.norm(scale * (pr - pc))
    norm = 100.0 * (n0 - n1) / n0 if n0 > 0 else float("nan")
    mean = float(np.nanmean(per)) if np.any(np.isfinite(per)) else float("nan")
    return GainReport(names=names, per_parameter=per, mean=mean, norm=float(norm))


# --------------------------------------------------------------------------- simulation helpers


def perturb_params(params: DeltaParams, error_mm: float, error_rad: float, seed) -> DeltaParams:
    """Add uniformly distributed errors (the paper's simulated real robot).

    Args:
        params: Parameters to perturb (usually nominal).
        error_mm: Half-width of the uniform error on lengths, mm (>= 0).
        error_rad: Half-width of the uniform error on angles, rad (>= 0).
        seed: Seed for ``np.random.default_rng``.

    Returns:
        Perturbed parameters (all 24 entries perturbed, ``Lay`` included).
    """
    _check_params(params)
    for nm, v in (("error_mm", error_mm), ("error_rad", error_rad)):
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"{nm} must be finite and >= 0, got {v}")
    rng = np.random.default_rng(seed)
    half = np.array([error_mm if u == "mm" else error_rad for u in PARAMETER_UNITS])
    return DeltaParams.from_vector(params.to_vector() + rng.uniform(-1.0, 1.0, 24) * half)


def random_workspace_positions(
    n: int,
    seed,
    *,
    radius_mm: float = 150.0,
    z_range_mm: tuple[float, float] = (-500.0, -330.0),
) -> np.ndarray:
    """Plate-centre targets uniformly distributed in a vertical cylinder.

    Args:
        n: Number of positions (>= 1).
        seed: Seed for ``np.random.default_rng``.
        radius_mm: Cylinder radius, mm.
        z_range_mm: (low, high) z of the cylinder, mm, base frame.

    Returns:
        Shape (n, 3), mm, base frame.
    """
    if not (isinstance(n, (int, np.integer)) and n >= 1):
        raise ValueError(f"n must be a positive integer, got {n!r}")
    lo, hi = z_range_mm
    if not (radius_mm > 0 and lo < hi):
        raise ValueError(f"radius_mm must be > 0 and z_range_mm increasing, got {radius_mm}, {z_range_mm}")
    rng = np.random.default_rng(seed)
    r = radius_mm * np.sqrt(rng.uniform(0.0, 1.0, n))
    a = rng.uniform(0.0, 2 * np.pi, n)
    z = rng.uniform(lo, hi, n)
    return np.stack([r * np.cos(a), r * np.sin(a), z], axis=1)


@dataclasses.dataclass(frozen=True)
class DeltaDataset:
    """Simulated calibration data.

    Attributes:
        q_cmd: Commanded joint readings (IK of the nominal model), shape (N, 3), rad.
        positions_true: True plate positions (FK of the real model), shape (N, 3), mm.
        q_meas: Joint readings with noise, shape (N, 3), rad.
        positions_meas: Plate positions with noise, shape (N, 3), mm.
    """

    q_cmd: np.ndarray
    positions_true: np.ndarray
    q_meas: np.ndarray
    positions_meas: np.ndarray


def make_dataset(
    true: DeltaParams,
    nominal: DeltaParams,
    n: int,
    seed,
    *,
    noise_mm: float = 0.0,
    noise_rad: float = 0.0,
    radius_mm: float = 150.0,
    z_range_mm: tuple[float, float] = (-500.0, -330.0),
) -> DeltaDataset:
    """Simulate ``n`` measured configurations with the pure kinematic model.

    Targets are drawn in the workspace cylinder, commanded through the nominal inverse
    kinematics, and the real robot's plate position is its forward kinematics; Gaussian
    noise (standard deviations ``noise_mm`` per coordinate and ``noise_rad`` per joint) is
    added to the measurements. Targets the real robot cannot reach are redrawn.

    Args:
        true: Real parameters.
        nominal: Nominal parameters (controller model).
        n: Number of configurations (>= 1).
        seed: Seed for ``np.random.default_rng``.
        noise_mm: Position noise standard deviation, mm (>= 0).
        noise_rad: Joint noise standard deviation, rad (>= 0).
        radius_mm: Workspace cylinder radius, mm.
        z_range_mm: Workspace cylinder z range, mm.

    Returns:
        A :class:`DeltaDataset`.
    """
    _check_params(true)
    _check_params(nominal)
    for nm, v in (("noise_mm", noise_mm), ("noise_rad", noise_rad)):
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"{nm} must be finite and >= 0, got {v}")
    rng = np.random.default_rng(seed)
    qs, xs = [], []
    for _ in range(100):
        targets = random_workspace_positions(n, rng, radius_mm=radius_mm, z_range_mm=z_range_mm)
        for t in targets:
            try:
                qc = inverse_kinematics(nominal, t[None])
                xt = forward_kinematics(true, qc)
            except ValueError:
                continue
            qs.append(qc[0])
            xs.append(xt[0])
        if len(qs) >= n:
            break
    if len(qs) < n:
        raise ValueError(f"true: the real robot reaches fewer than n={n} workspace targets")
    q_cmd, x_true = np.array(qs[:n]), np.array(xs[:n])
    q_meas = q_cmd + rng.normal(0.0, 1.0, q_cmd.shape) * noise_rad
    x_meas = x_true + rng.normal(0.0, 1.0, x_true.shape) * noise_mm
    return DeltaDataset(q_cmd, x_true, q_meas, x_meas)
