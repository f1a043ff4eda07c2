"""The hexapod (6-UPS Stewart-Gough platform): six legs of actuated length between base and platform.

Parameters (42, seven per leg, the hexapod paper's Table 3 order): ``B{i}.x B{i}.y B{i}.z`` the
base joint centre (mm, base frame), ``dl{i}`` the leg-length offset (mm: commanding length ``l``
makes the leg ``l + dl`` long), ``P{i}.x P{i}.y P{i}.z`` the platform joint centre (mm, platform
frame). Pose ``[x, y, z, alpha, beta, gamma]``, ``R = Rz(gamma) Ry(beta) Rx(alpha)``. Joints: the
commanded leg lengths ``l1..l6`` (mm). Closure of leg i (paper Eq. 1):
``F_i = |R P_i + t - B_i| - dl_i - l_i``.
"""

from __future__ import annotations

import numpy as np

from .. import paper
from ..validation import as_array
from ..robot import ClosureJacobians, Parameter, ParameterTable, Robot
from ..rotation import rotation_matrix

__all__ = ["Hexapod", "LEG_PARAMETERS", "DEFAULT_STROKE_MM", "paper_hexapod", "PAPER_WORKSPACE_HALF_WIDTHS",
           "FULL_WORKSPACE_OFFSETS"]

#: Names of a leg's seven parameters, before the leg number (``B.x`` -> ``B3.x``).
LEG_PARAMETERS = ("B.x", "B.y", "B.z", "dl", "P.x", "P.y", "P.z")
#: Default stroke of each leg about its home length, mm.
DEFAULT_STROKE_MM = 50.0
#: The paper's Table 4 workspace about the home pose: x, y within +-10 mm, z from 0 to +10 mm,
#: angles within +-3 degrees ((6, 2) low/high offsets, mm and rad).
PAPER_WORKSPACE_HALF_WIDTHS = np.array([
    [-10.0, 10.0], [-10.0, 10.0], [0.0, 10.0],
    [-np.deg2rad(3.0), np.deg2rad(3.0)], [-np.deg2rad(3.0), np.deg2rad(3.0)],
    [-np.deg2rad(3.0), np.deg2rad(3.0)],
])

#: The machine's whole design workspace about the home pose ((6, 2) low/high offsets, mm and
#: rad): x, y within +-80 mm, z from -50 to +60 mm (150 ... 260 mm for the paper's machine),
#: angles within +-25 degrees; :mod:`calib.design` keeps the feasible poses of this box.
FULL_WORKSPACE_OFFSETS = np.array([
    [-80.0, 80.0], [-80.0, 80.0], [-50.0, 60.0],
    [-np.deg2rad(25.0), np.deg2rad(25.0)], [-np.deg2rad(25.0), np.deg2rad(25.0)],
    [-np.deg2rad(25.0), np.deg2rad(25.0)],
])


def _leg_name(template: str, leg: int) -> str:
    head, _, tail = template.partition(".")
    return f"{head}{leg + 1}" + (f".{tail}" if tail else "")


class Hexapod(Robot):
    """A hexapod's nominal geometry.

    Args:
        base_joints: (6, 3) mm, nominal base joint centres, base frame.
        platform_joints: (6, 3) mm, nominal platform joint centres, platform frame.
        home_lengths: (6,) mm, leg lengths at ``home_pose``.
        home_pose: (6,) the pose the home lengths refer to; start of the forward kinematics.
        stroke_mm: each leg accepts ``home length +- stroke_mm``.
    """

    name = "hexapod"
    pose_names = ("x", "y", "z", "alpha", "beta", "gamma")
    pose_units = ("mm", "mm", "mm", "rad", "rad", "rad")
    joint_unit = "mm"
    joint_symbol = "l"
    chain_word = "leg"

    def __init__(self, base_joints, platform_joints, home_lengths, home_pose=paper.TABLE2_HOME_POSE,
                 stroke_mm: float = DEFAULT_STROKE_MM):
        self.base_joints = as_array(base_joints, "base_joints", (6, 3))
        self.platform_joints = as_array(platform_joints, "platform_joints", (6, 3))
        self.home_lengths = as_array(home_lengths, "home_lengths", (6,))
        self._home_pose = as_array(home_pose, "home_pose", (6,))
        if not (np.isfinite(stroke_mm) and stroke_mm > 0):
            raise ValueError(f"stroke_mm must be > 0, got {stroke_mm!r}")
        self.stroke_mm = float(stroke_mm)
        for a in (self.base_joints, self.platform_joints, self.home_lengths, self._home_pose):
            a.setflags(write=False)
        nominal = np.concatenate([self.base_joints, np.zeros((6, 1)), self.platform_joints], axis=1)
        self.table = ParameterTable([
            Parameter(_leg_name(t, leg), "mm", float(nominal[leg, k]), leg)
            for leg in range(6) for k, t in enumerate(LEG_PARAMETERS)])

    # -- description ----------------------------------------------------------------------
    @property
    def home_pose(self) -> np.ndarray:
        return self._home_pose

    @property
    def length_scale_mm(self) -> float:
        return float(np.linalg.norm(self.platform_joints, axis=1).mean())

    def workspace_bounds(self) -> np.ndarray:
        return self._home_pose[:, None] + PAPER_WORKSPACE_HALF_WIDTHS

    def joint_limits(self) -> np.ndarray:
        return np.stack([self.home_lengths - self.stroke_mm, self.home_lengths + self.stroke_mm], axis=1)

    def full_workspace_bounds(self) -> np.ndarray:
        return self._home_pose[:, None] + FULL_WORKSPACE_OFFSETS

    def passive_joint_angles(self, theta: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, 12) rad, leg by leg: the angle between the leg and the base normal (z of the base
        frame) at its base joint, then between the leg and the platform normal (z of the
        platform frame) at its platform joint: what a spherical or universal joint allows."""
        L, R = self.leg_vectors(theta, poses)
        u = L / np.linalg.norm(L, axis=-1, keepdims=True)
        base = np.arccos(np.clip(u[..., 2], -1.0, 1.0))
        platform = np.arccos(np.clip(np.einsum("nli,ni->nl", u, R[:, :, 2]), -1.0, 1.0))
        return np.stack([base, platform], axis=-1).reshape(len(poses), 12)

    def description(self) -> dict:
        return {"base_joints_mm": self.base_joints.tolist(), "platform_joints_mm": self.platform_joints.tolist(),
                "home_lengths_mm": self.home_lengths.tolist(), "home_pose": self._home_pose.tolist(),
                "stroke_mm": self.stroke_mm}

    @classmethod
    def from_description(cls, description: dict) -> "Hexapod":
        return cls(description["base_joints_mm"], description["platform_joints_mm"],
                   description["home_lengths_mm"], description.get("home_pose", paper.TABLE2_HOME_POSE),
                   description.get("stroke_mm", DEFAULT_STROKE_MM))

    # -- parameter layout -----------------------------------------------------------------
    @staticmethod
    def legs(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(B, dl, P)``: (6, 3) base joints, (6,) offsets, (6, 3) platform joints of ``theta``."""
        t = np.asarray(theta, dtype=float).reshape(6, 7)
        return t[:, 0:3], t[:, 3], t[:, 4:7]

    def leg_vectors(self, theta: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(L, R)``: (N, 6, 3) leg vectors ``R P_i + t - B_i`` (mm, base frame), (N, 3, 3) rotations."""
        B, _, P = self.legs(theta)
        R = rotation_matrix(poses[:, 3:6])
        L = np.einsum("nij,lj->nli", R, P) + poses[:, None, 0:3] - B[None]
        return L, R

    def chain_points(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        B, _, _ = self.legs(theta)
        L, _ = self.leg_vectors(theta, poses)
        base = np.broadcast_to(B, L.shape)
        return np.stack([base, base + L], axis=2)

    # -- kinematics -----------------------------------------------------------------------
    def inverse_kinematics(self, theta: np.ndarray, poses: np.ndarray) -> np.ndarray:
        return self._leg_geometry(theta, poses)[3] - self.legs(theta)[1]

    def closure(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        return self.inverse_kinematics(theta, poses) - joints

    def _leg_geometry(self, theta: np.ndarray, poses: np.ndarray):
        """``(R, w, L, norm, sg, cg)``: (N, 3, 3) rotations, ``w = R P_i`` and leg vectors
        ``L = R P_i + t - B_i`` as three (N, 6) coordinate arrays each, (N, 6) leg lengths
        ``|L|`` and (N, 1) ``sin``/``cos`` of gamma. Written coordinate by coordinate on (N, 6)
        arrays, the fastest numpy layout for these small vectors."""
        B, _, P = self.legs(theta)
        n = poses.shape[0]
        c, s = np.cos(poses[:, 3:6]), np.sin(poses[:, 3:6])
        ca, cb, cg = c[:, 0:1], c[:, 1:2], c[:, 2:3]  # (N, 1) columns, broadcast over the legs
        sa, sb, sg = s[:, 0:1], s[:, 1:2], s[:, 2:3]
        R = np.empty((n, 3, 3))
        R[:, 0, 0:1] = cg * cb
        R[:, 0, 1:2] = cg * sb * sa - sg * ca
        R[:, 0, 2:3] = cg * sb * ca + sg * sa
        R[:, 1, 0:1] = sg * cb
        R[:, 1, 1:2] = sg * sb * sa + cg * ca
        R[:, 1, 2:3] = sg * sb * ca - cg * sa
        R[:, 2, 0:1] = -sb
        R[:, 2, 1:2] = cb * sa
        R[:, 2, 2:3] = cb * ca
        Px, Py, Pz = P[:, 0], P[:, 1], P[:, 2]
        w = [R[:, i, 0:1] * Px + R[:, i, 1:2] * Py + R[:, i, 2:3] * Pz for i in range(3)]
        L = [w[i] + (poses[:, i:i + 1] - B[:, i]) for i in range(3)]
        norm = np.sqrt(L[0] * L[0] + L[1] * L[1] + L[2] * L[2])
        return R, w, L, norm, sg, cg

    def _legs_and_pose_jacobian(self, theta: np.ndarray, poses: np.ndarray, closure_of=None):
        """One pass over the legs: ``(Jt, R, r)``: (N, 6, 6) ``dF / d pose`` *transposed*
        (``Jt[n, k, i] = dF_i / d pose_k``; ``Jt[:, 0:3]`` are the unit leg vectors), (N, 3, 3)
        rotations and, when ``closure_of`` (the joints, (N, 6)) is given, (N, 6) closure
        residuals (else None).

        With ``w_i = R P_i`` and ``R = Rz Ry Rx``, the angle columns are
        ``dF_i/d alpha = (R e_x) . (w_i x u_i)``, ``dF_i/d beta = (Rz e_y) . (w_i x u_i)``,
        ``dF_i/d gamma = e_z . (w_i x u_i)`` (as ``dR/d alpha = R [e_x]x``, ``dR/d beta =
        [Rz e_y]x R``, ``dR/d gamma = [e_z]x R``): no derivative matrices, one cross product."""
        R, w, L, norm, sg, cg = self._leg_geometry(theta, poses)
        inv = 1.0 / norm
        Jt = np.empty((poses.shape[0], 6, 6))
        for i in range(3):
            np.multiply(L[i], inv, out=Jt[:, i])
        ux, uy, uz = Jt[:, 0], Jt[:, 1], Jt[:, 2]
        mx = w[1] * uz - w[2] * uy  # m = w x u
        my = w[2] * ux - w[0] * uz
        mz = w[0] * uy - w[1] * ux
        Jt[:, 3] = R[:, 0, 0:1] * mx + R[:, 1, 0:1] * my + R[:, 2, 0:1] * mz
        Jt[:, 4] = cg * my - sg * mx
        Jt[:, 5] = mz
        r = None if closure_of is None else (norm - self.legs(theta)[1]) - closure_of
        return Jt, R, r

    def _pose_jacobian(self, theta: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(Jpose, u, R)``: (N, 6, 6) ``dF / d pose``, (N, 6, 3) unit leg vectors, (N, 3, 3)
        rotations; one computation for :meth:`closure_jacobians` and :meth:`closure_pose_jacobian`."""
        Jt, R, _ = self._legs_and_pose_jacobian(theta, poses)
        J = np.ascontiguousarray(Jt.transpose(0, 2, 1))
        return J, J[:, :, 0:3], R

    def closure_pose_jacobian(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        return self._pose_jacobian(theta, poses)[0]

    def closure_and_pose_jacobian(self, theta: np.ndarray, joints: np.ndarray,
                                  poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Jt, _, r = self._legs_and_pose_jacobian(theta, poses, closure_of=joints)
        return r, Jt.transpose(0, 2, 1)

    def closure_jacobians(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> ClosureJacobians:
        Jpose, u, R = self._pose_jacobian(theta, poses)
        n = poses.shape[0]
        Jleg = np.empty((n, 6, 7))
        Jleg[:, :, 0:3] = -u
        Jleg[:, :, 3] = -1.0
        Jleg[:, :, 4:7] = np.einsum("nji,nlj->nli", R, u)  # R^T u
        Jtheta = np.zeros((n, 6, 6, 7))
        idx = np.arange(6)
        Jtheta[:, idx, idx] = Jleg
        return ClosureJacobians(pose=Jpose, joints=np.broadcast_to(-np.eye(6), (n, 6, 6)).copy(),
                                parameters=Jtheta.reshape(n, 6, 42))


def paper_hexapod() -> Hexapod:
    """The hexapod of the paper's Table 2 (its Table 3 errors: :data:`calib.paper.TABLE3_ERRORS`)."""
    return Hexapod(paper.TABLE2_BASE_JOINTS_MM, paper.TABLE2_PLATFORM_JOINTS_MM,
                   paper.TABLE2_HOME_LENGTHS_MM, paper.TABLE2_HOME_POSE)
