"""Observability of the 42 hexapod errors from a set of measured poses, and uncertainty.

The measurement model is that of :func:`~calib.identification.identify_forward`: at pose j
the controller commands leg lengths ``l_j``, the machine reaches ``FK(theta, l_j)`` and a
6-D sensor reports it with Gaussian noise of standard deviation ``std`` (mm for positions,
rad for angles; :class:`~calib.noise.SensorNoise`). Linearised about ``theta``:

* identification Jacobian ``J`` (6N, 42): the stacked
  :func:`~calib.kinematics.forward_parameter_jacobian` (d pose / d errors at fixed commanded
  lengths), rows 0-2 of each pose in mm/mm, rows 3-5 in rad/mm;
* noise-weighted Jacobian ``A = W J`` with ``W = diag(1/std)`` repeated per pose: its rows are
  dimensionless per mm of parameter, so mm and rad are never mixed raw;
* Fisher information ``F = A^T A`` (1/mm^2) and Cramer-Rao bound ``CRB = F^-1`` (mm^2): the
  smallest covariance any unbiased estimator of the 42 errors can reach. The weighted
  Levenberg-Marquardt fit (``identify_forward``) is the maximum-likelihood estimator for
  Gaussian noise and reaches it when the linearisation holds.

Observability indices (Sun and Hollerbach, "Observability index selection for robot
calibration", ICRA 2008), computed on the singular values ``sigma_1 >= ... >= sigma_L``
(``L = 42``) of the noise-weighted Jacobian ``A`` with ``m = 6N`` rows (all 42 parameters
are lengths in mm, so no further column scaling is needed for the indices):

* ``O1 = (sigma_1 ... sigma_L)^(1/L) / sqrt(m)`` (D-optimality),
* ``O2 = sigma_L / sigma_1`` (inverse condition number),
* ``O3 = sigma_L`` (E-optimality; ``1 / sigma_L`` mm is the standard deviation of the worst
  determined parameter combination),
* ``O4 = sigma_L^2 / sigma_1`` (noise amplification index).

The condition number is reported twice: of ``A`` (noise-weighted) and of ``A`` with unit-norm
columns (the column-scaled figure :func:`~calib.identification.identify_forward` reports).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._validate import as_array, as_poses
from .hexapod import N_PARAMETERS, Hexapod, parameter_table
from .kinematics import forward_parameter_jacobian
from .noise import SensorNoise

__all__ = [
    "identification_jacobian",
    "fisher_information",
    "ObservabilityAnalysis",
    "analyze_observability",
    "describe_combination",
    "PoseUncertainty",
    "pose_uncertainty",
]

#: Parameter names in flat-vector order (``dXB1 .. dZP6``).
PARAMETER_NAMES = tuple(name for name, _, _ in parameter_table())


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def _check_hexapod(hexapod) -> None:
    if not isinstance(hexapod, Hexapod):
        raise TypeError(f"hexapod must be a Hexapod, got {type(hexapod).__name__}")


def _check_noise(noise) -> None:
    if not isinstance(noise, SensorNoise):
        raise TypeError(f"noise must be a SensorNoise, got {type(noise).__name__}")


def identification_jacobian(hexapod: Hexapod, poses: np.ndarray, noise: SensorNoise) -> np.ndarray:
    """Noise-weighted identification Jacobian of pose measurements.

    Args:
        hexapod: parameter set at which to linearise (the machine, or the nominal one when
            designing an experiment before the errors are known).
        poses: (N, 6) poses the machine reaches, mm and rad, base frame.
        noise: declared sensor noise; ``W = noise.weights()`` (zero components floored).

    Returns:
        (6N, 42) ``W d pose / d errors``, 1/mm; row ``6 j + k`` is coordinate k of pose j,
        columns in :func:`~calib.hexapod.parameter_table` order.
    """
    _check_hexapod(hexapod)
    _check_noise(noise)
    poses = as_poses(poses)
    J = forward_parameter_jacobian(hexapod, poses)
    return (J * noise.weights()[None, :, None]).reshape(-1, N_PARAMETERS)


def fisher_information(hexapod: Hexapod, poses: np.ndarray, noise: SensorNoise) -> np.ndarray:
    """Fisher information of the 42 errors, ``J^T W^2 J``.

    Args:
        hexapod: parameter set at which to linearise.
        poses: (N, 6) poses, mm and rad.
        noise: declared Gaussian sensor noise.

    Returns:
        (42, 42) 1/mm^2, symmetric positive semi-definite.
    """
    A = identification_jacobian(hexapod, poses, noise)
    return A.T @ A


def describe_combination(vector: np.ndarray, *, n_terms: int = 4, min_coefficient: float = 0.05) -> str:
    """A parameter combination in words, e.g. ``"0.71 dZB1 - 0.70 dl1"``.

    Args:
        vector: (42,) coefficients over the parameters (a unit right singular vector).
        n_terms: at most this many terms, largest magnitude first.
        min_coefficient: drop terms smaller than this in magnitude (at least one is kept).

    Returns:
        The signed sum of the dominant terms, with ``+ ...`` when terms were left out.
    """
    v = as_array(vector, "vector", (N_PARAMETERS,))
    if int(n_terms) != n_terms or n_terms < 1:
        raise ValueError(f"n_terms must be a positive integer, got {n_terms!r}")
    v = v if v[np.argmax(np.abs(v))] >= 0 else -v  # sign of a singular vector is arbitrary
    order = np.argsort(-np.abs(v), kind="stable")
    keep = [i for i in order[:n_terms] if abs(v[i]) >= min_coefficient] or [int(order[0])]
    parts = []
    for k, i in enumerate(keep):
        c = v[i]
        sign = ("-" if c < 0 else "") if k == 0 else (" - " if c < 0 else " + ")
        parts.append(f"{sign}{abs(c):.2f} {PARAMETER_NAMES[i]}")
    if len(keep) < np.count_nonzero(np.abs(v) >= 1e-12):
        parts.append(" + ...")
    return "".join(parts)


@dataclass(frozen=True, eq=False)
class ObservabilityAnalysis:
    """How well a pose set determines the 42 errors (see the module docstring).

    Attributes:
        n_poses: number of measured poses N.
        noise: the declared sensor noise used for weighting.
        jacobian: (6N, 42) 1/mm, noise-weighted identification Jacobian ``A = W J``.
        singular_values: (42,) 1/mm, of ``A``, descending.
        right_singular_vectors: (42, 42) rows are the unit parameter combinations ``v_k``
            belonging to ``singular_values[k]`` (``v_k . theta`` has standard deviation
            ``1 / sigma_k`` mm at the Cramer-Rao bound).
        rank: numerical rank of ``A`` (singular values above ``rank_rtol * sigma_1``).
        condition_number: ``sigma_1 / sigma_42`` of ``A`` (inf if rank deficient).
        scaled_condition_number: condition number of ``A`` with unit-norm columns.
        o1, o2, o3, o4: Sun-Hollerbach observability indices of ``A`` (1/mm, -, 1/mm, 1/mm).
        fisher: (42, 42) 1/mm^2, ``A^T A``.
        crb: (42, 42) mm^2, Cramer-Rao bound (pseudo-inverse of ``fisher``; parameters touched
            by an undetermined combination have infinite variance on the diagonal).
        crb_std: (42,) mm, square root of the diagonal of ``crb``.
    """

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

    @property
    def names(self) -> tuple[str, ...]:
        """The 42 parameter names in column order."""
        return PARAMETER_NAMES

    @property
    def crb_rms(self) -> float:
        """mm, ``sqrt(trace(CRB) / 42)``: the RMS parameter error an efficient estimator gets."""
        return float(np.sqrt(np.mean(self.crb_std ** 2)))

    def weakest_combinations(self, k: int = 3, *, n_terms: int = 4) -> list[dict]:
        """The ``k`` worst-determined parameter combinations, worst first.

        Returns:
            ``[{"sigma": 1/mm, "std_mm": 1/sigma (inf if undetermined), "determined": bool,
            "combination": "0.71 dZB1 - 0.70 dl1", "coefficients": {name: coef}}, ...]``.
        """
        if int(k) != k or not 1 <= k <= N_PARAMETERS:
            raise ValueError(f"k must be an integer in 1..{N_PARAMETERS}, got {k!r}")
        out = []
        for j in range(N_PARAMETERS - 1, N_PARAMETERS - 1 - int(k), -1):
            v = self.right_singular_vectors[j]
            v = v if v[np.argmax(np.abs(v))] >= 0 else -v
            s = float(self.singular_values[j])
            determined = j < self.rank
            idx = np.argsort(-np.abs(v), kind="stable")[:n_terms]
            out.append({
                "sigma": s,
                "std_mm": float(1.0 / s) if determined else float("inf"),
                "determined": bool(determined),
                "combination": describe_combination(v, n_terms=n_terms),
                "coefficients": {PARAMETER_NAMES[i]: float(v[i]) for i in idx},
            })
        return out

    def summary(self, k: int = 5) -> dict:
        """JSON-ready figures (mm, 1/mm); infinities written as None."""
        fin = lambda x: float(x) if np.isfinite(x) else None  # noqa: E731
        return {
            "n_poses": self.n_poses,
            "noise": self.noise.to_dict(),
            "rank": self.rank,
            "condition_number": fin(self.condition_number),
            "scaled_condition_number": fin(self.scaled_condition_number),
            "indices": {"O1": fin(self.o1), "O2": fin(self.o2), "O3": fin(self.o3), "O4": fin(self.o4)},
            "singular_values": self.singular_values.tolist(),
            "crb_std_mm": {n: fin(s) for n, s in zip(PARAMETER_NAMES, self.crb_std)},
            "crb_rms_mm": fin(self.crb_rms),
            "weakest_combinations": [
                {**c, "std_mm": fin(c["std_mm"])} for c in self.weakest_combinations(k)
            ],
        }


def analyze_observability(
    hexapod: Hexapod, poses: np.ndarray, noise: SensorNoise, *, rank_rtol: float = 1e-10
) -> ObservabilityAnalysis:
    """Singular values, indices and Cramer-Rao bound of the 42 errors for a pose set.

    To report the uncertainty of an identified parameter set, call it with the identified
    hexapod and the measured poses (the bound at the estimate); to judge a planned pose set,
    with the nominal hexapod and the target poses.

    Args:
        hexapod: parameter set at which to linearise.
        poses: (N, 6) poses, mm and rad.
        noise: declared Gaussian sensor noise (standard deviations ``noise.std``).
        rank_rtol: singular values below ``rank_rtol * sigma_1`` count as zero.

    Returns:
        The :class:`ObservabilityAnalysis`.
    """
    if not (np.isfinite(rank_rtol) and 0 < rank_rtol < 1):
        raise ValueError(f"rank_rtol must be in (0, 1), got {rank_rtol!r}")
    A = identification_jacobian(hexapod, poses, noise)
    m = A.shape[0]
    # A full SVD is needed: with fewer rows than 42 the missing singular vectors are the
    # combinations the poses do not see at all.
    _, s_thin, Vt = np.linalg.svd(A, full_matrices=True)
    s = np.zeros(N_PARAMETERS)
    s[: s_thin.size] = s_thin
    tol = rank_rtol * s[0] if s[0] > 0 else 0.0
    rank = int(np.count_nonzero(s > tol)) if s[0] > 0 else 0
    Vr = Vt[:rank]
    crb = (Vr.T / s[:rank] ** 2) @ Vr
    var = np.diag(crb).copy()
    if rank < N_PARAMETERS:
        touched = np.max(np.abs(Vt[rank:]), axis=0) > 1e-8
        var[touched] = np.inf
    with np.errstate(divide="ignore"):
        cond = float(s[0] / s[-1]) if s[-1] > tol else float("inf")
        norms = np.linalg.norm(A, axis=0)
        As = A / np.where(norms > 0, norms, 1.0)
        ss = np.linalg.svd(As, compute_uv=False)
        scond = float(ss[0] / ss[-1]) if (ss.size == N_PARAMETERS and ss[-1] > rank_rtol * ss[0]) \
            else float("inf")
        logs = np.log(np.where(s > 0, s, 1.0))
        o1 = float(np.exp(logs.mean()) / np.sqrt(m)) if rank == N_PARAMETERS else 0.0
    smin = float(s[-1]) if rank == N_PARAMETERS else 0.0
    return ObservabilityAnalysis(
        n_poses=m // 6, noise=noise, jacobian=_frozen(A), singular_values=_frozen(s),
        right_singular_vectors=_frozen(Vt), rank=rank, condition_number=cond,
        scaled_condition_number=scond, o1=o1, o2=smin / float(s[0]) if s[0] > 0 else 0.0, o3=smin,
        o4=smin ** 2 / float(s[0]) if s[0] > 0 else 0.0,
        fisher=_frozen(A.T @ A), crb=_frozen(crb), crb_std=_frozen(np.sqrt(var)),
    )


@dataclass(frozen=True, eq=False)
class PoseUncertainty:
    """Predicted pose error of a compensated controller at target poses.

    Attributes:
        targets: (N, 6) target poses, mm and rad, base frame.
        covariance: (N, 6, 6) covariance of ``reached - target``; blocks in mm^2, mm rad and
            rad^2.
        position_rms_mm: (N,) mm, ``sqrt(trace)`` of the position block: the RMS length of the
            position error vector.
        orientation_rms_rad: (N,) rad, the same for the angles.
    """

    targets: np.ndarray
    covariance: np.ndarray
    position_rms_mm: np.ndarray
    orientation_rms_rad: np.ndarray


def pose_uncertainty(hexapod: Hexapod, targets: np.ndarray, parameter_covariance: np.ndarray) -> PoseUncertainty:
    """Uncertainty of the pose reached anywhere in the workspace after compensation.

    The controller commands ``l = IK(theta_hat, target)``; the machine reaches
    ``FK(theta, l)``. To first order ``reached - target = J_fk (theta - theta_hat)`` with
    ``J_fk = d pose / d errors`` (:func:`~calib.kinematics.forward_parameter_jacobian`), so
    ``Cov(reached - target) = J_fk Cov(theta_hat) J_fk^T``.

    Args:
        hexapod: parameter set at which to linearise (the identified one).
        targets: (N, 6) target poses, mm and rad.
        parameter_covariance: (42, 42) mm^2, covariance of the identified errors (e.g.
            ``ObservabilityAnalysis.crb`` or ``IdentificationResult.covariance``).

    Returns:
        The :class:`PoseUncertainty`.
    """
    _check_hexapod(hexapod)
    targets = as_poses(targets, "targets")
    C = as_array(parameter_covariance, "parameter_covariance", (N_PARAMETERS, N_PARAMETERS))
    if not np.allclose(C, C.T, rtol=1e-8, atol=1e-300):
        raise ValueError("parameter_covariance must be symmetric")
    J = forward_parameter_jacobian(hexapod, targets)
    cov = np.einsum("nia,ab,njb->nij", J, C, J)
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    pos = np.sqrt(np.clip(np.trace(cov[:, :3, :3], axis1=1, axis2=2), 0.0, None))
    ori = np.sqrt(np.clip(np.trace(cov[:, 3:, 3:], axis1=1, axis2=2), 0.0, None))
    return PoseUncertainty(targets=_frozen(targets), covariance=_frozen(cov), position_rms_mm=_frozen(pos),
                           orientation_rms_rad=_frozen(ori))
