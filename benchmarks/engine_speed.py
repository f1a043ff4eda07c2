"""Speed of the calibration engine against the older per-robot identification modules.

Run by hand: ``python benchmarks/engine_speed.py [--poses 100] [--repeat 7] [--no-delta]``.

Hexapod (the paper's machine, Table 3 errors): ``N`` reachable workspace poses of the actual
machine, its leg lengths, measured poses = poses + sensor noise. Times, best of ``--repeat``,
measured in one run with the contenders interleaved (so that load from other processes hits
them alike):

* chain-wise: ``calib.engine.identify_chainwise(solver="gn")`` against the old per-leg method
  ``calib.identification.identify_paper`` (the hexapod paper's method);
* forward: ``calib.engine.identify_forward`` (Levenberg-Marquardt) against the old
  ``calib.identification.identify_forward``.

Delta (``--no-delta`` skips it): the engine's weighted chain-wise LM (the Delta paper's IKM) and
forward fit (FKM) against ``calib.delta_identification.identify_ikm`` / ``identify_fkm``.

The old modules are on their way out: when one cannot be imported, its rows show the engine's
timing only, and the output says so.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from calib.engine import identify_chainwise, identify_forward
from calib.noise import SensorNoise
from calib.robots import default_robot, reference_errors
from calib.workspace import reachable_poses

try:
    from calib.hexapod import paper_hexapod as old_paper_hexapod
    from calib.identification import identify_forward as old_identify_forward
    from calib.identification import identify_paper as old_identify_paper
except ImportError as exc:  # the old hexapod modules have been removed
    OLD_HEXAPOD, OLD_HEXAPOD_WHY = False, str(exc)
else:
    OLD_HEXAPOD, OLD_HEXAPOD_WHY = True, ""

try:
    from calib.delta_identification import identify_fkm as old_identify_fkm
    from calib.delta_identification import identify_ikm as old_identify_ikm
except ImportError as exc:  # the old Delta module has been removed
    OLD_DELTA, OLD_DELTA_WHY = False, str(exc)
else:
    OLD_DELTA, OLD_DELTA_WHY = True, ""


def best_of(contenders: dict, repeat: int) -> dict:
    """``{name: best seconds}`` over ``repeat`` rounds, each round running every contender once."""
    times = {name: [] for name in contenders}
    for _ in range(repeat):
        for name, fn in contenders.items():
            t = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t)
    return {name: min(ts) for name, ts in times.items()}


def data(robot, n: int, seed: int, noise: SensorNoise):
    """``(joints, measured)``: ``n`` poses of the reference machine, its joints, noisy poses."""
    theta = robot.table.nominal + reference_errors(robot, seed)
    poses = reachable_poses(robot, n, seed, theta=theta)
    joints = robot.inverse_kinematics(theta, poses)
    measured = poses + noise.sample(n, seed + 1, robot.pose_units)
    if noise.joint > 0:
        joints = joints + noise.sample_joints(n, robot.n_chains, seed + 2)
    return joints, measured


def row(task: str, t_new: float, t_old: float | None, agree: str) -> str:
    if t_old is None:
        return f"| {task} | {1e3 * t_new:.2f} ms | (old module missing) | | |"
    return f"| {task} | {1e3 * t_new:.2f} ms | {1e3 * t_old:.2f} ms | {t_new / t_old:.2f}x | {agree} |"


def hexapod_rows(n: int, seed: int, repeat: int, forward_repeat: int) -> list[str]:
    robot = default_robot("hexapod")
    noise = SensorNoise(0.001, 1e-6)  # the paper's +-1 um, uniform; 1 urad on the angles
    joints, measured = data(robot, n, seed, noise)
    chain = lambda: identify_chainwise(robot, joints, measured, noise, solver="gn")  # noqa: E731
    fwd = lambda: identify_forward(robot, joints, measured, noise)  # noqa: E731
    out = []
    if OLD_HEXAPOD:
        nominal = old_paper_hexapod()
        if not (np.array_equal(nominal.base_joints, robot.base_joints)
                and np.array_equal(nominal.platform_joints, robot.platform_joints) and not nominal.vector.any()):
            raise SystemExit("the old and new hexapods do not start from the same nominal machine")
        old_chain = lambda: old_identify_paper(nominal, joints, measured)  # noqa: E731
        old_fwd = lambda: old_identify_forward(nominal, joints, measured, noise)  # noqa: E731
        new, old = chain(), old_chain()
        agree = f"{np.abs(new.errors - old.estimate).max():.1e} mm, {new.iterations}/{old.iterations} it"
        t = best_of({"new": chain, "old": old_chain}, repeat)
        out.append(row(f"hexapod chain-wise GN (paper's method), {n} poses", t["new"], t["old"], agree))
        new, old = fwd(), old_fwd()
        agree = f"{np.abs(new.errors - old.estimate).max():.1e} mm, {new.iterations}/{old.iterations} jac"
        t = best_of({"new": fwd, "old": old_fwd}, forward_repeat)
        out.append(row(f"hexapod forward LM, {n} poses", t["new"], t["old"], agree))
    else:
        out.append(row(f"hexapod chain-wise GN (paper's method), {n} poses", best_of({"new": chain}, repeat)["new"], None, ""))
        out.append(row(f"hexapod forward LM, {n} poses", best_of({"new": fwd}, forward_repeat)["new"], None, ""))
    return out


def delta_rows(n: int, seed: int, repeat: int) -> list[str]:
    robot = default_robot("delta")
    sigma_mm, sigma_rad = 1e-3, float(np.deg2rad(0.01))
    noise = SensorNoise(sigma_mm, 0.0, "normal", joint=sigma_rad)
    joints, measured = data(robot, n, seed, noise)
    ikm = lambda: identify_chainwise(robot, joints, measured, noise, solver="lm", weighted=True)  # noqa: E731
    fkm = lambda: identify_forward(robot, joints, measured, noise)  # noqa: E731
    out = []
    if OLD_DELTA:
        nominal = robot.params(robot.table.nominal)
        old_ikm = lambda: old_identify_ikm(nominal, joints, measured, sigma_mm=sigma_mm, sigma_rad=sigma_rad)  # noqa: E731
        old_fkm = lambda: old_identify_fkm(nominal, joints, measured, sigma_mm=sigma_mm, sigma_rad=sigma_rad)  # noqa: E731
        for task, new_fn, old_fn in ((f"Delta chain-wise LM weighted (IKM), {n} poses", ikm, old_ikm),
                                     (f"Delta forward LM (FKM), {n} poses", fkm, old_fkm)):
            new, old = new_fn(), old_fn()
            agree = f"{np.abs(new.theta - old.estimate.to_vector()).max():.1e}"
            t = best_of({"new": new_fn, "old": old_fn}, repeat)
            out.append(row(task, t["new"], t["old"], agree))
    else:
        out.append(row(f"Delta chain-wise LM weighted (IKM), {n} poses", best_of({"new": ikm}, repeat)["new"], None, ""))
        out.append(row(f"Delta forward LM (FKM), {n} poses", best_of({"new": fkm}, repeat)["new"], None, ""))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--poses", type=int, default=100, help="measured poses (default 100)")
    ap.add_argument("--repeat", type=int, default=7, help="best of this many runs (default 7)")
    ap.add_argument("--forward-repeat", type=int, default=None,
                    help="best of this many runs for the forward fits (default: --repeat)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-delta", action="store_true", help="skip the Delta rows")
    a = ap.parse_args()
    forward_repeat = a.repeat if a.forward_repeat is None else a.forward_repeat
    print(f"best of {a.repeat} (forward fits: {forward_repeat}), old and new interleaved; "
          f"ratio = new / old (below 1: the engine is faster)")
    if not OLD_HEXAPOD:
        print(f"old hexapod identification not importable ({OLD_HEXAPOD_WHY}): engine timings only")
    if not OLD_DELTA and not a.no_delta:
        print(f"old Delta identification not importable ({OLD_DELTA_WHY}): engine timings only")
    print("| task | engine (new) | old module | ratio new/old | agreement (max abs diff, iterations) |")
    print("|---|---|---|---|---|")
    for line in hexapod_rows(a.poses, a.seed, a.repeat, forward_repeat):
        print(line)
    if not a.no_delta:
        for line in delta_rows(a.poses, a.seed, a.repeat):
            print(line)


if __name__ == "__main__":
    main()
