"""The joint-space fit of the geometry and the effects (a room of :mod:`calib.effects.discovery`).

In joint space the measured pose gives, for chain i at measurement j, the closure residual of
the geometric model ``r_ij(theta) = F_i(theta, q_ij, QM_j)`` (mm; for a hexapod
``|R_j P_i + OP_j - B_i| - dl_i - l_ij``). An effect moves each joint by a known physical
regressor times unknown coefficients, ``dq = Xq . phi`` (:mod:`calib.effects.base`), and the
joint fit makes ``F(theta, q + Xq phi, QM)`` vanish to the noise: exactly, not only to first
order (to first order the effect adds ``X phi``, ``X = -dF/dq Xq``, to the residual; for a
hexapod, whose closure is linear in the leg length, the two are the same). Several effects fit
together simply concatenate their regressors. Every fit is whitened by the declared noise
(:mod:`calib.effects.whitening`). The geometry fitted with the effects is the robot's free
parameters (``robot.free_default``).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2 as chi2_dist

from ..engine import newton_offset
from ..robot import Robot
from .base import Effect, EffectData, orthonormal_columns
from .granularity import shared_form
from .registry import EFFECTS, effect as registered
from .search import LinearisedFit
from .separability import GRAM_MIN_RESIDUALS, GeometryBasis
from .whitening import (free_indices, geometry_basis_of, noise_covariance, scaled_least_squares, whiten,
                        whitening_matrices)

__all__ = ["GN_ITERATIONS", "GN_TOLERANCE", "EffectFit", "fit_effects", "fit_effect", "as_models", "check_applies",
           "model_poses", "span_bases", "release_span_bases"]

#: Gauss-Newton iterations at most; stops when an iteration lowers the chi-square by less than
#: :data:`GN_TOLERANCE`.
GN_ITERATIONS = 30
GN_TOLERANCE = 1e-6


def as_models(effects) -> tuple[Effect, ...]:
    """A model: a registered name, an :class:`Effect` or a sequence of them; ``none`` dropped."""
    if effects is None:
        return ()
    if isinstance(effects, (str, Effect)):
        effects = (effects,)
    models = tuple(registered(e) for e in effects)
    names = [m.name for m in models]
    if len(set(names)) != len(names):
        raise ValueError(f"an effect appears twice in {names}")
    return tuple(m for m in models if m.name != "none")


def check_applies(eff: Effect, robot: Robot) -> None:
    if not eff.applies_to(robot):
        raise ValueError(f"effect {eff.name!r} does not apply to the {robot.name}: "
                         f"{' '.join((type(eff).__doc__ or '').split())}")


@dataclass(frozen=True, eq=False)
class EffectFit:
    """Geometry and zero or more effects fitted jointly (whitened by the declared noise).

    Attributes:
        models: the effects fitted (empty: geometry alone).
        robot: the robot.
        theta: (P,) identified parameters.
        coefficients: (p,) the effects' coefficients, concatenated in the order of ``models``.
        coefficient_std: (p,) their standard uncertainties (declared noise, inflated by the
            reduced chi-square when it exceeds 1).
        extras: each model's searched parameter (e.g. the screw pitch), or None.
        residuals: (N, C) mm, closure residuals after the fit.
        whitened: (N, C) whitened residuals (unit variance under the declared noise).
        chi2: sum of squares of ``whitened``; dof = N C - n_params.
        n_params: free geometric parameters + p (+1 per searched parameter).
        design: (N C, g + p) whitened derivatives of the residuals at the solution (the
            hat matrix of the leave-one-out tests): g geometric columns, the free parameters or,
            with a prior, the combinations the rows determine (``basis``).
        coefficient_cov: (p, p) covariance of ``coefficients`` (same inflation as the std).
        basis: the geometric combinations fitted and those held at the prior mean
            (:class:`calib.effects.separability.GeometryBasis`), or None: every free parameter fitted.
        held_design: (N C, F - g) whitened derivatives of the residuals along the held
            combinations (per tolerance), or None.
    """

    models: tuple
    robot: Robot
    theta: np.ndarray
    coefficients: np.ndarray
    coefficient_std: np.ndarray
    extras: tuple
    residuals: np.ndarray
    whitened: np.ndarray
    chi2: float
    n_params: int
    design: np.ndarray = field(repr=False, default=None)
    coefficient_cov: np.ndarray = field(repr=False, default=None)
    basis: GeometryBasis | None = field(repr=False, default=None)
    held_design: np.ndarray | None = field(repr=False, default=None)

    @property
    def effects(self) -> tuple[str, ...]:
        """Names of the effects fitted."""
        return tuple(m.name for m in self.models)

    @property
    def effect(self) -> str:
        """``"none"``, the one effect's name, or the names joined by ``+``."""
        return "+".join(self.effects) or "none"

    @property
    def model(self) -> Effect:
        """The single effect fitted (``none`` for geometry alone)."""
        if len(self.models) > 1:
            raise ValueError(f"the fit holds several effects: {self.effects}")
        return self.models[0] if self.models else EFFECTS["none"]

    @property
    def extra(self) -> float | None:
        """The single effect's searched parameter."""
        return self.extras[0] if len(self.extras) == 1 else None

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

    @property
    def span(self) -> np.ndarray:
        """(N C, k) the columns whatever the model could explain lies in: :attr:`design` and,
        with held geometric combinations, theirs (the remainder's tests project them out: what a
        held combination could explain is no evidence of anything else; the outlier scan takes
        :attr:`design` alone, the columns fitted)."""
        return self.design if self.held_design is None else np.hstack([self.design, self.held_design])

    def slices(self) -> dict:
        """name -> slice of each effect's coefficients in :attr:`coefficients`."""
        out, k = {}, 0
        for m in self.models:
            p = len(m.coefficients(self.robot))
            out[m.name] = slice(k, k + p)
            k += p
        return out

    def significance(self, name: str) -> dict:
        """Wald test that effect ``name``'s coefficients are zero: ``{"wald_chi2", "dof",
        "p_value"}`` (of those the effect names as its evidence, ``evidence_coefficients``, where
        it names some: a compliance at several payloads is tested on its payload terms)."""
        s = self.slices()[name]
        idx = np.arange(s.start, s.stop)
        model = next(m for m in self.models if m.name == name)
        evidence = getattr(shared_form(model), "evidence_coefficients", ())
        if evidence:  # the coefficients whose being non-zero is the effect's evidence
            names = [c.name.split("[")[0] for c in model.coefficients(self.robot)]
            idx = idx[[n in evidence for n in names]]
        phi = self.coefficients[idx]
        cov = self.coefficient_cov[np.ix_(idx, idx)]
        w = float(phi @ np.linalg.pinv(cov, hermitian=True) @ phi)
        return {"wald_chi2": w, "dof": int(phi.size), "p_value": float(chi2_dist.sf(w, phi.size))}

    def parameters(self) -> dict:
        """``{effect: {coefficient: {"value", "std", "unit"}}}``, with the searched parameter
        where there is one, each effect's significance under ``"significance"`` and its form
        under ``"granularity"`` (``"shared"`` or ``"per_chain"``: a per-chain form's
        coefficients are named by chain, ``dead_band[leg 3]``)."""
        out = {}
        for m, extra in zip(self.models, self.extras):
            s = self.slices()[m.name]
            d = {c.name: {"value": float(v), "std": float(sd), "unit": c.unit}
                 for c, v, sd in zip(m.coefficients(self.robot), self.coefficients[s], self.coefficient_std[s])}
            if extra is not None:
                d.update({k: {"value": v, "std": float("nan"), "unit": u} for k, (v, u) in m.searched_values(extra).items()})
            d["significance"] = self.significance(m.name)
            d["granularity"] = m.granularity
            out[m.name] = d
        return out

    def named_coefficients(self) -> dict:
        """``{name: {"value", "std", "unit"}}`` of every effect's coefficients (and searched
        parameters), flat."""
        out = {}
        for d in self.parameters().values():
            out.update({k: v for k, v in d.items() if k not in ("significance", "granularity")})
        return out

    def geometry_covariance(self) -> np.ndarray:
        """(P, P) covariance of :attr:`theta` (the free parameters', jointly with the effects'
        coefficients and marginalised over them; zero rows and columns for the fixed ones), with
        the same inflation as :attr:`coefficient_cov`."""
        A = self.design
        scale = np.linalg.norm(A, axis=0)
        scale[scale == 0] = 1.0
        cov = np.linalg.pinv((A / scale).T @ (A / scale), hermitian=True) / np.outer(scale, scale)
        cov = cov * max(1.0, self.chi2 / max(self.dof, 1))
        free = free_indices(self.robot)
        out = np.zeros((self.robot.n_parameters,) * 2)
        if self.basis is None:
            out[np.ix_(free, free)] = cov[:free.size, :free.size]
        else:  # the held combinations with the prior's covariance
            g = self.basis.size
            out[np.ix_(free, free)] = self.basis.covariance(cov[:g, :g])
        return out

    def joint_displacement(self, data: EffectData) -> np.ndarray:
        """(N, C) joint displacement of the fitted effects on ``data``, joint unit."""
        if not self.models:
            return np.zeros_like(data.joints)
        return _joint_regressors(self.models, self.theta, data, self.extras) @ self.coefficients

    def predict(self, data: EffectData) -> tuple[np.ndarray, np.ndarray]:
        """(N, C) residuals (mm) and whitened residuals of this fitted model on other data."""
        r = self.robot.closure(self.theta, data.joints + self.joint_displacement(data), data.measured)
        return r, whiten(whitening_matrices(self.robot, self.theta, data), r)


def _joint_regressors(models, theta, data: EffectData, extras) -> np.ndarray:
    """(N, C, p) the effects' joint regressors, concatenated in the order of ``models``."""
    if not models:
        return np.zeros((data.n, data.robot.n_chains, 0))
    return np.concatenate([m.joint_regressors(data.robot, theta, data, e) for m, e in zip(models, extras)], axis=-1)


def model_poses(robot: Robot, theta: np.ndarray, joints: np.ndarray, measured: np.ndarray,
                 basis: GeometryBasis | None, r: np.ndarray | None = None) -> np.ndarray:
    """(N, D) the poses the discovery's columns and quantities are taken at: the poses the model
    ``theta`` reaches at ``joints`` where ``basis`` holds combinations, else ``measured`` itself.

    A combination held because the poses barely show it (a level grid) moves the closure at those
    poses by less than the measurement's noise moves its derivative: at the *measured* poses its
    column is mostly the noise (a tilt of 1.5 mrad read on a level grid changes it more than the
    combination's own effect does), and so are the weakly determined columns' small parts and
    what the geometry leaves of a quantity read from the measured poses (a position, the load of
    a statics at that pose). Columns built of the noise absorb the noise (errors in the
    variables): on a level grid with nothing but noise the 24 held columns took 274 of a
    chi-square of 515 (24 expected), and the remainder's tests, which project them out, found
    structure in stroke, load and position at p = 1e-13 to 1e-77 in what was white. The poses the
    model reaches are the measured ones moved by one Newton step of the closure,
    ``m - (dF/dpose)^-1 F``: the noise removed to first order (what is left is of order
    ``noise^2 / machine size``). A pose set that determines every combination keeps the measured
    poses (its columns dwarf their noise). ``r``: the closure at ``measured``, where the caller
    has it."""
    if basis is None or basis.held.shape[1] == 0:
        return measured
    if r is None:
        r, pose_jacobian = robot.closure_and_pose_jacobian(theta, joints, measured)
    else:
        pose_jacobian = robot.closure_pose_jacobian(theta, joints, measured)
    offset = newton_offset(pose_jacobian, r)
    return measured - offset if np.all(np.isfinite(offset)) else measured  # a singular pose: as measured


def _design(models, theta, coef, data: EffectData, free: np.ndarray, extras, basis: GeometryBasis | None = None):
    """Closure residuals (N, C) with the effects' joint displacement applied, their derivatives
    (N, C, g + p) (geometry columns: the free parameters', or the determined combinations' of
    ``basis``; then the effects'), and the closure Jacobians (at the model's poses where
    ``basis`` holds combinations: :func:`model_poses`)."""
    robot = data.robot
    Xq = _joint_regressors(models, theta, data, extras)
    joints = data.joints + Xq @ coef
    r = robot.closure(theta, joints, data.measured)
    jac = robot.closure_jacobians(theta, joints, model_poses(robot, theta, joints, data.measured, basis, r))
    geo = jac.parameters[:, :, free] if basis is None else jac.parameters[:, :, free] @ basis.step
    return r, np.concatenate([geo, jac.joints @ Xq], axis=-1), jac


def fit_effects(data: EffectData, effects=(), *, extras=None, iterations: int = GN_ITERATIONS,
                start: np.ndarray | None = None) -> EffectFit:
    """Fit the robot's free geometric parameters and several effects' coefficients jointly
    (whitened Gauss-Newton, to convergence). With a prior (``data.tolerance``) the geometric
    combinations the rows leave to it are held at ``data.theta`` and the others fitted
    (:mod:`calib.effects.separability`).

    Args:
        data: the measurements.
        effects: registered names or :class:`Effect` objects (empty: geometry alone).
        extras: ``{name: value}`` of searched parameters (e.g. the screw pitch); a searched
            parameter not given is searched (the other effects' columns projected out).
        iterations: Gauss-Newton iterations at most.
        start: (P,) starting parameters (default ``data.theta``).

    Raises:
        ValueError: unknown effect, or one that does not apply to the robot (says why).
    """
    models = as_models(effects)
    robot = data.robot
    for m in models:
        check_applies(m, robot)
    free = free_indices(robot)
    extras = dict(extras or {})
    n_searched = sum(m.searched is not None for m in models)
    missing = [m for m in models if m.searched is not None and extras.get(m.name) is None]
    if missing:
        geo = fit_effects(data, (), start=start)
        lin = LinearisedFit(data, geo)
        fixed = [lin.columns(m, None) for m in models if m.searched is None]
        for m in missing:
            extras[m.name] = lin.search(m, fixed)
            fixed.append(lin.columns(m, extras[m.name]))
        start = geo.theta
    ex = tuple(extras.get(m.name) if m.searched is not None else None for m in models)
    theta = np.array(data.theta if start is None else start, dtype=float)
    basis = geometry_basis_of(data)
    if basis is not None:
        theta = basis.hold(theta, data.theta)
    g = free.size if basis is None else basis.size
    coef = np.zeros(sum(len(m.coefficients(robot)) for m in models))
    for _ in range(max(int(iterations), 1)):
        r, D, jac = _design(models, theta, coef, data, free, ex, basis)
        winv = np.linalg.inv(np.linalg.cholesky(noise_covariance(robot, jac, data)))
        A = whiten(winv, D).reshape(-1, D.shape[-1])
        x = scaled_least_squares(A, -whiten(winv, r).ravel())
        theta[free] += x[:g] if basis is None else basis.step @ x[:g]
        coef = coef + x[g:]
        if float(np.sum((A @ x) ** 2)) < GN_TOLERANCE:
            break
    resid, D, jac = _design(models, theta, coef, data, free, ex, basis)
    winv = np.linalg.inv(np.linalg.cholesky(noise_covariance(robot, jac, data)))
    w = whiten(winv, resid)
    chi2 = float(np.sum(w ** 2))
    A = whiten(winv, D).reshape(-1, D.shape[-1])
    n_params = D.shape[-1] + n_searched
    dof = resid.size - n_params
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    cov = np.linalg.pinv((A / scale).T @ (A / scale), hermitian=True) / np.outer(scale, scale)
    cov = cov * max(1.0, chi2 / max(dof, 1))
    ccov = cov[g:, g:]
    std = np.sqrt(np.clip(np.diag(ccov), 0, None))
    held = None if basis is None else whiten(winv, jac.parameters[:, :, free] @ basis.held_step).reshape(A.shape[0], -1)
    return EffectFit(models, robot, theta, coef, std, ex, resid, w, chi2, n_params, A, ccov, basis, held)


def fit_effect(data: EffectData, effect: str | Effect = "none", *, extra: float | None = None,
               iterations: int = GN_ITERATIONS, start: np.ndarray | None = None) -> EffectFit:
    """Fit the robot's free geometric parameters and one effect's coefficients jointly
    (:func:`fit_effects` with one effect; ``extra`` its searched parameter, None searches it)."""
    models = as_models(effect)
    extras = {models[0].name: extra} if models and extra is not None else None
    return fit_effects(data, models, extras=extras, iterations=iterations, start=start)


_SPANS: "weakref.WeakKeyDictionary[EffectFit, tuple]" = weakref.WeakKeyDictionary()


def span_bases(fit: "EffectFit") -> tuple[np.ndarray, np.ndarray | None]:
    """``(Q, Q_det)`` orthonormal bases of ``fit.span`` (what the model could explain, the held
    geometric combinations' columns too) and of ``fit.design`` (None without held combinations),
    computed once per fit (the outlier scan and the remainder's tests share them). Above
    :data:`GRAM_MIN_RESIDUALS` residuals ``Q`` is ``[Q_det, the held columns' remainder]``, so
    that one product with ``Q`` gives both projections (:meth:`calib.effects.remainder._Remainder.f_test`)."""
    if fit not in _SPANS:
        if fit.held_design is None:
            _SPANS[fit] = (orthonormal_columns(fit.design), None)
        elif fit.design.shape[0] > GRAM_MIN_RESIDUALS:
            Q_det = orthonormal_columns(fit.design)
            H = fit.held_design - Q_det @ (Q_det.T @ fit.held_design)
            Q = np.hstack([Q_det, orthonormal_columns(H)])
            _SPANS[fit] = (Q, Q[:, :Q_det.shape[1]])
        else:
            _SPANS[fit] = (orthonormal_columns(fit.span), orthonormal_columns(fit.design))
    return _SPANS[fit]


def release_span_bases(fit: EffectFit) -> None:
    """Forget ``fit``'s bases (:func:`span_bases`) once its outlier scan and remainder tests are
    done (at 100,000 rows, 0.4 GB)."""
    _SPANS.pop(fit, None)
