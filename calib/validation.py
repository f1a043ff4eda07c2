"""Argument validation shared by the public functions of ``calib`` (checks once, at the edge)."""

from __future__ import annotations

import numpy as np


def as_array(value, name: str, shape: tuple, *, finite: bool = True) -> np.ndarray:
    """Convert to a float64 array and check its shape; -1 in ``shape`` matches any size.

    Raises:
        ValueError: naming ``name``, the expected and the actual shape, or the first
            non-finite entry.
    """
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric array, got {type(value).__name__}") from exc
    want = "(" + ", ".join("N" if s == -1 else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
    if a.ndim != len(shape) or any(s != -1 and s != t for s, t in zip(shape, a.shape)):
        raise ValueError(f"{name} must have shape {want}, got {a.shape}")
    if finite and not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise ValueError(f"{name} has a non-finite value at index {tuple(int(i) for i in bad)}")
    return a


def as_poses(value, name: str = "poses") -> np.ndarray:
    """(N, 6) poses; a single (6,) pose is not silently promoted."""
    return as_array(value, name, (-1, 6))


def frozen_array(value) -> np.ndarray:
    """A read-only float64 copy (for the fields of frozen parameter sets)."""
    a = np.array(value, dtype=float)
    a.setflags(write=False)
    return a
