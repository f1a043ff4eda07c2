"""The simulated testbed of any robot: command joint values, let the MuJoCo machine settle, read
the platform pose sensors, add seeded sensor noise.

The machine is built by :func:`mjcf.build_machine` from the robot and its true parameter vector;
the conversion between the project's units (mm, rad) and MuJoCo's SI happens in the
:class:`mjcf.machine.Machine` it returns (through :mod:`mjcf.units`).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from calib.noise import SensorNoise
from calib.robot import Robot
from mjcf import build_machine
from mjcf.machine import MachineEffects, MachineOptions

__all__ = ["SettleError", "Measurements", "Testbed"]


class SettleError(RuntimeError):
    """The machine did not come to rest within the step cap."""


@dataclass(frozen=True, eq=False)
class Measurements:
    """What the testbed returns for N commanded joint sets (C chains, D pose coordinates).

    Attributes:
        t_s: (N,) time of each measurement, s (simulated, or the ``times_s`` given).
        commanded: (N, C) commanded joint values, robot joint unit (mm or rad).
        settled_joints: (N, C) where the actuated joints came to rest (no noise), robot joint
            unit: the command moved by load (servo compliance), friction, drift, screw error and
            transmission scale.
        encoders: (N, C) the joint values the machine reports: its encoders sit on the motors,
            ahead of the servo's and the transmission's compliance, so they read the command,
            plus seeded joint noise; robot joint unit. What a recording holds and calibration uses.
        true_poses: (N, D) settled platform poses before sensor noise, mm and rad, base frame.
        measured: (N, D) measured poses (true + seeded noise), mm and rad, base frame.
        steps: (N,) simulation steps each pose took to settle.
    """

    t_s: np.ndarray
    commanded: np.ndarray
    settled_joints: np.ndarray
    encoders: np.ndarray
    true_poses: np.ndarray
    measured: np.ndarray
    steps: np.ndarray


class Testbed:
    """A robot with true parameters ``theta`` simulated in MuJoCo, measured like a metrology lab.

    Args:
        robot: the robot (:class:`calib.robot.Robot`).
        theta: (P,) its true parameter vector (nominal + errors), mm and rad.
        options: physical options of the machine (gravity, payload, servo, friction,
            transmission scale).
        effects: joint-space effects the testbed adds (thermal drift, periodic screw error).
        noise: sensor noise added to the measured poses (and to the joint readings).
        seed: seed of the sensor noise; the same seed gives the same numbers.
        settle_velocity: at rest when every joint speed is below this, m/s or rad/s.
        max_steps: step cap per pose; beyond it :class:`SettleError` is raised.

    Each measurement commands the servo references ``machine.ctrl(joints + effects)`` and steps
    until at rest. The effects, per actuated chain, in the robot's joint unit:

    * thermal drift: ``effects.joint_drift_per_s * t`` with ``t`` the time of the measurement
      (``times_s``, default the simulated time) at the start of the move; drift is slow next to
      settling, so the chain keeps that length while the machine settles;
    * periodic screw error: ``A_i sin(2 pi stroke_i / pitch + phase_i)``, ``stroke`` the command
      minus the joint value of the home keyframe (MuJoCo has no periodic transmission element);
    * transmission scale: built into the actuator's gear by the builder;
    * Coulomb friction ``options.joint_friction`` (N or N m) in its quasi-static limit: while a
      chain moves to a new command the friction force opposes its motion, and a chain approached
      monotonically comes to rest where its servo force equals the friction, short of the target
      by friction / stiffness: a dead band whose sign is the direction in which the chain last
      moved (hysteresis). It is applied as a joint force on the actuated dof. MuJoCo's own
      ``frictionloss`` (which the builders write, for the viewer and the dynamics) is a soft
      constraint: it creeps to the target and leaves no dead band;
    * instrument drift: ``effects.instrument_drift_mm_per_s * t`` added to the measured
      positions (x, y, z: the first three pose coordinates of every robot), the machine untouched.

    Noise: pose noise ``noise.sample`` is drawn after the poses settle, then joint noise
    ``noise.sample_joints`` from the same stream (not drawn at all when ``noise.joint`` is 0).
    """

    __test__ = False  # a name pytest would otherwise try to collect

    def __init__(self, robot: Robot, theta, *, options: MachineOptions = MachineOptions(),
                 effects: MachineEffects = MachineEffects(), noise: SensorNoise = SensorNoise(), seed=0,
                 settle_velocity: float = 1e-9, max_steps: int = 20000):
        if not (np.isfinite(settle_velocity) and settle_velocity > 0):
            raise ValueError(f"settle_velocity must be > 0, got {settle_velocity!r}")
        if not (isinstance(max_steps, (int, np.integer)) and max_steps >= 1):
            raise ValueError(f"max_steps must be a positive integer, got {max_steps!r}")
        c = robot.n_chains
        if len(effects.screw_amplitude) not in (0, c):
            raise ValueError(f"effects.screw_amplitude must have {c} values (one per {robot.chain_word}), "
                             f"got {len(effects.screw_amplitude)}")
        self.robot, self.options, self.effects, self.noise = robot, options, effects, noise
        self.settle_velocity, self.max_steps = float(settle_velocity), int(max_steps)
        self.machine = build_machine(robot, theta, options)
        self.model = self.machine.model
        self.data = mujoco.MjData(self.model)
        self.machine.reset(self.data)
        #: (C,) joint values at the home keyframe (origin of the screw error's stroke).
        self.home_joints = self.machine.read_joints(self.data)
        self._rng = np.random.default_rng(seed)
        self._screw_amplitude = np.asarray(effects.screw_amplitude) if effects.screw_amplitude else np.zeros(c)
        self._screw_phase = np.asarray(effects.screw_phase_rad) if effects.screw_phase_rad else np.zeros(c)
        self._last_ctrl = self.data.ctrl.copy()
        self._direction = np.zeros(c)

    def servo_reference(self, joints: np.ndarray, time_s: float) -> np.ndarray:
        """(C,) the joint values the servos are sent for commanded ``joints`` at ``time_s``:
        the command plus thermal drift and screw error (robot joint unit)."""
        fx = self.effects
        screw = self._screw_amplitude * np.sin(2 * np.pi * (joints - self.home_joints) / fx.screw_pitch
                                               + self._screw_phase)
        return joints + screw + fx.joint_drift_per_s * time_s

    def settle(self, joints: np.ndarray, at_time_s: float | None = None) -> tuple[np.ndarray, int]:
        """Command one set of joint values and step until at rest.

        Args:
            joints: (C,) commanded joint values, robot joint unit.
            at_time_s: the (lab) time of this measurement for time-dependent effects; default
                the simulated time.

        Returns:
            ``(pose, steps)``: (D,) settled true pose (mm, rad) and steps taken.

        Raises:
            SettleError: not at rest after ``max_steps`` steps.
        """
        m, d, mc = self.model, self.data, self.machine
        t = d.time if at_time_s is None else at_time_s
        d.ctrl[:] = mc.ctrl(self.servo_reference(np.asarray(joints, dtype=float), t))
        move = np.sign(d.ctrl - self._last_ctrl)
        self._direction = np.where(move != 0, move, self._direction)
        self._last_ctrl = d.ctrl.copy()
        d.qfrc_applied[mc.dof_index] = -self.options.joint_friction * self._direction
        qvel, v = d.qvel, self.settle_velocity
        # max |qvel| < v needs qvel . qvel < nv v^2: the cheap test rules out most steps.
        bound = qvel.size * v * v
        for step in range(1, self.max_steps + 1):
            mujoco.mj_step(m, d)
            if step > 5 and qvel @ qvel < bound and np.max(np.abs(qvel)) < v:
                return mc.read_pose(d), step
        raise SettleError(
            f"the machine did not settle within {self.max_steps} steps "
            f"({self.max_steps * m.opt.timestep:g} s) for commanded joints "
            f"{np.array2string(np.asarray(joints), precision=4)} {self.robot.joint_unit}: max joint speed "
            f"{np.max(np.abs(d.qvel)):.3g} > {self.settle_velocity:g}")

    def measure(self, joints: np.ndarray, *, times_s: np.ndarray | None = None, progress=None) -> Measurements:
        """Command each row of joint values in turn, settle, read the sensors, add noise.

        Args:
            joints: (N, C) commanded joint values, robot joint unit.
            times_s: (N,) lab times of the measurements (to replay a recording's time axis);
                default the simulated time.
            progress: optional callable ``progress(done, total)``.
        """
        c = self.robot.n_chains
        joints = np.asarray(joints, dtype=float)
        if joints.ndim != 2 or joints.shape[1] != c:
            raise ValueError(f"joints must have shape (N, {c}), got {joints.shape}")
        if not np.all(np.isfinite(joints)):
            raise ValueError("joints must be finite")
        n = joints.shape[0]
        if times_s is not None:
            times_s = np.asarray(times_s, dtype=float)
            if times_s.shape != (n,):
                raise ValueError(f"times_s must have shape ({n},), got {times_s.shape}")
        true = np.empty((n, self.robot.pose_dim))
        read = np.empty((n, c))
        t = np.empty(n)
        steps = np.empty(n, dtype=int)
        for k in range(n):
            true[k], steps[k] = self.settle(joints[k], None if times_s is None else times_s[k])
            read[k] = self.machine.read_joints(self.data)
            t[k] = self.data.time if times_s is None else times_s[k]
            if progress is not None:
                progress(k + 1, n)
        measured = true + self.noise.sample(n, self._rng, self.robot.pose_units)
        if self.effects.instrument_drift_mm_per_s:
            measured[:, :3] += t[:, None] * np.asarray(self.effects.instrument_drift_mm_per_s)
        encoders = joints.copy()
        if self.noise.joint > 0:
            encoders += self.noise.sample_joints(n, c, self._rng)
        return Measurements(t, joints.copy(), read, encoders, true, measured, steps)
