"""The LinuxCNC delivery (``--to linuxcnc``): the robot's LinuxCNC kinematics with its identified
parameters (a HAL file), an INI fragment, one compensation file per joint holding the joint's
offset and the effects a joint's table can hold, a ``NOTES.md`` naming what LinuxCNC cannot hold
with the accuracy given up, and ``export.json`` with every figure. The mathematics (the fit onto
LinuxCNC's kinematics, the tables, the accuracy given up) is :mod:`calib.linuxcnc`; the files'
text is :mod:`pipeline.formats.linuxcnc`.

The hexapod: ``genhexkins`` with its identified joints. The Delta: ``rotarydeltakins`` fitted to
the identified Delta (:func:`calib.linuxcnc.rotarydelta_fit`), the transform from the base frame
to LinuxCNC's world and the projection's residual stated in NOTES.md, export.json and on stderr.
The robots it accepts are the keys of :data:`KINEMATICS_WRITERS`.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from calib.calibration import Calibration
from calib.linuxcnc import (COMP_TABLE_SIZE, FINE_FACTOR, FIT_SAMPLE, FIT_SEED,
                            accuracy_given_up, comp_tables, genhex_geometry, genhex_joints, joint_table_effects,
                            projection_errors, rotarydelta_fit, rotarydelta_joints, workspace_sample)
from pipeline.formats import (HAL_NAME, INI_NAME, NOTES_NAME, RECORD_NAME, check_export_folder, comp_file_name,
                              comp_text, genhex_hal_text, kins_ini_text, rotarydelta_hal_text, write_export_folder)

from .protocol import Delivery, ExportReport, ExportSettings

__all__ = ["DELIVERY", "KINEMATICS_WRITERS", "write_linuxcnc", "UM_PER_MM", "WORKSPACE_SEED"]

#: Micrometres per millimetre (figures on stderr and in NOTES.md are in um).
UM_PER_MM = 1000.0
#: The seed of the calibrated workspace's poses on which the accuracy given up and the Delta's
#: projection residual are measured (:func:`calib.linuxcnc.workspace_sample`).
WORKSPACE_SEED = 0



def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _um(v: float) -> str:
    return "not evaluated" if not np.isfinite(v) else f"{UM_PER_MM * v:.3g} um"


def _left_out_lines(given) -> list[str]:
    lines = []
    for lo in given.left:
        cost = lo.note or (f"leaving it out costs {_um(lo.rms_mm)} RMS, {_um(lo.max_mm)} max over {given.poses} poses "
                           "of the calibrated workspace")
        lines.append(f"LinuxCNC cannot hold {lo.name}: {lo.why}; {cost}")
    if given.left:
        lines.append(f"the identified model commanded as LinuxCNC will command it: {_um(given.rms_mm)} RMS, "
                     f"{_um(given.max_mm)} max position error over {given.poses} poses of the calibrated workspace "
                     "(0 with everything compensated, as pipeline.compensate does)")
    return lines


def _notes(cal: Calibration, source: str, kinematics: str, tables, held, given, extra: list[str], unit: str) -> str:
    lines = [f"# LinuxCNC export of {source}", "",
             f"Robot: {cal.robot.name}; kinematics: `{kinematics}` ({HAL_NAME}); INI fragment: {INI_NAME}; one "
             f"compensation file per joint (`{comp_file_name(0)}` ...), type 0, {len(tables[0].nominal)} entries "
             f"(LinuxCNC holds {COMP_TABLE_SIZE} at most); every figure: {RECORD_NAME}.", "", *extra,
             "## What the compensation files hold", "",
             "Each joint's offset and the effects found that follow the joint's own position and direction: "
             + (", ".join(fe.name for fe in held) or "none") + ". LinuxCNC adds `trim = nominal - actual` to the joint "
             "value, interpolated linearly between entries, the up or down column by the sign of the joint's commanded "
             "velocity, the end entries held beyond the table. The tables span the joint values the calibrated "
             "commands reach (its validity: `joint_min` .. `joint_max`); beyond them the end trims hold (the offset "
             "stays right, the effects are not extrapolated, where `pipeline.compensate` extrapolates them with a "
             "warning).", "",
             "| joint | span | interpolation error |", "|---|---|---|"]
    lines += [f"| {t.joint} | {t.nominal[0]:.6g} .. {t.nominal[-1]:.6g} {unit} | {t.interpolation_error:.3g} {unit} |"
              for t in tables]
    lines += ["", "The interpolation error is the largest difference between LinuxCNC's trim (single-precision trims "
              f"and slopes, linear between entries) and the exact one, on a grid {FINE_FACTOR} times finer than the "
              "table.", "",
              "## What LinuxCNC cannot hold", ""]
    if not given.left:
        lines.append("Nothing: every effect the calibration found is in the compensation files.")
    for lo in given.left:
        cost = lo.note or f"leaving it out costs {_um(lo.rms_mm)} RMS, {_um(lo.max_mm)} max"
        lines.append(f"- **{lo.name}**: {lo.why}; {cost}.")
    if given.left:
        lines += ["", f"All left out together: {_um(given.rms_mm)} RMS, {_um(given.max_mm)} max. Figures: position "
                  f"error of the identified model (geometry and effects) over {given.poses} poses drawn in the "
                  "calibrated workspace (the box of the calibration poses), visited in order, commanded as LinuxCNC "
                  "will command it, against 0 with everything compensated (`pipeline.compensate`)."
                  " Noise-free model figures, not measurements."]
    return "\n".join(lines) + "\n"


def _workspace(cal: Calibration) -> tuple[np.ndarray, np.ndarray]:
    """``(poses, t_s)``: poses of the calibrated workspace, visited in order, and their times
    spread over the recording's span."""
    v = cal.validity
    poses = workspace_sample(cal.robot, cal.theta, v["pose_min"], v["pose_max"], seed=WORKSPACE_SEED)
    return poses, np.linspace(v["t_s"][0], v["t_s"][1], len(poses))


def _given_up(cal: Calibration, effects, held, poses, t_s):
    return accuracy_given_up(cal.robot, cal.theta, effects, held, poses, t_s)


def _record(cal: Calibration, settings: ExportSettings, kinematics: str, tables, held, given, extra: dict) -> dict:
    return {"format": "linuxcnc", "produced_by": "pipeline.export", "robot": cal.robot.name, "kinematics": kinematics,
            "calibration": {"path": str(settings.calibration), "sha256": _sha256(settings.calibration),
                            "produced_by": cal.produced_by, "recording": cal.recording},
            **extra,
            "comp_files": {comp_file_name(t.joint): {"entries": len(t.nominal), "span": [float(t.nominal[0]),
                                                                                       float(t.nominal[-1])],
                                                     "interpolation_error": t.interpolation_error}
                           for t in tables},
            "held_by_comp_files": [fe.name for fe in held],
            "not_held": {lo.name: {"why": lo.why, "rms_mm": None if not np.isfinite(lo.rms_mm) else lo.rms_mm,
                                   "max_mm": None if not np.isfinite(lo.max_mm) else lo.max_mm, "note": lo.note}
                         for lo in given.left},
            "given_up": {"poses": given.poses, "rms_mm": given.rms_mm, "max_mm": given.max_mm}}


def _names(robot) -> list[str]:
    return [HAL_NAME, INI_NAME, NOTES_NAME, RECORD_NAME] + [comp_file_name(j) for j in range(robot.n_chains)]


def _hexapod(cal: Calibration, settings: ExportSettings) -> ExportReport:
    robot, source = cal.robot, Path(settings.calibration).name
    check_export_folder(settings.out, _names(robot), overwrite=settings.overwrite)
    effects = cal.fitted_effects()
    held, _ = joint_table_effects(effects)
    geometry = genhex_geometry(robot, cal.theta)
    tables = comp_tables(robot, cal.theta, held, cal.validity["joint_min"], cal.validity["joint_max"], geometry.jmap)
    given = _given_up(cal, effects, held, *_workspace(cal))
    home = genhex_joints(geometry, robot.home_pose[None])[0]
    frame = ["## Frames and units", "",
             "LinuxCNC's world is the calibration's base frame; X Y Z (mm) are the pose's x y z, A B C (degrees) its "
             "alpha beta gamma, R = Rz(C) Ry(B) Rx(A), the project's convention (genhexkins' `pmRpyMatConvert`). "
             "Joint N is leg N+1 of the calibration; its value is the leg's length |R P + t - B| (mm). The project's "
             "command for leg i makes it `l + dl_i` long: the offsets `dl_i` are in the compensation files (trim = "
             "-dl_i - the effects' displacement), so the motor positions LinuxCNC outputs are the project's leg "
             "commands (those `pipeline.compensate` writes).", "",
             "Leg lengths at the home pose " + ", ".join(f"{v:.6f}" for v in home) + " mm (joint 0 .. 5).", ""]
    texts = {HAL_NAME: genhex_hal_text(geometry.base, geometry.platform, source),
             INI_NAME: kins_ini_text("genhexkins", "LINEAR", tables, source, robot.chain_word),
             **{comp_file_name(t.joint): comp_text(t) for t in tables},
             NOTES_NAME: _notes(cal, source, "genhexkins", tables, held, given, frame, "mm")}
    record = _record(cal, settings, "genhexkins", tables, held, given,
                     {"joint_map": {"scale": geometry.jmap.scale.tolist(), "offset": geometry.jmap.offset.tolist(),
                                    "motor_offset": geometry.jmap.motor_offset.tolist()},
                      "home_joint_values_mm": home.tolist()})
    texts[RECORD_NAME] = json.dumps(record, indent=1) + "\n"
    paths = write_export_folder(settings.out, texts, overwrite=settings.overwrite)
    return ExportReport("linuxcnc", robot.name, {k: str(p) for k, p in paths.items()}, _left_out_lines(given), record)


def _projection_line(rms: float, mx: float, n: int) -> str:
    return (f"rotarydeltakins (four lengths, three identical chains 120 degrees apart) cannot hold the identified Delta's "
            f"geometry exactly: the projection leaves {_um(rms)} RMS, {_um(mx)} max position error over {n} poses of the "
            "calibrated workspace (rotarydeltakins with the fitted parameters and the comp files, against the identified "
            "model)")


def _delta(cal: Calibration, settings: ExportSettings) -> ExportReport:
    robot, source, v = cal.robot, Path(settings.calibration).name, cal.validity
    check_export_folder(settings.out, _names(robot), overwrite=settings.overwrite)
    effects = cal.fitted_effects()
    held, _ = joint_table_effects(effects)
    fit_poses = workspace_sample(robot, cal.theta, v["pose_min"], v["pose_max"], FIT_SAMPLE, FIT_SEED)
    geometry = rotarydelta_fit(robot, cal.theta, fit_poses)
    by_chain = comp_tables(robot, cal.theta, held, v["joint_min"], v["joint_max"], geometry.jmap)
    tables = [replace(by_chain[c], joint=n) for n, c in enumerate(geometry.chain_of_joint)]
    poses, t_s = _workspace(cal)
    given = _given_up(cal, effects, held, poses, t_s)
    e = projection_errors(robot, cal.theta, held, geometry, tables, poses, t_s)
    rms, mx = float(np.sqrt(np.mean(e ** 2))), float(np.max(e))
    home = rotarydelta_joints(geometry, geometry.world(robot.home_pose[None]))[0]
    R, t, turn = geometry.rotation, geometry.translation, geometry.rotation_about_z_deg()
    chains = ", ".join(f"joint {n} = {robot.chain_word} {c + 1}" for n, c in enumerate(geometry.chain_of_joint))
    offsets = ", ".join(f"{geometry.jmap.offset[c]:.6f}" for c in geometry.chain_of_joint)
    frame_line = (f"LinuxCNC's world from the base frame: X Y Z = R p + t, a turn of {turn:.6f} degrees about z "
                  f"(R and t in {RECORD_NAME}); {chains}.")
    frame = ["## Frames and units", "",
             "rotarydeltakins fixes LinuxCNC's world: origin at the centre of the hips' plane, z up, joint 0's hip on -y, "
             "joints 1 and 2 at +-120 degrees from it (30 and 150 degrees from +x). " + frame_line +
             " A target p (mm, the calibration's base frame) is commanded in LinuxCNC at X Y Z = R p + t:", "",
             "| | x | y | z | t (mm) |", "|---|---|---|---|---|"]
    frame += [f"| {'XYZ'[i]} | {R[i, 0]:.12f} | {R[i, 1]:.12f} | {R[i, 2]:.12f} | {t[i]:.6f} |" for i in range(3)]
    frame += ["", "The joint value is rotarydeltakins' hip angle in degrees: 0 with the thigh horizontal, positive turning "
              "the knee down, the sign and zero of the project's arm angle `q + alpha` (`calib.robots.delta`). The project's "
              "command q (rad) puts the hip at `degrees(q + dq) + offset`, the offset fitted per joint (degrees, joint 0 .. "
              f"2: {offsets}) and dq the effects' displacement: both are in the compensation files, so the motor "
              "positions LinuxCNC outputs are the project's joint commands in degrees (`pipeline.compensate` writes them in "
              "rad).", "",
              f"rotarydeltakins' kinematics depend on `platformradius - footradius` only: `footradius` is the robot's "
              f"plate radius ({robot.rn_mm:g} mm), `platformradius` that plus the fitted reach.", "",
              "Hip angles at the home pose " + ", ".join(f"{a:.6f}" for a in home) + " degrees (joint 0 .. 2).", "",
              "## The projection onto rotarydeltakins", "",
              "rotarydeltakins holds three identical chains 120 degrees apart (its four lengths); the identified Delta has "
              "24 parameters, each chain its own shoulder, azimuth, arm and forearm. The lengths, each joint's angle "
              "offset and the transform R, t were fitted by least squares (scipy.optimize.least_squares) to the "
              f"identified model's position errors over {geometry.fit_poses} poses of the calibrated workspace "
              f"(seed {FIT_SEED}): {_um(geometry.fit_rms_mm)} RMS, {_um(geometry.fit_max_mm)} max there. What it leaves, "
              f"rotarydeltakins with the fitted parameters and the comp files against the identified model over {len(poses)} "
              f"other poses of the calibrated workspace (seed {WORKSPACE_SEED}, visited in order): **{_um(rms)} RMS, "
              f"{_um(mx)} max** (noise-free model figures; `pipeline.compensate` leaves 0 there). A machine whose "
              "chains differ by more than this needs the identified model (`pipeline.compensate`), not rotarydeltakins.",
              ""]
    texts = {HAL_NAME: rotarydelta_hal_text(geometry.values(), source, frame_line),
             INI_NAME: kins_ini_text("rotarydeltakins", "ANGULAR", tables, source, robot.chain_word,
                                     chains=geometry.chain_of_joint),
             **{comp_file_name(t.joint): comp_text(t) for t in tables},
             NOTES_NAME: _notes(cal, source, "rotarydeltakins", tables, held, given, frame, "deg")}
    record = _record(cal, settings, "rotarydeltakins", tables, held, given,
                     {"rotarydeltakins": geometry.values(),
                      "world_from_base": {"rotation": R.tolist(), "translation_mm": t.tolist(),
                                          "rotation_about_z_deg": turn},
                      "chain_of_joint": geometry.chain_of_joint.tolist(), "joint_unit": "deg",
                      "joint_map": {"scale": geometry.jmap.scale.tolist(), "offset": geometry.jmap.offset.tolist(),
                                    "motor_offset": geometry.jmap.motor_offset.tolist()},
                      "projection": {"poses": len(poses), "seed": WORKSPACE_SEED, "rms_mm": rms, "max_mm": mx,
                                     "fit": {"poses": geometry.fit_poses, "seed": FIT_SEED, "rms_mm": geometry.fit_rms_mm,
                                             "max_mm": geometry.fit_max_mm}},
                      "home_joint_values_deg": home.tolist()})
    texts[RECORD_NAME] = json.dumps(record, indent=1) + "\n"
    paths = write_export_folder(settings.out, texts, overwrite=settings.overwrite)
    messages = [_projection_line(rms, mx, len(poses))] + _left_out_lines(given)
    return ExportReport("linuxcnc", robot.name, {k: str(p) for k, p in paths.items()}, messages, record)


#: The robots LinuxCNC has kinematics for, and the writer of each one's configuration.
KINEMATICS_WRITERS = {"hexapod": _hexapod, "delta": _delta}


def write_linuxcnc(cal: Calibration, settings: ExportSettings) -> ExportReport:
    """The LinuxCNC configuration of ``cal`` in the folder ``settings.out`` (see the module
    docstring); ``cal`` is of a robot of :data:`KINEMATICS_WRITERS` (:func:`pipeline.deliveries.deliver`
    refuses the others).

    Raises:
        FileExistsError: a file of the export exists and ``overwrite`` is off.
    """
    return KINEMATICS_WRITERS[cal.robot.name](cal, settings)


#: The delivery: its robots, those LinuxCNC has kinematics for; its record hashes the calibration file.
DELIVERY = Delivery(name="linuxcnc", robots=tuple(KINEMATICS_WRITERS), write=write_linuxcnc, names_its_file=True,
                    refusal="LinuxCNC has no kinematics for the {robot} ({source}); it has for the {robots}")
