"""The MuJoCo hexapod (6-UPS Stewart-Gough platform), composed with ``mujoco.MjSpec``.

The machine: a fixed base; six legs, each a lower body on a universal joint (two hinges) at its
base joint ``B_i`` and an upper body on an actuated slide; each leg's tip closed on its
platform joint ``P_i`` by a ``connect`` equality (a ball joint); the platform on a free joint
carrying the ``platform`` site and its ``framepos``/``framequat`` sensors; an optional payload
above the platform. Contacts are off: the legs would touch the platform and the machine would
never settle.

Built from the parameter vector ``theta`` (:class:`calib.robots.Hexapod`, mm): leg i's tip is
``home_i + dl_i + q_i`` from its base joint, ``q_i`` the slide position, so that the joint value
(commanded leg length) ``l_i`` maps to ``q_i = l_i - home_i`` (``joint_offset`` = the home
lengths, ``joint_scale`` = 1e-3 m/mm) and the leg is ``l_i + dl_i`` long, as in the closure of
:mod:`calib.robots.hexapod`. The bodies are placed assembled at the pose the home lengths reach
(the forward kinematics of ``theta``), which is the keyframe ``home`` (every joint at 0).

Physics (SI): each leg's servo has stiffness ``actuator_stiffness`` (one per leg or shared; default
:data:`DEFAULT_STIFFNESS_N_PER_M`) and near-critical damping; explicit stiffness is stable for
``omega dt < 2`` with ``omega = sqrt(k / m_leg)``, so beyond ``omega dt = 1`` the step drops to
``0.3 / omega`` (:func:`integration_step`), and the closures' time constant follows the step so
that their own compliance stays well below the servo's. The transmission scale ``s_i`` is the
actuator's gear ``g = 1 / (1 + s_i)`` (the slide moves ``1 + s_i`` times the command) with gains
``kp / g^2``, ``kv / g^2`` so that the leg's stiffness stays ``actuator_stiffness``. Joint friction
is written as the slides' ``frictionloss`` (for the viewer and the dynamics); the testbed adds
its quasi-static limit itself (:mod:`pipeline.testbed`).

``python -m mjcf.hexapod --overwrite`` regenerates :data:`DEFAULT_XML` (the paper's machine,
Table 2 + Table 3, default options) for MuJoCo's viewer (``--out PATH`` writes it elsewhere;
``--help``; an existing file is replaced only with ``--overwrite``).
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from calib.files import atomic_write
from calib.robots.hexapod import Hexapod
from calib.rotation import quaternion_from_euler, rotation_matrix

from .machine import (HOME_KEY, PLATFORM_SITE, SENSOR_POS, SENSOR_QUAT, Machine, MachineOptions, add_end_stop, chain_values,
                      new_spec)
from .units import M_PER_MM, mm_to_m

__all__ = ["build_machine", "build_spec", "integration_step", "servo_damping", "DEFAULT_XML",
           "DEFAULT_STIFFNESS_N_PER_M", "DEFAULT_PLATFORM_MASS_KG", "LEG_MASS_KG", "save_default_xml", "main"]

#: The default machine (Table 2 + Table 3), saved for MuJoCo's viewer.
DEFAULT_XML = Path(__file__).with_name("hexapod_paper_actual.xml")
#: Default servo stiffness of each leg, N/m.
DEFAULT_STIFFNESS_N_PER_M = 2e5
#: Default mass of the moving platform, kg.
DEFAULT_PLATFORM_MASS_KG = 2.0
#: Mass of each half (lower, upper) of a leg, kg.
LEG_MASS_KG = 0.3
#: Viscous damping of each universal-joint hinge, N m s/rad.
UNIVERSAL_DAMPING = 0.5
#: Soft-constraint impedance of the leg closures (MuJoCo ``solimp``).
CLOSURE_SOLIMP = (0.99, 0.999, 0.0001, 0.5, 2.0)


def _stiffness(options: MachineOptions) -> np.ndarray:
    """(6,) each leg's servo stiffness, N/m."""
    k = DEFAULT_STIFFNESS_N_PER_M if options.actuator_stiffness is None else options.actuator_stiffness
    return chain_values(k, 6, "actuator_stiffness")


def _platform_mass(options: MachineOptions) -> float:
    return DEFAULT_PLATFORM_MASS_KG if options.platform_mass_kg is None else options.platform_mass_kg


def integration_step(options: MachineOptions) -> float:
    """The integration step used, s: ``options.timestep`` capped at ``0.3 / omega`` when
    ``omega dt > 1``, ``omega = sqrt(stiffness / leg mass)`` (the servo's stiffness is
    integrated explicitly; 0.3 / omega also settled fastest in our trials)."""
    omega = np.sqrt(_stiffness(options).max() / LEG_MASS_KG)
    return float(options.timestep if omega * options.timestep <= 1.0 else 0.3 / omega)


def servo_damping(options: MachineOptions) -> np.ndarray:
    """(6,) servo damping of each leg, N s/m: ``options.actuator_damping``, or critical damping
    of a leg (its own stiffness) carrying its share of platform and payload."""
    if options.actuator_damping is not None:
        return np.full(6, float(options.actuator_damping))
    m = LEG_MASS_KG + (_platform_mass(options) + options.payload_kg) / 6.0
    return 2.0 * np.sqrt(_stiffness(options) * m)


def _quat_z_to(d: np.ndarray) -> np.ndarray:
    """Quaternion [w, x, y, z] rotating the z axis onto the unit vector ``d``."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    s = np.linalg.norm(axis)
    if s < 1e-15:
        return np.array([1.0, 0.0, 0.0, 0.0])
    angle = np.arctan2(s, z @ d)
    return np.r_[np.cos(angle / 2), np.sin(angle / 2) * axis / s]


def _transmission(options: MachineOptions) -> np.ndarray:
    if options.transmission_scale is None:
        return np.zeros(6)
    s = np.asarray(options.transmission_scale, dtype=float)
    if s.shape != (6,):
        raise ValueError(f"transmission_scale must have 6 values (one per leg), got {s.size}")
    return s


def build_spec(robot: Hexapod, theta: np.ndarray, options: MachineOptions = MachineOptions(),
               name: str = "hexapod") -> mujoco.MjSpec:
    """The hexapod machine ``theta`` as an uncompiled ``MjSpec`` (see the module docstring).

    Args:
        robot: the hexapod (nominal geometry, home lengths and pose).
        theta: (42,) parameter vector, mm (nominal + errors).
        options: physical options.
        name: model name.
    """
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (robot.n_parameters,):
        raise ValueError(f"theta must have shape ({robot.n_parameters},), got {theta.shape}")
    s_scale = _transmission(options)
    B_mm, dl_mm, P_mm = robot.legs(theta)
    # Assembled at the pose the home lengths reach on this machine.
    home = robot.forward_kinematics(theta, robot.home_lengths[None])[0]
    B, P = mm_to_m(B_mm), mm_to_m(P_mm)
    t_home, R_home = mm_to_m(home[:3]), rotation_matrix(home[3:])
    rest = mm_to_m(robot.home_lengths + dl_mm)  # leg length at slide position 0
    radius = float(np.linalg.norm(P, axis=1).mean())
    step = integration_step(options)
    kp, kv = _stiffness(options), servo_damping(options)
    friction = chain_values(options.joint_friction, 6, "joint_friction")

    spec = new_spec(name, step, options.gravity)
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 960
    world = spec.worldbody
    world.add_light(pos=[0.0, 0.0, 1.5], dir=[0.0, 0.0, -1.0])
    world.add_geom(name="base", type=mujoco.mjtGeom.mjGEOM_CYLINDER, pos=[0.0, 0.0, -0.005],
                   size=[float(np.linalg.norm(B, axis=1).max()) + 0.02, 0.005, 0.0], rgba=[0.25, 0.25, 0.3, 1.0])
    for i in range(6):
        k = i + 1
        d = R_home @ P[i] + t_home - B[i]
        lower = world.add_body(name=f"leg{k}_lower", pos=B[i], quat=_quat_z_to(d / np.linalg.norm(d)))
        for axis, hinge in (([1.0, 0.0, 0.0], "ux"), ([0.0, 1.0, 0.0], "uy")):
            lower.add_joint(name=f"leg{k}_{hinge}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=axis,
                            damping=UNIVERSAL_DAMPING)
        half = rest[i] / 2
        lower.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, 0, 0, 0, half], size=[0.012, 0, 0],
                       mass=LEG_MASS_KG, rgba=[0.35, 0.4, 0.5, 1.0])
        upper = lower.add_body(name=f"leg{k}_upper")
        slide = upper.add_joint(name=f"leg{k}_slide", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0.0, 0.0, 1.0],
                                frictionloss=float(friction[i]))
        if robot.joint_ranges is not None:  # the legs' end stops as built, at the slide (m from home)
            add_end_stop(slide, *mm_to_m(robot.joint_ranges[i] - robot.home_lengths[i]), step)
        upper.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0, 0, half, 0, 0, rest[i]], size=[0.008, 0, 0],
                       mass=LEG_MASS_KG, rgba=[0.8, 0.55, 0.2, 1.0])
        upper.add_site(name=f"leg{k}_tip", pos=[0.0, 0.0, rest[i]], size=[0.005, 0, 0])
    platform = world.add_body(name="platform", pos=t_home, quat=quaternion_from_euler(home[3:]))
    platform.add_freejoint(name="platform_free")
    platform.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[radius + 0.01, 0.004, 0.0],
                      mass=_platform_mass(options), rgba=[0.3, 0.6, 0.8, 0.8])
    platform.add_site(name=PLATFORM_SITE, size=[0.004, 0, 0])
    for i in range(6):
        platform.add_site(name=f"P{i + 1}", pos=P[i], size=[0.006, 0, 0], rgba=[1.0, 1.0, 0.0, 1.0])
    if options.payload_kg > 0:
        payload = platform.add_body(name="payload", pos=[0.0, 0.0, options.payload_height_m])
        payload.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.5 * radius, 0.01, 0.0],
                         mass=options.payload_kg, rgba=[0.6, 0.2, 0.2, 1.0])
    for i in range(6):
        k = i + 1
        # Time constant of two steps (MuJoCo's stable minimum): the closure's compliance stays
        # well below the servo's, also for stiff servos.
        spec.add_equality(name=f"leg{k}_close", type=mujoco.mjtEq.mjEQ_CONNECT, objtype=mujoco.mjtObj.mjOBJ_SITE,
                          name1=f"leg{k}_tip", name2=f"P{k}", solref=[2 * step, 1.0], solimp=list(CLOSURE_SOLIMP))
        # Gear g: the servo acts on g q and holds the slide at ctrl / g; the slide sees the
        # stiffness kp g^2, hence kp / g^2.
        g = 1.0 / (1.0 + s_scale[i])
        act = spec.add_actuator(name=f"leg{k}", target=f"leg{k}_slide", trntype=mujoco.mjtTrn.mjTRN_JOINT,
                                gear=[g, 0, 0, 0, 0, 0])
        act.set_to_position(kp=float(kp[i]) / g**2, kv=float(kv[i]) / g**2)
    spec.add_sensor(name=SENSOR_POS, type=mujoco.mjtSensor.mjSENS_FRAMEPOS, objtype=mujoco.mjtObj.mjOBJ_SITE,
                    objname=PLATFORM_SITE)
    spec.add_sensor(name=SENSOR_QUAT, type=mujoco.mjtSensor.mjSENS_FRAMEQUAT, objtype=mujoco.mjtObj.mjOBJ_SITE,
                    objname=PLATFORM_SITE)
    # Home: every leg joint at 0 (6 x ux, uy, slide), the platform where it was placed.
    spec.add_key(name=HOME_KEY, qpos=np.r_[np.zeros(18), t_home, quaternion_from_euler(home[3:])], ctrl=np.zeros(6))
    return spec


def build_machine(robot: Hexapod, theta: np.ndarray, options: MachineOptions = MachineOptions()) -> Machine:
    """The compiled hexapod machine ``theta`` (the builder contract of :mod:`mjcf.machine`).

    Joint values are commanded leg lengths, mm: ``ctrl = (l - home) * 1e-3``.
    """
    model = build_spec(robot, theta, options).compile()
    return Machine(robot, theta, model, joint_offset=robot.home_lengths, joint_scale=np.full(6, M_PER_MM),
                   actuated_joints=tuple(f"leg{i + 1}_slide" for i in range(6)))


def save_default_xml(path: Path = DEFAULT_XML, *, overwrite: bool = False) -> Path:
    """Write the paper's machine (Table 2 + Table 3, default options) for MuJoCo's viewer, atomically.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    from calib.paper import TABLE3_ERRORS
    from calib.robots.hexapod import paper_hexapod

    robot = paper_hexapod()
    spec = build_spec(robot, robot.table.nominal + TABLE3_ERRORS.ravel(), name="hexapod_paper_actual")
    spec.compile()
    return atomic_write(path, spec.to_xml(), overwrite=overwrite)


def main(argv: list[str] | None = None) -> int:
    """``python -m mjcf.hexapod [--out PATH] [--overwrite]``: :func:`save_default_xml`, the path
    written on stdout; a refused flag or output is one line on stderr, exit status 2."""
    import argparse
    import sys

    p = argparse.ArgumentParser(prog="python -m mjcf.hexapod",
                                description="Write the hexapod paper's machine (Table 2 + Table 3, default "
                                            "options) as MJCF for MuJoCo's viewer.")
    p.add_argument("--out", type=Path, default=DEFAULT_XML, help=f"the MJCF file (default {DEFAULT_XML.name} beside this module)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing file (the saved default included)")
    p.error = lambda message: p.exit(2, f"error: {p.prog}: {' '.join(message.split())} (see --help)\n")
    args = p.parse_args(argv)
    try:
        print(save_default_xml(args.out, overwrite=args.overwrite))
    except OSError as exc:  # FileExistsError included
        print(f"error: --out: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
