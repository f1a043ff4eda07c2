"""Speed of the simulated machine and of the default command, as ratios measured in one run.

    PYTHONPATH=. python benchmarks/machine_speed.py [--poses 100] [--repeats 3] [--robots hexapod,delta,rus]
        [--gravity] [--baseline-ref REF] [--command-only] [--bytecode]

1. The testbed settling ``--poses`` poses of each robot (its reference errors injected, reachable
   poses commanded through the nominal inverse kinematics): one pose after another
   (``settle="sequential"``) and all together from their warm starts (``settle="rollout"``, every
   core), and with ``--baseline-ref`` the testbed of that git revision (the code before the
   rollout). Best of ``--repeats``, the variants alternated within each repeat, each timing in a
   fresh process with one BLAS thread; the largest difference of the settled poses from the
   sequential ones is printed with each.
2. The default ``python -m pipeline.run`` (simulated hexapod, writes .rrd, .csv, .json) and
   ``python -m pipeline.run --help``: wall time of the whole process, best of ``--repeats``, this
   tree and (with ``--baseline-ref``) the baseline's, alternated in one run; beside them the
   import-only time: a process that imports what the default run imports (:data:`RUN_IMPORTS`)
   and runs nothing; the run's own split (simulate, identify, log: importing Rerun and writing
   the .rrd) from its summary; and the floor: the libraries alone (numpy, scipy.special,
   mujoco, rerun).
   ``--command-only`` skips part 1. Python compiles this package's modules in every process when
   bytecode caching is off (``PYTHONDONTWRITEBYTECODE`` set, as on the machine these figures were
   first taken on): ``--bytecode`` compiles both trees first and lets the children use the cache,
   as an installed package does.

The machine's load (``os.getloadavg``) is printed before and after: on a shared machine the
ratios are the figures to quote, the absolute times move with the load.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: Times one testbed measurement in a fresh process; prints JSON, saves the settled poses.
CHILD = r"""
import json, sys, time
import numpy as np
from calib.robots import default_robot, reference_errors
from calib.workspace import reachable_poses
from mjcf.machine import MachineOptions
from pipeline.simulation import Testbed
name, n, variant, gravity, out = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4] == "1", sys.argv[5]
robot = default_robot(name)
theta = robot.table.nominal + reference_errors(robot, 0)
joints = robot.inverse_kinematics(robot.table.nominal, reachable_poses(robot, n, 1))
options = MachineOptions(gravity=gravity)
extra = {} if variant == "baseline" else {"settle": variant.split("-")[0]}
if variant.endswith("-1thread"):
    extra["threads"] = 1
bed = Testbed(robot, theta, options=options, **extra)
t = time.perf_counter()
m = bed.measure(joints)
wall = time.perf_counter() - t
np.save(out, m.true_poses)
print(json.dumps({"s": wall, "steps": float(m.steps.mean())}))
"""


#: What the default run imports (its modules, and through them the libraries), nothing run.
RUN_IMPORTS = ("import pipeline.run, pipeline.workflows.calibration, pipeline.formats, pipeline.simulation.testbed, "
               "pipeline.views.run_view, calib.observability, mjcf.hexapod")
#: Whether the children may use compiled bytecode (``--bytecode``).
BYTECODE = {"on": False}


def child_env(pythonpath: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(pythonpath), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1",
               MKL_NUM_THREADS="1")
    if BYTECODE["on"]:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def copy_tree(into: Path) -> Path:
    """A copy of this working tree's packages without their bytecode (``__pycache__``), so that it
    and the baseline export start alike."""
    dest = into / "this_tree"
    for pkg in ("calib", "mjcf", "pipeline"):
        shutil.copytree(ROOT / pkg, dest / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    return dest


def compile_tree(tree: Path) -> None:
    """Compile the tree's packages to bytecode (``__pycache__``, ignored by git)."""
    for pkg in ("calib", "mjcf", "pipeline"):
        subprocess.run([sys.executable, "-m", "compileall", "-q", str(tree / pkg)], check=True)


def load() -> str:
    return "load average " + ", ".join(f"{v:.2f}" for v in os.getloadavg()) + f" on {os.cpu_count()} cores"


def export_revision(ref: str, into: Path) -> Path:
    """A clean copy of the tree at git revision ``ref`` (git archive; nothing in the repository
    is changed)."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", ref], check=True,
                             capture_output=True).stdout
    dest = into / "baseline"
    dest.mkdir()
    with tempfile.TemporaryFile() as f:
        f.write(archive)
        f.seek(0)
        with tarfile.open(fileobj=f) as tar:
            tar.extractall(dest, filter="data")
    return dest


def time_testbed(tree: Path, robot: str, n: int, variant: str, gravity: bool, out: Path) -> dict:
    res = subprocess.run([sys.executable, "-c", CHILD, robot, str(n), variant, "1" if gravity else "0", str(out)],
                         env=child_env(tree), capture_output=True, text=True, cwd=tree)
    if res.returncode:
        raise RuntimeError(f"{variant} on {robot} failed:\n{res.stderr}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def time_process(tree: Path, args: list[str], env_extra: dict | None = None) -> tuple[float, float]:
    """(wall, CPU) seconds of ``python ARGS`` run in ``tree`` (CPU: user + system of the child,
    less sensitive to the machine's load than the wall time)."""
    env = child_env(tree)
    env.pop("MUJOCO_GL", None)
    env.update(env_extra or {})
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    res = subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True, cwd=tree)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode:
        raise RuntimeError(f"python {' '.join(args)} failed in {tree}:\n{res.stderr}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--poses", type=int, default=100)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--robots", default="hexapod,delta,rus")
    p.add_argument("--gravity", action="store_true", help="the machine with gravity (loaded servos)")
    p.add_argument("--baseline-ref", default=None, help="git revision to compare with (e.g. main)")
    p.add_argument("--skip-command", action="store_true", help="only the testbed")
    p.add_argument("--command-only", action="store_true", help="only the command (part 2)")
    p.add_argument("--bytecode", action="store_true",
                   help="compile both trees first and let the children use bytecode (as an installed package)")
    return p.parse_args(argv)


def testbed_part(a: argparse.Namespace, base: Path | None, tmp: Path) -> None:
    """Part 1: each robot's testbed, every variant once a repeat, best of ``a.repeats``; prints a
    table (best wall time in ms, mean settling steps a pose, ratios, the largest difference of
    the settled poses from the sequential ones, mm and rad)."""
    variants = (["baseline"] if base else []) + ["sequential", "rollout-1thread", "rollout"]
    robots = [] if a.command_only else a.robots.split(",")
    if robots:
        print(f"\n1. testbed, {a.poses} poses, gravity {'on' if a.gravity else 'off'} "
              f"(rollout: {os.cpu_count()} threads; rollout-1thread: the warm start alone)")
        print(f"  {'robot':<8}{'variant':<17}{'best ms':>9}{'steps/pose':>12}{'vs sequential':>15}"
              f"{'vs baseline':>13}{'max |d pose|':>14}")
    for robot in robots:
        best: dict[str, float] = {}
        steps: dict[str, float] = {}
        for _ in range(a.repeats):
            for v in variants:
                r = time_testbed(base if v == "baseline" else ROOT, robot, a.poses, v, a.gravity, tmp / f"{v}.npy")
                best[v] = min(best.get(v, np.inf), r["s"])
                steps[v] = r["steps"]
        ref = np.load(tmp / "sequential.npy")
        for v in variants:
            d = np.abs(np.load(tmp / f"{v}.npy") - ref).max()
            vs_base = f"{best['baseline'] / best[v]:.1f}x" if base else "-"
            print(f"  {robot:<8}{v:<17}{1e3 * best[v]:>9.0f}{steps[v]:>12.0f}"
                  f"{best['sequential'] / best[v]:>14.1f}x{vs_base:>13}{d:>14.2g}")


#: Part 2's processes: label, arguments of ``python`` (None: the default run, written to a folder).
COMMAND_RUNS = (("--help", ["-m", "pipeline.run", "--help"]), ("default run", None),
                ("its imports", ["-c", RUN_IMPORTS]))


def command_timings(repeats: int, trees: list[tuple[str, Path]], tmp: Path) -> tuple[dict, dict, dict]:
    """``(wall, cpu, split)``: best seconds of each of :data:`COMMAND_RUNS` in each tree
    (``wall[label][tree]``, ``cpu[label][tree]``) and the default run's own split (simulate,
    identify, log; ``split[tree][step]``), best of each over ``repeats``."""
    wall = {label: {} for label, _ in COMMAND_RUNS}
    cpu = {label: {} for label, _ in COMMAND_RUNS}
    split: dict[str, dict] = {}
    for _ in range(repeats):  # every variant once a repeat: the load moves them alike
        for label, args in COMMAND_RUNS:
            for name, tree in trees:
                out = tmp / f"out-{name.replace(' ', '_')}"
                argv_ = args or ["-m", "pipeline.run", "--out", str(out), "--overwrite", "--name", "bench",
                                 "--quiet", "--summary-json", str(out / "summary.json")]
                w, c = time_process(tree, argv_, {"MUJOCO_GL": "disable"} if label == "its imports" else None)
                wall[label][name] = min(wall[label].get(name, np.inf), w)
                cpu[label][name] = min(cpu[label].get(name, np.inf), c)
                if args is None:
                    got = json.loads((out / "summary.json").read_text())["wall_time_split_s"]
                    split[name] = {k: min(v, split.get(name, {}).get(k, np.inf)) for k, v in got.items()}
    return wall, cpu, split


def command_part(a: argparse.Namespace, base: Path | None, here: Path, tmp: Path) -> None:
    """Part 2: the command's processes in each tree (:func:`command_timings`), the default run
    split into its imports and the rest, and the floor (the libraries alone); prints seconds."""
    print("\n2. python -m pipeline.run, wall time of the process (best of "
          f"{a.repeats}; {'this tree and ' + a.baseline_ref if base else 'this tree'})")
    trees = ([("baseline", base)] if base else []) + [("this tree", here)]
    wall, cpu, split = command_timings(a.repeats, trees, tmp)
    for label, _ in COMMAND_RUNS:
        line = ", ".join(f"{name} {wall[label][name]:.2f} s wall ({cpu[label][name]:.2f} s CPU)"
                         for name, _ in trees)
        ratio = f"  {wall[label]['baseline'] / wall[label]['this tree']:.2f}x wall" if base else ""
        print(f"  {label:<12} {line}{ratio}")
    for name, _ in trees:
        w = wall["default run"][name]
        print(f"  {name}: default run {w:.2f} s wall, of which its imports {wall['its imports'][name]:.2f} s "
              f"and the rest {w - wall['its imports'][name]:.2f} s; the run's own split (best of each): "
              + ", ".join(f"{k} {v:.3f} s" for k, v in split[name].items())
              + " (log: importing Rerun and writing the .rrd)")
    # What the default run cannot go below: the libraries it needs, nothing else.
    w = c = np.inf
    for _ in range(a.repeats):
        wi, ci = time_process(ROOT, ["-c", "import numpy, scipy.special, mujoco, rerun"], {"MUJOCO_GL": "disable"})
        w, c = min(w, wi), min(c, ci)
    print(f"  {'floor':<12} import numpy, scipy.special, mujoco (no OpenGL), rerun: {w:.2f} s wall ({c:.2f} s CPU)")


def main(argv: list[str] | None = None) -> int:
    a = parse_args(argv)
    BYTECODE["on"] = a.bytecode
    caching = "on (--bytecode)" if a.bytecode else ("off (PYTHONDONTWRITEBYTECODE)" if os.environ.get(
        "PYTHONDONTWRITEBYTECODE") else "as Python does by default")
    print(f"machine_speed: {a.poses} poses, best of {a.repeats}, one BLAS thread; bytecode cache {caching}; {load()}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base = export_revision(a.baseline_ref, tmp) if a.baseline_ref else None
        here = copy_tree(tmp)
        if a.bytecode:
            for tree in ([base] if base else []) + [here]:
                compile_tree(tree)
        testbed_part(a, base, tmp)
        if not a.skip_command:
            command_part(a, base, here, tmp)
    print(f"\n{load()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
