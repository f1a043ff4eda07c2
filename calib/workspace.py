"""Workspaces to draw poses from."""

from __future__ import annotations

import numpy as np

__all__ = ["PAPER_WORKSPACE", "random_poses", "reachable_poses"]

#: The paper's Table 4 workspace: x, y within +-10 mm, z in [200, 210] mm, angles within
#: +-3 degrees. Rows are (low, high) per pose coordinate, mm and rad.
PAPER_WORKSPACE = np.array([
    [-10.0, 10.0], [-10.0, 10.0], [200.0, 210.0],
    [-np.deg2rad(3.0), np.deg2rad(3.0)], [-np.deg2rad(3.0), np.deg2rad(3.0)],
    [-np.deg2rad(3.0), np.deg2rad(3.0)],
])


def random_poses(n: int, seed: int | np.random.Generator, bounds: np.ndarray = PAPER_WORKSPACE) -> np.ndarray:
    """(n, 6) poses drawn uniformly within ``bounds`` ((6, 2) low/high, mm and rad)."""
    if int(n) != n or n < 0:
        raise ValueError(f"n must be a non-negative integer, got {n!r}")
    b = np.asarray(bounds, dtype=float)
    if b.shape != (6, 2) or np.any(b[:, 0] > b[:, 1]):
        raise ValueError(f"bounds must have shape (6, 2) with low <= high, got {b.shape}")
    rng = np.random.default_rng(seed)
    return b[:, 0] + rng.uniform(size=(int(n), 6)) * (b[:, 1] - b[:, 0])


def reachable_poses(robot, n: int, seed, *, bounds: np.ndarray | None = None,
                    theta: np.ndarray | None = None, max_rounds: int = 50) -> np.ndarray:
    """(n, D) poses drawn uniformly within ``bounds`` (default the robot's workspace) that the
    machine ``theta`` (default nominal) of a :class:`calib.robot.Robot` reaches with every joint
    inside its limits.

    Raises:
        ValueError: fewer than ``n`` reachable poses found in ``max_rounds`` rounds of draws.
    """
    from .robot import KinematicsError

    theta = robot.table.nominal if theta is None else theta
    b = robot.workspace_bounds() if bounds is None else np.asarray(bounds, dtype=float)
    rng = np.random.default_rng(seed)
    limits = robot.joint_limits()
    kept: list[np.ndarray] = []
    for _ in range(max_rounds):
        cand = b[:, 0] + rng.uniform(size=(max(n, 8), b.shape[0])) * (b[:, 1] - b[:, 0])
        try:  # the whole draw at once; pose by pose only when some pose is out of reach
            joints = robot.inverse_kinematics(theta, cand)
            reached = cand
        except KinematicsError:
            reached, rows = [], []
            for pose in cand:
                try:
                    rows.append(robot.inverse_kinematics(theta, pose[None])[0])
                    reached.append(pose)
                except KinematicsError:
                    continue
            joints = np.array(rows).reshape(-1, limits.shape[0])
        inside = np.all((joints >= limits[:, 0]) & (joints <= limits[:, 1]), axis=1)
        kept.extend(np.asarray(reached)[inside])
        if len(kept) >= n:
            return np.array(kept[:n]).reshape(n, robot.pose_dim)
    raise ValueError(f"fewer than {n} reachable poses found in the workspace {b.tolist()}")
