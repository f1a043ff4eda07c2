"""A calibration delivered where it is used, as a library function.

:func:`run_export` does what ``python -m pipeline.export`` does: read the calibration file
(:func:`pipeline.formats.read_calibration`) and hand it to the exporter of the format asked for
(:data:`EXPORTERS`, one function per format: ``exporter(cal, settings) -> ExportReport``). A new
format is one entry there.

``mjcf`` (:func:`export_to_mjcf`): the identified machine as a MuJoCo model file
(:mod:`pipeline.simulation.mjcf_export`).

``linuxcnc`` (:func:`export_linuxcnc`): the robot's LinuxCNC kinematics with its identified
parameters (a HAL file), an INI fragment, one compensation file per joint holding the joint's
offset and the effects a joint's table can hold, a ``NOTES.md`` naming what LinuxCNC cannot hold
with the accuracy given up, and ``export.json`` with every figure (:mod:`calib.linuxcnc`,
:mod:`pipeline.formats.linuxcnc`).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib.calibration import register_delivery
from calib.linuxcnc import (COMP_TABLE_SIZE, FINE_FACTOR, accuracy_given_up, comp_tables, genhex_geometry, genhex_joints,
                            joint_table_effects, workspace_sample)
from pipeline.formats import (HAL_NAME, INI_NAME, NOTES_NAME, RECORD_NAME, Calibration, check_export_folder, comp_file_name, comp_text, genhex_hal_text,
                              kins_ini_text, read_calibration, write_export_folder)

__all__ = ["ExportSettings", "ExportReport", "run_export", "export_linuxcnc", "export_to_mjcf", "EXPORTERS", "delivery_of",
           "deliver_linuxcnc", "deliver_mjcf"]

#: Micrometres per millimetre (figures on stderr and in NOTES.md are in um).
UM_PER_MM = 1000.0


@dataclass(frozen=True)
class ExportSettings:
    """What :func:`run_export` does (``python -m pipeline.export --help`` for each field).

    Attributes:
        calibration: the calibration file.
        to: the format (a key of :data:`EXPORTERS`).
        out: where to write (a folder for ``linuxcnc``).
        overwrite: allow replacing existing files.
    """

    calibration: Path
    to: str
    out: Path
    overwrite: bool = False


@dataclass
class ExportReport:
    """What an export wrote.

    Attributes:
        format: the format.
        robot: the robot's name.
        paths: ``{file name: path}`` written.
        messages: what the user must know (what the target cannot hold, with the accuracy given
            up; the projection's residual), one line each, for stderr.
        summary: the export's record (``export.json`` for LinuxCNC).
    """

    format: str
    robot: str
    paths: dict = field(default_factory=dict)
    messages: list = field(default_factory=list)
    summary: dict = field(default_factory=dict)


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


def _notes(cal: Calibration, source: str, kinematics: str, tables, held, given, extra: list[str]) -> str:
    unit = cal.robot.joint_unit
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


def _given_up(cal: Calibration, effects, held):
    v, robot = cal.validity, cal.robot
    poses = workspace_sample(robot, cal.theta, v["pose_min"], v["pose_max"])
    t_s = np.linspace(v["t_s"][0], v["t_s"][1], len(poses))
    return accuracy_given_up(robot, cal.theta, effects, held, poses, t_s)


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
    effects = cal.effects()
    held, _ = joint_table_effects(effects)
    geometry = genhex_geometry(robot, cal.theta)
    tables = comp_tables(robot, cal.theta, held, cal.validity["joint_min"], cal.validity["joint_max"], geometry.jmap)
    given = _given_up(cal, effects, held)
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
             NOTES_NAME: _notes(cal, source, "genhexkins", tables, held, given, frame)}
    record = _record(cal, settings, "genhexkins", tables, held, given,
                     {"joint_map": {"scale": geometry.jmap.scale.tolist(), "offset": geometry.jmap.offset.tolist(),
                                    "motor_offset": geometry.jmap.motor_offset.tolist()},
                      "home_joint_values_mm": home.tolist()})
    texts[RECORD_NAME] = json.dumps(record, indent=1) + "\n"
    paths = write_export_folder(settings.out, texts, overwrite=settings.overwrite)
    return ExportReport("linuxcnc", robot.name, {k: str(p) for k, p in paths.items()}, _left_out_lines(given), record)


#: The robots LinuxCNC has kinematics for, and how each is exported.
LINUXCNC_ROBOTS = {"hexapod": _hexapod}
#: Robots LinuxCNC has kinematics for that this export does not project onto yet, and why.
LINUXCNC_NOT_YET = {"delta": "LinuxCNC's rotarydeltakins fitted to the identified Delta is not built yet"}


def export_linuxcnc(cal: Calibration, settings: ExportSettings) -> ExportReport:
    """The LinuxCNC export of ``cal`` into the folder ``settings.out`` (see the module docstring).

    Raises:
        ValueError: a robot LinuxCNC has no kinematics for (the 6-RUS), or the Delta (its
            rotarydeltakins projection is not built yet).
        FileExistsError: a file of the export exists and ``overwrite`` is off.
    """
    if cal.robot.name in LINUXCNC_NOT_YET:
        raise ValueError(f"--to linuxcnc: {LINUXCNC_NOT_YET[cal.robot.name]} ({settings.calibration})")
    if cal.robot.name not in LINUXCNC_ROBOTS:
        raise ValueError(f"--to linuxcnc: LinuxCNC has no kinematics for the {cal.robot.name} ({settings.calibration}); "
                         f"it has for the {', '.join(LINUXCNC_ROBOTS)}")
    return LINUXCNC_ROBOTS[cal.robot.name](cal, settings)


#: The formats ``pipeline.export`` writes: ``{name: exporter(cal, settings) -> ExportReport}``.
def export_to_mjcf(cal: Calibration, settings: ExportSettings) -> ExportReport:
    """The identified machine as a MuJoCo MJCF file at ``settings.out`` (a file path;
    :func:`pipeline.simulation.mjcf_export.export_mjcf`): the effects MuJoCo can hold built in, the
    others named in the file's comment and here, one line each.

    Raises:
        FileExistsError: the file exists and ``overwrite`` is off.
    """
    from pipeline.simulation.mjcf_export import export_mjcf, identified_machine  # MuJoCo only for this format

    path = export_mjcf(cal, settings.out, overwrite=settings.overwrite)
    machine = identified_machine(cal)
    messages = [f"not held by the MuJoCo model: {name} ({why})" for name, why in machine.not_held.items()]
    return ExportReport(format="mjcf", robot=cal.robot.name, paths={Path(path).name: str(path)}, messages=messages,
                        summary={"path": str(path), "held": list(machine.held), "not_held": dict(machine.not_held)})


EXPORTERS = {
    "linuxcnc": export_linuxcnc,
    "mjcf": export_to_mjcf,
}


def delivery_of(to: str):
    """The exporter of format ``to`` as a delivery of :mod:`calib.calibration`'s registry
    (``cal.deliver(to, out)``, ``cal.to_linuxcnc(folder)``): ``deliver(cal, out, *,
    overwrite=False) -> ExportReport``, the files ``python -m pipeline.export --calibration
    cal.source --to TO --out OUT`` writes.

    Raises (when called):
        ValueError: ``to`` is not a format of :data:`EXPORTERS`; for ``linuxcnc``, a
            calibration made in memory (its export names the file it came from: write it first).
    """
    def deliver(cal: Calibration, out, *, overwrite: bool = False) -> ExportReport:
        if to not in EXPORTERS:
            raise ValueError(f"delivery {to!r}: pipeline.export has no such format ({', '.join(EXPORTERS)})")
        if cal.source is None and to == "linuxcnc":
            raise ValueError("--to linuxcnc: the calibration was made in memory; its export names and hashes the "
                             "calibration file: write it (cal.write(path)) and read it back (Calibration.read(path))")
        settings = ExportSettings(calibration=cal.source, to=to, out=Path(out), overwrite=overwrite)
        return EXPORTERS[to](cal, settings)

    deliver.__name__ = deliver.__qualname__ = f"deliver_{to}"
    return deliver


#: The deliveries of the entry points ``parallel_calib.deliveries`` (pyproject.toml).
deliver_linuxcnc = delivery_of("linuxcnc")
deliver_mjcf = delivery_of("mjcf")
for _to in EXPORTERS:  # every format a delivery when this module is imported
    register_delivery(_to, delivery_of(_to))


def run_export(settings: ExportSettings) -> ExportReport:
    """Read the calibration file and export it (see the module docstring).

    Raises:
        ValueError: an unknown format, a bad calibration file (names the file and the key), a
            robot the format has no kinematics for.
        FileExistsError: an output exists and ``overwrite`` is off.
    """
    if settings.to not in EXPORTERS:
        raise ValueError(f"--to {settings.to}: unknown format (expected one of {', '.join(EXPORTERS)})")
    cal = read_calibration(settings.calibration)
    return EXPORTERS[settings.to](cal, settings)
