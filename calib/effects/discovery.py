"""Discovery of left-out physics, written once over :class:`calib.robot.Robot`.

In joint space the measured pose gives, for chain i at measurement j, the closure residual of
the geometric model ``r_ij(theta) = F_i(theta, q_ij, QM_j)`` (mm; for a hexapod
``|R_j P_i + OP_j - B_i| - dl_i - l_ij``). An effect moves each joint by a known physical
regressor times unknown coefficients, ``dq = Xq . phi`` (:mod:`calib.effects.base`), and the
joint fit makes ``F(theta, q + Xq phi, QM)`` vanish to the noise: exactly, not only to first
order (to first order the effect adds ``X phi``, ``X = -dF/dq Xq``, to the residual; for a
hexapod, whose closure is linear in the leg length, the two are the same).
The noise of ``r_j`` (C chains) comes from the pose sensor and the joint readings through the
closure Jacobians, ``S_j = dF/dpose Sigma_pose dF/dpose^T + dF/dq Sigma_q dF/dq^T``; every fit
is whitened by it (mm and rad never mixed by a raw norm), so that the sum of squares is
chi-square distributed when the model is right. The geometry fitted with the effect is the
robot's free parameters (``robot.free_default``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2 as chi2_dist

from ..robot import KinematicsError, Robot
from . import EFFECTS, effect as registered, effects_for
from .base import Effect, EffectData, closure_regressors

__all__ = ["MIN_DELTA_BIC", "MIN_ROWS", "EffectFit", "Discovery", "fit_effect", "discover_effect", "locate_mismatch",
           "closure_noise_covariance", "closure_noise_std"]

#: Evidence an effect needs over geometry alone: BIC lower by at least this ("very strong" on
#: the Kass-Raftery scale; a chance reduction of a one-parameter effect's chi-square by 16 has
#: probability 5e-5).
MIN_DELTA_BIC = 10.0
#: Fewest measurements a discovery accepts.
MIN_ROWS = 12


def closure_noise_covariance(robot: Robot, theta: np.ndarray, data: EffectData) -> np.ndarray:
    """(N, C, C) covariance of each measurement's closure residuals caused by the declared
    noise: pose sensor noise and joint-reading noise through the closure Jacobians, mm^2."""
    jac = robot.closure_jacobians(theta, data.joints, data.measured)
    var = data.noise.pose_std(robot.pose_units) ** 2
    S = np.einsum("nik,k,njk->nij", jac.pose, var, jac.pose)
    if data.noise.joint_std > 0:
        S += data.noise.joint_std ** 2 * jac.joints @ np.swapaxes(jac.joints, 1, 2)
    return S


def closure_noise_std(robot: Robot, theta: np.ndarray, data: EffectData) -> np.ndarray:
    """(N, C) mm, standard deviation of each closure residual caused by the declared noise."""
    return np.sqrt(np.diagonal(closure_noise_covariance(robot, theta, data), axis1=1, axis2=2))


def _whitening(robot: Robot, theta: np.ndarray, data: EffectData) -> np.ndarray:
    """(N, C, C) ``L^-1``, ``L`` the Cholesky factor of each measurement's closure noise
    covariance: ``L^-1 r`` has unit covariance."""
    return np.linalg.inv(np.linalg.cholesky(closure_noise_covariance(robot, theta, data)))


def _whiten(winv: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``L^-1 v`` measurement by measurement; ``v`` is (N, C) or (N, C, k)."""
    if v.ndim == 2:
        return np.einsum("nij,nj->ni", winv, v)
    return winv @ v


def _free_indices(robot: Robot) -> np.ndarray:
    return np.sort(robot.table.indices(robot.free_default))


@dataclass(frozen=True, eq=False)
class EffectFit:
    """Geometry and one effect fitted jointly (whitened by the declared noise).

    Attributes:
        model: the effect fitted (its ``name`` is :attr:`effect`).
        robot: the robot.
        theta: (P,) identified parameters.
        coefficients: (p,) effect coefficients (see ``Effect.coefficients``).
        coefficient_std: (p,) their standard uncertainties (declared noise, inflated by the
            reduced chi-square when it exceeds 1).
        extra: the searched parameter's value (e.g. the screw pitch), else None.
        residuals: (N, C) mm, closure residuals after the fit.
        whitened: (N, C) whitened residuals (unit variance under the declared noise).
        chi2: sum of squares of ``whitened``; dof = N C - n_params.
        n_params: free geometric parameters + p (+1 for a searched parameter).
    """

    model: Effect
    robot: Robot
    theta: np.ndarray
    coefficients: np.ndarray
    coefficient_std: np.ndarray
    extra: float | None
    residuals: np.ndarray
    whitened: np.ndarray
    chi2: float
    n_params: int

    @property
    def effect(self) -> str:
        """The effect's name."""
        return self.model.name

    @property
    def errors(self) -> np.ndarray:
        """(P,) identified parameters minus the robot's nominal ones."""
        return self.theta - self.robot.table.nominal

    @property
    def dof(self) -> int:
        return int(self.residuals.size - self.n_params)

    @property
    def p_value(self) -> float:
        """Probability of a chi-square this large if the model were right."""
        return float(chi2_dist.sf(self.chi2, self.dof))

    def bic(self) -> float:
        """Bayesian information criterion (chi-square + n_params ln n_residuals)."""
        return float(self.chi2 + self.n_params * np.log(self.residuals.size))

    def aic(self) -> float:
        return float(self.chi2 + 2 * self.n_params)

    def named_coefficients(self) -> dict:
        """``{name: {"value", "std", "unit"}}`` plus the searched parameter when there is one."""
        eff = self.model
        out = {c.name: {"value": float(v), "std": float(s), "unit": c.unit}
               for c, v, s in zip(eff.coefficients(self.robot), self.coefficients, self.coefficient_std)}
        if self.extra is not None:
            out[eff.searched.name] = {"value": float(self.extra), "std": float("nan"), "unit": eff.searched.unit}
        return out

    def predict(self, data: EffectData) -> tuple[np.ndarray, np.ndarray]:
        """(N, C) residuals (mm) and whitened residuals of this fitted model on other data."""
        Xq = self.model.joint_regressors(self.robot, self.theta, data, self.extra)
        r = self.robot.closure(self.theta, data.joints + Xq @ self.coefficients, data.measured)
        return r, _whiten(_whitening(self.robot, self.theta, data), r)


def _design(eff: Effect, theta: np.ndarray, coef: np.ndarray, data: EffectData, free: np.ndarray, extra):
    """Closure residuals (N, C) with the effect's joint displacement applied, and their
    derivatives (N, C, free + p): geometry columns, then the effect's."""
    robot = data.robot
    Xq = eff.joint_regressors(robot, theta, data, extra)
    joints = data.joints + Xq @ coef
    r = robot.closure(theta, joints, data.measured)
    jac = robot.closure_jacobians(theta, joints, data.measured)
    return r, np.concatenate([jac.parameters[:, :, free], jac.joints @ Xq], axis=-1)


def _solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    x, *_ = np.linalg.lstsq(A / scale, b, rcond=None)
    return x / scale


def _check_applies(eff: Effect, robot: Robot) -> None:
    if not eff.applies_to(robot):
        raise ValueError(f"effect {eff.name!r} does not apply to the {robot.name}: "
                         f"{' '.join((type(eff).__doc__ or '').split())}")


def fit_effect(data: EffectData, effect: str | Effect, *, extra: float | None = None, iterations: int = 3,
               start: np.ndarray | None = None) -> EffectFit:
    """Fit the robot's free geometric parameters and an effect's coefficients jointly
    (whitened Gauss-Newton).

    Args:
        data: the measurements.
        effect: a registered name or an :class:`Effect`.
        extra: the searched parameter's value (e.g. the screw pitch); None searches it.
        iterations: Gauss-Newton iterations (the problem is nearly linear near the nominal).
        start: (P,) starting parameters (default ``data.theta``).

    Raises:
        ValueError: unknown effect, or one that does not apply to the robot (says why).
    """
    eff = registered(effect)
    robot = data.robot
    _check_applies(eff, robot)
    free = _free_indices(robot)
    searched = False
    if eff.searched is not None and extra is None:
        base = start if start is not None else fit_effect(data, EFFECTS["none"]).theta
        extra = _search(eff, data, base, free)
        searched = True
        start = base
    theta = np.array(data.theta if start is None else start, dtype=float)
    winv = _whitening(robot, theta, data)
    g = free.size
    coef = np.zeros(len(eff.coefficients(robot)))
    for _ in range(iterations):
        r, D = _design(eff, theta, coef, data, free, extra)
        x = _solve(_whiten(winv, D).reshape(-1, D.shape[-1]), -_whiten(winv, r).ravel())
        theta[free] += x[:g]
        coef = coef + x[g:]
    resid, D = _design(eff, theta, coef, data, free, extra)
    w = _whiten(winv, resid)
    chi2 = float(np.sum(w ** 2))
    A = _whiten(winv, D).reshape(-1, D.shape[-1])
    n_params = D.shape[-1] + (1 if searched else 0)
    dof = resid.size - n_params
    cov = np.linalg.pinv(A.T @ A) * max(1.0, chi2 / max(dof, 1))
    std = np.sqrt(np.clip(np.diag(cov)[g:], 0, None))
    return EffectFit(eff, robot, theta, coef, std, extra, resid, w, chi2, n_params)


def _search(eff: Effect, data: EffectData, base: np.ndarray, free: np.ndarray) -> float:
    """The searched parameter minimising the chi-square of the linearised joint fit: on the
    effect's grid of the search coordinate, refined by golden-section search between the best
    grid point's neighbours."""
    robot = data.robot
    winv = _whitening(robot, base, data)
    dF_dq = robot.closure_jacobians(base, data.joints, data.measured).joints
    r, D = _design(EFFECTS["none"], base, np.zeros(0), data, free, None)
    Ag = _whiten(winv, D).reshape(-1, D.shape[-1])
    b = -_whiten(winv, r).ravel()
    # Project the geometry out once; each value then costs one small least-squares problem.
    Q, _ = np.linalg.qr(Ag / np.linalg.norm(Ag, axis=0))
    b_perp = b - Q @ (Q.T @ b)

    def cost(u):
        X = closure_regressors(dF_dq, eff.joint_regressors(robot, base, data, eff.searched_value(u)))
        Xw = _whiten(winv, X).reshape(-1, X.shape[-1])
        Xp = Xw - Q @ (Q.T @ Xw)
        x, *_ = np.linalg.lstsq(Xp, b_perp, rcond=None)
        e = b_perp - Xp @ x
        return float(e @ e)

    grid = eff.search_grid(data)
    costs = np.array([cost(u) for u in grid])
    k = int(np.argmin(costs))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    g = (np.sqrt(5) - 1) / 2
    a, b_ = lo, hi
    c, d = b_ - g * (b_ - a), a + g * (b_ - a)
    fc, fd = cost(c), cost(d)
    for _ in range(40):
        if fc < fd:
            b_, d, fd = d, c, fc
            c = b_ - g * (b_ - a)
            fc = cost(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b_ - a)
            fd = cost(d)
    return eff.searched_value((a + b_) / 2)


@dataclass(frozen=True, eq=False)
class Discovery:
    """The outcome of :func:`discover_effect`.

    Attributes:
        effect: the chosen effect (``"none"`` when geometry explains the data).
        fits: every candidate's joint fit on the rows kept, by name.
        evidence: per candidate: chi2, dof, p-value, BIC, delta BIC to geometry only,
            cross-validated whitened RMS; and the geometry-only chi-square test.
        chosen: the chosen fit.
        flagged: indices of rows removed as outliers (gross errors, not physics).
        kept: indices of the rows used.
        located: where the geometry-only residuals concentrate (:func:`locate_mismatch`).
        adequate: whether the chosen model passes the chi-square test.
    """

    effect: str
    fits: dict
    evidence: dict
    chosen: EffectFit
    flagged: tuple
    kept: np.ndarray
    located: dict
    adequate: bool


def _cv_rms(data: EffectData, effect: Effect, folds: int, seed: int, extra: float | None) -> float:
    order = np.random.default_rng(seed).permutation(data.n)
    ss, cnt = 0.0, 0
    for k in range(folds):
        test = np.sort(order[k::folds])
        train = np.setdiff1d(np.arange(data.n), test)
        fit = fit_effect(data.subset(train), effect, extra=extra)
        _, w = fit.predict(data.subset(test))
        ss += float(np.sum(w ** 2))
        cnt += w.size
    return float(np.sqrt(ss / cnt))


def discover_effect(data: EffectData, *, candidates=None, alpha: float = 0.01, outlier_alpha: float = 1e-3,
                    folds: int = 5, seed: int = 0, max_outliers: int = 5,
                    min_delta_bic: float = MIN_DELTA_BIC) -> Discovery:
    """Locate the mismatch, name the left-out physics, and fit it.

    1. Gross rows: under the best model, a row whose whitened chi-square (C dof) exceeds the
       Bonferroni-corrected ``outlier_alpha`` is removed as an outlier and everything is redone
       (a physical effect is smooth over the workspace and cannot explain one wild row).
    2. Each candidate is fitted jointly with the geometry; the one with the lowest BIC is
       chosen if its BIC is at least ``min_delta_bic`` below that of geometry alone and it also
       lowers the cross-validated residual (``folds``-fold): a richer model must earn its
       parameters twice. Otherwise ``none``. (The omnibus chi-square test of geometry alone,
       at ``alpha``, is reported as evidence and decides ``adequate``; against one specific
       alternative such as a drift in time it is much weaker than the comparison of models.)

    Args:
        data: the measurements.
        candidates: effects to consider, registered names or :class:`Effect` objects
            (``"none"`` is always included); default every registered effect that applies to
            the robot.
        alpha: significance of the geometry-only chi-square test.
        outlier_alpha: family-wise significance of the outlier test.
        folds, seed: cross-validation.
        max_outliers: at most this many rows are removed.

    Raises:
        ValueError: too few rows, an unknown candidate or one that does not apply to the robot.
    """
    robot = data.robot
    if candidates is None:
        candidates = effects_for(robot)
    models = {e.name: e for e in [EFFECTS["none"]] + [registered(c) for c in candidates]}
    cands = tuple(models)
    for c in cands:
        _check_applies(models[c], robot)
    if data.n < MIN_ROWS:
        raise ValueError(f"effect discovery needs at least {MIN_ROWS} measurements, got {data.n}")
    kept = np.arange(data.n)
    flagged: list[int] = []
    while True:
        sub = data.subset(kept)
        fits = {c: fit_effect(sub, models[c]) for c in cands}
        geo = fits["none"]
        effect = min(cands, key=lambda c: fits[c].bic())
        if fits[effect].bic() > geo.bic() - min_delta_bic:
            effect = "none"
        per_pose = np.sum(fits[effect].whitened ** 2, axis=1)
        thr = float(chi2_dist.isf(outlier_alpha / kept.size, robot.n_chains))
        worst = int(np.argmax(per_pose))
        if per_pose[worst] > thr and len(flagged) < max_outliers and kept.size > MIN_ROWS:
            flagged.append(int(kept[worst]))
            kept = np.delete(kept, worst)
            continue
        break
    sub = data.subset(kept)
    evidence = {"geometry_chi2_test": {"chi2": geo.chi2, "dof": geo.dof, "p_value": geo.p_value, "alpha": alpha}}
    cv = {}
    for c in cands:
        f = fits[c]
        cv[c] = _cv_rms(sub, models[c], folds, seed, f.extra)
        evidence[c] = {"chi2": f.chi2, "dof": f.dof, "p_value": f.p_value, "n_params": f.n_params, "bic": f.bic(),
                       "delta_bic_vs_none": f.bic() - geo.bic(), "aic": f.aic(), "cv_whitened_rms": cv[c]}
    if effect != "none" and not cv[effect] < cv["none"]:
        effect = "none"
    chosen = fits[effect]
    return Discovery(effect=effect, fits=fits, evidence=evidence, chosen=chosen, flagged=tuple(sorted(flagged)),
                     kept=kept, located=locate_mismatch(sub, geo), adequate=chosen.p_value > alpha)


def _rms(v: np.ndarray, axis=None):
    return np.sqrt(np.mean(v ** 2, axis=axis))


def locate_mismatch(data: EffectData, geometry_fit: EffectFit) -> dict:
    """Where the residuals of the geometry-only fit concentrate.

    Joint space: RMS of the standardised closure residuals per chain. Task space: RMS of
    ``measured - FK(identified, q_cmd)`` per pose coordinate over its declared standard
    deviation (NaN where the forward kinematics fails). Workspace: for each pose coordinate,
    the per-pose residual RMS in its lower and upper thirds. Time: in the first, middle and last
    thirds of the record. Direction of motion: the mean residual of chains whose joint last
    increased minus that of chains whose joint last decreased, in standard errors (hysteresis
    shows here).

    Returns:
        JSON-ready dict; ``summary`` holds the findings in words.
    """
    robot, theta = data.robot, geometry_fit.theta
    z = geometry_fit.residuals / closure_noise_std(robot, theta, data)  # standardised closure residuals
    per_chain = _rms(z, axis=0)
    try:
        pred = robot.forward_kinematics(theta, data.joints, initial=data.measured)
        per_dof = _rms((data.measured - pred) / data.noise.pose_std(robot.pose_units), axis=0)
    except KinematicsError:
        per_dof = np.full(robot.pose_dim, np.nan)
    per_pose = _rms(z, axis=1)
    region = {}
    for k, name in enumerate(robot.pose_names):
        q = np.quantile(data.measured[:, k], [1 / 3, 2 / 3])
        lo, hi = data.measured[:, k] <= q[0], data.measured[:, k] >= q[1]
        region[name] = {"low_third_rms": float(_rms(per_pose[lo])), "high_third_rms": float(_rms(per_pose[hi]))}
    thirds = np.array_split(np.argsort(data.t_s), 3)
    time_rms = [float(_rms(per_pose[s])) for s in thirds]
    tc = np.corrcoef(data.t_s, z.mean(axis=1))[0, 1] if np.ptp(data.t_s) > 0 else 0.0
    up, down = z[data.direction > 0], z[data.direction < 0]
    if up.size > 1 and down.size > 1:
        hyst = float((up.mean() - down.mean()) / np.sqrt(up.var() / up.size + down.var() / down.size))
    else:
        hyst = 0.0
    worst = int(np.argmax(per_chain))
    reg_name, reg = max(region.items(), key=lambda kv: abs(kv[1]["high_third_rms"] - kv[1]["low_third_rms"]))
    chain = robot.chain_word
    summary = [
        f"joint space: residual RMS per {chain} {', '.join(f'{v:.2f}' for v in per_chain)} (in noise standard "
        f"deviations); largest on {chain} {worst + 1}",
        f"task space: RMS per coordinate {' '.join(robot.pose_names)} {', '.join(f'{v:.2f}' for v in per_dof)} "
        f"(noise standard deviations)",
        f"workspace: largest contrast along {reg_name}: low third {reg['low_third_rms']:.2f}, "
        f"high third {reg['high_third_rms']:.2f}",
        f"time: RMS in first/middle/last third {', '.join(f'{v:.2f}' for v in time_rms)}; correlation of the "
        f"mean residual with time {tc:+.2f}",
        f"direction of motion: {chain}s whose joint last increased minus those whose joint last decreased: "
        f"{hyst:+.1f} standard errors",
    ]
    return {
        "joint_space_rms_per_chain": per_chain.tolist(),
        "task_space_rms_per_dof": dict(zip(robot.pose_names, per_dof.tolist())),
        "workspace_thirds": region,
        "time_thirds_rms": time_rms,
        "time_correlation": float(tc),
        "direction_contrast_se": hyst,
        "worst_poses": [int(i) for i in np.argsort(per_pose)[::-1][:5]],
        "summary": summary,
    }
