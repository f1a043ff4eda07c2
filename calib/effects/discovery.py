"""Discovery of left-out physics, written once over :class:`calib.robot.Robot`.

In joint space the measured pose gives, for chain i at measurement j, the closure residual of
the geometric model ``r_ij(theta) = F_i(theta, q_ij, QM_j)`` (mm; for a hexapod
``|R_j P_i + OP_j - B_i| - dl_i - l_ij``). An effect moves each joint by a known physical
regressor times unknown coefficients, ``dq = Xq . phi`` (:mod:`calib.effects.base`), and the
joint fit makes ``F(theta, q + Xq phi, QM)`` vanish to the noise: exactly, not only to first
order (to first order the effect adds ``X phi``, ``X = -dF/dq Xq``, to the residual; for a
hexapod, whose closure is linear in the leg length, the two are the same). Several effects fit
together simply concatenate their regressors.
The noise of ``r_j`` (C chains) comes from the pose sensor and the joint readings through the
closure Jacobians, ``S_j = dF/dpose Sigma_pose dF/dpose^T + dF/dq Sigma_q dF/dq^T``; every fit
is whitened by it (mm and rad never mixed by a raw norm), so that the sum of squares is
chi-square distributed when the model is right. The geometry fitted with the effects is the
robot's free parameters (``robot.free_default``).

:func:`discover_effects` then

1. chooses a subset of the candidates, up to :data:`MAX_EFFECTS`, by stepwise selection on the
   joint fit linearised at the geometry-only solution (every subset fit is then one small
   least-squares problem): each effect must lower the BIC by :data:`MIN_DELTA_BIC` (the
   chi-square divided by the remainder's variance when that exceeds the declared noise, so that
   an underestimated noise does not turn chance into evidence) and lower the cross-validated
   residual (closed form: deleted residuals of each fold through the hat matrix); an effect the
   later ones make redundant is dropped; effects the data cannot tell apart are reported as
   aliases. Nested effects (one generalises the other: :attr:`Effect.generalises`) are never
   named together; the simpler is named unless the general one lowers the BIC by
   :data:`MIN_NESTED_DELTA_BIC` more (its extra parameters must pay), decided during the
   selection and again on the exact joint fits; a general one ahead by less is reported as an
   alias;
2. fits the chosen effects and the geometry jointly (whitened Gauss-Newton) and keeps only
   effects whose coefficients are significantly non-zero (Wald test);
3. tests the remainder (:func:`remainder_tests`): chi-square against the declared noise overall
   and per chain, and structure against time, the direction and size of each joint's last
   move, its stroke, the load it carries and the position in the workspace, and the measured
   pose drifting with time (the same at every pose: a moving measurement frame). ``explained`` is
   true only when every test passes;
4. flags outliers (:func:`outlier_scan`): rows whose studentized deleted residual (closed-form
   leave-one-out) is gross and not shared by their neighbours in time, in the workspace or in
   the direction of motion. When more than :data:`MAX_BAD_FRACTION` of the rows look bad the
   model is wrong, not the data, and nothing is flagged.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import chi2 as chi2_dist, norm

from ..engine import newton_offset
from ..observability import describe_combination
from ..robot import KinematicsError, Robot, check_joint_limits
from .registry import EFFECTS, effect as registered, effect_family, effects_for, nested_in
from .base import GRAM_BASIS_RTOL, Effect, EffectData, closure_regressors, orthonormal_columns
from .granularity import PerChainForm, form_key, per_chain_form
from .compliance import for_payload, payload_varies
from .laws import LawSpace, ProposedLaw, law_effect, search_law
from .separability import (GRAM_MIN_RESIDUALS, HELD_INFORMATION, GeometryBasis, flat_coordinates, geometry_basis,
                           pose_families, unseparated_combinations, unseparated_information)

__all__ = ["MIN_DELTA_BIC", "MIN_ROWS", "MAX_EFFECTS", "ALIAS_CORRELATION", "ALIAS_DELTA_BIC",
           "MIN_NESTED_DELTA_BIC", "MIN_GRANULARITY_DELTA_BIC", "VERDICT_ALPHA", "POSE_DRIFT_Z",
           "NOISE_ALPHA", "OUTLIER_ALPHA", "MAX_BAD_FRACTION", "SIGNIFICANCE_ALPHA", "EffectFit", "Discovery", "fit_effect",
           "fit_effects", "discover_effects", "discover_effect", "remainder_tests", "outlier_scan",
           "locate_mismatch", "closure_noise_covariance", "closure_noise_std", "regressor_correlation", "candidate_forms",
           "propose_law", "SEARCH_ROWS_MAX", "SEARCH_SUBSAMPLE_ROWS", "search_subsample"]

#: Evidence an effect needs to enter the model: BIC lower by at least this ("very strong" on
#: the Kass-Raftery scale; a chance reduction of a one-parameter effect's chi-square by 16 has
#: probability 5e-5).
MIN_DELTA_BIC = 10.0
#: Fewest measurements a discovery accepts.
MIN_ROWS = 12
#: Most effects named together.
MAX_EFFECTS = 3
#: Evidence a general effect needs over one it contains (:attr:`Effect.generalises`) to be named
#: in its place: BIC lower by at least this, on top of the BIC's own charge for the extra
#: parameters (as much as an effect needs to enter at all: :data:`MIN_DELTA_BIC`).
MIN_NESTED_DELTA_BIC = MIN_DELTA_BIC
#: Evidence a per-chain form needs over its own shared form (:mod:`calib.effects.granularity`)
#: on top of the BIC's charge of ``ln(n)`` for each of its ``C - 1`` extra coefficients: none more.
#: That charge alone keeps a shared machine shared (a chance gain of ``(C - 1) ln n``, 31 for
#: six chains and 500 residuals, has probability 1e-5 under chi-square(5)), while a per-joint
#: spread the shared form cannot fit leaves structure the remainder tests would call unexplained.
MIN_GRANULARITY_DELTA_BIC = 0.0
#: Largest canonical correlation of two effects' whitened regressors (geometry projected out)
#: above which this recording cannot tell them apart.
ALIAS_CORRELATION = 0.95
#: Two effects whose evidence at the same step differs by less than this BIC ("positive" on the
#: Kass-Raftery scale), and of which only one enters, are reported as aliases.
ALIAS_DELTA_BIC = 6.0
#: Significance of the remainder's structure tests (Bonferroni-corrected over chains, quantities
#: and statistics).
VERDICT_ALPHA = 0.01
#: A pose coordinate is said to drift with time (in the remainder's words) when its drift rate
#: is this many standard errors from zero.
POSE_DRIFT_Z = 3.0
#: Significance of the remainder's chi-square tests against the declared noise (overall; per
#: chain Bonferroni-corrected). Stricter than the structure tests: the omnibus test also reacts to
#: a declared noise a few percent off, which is no physics left out.
NOISE_ALPHA = 0.001
#: Family-wise significance of the outlier test (Bonferroni over the rows).
OUTLIER_ALPHA = 1e-3
#: More rows than this fraction looking bad: the model is wrong, not the data.
MAX_BAD_FRACTION = 0.05
#: A named effect's coefficients must differ from zero at this significance (Wald test).
SIGNIFICANCE_ALPHA = 1e-3
#: Gauss-Newton iterations at most; stops when an iteration lowers the chi-square by less than
#: :data:`GN_TOLERANCE`.
GN_ITERATIONS = 30
GN_TOLERANCE = 1e-6
#: Neighbours a row is compared with (in time, in the workspace, in the direction of motion).
NEIGHBOURS = 6
#: A row's residual is shared by its neighbours when their mean residual along it is this many
#: standard errors from zero.
SHARED_Z = 3.0


# ----------------------------------------------------------------------------- noise and whitening


def _noise_covariance(robot: Robot, jac, data: EffectData) -> np.ndarray:
    var = data.noise.pose_std(robot.pose_units) ** 2
    S = np.einsum("nik,k,njk->nij", jac.pose, var, jac.pose)
    if data.noise.joint_std > 0:
        S += data.noise.joint_std ** 2 * jac.joints @ np.swapaxes(jac.joints, 1, 2)
    return S


def closure_noise_covariance(robot: Robot, theta: np.ndarray, data: EffectData) -> np.ndarray:
    """(N, C, C) covariance of each measurement's closure residuals caused by the declared
    noise: pose sensor noise and joint-reading noise through the closure Jacobians, mm^2."""
    return _noise_covariance(robot, robot.closure_jacobians(theta, data.joints, data.measured), data)


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


_BASES: "weakref.WeakKeyDictionary[EffectData, GeometryBasis | None]" = weakref.WeakKeyDictionary()


def _geometry(data: EffectData) -> GeometryBasis | None:
    """The determined and held geometric combinations of ``data`` (at ``data.theta``;
    :mod:`calib.effects.separability`), or None: no prior, or every combination determined
    (the fits are then those without a prior, unchanged)."""
    if data.tolerance is None:
        return None
    if data not in _BASES:
        robot = data.robot
        free = _free_indices(robot)
        jac = robot.closure_jacobians(data.theta, data.joints, data.measured)
        winv = np.linalg.inv(np.linalg.cholesky(_noise_covariance(robot, jac, data)))
        G = _whiten(winv, jac.parameters[:, :, free]).reshape(-1, free.size)
        basis = geometry_basis(G, data.tolerance[free], free)
        _BASES[data] = basis if basis.held.shape[1] else None
    return _BASES[data]




_SPANS: "weakref.WeakKeyDictionary[EffectFit, tuple]" = weakref.WeakKeyDictionary()


def _span_bases(fit: "EffectFit") -> tuple[np.ndarray, np.ndarray | None]:
    """``(Q, Q_det)`` orthonormal bases of ``fit.span`` (what the model could explain, the held
    geometric combinations' columns too) and of ``fit.design`` (None without held combinations),
    computed once per fit (the outlier scan and the remainder's tests share them). Above
    :data:`GRAM_MIN_RESIDUALS` residuals ``Q`` is ``[Q_det, the held columns' remainder]``, so
    that one product with ``Q`` gives both projections (:meth:`_Remainder.f_test`)."""
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


def _solve(A: np.ndarray, b: np.ndarray, gram: bool | None = None) -> np.ndarray:
    """Least squares ``A x ~ b``, columns scaled; through the Gram matrix with ``gram`` (default:
    above :data:`GRAM_MIN_RESIDUALS` rows)."""
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    As = A / scale
    if (A.shape[0] > GRAM_MIN_RESIDUALS) if gram is None else gram:
        return np.linalg.pinv(As.T @ As, hermitian=True) @ (As.T @ b) / scale
    x, *_ = np.linalg.lstsq(As, b, rcond=None)
    return x / scale


# ----------------------------------------------------------------------------- models


def _as_models(effects) -> tuple[Effect, ...]:
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


def _check_applies(eff: Effect, robot: Robot) -> None:
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
        evidence = getattr(_base(model), "evidence_coefficients", ())
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
        free = _free_indices(self.robot)
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
        return r, _whiten(_whitening(self.robot, self.theta, data), r)


def _joint_regressors(models, theta, data: EffectData, extras) -> np.ndarray:
    """(N, C, p) the effects' joint regressors, concatenated in the order of ``models``."""
    if not models:
        return np.zeros((data.n, data.robot.n_chains, 0))
    return np.concatenate([m.joint_regressors(data.robot, theta, data, e) for m, e in zip(models, extras)], axis=-1)


def _model_poses(robot: Robot, theta: np.ndarray, joints: np.ndarray, measured: np.ndarray,
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
    ``basis`` holds combinations: :func:`_model_poses`)."""
    robot = data.robot
    Xq = _joint_regressors(models, theta, data, extras)
    joints = data.joints + Xq @ coef
    r = robot.closure(theta, joints, data.measured)
    jac = robot.closure_jacobians(theta, joints, _model_poses(robot, theta, joints, data.measured, basis, r))
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
    models = _as_models(effects)
    robot = data.robot
    for m in models:
        _check_applies(m, robot)
    free = _free_indices(robot)
    extras = dict(extras or {})
    n_searched = sum(m.searched is not None for m in models)
    missing = [m for m in models if m.searched is not None and extras.get(m.name) is None]
    if missing:
        geo = fit_effects(data, (), start=start)
        lin = _Linear(data, geo)
        fixed = [lin.columns(m, None) for m in models if m.searched is None]
        for m in missing:
            extras[m.name] = lin.search(m, fixed)
            fixed.append(lin.columns(m, extras[m.name]))
        start = geo.theta
    ex = tuple(extras.get(m.name) if m.searched is not None else None for m in models)
    theta = np.array(data.theta if start is None else start, dtype=float)
    basis = _geometry(data)
    if basis is not None:
        theta = basis.hold(theta, data.theta)
    g = free.size if basis is None else basis.size
    coef = np.zeros(sum(len(m.coefficients(robot)) for m in models))
    for _ in range(max(int(iterations), 1)):
        r, D, jac = _design(models, theta, coef, data, free, ex, basis)
        winv = np.linalg.inv(np.linalg.cholesky(_noise_covariance(robot, jac, data)))
        A = _whiten(winv, D).reshape(-1, D.shape[-1])
        x = _solve(A, -_whiten(winv, r).ravel())
        theta[free] += x[:g] if basis is None else basis.step @ x[:g]
        coef = coef + x[g:]
        if float(np.sum((A @ x) ** 2)) < GN_TOLERANCE:
            break
    resid, D, jac = _design(models, theta, coef, data, free, ex, basis)
    winv = np.linalg.inv(np.linalg.cholesky(_noise_covariance(robot, jac, data)))
    w = _whiten(winv, resid)
    chi2 = float(np.sum(w ** 2))
    A = _whiten(winv, D).reshape(-1, D.shape[-1])
    n_params = D.shape[-1] + n_searched
    dof = resid.size - n_params
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    cov = np.linalg.pinv((A / scale).T @ (A / scale), hermitian=True) / np.outer(scale, scale)
    cov = cov * max(1.0, chi2 / max(dof, 1))
    ccov = cov[g:, g:]
    std = np.sqrt(np.clip(np.diag(ccov), 0, None))
    held = None if basis is None else _whiten(winv, jac.parameters[:, :, free] @ basis.held_step).reshape(A.shape[0], -1)
    return EffectFit(models, robot, theta, coef, std, ex, resid, w, chi2, n_params, A, ccov, basis, held)


def fit_effect(data: EffectData, effect: str | Effect = "none", *, extra: float | None = None,
               iterations: int = GN_ITERATIONS, start: np.ndarray | None = None) -> EffectFit:
    """Fit the robot's free geometric parameters and one effect's coefficients jointly
    (:func:`fit_effects` with one effect; ``extra`` its searched parameter, None searches it)."""
    models = _as_models(effect)
    extras = {models[0].name: extra} if models and extra is not None else None
    return fit_effects(data, models, extras=extras, iterations=iterations, start=start)


# ----------------------------------------------------------------------------- linearised selection


class _Linear:
    """The joint fit linearised at the geometry-only solution: whitened residual ``b`` and
    effect columns with the geometry projected out, so that a subset's fit is one small
    least-squares problem and its cross-validation closed form. Every free geometric combination
    is projected out, those a prior holds too: an effect earns its place only by what no
    geometry explains. The columns are taken at ``data``'s regressor poses (on a plane of poses
    the model's: :func:`_model_poses`)."""

    def __init__(self, data: EffectData, geometry: EffectFit, *, search_rows_max: int | None = None,
                 search_subsample_rows: int | None = None, seed: int = 0):
        robot = data.robot
        self.data, self.theta = data, geometry.theta
        self.search_rows_max = SEARCH_ROWS_MAX if search_rows_max is None else int(search_rows_max)
        self.search_subsample_rows = SEARCH_SUBSAMPLE_ROWS if search_subsample_rows is None else int(search_subsample_rows)
        self.seed = seed
        self.searches: list = []  # the subsampled searches made (:meth:`search_form`)
        self._spaces_for: tuple = ((), None)
        self._cv_folds: tuple = (None,)  # (key, ...) of _cv_rms_blocked's fold blocks
        self._M = None  # the whitened closure per joint displacement, made by _spaces when first asked
        jac = robot.closure_jacobians(self.theta, data.joints, data.regressor_poses)
        self.winv = np.linalg.inv(np.linalg.cholesky(_noise_covariance(robot, jac, data)))
        self.dF_dq = jac.joints
        free = _free_indices(robot)
        G = _whiten(self.winv, jac.parameters[:, :, free]).reshape(-1, free.size)
        self.basis = geometry.basis
        self.Qg = orthonormal_columns(G)
        if self.basis is not None:  # for the separability screen: the determined combinations alone
            self.Q_det = orthonormal_columns(G @ self.basis.step)
            H = G @ self.basis.held_step
            self.G_held = H - self.Q_det @ (self.Q_det.T @ H)
        self.b = self.perp(-_whiten(self.winv, robot.closure(self.theta, data.joints, data.measured)).ravel())
        self.n = self.b.size
        self.dof0 = self.n - self.Qg.shape[1]
        self.C = robot.n_chains
        self._cols: dict = {}

    def perp(self, M: np.ndarray) -> np.ndarray:
        return M - self.Qg @ (self.Qg.T @ M)

    def columns(self, eff: Effect, extra) -> np.ndarray:
        """(N C, p) whitened closure regressors of ``eff``, geometry projected out."""
        key = (eff.name, id(eff), extra)
        if key not in self._cols:
            robot = self.data.robot
            X = closure_regressors(self.dF_dq, eff.joint_regressors(robot, self.theta, self.data, extra))
            self._cols[key] = self.perp(_whiten(self.winv, X).reshape(self.n, -1))
        return self._cols[key]

    def unseparated(self, eff: Effect, extra) -> list[dict]:
        """The coefficient combinations of ``eff`` the rows cannot separate from the geometry's
        held combinations (:func:`calib.effects.separability.unseparated_combinations`), each
        with the geometric combination that mimics it: ``[{"combination", "ratio", "geometry"}]``
        (empty without a held combination)."""
        if self.basis is None:
            return []
        robot = self.data.robot
        X = _whiten(self.winv, closure_regressors(self.dF_dq, eff.joint_regressors(robot, self.theta, self.data, extra)))
        X = X.reshape(self.n, -1)
        held = X - self.Q_det @ (self.Q_det.T @ X)
        found = unseparated_combinations(held, self.perp(X))
        if not found:
            return []
        coef_names = [c.name for c in eff.coefficients(robot)]
        free_names = [robot.table.names[i] for i in self.basis.free]
        out = []
        for v, ratio in found:
            w, *_ = np.linalg.lstsq(self.G_held, held @ v, rcond=None)  # held combinations mimicking it
            u = self.basis.held @ w
            out.append({"combination": describe_combination(v, coef_names),
                        "ratio": ratio,
                        "geometry": describe_combination(u / np.linalg.norm(u), free_names) if np.any(u) else ""})
        return out

    def chi2(self, blocks: list) -> float:
        if not blocks:
            return float(self.b @ self.b)
        A = np.hstack(blocks)
        e = self.b - A @ _solve(A, self.b)
        return float(e @ e)

    @property
    def above_search_rows(self) -> bool:
        """More measurements than ``search_rows_max``: the searches on a subsample
        (:meth:`_subsampled_search`), the cross-validation by blocks (:meth:`_cv_rms_blocked`)."""
        return self.n // self.C > self.search_rows_max

    def search(self, eff: Effect, blocks: list) -> float:
        """The searched parameter minimising the chi-square with ``blocks`` fitted too: on the
        effect's grid of the search coordinate, refined by golden-section search between the
        best grid point's neighbours (unless the effect says its fit is constant between grid
        points: :attr:`Effect.refine_search`). Above ``search_rows_max`` measurements the grid is
        scanned on a subsample and confirmed and refined on every row (:meth:`_subsampled_search`)."""
        if self.above_search_rows:
            return self._subsampled_search(eff, blocks)
        Q = orthonormal_columns(np.hstack(blocks)) if blocks else np.zeros((self.n, 0))
        b = self.b - Q @ (Q.T @ self.b)
        robot = self.data.robot

        def cost(u):
            X = closure_regressors(self.dF_dq, eff.joint_regressors(robot, self.theta, self.data,
                                                                     eff.searched_value(u)))
            Xp = self.perp(_whiten(self.winv, X).reshape(self.n, -1))
            Xp = Xp - Q @ (Q.T @ Xp)
            x, *_ = np.linalg.lstsq(Xp, b, rcond=None)
            e = b - Xp @ x
            return float(e @ e)

        grid = eff.search_grid(self.data)
        if not eff.refine_search and len(grid) > SEARCH_GRID_MAX:
            return eff.searched_value(grid[_coarse_to_fine(cost, grid)])
        costs = np.array([cost(u) for u in grid])
        k = int(np.argmin(costs))
        if not eff.refine_search:
            return eff.searched_value(grid[k])
        a, b_ = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        return eff.searched_value(_golden(cost, a, b_, SEARCH_GOLDEN_ITERATIONS))

    def _cv_rms_blocked(self, blocks: list, folds: int, seed: int) -> float:
        """:meth:`cv_rms` through the Woodbury identity with the geometry's part of each fold
        kept: the rows reordered fold by fold once (each fold a slice), and each fold's
        ``Qg_k^T Qg_k`` computed once for every call with the same ``folds`` and ``seed``; a call
        then costs a pass over the effects' few columns. The same deleted residuals."""
        key = (folds, seed)
        if self._cv_folds[0] != key:
            m = self.n // self.C
            order = np.random.default_rng(seed).permutation(m)
            parts = [np.sort(order[k::folds]) for k in range(folds)]
            idx = np.concatenate([(r[:, None] * self.C + np.arange(self.C)).ravel() for r in parts])
            bounds = np.cumsum([0] + [r.size * self.C for r in parts])
            Qg = self.Qg[idx]
            grams = [Qg[lo:hi].T @ Qg[lo:hi] for lo, hi in zip(bounds[:-1], bounds[1:])]
            self._cv_folds = (key, idx, bounds, Qg, grams)
        _, idx, bounds, Qg, grams = self._cv_folds
        Qb = orthonormal_columns(np.hstack(blocks)) if blocks else np.zeros((self.n, 0))
        e = (self.b - Qb @ (Qb.T @ self.b))[idx]  # b has the geometry projected out already
        Qb = Qb[idx]
        g = Qg.shape[1]
        ss = 0.0
        for (lo, hi), Gk in zip(zip(bounds[:-1], bounds[1:]), grams):
            Qgk, Qbk, ek = Qg[lo:hi], Qb[lo:hi], e[lo:hi]
            cross = Qgk.T @ Qbk
            K = np.eye(g + Qbk.shape[1]) - np.block([[Gk, cross], [cross.T, Qbk.T @ Qbk]])
            y = np.linalg.solve(K, np.concatenate([Qgk.T @ ek, Qbk.T @ ek]))
            d = ek + Qgk @ y[:g] + Qbk @ y[g:]
            ss += float(d @ d)
        return float(np.sqrt(ss / self.n))

    def _spaces(self, blocks: list) -> tuple["_SearchSpace", "_SearchSpace"]:
        """The subsample's and every row's :class:`_SearchSpace` with ``blocks`` fitted (the last
        ones kept: every candidate of a selection step is searched with the same blocks)."""
        kept, spaces = self._spaces_for
        if spaces is not None and len(kept) == len(blocks) and all(a is b for a, b in zip(kept, blocks)):
            return spaces
        C = self.C
        if self._M is None:
            self._M = -(self.winv @ self.dF_dq)  # whitened closure per joint displacement (closure_regressors)
        Qb = orthonormal_columns(np.hstack(blocks)) if blocks else np.zeros((self.n, 0))
        full = _SearchSpace(self.data, self.theta, self._M, np.hstack([self.Qg, Qb]), self.b - Qb @ (Qb.T @ self.b))
        rows = search_subsample(self.data.t_s, self.search_subsample_rows, self.seed)
        idx = (rows[:, None] * C + np.arange(C)).ravel()
        # Every row's geometry columns restricted to the subsample span the subsample's own; so do
        # the blocks and b (each every row's minus a geometric part): projected again on the
        # subsample they are the subsample's linearised fit.
        Qg = orthonormal_columns(self.Qg[idx])
        B = np.hstack([x[idx] for x in blocks]) if blocks else np.zeros((idx.size, 0))
        Q = np.hstack([Qg, orthonormal_columns(B - Qg @ (Qg.T @ B))])
        sub = _SearchSpace(self.data.subset(rows), self.theta, self._M[rows], Q, self.b[idx] - Q @ (Q.T @ self.b[idx]))
        self._spaces_for = (list(blocks), (sub, full))
        return sub, full

    def _subsampled_search(self, eff: Effect, blocks: list) -> float:
        """:meth:`search` above ``search_rows_max`` measurements: the effect's grid (every row's)
        scanned on ``search_subsample_rows`` rows (:func:`search_subsample`), then on every
        row the :data:`SEARCH_CONFIRMED` best local minima of the subsample's chi-square
        compared, the best followed down to a local minimum of every row's chi-square over the
        grid and refined by :data:`SEARCH_REFINE_ITERATIONS` golden-section steps between its
        grid neighbours; a search not refined (:attr:`Effect.refine_search`) tries
        every grid point within :data:`SEARCH_WINDOW_SPACINGS` subsample row spacings of the
        subsample's best on every row (coarse to fine past :data:`SEARCH_GRID_MAX`)."""
        sub, full = self._spaces(blocks)
        grid = eff.search_grid(self.data)
        m = sub.data.n
        self.searches.append(eff.name)
        if not eff.refine_search:
            if len(grid) > SEARCH_GRID_MAX:
                k = _coarse_to_fine(lambda u: sub.cost(eff, u), grid)
            else:
                k = int(np.argmin([sub.cost(eff, u) for u in grid]))
            w = int(np.ceil(SEARCH_WINDOW_SPACINGS * self.data.n / m))
            lo, hi = max(k - w, 0), min(k + w, len(grid) - 1)
            window = grid[lo:hi + 1]
            if len(window) > SEARCH_GRID_MAX:
                j = _coarse_to_fine(lambda u: full.cost(eff, u), window)
            else:  # consecutive points: each updated from the one before (a step time: one row changes)
                j = int(np.argmin(full.costs(eff, window)))
            return eff.searched_value(window[j])
        costs = np.array([sub.cost(eff, u) for u in grid])
        inner = np.r_[True, costs[1:] <= costs[:-1]] & np.r_[costs[:-1] <= costs[1:], True]
        minima = sorted(np.flatnonzero(inner), key=lambda i: (costs[i], i))[:SEARCH_CONFIRMED]
        known: dict[int, float] = {}

        def at(i: int) -> float:
            if i not in known:
                known[i] = full.cost(eff, grid[i])
            return known[i]

        k = min(minima, key=lambda i: (at(i), i))
        while True:  # down to a local minimum of every row's chi-square over the grid
            j = min((i for i in (k - 1, k + 1) if 0 <= i < len(grid)), key=lambda i: (at(i), i))
            if at(j) >= at(k):
                break
            k = j
        a, b_ = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        return eff.searched_value(_golden(lambda u: full.cost(eff, u), a, b_, SEARCH_REFINE_ITERATIONS))

    def search_form(self) -> dict:
        """How the searched parameters were searched, for the discovery's summary: ``{"form":
        "every row"}`` or, when a search ran on a subsample, ``{"form": "subsample", "rows",
        "subsample_rows", "threshold", "effects"}`` (the effects so searched)."""
        if not self.searches:
            return {"form": "every row"}
        return {"form": "subsample", "rows": int(self.data.n),
                "subsample_rows": int(min(self.search_subsample_rows, self.data.n)), "threshold": self.search_rows_max,
                "effects": sorted(set(self.searches))}

    def cv_rms(self, blocks: list, folds: int, seed: int) -> float:
        """Whitened RMS of the deleted residuals of ``folds``-fold cross-validation (whole
        measurements left out), closed form through the hat matrix. Above ``search_rows_max``
        measurements the folds' geometry blocks are computed once (:meth:`_cv_rms_blocked`)."""
        if self.above_search_rows:
            return self._cv_rms_blocked(blocks, folds, seed)
        Q = self.Qg if not blocks else np.hstack([self.Qg, orthonormal_columns(np.hstack(blocks))])
        e = self.b - Q @ (Q.T @ self.b)
        m = self.n // self.C
        order = np.random.default_rng(seed).permutation(m)
        ss = 0.0
        for k in range(folds):
            rows = np.sort(order[k::folds])
            idx = (rows[:, None] * self.C + np.arange(self.C)).ravel()
            Qi = Q[idx]
            if idx.size <= DENSE_FOLD_MAX:
                d = np.linalg.solve(np.eye(idx.size) - Qi @ Qi.T, e[idx])
            else:  # Woodbury: (I - Qi Qi^T)^-1 e = e + Qi (I - Qi^T Qi)^-1 Qi^T e, a (p, p) system
                d = e[idx] + Qi @ np.linalg.solve(np.eye(Qi.shape[1]) - Qi.T @ Qi, Qi.T @ e[idx])
            ss += float(d @ d)
        return float(np.sqrt(ss / self.n))


#: A search grid longer than this (a step's time: one point per row and chain, the search's cost
#: growing as the rows squared) is searched coarse to fine: this many evenly spaced points, then
#: as many across the coarse intervals around the :data:`SEARCH_BEAM` best, and so on down to
#: single points. Where the chi-square has a basin around its minimum wider than a coarse
#: interval (a step misplaced by d rows leaves d rows wrong: it rises with |d|) the search finds
#: the point trying every one would.
SEARCH_GRID_MAX = 200
#: The best points of a level of the coarse-to-fine search whose neighbourhoods the next refines.
SEARCH_BEAM = 3


def _coarse_to_fine(cost, grid) -> int:
    """The index into ``grid`` that the coarse-to-fine search finds (:data:`SEARCH_GRID_MAX`
    points a level, :data:`SEARCH_BEAM` windows refined; ``cost(grid[i])`` the chi-square of
    point i)."""
    known: dict[int, float] = {}

    def at(i: int) -> float:
        if i not in known:
            known[i] = cost(grid[i])
        return known[i]

    windows, last = [(0, len(grid) - 1)], len(grid)
    while True:
        per = max(2, SEARCH_GRID_MAX // len(windows))
        tried, step = set(), 1
        for lo, hi in windows:
            idx = np.unique(np.linspace(lo, hi, min(per, hi - lo + 1)).round().astype(int))
            tried.update(int(i) for i in idx)
            if idx.size > 1:
                step = max(step, int(np.max(np.diff(idx))))
        if step >= last:  # no finer than the level before: every point of the windows
            tried.update(i for lo, hi in windows for i in range(lo, hi + 1))
            step = 1
        best = sorted(tried, key=lambda i: (at(i), i))[:SEARCH_BEAM]
        if step == 1:  # every point of the windows tried
            return best[0]
        windows, last = [(max(k - step, 0), min(k + step, len(grid) - 1)) for k in best], step


#: A fold of the closed-form cross-validation (:meth:`cv_rms`) with more whitened residuals than
#: this is solved through the Woodbury identity (a P x P system, P the regressors) instead of
#: the dense (n_k x n_k) one of its rows: the same deleted residuals, without a matrix that
#: grows as the fold's rows squared (107 GiB at 100,000 hexapod rows in 5 folds).
DENSE_FOLD_MAX = 2000


#: Measurements above which a searched parameter's grid is scanned on a subsample
#: (:meth:`_Linear.search`): one evaluation of the chi-square is a pass over every whitened
#: residual (0.22 s at 100,000 hexapod rows), and a selection step searches every candidate's grid
#: (about 1,300 evaluations on the full library). Below it nothing changes.
SEARCH_ROWS_MAX = 20_000
#: Rows of that subsample (:func:`search_subsample`). A searched value is located to within its
#: grid step when its effect's chi-square reduction on the subsample, ``S m / N`` for a
#: reduction ``S`` on every row, is some 44 or more (a screw's pitch: a grid step shifts the
#: phase by a sixth of a turn across the stroke, which costs ``S m / N`` times about 9%); every row
#: then confirms and refines it (:data:`SEARCH_CONFIRMED`, :data:`SEARCH_REFINE_ITERATIONS`).
SEARCH_SUBSAMPLE_ROWS = 10_000
#: Golden-section steps of the search between the best grid point's neighbours.
SEARCH_GOLDEN_ITERATIONS = 30
#: Local minima of the subsample's chi-square over the grid compared on every row.
SEARCH_CONFIRMED = 3
#: Golden-section steps on every row between the confirmed grid point's neighbours: the bracket
#: of two grid steps shrinks to 0.016 of one (:data:`SEARCH_GOLDEN_ITERATIONS` on every row take it to 1e-6 of one).
SEARCH_REFINE_ITERATIONS = 10
#: A search that is not refined (a step time between two measurements) tries, on every row,
#: the grid points within this many subsample row spacings (rows / subsample rows) of the
#: subsample's best: the subsample's chi-square is the same anywhere between two of its rows.
SEARCH_WINDOW_SPACINGS = 2


def search_subsample(t_s: np.ndarray, size: int, seed: int) -> np.ndarray:
    """Sorted indices of a seeded subsample of ``size`` rows stratified in time: the rows in time
    order cut into ``size`` consecutive strata, one row drawn from each (every row when there are
    no more than ``size``). ``t_s`` (N,) s."""
    n = t_s.size
    if n <= size:
        return np.arange(n)
    order = np.argsort(t_s, kind="stable")
    edges = np.linspace(0, n, size + 1).astype(int)
    rng = np.random.default_rng(seed)
    pick = edges[:-1] + (rng.random(size) * np.diff(edges)).astype(int)
    return np.sort(order[pick])


@dataclass(frozen=True, eq=False)
class _SearchSpace:
    """The linearised fit's whitened space on some rows, for a searched parameter's chi-square:
    ``data`` those rows, ``theta`` (P,) the linearisation point, ``M`` (n, C, C) the whitened
    closure per unit joint displacement, ``Q`` (n C, r) an orthonormal basis of what is fitted
    beside the effect (the geometry, the other effects' columns), ``b`` (n C,) the whitened
    residual with ``Q`` projected out."""

    data: EffectData
    theta: np.ndarray
    M: np.ndarray
    Q: np.ndarray
    b: np.ndarray

    def cost(self, eff: Effect, u) -> float:
        """The chi-square left with ``eff`` at search coordinate ``u`` fitted too."""
        Xq = eff.joint_regressors(self.data.robot, self.theta, self.data, eff.searched_value(u))
        X = (self.M @ Xq).reshape(self.b.size, -1)
        # One pass over Q, not two: with P = I - Q Q^T, (P X)^T (P X) = X^T X - (Q^T X)^T (Q^T X)
        # and (P X)^T b = X^T b (b has Q projected out). (X^T Q)^T: the product with the tall Q
        # as BLAS does it fastest (half the time of Q^T X for a few columns).
        return self._cost(X.T @ X, (X.T @ self.Q).T, X.T @ self.b)

    def _cost(self, XtX: np.ndarray, QX: np.ndarray, Xtb: np.ndarray) -> float:
        """The chi-square from the products of the effect's whitened columns ``X``: ``X^T X``,
        ``Q^T X`` and ``X^T b``. The chi-square's reduction is b^T P X ((P X)^T P X)^+ (P X)^T b,
        the columns scaled to unit norm first."""
        G = XtX - QX.T @ QX
        scale = np.sqrt(np.clip(np.diag(G), 0.0, None))
        scale[scale == 0] = 1.0
        Xb = Xtb / scale
        return float(self.b @ self.b - Xb @ np.linalg.pinv(G / np.outer(scale, scale), hermitian=True) @ Xb)

    def costs(self, eff: Effect, us) -> np.ndarray:
        """(len(us),) :meth:`cost` at each of ``us`` in turn, updated from the one before where
        the effect's joint regressors differ on at most :data:`SEARCH_UPDATE_ROWS` rows (a step
        time moved to the next midpoint changes one row): the products over every row are then
        corrected by the changed rows' alone. The same chi-squares to rounding."""
        robot, C = self.data.robot, self.M.shape[1]
        out, last = [], None
        for u in us:
            Xq = eff.joint_regressors(robot, self.theta, self.data, eff.searched_value(u))
            rows = None if last is None else np.flatnonzero(np.any(Xq != last[0], axis=(1, 2)))
            if rows is None or rows.size > SEARCH_UPDATE_ROWS:
                X = (self.M @ Xq).reshape(self.b.size, -1)
                XtX, QX, Xtb = X.T @ X, (X.T @ self.Q).T, X.T @ self.b
            else:
                _, XtX, QX, Xtb = last
                idx = (rows[:, None] * C + np.arange(C)).ravel()
                old = (self.M[rows] @ last[0][rows]).reshape(idx.size, -1)
                D = (self.M[rows] @ Xq[rows]).reshape(idx.size, -1) - old
                XtX = XtX + D.T @ old + old.T @ D + D.T @ D
                QX = QX + self.Q[idx].T @ D
                Xtb = Xtb + D.T @ self.b[idx]
            last = (Xq, XtX, QX, Xtb)
            out.append(self._cost(XtX, QX, Xtb))
        return np.array(out)


#: Rows on which two consecutive points of a search differ at most for :meth:`_SearchSpace.costs`
#: to update the chi-square from the point before rather than pass over every row.
SEARCH_UPDATE_ROWS = 1000


def _golden(cost, a: float, b: float, iterations: int) -> float:
    """The midpoint of the bracket golden-section search leaves of ``[a, b]`` after ``iterations`` steps."""
    g = (np.sqrt(5) - 1) / 2
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = cost(c), cost(d)
    for _ in range(iterations):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = cost(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = cost(d)
    return (a + b) / 2


def _canonical_correlation(A: np.ndarray, B: np.ndarray) -> float:
    Qa, Qb = orthonormal_columns(A), orthonormal_columns(B)
    if Qa.shape[1] == 0 or Qb.shape[1] == 0:
        return 0.0
    return float(np.clip(np.linalg.svd(Qa.T @ Qb, compute_uv=False)[0], 0.0, 1.0))


def regressor_correlation(data: EffectData, candidates=None, extras=None) -> dict:
    """``{(a, b): c}``: the largest canonical correlation between the whitened regressors of
    each pair of effects, with the geometry projected out (1: the data cannot tell them apart).

    Args:
        data: the measurements (the linearisation point is the geometry-only fit).
        candidates: effects (default every one that applies to the robot).
        extras: ``{name: value}`` for searched parameters (default searched on ``data``).
    """
    models = _as_models(effects_for(data.robot) if candidates is None else candidates)
    lin = _Linear(data, fit_effects(data, ()))
    extras = dict(extras or {})
    cols = {m.name: lin.columns(m, extras.get(m.name) if m.searched is None or m.name in extras
                                else lin.search(m, [])) for m in models}
    names = list(cols)
    return {(a, b): _canonical_correlation(cols[a], cols[b]) for i, a in enumerate(names) for b in names[i + 1:]}


def _base(eff: Effect) -> Effect:
    return eff.base if isinstance(eff, PerChainForm) else eff


def candidate_forms(candidates, per_chain: bool = True) -> dict:
    """``{key: effect}``: every candidate effect (its shared form, under its name) and, with
    ``per_chain``, the per-chain form of each that has one (under ``name[per_chain]``,
    :func:`calib.effects.granularity.form_key`); ``none`` dropped."""
    out = {}
    for m in _as_models(candidates):
        out[form_key(m)] = m
        pc = per_chain_form(m) if per_chain else None
        if pc is not None:
            out[form_key(pc)] = pc
    return out


def _relations(models: dict) -> tuple[dict, dict]:
    """``(family, nested)`` over the candidate forms ``models`` (key -> effect): ``family[k]``
    the keys of every form of every effect nested with ``k``'s (one of them in a model at
    most); ``nested[k]`` ``{key: margin}`` of the keys ``k`` generalises: the other forms of its
    own effect (margin :data:`MIN_GRANULARITY_DELTA_BIC`) or of an effect it generalises
    (:attr:`Effect.generalises`; margin :data:`MIN_NESTED_DELTA_BIC`) whose granularity is no
    finer (a per-chain form contains its shared form; a shared warm-up a shared drift, not a
    per-chain one)."""
    family, nested = {}, {}
    for k, m in models.items():
        fam = set(effect_family(_base(m)))
        inner = set(nested_in(_base(m))) | {m.name}
        fine = isinstance(m, PerChainForm)
        family[k] = {k2 for k2, m2 in models.items() if m2.name in fam}
        nested[k] = {k2: MIN_GRANULARITY_DELTA_BIC if models[k2].name == m.name else MIN_NESTED_DELTA_BIC
                     for k2 in family[k] if k2 != k and models[k2].name in inner
                     and (fine or not isinstance(models[k2], PerChainForm))}
    return family, nested


def _simplest(trials: dict, names, nested: dict) -> str:
    """Among ``names`` (one family of nested effects, each with its ``delta_bic`` in ``trials``;
    ``nested[name]``: ``{effect it generalises: margin}``), the one selection names: the best by
    BIC, then, as long as an effect it generalises is within the margin of it
    (:data:`MIN_NESTED_DELTA_BIC`, :data:`MIN_GRANULARITY_DELTA_BIC`), that simpler one (the
    extra parameters must pay)."""
    names = [n for n in names if n in trials]
    best = max(names, key=lambda n: trials[n]["delta_bic"])
    while True:
        simpler = [n for n in nested[best] if n in names
                   and trials[best]["delta_bic"] - trials[n]["delta_bic"] < nested[best][n]]
        if not simpler:
            return best
        best = max(simpler, key=lambda n: trials[n]["delta_bic"])


def _trial(lin: _Linear, eff: Effect, blocks: list, chi2_ref: float, p_ref: int, log_n: float) -> dict:
    """``eff`` fitted with ``blocks``: its columns, chi-square and BIC evidence against
    ``blocks`` alone (chi-square ``chi2_ref``, ``p_ref`` parameters)."""
    extra = lin.search(eff, blocks) if eff.searched is not None else None
    X = lin.columns(eff, extra)
    chi2_new = lin.chi2(blocks + [X])
    k = X.shape[1] + (eff.searched is not None)
    s2 = max(1.0, chi2_new / max(lin.dof0 - p_ref - k, 1))
    return {"extra": extra, "X": X, "k": k, "chi2": chi2_new, "scale": s2,
            "delta_bic": (chi2_ref - chi2_new) / s2 - k * log_n}


def _select(lin: _Linear, models: dict, max_effects: int, min_delta_bic: float, folds: int, seed: int) -> dict:
    """Stepwise selection (forward, with a backward check after each addition).

    Nested effects (:attr:`Effect.generalises`) are one family: at most one of a family is in
    the model, the simplest unless a more general one gains :data:`MIN_NESTED_DELTA_BIC` over it
    (:func:`_simplest`), and after each step the family's member in the model is reviewed with
    the other effects fitted (a warm-up's curvature can show only once another effect is in).
    A form the rows cannot separate from the geometry's held combinations (:meth:`_Linear.unseparated`)
    is no candidate; it is returned under ``"unseparated"``."""
    log_n = np.log(lin.n)
    unseparated: dict = {}
    family, nested = _relations(models)
    chosen: dict = {}  # name -> {"extra", "X", "k"}
    excluded: set = set()
    chi2_cur, p_cur = lin.chi2([]), 0
    cv_cur = lin.cv_rms([], folds, seed)
    steps, rivals, first = [], [], None
    while len(chosen) < max_effects:
        blocks = [c["X"] for c in chosen.values()]
        trials = {}
        for name, eff in models.items():
            if name in chosen or name in excluded or (family[name] - {name}) & set(chosen):
                continue
            if eff.searched is None and unseparated.get(name):
                continue
            t = _trial(lin, eff, blocks, chi2_cur, p_cur, log_n)
            if eff.searched is not None or name not in unseparated:
                unseparated[name] = lin.unseparated(eff, t["extra"])
            if unseparated[name]:
                unseparated[name] = {"extra": t["extra"], "combinations": unseparated[name]}
                continue
            trials[name] = t
        if first is None:
            first = {n: {"chi2": t["chi2"], "delta_bic_vs_none": t["delta_bic"], "n_params": t["k"],
                         "extra": t["extra"],
                         "cv_whitened_rms": lin.cv_rms([t["X"]], folds, seed)} for n, t in trials.items()}
        # One member per family competes: the simplest that the evidence allows.
        winners = {n: _simplest(trials, family[n], nested) for n in trials}
        order = sorted((n for n in trials if winners[n] == n), key=lambda c: -trials[c]["delta_bic"])
        added, cv_new = None, None
        for name in order:
            t = trials[name]
            if t["delta_bic"] < min_delta_bic:
                break
            cv_try = lin.cv_rms(blocks + [t["X"]], folds, seed)
            if cv_try < cv_cur:
                added, cv_new = name, cv_try
                break
        step = {"trials": {n: {"delta_bic": t["delta_bic"], "chi2": t["chi2"]} for n, t in trials.items()},
                "added": added, "dropped": []}
        steps.append(step)
        if added is None:
            break
        t = trials[added]
        for other in order:
            if other != added and trials[other]["delta_bic"] >= min_delta_bic \
                    and t["delta_bic"] - trials[other]["delta_bic"] < ALIAS_DELTA_BIC:
                rivals.append((added, other, t["delta_bic"] - trials[other]["delta_bic"],
                               _canonical_correlation(t["X"], trials[other]["X"]), False))
        chosen[added] = {"extra": t["extra"], "X": t["X"], "k": t["k"]}
        chi2_cur, p_cur, cv_cur = t["chi2"], p_cur + t["k"], cv_new
        # Nested review: with the others fitted, the family's simplest member that the evidence allows.
        for name in [n for n in chosen if n != added and len(family[n]) > 1]:
            rest = {n: c for n, c in chosen.items() if n != name}
            blocks_rest = [c["X"] for c in rest.values()]
            chi2_rest, p_rest = lin.chi2(blocks_rest), p_cur - chosen[name]["k"]
            review = {f: _trial(lin, models[f], blocks_rest, chi2_rest, p_rest, log_n)
                      for f in family[name] if f not in excluded and not unseparated.get(f)}
            better = _simplest(review, review, nested)
            if better != name:
                r = review[better]
                chosen = {(better if n == name else n): ({"extra": r["extra"], "X": r["X"], "k": r["k"]} if n == name
                                                         else c) for n, c in chosen.items()}
                chi2_cur, p_cur = r["chi2"], p_rest + r["k"]
                cv_cur = lin.cv_rms([c["X"] for c in chosen.values()], folds, seed)
                step.setdefault("replaced", []).append((name, better))
        # Backward: an earlier effect the later ones make redundant leaves the model.
        for name in [n for n in chosen if n != added]:
            rest = [c["X"] for n, c in chosen.items() if n != name]
            chi2_wo = lin.chi2(rest)
            s2 = max(1.0, chi2_cur / max(lin.dof0 - p_cur, 1))
            if (chi2_wo - chi2_cur) / s2 - chosen[name]["k"] * log_n < min_delta_bic:
                p_cur -= chosen[name]["k"]
                del chosen[name]
                excluded.add(name)
                chi2_cur = chi2_wo
                cv_cur = lin.cv_rms(rest, folds, seed)
                step["dropped"].append(name)
    return {"chosen": {n: c["extra"] for n, c in chosen.items()}, "steps": steps, "rivals": rivals,
            "single": first or {}, "cv_geometry": lin.cv_rms([], folds, seed), "cv_chosen": cv_cur,
            "unseparated": {n: u for n, u in unseparated.items() if u}}


# ----------------------------------------------------------------------------- the remainder


def _rms(v: np.ndarray, axis=None):
    return np.sqrt(np.mean(v ** 2, axis=axis))


def _features(data: EffectData, flat=()) -> list[tuple[str, str, np.ndarray]]:
    """``(quantity, kind, values (N, C))``: what a remainder is tested against (not the pose
    coordinates ``flat``, which the poses did not vary: their recorded values are their noise,
    which the residuals carry too)."""
    robot = data.robot
    n, c = data.n, robot.n_chains
    out = [("time", "ordered", np.broadcast_to(data.t_s[:, None], (n, c))),
           ("direction of the last move", "binary", data.direction),
           ("size of the last move", "ordered", np.abs(data.last_move)),
           ("stroke", "ordered", data.stroke)]
    load = EFFECTS.get("compliance")
    if load is not None and load.applies_to(robot):
        # The axial load of each chain under the platform's weight (statics, per unit weight).
        u = load.joint_regressors(robot, data.theta, data)[..., 0]
        if payload_varies(data):
            # Several payloads: the load the payload brings (the platform's own share is the
            # one-payload pattern, which the geometry mostly absorbs: on the Delta's two-payload
            # recordings the remainder of a compliance left out followed time, the payload's
            # swaps, and not the per-unit-weight load).
            u = u * data.payload_kg[:, None]
        out.append(("load", "ordered", u))
    for k, name in enumerate(robot.pose_names):
        if name not in flat:
            out.append((f"position {name}", "ordered", np.broadcast_to(data.regressor_poses[:, k:k + 1], (n, c))))
    return out


def _lag1(z: np.ndarray, values: np.ndarray) -> float:
    """Serial correlation of ``z`` ordered by ``values``, in standard errors (N(0, 1) when
    ``z`` is white; large when ``z`` is a smooth function of ``values``)."""
    zz = z[np.argsort(values, kind="stable")]
    zz = zz - zz.mean()
    den = float(zz @ zz)
    if den <= 0:
        return 0.0
    return float(zz[:-1] @ zz[1:] / den * np.sqrt(zz.size))


def _noise_tests(fit: EffectFit, z: np.ndarray, noise_alpha: float) -> dict:
    """The chi-square tests of the remainder against the declared noise: overall (``fit.p_value``)
    and per chain (Bonferroni, ``noise_alpha / C``), as :func:`remainder_tests` reports them."""
    n, C = z.shape
    dof_chain = max(n - fit.n_params / C, 1.0)
    chain_chi2 = np.sum(z ** 2, axis=0)
    p_chain = chi2_dist.sf(chain_chi2, dof_chain)
    chains_noisy = [int(i) for i in np.flatnonzero(p_chain < noise_alpha / C)]
    noise_ok = fit.p_value > noise_alpha and not chains_noisy
    return {"chi2": fit.chi2, "dof": fit.dof, "p_value": fit.p_value, "alpha": noise_alpha,
            "chi2_per_chain": chain_chi2.tolist(), "dof_per_chain": dof_chain,
            "p_value_per_chain": p_chain.tolist(), "chains_failing": [c + 1 for c in chains_noisy],
            "consistent": bool(noise_ok)}


@dataclass(frozen=True, eq=False)
class _Remainder:
    """The fitted model's whitened space, where the remainder's F tests run: ``jac`` the closure
    Jacobians at the fit, ``winv`` the whitening, ``Q`` an orthonormal basis of the model's
    columns, ``w`` the whitened remainder."""

    fit: EffectFit
    jac: object
    winv: np.ndarray
    Q: np.ndarray
    w: np.ndarray
    Q_det: np.ndarray | None = None

    def f_test(self, X):
        """F test of the whitened remainder on columns ``X`` (the model's columns projected out):
        ``(p, beta, cov, keep)``. Columns the rows cannot separate from the geometry's held
        combinations (:func:`calib.effects.separability.unseparated_combinations`) are not tested
        (p = 1): what is left of them is the measured orientation's noise in the held columns."""
        from scipy.stats import f as f_dist

        fit, Q = self.fit, self.Q
        QX = Q.T @ X
        Xp = X - Q @ QX
        gram = X.shape[0] > GRAM_MIN_RESIDUALS
        if self.Q_det is not None:
            if gram:  # Q = [Q_det, Q_rest] (:func:`_span_bases`): X less Q_det's part is Xp + Q_rest Q_rest^T X
                I_free = Xp.T @ Xp
                QXr = QX[self.Q_det.shape[1]:]
                unseparated = unseparated_information(I_free + QXr.T @ QXr, I_free)
            else:
                unseparated = unseparated_combinations(X - self.Q_det @ (self.Q_det.T @ X), Xp)
            if unseparated:
                return 1.0, None, None, np.zeros(X.shape[1], dtype=bool)  # the held geometry absorbs it: untestable here
        X = Xp
        keep = np.linalg.norm(X, axis=0) > 1e-9 * max(np.linalg.norm(X), 1e-300)
        X = X[:, keep]
        if gram and X.size:
            # The normal equations of the few columns (one product over the tall ones): rank at
            # GRAM_BASIS_RTOL of the largest singular value, as the Gram matrix resolves them.
            Gx = X.T @ X
            scale = np.sqrt(np.diag(Gx))
            lam, V = np.linalg.eigh(Gx / np.outer(scale, scale))
            resolved = lam > GRAM_BASIS_RTOL ** 2 * lam.max()
            k = int(np.sum(resolved))
            if k == 0 or fit.dof - k <= 0:
                return 1.0, None, None, keep
            # The estimate and its covariance on the same k resolved directions: with pinv's own
            # cut-off for the one and not the other, nearly collinear columns (what the linear
            # Delta's geometry and a shared drift leave of its towers' stroke columns) gave a
            # coefficient of 7e8 on a direction the covariance had dropped, and t of 1.5e10.
            inverse = (V[:, resolved] / lam[resolved]) @ V[:, resolved].T / np.outer(scale, scale)
            beta = inverse @ (X.T @ self.w)
            d2 = float(beta @ Gx @ beta)
            s2 = max(fit.chi2 - d2, 1e-300) / (fit.dof - k)
            return float(f_dist.sf((d2 / k) / s2, k, fit.dof - k)), beta, inverse * s2, keep
        if not X.size:
            return 1.0, None, None, keep
        # The estimate and its covariance from one SVD of the scaled columns, on the directions
        # its rank keeps (numpy's matrix_rank tolerance), as the Gram path above does.
        scale = np.linalg.norm(X, axis=0)
        U, sv, Vt = np.linalg.svd(X / scale, full_matrices=False)
        resolved = sv > sv.max() * max(X.shape) * np.finfo(float).eps
        k = int(np.sum(resolved))
        if k == 0 or fit.dof - k <= 0:
            return 1.0, None, None, keep
        V = Vt[resolved].T / scale[:, None]
        beta = (V / sv[resolved]) @ (U[:, resolved].T @ self.w)
        d2 = float(np.sum((X @ beta) ** 2))
        s2 = max(fit.chi2 - d2, 1e-300) / (fit.dof - k)
        return float(f_dist.sf((d2 / k) / s2, k, fit.dof - k)), beta, (V / sv[resolved] ** 2) @ V.T * s2, keep

    def joint_test(self, Xq: np.ndarray, k: int):
        """:meth:`f_test` of joint displacements ``Xq`` (N, C, k), mapped to the closure."""
        return self.f_test(_whiten(self.winv, closure_regressors(self.jac.joints, Xq)).reshape(-1, k))


def _pose_drift_test(data: EffectData, rem: _Remainder) -> tuple[float, np.ndarray]:
    """The measured pose drifting with time: every pose coordinate off in proportion to time, the
    same at every pose (the measurement frame moving; nothing the joints do), through the
    closure's pose Jacobian; one F test over the pose coordinates: ``(p, t per coordinate)``."""
    robot = data.robot
    tc = data.t_s - data.t_s.mean()
    p_pose, t_pose = 1.0, np.zeros(robot.pose_dim)
    if np.ptp(tc) > 0:
        p_pose, beta, cov, keep = rem.f_test(_whiten(rem.winv, rem.jac.pose * tc[:, None, None])
                                             .reshape(-1, robot.pose_dim))
        if beta is not None:
            t_pose[keep] = beta / np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    return p_pose, t_pose


def _quantity_tests(rem: _Remainder, kind: str, values: np.ndarray, z: np.ndarray, R: np.ndarray) -> dict:
    """One quantity's tests (:func:`remainder_tests`): in proportion to it (F, per-chain t) and,
    for an ordered one, smooth in it (serial correlation per chain and combined) and common and
    smooth in it (a cubic shared by every chain, F)."""
    n, C = z.shape
    v = values - values.mean(axis=0)
    Xq = np.zeros((n, C, C))
    Xq[:, np.arange(C), np.arange(C)] = v
    p_f, beta, cov, keep = rem.joint_test(Xq, C)
    t_chain = np.zeros(C)
    if beta is not None:
        t_chain[keep] = beta / np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    p_t = 2 * norm.sf(np.abs(t_chain))
    p_smooth = 1.0
    if kind == "ordered":
        lag = np.array([_lag1(z[:, c], values[:, c]) for c in range(C)])
        comb = float(np.sum(lag) / np.sqrt(max(np.sum(R ** 2), 1e-12)))
        p_lag = norm.sf(lag)
        p_comb = float(norm.sf(comb))
        # Common and smooth: every joint displaced by one cubic function of its own value
        # of the quantity (a warm-up, a drift that levels off: shared by every chain, so a
        # test per chain is six times weaker against it).
        span = float(np.ptp(values))
        if span > 0:
            u = 2 * (values - values.min()) / span - 1
            p_smooth = rem.joint_test(np.stack([u, 1.5 * u ** 2 - 0.5, 2.5 * u ** 3 - 1.5 * u], axis=-1), 3)[0]
    else:
        lag, comb, p_lag, p_comb = np.zeros(C), 0.0, np.ones(C), 1.0
    p_per = np.minimum(p_t, p_lag)
    return {"p_f": p_f, "p_smooth": p_smooth, "p_comb": p_comb, "t_chain": t_chain, "lag": lag, "comb": comb,
            "p_per": p_per, "p_min": min(p_f, p_comb, p_smooth, float(p_per.min()))}


def _structure(data: EffectData, rem: _Remainder, z: np.ndarray, alpha: float) -> tuple[dict, np.ndarray, bool]:
    """Every quantity's tests, Bonferroni over every statistic at ``alpha``: ``(structure, the
    pose drift's t per coordinate, whether the pose drift is time's strongest)``; the quantities
    read from a pose at ``data``'s regressor poses."""
    robot = data.robot
    C = robot.n_chains
    R = np.nan_to_num(np.corrcoef(z.T), nan=0.0) if data.n > 2 else np.eye(C)
    feats = _features(data, flat_coordinates(data) if rem.Q_det is not None else ())
    n_ordered = sum(kind == "ordered" for _, kind, _ in feats)
    # per quantity: F, combined serial, per chain t and serial; per ordered quantity: common smooth;
    # the measured pose drifting with time
    m_tests = len(feats) * (2 * C + 2) + n_ordered + 1
    p_pose, t_pose = _pose_drift_test(data, rem)
    pose_best = False
    structure = {}
    for name, kind, values in feats:
        q = _quantity_tests(rem, kind, values, z, R)
        p_min = q["p_min"]
        extra = {}
        if name == "time":
            # Said in the words when the pose-space description beats every joint-space one.
            pose_best = p_pose < p_min
            p_min = min(p_min, p_pose)
            extra = {"p_value_pose_drift": p_pose, "t_pose_drift": dict(zip(robot.pose_names, t_pose.tolist()))}
        structure[name] = {"p_value_proportional": q["p_f"], "p_value_common_smooth": q["p_smooth"], **extra,
                           "t_per_chain": q["t_chain"].tolist(),
                           "serial_correlation_per_chain": q["lag"].tolist(),
                           "serial_correlation_combined": q["comb"],
                           "p_value": min(1.0, p_min * m_tests),
                           "chains": [int(c) for c in np.flatnonzero(q["p_per"] * m_tests < alpha)],
                           "score": float(-np.log10(max(p_min, 1e-300)))}
    return structure, t_pose, pose_best


def _remaining(robot: Robot, fit: EffectFit, std: np.ndarray, z: np.ndarray, noise: dict, structure: dict,
               t_pose: np.ndarray, pose_best: bool, alpha: float) -> dict:
    """What the remainder's tests leave (:func:`remainder_tests`' ``remaining``), in numbers and
    in words."""
    follows = sorted((k for k, v in structure.items() if v["p_value"] < alpha), key=lambda k: -structure[k]["score"])
    explained = bool(noise["consistent"] and not follows)
    floor = float(_rms(std))
    rms = float(_rms(fit.residuals))
    ratio = float(np.sqrt(fit.chi2 / max(fit.dof, 1)))
    chains_noisy = [c - 1 for c in noise["chains_failing"]]
    chains = sorted(set(chains_noisy) | {c for k in follows for c in structure[k]["chains"]})
    remaining = {
        "present": not explained,
        "noise_ratio": ratio,
        "rms_mm": rms,
        "noise_floor_mm": floor,
        "excess_rms_mm": float(np.sqrt(max(rms ** 2 - floor ** 2, 0.0))),
        "rms_per_chain_noise": _rms(z, axis=0).tolist(),
        "chains": [c + 1 for c in chains],
        "follows": follows,
        "does_not_follow": [k for k in ("time", "direction of the last move", "size of the last move", "stroke", "load")
                            if k in structure and k not in follows],
        # The measured pose drifting with time (alike at every pose; it follows time in pose space
        # better than in any chain's joint): the coordinates that drift.
        "pose_drift": [k for k, t in zip(robot.pose_names, t_pose) if abs(t) > POSE_DRIFT_Z]
        if "time" in follows and pose_best else [],
    }
    remaining["summary"] = _remaining_words(remaining, robot.chain_word, explained)
    return remaining


def remainder_tests(data: EffectData, fit: EffectFit, *, alpha: float = VERDICT_ALPHA,
                    noise_alpha: float = NOISE_ALPHA) -> dict:
    """Test what the fitted model leaves against the declared noise and for structure.

    Noise: the chi-square of the whitened residuals overall (at ``noise_alpha``), and per chain
    the sum of squares of its standardised residuals (Bonferroni, ``noise_alpha / C``).

    Structure, for each quantity (time, direction and size of each joint's last move, its
    stroke, the load it carries, each pose coordinate):

    - in proportion to it: the whitened remainder regressed on a generic effect, each chain's
      joint displaced in proportion to the quantity (one coefficient per chain, mapped to the
      closure like any effect and with the fitted model's columns projected out, so that what
      the geometry absorbs is not counted); F test (the noise's scale estimated, so it speaks
      also when the noise is larger than declared), per-chain t of the coefficients;
    - smooth in it (ordered quantities): the standardised residuals' serial correlation when the
      rows are sorted by the quantity (any smooth function shows, a periodic one included);
    - common and smooth in it (ordered quantities): every chain's joint displaced by one cubic
      function of the quantity (three coefficients, Legendre polynomials of the quantity scaled
      to [-1, 1]), mapped and projected like the proportional test; F test;
    - in pose space (time): every measured pose coordinate off in proportion to time, the same
      at every pose (a measurement frame moving, nothing the joints do), mapped to the closure
      through its pose Jacobian and projected like the proportional test; one F test over the
      pose coordinates, counted with time's statistics. Growing legs raise the platform too and
      take most of a frame's drift; what they leave is one displacement in pose space, which no
      statistic per chain sees as well. ``remaining['pose_drift']`` names the coordinates that
      drift (drift rate more than :data:`POSE_DRIFT_Z` standard errors from zero) when time is
      followed and this test is time's strongest.

    Bonferroni over every statistic, at ``alpha``.

    Returns:
        JSON-ready dict: ``explained`` (every test passes), ``noise`` (the chi-square tests),
        ``structure`` (per quantity: statistics, corrected p-value, chains), ``remaining``
        (what is left, in numbers and in words).
    """
    robot = data.robot
    std = closure_noise_std(robot, fit.theta, data)
    z = fit.residuals / std
    noise = _noise_tests(fit, z, noise_alpha)
    # The generic effects' columns in the fitted model's whitened space.
    joints = data.joints + fit.joint_displacement(data)
    poses = _model_poses(robot, fit.theta, joints, data.measured, fit.basis)
    jac = robot.closure_jacobians(fit.theta, joints, poses)
    winv = np.linalg.inv(np.linalg.cholesky(_noise_covariance(robot, jac, data)))
    Q, Q_det = _span_bases(fit)
    rem = _Remainder(fit, jac, winv, Q, fit.whitened.ravel(), Q_det)
    # The quantities read from the poses (positions, the load) at the same poses: the flat
    # coordinates are still those the recorded poses did not vary.
    quantities = data if poses is data.measured else replace(data, model_poses=poses)
    structure, t_pose, pose_best = _structure(quantities, rem, z, alpha)
    remaining = _remaining(robot, fit, std, z, noise, structure, t_pose, pose_best, alpha)
    return {"explained": not remaining["present"], "noise": noise, "structure": structure, "remaining": remaining}


def _chain_list(word: str, chains: list) -> str:
    if not chains:
        return ""
    if len(chains) == 1:
        return f"{word} {chains[0]}"
    return f"{word}s {', '.join(map(str, chains[:-1]))} and {chains[-1]}"


def _remaining_words(rem: dict, chain: str, explained: bool) -> str:
    if explained:
        return (f"nothing beyond the declared noise: residual {rem['noise_ratio']:.2f} x the noise, "
                f"no structure in time, motion, stroke, load or workspace")
    size = (f"a remainder of RMS {1e3 * rem['rms_mm']:.2f} um against a noise floor of "
            f"{1e3 * rem['noise_floor_mm']:.2f} um (whitened: {rem['noise_ratio']:.1f} x the declared noise)")
    if rem["noise_ratio"] < 1.0:  # structure, not size: say that the rows' own noise is smaller
        size = (f"structure in a remainder of RMS {1e3 * rem['rms_mm']:.2f} um, below the noise floor of "
                f"{1e3 * rem['noise_floor_mm']:.2f} um the declared noise gives: the declared noise is larger than "
                f"the rows show (they show {rem['noise_ratio']:.2f} x it), and the structure is judged at the rows' "
                f"own noise")
    where = _chain_list(chain, rem["chains"]) or f"every {chain} alike"
    if rem["follows"]:
        what = "following " + ", ".join(rem["follows"][:3])
        if rem.get("pose_drift"):
            what += (f" (the measured pose drifts with time, alike at every pose: "
                     f"{', '.join(rem['pose_drift'])})")
        if rem["does_not_follow"]:
            what += "; not " + ", ".join(rem["does_not_follow"])
    else:
        what = ("following none of the quantities tested (time, motion, stroke, load, workspace): noise larger than "
                "declared, or rows off at random")
    return f"{size}, on {where}, {what}"


# ----------------------------------------------------------------------------- outliers


def _neighbour_sets(data: EffectData) -> list[np.ndarray]:
    """(N, K) indices of each row's nearest neighbours in time, in the workspace (pose
    coordinates scaled by their spread) and in the direction of motion (fewest joints moving
    the other way, then nearest in the workspace)."""
    n = data.n
    k = min(NEIGHBOURS, n - 1)
    t = data.t_s
    dt = np.abs(t[:, None] - t[None, :])
    np.fill_diagonal(dt, np.inf)
    spread = data.measured.std(axis=0)
    spread[spread == 0] = 1.0
    p = data.measured / spread
    dp = np.sqrt(((p[:, None, :] - p[None, :, :]) ** 2).sum(-1))
    np.fill_diagonal(dp, np.inf)
    dd = (data.direction[:, None, :] != data.direction[None, :, :]).sum(-1) + dp / (dp[np.isfinite(dp)].max() + 1)
    np.fill_diagonal(dd, np.inf)
    return [np.argsort(d, axis=1, kind="stable")[:, :k] for d in (dt, dp, dd)]


def _deleted(Q: np.ndarray, w: np.ndarray, bad: np.ndarray):
    """Leave-one-out statistics with the rows ``bad`` left out of the fit, closed form.

    ``Q`` (N C, r) orthonormal basis of the whitened design, ``w`` (N, C) whitened residuals.
    With ``G = (I - H_BB)^-1`` the bad rows' joint deleted residuals are ``u = G w_B``
    (covariance ``G``), the other rows' residuals of the fit without them
    ``e = w + Q Q_B^T u``, and that fit's hat matrix ``Q (I + Q_B^T G Q_B) Q^T``.

    Returns:
        ``(statistic (N,), e (N, C), u (|B|, C))``: each row's chi-square(C) statistic (a
        kept row's studentized deleted residual, a bad row's deleted residual against the fit
        without every bad row).
    """
    n, C = w.shape
    r = Q.shape[1]
    idx = (bad[:, None] * C + np.arange(C)).ravel()
    if idx.size:
        QB = Q[idx]
        G = np.linalg.inv(np.eye(idx.size) - QB @ QB.T)
        u = G @ w.ravel()[idx]
        e = (w.ravel() + Q @ (QB.T @ u)).reshape(n, C)
        K = np.eye(r) + QB.T @ G @ QB
    else:
        G = u = np.zeros(0)
        e, K = w, np.eye(r)
    Qr = Q.reshape(n, C, r)
    H = Qr @ K @ np.swapaxes(Qr, 1, 2)
    d = np.linalg.solve(np.eye(C)[None] - H, e[..., None])[..., 0]
    stat = np.einsum("ni,ni->n", e, d)
    u = np.asarray(u).reshape(-1, C)
    for b, j in enumerate(bad):
        blk = G[b * C:(b + 1) * C, b * C:(b + 1) * C]
        stat[j] = float(u[b] @ np.linalg.solve(blk, u[b]))
    return stat, e, u


def outlier_scan(data: EffectData, fit: EffectFit, *, alpha: float = OUTLIER_ALPHA,
                 max_bad_fraction: float = MAX_BAD_FRACTION) -> dict:
    """Rows that are gross and isolated (closed-form leave-one-out, no refits).

    With ``Q`` an orthonormal basis of the fit's whitened design (the columns it fitted: a
    combination held at its prior is not fitted and lends no row leverage; with its small column
    made a unit vector, a row it alone moves, the first row of a level grid, the move from home,
    had leverage near one and a 2 mm dead band's first row was flagged, and the dead band lost),
    the hat matrix's block of row j is ``H_jj = Q_j Q_j^T`` (C x C); the row's deleted residual (predicted by the model fitted
    without it) is ``d_j = (I - H_jj)^-1 w_j`` and ``t_j = w_j^T (I - H_jj)^-1 w_j`` is
    chi-square with C degrees of freedom for a consistent row. ``t`` is divided by a robust
    scale (its median over the median of chi-square(C), at least 1), so that "gross" means
    gross against the remainder's own spread. A row is bad when ``t`` exceeds the
    Bonferroni-corrected ``alpha``, the statistics being recomputed with the bad rows left out
    of the fit until the set settles (:func:`_deleted`, against masking and swamping). A bad row
    is an outlier only when it is isolated: the sum of its good neighbours' residuals (the fit
    without every bad row) along its own deleted residual, over the square root of their
    number, stays below :data:`SHARED_Z` (in time, in the workspace, in the direction of
    motion). When more than ``max_bad_fraction`` of the rows are
    bad, the model is wrong, not the data: nothing is flagged.

    Returns:
        dict: ``statistic`` (N,), ``threshold``, ``scale``, ``bad`` and ``flagged`` (0-based
        indices), ``shared`` (bad rows not flagged, with the neighbourhood that shares them),
        ``model_wrong`` (bool).
    """
    n, C = data.n, data.robot.n_chains
    Q, Q_det = _span_bases(fit)
    Q = Q if Q_det is None else Q_det
    w = fit.whitened
    stat, clean, u = _deleted(Q, w, np.zeros(0, dtype=int))
    scale = max(1.0, float(np.median(stat) / chi2_dist.median(C)))
    thr = float(chi2_dist.isf(alpha / n, C))
    bad = np.flatnonzero(stat / scale > thr)
    # Masking and swamping: the statistics again with the bad rows left out of the fit, until the
    # set of bad rows settles (closed form each time).
    for _ in range(10):
        if bad.size == 0 or bad.size > max(1, max_bad_fraction * n):
            break
        stat, clean, u = _deleted(Q, w, bad)
        again = np.flatnonzero(stat / scale > thr)
        if np.array_equal(again, bad):
            break
        bad = again
    out = {"statistic": (stat / scale).tolist(), "threshold": thr, "scale": scale, "bad": bad.tolist(),
           "flagged": [], "shared": {}, "model_wrong": False}
    if bad.size > max(1, max_bad_fraction * n):
        out["model_wrong"] = True
        return out
    if bad.size == 0:
        return out
    stat, clean, u = _deleted(Q, w, bad)
    clean = clean / np.sqrt(scale)
    bad_set = set(bad.tolist())
    flagged = []
    for b, j in enumerate(bad):
        unit = u[b] / np.linalg.norm(u[b])
        shared = {}
        for label, nb in zip(("time", "workspace", "direction of motion"), _neighbour_sets(data)):
            others = [i for i in nb[j] if i not in bad_set]
            if not others:
                continue
            score = float((clean[others] @ unit).sum() / np.sqrt(len(others)))
            if score > SHARED_Z:
                shared[label] = score
        if shared:
            out["shared"][int(j)] = shared
        else:
            flagged.append(int(j))
    out["flagged"] = flagged
    return out


# ----------------------------------------------------------------------------- discovery


@dataclass(frozen=True, eq=False)
class Discovery:
    """The outcome of :func:`discover_effects`.

    Attributes:
        effects: names of the effects named (empty: geometry alone).
        explained: whether the remainder is consistent with the declared noise and shows no
            structure (:func:`remainder_tests`).
        remaining: what is left (numbers and ``summary`` in words; ``present`` False when
            explained).
        partial: names of named effects that leave structure behind (all of them when not
            explained).
        chosen: the chosen model's joint fit (on the rows kept).
        geometry: the geometry-only fit (on the rows kept).
        evidence: per candidate alone: chi2, BIC evidence, cross-validated whitened RMS; the
            selection's steps; the geometry-only chi-square test.
        tests: the remainder's tests (:func:`remainder_tests`).
        aliases: pairs the data could not tell apart: ``{"named", "rival", "delta_bic",
            "correlation", "nested"}``; ``nested``: the rival generalises the effect named, which
            is named because the rival's extra parameters did not gain :data:`MIN_NESTED_DELTA_BIC`
            (``delta_bic`` is then the rival's gain, positive).
        outliers: the outlier scan (:func:`outlier_scan`) of the last round.
        flagged: indices of rows removed as outliers (gross and isolated).
        kept: indices of the rows used.
        located: where the geometry-only residuals concentrate (:func:`locate_mismatch`).
        proposed_law: where the library leaves a remainder, the law over joint-space terms that
            explains it (:func:`propose_law`), or None (explained, none found, or not searched).
        separation: with a prior that the rows leave combinations to (:func:`separation`): the
            geometric combinations held at the prior mean, the candidate forms that cannot be
            separated from them on this pose set (never named), and the poses that would
            separate them; empty otherwise.
        search: how the searched parameters (a pitch, a time constant, a step time) were
            searched in the last round's selection: ``{"form": "every row"}``, or above
            ``search_rows_max`` measurements ``{"form": "subsample", "rows", "subsample_rows",
            "threshold", "effects"}`` (:meth:`_Linear.search_form`).
    """

    effects: tuple
    explained: bool
    remaining: dict
    partial: tuple
    chosen: EffectFit
    geometry: EffectFit
    evidence: dict
    tests: dict
    aliases: list
    outliers: dict
    flagged: tuple
    kept: np.ndarray
    located: dict
    proposed_law: ProposedLaw | None = None
    separation: dict = field(default_factory=dict)
    search: dict = field(default_factory=lambda: {"form": "every row"})

    @property
    def effect(self) -> str:
        """``"none"``, the one effect, or the names joined by ``+``."""
        return "+".join(self.effects) or "none"

    @property
    def adequate(self) -> bool:
        return self.explained

    @property
    def model_wrong(self) -> bool:
        """More than :data:`MAX_BAD_FRACTION` of the rows looked bad."""
        return bool(self.outliers.get("model_wrong"))


def _nested_check(sub: EffectData, lin: _Linear, geo: EffectFit, models: dict, sel: dict) -> None:
    """The chosen member of each family of nested effects decided again on the exact joint fits
    (the other chosen effects fitted too): the linearised evidence of two nested effects can
    differ by a few units of BIC from the exact one, as much as the margin the general one needs.
    Updates ``sel["chosen"]`` and appends nested aliases to ``sel["rivals"]``."""
    chosen = dict(sel["chosen"])
    log_n = np.log(lin.n)
    family, nested = _relations(models)
    for name in list(chosen):
        fam = [f for f in models if f in family[name] and f not in sel["unseparated"]]
        if len(fam) < 2:
            continue
        others = {n: e for n, e in chosen.items() if n != name}
        fits = {f: fit_effects(sub, [models[n] for n in others] + [models[f]], start=geo.theta,
                               extras={models[n].name: e for n, e in others.items()}) for f in fam}
        s2 = max(1.0, min(f.chi2 / max(f.dof, 1) for f in fits.values()))
        trials = {f: {"delta_bic": -(fit.chi2 / s2 + fit.n_params * log_n)} for f, fit in fits.items()}
        better = _simplest(trials, fam, nested)
        extra = fits[better].extras[-1]
        for g in fam:
            gap = trials[g]["delta_bic"] - trials[better]["delta_bic"]
            if better in nested[g] and 0 < gap < nested[g][better]:
                corr = _canonical_correlation(lin.columns(models[better], extra),
                                              lin.columns(models[g], fits[g].extras[-1]))
                sel["rivals"].append((better, g, float(gap), corr, True))
        if better != name:
            chosen = {(better if n == name else n): (extra if n == name else e) for n, e in chosen.items()}
            sel.setdefault("nested_replaced", []).append((name, better))
    sel["chosen"] = chosen


def _choose(sub: EffectData, models: dict, max_effects: int, min_delta_bic: float, folds: int, seed: int,
            search_rows_max: int | None = None, search_subsample_rows: int | None = None):
    geo = fit_effects(sub, ())
    poses = _model_poses(sub.robot, geo.theta, sub.joints, sub.measured, geo.basis)
    if poses is not sub.measured:  # combinations held: the effects' regressors at the model's poses
        sub = replace(sub, model_poses=poses)
    lin = _Linear(sub, geo, search_rows_max=search_rows_max, search_subsample_rows=search_subsample_rows, seed=seed)
    sel = _select(lin, models, max_effects, min_delta_bic, folds, seed)
    _nested_check(sub, lin, geo, models, sel)
    names = list(sel["chosen"])
    fit = geo
    while names:
        fit = fit_effects(sub, [models[n] for n in names], start=geo.theta,
                          extras={models[n].name: sel["chosen"][n] for n in names})
        p_value = {n: fit.significance(models[n].name)["p_value"] for n in names}
        weak = [n for n in names if p_value[n] > SIGNIFICANCE_ALPHA]
        if not weak:
            break
        names.remove(max(weak, key=lambda n: p_value[n]))
        sel.setdefault("insignificant", []).append(weak)
        fit = geo
    sel["search"] = lin.search_form()
    return sub, geo, fit, sel


def discover_effects(data: EffectData, *, candidates=None, max_effects: int = MAX_EFFECTS, alpha: float = VERDICT_ALPHA,
                     outlier_alpha: float = OUTLIER_ALPHA, folds: int = 5, seed: int = 0, max_rounds: int = 3,
                     min_delta_bic: float = MIN_DELTA_BIC, per_chain: bool = True, laws: bool = True,
                     channels: dict | None = None, search_rows_max: int | None = None,
                     search_subsample_rows: int | None = None) -> Discovery:
    """Name the left-out physics (up to ``max_effects`` effects together), fit it, test what
    remains, and isolate gross rows (see the module docstring).

    Args:
        data: the measurements.
        candidates: effects to consider, registered names or :class:`Effect` objects (``none``
            is always the reference); default every registered effect that applies to the robot.
        max_effects: most effects named together.
        alpha: significance of the remainder's tests.
        outlier_alpha: family-wise significance of the outlier test.
        folds, seed: cross-validation.
        max_rounds: outlier rounds (each removes the isolated gross rows and redoes the choice).
        per_chain: also consider each candidate's per-chain form
            (:mod:`calib.effects.granularity`), chosen against its shared form by the nested
            rule (False: the shared forms only).
        laws: where the library leaves a remainder (not explained), search a law over joint-space
            terms (:func:`propose_law`, :mod:`calib.effects.laws`).
        channels: extra recorded channels ``{name: (N,) or (N, C)}`` (a temperature) the law's
            terms may use.
        search_rows_max: measurements above which the searched parameters' grids are scanned on
            a subsample and confirmed on every row (default :data:`SEARCH_ROWS_MAX`; the
            discovery's ``search`` says which form ran).
        search_subsample_rows: rows of that subsample (default :data:`SEARCH_SUBSAMPLE_ROWS`).

    Raises:
        ValueError: too few rows, an unknown candidate or one that does not apply to the robot.
    """
    robot = data.robot
    if candidates is None:
        candidates = effects_for(robot)
    # A recording at several payloads: compliance with its payload terms (calib.effects.compliance).
    candidates = [for_payload(m, data) for m in _as_models(candidates)]
    models = candidate_forms(candidates, per_chain)
    for m in models.values():
        _check_applies(m, robot)
    if data.n < MIN_ROWS:
        raise ValueError(f"effect discovery needs at least {MIN_ROWS} measurements, got {data.n}")
    kept = np.arange(data.n)
    flagged: list[int] = []
    for _ in range(max_rounds):
        sub = data.subset(kept)
        sub, geo, fit, sel = _choose(sub, models, max_effects, min_delta_bic, folds, seed, search_rows_max,
                                search_subsample_rows)
        scan = outlier_scan(sub, fit, alpha=outlier_alpha)
        new = scan["flagged"]
        if scan["model_wrong"] or not new or kept.size - len(new) < MIN_ROWS \
                or len(flagged) + len(new) > MAX_BAD_FRACTION * data.n:
            if not scan["model_wrong"] and new and len(flagged) + len(new) > MAX_BAD_FRACTION * data.n:
                scan = dict(scan, model_wrong=True, flagged=[])
            break
        flagged += [int(kept[j]) for j in new]
        kept = np.delete(kept, new)
    else:  # the last round's removal is not re-checked: re-run the choice on the rows kept
        sub = data.subset(kept)
        sub, geo, fit, sel = _choose(sub, models, max_effects, min_delta_bic, folds, seed, search_rows_max,
                                search_subsample_rows)
        scan = dict(outlier_scan(sub, fit, alpha=outlier_alpha), flagged=[])
    tests = remainder_tests(sub, fit, alpha=alpha)
    _SPANS.pop(fit, None)  # the outlier scan and the tests are done with its bases (at 100,000 rows, 0.4 GB)
    explained = tests["explained"]
    separated = separation(sub, fit, models, sel["unseparated"])
    aliases = [{"named": models[a].name, "rival": b, "delta_bic": gap, "correlation": corr, "nested": nested}
               for a, b, gap, corr, nested in sel["rivals"]
               if models[a] in fit.models and (nested or models[b].name not in fit.effects)]
    evidence = _evidence(geo, sel, models, fit, alpha)
    remaining = tests["remaining"]
    if scan["model_wrong"]:
        remaining = dict(remaining, bad_rows=len(scan["bad"]),
                         summary=remaining["summary"] + f"; {len(scan['bad'])} of {sub.n} rows look bad (more than "
                         f"{100 * MAX_BAD_FRACTION:.0f}%): the model is wrong, not the data, and no row is left out")
    law = None
    if laws and not explained:
        try:
            law = propose_law(sub, fit, channels=None if channels is None else
                              {k: np.asarray(v)[kept] for k, v in channels.items()}, folds=folds, seed=seed)
        except np.linalg.LinAlgError:
            if fit.basis is None:
                raise
            # With combinations held at the prior a law's terms can resemble them; its exact fit
            # then runs away along them: no law proposed (the pose set cannot tell it from the geometry).
            law = None
    return Discovery(effects=fit.effects, explained=explained, remaining=remaining,
                     partial=() if explained else fit.effects, chosen=fit, geometry=geo, evidence=evidence,
                     tests=tests, aliases=aliases, outliers=scan, flagged=tuple(sorted(flagged)), kept=kept,
                     located=locate_mismatch(sub, geo), proposed_law=law, separation=separated, search=sel["search"])


def separation(data: EffectData, fit: EffectFit, models: dict, unseparated: dict) -> dict:
    """What the rows cannot separate, and the poses that would (:mod:`calib.effects.separability`).

    Args:
        data: the rows; fit: the chosen model's fit on them (its ``basis``).
        models: the candidate forms (key -> effect); unseparated: ``{key: {"extra",
            "combinations"}}`` of the forms the selection set aside (:meth:`_Linear.unseparated`).

    Returns:
        JSON-ready dict, empty when every geometric combination is determined:
        ``left_to_prior`` (the held combinations in words, :meth:`GeometryBasis.combinations`),
        ``determined`` and ``free`` (how many geometric combinations are fitted, of how many),
        ``unseparated`` (per form: ``effect``, ``form``, ``combinations`` each with the geometric
        combination that mimics it, ``separated_by`` the pose families that would separate it),
        ``poses`` (per family of added poses, :func:`calib.effects.separability.pose_families`:
        how many of the held combinations it would determine, the forms it would separate, the
        poses reachable of those tried).
    """
    basis = fit.basis
    if basis is None:
        return {}
    robot = data.robot
    names = [robot.table.names[i] for i in basis.free]
    out = {"determined": basis.size, "free": int(basis.free.size),
           "left_to_prior": basis.combinations(names, robot.table.chains[basis.free]),
           "unseparated": [{"effect": models[k].name, "form": k, "combinations": u["combinations"], "separated_by": []}
                           for k, u in unseparated.items()],
           "poses": {}}
    families = pose_families(data.measured, robot.workspace_bounds(), robot.pose_names, robot.pose_units)
    for family, poses in families.items():
        joints, ok = np.full((len(poses), robot.n_chains), np.nan), np.zeros(len(poses), dtype=bool)
        for k in range(len(poses)):
            try:
                joints[k] = robot.inverse_kinematics(fit.theta, poses[k:k + 1])[0]
                check_joint_limits(robot, joints[k:k + 1])
                ok[k] = True
            except KinematicsError:
                pass
        if not ok.any():
            out["poses"][family] = {"reachable": 0, "tried": len(poses), "determines": 0, "separates": []}
            continue
        added = EffectData(robot, data.theta, joints[ok], poses[ok], data.t_s[-1] + np.arange(1, ok.sum() + 1), data.noise,
                           payload_kg=None if data.payload_kg is None else np.full(ok.sum(), data.payload_kg.mean()))
        both = EffectData(robot, data.theta, np.vstack([data.joints, added.joints]),
                          np.vstack([data.measured, added.measured]), np.concatenate([data.t_s, added.t_s]), data.noise,
                          np.vstack([data.direction, added.direction]), np.vstack([data.last_move, added.last_move]),
                          None if data.payload_kg is None else np.concatenate([data.payload_kg, added.payload_kg]),
                          data.tolerance)
        aug = _geometry(both)
        info = basis.held.T @ (aug.information if aug is not None else _information(both, basis)) @ basis.held
        determines = int(np.sum(np.linalg.eigvalsh(0.5 * (info + info.T)) > HELD_INFORMATION))
        lin = _Linear(both, _Stub(fit.theta, aug))
        separates = [u["form"] for u in out["unseparated"]
                     if not lin.unseparated(models[u["form"]], unseparated[u["form"]]["extra"])]
        for u in out["unseparated"]:
            if u["form"] in separates:
                u["separated_by"].append(family)
        out["poses"][family] = {"reachable": int(ok.sum()), "tried": len(poses), "determines": determines,
                                "separates": separates}
    return out


@dataclass(frozen=True)
class _Stub:
    """What :class:`_Linear` takes of a geometry fit."""

    theta: np.ndarray
    basis: GeometryBasis | None


def _information(data: EffectData, basis: GeometryBasis) -> np.ndarray:
    """(F, F) the rows' information on ``basis``'s free parameters, tolerance units."""
    robot = data.robot
    jac = robot.closure_jacobians(data.theta, data.joints, data.measured)
    winv = np.linalg.inv(np.linalg.cholesky(_noise_covariance(robot, jac, data)))
    G = _whiten(winv, jac.parameters[:, :, basis.free]).reshape(-1, basis.free.size) * basis.std
    return G.T @ G


def propose_law(data: EffectData, fit: EffectFit, *, channels: dict | None = None, folds: int = 5,
                seed: int = 0) -> ProposedLaw | None:
    """The law over joint-space terms that explains what ``fit`` (geometry and the library's
    effects) leaves, searched on the fit linearised at its solution (:func:`calib.effects.laws.search_law`)
    and then fitted exactly with it; None when no term earns its place. The library's effects
    are then re-examined (:func:`reexamined`), and the law searched again without those dropped
    and without each effect kept in turn: a trial whose law has no more terms and whose BIC is no
    higher replaces the model (its effects dropped too)."""
    def space(f: EffectFit) -> LawSpace:
        jac = data.robot.closure_jacobians(f.theta, data.joints + f.joint_displacement(data), data.measured)
        winv = np.linalg.inv(np.linalg.cholesky(_noise_covariance(data.robot, jac, data)))
        return LawSpace(data, winv, jac.joints, f.span, f.whitened, dict(channels or {}))

    found = search_law(space(fit), folds=folds, seed=seed)
    if not found.terms:
        return None
    eff = law_effect(found.terms, found.granularity, channels)
    extras = {m.name: e for m, e in zip(fit.models, fit.extras) if e is not None}
    exact = fit_effects(data, fit.models + (eff,), extras=extras, start=fit.theta)
    exact, dropped = reexamined(data, exact, eff, extras)
    # The law was searched with the library's effects in: searched again without those dropped,
    # and without each one kept in turn, its form may differ (a dead band named for a friction
    # growing with the load took each joint's mean level, and on three chains the law's
    # per-joint spread no longer paid for two more constants). A trial is kept when its law has
    # no more terms (it does not turn a library effect into a term of its own: on hexapod law
    # seed 900 an actuator scale left out came back as the term `stroke`) and the BIC is no higher.
    def searched_without(names: tuple):
        kept = tuple(m for m in fit.models if m.name not in names)
        ex = {k: v for k, v in extras.items() if k not in names}
        rest = fit_effects(data, kept, extras=ex, start=fit.theta)
        again = search_law(space(rest), folds=folds, seed=seed)
        if not again.terms or len(again.terms) > len(found.terms):
            return None
        e2 = law_effect(again.terms, again.granularity, channels)
        return again, e2, fit_effects(data, kept + (e2,), extras=ex, start=rest.theta)

    for m in (None,) + fit.models:
        if m is not None and m.name in dropped:
            continue
        names = dropped if m is None else dropped + (m.name,)
        if not names:
            continue
        trial = searched_without(names)
        if trial is not None and trial[2].bic() <= exact.bic():
            (found, eff, exact), dropped = trial, names
    floor = float(_rms(closure_noise_std(data.robot, exact.theta, data)))
    cv_w, cv_mm = space(exact).cv([], folds, seed)
    return ProposedLaw(found, eff, exact, remainder_tests(data, exact)["remaining"], floor, cv_w, cv_mm, dropped)


def reexamined(data: EffectData, exact: EffectFit, law: Effect, extras: dict,
               min_delta_bic: float = MIN_DELTA_BIC) -> tuple[EffectFit, tuple]:
    """The library's effects of ``exact`` re-examined once ``law`` is in: the one whose removal
    costs least is dropped while that cost (the BIC's rise, exact refits) is below
    ``min_delta_bic``, the evidence an effect needs to enter at all; a law that contains an
    effect's physics (a settle lag and a dead band both follow the last move) leaves it nothing to
    explain. Returns the fit kept and the names dropped, in the order dropped."""
    dropped: list[str] = []
    while True:
        trials = []
        for m in exact.models:
            if m is law:
                continue
            rest = tuple(x for x in exact.models if x is not m)
            f = fit_effects(data, rest, extras={k: v for k, v in extras.items() if k != m.name}, start=exact.theta)
            trials.append((f.bic() - exact.bic(), m.name, f))
        cheapest = min(trials, key=lambda t: t[0], default=None)
        if cheapest is None or cheapest[0] >= min_delta_bic:
            return exact, tuple(dropped)
        dropped.append(cheapest[1])
        exact = cheapest[2]


def _evidence(geo: EffectFit, sel: dict, models: dict, fit: EffectFit, alpha: float) -> dict:
    """The discovery's ``evidence``: per candidate form alone (keys as in
    :func:`candidate_forms`), the selection's steps, the chosen model's cross-validated residual
    and each named effect's granularity."""
    evidence = {"geometry_chi2_test": {"chi2": geo.chi2, "dof": geo.dof, "p_value": geo.p_value, "alpha": alpha},
                "none": {"chi2": geo.chi2, "dof": geo.dof, "p_value": geo.p_value, "n_params": geo.n_params,
                         "bic": geo.bic(), "delta_bic_vs_none": 0.0, "cv_whitened_rms": sel["cv_geometry"]}}
    for name, e in sel["single"].items():
        evidence[name] = {"chi2_linearised": e["chi2"], "n_params": e["n_params"],
                          "delta_bic_vs_none": e["delta_bic_vs_none"], "cv_whitened_rms": e["cv_whitened_rms"]}
    replaced = dict(sel.get("nested_replaced", []))
    for step in sel["steps"]:
        if step["added"] in evidence:
            evidence[step["added"]]["delta_bic_when_added"] = step["trials"][step["added"]]["delta_bic"]
        new = replaced.get(step["added"])
        if new in evidence and new in step["trials"]:  # named in its family member's place
            evidence[new]["delta_bic_when_added"] = step["trials"][new]["delta_bic"]
    for key, m in models.items():  # a per-chain form named: its evidence under the effect's name too
        if m in fit.models and key != m.name and "delta_bic_when_added" in evidence.get(key, {}):
            evidence.setdefault(m.name, {})["delta_bic_when_added"] = evidence[key]["delta_bic_when_added"]
    evidence["steps"] = [{"added": s["added"], "dropped": s["dropped"],
                          "delta_bic": {k: v["delta_bic"] for k, v in s["trials"].items()}} for s in sel["steps"]]
    evidence["cv_whitened_rms_chosen"] = sel["cv_chosen"]
    evidence["granularity"] = {m.name: m.granularity for m in fit.models}
    if replaced:
        evidence["nested_replaced"] = [list(p) for p in replaced.items()]
    if sel.get("insignificant"):
        evidence["dropped_not_significant"] = sel["insignificant"]
    return evidence


#: The former name (one effect at a time); the same function.
discover_effect = discover_effects


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
