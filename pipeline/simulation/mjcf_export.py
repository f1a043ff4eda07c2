"""The identified machine in MuJoCo: a calibration turned into an MJCF file any MuJoCo loads.

:func:`export_mjcf` builds the machine a calibration identified with ``mujoco.MjSpec``, exactly as
the testbed builds the actual machine (:func:`mjcf.build_spec`, the robot's own builder: the
identified parameters, closed chains as ``connect`` equality constraints, position servos, contacts
off), with the effects the calibration found that MuJoCo can hold, put there by the same code path
the testbed and discovery's re-simulation use (each effect's
:meth:`calib.effects.Effect.machine_settings`, merged by
:func:`pipeline.simulation.effects_settings`, turned into :class:`mjcf.machine.MachineOptions`):

* ``joint_friction`` (a dead band): each actuated joint's ``frictionloss``, the dead band times the
  servo stiffness (N or N m);
* ``actuator_scale``: each actuator's ``gear`` ``1 / (1 + s_i)`` (the joint moves ``1 + s_i`` times
  the command), the servo gains divided by the gear squared;
* ``compliance``: each servo's stiffness (the actuator's ``kp``), gravity on, the payload it was
  identified at.

Effects MuJoCo has no element for (thermal drift and warm-up, periodic screw error, instrument
drift, a lost count: the testbed adds them to the servo references or the measurements) and a
proposed law are left out and named in an XML comment at the top of the file, which also says how
to command the machine.

The command. Each actuator's control is its joint's command in SI, ``ctrl_i = q_i * s`` (``s`` =
1e-3 m/mm for a prismatic joint, 1 for a revolute one): the actuator's bias (``biasprm[0]``) holds
the builder's joint offset (a hexapod leg's home length) and the actuator scale's reference point
(the centre of travel, where :mod:`calib.effects.actuator_scale` measures the stroke from), so that
at rest, unloaded, the joint sits where the identified model puts it, ``q_i + s_i (q_i - c_i)``.
The home keyframe's controls hold it where it is placed.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.effects.base import MachineContext
from mjcf import build_machine, build_spec
from mjcf.machine import HOME_KEY, PLATFORM_SITE, SENSOR_POS, SENSOR_QUAT, MachineOptions, spec_xml, xml_digits
from pipeline.formats import Calibration, atomic_write

from .scenarios import effects_settings, machine_context

__all__ = ["IdentifiedMachine", "identified_machine", "mjcf_text", "export_mjcf", "HELD_EFFECTS_IN_WORDS",
           "LAW_NOT_HELD"]

#: How each MachineOptions field an effect sets is held in the MJCF, in words (the comment).
HELD_EFFECTS_IN_WORDS = {
    "joint_friction": "frictionloss of each actuated joint (N or N m: dead band x servo stiffness)",
    "actuator_stiffness": "servo stiffness (each actuator's kp x gear^2, N/m or N m/rad)",
    "transmission_scale": "gear of each actuator, 1 / (1 + s)",
    "gravity": "gravity on",
    "payload_kg": "payload on the platform (kg)",
    "payload_height_m": "the payload's height over the platform (m)",
}
#: Why a proposed law is not in the model.
LAW_NOT_HELD = "a proposed law: no MuJoCo element follows its terms"


@dataclass(frozen=True, eq=False)
class IdentifiedMachine:
    """A calibration's identified machine, ready to be written.

    Attributes:
        spec: the ``mujoco.MjSpec`` (its ``comment`` the header comment of the file).
        options: the :class:`mjcf.machine.MachineOptions` it was built with (the effects held).
        held: names of the effects held, in the calibration's order.
        not_held: ``{name: why}`` of the effects left out.
        ctrl_per_joint_unit: SI per joint unit of the controls (1e-3 for mm, 1 for rad).
    """

    spec: object
    options: MachineOptions
    held: tuple
    not_held: dict
    ctrl_per_joint_unit: float


def _settings_of(fe, robot, context: MachineContext) -> dict | None:
    """An effect's machine settings, or None for one without (a law)."""
    try:
        return fe.effect.machine_settings(fe.coefficients, robot, context, fe.extra)
    except NotImplementedError:
        return None


def _context(cal: Calibration) -> MachineContext:
    """The machine the effects' coefficients are turned into physics on: the robot's nominal
    machine (:func:`pipeline.simulation.machine_context`), carrying the payload a compliance fitted
    at several payloads stands for (its record's ``reference_payload_kg``, kg)."""
    context = machine_context(cal.robot)
    payloads = [e.reference_payload_kg for e in cal.effects if e.reference_payload_kg is not None]
    return context.with_payload(payloads[0]) if payloads else context


def identified_machine(cal: Calibration) -> IdentifiedMachine:
    """The MuJoCo machine ``cal`` identified (see the module docstring).

    Raises:
        KeyError: no MuJoCo machine for the calibration's robot.
        calib.robot.KinematicsError: the identified parameters cannot reach the robot's home pose.
    """
    robot = cal.robot
    context = _context(cal)
    held, not_held, drawn = [], {}, []
    for fe in cal.fitted_effects():
        s = _settings_of(fe, robot, context)
        if s is None:
            not_held[fe.name] = LAW_NOT_HELD
        elif s.get("effects"):
            not_held[fe.name] = ("MuJoCo has no element for it (the testbed adds it in joint space: "
                                 f"{', '.join(s['effects'])})")
        else:
            held.append(fe.name)
            drawn.append((fe.effect, fe.coefficients, fe.extra))
    options = MachineOptions(**effects_settings(robot, context, drawn)["options"])
    spec = build_spec(robot, cal.theta, options)
    offset = build_machine(robot, cal.theta, options).joint_offset
    per_unit = context.si_per_joint_unit(robot)
    scale = np.zeros(robot.n_chains) if options.transmission_scale is None else np.asarray(options.transmission_scale)
    _command_in_si(spec, offset, robot.joint_limits().mean(axis=1), scale, per_unit)
    spec.comment = _comment(cal, options, held, not_held, per_unit)
    return IdentifiedMachine(spec, options, tuple(held), not_held, per_unit)


def _command_in_si(spec, offset: np.ndarray, centre: np.ndarray, scale: np.ndarray, per_unit: float) -> None:
    """Each actuator's bias set so that its control is its joint's command in SI (module docstring):
    at rest unloaded ``gear qpos = ctrl + b0 / kp`` with ``b0 = -kp (offset + s centre) si / (1 + s)``;
    the home keyframe's controls set to hold its joints where they are (``ctrl = gear qpos - b0 / kp``)."""
    model = spec.compile()
    key = spec.key(HOME_KEY)
    qpos_key = np.asarray(key.qpos, dtype=float)
    ctrl = np.empty(len(spec.actuators))
    for i, act in enumerate(spec.actuators):
        kp, gear = float(act.gainprm[0]), float(act.gear[0])
        b0 = -kp * (offset[i] + scale[i] * centre[i]) * per_unit / (1.0 + scale[i])
        act.biasprm[0] = b0
        adr = model.jnt_qposadr[model.actuator_trnid[i, 0]]
        ctrl[i] = gear * qpos_key[adr] - b0 / kp
    key.ctrl = ctrl


def _plain(text: str) -> str:
    """Text an XML comment may hold (no ``--``)."""
    while "--" in text:
        text = text.replace("--", "- -")
    return text


def _comment(cal: Calibration, options: MachineOptions, held: list, not_held: dict, per_unit: float) -> str:
    robot = cal.robot
    unit = "m" if robot.joint_unit == "mm" else "rad"
    source = cal.recording.get("name") or cal.recording.get("simulated") or "unnamed"
    lines = [
        f"The identified {robot.name} of a calibration ({cal.produced_by or 'calibration file'}, recording {source}): "
        "the identified parameters, built with mujoco.MjSpec as the project's testbed builds the actual machine "
        "(closed chains as connect equality constraints). SI units.",
        f"Command: actuator i's ctrl is joint i's command in {unit} (the recorded joint value, "
        f"{robot.joint_unit}, times {per_unit:g}). The pose is site '{PLATFORM_SITE}' (sensor '{SENSOR_POS}'"
        + (f", '{SENSOR_QUAT}' w x y z" if robot.pose_dim == 6 else "") + f"); keyframe '{HOME_KEY}' is the home pose. "
        f"Numbers are written with {xml_digits()} significant digits.",
    ]
    if held:
        fields = [f for f in HELD_EFFECTS_IN_WORDS if f in _set_fields(options)]
        lines.append(f"Effects held: {', '.join(held)}, as " + "; ".join(HELD_EFFECTS_IN_WORDS[f] for f in fields) + ".")
        if "joint_friction" in held:
            lines.append("MuJoCo's frictionloss is a soft constraint: at rest a joint creeps through it to its target, "
                         "so the friction acts while the joints move but leaves no dead band at rest.")
    else:
        lines.append("Effects held: none" + (" (the calibration found none)." if not cal.effects else "."))
    if not_held:
        lines.append("Effects MuJoCo cannot hold, left out of this model: "
                     + "; ".join(f"{n} ({why})" for n, why in not_held.items()) + ".")
    return _plain("\n" + "\n".join(lines) + "\n")


def _set_fields(options: MachineOptions) -> set:
    """The MachineOptions fields that differ from the defaults."""
    default = MachineOptions()
    return {f for f in HELD_EFFECTS_IN_WORDS if getattr(options, f) != getattr(default, f)}


def mjcf_text(cal: Calibration) -> str:
    """The MJCF (XML) text of the machine ``cal`` identified (:func:`identified_machine`), written
    by ``MjSpec.to_xml`` with every number in full (:func:`mjcf.machine.spec_xml`)."""
    spec = identified_machine(cal).spec
    spec.compile()
    return spec_xml(spec)


def export_mjcf(calibration: Calibration, path, *, overwrite: bool = False) -> Path:
    """Write the machine ``calibration`` identified as an MJCF file at ``path``, atomically (see the
    module docstring); load it with ``mujoco.MjModel.from_xml_path``.

    Args:
        calibration: what a calibration found (:func:`pipeline.formats.read_calibration`).
        path: the ``.xml`` file to write.
        overwrite: replace an existing file (refused otherwise).

    Returns:
        ``path``.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is off.
        OSError: ``path`` cannot be written.
        KeyError: no MuJoCo machine for the calibration's robot.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{path}: is a folder, not a file")
    if path.exists() and not overwrite:  # refused before the machine is built
        raise FileExistsError(f"{path} exists; pass --overwrite to replace it (refusing to overwrite it silently)")
    return atomic_write(path, mjcf_text(calibration), overwrite=overwrite)
