"""Scale curve of the Dask executor (figures of docs/scaling.md); prints them as JSON and markdown.

Usage::

    python benchmarks/scale.py [--trials 400] [--robot hexapod] [--blind-seeds 5] [--blind-threads-compare]
        [--machines 6] [--out FILE.json]

Measured in one run:

1. **Monte Carlo study** (:func:`pipeline.workflows.study.monte_carlo`, forward method, 10 designed poses,
   20 held-out poses, Gaussian noise 1 um / 1 urad): in this process (``workers=1``), then on a
   local Dask cluster of 1 and of 2 workers (cluster started beforehand; its start timed apart).
   Per-trial cost, speed-up 1 -> 2 workers, and the scheduler's overhead per task:
   ``(wall x workers - sum of the tasks' compute time) / tasks``, the compute times from Dask's
   own task stream (:func:`distributed.get_task_stream`). Also checked: the three runs give the
   same numbers.
2. **Round trip of an empty task**: 500 no-op tasks on the 2-worker cluster, wall / tasks.
3. **Blind suite** (:func:`pipeline.workflows.blind.blind_case`, the cases of
   ``run_blind_suite(seeds=range(S), kinds=("single",))``: every single effect that applies to
   the robot and none, ``--blind-seeds`` S seeds each; each case simulates its recording in
   MuJoCo and runs discovery on it): on a local cluster of 1 and of 2 workers (started
   beforehand, warmed by one case each), the same measurements as the study, each task's CPU time
   (all its threads) beside its wall time, and a check that both give the same results. With
   ``--blind-threads-compare``, the 2-worker cluster again with each task's testbed allowed every
   core (``THREADS_VAR`` raised in the task: the executor's setting before it limited it).
4. **What the hardware gives two processes** (:func:`parallel_capacity`): the same CPU-bound
   loop (Python arithmetic and small numpy solves, no Dask, no files) run alone and as two
   processes at once, alternated over several rounds: ``2 x alone / slower of the pair`` is the
   best speed-up any executor can reach from 1 to 2 processes on this machine at that time (2.0
   with two free cores; less when the cores share a physical core or the host's other guests
   take a share of them). The executor's own efficiency is its speed-up over this figure.
5. **Fleet**: the cost of one machine (:func:`pipeline.workflows.fleet.calibrate_machine`, in this process,
   with the fleet's default effect discovery and without) over ``--machines`` recordings (one
   simulated per robot in MuJoCo, then copies).

The numbers depend on what else runs on the machine: print ``os.getloadavg()`` with them.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# One BLAS thread here too (before numpy loads), as in the workers: the in-process figure is then
# one core's, comparable with a worker's (multi-threaded BLAS on these small problems is slower).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calib.design import design_poses, robot_workspace, sample_feasible_poses  # noqa: E402
from calib.noise import SensorNoise  # noqa: E402
from calib.robots import default_robot, reference_poses  # noqa: E402
from pipeline.execution import THREADS_VAR, dask_client, run_tasks  # noqa: E402
from pipeline.formats import atomic_write  # noqa: E402
from pipeline.workflows.study import monte_carlo, true_errors  # noqa: E402

NOISE = SensorNoise(position_mm=1e-3, orientation_rad=1e-6, distribution="normal")


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def noop(x):
    return x


#: The loop :func:`parallel_capacity` times: waits for a start time (argv[1], ``time.time()``)
#: so that the two processes of a pair compute together, then prints its compute seconds.
CAPACITY_LOOP = """
import sys, time
import numpy as np
A = np.random.default_rng(0).random((64, 6, 6)) + 6.0 * np.eye(6)
b = np.ones((64, 6, 1))
time.sleep(max(0.0, float(sys.argv[1]) - time.time()))
t = time.perf_counter()
x = 0
for i in range(3_000_000):
    x += i * i % 7
    if i % 200 == 0:
        np.linalg.solve(A, b)
print(time.perf_counter() - t)
"""


def parallel_capacity(rounds: int = 5) -> dict:
    """Speed-up the hardware gives two CPU-bound processes over one, now (see the module's item 4):
    ``rounds`` alternations of one process alone and two at once; per round ``2 x alone / slower
    of the pair``; the median round is the figure."""
    def timed(k: int) -> list[float]:
        start = f"{time.time() + 1.0:.6f}"  # after the interpreters and numpy have loaded
        procs = [subprocess.Popen([sys.executable, "-c", CAPACITY_LOOP, start], stdout=subprocess.PIPE, text=True)
                 for _ in range(k)]
        return [float(p.communicate()[0]) for p in procs]

    alone, pairs, ratios = [], [], []
    for _ in range(rounds):
        a, pair = timed(1)[0], timed(2)
        alone.append(a)
        pairs.append(pair)
        ratios.append(2.0 * a / max(pair))
    return {"rounds": rounds, "alone_s": alone, "pair_s": pairs, "speedup_per_round": ratios,
            "speedup": float(np.median(ratios))}


def blind_task(job):
    """A blind-suite case and what it cost: (results, CPU s of the worker process, wall s).

    ``job``: (case, threads) with ``threads`` the testbed threads the task may use (None: the
    worker's setting)."""
    from pipeline.workflows.blind import blind_case

    case, threads = job
    if threads is not None:
        os.environ[THREADS_VAR] = str(threads)
    c0, t0 = time.process_time(), time.perf_counter()
    out = blind_case(case)
    return out, time.process_time() - c0, time.perf_counter() - t0


def blind_on(client, cases, threads=None) -> dict:
    """The blind suite on ``client``: wall, per-task compute (Dask's task stream) and overhead."""
    from distributed import get_task_stream

    n = len(client.scheduler_info()["workers"])
    list(run_tasks(blind_task, [((cases[0][0], (), 99, ("single",)), threads)] * n, client=client))  # warm
    with get_task_stream(client) as ts:
        t0 = time.perf_counter()
        out = dict(run_tasks(blind_task, [(c, threads) for c in cases], client=client))
        wall = time.perf_counter() - t0
    compute = [sum(s["stop"] - s["start"] for s in t["startstops"] if s["action"] == "compute") for t in ts.data]
    results = [out[i][0] for i in range(len(cases))]
    cpu, task_wall = sum(out[i][1] for i in out), sum(out[i][2] for i in out)
    per_task = sum(compute) / len(compute)
    overhead = (wall * n - sum(compute)) / len(compute)
    return {"workers": n, "wall_s": wall, "tasks": len(compute), "task_compute_s": float(sum(compute)),
            "per_task_s": per_task, "overhead_per_task_ms": 1e3 * overhead, "overhead_fraction": overhead / per_task,
            "cores_per_task": cpu / task_wall, "results": json.dumps(results, sort_keys=True, default=str)}


def blind_scale(robot: str, seeds: int, compare_threads: bool) -> dict:
    from pipeline.workflows.blind import blind_cases

    cases = blind_cases(seeds=range(seeds), robot=robot, kinds=("single",))
    fig = {"cases": len(cases), "seeds": seeds}
    for n in (1, 2):
        log(f"blind suite, {len(cases)} cases, local cluster of {n} worker(s)...")
        with dask_client(n) as client:
            fig[f"w{n}"] = blind_on(client, cases)
            if n == 2 and compare_threads:
                log("blind suite, 2 workers, each task's testbed on every core...")
                fig["w2_every_core"] = blind_on(client, cases, threads=os.cpu_count())
    fig["same_results"] = fig["w1"]["results"] == fig["w2"]["results"]
    assert fig["same_results"], "the blind suite's results differ between 1 and 2 workers"
    fig["speedup_1_to_2"] = fig["w1"]["wall_s"] / fig["w2"]["wall_s"]
    for w in fig.values():
        if isinstance(w, dict):
            w.pop("results", None)
    return fig


def study_inputs(name: str):
    robot = default_robot(name)
    nominal = robot.table.nominal
    kind = "reference" if reference_poses(robot) is not None else "random"
    theta = nominal + true_errors(robot, kind, 0)
    ws = robot_workspace(robot, "full")
    poses = design_poses(robot, nominal, 10, ws, NOISE, seed=0, n_candidates=300).poses
    held = sample_feasible_poses(robot, nominal, ws, 20, [0, 1])
    return robot, theta, poses, robot.inverse_kinematics(nominal, poses), held


def study_on(client, inputs, trials):
    """(wall s, results, tasks, sum of the tasks' compute time s) of the study on ``client``."""
    from distributed import get_task_stream

    robot, theta, poses, commanded, held = inputs
    with get_task_stream(client) as ts:
        t0 = time.perf_counter()
        r = monte_carlo(robot, theta, commanded, NOISE, trials, 0, heldout=held, client=client, initial=poses)
        wall = time.perf_counter() - t0
    compute = [sum(s["stop"] - s["start"] for s in t["startstops"] if s["action"] == "compute") for t in ts.data]
    return wall, r, len(compute), float(sum(compute))


def fleet_cost(n_machines: int) -> dict:
    from pipeline.workflows.calibration import RunSettings, run_calibration
    from pipeline.workflows.fleet import calibrate_machine, input_hash
    from pipeline.formats import read_recording, write_recording

    poses = {"hexapod": 12, "delta": 12, "rus": 20}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        files = []
        for robot, n in poses.items():
            run_calibration(RunSettings(robot=robot, poses=str(n), heldout=5, seed=3, out=tmp / "sim", name=robot))
            rec = read_recording(tmp / "sim" / f"{robot}.csv")
            for k in range(max(1, n_machines // 3)):
                m = rec.measured.copy()
                m[:, :3] += np.random.default_rng([k, 1]).uniform(-3e-4, 3e-4, (len(m), 3))
                files.append(write_recording(tmp / "fleet" / f"{robot}_{k}.csv", dataclasses.replace(rec, measured=m))[0])
        walls = {True: {}, False: {}}  # with the fleet's default effect discovery, and without
        for discover in (True, False):
            for f in files:
                row = calibrate_machine({"machine": f.stem, "file": str(f), "out": str(tmp / "out"),
                                         "method": "chainwise", "sha256": input_hash(f), "discover": discover})
                assert row["status"] == "calibrated", row["error"]
                walls[discover].setdefault(row["robot"], []).append(row["wall_s"])
    # The first machine of a process pays the imports (rerun, the observability...): reported apart.
    first = [w[0] for w in walls[True].values()]
    rest = {d: [x for w in walls[d].values() for x in w[1:]] for d in walls}
    return {"machines": len(files), "per_robot_mean_s": {k: float(np.mean(v[1:] or v)) for k, v in walls[True].items()},
            "mean_s": float(np.mean(rest[True] or first)), "mean_without_discovery_s": float(np.mean(rest[False])),
            "first_in_process_s": float(first[0])}


def study_scale(args, fig: dict) -> None:
    inputs = study_inputs(args.robot)
    robot, theta, poses, commanded, held = inputs

    log("study in this process...")
    t0 = time.perf_counter()
    here = monte_carlo(robot, theta, commanded, NOISE, args.trials, 0, heldout=held, workers=1, initial=poses)
    fig["here_s"] = time.perf_counter() - t0
    fig["per_trial_ms"] = 1e3 * fig["here_s"] / args.trials

    for n in (1, 2):
        log(f"local cluster of {n} worker(s)...")
        t0 = time.perf_counter()
        with dask_client(n) as client:
            fig[f"start_{n}_s"] = time.perf_counter() - t0
            # Warm the workers (their imports) with a tiny study, so the wall is the tasks' work.
            study_on(client, inputs, 2 * n)
            wall, r, tasks, compute = study_on(client, inputs, args.trials)
            same = all(np.array_equal(here["forward"][k], r["forward"][k], equal_nan=True) for k in here["forward"])
            fig[f"w{n}"] = {"wall_s": wall, "tasks": tasks, "task_compute_s": compute,
                            "per_task_ms": 1e3 * compute / tasks,
                            "overhead_per_task_ms": 1e3 * (wall * n - compute) / tasks, "same_numbers": same}
            if n == 2:
                t0 = time.perf_counter()
                list(client.gather(client.map(noop, range(500), pure=False)))
                fig["noop_round_trip_ms"] = 1e3 * (time.perf_counter() - t0) / 500
    fig["speedup_1_to_2"] = fig["w1"]["wall_s"] / fig["w2"]["wall_s"]
    for n in (1, 2):
        w = fig[f"w{n}"]
        w["overhead_fraction"] = w["overhead_per_task_ms"] / w["per_task_ms"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default="hexapod")
    p.add_argument("--trials", type=int, default=400, help="Monte Carlo trials (0: skip the study)")
    p.add_argument("--blind-seeds", type=int, default=5, help="seeds of each blind-suite case (0: skip the blind suite)")
    p.add_argument("--blind-threads-compare", action="store_true",
                   help="also run the blind suite on 2 workers with each task's testbed on every core")
    p.add_argument("--machines", type=int, default=6, help="fleet machines timed (0: skip)")
    p.add_argument("--out", default=None, help="write the figures as JSON here")
    args = p.parse_args(argv)
    fig = {"cpu_count": os.cpu_count(), "load_before": os.getloadavg(), "robot": args.robot, "trials": args.trials}
    log("what the hardware gives two processes...")
    fig["capacity_before"] = parallel_capacity()
    if args.trials:
        study_scale(args, fig)
    if args.blind_seeds:
        fig["blind"] = blind_scale(args.robot, args.blind_seeds, args.blind_threads_compare)
    if args.machines:
        log("fleet machines in this process...")
        fig["fleet"] = fleet_cost(args.machines)
    log("what the hardware gives two processes, again...")
    fig["capacity_after"] = parallel_capacity()
    fig["load_after"] = os.getloadavg()
    print(json.dumps(fig, indent=1))
    if args.trials:
        w1, w2 = fig["w1"], fig["w2"]
        print(f"\n| study | here | 1 worker | 2 workers |\n|---|---|---|---|\n"
              f"| wall, {args.trials} trials (s) | {fig['here_s']:.2f} | {w1['wall_s']:.2f} | {w2['wall_s']:.2f} |\n"
              f"| tasks (chunks of trials) | - | {w1['tasks']} | {w2['tasks']} |\n"
              f"| compute per task (ms) | - | {w1['per_task_ms']:.1f} | {w2['per_task_ms']:.1f} |\n"
              f"| overhead per task (ms) | - | {w1['overhead_per_task_ms']:.2f} | {w2['overhead_per_task_ms']:.2f} |\n"
              f"| overhead / task cost | - | {100 * w1['overhead_fraction']:.1f}% | {100 * w2['overhead_fraction']:.1f}% |\n"
              f"| cluster start (s) | - | {fig['start_1_s']:.1f} | {fig['start_2_s']:.1f} |\n\n"
              f"per trial {fig['per_trial_ms']:.2f} ms; speed-up 1 -> 2 workers {fig['speedup_1_to_2']:.2f}x; "
              f"empty-task round trip {fig['noop_round_trip_ms']:.2f} ms")
    if args.blind_seeds:
        b = fig["blind"]
        runs = [("1 worker", b["w1"]), ("2 workers", b["w2"])] + (
            [("2 workers, every core a task", b["w2_every_core"])] if "w2_every_core" in b else [])
        print(f"\n| blind suite, {b['cases']} cases | " + " | ".join(k for k, _ in runs) + " |\n" + "|---" * (len(runs) + 1)
              + "|\n" + "".join(f"| {label} | " + " | ".join(fmt(w) for _, w in runs) + " |\n" for label, fmt in (
                  ("wall (s)", lambda w: f"{w['wall_s']:.1f}"),
                  ("compute per task (s)", lambda w: f"{w['per_task_s']:.2f}"),
                  ("cores a task uses (CPU / wall)", lambda w: f"{w['cores_per_task']:.2f}"),
                  ("overhead per task (ms)", lambda w: f"{w['overhead_per_task_ms']:.1f}"),
                  ("overhead / task cost", lambda w: f"{100 * w['overhead_fraction']:.1f}%")))
              + f"\nspeed-up 1 -> 2 workers {b['speedup_1_to_2']:.2f}x"
              + (f" ({b['w1']['wall_s'] / b['w2_every_core']['wall_s']:.2f}x with every core a task)"
                 if "w2_every_core" in b else "") + f"; same results on 1 and 2 workers: {b['same_results']}")
        slower = b["w2"]["per_task_s"] / b["w1"]["per_task_s"]
        print(f"a task's compute on 2 workers / on 1: {slower:.2f} (the hardware's share of the loss); "
              f"the speed-up at the 1-worker task cost: {b['speedup_1_to_2'] * slower:.2f}x (the executor's share)")
    before, after = fig["capacity_before"]["speedup"], fig["capacity_after"]["speedup"]
    print(f"\nwhat the hardware gives two CPU-bound processes over one (no executor): {before:.2f}x before, "
          f"{after:.2f}x after (medians of {fig['capacity_before']['rounds']} alternated rounds)")
    print(f"load {fig['load_before']} -> {fig['load_after']}")
    if args.out:
        atomic_write(args.out, json.dumps(fig, indent=1) + "\n", overwrite=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
