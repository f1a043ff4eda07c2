"""Gross rows named by calib.robust.find_gross_rows: rows named, held-out ratio, time per call.

    PYTHONPATH=. OPENBLAS_NUM_THREADS=1 python benchmarks/gross_rows.py

Every registered robot, the scenarios of tests/test_robust.py (kinematic simulation, 60 rows,
uniform noise +-1 um / +-1 urad): clean; 3 rows at z = 1000 mm, in the base frame and in a frame
0.5 m away turned 0.4 rad; 18 of 60 rows 50 times the noise off; and the issue's 12 of 40 rows
50 um off (positions only). Held-out: mean position error at 50 other poses, relative to the fit
of the clean file (``identify_measured``, frame "auto"). Time: best of three calls.
"""

import time

import numpy as np

from calib.measurement import identify_measured, instrument_measurements
from calib.noise import SensorNoise
from calib.paper import PAPER_NOISE_MM
from calib.robots import ROBOTS, default_robot, reference_errors
from calib.robust import find_gross_rows
from calib.workspace import reachable_poses

NOISE = SensorNoise(PAPER_NOISE_MM, 1e-6)
FAR_FRAME = np.array([500 / np.sqrt(3)] * 3 + [0.4 / np.sqrt(3)] * 3)


def experiment(robot, n, frame):
    nominal = robot.table.nominal
    true = nominal + reference_errors(robot, 0)
    bounds = robot.full_workspace_bounds()
    cal, val = reachable_poses(robot, n, 1, bounds=bounds), reachable_poses(robot, 50, 2, bounds=bounds)
    q, qv = robot.inverse_kinematics(nominal, cal), robot.inverse_kinematics(nominal, val)
    clean = instrument_measurements(robot, robot.forward_kinematics(true, q, initial=cal), frame) \
        + NOISE.sample(n, 3, robot.pose_units)
    truth = instrument_measurements(robot, robot.forward_kinematics(true, qv, initial=val), frame)
    return q, clean, qv, truth


def heldout(fit, qv, truth):
    return float(np.linalg.norm((fit.predict(qv) - truth)[:, :3], axis=1).mean())


def scenarios(robot):
    """(label, frame, n, spoil(clean, rng) -> (data, gross rows))."""
    half = np.where(robot.angle_pose_mask, NOISE.orientation_rad, NOISE.position_mm)

    def far(clean, rng):
        data = clean.copy()
        data[[5, 22, 47], 2] = 1000.0
        return data, np.array([5, 22, 47])

    def off(count, size_of):
        def spoil(clean, rng):
            rows = np.sort(rng.choice(len(clean), count, replace=False))
            u = rng.standard_normal((count, clean.shape[1]))
            u /= np.linalg.norm(u, axis=1, keepdims=True)
            data = clean.copy()
            data[rows] += size_of(u)
            return data, rows
        return spoil

    position = ~robot.angle_pose_mask
    return [("clean", None, 60, lambda c, r: (c, np.zeros(0, int))),
            ("3 rows z=1000 mm", None, 60, far),
            ("3 rows z=1000 mm, far frame", FAR_FRAME, 60, far),
            ("18 of 60 rows 50x noise", None, 60, off(18, lambda u: 50 * half * u)),
            ("12 of 40 rows 50 um", None, 40, off(12, lambda u: 0.05 * position * u / np.linalg.norm(
                u[:, position], axis=1, keepdims=True)))]


def main() -> None:
    print(f"{'robot':8} {'case':30} {'named':>8} {'wrong':>5} {'frame':>5} {'held-out':>8} {'fits':>4} {'time s':>6}")
    for name in sorted(ROBOTS):
        robot = default_robot(name)
        for label, frame, n, spoil in scenarios(robot):
            q, clean, qv, truth = experiment(robot, n, frame)
            data, gross = spoil(clean, np.random.default_rng(11))
            reference = heldout(identify_measured(robot, q, clean, NOISE), qv, truth)
            times = []
            for _ in range(3):
                t = time.perf_counter()
                found = find_gross_rows(robot, q, data, NOISE, seed=0)
                times.append(time.perf_counter() - t)
            named = len(set(found.gross) & set(gross.tolist()))
            wrong = len(set(found.gross) - set(gross.tolist()))
            ratio = heldout(found.fit, qv, truth) / reference if found.fit is not None else float("nan")
            print(f"{name:8} {label:30} {named:>3}/{gross.size:<4} {wrong:>5} {str(found.frame_estimated):>5} "
                  f"{ratio:>7.3f}x {found.fits:>4} {min(times):>6.2f}" + ("" if found.success else f"  {found.message}"))


if __name__ == "__main__":
    main()
