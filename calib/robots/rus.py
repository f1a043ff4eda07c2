"""The rotary hexapod (6-RUS Stewart platform): six base motors, each turning a crank whose tip
drives a rod with spherical joints at both ends up to the platform (motion simulators, small
hexapod kits).

Parameters (66, eleven per chain i = 1..6, :data:`CHAIN_PARAMETERS` order):

* ``M{i}.x M{i}.y M{i}.z`` (mm, base frame): the motor's crank-circle centre;
* ``a{i}.az a{i}.el`` (rad): the motor axis ``a = (cos el cos az, cos el sin az, sin el)``;
* ``r{i}`` (mm): crank length; ``q0_{i}`` (rad): motor zero offset; ``s{i}`` (mm): rod length;
* ``P{i}.x P{i}.y P{i}.z`` (mm, platform frame): the rod's platform joint centre.

Crank frame: ``u = da/daz / cos(el) = (-sin az, cos az, 0)``, ``v = da/del =
(-sin el cos az, -sin el sin az, cos el)``; ``(u, v, a)`` is right-handed and orthonormal, a
smooth function of the axis angles (singular only for a vertical axis, ``cos el = 0``). The
crank tip is ``C_i = M_i + r_i (cos phi_i u_i + sin phi_i v_i)``, ``phi_i = q_i + q0_i``: a
positive ``q_i`` turns the crank positively about ``a_i``. Closure of chain i (mm):
``F_i = |R P_i + t - C_i| - s_i``. Pose ``[x, y, z, alpha, beta, gamma]`` (mm, rad),
``R = Rz(gamma) Ry(beta) Rx(alpha)``; joints the motor angles ``q1..q6`` (rad).
"""

from __future__ import annotations

import numpy as np

from ..validation import as_array
from ..robot import (JOINT_RANGES_KEY, ClosureJacobians, KinematicsError, Parameter, ParameterTable, Robot,
                     checked_joint_ranges)
from ..rotation import length_pose_jacobian, rotation_entries, rotation_matrix

__all__ = ["RotaryHexapod", "CHAIN_PARAMETERS", "CHAIN_UNITS", "WORKSPACE_HALF_WIDTHS",
           "JOINT_RANGE_RAD", "crank_frames", "default_rotary_hexapod"]

#: Names of a chain's eleven parameters; ``{i}`` is the 1-based chain number.
CHAIN_PARAMETERS = ("M{i}.x", "M{i}.y", "M{i}.z", "a{i}.az", "a{i}.el", "r{i}", "q0_{i}", "s{i}",
                    "P{i}.x", "P{i}.y", "P{i}.z")
#: Unit of each of :data:`CHAIN_PARAMETERS`.
CHAIN_UNITS = ("mm", "mm", "mm", "rad", "rad", "mm", "rad", "mm", "mm", "mm", "mm")
#: Default calibration workspace about the home pose, (6, 2) low/high offsets (mm, rad); every
#: corner of it is reachable by the default machine with motor angles within +-43 degrees.
WORKSPACE_HALF_WIDTHS = np.array([[-12.0, 12.0], [-12.0, 12.0], [-8.0, 8.0],
                                  [-np.deg2rad(4.0), np.deg2rad(4.0)], [-np.deg2rad(4.0), np.deg2rad(4.0)],
                                  [-np.deg2rad(4.0), np.deg2rad(4.0)]])
#: Default range of every motor angle, rad (low, high).
JOINT_RANGE_RAD = (-np.deg2rad(80.0), np.deg2rad(80.0))


def crank_frames(az: np.ndarray, el: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(u, v, a)``, each (..., 3): the crank frame of motor axes given by angles (rad)."""
    ca, sa, ce, se = np.cos(az), np.sin(az), np.cos(el), np.sin(el)
    z = np.zeros_like(ca)
    return (np.stack([-sa, ca, z], -1), np.stack([-se * ca, -se * sa, ce], -1),
            np.stack([ce * ca, ce * sa, se], -1))


class RotaryHexapod(Robot):
    """A 6-RUS rotary hexapod's nominal geometry.

    Args:
        chains: (6, 11) nominal parameters, one row per chain in :data:`CHAIN_PARAMETERS`
            order (mm, rad).
        home_pose: (6,) the home pose, start of the forward kinematics.
        workspace_half_widths: (6, 2) calibration workspace about the home pose (mm, rad).
        joint_range_rad: (2,) accepted range of every motor angle, rad (when no ``joint_ranges``).
        joint_ranges: (6, 2) rad, each motor's range as built (:attr:`Robot.joint_ranges`);
            None: ``joint_range_rad`` for every motor.
    """

    name = "rus"
    pose_names = ("x", "y", "z", "alpha", "beta", "gamma")
    pose_units = ("mm", "mm", "mm", "rad", "rad", "rad")
    joint_unit = "rad"
    joint_symbol = "q"
    joint_zero_names = tuple(f"q0_{i}" for i in range(1, 7))
    chain_word = "chain"
    #: Tolerance of the parameters, the default prior's standard deviation: 0.2 mm on lengths
    #: and 5e-3 rad on angles. Motor mounts, crank and rod lengths and joint centres of a
    #: machined 6-RUS, assembled (crank clamping and the motors' zero set by hand add to the
    #: parts' own tolerance); the reference experiment's errors are within 0.5 mm and 0.5 degree.
    default_parameter_tolerance = {"mm": 0.2, "rad": 5e-3}

    def __init__(self, chains, home_pose, workspace_half_widths=WORKSPACE_HALF_WIDTHS,
                 joint_range_rad=JOINT_RANGE_RAD, joint_ranges=None):
        self.chains = as_array(chains, "chains", (6, len(CHAIN_PARAMETERS)))
        self._home_pose = as_array(home_pose, "home_pose", (6,))
        self.workspace_half_widths = as_array(workspace_half_widths, "workspace_half_widths", (6, 2))
        self.joint_range_rad = as_array(joint_range_rad, "joint_range_rad", (2,))
        if not np.all(self.chains[:, [5, 7]] > 0):
            raise ValueError("chains: crank lengths r and rod lengths s must be > 0")
        if not self.joint_range_rad[0] < self.joint_range_rad[1]:
            raise ValueError(f"joint_range_rad must be (low, high) with low < high, got {self.joint_range_rad}")
        for a in (self.chains, self._home_pose, self.workspace_half_widths, self.joint_range_rad):
            a.setflags(write=False)
        self.joint_ranges = checked_joint_ranges(joint_ranges, self)
        self.table = ParameterTable([
            Parameter(t.format(i=c + 1), CHAIN_UNITS[k], float(self.chains[c, k]), c)
            for c in range(6) for k, t in enumerate(CHAIN_PARAMETERS)])

    # -- description ----------------------------------------------------------------------
    @property
    def home_pose(self) -> np.ndarray:
        return self._home_pose

    @property
    def length_scale_mm(self) -> float:
        return float(np.linalg.norm(self.chains[:, 8:11], axis=1).mean())

    def workspace_bounds(self) -> np.ndarray:
        return self._home_pose[:, None] + self.workspace_half_widths

    def default_joint_limits(self) -> np.ndarray:
        return np.tile(self.joint_range_rad, (6, 1))

    def description(self) -> dict:
        return {"parameters": self.table.to_dict(self.table.nominal), "home_pose": self._home_pose.tolist(),
                "workspace_half_widths": self.workspace_half_widths.tolist(),
                "joint_range_rad": self.joint_range_rad.tolist(), **self.joint_ranges_description()}

    @classmethod
    def from_description(cls, description: dict) -> "RotaryHexapod":
        values = description["parameters"]
        names = [t.format(i=c + 1) for c in range(6) for t in CHAIN_PARAMETERS]
        missing = [n for n in names if n not in values]
        if missing:
            raise KeyError(f"parameters: missing {', '.join(missing)}")
        return cls(np.reshape([values[n] for n in names], (6, len(CHAIN_PARAMETERS))), description["home_pose"],
                   description.get("workspace_half_widths", WORKSPACE_HALF_WIDTHS),
                   description.get("joint_range_rad", JOINT_RANGE_RAD), description.get(JOINT_RANGES_KEY))

    # -- parameter layout -----------------------------------------------------------------
    @staticmethod
    def split(theta: np.ndarray) -> dict[str, np.ndarray]:
        """Named views of ``theta``: ``M`` (6, 3), ``az el r q0 s`` (6,), ``P`` (6, 3), mm/rad."""
        t = np.asarray(theta, dtype=float).reshape(6, len(CHAIN_PARAMETERS))
        return {"M": t[:, 0:3], "az": t[:, 3], "el": t[:, 4], "r": t[:, 5], "q0": t[:, 6], "s": t[:, 7],
                "P": t[:, 8:11]}

    def _chain_parts(self, theta) -> dict:
        """:meth:`split`'s views of ``theta`` with what the kinematics derive from them alone: the
        crank frames ``u v a`` (6, 3), ``u_t v_t M_t`` (3, 6, 1) their chain-major columns, ``cos_az
        sin_az sin_el`` (6, 1). Kept for the last ``theta`` asked (a Newton iteration asks for one
        ``theta`` many times); read-only."""
        t = np.asarray(theta, dtype=float)
        key = t.tobytes()
        kept = self.__dict__.get("_parts")
        if kept is not None and kept[0] == key:
            return kept[1]
        p = self.split(t.copy())
        p["u"], p["v"], p["a"] = crank_frames(p["az"], p["el"])
        p["u_t"], p["v_t"], p["M_t"] = (p[k].T[:, :, None].copy() for k in ("u", "v", "M"))
        p["cos_az"], p["sin_az"], p["sin_el"] = (f(p[k])[:, None] for f, k in ((np.cos, "az"), (np.sin, "az"),
                                                                                (np.sin, "el")))
        for v in p.values():
            v.setflags(write=False)
        self.__dict__["_parts"] = (key, p)
        return p

    def _vectors(self, theta, joints, poses):
        """Chain-major (each quantity (3, 6, N) or (6, N): numpy's inner loops then run over the
        poses, several times faster than over the chains of an (N, 6, 3) array): ``(p, R, c, s,
        e, w, C, D)`` with ``p`` :meth:`split`'s views, the crank frames ``u v a`` (6, 3) and the
        yaw's ``cos_gamma sin_gamma`` (N,); ``R`` (3, 3, N) the rotations' entries; ``c, s`` (6,
        N) cos and sin of ``phi``; ``e`` (3, 6, N) the crank directions; ``w = R P``, the crank
        tips ``C`` and the rod vectors ``D = R P + t - C``, each (3, 6, N) mm."""
        p = self._chain_parts(theta)
        x = np.ascontiguousarray(np.asarray(poses, dtype=float).T)  # (6, N)
        phi = np.asarray(joints, dtype=float).T + p["q0"][:, None]
        c, s = np.cos(phi), np.sin(phi)
        R, cos, sin = rotation_entries(x[3:6])
        p = dict(p, cos_gamma=cos[2], sin_gamma=sin[2])
        e = c * p["u_t"] + s * p["v_t"]
        C = p["M_t"] + p["r"][:, None] * e
        w = np.einsum("ikn,lk->iln", R, p["P"])
        D = (w + x[0:3, None, :]) - C
        return p, R, c, s, e, w, C, D

    def _chains(self, theta, joints, poses, jacobian: bool = False, parameters: bool = False):
        """One pass over the six chains at N poses (:meth:`_vectors`' layout).

        Returns ``(F, Jt, Jc, dq)``:

        * ``F`` (6, N) mm: the closure ``|D_i| - s_i``;
        * ``Jt`` (6, 6, N) (``jacobian``; else None): ``Jt[i, k, n] = dF_i / d pose_k``. With
          ``n_i = D_i / |D_i|``, ``w_i = R P_i`` and ``m_i = w_i x n_i``: ``dF_i/d t = n_i``,
          ``dF_i/d alpha = (R e_x) . m_i``, ``dF_i/d beta = (Rz e_y) . m_i``, ``dF_i/d gamma =
          e_z . m_i`` (``dR/d alpha = R [e_x]x``, ``dR/d beta = [Rz e_y]x R``, ``dR/d gamma =
          [e_z]x R``);
        * ``Jc`` (6, 11, N) (``parameters``; else None): ``dF_i / d`` chain i's own eleven
          parameters (:data:`CHAIN_PARAMETERS` order); ``dq`` (6, N): ``dF_i / d q_i`` (also
          ``dF_i / d q0_i``), with ``parameters``.
        """
        p, R, c, s, e, w, C, D = self._vectors(theta, joints, poses)
        norm = np.sqrt(np.einsum("iln,iln->ln", D, D))
        F = norm - p["s"][:, None]
        if not (jacobian or parameters):
            return F, None, None, None
        n = D / norm  # (3, 6, N) unit rod directions
        n0, n1, n2 = n
        Jt = Jc = dq = None
        if jacobian:
            Jt = length_pose_jacobian(n, w, R, p["cos_gamma"], p["sin_gamma"])
        if parameters:
            r = p["r"][:, None]
            nu, nv, na = (np.einsum("iln,li->ln", n, p[k]) for k in ("u", "v", "a"))
            ca, sa, se = p["cos_az"], p["sin_az"], p["sin_el"]
            Jc = np.empty((6, len(CHAIN_PARAMETERS), n.shape[2]))
            np.negative(n.transpose(1, 0, 2), out=Jc[:, 0:3])
            # du/daz = (-cos az, -sin az, 0), dv/daz = sin el (sin az, -cos az, 0)
            Jc[:, 3] = -r * (c * (-ca * n0 - sa * n1) + s * (se * (sa * n0 - ca * n1)))
            Jc[:, 4] = r * s * na  # dv/del = -a, du/del = 0
            Jc[:, 5] = -(c * nu + s * nv)
            dq = -r * (c * nv - s * nu)  # crank tangent -sin(phi) u + cos(phi) v
            Jc[:, 6] = dq
            Jc[:, 7] = -1.0
            np.einsum("ikn,iln->lkn", R, n, out=Jc[:, 8:11])  # R^T n_l
        return F, Jt, Jc, dq

    def chain_points(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, 6, 3, 3) mm: motor centre ``M_i``, crank tip ``C_i``, platform joint ``R P_i + t``."""
        p, _, _, _, _, _, C, D = self._vectors(theta, joints, poses)
        C, D = C.transpose(2, 1, 0), D.transpose(2, 1, 0)
        return np.stack([np.broadcast_to(p["M"], C.shape), C, C + D], axis=2)

    # -- kinematics -----------------------------------------------------------------------
    def closure(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        return self._chains(theta, joints, poses)[0].T

    def closure_pose_jacobian(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        return self._chains(theta, joints, poses, jacobian=True)[1].transpose(2, 0, 1)

    def closure_and_pose_jacobian(self, theta: np.ndarray, joints: np.ndarray,
                                  poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        F, Jt, _, _ = self._chains(theta, joints, poses, jacobian=True)
        return F.T, Jt.transpose(2, 0, 1)

    def closure_jacobians(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> ClosureJacobians:
        return self.closure_with_jacobians(theta, joints, poses)[1]

    def closure_with_jacobians(self, theta: np.ndarray, joints: np.ndarray,
                               poses: np.ndarray) -> tuple[np.ndarray, ClosureJacobians]:
        F, Jt, Jc, dq = self._chains(theta, joints, poses, jacobian=True, parameters=True)
        n_rows = F.shape[1]
        idx = np.arange(6)
        Jq = np.zeros((n_rows, 6, 6))
        Jq[:, idx, idx] = dq.T
        # contiguous: LAPACK's batched inverse and solve take it faster than the view. Each
        # chain's closure moves with its own parameters alone (the table's chain by chain order):
        # the (N, P) own entries, the dense (N, 6, P) built only where asked for.
        return F.T, ClosureJacobians(pose=np.ascontiguousarray(Jt.transpose(2, 0, 1)), joints=Jq,
                                     own=Jc.transpose(2, 0, 1).reshape(n_rows, -1), chains=self.table.chains)

    def inverse_kinematics(self, theta: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, 6) motor angles, rad, wrapped to (-pi, pi].

        Per chain, with ``d = R P + t - M``, the closure squared reads ``K cos phi + L sin phi =
        N`` with ``K = 2 r d.u``, ``L = 2 r d.v``, ``N = |d|^2 + r^2 - s^2``. Branch:
        ``phi = atan2(L, K) - arccos(N / hypot(K, L))``, the crank turned negatively about
        ``a`` from the direction of the platform joint (seen along ``a``), which is the
        assembly of :func:`default_rotary_hexapod` (cranks pointing away from their pair partner).

        Raises:
            KinematicsError: the rod cannot reach (``|N| > hypot(K, L)``) or crank and rod are
                aligned (serial singularity); names the row and the chain.
        """
        p = self.split(theta)
        u, v, _ = crank_frames(p["az"], p["el"])
        R = rotation_matrix(poses[:, 3:6])
        d = np.einsum("nij,lj->nli", R, p["P"]) + poses[:, None, 0:3] - p["M"][None]
        r, s = p["r"][None], p["s"][None]
        K = 2.0 * r * np.einsum("nli,li->nl", d, u)
        L = 2.0 * r * np.einsum("nli,li->nl", d, v)
        N = np.einsum("nli,nli->nl", d, d) + r ** 2 - s ** 2
        rho = np.hypot(K, L)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = N / rho
        bad = ~(np.abs(ratio) < 1.0 - 1e-12)
        if np.any(bad):
            row, chain = (int(x) for x in np.argwhere(bad)[0])
            why = "cannot reach" if not np.abs(ratio[row, chain]) <= 1.0 else "is aligned with its crank (singular)"
            raise KinematicsError(f"row {row} is unreachable: the rod of {self.chain_word} {chain + 1} {why} "
                                  f"(pose {np.array2string(poses[row], precision=4)})", row)
        q = np.arctan2(L, K) - np.arccos(ratio) - p["q0"][None]
        return np.angle(np.exp(1j * q))


def default_rotary_hexapod(base_radius_mm: float = 150.0, platform_radius_mm: float = 100.0,
                           crank_mm: float = 40.0, rod_mm: float = 200.0, base_half_angle_deg: float = 20.0,
                           platform_half_angle_deg: float = 10.0) -> RotaryHexapod:
    """A nominal rotary hexapod with motors and platform joints in pairs (not singular).

    Motors sit in three pairs at ``120 k +- base_half_angle_deg`` on the base circle (z = 0),
    axes horizontal and radial, each crank pointing tangentially away from its partner at
    ``q = 0`` (``q0 = 0``). Platform joints pair at ``60 + 120 k -+ platform_half_angle_deg``,
    each joined to the nearer motor of the neighbouring pair. The home pose puts the platform
    level at the height where every rod is ``rod_mm`` long with the cranks horizontal
    (home joints all zero).
    """
    rows, tips, plat = [], [], []
    for k in range(3):
        for sign in (-1.0, 1.0):
            ang = np.deg2rad(120.0 * k + sign * base_half_angle_deg)
            # sign +1: axis outward (u = +tangent, counter-clockwise); -1: inward (u clockwise).
            az = ang if sign > 0 else ang + np.pi
            M = base_radius_mm * np.array([np.cos(ang), np.sin(ang), 0.0])
            u, _, _ = crank_frames(np.array(az), np.array(0.0))
            tips.append(M + crank_mm * u)
            pa = np.deg2rad(120.0 * k + sign * (60.0 - platform_half_angle_deg))
            plat.append(platform_radius_mm * np.array([np.cos(pa), np.sin(pa), 0.0]))
            rows.append([*M, np.angle(np.exp(1j * az)), 0.0, crank_mm, 0.0, rod_mm, *plat[-1]])
    horizontal = np.linalg.norm(np.array(plat)[:, :2] - np.array(tips)[:, :2], axis=1)
    if not np.all(horizontal < rod_mm):
        raise ValueError(f"rod_mm = {rod_mm} is too short to reach the platform")
    height = float(np.sqrt(rod_mm ** 2 - horizontal[0] ** 2))
    return RotaryHexapod(np.array(rows), [0.0, 0.0, height, 0.0, 0.0, 0.0])
