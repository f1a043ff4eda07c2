"""Observability of a robot's parameters from a set of measured poses, and uncertainty.

Written once over :class:`calib.robot.Robot`. The measurement model is that of
:func:`calib.engine.identify_forward`: at pose j the controller commands joints ``q_j``, the
machine ``theta`` reaches ``FK(theta, q_j)`` and a sensor reports it with Gaussian noise
(:class:`~calib.noise.SensorNoise`: ``noise.pose_std(robot.pose_units)`` per pose coordinate,
plus joint-reading noise ``noise.joint_std`` propagated through the manipulator Jacobian).
Linearised about ``theta``, over the free parameters (default ``robot.free_default``):

* identification Jacobian ``J`` (D N, F): the stacked
  :func:`~calib.robot.pose_jacobian_of_parameters` (d pose / d theta at fixed joints);
* noise-whitened Jacobian ``A = W J`` with ``W`` the whitening of each pose's measurement
  covariance (:func:`calib.robot.pose_whitening`, the weights of ``identify_forward``): its
  rows are dimensionless per unit of parameter, so mm and rad are never mixed raw;
* Fisher information ``F = A^T A`` and Cramer-Rao bound ``CRB = F^-1`` (parameter units
  squared): the smallest covariance of any unbiased estimator of the free parameters. The
  weighted forward fit is the maximum-likelihood estimator for Gaussian pose noise and reaches
  it when the linearisation holds.

Singular values, condition numbers, observability indices and parameter combinations are those
of the *scaled* Jacobian ``A S^-1``: a parameter in rad is expressed as the length it moves at
the machine's size, ``S = robot.length_scale_mm`` for angles and 1 for lengths
(:func:`parameter_scale`), so every column is per mm and the combinations are unit vectors in
mm. For a robot whose parameters are all lengths (the hexapod) ``S = I``.

Observability indices (Sun and Hollerbach, "Observability index selection for robot
calibration", ICRA 2008) on the singular values ``sigma_1 >= ... >= sigma_L`` (``L = F``) of
the scaled Jacobian with ``m = D N`` rows:

* ``O1 = (sigma_1 ... sigma_L)^(1/L) / sqrt(m)`` (D-optimality),
* ``O2 = sigma_L / sigma_1`` (inverse condition number),
* ``O3 = sigma_L`` (E-optimality; ``1 / sigma_L`` mm is the standard deviation of the worst
  determined parameter combination),
* ``O4 = sigma_L^2 / sigma_1`` (noise amplification index).

Exact null directions (combinations no pose set can determine, e.g. the Delta's joint offset
``alpha_i`` against the direction of its arm vector ``(Lax_i, Lay_i)`` when ``Lay_i`` is free)
are reported as *not identifiable*, chain by chain, named by parameter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .validation import as_array, frozen_array
from .noise import SensorNoise
from .prior import DATA_SOURCE_RATIO
from .robot import Robot, pose_jacobian_of_parameters, pose_whitening
from .tsqr import triangular_factor

__all__ = [
    "parameter_scale",
    "free_indices",
    "identification_jacobian",
    "fisher_information",
    "describe_combination",
    "ObservabilityAnalysis",
    "analyze_observability",
    "PoseUncertainty",
    "pose_uncertainty",
    "combinations_left_to_prior",
]

#: Coefficients below this (after normalising the largest to 1) are left out of a
#: not-identifiable combination.
NULL_COEFFICIENT_TOL = 1e-6


def _check_robot(robot) -> None:
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be a calib.robot.Robot, got {type(robot).__name__}")


def _check_noise(noise) -> None:
    if not isinstance(noise, SensorNoise):
        raise TypeError(f"noise must be a SensorNoise, got {type(noise).__name__}")


def parameter_scale(robot: Robot) -> np.ndarray:
    """(P,) mm per parameter unit: 1 for a length, ``robot.length_scale_mm`` for an angle (the
    length an angle moves at the machine's size)."""
    _check_robot(robot)
    return np.where(robot.table.angle_mask(), robot.length_scale_mm, 1.0)


def free_indices(robot: Robot, free=None) -> tuple[tuple[str, ...], np.ndarray]:
    """The free parameters in table order: ``(names, (F,) flat indices)``.

    Args:
        robot: the robot.
        free: names of the free parameters, any order; default ``robot.free_default``.

    Raises:
        ValueError: empty or repeated names. KeyError: an unknown name.
    """
    _check_robot(robot)
    names = robot.free_default if free is None else tuple(free)
    if not names or len(set(names)) != len(names):
        raise ValueError(f"free must be a non-empty list of distinct parameter names, got {names}")
    idx = np.sort(robot.table.indices(names))
    return tuple(robot.table.names[i] for i in idx), idx


def _configurations(robot: Robot, theta, poses, joints, name: str = "poses"):
    theta = as_array(theta, "theta", (robot.n_parameters,))
    poses = as_array(poses, name, (-1, robot.pose_dim))
    if joints is None:
        joints = robot.inverse_kinematics(theta, poses)
    else:
        joints = as_array(joints, "joints", (poses.shape[0], robot.n_chains))
    return theta, poses, joints


def _whitened_jacobian(robot: Robot, theta, poses, joints, noise, idx) -> np.ndarray:
    """(N, D, F) ``W d pose / d theta_free`` (a new array)."""
    J = pose_jacobian_of_parameters(robot, theta, joints, poses)  # a new array: scaled in place
    if not np.array_equal(idx, np.arange(J.shape[2])):  # every parameter free: no gathered copy
        J = J[:, :, idx]
    if not noise.joint_std > 0:  # the same diagonal whitening for every pose: a product, the einsum's numbers
        J *= (1.0 / noise.pose_std(robot.pose_units))[None, :, None]
        return J
    winv = pose_whitening(robot, theta, joints, poses, noise)
    return np.einsum("nij,njk->nik", winv, J)


def identification_jacobian(robot: Robot, theta, poses, noise: SensorNoise, *, joints=None,
                            free=None) -> np.ndarray:
    """Noise-whitened identification Jacobian of pose measurements.

    Args:
        robot: the robot.
        theta: (P,) parameter vector at which to linearise (the machine's, or the nominal one
            when designing an experiment before the errors are known).
        poses: (N, D) poses the machine ``theta`` reaches, in the robot's pose units.
        noise: declared sensor noise (pose and joint noise, see :func:`calib.robot.pose_whitening`).
        joints: (N, C) the joints commanded there; default ``robot.inverse_kinematics(theta, poses)``.
        free: names of the free parameters; default ``robot.free_default``.

    Returns:
        (D N, F) ``W d pose / d theta``, 1 per parameter unit; row ``D j + k`` is coordinate k
        of pose j, columns the free parameters in table order.
    """
    _check_robot(robot)
    _check_noise(noise)
    _, idx = free_indices(robot, free)
    theta, poses, joints = _configurations(robot, theta, poses, joints)
    return _whitened_jacobian(robot, theta, poses, joints, noise, idx).reshape(-1, idx.size)


def fisher_information(robot: Robot, theta, poses, noise: SensorNoise, *, joints=None, free=None) -> np.ndarray:
    """(F, F) Fisher information ``A^T A`` of the free parameters, 1 per parameter unit squared."""
    A = identification_jacobian(robot, theta, poses, noise, joints=joints, free=free)
    return A.T @ A


def describe_combination(vector, names, *, n_terms: int = 4, min_coefficient: float = 0.05,
                         number_format: str = ".2f") -> str:
    """A parameter combination in words, e.g. ``"0.71 B1.z - 0.70 dl1"``.

    Args:
        vector: (K,) coefficients (a unit singular vector, or a direction normalised to 1).
        names: (K,) parameter names of the coefficients.
        n_terms: at most this many terms, largest magnitude first.
        min_coefficient: drop terms smaller than this in magnitude (at least one is kept).
        number_format: format of the coefficients.

    Returns:
        The signed sum of the dominant terms (sign chosen so that the largest is positive),
        with ``+ ...`` when terms were left out.
    """
    names = tuple(names)
    v = as_array(vector, "vector", (len(names),))
    if int(n_terms) != n_terms or n_terms < 1:
        raise ValueError(f"n_terms must be a positive integer, got {n_terms!r}")
    v = v if v[np.argmax(np.abs(v))] >= 0 else -v  # the sign of a singular vector is arbitrary
    order = np.argsort(-np.abs(v), kind="stable")
    keep = [i for i in order[:n_terms] if abs(v[i]) >= min_coefficient] or [int(order[0])]
    parts = []
    for k, i in enumerate(keep):
        c = v[i]
        sign = ("-" if c < 0 else "") if k == 0 else (" - " if c < 0 else " + ")
        parts.append(f"{sign}{abs(c):{number_format}} {names[i]}")
    if len(keep) < np.count_nonzero(np.abs(v) >= 1e-12):
        parts.append(" + ...")
    return "".join(parts)


@dataclass(frozen=True, eq=False)
class ObservabilityAnalysis:
    """How well a pose set determines the free parameters (see the module docstring).

    Attributes:
        names: (F,) the free parameter names, table order (the columns below).
        units: (F,) their units (``"mm"``/``"rad"``).
        indices: (F,) int, their flat indices in the robot's parameter vector.
        n_parameters: P, the length of the robot's parameter vector.
        scale: (F,) mm per parameter unit (:func:`parameter_scale`).
        n_poses: number of measured poses N.
        noise: the declared noise used for whitening.
        jacobian: (D N, F) noise-whitened identification Jacobian ``A``, 1 per parameter unit.
        singular_values: (F,) 1/mm, of the scaled ``A S^-1``, descending (zeros appended when
            there are fewer rows than parameters).
        right_singular_vectors: (F, F) rows are the unit combinations ``v_k`` (scaled
            coordinates, mm) of ``singular_values[k]``: ``v_k . (S theta)`` has standard deviation
            ``1 / sigma_k`` mm at the Cramer-Rao bound.
        rank: numerical rank (singular values above ``rank_rtol * sigma_1``).
        condition_number: ``sigma_1 / sigma_F`` of the scaled Jacobian (inf if rank deficient).
        scaled_condition_number: condition number of ``A`` with unit-norm columns (the figure
            :func:`calib.engine.identify_forward` reports).
        o1, o2, o3, o4: Sun-Hollerbach indices (1/mm, -, 1/mm, 1/mm).
        fisher: (F, F) ``A^T A``, 1 per parameter unit squared.
        crb: (F, F) Cramer-Rao bound, parameter units squared (pseudo-inverse of ``fisher``).
        crb_std: (F,) square root of the diagonal of ``crb``, parameter units; inf for a
            parameter touched by an undetermined combination.
        not_identifiable: one dict per exact null direction, chain by chain where the direction
            lies in one chain's parameters: ``{"chain": 0-based chain or None,
            "combination": "1 Lay1 + 0.00385 alpha1", "coefficients": {name: coefficient}}``,
            coefficients in parameter units normalised so that the largest is +1 (a change
            along it leaves every pose unchanged to first order).
    """

    names: tuple
    units: tuple
    indices: np.ndarray
    n_parameters: int
    scale: np.ndarray
    n_poses: int
    noise: SensorNoise
    jacobian: np.ndarray
    singular_values: np.ndarray
    right_singular_vectors: np.ndarray
    rank: int
    condition_number: float
    scaled_condition_number: float
    o1: float
    o2: float
    o3: float
    o4: float
    fisher: np.ndarray
    crb: np.ndarray
    crb_std: np.ndarray
    not_identifiable: tuple

    @property
    def n_free(self) -> int:
        return len(self.names)

    @property
    def crb_std_mm(self) -> np.ndarray:
        """(F,) mm, ``crb_std`` scaled (an angle as the length it moves at the machine's size)."""
        return frozen_array(self.crb_std * self.scale)

    @property
    def crb_rms(self) -> float:
        """mm, RMS of :attr:`crb_std_mm`: the RMS parameter error an efficient estimator gets."""
        return float(np.sqrt(np.mean(self.crb_std_mm ** 2)))

    def parameter_covariance(self) -> np.ndarray:
        """(P, P) the CRB over the whole parameter vector, zero for fixed parameters (the layout
        of :attr:`calib.engine.IdentificationResult.covariance`)."""
        cov = np.zeros((self.n_parameters, self.n_parameters))
        cov[np.ix_(self.indices, self.indices)] = self.crb
        return cov

    def weakest_combinations(self, k: int = 3, *, n_terms: int = 4) -> list[dict]:
        """The ``k`` worst-determined parameter combinations, worst first.

        Returns:
            ``[{"sigma": 1/mm, "std_mm": 1/sigma (inf if undetermined), "determined": bool,
            "combination": "0.71 B1.z - 0.70 dl1", "coefficients": {name: coefficient}}, ...]``;
            coefficients of the unit vector in scaled coordinates (mm).
        """
        n = self.n_free
        if isinstance(k, bool) or int(k) != k or not 1 <= k <= n:
            raise ValueError(f"k must be an integer in 1..{n}, got {k!r}")
        out = []
        for j in range(n - 1, n - 1 - int(k), -1):
            v = self.right_singular_vectors[j]
            v = v if v[np.argmax(np.abs(v))] >= 0 else -v
            s = float(self.singular_values[j])
            determined = j < self.rank
            idx = np.argsort(-np.abs(v), kind="stable")[:n_terms]
            out.append({
                "sigma": s,
                "std_mm": float(1.0 / s) if determined else float("inf"),
                "determined": bool(determined),
                "combination": describe_combination(v, self.names, n_terms=n_terms),
                "coefficients": {self.names[i]: float(v[i]) for i in idx},
            })
        return out

    def summary(self, k: int = 5) -> dict:
        """JSON-ready figures (parameter units, mm, 1/mm); infinities written as None."""
        fin = lambda x: float(x) if np.isfinite(x) else None  # noqa: E731
        return {
            "n_poses": self.n_poses,
            "noise": self.noise.to_dict(),
            "parameters": list(self.names),
            "parameter_units": dict(zip(self.names, self.units)),
            "rank": self.rank,
            "n_free": self.n_free,
            "condition_number": fin(self.condition_number),
            "scaled_condition_number": fin(self.scaled_condition_number),
            "indices": {"O1": fin(self.o1), "O2": fin(self.o2), "O3": fin(self.o3), "O4": fin(self.o4)},
            "singular_values": self.singular_values.tolist(),
            "crb_std": {n: fin(s) for n, s in zip(self.names, self.crb_std)},
            "crb_std_mm": {n: fin(s) for n, s in zip(self.names, self.crb_std_mm)},
            "crb_rms_mm": fin(self.crb_rms),
            "weakest_combinations": [
                {**c, "std_mm": fin(c["std_mm"])} for c in self.weakest_combinations(min(k, self.n_free))
            ],
            "not_identifiable": [dict(c) for c in self.not_identifiable],
        }


def _null_combinations(robot: Robot, As: np.ndarray, idx: np.ndarray, names, scale, tol: float,
                       null_dim: int) -> tuple[np.ndarray, tuple]:
    """Exact null directions of the scaled Jacobian ``As`` (D N, F), chain by chain first.

    Returns:
        ``(basis, combinations)``: (null_dim, F) orthonormal basis of the null space in scaled
        coordinates (within one chain where possible), and their descriptions in parameter units.
    """
    if null_dim == 0:
        return np.zeros((0, len(names))), ()
    found, chains = [], []
    for c in range(robot.n_chains):
        cols = np.flatnonzero(robot.table.chains[idx] == c)
        if cols.size == 0:
            continue
        _, s, vt = np.linalg.svd(As[:, cols], full_matrices=As.shape[0] < cols.size)  # every V; no N x N U
        s = np.r_[s, np.zeros(cols.size - s.size)]
        for v in vt[s <= tol]:
            full = np.zeros(len(names))
            full[cols] = v
            found.append(full)
            chains.append(c)
    basis = np.array(found).reshape(-1, len(names))[:null_dim]
    chains = chains[:null_dim]
    if len(chains) < null_dim:  # directions across chains: the rest of the null space
        _, s, vt = np.linalg.svd(As, full_matrices=As.shape[0] < As.shape[1])
        null = vt[np.r_[s, np.zeros(len(names) - s.size)] <= tol]
        if basis.size:
            q, _ = np.linalg.qr(basis.T)
            null = null - (null @ q) @ q.T
        u, sv, _ = np.linalg.svd(null.T, full_matrices=False)
        extra = u[:, : null_dim - len(chains)].T
        basis = np.vstack([basis, extra])
        chains += [None] * extra.shape[0]
    out = []
    for v, c in zip(basis, chains):
        natural = v / scale  # back to parameter units
        natural = natural / natural[np.argmax(np.abs(natural))]
        keep = np.abs(natural) > NULL_COEFFICIENT_TOL
        out.append({
            "chain": c,
            "combination": describe_combination(np.where(keep, natural, 0.0), names, n_terms=int(keep.sum()),
                                                min_coefficient=NULL_COEFFICIENT_TOL, number_format=".3g"),
            "coefficients": {names[i]: float(natural[i]) for i in np.flatnonzero(keep)},
        })
    return basis, tuple(out)


#: Above this many poses :func:`analyze_observability` takes its singular values from the
#: triangle of a QR factorisation of the Jacobian (one pass over the N D rows, no N D x P factor
#: formed) instead of from the Jacobian itself (two SVDs of it); the figures agree to rounding.
QR_FIRST_ROWS = 2000


def analyze_observability(robot: Robot, theta, poses, noise: SensorNoise, *, joints=None, free=None,
                          rank_rtol: float = 1e-10) -> ObservabilityAnalysis:
    """Singular values, indices, Cramer-Rao bound and weak or unidentifiable combinations.

    To report the uncertainty of an identified parameter set, call it with the identified
    ``theta`` and the measured poses (the bound at the estimate); to judge a planned pose set,
    with the nominal ``theta`` and the target poses.

    Args:
        robot: the robot.
        theta: (P,) parameter vector at which to linearise.
        poses: (N, D) poses the machine ``theta`` reaches, robot's pose units.
        noise: declared Gaussian noise.
        joints: (N, C) commanded joints; default ``robot.inverse_kinematics(theta, poses)``.
        free: names of the free parameters; default ``robot.free_default``.
        rank_rtol: singular values below ``rank_rtol * sigma_1`` count as zero.

    Returns:
        The :class:`ObservabilityAnalysis`.
    """
    if not (np.isfinite(rank_rtol) and 0 < rank_rtol < 1):
        raise ValueError(f"rank_rtol must be in (0, 1), got {rank_rtol!r}")
    _check_robot(robot)
    _check_noise(noise)
    names, idx = free_indices(robot, free)
    theta, poses, joints = _configurations(robot, theta, poses, joints)
    A = _whitened_jacobian(robot, theta, poses, joints, noise, idx).reshape(-1, idx.size)
    n_free = idx.size
    scale = parameter_scale(robot)[idx]
    m = A.shape[0]
    # A full SVD where there are fewer rows than parameters: the missing singular vectors are the
    # combinations the poses do not see at all (with more rows the thin one has every V: the full
    # U of N rows would hold N^2 numbers).
    # Above QR_FIRST_ROWS rows, the SVDs of the triangle R of As = Q R (the same singular values
    # and right vectors; Q, N x P, never formed: calib.tsqr, block by block): A's column scalings are R's (An = As D, R D).
    # As = A / scale formed only where the SVD or the null directions need it (not a copy of the
    # rows where the triangle serves: its blocks are scaled as they are taken, the same numbers).
    R = triangular_factor(A, column_scale=scale) if poses.shape[0] > QR_FIRST_ROWS and m >= n_free else None
    As = A / scale if R is None else None
    _, s_thin, Vt = np.linalg.svd(As if R is None else R, full_matrices=m < n_free)
    s = np.zeros(n_free)
    s[: s_thin.size] = s_thin
    tol = rank_rtol * s[0] if s[0] > 0 else 0.0
    rank = int(np.count_nonzero(s > tol)) if s[0] > 0 else 0
    null_basis, not_identifiable = _null_combinations(robot, A / scale if As is None and rank < n_free else As, idx,
                                                      names, scale, tol, n_free - rank)
    Vt[rank:] = null_basis  # the same null space, in one chain's parameters where possible
    Vr = Vt[:rank]
    crb_scaled = (Vr.T / s[:rank] ** 2) @ Vr
    crb = crb_scaled / np.outer(scale, scale)
    var = np.diag(crb).copy()
    if rank < n_free:
        touched = np.max(np.abs(Vt[rank:]), axis=0) > 1e-8
        var[touched] = np.inf
    with np.errstate(divide="ignore"):
        cond = float(s[0] / s[-1]) if s[-1] > tol else float("inf")
        # A's column norms are R's times the scale (As = Q R): no pass over the N D rows for them
        norms = np.linalg.norm(A, axis=0) if R is None else np.linalg.norm(R, axis=0) * scale
        unit = np.where(norms > 0, norms, 1.0)
        ss = np.linalg.svd(A / unit if R is None else R * (scale / unit), compute_uv=False)
        scond = float(ss[0] / ss[-1]) if (ss.size == n_free and ss[-1] > rank_rtol * ss[0]) else float("inf")
        logs = np.log(np.where(s > 0, s, 1.0))
        o1 = float(np.exp(logs.mean()) / np.sqrt(m)) if rank == n_free else 0.0
    smin = float(s[-1]) if rank == n_free else 0.0
    indices = np.array(idx)
    indices.setflags(write=False)
    A.setflags(write=False)  # made here, held by nobody else: read-only without a copy
    # A^T A from the triangle where there is one (A = Q R D_scale): equal to rounding, no pass over the rows
    fisher = A.T @ A if R is None else (R * scale).T @ (R * scale)
    return ObservabilityAnalysis(
        names=names, units=tuple(robot.table.units[i] for i in idx), indices=indices,
        n_parameters=robot.n_parameters, scale=frozen_array(scale), n_poses=poses.shape[0], noise=noise,
        jacobian=A, singular_values=frozen_array(s), right_singular_vectors=frozen_array(Vt),
        rank=rank, condition_number=cond, scaled_condition_number=scond, o1=o1,
        o2=smin / float(s[0]) if s[0] > 0 else 0.0, o3=smin, o4=smin ** 2 / float(s[0]) if s[0] > 0 else 0.0,
        fisher=frozen_array(fisher), crb=frozen_array(crb), crb_std=frozen_array(np.sqrt(var)),
        not_identifiable=not_identifiable,
    )


@dataclass(frozen=True, eq=False)
class PoseUncertainty:
    """Predicted pose error of a compensated controller at target poses.

    Attributes:
        targets: (N, D) target poses, robot's pose units, base frame.
        covariance: (N, D, D) covariance of ``reached - target`` (products of the pose units).
        position_rms_mm: (N,) mm, ``sqrt(trace)`` of the block of the mm coordinates: the RMS
            length of the position error vector.
        orientation_rms_rad: (N,) rad, the same for the angle coordinates (0 for a robot whose
            platform only translates).
    """

    targets: np.ndarray
    covariance: np.ndarray
    position_rms_mm: np.ndarray
    orientation_rms_rad: np.ndarray


def pose_uncertainty(robot: Robot, theta, targets, parameter_covariance) -> PoseUncertainty:
    """Uncertainty of the pose reached anywhere in the workspace after compensation.

    The controller commands ``q = IK(theta_hat, target)``; the machine reaches
    ``FK(theta, q)``. To first order ``reached - target = -J (theta_hat - theta)`` with
    ``J = d pose / d theta`` at fixed joints (:func:`calib.robot.pose_jacobian_of_parameters`),
    so ``Cov(reached - target) = J Cov(theta_hat) J^T``.

    Args:
        robot: the robot.
        theta: (P,) parameter vector at which to linearise (the identified one).
        targets: (N, D) target poses, robot's pose units.
        parameter_covariance: (P, P) covariance of the identified parameters (e.g.
            :meth:`ObservabilityAnalysis.parameter_covariance` or
            ``IdentificationResult.covariance``), zero for fixed parameters.

    Returns:
        The :class:`PoseUncertainty`.
    """
    _check_robot(robot)
    theta, targets, joints = _configurations(robot, theta, targets, None, "targets")
    P = robot.n_parameters
    C = as_array(parameter_covariance, "parameter_covariance", (P, P))
    if not np.allclose(C, C.T, rtol=1e-8, atol=1e-300):
        raise ValueError("parameter_covariance must be symmetric")
    J = pose_jacobian_of_parameters(robot, theta, joints, targets)
    cov = np.einsum("nia,ab,njb->nij", J, C, J)
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    angle = robot.angle_pose_mask
    pos = np.sqrt(np.clip(np.trace(cov[:, ~angle][:, :, ~angle], axis1=1, axis2=2), 0.0, None))
    ori = np.sqrt(np.clip(np.trace(cov[:, angle][:, :, angle], axis1=1, axis2=2), 0.0, None))
    return PoseUncertainty(targets=frozen_array(targets), covariance=frozen_array(cov),
                           position_rms_mm=frozen_array(pos), orientation_rms_rad=frozen_array(ori))


def combinations_left_to_prior(robot: Robot, covariance, prior_std, indices, *, n_terms: int = 4) -> tuple[dict, ...]:
    """The parameter combinations a maximum a posteriori fit's poses left to its prior.

    In tolerance units (each parameter divided by its prior standard deviation, so that the
    prior is the identity) the posterior covariance ``Cw = S^-1 C S^-1`` has eigenvalues in
    ``(0, 1]``: the squared ratio of posterior to prior standard deviation along each
    eigenvector. The eigenvectors whose ratio is at least :data:`calib.prior.DATA_SOURCE_RATIO`
    (the data did not halve the tolerance along them) are left to the prior. Chain by chain
    where the covariance has no entries across chains (a chain-wise fit), over all parameters
    otherwise.

    Args:
        robot: the robot.
        covariance: (K, K) posterior covariance of the free parameters, parameter units squared.
        prior_std: (K,) their prior standard deviations, parameter units.
        indices: (K,) int, their flat indices in the robot's parameter vector (table order).
        n_terms: largest terms named in each combination.

    Returns:
        One dict per combination, least determined first: ``{"chain": 0-based chain or None,
        "std_ratio": posterior / prior standard deviation along it, "combination": "0.71 B1.z -
        0.70 P1.z" (unit vector in tolerance units, see :func:`describe_combination`),
        "coefficients": {name: coefficient}}``.
    """
    _check_robot(robot)
    indices = np.asarray(indices, dtype=int)
    k = indices.size
    C = as_array(covariance, "covariance", (k, k))
    s = as_array(prior_std, "prior_std", (k,))
    Cw = C / np.outer(s, s)
    names = [robot.table.names[i] for i in indices]
    chains = robot.table.chains[indices]
    across = chains[:, None] != chains[None, :]
    blocks = [np.flatnonzero(chains == c) for c in np.unique(chains)] if not np.any(Cw[across]) else [np.arange(k)]
    out = []
    for cols in blocks:
        lam, V = np.linalg.eigh(0.5 * (Cw[np.ix_(cols, cols)] + Cw[np.ix_(cols, cols)].T))
        for j in np.flatnonzero(lam >= DATA_SOURCE_RATIO ** 2)[::-1]:
            v = np.zeros(k)
            v[cols] = V[:, j]
            v = v if v[np.argmax(np.abs(v))] >= 0 else -v
            top = np.argsort(-np.abs(v), kind="stable")[:n_terms]
            out.append({"chain": int(chains[cols[0]]) if len(blocks) > 1 else None,
                        "std_ratio": float(np.sqrt(max(lam[j], 0.0))),
                        "combination": describe_combination(v, names, n_terms=n_terms),
                        "coefficients": {names[i]: float(v[i]) for i in top}})
    return tuple(sorted(out, key=lambda c: -c["std_ratio"]))
