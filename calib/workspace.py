"""Poses drawn from a robot's workspace (seeded)."""

from __future__ import annotations

import numpy as np

from .robot import KinematicsError, Robot

__all__ = ["random_poses", "reachable_poses"]


def random_poses(n: int, seed: int | np.random.Generator | np.random.SeedSequence, bounds: np.ndarray) -> np.ndarray:
    """(n, D) poses drawn uniformly within ``bounds`` ((D, 2) low/high per pose coordinate)."""
    if int(n) != n or n < 0:
        raise ValueError(f"n must be a non-negative integer, got {n!r}")
    b = np.asarray(bounds, dtype=float)
    if b.ndim != 2 or b.shape[1] != 2 or np.any(b[:, 0] > b[:, 1]):
        raise ValueError(f"bounds must have shape (D, 2) with low <= high, got {b.shape}")
    rng = np.random.default_rng(seed)
    return b[:, 0] + rng.uniform(size=(int(n), b.shape[0])) * (b[:, 1] - b[:, 0])


def reachable_poses(robot: Robot, n: int, seed, *, bounds: np.ndarray | None = None,
                    theta: np.ndarray | None = None, max_rounds: int = 50) -> np.ndarray:
    """(n, D) poses drawn uniformly within ``bounds`` (default the robot's workspace) that the
    machine ``theta`` (default nominal) reaches with every joint inside its limits.

    Raises:
        ValueError: fewer than ``n`` reachable poses found in ``max_rounds`` rounds of draws.
    """
    theta = robot.table.nominal if theta is None else theta
    bounds = robot.workspace_bounds() if bounds is None else bounds
    rng = np.random.default_rng(seed)
    limits = robot.joint_limits()
    kept: list[np.ndarray] = []
    for _ in range(max_rounds):
        cand = random_poses(max(n, 8), rng, bounds)
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
    raise ValueError(f"fewer than {n} reachable poses found in the workspace {bounds.tolist()}")
