"""Optimal measurement poses: a feasible workspace and D-/E-optimal pose selection.

A :class:`Workspace` is the set of poses the machine may be sent to during calibration:

* pose bounds (box in x, y, z, alpha, beta, gamma; mm and rad, base frame);
* leg stroke: every commanded (nominal inverse-kinematics) leg length within
  ``home length +- stroke_mm``;
* joint cone limit: the angle between a leg and the base normal (z of the base frame) at its
  base joint, and between the leg and the platform normal (z of the platform frame) at its
  platform joint, at most ``cone_limit_rad`` (what a spherical or universal joint allows);
* distance to singularity: the condition number of the 6x6 pose Jacobian (d leg lengths /
  d pose), with its angle columns divided by the mean platform-joint radius (so that it does
  not depend on units, as in :func:`~calib.kinematics.forward_kinematics`), at most
  ``max_condition``.

Defaults (:func:`full_workspace`): x, y within +-80 mm, z in [150, 260] mm, angles within
+-25 degrees, stroke +-50 mm, cone limit 45 degrees, scaled condition number <= 10 (the paper's
geometry has 31 degrees and 2.4 at home). :func:`paper_workspace` is the paper's Table 4 box
(+-10 mm, z 200-210 mm, +-3 degrees) with the same joint limits (which do not bind there).

Pose selection works on the noise-weighted identification Jacobian of each candidate pose,
``A_c`` (6, 42), linearised at a given parameter set (the nominal one before calibration):

* D-optimal: maximise ``log det F`` with ``F = sum_c A_c^T A_c`` (minimises the volume of the
  Cramer-Rao ellipsoid). Greedy forward selection (a tiny ridge makes ``F`` invertible
  while fewer than 7 poses are chosen), then Fedorov exchange passes: each chosen pose is
  swapped for the candidate that most increases ``log det F``, using the determinant lemma
  ``det(F + A^T A) = det F det(I_6 + A F^-1 A^T)`` evaluated for all candidates at once.
* E-optimal: maximise ``lambda_min(F)`` (minimises the variance of the worst-determined
  combination). Exchange passes starting from the D-optimal design; candidates are screened
  by the first-order gain ``|A_c v_min|^2`` and the best ``screen`` of them evaluated exactly.

Candidate poses are drawn uniformly (seeded) in the bounds and kept when feasible.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ._validate import as_array, frozen_array, as_poses
from .hexapod import N_PARAMETERS, Hexapod
from .kinematics import DEFAULT_STROKE_MM, _commanded, _leg_vectors, _pose_jacobian
from .noise import SensorNoise
from .observability import identification_jacobian
from .workspace import PAPER_WORKSPACE

__all__ = [
    "Workspace",
    "full_workspace",
    "paper_workspace",
    "workspace_by_name",
    "FULL_WORKSPACE_BOUNDS",
    "CRITERIA",
    "joint_cone_angles",
    "scaled_condition",
    "feasibility",
    "sample_feasible_poses",
    "DesignResult",
    "select_poses",
    "design_poses",
]

#: Pose bounds of the default full workspace, (6, 2) low/high, mm and rad.
FULL_WORKSPACE_BOUNDS = np.array([
    [-80.0, 80.0], [-80.0, 80.0], [150.0, 260.0],
    [-np.deg2rad(25.0), np.deg2rad(25.0)], [-np.deg2rad(25.0), np.deg2rad(25.0)],
    [-np.deg2rad(25.0), np.deg2rad(25.0)],
])
_BOUNDS_TOL = 1e-6
#: Selection criteria: ``"d"`` (D-optimal) and ``"e"`` (E-optimal).
CRITERIA = ("d", "e")


@dataclass(frozen=True, eq=False)
class Workspace:
    """Feasible calibration poses (see the module docstring).

    Attributes:
        bounds: (6, 2) low/high per pose coordinate, mm and rad, base frame.
        stroke_mm: allowed leg-length deviation from the home length, mm.
        cone_limit_rad: largest angle between a leg and the joint's normal, rad.
        max_condition: largest scaled condition number of the 6x6 pose Jacobian.
        name: label written to command files and summaries.
    """

    bounds: np.ndarray = field(default_factory=lambda: FULL_WORKSPACE_BOUNDS.copy())
    stroke_mm: float = DEFAULT_STROKE_MM
    cone_limit_rad: float = float(np.deg2rad(45.0))
    max_condition: float = 10.0
    name: str = "custom"

    def __post_init__(self) -> None:
        b = as_array(self.bounds, "bounds", (6, 2))
        if np.any(b[:, 0] > b[:, 1]):
            i = int(np.argmax(b[:, 0] > b[:, 1]))
            raise ValueError(f"bounds must have low <= high, got row {i}: {b[i].tolist()}")
        object.__setattr__(self, "bounds", frozen_array(b))
        for name, lo, hi in (("stroke_mm", 0.0, np.inf), ("cone_limit_rad", 0.0, np.pi / 2),
                             ("max_condition", 1.0, np.inf)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and lo < v <= hi):
                raise ValueError(f"{name} must be a finite number in ({lo:g}, {hi:g}], got {v!r}")
            object.__setattr__(self, name, float(v))

    def to_dict(self) -> dict:
        """JSON-ready dict (mm and rad)."""
        return {"name": self.name, "bounds": self.bounds.tolist(), "stroke_mm": self.stroke_mm,
                "cone_limit_rad": self.cone_limit_rad, "max_condition": self.max_condition}

    @classmethod
    def from_dict(cls, d: dict) -> "Workspace":
        """Inverse of :meth:`to_dict`."""
        return cls(bounds=d["bounds"], stroke_mm=d["stroke_mm"], cone_limit_rad=d["cone_limit_rad"],
                   max_condition=d["max_condition"], name=d.get("name", "custom"))


def full_workspace() -> Workspace:
    """The machine's whole default workspace (see the module docstring)."""
    return Workspace(name="full")


def paper_workspace() -> Workspace:
    """The paper's small Table 4 workspace (+-10 mm, z 200-210 mm, +-3 degrees)."""
    return Workspace(bounds=PAPER_WORKSPACE, name="paper")


def workspace_by_name(name: str) -> Workspace:
    """``"full"`` or ``"paper"``."""
    if name == "full":
        return full_workspace()
    if name == "paper":
        return paper_workspace()
    raise ValueError(f"workspace must be 'full' or 'paper', got {name!r}")


def _check_hexapod(hexapod) -> None:
    if not isinstance(hexapod, Hexapod):
        raise TypeError(f"hexapod must be a Hexapod, got {type(hexapod).__name__}")


def _check_workspace(workspace) -> None:
    if not isinstance(workspace, Workspace):
        raise TypeError(f"workspace must be a Workspace, got {type(workspace).__name__}")


def _cone_angles(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    L, R = _leg_vectors(hexapod, poses)
    u = L / np.linalg.norm(L, axis=-1, keepdims=True)
    base = np.arccos(np.clip(u[..., 2], -1.0, 1.0))
    plat = np.arccos(np.clip(np.einsum("nli,ni->nl", u, R[:, :, 2]), -1.0, 1.0))
    return np.stack([base, plat], axis=-1)


def joint_cone_angles(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    """Angles between each leg and the joint normals.

    Args:
        hexapod: parameter set.
        poses: (N, 6) poses, mm and rad.

    Returns:
        (N, 6, 2) rad: ``[..., 0]`` at the base joint (leg vs base z axis), ``[..., 1]`` at the
        platform joint (leg vs platform z axis).
    """
    _check_hexapod(hexapod)
    return _cone_angles(hexapod, as_poses(poses))


def _scaled_condition(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    r = np.linalg.norm(hexapod.platform_joints, axis=1).mean()
    scale = np.r_[np.ones(3), np.full(3, 1.0 / r)]
    return np.linalg.cond(_pose_jacobian(hexapod, poses) * scale)


def scaled_condition(hexapod: Hexapod, poses: np.ndarray) -> np.ndarray:
    """Condition number of the 6x6 pose Jacobian, angle columns divided by the platform radius.

    Args:
        hexapod: parameter set.
        poses: (N, 6) poses, mm and rad.

    Returns:
        (N,) dimensionless; large near a singularity (inf at one).
    """
    _check_hexapod(hexapod)
    return _scaled_condition(hexapod, as_poses(poses))


def feasibility(hexapod: Hexapod, poses: np.ndarray, workspace: Workspace) -> dict:
    """Which workspace limits each pose meets.

    Args:
        hexapod: parameter set the controller uses (nominal before calibration).
        poses: (N, 6) target poses, mm and rad.
        workspace: the limits.

    Returns:
        ``{"bounds", "stroke", "cone", "singularity", "feasible"}``, each (N,) bool.
    """
    _check_hexapod(hexapod)
    _check_workspace(workspace)
    poses = as_poses(poses)
    b = workspace.bounds
    # A tolerance of 1e-6 (mm or rad) keeps poses printed to a few digits on the boundary
    # (the paper's 0.05236 rad for 3 degrees) inside.
    in_box = np.all((poses >= b[:, 0] - _BOUNDS_TOL) & (poses <= b[:, 1] + _BOUNDS_TOL), axis=1)
    dev = np.abs(_commanded(hexapod, poses) - hexapod.geometry.home_lengths)
    stroke = np.all(dev <= workspace.stroke_mm, axis=1)
    cone = np.all(_cone_angles(hexapod, poses) <= workspace.cone_limit_rad, axis=(1, 2))
    with np.errstate(all="ignore"):
        sing = _scaled_condition(hexapod, poses) <= workspace.max_condition
    return {"bounds": in_box, "stroke": stroke, "cone": cone, "singularity": sing,
            "feasible": in_box & stroke & cone & sing}


def _check_count(n, name: str, minimum: int) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {n!r}")
    return int(n)


def sample_feasible_poses(
    hexapod: Hexapod, workspace: Workspace, n: int, seed: int | np.random.Generator,
    *, max_draws: int = 2_000_000,
) -> np.ndarray:
    """Poses drawn uniformly in the workspace bounds, keeping the feasible ones.

    Args:
        hexapod: parameter set the controller uses.
        workspace: the limits.
        n: number of poses wanted.
        seed: seed or generator; the same seed gives the same poses.
        max_draws: give up after this many draws.

    Returns:
        (n, 6) feasible poses, mm and rad, in draw order.

    Raises:
        ValueError: fewer than ``n`` feasible poses in ``max_draws`` draws.
    """
    _check_hexapod(hexapod)
    _check_workspace(workspace)
    n = _check_count(n, "n", 0)
    rng = np.random.default_rng(seed)
    b = workspace.bounds
    out, drawn, got = [], 0, 0
    while got < n:
        if drawn >= max_draws:
            raise ValueError(
                f"only {got} of {n} feasible poses found in {drawn} draws: the workspace "
                f"{workspace.name!r} is (nearly) empty")
        m = int(min(max(4 * (n - got), 1024), max_draws - drawn))
        p = b[:, 0] + rng.uniform(size=(m, 6)) * (b[:, 1] - b[:, 0])
        drawn += m
        ok = feasibility(hexapod, p, workspace)["feasible"]
        out.append(p[ok])
        got += int(ok.sum())
    return np.concatenate(out)[:n]


@dataclass(frozen=True, eq=False)
class DesignResult:
    """A selected pose set.

    Attributes:
        poses: (n, 6) selected poses, mm and rad.
        indices: (n,) int, rows of the candidate array they came from.
        criterion: ``"d"`` or ``"e"``.
        log_det: ``log det F`` of the selected set (F in 1/mm^2; -inf if singular).
        lambda_min: smallest eigenvalue of F, 1/mm^2.
        exchanges: number of exchanges made after the initial design.
        n_candidates: number of candidate poses.
    """

    poses: np.ndarray
    indices: np.ndarray
    criterion: str
    log_det: float
    lambda_min: float
    exchanges: int
    n_candidates: int


def _logdet_gain(A: np.ndarray, Finv: np.ndarray) -> np.ndarray:
    """(C,) log det(I_6 + A_c F^-1 A_c^T) for all candidates (A: (C, 6, 42))."""
    AF = A @ Finv
    M = np.einsum("cik,cjk->cij", AF, A)
    M[:, np.arange(6), np.arange(6)] += 1.0
    sign, ld = np.linalg.slogdet(M)
    return np.where(sign > 0, ld, -np.inf)


def _d_optimal(A: np.ndarray, n: int, ridge: float, max_passes: int, tol: float):
    C = A.shape[0]
    F = ridge * np.eye(N_PARAMETERS)
    chosen: list[int] = []
    used = np.zeros(C, bool)
    for _ in range(n):
        g = _logdet_gain(A, np.linalg.inv(F))
        g[used] = -np.inf
        c = int(np.argmax(g))
        chosen.append(c)
        used[c] = True
        F = F + A[c].T @ A[c]
    exchanges = 0
    for _ in range(max_passes):
        swapped = False
        for k in range(n):
            i = chosen[k]
            Fm = F - A[i].T @ A[i]
            Fminv = np.linalg.inv(Fm)
            g = _logdet_gain(A, Fminv)
            g[used] = -np.inf
            c = int(np.argmax(g))
            gi = _logdet_gain(A[i:i + 1], Fminv)[0]
            if g[c] > gi + tol:
                chosen[k] = c
                used[i], used[c] = False, True
                F = Fm + A[c].T @ A[c]
                exchanges += 1
                swapped = True
        if not swapped:
            break
    return chosen, exchanges


def _e_optimal(A: np.ndarray, chosen: list[int], max_passes: int, screen: int, tol: float):
    C = A.shape[0]
    used = np.zeros(C, bool)
    used[chosen] = True
    G = np.einsum("cki,ckj->cij", A, A)  # (C, 42, 42) per-candidate information
    F = G[chosen].sum(axis=0)
    exchanges = 0
    for _ in range(max_passes):
        swapped = False
        for k in range(len(chosen)):
            i = chosen[k]
            Fm = F - G[i]
            lam_now = np.linalg.eigvalsh(F)[0]
            w, V = np.linalg.eigh(Fm)
            # First-order screen: gain of lambda_min along the few weakest directions.
            Vw = V[:, :3]
            # approximate new lambda_min = min_q (w_q + |A_c v_q|^2) over the weakest q
            proj = np.sum(np.einsum("ckp,pq->ckq", A, Vw) ** 2, axis=1)  # (C, 3)
            score = np.min(proj + w[:3], axis=1)
            score[used] = -np.inf
            top = np.argsort(-score)[:screen]
            top = top[np.isfinite(score[top])]
            if top.size == 0:
                continue
            lam = np.linalg.eigvalsh(Fm[None] + G[top])[:, 0]
            j = int(np.argmax(lam))
            if lam[j] > lam_now * (1.0 + tol):
                c = int(top[j])
                chosen[k] = c
                used[i], used[c] = False, True
                F = Fm + G[c]
                exchanges += 1
                swapped = True
        if not swapped:
            break
    return chosen, exchanges


def select_poses(
    hexapod: Hexapod,
    candidates: np.ndarray,
    n: int,
    noise: SensorNoise,
    *,
    criterion: str = "d",
    max_passes: int = 20,
    screen: int = 64,
) -> DesignResult:
    """Choose ``n`` of the candidate poses maximising a design criterion (module docstring).

    Args:
        hexapod: parameter set at which to linearise (the nominal one before calibration).
        candidates: (C, 6) feasible candidate poses, mm and rad, C >= n.
        n: number of poses to choose, >= 7 (the 42 errors need 42 equations).
        noise: declared sensor noise (weights mm against rad).
        criterion: ``"d"`` (D-optimal) or ``"e"`` (E-optimal).
        max_passes: exchange passes over the design at most.
        screen: E-optimal only, candidates evaluated exactly per exchange.

    Returns:
        The :class:`DesignResult`; deterministic for given inputs.
    """
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
    candidates = as_poses(candidates, "candidates")
    n = _check_count(n, "n", 7)
    if candidates.shape[0] < n:
        raise ValueError(f"candidates must have at least n = {n} rows, got {candidates.shape[0]}")
    max_passes = _check_count(max_passes, "max_passes", 0)
    screen = _check_count(screen, "screen", 1)
    A = identification_jacobian(hexapod, candidates, noise).reshape(-1, 6, N_PARAMETERS)
    ridge = 1e-9 * float(np.einsum("cki,cki->", A, A)) / (A.shape[0] * N_PARAMETERS)
    chosen, ex = _d_optimal(A, n, ridge, max_passes, 1e-10)
    if criterion == "e":
        chosen, ex2 = _e_optimal(A, list(chosen), max_passes, screen, 1e-10)
        ex += ex2
    idx = np.array(chosen, dtype=int)
    F = np.einsum("cki,ckj->ij", A[idx], A[idx])
    sign, ld = np.linalg.slogdet(F)
    idx.setflags(write=False)
    return DesignResult(
        poses=frozen_array(candidates[idx]), indices=idx, criterion=criterion,
        log_det=float(ld) if sign > 0 else float("-inf"),
        lambda_min=float(np.linalg.eigvalsh(F)[0]), exchanges=ex, n_candidates=candidates.shape[0],
    )


def design_poses(
    hexapod: Hexapod,
    n: int,
    workspace: Workspace,
    noise: SensorNoise,
    *,
    criterion: str = "d",
    seed: int = 0,
    n_candidates: int = 3000,
) -> DesignResult:
    """Sample feasible candidates in ``workspace`` (seeded) and select ``n`` optimal poses.

    Args:
        hexapod: parameter set (nominal before calibration).
        n: number of poses, >= 7.
        workspace: feasible set.
        noise: declared sensor noise.
        criterion: ``"d"`` or ``"e"``.
        seed: seed of the candidate draw.
        n_candidates: number of feasible candidates drawn (>= n).

    Returns:
        The :class:`DesignResult` (its poses all satisfy ``workspace``).
    """
    n = _check_count(n, "n", 7)
    n_candidates = _check_count(n_candidates, "n_candidates", n)
    cands = sample_feasible_poses(hexapod, workspace, n_candidates, seed)
    return select_poses(hexapod, cands, n, noise, criterion=criterion)
