"""The robot description interface: what the calibration engine needs to know of a parallel robot.

A robot is described by a :class:`Robot` object (the *model*: its nominal geometry, its named
parameter table, its kinematics) and a flat parameter vector ``theta`` (the *data*: the values
of every geometric parameter of one particular machine, nominal or identified), in the spirit of
Pinocchio's ``Model`` / ``Data`` split. The engine (:mod:`calib.identification`,
:mod:`calib.observability`, :mod:`calib.design`, :mod:`calib.effects`) only ever calls the
methods below; it never asks which robot it has.

Every robot of this package is a closed-chain mechanism with one actuated joint per chain and as
many chains as its platform has degrees of freedom. Chain ``i`` closes through one scalar
equation ``closure_i(theta, joints, pose) = 0`` (mm) that involves only chain ``i``'s joint and
parameters, e.g. a leg length ``|R P_i + t - B_i| - dl_i - l_i`` for the hexapod. The joint-space
("chain-wise") identification works on these residuals, the forward one on poses through the
forward kinematics; both use the closure's analytic Jacobians (implicit function theorem).

Units: mm and rad everywhere. Poses are ``(N, pose_dim)`` float64 in the robot's pose coordinates
(:attr:`Robot.pose_names`), joints ``(N, n_chains)`` in :attr:`Robot.joint_unit`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar, Iterator, Sequence

import numpy as np

from .batched_lu import BatchedLU, inverse_stacked, solve_stacked
from .noise import SensorNoise
from .validation import as_array, frozen_array

__all__ = ["KinematicsError", "Parameter", "ParameterTable", "ClosureJacobians", "Robot",
           "newton_forward_kinematics", "pose_jacobian_of_joints", "pose_jacobian_of_parameters",
           "solve_closure_parameters",
           "check_joint_limits", "pose_whitening", "SINGULAR_CONDITION", "NEWTON_BLOCK_ROWS", "CHORD_STEP_MM",
           "FORWARD_KINEMATICS_TOL_MM", "SINGULAR_BOUND_REFERENCES", "raise_if_singular", "JOINT_RANGES_KEY",
           "checked_joint_ranges", "ChainJacobianFactors", "chain_jacobian_factors", "HAT_BLOCK_ROWS"]

#: Scaled condition number of the closure's pose Jacobian beyond which a configuration is singular.
SINGULAR_CONDITION = 1e5


class KinematicsError(ValueError):
    """A pose or set of joint values the machine cannot reach, or a singular configuration.

    Attributes:
        index: index of the first offending row.
    """

    def __init__(self, message: str, index: int):
        super().__init__(message)
        self.index = index


@dataclass(frozen=True)
class Parameter:
    """One named geometric parameter.

    Attributes:
        name: e.g. ``"B3.y"`` (a point's coordinate) or ``"dl4"`` (a scalar of chain 4).
        unit: ``"mm"`` or ``"rad"``.
        nominal: nominal value, in ``unit``.
        chain: 0-based chain the parameter belongs to.
    """

    name: str
    unit: str
    nominal: float
    chain: int


class ParameterTable:
    """The ordered table of a robot's parameters: names, units, nominal values, chains.

    The flat parameter vector ``theta`` of a robot is indexed in this order.
    """

    def __init__(self, parameters: Sequence[Parameter]):
        self.parameters = tuple(parameters)
        self.names = tuple(p.name for p in self.parameters)
        if len(set(self.names)) != len(self.names):
            raise ValueError("parameter names must be unique")
        self.units = tuple(p.unit for p in self.parameters)
        self.nominal = frozen_array([p.nominal for p in self.parameters])
        self.chains = np.array([p.chain for p in self.parameters], dtype=int)
        self.chains.setflags(write=False)
        self._index = {n: k for k, n in enumerate(self.names)}

    def __len__(self) -> int:
        return len(self.parameters)

    def __iter__(self) -> Iterator[Parameter]:
        return iter(self.parameters)

    def index(self, name: str) -> int:
        """Flat index of a parameter name.

        Raises:
            KeyError: the name is unknown (the message shows a few valid names).
        """
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"unknown parameter {name!r}: expected a name such as "
                           f"{', '.join(self.names[:4])}, ... (see the robot's parameter table)") from None

    def indices(self, names: Sequence[str]) -> np.ndarray:
        """Flat indices of several names, in the order given."""
        return np.array([self.index(n) for n in names], dtype=int)

    def chain_indices(self, chain: int) -> np.ndarray:
        """Flat indices of chain ``chain``'s parameters (0-based chain)."""
        return np.flatnonzero(self.chains == chain)

    def to_dict(self, theta: np.ndarray) -> dict[str, float]:
        """``{name: value}`` of a flat vector."""
        return {n: float(v) for n, v in zip(self.names, np.asarray(theta, dtype=float))}

    def vector(self, values: dict, base: np.ndarray | None = None) -> np.ndarray:
        """A flat vector from ``{name: value}``; names not given keep ``base`` (default nominal)."""
        v = np.array(self.nominal if base is None else base, dtype=float)
        for name, value in values.items():
            v[self.index(name)] = float(value)
        return v

    def angle_mask(self) -> np.ndarray:
        """(P,) bool, True for parameters in rad."""
        return np.array([u == "rad" for u in self.units])


class ClosureJacobians:
    """Derivatives of the closure residuals ``F`` (N, C) at N configurations.

    Attributes:
        pose: (N, C, D) ``dF_i / d pose_k``; mm/mm for positions, mm/rad for angles.
        joints: (N, C, C) ``dF_i / d q_k`` (diagonal for these mechanisms), mm per joint unit.
        parameters: (N, C, P) ``dF_i / d theta_k``, mm per parameter unit; where the robot gives
            ``own``, built from it on first use (zeros off each parameter's own chain).
        own: (N, P) or None. Where each chain's closure moves with its own parameters alone
            (``chains[k]`` the chain of parameter k, the parameter table's ``chains``): parameter
            k's derivative of its own chain's closure, ``dF_{chains[k]} / d theta_k``, every other
            entry of ``parameters`` being zero. None: ``parameters`` given densely, structure not
            declared.

    The arrays may be read-only views (the hexapod's ``joints`` is ``-I`` broadcast): copy
    before writing.
    """

    __slots__ = ("pose", "joints", "own", "chains", "_parameters")

    def __init__(self, pose: np.ndarray, joints: np.ndarray, parameters: np.ndarray | None = None, *,
                 own: np.ndarray | None = None, chains: np.ndarray | None = None):
        if (parameters is None) == (own is None) or (own is not None and chains is None):
            raise ValueError("give the dense parameters, or own with the parameters' chains")
        self.pose, self.joints, self.own, self.chains = pose, joints, own, chains
        self._parameters = parameters

    def own_for(self, chains: np.ndarray) -> np.ndarray | None:
        """The (N, P) ``own`` entries where they are declared for the parameters' chains
        ``chains`` (P,) (a robot's ``table.chains``), else None."""
        return self.own if self.own is not None and np.array_equal(self.chains, chains) else None

    @property
    def parameters(self) -> np.ndarray:
        if self._parameters is None:
            n, p = self.own.shape
            dense = np.zeros((n, self.pose.shape[1], p))
            dense[:, self.chains, np.arange(p)] = self.own
            self._parameters = dense
        return self._parameters


class Robot(ABC):
    """A parallel robot: nominal geometry, parameter table and kinematics.

    Subclasses set the class attributes and implement the abstract methods; the methods are
    back ends that trust their input (the engine's front ends validate). A robot instance is
    immutable.

    Class attributes:
        name: registry key, e.g. ``"hexapod"``.
        pose_names: names of the pose coordinates, e.g. ``("x", "y", "z")``.
        pose_units: unit of each pose coordinate (``"mm"`` or ``"rad"``).
        joint_unit: unit of the actuated joints (``"mm"`` for a leg length, ``"rad"`` for a motor).
        joint_symbol: column prefix of the joints in recordings (``"l"``, ``"q"``).
        chain_word: what a chain is called in messages (``"leg"``, ``"chain"``).
    """

    name: ClassVar[str]
    pose_names: ClassVar[tuple[str, ...]]
    pose_units: ClassVar[tuple[str, ...]]
    joint_unit: ClassVar[str]
    joint_symbol: ClassVar[str]
    chain_word: ClassVar[str] = "chain"

    #: The parameter table; ``table.nominal`` is the nominal geometry as a flat vector.
    table: ParameterTable
    #: Parameters held at their start value by default because pose data cannot identify them
    #: (a gauge choice), e.g. the Delta's ``Lay1..3``.
    gauge_fixed: tuple[str, ...] = ()
    #: Manufacturing tolerance of the parameters, the standard deviation of the default prior
    #: (:class:`calib.prior.ParameterPrior`): ``{"mm": value, "rad": value}`` per unit and/or
    #: ``{name: value}``, each in its parameter's unit. This generic one (0.1 mm on lengths,
    #: 1e-3 rad on angles: a machined and assembled part's usual general tolerance, ISO 2768-m
    #: for sizes of 30-400 mm, and about 0.1 mm at 100 mm for an angle) is for robots that
    #: declare none; every registered robot declares its own, with its reasons.
    default_parameter_tolerance: ClassVar[dict[str, float]] = {"mm": 0.1, "rad": 1e-3}
    #: Each chain's joint zero, one parameter a chain in chain order: the parameter that adds to the
    #: joint reading (the closure at joints ``q + d e_i`` with ``theta`` is the closure at ``q`` with
    #: that parameter of chain ``i`` moved by ``d``). A re-homing, an encoder re-zeroed or a spool
    #: re-wound moves these and nothing else (:mod:`calib.session_shift`).
    joint_zero_names: ClassVar[tuple[str, ...]] = ()
    #: Parameters of the physical machine that no pose data tell from the others, e.g. the linear
    #: Delta's tool offset (its towers are taken relative to the tool point): held (they are
    #: among :attr:`gauge_fixed`), and seeded errors leave them at nominal so that a machine and
    #: its kinematics agree unless a case sets them on purpose.
    machine_only: ClassVar[tuple[str, ...]] = ()
    #: Parameters that move every chain's closure, not only their own chain's (the linear Delta's
    #: rod-pair differences tilt the effector all its chains hold): the chain-wise identification,
    #: which fits chain by chain, cannot separate them, so they are not among :attr:`free_default`
    #: (a fit that names them, as :func:`calib.probe.fit_probe` does, identifies them), and
    #: seeded errors leave them at nominal.
    chain_coupled: ClassVar[tuple[str, ...]] = ()

    # -- description ----------------------------------------------------------------------
    @property
    def n_chains(self) -> int:
        """Number of chains (= actuated joints = pose coordinates)."""
        return len(self.pose_names)

    @property
    def pose_dim(self) -> int:
        return len(self.pose_names)

    @property
    def n_parameters(self) -> int:
        return len(self.table)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """``("l1", ..., "l6")`` or ``("q1", "q2", "q3")``."""
        return tuple(f"{self.joint_symbol}{i + 1}" for i in range(self.n_chains))

    @property
    def free_default(self) -> tuple[str, ...]:
        """Names identified by default: every parameter not in :attr:`gauge_fixed` nor in
        :attr:`chain_coupled`."""
        return tuple(n for n in self.table.names if n not in self.gauge_fixed and n not in self.chain_coupled)

    @property
    def angle_pose_mask(self) -> np.ndarray:
        """(D,) bool, True for pose coordinates in rad."""
        return np.array([u == "rad" for u in self.pose_units])

    @property
    @abstractmethod
    def home_pose(self) -> np.ndarray:
        """(D,) the home pose: the start of the forward kinematics' Newton iteration."""

    @property
    @abstractmethod
    def length_scale_mm(self) -> float:
        """A characteristic size of the machine, mm (turns angles into lengths for scaling)."""

    @abstractmethod
    def workspace_bounds(self) -> np.ndarray:
        """(D, 2) low/high of each pose coordinate of the default calibration workspace."""

    #: (C, 2) read-only low/high of each joint as built (joint unit), declared by a description's
    #: ``joint_ranges`` (:func:`checked_joint_ranges`), or None: :meth:`default_joint_limits` hold.
    joint_ranges: np.ndarray | None = None

    def joint_limits(self) -> np.ndarray:
        """(C, 2) low/high of each commanded joint value the machine accepts (joint unit): the
        declared :attr:`joint_ranges` where the description gives them, else the robot's
        :meth:`default_joint_limits` (the hexapod's ``home length +- stroke_mm``). Every user of
        a joint's range (checks, pose design, suggested poses, compensation) calls this one."""
        if self.joint_ranges is not None:
            return self.joint_ranges.copy()
        return self.default_joint_limits()

    @abstractmethod
    def default_joint_limits(self) -> np.ndarray:
        """(C, 2) low/high of each joint when the description declares no ``joint_ranges``."""

    def joint_ranges_description(self) -> dict:
        """``{"joint_ranges": [[low, high], ...]}`` when ranges are declared, else ``{}``: the part
        of :meth:`description` that :func:`checked_joint_ranges` reads back."""
        return {} if self.joint_ranges is None else {JOINT_RANGES_KEY: self.joint_ranges.tolist()}

    @abstractmethod
    def description(self) -> dict:
        """JSON-ready nominal geometry (mm, rad), the inverse of :meth:`from_description`."""

    @classmethod
    @abstractmethod
    def from_description(cls, description: dict) -> "Robot":
        """The robot of a :meth:`description` (raises ``KeyError``/``ValueError`` naming the key)."""

    # -- optional: pose design and reference data (defaults: none) -----------------------
    def full_workspace_bounds(self) -> np.ndarray:
        """(D, 2) low/high of a box around every pose worth measuring: the "full" design
        workspace of :mod:`calib.design`, cut there by the feasibility checks (reach, joint
        limits, passive joints, singularity). Default: :meth:`workspace_bounds`."""
        return self.workspace_bounds()

    def passive_joint_angles(self, theta: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, K) rad, deflection of each range-limited passive joint at ``poses`` (e.g. the
        angle between a leg and the normal of its spherical joint's seat), for the design's
        passive-joint limit. Default: none (K = 0)."""
        return np.zeros((np.shape(poses)[0], 0))

    # -- kinematics -----------------------------------------------------------------------
    @abstractmethod
    def closure(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, C) mm, closure residuals; zero when ``joints`` bring a machine ``theta`` to ``poses``."""

    @abstractmethod
    def closure_jacobians(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> ClosureJacobians:
        """Analytic derivatives of :meth:`closure` (see :class:`ClosureJacobians`)."""

    def closure_pose_jacobian(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, C, D) ``dF_i / d pose_k`` alone: what the forward kinematics' Newton steps need.

        Must equal ``closure_jacobians(theta, joints, poses).pose`` exactly (bit for bit); a
        robot overrides it when the pose columns come cheaper than the whole set (the parameter
        Jacobian is (N, C, P)). Default: taken from :meth:`closure_jacobians`.
        """
        return self.closure_jacobians(theta, joints, poses).pose

    def closure_and_pose_jacobian(self, theta: np.ndarray, joints: np.ndarray,
                                  poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(closure, pose Jacobian)``, (N, C) and (N, C, D), in one call: what each Newton step
        of the forward kinematics needs. The Jacobian may be a strided view (e.g. a transposed
        one). Default: :meth:`closure` and :meth:`closure_pose_jacobian`; a robot overrides it
        when the two share most of their work (the hexapod's leg vectors)."""
        return self.closure(theta, joints, poses), self.closure_pose_jacobian(theta, joints, poses)

    def closure_with_jacobians(self, theta: np.ndarray, joints: np.ndarray,
                               poses: np.ndarray) -> tuple[np.ndarray, ClosureJacobians]:
        """``(closure, Jacobians)``, (N, C) and :class:`ClosureJacobians`, in one call: what each
        iteration of the identification needs. Default: :meth:`closure` and
        :meth:`closure_jacobians`; a robot overrides it when the two share their work."""
        return self.closure(theta, joints, poses), self.closure_jacobians(theta, joints, poses)

    @abstractmethod
    def inverse_kinematics(self, theta: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, C) joint values that bring the machine ``theta`` to ``poses``.

        Raises:
            KinematicsError: a pose the machine cannot reach (names the row and the chain).
        """

    @abstractmethod
    def chain_points(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, C, K, 3) mm, base frame: each chain drawn as a polyline of K points from its base
        joint to its platform joint (for pictures; e.g. the hexapod's ``B_i, R P_i + t``)."""

    def forward_kinematics(self, theta: np.ndarray, joints: np.ndarray, *,
                           initial: np.ndarray | None = None) -> np.ndarray:
        """(N, D) poses reached when ``joints`` are commanded (default: Newton on the closure).

        Args:
            theta: (P,) parameter vector.
            joints: (N, C) joint values.
            initial: (N, D) or (D,) start of the iteration; default :attr:`home_pose`.

        Raises:
            KinematicsError: singular configuration or no convergence (names the row).
        """
        return newton_forward_kinematics(self, theta, joints, initial=initial)

    def pose_scale(self) -> np.ndarray:
        """(D,) multiplies pose coordinates to make them comparable: 1 for mm, the machine's
        size for rad (computed once per robot, read-only)."""
        scale = self.__dict__.get("_pose_scale")
        if scale is None:
            scale = np.where(self.angle_pose_mask, self.length_scale_mm, 1.0)
            scale.setflags(write=False)
            self.__dict__["_pose_scale"] = scale
        return scale

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}: {self.n_parameters} parameters, {self.n_chains} chains>"


#: Largest closure residual (mm) of a pose the forward kinematics returns: converged.
FORWARD_KINEMATICS_TOL_MM = 1e-11


def newton_forward_kinematics(robot: Robot, theta: np.ndarray, joints: np.ndarray, *,
                              initial: np.ndarray | None = None, tol: float = FORWARD_KINEMATICS_TOL_MM,
                              max_iter: int = 50) -> np.ndarray:
    """Forward kinematics by Newton's method on the closure, vectorised over rows.

    Each step takes the closure and its pose Jacobian in one call
    (:meth:`Robot.closure_and_pose_jacobian`) and solves the rows' (C, C) systems in one batched
    LAPACK call; rows leave the iteration as they converge.

    Args:
        robot: the robot.
        theta: (P,) parameter vector.
        joints: (N, C) joint values.
        initial: (N, D) or (D,) start; default the robot's home pose. Newton's method finds the
            assembly mode nearest the start: pass poses near the answer (the measured or
            commanded ones) to save iterations.
        tol: converged when every closure residual is below ``tol`` mm.
        max_iter: iterations before giving up.

    Returns:
        (N, D) poses.

    Raises:
        KinematicsError: singular configuration met, divergence or no convergence; names the row.
    """
    joints = np.asarray(joints, dtype=float)
    n, d = joints.shape[0], robot.pose_dim
    if initial is None:
        poses = np.tile(robot.home_pose, (n, 1))
    else:
        init = np.asarray(initial, dtype=float)
        poses = np.tile(as_array(init, "initial", (d,)), (n, 1)) if init.ndim == 1 else \
            as_array(init, "initial", (n, d)).copy()
    # Singularity is judged with the angle columns scaled to lengths, so that the threshold
    # does not depend on the units of the pose coordinates.
    scale = 1.0 / robot.pose_scale()
    # Blocks of rows small enough for the temporaries to stay in cache: about twice as fast
    # as one pass over 10,000 rows, and the same iterates.
    for start in range(0, n, NEWTON_BLOCK_ROWS):
        block = slice(start, start + NEWTON_BLOCK_ROWS)
        poses[block] = _newton_block(robot, theta, joints[block], poses[block], tol, max_iter, scale, start)
    return poses


#: Rows the forward kinematics' Newton iteration handles at a time.
NEWTON_BLOCK_ROWS = 2048


#: Largest Newton step (mm, angles scaled to lengths by :meth:`Robot.pose_scale`) after which the
#: next step reuses the pose Jacobian (a chord step): a step this small changes the Jacobian by
#: about step / machine size (1e-4 here), so the chord step still cuts the residual by that factor
#: (1e-9 mm to 1e-13 mm), at the price of the closure alone instead of closure and Jacobian.
CHORD_STEP_MM = 1e-2


def _newton_block(robot, theta, joints, poses, tol, max_iter, scale, offset) -> np.ndarray:
    """Newton's iteration on rows ``offset ...`` of :func:`newton_forward_kinematics`.

    Full Newton steps while the steps are large; once every remaining row's last step is below
    :data:`CHORD_STEP_MM`, chord steps (the last pose Jacobian and its LU factors
    (:class:`calib.batched_lu.BatchedLU`) kept, the closure alone re-evaluated). A converged
    row's singularity is judged on the last Jacobian evaluated for it (at most
    :data:`CHORD_STEP_MM` away)."""
    n, d = poses.shape
    active = None  # rows still iterating (None: all of them, no gathering)
    p, q = poses, joints
    J = factors = None  # the pose Jacobian and its LU factors (computed when first solved with)
    chord = False
    for _ in range(max_iter):
        if chord:
            r = robot.closure(theta, q, p)
        else:
            r, J = robot.closure_and_pose_jacobian(theta, q, p)
            factors = None
        done = np.max(np.abs(r), axis=1) <= tol
        n_done = int(np.count_nonzero(done))
        if n_done:
            rows = np.arange(n) + offset if active is None else active
            raise_if_singular(J[done] if n_done < done.size else J, scale, rows[done])
            if n_done == done.size:
                if active is not None:
                    poses[active - offset] = p
                return poses
            keep = ~done
            if active is not None:
                poses[active - offset] = p
            active, p, q, r, J = rows[keep], p[keep], q[keep], r[keep], J[keep]
            factors = None
        try:
            if factors is None:
                factors = BatchedLU(J)
            step = factors.solve(r)
        except np.linalg.LinAlgError:
            rows = np.arange(n) + offset if active is None else active
            bad = np.linalg.matrix_rank(J * scale) < d
            k = int(rows[np.argmax(bad)])
            raise KinematicsError(f"forward kinematics met a singular configuration at row {k}", k) from None
        p = p - step
        finite = np.isfinite(p).all(axis=1)
        if not finite.all():
            rows = np.arange(n) + offset if active is None else active
            k = int(rows[np.argmax(~finite)])
            raise KinematicsError(f"forward kinematics diverged at row {k}", k)
        chord = bool(np.max(np.abs(step) / scale) <= CHORD_STEP_MM)
        if active is None:
            poses = p
    k = int(offset if active is None else active[0])
    raise KinematicsError(
        f"forward kinematics did not converge for row {k} in {max_iter} iterations "
        f"(joints {np.array2string(joints[k - offset], precision=4)}): no assembly near the start pose", k)


#: Reference rows :func:`raise_if_singular` tries before it takes the SVD of the rows left.
SINGULAR_BOUND_REFERENCES = 4


def raise_if_singular(J: np.ndarray, scale: np.ndarray, rows: np.ndarray) -> None:
    """Raise :class:`KinematicsError` for the first of the (M, C, D) pose Jacobians ``J`` whose
    column-scaled condition number reaches :data:`SINGULAR_CONDITION`; ``scale`` (D,) multiplies
    the columns (the forward kinematics passes ``1 / Robot.pose_scale()``), ``rows`` (M,) are the
    row numbers the error names (its ``index``).

    An exact condition number is an SVD per matrix; most rows are cleared by a cheap rigorous
    bound instead: with ``A`` the scaled Jacobian of a reference row, ``H = A^-1`` and ``E = I -
    H Js``, ``Js = A (I - E)`` gives ``cond(Js) <= cond(A) (1 + e) / (1 - e)`` for ``e = |E|_F
    < 1`` (one matrix product for all rows), with ``cond(A) <= |A|_F |H|_F``. The reference is
    the first row, then the first row not yet cleared (up to :data:`SINGULAR_BOUND_REFERENCES`
    of them: a machine whose Jacobian varies much over the workspace, like the Delta's, needs a
    few); rows no bound clears get the SVD."""
    m, c, dd = J.shape
    # Structure-of-arrays (C, D, M), columns scaled: a contiguous result whatever J's strides
    # (for a robot that returns a transposed view, a plain product), so that the M products
    # below are one matrix product and the reductions run over the M rows.
    Js = J.transpose(1, 2, 0) * scale[None, :, None]
    unsure = np.ones(m, dtype=bool)
    if c == dd:
        for _ in range(SINGULAR_BOUND_REFERENCES):
            todo = np.flatnonzero(unsure)
            if not todo.size:
                return
            rest = Js if todo.size == m else Js[:, :, todo]
            A = rest[:, :, 0]
            try:  # cond(A) <= |A|_F |A^-1|_F: no SVD for the reference row either
                H = np.linalg.inv(A)
                cond_a = float(np.linalg.norm(A) * np.linalg.norm(H))
            except np.linalg.LinAlgError:
                break
            if not cond_a < SINGULAR_CONDITION:
                break
            E = (H @ rest.reshape(c, -1)).reshape(dd, dd, todo.size)  # H Js, row by row
            E[np.arange(dd), np.arange(dd)] -= 1.0
            e = np.sqrt(np.einsum("ijm,ijm->m", E, E))
            with np.errstate(divide="ignore"):
                bound = cond_a * (1.0 + e) / (1.0 - e)
            unsure[todo] = ~((e < 1.0) & (bound < SINGULAR_CONDITION))
    if not unsure.any():
        return
    cond = np.full(m, 0.0)
    cond[unsure] = np.linalg.cond(Js[:, :, unsure].transpose(2, 0, 1))
    singular = ~(cond < SINGULAR_CONDITION)
    if np.any(singular):
        i = int(np.argmax(singular))
        k = int(rows[i])
        raise KinematicsError(
            f"forward kinematics met a singular configuration at row {k} (scaled condition "
            f"number of the pose Jacobian {cond[i]:.3g})", k)


def pose_jacobian_of_joints(robot: Robot, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N, D, C) ``d pose / d joints`` at consistent ``(joints, poses)`` (implicit function theorem)."""
    jac = robot.closure_jacobians(theta, joints, poses)
    return -solve_stacked(jac.pose, jac.joints)


def pose_jacobian_of_parameters(robot: Robot, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N, D, P) ``d pose / d theta`` at fixed joints, at consistent ``(joints, poses)``.

    By the implicit function theorem on ``closure(theta, joints, pose) = 0``:
    ``d pose / d theta = -(dF / d pose)^-1 dF / d theta``.
    """
    jac = robot.closure_jacobians(theta, joints, poses)
    out = solve_closure_parameters(robot, jac)
    return np.negative(out, out=out)


def solve_closure_parameters(robot: Robot, jac: ClosureJacobians) -> np.ndarray:
    """(N, D, P) ``pose^-1 parameters`` of a :class:`ClosureJacobians`' (N, C, D) ``pose`` and (N,
    C, P) ``parameters`` blocks (``numpy.linalg.solve``'s result, to rounding).

    Where, as every robot here has it, each closure involves only its own chain's parameters
    (``jac.own`` given, or ``parameters[:, i, k]`` zero unless parameter k belongs to chain i,
    checked by counting the nonzero entries), column k is chain c's column of the inverse times
    parameter k's own entry: one (N, C, C) inverse instead of a solve with P right-hand sides (the
    6-RUS's 66: 8 times fewer flops, and no LAPACK call per right-hand side; the inverse by
    :func:`calib.batched_lu.inverse_stacked`). Otherwise :func:`calib.batched_lu.solve_stacked`.

    Raises:
        numpy.linalg.LinAlgError: a singular ``pose`` block.
    """
    pose = jac.pose
    chains = robot.table.chains
    c = pose.shape[1]
    if pose.shape[1] != pose.shape[2] or c != robot.n_chains:
        return solve_stacked(pose, jac.parameters)
    own = jac.own_for(chains)
    if own is None:
        parameters = jac.parameters
        if chains.size != parameters.shape[2]:
            return solve_stacked(pose, parameters)
        own = parameters[:, chains, np.arange(chains.size)]  # (N, P): each column's own chain's entry
        if np.count_nonzero(parameters) != np.count_nonzero(own):
            return solve_stacked(pose, parameters)
    n = own.shape[0]
    inverse = inverse_stacked(pose)
    k = chains.size // c
    if k * c == chains.size and np.array_equal(chains, np.repeat(np.arange(c), k)):
        # chain by chain in table order, k parameters each: one broadcast product, no gather
        return (inverse[:, :, :, None] * own.reshape(n, 1, c, k)).reshape(n, pose.shape[1], -1)
    return inverse[:, :, chains] * own[:, None, :]


#: Rows of a block of :meth:`ChainJacobianFactors.hat` (a block's (B, m, P) products stay in cache).
HAT_BLOCK_ROWS = 4096


class ChainJacobianFactors:
    """The pose Jacobian ``d pose / d theta`` of N rows by P parameters (row-scaled, e.g. whitened),
    kept as its factors (:func:`chain_jacobian_factors`): row j's (D, P) block is ``M_j S_j``
    with ``M`` (N, D, m) the scaled columns of ``-(dF/dpose)^-1`` of the m chains with
    parameters and ``S_j`` block-diagonal, chain a's K parameters' own entries ``own`` (N, m, K)
    (:attr:`ClosureJacobians.own`); the parameters are chain a's K in order, chain by chain.
    Its products take about a fifth of the dense Jacobian's flops and never hold the (N, D, P)
    array; they equal the dense ones to rounding."""

    def __init__(self, M: np.ndarray, own: np.ndarray):
        self.M, self.own = M, own
        self.n, self.m, self.k = own.shape
        self.p = self.m * self.k

    def gram(self, rows=None) -> np.ndarray:
        """(P, P) ``sum_j J_j^T J_j`` over ``rows`` (an index array; None: every row)."""
        M, own = (self.M, self.own) if rows is None else (self.M[rows], self.own[rows])
        W = np.einsum("nia,nib->nab", M, M)  # (N, m, m): M_j^T M_j
        G = np.empty((self.p, self.p))
        k = self.k
        for a in range(self.m):
            scaled = (W[:, a, :, None] * own).reshape(own.shape[0], -1)  # (N, P)
            G[a * k:(a + 1) * k] = own[:, a].T @ scaled
        return G

    def rmatvec(self, r: np.ndarray) -> np.ndarray:
        """(P,) ``sum_j J_j^T r_j`` of ``r`` (N, D)."""
        t = np.einsum("nia,ni->na", self.M, r)
        return np.einsum("nak,na->ak", self.own, t).ravel()

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """(N, D) ``J_j x`` of every row, ``x`` (P,)."""
        s = np.einsum("nak,ak->na", self.own, x.reshape(self.m, self.k))
        return np.einsum("nia,na->ni", self.M, s)

    def hat(self, cov: np.ndarray) -> np.ndarray:
        """(N, D, D) ``J_j cov J_j^T``, ``cov`` (P, P) symmetric positive semi-definite, through the
        factors: with ``cov = L L^T`` (its eigenvectors scaled by the square roots of its
        eigenvalues, negative rounding ones taken as zero, as :func:`calib.outliers.hat_blocks`),
        ``V_j = S_j L`` (m, P) chain block by chain block, ``Q_j = V_j V_j^T`` (m, m), then
        ``M_j Q_j M_j^T``; block by block of :data:`HAT_BLOCK_ROWS` rows."""
        w, v = np.linalg.eigh(cov)
        L = (v * np.sqrt(np.clip(w, 0.0, None))).reshape(self.m, self.k, self.p)  # chain a's rows of L

        def inner(own):
            V = self._chain_products(own, L)
            return V @ np.swapaxes(V, 1, 2)

        return self._sandwiched(inner)

    def sandwich(self, cov: np.ndarray) -> np.ndarray:
        """(N, D, D) ``J_j cov J_j^T`` with ``cov`` (P, P) as given (no factor of it: where ``cov``
        is large along directions the Jacobian nearly annihilates, e.g. a prior-held gauge, its
        eigen-factor's rounding would leak into the rest), as ``J_j (cov J_j^T)``: ``U_j = S_j
        cov`` (m, P) chain block by chain block, ``U_j S_j^T`` (m, m), then ``M_j (.) M_j^T``;
        block by block of :data:`HAT_BLOCK_ROWS` rows."""
        cov = np.asarray(cov, dtype=float).reshape(self.m, self.k, self.p)  # chain a's rows of cov

        def inner(own):
            U = self._chain_products(own, cov)
            return np.einsum("nabl,nbl->nab", U.reshape(own.shape[0], self.m, self.m, self.k), own)

        return self._sandwiched(inner)

    def _chain_products(self, own: np.ndarray, F: np.ndarray) -> np.ndarray:
        """(B, m, P) ``S_j F`` of a block's own entries ``own`` (B, m, K), ``F`` (m, K, P) chain
        a's rows of a (P, P) matrix: chain block by chain block."""
        out = np.empty((own.shape[0], self.m, self.p))
        for a in range(self.m):
            out[:, a] = own[:, a] @ F[a]
        return out

    def _sandwiched(self, inner) -> np.ndarray:
        """(N, D, D) ``M_j inner(S_j) M_j^T``, ``inner`` mapping a block's own entries (B, m, K)
        to (B, m, m); block by block of :data:`HAT_BLOCK_ROWS` rows."""
        out = np.empty((self.n, self.M.shape[1], self.M.shape[1]))
        for start in range(0, self.n, HAT_BLOCK_ROWS):
            rows = slice(start, start + HAT_BLOCK_ROWS)
            M = self.M[rows]
            out[rows] = (M @ inner(self.own[rows])) @ np.swapaxes(M, 1, 2)
        return out

    def dense(self, rows) -> np.ndarray:
        """(len(rows), D, P) the Jacobian's rows ``rows`` formed."""
        M, own = self.M[rows], self.own[rows]
        return (M[:, :, :, None] * own[:, None, :, :]).reshape(M.shape[0], M.shape[1], self.p)


def _chain_blocks(robot: Robot, jac: ClosureJacobians, idx: np.ndarray):
    """``(chains (m,), columns (m, K))`` where the free parameters ``idx`` come chain by chain, K
    of each chain's, and ``jac`` gives their own entries (square pose blocks), else None."""
    if jac.own_for(robot.table.chains) is None or jac.pose.shape[1] != jac.pose.shape[2]:
        return None
    owner = robot.table.chains[idx]
    chains = np.unique(owner)
    k = idx.size // chains.size
    if k * chains.size != idx.size or not np.array_equal(owner, np.repeat(owner[::k], k)) or \
            np.unique(owner[::k]).size != chains.size:
        return None
    return owner[::k], idx.reshape(-1, k)


def chain_jacobian_factors(robot: Robot, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray, idx=None,
                           row_scale=None) -> ChainJacobianFactors | None:
    """The pose Jacobian ``d pose / d theta[idx]`` (``idx`` default every parameter) at consistent
    ``(joints, poses)`` (N, C), (N, D), each pose coordinate times ``row_scale`` (D,) (default 1),
    as its :class:`ChainJacobianFactors`: ``pose_jacobian_of_parameters(...)[:, :, idx] *
    row_scale[:, None]`` to rounding, never formed. None where the robot's closures give no own
    entries, the pose block is not square, or ``idx`` does not come chain by chain, as many of
    each chain's (then form the Jacobian)."""
    jac = robot.closure_jacobians(theta, joints, poses)
    blocks = _chain_blocks(robot, jac, np.arange(robot.n_parameters) if idx is None else np.asarray(idx))
    if blocks is None:
        return None
    chains, columns = blocks
    M = inverse_stacked(jac.pose)[:, :, chains]
    scale = -np.ones(jac.pose.shape[2]) if row_scale is None else -np.asarray(row_scale, dtype=float)
    M *= scale[None, :, None]
    return ChainJacobianFactors(M, jac.own[:, columns])


#: The description key of the joints' declared ranges: ``[[low, high], ...]``, one pair per joint
#: in chain order, joint unit (e.g. a hexapod's legs from 640.2 to 920.2 mm, fully retracted to
#: fully extended).
JOINT_RANGES_KEY = "joint_ranges"


def checked_joint_ranges(value, robot: Robot) -> np.ndarray | None:
    """(C, 2) read-only declared joint ranges of ``robot`` from a description's ``joint_ranges``
    value (None: none declared).

    Raises:
        ValueError: one line naming the key and the joint: not a list of ``robot.n_chains``
            ``[low, high]`` pairs, a value not a finite number, or ``low >= high``.
    """
    if value is None:
        return None
    c, key, unit = robot.n_chains, JOINT_RANGES_KEY, robot.joint_unit
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__") or len(value) != c:
        got = f"{len(value)} entries" if hasattr(value, "__len__") and not isinstance(value, (str, bytes)) \
            else repr(value)
        raise ValueError(f"{key}: expected one [low, high] pair ({unit}) per {robot.chain_word} ({c}), got {got}")
    out = np.empty((c, 2))
    for i, pair in enumerate(value):
        where = f"{key}[{i}] ({robot.chain_word} {i + 1}, {robot.joint_names[i]})"
        if isinstance(pair, (str, bytes, dict)) or not hasattr(pair, "__len__") or len(pair) != 2:
            raise ValueError(f"{where}: expected [low, high] in {unit}, got {pair!r}")
        for k, v in enumerate(pair):
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not np.isfinite(v):
                raise ValueError(f"{where}: {('low', 'high')[k]} must be a finite number ({unit}), got {v!r}")
            out[i, k] = float(v)
        if not out[i, 0] < out[i, 1]:
            raise ValueError(f"{where}: low must be below high, got [{out[i, 0]:.6g}, {out[i, 1]:.6g}] {unit}")
    out.setflags(write=False)
    return out


def check_joint_limits(robot: Robot, joints: np.ndarray, what: str = "row") -> None:
    """Raise :class:`KinematicsError` naming the first row and chain outside :meth:`Robot.joint_limits`."""
    limits = robot.joint_limits()
    bad = np.argwhere((joints < limits[:, 0]) | (joints > limits[:, 1]) | ~np.isfinite(joints))
    if bad.size:
        n, c = (int(v) for v in bad[0])
        raise KinematicsError(
            f"{what} {n} is unreachable: {robot.chain_word} {c + 1} needs {joints[n, c]:.6f} "
            f"{robot.joint_unit}, outside its range [{limits[c, 0]:.6g}, {limits[c, 1]:.6g}] "
            f"{robot.joint_unit}", n)


def pose_whitening(robot: Robot, theta, joints, poses, noise: SensorNoise) -> np.ndarray:
    """(N, D, D) whitening ``L^-1`` of each pose's measurement covariance
    ``S_pose + Jq S_joint Jq^T`` (pose sensor plus joint noise through the manipulator Jacobian).

    ``theta`` (P,), ``joints`` (N, C) and ``poses`` (N, D) consistent (``poses`` reached by the
    machine ``theta`` at ``joints``); rows of ``L^-1 (measured - predicted)`` are dimensionless.
    Used by the forward identification (:mod:`calib.engine`) and by :mod:`calib.observability`."""
    n, d = poses.shape
    std = noise.pose_std(robot.pose_units)
    cov = np.broadcast_to(np.diag(std ** 2), (n, d, d)).copy()
    if noise.joint_std > 0:
        jq = pose_jacobian_of_joints(robot, theta, joints, poses)
        cov += noise.joint_std ** 2 * jq @ np.swapaxes(jq, 1, 2)
        return np.linalg.inv(np.linalg.cholesky(cov))
    return np.broadcast_to(np.diag(1.0 / std), (n, d, d)).copy()
