"""What a fitted model leaves: the remainder's tests against the declared noise and for
structure, in numbers and in words (a room of :mod:`calib.effects.discovery`; where the
geometry-only residuals concentrate is :mod:`calib.effects.located`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import chi2 as chi2_dist, norm

from ..robot import Robot
from .base import GRAM_BASIS_RTOL, EffectData, closure_regressors
from .compliance import payload_varies
from .joint_fit import EffectFit, model_poses, span_bases
from .registry import EFFECTS
from .separability import GRAM_MIN_RESIDUALS, flat_coordinates, unseparated_combinations, unseparated_information
from .whitening import closure_noise_std, noise_covariance, whiten

__all__ = ["VERDICT_ALPHA", "POSE_DRIFT_Z", "NOISE_ALPHA", "NoiseTest", "QuantityTest", "Remaining", "RemainderTests",
           "remainder_tests", "root_mean_square"]

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


@dataclass(frozen=True, eq=False)
class NoiseTest:
    """The remainder's chi-square tests against the declared noise (:func:`remainder_tests`).

    Attributes:
        chi2, dof, p_value: the overall test; alpha: its significance.
        chi2_per_chain: (C,) each chain's sum of squared standardised residuals; dof_per_chain:
            their degrees of freedom; p_value_per_chain: (C,) their p-values.
        chains_failing: the chains (1-based) whose test fails (Bonferroni, ``alpha / C``).
        consistent: the overall test and every chain's pass.
    """

    chi2: float
    dof: float
    p_value: float
    alpha: float
    chi2_per_chain: np.ndarray
    dof_per_chain: float
    p_value_per_chain: np.ndarray
    chains_failing: tuple
    consistent: bool

    def to_dict(self) -> dict:
        """JSON-ready (the summary's ``tests.noise``)."""
        return {"chi2": self.chi2, "dof": self.dof, "p_value": self.p_value, "alpha": self.alpha,
                "chi2_per_chain": self.chi2_per_chain.tolist(), "dof_per_chain": self.dof_per_chain,
                "p_value_per_chain": self.p_value_per_chain.tolist(), "chains_failing": list(self.chains_failing),
                "consistent": self.consistent}


@dataclass(frozen=True, eq=False)
class QuantityTest:
    """The remainder's structure tests against one quantity (:func:`remainder_tests`).

    Attributes:
        quantity: the quantity (``time``, ``stroke``, ``position x``, ...).
        p_value_proportional: F test of each chain's joint displaced in proportion to it.
        p_value_common_smooth: F test of a cubic in it shared by every chain (1 for a binary one).
        t_per_chain: (C,) the proportional coefficients' t.
        serial_correlation_per_chain: (C,) the standardised residuals' serial correlation ordered
            by it, in standard errors; serial_correlation_combined: over the chains.
        p_value: the smallest p-value, Bonferroni-corrected over every statistic.
        chains: the chains (0-based) whose own statistics fail.
        score: ``-log10`` of the smallest uncorrected p-value.
        pose_drift: time only: the F test of the measured pose drifting with time (its p-value)
            and the drift's t per pose coordinate (``pose_names`` order); None for the others.
    """

    quantity: str
    p_value_proportional: float
    p_value_common_smooth: float
    t_per_chain: np.ndarray
    serial_correlation_per_chain: np.ndarray
    serial_correlation_combined: float
    p_value: float
    chains: tuple
    score: float
    p_value_pose_drift: float | None = None
    t_pose_drift: np.ndarray | None = None
    pose_names: tuple = ()

    def to_dict(self) -> dict:
        """JSON-ready (the summary's ``tests.structure[quantity]``)."""
        out = {"p_value_proportional": self.p_value_proportional, "p_value_common_smooth": self.p_value_common_smooth}
        if self.p_value_pose_drift is not None:
            out.update(p_value_pose_drift=self.p_value_pose_drift,
                       t_pose_drift=dict(zip(self.pose_names, self.t_pose_drift.tolist())))
        return dict(out, t_per_chain=self.t_per_chain.tolist(),
                    serial_correlation_per_chain=self.serial_correlation_per_chain.tolist(),
                    serial_correlation_combined=self.serial_correlation_combined, p_value=self.p_value,
                    chains=list(self.chains), score=self.score)


@dataclass(frozen=True, eq=False)
class Remaining:
    """What a fitted model leaves (:func:`remainder_tests`), in numbers and in words.

    Attributes:
        present: a remainder beyond the declared noise or with structure (not explained).
        noise_ratio: whitened RMS over the declared noise.
        rms_mm, noise_floor_mm, excess_rms_mm: the closure residual RMS, the noise's, and the
            RMS beyond it (mm).
        rms_per_chain_noise: (C,) each chain's standardised RMS.
        chains: the chains (1-based) that fail a test.
        follows: the quantities the remainder follows, strongest first; does_not_follow: the
            physical ones it does not.
        pose_drift: the pose coordinates that drift with time, alike at every pose (empty unless
            time is followed best in pose space).
        summary: the above in words.
        bad_rows: in a discovery where more than the limit of the rows looked bad (the model is
            wrong), how many; None otherwise.
    """

    present: bool
    noise_ratio: float
    rms_mm: float
    noise_floor_mm: float
    excess_rms_mm: float
    rms_per_chain_noise: np.ndarray
    chains: tuple
    follows: tuple
    does_not_follow: tuple
    pose_drift: tuple
    summary: str = ""
    bad_rows: int | None = None

    def to_dict(self) -> dict:
        """JSON-ready (the summary's ``remaining``)."""
        out = {"present": self.present, "noise_ratio": self.noise_ratio, "rms_mm": self.rms_mm,
               "noise_floor_mm": self.noise_floor_mm, "excess_rms_mm": self.excess_rms_mm,
               "rms_per_chain_noise": self.rms_per_chain_noise.tolist(), "chains": list(self.chains),
               "follows": list(self.follows), "does_not_follow": list(self.does_not_follow),
               "pose_drift": list(self.pose_drift), "summary": self.summary}
        if self.bad_rows is not None:
            out["bad_rows"] = self.bad_rows
        return out


@dataclass(frozen=True, eq=False)
class RemainderTests:
    """The remainder's tests (:func:`remainder_tests`): ``explained`` (every test passes), the
    tests against the declared noise, the structure tests per quantity (in the order tested),
    what is left."""

    explained: bool
    noise: NoiseTest
    structure: tuple
    remaining: Remaining

    def quantity(self, name: str) -> QuantityTest:
        """The structure tests against the quantity ``name``.

        Raises:
            KeyError: a quantity not tested.
        """
        for q in self.structure:
            if q.quantity == name:
                return q
        raise KeyError(name)

    def structure_dict(self) -> dict:
        """JSON-ready ``{quantity: tests}`` (the summary's ``tests.structure``)."""
        return {q.quantity: q.to_dict() for q in self.structure}

    def to_dict(self) -> dict:
        """JSON-ready: ``noise`` and ``structure`` (the summary's ``tests``)."""
        return {"noise": self.noise.to_dict(), "structure": self.structure_dict()}


def root_mean_square(v: np.ndarray, axis=None):
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


def _noise_tests(fit: EffectFit, z: np.ndarray, noise_alpha: float) -> NoiseTest:
    """The chi-square tests of the remainder against the declared noise: overall (``fit.p_value``)
    and per chain (Bonferroni, ``noise_alpha / C``), as :func:`remainder_tests` reports them."""
    n, C = z.shape
    dof_chain = max(n - fit.n_params / C, 1.0)
    chain_chi2 = np.sum(z ** 2, axis=0)
    p_chain = chi2_dist.sf(chain_chi2, dof_chain)
    chains_noisy = [int(i) for i in np.flatnonzero(p_chain < noise_alpha / C)]
    noise_ok = fit.p_value > noise_alpha and not chains_noisy
    return NoiseTest(fit.chi2, fit.dof, fit.p_value, noise_alpha, chain_chi2, dof_chain, np.asarray(p_chain),
                     tuple(c + 1 for c in chains_noisy), bool(noise_ok))


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
            if gram:  # Q = [Q_det, Q_rest] (joint_fit.span_bases): X less Q_det's part is Xp + Q_rest Q_rest^T X
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
        return self.f_test(whiten(self.winv, closure_regressors(self.jac.joints, Xq)).reshape(-1, k))


def _pose_drift_test(data: EffectData, rem: _Remainder) -> tuple[float, np.ndarray]:
    """The measured pose drifting with time: every pose coordinate off in proportion to time, the
    same at every pose (the measurement frame moving; nothing the joints do), through the
    closure's pose Jacobian; one F test over the pose coordinates: ``(p, t per coordinate)``."""
    robot = data.robot
    tc = data.t_s - data.t_s.mean()
    p_pose, t_pose = 1.0, np.zeros(robot.pose_dim)
    if np.ptp(tc) > 0:
        p_pose, beta, cov, keep = rem.f_test(whiten(rem.winv, rem.jac.pose * tc[:, None, None])
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


def _structure(data: EffectData, rem: _Remainder, z: np.ndarray, alpha: float) -> tuple[tuple, np.ndarray, bool]:
    """Every quantity's tests (:class:`QuantityTest`, in the order tested), Bonferroni over every
    statistic at ``alpha``: ``(structure, the pose drift's t per coordinate, whether the pose drift
    is time's strongest)``; the quantities read from a pose at ``data``'s regressor poses."""
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
    structure = []
    for name, kind, values in feats:
        q = _quantity_tests(rem, kind, values, z, R)
        p_min = q["p_min"]
        drift = {}
        if name == "time":
            # Said in the words when the pose-space description beats every joint-space one.
            pose_best = p_pose < p_min
            p_min = min(p_min, p_pose)
            drift = {"p_value_pose_drift": p_pose, "t_pose_drift": t_pose, "pose_names": tuple(robot.pose_names)}
        structure.append(QuantityTest(name, q["p_f"], q["p_smooth"], q["t_chain"], q["lag"], q["comb"],
                                      min(1.0, p_min * m_tests),
                                      tuple(int(c) for c in np.flatnonzero(q["p_per"] * m_tests < alpha)),
                                      float(-np.log10(max(p_min, 1e-300))), **drift))
    return tuple(structure), t_pose, pose_best


def _remaining(robot: Robot, fit: EffectFit, std: np.ndarray, z: np.ndarray, noise: NoiseTest, structure: tuple,
               t_pose: np.ndarray, pose_best: bool, alpha: float) -> Remaining:
    """What the remainder's tests leave (:func:`remainder_tests`' ``remaining``), in numbers and
    in words."""
    follows = sorted((q for q in structure if q.p_value < alpha), key=lambda q: -q.score)
    explained = bool(noise.consistent and not follows)
    floor = float(root_mean_square(std))
    rms = float(root_mean_square(fit.residuals))
    chains_noisy = [c - 1 for c in noise.chains_failing]
    chains = sorted(set(chains_noisy) | {c for q in follows for c in q.chains})
    tested = {q.quantity for q in structure}
    followed = tuple(q.quantity for q in follows)
    remaining = Remaining(
        present=not explained, noise_ratio=float(np.sqrt(fit.chi2 / max(fit.dof, 1))), rms_mm=rms,
        noise_floor_mm=floor, excess_rms_mm=float(np.sqrt(max(rms ** 2 - floor ** 2, 0.0))),
        rms_per_chain_noise=root_mean_square(z, axis=0), chains=tuple(c + 1 for c in chains), follows=followed,
        does_not_follow=tuple(k for k in ("time", "direction of the last move", "size of the last move", "stroke",
                                          "load") if k in tested and k not in followed),
        # The measured pose drifting with time (alike at every pose; it follows time in pose space
        # better than in any chain's joint): the coordinates that drift.
        pose_drift=tuple(k for k, t in zip(robot.pose_names, t_pose) if abs(t) > POSE_DRIFT_Z)
        if "time" in followed and pose_best else ())
    return replace(remaining, summary=_remaining_words(remaining, robot.chain_word, explained))


def remainder_tests(data: EffectData, fit: EffectFit, *, alpha: float = VERDICT_ALPHA,
                    noise_alpha: float = NOISE_ALPHA) -> RemainderTests:
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
      statistic per chain sees as well. ``remaining.pose_drift`` names the coordinates that
      drift (drift rate more than :data:`POSE_DRIFT_Z` standard errors from zero) when time is
      followed and this test is time's strongest.

    Bonferroni over every statistic, at ``alpha``.

    Returns:
        :class:`RemainderTests`: ``explained`` (every test passes), ``noise`` (the chi-square
        tests), ``structure`` (per quantity: statistics, corrected p-value, chains), ``remaining``
        (what is left, in numbers and in words).
    """
    robot = data.robot
    std = closure_noise_std(robot, fit.theta, data)
    z = fit.residuals / std
    noise = _noise_tests(fit, z, noise_alpha)
    # The generic effects' columns in the fitted model's whitened space.
    joints = data.joints + fit.joint_displacement(data)
    poses = model_poses(robot, fit.theta, joints, data.measured, fit.basis)
    jac = robot.closure_jacobians(fit.theta, joints, poses)
    winv = np.linalg.inv(np.linalg.cholesky(noise_covariance(robot, jac, data)))
    Q, Q_det = span_bases(fit)
    rem = _Remainder(fit, jac, winv, Q, fit.whitened.ravel(), Q_det)
    # The quantities read from the poses (positions, the load) at the same poses: the flat
    # coordinates are still those the recorded poses did not vary.
    quantities = data if poses is data.measured else replace(data, model_poses=poses)
    structure, t_pose, pose_best = _structure(quantities, rem, z, alpha)
    remaining = _remaining(robot, fit, std, z, noise, structure, t_pose, pose_best, alpha)
    return RemainderTests(not remaining.present, noise, structure, remaining)


def _chain_list(word: str, chains: list) -> str:
    if not chains:
        return ""
    if len(chains) == 1:
        return f"{word} {chains[0]}"
    return f"{word}s {', '.join(map(str, chains[:-1]))} and {chains[-1]}"


def _remaining_words(rem: Remaining, chain: str, explained: bool) -> str:
    if explained:
        return (f"nothing beyond the declared noise: residual {rem.noise_ratio:.2f} x the noise, "
                f"no structure in time, motion, stroke, load or workspace")
    size = (f"a remainder of RMS {1e3 * rem.rms_mm:.2f} um against a noise floor of "
            f"{1e3 * rem.noise_floor_mm:.2f} um (whitened: {rem.noise_ratio:.1f} x the declared noise)")
    if rem.noise_ratio < 1.0:  # structure, not size: say that the rows' own noise is smaller
        size = (f"structure in a remainder of RMS {1e3 * rem.rms_mm:.2f} um, below the noise floor of "
                f"{1e3 * rem.noise_floor_mm:.2f} um the declared noise gives: the declared noise is larger than "
                f"the rows show (they show {rem.noise_ratio:.2f} x it), and the structure is judged at the rows' "
                f"own noise")
    where = _chain_list(chain, rem.chains) or f"every {chain} alike"
    if rem.follows:
        what = "following " + ", ".join(rem.follows[:3])
        if rem.pose_drift:
            what += (f" (the measured pose drifts with time, alike at every pose: "
                     f"{', '.join(rem.pose_drift)})")
        if rem.does_not_follow:
            what += "; not " + ", ".join(rem.does_not_follow)
    else:
        what = ("following none of the quantities tested (time, motion, stroke, load, workspace): noise larger than "
                "declared, or rows off at random")
    return f"{size}, on {where}, {what}"
