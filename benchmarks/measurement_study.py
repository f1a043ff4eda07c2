"""Instrument frame and position-only figures of docs/measurement.md, for every robot.

Kinematic simulation: the machine ``nominal + reference_errors(robot, 0)`` moves by its forward
kinematics; noise uniform within +-1 um on every position coordinate and +-1 urad on every angle.
60 calibration and 50 held-out poses drawn in the robot's full design workspace
(``--workspace paper`` for the default calibration workspace, 30 poses).

    PYTHONPATH=. python benchmarks/measurement_study.py [--workspace full|paper]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from calib.measurement import identify_measured, instrument_measurements
from calib.noise import SensorNoise
from calib.robots import ROBOTS, default_robot, reference_errors
from calib.workspace import reachable_poses

NOISE = SensorNoise(0.001, 1e-6)
FAR_FRAME = np.array([500 / np.sqrt(3)] * 3 + [0.5, -0.5, 0.5])
TARGETS = np.array([[60.0, 0.0, 20.0], [-30.0, 52.0, 20.0], [-30.0, -52.0, 20.0]])


def study(name: str, workspace: str) -> None:
    robot = default_robot(name)
    nominal = robot.table.nominal
    true = nominal + reference_errors(robot, 0)
    bounds = robot.full_workspace_bounds() if workspace == "full" else None
    n = 60 if workspace == "full" else 30
    cal, val = reachable_poses(robot, n, 1, bounds=bounds), reachable_poses(robot, 50, 2, bounds=bounds)
    q, qv = robot.inverse_kinematics(nominal, cal), robot.inverse_kinematics(nominal, val)
    poses, truev = robot.forward_kinematics(true, q, initial=cal), robot.forward_kinematics(true, qv, initial=val)
    rng = np.random.default_rng(7)
    noise = NOISE.sample(n, rng, robot.pose_units)

    def heldout_um(fit, targets, frame=None):
        pred = instrument_measurements(robot, robot.forward_kinematics(fit.result.theta, qv), fit.frame,
                                       targets if fit.targets is None else fit.targets)
        truth = instrument_measurements(robot, truev, frame, targets)
        if targets is None:
            return 1e3 * float(np.linalg.norm(pred[:, :3] - truth[:, :3], axis=1).mean())
        return 1e3 * float(np.linalg.norm((pred - truth).reshape(-1, 3), axis=1).mean())

    # 2. the far, turned frame
    t0 = time.perf_counter()
    far = identify_measured(robot, q, instrument_measurements(robot, poses, FAR_FRAME) + noise, NOISE)
    t_far = time.perf_counter() - t0
    exact = identify_measured(robot, q, instrument_measurements(robot, poses, FAR_FRAME), NOISE)
    base = identify_measured(robot, q, poses + noise, NOISE, frame="base")
    d = far.frame - exact.frame
    print(f"{name}: instrument frame 500 mm away, 0.5 rad on each axis ({n} poses, {workspace} workspace)")
    print(f"  frame error after the gauge: {np.abs(d[:3]).max() * 1e3:.2f} um, {np.abs(d[3:]).max():.2e} rad "
          f"(std {far.frame_std[:3].max() * 1e3:.2f} um, {far.frame_std[3:].max():.2e} rad); gauge directions "
          f"{len(far.gauge)}; {t_far:.1f} s")
    print(f"  held-out position error (noise-free truth): with frame {heldout_um(far, None, FAR_FRAME):.3f} um, "
          f"in the base frame {heldout_um(base, None):.3f} um")
    # 3. three targets, offsets estimated
    points = instrument_measurements(robot, poses, None, TARGETS) + NOISE.sample(n, rng, ("mm",) * 9)
    t0 = time.perf_counter()
    pos = identify_measured(robot, q, points, NOISE, targets=np.zeros((3, 3)))
    t_pos = time.perf_counter() - t0
    given = identify_measured(robot, q, points, NOISE, targets=TARGETS, estimate_targets=False, frame="base")
    far_pos = identify_measured(robot, q, instrument_measurements(robot, poses, FAR_FRAME, TARGETS)
                                + (points - instrument_measurements(robot, poses, None, TARGETS)), NOISE,
                                targets=np.zeros((3, 3)))
    e_full, e_pos = heldout_um(base, TARGETS), heldout_um(pos, TARGETS)
    print(f"  three targets: held-out target position error {e_pos:.3f} um (offsets estimated, {t_pos:.1f} s), "
          f"{heldout_um(given, TARGETS):.3f} um (offsets given), {heldout_um(far_pos, TARGETS, FAR_FRAME):.3f} um "
          f"(offsets and far frame estimated); full poses {e_full:.3f} um; ratio {e_pos / e_full:.2f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--workspace", choices=["full", "paper"], default="full")
    args = p.parse_args()
    for name in sorted(ROBOTS):
        study(name, args.workspace)


if __name__ == "__main__":
    main()
