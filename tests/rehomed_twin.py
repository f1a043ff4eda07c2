"""The simulated twin of a hand-built hexapod over two days (issue 46): the MuJoCo machine of
tests/test_hand_built.py (1-3 mm geometry errors, one-sided leg strokes, a motion capture of 0.3 mm /
1.5 mrad in its own frame).

Day 1: a 100-pose level grid at the home height, commanded with the nominal inverse kinematics
(calibration rows, session ``day1``). Day 2: the machine re-homed (each leg's zero moved by 0.3 to
1.5 mm, random signs: at the reading ``l`` the leg is ``l + d`` long) and 60 poses of another pattern
(off the plane: other heights, tilts), captured in day 1's frame (session ``day2``, its frame named
``day1``), as validation rows unless told otherwise.

Independent truths: the zeros moved (the machine simulated at the commands plus them, the commands
recorded), the geometry injected.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.measurement import compose
from calib.noise import SensorNoise
from calib.robots.hexapod import Hexapod
from pipeline.formats.recording import Recording, write_recording
from pipeline.simulation.testbed import Testbed

#: The capture's noise: 0.3 mm on positions, 1.5 mrad on angles, one standard deviation.
CAPTURE_NOISE = SensorNoise(0.3, 1.5e-3, "normal")
#: The capture's frame relative to the base: 574.3 mm below, turned 2 degrees about x.
CAPTURE_FRAME = np.array([3.0, -2.0, -574.3, np.deg2rad(2.0), 0.0, 0.01])
#: Each leg's stroke as built, from fully retracted; home is this far above retracted.
STROKE_MM, HOME_ABOVE_RETRACTED_MM = 280.0, 100.0
#: How far a re-homing moves each leg's zero, mm (its size; the sign is drawn).
REHOMING_MM = (0.3, 1.5)
#: The rows of each day.
GRID_ROWS, DAY2_ROWS = 100, 60


def hand_built_hexapod() -> Hexapod:
    """The nominal hand-built hexapod: base joints on a 300 mm circle, platform joints on a 150 mm
    one, home 700 mm up, its legs' ranges one-sided about home."""
    a = np.deg2rad([-10, 10, 110, 130, 230, 250])
    base = np.stack([300 * np.cos(a), 300 * np.sin(a), np.zeros(6)], axis=1)
    b = np.deg2rad([-50, 50, 70, 170, 190, 290])
    platform = np.stack([150 * np.cos(b), 150 * np.sin(b), np.zeros(6)], axis=1)
    home = np.array([0.0, 0.0, 700.0, 0.0, 0.0, 0.0])
    legs = np.linalg.norm(platform + home[:3] - base, axis=1)
    low = legs - HOME_ABOVE_RETRACTED_MM
    return Hexapod(base, platform, legs, home_pose=home, joint_ranges=np.stack([low, low + STROKE_MM], axis=1))


def level_grid() -> np.ndarray:
    """(100, 6) a 10 x 10 grid, 240 mm square, at the home height, level."""
    xs = np.linspace(-120.0, 120.0, 10)
    X, Y = np.meshgrid(xs, xs)
    poses = np.zeros((GRID_ROWS, 6))
    poses[:, 0], poses[:, 1], poses[:, 2] = X.ravel(), Y.ravel(), 700.0
    return poses


def off_plane_runs(rng: np.random.Generator, n: int = DAY2_ROWS) -> np.ndarray:
    """(n, 6) poses off the grid: other heights and tilts."""
    poses = np.zeros((n, 6))
    poses[:, :2] = rng.uniform(-100.0, 100.0, (n, 2))
    poses[:, 2] = rng.uniform(650.0, 750.0, n)
    poses[:, 3:] = rng.uniform(-0.08, 0.08, (n, 3))
    return poses


@dataclass(frozen=True)
class Twin:
    """The two days' recording and its truths.

    Attributes:
        csv: the recording written (with its ``.json`` sidecar).
        recording: the same in memory.
        theta: (42,) the machine's true geometry.
        zero_moves: (6,) each leg's zero moved on day 2, mm (zeros when nothing moved).
    """

    csv: Path
    recording: Recording
    theta: np.ndarray
    zero_moves: np.ndarray


def rehomed_twin(folder: Path, *, moved: bool = True, seed: int = 46, day2_calibration_rows: int = 0,
                 name: str = "twin") -> Twin:
    """Simulate both days (MuJoCo, the noise seeded) and write ``folder/<name>.csv``.

    Args:
        moved: re-home the machine between the days (False: nothing moved).
        seed: seed of the errors, the zeros' moves, day 2's poses and the noise.
        day2_calibration_rows: the first rows of day 2 marked as calibration (a re-reference's
            handful); the others are validation.
    """
    robot = hand_built_hexapod()
    rng = np.random.default_rng(seed)
    errors = rng.uniform(1.0, 3.0, robot.n_parameters) * rng.choice([-1.0, 1.0], robot.n_parameters)
    theta = robot.table.nominal + errors
    moves = rng.uniform(*REHOMING_MM, 6) * rng.choice([-1.0, 1.0], 6) if moved else np.zeros(6)
    grid, day2 = level_grid(), off_plane_runs(rng)
    q1 = robot.inverse_kinematics(robot.table.nominal, grid)
    q2 = robot.inverse_kinematics(robot.table.nominal, day2)
    # the machine re-homed: where the controller reads q2 the leg is q2 + moves long
    bed = Testbed(robot, theta, noise=CAPTURE_NOISE, seed=seed)
    measured = bed.measure(np.vstack([q1, q2 + moves])).measured
    sets = np.array(["calibration"] * (GRID_ROWS + day2_calibration_rows)
                    + ["validation"] * (DAY2_ROWS - day2_calibration_rows))
    sessions = np.array(["day1"] * GRID_ROWS + ["day2"] * DAY2_ROWS)
    t_s = np.r_[np.arange(GRID_ROWS, dtype=float), np.arange(DAY2_ROWS, dtype=float)]
    rec = Recording(robot=robot, noise=CAPTURE_NOISE, t_s=t_s, joints=np.vstack([q1, q2]),
                    measured=compose(CAPTURE_FRAME, robot, measured), sets=sets, sessions=sessions,
                    session_info={"day2": {"measurement": {"frame": "day1"}}},
                    meta={"simulation": {"injected_errors": robot.table.to_dict(errors),
                                         "zero_moves_mm": moves.tolist()}})
    csv, _ = write_recording(Path(folder) / f"{name}.csv", rec)
    return Twin(csv, rec, theta, moves)
