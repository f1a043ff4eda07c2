"""Workspaces to draw poses from."""

from __future__ import annotations

import numpy as np

__all__ = ["PAPER_WORKSPACE", "random_poses"]

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
