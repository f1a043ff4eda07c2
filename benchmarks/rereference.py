"""Speed of a re-reference (issue 46: re-referencing 100 rows under 1 s of work): the hand-built
hexapod of tests/test_hand_built.py calibrated by ``pipeline.run --real`` on its 100-pose level
grid (kinematic, capture of 0.3 mm / 1.5 mrad in its own frame), then a re-homed session (each
leg's zero moved by 0.3 to 1.5 mm) of ``--rows`` rows re-referenced to it, one core:
``OPENBLAS_NUM_THREADS=1 PYTHONPATH=. taskset -c 0 python benchmarks/rereference.py``.

Timed, best of ``--repeat``: :func:`calib.rereference.rereference` on every row as calibration
rows (the shift's four models fitted and chosen, the held prediction's covariance, the new
calibration, the rows' errors before and after), and ``python -m pipeline.run --from`` in-process
(reading both files, writing the calibration).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from timing import best_time, print_table_head  # benchmarks/timing.py

from calib.calibration import Calibration
from calib.measurement import compose
from calib.rereference import held_frame, rereference
from pipeline.formats import read_recording
from pipeline.formats.recording import Recording, write_recording
from pipeline.run import run
from tests.test_hand_built import CAPTURE_FRAME, CAPTURE_NOISE, hand_built_hexapod, level_grid, off_plane_runs


def recordings(folder: Path, rows: int, seed: int) -> np.ndarray:
    """Day 1 (the grid) and day 2 (``rows`` off-plane rows, re-homed) written to ``folder``; the shift."""
    robot = hand_built_hexapod()
    rng = np.random.default_rng(seed)
    theta = robot.table.nominal + rng.uniform(1.0, 3.0, robot.n_parameters) * rng.choice([-1.0, 1.0], robot.n_parameters)
    shift = rng.uniform(0.3, 1.5, 6) * rng.choice([-1.0, 1.0], 6)
    for name, poses, d in (("day1", level_grid(), np.zeros(6)), ("day2", off_plane_runs(rng, rows), shift)):
        q = robot.inverse_kinematics(robot.table.nominal, poses)
        seen = robot.forward_kinematics(theta, q) + CAPTURE_NOISE.sample(len(q), seed, robot.pose_units)
        write_recording(folder / f"{name}.csv", Recording(robot=robot, noise=CAPTURE_NOISE, t_s=np.arange(len(q), dtype=float),
                                                          joints=q - d, measured=compose(CAPTURE_FRAME, robot, seen),
                                                          sets=np.array(["calibration"] * len(q)), meta={}))
    return shift


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rows", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=46)
    a = ap.parse_args(argv)
    folder = Path(tempfile.mkdtemp(prefix="rereference_"))
    shift = recordings(folder, a.rows, a.seed)
    run(["--real", str(folder / "day1.csv"), "--out", str(folder), "--quiet", "--name", "day1"])
    cal = Calibration.read(folder / "day1.calibration.json")
    rec = read_recording(folder / "day2.csv")
    t_lib, rr = best_time(lambda: rereference(cal, rec.joints, rec.measured, rec.noise, session="1",
                                              frame_session=held_frame(cal, "1"), t_s=rec.t_s), a.repeat)
    t_cmd, _ = best_time(lambda: run(["--real", str(folder / "day2.csv"), "--from", str(folder / "day1.calibration.json"),
                                      "--out", str(folder), "--quiet", "--name", "day2", "--overwrite"]), a.repeat)
    print_table_head(f"{a.rows} rows re-referenced, hand-built hexapod, seed {a.seed}",
                     ["rows", "model chosen", "largest shift error (sigma)", "rows' RMS after / floor",
                      "rereference() (s)", "pipeline.run --from (s)"])
    err = np.abs(rr.shift.zeros - shift) / rr.shift.zeros_std
    print(f"| {a.rows} | {rr.shift.chosen} | {err.max():.2f} | "
          f"{rr.calibration_after.position_mm['rms'] / rr.noise_floor['position_mm']:.3f} | {t_lib:.3f} | {t_cmd:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
