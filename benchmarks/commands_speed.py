"""What ``Calibration.commands`` costs for 10,000 targets, next to the per-target root-finding a
user would write (issue 38: at most 0.1 s).

Per robot: a calibration with an identified geometry (errors drawn on the default free parameters,
0.05 mm and 5e-4 rad) and a dead band per joint (2-4 um, 2-4e-5 rad), made here; 10,000 targets
drawn in the workspace the identified machine reaches, commanded in order from the home pose.
``Calibration.commands`` (best of ``--repeat``; the fixed point of :mod:`calib.compensation`,
vectorised over the targets) against ``scipy.optimize.root`` (``hybr``) per target on the inverse
kinematics residual ``q + dq(q) - IK(theta, target)``, the dead band's direction from the last
command (the first ``--generic`` targets, once; its figure for 10,000 scaled from them). Both in
one run. The last columns check that both solve the same problem: each answer's largest residual
``|q + dq(q) - IK|`` (the dead band's direction that of the commanded move), and the targets where
the two answers differ: where a joint's move is smaller than its band, two commands put it there
(approached from above or from below), and each method may settle on either.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. python benchmarks/commands_speed.py [--repeat 7] [--generic 1000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import root

from calib.calibration import Calibration
from calib.effects import EFFECTS
from calib.effects.granularity import per_chain_form
from calib.effects.records import EffectRecord, FittedEffect
from calib.robots import ROBOTS, default_robot
from calib.workspace import reachable_poses
from timing import best_time, print_table_head

TARGETS = 10_000


def calibration(robot) -> tuple[Calibration, np.ndarray]:
    """``(a calibration with a geometry and a dead band per joint, its (C,) bands)``."""
    rng = np.random.default_rng(0)
    theta = robot.table.nominal.copy()
    free = robot.table.indices(robot.free_default)
    theta[free] += rng.uniform(-1.0, 1.0, free.size) * np.where(robot.table.angle_mask()[free], 5e-4, 0.05)
    band = np.linspace(2.0, 4.0, robot.n_chains) * (1e-3 if robot.joint_unit == "mm" else 1e-5)
    dead_band = FittedEffect(per_chain_form(EFFECTS["joint_friction"]), band, np.zeros(robot.n_chains))
    names = tuple(robot.free_default)
    cal = Calibration(robot=robot, theta=theta, std=np.zeros(robot.n_parameters), free=names,
                      covariance=np.zeros((len(names), len(names))), effects=(EffectRecord.from_fitted(dead_band, robot),))
    return cal, band


def generic(cal: Calibration, band: np.ndarray, targets: np.ndarray) -> tuple[np.ndarray, float]:
    """``(the commands by scipy.optimize.root per target, in order, as a user would write them,
    the largest residual)``."""
    robot, theta = cal.robot, cal.theta
    last = robot.inverse_kinematics(theta, robot.home_pose[None])[0]
    direction = np.zeros(robot.n_chains)
    out = np.empty((len(targets), robot.n_chains))
    worst = 0.0
    for j, x in enumerate(targets):
        needed = robot.inverse_kinematics(theta, x[None])[0]

        def residual(q):
            d = np.where(q > last, 1.0, np.where(q < last, -1.0, direction))
            return q - band * d - needed

        q = root(residual, needed, method="hybr", options={"xtol": 1e-13}).x
        worst = max(worst, float(np.max(np.abs(residual(q)))))
        direction = np.where(q > last, 1.0, np.where(q < last, -1.0, direction))
        out[j], last = q, q
    return out, worst


def case(name: str, repeat: int, n_generic: int) -> list[str]:
    robot = default_robot(name)
    cal, band = calibration(robot)
    targets = reachable_poses(robot, TARGETS, np.random.default_rng(1), theta=cal.theta)
    t_api, commands = best_time(lambda: cal.commands(targets), repeat)
    comp = cal.compensation(targets)
    ours = float(np.max(np.abs(comp.commands + comp.displacement - comp.geometric)))
    start = time.perf_counter()
    slow, theirs = generic(cal, band, targets[:n_generic])
    t_generic = (time.perf_counter() - start) * TARGETS / n_generic
    travel = float(np.max(np.ptp(robot.joint_limits(), axis=1)))
    differ = int(np.count_nonzero(np.max(np.abs(slow - commands[:n_generic]), axis=1) > 1e-9 * travel))
    unit = robot.joint_unit
    return [name, f"{1e3 * t_api:.1f}", "yes" if t_api <= 0.1 else "NO", f"{t_generic:.2f}", f"{t_generic / t_api:.0f}x",
            f"{ours:.1e} / {theirs:.1e} {unit}", f"{differ} of {n_generic}"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=7)
    p.add_argument("--generic", type=int, default=1000, help="targets the per-target root-finding is timed on")
    args = p.parse_args()
    print_table_head(f"{TARGETS} targets, geometry + a dead band per joint; Calibration.commands best of "
                     f"{args.repeat}, scipy.optimize.root per target timed on {args.generic} and scaled",
                     ["robot", "Calibration.commands, ms", "<= 0.1 s", "root per target, s (10,000)",
                      "root / commands", "largest residual, commands / root", "targets where they differ"])
    for name in sorted(ROBOTS):
        print("| " + " | ".join(case(name, args.repeat, args.generic)) + " |", flush=True)


if __name__ == "__main__":
    main()
