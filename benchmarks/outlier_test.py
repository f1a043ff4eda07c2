"""The outlier test on 200 hexapod poses: time, gross rows found, model misfit reported.

    PYTHONPATH=. OPENBLAS_NUM_THREADS=1 python benchmarks/outlier_test.py

Table 3 machine, 200 random workspace poses, normal noise 1 um / 1 urad declared and drawn.
Cases: clean; three gross rows (20 um); an unmodelled sag 20 times the noise; noise 100 times
the declared. Prints the best of three timings of ``calib.outliers.find_outliers``.
"""

import time

import numpy as np

from calib import paper
from calib.noise import SensorNoise
from calib.outliers import find_outliers
from calib.robots import paper_hexapod
from calib.workspace import reachable_poses


def main() -> None:
    robot = paper_hexapod()
    nominal = robot.table.nominal
    actual = nominal + paper.TABLE3_ERRORS.ravel()
    targets = reachable_poses(robot, 200, np.random.default_rng(3))
    joints = robot.inverse_kinematics(nominal, targets)
    exact = robot.forward_kinematics(actual, joints, initial=targets)
    noise = SensorNoise(0.001, 1e-6, "normal")
    clean = exact + noise.sample(200, 1)
    gross = clean.copy()
    gross[[5, 50, 150], :3] += [0.02, -0.02, 0.0]
    r2 = targets[:, 0] ** 2 + targets[:, 1] ** 2
    sag = clean.copy()
    sag[:, 2] += 20 * 0.001 * (2 * r2 / r2.max() - 1)
    loud = exact + SensorNoise(0.1, 1e-4, "normal").sample(200, 1)
    for name, data in [("clean", clean), ("3 gross rows", gross), ("misfit, sag 20x noise", sag),
                       ("noise 100x declared", loud)]:
        times = []
        for _ in range(3):
            t = time.perf_counter()
            report = find_outliers(robot, joints, data, noise)
            times.append(time.perf_counter() - t)
        print(f"{name:<24} {min(times):6.3f} s  flagged {list(report.flagged)}  misfit {report.misfit}")
        print(f"{'':<24} {report.verdict}")


if __name__ == "__main__":
    main()
