"""Delta robot kinematics with the 24-parameter "Model 24" of the Delta calibration paper.

Frames and conventions (all lengths mm, all angles rad):

* Base frame ``R0``: origin ``O0`` at the centre of the fixed platform, ``z0`` up, the
  travelling plate hangs below the base (``z < 0``), ``x0`` towards shoulder 1.
* Chain ``i`` (i = 1, 2, 3) has eight parameters (paper Eq. 3.6)
  ``P_i = [Dx_i, Dy_i, Dz_i, theta_i, alpha_i, Lax_i, Lay_i, Lb_i]``:

  - ``(Dx_i, Dy_i, Dz_i)`` (mm, base frame): the shoulder point ``A_i`` of the *reduced*
    Delta, i.e. the actuated-joint centre translated by the plate-attachment offset
    (the paper's simplification "combining the points O_i and A_i": each parallelogram
    is a single bar ending at the plate centre ``O``). Nominally
    ``(Rb - Rn) * (cos theta_i, sin theta_i, 0)``.
  - ``theta_i`` (rad): rotation of the chain plane ``pi_i`` about ``z0``. The chain frame is
    ``R_z(theta_i)``: ``x_i`` radial, ``y_i`` tangential (the actuated joint axis), ``z_i = z0``.
  - ``alpha_i`` (rad): actuated joint offset; the arm angle is ``phi_i = q_i + alpha_i``
    where ``q_i`` is the joint reading. ``phi > 0`` turns the arm down, towards the plate.
  - ``(Lax_i, Lay_i)`` (mm): the arm vector at ``phi_i = 0`` in the chain plane
    (``x_i`` and ``z_i`` components). Nominally ``(La, 0)``.
  - ``Lb_i`` (mm): forearm (parallelogram) length.

  Elbow: ``B_i = D_i + R_z(theta_i) R_y(phi_i) [Lax_i, 0, Lay_i]``.
  Closure (paper Eq. 3.8, distance form): ``F_i = ||X - B_i|| - Lb_i = 0`` where ``X`` is
  the plate centre.

The flat parameter vector (shape (24,)) is chain-major: chain 1's eight parameters, then
chain 2's, then chain 3's, see :data:`PARAMETER_TABLE`.

Not identifiable from position measurements: for each chain, rotating the arm vector
``(Lax_i, Lay_i)`` by an angle ``d`` in the chain plane and adding ``d`` to ``alpha_i`` leaves
every elbow position unchanged. :func:`canonical_params` maps any parameter set to the
equivalent one with ``Lay_i = 0`` (arm length ``Lax_i`` and joint offset ``alpha_i``), which is
what the identification estimates.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ..robot import (JOINT_RANGES_KEY, ClosureJacobians, KinematicsError, Parameter, ParameterTable, Robot,
                     checked_joint_ranges)

__all__ = [
    "Delta",
    "CHAIN_TABLE_NAMES",
    "CHAIN_PARAMETER_NAMES",
    "CHAIN_PARAMETER_UNITS",
    "DeltaParams",
    "NOMINAL_GEOMETRY",
    "PARAMETER_NAMES",
    "PARAMETER_TABLE",
    "PARAMETER_UNITS",
    "canonical_params",
    "constraint_residuals",
    "constraint_jacobian_joints",
    "constraint_jacobian_params",
    "constraint_jacobian_position",
    "elbow_positions",
    "forward_kinematics",
    "fk_jacobian_joints",
    "fk_jacobian_params",
    "inverse_kinematics",
    "parameter_index",
]

#: Names of the eight per-chain parameters, paper Eq. (3.6) order.
CHAIN_PARAMETER_NAMES: tuple[str, ...] = ("Dx", "Dy", "Dz", "theta", "alpha", "Lax", "Lay", "Lb")
#: Units of the eight per-chain parameters.
CHAIN_PARAMETER_UNITS: tuple[str, ...] = ("mm", "mm", "mm", "rad", "rad", "mm", "mm", "mm")
#: The 24 flat-vector names, e.g. ``Dx1``, ``theta2``, ``Lb3``.
PARAMETER_NAMES: tuple[str, ...] = tuple(
    f"{n}{i}" for i in (1, 2, 3) for n in CHAIN_PARAMETER_NAMES
)
#: Units of the 24 flat-vector entries.
PARAMETER_UNITS: tuple[str, ...] = CHAIN_PARAMETER_UNITS * 3
#: The one table of the flat parameter vector: ``(name, index, unit)``.
PARAMETER_TABLE: tuple[tuple[str, int, str], ...] = tuple(
    (n, k, u) for k, (n, u) in enumerate(zip(PARAMETER_NAMES, PARAMETER_UNITS))
)

#: Nominal geometry of the paper's Delta (Section 2). Lengths mm, angles deg.
NOMINAL_GEOMETRY: dict[str, float | tuple[float, float, float]] = {
    "La_mm": 260.0,
    "Lb_mm": 480.0,
    "Rb_mm": 194.0,
    "Rn_mm": 30.0,
    "theta_deg": (0.0, 120.0, 240.0),
}

# Relative tolerance below which a configuration counts as singular.
_SINGULAR_TOL = 1e-9


def parameter_index(name: str) -> int:
    """Index of a parameter in the flat (24,) vector.

    Args:
        name: One of :data:`PARAMETER_NAMES`, e.g. ``"theta2"``.

    Returns:
        The index 0..23.

    Raises:
        ValueError: If ``name`` is unknown.
    """
    try:
        return PARAMETER_NAMES.index(name)
    except ValueError:
        raise ValueError(f"name must be one of {PARAMETER_NAMES}, got {name!r}") from None


# --------------------------------------------------------------------------- validation


def _as_array(value, name: str, shape: tuple) -> np.ndarray:
    """Float64 copy of ``value`` checked against ``shape`` (``-1`` = any length >= 1)."""
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a float array, got {type(value).__name__}") from None
    ok = arr.ndim == len(shape) and all(
        (s == -1 and a >= 1) or s == a for s, a in zip(shape, arr.shape)
    )
    if not ok:
        want = "(" + ", ".join("N" if s == -1 else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got non-finite values")
    return arr


def _positions(positions) -> np.ndarray:
    return _as_array(positions, "positions", (-1, 3))


def _joints(q) -> np.ndarray:
    return _as_array(q, "q", (-1, 3))


def _check_params(params) -> None:
    if not isinstance(params, DeltaParams):
        raise ValueError(f"params must be a DeltaParams, got {type(params).__name__}")


def _closure_arguments(params, q, positions) -> tuple[np.ndarray, np.ndarray]:
    """``(q, positions)`` as (N, 3) arrays, checked with ``params`` (one place for every closure function)."""
    _check_params(params)
    q, positions = _joints(q), _positions(positions)
    _check_same_n(q, positions)
    return q, positions


def _check_same_n(q: np.ndarray, positions: np.ndarray) -> None:
    if q.shape[0] != positions.shape[0]:
        raise ValueError(
            f"q and positions must have the same number of configurations, "
            f"got {q.shape[0]} and {positions.shape[0]}"
        )


# --------------------------------------------------------------------------- parameters


@dataclasses.dataclass(frozen=True)
class DeltaParams:
    """The 24 parameters of Model 24 (three chains of eight), paper Eq. (3.6).

    Every field is a read-only float64 array of shape (3,), one entry per chain.

    Attributes:
        Dx: Shoulder point x, mm, base frame.
        Dy: Shoulder point y, mm, base frame.
        Dz: Shoulder point z, mm, base frame.
        theta: Chain-plane rotation about z0, rad.
        alpha: Actuated joint offset, rad (arm angle = reading + alpha).
        Lax: Arm vector component along the chain's radial axis at zero arm angle, mm.
        Lay: Arm vector component along z at zero arm angle, mm.
        Lb: Forearm length, mm.
    """

    Dx: np.ndarray
    Dy: np.ndarray
    Dz: np.ndarray
    theta: np.ndarray
    alpha: np.ndarray
    Lax: np.ndarray
    Lay: np.ndarray
    Lb: np.ndarray

    FIELDS: ClassVar[tuple[str, ...]] = CHAIN_PARAMETER_NAMES

    def __post_init__(self) -> None:
        for f in self.FIELDS:
            arr = _as_array(getattr(self, f), f, (3,))
            arr.setflags(write=False)
            object.__setattr__(self, f, arr)
        if np.any(self.Lb <= 0.0):
            raise ValueError(f"Lb must be positive, got {self.Lb.tolist()}")
        if np.any(np.hypot(self.Lax, self.Lay) <= 0.0):
            raise ValueError("arm vector (Lax, Lay) must be non-zero for every chain")

    # -- construction ------------------------------------------------------------
    @classmethod
    def nominal(
        cls,
        la_mm: float = 260.0,
        lb_mm: float = 480.0,
        rb_mm: float = 194.0,
        rn_mm: float = 30.0,
        theta_deg: tuple[float, float, float] = (0.0, 120.0, 240.0),
    ) -> "DeltaParams":
        """Nominal symmetric Delta (paper Section 2 by default).

        Args:
            la_mm: Arm length La, mm.
            lb_mm: Forearm length Lb, mm.
            rb_mm: Base radius (centre to actuated joint), mm.
            rn_mm: Plate radius (centre to forearm attachment), mm.
            theta_deg: Chain angles, degrees, shape (3,).

        Returns:
            Parameters with ``D_i = (rb - rn)(cos theta_i, sin theta_i, 0)``, ``alpha = 0``,
            ``(Lax, Lay) = (la, 0)`` and ``Lb = lb``.
        """
        th = np.deg2rad(_as_array(theta_deg, "theta_deg", (3,)))
        for name, val in (("la_mm", la_mm), ("lb_mm", lb_mm)):
            if not np.isfinite(val) or val <= 0:
                raise ValueError(f"{name} must be positive, got {val}")
        r = float(rb_mm) - float(rn_mm)
        return cls(
            Dx=r * np.cos(th),
            Dy=r * np.sin(th),
            Dz=np.zeros(3),
            theta=th,
            alpha=np.zeros(3),
            Lax=np.full(3, float(la_mm)),
            Lay=np.zeros(3),
            Lb=np.full(3, float(lb_mm)),
        )

    @classmethod
    def from_vector(cls, vector) -> "DeltaParams":
        """Build from the flat vector.

        Args:
            vector: Shape (24,), order of :data:`PARAMETER_TABLE` (mm / rad).
        """
        v = _as_array(vector, "vector", (24,)).reshape(3, 8)
        return cls(**{f: v[:, k] for k, f in enumerate(cls.FIELDS)})

    def to_vector(self) -> np.ndarray:
        """Flat vector, shape (24,), order of :data:`PARAMETER_TABLE` (mm / rad)."""
        return np.stack([getattr(self, f) for f in self.FIELDS], axis=1).reshape(24).copy()

    def chain_vector(self, i: int) -> np.ndarray:
        """The eight parameters of chain ``i`` (0-based), shape (8,), Eq. (3.6) order."""
        if i not in (0, 1, 2):
            raise ValueError(f"i must be 0, 1 or 2, got {i!r}")
        return np.array([getattr(self, f)[i] for f in self.FIELDS])

    def to_dict(self) -> dict[str, float]:
        """``{name: value}`` for the 24 parameters (mm / rad)."""
        return {n: float(v) for n, v in zip(PARAMETER_NAMES, self.to_vector())}

    def shoulders(self) -> np.ndarray:
        """Shoulder points ``D_i``, shape (3, 3), mm, base frame (row = chain)."""
        return np.stack([self.Dx, self.Dy, self.Dz], axis=1)


def canonical_params(params: DeltaParams) -> DeltaParams:
    """Equivalent parameter set with ``Lay_i = 0`` for every chain.

    Rotating the arm vector in the chain plane and shifting the joint offset by the same
    angle gives identical kinematics; this picks the representative with the arm along
    the chain's radial axis at zero arm angle: ``Lax' = hypot(Lax, Lay)``,
    ``alpha' = alpha - atan2(Lay, Lax)``.

    Args:
        params: Any parameter set.

    Returns:
        The canonical equivalent parameter set.
    """
    _check_params(params)
    return dataclasses.replace(
        params,
        alpha=params.alpha - np.arctan2(params.Lay, params.Lax),
        Lax=np.hypot(params.Lax, params.Lay),
        Lay=np.zeros(3),
    )


# --------------------------------------------------------------------------- geometry


def _rot_z(theta: np.ndarray) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def _arm_terms(params: DeltaParams, q: np.ndarray):
    """Arm vector and its derivatives in the base frame.

    Returns arrays of shape (N, 3, 3) indexed [config, chain, xyz]: the arm vector
    ``a = Rz Ry(phi) [Lax,0,Lay]``, ``da/dphi``, ``da/dLax``, ``da/dLay``, and the
    tangential axis ``Rz e_y`` (shape (3, 3)).
    """
    phi = q + params.alpha[None, :]
    c, s = np.cos(phi), np.sin(phi)
    lax, lay = params.Lax[None, :], params.Lay[None, :]
    zero = np.zeros_like(phi)
    local = np.stack([lax * c + lay * s, zero, -lax * s + lay * c], -1)
    dlocal = np.stack([-lax * s + lay * c, zero, -lax * c - lay * s], -1)
    dlax = np.stack([c, zero, -s], -1)
    dlay = np.stack([s, zero, c], -1)
    rz = _rot_z(params.theta)  # (3, 3, 3) [chain, row, col]
    rot = lambda v: np.einsum("irc,nic->nir", rz, v)  # noqa: E731
    return rot(local), rot(dlocal), rot(dlax), rot(dlay)


def elbow_positions(params: DeltaParams, q) -> np.ndarray:
    """Elbow points ``B_i``.

    Args:
        params: Model-24 parameters.
        q: Joint readings, shape (N, 3), rad.

    Returns:
        Shape (N, 3, 3) [config, chain, xyz], mm, base frame.
    """
    _check_params(params)
    q = _joints(q)
    arm, *_ = _arm_terms(params, q)
    return params.shoulders()[None, :, :] + arm


def constraint_residuals(params: DeltaParams, q, positions) -> np.ndarray:
    """Closure residuals ``F_i = ||X - B_i|| - Lb_i`` (paper Eq. 3.8, distance form).

    Args:
        params: Model-24 parameters.
        q: Joint readings, shape (N, 3), rad.
        positions: Plate-centre positions X, shape (N, 3), mm, base frame.

    Returns:
        Shape (N, 3), mm; zero for consistent data.
    """
    q, positions = _closure_arguments(params, q, positions)
    b = elbow_positions(params, q)
    return np.linalg.norm(positions[:, None, :] - b, axis=-1) - params.Lb[None, :]


def _unit_forearm(params: DeltaParams, q: np.ndarray, positions: np.ndarray):
    arm, darm, dlax, dlay = _arm_terms(params, q)
    b = params.shoulders()[None] + arm
    d = positions[:, None, :] - b
    dist = np.linalg.norm(d, axis=-1)
    bad = np.argwhere(dist <= 1e-12)
    if bad.size:
        raise ValueError(f"configuration {int(bad[0, 0])}: plate point coincides with elbow {int(bad[0, 1]) + 1}")
    return d / dist[..., None], arm, darm, dlax, dlay


def constraint_jacobian_position(params: DeltaParams, q, positions) -> np.ndarray:
    """``dF_i/dX``: unit forearm vectors ``u_i = (X - B_i)/||X - B_i||``.

    Args:
        params: Model-24 parameters.
        q: Joint readings, shape (N, 3), rad.
        positions: Plate-centre positions, shape (N, 3), mm.

    Returns:
        Shape (N, 3, 3) [config, chain, xyz], dimensionless (the paper's ``J_chi``).
    """
    q, positions = _closure_arguments(params, q, positions)
    return _unit_forearm(params, q, positions)[0]


def constraint_jacobian_joints(params: DeltaParams, q, positions) -> np.ndarray:
    """``dF_i/dq_i`` (each closure depends only on its own joint).

    Args:
        params: Model-24 parameters.
        q: Joint readings, shape (N, 3), rad.
        positions: Plate-centre positions, shape (N, 3), mm.

    Returns:
        Shape (N, 3), mm/rad.
    """
    q, positions = _closure_arguments(params, q, positions)
    u, _, darm, _, _ = _unit_forearm(params, q, positions)
    return -np.einsum("nic,nic->ni", u, darm)


def constraint_jacobian_params(params: DeltaParams, q, positions) -> np.ndarray:
    """``dF_i/dP_i`` of each closure with respect to its own chain's eight parameters.

    Args:
        params: Model-24 parameters.
        q: Joint readings, shape (N, 3), rad.
        positions: Plate-centre positions, shape (N, 3), mm.

    Returns:
        Shape (N, 3, 8) [config, chain, parameter in Eq. 3.6 order]; units mm/mm for
        lengths, mm/rad for angles (the rows of the paper's Eq. 3.21).
    """
    q, positions = _closure_arguments(params, q, positions)
    u, arm, darm, dlax, dlay = _unit_forearm(params, q, positions)
    ez = np.array([0.0, 0.0, 1.0])
    dtheta = np.cross(ez[None, None, :], arm)  # d(arm)/dtheta = ez x arm
    out = np.empty(q.shape + (8,))
    out[..., 0:3] = -u
    out[..., 3] = -np.einsum("nic,nic->ni", u, dtheta)
    out[..., 4] = -np.einsum("nic,nic->ni", u, darm)
    out[..., 5] = -np.einsum("nic,nic->ni", u, dlax)
    out[..., 6] = -np.einsum("nic,nic->ni", u, dlay)
    out[..., 7] = -1.0
    return out


# --------------------------------------------------------------------------- IK / FK


def inverse_kinematics(params: DeltaParams, positions) -> np.ndarray:
    """Joint readings that put the plate centre at ``positions`` (elbows-out branch).

    Solves ``K cos(phi) + M sin(phi) = N`` per chain in closed form and returns
    ``q = phi - alpha`` wrapped to (-pi, pi].

    Args:
        params: Model-24 parameters.
        positions: Plate-centre positions, shape (N, 3), mm, base frame.

    Returns:
        Joint readings, shape (N, 3), rad.

    Raises:
        ValueError: Naming the configuration index and chain when a position is outside the
            workspace (the forearm cannot reach) or at a serial singularity (arm and
            forearm aligned).
    """
    _check_params(params)
    x = _positions(positions)
    rz = _rot_z(params.theta)
    v = np.einsum("irc,nir->nic", rz, x[:, None, :] - params.shoulders()[None])  # chain frame
    lax, lay, lb = params.Lax[None], params.Lay[None], params.Lb[None]
    k = v[..., 0] * lax + v[..., 2] * lay
    m = v[..., 0] * lay - v[..., 2] * lax
    n = 0.5 * (np.sum(v**2, -1) + lax**2 + lay**2 - lb**2)
    r = np.hypot(k, m)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = n / r
    unreachable = ~(np.abs(ratio) <= 1.0)
    if np.any(unreachable):
        c, i = np.argwhere(unreachable)[0]
        raise ValueError(
            f"configuration {c}: position {x[c].tolist()} is outside the workspace "
            f"(chain {i + 1} cannot reach it)"
        )
    singular = 1.0 - np.abs(ratio) < _SINGULAR_TOL
    if np.any(singular):
        c, i = np.argwhere(singular)[0]
        raise ValueError(
            f"configuration {c}: position {x[c].tolist()} is at a singularity "
            f"(arm and forearm of chain {i + 1} aligned)"
        )
    phi = np.arctan2(m, k) - np.arccos(ratio)
    q = phi - params.alpha[None]
    return np.angle(np.exp(1j * q))


def forward_kinematics(params: DeltaParams, q) -> np.ndarray:
    """Plate-centre positions from joint readings (intersection of three spheres).

    Of the two intersections the lower one (plate below the elbows) is returned.

    Args:
        params: Model-24 parameters.
        q: Joint readings, shape (N, 3), rad.

    Returns:
        Plate-centre positions, shape (N, 3), mm, base frame.

    Raises:
        ValueError: Naming the configuration index when the spheres do not intersect
            (outside the workspace) or the configuration is singular (elbows collinear, or
            the three forearms coplanar: a parallel singularity).
    """
    _check_params(params)
    q = _joints(q)
    b = elbow_positions(params, q)
    lb = params.Lb
    p1, p2, p3 = b[:, 0], b[:, 1], b[:, 2]
    d12 = p2 - p1
    d = np.linalg.norm(d12, axis=-1)
    scale = float(np.max(lb))
    ex = d12 / np.where(d > 0, d, 1.0)[:, None]
    d13 = p3 - p1
    i = np.einsum("nc,nc->n", ex, d13)
    eyv = d13 - i[:, None] * ex
    j = np.linalg.norm(eyv, axis=-1)
    degenerate = (d < _SINGULAR_TOL * scale) | (j < _SINGULAR_TOL * scale)
    if np.any(degenerate):
        c = int(np.argmax(degenerate))
        raise ValueError(f"configuration {c}: singular configuration (elbows collinear)")
    ey = eyv / j[:, None]
    ez = np.cross(ex, ey)
    xx = (lb[0] ** 2 - lb[1] ** 2 + d**2) / (2 * d)
    yy = (lb[0] ** 2 - lb[2] ** 2 + i**2 + j**2) / (2 * j) - i * xx / j
    z2 = lb[0] ** 2 - xx**2 - yy**2
    if np.any(z2 < 0):
        c = int(np.argmax(z2 < 0))
        raise ValueError(
            f"configuration {c}: joint readings {q[c].tolist()} are outside the workspace "
            f"(forearms cannot close on the plate)"
        )
    zz = np.sqrt(z2)
    if np.any(zz < 1e-6 * scale):
        c = int(np.argmax(zz < 1e-6 * scale))
        raise ValueError(f"configuration {c}: parallel singularity (forearms coplanar)")
    base = p1 + xx[:, None] * ex + yy[:, None] * ey
    up, down = base + zz[:, None] * ez, base - zz[:, None] * ez
    return np.where((up[:, 2] < down[:, 2])[:, None], up, down)


def fk_jacobian_params(params: DeltaParams, q) -> np.ndarray:
    """``dX/dP`` of the forward kinematics w.r.t. the 24 parameters (paper Eq. 3.17-3.18).

    ``dX/dP = -(J_chi)^-1 J_P`` with ``J_chi = dF/dX`` and ``J_P = dF/dP`` block-diagonal.

    Args:
        params: Model-24 parameters.
        q: Joint readings, shape (N, 3), rad.

    Returns:
        Shape (N, 3, 24), mm/mm or mm/rad, base frame, columns in :data:`PARAMETER_TABLE`
        order.

    Raises:
        ValueError: As :func:`forward_kinematics`.
    """
    x = forward_kinematics(params, q)
    q = _joints(q)
    jx = constraint_jacobian_position(params, q, x)
    jp_chain = constraint_jacobian_params(params, q, x)
    jp = np.zeros((q.shape[0], 3, 24))
    for i in range(3):
        jp[:, i, 8 * i : 8 * i + 8] = jp_chain[:, i]
    return -np.linalg.solve(jx, jp)


def fk_jacobian_joints(params: DeltaParams, q) -> np.ndarray:
    """``dX/dq`` of the forward kinematics (the manipulator Jacobian).

    Args:
        params: Model-24 parameters.
        q: Joint readings, shape (N, 3), rad.

    Returns:
        Shape (N, 3, 3) [config, xyz, joint], mm/rad, base frame.

    Raises:
        ValueError: As :func:`forward_kinematics`.
    """
    x = forward_kinematics(params, q)
    q = _joints(q)
    jx = constraint_jacobian_position(params, q, x)
    jq = constraint_jacobian_joints(params, q, x)
    return -np.linalg.solve(jx, jq[:, :, None] * np.eye(3)[None])


# --------------------------------------------------------------------------- robot interface

#: Names of a chain's eight parameters in the robot's table (``D.x`` -> ``D2.x``).
CHAIN_TABLE_NAMES: tuple[str, ...] = ("D.x", "D.y", "D.z", "theta", "alpha", "Lax", "Lay", "Lb")
#: Plate-centre home position of the default Delta, mm, base frame.
HOME_POSITION_MM = (0.0, 0.0, -420.0)
#: Default calibration workspace of the paper's Delta: a box in x, y and z, mm.
WORKSPACE_BOUNDS_MM = ((-150.0, 150.0), (-150.0, 150.0), (-500.0, -330.0))
#: Range of the actuated joints, rad.
JOINT_RANGE_RAD = (-np.pi / 2, np.pi / 2)


def _chain_name(template: str, chain: int) -> str:
    head, _, tail = template.partition(".")
    return f"{head}{chain + 1}" + (f".{tail}" if tail else "")


class Delta(Robot):
    """A Delta robot (three rotary-actuated parallelogram chains, translating plate), Model 24.

    Pose: the plate centre ``(x, y, z)`` in mm (the parallelograms hold the plate's orientation).
    Joints: the arm angles ``q1..q3`` read by the motors (rad). Parameters: the 24 of
    :class:`DeltaParams` named ``D{i}.x D{i}.y D{i}.z theta{i} alpha{i} Lax{i} Lay{i} Lb{i}``;
    ``Lay1..3`` are held by default (gauge: with the joint offset they form one unidentifiable
    direction per chain, see :func:`canonical_params`).

    Args:
        nominal: nominal parameters (default the paper's Delta).
        rn_mm: plate radius (centre to forearm attachment), mm: physical size of the machine
            built in MuJoCo; the kinematics use the reduced model.
        home_position_mm: (3,) home plate position, start of iterations.
        workspace_mm: (3, 2) calibration workspace box, mm.
        joint_ranges: (3, 2) rad, each motor's range as built (:attr:`Robot.joint_ranges`);
            None: :data:`JOINT_RANGE_RAD` for every motor.
    """

    name = "delta"
    pose_names = ("x", "y", "z")
    pose_units = ("mm", "mm", "mm")
    joint_unit = "rad"
    joint_symbol = "q"
    joint_zero_names = ("alpha1", "alpha2", "alpha3")
    chain_word = "chain"
    gauge_fixed = ("Lay1", "Lay2", "Lay3")
    #: Tolerance of the parameters, the default prior's standard deviation: 0.5 mm on lengths
    #: and 0.01 rad (0.6 degree) on angles. A Delta's arms and forearms are long welded or
    #: bonded tubes and its motors' zero is set by hand, looser than a machined part: the
    #: reference experiment's errors (its paper's primary study) reach 1 mm and 1 degree.
    default_parameter_tolerance = {"mm": 0.5, "rad": 0.01}

    def __init__(self, nominal: DeltaParams | None = None, *, rn_mm: float = NOMINAL_GEOMETRY["Rn_mm"],
                 home_position_mm=HOME_POSITION_MM, workspace_mm=WORKSPACE_BOUNDS_MM, joint_ranges=None):
        self.nominal_params = DeltaParams.nominal() if nominal is None else nominal
        _check_params(self.nominal_params)
        if not (np.isfinite(rn_mm) and rn_mm >= 0):
            raise ValueError(f"rn_mm must be finite and >= 0, got {rn_mm!r}")
        self.rn_mm = float(rn_mm)
        self._home = _as_array(home_position_mm, "home_position_mm", (3,))
        self._workspace = _as_array(workspace_mm, "workspace_mm", (3, 2))
        self.joint_ranges = checked_joint_ranges(joint_ranges, self)
        v = self.nominal_params.to_vector()
        self.table = ParameterTable([
            Parameter(_chain_name(t, c), CHAIN_PARAMETER_UNITS[k], float(v[8 * c + k]), c)
            for c in range(3) for k, t in enumerate(CHAIN_TABLE_NAMES)])

    @property
    def home_pose(self) -> np.ndarray:
        return self._home.copy()

    @property
    def length_scale_mm(self) -> float:
        return float(np.mean(np.hypot(self.nominal_params.Lax, self.nominal_params.Lay)))

    def workspace_bounds(self) -> np.ndarray:
        return self._workspace.copy()

    def default_joint_limits(self) -> np.ndarray:
        return np.tile(JOINT_RANGE_RAD, (3, 1))

    def description(self) -> dict:
        return {"parameters": self.table.to_dict(self.table.nominal), "rn_mm": self.rn_mm,
                "home_position_mm": self._home.tolist(), "workspace_mm": self._workspace.tolist(),
                **self.joint_ranges_description()}

    @classmethod
    def from_description(cls, description: dict) -> "Delta":
        names = [_chain_name(t, c) for c in range(3) for t in CHAIN_TABLE_NAMES]
        values = description["parameters"]
        missing = [n for n in names if n not in values]
        if missing:
            raise KeyError(f"parameters: missing {', '.join(missing)}")
        return cls(DeltaParams.from_vector([values[n] for n in names]),
                   rn_mm=description.get("rn_mm", NOMINAL_GEOMETRY["Rn_mm"]),
                   home_position_mm=description.get("home_position_mm", HOME_POSITION_MM),
                   workspace_mm=description.get("workspace_mm", WORKSPACE_BOUNDS_MM),
                   joint_ranges=description.get(JOINT_RANGES_KEY))

    @staticmethod
    def params(theta: np.ndarray) -> DeltaParams:
        """The structured :class:`DeltaParams` view of a flat parameter vector."""
        return DeltaParams.from_vector(theta)

    def chain_points(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """Physical points: actuated joint, elbow, plate attachment (the reduced model shifted by
        each chain's plate attachment of radius ``rn_mm``)."""
        p = self.params(theta)
        attach = self.rn_mm * np.stack([np.cos(p.theta), np.sin(p.theta), np.zeros(3)], axis=1)
        elbow = elbow_positions(p, joints) + attach[None]
        shoulder = np.broadcast_to(p.shoulders() + attach, elbow.shape)
        plate = poses[:, None, :] + attach[None]
        return np.stack([shoulder, elbow, plate], axis=2)

    def inverse_kinematics(self, theta: np.ndarray, poses: np.ndarray) -> np.ndarray:
        try:
            return inverse_kinematics(self.params(theta), poses)
        except ValueError as exc:
            raise KinematicsError(str(exc), _row_of(exc)) from None

    def forward_kinematics(self, theta: np.ndarray, joints: np.ndarray, *, initial=None) -> np.ndarray:
        try:
            return forward_kinematics(self.params(theta), joints)
        except ValueError as exc:
            raise KinematicsError(str(exc), _row_of(exc)) from None

    def _valid_params(self, theta: np.ndarray) -> DeltaParams:
        """:meth:`params`, an impossible vector (``Lb <= 0``, zero arm; a fit's trial step may
        propose one) raised as a :class:`KinematicsError`, as the engine expects of a robot."""
        try:
            return self.params(theta)
        except ValueError as exc:
            raise KinematicsError(f"theta: {exc}", 0) from None

    def closure(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        return constraint_residuals(self._valid_params(theta), joints, poses)

    def closure_jacobians(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> ClosureJacobians:
        p = self._valid_params(theta)
        n = joints.shape[0]
        jp = np.zeros((n, 3, 3, 8))
        idx = np.arange(3)
        jp[:, idx, idx] = constraint_jacobian_params(p, joints, poses)
        return ClosureJacobians(pose=constraint_jacobian_position(p, joints, poses),
                                joints=constraint_jacobian_joints(p, joints, poses)[:, :, None] * np.eye(3)[None],
                                parameters=jp.reshape(n, 3, 24))


def _row_of(exc: ValueError) -> int:
    """The configuration index named by a kinematics message (``configuration 12: ...``)."""
    text = str(exc)
    if text.startswith("configuration "):
        head = text[len("configuration "):].split(":", 1)[0]
        if head.isdigit():
            return int(head)
    return 0
