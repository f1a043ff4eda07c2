"""The simulated testbed of any robot: command joint values, let the MuJoCo machine settle, read
the platform pose sensors, add seeded sensor noise.

The machine is built by :func:`mjcf.build_machine` from the robot and its true parameter vector;
the conversion between the project's units (mm, rad) and MuJoCo's SI happens in the
:class:`mjcf.machine.Machine` it returns (through :mod:`mjcf.units`). Poses without history
(no friction, drift or screw error) settle together in ``mujoco.rollout`` from warm starts;
the others one after another (see :class:`Testbed`, "Settling").
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from calib.noise import SensorNoise
from calib.robot import Robot
from calib.rotation import rotation_matrix
from mjcf import build_machine
from mjcf.machine import PLATFORM_SITE, MachineEffects, MachineOptions
from mjcf.units import mm_to_m

from pipeline.execution import available_cores

__all__ = ["SettleError", "Measurements", "Testbed", "SETTLE_MODES"]

#: How :meth:`Testbed.measure` settles the poses: ``auto`` (rollout when the physics has no
#: history, sequential otherwise), ``rollout`` or ``sequential``.
SETTLE_MODES = ("auto", "rollout", "sequential")
#: Fewest steps a pose is simulated before it may be declared at rest.
MIN_SETTLE_STEPS = 6
#: Steps of the first batch of the rollout; each further batch doubles, up to :data:`MAX_BATCH_STEPS`.
FIRST_BATCH_STEPS = 8
MAX_BATCH_STEPS = 512
#: Assembly (the warm start): Gauss-Newton on the closures until every residual is below this, m.
ASSEMBLY_TOLERANCE_M = 1e-13
ASSEMBLY_MAX_ITERATIONS = 30
#: ... the damping of its normal equations, relative to their largest diagonal entry (directions
#: the closures leave free, e.g. a rod's spin, get no step).
ASSEMBLY_DAMPING = 1e-12
#: ... and, while the platform is steered onto its branch, until it is this close to its pose (m, rad).
ASSEMBLY_POSE_TOLERANCE = 1e-9
#: Loaded machine (gravity, payload): Newton to the rest point, at most this many steps, the
#: stiffness by finite differences of this step (m or rad), pseudo-inverse cut-off.
REST_MAX_ITERATIONS = 12
REST_FD_STEP = 1e-7
REST_RCOND = 1e-6


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
        settle: ``"auto"`` (default), ``"rollout"`` or ``"sequential"`` (:data:`SETTLE_MODES`);
            see "Settling" below.
        threads: threads of the rollout; default :func:`available_cores` (every core this process
            may use, one in a worker of the local Dask cluster).

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
      positions (x, y, z: the first three pose coordinates of every robot), the machine untouched;
    * lost count: ``effects.joint_offset_step`` added to the servo reference of a move that starts
      at or after ``effects.joint_offset_step_time_s``;
    * thermal warm-up: ``g tau (1 - exp(-t / tau))`` (``effects.joint_warmup_per_s``,
      ``effects.joint_warmup_tau_s``), ``t`` as for the thermal drift.

    Settling. ``sequential``: each pose starts from the previous pose's settled state, one after
    another (the history the friction's hysteresis and the drift's clock need). ``rollout``: the
    poses are independent, so each starts at rest from a warm start of its own
    (:meth:`assemble`: the closures solved by Gauss-Newton with the actuated joints at their
    servo references and the platform steered onto its branch by the forward kinematics; for a
    loaded machine, :meth:`rest`: Newton on MuJoCo's own accelerations to where gravity, payload,
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
        self.history_free = (options.joint_friction == 0 and effects.joint_drift_per_s == 0
                             and not np.any(self._screw_amplitude) and not np.any(effects.instrument_drift_mm_per_s)
                             and not np.any(effects.joint_offset_step) and effects.joint_warmup_per_s == 0)
        if settle == "rollout" and not self.history_free:
            raise ValueError("settle='rollout' needs physics without history (no joint friction, drift, "
                             "instrument drift, screw error, lost count or warm-up): use 'sequential' or 'auto'")
        self.settle_mode = settle
        self.threads = int(threads) if threads is not None else available_cores()
        m = self.model
        #: dofs the assembly solves (all but the actuated ones); None when the warm start is
        #: unavailable (an actuator not on a joint, a zero gear, a sparse constraint Jacobian).
        warm = not (np.any(m.actuator_trntype != int(mujoco.mjtTrn.mjTRN_JOINT)) or mujoco.mj_isSparse(m)
                    or np.any(m.actuator_gear[:, 0] == 0))
        self._free_dofs = np.setdiff1d(np.arange(m.nv), m.jnt_dofadr[m.actuator_trnid[:, 0]]) if warm else None
        self._actuated_qpos = m.jnt_qposadr[m.actuator_trnid[:, 0]]
        self._actuated_gear = m.actuator_gear[:, 0].copy()
        self._site = m.site(PLATFORM_SITE).id
        self._rest_inverse = None

    def servo_reference(self, joints: np.ndarray, time_s: float) -> np.ndarray:
        """(C,) the joint values the servos are sent for commanded ``joints`` at ``time_s``:
        the command plus thermal drift, warm-up, screw error and lost count (robot joint unit)."""
        fx = self.effects
        screw = self._screw_amplitude * np.sin(2 * np.pi * (joints - self.home_joints) / fx.screw_pitch
                                               + self._screw_phase)
        ref = joints + screw + fx.joint_drift_per_s * time_s
        if fx.joint_warmup_per_s:
            from calib.effects.thermal_warmup import warmup_growth  # imported where a warm-up is simulated

            ref = ref + fx.joint_warmup_per_s * warmup_growth(time_s, fx.joint_warmup_tau_s)
        if fx.joint_offset_step and time_s >= fx.joint_offset_step_time_s:
            ref = ref + np.asarray(fx.joint_offset_step)
        return ref

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
        if self.uses_rollout(times_s):
            true, read, t, steps = self._settle_rollout(joints, progress)
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
            read[k] = self.machine.read_joints(self.data)
            t[k] = self.data.time if times_s is None else times_s[k]
            if progress is not None:
                progress(k + 1, n)
        return true, read, t, steps

    def assemble(self, data: mujoco.MjData, joints: np.ndarray, pose: np.ndarray | None = None) -> bool:
        """Put ``data`` at rest in the machine assembled at commanded ``joints`` ((C,), robot unit):
        each actuated joint where its servo reference holds it unloaded, the other joints solved by
        Gauss-Newton on the closures (the equality constraints), from the home keyframe. Kinematics
        only: the warm start of the rollout, which physics then settles.

        Args:
            data: the machine's data, overwritten.
            joints: (C,) commanded joint values.
            pose: (D,) where the platform goes (mm, rad), to pick the assembly (the branch) the
                machine is in: the forward kinematics of the machine's parameters at the actuated
                joints' values; the closures alone may close on another branch. Default: none.

        Returns:
            True when the closures close to :data:`ASSEMBLY_TOLERANCE_M`; otherwise ``data`` is
            left at the home keyframe (physics settles from there) and False.
        """
        m, mc = self.model, self.machine
        mc.reset(data)
        free = self._free_dofs
        if free is None:
            return False
        ctrl = mc.ctrl(self.servo_reference(np.asarray(joints, dtype=float), 0.0))
        data.qpos[self._actuated_qpos] = ctrl / self._actuated_gear
        if pose is not None:
            pose = np.asarray(pose, dtype=float)
            target_pos = mm_to_m(pose[:3])
            target_rot = rotation_matrix(pose[3:]) if pose.size == 6 else None
            jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
            quat, err_rot = np.zeros(4), np.zeros(3)
        step = np.zeros(m.nv)
        for _ in range(ASSEMBLY_MAX_ITERATIONS):
            mujoco.mj_fwdPosition(m, data)
            ne = data.ne  # the equality rows come first
            res = -data.efc_pos[:ne]
            jac = data.efc_J[:ne * m.nv].reshape(ne, m.nv)
            if pose is not None:
                site = self._site
                err = target_pos - data.site_xpos[site]
                mujoco.mj_jacSite(m, data, jacp, jacr, site)
                if target_rot is not None:
                    mujoco.mju_mat2Quat(quat, (target_rot @ data.site_xmat[site].reshape(3, 3).T).ravel())
                    mujoco.mju_quat2Vel(err_rot, quat, 1.0)
                    err, rows = np.concatenate([err, err_rot]), np.concatenate([jacp, jacr])
                else:
                    rows = jacp
                if abs(err).max() < ASSEMBLY_POSE_TOLERANCE:
                    pose = None  # on the branch: the closures alone from here
                else:
                    res, jac = np.concatenate([res, err]), np.concatenate([jac, rows])
            if pose is None and (res.size == 0 or abs(res).max() < ASSEMBLY_TOLERANCE_M):
                data.qvel[:] = 0.0
                return True
            jac = jac[:, free]
            # Least squares; minimum norm where the closures leave freedom.
            # Cholesky by MuJoCo (small matrices: numpy's per-call overhead would dominate).
            wide = jac.shape[0] <= jac.shape[1]
            a = jac @ jac.T if wide else jac.T @ jac
            a.flat[::len(a) + 1] += ASSEMBLY_DAMPING * a.diagonal().max()
            mujoco.mju_cholFactor(a, 0.0)
            x = np.empty(len(a))
            mujoco.mju_cholSolve(x, a, res if wide else jac.T @ res)
            step[free] = jac.T @ x if wide else x
            mujoco.mj_integratePos(m, data.qpos, step, 1.0)
        mc.reset(data)
        return False

    def rest(self, data: mujoco.MjData) -> bool:
        """Move ``data`` (at rest, its controls set) to where the machine's forces balance:
        Newton on the accelerations ``qacc(qpos) = 0`` with zero velocity, the stiffness
        ``d qacc / d qpos`` by finite differences of ``mj_forward`` (reused while a step shrinks
        the accelerations tenfold; a pseudo-inverse for directions without stiffness, such as a
        rod's spin). MuJoCo's own forces (gravity, payload, servos, closures): the warm start
        for a loaded machine, which physics then settles.

        Returns:
            True when one step's velocity gain ``max |qacc| dt`` is below the settle velocity;
            otherwise ``data`` is put back where it was and False.
        """
        m = self.model
        nv, eps = m.nv, REST_FD_STEP
        data.qvel[:] = 0.0
        mujoco.mj_forward(m, data)
        start = data.qpos.copy()
        limit = self.settle_velocity / m.opt.timestep
        acc = data.qacc.copy()
        first = np.max(np.abs(acc))
        # Start from the previous pose's stiffness (poses differ little in it); fresh when stale.
        norm, inverse, fresh = first, self._rest_inverse, False
        stiffness, unit = np.empty((nv, nv)), np.zeros(nv)
        for _ in range(REST_MAX_ITERATIONS):
            if norm < limit:
                return True
            if inverse is None:
                here = data.qpos.copy()
                for i in range(nv):
                    unit[:] = 0.0
                    unit[i] = eps
                    data.qpos[:] = here
                    mujoco.mj_integratePos(m, data.qpos, unit, 1.0)
                    mujoco.mj_forward(m, data)
                    stiffness[:, i] = (data.qacc - acc) / eps
                data.qpos[:] = here
                inverse = self._rest_inverse = np.linalg.pinv(stiffness, rcond=REST_RCOND)
                fresh = True
            before = data.qpos.copy()
            mujoco.mj_integratePos(m, data.qpos, -inverse @ acc, 1.0)
            mujoco.mj_forward(m, data)
            previous = norm
            norm = np.max(np.abs(data.qacc))
            if not fresh and not norm < 0.1 * previous:  # a stale stiffness: undo, measure it here
                data.qpos[:] = before
                mujoco.mj_forward(m, data)
                norm, inverse = previous, None
                continue
            acc = data.qacc.copy()
            if not np.isfinite(norm) or norm > 1e3 * first:
                break
            if norm > 0.1 * previous:
                inverse = None
            fresh = False
        if norm < limit:
            return True
        data.qpos[:] = start
        mujoco.mj_forward(m, data)
        return False

    def _settle_rollout(self, joints: np.ndarray, progress):
        """Every pose from its own warm start, stepped together by ``mujoco.rollout`` in batches
        of steps until at rest (see the class docstring)."""
        from mujoco import rollout as mj_rollout

        m, mc, v = self.model, self.machine, self.settle_velocity
        n, c = joints.shape
        if n == 0:
            return np.empty((0, self.robot.pose_dim)), np.empty((0, c)), np.empty(0), np.empty(0, dtype=int)
        ctrl = mc.ctrl(self.servo_reference(joints, 0.0))
        full = mujoco.mjtState.mjSTATE_FULLPHYSICS
        nstate = mujoco.mj_stateSize(m, full)
        q0 = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_TIME)
        v0 = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_TIME | mujoco.mjtState.mjSTATE_QPOS)
        scratch = mujoco.MjData(m)
        start = np.empty((n, nstate))
        # The platform's pose at the actuated joints' unloaded values picks each pose's branch.
        at = ctrl / self._actuated_gear / mc.joint_scale + mc.joint_offset
        try:
            poses = self.robot.forward_kinematics(mc.theta, at)
        except (ValueError, ArithmeticError):  # no solution found: the closures alone
            poses = [None] * n
        for k in range(n):
            self.assemble(scratch, joints[k], poses[k])
            scratch.ctrl[:] = ctrl[k]
            self.rest(scratch)
            mujoco.mj_getState(m, scratch, start[k], full)
        true = np.empty((n, self.robot.pose_dim))
        read = np.empty((n, c))
        steps = np.zeros(n, dtype=int)
        last = np.empty(nstate)
        pending = np.arange(n)
        done, batch = 0, FIRST_BATCH_STEPS
        with mj_rollout.Rollout(nthread=self.threads if self.threads > 1 else 0) as pool:
            workers = [mujoco.MjData(m) for _ in range(max(1, self.threads))]
            while pending.size:
                nstep = min(batch, self.max_steps - done)
                if nstep <= 0:
                    k = pending[0]
                    raise SettleError(
                        f"the machine did not settle within {self.max_steps} steps "
                        f"({self.max_steps * m.opt.timestep:g} s) for commanded joints "
                        f"{np.array2string(joints[k], precision=4)} {self.robot.joint_unit}: max joint speed "
                        f"{np.max(np.abs(start[0, v0:v0 + m.nv])):.3g} > {v:g}")
                state, sensors = pool.rollout(m, workers, start, ctrl[pending][:, None, :], nstep=nstep)
                rest = np.max(np.abs(state[:, :, v0:v0 + m.nv]), axis=2) < v
                rest[:, :max(0, MIN_SETTLE_STEPS - 1 - done)] = False  # step j is step done + j + 1
                settled = rest.any(axis=1)
                first = rest.argmax(axis=1)
                for i in np.flatnonzero(settled):
                    k, j = pending[i], first[i]
                    steps[k] = done + j + 1
                    scratch.sensordata[:] = sensors[i, j]
                    true[k] = mc.read_pose(scratch)
                    scratch.qpos[:] = state[i, j, q0:v0]
                    read[k] = mc.read_joints(scratch)
                    if k == n - 1:
                        last[:] = state[i, j]
                start, pending = state[~settled, -1], pending[~settled]
                done += nstep
                batch = min(2 * batch, MAX_BATCH_STEPS)
                if progress is not None:
                    progress(n - pending.size, n)
        t = self.data.time + np.cumsum(steps) * m.opt.timestep
        # The machine is left where the last pose settled, as after the sequential settle.
        mujoco.mj_setState(m, self.data, last, full)
        self.data.time = t[-1]
        self.data.ctrl[:] = ctrl[-1]
        mujoco.mj_forward(m, self.data)
        move = np.sign(ctrl[-1] - self._last_ctrl)
        self._direction = np.where(move != 0, move, self._direction)
        self._last_ctrl = ctrl[-1].copy()
        return true, read, t, steps
