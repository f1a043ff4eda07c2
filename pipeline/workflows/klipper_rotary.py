"""A Klipper rotary Delta's config, converted (``python -m pipeline.convert printer.cfg --klipper
--out NAME`` on ``[printer] kinematics: rotary_delta``; docs/klipper.md).

What a rotary config honestly gives: the machine Klipper believes in, as the workbench's
:class:`calib.robots.delta.Delta` (:func:`calib.klipper_rotary.delta_from_klipper_rotary`: base
frame at the shoulders, the bed ``shoulder_height`` below, the joints the arms' turns below their
endstops = Klipper's stable positions x the step angles). Written as ``NAME.json``: the robot's
description (what ``--geometry`` of ``pipeline.design`` and ``pipeline.study`` and a lab map's
``[robot] description`` read), with the config's name, SHA-256 and step angles under ``klipper``.

Klipper's ``DELTA_CALIBRATE`` runs on a rotary Delta too (its kinematics give it a calibration
helper) and saves touches in ``[delta_calibrate]`` as stable positions (steps counted from each
arm's endstop). Those, with the manual heights and distances, go into ``NAME.probe.json``
(:mod:`pipeline.formats.probe_file`, what ``python -m pipeline.probe`` fits): the joints the stable
positions times the step angles, the arms' turns below their endstops as ``NAME.json`` defines
them, the robot the same. A touch whose arm angles the robot cannot assemble is refused naming its
key; nothing is written then.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.files import atomic_write
from calib.klipper import joints_from_stable
from calib.klipper_rotary import delta_from_klipper_rotary
from calib.probe import ProbeData, ProbeNoise
from calib.robot import KinematicsError
from pipeline.formats.klipper import CALIBRATE_SECTION, STEPPERS, KlipperError, KlipperPrinter
from pipeline.formats.outputs import check_outputs
from pipeline.formats.probe_file import PROBE_SUFFIX, probe_file_text

__all__ = ["RotaryConvertResult", "convert_rotary_klipper", "rotary_output_path", "ROTARY_SOURCE_KEY",
           "rotary_probe_data", "stable_key"]

#: The description's key holding where it came from (the config's name and SHA-256, the step angles).
ROTARY_SOURCE_KEY = "klipper"


@dataclass(frozen=True)
class RotaryConvertResult:
    """What :func:`convert_rotary_klipper` wrote: the robot's file, the probe-data file (None
    without touches), the step angles (rad) and the probe data's counts."""

    path: Path
    probe_path: Path | None
    step_angles_rad: tuple
    counts: dict

    def line(self) -> str:
        """What the command prints."""
        steps = ", ".join(f"{v:.6g}" for v in self.step_angles_rad)
        robot = (f"wrote {self.path}: the delta robot of the rotary_delta config (base frame at the shoulders; joints: "
                 f"the arms' turns below their endstops, stable positions x step angles {steps} rad)")
        if self.probe_path is None:
            return robot
        counts = ", ".join(f"{v} {k}" for k, v in self.counts.items())
        return f"{robot}\nwrote {self.probe_path}: {counts} of [{CALIBRATE_SECTION}] at those joints"

    def warnings(self) -> list[str]:
        """What was left out, one line each."""
        return [] if self.probe_path else [f"no touches in [{CALIBRATE_SECTION}]: no probe-data file written "
                                           "(run DELTA_CALIBRATE and SAVE_CONFIG for one)"]


def rotary_output_path(out: str) -> Path:
    """``NAME.json`` of ``--out NAME`` (or of a name already ending so)."""
    name = str(out)
    return Path(name if name.endswith(".json") else name + ".json")


def stable_key(row: int, counts: dict) -> str:
    """The ``[delta_calibrate]`` key of the ``row``-th joints of :meth:`ProbeData.all_joints`."""
    n, m = counts["touches"], counts["manual heights"]
    if row < n:
        return f"height{row}_pos"
    if row < n + m:
        return f"manual_height{row - n}_pos"
    return f"distance{(row - n - m) // 2}_pos{1 + (row - n - m) % 2}"


def rotary_probe_data(printer: KlipperPrinter, robot) -> ProbeData | None:
    """The probe data of the config's ``[delta_calibrate]`` at the robot's joints (module
    docstring), None without touches.

    Raises:
        KlipperError: a stable position whose arm angles the robot cannot assemble (naming its key).
    """
    probe = printer.probe
    if probe is None or not len(probe.touch_z_mm):
        return None
    a = printer.machine.step_angles_rad
    data = ProbeData(joints_from_stable(probe.touch_steps, a), probe.touch_z_mm,
                     joints_from_stable(probe.manual_steps, a), probe.manual_z_mm,
                     joints_from_stable(probe.distance_steps, a), probe.distance_mm)
    joints = data.all_joints()
    try:
        robot.forward_kinematics(robot.table.nominal, joints)
        ranges = np.asarray(robot.joint_ranges)
        outside = ~np.all((joints >= ranges[:, 0]) & (joints <= ranges[:, 1]), axis=1)
        if np.any(outside):
            row = int(np.flatnonzero(outside)[0])
            raise KinematicsError("an arm beyond its endstop or past hanging straight down (its range "
                                  f"{np.round(ranges, 4).tolist()} rad)", row)
    except KinematicsError as exc:
        row = exc.index
        raise KlipperError(f"{printer.path}: [{CALIBRATE_SECTION}] {stable_key(row, data.counts)}: the arms turned "
                           f"{np.round(joints[row], 6).tolist()} rad below their endstops do not assemble ({exc}): "
                           "check the stable positions, gear_ratio and microsteps") from None
    return data


def convert_rotary_klipper(printer: KlipperPrinter, config, out: str, *, overwrite: bool = False) -> RotaryConvertResult:
    """The Delta robot of the rotary config ``printer`` (read from ``config``) as ``NAME.json`` and
    its ``[delta_calibrate]`` data as ``NAME.probe.json`` (module docstring).

    Raises:
        KlipperError: an endstop height its arm cannot reach at the centre (naming the stepper), a
            stable position the robot cannot assemble (naming its key).
        FileExistsError: an output exists and ``overwrite`` is off.
    """
    path = rotary_output_path(out)
    probe_path = Path(str(path).removesuffix(".json") + PROBE_SUFFIX)
    m = printer.machine
    try:
        robot = delta_from_klipper_rotary(m.shoulder_radius_mm, m.shoulder_height_mm, m.angles_rad,
                                          m.upper_arm_lengths_mm, m.lower_arm_lengths_mm, m.endstops_mm)
    except KinematicsError as exc:
        raise KlipperError(f"{printer.path}: [{STEPPERS[exc.index]}] position_endstop: {exc}; check shoulder_height, "
                           "the arms and position_endstop (the tool's height at the centre at the endstop)") from None
    data = rotary_probe_data(printer, robot)
    check_outputs({"--out": path} if data is None else {"--out": path, "--out ": probe_path}, overwrite=overwrite)
    raw = Path(config).read_bytes()
    source = {"name": Path(config).name, "sha256": hashlib.sha256(raw).hexdigest(), "kinematics": printer.kinematics,
              "step_angles_rad": [float(v) for v in m.step_angles_rad]}
    atomic_write(path, json.dumps({**robot.description(), ROTARY_SOURCE_KEY: source}, indent=1) + "\n",
                 overwrite=overwrite)
    if data is None:
        return RotaryConvertResult(path=path, probe_path=None, step_angles_rad=tuple(source["step_angles_rad"]),
                                   counts={})
    what = (f"Klipper printer.cfg, rotary_delta, [{CALIBRATE_SECTION}]: stable positions x the steppers' step angles "
            "(the arms' turns below their endstops)")
    atomic_write(probe_path, probe_file_text(robot, data, ProbeNoise(), m.step_angles_rad,
                                             {"name": source["name"], "sha256": source["sha256"], "what": what}),
                 overwrite=overwrite)
    return RotaryConvertResult(path=path, probe_path=probe_path, step_angles_rad=tuple(source["step_angles_rad"]),
                               counts=data.counts)
