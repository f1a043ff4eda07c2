"""Speed of the calibration engine (run by hand).

``python benchmarks/engine_speed.py [--poses 100] [--repeat 7] [--kinematics-poses 10000] [--no-delta]``

Hexapod (the paper's machine, Table 3 errors): ``N`` reachable workspace poses of the actual
machine, its leg lengths, measured poses = poses + the paper's sensor noise (+-1 um, uniform;
1 urad on the angles). Timed, best of ``--repeat``:

* chain-wise: ``calib.engine.identify_chainwise(solver="gn")`` (the hexapod paper's per-leg
  method);
* forward: ``calib.engine.identify_forward`` (Levenberg-Marquardt, all 42 parameters through the
  forward kinematics);
* the inverse kinematics and the (Newton) forward kinematics of ``--kinematics-poses`` poses.

Delta (``--no-delta`` skips it), 1 um and 0.01 deg noise: the weighted chain-wise LM (the Delta
paper's IKM) and the forward fit (FKM).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from calib.engine import identify_chainwise, identify_forward
from calib.noise import SensorNoise
from calib.robots import default_robot, reference_errors
from calib.workspace import reachable_poses


def best_of(fn, repeat: int) -> float:
    """Best wall time of ``repeat`` calls of ``fn``, seconds."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def data(robot, n: int, seed: int, noise: SensorNoise):
    """``(theta, joints, measured)``: the reference machine, its joints at ``n`` reachable poses, noisy poses."""
    theta = robot.table.nominal + reference_errors(robot, seed)
    poses = reachable_poses(robot, n, seed, theta=theta)
    joints = robot.inverse_kinematics(theta, poses)
    measured = poses + noise.sample(n, seed + 1, robot.pose_units)
    if noise.joint > 0:
        joints = joints + noise.sample_joints(n, robot.n_chains, seed + 2)
    return theta, joints, measured


def row(task: str, seconds: float, result=None, counted: str = "Jacobian evaluations") -> str:
    detail = "" if result is None else \
        f"{result.iterations} {counted}; {'converged' if result.success else 'not converged'}"
    return f"| {task} | {1e3 * seconds:.2f} ms | {detail} |"


def hexapod_rows(n: int, seed: int, repeat: int, n_kin: int) -> list[str]:
    robot = default_robot("hexapod")
    noise = SensorNoise(0.001, 1e-6)
    theta, joints, measured = data(robot, n, seed, noise)
    chain = lambda: identify_chainwise(robot, joints, measured, noise, solver="gn")  # noqa: E731
    fwd = lambda: identify_forward(robot, joints, measured, noise)  # noqa: E731
    poses = reachable_poses(robot, n_kin, seed + 3, theta=theta)
    lengths = robot.inverse_kinematics(theta, poses)
    return [
        row(f"hexapod chain-wise GN (paper's method), {n} poses", best_of(chain, repeat), chain(), "iterations"),
        row(f"hexapod forward LM, {n} poses", best_of(fwd, repeat), fwd()),
        row(f"hexapod inverse kinematics, {n_kin:,} poses", best_of(lambda: robot.inverse_kinematics(theta, poses), repeat)),
        row(f"hexapod forward kinematics (Newton), {n_kin:,} poses",
            best_of(lambda: robot.forward_kinematics(theta, lengths), repeat)),
    ]


def delta_rows(n: int, seed: int, repeat: int) -> list[str]:
    robot = default_robot("delta")
    noise = SensorNoise(1e-3, 0.0, "normal", joint=float(np.deg2rad(0.01)))
    _, joints, measured = data(robot, n, seed, noise)
    ikm = lambda: identify_chainwise(robot, joints, measured, noise, solver="lm", weighted=True)  # noqa: E731
    fkm = lambda: identify_forward(robot, joints, measured, noise)  # noqa: E731
    return [row(f"Delta chain-wise LM weighted (IKM), {n} poses", best_of(ikm, repeat), ikm()),
            row(f"Delta forward LM (FKM), {n} poses", best_of(fkm, repeat), fkm())]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--poses", type=int, default=100, help="measured poses (default 100)")
    ap.add_argument("--repeat", type=int, default=7, help="best of this many runs (default 7)")
    ap.add_argument("--kinematics-poses", type=int, default=10_000,
                    help="poses of the hexapod IK/FK timing (default 10000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-delta", action="store_true", help="skip the Delta rows")
    a = ap.parse_args()
    print(f"best of {a.repeat}")
    print("| task | time | result |")
    print("|---|---|---|")
    for line in hexapod_rows(a.poses, a.seed, a.repeat, a.kinematics_poses):
        print(line)
    if not a.no_delta:
        for line in delta_rows(a.poses, a.seed, a.repeat):
            print(line)


if __name__ == "__main__":
    main()
