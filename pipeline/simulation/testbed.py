"""The simulated testbed of any robot, measured like a metrology lab: the joint-space effects
(thermal drift and warm-up, screw error, lost counts) turned into servo references, the machine
settled, the measurements' seeded sensor noise and instrument drift added.

The machine itself is :mod:`mjcf`'s: built by :func:`mjcf.build_machine` from the robot and its
true parameter vector, commanded, settled and read by :class:`mjcf.simulator.MachineSimulator`
(MuJoCo data stays there; the unit boundary is the :class:`mjcf.machine.Machine`). Poses without
history (no friction, drift or screw error) settle together in ``mujoco.rollout`` from warm
starts; the others one after another (see :class:`Testbed`, "Settling").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.noise import SensorNoise
from calib.robot import Robot
from mjcf import build_machine
from mjcf.machine import MachineEffects, MachineOptions, chain_values
from mjcf.simulator import MachineSimulator, SettleError
from pipeline.execution import available_cores

__all__ = ["SettleError", "Measurements", "Testbed", "SETTLE_MODES"]

#: How :meth:`Testbed.measure` settles the poses: ``auto`` (rollout when the physics has no
#: history, sequential otherwise), ``rollout`` or ``sequential``.
SETTLE_MODES = ("auto", "rollout", "sequential")


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
        settle: ``"auto"`` (default), ``"rollout"`` or ``"sequential"`` (:data:`SETTLE_MODES`);
            see "Settling" below.
        threads: threads of the rollout; default :func:`available_cores` (every core this process
            may use, one in a worker of the local Dask cluster).

    Each measurement commands the servo references ``machine.ctrl(joints + effects)`` and steps
    until at rest. The effects, per actuated chain, in the robot's joint unit:

    Every per-joint value (friction, stiffness, drift and warm-up rates) is one number for every
    joint or one per joint.

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
      positions (x, y, z: the first three pose coordinates of every robot), the machine untouched;
    * lost count: ``effects.joint_offset_step`` added to the servo reference of a move that starts
      at or after ``effects.joint_offset_step_time_s``;
    * thermal warm-up: ``g tau (1 - exp(-t / tau))`` (``effects.joint_warmup_per_s``,
      ``effects.joint_warmup_tau_s``), ``t`` as for the thermal drift.

    Settling. ``sequential``: each pose starts from the previous pose's settled state, one after
    another (the history the friction's hysteresis and the drift's clock need). ``rollout``: the
    poses are independent, so each starts at rest from a warm start of its own
    (:meth:`mjcf.simulator.MachineSimulator.assemble`: the closures solved by Gauss-Newton with the actuated joints at their
    servo references and the platform steered onto its branch by the forward kinematics; for a
    loaded machine, :meth:`~mjcf.simulator.MachineSimulator.rest`: Newton on MuJoCo's own accelerations to where gravity, payload,
    servos and closures balance), and all are stepped together, on every core, by
    ``mujoco.rollout`` in batches of steps (8, 16, 32, ...) until each is at rest by the same
    test as the sequential settle (at least :data:`MIN_SETTLE_STEPS` steps, every joint speed
    below ``settle_velocity``): physics decides where each pose rests. The settled poses agree
    with the sequential ones to within what the settle velocity leaves, about 1e-8 mm and
    1e-10 rad (tests/test_testbed.py), in about 6 steps a pose instead of 350-650.
    ``auto`` uses the rollout when the physics has no history: no joint friction, no drift, no
    instrument drift, no screw error, no lost count, no warm-up and no ``times_s`` given; the sequential path otherwise. In the rollout, ``t_s``
    is the time the machine spends settling the poses one after another from the warm start.

    Noise: pose noise ``noise.sample`` is drawn after the poses settle, then joint noise
    ``noise.sample_joints`` from the same stream (not drawn at all when ``noise.joint`` is 0);
    the same whichever way the poses settle.
    """

    __test__ = False  # a name pytest would otherwise try to collect

    def __init__(self, robot: Robot, theta, *, options: MachineOptions = MachineOptions(),
                 effects: MachineEffects = MachineEffects(), noise: SensorNoise = SensorNoise(), seed=0,
                 settle_velocity: float = 1e-9, max_steps: int = 20000, settle: str = "auto",
                 threads: int | None = None):
        if settle not in SETTLE_MODES:
            raise ValueError(f"settle must be one of {', '.join(SETTLE_MODES)}, got {settle!r}")
        if threads is not None and not (isinstance(threads, (int, np.integer)) and threads >= 1):
            raise ValueError(f"threads must be a positive integer, got {threads!r}")
        if not (np.isfinite(settle_velocity) and settle_velocity > 0):
            raise ValueError(f"settle_velocity must be > 0, got {settle_velocity!r}")
        if not (isinstance(max_steps, (int, np.integer)) and max_steps >= 1):
            raise ValueError(f"max_steps must be a positive integer, got {max_steps!r}")
        c = robot.n_chains
        if len(effects.joint_offset_step) not in (0, c):
            raise ValueError(f"effects.joint_offset_step must have {c} values (one per {robot.chain_word}), "
                             f"got {len(effects.joint_offset_step)}")
        if len(effects.screw_amplitude) not in (0, c):
            raise ValueError(f"effects.screw_amplitude must have {c} values (one per {robot.chain_word}), "
                             f"got {len(effects.screw_amplitude)}")
        self.robot, self.options, self.effects, self.noise = robot, options, effects, noise
        self.settle_velocity, self.max_steps = float(settle_velocity), int(max_steps)
        self.machine = build_machine(robot, theta, options)
        self.simulator = MachineSimulator(self.machine, settle_velocity=settle_velocity, max_steps=max_steps,
                                          threads=int(threads) if threads is not None else available_cores())
        self.threads = self.simulator.threads
        #: (C,) joint values at the home keyframe (origin of the screw error's stroke).
        self.home_joints = self.simulator.home_joints
        self._rng = np.random.default_rng(seed)
        self._screw_amplitude = np.asarray(effects.screw_amplitude) if effects.screw_amplitude else np.zeros(c)
        self._screw_phase = np.asarray(effects.screw_phase_rad) if effects.screw_phase_rad else np.zeros(c)
        #: (C,) each joint's Coulomb friction, thermal drift rate and warm-up rate.
        self.friction = chain_values(options.joint_friction, c, "options.joint_friction")
        self._drift = chain_values(effects.joint_drift_per_s, c, "effects.joint_drift_per_s")
        self._warmup = chain_values(effects.joint_warmup_per_s, c, "effects.joint_warmup_per_s")
        self.history_free = (not np.any(self.friction) and not np.any(self._drift)
                             and not np.any(self._screw_amplitude) and not np.any(effects.instrument_drift_mm_per_s)
                             and not np.any(effects.joint_offset_step) and not np.any(self._warmup))
        if settle == "rollout" and not self.history_free:
            raise ValueError("settle='rollout' needs physics without history (no joint friction, drift, "
                             "instrument drift, screw error, lost count or warm-up): use 'sequential' or 'auto'")
        self.settle_mode = settle

    def servo_reference(self, joints: np.ndarray, time_s: float) -> np.ndarray:
        """(C,) the joint values the servos are sent for commanded ``joints`` at ``time_s``:
        the command plus thermal drift, warm-up, screw error and lost count (robot joint unit)."""
        fx = self.effects
        screw = self._screw_amplitude * np.sin(2 * np.pi * (joints - self.home_joints) / fx.screw_pitch
                                               + self._screw_phase)
        ref = joints + screw + self._drift * time_s
        if np.any(self._warmup):
            from calib.effects.thermal_warmup import warmup_growth  # imported where a warm-up is simulated

            ref = ref + self._warmup * warmup_growth(time_s, fx.joint_warmup_tau_s)
        if fx.joint_offset_step and time_s >= fx.joint_offset_step_time_s:
            ref = ref + np.asarray(fx.joint_offset_step)
        return ref

    def settle(self, joints: np.ndarray, at_time_s: float | None = None) -> tuple[np.ndarray, int]:
        """Command one set of joint values and step until at rest (:meth:`mjcf.simulator.MachineSimulator.settle`).

        Args:
            joints: (C,) commanded joint values, robot joint unit.
            at_time_s: the (lab) time of this measurement for time-dependent effects; default
                the simulated time.

        Returns:
            ``(pose, steps)``: (D,) settled true pose (mm, rad) and steps taken.

        Raises:
            SettleError: not at rest after ``max_steps`` steps.
        """
        joints = np.asarray(joints, dtype=float)
        t = self.simulator.time if at_time_s is None else at_time_s
        return self.simulator.settle(self.servo_reference(joints, t), self.friction, commanded=joints)

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
        if self.uses_rollout(times_s):
            true, read, t, steps = self.simulator.settle_many(self.servo_reference(joints, 0.0), progress,
                                                              commanded=joints)
        else:
            true, read, t, steps = self._settle_sequential(joints, times_s, progress)
        measured = true + self.noise.sample(n, self._rng, self.robot.pose_units)
        if np.any(self.effects.instrument_drift_mm_per_s):
            measured[:, :3] += t[:, None] * np.asarray(self.effects.instrument_drift_mm_per_s)
        encoders = joints.copy()
        if self.noise.joint > 0:
            encoders += self.noise.sample_joints(n, c, self._rng)
        return Measurements(t, joints.copy(), read, encoders, true, measured, steps)

    def uses_rollout(self, times_s=None) -> bool:
        """Whether :meth:`measure` settles by the rollout (with these ``times_s``; see "Settling").

        Raises:
            ValueError: ``settle='rollout'`` with ``times_s`` given.
        """
        if self.settle_mode == "rollout" and times_s is not None:
            raise ValueError("times_s needs the sequential settle (settle='sequential' or 'auto')")
        return self.settle_mode == "rollout" or (self.settle_mode == "auto" and self.history_free and times_s is None)

    def _settle_sequential(self, joints: np.ndarray, times_s: np.ndarray | None, progress):
        n, c = joints.shape
        true = np.empty((n, self.robot.pose_dim))
        read = np.empty((n, c))
        t = np.empty(n)
        steps = np.empty(n, dtype=int)
        for k in range(n):
            true[k], steps[k] = self.settle(joints[k], None if times_s is None else times_s[k])
            read[k] = self.simulator.read_joints()
            t[k] = self.simulator.time if times_s is None else times_s[k]
            if progress is not None:
                progress(k + 1, n)
        return true, read, t, steps
