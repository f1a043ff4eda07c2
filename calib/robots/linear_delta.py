"""The linear Delta (a Delta 3D printer): three towers, a carriage riding each, a pair of equal
rods (a parallelogram) from each carriage down to a translating effector that carries the tool.

Frames and conventions (mm, rad):

* Base frame: origin at the bed's centre, ``z`` up, the bed the plane ``z = 0``; the pose is the
  tool point (the nozzle) ``(x, y, z)``.
* The *reduced* model, Klipper's: each rod pair is one rod of the pair's mean length from a point
  that rides the tower to the tool point ``X`` (the carriage's joint midpoint minus the
  effector's joint offset and minus the tool offset ``t``, the vector from the effector's
  centre to the tool), so that the towers' radius is Klipper's ``delta_radius`` and the
  effector's own size is gone.
* Tower i (1, 2, 3: Klipper's stepper_a, _b, _c) stands at ``F_i = radius_i (cos a_i, sin a_i,
  0)`` on the bed plane, ``a_i = angle_i`` (Klipper's ``angle``, defaults 210, 330, 90 degrees),
  and rises along the unit vector ``u_i = sin(lr) cos(lt) e_r + sin(lt) e_t + cos(lr) cos(lt) e_z``
  (``e_r = (cos a, sin a, 0)`` radial, ``e_t = (-sin a, cos a, 0)`` counter-clockwise, ``lr =
  lean_r_i`` the top leaning outwards, ``lt = lean_t_i`` leaning counter-clockwise).
* Joint ``q_i`` (mm): the carriage's travel *down* from its endstop, as the controller counts it:
  the steps from the endstop times the nominal step distance (Klipper's stable position times
  its step distance). The carriage's point sits ``s_i = H_i - (1 + step_error_i / 100) (q_i +
  endstop_drop_i)`` along the tower from ``F_i``: ``H_i`` the nominal endstop height along the
  tower (the description's ``endstop_height_mm``, not a parameter), ``endstop_drop_i`` how far
  (in counted travel) the real endstop sits below it, the joint zero (a re-homing moves it and
  nothing else: it adds to the reading), and ``step_error_i`` the travel error, mm over 100 mm of
  counted travel (the real step distance is the nominal one times ``1 + step_error_i / 100``).
  Klipper's carriage height ``abs_endstop - position`` is ``s_i`` with ``H_i - endstop_drop_i``
  its absolute endstop and ``q_i`` its position.
* Closure of chain i (mm): ``F_i = |F_i + s_i u_i - X| - arm_i``.

Parameters (27): per tower ``radius angle lean_r lean_t arm arm_diff endstop_drop step_error``
(:data:`CHAIN_PARAMETERS`), then the tool offset ``tool.x tool.y tool.z`` (from the effector's
centre to the tool point, effector frame).

What the closure cannot see, and why (:attr:`LinearDelta.machine_only`, held by default):

* ``tool.x tool.y tool.z`` (mm): the tool offset. With a translating effector the towers' points
  are taken relative to the tool point (Klipper's), so the tool offset is in them: another tool
  offset on the same physical printer moves the three reduced towers by its difference together,
  which their radii, angles and endstops do exactly. The closure does not see it, and pose data
  could not tell it from the towers. It places the effector behind the tool in the MuJoCo machine
  (the effector's centre is ``X - t``), where it is the lever of the effector's tilt. It belongs
  to no tower (the table files it under tower 3, after it, so that the table stays in tower
  order; its column is zero).
* ``arm_diff_i``: the second rod of pair i (counter-clockwise) minus the first, mm. Unequal rods
  make no parallelogram: the effector tilts, about ``arm_diff / rod spacing`` (1 mm over 50 mm:
  20 mrad), by an amount that varies with the rods' directions over the volume, and the tilt
  moves the tool point through the tool offset and the effector's joints. A translating
  effector's kinematics has no tilt: its closure does not see ``arm_diff`` (the column is zero),
  the parameter is held, left to its tolerance, and only the MuJoCo machine
  (:mod:`mjcf.linear_delta`) carries it (:attr:`LinearDelta.machine_only`). The part of a tilt
  that is the same everywhere moves the tool point by a constant the towers absorb; its variation
  is a model error of this robot, which these docs say rather than hide.

Both are named with their tolerances so that an identification says they are left to them.

Identifiable from tool positions: each tower's seven others (the line the carriage rides, its
origin and scale along it, and the arm), 21 in all. Physical sizes for the MuJoCo machine and
pictures (not parameters): the effector's joint offset ``effector_radius_mm`` and the spacing of a
pair's rods ``rod_spacing_mm``.
"""

from __future__ import annotations

import numpy as np

from ..robot import (JOINT_RANGES_KEY, ClosureJacobians, KinematicsError, Parameter, ParameterTable, Robot,
                     checked_joint_ranges, newton_forward_kinematics)
from ..validation import as_array

__all__ = ["LinearDelta", "CHAIN_PARAMETERS", "CHAIN_UNITS", "TOOL_PARAMETERS", "STEP_ERROR_REFERENCE_MM",
           "KLIPPER_ANGLES_DEG", "DEFAULT_GEOMETRY", "tower_directions"]

#: Names of a tower's eight parameters; ``{i}`` is the 1-based tower number.
CHAIN_PARAMETERS = ("radius{i}", "angle{i}", "lean_r{i}", "lean_t{i}", "arm{i}", "arm_diff{i}", "endstop_drop{i}",
                    "step_error{i}")
#: Unit of each of :data:`CHAIN_PARAMETERS`.
CHAIN_UNITS = ("mm", "rad", "rad", "rad", "mm", "mm", "mm", "mm")
#: The tool offset's names (mm, effector frame), after the towers'.
TOOL_PARAMETERS = ("tool.x", "tool.y", "tool.z")
#: Counted travel over which ``step_error`` is the travel error, mm: ``step_error`` is then the
#: step distance's error in percent.
STEP_ERROR_REFERENCE_MM = 100.0
#: Klipper's default tower angles (stepper_a, _b, _c), degrees.
KLIPPER_ANGLES_DEG = (210.0, 330.0, 90.0)
#: The default printer, a large Kossel-type machine (mm): Klipper's ``delta_radius`` 140 and
#: ``arm_length`` 250, a print volume of radius 100 from the bed to 250 above it, the endstops
#: 510 mm along the towers (Klipper's ``position_endstop`` 510 - sqrt(250^2 - 140^2) = 303.9: the
#: tool 263 mm above the bed at the volume's edge nearest a tower, the carriage opposite 440 mm
#: below its endstop with the tool on the bed at the far edge), 480 mm of travel below them; the
#: tool 50 mm under the effector's centre, its joints 30 mm from it, each pair's rods 50 mm apart.
DEFAULT_GEOMETRY = {"delta_radius_mm": 140.0, "arm_mm": 250.0, "endstop_height_mm": 510.0, "travel_mm": 480.0,
                    "tool_z_mm": -50.0, "print_radius_mm": 100.0, "print_height_mm": 250.0,
                    "effector_radius_mm": 30.0, "rod_spacing_mm": 50.0, "home_z_mm": 100.0}


def tower_directions(angle, lean_r, lean_t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(e_r, e_t, u)``, each (..., 3): the towers' radial and counter-clockwise horizontal unit
    vectors and their unit directions (module docstring), from their angles and leans (rad)."""
    ca, sa = np.cos(angle), np.sin(angle)
    zero = np.zeros_like(ca)
    e_r = np.stack([ca, sa, zero], -1)
    e_t = np.stack([-sa, ca, zero], -1)
    e_z = np.stack([zero, zero, np.ones_like(ca)], -1)
    sr, cr, st, ct = np.sin(lean_r), np.cos(lean_r), np.sin(lean_t), np.cos(lean_t)
    u = (sr * ct)[..., None] * e_r + st[..., None] * e_t + (cr * ct)[..., None] * e_z
    return e_r, e_t, u


def _tolerances() -> dict[str, float]:
    """The default prior's standard deviations, by unit and by name (see
    :attr:`LinearDelta.default_parameter_tolerance`)."""
    by_kind = {"radius": 0.5, "angle": 5e-3, "lean_r": 3e-3, "lean_t": 3e-3, "arm": 0.2, "arm_diff": 0.2,
               "endstop_drop": 1.0, "step_error": 0.3}
    out = {"mm": 0.5, "rad": 5e-3}
    out.update({t.format(i=i): by_kind[t[:-3]] for i in (1, 2, 3) for t in CHAIN_PARAMETERS})
    out.update({n: 1.0 for n in TOOL_PARAMETERS})
    return out


class LinearDelta(Robot):
    """A linear Delta printer's nominal geometry (see the module docstring).

    Args:
        towers: (3, 8) nominal parameters, one row per tower in :data:`CHAIN_PARAMETERS` order.
        tool: (3,) nominal tool offset, mm (effector frame).
        endstop_height_mm: (3,) each endstop's nominal distance along its tower from the bed, mm.
        travel_mm: each carriage's travel below its endstop, mm (the default joint range is
            ``[0, travel_mm]`` when no ``joint_ranges`` are declared).
        home_pose: (3,) the home tool position, mm (start of iterations, the MuJoCo keyframe).
        workspace_mm: (3, 2) the calibration workspace box, mm.
        full_workspace_mm: (3, 2) the design workspace box, mm.
        effector_radius_mm: the effector's joint offset (centre to a pair's midpoint), mm.
        rod_spacing_mm: distance between a pair's two rods, mm.
        joint_ranges: (3, 2) mm, each carriage's travel as built (:attr:`Robot.joint_ranges`).
    """

    name = "linear_delta"
    pose_names = ("x", "y", "z")
    pose_units = ("mm", "mm", "mm")
    joint_unit = "mm"
    joint_symbol = "q"
    chain_word = "tower"
    joint_zero_names = ("endstop_drop1", "endstop_drop2", "endstop_drop3")
    #: Parameters of the machine that the closure cannot see (their columns are zero): the MuJoCo
    #: machine builds them, the kinematics does not (module docstring); seeded errors leave them
    #: at nominal.
    machine_only = ("arm_diff1", "arm_diff2", "arm_diff3") + TOOL_PARAMETERS
    gauge_fixed = machine_only
    #: Tolerance of the parameters, the default prior's standard deviation, with its reasons:
    #: ``radius`` 0.5 mm (frame extrusions cut and printed vertices assembled: a few tenths, and
    #: Klipper's fits move ``delta_radius`` by up to a millimetre); ``angle`` 5 mrad (0.3 degree:
    #: a tower's angle set by printed or cast vertices) and each lean 3 mrad (0.17 degree: towers
    #: stand square to tenths of a degree); ``arm`` 0.2 mm and ``arm_diff`` 0.2 mm (rods glued in a
    #: jig match to about a tenth); ``endstop_drop`` 1 mm (switches placed by hand: Klipper's
    #: ``position_endstop`` fits differ by millimetres between towers); ``step_error`` 0.3 mm over
    #: 100 mm (belts and pulleys: a stretched belt or a pulley's diameter off by 0.3 percent); the
    #: tool offset 1 mm (a hot end mounted by hand; held: see the module docstring).
    default_parameter_tolerance = _tolerances()

    def __init__(self, towers, tool, endstop_height_mm, *, travel_mm: float = DEFAULT_GEOMETRY["travel_mm"],
                 home_pose=None, workspace_mm=None, full_workspace_mm=None,
                 effector_radius_mm: float = DEFAULT_GEOMETRY["effector_radius_mm"],
                 rod_spacing_mm: float = DEFAULT_GEOMETRY["rod_spacing_mm"], joint_ranges=None):
        g = DEFAULT_GEOMETRY
        self.towers = as_array(towers, "towers", (3, len(CHAIN_PARAMETERS)))
        self.tool = as_array(tool, "tool", (3,))
        self.endstop_height_mm = as_array(endstop_height_mm, "endstop_height_mm", (3,))
        square = g["print_radius_mm"] / np.sqrt(2.0)
        self._home = as_array([0.0, 0.0, g["home_z_mm"]] if home_pose is None else home_pose, "home_pose", (3,))
        self._workspace = as_array([[-square, square], [-square, square], [0.0, g["print_height_mm"]]]
                                   if workspace_mm is None else workspace_mm, "workspace_mm", (3, 2))
        r = g["print_radius_mm"]
        self._full = as_array([[-r, r], [-r, r], [0.0, g["print_height_mm"]]] if full_workspace_mm is None
                              else full_workspace_mm, "full_workspace_mm", (3, 2))
        for label, v in (("travel_mm", travel_mm), ("effector_radius_mm", effector_radius_mm),
                         ("rod_spacing_mm", rod_spacing_mm)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{label} must be a finite number > 0, got {v!r}")
        if not np.all(self.towers[:, 4] > 0):
            raise ValueError("towers: the arm lengths must be > 0")
        self.travel_mm, self.effector_radius_mm, self.rod_spacing_mm = (float(travel_mm), float(effector_radius_mm),
                                                                        float(rod_spacing_mm))
        for a in (self.towers, self.tool, self.endstop_height_mm, self._home, self._workspace, self._full):
            a.setflags(write=False)
        self.joint_ranges = checked_joint_ranges(joint_ranges, self)
        self.table = ParameterTable(
            [Parameter(t.format(i=c + 1), CHAIN_UNITS[k], float(self.towers[c, k]), c)
             for c in range(3) for k, t in enumerate(CHAIN_PARAMETERS)]
            + [Parameter(n, "mm", float(v), 2) for n, v in zip(TOOL_PARAMETERS, self.tool)])

    @classmethod
    def default(cls) -> "LinearDelta":
        """The default printer (:data:`DEFAULT_GEOMETRY`, towers at Klipper's default angles)."""
        g = DEFAULT_GEOMETRY
        towers = [[g["delta_radius_mm"], np.deg2rad(a), 0.0, 0.0, g["arm_mm"], 0.0, 0.0, 0.0]
                  for a in KLIPPER_ANGLES_DEG]
        return cls(towers, [0.0, 0.0, g["tool_z_mm"]], np.full(3, g["endstop_height_mm"]))

    # -- description ----------------------------------------------------------------------
    @property
    def home_pose(self) -> np.ndarray:
        return self._home.copy()

    @property
    def length_scale_mm(self) -> float:
        return float(self.towers[:, 4].mean())

    def workspace_bounds(self) -> np.ndarray:
        return self._workspace.copy()

    def full_workspace_bounds(self) -> np.ndarray:
        return self._full.copy()

    def default_joint_limits(self) -> np.ndarray:
        return np.tile([0.0, self.travel_mm], (3, 1))

    def description(self) -> dict:
        return {"parameters": self.table.to_dict(self.table.nominal),
                "endstop_height_mm": self.endstop_height_mm.tolist(), "travel_mm": self.travel_mm,
                "home_pose": self._home.tolist(), "workspace_mm": self._workspace.tolist(),
                "full_workspace_mm": self._full.tolist(), "effector_radius_mm": self.effector_radius_mm,
                "rod_spacing_mm": self.rod_spacing_mm, **self.joint_ranges_description()}

    @classmethod
    def from_description(cls, description: dict) -> "LinearDelta":
        values = description["parameters"]
        names = [t.format(i=c + 1) for c in range(3) for t in CHAIN_PARAMETERS] + list(TOOL_PARAMETERS)
        missing = [n for n in names if n not in values]
        if missing:
            raise KeyError(f"parameters: missing {', '.join(missing)}")
        g = DEFAULT_GEOMETRY
        v = [values[n] for n in names]
        return cls(np.reshape(v[:24], (3, len(CHAIN_PARAMETERS))), v[24:], description["endstop_height_mm"],
                   travel_mm=description.get("travel_mm", g["travel_mm"]), home_pose=description.get("home_pose"),
                   workspace_mm=description.get("workspace_mm"),
                   full_workspace_mm=description.get("full_workspace_mm"),
                   effector_radius_mm=description.get("effector_radius_mm", g["effector_radius_mm"]),
                   rod_spacing_mm=description.get("rod_spacing_mm", g["rod_spacing_mm"]),
                   joint_ranges=description.get(JOINT_RANGES_KEY))

    # -- parameter layout -----------------------------------------------------------------
    @staticmethod
    def split(theta: np.ndarray) -> dict[str, np.ndarray]:
        """Named views of ``theta``: each tower's ``radius angle lean_r lean_t arm arm_diff
        endstop_drop step_error`` (3,), and ``tool`` (3,)."""
        values = np.asarray(theta, dtype=float)
        towers = values[:24].reshape(3, len(CHAIN_PARAMETERS))
        out = {name.split("{")[0]: towers[:, k] for k, name in enumerate(CHAIN_PARAMETERS)}
        out["tool"] = values[24:27]
        return out

    def carriage_points(self, theta: np.ndarray, joints: np.ndarray) -> tuple[np.ndarray, dict]:
        """``(P, parts)``: (N, 3, 3) each tower's reduced carriage point at ``joints`` (mm), and the
        :meth:`split` views with ``e_r e_t u`` (3, 3), ``scale`` (3,) ``1 + step_error / 100``,
        ``travel`` (N, 3) ``q + endstop_drop`` and ``s`` (N, 3) the distance along the tower."""
        p = self.split(theta)
        p["e_r"], p["e_t"], p["u"] = tower_directions(p["angle"], p["lean_r"], p["lean_t"])
        p["scale"] = 1.0 + p["step_error"] / STEP_ERROR_REFERENCE_MM
        p["travel"] = np.asarray(joints, dtype=float) + p["endstop_drop"]
        p["s"] = self.endstop_height_mm - p["scale"] * p["travel"]
        foot = p["radius"][:, None] * p["e_r"]
        return foot + p["s"][:, :, None] * p["u"], p

    # -- kinematics -----------------------------------------------------------------------
    def _rods(self, theta, joints, poses):
        """``(w, norm, parts)``: (N, 3, 3) each reduced rod from the tool point to its carriage
        point, (N, 3) their lengths, and :meth:`carriage_points`' parts."""
        P, p = self.carriage_points(theta, joints)
        w = P - np.asarray(poses, dtype=float)[:, None, :]
        return w, np.sqrt(np.einsum("nij,nij->ni", w, w)), p

    def closure(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        w, norm, p = self._rods(theta, joints, poses)
        return norm - p["arm"]

    def closure_pose_jacobian(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        w, norm, _ = self._rods(theta, joints, poses)
        return -w / norm[:, :, None]

    def closure_and_pose_jacobian(self, theta, joints, poses):
        w, norm, p = self._rods(theta, joints, poses)
        return norm - p["arm"], -w / norm[:, :, None]

    def closure_jacobians(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> ClosureJacobians:
        return self.closure_with_jacobians(theta, joints, poses)[1]

    def closure_with_jacobians(self, theta, joints, poses):
        """The closure and its derivatives; with ``n`` the unit rod (effector to carriage): pose
        ``-n``; joint and ``endstop_drop`` ``-(1 + step_error/100) n.u``; ``step_error``
        ``-(q + endstop_drop) / 100 n.u``; ``radius`` ``n.e_r``; ``angle`` ``n.(radius e_t + s
        du/da)``; the leans ``s n.du/dlean``; ``arm`` -1; ``arm_diff`` and the tool 0. Each
        tower's closure moves with its own parameters alone: the (N, P) own entries."""
        w, norm, p = self._rods(theta, joints, poses)
        n = w / norm[:, :, None]
        rows = n.shape[0]
        nu = np.einsum("nij,ij->ni", n, p["u"])
        s = p["s"]
        a, lr, lt = p["angle"], p["lean_r"], p["lean_t"]
        e_r, e_t = p["e_r"], p["e_t"]
        e_z = np.array([0.0, 0.0, 1.0])
        sr, cr, st, ct = np.sin(lr), np.cos(lr), np.sin(lt), np.cos(lt)
        du_da = (sr * ct)[:, None] * e_t - st[:, None] * e_r
        du_dlr = (cr * ct)[:, None] * e_r - (sr * ct)[:, None] * e_z
        du_dlt = -(sr * st)[:, None] * e_r + ct[:, None] * e_t - (cr * st)[:, None] * e_z
        dq = -p["scale"] * nu
        towers = np.empty((rows, 3, len(CHAIN_PARAMETERS)))
        towers[:, :, 0] = np.einsum("nij,ij->ni", n, e_r)
        towers[:, :, 1] = np.einsum("nij,ij->ni", n, p["radius"][:, None] * e_t) + s * np.einsum("nij,ij->ni", n, du_da)
        towers[:, :, 2] = s * np.einsum("nij,ij->ni", n, du_dlr)
        towers[:, :, 3] = s * np.einsum("nij,ij->ni", n, du_dlt)
        towers[:, :, 4] = -1.0
        towers[:, :, 5] = 0.0
        towers[:, :, 6] = dq
        towers[:, :, 7] = -p["travel"] / STEP_ERROR_REFERENCE_MM * nu
        own = np.concatenate([towers.reshape(rows, -1), np.zeros((rows, len(TOOL_PARAMETERS)))], axis=1)
        jq = np.zeros((rows, 3, 3))
        jq[:, np.arange(3), np.arange(3)] = dq
        return norm - p["arm"], ClosureJacobians(pose=-n, joints=jq, own=own, chains=self.table.chains)

    def inverse_kinematics(self, theta: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, 3) carriage travels below the endstops, mm: per tower, the carriage point at
        distance ``s`` along the tower from ``F`` with ``|F + s u - X| = arm``, the upper root
        ``s = u.d + sqrt((u.d)^2 - |d|^2 + arm^2)``, ``d = X - F`` (the carriage above the
        effector), then ``q = (H - s) / (1 + step_error/100) - endstop_drop``.

        Raises:
            KinematicsError: the arm cannot reach the tower, or is square to it (a serial
                singularity); names the row and the tower.
        """
        p = self.split(theta)
        e_r, _, u = tower_directions(p["angle"], p["lean_r"], p["lean_t"])
        d = np.asarray(poses, dtype=float)[:, None, :] - p["radius"][:, None] * e_r
        b = np.einsum("nij,ij->ni", d, u)
        disc = b * b - np.einsum("nij,nij->ni", d, d) + p["arm"] ** 2
        bad = ~(disc > (1e-6 * p["arm"]) ** 2)
        if np.any(bad):
            row, chain = (int(x) for x in np.argwhere(bad)[0])
            why = "cannot reach its tower" if not disc[row, chain] >= 0 else "is square to its tower (singular)"
            raise KinematicsError(f"row {row} is unreachable: the arm of {self.chain_word} {chain + 1} {why} "
                                  f"(pose {np.array2string(np.asarray(poses)[row], precision=4)})", row)
        s = b + np.sqrt(disc)
        scale = 1.0 + p["step_error"] / STEP_ERROR_REFERENCE_MM
        return (self.endstop_height_mm - s) / scale - p["endstop_drop"]

    def forward_kinematics(self, theta: np.ndarray, joints: np.ndarray, *, initial=None) -> np.ndarray:
        """(N, 3) tool points: the trilateration of the three spheres (carriage points, arms), the
        lower of the two intersections (the effector under the carriages), then polished by Newton on the closure (:func:`newton_forward_kinematics`, which
        also refuses a singular configuration).

        Raises:
            KinematicsError: the spheres do not meet, or meet where the rods lie in the plane of
                the carriages (a parallel singularity); names the row.
        """
        joints = np.asarray(joints, dtype=float)
        P, p = self.carriage_points(theta, joints)
        arm = p["arm"]
        p1, p2, p3 = P[:, 0], P[:, 1], P[:, 2]
        d12, d13 = p2 - p1, p3 - p1
        d = np.linalg.norm(d12, axis=-1)
        ex = d12 / d[:, None]
        i = np.einsum("nc,nc->n", ex, d13)
        ey_raw = d13 - i[:, None] * ex
        j = np.linalg.norm(ey_raw, axis=-1)
        ey = ey_raw / j[:, None]
        ez = np.cross(ex, ey)
        x = (arm[0] ** 2 - arm[1] ** 2 + d ** 2) / (2 * d)
        y = (arm[0] ** 2 - arm[2] ** 2 + i ** 2 + j ** 2) / (2 * j) - i * x / j
        z2 = arm[0] ** 2 - x ** 2 - y ** 2
        bad = ~(z2 > (1e-6 * arm.max()) ** 2)
        if np.any(bad):
            row = int(np.argmax(bad))
            why = "the arms cannot meet" if not z2[row] >= 0 else "the rods lie in the carriages' plane (singular)"
            raise KinematicsError(f"forward kinematics: row {row}: {why} (joints "
                                  f"{np.array2string(joints[row], precision=4)})", row)
        base = p1 + x[:, None] * ex + y[:, None] * ey
        h = np.sqrt(z2)[:, None] * ez
        lower = np.where(((base + h)[:, 2] < (base - h)[:, 2])[:, None], base + h, base - h)
        return newton_forward_kinematics(self, theta, joints, initial=lower)

    def chain_points(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, 3, 3, 3) mm: each tower's foot on the bed, its carriage's joint midpoint and the
        effector's joint midpoint: the reduced model shifted by the effector's joint offset
        ``E_i`` (at the tower's angle) less the tool offset ``t`` (the physical tower is the
        reduced one's line through ``F_i - t + E_i``)."""
        P, p = self.carriage_points(theta, joints)
        shift = self.effector_radius_mm * p["e_r"] - p["tool"]
        u = p["u"]
        foot = p["radius"][:, None] * p["e_r"] + shift - (shift[:, 2] / u[:, 2])[:, None] * u  # at z = 0
        effector = np.asarray(poses, dtype=float)[:, None, :] + shift
        return np.stack([np.broadcast_to(foot, P.shape), P + shift, effector], axis=2)
