"""MuJoCo machine of a rotary hexapod (6-RUS, :mod:`calib.robots.rus`) composed with ``MjSpec``.

A fixed base; per chain a motor body at ``M_i`` whose frame is ``(u'_i, v'_i, a_i)`` (the
crank frame turned by the zero offset ``q0_i``) with a hinge about ``a_i``, so that the hinge
position is the motor angle ``q_i`` (``joint_offset`` 0, ``joint_scale`` 1); the crank along the
body's x axis, ``r_i`` long; a rod body on a ball joint at the crank tip, ``s_i`` long along its
z axis, ending at a site closed on the platform joint site ``P_i`` by a ``connect`` equality
constraint; the platform on a free joint. Position servos on the hinges, contacts off, the
keyframe ``home`` assembled at the robot's home pose (motor angles from the inverse kinematics
of ``theta``). The motors carry a reflected rotor inertia (``armature``) that keeps a stiff
servo stable at a millisecond step.
"""

from __future__ import annotations

import mujoco
import numpy as np

from calib.robots.rus import RotaryHexapod, crank_frames
from calib.rotation import quaternion_from_euler, rotation_matrix

from .machine import (HOME_KEY, PLATFORM_SITE, SENSOR_POS, SENSOR_QUAT, Machine, MachineOptions, add_end_stop, chain_values,
                      new_spec)
from .units import mm_to_m

__all__ = ["build_machine", "build_spec", "MOTOR_JOINTS", "DEFAULT_STIFFNESS_NM_PER_RAD", "MOTOR_ARMATURE_KG_M2", "DEFAULT_PLATFORM_MASS_KG"]

#: Default servo stiffness of each motor, N m/rad.
DEFAULT_STIFFNESS_NM_PER_RAD = 200.0
#: Rotor inertia reflected through each motor's gearbox, kg m^2.
MOTOR_ARMATURE_KG_M2 = 1e-3
#: Default mass of the moving platform, kg.
DEFAULT_PLATFORM_MASS_KG = 1.0
#: Masses of each crank and each rod, kg.
CRANK_MASS_KG, ROD_MASS_KG = 0.05, 0.02
#: The chain's masses lumped at its crank tip and at its platform joint, kg: the crank's centre of
#: mass is half-way to its tip, the rod's half-way along it (see ``Machine.chain_point_masses_kg``).
CHAIN_POINT_MASSES_KG = (CRANK_MASS_KG / 2 + ROD_MASS_KG / 2, ROD_MASS_KG / 2)
#: Names of the actuated (motor) hinge joints, chain order.
MOTOR_JOINTS: tuple[str, ...] = tuple(f"motor{i + 1}" for i in range(6))
#: Damping of each rod's ball joint (settles the rod's free spin about its own axis), N m s/rad.
BALL_DAMPING = 1e-4


def _quat(R: np.ndarray) -> np.ndarray:
    """[w, x, y, z] of a rotation matrix."""
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R).ravel())
    return q


def _z_onto(d: np.ndarray) -> np.ndarray:
    """A rotation matrix whose z column is the unit vector ``d``."""
    x = np.cross([0.0, 1.0, 0.0], d) if abs(d[1]) < 0.9 else np.cross([1.0, 0.0, 0.0], d)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(d, x), d])


def _rz(t: float) -> np.ndarray:
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _servo(o: MachineOptions, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``(kp (6,), kv (6,), step)``: the motors' servo stiffness and damping (near-critical for a motor
    carrying its crank, its rod and a sixth of the platform, unless given) and the integration
    step (lowered so that the explicit stiffness stays stable)."""
    platform_mass = DEFAULT_PLATFORM_MASS_KG if o.platform_mass_kg is None else o.platform_mass_kg
    kp = chain_values(DEFAULT_STIFFNESS_NM_PER_RAD if o.actuator_stiffness is None else o.actuator_stiffness, 6,
                      "actuator_stiffness")
    crank_inertia = MOTOR_ARMATURE_KG_M2 + CRANK_MASS_KG * r ** 2 / 3.0
    loaded = crank_inertia + (ROD_MASS_KG + (platform_mass + o.payload_kg) / 6.0) * r ** 2
    kv = 2.0 * np.sqrt(kp * loaded) if o.actuator_damping is None else np.full(6, o.actuator_damping)
    omega = float(np.sqrt(kp.max() / crank_inertia.min()))
    step = o.timestep if omega * o.timestep <= 1.0 else 0.3 / omega
    return kp, kv, step


def _add_chains(world, robot: RotaryHexapod, p: dict, q_home: np.ndarray, o: MachineOptions, step: float) -> None:
    """The base's disc and each chain's motor (with its end stops where the description declares
    joint ranges), crank and rod, the rod pointing at its platform joint with the motor at
    ``q_home``."""
    home = robot.home_pose
    u, v, a = crank_frames(p["az"], p["el"])
    M, P = mm_to_m(p["M"]), mm_to_m(p["P"])
    r, s = mm_to_m(p["r"]), mm_to_m(p["s"])
    R_home, t_home = rotation_matrix(home[3:6]), mm_to_m(home[0:3])
    world.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[float(np.linalg.norm(M, axis=1).max()) + 0.03, 0.005, 0],
                   pos=[0, 0, float(M[:, 2].min()) - 0.03], contype=0, conaffinity=0, rgba=[0.25, 0.25, 0.3, 1])
    platform_joints = R_home @ P.T + t_home[:, None]  # (3, 6) base frame, m
    friction = chain_values(o.joint_friction, 6, "joint_friction")
    for i in range(6):
        c, sn = np.cos(p["q0"][i]), np.sin(p["q0"][i])
        R_motor = np.column_stack([c * u[i] + sn * v[i], -sn * u[i] + c * v[i], a[i]])
        motor = world.add_body(name=f"motor{i + 1}", pos=M[i], quat=_quat(R_motor))
        hinge = motor.add_joint(name=MOTOR_JOINTS[i], type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1],
                                armature=MOTOR_ARMATURE_KG_M2, frictionloss=float(friction[i]))
        if robot.joint_ranges is not None:  # the motors' end stops as built, rad
            add_end_stop(hinge, *robot.joint_ranges[i], step)
        motor.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, r[i], 0, 0], size=[0.006, 0, 0],
                       mass=CRANK_MASS_KG, contype=0, conaffinity=0, rgba=[0.35, 0.4, 0.5, 1])
        # The rod's frame points its z axis at the platform joint when the motor is at q_home.
        R_crank = R_motor @ _rz(q_home[i])
        tip = M[i] + R_crank[:, 0] * r[i]
        d = platform_joints[:, i] - tip
        rod = motor.add_body(name=f"rod{i + 1}", pos=[r[i], 0, 0], quat=_quat(R_crank.T @ _z_onto(d / np.linalg.norm(d))))
        rod.add_joint(name=f"rod{i + 1}_ball", type=mujoco.mjtJoint.mjJNT_BALL, damping=BALL_DAMPING)
        rod.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, 0, 0, s[i]], size=[0.004, 0, 0],
                     mass=ROD_MASS_KG, contype=0, conaffinity=0, rgba=[0.8, 0.55, 0.2, 1])
        rod.add_site(name=f"rod{i + 1}_end", pos=[0, 0, s[i]])


def _add_platform(world, robot: RotaryHexapod, p: dict, o: MachineOptions) -> None:
    """The platform (a free body at the home pose) with its joints' sites and the payload."""
    home = robot.home_pose
    P = mm_to_m(p["P"])
    platform_mass = DEFAULT_PLATFORM_MASS_KG if o.platform_mass_kg is None else o.platform_mass_kg
    plat = world.add_body(name="platform", pos=mm_to_m(home[0:3]), quat=quaternion_from_euler(home[3:6]))
    plat.add_freejoint(name="platform_free")
    radius = float(np.linalg.norm(P, axis=1).max())
    plat.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[radius + 0.01, 0.004, 0], mass=platform_mass,
                  contype=0, conaffinity=0, rgba=[0.3, 0.6, 0.8, 0.8])
    plat.add_site(name=PLATFORM_SITE)
    for i in range(6):
        plat.add_site(name=f"P{i + 1}", pos=P[i])
    if o.payload_kg > 0:
        plat.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.5 * radius, 0.01, 0], pos=[0, 0, o.payload_height_m],
                      mass=o.payload_kg, contype=0, conaffinity=0, rgba=[0.6, 0.2, 0.2, 1])


def _add_closures_and_servos(spec: mujoco.MjSpec, scale, kp: np.ndarray, kv: np.ndarray, step: float) -> None:
    """Each chain's closure (rod end onto platform joint), its position servo and the pose sensors."""
    for i in range(6):
        # The closure's time constant follows the step (two steps, MuJoCo's stable minimum).
        spec.add_equality(name=f"chain{i + 1}_close", type=mujoco.mjtEq.mjEQ_CONNECT, objtype=mujoco.mjtObj.mjOBJ_SITE,
                          name1=f"rod{i + 1}_end", name2=f"P{i + 1}", solref=[2 * step, 1],
                          solimp=[0.99, 0.999, 1e-4, 0.5, 2])
        # gear g: the servo holds the hinge at ctrl / g; kp / g^2 keeps its stiffness at kp.
        g = 1.0 / (1.0 + scale[i])
        act = spec.add_actuator(name=f"motor{i + 1}", target=MOTOR_JOINTS[i], trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.gear[0] = g
        act.set_to_position(kp=float(kp[i]) / g ** 2, kv=float(kv[i]) / g ** 2)
    spec.add_sensor(name=SENSOR_POS, type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objtype=mujoco.mjtObj.mjOBJ_SITE,
                    objname=PLATFORM_SITE)
    spec.add_sensor(name=SENSOR_QUAT, type=mujoco.mjtSensor.mjSENS_FRAMEQUAT, objtype=mujoco.mjtObj.mjOBJ_SITE,
                    objname=PLATFORM_SITE)


def build_spec(robot: RotaryHexapod, theta: np.ndarray, options: MachineOptions = MachineOptions(),
               name: str = "rus") -> mujoco.MjSpec:
    """The machine of parameter set ``theta`` (66,) (mm, rad) of ``robot`` as an uncompiled ``MjSpec``
    with its keyframe ``home`` (see the module docstring).

    Raises:
        calib.robot.KinematicsError: ``theta`` cannot reach the robot's home pose.
        ValueError: ``options.transmission_scale`` is not six numbers.
    """
    o = options
    scale = (0.0,) * 6 if o.transmission_scale is None else o.transmission_scale
    if len(scale) != 6:
        raise ValueError(f"transmission_scale must have 6 entries for the rotary hexapod, got {len(scale)}")
    p = robot.split(theta)
    q_home = robot.inverse_kinematics(theta, robot.home_pose[None])[0]
    kp, kv, step = _servo(o, mm_to_m(p["r"]))
    spec = new_spec(name, step, o.gravity)
    _add_chains(spec.worldbody, robot, p, q_home, o, step)
    _add_platform(spec.worldbody, robot, p, o)
    _add_closures_and_servos(spec, scale, kp, kv, step)
    model = spec.compile()  # the keyframe's qpos: the compiled layout, the motors at q_home
    qpos = model.qpos0.copy()
    qpos[[model.joint(n).qposadr[0] for n in MOTOR_JOINTS]] = q_home
    gears = 1.0 / (1.0 + np.asarray(scale))
    spec.add_key(name=HOME_KEY, qpos=qpos, ctrl=q_home * gears)
    return spec


def build_machine(robot: RotaryHexapod, theta: np.ndarray, options: MachineOptions = MachineOptions()) -> Machine:
    """The compiled machine of parameter set ``theta`` (66,) (mm, rad) of ``robot`` (the builder
    contract of :mod:`mjcf.machine`; :func:`build_spec` composes it).

    Raises:
        calib.robot.KinematicsError: ``theta`` cannot reach the robot's home pose.
        ValueError: ``options.transmission_scale`` is not six numbers.
    """
    return Machine(robot, theta, build_spec(robot, theta, options).compile(), joint_offset=np.zeros(6),
                   joint_scale=np.ones(6), actuated_joints=MOTOR_JOINTS, chain_point_masses_kg=CHAIN_POINT_MASSES_KG)
