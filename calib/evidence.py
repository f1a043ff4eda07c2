"""Tolerances learnt from the data: the prior's scale that maximises the evidence (empirical Bayes).

A machine built by hand is millimetres off its drawing; a precision hexapod micrometres. The
robot's documented ``default_parameter_tolerance`` (:class:`calib.prior.ParameterPrior`) cannot
fit both, and a prior far too tight holds every parameter at its nominal value whatever the rows
say. Where no tolerance is declared the run estimates the prior's scale from the rows instead:
one factor per unit (mm, rad) on the reference prior's standard deviations, chosen to maximise
the marginal likelihood of the rows (MacKay, "Bayesian interpolation", Neural Computation 4, 1992;
Bishop, *Pattern Recognition and Machine Learning*, section 3.5). Where a tolerance is declared the
same figures say whether the rows contradict it (:attr:`ToleranceEstimate.contradicted`).

The model is the fit linearised at its solution (a maximum a posteriori fit under the reference
prior, :class:`calib.engine.IdentificationResult`): with the free parameters' errors ``d = theta -
mean`` (K,), the whitened rows ``y = J d + e`` (``e`` ~ N(0, I), the declared noise), and the prior
``d ~ N(0, S(s))``, ``S(s) = diag((s_u sigma_k)^2)`` (``sigma_k`` the reference standard deviation,
``s_u`` the factor of parameter k's unit), everything the evidence needs is in the fit's posterior:
its precision ``P0 = Sigma0^-1`` gives the data's information ``H = J^T J = P0 - S0^-1`` and its
mean ``m0`` the data's vector ``b = J^T y = P0 m0`` (nuisance unknowns fitted without a prior, an
instrument frame or target offsets, are already marginalised in ``Sigma0``). Then, up to a
constant,

    log p(y | s) = 1/2 b^T A^-1 b - 1/2 log det(I + S^1/2 H S^1/2),     A = H + S^-1,

maximised by MacKay's fixed point per unit ``u``:
``gamma_u = sum_k in u (1 - (A^-1)_kk / S_kk)`` (the parameters of unit u the data determine) and
``s_u^2 = sum_k in u (m_k / sigma_k)^2 / gamma_u``, ``m = A^-1 b``. Directions the rows do not see
add nothing to ``gamma`` or to ``m``: a gauge or a plane of poses does not drive the scale to zero
or to infinity, the estimate comes from the directions the data determine. A unit whose
parameters the rows leave undetermined (``gamma_u`` below :data:`MIN_DETERMINED`) keeps the
reference scale. The cost is one small (K, K) problem per step, nothing beside the fit it reads.

The code evaluates the same evidence as a change from the fit it reads (``m = m0 + d``, the rows'
residual ``|y - J m0|^2 - 2 d^T S0^-1 m0 + d^T H d``, the posterior's energy at its own mean):
``b^T A^-1 b`` is of order ``|H| |m|^2``, a trillion on millimetre errors seen at micrometre noise,
and its rounding alone moved the evidence by thousands of nats between BLAS kernels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .prior import ParameterPrior
from .robot import Robot

__all__ = ["ToleranceEstimate", "tolerance_from_data", "MIN_DETERMINED", "SCALE_BOUNDS", "CONTRADICTION_NATS",
           "CONTRADICTION_FACTOR", "FAR_TOLERANCES"]

#: A unit whose free parameters the rows determine less than this many of (``gamma_u``, MacKay's
#: effective number of parameters) keeps the reference prior's scale: the rows say nothing of it.
MIN_DETERMINED = 1.0
#: The estimated factor on the reference standard deviations is kept within these bounds (a
#: thousandth to ten thousand times): beyond them the linearised evidence is no guide.
SCALE_BOUNDS = (1e-3, 1e4)
#: A reference tolerance counts as contradicted by the rows when the evidence at the estimate
#: exceeds the evidence at the reference by more than this many nats (a likelihood ratio of about
#: 20, "strong" on Jeffreys' scale) ...
CONTRADICTION_NATS = 3.0
#: ... and the estimated tolerance of some unit is more than this factor from the reference's.
CONTRADICTION_FACTOR = 3.0
#: A parameter the rows determine counts as far from nominal, in the reference tolerance's
#: terms, beyond this many reference standard deviations.
FAR_TOLERANCES = 3.0
#: Smallest posterior variance, relative to the prior's, read back from a fit's covariance.
POSTERIOR_FLOOR = 1e-12
#: Fixed-point steps: at most this many, stopping when no factor's square moves by a relative
#: :data:`STEP_RTOL` (the evidence is flat near its maximum: a tolerance right to a part in a
#: million is far more than the prior needs).
MAX_STEPS = 500
STEP_RTOL = 1e-5


@dataclass(frozen=True, eq=False)
class ToleranceEstimate:
    """The prior's scale learnt from the rows (:func:`tolerance_from_data`).

    Attributes:
        prior: the estimated prior (P,): the reference's means, its standard deviations times the
            factor of each parameter's unit.
        reference: the prior the fit was made under (the robot's default or the declared one).
        factor: ``{unit: s_u}`` the factor on the reference's standard deviations of that unit's
            parameters (1.0 where the rows determine none of them).
        tolerance: ``{unit: tolerance}`` the estimated one-sigma tolerance of the unit (the
            reference's typical value of the unit, its median over the free parameters, times the
            factor), in the unit.
        reference_tolerance: ``{unit: tolerance}`` the reference's typical value of the unit.
        determined: ``{unit: gamma_u}`` MacKay's effective number of parameters of that unit the
            rows determine, at the estimate.
        log_evidence_gain: log evidence at the estimate minus at the reference (nats, >= 0 up to
            the fixed point's precision).
        far: ``((name, reference tolerances from nominal), ...)`` the free parameters the rows
            place away from nominal (estimated error beyond :data:`FAR_TOLERANCES` of its own
            posterior standard deviation at the estimate) and beyond :data:`FAR_TOLERANCES`
            reference standard deviations from nominal, farthest first (the estimated error over
            the reference standard deviation).
        prior_units: (P,) the unit of every parameter of the robot's table.
        noise_scale: the rows' scatter about the linearised model, in declared noise standard
            deviations, estimated with the scale (``1 / sqrt(beta)``): about 1 when the declared
            noise is right and the geometry explains the rows; well above 1 when physics the
            geometry leaves out adds to the scatter (it then does not inflate the tolerance).
    """

    prior: ParameterPrior
    reference: ParameterPrior
    factor: dict
    tolerance: dict
    reference_tolerance: dict
    determined: dict
    log_evidence_gain: float
    far: tuple = ()
    prior_units: tuple = ()
    noise_scale: float = 1.0

    @property
    def contradicted(self) -> bool:
        """The rows contradict the reference tolerance: the evidence prefers the estimate by more
        than :data:`CONTRADICTION_NATS` and some unit's factor is beyond :data:`CONTRADICTION_FACTOR`
        either way."""
        beyond = any(f > CONTRADICTION_FACTOR or f < 1.0 / CONTRADICTION_FACTOR for f in self.factor.values())
        return bool(self.log_evidence_gain > CONTRADICTION_NATS and beyond)

    @property
    def wider(self) -> tuple:
        """The units whose errors the rows show wider than the reference tolerance, contradicting it:
        the evidence prefers the estimate by more than :data:`CONTRADICTION_NATS` and the unit's
        factor is beyond :data:`CONTRADICTION_FACTOR`."""
        if self.log_evidence_gain <= CONTRADICTION_NATS:
            return ()
        return tuple(u for u, f in self.factor.items() if f > CONTRADICTION_FACTOR)

    def widened_prior(self) -> ParameterPrior:
        """The reference prior with the units of :attr:`wider` at their estimated scale and every
        other unit at the reference's: the prior a run takes when no tolerance is declared. A prior
        looser than the machine costs little where the rows determine the parameters, one too
        tight biases them; so the documented default stands unless the rows show it too tight."""
        std = np.array(self.reference.std, dtype=float)
        units = np.array([str(u) for u in self.prior_units])
        for u in self.wider:
            std[units == u] *= self.factor[u]
        return ParameterPrior(mean=self.reference.mean, std=std)

    def tolerance_words(self, which: str = "estimate") -> str:
        """``"2.1 mm, 0.012 rad"``: the estimated (or ``"reference"``) tolerance per unit."""
        tol = self.tolerance if which == "estimate" else self.reference_tolerance
        return ", ".join(f"{v:.3g} {u}" for u, v in tol.items())

    def evidence_words(self) -> str:
        """Why the reference is (or is not) contradicted, in figures: ``"28 parameters the rows
        determine lie beyond 3 of its tolerances from nominal (up to 29 for B2.y); the evidence
        prefers the estimate by 412 nats"``."""
        parts = []
        if self.far:
            name, z = self.far[0]
            parts.append(f"{len(self.far)} parameter{'s' if len(self.far) > 1 else ''} the rows determine "
                         f"lie{'s' if len(self.far) == 1 else ''} beyond {FAR_TOLERANCES:g} times the tolerance "
                         f"from nominal (up to {z:.3g} for {name})")
        narrower = [u for u, f in self.factor.items() if f < 1.0 / CONTRADICTION_FACTOR]
        if narrower:
            parts.append(f"the rows show {' and '.join(narrower)} errors {1.0 / min(self.factor.values()):.3g} "
                         "times smaller than it")
        parts.append(f"the evidence prefers the estimate by {self.log_evidence_gain:.3g} nats")
        return "; ".join(parts)

    def summary(self) -> dict:
        """JSON-ready figures."""
        return {"tolerance": dict(self.tolerance), "reference_tolerance": dict(self.reference_tolerance),
                "factor": dict(self.factor), "determined_parameters": dict(self.determined),
                "log_evidence_gain_nats": float(self.log_evidence_gain), "contradicted": self.contradicted,
                "wider_than_reference": list(self.wider), "noise_scale": float(self.noise_scale),
                "far_from_nominal": [{"name": n, "reference_tolerances": float(z)} for n, z in self.far],
                "method": "empirical Bayes: the prior's scale per unit maximising the marginal likelihood of "
                          "the rows (MacKay's fixed point, the fit linearised at its solution)"}


def tolerance_from_data(result, reference: ParameterPrior | None = None) -> ToleranceEstimate:
    """The prior's scale per unit that maximises the evidence of the rows behind ``result``.

    Args:
        result: a :class:`calib.engine.IdentificationResult` fitted under a prior (its ``prior``,
            ``theta``, ``covariance`` the posterior's, ``free_indices``, ``robot``).
        reference: the prior whose standard deviations are scaled; default ``result.prior``. Its
            means must be the prior means of the fit (the scale, not the centre, is estimated).

    Raises:
        ValueError: a result without a prior, or whose covariance is not finite.
    """
    if getattr(result, "prior", None) is None:
        raise ValueError("the tolerance is learnt from a fit made under a prior (result.prior is None)")
    robot: Robot = result.robot
    reference = result.prior if reference is None else reference
    reference.check(robot)
    idx = result.free_indices
    cov0 = np.asarray(result.covariance, dtype=float)[np.ix_(idx, idx)]
    if not np.all(np.isfinite(cov0)):
        raise ValueError("the fit's covariance is not finite: no tolerance can be learnt from it")
    fit_std = np.asarray(result.prior.std, dtype=float)[idx]
    sigma = np.asarray(reference.std, dtype=float)[idx]
    m0 = np.asarray(result.theta, dtype=float)[idx] - np.asarray(result.prior.mean, dtype=float)[idx]
    rows = _Rows(H=_data_information(cov0, fit_std), m0=m0, g0=m0 / fit_std ** 2, **_scatter(result, m0, fit_std))
    units = np.array([str(u) for u in robot.table.units], dtype=object)[idx]
    names = [robot.table.names[i] for i in idx]
    present = [u for u in dict.fromkeys(units)]
    if len(present) == 1:  # one unit: everything in one eigenbasis
        eig = _eigen(rows, sigma)
        f, beta = _one_unit_fixed_point(rows, sigma, eig)
        if f == 1.0:
            beta = _one_unit_noise(rows, eig, 1.0)
        factor = {present[0]: f}
        m, post_var, top = _one_unit_state(rows, sigma, eig, f, beta)
        gain = top - _one_unit_state(rows, sigma, eig, 1.0, _one_unit_noise(rows, eig, 1.0))[2]
        std_at = sigma * f
    else:
        factor, beta = _fixed_point(rows, sigma, units, present)
        std_at = sigma * _per_parameter(factor, units)
        gain = _log_evidence(rows, std_at, beta) - _log_evidence(rows, sigma, _noise_fixed_point(rows, sigma))
        m, post_var, _ = _posterior(rows, std_at, beta)
    gamma = 1.0 - post_var / std_at ** 2
    determined = {u: float(np.sum(gamma[units == u])) for u in present}
    z = np.abs(m) / sigma
    seen = np.abs(m) > FAR_TOLERANCES * np.sqrt(post_var)  # the rows place it away from nominal
    far = sorted(((names[k], float(z[k])) for k in range(len(idx)) if seen[k] and z[k] > FAR_TOLERANCES),
                 key=lambda t: -t[1])
    std = np.array(reference.std, dtype=float)
    all_units = np.array(robot.table.units)
    for u, f in factor.items():
        std[all_units == u] *= f
    typical = {u: float(np.median(sigma[units == u])) for u in present}
    return ToleranceEstimate(prior=ParameterPrior(mean=reference.mean, std=std), reference=reference,
                             factor={u: float(f) for u, f in factor.items()},
                             tolerance={u: typical[u] * float(factor[u]) for u in present},
                             reference_tolerance=typical, determined=determined, log_evidence_gain=float(gain),
                             far=tuple(far),
                             prior_units=tuple(str(u) for u in robot.table.units),
                             noise_scale=float(1.0 / np.sqrt(beta)))


def _data_information(cov0: np.ndarray, prior_std: np.ndarray) -> np.ndarray:
    """The data's information (K, K) behind a posterior of covariance ``cov0`` under the prior
    N(0, diag(prior_std^2)). Computed in the prior's scale (``C = D^-1 cov0 D^-1``,
    ``D = diag(prior_std)``: a well-conditioned matrix whose eigenvalues lie in (0, 1], floored at
    :data:`POSTERIOR_FLOOR`), so the scaled information's eigenvalues ``1/w - 1`` are >= 0 but for
    rounding."""
    D = prior_std
    C = cov0 / np.outer(D, D)
    C = 0.5 * (C + C.T)
    w, V = np.linalg.eigh(C)
    # A direction the rows pin far below the prior (a fit declaring angles exact; a covariance
    # whose pseudo-inverse dropped it) has a scaled variance at or near zero: it is held at
    # POSTERIOR_FLOOR, a millionth of the prior's standard deviation, as good as exact here.
    w = np.clip(w, POSTERIOR_FLOOR, None)
    Hs = (V / w) @ V.T - np.eye(len(D))                 # scaled information D H D (eigenvalues 1/w - 1 >= 0
    return 0.5 * (Hs + Hs.T) / np.outer(D, D)           # but for rounding, which the users clip)


def _per_parameter(factor: dict, units: np.ndarray) -> np.ndarray:
    return np.array([factor[u] for u in units])


@dataclass(frozen=True)
class _Rows:
    """The rows as the evidence sees them, about the fit they came from: the data's information
    ``H`` (K, K), the fit's estimate ``m0`` (K,, from the prior mean) and its prior's pull there
    ``g0 = m0 / sigma0^2`` (K,), which is ``J^T (y - J m0)`` at the fit's optimum; ``r0`` the
    whitened rows' residual ``|y - J m0|^2`` and their number ``n`` (less the nuisance unknowns), or
    ``r0`` None where the fit does not say (the noise scale is then the declared one).

    Every quantity below is written as a change from the fit (``d = m - m0``): the rows' residual
    is ``r0 - 2 d.g0 + d^T H d``. The textbook form (``y^T y - 2 b^T m + m^T H m``, ``b = J^T y``)
    subtracts terms of order ``|H| |m|^2`` (1e12 on a hand-built machine's millimetre errors at
    micrometre noise) to reach a residual of order ``n``: its rounding changed the evidence by
    thousands of nats from one BLAS kernel to another."""

    H: np.ndarray
    m0: np.ndarray
    g0: np.ndarray
    r0: float | None
    n: float


def _scatter(result, m0: np.ndarray, fit_std: np.ndarray) -> dict:
    """``{"r0", "n"}`` of the whitened rows behind ``result``: its chi-square holds the rows' and
    the prior's (``|r|^2 + |m0 / sigma0|^2``)."""
    prior_term = float(np.sum((m0 / fit_std) ** 2))
    chi2, n = float(getattr(result, "chi2", np.nan)), float(getattr(result, "dof", 0))
    rows_chi2 = chi2 - prior_term
    if not (np.isfinite(rows_chi2) and rows_chi2 >= 0 and n > m0.size):
        return {"r0": None, "n": n}
    return {"r0": rows_chi2, "n": n}


def _factor(rows: _Rows, std: np.ndarray, beta: float):
    """``(L, B^-1)``: the Cholesky factor of ``B = beta S^1/2 H S^1/2 + I`` and its inverse."""
    Bm = beta * std[:, None] * rows.H * std[None, :] + np.eye(len(std))
    L = np.linalg.cholesky(Bm)
    Linv = np.linalg.solve(L, np.eye(len(std)))
    return L, Linv.T @ Linv


def _shift(rows: _Rows, std: np.ndarray, beta: float, Binv: np.ndarray) -> np.ndarray:
    """``d = m - m0`` (K,): the posterior mean under N(0, diag(std^2)) and the noise scale
    ``beta``, less the fit's. ``A d = beta g0 - m0 / std^2`` (``A = beta H + S^-1``), solved in
    the prior's scale with ``B^-1``."""
    return std * (Binv @ (beta * std * rows.g0 - rows.m0 / std))


def _posterior(rows: _Rows, std: np.ndarray, beta: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(m, diag(A^-1), d)``, ``A = beta H + S^-1``, under the prior N(0, diag(std^2)): mean (K,),
    variances (K,) and the mean's change from the fit's (K,). ``B = beta S^1/2 H S^1/2 + I`` has
    eigenvalues >= 1: inverted directly."""
    Binv = np.linalg.inv(beta * std[:, None] * rows.H * std[None, :] + np.eye(len(std)))
    d = _shift(rows, std, beta, Binv)
    return rows.m0 + d, std ** 2 * np.diag(Binv), d


def _residual_change(rows: _Rows, d: np.ndarray) -> float:
    """``|y - J m|^2 - |y - J m0|^2 = -2 d.g0 + d^T H d`` for ``m = m0 + d``."""
    return float(-2.0 * rows.g0 @ d + d @ rows.H @ d)


def _evidence(rows: _Rows, beta: float, residual_change: float, prior_term: float, log_det: float) -> float:
    """``n/2 log beta - beta/2 |y - J m|^2 - 1/2 m^T S^-1 m - 1/2 log det B``, the log evidence up
    to a constant (without ``r0``, at ``beta = 1``, less ``r0 / 2``: the same for every prior)."""
    out = -0.5 * beta * residual_change - 0.5 * prior_term - 0.5 * log_det
    if rows.r0 is not None:
        out += 0.5 * rows.n * np.log(beta) - 0.5 * beta * rows.r0
    return float(out)


def _log_evidence(rows: _Rows, std: np.ndarray, beta: float = 1.0) -> float:
    """The log evidence of the rows under the prior N(0, diag(std^2)) and noise scale ``beta``
    (:func:`_evidence`), at the posterior mean: a stationary point, so the solve's rounding enters
    to second order only."""
    L, Binv = _factor(rows, std, beta)
    d = _shift(rows, std, beta, Binv)
    m = rows.m0 + d
    return _evidence(rows, beta, _residual_change(rows, d), float(np.sum((m / std) ** 2)),
                     2.0 * float(np.sum(np.log(np.diag(L)))))


def _beta_update(rows: _Rows, d: np.ndarray, gamma: float) -> float:
    """MacKay's noise update ``beta = (n - gamma) / |y - J m|^2`` (1 without ``r0``)."""
    if rows.r0 is None:
        return 1.0
    res = rows.r0 + _residual_change(rows, d)
    return float(np.clip((rows.n - gamma) / res, 1e-8, 1e8)) if res > 0 else 1.0


def _noise_fixed_point(rows: _Rows, std: np.ndarray) -> float:
    """The noise scale ``beta`` that maximises the evidence under the prior ``std`` (fixed): the
    root in ``log beta`` of MacKay's update ``beta = (n - gamma) / |y - J m|^2`` (Brent's method on
    a bracket grown tenfold a step; a dozen posteriors where the plain iteration takes many)."""
    if rows.r0 is None:
        return 1.0

    def gap(log_beta: float) -> float:
        beta = float(np.exp(log_beta))
        _, post_var, d = _posterior(rows, std, beta)
        update = _beta_update(rows, d, float(np.sum(1.0 - post_var / std ** 2)))
        return float(np.log(update)) - log_beta

    lo, hi = -np.log(10.0), np.log(10.0)
    f_lo, f_hi = gap(lo), gap(hi)
    for _ in range(8):
        if f_lo * f_hi <= 0:
            break
        if f_lo < 0:
            lo -= np.log(10.0)
            f_lo = gap(lo)
        else:
            hi += np.log(10.0)
            f_hi = gap(hi)
    if f_lo * f_hi > 0:
        return 1.0
    from scipy.optimize import brentq  # only where a noise scale is estimated

    return float(np.exp(brentq(gap, lo, hi, xtol=STEP_RTOL)))


@dataclass(frozen=True)
class _Eigen:
    """The scaled information ``D H D = V diag(lam) V^T`` (``lam`` clipped at 0) and, in its
    basis, the fit's estimate ``z0 = V^T (m0 / D)`` and its prior's pull ``p0 = V^T (D g0)``."""

    lam: np.ndarray
    V: np.ndarray
    z0: np.ndarray
    p0: np.ndarray


def _eigen(rows: _Rows, sigma: np.ndarray) -> _Eigen:
    lam, V = np.linalg.eigh(sigma[:, None] * rows.H * sigma[None, :])
    return _Eigen(lam=np.clip(lam, 0.0, None), V=V, z0=V.T @ (rows.m0 / sigma), p0=V.T @ (sigma * rows.g0))


def _one_unit_terms(eig: _Eigen, s: float, beta: float):
    """``(shrink, gamma, z, dz, residual change)`` with one factor ``s`` on the reference and the
    noise scale ``beta``, in the eigenbasis: ``shrink = 1 / (beta s^2 lam + 1)``, the posterior
    mean ``z`` (of ``m / D``) and its change from the fit's ``dz = (beta s^2 p0 - z0) shrink``."""
    shrink = 1.0 / (beta * s * s * eig.lam + 1.0)
    gamma = float(np.sum(beta * s * s * eig.lam * shrink))
    dz = (beta * s * s * eig.p0 - eig.z0) * shrink
    z = eig.z0 + dz
    return shrink, gamma, z, dz, float(-2.0 * eig.p0 @ dz + eig.lam @ (dz * dz))


def _one_unit_fixed_point(rows: _Rows, sigma: np.ndarray, eig: _Eigen | None = None) -> tuple[float, float]:
    """MacKay's fixed point with a single factor ``s`` and the noise scale ``beta``, in the
    eigenbasis of the scaled information (:class:`_Eigen`): ``gamma = sum beta s^2 l /
    (beta s^2 l + 1)``, ``s^2 = |z|^2 / gamma``, ``beta = (n - gamma) / |y - J m|^2``: O(K) a
    step after one eigendecomposition. ``(s, beta)``."""
    eig = _eigen(rows, sigma) if eig is None else eig
    s2, beta, (lo, hi) = 1.0, 1.0, SCALE_BOUNDS
    for _ in range(MAX_STEPS):
        _, gamma, z, _, change = _one_unit_terms(eig, np.sqrt(s2), beta)
        if gamma < MIN_DETERMINED:
            return 1.0, beta
        new_s2 = float(np.clip(np.sum(z * z) / gamma, lo * lo, hi * hi))
        new_beta = beta
        if rows.r0 is not None:
            res = rows.r0 + change
            new_beta = float(np.clip((rows.n - gamma) / res, 1e-8, 1e8)) if res > 0 else 1.0
        moved = max(abs(new_s2 / s2 - 1.0), abs(new_beta / beta - 1.0))
        s2, beta = new_s2, new_beta
        if moved < STEP_RTOL:
            break
    return float(np.sqrt(s2)), beta


def _one_unit_state(rows: _Rows, sigma, eig: _Eigen, s: float, beta: float) -> tuple[np.ndarray, np.ndarray, float]:
    """``(m, diag(A^-1), log evidence)`` with one factor ``s`` on ``sigma``: the quantities
    :func:`_posterior` and :func:`_log_evidence` give, in O(K^2)."""
    shrink, _, z, _, change = _one_unit_terms(eig, s, beta)
    m = sigma * (eig.V @ z)
    post_var = sigma ** 2 * s * s * ((eig.V * eig.V) @ shrink)
    return m, post_var, _evidence(rows, beta, change, float(z @ z) / (s * s), -float(np.sum(np.log(shrink))))


def _one_unit_noise(rows: _Rows, eig: _Eigen, s: float) -> float:
    """The noise scale ``beta`` maximising the evidence with the factor ``s`` held (eigenbasis)."""
    beta = 1.0
    if rows.r0 is None:
        return beta
    for _ in range(MAX_STEPS):
        _, gamma, _, _, change = _one_unit_terms(eig, s, beta)
        res = rows.r0 + change
        new = float(np.clip((rows.n - gamma) / res, 1e-8, 1e8)) if res > 0 else 1.0
        moved, beta = abs(new / beta - 1.0), new
        if moved < STEP_RTOL:
            break
    return beta


def _fixed_point(rows: _Rows, sigma, units, present) -> tuple[dict, float]:
    """MacKay's fixed point for one factor per unit and the noise scale ``beta`` (see the
    module's docstring): ``(factor, beta)``."""
    if len(present) == 1:
        f, beta = _one_unit_fixed_point(rows, sigma)
        return {present[0]: f}, beta
    factor, beta = dict.fromkeys(present, 1.0), 1.0
    lo, hi = SCALE_BOUNDS
    for _ in range(MAX_STEPS):
        std = sigma * _per_parameter(factor, units)
        m, post_var, d = _posterior(rows, std, beta)
        gamma = 1.0 - post_var / std ** 2
        new = {}
        for u in present:
            k = units == u
            g = float(np.sum(gamma[k]))
            new[u] = factor[u] if g < MIN_DETERMINED else float(np.clip(np.sqrt(np.sum((m[k] / sigma[k]) ** 2) / g),
                                                                        lo, hi))
        new_beta = _beta_update(rows, d, float(np.sum(gamma)))
        moved = max([abs(new[u] / factor[u] - 1.0) for u in present] + [abs(new_beta / beta - 1.0)])
        factor, beta = new, new_beta
        if moved < STEP_RTOL:
            break
    # A unit the rows leave undetermined at the estimate keeps the reference's scale.
    std = sigma * _per_parameter(factor, units)
    _, post_var, _ = _posterior(rows, std, beta)
    gamma = 1.0 - post_var / std ** 2
    for u in present:
        if float(np.sum(gamma[units == u])) < MIN_DETERMINED:
            factor[u] = 1.0
    return factor, beta
