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
from ..robot import JOINT_RANGES_KEY, ClosureJacobians, Parameter, ParameterTable, Robot, checked_joint_ranges
from ..rotation import length_pose_jacobian, rotation_entries, rotation_matrix

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
        stroke_mm: each leg accepts ``home length +- stroke_mm`` (when no ``joint_ranges``).
        joint_ranges: (6, 2) mm, each leg's commanded length from fully retracted to fully
            extended, as built (:attr:`Robot.joint_ranges`); None: ``home length +- stroke_mm``.
    """

    name = "hexapod"
    pose_names = ("x", "y", "z", "alpha", "beta", "gamma")
    pose_units = ("mm", "mm", "mm", "rad", "rad", "rad")
    joint_unit = "mm"
    joint_symbol = "l"
    joint_zero_names = tuple(f"dl{i}" for i in range(1, 7))
    chain_word = "leg"
    #: Tolerance of every parameter (all lengths), mm: the default prior's standard deviation.
    #: 0.1 mm: the joint centres of a machined base and platform and a leg's length offset, as
    #: built and assembled to a precision hexapod's drawing (ISO 2768-f gives +-0.15 mm for
    #: 120-400 mm; the paper's Table 3 errors are within +-0.05 mm).
    default_parameter_tolerance = {"mm": 0.1}

    def __init__(self, base_joints, platform_joints, home_lengths, home_pose=paper.TABLE2_HOME_POSE,
                 stroke_mm: float = DEFAULT_STROKE_MM, joint_ranges=None):
        self.base_joints = as_array(base_joints, "base_joints", (6, 3))
        self.platform_joints = as_array(platform_joints, "platform_joints", (6, 3))
        self.home_lengths = as_array(home_lengths, "home_lengths", (6,))
        self._home_pose = as_array(home_pose, "home_pose", (6,))
        if not (np.isfinite(stroke_mm) and stroke_mm > 0):
            raise ValueError(f"stroke_mm must be > 0, got {stroke_mm!r}")
        self.stroke_mm = float(stroke_mm)
        self.joint_ranges = checked_joint_ranges(joint_ranges, self)
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

    def default_joint_limits(self) -> np.ndarray:
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
                "stroke_mm": self.stroke_mm, **self.joint_ranges_description()}

    @classmethod
    def from_description(cls, description: dict) -> "Hexapod":
        return cls(description["base_joints_mm"], description["platform_joints_mm"],
                   description["home_lengths_mm"], description.get("home_pose", paper.TABLE2_HOME_POSE),
                   description.get("stroke_mm", DEFAULT_STROKE_MM), description.get(JOINT_RANGES_KEY))

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
        return self._legs(theta, poses)[0].T

    def closure(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        return self._legs(theta, poses, joints)[0].T

    def _legs(self, theta: np.ndarray, poses: np.ndarray, joints: np.ndarray | None = None,
              jacobian: bool = False, parameters: bool = False):
        """One pass over the six legs at N poses, leg-major (each quantity a contiguous (6, N)
        array: numpy's inner loops then run over the poses, several times faster than over the
        legs of an (N, 6) array).

        Returns ``(F, Jt, Jleg)``:

        * ``F`` (6, N) mm: the closure ``|R P_i + t - B_i| - dl_i - joints`` (the inverse
          kinematics ``|...| - dl_i`` when ``joints`` is None);
        * ``Jt`` (6, 6, N) (``jacobian``; else None): ``Jt[i, k, n] = dF_i / d pose_k`` at pose
          n. With ``w_i = R P_i``, ``u_i`` the unit leg vector, ``m_i = w_i x u_i`` and ``R = Rz
          Ry Rx``: ``dF_i/d t = u_i``, ``dF_i/d alpha = (R e_x) . m_i``, ``dF_i/d beta = (Rz e_y)
          . m_i``, ``dF_i/d gamma = e_z . m_i`` (as ``dR/d alpha = R [e_x]x``, ``dR/d beta = [Rz
          e_y]x R``, ``dR/d gamma = [e_z]x R``);
        * ``Jleg`` (6, 7, N) (``parameters``; else None): ``dF_i / d`` leg i's own seven
          parameters ``(B_i, dl_i, P_i)``: ``-u_i``, ``-1``, ``R^T u_i``.
        """
        B, dl, P = self.legs(theta)
        p = np.ascontiguousarray(np.asarray(poses, dtype=float).T)  # (6, N)
        n = p.shape[1]
        R, c, s = rotation_entries(p[3:6])  # R[i, k] (N,): the rotation's entries
        cg, sg = c[2], s[2]
        w = np.einsum("ikn,lk->iln", R, P)  # (3, 6, N): R P_l
        L = w + (p[0:3, None, :] - B.T[:, :, None])  # (3, 6, N) leg vectors
        norm = np.sqrt(np.einsum("iln,iln->ln", L, L))
        F = norm - dl[:, None]
        if joints is not None:
            F -= np.asarray(joints, dtype=float).T
        if not (jacobian or parameters):
            return F, None, None
        u = L / norm  # (3, 6, N) unit leg vectors
        Jt = Jleg = None
        if jacobian:
            Jt = length_pose_jacobian(u, w, R, cg, sg)
        if parameters:
            Jleg = np.empty((6, 7, n))
            np.negative(u.transpose(1, 0, 2), out=Jleg[:, 0:3])
            np.einsum("ikn,iln->lkn", R, u, out=Jleg[:, 4:7])  # R^T u_l, one call for the three rows
            Jleg[:, 3] = -1.0
        return F, Jt, Jleg

    def closure_pose_jacobian(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        return self._legs(theta, poses, jacobian=True)[1].transpose(2, 0, 1)

    def closure_and_pose_jacobian(self, theta: np.ndarray, joints: np.ndarray,
                                  poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        F, Jt, _ = self._legs(theta, poses, joints, jacobian=True)
        return F.T, Jt.transpose(2, 0, 1)

    def closure_jacobians(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> ClosureJacobians:
        return self.closure_with_jacobians(theta, joints, poses)[1]

    def closure_with_jacobians(self, theta: np.ndarray, joints: np.ndarray,
                               poses: np.ndarray) -> tuple[np.ndarray, ClosureJacobians]:
        F, Jt, Jleg = self._legs(theta, poses, joints, jacobian=True, parameters=True)
        n = F.shape[1]
        # contiguous: LAPACK's batched inverse and solve take it about 1.5x faster than the view
        # Each leg's length moves with its own 7 parameters alone (the table's leg by leg order):
        # the (N, 42) own entries, the dense (N, 6, 42) built only where asked for.
        return F.T, ClosureJacobians(pose=np.ascontiguousarray(Jt.transpose(2, 0, 1)),
                                     joints=np.broadcast_to(-np.eye(6), (n, 6, 6)),  # read-only view
                                     own=Jleg.transpose(2, 0, 1).reshape(n, 42), chains=self.table.chains)


def paper_hexapod() -> Hexapod:
    """The hexapod of the paper's Table 2 (its Table 3 errors: :data:`calib.paper.TABLE3_ERRORS`)."""
    return Hexapod(paper.TABLE2_BASE_JOINTS_MM, paper.TABLE2_PLATFORM_JOINTS_MM,
                   paper.TABLE2_HOME_LENGTHS_MM, paper.TABLE2_HOME_POSE)
