"""The linear Delta (a Delta 3D printer): three towers, a carriage riding each, a pair of rods (a
parallelogram where they are equal) from each carriage down to the effector that carries the tool
(translating, or tilted where a pair's rods differ).

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
* The effector turns by ``R`` when a pair's rods differ (below); pair i's mean rod is ``m_i = P_i
  - X + (I - R) o_i`` (``P_i = F_i + s_i u_i`` the reduced carriage point, ``o_i`` the pair's
  joint midpoint on the effector from the tool point, effector frame) and half their difference
  ``d_i = h (I - R) w_i`` (``w_i`` the pair's axle, ``h`` half the rods' spacing).
* Closure of chain i (mm): ``F_i = sqrt(|m_i|^2 + |d_i|^2) - sqrt(arm_i^2 + arm_diff_i^2 / 4)``,
  with ``R`` solving ``m_i.d_i = arm_i arm_diff_i / 2`` for the three pairs (:class:`RodPairs`):
  together, the six rods ``m_i -+ d_i`` have their lengths ``arm_i -+ arm_diff_i / 2``. With
  equal rods ``R = I`` and ``F_i = |P_i - X| - arm_i``, Klipper's model.

Parameters (27): per tower ``radius angle lean_r lean_t arm arm_diff endstop_drop step_error``
(:data:`CHAIN_PARAMETERS`), then the tool offset ``tool.x tool.y tool.z`` (from the effector's
centre to the tool point, effector frame).

* ``arm_diff_i``: the second rod of pair i (counter-clockwise) minus the first, mm. Unequal rods
  make no parallelogram: the effector tilts, about ``arm_diff / rod spacing`` (1 mm over 50 mm:
  20 mrad), by an amount that varies with the rods' directions over the volume, and the tilt
  moves the tool point through the tool offset and the effector's joints (0.28 mm RMS over the
  print volume for a 1 mm pair, measured on the MuJoCo machine). The closure holds it exactly:
  the effector's rotation is solved from the three pairs' length differences by Newton's method
  (a few steps from level), each closure's derivatives through it by the implicit function
  theorem, so that every chain's closure moves with every pair's ``arm_diff`` (and, where the
  effector is tilted, with every carriage): the chains are coupled. The MuJoCo machine
  (:mod:`mjcf.linear_delta`), six rods closed on a free effector, agrees to 2e-9 mm.

What the closure does not determine, and why (:attr:`LinearDelta.machine_only`, held by default):

* ``tool.x tool.y tool.z`` (mm): the tool offset. With a translating effector the towers' points
  are taken relative to the tool point (Klipper's), so the tool offset is in them: another tool
  offset on the same physical printer moves the three reduced towers by its difference together,
  which their radii, angles and endstops do exactly. The closure sees it only as the lever of the
  effector's tilt (a second-order term: none with equal rods), and pose data could not tell it
  from the towers. It places the effector behind the tool in the MuJoCo machine (the effector's
  centre is ``X - R t``). It belongs to no tower (the table files it under tower 3, after it, so
  that the table stays in tower order).

It is named with its tolerance so that an identification says it is left to it.

Identifiable from tool positions: each tower's seven others (the line the carriage rides, its
origin and scale along it, and the arm), 21 in all, identified by default, and the pairs' rod
differences, where a fit names them (:attr:`LinearDelta.chain_coupled`). Physical sizes for the
kinematics' tilt, the MuJoCo machine and pictures (not parameters): the effector's joint offset
``effector_radius_mm`` and the spacing of a pair's rods ``rod_spacing_mm``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robot import (JOINT_RANGES_KEY, ClosureJacobians, KinematicsError, Parameter, ParameterTable, Robot,
                     checked_joint_ranges, newton_forward_kinematics)
from ..rotation import matrix_from_rotation_vector
from ..validation import as_array

__all__ = ["LinearDelta", "CHAIN_PARAMETERS", "CHAIN_UNITS", "TOOL_PARAMETERS", "STEP_ERROR_REFERENCE_MM",
           "KLIPPER_ANGLES_DEG", "DEFAULT_GEOMETRY", "tower_directions", "RodPairs", "TILT_STEP_TOL_RAD",
           "TILT_MAX_ITER", "IK_STEP_TOL_MM"]

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


#: Newton's method on the effector's rotation stops when its step is below this, rad (it converges
#: quadratically: the step after it would be at rounding), or after :data:`TILT_MAX_ITER` steps;
#: the inverse kinematics alternates the rotation and the carriages' travels until the travels
#: move less than :data:`IK_STEP_TOL_MM`.
TILT_STEP_TOL_RAD, TILT_MAX_ITER, IK_STEP_TOL_MM = 1e-13, 20, 1e-11


@dataclass(frozen=True, eq=False)
class RodPairs:
    """The three rod pairs at N configurations, the effector turned by ``rotation`` (mm).

    Pair i's rods run from the effector's joints ``X + R (o_i -+ h w_i)`` to the carriage's ``P_i
    - t + E_i -+ h w_i`` (``o_i = E_i - t`` the pair's joint midpoint from the tool point in the
    effector frame, ``w_i`` the pair's axle, ``h`` half the rods' spacing, ``P_i`` the reduced
    carriage point): they are ``m_i -+ d_i`` with ``m_i = P_i - X + (I - R) o_i`` (:attr:`mean`)
    and ``d_i = h (I - R) w_i`` (:attr:`half_difference`). Their lengths are ``arm_i -+
    arm_diff_i / 2`` exactly when ``|m_i|^2 + |d_i|^2 = arm_i^2 + arm_diff_i^2 / 4`` (the closure,
    :meth:`closure`, in mm: the root of the left side minus that of the right) and ``m_i.d_i =
    arm_i arm_diff_i / 2`` (:meth:`length_differences`, which fix the rotation).
    """

    rotation: np.ndarray
    mean: np.ndarray
    half_difference: np.ndarray
    offsets: np.ndarray
    rotated_offsets: np.ndarray
    rotated_axles: np.ndarray
    half_spacing: float
    length: np.ndarray
    target: np.ndarray
    parts: dict

    @classmethod
    def at(cls, rotation, reach, offsets, axles, half_spacing: float, parts: dict) -> "RodPairs":
        """The pairs with the effector turned by ``rotation`` (N, 3, 3): ``reach`` (N, 3, 3) ``P_i -
        X``, ``offsets`` (3, 3) ``o_i``, ``axles`` (3, 3) ``w_i``, ``parts`` the carriage points'."""
        turned = np.einsum("nij,cj->nci", rotation, offsets)
        turned_axles = np.einsum("nij,cj->nci", rotation, axles)
        mean = reach + (offsets - turned)
        half = half_spacing * (axles - turned_axles)
        length = np.sqrt(np.einsum("nij,nij->ni", mean, mean) + np.einsum("nij,nij->ni", half, half))
        target = np.sqrt(parts["arm"] ** 2 + parts["arm_diff"] ** 2 / 4)
        return cls(rotation, mean, half, offsets, turned, turned_axles, half_spacing, length, target, parts)

    @property
    def unit_mean(self) -> np.ndarray:
        """(N, 3, 3) ``m_i / sqrt(|m_i|^2 + |d_i|^2)``: the closure's derivative in ``m_i``."""
        return self.mean / self.length[..., None]

    def closure(self) -> np.ndarray:
        """(N, 3) mm: ``sqrt(|m_i|^2 + |d_i|^2) - sqrt(arm_i^2 + arm_diff_i^2 / 4)``."""
        return self.length - self.target

    def length_differences(self) -> np.ndarray:
        """(N, 3) mm^2: ``m_i.d_i - arm_i arm_diff_i / 2`` (zero at the effector's rotation)."""
        half_product = self.parts["arm"] * self.parts["arm_diff"] / 2
        return np.einsum("nij,nij->ni", self.mean, self.half_difference) - half_product

    def rotation_jacobians(self) -> tuple[np.ndarray, np.ndarray]:
        """``(dF/dw, dG/dw)`` (N, 3, 3): the closure's and the length differences' derivatives in
        a small turn ``w`` of the effector (``R -> (I + [w]x) R``), which moves ``m_i`` by
        ``R o_i x w`` and ``d_i`` by ``h R w_i x w``."""
        h = self.half_spacing
        m, d, o, w = self.mean, self.half_difference, self.rotated_offsets, self.rotated_axles
        return ((np.cross(m, o) + h * np.cross(d, w)) / self.length[..., None],
                np.cross(d, o) + h * np.cross(m, w))

    def coupling(self) -> np.ndarray:
        """(N, 3, 3) ``K = dF/dw (dG/dw)^-1``: a change that moves the length differences by
        ``dG`` turns the effector so that the closure moves by ``-K dG`` (the implicit function
        theorem on ``G = 0``)."""
        f, g = self.rotation_jacobians()
        return np.swapaxes(np.linalg.solve(np.swapaxes(g, 1, 2), np.swapaxes(f, 1, 2)), 1, 2)


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
    #: Parameters of the machine that no measurement tells from the towers (the tool offset: the
    #: closure sees it only as the lever of the effector's tilt, module docstring); held, and
    #: seeded errors leave them at nominal.
    machine_only = TOOL_PARAMETERS
    gauge_fixed = machine_only
    #: The rod-pair differences tilt the effector that all three chains hold (module docstring):
    #: identified where a fit names them (:func:`calib.probe.fit_probe` does), not chain by chain.
    chain_coupled = ("arm_diff1", "arm_diff2", "arm_diff3")
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
        radial, self._axles, _ = tower_directions(self.towers[:, 1], np.zeros(3), np.zeros(3))
        self._joint_offsets = self.effector_radius_mm * radial  # the pairs' joints, effector frame
        for a in (self._axles, self._joint_offsets, self.towers, self.tool, self.endstop_height_mm, self._home,
                  self._workspace, self._full):
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
    def pairs(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray, *, rotation=None) -> RodPairs:
        """The rod pairs at ``joints`` with the tool at ``poses`` (:class:`RodPairs`), the
        effector's rotation solved from the pairs' rod-length differences (module docstring) by
        Newton's method from ``rotation`` (N, 3, 3; default level); level where every pair's rods
        are equal."""
        P, p = self.carriage_points(theta, joints)
        reach = P - np.asarray(poses, dtype=float)[:, None, :]
        offsets = self._joint_offsets - p["tool"]
        R = np.broadcast_to(np.eye(3), (reach.shape[0], 3, 3)) if rotation is None else rotation
        if np.any(p["arm_diff"] != 0):
            for _ in range(TILT_MAX_ITER):
                pairs = RodPairs.at(R, reach, offsets, self._axles, self.rod_spacing_mm / 2, p)
                step = np.linalg.solve(pairs.rotation_jacobians()[1], -pairs.length_differences()[..., None])[..., 0]
                R = matrix_from_rotation_vector(step) @ R
                if np.all(np.abs(step) < TILT_STEP_TOL_RAD):
                    break
        return RodPairs.at(R, reach, offsets, self._axles, self.rod_spacing_mm / 2, p)

    def closure(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        return self.pairs(theta, joints, poses).closure()

    def closure_pose_jacobian(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> np.ndarray:
        return self.closure_and_pose_jacobian(theta, joints, poses)[1]

    def closure_and_pose_jacobian(self, theta, joints, poses):
        pairs = self.pairs(theta, joints, poses)
        coupling = pairs.coupling()
        return pairs.closure(), -pairs.unit_mean + coupling @ pairs.half_difference

    def closure_jacobians(self, theta: np.ndarray, joints: np.ndarray, poses: np.ndarray) -> ClosureJacobians:
        return self.closure_with_jacobians(theta, joints, poses)[1]

    def closure_with_jacobians(self, theta, joints, poses):
        """The closure and its derivatives. Each variable ``z`` moves a pair's mean rod ``m`` and
        half difference ``d`` directly (partials ``dF/dz``, ``dG/dz`` of the closure ``F`` and of
        the length differences ``G = m.d - arm arm_diff / 2``) and through the effector's rotation,
        which keeps ``G = 0``: ``dF/dz - K dG/dz``, ``K = dF/dw (dG/dw)^-1`` (:meth:`RodPairs.coupling`).
        Directly: the carriage point ``P`` moves ``F`` by ``m/|.|`` and ``G`` by ``d``; the pose by
        minus these; ``arm`` ``-arm/L``, ``-arm_diff/2``; ``arm_diff`` ``-arm_diff/(4L)``,
        ``-arm/2`` (``L = sqrt(arm^2 + arm_diff^2/4)``); the tool ``-(m/|.|) (I - R)``, ``-d (I - R)``."""
        pairs = self.pairs(theta, joints, poses)
        p = pairs.parts
        rows, k = pairs.mean.shape[0], len(CHAIN_PARAMETERS)
        moves = np.zeros((rows, 3, k, 3))  # dP / d(tower parameter)
        moves[:, :, 0] = p["e_r"]
        sr, cr, st, ct = np.sin(p["lean_r"]), np.cos(p["lean_r"]), np.sin(p["lean_t"]), np.cos(p["lean_t"])
        e_r, e_t, e_z = p["e_r"], p["e_t"], np.array([0.0, 0.0, 1.0])
        s = p["s"][:, :, None]
        moves[:, :, 1] = p["radius"][:, None] * e_t + s * ((sr * ct)[:, None] * e_t - st[:, None] * e_r)
        moves[:, :, 2] = s * ((cr * ct)[:, None] * e_r - (sr * ct)[:, None] * e_z)
        moves[:, :, 3] = s * (-(sr * st)[:, None] * e_r + ct[:, None] * e_t - (cr * st)[:, None] * e_z)
        moves[:, :, 6] = -p["scale"][:, None] * p["u"]
        moves[:, :, 7] = -(p["travel"] / STEP_ERROR_REFERENCE_MM)[..., None] * p["u"]
        direct = [np.zeros((rows, 3, self.n_parameters)) for _ in range(2)]
        for j, along in enumerate((pairs.unit_mean, pairs.half_difference)):
            towers = np.einsum("nik,nijk->nij", along, moves)
            towers[:, :, 4] = (-p["arm"] / pairs.target, -p["arm_diff"] / 2)[j]
            towers[:, :, 5] = (-p["arm_diff"] / (4 * pairs.target), -p["arm"] / 2)[j]
            for c in range(3):
                direct[j][:, c, c * k:(c + 1) * k] = towers[:, c]
            direct[j][:, :, 3 * k:] = -(along - np.einsum("nik,nkj->nij", along, pairs.rotation))
        coupling = pairs.coupling()
        dq = -p["scale"] * np.einsum("nij,ij->ni", pairs.unit_mean, p["u"])
        dg = -p["scale"] * np.einsum("nij,ij->ni", pairs.half_difference, p["u"])
        eye = np.eye(3)
        jac = ClosureJacobians(pose=-pairs.unit_mean + coupling @ pairs.half_difference,
                               joints=dq[:, :, None] * eye - coupling * dg[:, None, :],
                               parameters=direct[0] - coupling @ direct[1])
        return pairs.closure(), jac

    def inverse_kinematics(self, theta: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """(N, 3) carriage travels below the endstops, mm. With the effector's rotation ``R``
        given, each tower's carriage point sits at distance ``s`` along the tower from ``F`` with
        ``|F + s u - Y| = a``, ``Y = X - (I - R) o`` (``o`` the pair's joint offset less the tool
        offset) and ``a^2 = arm^2 + arm_diff^2/4 - |d|^2``: the upper root ``s = u.e +
        sqrt((u.e)^2 - |e|^2 + a^2)``, ``e = Y - F`` (the carriage above the effector), then ``q
        = (H - s) / (1 + step_error/100) - endstop_drop``; the rotation is then solved at these
        joints (:meth:`pairs`), and the two alternate until the travels move less than
        :data:`IK_STEP_TOL_MM` (once, for equal rods: the effector is level).

        Raises:
            KinematicsError: the arm cannot reach the tower, or is square to it (a serial
                singularity); names the row and the tower.
        """
        p = self.split(theta)
        e_r, _, u = tower_directions(p["angle"], p["lean_r"], p["lean_t"])
        poses = np.asarray(poses, dtype=float)
        X = np.broadcast_to(poses[:, None, :], (poses.shape[0], 3, 3))
        offset, arm2, R, q = np.zeros(3), p["arm"] ** 2, None, None
        for _ in range(TILT_MAX_ITER):
            d = X - offset - p["radius"][:, None] * e_r
            b = np.einsum("nij,ij->ni", d, u)
            disc = b * b - np.einsum("nij,nij->ni", d, d) + arm2
            bad = ~(disc > (1e-6 * p["arm"]) ** 2)
            if np.any(bad):
                row, chain = (int(x) for x in np.argwhere(bad)[0])
                why = "cannot reach its tower" if not disc[row, chain] >= 0 else "is square to its tower (singular)"
                raise KinematicsError(f"row {row} is unreachable: the arm of {self.chain_word} {chain + 1} {why} "
                                      f"(pose {np.array2string(poses[row], precision=4)})", row)
            scale = 1.0 + p["step_error"] / STEP_ERROR_REFERENCE_MM
            q, before = (self.endstop_height_mm - (b + np.sqrt(disc))) / scale - p["endstop_drop"], q
            if not np.any(p["arm_diff"] != 0) or (before is not None and np.all(np.abs(q - before) < IK_STEP_TOL_MM)):
                return q
            pairs = self.pairs(theta, q, poses, rotation=R)
            R = pairs.rotation
            offset = pairs.offsets - pairs.rotated_offsets
            arm2 = pairs.target ** 2 - np.einsum("nij,nij->ni", pairs.half_difference, pairs.half_difference)
        return q

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
        reduced one's line through ``F_i - t + E_i``); the effector's, turned with it where a
        pair's rods differ (:meth:`pairs`)."""
        P, p = self.carriage_points(theta, joints)
        shift = self.effector_radius_mm * p["e_r"] - p["tool"]
        u = p["u"]
        foot = p["radius"][:, None] * p["e_r"] + shift - (shift[:, 2] / u[:, 2])[:, None] * u  # at z = 0
        pairs = self.pairs(theta, joints, poses)
        effector = np.asarray(poses, dtype=float)[:, None, :] + shift + (pairs.rotated_offsets - pairs.offsets)
        return np.stack([np.broadcast_to(foot, P.shape), P + shift, effector], axis=2)
