"""Simulation testbed for the Delta: command joint angles in MuJoCo, wait until the machine
settles, read the plate position, add seeded measurement noise.

This is the ONE place where the Delta's lengths are converted between the calib package's
millimetres and MuJoCo's metres (:data:`M_PER_MM`).
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from calib.delta import DeltaParams, _as_array, forward_kinematics, inverse_kinematics
from mjcf.delta import ACTUATORS, ARM_JOINTS, PLATE_SENSOR, DeltaMjcfGeometry, build_delta_model

__all__ = ["M_PER_MM", "DeltaMeasurements", "DeltaTestbed", "delta_geometry_si"]

#: Metres per millimetre: the only unit conversion of the Delta pipeline.
from mjcf.units import M_PER_MM  # the one place units meet MuJoCo

#: Plate-centre target used for the home pose, mm, base frame.
HOME_TARGET_MM = (0.0, 0.0, -420.0)


def delta_geometry_si(
    params: DeltaParams,
    *,
    rn_mm: float = 30.0,
    plate_attach_theta=None,
    home_q=None,
) -> DeltaMjcfGeometry:
    """Convert a Model-24 parameter set (mm) to the SI geometry of the MJCF builder.

    Args:
        params: The simulated robot's parameters (mm / rad).
        rn_mm: Plate radius (centre to forearm attachment), mm.
        plate_attach_theta: Directions of the plate attachments, shape (3,), rad; default
            ``params.theta``.
        home_q: Initial joint readings, shape (3,), rad; default: reaches
            :data:`HOME_TARGET_MM` with ``params``.

    Returns:
        The geometry in metres / radians, home pose consistent with ``params``.
    """
    if not isinstance(params, DeltaParams):
        raise ValueError(f"params must be a DeltaParams, got {type(params).__name__}")
    if not (np.isfinite(rn_mm) and rn_mm >= 0):
        raise ValueError(f"rn_mm must be finite and >= 0, got {rn_mm}")
    th = params.theta if plate_attach_theta is None else _as_array(plate_attach_theta, "plate_attach_theta", (3,))
    if home_q is None:
        home_q = inverse_kinematics(params, np.array([HOME_TARGET_MM]))[0]
    home_q = _as_array(home_q, "home_q", (3,))
    home_plate = forward_kinematics(params, home_q[None])[0]
    attach = rn_mm * np.stack([np.cos(th), np.sin(th), np.zeros(3)], axis=1)
    return DeltaMjcfGeometry(
        shoulder=params.shoulders() * M_PER_MM,
        theta=params.theta,
        alpha=params.alpha,
        arm=np.stack([params.Lax, params.Lay], axis=1) * M_PER_MM,
        forearm=params.Lb * M_PER_MM,
        plate_attach=attach * M_PER_MM,
        home_q=home_q,
        home_plate=home_plate * M_PER_MM,
    )


@dataclasses.dataclass(frozen=True)
class DeltaMeasurements:
    """What the testbed measured, one row per configuration.

    Attributes:
        t_s: Simulated time at which each configuration was read, shape (N,), s.
        q_cmd: Commanded joint readings, shape (N, 3), rad.
        q_true: Settled (noise-free) joint readings, shape (N, 3), rad.
        q_meas: Measured joint readings (settled joint + noise), shape (N, 3), rad.
        positions_meas: Measured plate-centre positions (+ noise), shape (N, 3), mm, base frame.
        positions_true: Noise-free settled plate-centre positions, shape (N, 3), mm.
        steps: Simulation steps needed to settle each configuration, shape (N,).
        elbows: Settled elbow points, shape (N, 3, 3), mm (for visualisation).
        shoulders: Physical shoulder points, shape (3, 3), mm.
        plate_attach: Settled plate attachment points, shape (N, 3, 3), mm.
    """

    t_s: np.ndarray
    q_cmd: np.ndarray
    q_true: np.ndarray
    q_meas: np.ndarray
    positions_meas: np.ndarray
    positions_true: np.ndarray
    steps: np.ndarray
    elbows: np.ndarray
    shoulders: np.ndarray
    plate_attach: np.ndarray


class DeltaTestbed:
    """A simulated Delta (MuJoCo) standing in for the real machine and its instruments.

    Args:
        true_params: Parameters of the simulated (real) robot, mm / rad.
        rn_mm: Plate radius, mm.
        noise_mm: Standard deviation of the position measurement noise per coordinate, mm.
        noise_rad: Standard deviation of the joint reading noise, rad.
        seed: Seed of the measurement noise (``np.random.default_rng``).
        max_steps: Step cap per configuration; exceeding it raises RuntimeError.
        vel_tol: Settled when every joint speed is below this (rad/s or m/s).
    """

    def __init__(
        self,
        true_params: DeltaParams,
        *,
        rn_mm: float = 30.0,
        noise_mm: float = 0.0,
        noise_rad: float = 0.0,
        seed=0,
        max_steps: int = 20000,
        vel_tol: float = 1e-11,
    ) -> None:
        for name, val in (("noise_mm", noise_mm), ("noise_rad", noise_rad)):
            if not (np.isfinite(val) and val >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {val}")
        if not (isinstance(max_steps, (int, np.integer)) and max_steps >= 1):
            raise ValueError(f"max_steps must be a positive integer, got {max_steps!r}")
        if not (np.isfinite(vel_tol) and vel_tol > 0):
            raise ValueError(f"vel_tol must be positive, got {vel_tol}")
        self.geometry = delta_geometry_si(true_params, rn_mm=rn_mm)
        self.model = build_delta_model(self.geometry)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_resetDataKeyframe(self.model, self.data, 0)
        mujoco.mj_forward(self.model, self.data)
        self.noise_mm = float(noise_mm)
        self.noise_rad = float(noise_rad)
        self.max_steps = int(max_steps)
        self.vel_tol = float(vel_tol)
        self._rng = np.random.default_rng(seed)
        self._qadr = np.array([self.model.joint(n).qposadr[0] for n in ARM_JOINTS])
        self._act = np.array([self.model.actuator(n).id for n in ACTUATORS])

    def _settle(self, k: int) -> int:
        m, d = self.model, self.data
        for step in range(1, self.max_steps + 1):
            mujoco.mj_step(m, d)
            if step % 10 == 0 and np.max(np.abs(d.qvel)) < self.vel_tol:
                mujoco.mj_forward(m, d)
                return step
        raise RuntimeError(
            f"configuration {k}: the Delta did not settle within max_steps={self.max_steps} steps "
            f"(max |qvel| = {np.max(np.abs(d.qvel)):.3g}, vel_tol = {self.vel_tol:g}); "
            "the command may be unreachable or the model unstable"
        )

    def measure(self, q_cmd) -> DeltaMeasurements:
        """Drive the arms to each commanded configuration and measure.

        Args:
            q_cmd: Commanded joint readings, shape (N, 3), rad.

        Returns:
            :class:`DeltaMeasurements` (positions converted to mm here).

        Raises:
            RuntimeError: Naming the configuration that did not settle within the step cap.
        """
        q_cmd = _as_array(q_cmd, "q_cmd", (-1, 3))
        d = self.data
        n = q_cmd.shape[0]
        t = np.empty(n)
        q_true = np.empty((n, 3))
        x_true = np.empty((n, 3))
        steps = np.empty(n, dtype=int)
        elbows = np.empty((n, 3, 3))
        attach = np.empty((n, 3, 3))
        for k in range(n):
            d.ctrl[self._act] = q_cmd[k]
            steps[k] = self._settle(k)
            t[k] = d.time
            q_true[k] = d.qpos[self._qadr]
            x_true[k] = d.sensor(PLATE_SENSOR).data / M_PER_MM
            elbows[k] = np.stack([d.site(f"elbow{i + 1}").xpos for i in range(3)]) / M_PER_MM
            attach[k] = np.stack([d.site(f"plate_c{i + 1}").xpos for i in range(3)]) / M_PER_MM
        shoulders = np.stack([d.body(f"arm{i + 1}").xpos for i in range(3)]) / M_PER_MM
        q_meas = q_true + self._rng.normal(0.0, 1.0, (n, 3)) * self.noise_rad
        x_meas = x_true + self._rng.normal(0.0, 1.0, (n, 3)) * self.noise_mm
        return DeltaMeasurements(t, q_cmd, q_true, q_meas, x_meas, x_true, steps, elbows, shoulders, attach)
