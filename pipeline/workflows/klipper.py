"""A Klipper printer's probe data, converted and fitted (docs/klipper.md).

:func:`convert_klipper` (``python -m pipeline.convert printer.cfg --klipper --out NAME``): the
linear Delta of a printer.cfg and the touches, manual heights and distances of its
``[delta_calibrate]`` block as a probe-data file ``NAME.probe.json``
(:mod:`pipeline.formats.probe_file`); joints = stable positions x each stepper's step distance (a
rotary Delta's: its robot ``NAME.json`` too, joints = stable positions x step angles,
:mod:`pipeline.workflows.klipper_rotary`).
:func:`fit_probe_file` (``python -m pipeline.probe NAME.probe.json --out DIR``): the MAP fit of
:func:`calib.probe.fit_probe`, written as a calibration file ``DIR/NAME.calibration.json`` (what
``pipeline.export`` reads) with the observability statement beside it
(``DIR/NAME.observability.txt``).

Refused in one line, nothing written: a config that is not a Delta or (a linear one) has no
``[delta_calibrate]`` touches (naming the file, section and key), stable positions counted with
another step distance (the factor that would fit), fewer measurements than parameters asked for.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.calibration import Calibration, validity_domain
from calib.files import atomic_write
from calib.klipper import STEP_MISMATCH_MM, joints_from_stable, linear_delta_from_klipper, step_distance_factor
from calib.probe import ProbeData, ProbeFit, ProbeNoise, fit_probe
from pipeline.formats.klipper import (CALIBRATE_SECTION, STEPPERS, KlipperError, klipper_printer,
                                      read_klipper_config)
from pipeline.formats.outputs import check_outputs, output_folder
from pipeline.formats.probe_file import PROBE_SUFFIX, read_probe_file, step_key, write_probe_file

from .klipper_rotary import RotaryConvertResult, convert_rotary_klipper

__all__ = ["KlipperConvertResult", "ProbeRunResult", "convert_klipper", "fit_probe_file", "probe_output_path"]

OBSERVABILITY_SUFFIX = ".observability.txt"


@dataclass(frozen=True)
class KlipperConvertResult:
    """What :func:`convert_klipper` wrote: the file and its counts."""

    path: Path
    counts: dict
    step_distances_mm: tuple


@dataclass(frozen=True)
class ProbeRunResult:
    """What :func:`fit_probe_file` wrote and found."""

    calibration_path: Path
    statement_path: Path
    fit: ProbeFit


def probe_output_path(out: str) -> Path:
    """``NAME.probe.json`` of ``--out NAME`` (or of a name already ending so)."""
    name = str(out)
    return Path(name if name.endswith(PROBE_SUFFIX) else name + PROBE_SUFFIX)


def convert_klipper(config, out: str, *, overwrite: bool = False) -> KlipperConvertResult | RotaryConvertResult:
    """The probe-data file of the printer.cfg ``config`` (module docstring); of a rotary Delta's
    config, its Delta robot (:func:`pipeline.workflows.klipper_rotary.convert_rotary_klipper`)."""
    cfg = read_klipper_config(config)
    printer = klipper_printer(cfg)
    if printer.kinematics == "rotary_delta":
        return convert_rotary_klipper(printer, config, out, overwrite=overwrite)
    path = probe_output_path(out)
    check_outputs({"--out": path}, overwrite=overwrite)
    probe = printer.probe
    if probe is None or not len(probe.touch_z_mm):
        raise KlipperError(f"{printer.path}: [{CALIBRATE_SECTION}] has no height0/height0_pos: run DELTA_CALIBRATE "
                           "and SAVE_CONFIG first")
    b = printer.built  # the prior's centre: the build, not a fit's values (docs/klipper.md)
    robot = linear_delta_from_klipper(b.radius_mm, b.angles_rad, b.arm_lengths_mm, b.endstops_mm,
                                      print_radius_mm=printer.machine.print_radius_mm)
    sd = printer.machine.step_distances_mm  # the steps were counted with these
    data = ProbeData(joints_from_stable(probe.touch_steps, sd), probe.touch_z_mm,
                     joints_from_stable(probe.manual_steps, sd), probe.manual_z_mm,
                     joints_from_stable(probe.distance_steps, sd), probe.distance_mm)
    check_step_distance(printer.path, robot, data)
    raw = Path(config).read_bytes()
    source = {"name": Path(config).name, "sha256": hashlib.sha256(raw).hexdigest(),
              "what": f"Klipper printer.cfg, [{CALIBRATE_SECTION}]: stable positions x the steppers' step distances",
              "rotation_distances_mm": [cfg.number(s, "rotation_distance") for s in STEPPERS]}
    write_probe_file(path, robot, data, ProbeNoise(), sd, source, overwrite=overwrite)
    return KlipperConvertResult(path=path, counts=data.counts, step_distances_mm=tuple(float(v) for v in sd))


def check_step_distance(path, robot, data: ProbeData) -> None:
    """Refuse touches the nominal machine puts more than :data:`calib.klipper.STEP_MISMATCH_MM`
    (RMS) from their heights, naming the factor of the step distance that would fit them."""
    rms, factor, rms_factor = step_distance_factor(robot, data.touch_joints, data.touch_z_mm)
    if rms > STEP_MISMATCH_MM:
        raise KlipperError(f"{path}: [{CALIBRATE_SECTION}] height0_pos...: the stable positions put the touches "
                           f"{rms:.3g} mm (RMS) off their heights with the steppers' step distance: they were counted "
                           f"with another one; {factor:.4g} x it fits them ({rms_factor:.3g} mm RMS): check "
                           "microsteps, rotation_distance, full_steps_per_rotation and gear_ratio")


def fit_probe_file(probe_path, out_dir, *, name: str | None = None, overwrite: bool = False) -> ProbeRunResult:
    """The calibration of a probe-data file (module docstring)."""
    probe_path = Path(probe_path)
    stem = name or probe_path.name.removesuffix(PROBE_SUFFIX).removesuffix(".json")
    out = output_folder(out_dir)
    cal_path, text_path = out / f"{stem}.calibration.json", out / f"{stem}{OBSERVABILITY_SUFFIX}"
    check_outputs({"--out": cal_path, "--out ": text_path}, overwrite=overwrite)
    robot, data, noise, d = read_probe_file(probe_path)
    fit = fit_probe(robot, data, noise=noise)
    cal = probe_calibration(fit, data, probe_path, d)
    cal.write(cal_path, overwrite=overwrite)
    atomic_write(text_path, fit.statement() + "\n", overwrite=overwrite)
    return ProbeRunResult(calibration_path=cal_path, statement_path=text_path, fit=fit)


def probe_calibration(fit: ProbeFit, data: ProbeData, probe_path: Path, d: dict) -> Calibration:
    """The :class:`Calibration` of a probe fit: the robot's parameters and their std (the bed's
    plane goes to ``recording``: it is the instrument's frame, not the robot's)."""
    robot = fit.robot
    p = robot.n_parameters
    free = tuple(n for n in robot.table.names if fit.sources[n] != "held")
    idx = robot.table.indices(free)
    std = np.where([fit.sources[n] == "held" for n in robot.table.names], 0.0, fit.std[:p])
    joints = data.all_joints()
    poses = robot.forward_kinematics(fit.theta, joints)
    bed = dict(zip(("z_mm", "tilt_x_rad", "tilt_y_rad"), map(float, fit.bed_plane)))
    recording = {"name": probe_path.name, "sha256": hashlib.sha256(probe_path.read_bytes()).hexdigest(),
                 "sidecar_sha256": None, "source": d["source"], "bed": bed, "bed_mode": fit.bed,
                 step_key(robot): d[step_key(robot)]}
    return Calibration(robot=robot, theta=fit.theta, std=std, free=free, covariance=fit.covariance[np.ix_(idx, idx)],
                       validity=validity_domain(robot, poses, joints, np.zeros(len(joints))), recording=recording,
                       produced_by="python -m pipeline.probe")
