"""Declared sensor noise of a pose measurement, used both to simulate and to weight."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SensorNoise", "chi2_quantile"]

_DISTRIBUTIONS = ("uniform", "normal")


@dataclass(frozen=True)
class SensorNoise:
    """Noise of a 6-D pose sensor.

    Attributes:
        position_mm: for ``"uniform"`` the half-width (noise within +-value), for ``"normal"``
            the standard deviation, of each position coordinate, mm.
        orientation_rad: the same for each angle, rad.
        joint: the same for each joint reading, in the robot's joint unit (mm or rad); 0 when the
            joints are commanded exactly (the hexapod paper's assumption).
        distribution: ``"uniform"`` (the paper's "+-0.001 mm") or ``"normal"``.
    """

    position_mm: float = 0.0
    orientation_rad: float = 0.0
    distribution: str = "uniform"
    joint: float = 0.0

    def __post_init__(self) -> None:
        if self.distribution not in _DISTRIBUTIONS:
            raise ValueError(f"distribution must be one of {_DISTRIBUTIONS}, got {self.distribution!r}")
        for name in ("position_mm", "orientation_rad", "joint"):
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

    @property
    def joint_std(self) -> float:
        """Standard deviation of each joint reading, joint unit."""
        return float(self.joint * self._scale)

    def pose_std(self, units=("mm",) * 3 + ("rad",) * 3, floor_mm: float = 1e-6,
                 floor_rad: float = 1e-9) -> np.ndarray:
        """(D,) standard deviation of each pose coordinate of the given units (``"mm"``/``"rad"``),
        floored: no sensor is exact, and a zero would make a weight infinite."""
        angle = np.array([u == "rad" for u in units])
        std = np.where(angle, self.orientation_rad, self.position_mm) * self._scale
        return np.maximum(std, np.where(angle, floor_rad, floor_mm))

    def weights(self, floor_mm: float = 1e-6, floor_rad: float = 1e-9) -> np.ndarray:
        """(6,) inverse standard deviations for weighting residuals, 1/mm and 1/rad.

        A declared noise of zero is floored (``floor_mm``, ``floor_rad``): no sensor is exact,
        and a zero would make the weight infinite.
        """
        return 1.0 / self.pose_std(floor_mm=floor_mm, floor_rad=floor_rad)

    def sample(self, n: int, seed: int | np.random.Generator,
               units=("mm",) * 3 + ("rad",) * 3) -> np.ndarray:
        """(n, D) noise draws for pose coordinates of the given units; the same seed gives the
        same numbers."""
        rng = np.random.default_rng(seed)
        half = np.array([self.orientation_rad if u == "rad" else self.position_mm for u in units])
        return self._draw(rng, (n, len(units))) * half

    def sample_joints(self, n: int, n_joints: int, seed: int | np.random.Generator) -> np.ndarray:
        """(n, n_joints) joint-reading noise draws, joint unit."""
        return self._draw(np.random.default_rng(seed), (n, n_joints)) * self.joint

    def _draw(self, rng: np.random.Generator, shape: tuple) -> np.ndarray:
        if self.distribution == "uniform":
            return rng.uniform(-1.0, 1.0, size=shape)
        return rng.standard_normal(shape)

    def to_dict(self) -> dict:
        return {"position_mm": self.position_mm, "orientation_rad": self.orientation_rad,
                "joint": self.joint, "distribution": self.distribution}


def chi2_quantile(probability: float, dof: float) -> float:
    """The chi-square(``dof``) quantile at ``probability``: ``scipy.stats.chi2.ppf(probability,
    dof)`` bit for bit, through ``scipy.special.gammaincinv`` (imported here: scipy.special takes
    0.15-0.2 s to import, which a command that judges no chi-square need not pay)."""
    from scipy.special import gammaincinv

    return float(2.0 * gammaincinv(dof / 2.0, probability))
