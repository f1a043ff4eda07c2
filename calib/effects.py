"""Physics the geometric model leaves out: candidate effects, joint fits, and model choice.

Every candidate effect changes the length of the legs. In joint space the measured pose gives,
for leg i at measurement j, the residual of the geometric model

    r_ij(theta) = |R_j P_i + OP_j - B_i| - dl_i - l_cmd_ij        (mm)

and an effect adds a known *physical* regressor times unknown coefficients:
``r_ij(theta) = X_ij(effect) . phi + noise``. The noise of ``r_j`` (6 legs) comes from the pose
sensor through the pose Jacobian, ``S_j = Jp_j Sigma Jp_j^T``; every fit is whitened by it
(mm and rad never mixed by a raw norm), so that the sum of squares is chi-square distributed
when the model is right.

Candidates (regressors derived from physics, not curve fits):

* ``none``: geometry only.
* ``leg_compliance``: each leg shortens by its axial compression over its stiffness. The axial
  forces follow from the static equilibrium of the platform under the weight of platform and
  payload (unknown magnitude and height of the centre of mass: two coefficients).
* ``joint_friction``: a dead band: each leg stops short of its target by ``delta`` against the
  direction in which it last moved (hysteresis).
* ``thermal_drift``: every leg grows at a constant rate with time.
* ``actuator_scale``: each leg's stroke is scaled by ``1 + s_i`` (transmission error).
* ``periodic_screw_error``: each leg's length is off by ``a_i sin(2 pi q / p) + b_i cos(2 pi q / p)``
  of its stroke ``q``; the pitch ``p`` (the same screws on every leg) is found by a search.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2 as chi2_dist

from ._validate import as_array, as_poses
from .hexapod import Hexapod
from .kinematics import _commanded, _parameter_jacobian, _pose_jacobian, forward_kinematics
from .noise import SensorNoise
from .rotation import rotation_matrix

__all__ = ["MIN_DELTA_BIC", "EFFECTS", "EffectData", "EffectFit", "Discovery", "effect_regressors", "fit_effect",
           "discover_effect", "locate_mismatch", "joint_noise_std", "PITCH_RANGE_MM"]

EFFECTS = ("none", "leg_compliance", "joint_friction", "thermal_drift", "actuator_scale", "periodic_screw_error")
#: Search range of the screw pitch, mm.
PITCH_RANGE_MM = (1.0, 30.0)
# Reference length for the centre-of-mass height coefficient of leg_compliance (conditioning).
_H_REF_MM = 100.0


@dataclass(frozen=True, eq=False)
class EffectData:
    """The measurements an effect analysis needs.

    Attributes:
        nominal: nominal parameter set (geometry of the recording).
        commanded: (N, 6) commanded leg lengths, mm, in the order taken.
        measured: (N, 6) measured poses, mm and rad.
        t_s: (N,) time of each measurement, s.
        noise: declared sensor noise.
        direction: (N, 6) direction (+1 extending, -1 retracting) in which each leg last moved
            before measurement j; the machine starts at the home lengths.
    """

    nominal: Hexapod
    commanded: np.ndarray
    measured: np.ndarray
    t_s: np.ndarray
    noise: SensorNoise
    direction: np.ndarray = field(default=None)

    def __post_init__(self) -> None:
        c = as_array(self.commanded, "commanded", (-1, 6))
        m = as_poses(self.measured, "measured")
        t = as_array(self.t_s, "t_s", (-1,))
        if not (c.shape[0] == m.shape[0] == t.shape[0]):
            raise ValueError(f"commanded, measured and t_s must have the same length, got "
                             f"{c.shape[0]}, {m.shape[0]} and {t.shape[0]}")
        object.__setattr__(self, "commanded", c)
        object.__setattr__(self, "measured", m)
        object.__setattr__(self, "t_s", t)
        if self.direction is None:
            prev = np.vstack([self.nominal.geometry.home_lengths, c[:-1]])
            step = np.sign(c - prev)
            d = np.zeros_like(c)
            last = np.zeros(6)
            for j in range(c.shape[0]):
                last = np.where(step[j] != 0, step[j], last)
                d[j] = last
            object.__setattr__(self, "direction", d)

    @property
    def stroke(self) -> np.ndarray:
        """(N, 6) mm, commanded stroke from the nominal home lengths."""
        return self.commanded - self.nominal.geometry.home_lengths

    def subset(self, rows: np.ndarray) -> "EffectData":
        """The same analysis restricted to ``rows`` (the motion history is kept)."""
        return EffectData(self.nominal, self.commanded[rows], self.measured[rows], self.t_s[rows], self.noise,
                          self.direction[rows])


def _compliance_regressors(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    """(N, 6, 2): leg shortening per unit coefficient for a load at the platform origin and per
    100 mm of height of its centre of mass.

    (A leg's own weight along its axis, ``-u_z``, would be a third regressor, but it is exactly
    the derivative of the leg length with respect to the height of its base joint: the
    geometric errors absorb it completely, so it is left out.)"""
    R = rotation_matrix(poses[:, 3:6])
    a = np.einsum("nij,lj->nli", R, hexapod.platform_joints) + poses[:, None, 0:3]  # joints, base frame
    L = a - hexapod.base_joints[None]
    u = L / np.linalg.norm(L, axis=-1, keepdims=True)
    # Columns of A: the wrench of a unit compressive force in leg i on the platform.
    A = np.concatenate([u, np.cross(a, u)], axis=-1).transpose(0, 2, 1)  # (N, 6, 6)
    W = np.array([0.0, 0.0, -1.0])  # unit weight, base z up
    c0 = poses[:, 0:3]
    b0 = -np.concatenate([np.broadcast_to(W, c0.shape), np.cross(c0, W)], axis=-1)
    ez = R[:, :, 2] * _H_REF_MM
    b1 = -np.concatenate([np.zeros_like(c0), np.cross(ez, W)], axis=-1)
    f0 = np.linalg.solve(A, b0[..., None])[..., 0]
    f1 = np.linalg.solve(A, b1[..., None])[..., 0]
    # Compression shortens the leg.
    return -np.stack([f0, f1], axis=-1)


def effect_regressors(effect: str, hexapod: Hexapod, data: EffectData, pitch_mm: float | None = None) -> np.ndarray:
    """Regressors ``X`` (N, 6, p) of an effect: leg-length change per unit coefficient, mm.

    Args:
        effect: one of :data:`EFFECTS`.
        hexapod: current geometric estimate (for the statics of ``leg_compliance``).
        data: the measurements.
        pitch_mm: the screw pitch, for ``periodic_screw_error``.
    """
    n = data.commanded.shape[0]
    if effect == "none":
        return np.zeros((n, 6, 0))
    if effect == "leg_compliance":
        return _compliance_regressors(hexapod, data.measured)
    if effect == "joint_friction":
        return -data.direction[..., None]
    if effect == "thermal_drift":
        return np.broadcast_to(data.t_s[:, None, None], (n, 6, 1)).copy()
    if effect == "actuator_scale":
        X = np.zeros((n, 6, 6))
        X[:, np.arange(6), np.arange(6)] = data.stroke
        return X
    if effect == "periodic_screw_error":
        if pitch_mm is None:
            raise ValueError("periodic_screw_error needs pitch_mm")
        ph = 2 * np.pi * data.stroke / pitch_mm
        X = np.zeros((n, 6, 12))
        X[:, np.arange(6), 2 * np.arange(6)] = np.sin(ph)
        X[:, np.arange(6), 2 * np.arange(6) + 1] = np.cos(ph)
        return X
    raise ValueError(f"unknown effect {effect!r}: expected one of {', '.join(EFFECTS)}")


def effect_parameter_names(effect: str) -> list[tuple[str, str]]:
    """``[(name, unit), ...]`` of an effect's coefficients."""
    return {
        "none": [],
        "leg_compliance": [("weight_over_stiffness", "mm"), ("weight_x_com_height_over_stiffness", "mm x 100 mm")],
        "joint_friction": [("dead_band", "mm")],
        "thermal_drift": [("growth_rate", "mm/s")],
        "actuator_scale": [(f"scale{i + 1}", "1") for i in range(6)],
        "periodic_screw_error": [(f"{ab}{i + 1}", "mm") for i in range(6) for ab in ("sin", "cos")],
    }[effect]


@dataclass(frozen=True, eq=False)
class EffectFit:
    """Geometry and one effect fitted jointly (whitened by the declared noise).

    Attributes:
        effect: the effect's name.
        hexapod: identified geometry.
        coefficients: (p,) effect coefficients (see :func:`effect_parameter_names`).
        coefficient_std: (p,) their standard uncertainties (declared noise, inflated by the
            reduced chi-square when it exceeds 1).
        pitch_mm: the screw pitch (``periodic_screw_error``), else None.
        residuals: (N, 6) mm, joint-space residuals after the fit.
        whitened: (N, 6) whitened residuals (unit variance under the declared noise).
        chi2: sum of squares of ``whitened``; dof = 6N - n_params.
        n_params: 42 + p (+1 for a searched pitch).
    """

    effect: str
    hexapod: Hexapod
    coefficients: np.ndarray
    coefficient_std: np.ndarray
    pitch_mm: float | None
    residuals: np.ndarray
    whitened: np.ndarray
    chi2: float
    n_params: int

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
        """``{name: {"value", "std", "unit"}}`` plus the pitch when searched."""
        out = {n: {"value": float(v), "std": float(s), "unit": u}
               for (n, u), v, s in zip(effect_parameter_names(self.effect), self.coefficients, self.coefficient_std)}
        if self.pitch_mm is not None:
            out["pitch"] = {"value": float(self.pitch_mm), "std": float("nan"), "unit": "mm"}
        return out

    def predict(self, data: EffectData) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (mm) and whitened residuals of this fitted model on other data."""
        X = effect_regressors(self.effect, self.hexapod, data, self.pitch_mm)
        r = _commanded(self.hexapod, data.measured) - data.commanded - X @ self.coefficients
        return r, _whiten(_noise_chol(self.hexapod, data), r)


def _noise_chol(hexapod: Hexapod, data: EffectData) -> np.ndarray:
    """(N, 6, 6) Cholesky factors of the joint-space noise covariance of each pose."""
    Jp = _pose_jacobian(hexapod, data.measured)
    var = 1.0 / data.noise.weights() ** 2
    S = np.einsum("nik,k,njk->nij", Jp, var, Jp)
    return np.linalg.cholesky(S)


def joint_noise_std(hexapod: Hexapod, data: EffectData) -> np.ndarray:
    """(N, 6) mm, standard deviation of each leg-length residual caused by the sensor noise."""
    Jp = _pose_jacobian(hexapod, data.measured)
    var = 1.0 / data.noise.weights() ** 2
    return np.sqrt(np.einsum("nik,k->ni", Jp ** 2, var))


def _whiten(Lc: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Solve L w = v pose by pose; v is (N, 6) or (N, 6, k)."""
    if v.ndim == 2:
        return np.linalg.solve(Lc, v[..., None])[..., 0]
    return np.linalg.solve(Lc, v)


def _design(hexapod: Hexapod, data: EffectData, effect: str, pitch: float | None):
    n = data.commanded.shape[0]
    r = _commanded(hexapod, data.measured) - data.commanded
    Jl = _parameter_jacobian(hexapod, data.measured)
    Jt = np.zeros((n, 6, 42))
    for leg in range(6):
        Jt[:, leg, leg * 7:(leg + 1) * 7] = Jl[:, leg]
    X = effect_regressors(effect, hexapod, data, pitch)
    return r, np.concatenate([Jt, -X], axis=-1)


def _solve(A: np.ndarray, b: np.ndarray):
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    x, *_ = np.linalg.lstsq(A / scale, b, rcond=None)
    return x / scale


def fit_effect(data: EffectData, effect: str, *, pitch_mm: float | None = None, iterations: int = 3,
               start: Hexapod | None = None) -> EffectFit:
    """Fit the 42 geometric errors and an effect's coefficients jointly (Gauss-Newton).

    Args:
        data: the measurements.
        effect: one of :data:`EFFECTS`.
        pitch_mm: screw pitch for ``periodic_screw_error``; None searches it
            (:data:`PITCH_RANGE_MM`).
        iterations: Gauss-Newton iterations (the problem is nearly linear near the nominal).
        start: starting geometry (default the nominal).
    """
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r}: expected one of {', '.join(EFFECTS)}")
    searched = False
    if effect == "periodic_screw_error" and pitch_mm is None:
        base = start if start is not None else fit_effect(data, "none").hexapod
        pitch_mm = _search_pitch(data, base)
        searched = True
        start = base
    hx = start if start is not None else data.nominal
    Lc = _noise_chol(hx, data)
    coef = None
    for _ in range(iterations):
        r, D = _design(hx, data, effect, pitch_mm)
        coef = np.zeros(D.shape[-1] - 42) if coef is None else coef
        resid = r + D[..., 42:] @ coef  # D holds -X for the effect columns
        x = _solve(_whiten(Lc, D).reshape(-1, D.shape[-1]), -_whiten(Lc, resid).ravel())
        hx = hx.with_errors(hx.vector + x[:42])
        coef = coef + x[42:]
    r, D = _design(hx, data, effect, pitch_mm)
    resid = r + D[..., 42:] @ coef
    w = _whiten(Lc, resid)
    chi2 = float(np.sum(w ** 2))
    A = _whiten(Lc, D).reshape(-1, D.shape[-1])
    n_params = D.shape[-1] + (1 if searched else 0)
    dof = resid.size - n_params
    cov = np.linalg.pinv(A.T @ A) * max(1.0, chi2 / max(dof, 1))
    std = np.sqrt(np.clip(np.diag(cov)[42:], 0, None))
    return EffectFit(effect, hx, coef, std, pitch_mm, resid, w, chi2, n_params)


def _search_pitch(data: EffectData, base: Hexapod) -> float:
    """Pitch minimising the chi-square of the linearised joint fit, on a grid in frequency
    fine enough for the stroke range, refined by golden-section search."""
    Lc = _noise_chol(base, data)
    r, D = _design(base, data, "none", None)
    Ag = _whiten(Lc, D).reshape(-1, 42)
    b = -_whiten(Lc, r).ravel()
    # Project the geometry out once; each pitch then costs one small least-squares problem.
    Q, _ = np.linalg.qr(Ag / np.linalg.norm(Ag, axis=0))
    b_perp = b - Q @ (Q.T @ b)

    def cost(p):
        X = effect_regressors("periodic_screw_error", base, data, p)
        Xw = _whiten(Lc, X).reshape(-1, 12)
        Xp = Xw - Q @ (Q.T @ Xw)
        x, *_ = np.linalg.lstsq(Xp, b_perp, rcond=None)
        e = b_perp - Xp @ x
        return float(e @ e)

    span = max(float(np.ptp(data.stroke)), 1.0)
    fmin, fmax = 1.0 / PITCH_RANGE_MM[1], 1.0 / PITCH_RANGE_MM[0]
    freqs = np.arange(fmin, fmax, 1.0 / (6.0 * span))
    costs = np.array([cost(1.0 / f) for f in freqs])
    k = int(np.argmin(costs))
    lo, hi = freqs[max(k - 1, 0)], freqs[min(k + 1, len(freqs) - 1)]
    g = (np.sqrt(5) - 1) / 2
    a, b_ = lo, hi
    c, d = b_ - g * (b_ - a), a + g * (b_ - a)
    fc, fd = cost(1 / c), cost(1 / d)
    for _ in range(40):
        if fc < fd:
            b_, d, fd = d, c, fc
            c = b_ - g * (b_ - a)
            fc = cost(1 / c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b_ - a)
            fd = cost(1 / d)
    return float(1.0 / ((a + b_) / 2))


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


def _cv_rms(data: EffectData, effect: str, folds: int, seed: int, pitch: float | None) -> float:
    n = data.commanded.shape[0]
    order = np.random.default_rng(seed).permutation(n)
    ss, cnt = 0.0, 0
    for k in range(folds):
        test = np.sort(order[k::folds])
        train = np.setdiff1d(np.arange(n), test)
        fit = fit_effect(data.subset(train), effect, pitch_mm=pitch)
        _, w = fit.predict(data.subset(test))
        ss += float(np.sum(w ** 2))
        cnt += w.size
    return float(np.sqrt(ss / cnt))


#: Evidence an effect needs over geometry alone: BIC lower by at least this ("very strong" on
#: the Kass-Raftery scale; a chance reduction of a one-parameter effect's chi-square by 16 has
#: probability 5e-5).
MIN_DELTA_BIC = 10.0


def discover_effect(data: EffectData, *, candidates=EFFECTS, alpha: float = 0.01, outlier_alpha: float = 1e-3,
                    folds: int = 5, seed: int = 0, max_outliers: int = 5,
                    min_delta_bic: float = MIN_DELTA_BIC) -> Discovery:
    """Locate the mismatch, name the left-out physics, and fit it.

    1. Gross rows: under the best model, a row whose whitened chi-square (6 dof) exceeds the
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
        candidates: effects to consider (``"none"`` is always included).
        alpha: significance of the geometry-only chi-square test.
        outlier_alpha: family-wise significance of the outlier test.
        folds, seed: cross-validation.
        max_outliers: at most this many rows are removed.
    """
    cands = ("none",) + tuple(c for c in candidates if c != "none")
    for c in cands:
        if c not in EFFECTS:
            raise ValueError(f"unknown effect {c!r}: expected one of {', '.join(EFFECTS)}")
    n = data.commanded.shape[0]
    if n < 12:
        raise ValueError(f"effect discovery needs at least 12 measurements, got {n}")
    kept = np.arange(n)
    flagged: list[int] = []
    while True:
        sub = data.subset(kept)
        fits = {c: fit_effect(sub, c) for c in cands}
        geo = fits["none"]
        effect = min(cands, key=lambda c: fits[c].bic())
        if fits[effect].bic() > geo.bic() - min_delta_bic:
            effect = "none"
        per_pose = np.sum(fits[effect].whitened ** 2, axis=1)
        thr = float(chi2_dist.isf(outlier_alpha / kept.size, 6))
        worst = int(np.argmax(per_pose))
        if per_pose[worst] > thr and len(flagged) < max_outliers and kept.size > 12:
            flagged.append(int(kept[worst]))
            kept = np.delete(kept, worst)
            continue
        break
    sub = data.subset(kept)
    evidence = {"geometry_chi2_test": {"chi2": geo.chi2, "dof": geo.dof, "p_value": geo.p_value, "alpha": alpha}}
    cv = {}
    for c in cands:
        f = fits[c]
        cv[c] = _cv_rms(sub, c, folds, seed, f.pitch_mm)
        evidence[c] = {"chi2": f.chi2, "dof": f.dof, "p_value": f.p_value, "n_params": f.n_params, "bic": f.bic(),
                       "delta_bic_vs_none": f.bic() - geo.bic(), "aic": f.aic(), "cv_whitened_rms": cv[c]}
    if effect != "none" and not cv[effect] < cv["none"]:
        effect = "none"
    chosen = fits[effect]
    return Discovery(effect=effect, fits=fits, evidence=evidence, chosen=chosen, flagged=tuple(sorted(flagged)),
                     kept=kept, located=locate_mismatch(sub, geo), adequate=chosen.p_value > alpha)


def locate_mismatch(data: EffectData, geometry_fit: EffectFit) -> dict:
    """Where the residuals of the geometry-only fit concentrate.

    Joint space: RMS of the standardised residuals per leg. Task space: RMS of
    ``measured - FK(identified, l_cmd)`` per pose coordinate over its declared standard
    deviation. Workspace: for each pose coordinate, the per-pose residual RMS in its lower and
    upper thirds. Time: in the first, middle and last thirds of the record. Direction of motion:
    the mean residual of legs that last extended minus that of legs that last retracted, in
    standard errors (hysteresis shows here).

    Returns:
        JSON-ready dict; ``summary`` holds the findings in words.
    """
    hx = geometry_fit.hexapod
    z = geometry_fit.residuals / joint_noise_std(hx, data)  # standardised joint residuals
    per_leg = np.sqrt(np.mean(z ** 2, axis=0))
    pred = forward_kinematics(hx, data.commanded, initial=data.measured, stroke_mm=None)
    task = (data.measured - pred) * data.noise.weights()
    per_dof = np.sqrt(np.mean(task ** 2, axis=0))
    per_pose = np.sqrt(np.mean(z ** 2, axis=1))
    names = ["x", "y", "z", "alpha", "beta", "gamma"]
    region = {}
    for k, nme in enumerate(names):
        q = np.quantile(data.measured[:, k], [1 / 3, 2 / 3])
        lo, hi = data.measured[:, k] <= q[0], data.measured[:, k] >= q[1]
        region[nme] = {"low_third_rms": float(np.sqrt(np.mean(per_pose[lo] ** 2))),
                       "high_third_rms": float(np.sqrt(np.mean(per_pose[hi] ** 2)))}
    order = np.argsort(data.t_s)
    thirds = np.array_split(order, 3)
    time_rms = [float(np.sqrt(np.mean(per_pose[s] ** 2))) for s in thirds]
    tc = np.corrcoef(data.t_s, z.mean(axis=1))[0, 1] if np.ptp(data.t_s) > 0 else 0.0
    up, down = z[data.direction > 0], z[data.direction < 0]
    if up.size > 1 and down.size > 1:
        hyst = float((up.mean() - down.mean()) / np.sqrt(up.var() / up.size + down.var() / down.size))
    else:
        hyst = 0.0
    leg_worst = int(np.argmax(per_leg))
    reg_name, reg = max(region.items(), key=lambda kv: abs(kv[1]["high_third_rms"] - kv[1]["low_third_rms"]))
    summary = [
        f"joint space: residual RMS per leg {', '.join(f'{v:.2f}' for v in per_leg)} (in noise standard deviations); "
        f"largest on leg {leg_worst + 1}",
        f"task space: RMS per coordinate x y z alpha beta gamma {', '.join(f'{v:.2f}' for v in per_dof)} "
        f"(noise standard deviations)",
        f"workspace: largest contrast along {reg_name}: low third {reg['low_third_rms']:.2f}, "
        f"high third {reg['high_third_rms']:.2f}",
        f"time: RMS in first/middle/last third {', '.join(f'{v:.2f}' for v in time_rms)}; correlation of the "
        f"mean residual with time {tc:+.2f}",
        f"direction of motion: legs that last extended minus legs that last retracted: {hyst:+.1f} standard errors",
    ]
    return {
        "joint_space_rms_per_leg": per_leg.tolist(),
        "task_space_rms_per_dof": dict(zip(names, per_dof.tolist())),
        "workspace_thirds": region,
        "time_thirds_rms": time_rms,
        "time_correlation": float(tc),
        "direction_contrast_se": hyst,
        "worst_poses": [int(i) for i in np.argsort(per_pose)[::-1][:5]],
        "summary": summary,
    }
