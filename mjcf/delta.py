"""The MuJoCo Delta robot, composed with ``mujoco.MjSpec`` from a Model-24 parameter vector.

Modelling choices (see docs/delta.md):

* Each parallelogram forearm is ONE bar with a universal joint at the elbow (two hinges: one
  parallel to the actuated axis, one perpendicular) and a ball joint at the plate, a
  ``connect`` equality between the bar's end site and the plate's attachment site. The plate
  carries three slides (x, y, z) and no rotation, which is what the three parallelograms
  enforce; with the orientation held, a single bar is kinematically equivalent to the
  parallelogram for the plate position. The universal joint (instead of a ball) removes the
  bar's free spin.
* Chain ``i`` is attached to the plate at ``c_i = rn (cos theta_i, sin theta_i, 0)`` (plate
  frame; ``rn`` = :attr:`calib.robots.Delta.rn_mm`) and its actuated joint sits at
  ``D_i + c_i``, so the closure is ``||X + c_i - (D_i + c_i + arm_i)|| = ||X - D_i - arm_i|| = Lb_i``:
  exactly the reduced Model 24 of :mod:`calib.robots.delta`, with a physically sized base and
  plate.
* Arm ``i``: body frame ``R_z(theta_i) R_y(alpha_i)`` at the physical shoulder, a hinge about its
  local ``y``, so that the hinge position IS the joint reading ``q_i`` (``joint_offset`` 0,
  ``joint_scale`` 1); elbow site at ``(Lax_i, 0, Lay_i)``; driven by a stiff, damped position
  servo (gear ``1 / (1 + s_i)`` for a transmission scale ``s_i``, gains divided by the gear
  squared). Joint friction is written as the hinges' ``frictionloss``; the testbed adds its
  quasi-static limit.
* Contacts off; the keyframe ``home`` is the machine assembled at the joint readings that reach
  the robot's home position (plate slides at 0, the plate body placed there).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from calib.robots.delta import Delta

from .machine import (HOME_KEY, PLATFORM_SITE, SENSOR_POS, Machine, MachineOptions, add_end_stop, chain_values,
                      checked_machine_inputs, new_spec)
from .units import mm_to_m

__all__ = ["build_machine", "build_spec", "integration_step", "ARM_JOINTS", "DEFAULT_STIFFNESS_NM_PER_RAD",
           "DEFAULT_DAMPING_NMS_PER_RAD", "DEFAULT_PLATFORM_MASS_KG"]

#: Names of the actuated (arm) hinge joints, chain order.
ARM_JOINTS: tuple[str, ...] = ("arm1_hinge", "arm2_hinge", "arm3_hinge")
#: Default servo stiffness of each arm, N m/rad.
DEFAULT_STIFFNESS_NM_PER_RAD = 2000.0
#: Default servo damping of each arm, N m s/rad.
DEFAULT_DAMPING_NMS_PER_RAD = 40.0
#: Default mass of the travelling plate, kg.
DEFAULT_PLATFORM_MASS_KG = 0.3
#: Arm mass, kg, and its inertia about its centre (diagonal), kg m^2.
ARM_MASS_KG, ARM_INERTIA = 0.3, 0.002
#: Forearm (bar) mass, kg.
FOREARM_MASS_KG = 0.1
#: The chain's masses lumped at its elbow and at its plate joint, kg: the arm's centre of mass is
#: half-way to the elbow, the forearm's half-way along the bar (see ``Machine.chain_point_masses_kg``).
CHAIN_POINT_MASSES_KG = (ARM_MASS_KG / 2 + FOREARM_MASS_KG / 2, FOREARM_MASS_KG / 2)
#: Damping of the actuated hinge (N m s/rad) and of the passive joints (forearm hinges
#: N m s/rad, plate slides N s/m).
ARM_DAMPING, PASSIVE_DAMPING = 0.1, 2.0
#: Soft-constraint impedance of the closures (MuJoCo ``solimp``); their time constant is two
#: integration steps (MuJoCo's stable minimum). With a time constant of 5 ms instead, the plate
#: sagged 0.1-0.8 mm under gravity (0-5 kg payload) at the closures, a softness the real
#: mechanism does not have and that swamped the servo compliance.
CLOSURE_SOLIMP = (0.99, 0.999, 0.0001, 0.5, 2.0)


def _rz(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _quat(r: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(r).ravel())
    return q


def _stiffness(options: MachineOptions) -> np.ndarray:
    """(3,) each arm's servo stiffness, N m/rad."""
    k = DEFAULT_STIFFNESS_NM_PER_RAD if options.actuator_stiffness is None else options.actuator_stiffness
    return chain_values(k, 3, "actuator_stiffness")


def integration_step(options: MachineOptions, arm_m: float) -> float:
    """The integration step, s: ``options.timestep`` capped at ``0.3 / omega`` when
    ``omega dt > 1``, ``omega = sqrt(stiffness / arm inertia about its hinge)`` (the servo's
    stiffness is integrated explicitly). ``arm_m``: arm length, m."""
    inertia = ARM_INERTIA + ARM_MASS_KG * (arm_m / 2) ** 2
    omega = np.sqrt(_stiffness(options).max() / inertia)
    return float(options.timestep if omega * options.timestep <= 1.0 else 0.3 / omega)


@dataclass(frozen=True)
class _Geometry:
    """The Delta machine ``theta``'s geometry in the model's metres: ``p`` its parameters,
    ``home_q`` (3,) the arm angles at the home pose, ``home_plate`` (3,) the plate there, and per
    chain (3, 3) the plate's attachment points (plate frame), the shoulders, the arm vectors
    (arm frame), and (3,) the forearm lengths."""

    p: object
    home_q: np.ndarray
    home_plate: np.ndarray
    attach: np.ndarray
    shoulders: np.ndarray
    arms: np.ndarray
    forearms: np.ndarray


def _geometry(robot: Delta, theta: np.ndarray) -> _Geometry:
    p = robot.params(theta)
    home_q = robot.inverse_kinematics(theta, robot.home_pose[None])[0]
    home_plate = mm_to_m(robot.forward_kinematics(theta, home_q[None])[0])
    attach = mm_to_m(robot.rn_mm * np.stack([np.cos(p.theta), np.sin(p.theta), np.zeros(3)], axis=1))
    return _Geometry(p=p, home_q=home_q, home_plate=home_plate, attach=attach,
                     shoulders=mm_to_m(p.shoulders()) + attach,
                     arms=mm_to_m(np.stack([p.Lax, np.zeros(3), p.Lay], axis=1)), forearms=mm_to_m(p.Lb))


def _add_plate(world, geo: _Geometry, options: MachineOptions) -> None:
    """The base's disc, and the plate (three slides) with its sites and the payload."""
    platform_kg = DEFAULT_PLATFORM_MASS_KG if options.platform_mass_kg is None else options.platform_mass_kg
    world.add_geom(name="base", type=mujoco.mjtGeom.mjGEOM_CYLINDER, pos=[0.0, 0.0, 0.01],
                   size=[float(np.linalg.norm(geo.shoulders, axis=1).max()) + 0.02, 0.01, 0.0],
                   rgba=[0.5, 0.5, 0.5, 0.5])
    plate = world.add_body(name="plate", pos=geo.home_plate)
    for axis, label in (([1.0, 0.0, 0.0], "x"), ([0.0, 1.0, 0.0], "y"), ([0.0, 0.0, 1.0], "z")):
        plate.add_joint(name=f"plate_{label}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis, damping=PASSIVE_DAMPING)
    plate.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                   size=[float(np.linalg.norm(geo.attach, axis=1).max()) + 0.01, 0.005, 0],
                   mass=platform_kg, rgba=[0.3, 0.7, 0.3, 1.0])
    plate.add_site(name=PLATFORM_SITE, size=[0.01, 0, 0])
    for i in range(3):
        plate.add_site(name=f"plate_c{i + 1}", pos=geo.attach[i], size=[0.008, 0, 0])
    if options.payload_kg > 0:
        payload = plate.add_body(name="payload", pos=[0.0, 0.0, options.payload_height_m])
        payload.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.03, 0.01, 0.0], mass=options.payload_kg,
                         rgba=[0.6, 0.2, 0.2, 1.0])


def _forearm_frame(geo: _Geometry, i: int, r_arm: np.ndarray) -> np.ndarray:
    """Chain i's forearm frame in its arm frame at home: z along the bar, x along the actuated
    axis (orthogonalised)."""
    r_home = r_arm @ _ry(geo.home_q[i])
    zf = r_home.T @ (geo.home_plate + geo.attach[i] - geo.shoulders[i] - r_home @ geo.arms[i])
    zf /= np.linalg.norm(zf)
    ey = np.array([0.0, 1.0, 0.0])
    xf = ey - (ey @ zf) * zf
    xf /= np.linalg.norm(xf)
    return np.stack([xf, np.cross(zf, xf), zf], axis=1)


def _add_chain(spec: mujoco.MjSpec, geo: _Geometry, i: int, options: MachineOptions, step: float,
               gear: float, stop: np.ndarray | None = None) -> None:
    """Chain i: the actuated arm, the forearm on its two-hinge universal joint, the closure to the
    plate and the position servo (gear ``gear``: it holds the hinge at ctrl / gear); ``stop``
    (low, high) the arm's end stops, rad, or None."""
    k = i + 1
    r_arm = _rz(geo.p.theta[i]) @ _ry(geo.p.alpha[i])  # arm frame at q = 0
    elbow = geo.arms[i]
    arm = spec.worldbody.add_body(name=f"arm{k}", pos=geo.shoulders[i], quat=_quat(r_arm))
    friction = chain_values(options.joint_friction, 3, "joint_friction")
    hinge = arm.add_joint(name=ARM_JOINTS[i], type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0.0, 1.0, 0.0],
                          damping=ARM_DAMPING, frictionloss=float(friction[i]))
    if stop is not None:
        add_end_stop(hinge, *stop, step)
    arm.explicitinertial = True
    arm.ipos, arm.mass, arm.inertia = elbow / 2, ARM_MASS_KG, [ARM_INERTIA] * 3
    arm.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=np.r_[np.zeros(3), elbow], size=[0.012, 0, 0],
                 rgba=[0.2, 0.4, 0.8, 1.0])
    arm.add_site(name=f"elbow{k}", pos=elbow, size=[0.01, 0, 0])
    fore = arm.add_body(name=f"forearm{k}", pos=elbow, quat=_quat(_forearm_frame(geo, i, r_arm)))
    for axis, label in (([1.0, 0.0, 0.0], "u1"), ([0.0, 1.0, 0.0], "u2")):
        fore.add_joint(name=f"fa{k}_{label}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=axis, damping=PASSIVE_DAMPING)
    lb = float(geo.forearms[i])
    fore.explicitinertial = True
    fore.ipos, fore.mass, fore.inertia = [0.0, 0.0, lb / 2], FOREARM_MASS_KG, [0.002, 0.002, 0.0002]
    fore.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, 0, 0, lb], size=[0.006, 0, 0],
                  rgba=[0.8, 0.5, 0.2, 1.0])
    fore.add_site(name=f"fa{k}_end", pos=[0.0, 0.0, lb], size=[0.008, 0, 0])
    spec.add_equality(name=f"close{k}", type=mujoco.mjtEq.mjEQ_CONNECT, objtype=mujoco.mjtObj.mjOBJ_SITE,
                      name1=f"fa{k}_end", name2=f"plate_c{k}", solref=[2 * step, 1.0],
                      solimp=list(CLOSURE_SOLIMP))
    kv = DEFAULT_DAMPING_NMS_PER_RAD if options.actuator_damping is None else options.actuator_damping
    act = spec.add_actuator(name=f"motor{k}", target=ARM_JOINTS[i], trntype=mujoco.mjtTrn.mjTRN_JOINT,
                            gear=[gear, 0, 0, 0, 0, 0])
    act.set_to_position(kp=float(_stiffness(options)[i]) / gear**2, kv=kv / gear**2)


def build_spec(robot: Delta, theta: np.ndarray, options: MachineOptions = MachineOptions(),
               name: str = "delta") -> mujoco.MjSpec:
    """The Delta machine ``theta`` as an uncompiled ``MjSpec`` (see the module docstring).

    Args:
        robot: the Delta (plate radius ``rn_mm``, home position).
        theta: (24,) Model-24 parameter vector, mm and rad.
        options: physical options.
        name: model name.
    """
    theta, scale = checked_machine_inputs(robot, theta, options)
    geo = _geometry(robot, theta)
    step = integration_step(options, float(np.linalg.norm(geo.arms, axis=1).max()))
    spec = new_spec(name, step, options.gravity)
    _add_plate(spec.worldbody, geo, options)
    home_qpos = [0.0, 0.0, 0.0]
    for i in range(3):
        _add_chain(spec, geo, i, options, step, 1.0 / (1.0 + scale[i]),
                   None if robot.joint_ranges is None else robot.joint_ranges[i])  # the arms' stops as built
        home_qpos += [float(geo.home_q[i]), 0.0, 0.0]
    spec.add_sensor(name=SENSOR_POS, type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objtype=mujoco.mjtObj.mjOBJ_SITE,
                    objname=PLATFORM_SITE)
    # The servo holds the hinge at ctrl / g.
    spec.add_key(name=HOME_KEY, qpos=home_qpos, ctrl=geo.home_q / (1.0 + scale))
    return spec


def build_machine(robot: Delta, theta: np.ndarray, options: MachineOptions = MachineOptions()) -> Machine:
    """The compiled Delta machine ``theta`` (the builder contract of :mod:`mjcf.machine`).

    Joint values are the arm angles read at the hinges, rad: ``ctrl = q``.
    """
    model = build_spec(robot, theta, options).compile()
    return Machine(robot, theta, model, joint_offset=np.zeros(3), joint_scale=np.ones(3), actuated_joints=ARM_JOINTS,
                   chain_point_masses_kg=CHAIN_POINT_MASSES_KG)
