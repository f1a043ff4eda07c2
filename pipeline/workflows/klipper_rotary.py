"""A Klipper rotary Delta's config, converted (``python -m pipeline.convert printer.cfg --klipper
--out NAME`` on ``[printer] kinematics: rotary_delta``; docs/klipper.md).

What a rotary config honestly gives: the machine Klipper believes in, as the workbench's
:class:`calib.robots.delta.Delta` (:func:`calib.klipper_rotary.delta_from_klipper_rotary`: base
frame at the shoulders, the bed ``shoulder_height`` below, the joints the arms' turns below their
endstops = Klipper's stable positions x the step angles). Written as ``NAME.json``: the robot's
description (what ``--geometry`` of ``pipeline.design`` and ``pipeline.study`` and a lab map's
``[robot] description`` read), with the config's name, SHA-256 and step angles under ``klipper``.

Klipper's ``DELTA_CALIBRATE`` runs on a rotary Delta too (its kinematics give it a calibration
helper) and saves touches in ``[delta_calibrate]``; the workbench's probe fit
(:mod:`calib.probe`) is for the linear Delta, so those touches are not converted, and the
result says how many were left.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from calib.files import atomic_write
from calib.klipper_rotary import delta_from_klipper_rotary
from calib.robot import KinematicsError
from pipeline.formats.klipper import CALIBRATE_SECTION, STEPPERS, KlipperError, KlipperPrinter
from pipeline.formats.outputs import check_outputs

__all__ = ["RotaryConvertResult", "convert_rotary_klipper", "rotary_output_path", "ROTARY_SOURCE_KEY"]

#: The description's key holding where it came from (the config's name and SHA-256, the step angles).
ROTARY_SOURCE_KEY = "klipper"


@dataclass(frozen=True)
class RotaryConvertResult:
    """What :func:`convert_rotary_klipper` wrote: the file, the step angles (rad) and the touches
    of ``[delta_calibrate]`` left unconverted."""

    path: Path
    step_angles_rad: tuple
    touches_left: int

    def line(self) -> str:
        """What the command prints."""
        steps = ", ".join(f"{v:.6g}" for v in self.step_angles_rad)
        return (f"wrote {self.path}: the delta robot of the rotary_delta config (base frame at the shoulders; joints: "
                f"the arms' turns below their endstops, stable positions x step angles {steps} rad)")

    def warnings(self) -> list[str]:
        """What was left out, one line each."""
        return [f"not converted: the {self.touches_left} touches of [{CALIBRATE_SECTION}]: the probe fit "
                "(pipeline.probe) is for the linear Delta (kinematics: delta)"] if self.touches_left else []


def rotary_output_path(out: str) -> Path:
    """``NAME.json`` of ``--out NAME`` (or of a name already ending so)."""
    name = str(out)
    return Path(name if name.endswith(".json") else name + ".json")


def convert_rotary_klipper(printer: KlipperPrinter, config, out: str, *, overwrite: bool = False) -> RotaryConvertResult:
    """The Delta robot of the rotary config ``printer`` (read from ``config``) as ``NAME.json``
    (module docstring).

    Raises:
        KlipperError: an endstop height its arm cannot reach at the centre (naming the stepper).
        FileExistsError: ``NAME.json`` exists and ``overwrite`` is off.
    """
    path = rotary_output_path(out)
    check_outputs({"--out": path}, overwrite=overwrite)
    m = printer.machine
    try:
        robot = delta_from_klipper_rotary(m.shoulder_radius_mm, m.shoulder_height_mm, m.angles_rad,
                                          m.upper_arm_lengths_mm, m.lower_arm_lengths_mm, m.endstops_mm)
    except KinematicsError as exc:
        raise KlipperError(f"{printer.path}: [{STEPPERS[exc.index]}] position_endstop: {exc}; check shoulder_height, "
                           "the arms and position_endstop (the tool's height at the centre at the endstop)") from None
    raw = Path(config).read_bytes()
    source = {"name": Path(config).name, "sha256": hashlib.sha256(raw).hexdigest(), "kinematics": printer.kinematics,
              "step_angles_rad": [float(v) for v in m.step_angles_rad]}
    atomic_write(path, json.dumps({**robot.description(), ROTARY_SOURCE_KEY: source}, indent=1) + "\n",
                 overwrite=overwrite)
    touches = 0 if printer.probe is None else len(printer.probe.touch_z_mm)
    return RotaryConvertResult(path=path, step_angles_rad=tuple(source["step_angles_rad"]), touches_left=touches)
