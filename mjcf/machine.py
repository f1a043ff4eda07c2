"""A compiled MuJoCo machine of one robot parameter set, and the physical options it is built with.

Every robot's builder module (``mjcf/<robot>.py``) exposes
``build_machine(robot, theta, options) -> Machine``: it composes the machine with
``mujoco.MjSpec`` from the parameter vector ``theta`` (mm, rad; errors are injected by building
from perturbed parameters, never by editing a compiled model), converting to SI through
:mod:`mjcf.units`. The :class:`Machine` it returns carries the one unit boundary the testbed
needs: joint values to actuator controls, sensors to poses.

Conventions every builder follows:

* one position actuator per chain, in chain order, acting on the chain's actuated joint;
  ``ctrl = (joint - joint_offset) * joint_scale`` (SI); reading back
  ``joint = qpos / joint_scale + joint_offset``;
* a site ``platform`` on the moving platform at the pose's origin, with a ``framepos`` sensor
  ``platform_pos`` and (6-DOF platforms) a ``framequat`` sensor ``platform_quat``;
* contacts off; a keyframe ``home`` in which the machine is assembled at its home pose.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import mujoco
import numpy as np

from calib.robot import Robot
from calib.rotation import euler_from_quaternion

from .units import m_to_mm

__all__ = ["MachineOptions", "MachineEffects", "Machine", "new_spec", "chain_values", "checked_machine_inputs", "add_end_stop", "END_STOP_SOLIMP", "END_STOP_DAMPING_RATIO", "spec_xml", "xml_digits", "XML_DIGITS", "MUJOCO_XML_DIGITS", "PLATFORM_SITE", "SENSOR_POS", "SENSOR_QUAT", "HOME_KEY", "GRAVITY_M_S2"]

#: Name of the platform site whose frame is the pose.
PLATFORM_SITE = "platform"
#: Name of the platform position sensor (framepos).
SENSOR_POS = "platform_pos"
#: Name of the platform orientation sensor (framequat), 6-DOF platforms only.
SENSOR_QUAT = "platform_quat"
#: Name of the keyframe at the home pose.
HOME_KEY = "home"
#: Standard gravity, m/s^2 (the one place it is named).
GRAVITY_M_S2 = 9.81
#: Significant digits of the numbers :func:`spec_xml` writes: a double read back exactly.
XML_DIGITS = 17
#: Significant digits of MuJoCo's XML writer by default.
MUJOCO_XML_DIGITS = 6
#: Impedance of an actuated joint's end stop (MuJoCo ``solimp`` of the limit): 0.99 to 0.999 of
#: the constraint's reference acceleration within 0.1 mm (0.1 mrad) of the stop.
END_STOP_SOLIMP = (0.99, 0.999, 0.0001, 0.5, 2.0)
#: Damping ratio of an end stop (MuJoCo ``solref``'s second number): overdamped. Critically damped
#: at the stop's time constant of two steps, the Delta's arm pushed against its stop chattered on
#: it (a 1.5 s cycle of 3 mrad) instead of settling.
END_STOP_DAMPING_RATIO = 2.0


def _scalar_or_tuple(value, name: str, low: float | None = None, strict: bool = False):
    """``value`` as a float or a tuple of floats (one per chain), each checked ``>= low`` (``>`` with
    ``strict``)."""
    many = isinstance(value, (tuple, list, np.ndarray))
    vals = tuple(float(v) for v in np.ravel(value)) if many else (float(value),)
    if low is not None and not all((v > low) if strict else (v >= low) for v in vals):
        raise ValueError(f"{name} must be {'>' if strict else '>='} {low:g}, got {value!r}")
    return vals if many else vals[0]


def chain_values(value, n_chains: int, name: str = "value") -> np.ndarray:
    """(C,) a per-joint option: a number (every chain alike) broadcast, or one value per chain.

    Raises:
        ValueError: a sequence of another length than ``n_chains``.
    """
    v = np.asarray(value, dtype=float)
    if v.ndim == 0:
        return np.full(n_chains, float(v))
    if v.shape != (n_chains,):
        raise ValueError(f"{name} must be one number or {n_chains} values (one per chain), got {v.size}")
    return v.copy()


def checked_machine_inputs(robot, theta, options: "MachineOptions") -> tuple[np.ndarray, np.ndarray]:
    """``(theta (P,), transmission scale (C,))`` of a three-chain machine's builder, checked: the
    parameter vector's shape and one transmission scale a chain (zeros where none is given).

    Raises:
        ValueError: naming the argument of the wrong shape.
    """
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (robot.n_parameters,):
        raise ValueError(f"theta must have shape ({robot.n_parameters},), got {theta.shape}")
    c = robot.n_chains
    scale = np.zeros(c) if options.transmission_scale is None else np.asarray(options.transmission_scale, dtype=float)
    if scale.shape != (c,):
        raise ValueError(f"transmission_scale must have {c} values (one per chain), got {scale.size}")
    return theta, scale


def add_end_stop(joint, low: float, high: float, timestep_s: float) -> None:
    """Stop ``joint`` (an ``mjsJoint`` of a spec) at ``[low, high]``, its own coordinate in SI
    (m for a slide, rad for a hinge): a limit with a time constant of two steps (MuJoCo's stable
    minimum), :data:`END_STOP_DAMPING_RATIO` and :data:`END_STOP_SOLIMP`, so that a servo
    commanded past the stop pushes against a stiff wall (MuJoCo's default limit, 20 ms and
    0.9-0.95, is a soft spring: the hexapod's leg commanded 5 mm past its stop settled 4.2 mm past
    it; with this one 0.08 mm)."""
    if not low < high:
        raise ValueError(f"an end stop needs low < high, got [{low!r}, {high!r}]")
    joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
    joint.range = [float(low), float(high)]
    joint.solref_limit = [2.0 * timestep_s, END_STOP_DAMPING_RATIO]
    joint.solimp_limit = list(END_STOP_SOLIMP)


def new_spec(name: str, timestep_s: float, gravity: bool) -> mujoco.MjSpec:
    """An empty machine spec with the settings every builder shares: angles in radians, the
    implicit-fast integrator, ``timestep_s``, gravity (``-GRAVITY_M_S2`` along base z) on or off,
    contacts off (geoms collide with nothing by default)."""
    spec = mujoco.MjSpec()
    spec.modelname = name
    spec.compiler.degree = False
    spec.option.timestep = timestep_s
    spec.option.gravity = [0.0, 0.0, -GRAVITY_M_S2 if gravity else 0.0]
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    spec.default.geom.contype = 0
    spec.default.geom.conaffinity = 0
    return spec


@functools.cache
def _xml_precision_functions():
    """MuJoCo's getter and setter of the digits its XML writer prints (exported by ``libmujoco``
    as ``_mjPRIVATE__get_xml_precision`` / ``_mjPRIVATE__set_xml_precision``, thread-local; the
    Python bindings do not expose them), or None where this MuJoCo lacks them."""
    import ctypes
    from pathlib import Path

    for lib in sorted(Path(mujoco.__file__).parent.glob("libmujoco.so*")) + \
            sorted(Path(mujoco.__file__).parent.glob("libmujoco*.dylib")):
        try:
            so = ctypes.CDLL(str(lib))
            get, put = so._mjPRIVATE__get_xml_precision, so._mjPRIVATE__set_xml_precision
        except (OSError, AttributeError):
            continue
        get.restype, get.argtypes = ctypes.c_int, []
        put.restype, put.argtypes = None, [ctypes.c_int]
        return get, put
    return None


def xml_digits() -> int:
    """The significant digits :func:`spec_xml` prints numbers with: :data:`XML_DIGITS`, or
    :data:`MUJOCO_XML_DIGITS` where this MuJoCo has no setter of its writer's precision."""
    return MUJOCO_XML_DIGITS if _xml_precision_functions() is None else XML_DIGITS


def spec_xml(spec: mujoco.MjSpec) -> str:
    """``spec.to_xml()`` with every number printed with :func:`xml_digits` significant digits.

    MuJoCo's XML writer prints :data:`MUJOCO_XML_DIGITS` by default: a 233 mm hexapod leg then reads
    back within 5e-4 mm only, and the machine loaded from the file settles 1e-4 mm from where the
    spec's own machine does.
    """
    functions = _xml_precision_functions()
    if functions is None:
        return spec.to_xml()
    get, put = functions
    before = get()
    put(XML_DIGITS)
    try:
        return spec.to_xml()
    finally:
        put(before)


@dataclass(frozen=True)
class MachineOptions:
    """Physical options of a simulated machine (SI: they describe MuJoCo physics).

    Attributes:
        gravity: gravity on (-9.81 m/s^2 along base z) or off.
        payload_kg: extra mass carried by the platform, kg, ``payload_height_m`` above it.
        payload_height_m: height of the payload's centre of mass over the platform frame, m.
        actuator_stiffness: position-servo stiffness of the actuators (N/m for a prismatic
            joint, N m/rad for a revolute one): one number for every chain, or a (C,) tuple,
            one per chain (each joint its own; applied through each actuator's gain in the
            ``MjSpec``); None: the builder's default.
        actuator_damping: servo damping; None: the builder's choice (near-critical).
        joint_friction: Coulomb friction of the actuated joints (N or N m): one number for every
            joint, or a (C,) tuple, one per joint (written as each joint's ``frictionloss`` in the
            ``MjSpec``); applied by the testbed in its quasi-static limit.
        transmission_scale: per-chain stroke scale error ``s_i`` (the joint moves ``1 + s_i`` times
            the command), or None.
        platform_mass_kg: mass of the moving platform, kg; None: the builder's default.
        timestep: integration step, s (a builder may lower it for the stability of a stiff servo).
    """

    gravity: bool = False
    payload_kg: float = 0.0
    payload_height_m: float = 0.05
    actuator_stiffness: float | tuple | None = None
    actuator_damping: float | None = None
    joint_friction: float | tuple = 0.0
    transmission_scale: tuple | None = None
    platform_mass_kg: float | None = None
    timestep: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("payload_kg", "payload_height_m"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        object.__setattr__(self, "joint_friction", _scalar_or_tuple(self.joint_friction, "joint_friction", 0.0))
        if self.actuator_stiffness is not None:
            object.__setattr__(self, "actuator_stiffness",
                               _scalar_or_tuple(self.actuator_stiffness, "actuator_stiffness", 0.0, strict=True))
        for name in ("actuator_damping", "platform_mass_kg"):
            v = getattr(self, name)
            if v is not None and not v > 0:
                raise ValueError(f"{name} must be > 0, got {v!r}")
        if not self.timestep > 0:
            raise ValueError(f"timestep must be > 0, got {self.timestep!r}")
        if self.transmission_scale is not None:
            ts = tuple(float(v) for v in self.transmission_scale)
            if not all(-0.5 < v < 0.5 for v in ts):
                raise ValueError(f"transmission_scale must be numbers in (-0.5, 0.5), got {ts!r}")
            object.__setattr__(self, "transmission_scale", ts)


@dataclass(frozen=True)
class MachineEffects:
    """Non-geometric effects the testbed adds in joint space (robot units: mm or rad per chain).

    Attributes:
        joint_drift_per_s: every actuated chain's effective length drifts at this rate with
            time (thermal growth of a leg; joint unit per s): one number for every chain or a
            (C,) tuple, one per chain; it enters the servo reference at the start of each move.
        screw_amplitude: (C,) amplitude of each chain's periodic transmission error (lead screw),
            joint unit: the joint sits ``A_i sin(2 pi stroke / pitch + phase_i)`` from where
            its encoder says, ``stroke`` the command minus the home joint value.
        screw_phase_rad: (C,) phase of each chain's periodic error, rad.
        screw_pitch: period of the error in stroke, joint unit.
        instrument_drift_mm_per_s: (3,) velocity of the measuring instrument's frame, mm/s: the
            testbed adds ``v t`` to every measured position (the machine does not move); empty
            for none.
        joint_offset_step: (C,) step in each chain's zero offset (lost encoder counts), joint
            unit: added to the servo reference from ``joint_offset_step_time_s`` on; empty for
            none.
        joint_offset_step_time_s: the time of that step, s.
        joint_warmup_per_s: initial growth rate of every actuated chain warming up, joint unit
            per s (one number, or a (C,) tuple one per chain): the servo reference gets
            ``g tau (1 - exp(-t / tau))``.
        joint_warmup_tau_s: the warm-up's time constant ``tau``, s.
    """

    joint_drift_per_s: float | tuple = 0.0
    screw_amplitude: tuple = ()
    screw_phase_rad: tuple = ()
    screw_pitch: float = 5.0
    instrument_drift_mm_per_s: tuple = ()
    joint_offset_step: tuple = ()
    joint_offset_step_time_s: float = 0.0
    joint_warmup_per_s: float | tuple = 0.0
    joint_warmup_tau_s: float = 60.0

    def __post_init__(self) -> None:
        for name in ("joint_drift_per_s", "joint_warmup_per_s"):
            object.__setattr__(self, name, _scalar_or_tuple(getattr(self, name), name))
        for name in ("screw_amplitude", "screw_phase_rad", "instrument_drift_mm_per_s", "joint_offset_step"):
            object.__setattr__(self, name, tuple(float(x) for x in getattr(self, name)))
        if len(self.screw_amplitude) != len(self.screw_phase_rad):
            raise ValueError("screw_amplitude and screw_phase_rad must have the same length")
        if not self.screw_pitch > 0:
            raise ValueError(f"screw_pitch must be > 0, got {self.screw_pitch!r}")
        if len(self.instrument_drift_mm_per_s) not in (0, 3):
            raise ValueError(f"instrument_drift_mm_per_s must have 3 values (x, y, z), "
                             f"got {len(self.instrument_drift_mm_per_s)}")
        if not self.joint_warmup_tau_s > 0:
            raise ValueError(f"joint_warmup_tau_s must be > 0, got {self.joint_warmup_tau_s!r}")

    def to_dict(self) -> dict:
        def plain(v):
            return list(v) if isinstance(v, tuple) else v

        return {"joint_drift_per_s": plain(self.joint_drift_per_s), "screw_amplitude": list(self.screw_amplitude),
                "screw_phase_rad": list(self.screw_phase_rad), "screw_pitch": self.screw_pitch,
                "instrument_drift_mm_per_s": list(self.instrument_drift_mm_per_s),
                "joint_offset_step": list(self.joint_offset_step),
                "joint_offset_step_time_s": self.joint_offset_step_time_s,
                "joint_warmup_per_s": plain(self.joint_warmup_per_s), "joint_warmup_tau_s": self.joint_warmup_tau_s}


class Machine:
    """A compiled machine and its unit boundary (see the module docstring).

    Args:
        robot: the robot it was built for.
        theta: (P,) the parameter vector it was built from.
        model: the compiled model.
        joint_offset: (C,) joint value (robot unit) at actuated-joint ``qpos = 0``.
        joint_scale: (C,) SI per robot joint unit (``1e-3`` for mm, 1 for rad).
        actuated_joints: (C,) names of the actuated joints, chain order.
        chain_point_masses_kg: the chains' own masses lumped at their points (every chain alike):
            one mass per point of :meth:`calib.robot.Robot.chain_points` after the base joint,
            the last at the platform joint, kg (a link of mass m whose centre of mass sits a
            fraction f of the way from its inner to its outer point puts ``(1 - f) m`` on the
            inner point and ``f m`` on the outer one: the same weight torques on the joints);
            empty where the builder does not lump them.
    """

    def __init__(self, robot: Robot, theta: np.ndarray, model: mujoco.MjModel, joint_offset, joint_scale,
                 actuated_joints: tuple[str, ...], chain_point_masses_kg: tuple = ()):
        self.robot = robot
        self.theta = np.array(theta, dtype=float)
        self.model = model
        self.joint_offset = np.asarray(joint_offset, dtype=float)
        self.joint_scale = np.asarray(joint_scale, dtype=float)
        self.actuated_joints = tuple(actuated_joints)
        self.chain_point_masses_kg = tuple(float(m) for m in chain_point_masses_kg)
        self.qpos_index = np.array([model.joint(n).qposadr[0] for n in actuated_joints])
        self.dof_index = np.array([model.joint(n).dofadr[0] for n in actuated_joints])
        self._pos = model.sensor(SENSOR_POS).adr[0]
        self._quat = model.sensor(SENSOR_QUAT).adr[0] if robot.pose_dim == 6 else None

    @property
    def platform_mass_kg(self) -> float:
        """Mass of the body that carries the platform site (the moving platform), kg."""
        m = self.model
        return float(m.body_mass[m.site_bodyid[m.site(PLATFORM_SITE).id]])

    @property
    def servo_stiffness(self) -> np.ndarray:
        """(C,) stiffness of each chain's position servo at its joint, SI (N/m or N m/rad):
        the actuator gain times its gear squared."""
        m = self.model
        return m.actuator_gainprm[:, 0] * m.actuator_gear[:, 0] ** 2

    def ctrl(self, joints: np.ndarray) -> np.ndarray:
        """(C,) SI actuator controls for joint values in the robot's units."""
        return (np.asarray(joints, dtype=float) - self.joint_offset) * self.joint_scale

    def read_joints(self, data: mujoco.MjData) -> np.ndarray:
        """(C,) actuated joint values in the robot's units."""
        return data.qpos[self.qpos_index] / self.joint_scale + self.joint_offset

    def read_pose(self, data: mujoco.MjData) -> np.ndarray:
        """(D,) the platform pose from the sensors, mm and rad."""
        s = data.sensordata
        pos = m_to_mm(s[self._pos:self._pos + 3])
        if self._quat is None:
            return pos
        return np.r_[pos, euler_from_quaternion(s[self._quat:self._quat + 4])]

    def reset(self, data: mujoco.MjData) -> None:
        """Put ``data`` at the home keyframe and compute its derived quantities."""
        mujoco.mj_resetDataKeyframe(self.model, data, self.model.key(HOME_KEY).id)
        mujoco.mj_forward(self.model, data)

