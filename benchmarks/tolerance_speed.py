"""What learning the tolerance from the rows costs, next to the fit it wraps (issue 37).

At 100 poses, per robot and method: the fit under the robot's default prior (best of ``--repeat``),
the estimate read from that fit (:func:`calib.evidence.tolerance_from_data`, best of ``--repeat``),
and their ratio ``(fit + estimate) / fit``: the estimate's cost as a multiple of the fit it wraps.
The run's whole learning step (the fit, the estimate and, where the rows show the default too
tight, the fit again under the learnt tolerance) is the last column, over one fit. Every ratio is
measured in one run. Rows: the kinematic model, errors drawn at 2 mm (a machine built by hand:
the default tolerance is contradicted and the run refits) on random reachable poses, 1 um / 1 urad
noise.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. python benchmarks/tolerance_speed.py [--repeat 7]
"""

from __future__ import annotations

import argparse

import numpy as np

from calib.engine import identify
from calib.evidence import tolerance_from_data
from calib.noise import SensorNoise
from calib.prior import ParameterPrior
from calib.robots import ROBOTS, default_robot
from calib.workspace import reachable_poses
from timing import best_time, print_table_head

POSES = 100
NOISE = SensorNoise(1e-3, 1e-6, "normal")


def case(name: str, method: str, repeat: int) -> list[str]:
    robot = default_robot(name)
    rng = np.random.default_rng(0)
    free = robot.table.indices(robot.free_default)
    ref = ParameterPrior.default(robot)
    errors = np.zeros(robot.n_parameters)
    errors[free] = np.where(np.array(robot.table.units)[free] == "mm", 2.0, 0.02) * rng.normal(size=free.size)
    theta = robot.table.nominal + errors
    poses = reachable_poses(robot, POSES, rng, theta=theta)
    joints = robot.inverse_kinematics(theta, poses)
    measured = poses + rng.normal(size=poses.shape) * NOISE.pose_std(robot.pose_units)
    fit = lambda prior: identify(robot, joints, measured, NOISE, method=method, prior=prior)  # noqa: E731
    t_fit, result = best_time(lambda: fit(ref), repeat)
    t_est, est = best_time(lambda: tolerance_from_data(result), repeat)
    t_refit, _ = best_time(lambda: fit(est.widened_prior()), repeat)
    step = t_fit + t_est + (t_refit if est.wider else 0.0)
    return [name, method, f"{1e3 * t_fit:.2f}", f"{1e3 * t_est:.2f}", f"{(t_fit + t_est) / t_fit:.2f}",
            est.tolerance_words(), f"{step / t_fit:.2f}"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=7)
    args = p.parse_args()
    print_table_head(f"{POSES} poses, best of {args.repeat}",
                     ["robot", "method", "fit, ms", "estimate, ms", "(fit + estimate) / fit", "learnt",
                      "learning step / fit"])
    for name in sorted(ROBOTS):
        for method in ("forward", "chainwise"):
            print("| " + " | ".join(case(name, method, args.repeat)) + " |")


if __name__ == "__main__":
    main()
