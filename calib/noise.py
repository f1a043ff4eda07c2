"""Declared sensor noise of a pose measurement, used both to simulate and to weight."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SensorNoise"]

_DISTRIBUTIONS = ("uniform", "normal")


@dataclass(frozen=True)
class SensorNoise:
    """Noise of a 6-D pose sensor.

    Attributes:
        position_mm: for ``"uniform"`` the half-width (noise within +-value), for ``"normal"``
            the standard deviation, of each position coordinate, mm.
        orientation_rad: the same for each angle, rad.
        distribution: ``"uniform"`` (the paper's "+-0.001 mm") or ``"normal"``.
    """

    position_mm: float = 0.0
    orientation_rad: float = 0.0
    distribution: str = "uniform"

    def __post_init__(self) -> None:
        if self.distribution not in _DISTRIBUTIONS:
            raise ValueError(f"distribution must be one of {_DISTRIBUTIONS}, got {self.distribution!r}")
        for name in ("position_mm", "orientation_rad"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")

    @property
    def _scale(self) -> float:
        # Standard deviation of a uniform variable on [-a, a] is a / sqrt(3).
        return 1.0 / np.sqrt(3.0) if self.distribution == "uniform" else 1.0

    @property
    def std(self) -> np.ndarray:
        """(6,) standard deviation per pose coordinate, mm and rad."""
        return np.repeat([self.position_mm, self.orientation_rad], 3) * self._scale

    def weights(self, floor_mm: float = 1e-6, floor_rad: float = 1e-9) -> np.ndarray:
        """(6,) inverse standard deviations for weighting residuals, 1/mm and 1/rad.

        A declared noise of zero is floored (``floor_mm``, ``floor_rad``): no sensor is exact,
        and a zero would make the weight infinite.
        """
        std = self.std
        return 1.0 / np.maximum(std, np.repeat([floor_mm, floor_rad], 3))

    def sample(self, n: int, seed: int | np.random.Generator) -> np.ndarray:
        """(n, 6) noise draws, mm and rad; the same seed gives the same numbers."""
        rng = np.random.default_rng(seed)
        half = np.repeat([self.position_mm, self.orientation_rad], 3)
        if self.distribution == "uniform":
            return rng.uniform(-1.0, 1.0, size=(n, 6)) * half
        return rng.standard_normal((n, 6)) * half

    def to_dict(self) -> dict:
        return {"position_mm": self.position_mm, "orientation_rad": self.orientation_rad,
                "distribution": self.distribution}
