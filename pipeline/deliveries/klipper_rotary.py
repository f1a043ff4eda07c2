"""Klipper's printer.cfg for a rotary Delta (the ``delta`` robot; ``python -m pipeline.export
--calibration C.json --to klipper --out DIR``, dispatched by :mod:`pipeline.deliveries.klipper`;
docs/klipper.md).

Klipper holds a rotary Delta as ``shoulder_radius``, ``shoulder_height`` and, per stepper,
``angle``, ``upper_arm_length``, ``lower_arm_length`` and ``position_endstop``: the shoulders on one
circle at one height, each in the vertical plane through the z axis at its angle, no thermal term.
:func:`calib.klipper_rotary.project_onto_klipper_rotary` fits those to the identified machine over
the box the calibration saw (least squares of the tool-point error on a grid). :func:`rotary_export`
gives the texts: the SAVE_CONFIG block (values ``%.6f``, Klipper's own precision; angles in degrees)
and NOTES.md (the projection's residual, what Klipper cannot hold, the accuracy given up).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.calibration import Calibration
from calib.klipper_rotary import ROTARY_GRID_STEP_MM, RotaryProjection, project_onto_klipper_rotary
from pipeline.formats.klipper import STEPPERS, save_config_block

from .protocol import ExportSettings

__all__ = ["RotaryExport", "rotary_export", "rotary_save_config_text", "rotary_notes_text"]

#: Klipper's keys per stepper, in the order written, and the projection's name of each (``_a`` ...).
STEPPER_KEYS = ("angle", "upper_arm_length", "lower_arm_length", "position_endstop")


@dataclass(frozen=True)
class RotaryExport:
    """The rotary Delta's export: the SAVE_CONFIG block, NOTES.md, the lines for the user and the record."""

    save_config: str
    notes: str
    messages: list
    summary: dict


def rotary_save_config_text(projection: RotaryProjection) -> str:
    """The SAVE_CONFIG block of Klipper's fitted parameters (``%.6f``; angles in degrees)."""
    k = projection.parameters()
    lines = ["[printer]", f"shoulder_radius = {k['shoulder_radius']:.6f}",
             f"shoulder_height = {k['shoulder_height']:.6f}", ""]
    for stepper in STEPPERS:
        t = stepper[-1]
        values = [np.degrees(k[f"angle_{t}"])] + [k[f"{key}_{t}"] for key in STEPPER_KEYS[1:]]
        lines += [f"[{stepper}]"] + [f"{key} = {v:.6f}" for key, v in zip(STEPPER_KEYS, values)] + [""]
    return save_config_block(lines[:-1])


def unheld_lines(projection: RotaryProjection, effects) -> list:
    """NOTES.md's list of what Klipper cannot hold, with the identified values."""
    u = projection.unheld

    def per_arm(key):
        return ", ".join(f"{s[-1]} {v:+.3f}" for s, v in zip(STEPPERS, u[key]))

    effect_names = ", ".join(e.name for e in effects)
    return [f"- Shoulders off one circle (radius minus the mean, mm): {per_arm('radius_off_mm')}.",
            f"- Shoulders off their arm's plane (Klipper puts each on the vertical plane through the z axis at "
            f"its angle; offset across it, mm): {per_arm('plane_offset_mm')}.",
            f"- Shoulders at different heights (height minus the mean, mm): {per_arm('height_off_mm')}.",
            "- " + (f"The effects found ({effect_names}): Klipper has no term for them (re-calibrate where they "
                    "change the machine)." if effects else
                    "Effects (thermal growth, drift): none found in this calibration; Klipper has no term for them.")]


def rotary_notes_text(cal: Calibration, settings: ExportSettings, projection: RotaryProjection) -> str:
    """NOTES.md: the projection's residual, what Klipper cannot hold, the accuracy given up."""
    lo, hi = projection.targets.min(axis=0), projection.targets.max(axis=0)
    box = " x ".join(f"{a:.1f}..{b:.1f}" for a, b in zip(lo, hi))
    bed = probe_bed(cal)
    tilt = [] if bed is None else [f"- The bed tilted against the shoulders' plane ({1e3 * bed[1]:+.3f}, {1e3 * bed[2]:+.3f} mrad "
                                   "in x, y): Klipper's shoulders stand at one height above a level bed."]
    unheld = "\n".join(unheld_lines(projection, cal.effects) + tilt)
    start = projection.start_figures()
    where = "at the bottom of the robot's workspace" if bed is None else \
        f"the plane the probe fit estimated (tilt {1e3 * bed[1]:+.3f}, {1e3 * bed[2]:+.3f} mrad in x, y)"
    seen = "the robot's workspace (a probe calibration's touches see no height)" if is_probe_calibration(cal) \
        else "the box the calibration saw"
    return f"""# Klipper export of {settings.calibration or 'a calibration made in memory'}

Klipper's rotary Delta holds `shoulder_radius`, `shoulder_height` and per stepper `angle`,
`upper_arm_length`, `lower_arm_length` and `position_endstop` (its own `DELTA_CALIBRATE` saves
the first two, the angles and the endstops; this block also writes the arms). They were fitted to
the identified machine by least squares of the tool-point error over {len(projection.targets)} points of {seen}
(every {ROTARY_GRID_STEP_MM:g} mm in x and y, {ROTARY_GRID_STEP_MM / 2:g} mm in z; in Klipper's
frame {box} mm).

Klipper's frame: the bed (z = 0) {where},
{projection.bed_depth_mm:.3f} mm below the base frame's origin; x, y and the turn about z are the
calibration's base frame. The joints' zero is taken to be where Klipper homes (the endstops):
Klipper's steps count the arms' turn from there.

## The projection's residual over the volume (mm)

| Klipper's parameters | RMS | max |
|---|---|---|
| fitted (this block) | {projection.rms_mm:.4f} | {projection.max_mm:.4f} |
| read off the identified ones one by one (no fit) | {start[0]:.4f} | {start[1]:.4f} |

## What Klipper cannot hold (the accuracy given up is the residual above)

{unheld}
"""


def projection_box(cal: Calibration) -> tuple:
    """``(pose_min, pose_max)`` the projection's box: the box the calibration saw; a probe
    calibration's (its touches on the bed see no height) the robot's workspace (None, None)."""
    if is_probe_calibration(cal):
        return None, None
    return cal.validity["pose_min"], cal.validity["pose_max"]


def is_probe_calibration(cal: Calibration) -> bool:
    """Whether ``cal`` was fitted to probe data (``pipeline.probe``: its recording names the bed's
    mode and plane); both Klipper deliveries ask."""
    return "bed_mode" in cal.recording


def probe_bed(cal: Calibration) -> np.ndarray | None:
    """(3,) the bed plane a probe calibration estimated (``z`` mm, ``tilt_x``, ``tilt_y`` rad:
    Klipper's z = 0), None for any other calibration."""
    if not is_probe_calibration(cal):
        return None
    bed = cal.recording["bed"]
    return np.array([bed["z_mm"], bed["tilt_x_rad"], bed["tilt_y_rad"]], dtype=float)


def rotary_export(cal: Calibration, settings: ExportSettings) -> RotaryExport:
    """The texts of the rotary Delta's Klipper export of ``cal`` (module docstring)."""
    projection = project_onto_klipper_rotary(cal.robot, cal.theta, *projection_box(cal), bed=probe_bed(cal))
    message = (f"projection onto Klipper's parameters over {len(projection.targets)} points: RMS "
               f"{projection.rms_mm:.4f} mm, max {projection.max_mm:.4f} mm")
    summary = {"parameters": projection.parameters(), "bed_depth_mm": projection.bed_depth_mm,
               "residual": {"rms_mm": projection.rms_mm, "max_mm": projection.max_mm},
               "residual_unfitted": dict(zip(("rms_mm", "max_mm"), projection.start_figures())),
               "unheld": projection.unheld}
    return RotaryExport(save_config=rotary_save_config_text(projection),
                        notes=rotary_notes_text(cal, settings, projection), messages=[message], summary=summary)
