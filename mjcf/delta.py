"""MJCF model of a Delta robot built from a Model-24 parameter set (SI units).

Modelling choices (documented in docs/delta.md):

* Each parallelogram forearm is modelled as ONE bar with a universal joint at the elbow
  (two hinges: one parallel to the actuated axis, one perpendicular) and a ball joint at the
  plate, the latter being an equality ``connect`` constraint between the bar's end site and
  the plate's attachment site. The plate carries three slide joints (x, y, z) and no
  rotation, which is exactly what the three parallelograms enforce; with the orientation
  held, a single bar is kinematically equivalent to the parallelogram for the plate
  position. The universal joint (instead of a ball) removes the bar's free spin.
* The plate attachment of chain ``i`` is at ``plate_attach[i]`` in the plate frame and the
  actuated joint at ``shoulder_physical[i] = shoulder_reduced[i] + plate_attach[i]``, so the
  closure is ``||X + c_i - (D_i + c_i + arm_i)|| = ||X - D_i - arm_i|| = Lb_i``: exactly the
  reduced Model 24 of :mod:`calib.delta`, with a physically sized base (radius Rb) and plate
  (radius Rn).
* Arm ``i``: body frame ``R_z(theta_i) R_y(alpha_i)`` at the physical shoulder, a hinge about
  its local ``y`` (so the hinge position IS the joint reading ``q_i``), elbow site at
  ``(Lax_i, 0, Lay_i)``; driven by a stiff, damped position actuator.
* Contacts off, gravity off, implicit-fast integrator: at rest there is no load, so the
  actuated joints sit exactly at their targets and the soft equality constraints are
  exactly satisfied; the settled plate position is the kinematic one.
* Sensor ``plate_pos``: ``framepos`` of site ``plate_center`` (the plate centre X, world
  frame, metres).

This module never converts units: every length it receives and writes is in metres (the
pipeline's testbed converts from the calib package's millimetres).
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

__all__ = [
    "DeltaMjcfGeometry",
    "build_delta_model",
    "build_delta_xml",
    "ARM_JOINTS",
    "ACTUATORS",
    "PLATE_SENSOR",
]

#: Names of the actuated (arm) hinge joints, chain order.
ARM_JOINTS: tuple[str, ...] = ("arm1_hinge", "arm2_hinge", "arm3_hinge")
#: Names of the position actuators, chain order.
ACTUATORS: tuple[str, ...] = ("motor1", "motor2", "motor3")
#: Name of the plate position sensor (framepos of site ``plate_center``).
PLATE_SENSOR = "plate_pos"


def _arr(value, name: str, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.array(value, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    arr.setflags(write=False)
    return arr


@dataclasses.dataclass(frozen=True)
class DeltaMjcfGeometry:
    """Geometry of the simulated Delta, SI units (metres, radians).

    Attributes:
        shoulder: Reduced shoulder points ``D_i`` (Model 24), shape (3, 3), m, world frame.
        theta: Chain-plane rotations about z, shape (3,), rad.
        alpha: Actuated joint offsets, shape (3,), rad.
        arm: Arm vectors ``(Lax_i, Lay_i)`` at zero arm angle, shape (3, 2), m.
        forearm: Forearm lengths ``Lb_i``, shape (3,), m.
        plate_attach: Forearm attachment points in the plate frame, shape (3, 3), m.
        home_q: Initial joint readings, shape (3,), rad.
        home_plate: Plate-centre position consistent with ``home_q``, shape (3,), m, world.
    """

    shoulder: np.ndarray
    theta: np.ndarray
    alpha: np.ndarray
    arm: np.ndarray
    forearm: np.ndarray
    plate_attach: np.ndarray
    home_q: np.ndarray
    home_plate: np.ndarray

    def __post_init__(self) -> None:
        shapes = {
            "shoulder": (3, 3),
            "theta": (3,),
            "alpha": (3,),
            "arm": (3, 2),
            "forearm": (3,),
            "plate_attach": (3, 3),
            "home_q": (3,),
            "home_plate": (3,),
        }
        for f, shp in shapes.items():
            object.__setattr__(self, f, _arr(getattr(self, f), f, shp))
        if np.any(self.forearm <= 0):
            raise ValueError(f"forearm must be positive, got {self.forearm.tolist()}")
        if np.any(np.linalg.norm(self.arm, axis=1) <= 0):
            raise ValueError("arm vectors must be non-zero")
        if np.max(np.abs(self.forearm)) > 100.0:
            raise ValueError(f"forearm must be in metres (expected < 100), got {self.forearm.tolist()}")


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


def _fmt(v) -> str:
    return " ".join(repr(float(x)) for x in np.ravel(v))


def build_delta_xml(
    geom: DeltaMjcfGeometry,
    *,
    timestep: float = 1e-3,
    kp: float = 2000.0,
    kv: float = 40.0,
    passive_damping: float = 2.0,
) -> str:
    """MJCF XML of the Delta.

    Args:
        geom: Geometry in metres / radians.
        timestep: Simulation step, s.
        kp: Position-actuator stiffness, N.m/rad.
        kv: Position-actuator damping, N.m.s/rad.
        passive_damping: Damping of the passive joints (forearm hinges N.m.s/rad, plate
            slides N.s/m).

    Returns:
        The MJCF document as a string (bodies ``plate``, ``arm{i}``, ``forearm{i}``; joints
        :data:`ARM_JOINTS`; actuators :data:`ACTUATORS`; sensor :data:`PLATE_SENSOR`;
        keyframe ``home``).
    """
    if not isinstance(geom, DeltaMjcfGeometry):
        raise ValueError(f"geom must be a DeltaMjcfGeometry, got {type(geom).__name__}")
    for name, val in (("timestep", timestep), ("kp", kp), ("kv", kv), ("passive_damping", passive_damping)):
        if not (np.isfinite(val) and val > 0):
            raise ValueError(f"{name} must be positive, got {val}")
    bodies, eqs, acts = [], [], []
    home_qpos = [0.0, 0.0, 0.0]  # plate slides (plate body placed at home_plate)
    for i in range(3):
        k = i + 1
        rarm = _rz(geom.theta[i]) @ _ry(geom.alpha[i])  # arm frame at q = 0
        shoulder = geom.shoulder[i] + geom.plate_attach[i]
        elbow_local = np.array([geom.arm[i, 0], 0.0, geom.arm[i, 1]])
        # Forearm frame: z along the bar at home, x along the actuated axis (orthogonalised).
        r_home = rarm @ _ry(geom.home_q[i])
        elbow_world = shoulder + r_home @ elbow_local
        target = geom.home_plate + geom.plate_attach[i]
        zf = r_home.T @ (target - elbow_world)
        zf /= np.linalg.norm(zf)
        ey = np.array([0.0, 1.0, 0.0])
        xf = ey - (ey @ zf) * zf
        xf /= np.linalg.norm(xf)
        yf = np.cross(zf, xf)
        rf = np.stack([xf, yf, zf], axis=1)  # forearm frame in arm frame
        lb = float(geom.forearm[i])
        bodies.append(
            f"""
    <body name="arm{k}" pos="{_fmt(shoulder)}" quat="{_fmt(_quat(rarm))}">
      <joint name="arm{k}_hinge" type="hinge" axis="0 1 0" damping="0.1"/>
      <inertial pos="{_fmt(elbow_local / 2)}" mass="0.3" diaginertia="0.002 0.002 0.002"/>
      <geom type="capsule" fromto="0 0 0 {_fmt(elbow_local)}" size="0.012" rgba="0.2 0.4 0.8 1"/>
      <site name="elbow{k}" pos="{_fmt(elbow_local)}" size="0.01"/>
      <body name="forearm{k}" pos="{_fmt(elbow_local)}" quat="{_fmt(_quat(rf))}">
        <joint name="fa{k}_u1" type="hinge" axis="1 0 0" damping="{passive_damping}"/>
        <joint name="fa{k}_u2" type="hinge" axis="0 1 0" damping="{passive_damping}"/>
        <inertial pos="0 0 {lb / 2!r}" mass="0.1" diaginertia="0.002 0.002 0.0002"/>
        <geom type="capsule" fromto="0 0 0 0 0 {lb!r}" size="0.006" rgba="0.8 0.5 0.2 1"/>
        <site name="fa{k}_end" pos="0 0 {lb!r}" size="0.008"/>
      </body>
    </body>"""
        )
        eqs.append(f'    <connect name="close{k}" site1="fa{k}_end" site2="plate_c{k}"/>')
        acts.append(
            f'    <position name="motor{k}" joint="arm{k}_hinge" kp="{kp!r}" kv="{kv!r}"/>'
        )
        home_qpos += [float(geom.home_q[i]), 0.0, 0.0]
    plate_sites = "\n".join(
        f'      <site name="plate_c{i + 1}" pos="{_fmt(geom.plate_attach[i])}" size="0.008"/>' for i in range(3)
    )
    rn = float(np.max(np.linalg.norm(geom.plate_attach, axis=1))) or 0.03
    return f"""<mujoco model="delta">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{timestep!r}" gravity="0 0 0" integrator="implicitfast"/>
  <default>
    <geom contype="0" conaffinity="0"/>
    <equality solref="0.005 1"/>
  </default>
  <worldbody>
    <geom name="base" type="cylinder" pos="0 0 0.01" size="{float(np.max(np.linalg.norm(geom.shoulder + geom.plate_attach, axis=1))) + 0.02!r} 0.01" rgba="0.5 0.5 0.5 0.5"/>
    <body name="plate" pos="{_fmt(geom.home_plate)}">
      <joint name="plate_x" type="slide" axis="1 0 0" damping="{passive_damping}"/>
      <joint name="plate_y" type="slide" axis="0 1 0" damping="{passive_damping}"/>
      <joint name="plate_z" type="slide" axis="0 0 1" damping="{passive_damping}"/>
      <inertial pos="0 0 0" mass="0.3" diaginertia="0.001 0.001 0.001"/>
      <geom type="cylinder" size="{rn + 0.01!r} 0.005" rgba="0.3 0.7 0.3 1"/>
      <site name="plate_center" pos="0 0 0" size="0.01"/>
{plate_sites}
    </body>{''.join(bodies)}
  </worldbody>
  <equality>
{chr(10).join(eqs)}
  </equality>
  <actuator>
{chr(10).join(acts)}
  </actuator>
  <sensor>
    <framepos name="{PLATE_SENSOR}" objtype="site" objname="plate_center"/>
  </sensor>
  <keyframe>
    <key name="home" qpos="{_fmt(home_qpos)}" ctrl="{_fmt(geom.home_q)}"/>
  </keyframe>
</mujoco>
"""


def build_delta_model(geom: DeltaMjcfGeometry, **kwargs) -> mujoco.MjModel:
    """Compile the Delta MJCF (see :func:`build_delta_xml` for keyword arguments).

    Args:
        geom: Geometry in metres / radians.
        **kwargs: Passed to :func:`build_delta_xml`.

    Returns:
        The compiled ``mujoco.MjModel``.
    """
    return mujoco.MjModel.from_xml_string(build_delta_xml(geom, **kwargs))
