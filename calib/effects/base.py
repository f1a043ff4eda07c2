"""What every physical effect declares, and the measurements it is evaluated on.

An effect is physics the geometric model leaves out. It acts on the actuated joints: chain i's
joint sits at ``q_ij + dq_ij`` where the controller commanded ``q_ij``, with

    dq_ij = sum_k Xq_ijk phi_k           (robot's joint unit)

``Xq`` the effect's *joint regressors* (derived from physics) and ``phi`` its unknown
coefficients. The discovery (:mod:`calib.effects.discovery`) fits ``phi`` jointly with the
geometry so that the closure ``F(theta, q + Xq phi, pose)`` vanishes at the measured poses. To
first order this adds to the closure residual at the commanded joints the effect's
*regressors* ``X = -dF/dq Xq`` (mm per unit coefficient, :meth:`Effect.regressors`), which
size an effect's contribution in mm for every robot alike.

Each effect also says how the MuJoCo machine produces it, as plain data (this package imports no
simulator): :meth:`Effect.machine_settings` returns ``{"options": {...}, "effects": {...}}``
with the field names of ``mjcf.machine.MachineOptions`` (SI) and ``mjcf.machine.MachineEffects``
(joint units). The SI numbers it needs (gravity, metres per mm, the machine's servo stiffness
and masses) come in a :class:`MachineContext` from the pipeline, which owns the MuJoCo side.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from ..validation import as_array
from ..noise import SensorNoise
from ..robot import Robot
from .separability import GRAM_MIN_RESIDUALS

__all__ = ["FOLLOWED_QUANTITIES", "PAYLOAD_CHANNEL", "SPREAD_RANGE", "orthonormal_columns", "GRAM_BASIS_RTOL",
           "Coefficient", "SearchedParameter", "PhysicalParameter", "MachineContext", "EffectScenario",
           "EffectData", "Effect", "motion_history", "closure_regressors", "scale_to_magnitude", "unabsorbed"]

#: The quantities a remainder is tested against (:func:`calib.effects.remainder.remainder_tests`):
#: time, the direction and size of each joint's last move, each joint's stroke from the centre
#: of travel, the load each chain carries (statics of the platform's weight), and the position in
#: the workspace (``"position <coordinate>"``).
FOLLOWED_QUANTITIES = ("time", "direction of the last move", "size of the last move", "stroke", "load", "position")
#: The recorded channel of the payload carried at each row, kg (a recording's ``extras``; read into
#: :attr:`EffectData.payload_kg`).
PAYLOAD_CHANNEL = "payload_kg"
#: A per-chain scenario (:meth:`Effect.per_chain_draw`) draws each chain's coefficient as this
#: fraction of the largest (real joints differ, none by orders of magnitude).
SPREAD_RANGE = (0.3, 1.0)


@dataclass(frozen=True)
class Coefficient:
    """One coefficient of an effect: name and unit (e.g. ``("dead_band", "mm")``)."""

    name: str
    unit: str


@dataclass(frozen=True)
class SearchedParameter:
    """A nonlinear parameter of an effect found by a one-dimensional search (e.g. a screw pitch).

    The search runs over the *search coordinate* ``u`` (e.g. the frequency ``1 / pitch``): a
    grid from :meth:`Effect.search_grid`, refined by golden section between the best grid
    point's neighbours; :meth:`Effect.searched_value` turns ``u`` into the parameter.

    Attributes:
        name: e.g. ``"pitch"``.
        unit: e.g. ``"mm"``.
    """

    name: str
    unit: str


@dataclass(frozen=True)
class PhysicalParameter:
    """The MuJoCo machine's parameter that carries an effect (re-fitted by ``mujoco.sysid``).

    Attributes:
        section: ``"options"`` (a ``MachineOptions`` field) or ``"effects"`` (``MachineEffects``).
        field: the field name, e.g. ``"joint_friction"``.
        unit: its unit, e.g. ``"N"``.
    """

    section: str
    field: str
    unit: str


@dataclass(frozen=True)
class MachineContext:
    """Numbers of the simulated machine that turn fitted coefficients into MuJoCo physics.

    Given by the pipeline (which owns the MuJoCo side), so that every constant is named once
    there: ``gravity_m_s2`` is ``mjcf.machine.GRAVITY_M_S2``, ``m_per_mm`` is
    ``mjcf.units.M_PER_MM``.

    Attributes:
        moving_mass_kg: platform plus payload, kg (the load of compliance).
        platform_mass_kg: the platform alone, kg (payload = moving - platform).
        payload_height_m: height of a payload's centre of mass over the platform frame, m.
        gravity_m_s2: standard gravity, m/s^2.
        m_per_mm: metres per millimetre.
        servo_stiffness: stiffness of the actuators' position servos, SI (N/m for a prismatic
            joint, N m/rad for a revolute one): one number, or a (C,) tuple, one per chain; it
            turns a dead band into a friction force.
        chain_point_masses_kg: each chain's own mass lumped at its points after the base joint
            (those of ``Robot.chain_points``; the last at the platform joint), kg; empty when
            the machine does not say (the chains' weight is then left out).
    """

    moving_mass_kg: float
    platform_mass_kg: float
    payload_height_m: float
    gravity_m_s2: float
    m_per_mm: float
    servo_stiffness: float | tuple
    chain_point_masses_kg: tuple = ()

    def si_per_joint_unit(self, robot: Robot) -> float:
        """SI units (m or rad) per joint unit of ``robot`` (mm or rad)."""
        return self.m_per_mm if robot.joint_unit == "mm" else 1.0

    def with_payload(self, payload_kg: float) -> "MachineContext":
        """The same machine carrying ``payload_kg`` on its platform."""
        return replace(self, moving_mass_kg=self.platform_mass_kg + float(payload_kg))

    @property
    def payload_kg(self) -> float:
        return max(self.moving_mass_kg - self.platform_mass_kg, 0.0)


@dataclass(frozen=True, eq=False)
class EffectScenario:
    """A drawn instance of an effect for a simulated recording (:meth:`Effect.scenario`).

    Attributes:
        coefficients: (p,) the true coefficients.
        extra: the searched parameter's true value, or None.
        context: the machine carrying it (e.g. with a drawn payload).
    """

    coefficients: np.ndarray
    extra: float | None
    context: MachineContext


def motion_history(start: np.ndarray, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(direction, last_move)`` of a command sequence: each joint's direction of motion (+1
    increasing, -1 decreasing; a command unchanged keeps the last direction, 0 before the first
    move) and its signed change in the move that ended at each row.

    Args:
        start: (C,) the joints before the first row (the machine's home), joint unit.
        joints: (N, C) the commands in the order taken, joint unit.

    Returns:
        (N, C) direction and (N, C) last move, joint unit.
    """
    q = np.asarray(joints, dtype=float)
    last_move = q - np.vstack([np.asarray(start, dtype=float)[None], q[:-1]])
    step = np.sign(last_move)
    rows = np.arange(q.shape[0])[:, None]
    moved = np.maximum.accumulate(np.where(step != 0, rows, -1), axis=0)  # the last row each joint moved
    direction = np.where(moved >= 0, np.take_along_axis(step, np.maximum(moved, 0), axis=0), 0.0)
    return direction, last_move


@dataclass(frozen=True, eq=False)
class EffectData:
    """The measurements an effect analysis works on.

    Attributes:
        robot: the robot measured (its nominal geometry).
        theta: (P,) parameter vector the fits start from (usually the nominal one).
        joints: (N, C) commanded joint values, joint unit, in the order taken.
        measured: (N, D) measured poses, the robot's pose units.
        t_s: (N,) time of each measurement, s.
        noise: declared sensor noise (pose, and joint readings).
        direction: (N, C) direction (+1 increasing, -1 decreasing) in which each joint last
            moved before measurement j; default from the commands, the machine starting at its
            home pose (``robot.home_pose`` reached with ``theta``).
        last_move: (N, C) signed change of each commanded joint in the move that ended at
            measurement j, joint unit (0 for a joint that did not move); default from the
            commands, from the same start.
        payload_kg: (N,) the payload the platform carried at each measurement, kg (a recording's
            :data:`PAYLOAD_CHANNEL`), or None when the recording does not say (one payload
            throughout). Where it varies, compliance is fitted with its payload terms
            (:func:`calib.effects.compliance.payload_varies`).
        tolerance: (P,) each parameter's manufacturing tolerance (the standard deviation of its
            prior about ``theta``, its unit: :class:`calib.prior.ParameterPrior`'s ``std``), or
            None (no prior: the fits take the geometry the rows determine, as plain least
            squares). With it, the combinations of the free parameters the rows leave to the
            prior are held at ``theta`` (:mod:`calib.effects.separability`).
        model_poses: (N, D) the poses a fitted model reaches at the commands (the measured poses
            less their noise), where the effects' regressors and the quantities read from a pose
            are taken (:attr:`regressor_poses`); None: the measured poses. The discovery sets it
            where the rows leave combinations to the prior (a level grid), whose regressors at
            the measured poses are built of the noise (:mod:`calib.effects.discovery`).
        sessions: (N,) int, each row's session (0, 1, ... in the order of the sessions' first
            rows), or None: one session (what a shift between sessions reads,
            :mod:`calib.effects.session_zeros`).
    """

    robot: Robot
    theta: np.ndarray
    joints: np.ndarray
    measured: np.ndarray
    t_s: np.ndarray
    noise: SensorNoise
    direction: np.ndarray = field(default=None)
    last_move: np.ndarray = field(default=None)
    payload_kg: np.ndarray | None = field(default=None)
    tolerance: np.ndarray | None = field(default=None)
    model_poses: np.ndarray | None = field(default=None)
    sessions: np.ndarray | None = field(default=None)

    def __post_init__(self) -> None:
        r = self.robot
        if not isinstance(r, Robot):
            raise TypeError(f"robot must be a calib.robot.Robot, got {type(r).__name__}")
        if not isinstance(self.noise, SensorNoise):
            raise TypeError(f"noise must be a SensorNoise, got {type(self.noise).__name__}")
        theta = as_array(self.theta, "theta", (r.n_parameters,))
        q = as_array(self.joints, "joints", (-1, r.n_chains))
        m = as_array(self.measured, "measured", (-1, r.pose_dim))
        t = as_array(self.t_s, "t_s", (-1,))
        if not (q.shape[0] == m.shape[0] == t.shape[0]):
            raise ValueError(f"joints, measured and t_s must have the same length, got "
                             f"{q.shape[0]}, {m.shape[0]} and {t.shape[0]}")
        for name, value in (("theta", theta), ("joints", q), ("measured", m), ("t_s", t)):
            object.__setattr__(self, name, value)
        if self.payload_kg is not None:
            p = as_array(self.payload_kg, "payload_kg", (q.shape[0],))
            if not np.all(np.isfinite(p)) or np.any(p < 0):
                raise ValueError("payload_kg must be finite and >= 0 at every row")
            object.__setattr__(self, "payload_kg", p)
        if self.tolerance is not None:
            tol = as_array(self.tolerance, "tolerance", (r.n_parameters,))
            if not np.all(np.isfinite(tol) & (tol > 0)):
                raise ValueError("tolerance must be finite and > 0 for every parameter")
            object.__setattr__(self, "tolerance", tol)
        if self.model_poses is not None:
            object.__setattr__(self, "model_poses", as_array(self.model_poses, "model_poses", m.shape))
        if self.sessions is not None:
            sessions = np.asarray(self.sessions)
            if sessions.shape != (q.shape[0],) or not np.issubdtype(sessions.dtype, np.integer) or np.any(sessions < 0):
                raise ValueError(f"sessions must be ({q.shape[0]},) non-negative integers")
            object.__setattr__(self, "sessions", sessions)
        if self.direction is None or self.last_move is None:
            direction, last_move = motion_history(r.inverse_kinematics(theta, r.home_pose[None])[0], q)
        if self.last_move is None:
            object.__setattr__(self, "last_move", last_move)
        else:
            object.__setattr__(self, "last_move", as_array(self.last_move, "last_move", q.shape))
        if self.direction is None:
            object.__setattr__(self, "direction", direction)
        else:
            object.__setattr__(self, "direction", as_array(self.direction, "direction", q.shape))

    @property
    def n(self) -> int:
        """Number of measurements."""
        return self.joints.shape[0]

    @property
    def travel_centre(self) -> np.ndarray:
        """(C,) the centre of each actuator's travel (midpoint of its joint limits), joint unit."""
        return self.robot.joint_limits().mean(axis=1)

    @property
    def regressor_poses(self) -> np.ndarray:
        """(N, D) the poses effects' regressors are taken at: :attr:`model_poses`, else the
        measured ones."""
        return self.measured if self.model_poses is None else self.model_poses

    @property
    def stroke(self) -> np.ndarray:
        """(N, C) commanded joint values from the centre of travel, joint unit."""
        return self.joints - self.travel_centre

    def subset(self, rows: np.ndarray) -> "EffectData":
        """The same analysis restricted to ``rows`` (the motion history is kept)."""
        return EffectData(self.robot, self.theta, self.joints[rows], self.measured[rows], self.t_s[rows],
                          self.noise, self.direction[rows], self.last_move[rows],
                          None if self.payload_kg is None else self.payload_kg[rows], self.tolerance,
                          None if self.model_poses is None else self.model_poses[rows],
                          None if self.sessions is None else self.sessions[rows])

    def with_measured(self, measured: np.ndarray) -> "EffectData":
        """The same commands with other measured poses."""
        return EffectData(self.robot, self.theta, self.joints, measured, self.t_s, self.noise, self.direction,
                          self.last_move, self.payload_kg, self.tolerance, sessions=self.sessions)

    def with_robot(self, robot: Robot, theta: np.ndarray | None = None) -> "EffectData":
        """The same measurements read with another nominal robot (motion history kept; no prior:
        a tolerance belongs to the robot it was declared for)."""
        return EffectData(robot, robot.table.nominal if theta is None else theta, self.joints, self.measured,
                          self.t_s, self.noise, self.direction, self.last_move, self.payload_kg, sessions=self.sessions)


def closure_regressors(dF_dq: np.ndarray, joint_regressors: np.ndarray) -> np.ndarray:
    """(N, C, p) closure residual per unit coefficient, mm: ``-dF/dq Xq`` (first order).

    Args:
        dF_dq: (N, C, C) closure Jacobian with respect to the joints, mm per joint unit.
        joint_regressors: (N, C, p) joint displacement per unit coefficient, joint unit.
    """
    return -dF_dq @ joint_regressors


def unabsorbed(robot: Robot, theta: np.ndarray, data: "EffectData", X: np.ndarray) -> np.ndarray:
    """(N, C, p) the part of regressors ``X`` that the robot's free geometric parameters cannot
    absorb: ``X`` with the closure's parameter columns ``dF/dtheta`` projected out (least squares
    over every measurement and chain at once)."""
    G = robot.closure_jacobians(theta, data.joints, data.measured).parameters[:, :, robot.table.indices(robot.free_default)]
    G = G.reshape(-1, G.shape[-1])
    U, s, _ = np.linalg.svd(G, full_matrices=False)
    U = U[:, s > s[0] * 1e-10]
    x = X.reshape(-1, X.shape[-1])
    return (x - U @ (U.T @ x)).reshape(X.shape)


def scale_to_magnitude(X: np.ndarray, coefficients: np.ndarray, magnitude_mm: float) -> np.ndarray:
    """``coefficients`` rescaled so that the largest closure contribution ``|X phi|`` is
    ``magnitude_mm``.

    Args:
        X: (N, C, p) regressors, mm per unit coefficient.
        coefficients: (p,) shape of the coefficients.
        magnitude_mm: the largest contribution wanted, mm.
    """
    c = np.asarray(coefficients, dtype=float)
    return c * (magnitude_mm / np.max(np.abs(X @ c)))


class Effect:
    """A physical effect the geometric model leaves out (one subclass per module).

    Class attributes:
        name: registry key, e.g. ``"joint_friction"``.
        physics: the physics in one sentence (for help texts and reports).
        searched: the nonlinear parameter found by search, or None.
        history_dependent: whether the machine's state depends on the motion history (the
            MuJoCo re-simulation must then replay every row in order).
        follows: the measurable quantity the effect's residuals follow, one of
            :data:`FOLLOWED_QUANTITIES` (what the remainder's structure tests should point at
            when the effect is left out of the candidates).
        refine_search: whether the searched parameter is refined by golden section between the
            best grid point's neighbours (False: the best grid point itself, for a fit that is
            constant between grid points, e.g. a step time between two measurements).
        generalises: names of the registered effects this one contains as a limiting case (nested
            models: ``thermal_warmup`` with a time constant much longer than the recording is
            ``thermal_drift``). Selection names the simpler one unless the general one earns a
            clear margin of evidence over it, never both; a recording analysed with an effect
            left out has its whole family left out (:func:`calib.effects.effect_family`).
        granularity: ``"shared"`` (one value of each coefficient for every chain) or
            ``"per_chain"`` (an effect whose coefficients already are one per chain, e.g. the
            actuator scale, or a per-chain form: :mod:`calib.effects.granularity`).
        per_chain_capable: names of the coefficients whose physics may differ from chain to
            chain (a dead band, a growth rate, a stiffness): the effect then has a per-chain
            form (:func:`calib.effects.granularity.per_chain_form`), and discovery chooses
            between the two by the evidence.
        per_chain_signed: whether a per-chain scenario may flip a chain's sign (physical for a
            phase, not for a dead band or a stiffness).
        not_compensable: why commands cannot compensate the effect (empty: they can): an effect
            of the instrument, not of the machine, or a one-off event of the recording.
    """

    name: ClassVar[str]
    physics: ClassVar[str]
    searched: ClassVar[SearchedParameter | None] = None
    history_dependent: ClassVar[bool] = False
    follows: ClassVar[str] = ""
    refine_search: ClassVar[bool] = True
    generalises: ClassVar[tuple[str, ...]] = ()
    granularity: ClassVar[str] = "shared"
    per_chain_capable: ClassVar[tuple[str, ...]] = ()
    per_chain_signed: ClassVar[bool] = False
    not_compensable: ClassVar[str] = ""

    def compensation_inputs(self) -> tuple[str, ...]:
        """What compensating the effect needs beside the commands: ``"t_s"`` (the times of the
        targets, for an effect that follows time) and the names of recorded channels (a law's
        temperature), in that order."""
        return ("t_s",) if self.follows == "time" else ()

    def applies_to(self, robot: Robot) -> bool:
        """Whether the effect makes physical sense on ``robot`` (subclasses say why not)."""
        return True

    def coefficients(self, robot: Robot) -> tuple[Coefficient, ...]:
        """Names and units of the coefficients on ``robot``."""
        raise NotImplementedError

    def joint_regressors(self, robot: Robot, theta: np.ndarray, data: EffectData,
                         extra: float | None = None) -> np.ndarray:
        """(N, C, p) joint displacement per unit coefficient, joint unit (see the module docstring).

        Args:
            robot: the robot.
            theta: (P,) current parameter estimate.
            data: the measurements.
            extra: the searched parameter's value (effects with :attr:`searched`).
        """
        raise NotImplementedError

    def regressors(self, robot: Robot, theta: np.ndarray, data: EffectData,
                   extra: float | None = None) -> np.ndarray:
        """(N, C, p) closure residual per unit coefficient, mm: ``-dF/dq Xq`` at the regressor
        poses (:attr:`EffectData.regressor_poses`) and commanded joints."""
        Xq = self.joint_regressors(robot, theta, data, extra)
        if Xq.shape[-1] == 0:
            return Xq
        return closure_regressors(robot.closure_jacobians(theta, data.joints, data.regressor_poses).joints, Xq)

    def search_grid(self, data: EffectData) -> np.ndarray:
        """(K,) grid of the search coordinate (effects with :attr:`searched`; a sequence of
        values for a search that is not refined, :attr:`refine_search`)."""
        raise NotImplementedError

    def searched_value(self, u: float) -> float:
        """The searched parameter at search coordinate ``u``."""
        raise NotImplementedError

    def searched_values(self, extra) -> dict:
        """``{name: (value, unit)}``: the searched parameter ``extra`` as reported (one entry,
        :attr:`searched`, unless the effect's searched parameter holds several numbers)."""
        return {self.searched.name: (float(extra), self.searched.unit)}

    def machine_settings(self, coefficients: np.ndarray, robot: Robot, context: MachineContext,
                         extra: float | None = None) -> dict:
        """How the MuJoCo machine produces the effect with these coefficients.

        Returns:
            ``{"options": {MachineOptions field: value (SI)}, "effects": {MachineEffects
            field: value (joint units)}}``, plain numbers and tuples.
        """
        raise NotImplementedError

    def physical_parameter(self, robot: Robot) -> PhysicalParameter | None:
        """The machine parameter that carries the effect, for a re-fit in MuJoCo; None when the
        fitted coefficients already are the machine's parameters."""
        return None

    def scenario(self, robot: Robot, theta: np.ndarray, data: EffectData, magnitude_mm: float,
                 rng: np.random.Generator, context: MachineContext) -> EffectScenario:
        """Draw a true instance whose largest closure contribution over ``data`` (the planned
        commands, at the target poses, with estimated times) is ``magnitude_mm``.

        Args:
            robot: the robot; theta: (P,) the machine's true parameters.
            data: the planned measurements.
            magnitude_mm: largest contribution, mm.
            rng: the scenario's random generator (draws made here are part of the scenario).
            context: the machine before the effect.
        """
        raise NotImplementedError

    def per_chain_draw(self, robot: Robot, shared: np.ndarray, capable: np.ndarray,
                       rng: np.random.Generator) -> np.ndarray:
        """(C, k) each chain's values of the ``k`` capable coefficients (mask ``capable`` over
        the shared draw ``shared`` (p,)) for a per-chain scenario: chain i's values are the
        shared ones times ``u_i`` in :data:`SPREAD_RANGE` (the same factor for every capable
        coefficient: one joint's own stiffness or friction), with a random sign when
        :attr:`per_chain_signed`."""
        c = robot.n_chains
        u = rng.uniform(*SPREAD_RANGE, c)
        if self.per_chain_signed:
            u = u * rng.choice([-1.0, 1.0], c)
        return u[:, None] * np.asarray(shared, dtype=float)[capable][None, :]

    def __repr__(self) -> str:
        return f"<effect {self.name!r}>"


#: Smallest singular value, relative to the largest, that the Gram form of
#: :func:`orthonormal_columns` keeps: its eigenvalues are the squared singular values to about
#: ``k eps`` of the largest, so that a singular value is resolved down to some ``sqrt(k eps)``,
#: 1e-7 of the largest (k columns, eps the float64 epsilon); the SVD's ``rtol`` (1e-9) lies below that.
GRAM_BASIS_RTOL = 1e-6


def orthonormal_columns(A: np.ndarray, rtol: float = 1e-9) -> np.ndarray:
    """Orthonormal basis of the column space of ``A`` (columns scaled to unit norm first; rank
    decided at ``rtol`` of the largest singular value).

    Above :data:`calib.effects.separability.GRAM_MIN_RESIDUALS` rows (the discovery's threshold:
    at 100,000 hexapod rows an SVD of the 600,000 x 48 whitened design takes about 1.5 s, this a
    few matrix products) from the scaled Gram matrix: its eigenvectors ``V`` and
    eigenvalues ``lam`` (those above ``max(rtol, GRAM_BASIS_RTOL)**2`` of the largest) give
    ``Q1 = A V lam^-1/2``, the SVD's left vectors to rounding amplified by the squared condition
    number; one more pass of the same on ``Q1`` (whose Gram matrix is the identity to about
    ``eps cond^2``) makes the columns orthonormal to rounding (Cholesky QR2's argument, with
    eigendecompositions). The same span; another basis of it than the SVD's."""
    if A.shape[1] == 0:
        return A
    scale = np.linalg.norm(A, axis=0)
    keep = scale > 0
    if not keep.any():
        return A[:, :0]
    if A.shape[0] > GRAM_MIN_RESIDUALS:
        # The scaling applied to the small matrices; one tall array written (twice, in place).
        Ak = A if keep.all() else A[:, keep]
        d = 1.0 / scale[keep]
        lam, V = np.linalg.eigh((Ak.T @ Ak) * np.outer(d, d))
        good = lam > max(rtol, GRAM_BASIS_RTOL) ** 2 * lam.max()
        W = d[:, None] * (V[:, good][:, ::-1] / np.sqrt(lam[good][::-1]))
        Q = Ak @ W
        lam2, V2 = np.linalg.eigh(Q.T @ Q)
        return np.matmul(Ak, W @ (V2 @ (V2.T / np.sqrt(lam2)[:, None])), out=Q)
    As = A[:, keep] / scale[keep]
    U, s, _ = np.linalg.svd(As, full_matrices=False)
    return U[:, s > rtol * s[0]]
