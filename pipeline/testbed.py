"""The simulated testbed: command leg lengths, let the MuJoCo machine settle, read the
platform pose sensors, add seeded sensor noise.

This is the boundary between the project's units (mm, rad) and MuJoCo's (m): conversions go
through :mod:`mjcf.units` and happen here only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from calib._validate import as_array
from calib.hexapod import Hexapod
from calib.noise import SensorNoise
from calib.rotation import euler_from_quaternion
from mjcf.hexapod import SENSOR_POS, SENSOR_QUAT, HexapodModelOptions, build_hexapod
from mjcf.units import m_to_mm, mm_to_m

__all__ = ["SettleError", "Measurements", "HexapodTestbed"]


class SettleError(RuntimeError):
    """The machine did not come to rest within the step cap."""


@dataclass(frozen=True, eq=False)
class Measurements:
    """What the testbed returns for N commanded leg-length sets.

    Attributes:
        t_s: (N,) simulated time at each measurement, s.
        commanded: (N, 6) commanded leg lengths, mm.
        true_poses: (N, 6) settled platform poses before sensor noise, mm and rad.
        measured: (N, 6) measured poses (true + seeded noise), mm and rad.
        steps: (N,) simulation steps each pose took to settle.
    """

    t_s: np.ndarray
    commanded: np.ndarray
    true_poses: np.ndarray
    measured: np.ndarray
    steps: np.ndarray


@dataclass
class HexapodTestbed:
    """A perturbed hexapod simulated in MuJoCo, measured like a metrology lab would.

    Args:
        actual: the machine's true parameter set (nominal geometry + errors), mm.
        options: MuJoCo physics options (gravity, payload, stiffness, friction).
        noise: sensor noise added to the measured poses.
        seed: seed of the sensor noise; the same seed gives the same numbers.
        settle_velocity: at rest when every joint speed is below this, m/s or rad/s.
        max_steps: step cap per pose; beyond it :class:`SettleError` is raised.
    """

    actual: Hexapod
    options: HexapodModelOptions = field(default_factory=HexapodModelOptions)
    noise: SensorNoise = field(default_factory=SensorNoise)
    seed: int = 0
    settle_velocity: float = 1e-9
    max_steps: int = 20000

    def __post_init__(self) -> None:
        self.model = build_hexapod(self.actual, self.options)
        self.data = mujoco.MjData(self.model)
        self._rng = np.random.default_rng(self.seed)
        self._home = self.actual.geometry.home_lengths
        self._pos = self.model.sensor(SENSOR_POS)
        self._quat = self.model.sensor(SENSOR_QUAT)
        mujoco.mj_forward(self.model, self.data)

    def _read_pose(self) -> np.ndarray:
        s = self.data.sensordata
        pos = s[self._pos.adr[0]:self._pos.adr[0] + 3]
        quat = s[self._quat.adr[0]:self._quat.adr[0] + 4]
        return np.r_[m_to_mm(pos), euler_from_quaternion(quat)]

    def settle(self, lengths_mm: np.ndarray) -> tuple[np.ndarray, int]:
        """Command one set of leg lengths and step until at rest.

        Args:
            lengths_mm: (6,) commanded leg lengths, mm.

        Returns:
            ``(pose, steps)``: (6,) settled true pose (mm, rad) and steps taken.

        Raises:
            SettleError: not at rest after ``max_steps`` steps.
        """
        m, d = self.model, self.data
        d.ctrl[:] = mm_to_m(lengths_mm - self._home)
        for step in range(1, self.max_steps + 1):
            mujoco.mj_step(m, d)
            if step > 5 and np.max(np.abs(d.qvel)) < self.settle_velocity:
                return self._read_pose(), step
        raise SettleError(
            f"the machine did not settle within {self.max_steps} steps "
            f"({self.max_steps * m.opt.timestep:g} s) for commanded lengths "
            f"{np.array2string(np.asarray(lengths_mm), precision=4)} mm: max joint speed "
            f"{np.max(np.abs(d.qvel)):.3g} > {self.settle_velocity:g}")

    def measure(self, commanded: np.ndarray, progress=None) -> Measurements:
        """Command each row of leg lengths in turn, settle, read the sensors, add noise.

        Args:
            commanded: (N, 6) commanded leg lengths, mm.
            progress: optional callable ``progress(done, total)``.
        """
        commanded = as_array(commanded, "commanded", (-1, 6))
        n = commanded.shape[0]
        true = np.empty((n, 6))
        t = np.empty(n)
        steps = np.empty(n, dtype=int)
        for k in range(n):
            true[k], steps[k] = self.settle(commanded[k])
            t[k] = self.data.time
            if progress is not None:
                progress(k + 1, n)
        measured = true + self.noise.sample(n, self._rng)
        return Measurements(t, commanded.copy(), true, measured, steps)
