"""Cost of the cross-validated prediction error (run by hand).

``PYTHONPATH=. OPENBLAS_NUM_THREADS=1 python benchmarks/crossval_speed.py [--rows 60 120] [--repeat 3]``

Every registered robot, its reference errors (seed 0), ``rows`` reachable workspace poses of the
actual machine, measured with 1 um / 1 urad normal noise. Timed, best of ``--repeat``:
``calib.crossval.crossvalidate`` with the forward method (exact leave-one-out: one refit per
row) and the chain-wise one (10-fold), and the single fit of each method, for scale.
"""

from __future__ import annotations

import argparse

from timing import best_time  # benchmarks/timing.py

from calib.crossval import crossvalidate
from calib.engine import identify
from calib.noise import SensorNoise
from calib.robots import ROBOTS, default_robot, reference_errors
from calib.workspace import reachable_poses

NOISE = SensorNoise(1e-3, 1e-6, "normal")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rows", type=int, nargs="+", default=[60, 120])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print(f"{'robot':<8} {'rows':>4} {'method':<10} {'scheme':<14} {'one fit':>9} {'crossvalidate':>14} "
          f"{'position rms':>13}")
    for name in sorted(ROBOTS):
        robot = default_robot(name)
        theta = robot.table.nominal + reference_errors(robot, 0)
        for rows in args.rows:
            poses = reachable_poses(robot, rows, 1, theta=theta)
            joints = robot.inverse_kinematics(theta, poses)
            measured = poses + NOISE.sample(rows, 2, robot.pose_units)
            for method in ("forward", "chainwise"):
                fit_s, _ = best_time(lambda: identify(robot, joints, measured, NOISE, method=method), args.repeat)
                cv_s, cv = best_time(lambda: crossvalidate(robot, joints, measured, NOISE, method=method),
                                     args.repeat)
                print(f"{name:<8} {rows:>4} {method:<10} {cv.scheme:<14} {fit_s:8.4f}s {cv_s:13.3f}s "
                      f"{1e3 * cv.position_summary['rms']:10.3f} um")


if __name__ == "__main__":
    main()
