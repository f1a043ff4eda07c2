"""Klipper's printer.cfg for a linear Delta (``python -m pipeline.export --calibration C.json --to
klipper --out DIR``; docs/klipper.md).

Klipper holds a linear Delta as ``delta_radius``, each tower's ``angle``, ``arm_length`` and
``position_endstop`` and each stepper's ``rotation_distance``: vertical towers, equal rods, no
thermal term. :func:`calib.klipper.fit_klipper` fits those to the identified machine over the
print volume (least squares of the tool-point error on :func:`calib.klipper.volume_grid`, in the
bed's frame where the calibration estimated the bed); what remains in z at the bed goes into a
``[bed_mesh]`` profile. Written into ``DIR``, all or nothing: ``save_config.cfg`` (the SAVE_CONFIG
block, values ``%.6f``, to append to printer.cfg in place of the old block) and ``NOTES.md`` (the
projection's residual over the volume with and without the mesh, what Klipper cannot hold, the
accuracy given up).

A rotary Delta (the ``delta`` robot) goes to :func:`write_klipper_rotary`: Klipper's rotary
parameters (:mod:`pipeline.deliveries.klipper_rotary`), the same two files, no bed mesh.
"""

from __future__ import annotations

import numpy as np

from calib.calibration import Calibration
from calib.klipper import KLIPPER_PARAMETERS, VOLUME_STEP_MM, fit_klipper, mesh_points, volume_grid
from pipeline.formats import check_export_folder, write_export_folder
from pipeline.formats.klipper import SAVE_CONFIG_HEADER, SAVE_CONFIG_NOTICE, SAVE_CONFIG_PREFIX, STEPPERS

from .klipper_rotary import is_probe_calibration, probe_bed, rotary_export
from .protocol import Delivery, ExportReport, ExportSettings

__all__ = ["DELIVERY", "write_klipper", "write_klipper_rotary", "write_klipper_for", "SAVE_CONFIG_NAME", "KLIPPER_NOTES_NAME", "MESH_COUNT", "MESH_PROFILE"]

SAVE_CONFIG_NAME, KLIPPER_NOTES_NAME = "save_config.cfg", "NOTES.md"
#: The mesh's nodes per axis (Klipper's bicubic interpolation; lagrange stops at 6) and its profile's name.
MESH_COUNT, MESH_PROFILE = 7, "workbench"
#: Klipper's bed_mesh profile version, its interpolation and the points it interpolates between nodes.
MESH_VERSION, MESH_ALGO, MESH_TENSION, MESH_PPS = 1, "bicubic", 0.2, 2


def bed_of(cal: Calibration) -> np.ndarray:
    """(3,) the bed plane a probe calibration estimated (:func:`probe_bed`; zero for any other)."""
    bed = probe_bed(cal)
    return np.zeros(3) if bed is None else bed


def calibrated_radius(cal: Calibration) -> float:
    """The radius the calibration saw (mm): the largest |x| or |y| of its validity box, within the
    robot's print radius."""
    v = cal.validity
    seen = max(abs(v["pose_min"][0]), abs(v["pose_max"][0]), abs(v["pose_min"][1]), abs(v["pose_max"][1]))
    return float(min(seen, cal.robot.full_workspace_bounds()[0, 1]))


def rotation_distances(cal: Calibration) -> list | None:
    """The config's ``rotation_distance`` per stepper the joints were counted with, or None."""
    source = cal.recording.get("source")
    return source.get("rotation_distances_mm") if isinstance(source, dict) else None


def save_config_text(kappa: np.ndarray, rotation: list | None, axis: np.ndarray, points: np.ndarray | None) -> str:
    """The SAVE_CONFIG block: Klipper's parameters (``%.6f``, angles in degrees) and the mesh
    (``points`` None: none)."""
    k = dict(zip(KLIPPER_PARAMETERS, kappa))
    lines = ["[printer]", f"delta_radius = {k['delta_radius']:.6f}", ""]
    for i, stepper in enumerate(STEPPERS):
        t = stepper[-1]
        lines += [f"[{stepper}]", f"angle = {np.degrees(k[f'angle_{t}']):.6f}",
                  f"arm_length = {k[f'arm_length_{t}']:.6f}", f"position_endstop = {k[f'position_endstop_{t}']:.6f}"]
        if rotation is not None:
            lines.append(f"rotation_distance = {rotation[i] * k[f'step_factor_{t}']:.6f}")
        lines.append("")
    if points is not None:
        lines += [f"[bed_mesh {MESH_PROFILE}]", f"version = {MESH_VERSION}", "points ="]
        lines += ["\t" + ", ".join(f"{v:.6f}" for v in row) for row in points]
        lines += [f"x_count = {MESH_COUNT}", f"y_count = {MESH_COUNT}", f"mesh_x_pps = {MESH_PPS}",
                  f"mesh_y_pps = {MESH_PPS}", f"algo = {MESH_ALGO}", f"tension = {MESH_TENSION}",
                  f"min_x = {axis[0]:.6f}", f"max_x = {axis[-1]:.6f}", f"min_y = {axis[0]:.6f}",
                  f"max_y = {axis[-1]:.6f}"]
    block = [f"{SAVE_CONFIG_NOTICE}. The contents are auto-generated.", ""] + lines
    return "\n".join([SAVE_CONFIG_HEADER] + [f"{SAVE_CONFIG_PREFIX}{line}".rstrip() for line in block]) + "\n"


def residuals(errors: np.ndarray, grid: np.ndarray) -> dict:
    """RMS and max (mm) of the tool-point error over the grid, without and with the mesh (the
    mesh taken at its exact values: the z error at the bed under each point removed)."""
    at_bed = {tuple(p[:2]): e[2] for p, e in zip(grid, errors) if p[2] == 0.0}
    meshed = errors.copy()
    meshed[:, 2] -= [at_bed[tuple(p[:2])] for p in grid]
    out = {}
    for label, e in (("without mesh", errors), ("with mesh", meshed)):
        n = np.linalg.norm(e, axis=1)
        out[label] = {"rms_mm": float(np.sqrt(np.mean(n ** 2))), "max_mm": float(n.max()),
                      "z_rms_mm": float(np.sqrt(np.mean(e[:, 2] ** 2))), "z_max_mm": float(np.abs(e[:, 2]).max())}
    return out


def mesh_lowers_the_residual(res: dict) -> bool:
    """Whether the mesh lowers the projection's RMS over the volume (:func:`residuals`): Klipper
    applies it at every height, so a z error at the bed that is not the z error above it may
    make the volume worse; the mesh is written only where it does not."""
    return res["with mesh"]["rms_mm"] < res["without mesh"]["rms_mm"]


def mesh_paragraph(res: dict) -> str:
    """NOTES.md's words on the mesh: how to load it, or why none was written."""
    if mesh_lowers_the_residual(res):
        return f""""with mesh": the `[bed_mesh {MESH_PROFILE}]` profile removes the z error at the bed under each point
(taken at its exact values; Klipper interpolates between its {MESH_COUNT} x {MESH_COUNT} nodes). Load it
with `BED_MESH_PROFILE LOAD={MESH_PROFILE}`. Nodes outside the print radius (the square's corners)
take the value at the nearest point of its circle."""
    return f""""with mesh": what a mesh of the z error at the bed would leave (the error at the bed under each
point removed at every height, as Klipper applies a mesh). It would not lower the residual over
the volume (RMS {res['with mesh']['rms_mm']:.4f} against {res['without mesh']['rms_mm']:.4f} mm without): the z
error left at the bed is not the one above it, so no `[bed_mesh]` profile was written."""


def notes_text(cal: Calibration, settings: ExportSettings, res: dict, n_points: int, radius: float, rotation) -> str:
    """NOTES.md: the projection's residual, what Klipper cannot hold, the accuracy given up."""
    shift = (", after the best shift of the whole print in x, y (the probe data fix none: the print as a whole "
             "may sit elsewhere in x, y than under the old settings)") if is_probe_calibration(cal) else ""
    by = cal.robot.table.to_dict(cal.theta)
    std = cal.robot.table.to_dict(cal.std)
    leans = ", ".join(f"{n} {1e3 * by[n]:+.2f} +- {1e3 * std[n]:.2f} mrad" for n in by if n.startswith("lean"))
    rods = ", ".join(f"{n} {by[n]:+.3f} +- {std[n]:.3f} mm" for n in by if n.startswith("arm_diff"))
    rows = "\n".join(f"| {k} | {v['rms_mm']:.4f} | {v['max_mm']:.4f} | {v['z_rms_mm']:.4f} | {v['z_max_mm']:.4f} |"
                     for k, v in res.items())
    steps = ("rotation_distance written per stepper (the config's times the fitted step factor)" if rotation
             else "no rotation_distance written: the calibration does not name the config's; the step factors are "
                  "in the record below")
    return f"""# Klipper export of {settings.calibration or 'a calibration made in memory'}

Klipper's linear Delta holds `delta_radius`, per tower `angle`, `arm_length`, `position_endstop`,
and per stepper `rotation_distance` ({steps}). They were fitted to the identified machine by
least squares of the tool-point error over {n_points} points of the print volume (every
{VOLUME_STEP_MM:g} mm across the calibrated radius, {radius:.1f} mm, from the bed to 150 mm above it),
in the bed's frame{shift}.

## The projection's residual over the volume (mm)

| | RMS | max | z RMS | z max |
|---|---|---|---|---|
{rows}

{mesh_paragraph(res)}

## What Klipper cannot hold (the accuracy given up is the residual above)

- Tower lean: {leans}.
- Unequal rods within a pair (the effector's tilt): {rods}; Klipper's equal-rod model has no
  term for it.
- Per-tower radius: Klipper has one `delta_radius`; the identified radii differ by
  {np.ptp([by[f'radius{i}'] for i in (1, 2, 3)]):.3f} mm.
- Thermal growth: none identified in this calibration; Klipper has no temperature term
  (re-calibrate at the printing temperature).
"""


def write_klipper(cal: Calibration, settings: ExportSettings) -> ExportReport:
    """Write ``save_config.cfg`` and ``NOTES.md`` into ``settings.out`` (module docstring)."""
    check_export_folder(settings.out, [SAVE_CONFIG_NAME, KLIPPER_NOTES_NAME], overwrite=settings.overwrite)
    robot, bed = cal.robot, bed_of(cal)
    radius = calibrated_radius(cal)
    grid = volume_grid(radius)
    kappa, errors = fit_klipper(robot, cal.theta, bed, grid, free_shift=is_probe_calibration(cal))
    axis, points = mesh_points(robot, cal.theta, bed, kappa, radius, MESH_COUNT)
    res = residuals(errors, grid)
    rotation = rotation_distances(cal)
    texts = {SAVE_CONFIG_NAME: save_config_text(kappa, rotation, axis,
                                                points if mesh_lowers_the_residual(res) else None),
             KLIPPER_NOTES_NAME: notes_text(cal, settings, res, len(grid), radius, rotation)}
    paths = write_export_folder(settings.out, texts, overwrite=settings.overwrite)
    lines = [f"projection onto Klipper's parameters over {len(grid)} points: {k} RMS {v['rms_mm']:.4f} mm, max "
             f"{v['max_mm']:.4f} mm" for k, v in res.items()]
    if not mesh_lowers_the_residual(res):
        lines.append("no [bed_mesh] profile written: the mesh would not lower the residual over the volume")
    return ExportReport(format="klipper", robot=robot.name, paths={k: str(v) for k, v in paths.items()}, messages=lines,
                        summary={"parameters": dict(zip(KLIPPER_PARAMETERS, map(float, kappa))), "residual": res,
                                 "mesh_written": mesh_lowers_the_residual(res)})


def write_klipper_rotary(cal: Calibration, settings: ExportSettings) -> ExportReport:
    """The rotary Delta's (``delta``) ``save_config.cfg`` and ``NOTES.md`` into ``settings.out``
    (:mod:`pipeline.deliveries.klipper_rotary`: Klipper's rotary parameters, no bed mesh)."""
    check_export_folder(settings.out, [SAVE_CONFIG_NAME, KLIPPER_NOTES_NAME], overwrite=settings.overwrite)
    export = rotary_export(cal, settings)
    paths = write_export_folder(settings.out, {SAVE_CONFIG_NAME: export.save_config, KLIPPER_NOTES_NAME: export.notes},
                                overwrite=settings.overwrite)
    return ExportReport(format="klipper", robot=cal.robot.name, paths={k: str(v) for k, v in paths.items()},
                        messages=export.messages, summary=export.summary)


def write_klipper_for(cal: Calibration, settings: ExportSettings) -> ExportReport:
    """The export of Klipper's kinematics for ``cal``'s robot: rotary (``delta``) or linear."""
    return (write_klipper_rotary if cal.robot.name == "delta" else write_klipper)(cal, settings)


DELIVERY = Delivery(name="klipper", robots=("linear_delta", "delta"), write=write_klipper_for,
                    refusal="Klipper has no kinematics for the {robot} ({source}); it has for the {robots}")
