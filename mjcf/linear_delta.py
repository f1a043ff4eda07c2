"""The MuJoCo linear Delta printer, composed with ``mujoco.MjSpec`` from a
:class:`calib.robots.LinearDelta` parameter vector.

The machine (see docs/linear_delta.md):

* Three carriages, each a body on an actuated slide along its tower's direction ``u_i``
  (pointing *down* the tower: the slide's position is the carriage's travel below where it was
  built), placed at the home pose. A joint value ``q`` (mm of counted travel below the endstop)
  is the slide at ``(1 + step_error/100) (q - q_home) 1e-3`` m: ``joint_offset = q_home`` (the
  machine's inverse kinematics at the robot's home pose), ``joint_scale = (1 + step_error/100)
  1e-3`` m/mm, so that the step error lives in the machine's unit boundary, as it does in a
  printer that counts steps. Each slide is driven by a stiff, damped position servo (gear ``1 /
  (1 + s_i)`` for a transmission scale ``s_i``, gains divided by the gear squared); joint
  friction is the slides' ``frictionloss``; declared joint ranges are the slides' end stops.
* Two rods per carriage, ``rod_spacing_mm`` apart along the pair's axle ``w_i`` (horizontal,
  counter-clockwise at the tower's nominal angle), each a body on a universal joint (two hinges,
  no spin) at the carriage and closed on the effector by a ``connect`` equality (a ball joint):
  six closures. The first rod of pair i is ``arm_i - arm_diff_i / 2`` long, the second (on the
  ``+w_i`` side) ``arm_i + arm_diff_i / 2``. The carriage's axle is parallel to the effector's,
  so equal rods make a parallelogram and the effector only translates; unequal rods tilt it.
  (A tower twisted about its own axis, or a carriage's axle tilted with a lean, would tilt the
  effector as well; the axles are held parallel here, as in the kinematic model.)
* The effector on a free joint (it may tilt), its pairs' joints ``effector_radius_mm`` from its
  centre at the towers' nominal angles, the ``platform`` site (the tool point, ``platform_pos``
  sensor) at the tool offset ``t`` from its centre. Each carriage's joint midpoint is the reduced
  carriage point (taken relative to the tool point) less ``t`` plus the effector's joint offset:
  with equal rods the effector's centre sits at ``X - t`` and the closures are exactly those of
  :mod:`calib.robots.linear_delta`, whatever ``t``; with unequal rods ``t`` is the tilt's lever.
* Contacts off; the keyframe ``home``: every slide and hinge at 0, the effector where the
  machine's forward kinematics puts it at the home joints, turned as the kinematics solves its
  rods (:meth:`calib.robots.linear_delta.LinearDelta.pairs`: level for equal rods), so that the
  six rods close there.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from calib.robots.linear_delta import STEP_ERROR_REFERENCE_MM, LinearDelta, tower_directions

from .hexapod import CLOSURE_SOLIMP  # the closures' impedance, as the other machines'
from .machine import (HOME_KEY, PLATFORM_SITE, SENSOR_POS, Machine, MachineOptions, add_end_stop, chain_values,
                      checked_machine_inputs, new_spec)
from .units import M_PER_MM, mm_to_m

__all__ = ["build_machine", "build_spec", "integration_step", "servo_damping", "CARRIAGE_JOINTS",
           "DEFAULT_STIFFNESS_N_PER_M", "DEFAULT_EFFECTOR_MASS_KG", "CARRIAGE_MASS_KG", "ROD_MASS_KG",
           "CHAIN_POINT_MASSES_KG", "rod_lengths"]

#: Names of the actuated (carriage) slides, tower order.
CARRIAGE_JOINTS: tuple[str, ...] = ("carriage1_slide", "carriage2_slide", "carriage3_slide")
#: Default servo stiffness of each carriage, N/m (a stepper holding a belt: 1e4-1e5 N/m).
DEFAULT_STIFFNESS_N_PER_M = 1e5
#: Default mass of the effector with its hot end, kg.
DEFAULT_EFFECTOR_MASS_KG = 0.15
#: A carriage's mass (with its wheels), kg, and one rod's, kg (a carbon tube with its ends).
CARRIAGE_MASS_KG, ROD_MASS_KG = 0.2, 0.02
#: The chain's masses lumped at its carriage (the carriage and half of each rod) and at the
#: effector's joints (the other halves), kg (see ``Machine.chain_point_masses_kg``).
CHAIN_POINT_MASSES_KG = (CARRIAGE_MASS_KG + ROD_MASS_KG, ROD_MASS_KG)
#: Viscous damping of the rods' hinges (N m s/rad) and of the effector's free joint (N s/m and
#: N m s/rad).
ROD_DAMPING, EFFECTOR_DAMPING = 0.05, 1.0


def _stiffness(options: MachineOptions) -> np.ndarray:
    """(3,) each carriage's servo stiffness, N/m."""
    k = DEFAULT_STIFFNESS_N_PER_M if options.actuator_stiffness is None else options.actuator_stiffness
    return chain_values(k, 3, "actuator_stiffness")


def _effector_mass(options: MachineOptions) -> float:
    return DEFAULT_EFFECTOR_MASS_KG if options.platform_mass_kg is None else options.platform_mass_kg


def integration_step(options: MachineOptions) -> float:
    """The integration step, s: ``options.timestep`` capped at ``0.3 / omega`` when ``omega dt >
    1``, ``omega = sqrt(stiffness / carriage mass)`` (the servo's stiffness is integrated
    explicitly; the hexapod's rule)."""
    omega = np.sqrt(_stiffness(options).max() / CARRIAGE_MASS_KG)
    return float(options.timestep if omega * options.timestep <= 1.0 else 0.3 / omega)


def servo_damping(options: MachineOptions) -> np.ndarray:
    """(3,) each carriage's servo damping, N s/m: ``options.actuator_damping``, or critical damping
    of a carriage (its own stiffness) carrying its rods and a third of effector and payload."""
    if options.actuator_damping is not None:
        return np.full(3, float(options.actuator_damping))
    m = CARRIAGE_MASS_KG + 2 * ROD_MASS_KG + (_effector_mass(options) + options.payload_kg) / 3.0
    return 2.0 * np.sqrt(_stiffness(options) * m)


def rod_lengths(robot: LinearDelta, theta: np.ndarray) -> np.ndarray:
    """(3, 2) mm: each pair's first and second rod, ``arm -+ arm_diff / 2``."""
    p = robot.split(theta)
    return np.stack([p["arm"] - p["arm_diff"] / 2, p["arm"] + p["arm_diff"] / 2], axis=1)


@dataclass(frozen=True)
class _Geometry:
    """The machine ``theta`` at its home pose, SI: ``home_q`` (3,) the joints there (mm),
    ``carriages`` (3, 3) the carriages' joint midpoints, ``down`` (3, 3) the slides' axes,
    ``axles`` (3, 3) the pairs' axles, ``centre`` (3,) the effector's centre, ``joints`` (3, 3) its
    pairs' joint midpoints (effector frame), ``tool`` (3,) the tool point (effector frame),
    ``rods`` (3, 2) the rods' lengths, ``scale`` (3,) ``1 + step_error / 100``, ``rotation`` (3, 3)
    the effector's (level for equal rods; tilted as the kinematics solves it for unequal ones)."""

    home_q: np.ndarray
    carriages: np.ndarray
    down: np.ndarray
    axles: np.ndarray
    centre: np.ndarray
    joints: np.ndarray
    tool: np.ndarray
    rods: np.ndarray
    scale: np.ndarray
    rotation: np.ndarray


def _geometry(robot: LinearDelta, theta: np.ndarray) -> _Geometry:
    home_q = robot.inverse_kinematics(theta, robot.home_pose[None])[0]
    tool_point = robot.forward_kinematics(theta, home_q[None], initial=robot.home_pose)[0]
    reduced, p = robot.carriage_points(theta, home_q[None])
    rotation = robot.pairs(theta, home_q[None], tool_point[None]).rotation[0]
    nominal_angle = robot.split(robot.table.nominal)["angle"]
    e_r, e_t, _ = tower_directions(nominal_angle, np.zeros(3), np.zeros(3))
    offsets = robot.effector_radius_mm * e_r
    return _Geometry(home_q=home_q, carriages=mm_to_m(reduced[0] - p["tool"] + offsets), down=-p["u"], axles=e_t,
                     centre=mm_to_m(tool_point - rotation @ p["tool"]), joints=mm_to_m(offsets),
                     tool=mm_to_m(p["tool"]), rods=mm_to_m(rod_lengths(robot, theta)), scale=p["scale"],
                     rotation=rotation)


def _effector_quaternion(geo: _Geometry) -> np.ndarray:
    """(4,) the effector's orientation at home, MuJoCo's ``[w, x, y, z]``."""
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(geo.rotation).ravel())
    return q


def _rod_frame(direction: np.ndarray, axle: np.ndarray) -> np.ndarray:
    """Quaternion of a rod's frame: z along the rod (``direction``, unit), x along the pair's axle
    made square to it."""
    x = axle - (axle @ direction) * direction
    x /= np.linalg.norm(x)
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.stack([x, np.cross(direction, x), direction], axis=1).ravel())
    return q


def _add_tower(spec: mujoco.MjSpec, geo: _Geometry, i: int, options: MachineOptions, step: float, gear: float,
               spacing_m: float, stop: np.ndarray | None) -> None:
    """Tower i: its carriage on the actuated slide (end stops ``stop``, mm of joint, or None), its
    two rods on universal joints, their closures on the effector and the position servo."""
    k = i + 1
    carriage = spec.worldbody.add_body(name=f"carriage{k}", pos=geo.carriages[i])
    slide = carriage.add_joint(name=CARRIAGE_JOINTS[i], type=mujoco.mjtJoint.mjJNT_SLIDE, axis=geo.down[i],
                               frictionloss=float(chain_values(options.joint_friction, 3, "joint_friction")[i]))
    if stop is not None:  # the carriage's travel as built, at the slide (m from home)
        add_end_stop(slide, *mm_to_m((stop - geo.home_q[i]) * geo.scale[i]), step)
    carriage.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.01, spacing_m / 2 + 0.01, 0.015],
                      mass=CARRIAGE_MASS_KG, rgba=[0.25, 0.25, 0.3, 1.0])
    for side, sign in enumerate((-1.0, 1.0)):
        name = f"rod{k}{'ab'[side]}"
        at = sign * spacing_m / 2 * geo.axles[i]
        reach = geo.centre + geo.rotation @ geo.joints[i] + geo.rotation @ at - (geo.carriages[i] + at)
        length = float(geo.rods[i, side])
        rod = carriage.add_body(name=name, pos=at, quat=_rod_frame(reach / np.linalg.norm(reach), geo.axles[i]))
        for axis, label in (([1.0, 0.0, 0.0], "u1"), ([0.0, 1.0, 0.0], "u2")):
            rod.add_joint(name=f"{name}_{label}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=axis, damping=ROD_DAMPING)
        rod.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, 0, 0, length], size=[0.003, 0, 0],
                     mass=ROD_MASS_KG, rgba=[0.1, 0.1, 0.1, 1.0])
        rod.add_site(name=f"{name}_end", pos=[0.0, 0.0, length], size=[0.004, 0, 0])
        spec.add_equality(name=f"close_{name}", type=mujoco.mjtEq.mjEQ_CONNECT, objtype=mujoco.mjtObj.mjOBJ_SITE,
                          name1=f"{name}_end", name2=f"effector_{name}", solref=[2 * step, 1.0],
                          solimp=list(CLOSURE_SOLIMP))
    act = spec.add_actuator(name=f"stepper{k}", target=CARRIAGE_JOINTS[i], trntype=mujoco.mjtTrn.mjTRN_JOINT,
                            gear=[gear, 0, 0, 0, 0, 0])
    act.set_to_position(kp=float(_stiffness(options)[i]) / gear ** 2, kv=float(servo_damping(options)[i]) / gear ** 2)


def _add_effector(world, geo: _Geometry, options: MachineOptions, spacing_m: float) -> None:
    """The effector on its free joint: the rods' joint sites, the tool site, the payload."""
    effector = world.add_body(name="effector", pos=geo.centre, quat=_effector_quaternion(geo))
    effector.add_freejoint(name="effector_free")
    effector.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, mass=_effector_mass(options), rgba=[0.3, 0.6, 0.8, 1.0],
                      size=[float(np.linalg.norm(geo.joints, axis=1).max()) + 0.005, 0.004, 0.0])
    effector.add_site(name=PLATFORM_SITE, pos=geo.tool, size=[0.003, 0, 0], rgba=[1.0, 0.3, 0.0, 1.0])
    for i in range(3):
        for side, sign in enumerate((-1.0, 1.0)):
            effector.add_site(name=f"effector_rod{i + 1}{'ab'[side]}",
                              pos=geo.joints[i] + sign * spacing_m / 2 * geo.axles[i], size=[0.004, 0, 0])
    if options.payload_kg > 0:
        payload = effector.add_body(name="payload", pos=[0.0, 0.0, options.payload_height_m])
        payload.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.02, 0.01, 0.0], mass=options.payload_kg,
                         rgba=[0.6, 0.2, 0.2, 1.0])


def build_spec(robot: LinearDelta, theta: np.ndarray, options: MachineOptions = MachineOptions(),
               name: str = "linear_delta") -> mujoco.MjSpec:
    """The linear Delta machine ``theta`` as an uncompiled ``MjSpec`` (see the module docstring).

    Args:
        robot: the linear Delta (endstop heights, home pose, effector and rod sizes).
        theta: (27,) parameter vector, mm and rad.
        options: physical options.
        name: model name.
    """
    theta, scale = checked_machine_inputs(robot, theta, options)
    geo = _geometry(robot, theta)
    step = integration_step(options)
    spacing_m = float(mm_to_m(robot.rod_spacing_mm))
    spec = new_spec(name, step, options.gravity)
    spec.worldbody.add_geom(name="bed", type=mujoco.mjtGeom.mjGEOM_CYLINDER, pos=[0.0, 0.0, -0.002],
                            size=[float(mm_to_m(robot.full_workspace_bounds()[0, 1])) + 0.01, 0.002, 0.0],
                            rgba=[0.5, 0.5, 0.5, 0.5])
    for i in range(3):
        _add_tower(spec, geo, i, options, step, 1.0 / (1.0 + scale[i]), spacing_m,
                   None if robot.joint_ranges is None else robot.joint_ranges[i])
    _add_effector(spec.worldbody, geo, options, spacing_m)
    spec.add_sensor(name=SENSOR_POS, type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objtype=mujoco.mjtObj.mjOBJ_SITE,
                    objname=PLATFORM_SITE)
    # Home: every slide and hinge at 0 (3 x slide, 2 x 2 hinges), the effector where it was placed.
    spec.add_key(name=HOME_KEY, qpos=np.r_[np.zeros(15), geo.centre, _effector_quaternion(geo)], ctrl=np.zeros(3))
    return spec


def build_machine(robot: LinearDelta, theta: np.ndarray, options: MachineOptions = MachineOptions()) -> Machine:
    """The compiled linear Delta machine ``theta`` (the builder contract of :mod:`mjcf.machine`).

    Joint values are counted travels below the endstops, mm: ``ctrl = (q - q_home) (1 +
    step_error/100) 1e-3``.
    """
    theta = np.asarray(theta, dtype=float)
    model = build_spec(robot, theta, options).compile()
    geo_scale = 1.0 + robot.split(theta)["step_error"] / STEP_ERROR_REFERENCE_MM
    home_q = robot.inverse_kinematics(theta, robot.home_pose[None])[0]
    return Machine(robot, theta, model, joint_offset=home_q, joint_scale=geo_scale * M_PER_MM,
                   actuated_joints=CARRIAGE_JOINTS, chain_point_masses_kg=CHAIN_POINT_MASSES_KG)
