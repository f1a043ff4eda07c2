"""Optimal measurement poses for any robot: a feasible workspace and D-/E-optimal pose selection.

Written once over :class:`calib.robot.Robot`. A :class:`Workspace` is the set of poses the
machine may be sent to during calibration:

* pose bounds: a box in the robot's pose coordinates (its units, base frame);
* reach: the inverse kinematics of the controller's parameter set succeeds;
* joint limits: every commanded joint within :meth:`Robot.joint_limits` (the hexapod's leg
  stroke, the Delta's motor range);
* passive joints: every angle of :meth:`Robot.passive_joint_angles` at most
  ``passive_joint_limit_rad`` (the hexapod's joint cones: the angle between a leg and the
  normal of its base or platform joint; robots without such limits report none);
* distance to singularity: the condition number of the closure's pose Jacobian ``dF / d pose``
  (C x D), its angle columns multiplied by the machine's size (:meth:`Robot.pose_scale`, as in
  :func:`calib.robot.newton_forward_kinematics`), at most ``max_condition``.

Two workspaces are named (:data:`WORKSPACES`), both given by the robot: ``"default"``, its
calibration workspace :meth:`Robot.workspace_bounds` (the hexapod paper's Table 4 box +-10 mm,
z 200-210 mm, +-3 degrees; the Delta paper's box), and ``"full"``, the box
:meth:`Robot.full_workspace_bounds` cut by the checks above (hexapod: x, y within +-80 mm,
z 150-260 mm, angles within +-25 degrees; stroke +-50 mm, cones 45 degrees, scaled condition
<= 10, 2.4 at home; for a robot without a wider box, the default one). Where the description
declares its joints' ranges (a machine as built), the "full" box is widened along each pose
coordinate as far as those ranges keep the poses feasible (:func:`widened_to_joint_ranges`): a
hexapod whose legs extend 150 mm above home reaches z = 362 mm (the default box: 260 mm).

Pose selection works on the noise-whitened identification Jacobian of each candidate pose,
``A_c`` (D, F), columns scaled to mm (:func:`calib.observability.parameter_scale`), linearised at
a given parameter set (the nominal one before calibration):

* D-optimal: maximise ``log det F`` with ``F = sum_c A_c^T A_c`` (minimises the volume of the
  Cramer-Rao ellipsoid). Greedy forward selection (a tiny ridge makes ``F`` invertible while
  too few poses are chosen), then Fedorov exchange passes: each chosen pose is swapped for the
  candidate that most increases ``log det F``, using the determinant lemma
  ``det(F + A^T A) = det F det(I_D + A F^-1 A^T)`` evaluated for all candidates at once.
* E-optimal: maximise ``lambda_min(F)`` (minimises the variance of the worst-determined
  combination). Exchange passes starting from the D-optimal design; candidates are screened by
  the first-order gain ``|A_c v_min|^2`` and the best ``screen`` of them evaluated exactly.

Candidate poses are drawn uniformly (seeded) in the bounds and kept when feasible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .validation import as_array, frozen_array
from .noise import SensorNoise
from .observability import free_indices, identification_jacobian, parameter_scale
from .robot import KinematicsError, Robot

__all__ = [
    "Workspace",
    "WORKSPACES",
    "CRITERIA",
    "DEFAULT_MAX_CONDITION",
    "DEFAULT_PASSIVE_JOINT_LIMIT_RAD",
    "robot_workspace",
    "widened_to_joint_ranges",
    "WIDENING_FACTOR",
    "WIDENING_STEPS",
    "scaled_condition",
    "reachable_joints",
    "feasibility",
    "sample_feasible_poses",
    "minimum_poses",
    "DesignResult",
    "select_poses",
    "design_poses",
    "augment_poses",
    "TooFewFeasiblePoses",
]

#: The named workspaces of every robot (see the module docstring).
WORKSPACES = ("full", "default")
#: Selection criteria: ``"d"`` (D-optimal) and ``"e"`` (E-optimal).
CRITERIA = ("d", "e")
#: Largest scaled condition number of the closure's pose Jacobian in a design workspace.
DEFAULT_MAX_CONDITION = 10.0
#: Largest passive-joint angle (what a spherical or universal joint allows), rad.
DEFAULT_PASSIVE_JOINT_LIMIT_RAD = float(np.deg2rad(45.0))
# Box bounds are checked with this tolerance (mm or rad), so that poses printed to a few digits
# on the boundary (the hexapod paper's 0.05236 rad for 3 degrees) stay inside.
BOUNDS_TOLERANCE = 1e-6
# Rows per inverse-kinematics call while locating unreachable candidates.
IK_CHUNK = 256
#: Where a description declares its joints' ranges, the "full" box is widened along each pose
#: coordinate through the home pose as far as the poses stay feasible, up to this many times the
#: box's own half-width from home, in steps of :data:`WIDENING_STEPS` per side.
WIDENING_FACTOR = 4.0
WIDENING_STEPS = 64


@dataclass(frozen=True, eq=False)
class Workspace:
    """Feasible calibration poses (see the module docstring).

    Attributes:
        bounds: (D, 2) low/high per pose coordinate, the robot's pose units, base frame.
        max_condition: largest scaled condition number of the closure's pose Jacobian.
        passive_joint_limit_rad: largest passive-joint angle (:meth:`Robot.passive_joint_angles`).
        name: label written to command files and summaries.
    """

    bounds: np.ndarray
    max_condition: float = DEFAULT_MAX_CONDITION
    passive_joint_limit_rad: float = DEFAULT_PASSIVE_JOINT_LIMIT_RAD
    name: str = "custom"

    def __post_init__(self) -> None:
        b = as_array(self.bounds, "bounds", (-1, 2))
        if np.any(b[:, 0] > b[:, 1]):
            i = int(np.argmax(b[:, 0] > b[:, 1]))
            raise ValueError(f"bounds must have low <= high, got row {i}: {b[i].tolist()}")
        object.__setattr__(self, "bounds", frozen_array(b))
        for name, lo, hi in (("max_condition", 1.0, np.inf), ("passive_joint_limit_rad", 0.0, np.pi)):
            v = getattr(self, name)
            number = isinstance(v, (int, float, np.floating)) and not isinstance(v, bool)
            if not (number and np.isfinite(v) and lo < v <= hi):
                raise ValueError(f"{name} must be a finite number in ({lo:g}, {hi:g}], got {v!r}")
            object.__setattr__(self, name, float(v))

    def to_dict(self) -> dict:
        """JSON-ready dict (the robot's pose units)."""
        return {"name": self.name, "bounds": self.bounds.tolist(), "max_condition": self.max_condition,
                "passive_joint_limit_rad": self.passive_joint_limit_rad}

    @classmethod
    def from_dict(cls, d: dict) -> "Workspace":
        """Inverse of :meth:`to_dict`."""
        return cls(bounds=d["bounds"], max_condition=d["max_condition"],
                   passive_joint_limit_rad=d["passive_joint_limit_rad"], name=d.get("name", "custom"))


def _check_robot(robot) -> None:
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be a calib.robot.Robot, got {type(robot).__name__}")


def _check_workspace(robot: Robot, workspace) -> None:
    if not isinstance(workspace, Workspace):
        raise TypeError(f"workspace must be a Workspace, got {type(workspace).__name__}")
    if workspace.bounds.shape[0] != robot.pose_dim:
        raise ValueError(f"workspace bounds must have {robot.pose_dim} rows ({', '.join(robot.pose_names)}) "
                         f"for the {robot.name}, got {workspace.bounds.shape[0]}")


def robot_workspace(robot: Robot, name: str) -> Workspace:
    """The robot's ``"full"`` or ``"default"`` workspace (see the module docstring)."""
    _check_robot(robot)
    if name == "full":
        bounds = robot.full_workspace_bounds()
        if robot.joint_ranges is not None:
            bounds = widened_to_joint_ranges(robot, bounds)
        return Workspace(bounds=bounds, name="full")
    if name == "default":
        return Workspace(bounds=robot.workspace_bounds(), name="default")
    raise ValueError(f"workspace must be one of {', '.join(WORKSPACES)}, got {name!r}")


def widened_to_joint_ranges(robot: Robot, bounds: np.ndarray) -> np.ndarray:
    """(D, 2) ``bounds`` widened to what the robot's joints as built allow: along each pose
    coordinate, through the home pose, both ways, out to the last pose of an unbroken run of
    feasible ones from home (reach, :meth:`Robot.joint_limits`, the default passive-joint and
    singularity limits, the nominal parameters), at most :data:`WIDENING_FACTOR` times the box's
    half-width from home. A machine whose legs reach past the robot's default box (one-sided
    strokes, long legs) gets a box its design can use; one whose ranges stop short keeps the box
    (the design's checks cut it, as before). Deterministic: a grid of :data:`WIDENING_STEPS`
    poses a side."""
    bounds = np.array(bounds, dtype=float)
    home = robot.home_pose
    half = 0.5 * np.ptp(bounds, axis=1)
    reach_box = home[:, None] + WIDENING_FACTOR * np.stack([-half, half], axis=1)  # holds every pose tried
    checks = Workspace(bounds=reach_box)
    t = np.linspace(0.0, WIDENING_FACTOR, WIDENING_STEPS + 1)[1:]
    for k in range(robot.pose_dim):
        for side, end in ((-1.0, 0), (1.0, 1)):
            poses = np.tile(home, (t.size, 1))
            poses[:, k] = home[k] + side * t * half[k]
            ok = _checks(robot, robot.table.nominal, poses, checks, every=False)["feasible"]
            run = t.size if ok.all() else int(np.argmin(ok))  # feasible poses before the first that is not
            if run:
                reach = home[k] + side * t[run - 1] * half[k]
                bounds[k, end] = min(bounds[k, end], reach) if side < 0 else max(bounds[k, end], reach)
    return bounds


def _poses(robot: Robot, poses, name: str = "poses") -> np.ndarray:
    return as_array(poses, name, (-1, robot.pose_dim))


def _theta(robot: Robot, theta) -> np.ndarray:
    return as_array(theta, "theta", (robot.n_parameters,))


def scaled_condition(robot: Robot, theta, poses, joints=None) -> np.ndarray:
    """Condition number of the closure's pose Jacobian, angle columns times the machine's size.

    Args:
        robot: the robot.
        theta: (P,) parameter vector.
        poses: (N, D) poses, robot's pose units.
        joints: (N, C) joints at the poses; default the inverse kinematics.

    Returns:
        (N,) dimensionless; large near a singularity (inf at one).
    """
    _check_robot(robot)
    theta, poses = _theta(robot, theta), _poses(robot, poses)
    if joints is None:
        joints = robot.inverse_kinematics(theta, poses)
    J = robot.closure_pose_jacobian(theta, joints, poses)
    with np.errstate(all="ignore"):
        return np.linalg.cond(J / robot.pose_scale())


def reachable_joints(robot: Robot, theta, poses) -> tuple[np.ndarray, np.ndarray]:
    """Inverse kinematics of many poses, skipping the ones out of reach.

    Returns:
        ``(ok, joints)``: (N,) bool, the poses the machine ``theta`` can reach (finite joints);
        (N, C) their joints, NaN where unreachable.
    """
    _check_robot(robot)
    theta, poses = _theta(robot, theta), _poses(robot, poses)
    n = poses.shape[0]
    joints = np.full((n, robot.n_chains), np.nan)
    for start in range(0, n, IK_CHUNK):
        pending = np.arange(start, min(start + IK_CHUNK, n))
        while pending.size:
            try:
                joints[pending] = robot.inverse_kinematics(theta, poses[pending])
                break
            except KinematicsError as exc:
                k = exc.index
            if not 0 <= k < pending.size:  # no usable row number: one row at a time
                for r in pending:
                    try:
                        joints[r] = robot.inverse_kinematics(theta, poses[r:r + 1])[0]
                    except KinematicsError:
                        pass
                break
            pending = np.delete(pending, k)  # the first unreachable row; retry the others
    ok = np.all(np.isfinite(joints), axis=1)
    return ok, joints


def _checks(robot: Robot, theta, poses, workspace: Workspace, every: bool) -> dict:
    """The checks of :func:`feasibility`; with ``every`` False a pose failing one check is not
    evaluated by the later, dearer ones (only ``"feasible"`` is then meaningful)."""
    b = workspace.bounds
    in_box = np.all((poses >= b[:, 0] - BOUNDS_TOLERANCE) & (poses <= b[:, 1] + BOUNDS_TOLERANCE), axis=1)
    n = poses.shape[0]
    reach, joints = np.zeros(n, bool), np.full((n, robot.n_chains), np.nan)
    todo = np.ones(n, bool) if every else in_box
    reach[todo], joints[todo] = reachable_joints(robot, theta, poses[todo])
    limits, passive, sing = np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, bool)
    lim = robot.joint_limits()
    todo = reach
    limits[todo] = np.all((joints[todo] >= lim[:, 0]) & (joints[todo] <= lim[:, 1]), axis=1)
    todo = reach if every else limits
    if np.any(todo):
        angles = robot.passive_joint_angles(theta, poses[todo])
        passive[todo] = np.all(angles <= workspace.passive_joint_limit_rad, axis=1)
    todo = reach if every else passive
    if np.any(todo):
        sing[todo] = scaled_condition(robot, theta, poses[todo], joints[todo]) <= workspace.max_condition
    return {"bounds": in_box, "reach": reach, "joint_limits": limits, "passive_joints": passive,
            "singularity": sing, "feasible": in_box & reach & limits & passive & sing}


def feasibility(robot: Robot, theta, poses, workspace: Workspace) -> dict:
    """Which workspace limits each pose meets.

    Args:
        robot: the robot.
        theta: (P,) parameter set the controller uses (nominal before calibration).
        poses: (N, D) target poses, robot's pose units.
        workspace: the limits.

    Returns:
        ``{"bounds", "reach", "joint_limits", "passive_joints", "singularity", "feasible"}``,
        each (N,) bool; a pose out of reach fails the later checks too.
    """
    _check_robot(robot)
    _check_workspace(robot, workspace)
    return _checks(robot, _theta(robot, theta), _poses(robot, poses), workspace, every=True)


def _check_count(n, name: str, minimum: int) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {n!r}")
    return int(n)


class TooFewFeasiblePoses(ValueError):
    """The workspace gives fewer feasible poses than asked for within the draw limit."""


def sample_feasible_poses(robot: Robot, theta, workspace: Workspace, n: int, seed: int | np.random.Generator,
                          *, max_draws: int = 2_000_000) -> np.ndarray:
    """Poses drawn uniformly in the workspace bounds, keeping the feasible ones.

    Args:
        robot: the robot.
        theta: (P,) parameter set the controller uses.
        workspace: the limits.
        n: number of poses wanted.
        seed: seed or generator; the same seed gives the same poses.
        max_draws: give up after this many draws.

    Returns:
        (n, D) feasible poses, robot's pose units, in draw order.

    Raises:
        ValueError: fewer than ``n`` feasible poses in ``max_draws`` draws.
    """
    _check_robot(robot)
    _check_workspace(robot, workspace)
    theta = _theta(robot, theta)
    n = _check_count(n, "n", 0)
    rng = np.random.default_rng(seed)
    b = workspace.bounds
    d = robot.pose_dim
    out, drawn, got = [np.zeros((0, d))], 0, 0
    while got < n:
        if drawn >= max_draws:
            why = (f"the workspace {workspace.name!r} is (nearly) empty" if got < 0.01 * n else
                   f"{got / drawn:.3g} of the draws are feasible in the workspace {workspace.name!r}: ask for at "
                   f"most about {got} poses")
            raise TooFewFeasiblePoses(f"only {got} of {n} feasible poses found in {drawn} draws: {why}")
        m = int(min(max(4 * (n - got), 1024), max_draws - drawn))
        p = b[:, 0] + rng.uniform(size=(m, d)) * (b[:, 1] - b[:, 0])
        drawn += m
        ok = _checks(robot, theta, p, workspace, every=False)["feasible"]
        out.append(p[ok])
        got += int(ok.sum())
    return np.concatenate(out)[:n]


def minimum_poses(robot: Robot, free=None) -> int:
    """Fewest poses whose equations can determine the free parameters: ``ceil(F / D)``."""
    names, _ = free_indices(robot, free)
    return -(-len(names) // robot.pose_dim)


@dataclass(frozen=True, eq=False)
class DesignResult:
    """A selected pose set.

    Attributes:
        poses: (n, D) selected poses, robot's pose units.
        indices: (n,) int, rows of the candidate array they came from.
        criterion: ``"d"`` or ``"e"``.
        log_det: ``log det F`` of the selected set (F of the scaled Jacobian, 1/mm^2; -inf if
            singular).
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
    """(K,) log det(I_D + A_c F^-1 A_c^T) for all candidates (A: (K, D, F))."""
    d = A.shape[1]
    AF = A @ Finv
    M = np.einsum("cik,cjk->cij", AF, A)
    M[:, np.arange(d), np.arange(d)] += 1.0
    sign, ld = np.linalg.slogdet(M)
    return np.where(sign > 0, ld, -np.inf)


def _d_optimal(A: np.ndarray, n: int, ridge: float, max_passes: int, tol: float):
    K, _, P = A.shape
    F = ridge * np.eye(P)
    chosen: list[int] = []
    used = np.zeros(K, bool)
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
    K = A.shape[0]
    used = np.zeros(K, bool)
    used[chosen] = True
    G = np.einsum("cki,ckj->cij", A, A)  # (K, F, F) per-candidate information
    F = G[chosen].sum(axis=0)
    exchanges = 0
    for _ in range(max_passes):
        swapped = False
        for k in range(len(chosen)):
            i = chosen[k]
            Fm = F - G[i]
            lam_now = np.linalg.eigvalsh(F)[0]
            w, V = np.linalg.eigh(Fm)
            # First-order screen: approximate new lambda_min = min_q (w_q + |A_c v_q|^2) over the
            # three weakest directions q.
            Vw = V[:, :3]
            proj = np.sum(np.einsum("ckp,pq->ckq", A, Vw) ** 2, axis=1)  # (K, 3)
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


def select_poses(robot: Robot, theta, candidates, n: int, noise: SensorNoise, *, free=None,
                 criterion: str = "d", max_passes: int = 20, screen: int = 64) -> DesignResult:
    """Choose ``n`` of the candidate poses maximising a design criterion (module docstring).

    Args:
        robot: the robot.
        theta: (P,) parameter set at which to linearise (the nominal one before calibration).
        candidates: (K, D) feasible candidate poses, robot's pose units, K >= n.
        n: number of poses to choose, at least :func:`minimum_poses` (7 for the hexapod's 42
            parameters and the Delta's 21).
        noise: declared noise (weights the pose coordinates and joints).
        free: names of the parameters to determine; default ``robot.free_default``.
        criterion: ``"d"`` (D-optimal) or ``"e"`` (E-optimal).
        max_passes: exchange passes over the design at most.
        screen: E-optimal only, candidates evaluated exactly per exchange.

    Returns:
        The :class:`DesignResult`; deterministic for given inputs.
    """
    _check_robot(robot)
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
    candidates = _poses(robot, candidates, "candidates")
    n = _check_count(n, "n", minimum_poses(robot, free))
    if candidates.shape[0] < n:
        raise ValueError(f"candidates must have at least n = {n} rows, got {candidates.shape[0]}")
    max_passes = _check_count(max_passes, "max_passes", 0)
    screen = _check_count(screen, "screen", 1)
    _, idx = free_indices(robot, free)
    d = robot.pose_dim
    A = identification_jacobian(robot, theta, candidates, noise, free=free).reshape(-1, d, idx.size)
    A = A / parameter_scale(robot)[idx]
    ridge = 1e-9 * float(np.einsum("cki,cki->", A, A)) / (A.shape[0] * idx.size)
    chosen, ex = _d_optimal(A, n, ridge, max_passes, 1e-10)
    if criterion == "e":
        chosen, ex2 = _e_optimal(A, list(chosen), max_passes, screen, 1e-10)
        ex += ex2
    chosen_idx = np.array(chosen, dtype=int)
    F = np.einsum("cki,ckj->ij", A[chosen_idx], A[chosen_idx])
    sign, ld = np.linalg.slogdet(F)
    chosen_idx.setflags(write=False)
    return DesignResult(
        poses=frozen_array(candidates[chosen_idx]), indices=chosen_idx, criterion=criterion,
        log_det=float(ld) if sign > 0 else float("-inf"),
        lambda_min=float(np.linalg.eigvalsh(F)[0]), exchanges=ex, n_candidates=candidates.shape[0],
    )


def design_poses(robot: Robot, theta, n: int, workspace: Workspace, noise: SensorNoise, *, free=None,
                 criterion: str = "d", seed: int = 0, n_candidates: int = 3000) -> DesignResult:
    """Sample feasible candidates in ``workspace`` (seeded) and select ``n`` optimal poses.

    Args:
        robot: the robot.
        theta: (P,) parameter set (nominal before calibration).
        n: number of poses, at least :func:`minimum_poses`.
        workspace: feasible set.
        noise: declared noise.
        free: names of the parameters to determine; default ``robot.free_default``.
        criterion: ``"d"`` or ``"e"``.
        seed: seed of the candidate draw.
        n_candidates: number of feasible candidates drawn (>= n).

    Returns:
        The :class:`DesignResult` (its poses all satisfy ``workspace``).
    """
    _check_robot(robot)
    n = _check_count(n, "n", minimum_poses(robot, free))
    n_candidates = _check_count(n_candidates, "n_candidates", n)
    cands = sample_feasible_poses(robot, theta, workspace, n_candidates, seed)
    return select_poses(robot, theta, cands, n, noise, free=free, criterion=criterion)


def augment_poses(robot: Robot, theta, measured_poses, n: int, noise: SensorNoise, prior_std, *, free=None,
                  workspace: Workspace | None = None, seed: int = 0, n_candidates: int = 2000) -> np.ndarray:
    """(n, D) poses to measure next: greedy D-optimal additions to the poses already measured.

    Each step adds the feasible candidate that most raises ``log det`` of the information of the
    measured poses plus the prior's (``diag(1 / prior_std**2)``) plus the poses already added (by
    the matrix determinant lemma, ``log det(I + A F^-1 A^T)`` of each candidate's whitened rows
    ``A``): the poses that determine what the measured ones left to the prior.

    Args:
        robot, theta: the robot and the parameters to linearise at (the identified ones).
        measured_poses: (N, D) the poses measured so far (may be rank-deficient).
        n: poses to add.
        noise: declared noise.
        prior_std: (P,) the prior's standard deviations (parameter units).
        free: the parameters identified; default ``robot.free_default``.
        workspace: where the candidates are drawn; default the robot's full workspace.
        seed: seed of the candidate draw.
        n_candidates: feasible candidates drawn.
    """
    _check_robot(robot)
    theta = as_array(theta, "theta", (robot.n_parameters,))
    n = _check_count(n, "n", 1)
    workspace = robot_workspace(robot, "full") if workspace is None else workspace
    _, idx = free_indices(robot, free)
    d = robot.pose_dim
    info = np.diag(1.0 / as_array(prior_std, "prior_std", (robot.n_parameters,))[idx] ** 2)
    measured_poses = _poses(robot, measured_poses, "measured_poses")
    if len(measured_poses):
        A0 = identification_jacobian(robot, theta, measured_poses, noise, free=free).reshape(-1, idx.size)
        info = info + A0.T @ A0
    # Feasible for the nominal machine (what its controller commands), linearised at ``theta``.
    cands = sample_feasible_poses(robot, robot.table.nominal, workspace, n_candidates, seed)
    A = identification_jacobian(robot, theta, cands, noise, free=free).reshape(-1, d, idx.size)
    chosen: list[int] = []
    for _ in range(min(n, len(cands))):
        inv = np.linalg.inv(info)
        gain = np.linalg.slogdet(np.eye(d) + A @ inv @ np.swapaxes(A, 1, 2))[1]
        gain[chosen] = -np.inf
        best = int(np.argmax(gain))
        chosen.append(best)
        info = info + A[best].T @ A[best]
    return cands[chosen]
