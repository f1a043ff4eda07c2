"""MJCF model of a hexapod (6-UPS Stewart-Gough platform) built from a parameter set.

The machine: a fixed base; six physical legs, each a lower body on a universal joint (two
hinges) at its base joint B_i and an upper body on an actuated prismatic joint; each leg's
tip closed on its platform joint P_i by a ``connect`` equality constraint (a ball joint);
the platform on a free joint carrying ``framepos``/``framequat`` sensors. Contacts are off:
the legs would touch the platform and the machine would never settle.

Leg i's tip is ``l_i + dl_i + q_i`` from its base joint, where ``q_i`` is the slide joint
position (stroke from the nominal home length); commanding ``q_i = l_cmd_i - l_i`` therefore
gives the leg length ``l_cmd_i + dl_i`` of the error model in :mod:`calib.hexapod`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from calib.hexapod import Hexapod
from calib.rotation import quaternion_from_euler

from .units import mm_to_m

__all__ = ["HexapodModelOptions", "hexapod_xml", "build_hexapod", "DEFAULT_XML"]

#: The default machine (Table 2 + Table 3), saved for MuJoCo's own viewer.
DEFAULT_XML = Path(__file__).with_name("hexapod_paper_actual.xml")

PLATFORM_SITE = "platform"
SENSOR_POS = "platform_pos"
SENSOR_QUAT = "platform_quat"


@dataclass(frozen=True)
class HexapodModelOptions:
    """Physical options of the simulated machine (SI units: they describe MuJoCo physics).

    Attributes:
        gravity: gravity on (-9.81 m/s^2 along base z) or off.
        payload_kg: extra mass carried by the platform, kg, centred ``payload_height_m`` above it.
        payload_height_m: height of the payload's centre of mass over the platform frame, m.
        actuator_stiffness: position servo stiffness of each leg, N/m (finite: the leg deflects
            under load by force / stiffness).
        actuator_damping: servo damping, N s/m; None chooses near-critical damping.
        joint_friction: Coulomb friction of each prismatic joint, N. Written to the model as
            MuJoCo's ``frictionloss`` (for the viewer and dynamics); MuJoCo's friction loss is a soft
            constraint that creeps to the servo target, so the testbed adds the quasi-static
            friction force itself (see :mod:`pipeline.testbed`).
        transmission_scale: (6,) stroke scale error of each leg's transmission: the slide moves
            ``(1 + s_i)`` times the commanded stroke (actuator gear ``1 / (1 + s_i)``).
        platform_mass_kg, leg_mass_kg: masses of the platform and of each leg half, kg.
        timestep: integration step, s; capped at 0.3 / omega with omega = sqrt(stiffness / leg
            mass), since the servo's stiffness is integrated explicitly (see :attr:`step`).
    """

    gravity: bool = False
    payload_kg: float = 0.0
    payload_height_m: float = 0.05
    actuator_stiffness: float = 2e5
    actuator_damping: float | None = None
    joint_friction: float = 0.0
    platform_mass_kg: float = 2.0
    leg_mass_kg: float = 0.3
    timestep: float = 1e-3
    transmission_scale: tuple = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        ts = tuple(float(v) for v in self.transmission_scale)
        if len(ts) != 6 or not all(-0.5 < v < 0.5 for v in ts):
            raise ValueError(f"transmission_scale must be 6 numbers in (-0.5, 0.5), got {self.transmission_scale!r}")
        object.__setattr__(self, "transmission_scale", ts)
        for name in ("payload_kg", "joint_friction"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        for name in ("actuator_stiffness", "platform_mass_kg", "leg_mass_kg", "timestep"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")

    @property
    def step(self) -> float:
        """The integration step used: ``timestep`` capped for the stability of a stiff servo."""
        omega = np.sqrt(self.actuator_stiffness / self.leg_mass_kg)
        # Explicit stiffness is stable for omega dt < 2; beyond omega dt = 1 the step drops to
        # 0.3 / omega, which also settled fastest in our trials (the default is not affected).
        return float(self.timestep if omega * self.timestep <= 1.0 else 0.3 / omega)

    @property
    def damping(self) -> float:
        if self.actuator_damping is not None:
            return self.actuator_damping
        # Critical damping of a leg carrying its share of the platform.
        m = self.leg_mass_kg + (self.platform_mass_kg + self.payload_kg) / 6.0
        return 2.0 * np.sqrt(self.actuator_stiffness * m)


def _quat_z_to(d: np.ndarray) -> np.ndarray:
    """Quaternion [w, x, y, z] rotating the z axis onto the unit vector d."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    s = np.linalg.norm(axis)
    angle = np.arctan2(s, z @ d)
    if s < 1e-15:
        return np.array([1.0, 0.0, 0.0, 0.0])
    axis /= s
    return np.r_[np.cos(angle / 2), np.sin(angle / 2) * axis]


def _f(v) -> str:
    return " ".join(f"{x:.17g}" for x in np.atleast_1d(v))


def hexapod_xml(hexapod: Hexapod, options: HexapodModelOptions = HexapodModelOptions(),
                name: str = "hexapod") -> str:
    """MJCF text of the hexapod ``hexapod`` (nominal geometry + its errors).

    Args:
        hexapod: parameter set of the machine to build (mm); converted to metres here.
        options: physical options.
        name: model name.

    Returns:
        The MJCF XML string (metres, kg, s).
    """
    o = options
    B = mm_to_m(hexapod.base_joints)
    P = mm_to_m(hexapod.platform_joints)
    home = hexapod.geometry.home_pose
    t_home = mm_to_m(home[:3])
    q_home = quaternion_from_euler(home[3:])
    from calib.rotation import rotation_matrix
    R_home = rotation_matrix(home[3:])
    rest = mm_to_m(hexapod.geometry.home_lengths + hexapod.leg_offsets)  # tip at q = 0
    radius = float(np.linalg.norm(P, axis=1).mean())
    gravity = "0 0 -9.81" if o.gravity else "0 0 0"
    legs, eqs, acts = [], [], []
    for i in range(6):
        d = R_home @ P[i] + t_home - B[i]
        d = d / np.linalg.norm(d)
        half = rest[i] / 2
        legs.append(f"""
    <body name="leg{i + 1}_lower" pos="{_f(B[i])}" quat="{_f(_quat_z_to(d))}">
      <joint name="leg{i + 1}_ux" type="hinge" axis="1 0 0" damping="0.5"/>
      <joint name="leg{i + 1}_uy" type="hinge" axis="0 1 0" damping="0.5"/>
      <geom type="capsule" fromto="0 0 0 0 0 {half:.17g}" size="0.012" mass="{o.leg_mass_kg:.17g}" rgba="0.35 0.4 0.5 1"/>
      <body name="leg{i + 1}_upper">
        <joint name="leg{i + 1}_slide" type="slide" axis="0 0 1" frictionloss="{o.joint_friction:.17g}"/>
        <geom type="capsule" fromto="0 0 {half:.17g} 0 0 {rest[i]:.17g}" size="0.008" mass="{o.leg_mass_kg:.17g}" rgba="0.8 0.55 0.2 1"/>
        <site name="leg{i + 1}_tip" pos="0 0 {rest[i]:.17g}" size="0.005"/>
      </body>
    </body>""")
        # The closure's time constant follows the step (two steps, MuJoCo's stable minimum) so
        # that its own compliance stays well below the servo's, also for stiff servos.
        eqs.append(f'    <connect name="leg{i + 1}_close" site1="leg{i + 1}_tip" site2="P{i + 1}" '
                   f'solref="{2 * o.step:.17g} 1" solimp="0.99 0.999 0.0001"/>')
        # gear g: the servo acts on g q, so it holds the slide at ctrl / g; its stiffness seen by
        # the slide is kp g^2, hence kp / g^2 keeps the leg's stiffness at actuator_stiffness.
        g = 1.0 / (1.0 + o.transmission_scale[i])
        acts.append(f'    <position name="leg{i + 1}" joint="leg{i + 1}_slide" gear="{g:.17g}" '
                    f'kp="{o.actuator_stiffness / g**2:.17g}" kv="{o.damping / g**2:.17g}"/>')
    payload = ""
    if o.payload_kg > 0:
        payload = f"""
      <body name="payload" pos="0 0 {o.payload_height_m:.17g}">
        <geom type="cylinder" size="{0.5 * radius:.17g} 0.01" mass="{o.payload_kg:.17g}" rgba="0.6 0.2 0.2 1"/>
      </body>"""
    psites = "\n".join(f'      <site name="P{i + 1}" pos="{_f(P[i])}" size="0.006" rgba="1 1 0 1"/>' for i in range(6))
    return f"""<mujoco model="{name}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{o.step:.17g}" gravity="{gravity}" integrator="implicitfast">
    <flag contact="disable"/>
  </option>
  <default>
    <geom contype="0" conaffinity="0"/>
  </default>
  <visual><global offwidth="1280" offheight="960"/></visual>
  <worldbody>
    <light pos="0 0 1.5" dir="0 0 -1"/>
    <geom name="base" type="cylinder" size="{float(np.linalg.norm(B, axis=1).max()) + 0.02:.17g} 0.005" pos="0 0 -0.005" rgba="0.25 0.25 0.3 1"/>{''.join(legs)}
    <body name="platform" pos="{_f(t_home)}" quat="{_f(q_home)}">
      <freejoint name="platform_free"/>
      <geom type="cylinder" size="{radius + 0.01:.17g} 0.004" mass="{o.platform_mass_kg:.17g}" rgba="0.3 0.6 0.8 0.8"/>
      <site name="{PLATFORM_SITE}" size="0.004"/>
{psites}{payload}
    </body>
  </worldbody>
  <equality>
{chr(10).join(eqs)}
  </equality>
  <actuator>
{chr(10).join(acts)}
  </actuator>
  <sensor>
    <framepos name="{SENSOR_POS}" objtype="site" objname="{PLATFORM_SITE}"/>
    <framequat name="{SENSOR_QUAT}" objtype="site" objname="{PLATFORM_SITE}"/>
  </sensor>
</mujoco>
"""


def build_hexapod(hexapod: Hexapod, options: HexapodModelOptions = HexapodModelOptions()) -> mujoco.MjModel:
    """Compiled MuJoCo model of the hexapod (see :func:`hexapod_xml`)."""
    return mujoco.MjModel.from_xml_string(hexapod_xml(hexapod, options))


def save_default_xml(path: Path = DEFAULT_XML) -> Path:
    """Write the paper's machine (Table 2 + Table 3, default options) for MuJoCo's viewer."""
    from calib.hexapod import paper_hexapod

    path.write_text(hexapod_xml(paper_hexapod(with_table3_errors=True), name="hexapod_paper_actual"))
    return path


if __name__ == "__main__":  # python -m mjcf.hexapod regenerates the saved default model
    print(save_default_xml())
