"""Speed of the calibration engine (run by hand).

``python benchmarks/engine_speed.py [--poses 100] [--repeat 7] [--kinematics-poses 10000] [--no-delta]
[--baseline-ref REV [--rounds 3]]``

Hexapod (the paper's machine, Table 3 errors): ``N`` reachable workspace poses of the actual
machine, its leg lengths, measured poses = poses + the paper's sensor noise (+-1 um, uniform;
1 urad on the angles). Timed, best of ``--repeat``:

* chain-wise: ``calib.engine.identify_chainwise(solver="gn")`` (the hexapod paper's per-leg
  method), and the robot calls it makes timed alone (a closure-and-Jacobians evaluation at the
  start and after each step taken, the forward kinematics of the result from the measured
  poses less one Newton step, where the fit starts it): the floor of the fit, whatever the
  engine does around them;
* forward: ``calib.engine.identify_forward`` (all 42 parameters through the forward kinematics:
  Gauss-Newton with the poses Newton-stepped along, Levenberg-Marquardt as its fallback);
* both fits with the robot's default prior (``prior=ParameterPrior.default(robot)``, maximum
  a posteriori), timed in the same run, and their ratio to the plain fits (the issue's budget:
  at most 1.2x at 100 poses);
* the generic fit the engine replaces, timed in the same run: ``scipy.optimize.least_squares``
  (its default trust-region solver) with a finite-difference Jacobian (``jac="2-point"``) on the
  same whitened forward residual (the engine's forward kinematics, warm-started from the
  measured poses), and its ratio to the forward identification; the largest difference between
  the two answers is printed;
* the inverse kinematics and the (Newton) forward kinematics of ``--kinematics-poses`` poses,
  started from the home pose (cold) and from the poses plus 1 um / 1 urad (warm: the engine's
  case, the measured poses are the start).

Delta (``--no-delta`` skips it), 1 um and 0.01 deg noise: the weighted chain-wise LM (the Delta
paper's IKM) and the forward fit (FKM).

``--baseline-ref REV``: the same timings of the engine at git revision ``REV`` (a clean export,
``git archive``), this tree's and the baseline's run in child processes one after the other,
``--rounds`` times, each figure the best over the rounds; prints both and their ratio (the
speed-up of this tree, measured in one run on the same machine).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from scipy.optimize import least_squares

from calib.engine import identify_chainwise, identify_forward
from calib.noise import SensorNoise
from calib.prior import ParameterPrior
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


def generic_forward_fit(robot, joints, measured, noise):
    """The generic fit: scipy's least_squares, finite-difference Jacobian, same residual."""
    w = 1.0 / noise.pose_std(robot.pose_units)
    free = robot.table.indices(robot.free_default)
    theta0 = robot.table.nominal.copy()

    def residual(x):
        th = theta0.copy()
        th[free] = x
        return ((measured - robot.forward_kinematics(th, joints, initial=measured)) * w).ravel()

    # Tolerances tight enough that it reaches the same minimum as the engine.
    return least_squares(residual, theta0[free], jac="2-point", xtol=1e-12, ftol=1e-12, gtol=1e-12)


def hexapod_rows(n: int, seed: int, repeat: int, n_kin: int) -> list[str]:
    robot = default_robot("hexapod")
    noise = SensorNoise(0.001, 1e-6)
    theta, joints, measured = data(robot, n, seed, noise)
    chain = lambda: identify_chainwise(robot, joints, measured, noise, solver="gn")  # noqa: E731
    fwd = lambda: identify_forward(robot, joints, measured, noise)  # noqa: E731
    generic = lambda: generic_forward_fit(robot, joints, measured, noise)  # noqa: E731
    poses = reachable_poses(robot, n_kin, seed + 3, theta=theta)
    lengths = robot.inverse_kinematics(theta, poses)
    near = poses + SensorNoise(0.001, 1e-6).sample(n_kin, seed + 4, robot.pose_units)
    t_fwd = best_of(fwd, repeat)
    prior = ParameterPrior.default(robot)
    chain_map = lambda: identify_chainwise(robot, joints, measured, noise, solver="gn", prior=prior)  # noqa: E731
    fwd_map = lambda: identify_forward(robot, joints, measured, noise, prior=prior)  # noqa: E731
    t_chain_map, t_fwd_map = best_of(chain_map, repeat), best_of(fwd_map, repeat)
    t_generic = best_of(generic, max(1, repeat // 3))
    fit, base = fwd(), generic()
    free = robot.table.indices(robot.free_default)
    diff = np.max(np.abs(fit.theta[free] - base.x))
    # The robot's own calls a chain-wise fit makes, timed alone: a closure-and-Jacobians evaluation
    # at the start and after each step taken, and the forward kinematics of the result from where
    # the fit starts it (the measured poses less one Newton step, which the last evaluation gives).
    # Whatever the engine does around them, the fit cannot take less.
    res_chain = chain()
    t_chain = best_of(chain, repeat)
    evaluations = res_chain.iterations + 1
    t_eval = best_of(lambda: robot.closure_with_jacobians(res_chain.theta, joints, measured), repeat)
    closure, jac = robot.closure_with_jacobians(res_chain.theta, joints, measured)
    start = measured - np.linalg.solve(jac.pose, closure[..., None])[..., 0]
    t_fk = best_of(lambda: robot.forward_kinematics(res_chain.theta, joints, initial=start), repeat)
    t_floor = evaluations * t_eval + t_fk
    t_cold = best_of(lambda: robot.forward_kinematics(theta, lengths), repeat)
    t_warm = best_of(lambda: robot.forward_kinematics(theta, lengths, initial=near), repeat)
    return [
        row(f"hexapod chain-wise GN (paper's method), {n} poses", t_chain, res_chain, "iterations"),
        f"| its robot calls alone: {evaluations} closure-and-Jacobians evaluations ({1e3 * t_eval:.3f} ms each) "
        f"+ the forward kinematics of the result ({1e3 * t_fk:.3f} ms) | {1e3 * t_floor:.2f} ms | "
        f"{100 * t_floor / t_chain:.0f}% of the chain-wise fit; the rest, "
        f"{1e3 * (t_chain - t_floor):.2f} ms, is the engine's per-{robot.chain_word} steps, stopping rule and "
        f"covariance |",
        row(f"hexapod forward identification, {n} poses", t_fwd, fit, "iterations"),
        row(f"hexapod chain-wise GN with the default prior, {n} poses", t_chain_map, chain_map(), "iterations")[:-2]
        + f"; {t_chain_map / t_chain:.2f}x the plain chain-wise fit |",
        row(f"hexapod forward identification with the default prior, {n} poses", t_fwd_map, fwd_map(),
            "iterations")[:-2] + f"; {t_fwd_map / t_fwd:.2f}x the plain forward fit |",
        f"| generic scipy fit (least_squares, jac='2-point'), {n} poses | {1e3 * t_generic:.2f} ms | "
        f"{base.nfev} evaluations + {base.nfev and base.njev or 0} finite-difference Jacobians; forward "
        f"is {t_generic / t_fwd:.0f}x faster; answers differ by {diff:.2g} mm at most |",
        row(f"hexapod inverse kinematics, {n_kin:,} poses", best_of(lambda: robot.inverse_kinematics(theta, poses), repeat)),
        f"| hexapod forward kinematics (Newton) from the home pose, {n_kin:,} poses | {1e3 * t_cold:.2f} ms | "
        f"{1e6 * t_cold / n_kin:.2f} us a pose |",
        f"| hexapod forward kinematics (Newton) from the poses + 1 um / 1 urad, {n_kin:,} poses | "
        f"{1e3 * t_warm:.2f} ms | {1e6 * t_warm / n_kin:.2f} us a pose |",
    ]


def delta_rows(n: int, seed: int, repeat: int) -> list[str]:
    robot = default_robot("delta")
    noise = SensorNoise(1e-3, 0.0, "normal", joint=float(np.deg2rad(0.01)))
    _, joints, measured = data(robot, n, seed, noise)
    ikm = lambda: identify_chainwise(robot, joints, measured, noise, solver="lm", weighted=True)  # noqa: E731
    fkm = lambda: identify_forward(robot, joints, measured, noise)  # noqa: E731
    return [row(f"Delta chain-wise LM weighted (IKM), {n} poses", best_of(ikm, repeat), ikm()),
            row(f"Delta forward identification (FKM), {n} poses", best_of(fkm, repeat), fkm(), "iterations")]


def compare_with(ref: str, args, rounds: int) -> None:
    """This tree's table and the baseline's, alternated ``rounds`` times; best of each row and the ratio."""
    from machine_speed import ROOT, child_env, export_revision, load

    here = Path(__file__).resolve()
    own = ["--poses", str(args.poses), "--repeat", str(args.repeat), "--kinematics-poses",
           str(args.kinematics_poses), "--seed", str(args.seed)] + (["--no-delta"] if args.no_delta else [])
    best: dict[str, dict[str, float]] = {"baseline": {}, "this tree": {}}
    print(f"engine_speed: this tree and {ref}, alternated, {rounds} rounds of best of {args.repeat}; {load()}")
    with tempfile.TemporaryDirectory() as tmp:
        base = export_revision(ref, Path(tmp))
        for _ in range(rounds):
            for label, tree in (("baseline", base), ("this tree", ROOT)):
                out = subprocess.run([sys.executable, str(here)] + own, cwd=tree, env=child_env(tree),
                                     capture_output=True, text=True, check=True).stdout
                for line in out.splitlines():
                    m = re.match(r"\| (.+?) \| ([0-9.]+) ms \|", line)
                    if m:
                        # an older revision's row name (its forward fit was Levenberg-Marquardt alone)
                        task = m.group(1).replace("forward LM", "forward identification")
                        best[label][task] = min(best[label].get(task, float("inf")), float(m.group(2)))
    print(f"| task | {ref} | this tree | speed-up |\n|---|---|---|---|")
    for task, t in best["this tree"].items():
        b = best["baseline"].get(task)
        print(f"| {task} | {'-' if b is None else f'{b:.2f} ms'} | {t:.2f} ms | "
              f"{'-' if b is None else f'{b / t:.2f}x'} |")
    print(load())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--poses", type=int, default=100, help="measured poses (default 100)")
    ap.add_argument("--repeat", type=int, default=7, help="best of this many runs (default 7)")
    ap.add_argument("--kinematics-poses", type=int, default=10_000,
                    help="poses of the hexapod IK/FK timing (default 10000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-delta", action="store_true", help="skip the Delta rows")
    ap.add_argument("--baseline-ref", default=None, help="also time the engine of this git revision")
    ap.add_argument("--rounds", type=int, default=3, help="alternations with --baseline-ref (default 3)")
    a = ap.parse_args()
    if a.baseline_ref:
        compare_with(a.baseline_ref, a, a.rounds)
        return
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
