"""A compiled machine in motion: commanded, settled and read (MuJoCo data never leaves here).

:class:`MachineSimulator` holds a :class:`mjcf.machine.Machine`'s ``MjData`` and does what a
testbed asks of the physics: send the servos their references (robot joint units, converted at
the machine's unit boundary), apply the actuated joints' Coulomb friction in its quasi-static
limit, step until at rest, and read the platform pose and the joints back. Poses without history
settle together in ``mujoco.rollout`` from warm starts (:meth:`MachineSimulator.settle_many`):
the closures assembled by Gauss-Newton (:meth:`~MachineSimulator.assemble`), a loaded machine
brought to rest by Newton on MuJoCo's accelerations (:meth:`~MachineSimulator.rest`), then
stepped on every core until each is at rest by the same test as the one-after-another settle.
"""

from __future__ import annotations

import mujoco
import numpy as np

from calib.rotation import rotation_matrix

from .machine import PLATFORM_SITE, Machine
from .units import mm_to_m

__all__ = ["MachineSimulator", "WarmStart", "SettleError", "MIN_SETTLE_STEPS"]

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


class MachineSimulator:
    """The machine ``machine`` simulated from its home keyframe (see the module docstring).

    Args:
        machine: the compiled machine (:func:`mjcf.build_machine`).
        settle_velocity: at rest when every joint speed is below this, m/s or rad/s.
        max_steps: step cap per pose; beyond it :class:`SettleError` is raised.
        threads: threads of the rollout (1: no thread pool).

    Attributes:
        home_joints: (C,) joint values at the home keyframe, robot joint unit.
        warm: the :class:`WarmStart` of the rollout.
    """

    def __init__(self, machine: Machine, *, settle_velocity: float, max_steps: int, threads: int):
        self.machine, self.robot, self.model = machine, machine.robot, machine.model
        self.settle_velocity, self.max_steps, self.threads = float(settle_velocity), int(max_steps), int(threads)
        self.data = mujoco.MjData(self.model)
        machine.reset(self.data)
        self.home_joints = machine.read_joints(self.data)
        self._last_ctrl = self.data.ctrl.copy()
        self._direction = np.zeros(self.robot.n_chains)
        self.warm = WarmStart(machine, settle_velocity=self.settle_velocity)

    @property
    def time(self) -> float:
        """Simulated time, s."""
        return float(self.data.time)

    def read_joints(self) -> np.ndarray:
        """(C,) where the actuated joints are now, robot joint unit."""
        return self.machine.read_joints(self.data)

    def read_pose(self) -> np.ndarray:
        """(D,) the platform pose from the sensors now, mm and rad."""
        return self.machine.read_pose(self.data)

    def _settle_error(self, joints, speed: float) -> SettleError:
        return SettleError(
            f"the machine did not settle within {self.max_steps} steps "
            f"({self.max_steps * self.model.opt.timestep:g} s) for commanded joints "
            f"{np.array2string(np.asarray(joints), precision=4)} {self.robot.joint_unit}: max joint speed "
            f"{speed:.3g} > {self.settle_velocity:g}")

    def settle(self, reference: np.ndarray, friction=0.0, commanded=None) -> tuple[np.ndarray, int]:
        """Send the servos ``reference`` ((C,), robot joint unit) and step until at rest, from
        where the machine is. Coulomb ``friction`` (N or N m) opposes each chain's last motion (a
        joint force on the actuated dof): a chain approached monotonically comes to rest short of
        its reference by friction / stiffness, a dead band whose sign is the direction it last moved.

        Args:
            reference: (C,) the servo references.
            friction: the actuated joints' Coulomb friction: one number, or (C,) one per joint.
            commanded: (C,) the commanded joints, for the message of a :class:`SettleError`
                (default ``reference``).

        Returns:
            ``(pose, steps)``: (D,) settled true pose (mm, rad) and steps taken.

        Raises:
            SettleError: not at rest after ``max_steps`` steps.
        """
        m, d, mc = self.model, self.data, self.machine
        d.ctrl[:] = mc.ctrl(reference)
        move = np.sign(d.ctrl - self._last_ctrl)
        self._direction = np.where(move != 0, move, self._direction)
        self._last_ctrl = d.ctrl.copy()
        d.qfrc_applied[mc.dof_index] = -friction * self._direction
        qvel, v = d.qvel, self.settle_velocity
        # max |qvel| < v needs qvel . qvel < nv v^2: the cheap test rules out most steps.
        bound = qvel.size * v * v
        for step in range(1, self.max_steps + 1):
            mujoco.mj_step(m, d)
            if step > 5 and qvel @ qvel < bound and np.max(np.abs(qvel)) < v:
                return mc.read_pose(d), step
        raise self._settle_error(reference if commanded is None else commanded, np.max(np.abs(d.qvel)))

    def settle_many(self, references: np.ndarray, progress=None, commanded=None):
        """Every pose from its own warm start, stepped together by ``mujoco.rollout`` in batches
        of steps (8, 16, 32, ... up to :data:`MAX_BATCH_STEPS`) until each is at rest (at least
        :data:`MIN_SETTLE_STEPS` steps, every joint speed below the settle velocity); physics without
        history (no friction) is assumed. The machine is left where the last pose settled.

        Args:
            references: (N, C) servo references, robot joint unit.
            progress: optional ``progress(done, total)``.
            commanded: (N, C) the commanded joints, for the message of a :class:`SettleError`
                (default ``references``).

        Returns:
            ``(true (N, D), joints (N, C), t (N,), steps (N,))``: settled poses (mm, rad), where the
            joints settled, the time each pose is reached settling one after another, steps.

        Raises:
            SettleError: a pose not at rest after ``max_steps`` steps.
        """
        from mujoco import rollout as mj_rollout

        m, mc, v = self.model, self.machine, self.settle_velocity
        references = np.asarray(references, dtype=float)
        joints = references if commanded is None else np.asarray(commanded, dtype=float)
        n, c = references.shape
        if n == 0:
            return np.empty((0, self.robot.pose_dim)), np.empty((0, c)), np.empty(0), np.empty(0, dtype=int)
        ctrl = mc.ctrl(references)
        full = mujoco.mjtState.mjSTATE_FULLPHYSICS
        nstate = mujoco.mj_stateSize(m, full)
        q0 = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_TIME)
        v0 = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_TIME | mujoco.mjtState.mjSTATE_QPOS)
        scratch = mujoco.MjData(m)
        start = self.warm_starts(references, scratch)
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
                    raise self._settle_error(joints[pending[0]], np.max(np.abs(start[0, v0:v0 + m.nv])))
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
        self._leave_at(last, t[-1], ctrl[-1])
        return true, read, t, steps

    def warm_starts(self, references: np.ndarray, scratch: mujoco.MjData) -> np.ndarray:
        """(N, S) full physics states, each pose's warm start: assembled at its servo references
        on the branch the forward kinematics picks (the platform's pose at the actuated joints'
        unloaded values), then brought to rest under load (:meth:`WarmStart.assemble`, :meth:`WarmStart.rest`)."""
        m, mc = self.model, self.machine
        full = mujoco.mjtState.mjSTATE_FULLPHYSICS
        ctrl = mc.ctrl(references)
        start = np.empty((len(references), mujoco.mj_stateSize(m, full)))
        at = ctrl / self.warm.actuated_gear / mc.joint_scale + mc.joint_offset
        try:
            poses = self.robot.forward_kinematics(mc.theta, at)
        except (ValueError, ArithmeticError):  # no solution found: the closures alone
            poses = [None] * len(references)
        for k in range(len(references)):
            self.warm.assemble(scratch, references[k], poses[k])
            scratch.ctrl[:] = ctrl[k]
            self.warm.rest(scratch)
            mujoco.mj_getState(m, scratch, start[k], full)
        return start

    def _leave_at(self, state: np.ndarray, time_s: float, ctrl: np.ndarray) -> None:
        """The machine left at ``state`` (where the last pose settled, as after the sequential
        settle), its controls ``ctrl``; the friction's direction follows the move there."""
        m = self.model
        mujoco.mj_setState(m, self.data, state, mujoco.mjtState.mjSTATE_FULLPHYSICS)
        self.data.time = time_s
        self.data.ctrl[:] = ctrl
        mujoco.mj_forward(m, self.data)
        move = np.sign(ctrl - self._last_ctrl)
        self._direction = np.where(move != 0, move, self._direction)
        self._last_ctrl = ctrl.copy()


class WarmStart:
    """Where a pose of the rollout starts: the machine assembled at its servo references
    (:meth:`assemble`) and, loaded, brought to where its forces balance (:meth:`rest`); physics
    then settles it. The stiffness of the last :meth:`rest` is reused while it still converges.

    Attributes:
        available: whether the assembly applies to this machine (every actuator on a joint, a
            non-zero gear, a dense constraint Jacobian); without it a pose starts from home.
        actuated_gear: (C,) the actuators' gears.
    """

    def __init__(self, machine: Machine, *, settle_velocity: float):
        self.machine, self.model, self.settle_velocity = machine, machine.model, settle_velocity
        m = self.model
        self.available = not (np.any(m.actuator_trntype != int(mujoco.mjtTrn.mjTRN_JOINT)) or mujoco.mj_isSparse(m)
                              or np.any(m.actuator_gear[:, 0] == 0))
        #: dofs the assembly solves (all but the actuated ones); None when unavailable.
        self._free_dofs = np.setdiff1d(np.arange(m.nv), m.jnt_dofadr[m.actuator_trnid[:, 0]]) \
            if self.available else None
        self._actuated_qpos = m.jnt_qposadr[m.actuator_trnid[:, 0]]
        self.actuated_gear = m.actuator_gear[:, 0].copy()
        self._site = m.site(PLATFORM_SITE).id
        self._rest_inverse = None

    def assemble(self, data: mujoco.MjData, reference: np.ndarray, pose: np.ndarray | None = None) -> bool:
        """Put ``data`` at rest in the machine assembled at servo ``reference`` ((C,), robot unit):
        each actuated joint where its servo reference holds it unloaded, the other joints solved by
        Gauss-Newton on the closures (the equality constraints), from the home keyframe. Kinematics
        only: the warm start of the rollout, which physics then settles.

        Args:
            data: the machine's data, overwritten.
            reference: (C,) the servo references.
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
        ctrl = mc.ctrl(np.asarray(reference, dtype=float))
        data.qpos[self._actuated_qpos] = ctrl / self.actuated_gear
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
