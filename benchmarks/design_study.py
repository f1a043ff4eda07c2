"""Figures of docs/observability.md (observability, efficiency, optimal poses); prints markdown tables.

Usage::

    python benchmarks/design_study.py [--robot hexapod] [--trials 1000] [--seed 0] [--workers 2]
        [--scheduler ADDRESS] [--out FILE.json] [--overwrite]

Noise: Gaussian, standard deviation 0.001 mm on each position coordinate and 1e-6 rad on each
angle (declared = simulated). Machine: the robot's default machine with its reference errors
(the hexapod paper's Table 2 geometry with Table 3 errors) or, for a robot without any, random
errors (:func:`pipeline.workflows.study.true_errors`), simulated by the robot's forward kinematics (no
MuJoCo).

1. Efficiency: Monte Carlo of the forward (ML) and the chain-wise method (the hexapod paper's
   per-leg least squares); per-parameter MSE / CRB (CRB at the true parameters and reached poses).
2. 10 poses: the robot's reference poses (the hexapod paper's Table 4) vs D-/E-optimal designs
   in the full and in the default workspace: CRB parameter RMS (linearised, noise-free
   computation), Monte Carlo parameter error RMS and held-out position error (noisy, measured),
   held-out poses drawn in both workspaces.
3. Number of poses for a held-out position error RMS of 1 um (and 0.5 um): designed vs random
   feasible poses in the same workspace (linearised prediction from the CRB, checked by Monte
   Carlo at the reported N).

The designs, the points of the curves of 3. (a design, or five random draws, per number of poses
and workspace) and the Monte Carlo trials run as tasks of :mod:`pipeline.executor`, on one local
Dask cluster of ``--workers`` processes (default the cores; ``--workers 1``: here) or on
``--scheduler ADDRESS``; the figures are the same whatever runs them.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calib.design import minimum_poses, robot_workspace, sample_feasible_poses, select_poses  # noqa: E402
from calib.noise import SensorNoise  # noqa: E402
from calib.observability import analyze_observability, parameter_scale, pose_uncertainty  # noqa: E402
from calib.robots import default_robot, reference_poses  # noqa: E402
from pipeline.workflows.design import DEFAULT_CANDIDATES, design_start  # noqa: E402
from pipeline.cli import add_executor_arguments
from pipeline.execution import dask_client, run_tasks, runs_here  # noqa: E402
from pipeline.formats import atomic_write  # noqa: E402
from pipeline.workflows.study import compensation_errors, monte_carlo, true_errors  # noqa: E402

NOISE = SensorNoise(position_mm=1e-3, orientation_rad=1e-6, distribution="normal")


def log(msg):
    print(msg, file=sys.stderr, flush=True)


class Bench:
    """The robot, its true parameters and the figures of one pose set."""

    def __init__(self, name: str, seed: int):
        self.robot = default_robot(name)
        self.nominal = self.robot.table.nominal
        kind = "reference" if reference_poses(self.robot) is not None else "random"
        self.theta = self.nominal + true_errors(self.robot, kind, seed)

    def heldout_errors(self, errors: np.ndarray, heldout: np.ndarray) -> dict:
        """Exact (nonlinear) held-out position errors of the compensated machine, per trial
        (``errors``: (T, F) identified minus true free parameters)."""
        idx = self.robot.table.indices(self.robot.free_default)
        rms, mean = [], []
        for e in errors:
            identified = self.theta.copy()
            identified[idx] += e
            pos, _ = compensation_errors(self.robot, self.theta, identified, heldout)
            rms.append(np.sqrt(np.mean(pos ** 2)))
            mean.append(pos.mean())
        rms, mean = np.array(rms), np.array(mean)
        return {"rms_um": float(np.sqrt(np.mean(rms ** 2)) * 1e3), "mean_um": float(mean.mean() * 1e3)}

    def predicted_heldout_rms_um(self, poses: np.ndarray, heldout: np.ndarray) -> float:
        """Linearised held-out position error RMS at the CRB of a pose set, um."""
        a = analyze_observability(self.robot, self.nominal, poses, NOISE)
        pu = pose_uncertainty(self.robot, self.nominal, heldout, a.parameter_covariance())
        return float(np.sqrt(np.mean(pu.position_rms_mm ** 2)) * 1e3)

    def run_mc(self, poses, trials, seed, workers, methods, client=None):
        commanded = self.robot.inverse_kinematics(self.nominal, poses)
        reached = self.robot.forward_kinematics(self.theta, commanded, initial=poses)
        crb = analyze_observability(self.robot, self.theta, reached, NOISE, joints=commanded)
        t0 = time.perf_counter()
        r = monte_carlo(self.robot, self.theta, commanded, NOISE, trials, seed, methods=methods, workers=workers,
                        initial=poses, client=client)
        return r, crb, time.perf_counter() - t0


def curve_point(job: dict) -> tuple:
    """A point of the curves of 3. (a task): ``(designed, random)`` predicted held-out position
    error RMS (um) of ``n`` poses in a workspace: the D-optimal design of ``n`` of the candidates
    (None above 100 poses) and the median of 5 seeded random feasible draws."""
    bench = Bench(job["robot"], job["seed"])
    robot, nominal, held, n = bench.robot, bench.nominal, job["held"], job["n"]
    designed = None
    if n <= 100:
        d = select_poses(robot, nominal, job["candidates"], n, NOISE, criterion="d").poses
        designed = bench.predicted_heldout_rms_um(d, held)
    vals = [bench.predicted_heldout_rms_um(sample_feasible_poses(robot, nominal, job["workspace"], n,
                                                                 [job["seed"], 5, k]), held) for k in range(5)]
    return designed, float(np.median(vals))


@contextlib.contextmanager
def executor(workers, scheduler):
    """One Dask client for every job of the study (None: tasks run here)."""
    if runs_here(workers, scheduler):
        yield None
    else:
        with dask_client(workers, scheduler) as client:
            yield client


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default="hexapod")
    p.add_argument("--trials", type=int, default=1000)
    p.add_argument("--seed", type=int, default=0)
    add_executor_arguments(p)
    p.add_argument("--out", default=None)
    p.add_argument("--overwrite", action="store_true")
    args = p.parse_args(argv)
    if args.out and Path(args.out).exists() and not args.overwrite:
        raise SystemExit(f"{args.out} exists; pass --overwrite to replace it")
    with executor(args.workers, args.scheduler) as client:
        return study(args, client)


def _ten_pose_sets(bench: Bench, args, tasks: dict, full, small) -> dict:
    """The sets of 10 poses compared: the robot's reference poses (if it has some), the D- and
    E-optimal designs in each workspace (each design_poses(robot, nominal, 10, ws, NOISE,
    criterion=c, seed=args.seed), as a task) and a random feasible set."""
    robot, nominal = bench.robot, bench.nominal
    reference = reference_poses(robot)
    sets = {} if reference is None else {"reference poses": reference}
    designs = [(c, wsn, ws) for wsn, ws in (("full", full), ("default", small)) for c in ("d", "e")]
    base = {"robot": robot.name, "description": robot.description(), "theta": nominal, "n": 10,
            "noise": NOISE.to_dict(), "free": None, "seed": args.seed, "start": 0, "n_candidates": DEFAULT_CANDIDATES}
    t0 = time.perf_counter()
    done = dict(run_tasks(design_start, [{**base, "workspace": ws.to_dict(), "criterion": c} for c, _, ws in designs],
                          **tasks))
    for k, (c, wsn, _) in enumerate(designs):
        sets[f"{c.upper()}-optimal, {wsn} workspace"] = done[k].poses
    log(f"designs ({', '.join(f'{c} {wsn}' for c, wsn, _ in designs)}): {time.perf_counter() - t0:.1f} s")
    sets["random, full workspace"] = sample_feasible_poses(robot, nominal, full, 10, [args.seed, 2])
    return sets


def _ten_pose_row(name: str, m: str, errors: np.ndarray, crb, scale: np.ndarray) -> tuple[dict, np.ndarray]:
    """One row of the 10-pose table (pose set ``name``, method ``m``, Monte Carlo ``errors``) and
    its MSE / CRB ratio per parameter."""
    mse = np.mean(errors ** 2, axis=0)
    ratio = mse / crb.crb_std ** 2
    row = {
        "poses": name, "method": m,
        "scaled_condition_number": crb.scaled_condition_number,
        "crb_rms_mm": crb.crb_rms,
        "mc_param_rms_mm": float(np.sqrt(np.mean(mse * scale ** 2))),
        "mse_over_crb_min": float(ratio.min()), "mse_over_crb_mean": float(ratio.mean()),
        "mse_over_crb_max": float(ratio.max()),
        "mse_over_crb_max_parameter": crb.names[int(np.argmax(ratio))],
    }
    return row, ratio


def _ten_pose_rows(bench: Bench, args, client, sets: dict, held: dict) -> tuple[list, dict]:
    """Monte Carlo of every 10-pose set (forward, and chain-wise for the reference and the
    D-optimal full-workspace set): the table's rows and the MSE / CRB ratios per parameter."""
    robot = bench.robot
    scale = parameter_scale(robot)[robot.table.indices(robot.free_default)]
    rows, eff = [], {}
    ref_rms = None
    for name, poses in sets.items():
        methods = ("forward", "chainwise") if name in ("reference poses", "D-optimal, full workspace") else ("forward",)
        r, crb, dt = bench.run_mc(poses, args.trials, args.seed, args.workers, methods, client)
        log(f"{name}: {args.trials} trials x {len(methods)} methods in {dt:.1f} s")
        for m in methods:
            e = r[m]["errors"]
            row, ratio = _ten_pose_row(name, m, e, crb, scale)
            row["success_rate"] = float(r[m]["success"].mean())
            n_eval = min(args.trials, 200)
            for hw in ("full", "default"):
                row[f"heldout_{hw}"] = bench.heldout_errors(e[:n_eval], held[hw])
                row[f"heldout_{hw}"]["predicted_rms_um"] = bench.predicted_heldout_rms_um(poses, held[hw])
            if name == "reference poses" and m == "forward":
                ref_rms = row
            rows.append(row)
            eff[f"{name} / {m}"] = {nm: float(v) for nm, v in zip(crb.names, ratio)}
    for row in rows:
        if row["method"] == "forward" and ref_rms is not None:
            row["crb_rms_gain_vs_reference_poses"] = ref_rms["crb_rms_mm"] / row["crb_rms_mm"]
            row["mc_rms_gain_vs_reference_poses"] = ref_rms["mc_param_rms_mm"] / row["mc_param_rms_mm"]
    return rows, eff


def _print_ten_poses(robot_name: str, trials: int, rows: list) -> None:
    print(f"\n## {robot_name}: 10 calibration poses ({trials} Monte Carlo trials per row; noise std 1 um, "
          f"1e-6 rad)\n")
    print("| poses | method | cond. (col-scaled) | CRB param RMS (mm) | MC param RMS (mm) | gain vs reference poses "
          "(CRB / MC) | MSE/CRB min / mean / max (param) | held-out pos. RMS full ws (um, MC / pred.) "
          "| held-out pos. RMS default ws (um, MC / pred.) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r_ in rows:
        gain = (f"{r_['crb_rms_gain_vs_reference_poses']:.1f}x / {r_['mc_rms_gain_vs_reference_poses']:.1f}x"
                if "crb_rms_gain_vs_reference_poses" in r_ else "-")
        print(f"| {r_['poses']} | {r_['method']} | {r_['scaled_condition_number']:.0f} | {r_['crb_rms_mm']:.4g} | "
              f"{r_['mc_param_rms_mm']:.4g} | {gain} | {r_['mse_over_crb_min']:.2f} / {r_['mse_over_crb_mean']:.2f} / "
              f"{r_['mse_over_crb_max']:.2f} ({r_['mse_over_crb_max_parameter']}) | "
              f"{r_['heldout_full']['rms_um']:.3g} / {r_['heldout_full']['predicted_rms_um']:.3g} | "
              f"{r_['heldout_default']['rms_um']:.3g} / {r_['heldout_default']['predicted_rms_um']:.3g} |")


def _heldout_curves(bench: Bench, args, tasks: dict, workspaces: dict, held: dict, grid: list) -> dict:
    """Predicted held-out position RMS (um) against the number of poses, designed and random,
    per workspace: ``curves[workspace][kind][n]`` (designed absent where no design was found)."""
    robot, nominal = bench.robot, bench.nominal
    curves = {}
    points = []
    for wsn, ws in workspaces.items():
        cands = sample_feasible_poses(robot, nominal, ws, 3000, [args.seed, 3])
        curves[wsn] = {"designed": {}, "random": {}}
        points += [{"robot": robot.name, "seed": args.seed, "wsn": wsn, "workspace": ws, "candidates": cands,
                    "held": held[wsn], "n": n} for n in grid]
    values = {}
    order = sorted(range(len(points)), key=lambda k: -points[k]["n"])  # the longest first: no long tail
    for i, (designed, random) in run_tasks(curve_point, [points[k] for k in order], **tasks):
        k = order[i]
        values[k] = designed, random
        log(f"{points[k]['wsn']} N={points[k]['n']}: designed {designed if designed is not None else float('nan'):.3g}"
            f" um, random {random:.3g} um")
    for k, point in enumerate(points):
        designed, random = values[k]
        if designed is not None:
            curves[point["wsn"]]["designed"][point["n"]] = designed
        curves[point["wsn"]]["random"][point["n"]] = random
    return curves


def _poses_needed(curves: dict) -> dict:
    """``need[(workspace, kind, target um)]``: the fewest poses whose predicted held-out RMS is at
    most the target (None: none on the grid)."""
    need = {}
    for wsn in ("full", "default"):
        for target in (1.0, 0.5):
            for kind in ("designed", "random"):
                ns = [n for n, v in sorted(curves[wsn][kind].items()) if v <= target]
                need[(wsn, kind, target)] = ns[0] if ns else None
    return need


def _mc_checks(bench: Bench, args, client, workspaces: dict, held: dict, need: dict) -> dict:
    """Monte Carlo check at the reported N (designed and random, 1 um target)."""
    robot, nominal = bench.robot, bench.nominal
    checks = {}
    for wsn, ws in workspaces.items():
        for kind in ("designed", "random"):
            n = need[(wsn, kind, 1.0)]
            if n is None:
                continue
            if kind == "designed":
                cands = sample_feasible_poses(robot, nominal, ws, 3000, [args.seed, 3])
                poses = select_poses(robot, nominal, cands, n, NOISE, criterion="d").poses
            else:
                vals = [(bench.predicted_heldout_rms_um(q := sample_feasible_poses(robot, nominal, ws, n,
                                                                                   [args.seed, 5, k]), held[wsn]), k, q)
                        for k in range(5)]
                poses = sorted(vals, key=lambda v: v[0])[2][2]  # the median draw
            trials = min(args.trials, 200)
            r, _, _ = bench.run_mc(poses, trials, args.seed + 1, args.workers, ("forward",), client)
            checks[f"{wsn}/{kind}"] = {"n": n, "trials": trials,
                                       **bench.heldout_errors(r["forward"]["errors"], held[wsn]),
                                       "predicted_rms_um": bench.predicted_heldout_rms_um(poses, held[wsn])}
            log(f"MC check {wsn}/{kind} N={n}: {checks[f'{wsn}/{kind}']}")
    return checks


def _print_poses_needed(need: dict, checks: dict, curves: dict, grid: list) -> None:
    print("\n## Poses needed for a held-out position error RMS of 1 um (0.5 um)\n")
    print("| workspace | designed (D-optimal) | random feasible (median of 5 draws) "
          "| MC check at that N, designed / random (um) |")
    print("|---|---|---|---|")
    for wsn in ("full", "default"):
        def fmt(kind):
            a, b = need[(wsn, kind, 1.0)], need[(wsn, kind, 0.5)]
            return f"{a if a is not None else '>' + str(max(grid))} ({b if b is not None else '>' + str(max(grid))})"
        cd, cr = checks.get(f"{wsn}/designed"), checks.get(f"{wsn}/random")
        print(f"| {wsn} | {fmt('designed')} | {fmt('random')} | "
              f"{cd['rms_um'] if cd else float('nan'):.3g} / {cr['rms_um'] if cr else float('nan'):.3g} |")
    print("\n## Predicted held-out position error RMS (um) vs number of poses\n")
    print("| N | " + " | ".join(f"{w} {k}" for w in ("full", "default") for k in ("designed", "random")) + " |")
    print("|---|" + "---|" * 4)
    for n in grid:
        cells = []
        for w in ("full", "default"):
            for k in ("designed", "random"):
                v = curves[w][k].get(n)
                cells.append(f"{v:.3g}" if v is not None else "-")
        print(f"| {n} | " + " | ".join(cells) + " |")


def study(args, client) -> int:
    bench = Bench(args.robot, args.seed)
    tasks = {"workers": args.workers, "client": client}
    robot, nominal = bench.robot, bench.nominal
    full, small = robot_workspace(robot, "full"), robot_workspace(robot, "default")
    workspaces = {"full": full, "default": small}
    held = {"full": sample_feasible_poses(robot, nominal, full, 100, [args.seed, 1]),
            "default": sample_feasible_poses(robot, nominal, small, 100, [args.seed, 1])}
    out = {"robot": robot.name, "noise": NOISE.to_dict(), "trials": args.trials, "seed": args.seed}

    # ---- designs with 10 poses -------------------------------------------------------------
    sets = _ten_pose_sets(bench, args, tasks, full, small)
    rows, eff = _ten_pose_rows(bench, args, client, sets, held)
    out["ten_poses"] = rows
    out["mse_over_crb_per_parameter"] = eff
    _print_ten_poses(robot.name, args.trials, rows)

    # ---- poses needed for 1 um -------------------------------------------------------------
    grid = list(range(minimum_poses(robot), 31)) + [35, 40, 50, 60, 80, 100, 130, 160, 200, 260, 330, 420, 540, 700]
    curves = _heldout_curves(bench, args, tasks, workspaces, held, grid)
    need = _poses_needed(curves)
    out["heldout_curves_um"] = {w: {k: {str(n): v for n, v in c.items()} for k, c in d.items()}
                                for w, d in curves.items()}
    checks = _mc_checks(bench, args, client, workspaces, held, need)
    out["poses_needed"] = {f"{w}/{k}/{t}um": v for (w, k, t), v in need.items()}
    out["poses_needed_mc_check"] = checks
    _print_poses_needed(need, checks, curves, grid)

    if args.out:
        atomic_write(args.out, json.dumps(out, indent=2) + "\n", overwrite=args.overwrite)
    return 0


if __name__ == "__main__":
    sys.exit(main())
