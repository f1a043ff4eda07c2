"""A rotary Delta's [delta_calibrate] touches simulated on its kinematic model with known errors
(tests/test_probe_rotary.py; tests/data/klipper/rotary_delta_probed.cfg is its output).

The model, not the MuJoCo Delta (mjcf/delta.py): that machine is built from the Delta paper's
geometry and its tool point is the plate's centre, not a Klipper rotary config's; the reduced
kinematics of the config's own Delta (calib.klipper_rotary.delta_from_klipper_rotary) with errors
injected is the machine the touches are made on, so what the fit recovers is compared with what
was injected and nothing else.

Errors: every parameter the fit frees (all but the gauge's Lay1..3) drawn from the Delta's
tolerances (seeded), the bed 0.3 mm off its nominal height and tilted by BED_TILT_RAD. Touches: Klipper's probe
points (the centre and rings at a third, two thirds and all of [delta_calibrate] radius), the tool
at the probe's z offset above the true bed plus 0.01 mm noise; stable positions the true arms'
turns below their endstops over the step angles, written %.3f as SAVE_CONFIG does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.klipper_rotary import delta_from_klipper_rotary
from calib.prior import ParameterPrior
from calib.probe import nominal_bed
from pipeline.formats.klipper import klipper_printer, read_klipper_config

DATA = Path(__file__).parent / "data" / "klipper"
BASE_CONFIG = DATA / "rotary_delta_printer.cfg"
PROBED_CONFIG = DATA / "rotary_delta_probed.cfg"
#: The probe's z offset (Klipper's heightN), the touches' noise and the bed's error (mm).
Z_OFFSET_MM, NOISE_MM, BED_OFFSET_MM = 0.1, 0.01, 0.3
SEED = 49
#: The bed's slopes along x and y (rad): 0.1 mm and 0.05 mm over 50 mm.
BED_TILT_RAD = (0.002, -0.001)
#: Points per ring of the probe pattern (centre, a third, two thirds, all of the radius).
RING_POINTS = (1, 6, 12, 18)


def base_robot():
    """The Delta of the base config as Klipper runs it (its SAVE_CONFIG values)."""
    m = klipper_printer(read_klipper_config(BASE_CONFIG)).machine
    return delta_from_klipper_rotary(m.shoulder_radius_mm, m.shoulder_height_mm, m.angles_rad,
                                     m.upper_arm_lengths_mm, m.lower_arm_lengths_mm, m.endstops_mm), m


def truth(robot, seed: int = SEED) -> tuple[np.ndarray, np.ndarray]:
    """``(theta, bed)`` of the simulated machine (module docstring)."""
    rng = np.random.default_rng(seed)
    theta = robot.table.nominal + rng.normal(size=robot.n_parameters) * ParameterPrior.default(robot).std
    held = robot.table.indices(robot.gauge_fixed)
    theta[held] = robot.table.nominal[held]
    return theta, nominal_bed(robot) + [BED_OFFSET_MM, *BED_TILT_RAD]


def probe_points(radius_mm: float) -> np.ndarray:
    """(N, 2) Klipper-style probe points: the centre and rings out to ``radius_mm``."""
    rings = [np.zeros((1, 2))]
    for k, n in enumerate(RING_POINTS[1:], start=1):
        a = np.arange(n) * 2 * np.pi / n
        rings.append(radius_mm * k / (len(RING_POINTS) - 1) * np.column_stack([np.cos(a), np.sin(a)]))
    return np.concatenate(rings)


def touch_joints(robot, theta, bed, xy, rng, heights=(0.0,)) -> tuple[np.ndarray, np.ndarray]:
    """``(joints (N, 3), z (N,))``: the true machine's joints with the tool at ``Z_OFFSET_MM`` (+
    each of ``heights``) above the bed at ``xy``, plus the noise, and the heights Klipper records."""
    z = np.concatenate([np.full(len(xy), Z_OFFSET_MM + h) for h in heights])
    pts = np.column_stack([np.tile(xy, (len(heights), 1)), z])
    pts[:, 2] += bed[0] + pts[:, :2] @ bed[1:] + rng.normal(0.0, NOISE_MM, len(pts))
    return robot.inverse_kinematics(theta, pts), z


def probed_config_text(seed: int = SEED) -> str:
    """The base config with a [delta_calibrate] block of the simulated touches in its SAVE_CONFIG."""
    robot, m = base_robot()
    theta, bed = truth(robot, seed)
    text = BASE_CONFIG.read_text()
    radius = float(klipper_printer(read_klipper_config(BASE_CONFIG)).probe.radius_mm)
    joints, z = touch_joints(robot, theta, bed, probe_points(radius), np.random.default_rng(seed + 1))
    steps = joints / np.asarray(m.step_angles_rad)
    lines = [f"#*# height{i} = {h:.6f}\n#*# height{i}_pos = {s[0]:.3f},{s[1]:.3f},{s[2]:.3f}"
             for i, (h, s) in enumerate(zip(z, steps))]
    head = text[:text.index("#*# [delta_calibrate]")]
    return (head.replace("# A rotary Delta's Klipper config, written by hand for tests/test_klipper_format.py",
                         "# Written by tests/rotary_probe_simulation.py (probed_config_text) from\n"
                         "# tests/data/klipper/rotary_delta_printer.cfg")
            + "#*# [delta_calibrate]\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    PROBED_CONFIG.write_text(probed_config_text())
