"""How the fits scale with the number of poses (run by hand; figures of docs/benchmarks.md).

``OPENBLAS_NUM_THREADS=1 taskset -c 0 python benchmarks/fit_scale.py [--sizes 100,1000,...] [--repeat 3]
[--generic-max 10000] [--baseline-ref REV] [--no-memory]``

Hexapod (the paper's machine, its reference errors), N reachable poses, the paper's sensor noise
(:func:`engine_speed.data`). For each N, in one run, best of ``--repeat``:

* forward: :func:`calib.engine.identify_forward` (Gauss-Newton with the poses solved along);
* chain-wise: :func:`calib.engine.identify_chainwise` (``solver="gn"``, the paper's method);
* the floor: one dense ``J^T J`` of that size in numpy, ``J`` (6 N, 42) (above 100,000 poses in
  slices of 100,000 poses' rows, summed: the same products, without a 2 GB matrix);
* the generic fit: ``scipy.optimize.least_squares`` with a finite-difference Jacobian on the same
  residual (:func:`engine_speed.generic_forward_fit`), up to ``--generic-max`` poses.

``--baseline-ref REV``: the two fits of the engine at git revision REV (a clean ``git archive``
export) timed in a child process on the same data, up to 100,000 poses (the old engine holds the
whole Jacobian: at a million poses it needs gigabytes).

Peak memory of each fit at the largest N (``--no-memory`` skips it): in a child process each,
``tracemalloc``'s peak of the fit alone (numpy reports its arrays to it) and the process's
``ru_maxrss``; beside them, what the whole Jacobian of that size would take.

The machine is shared: print the load with the figures and take best of several runs.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from engine_speed import best_of, data, generic_forward_fit  # noqa: E402
from machine_speed import child_env, export_revision, load  # noqa: E402

from calib.engine import identify_chainwise, identify_forward  # noqa: E402
from calib.noise import SensorNoise  # noqa: E402
from calib.robots import default_robot  # noqa: E402

NOISE = SensorNoise(0.001, 1e-6)
SIZES = (100, 1_000, 10_000, 100_000, 1_000_000)
#: Poses of one slice of the floor's J^T J above which it is summed over slices.
FLOOR_SLICE = 100_000

#: Times both fits of the engine on sys.path at N poses (argv: N, repeat); prints JSON.
CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[3])
from engine_speed import best_of, data
from calib.engine import identify_chainwise, identify_forward
from calib.noise import SensorNoise
from calib.robots import default_robot
robot, noise = default_robot("hexapod"), SensorNoise(0.001, 1e-6)
n, repeat = int(sys.argv[1]), int(sys.argv[2])
_, joints, measured = data(robot, n, 0, noise)
fwd = best_of(lambda: identify_forward(robot, joints, measured, noise), repeat)
chain = best_of(lambda: identify_chainwise(robot, joints, measured, noise, solver="gn"), repeat)
theta = identify_forward(robot, joints, measured, noise).theta.tolist()
print(json.dumps({"forward": fwd, "chainwise": chain, "theta": theta}))
"""

#: Peak memory of one fit (argv: N, method); prints JSON.
MEMORY = r"""
import json, resource, sys, tracemalloc
sys.path.insert(0, sys.argv[3])
from engine_speed import data
from calib.engine import identify
from calib.noise import SensorNoise
from calib.robots import default_robot
robot, noise = default_robot("hexapod"), SensorNoise(0.001, 1e-6)
_, joints, measured = data(robot, int(sys.argv[1]), 0, noise)
kw = {"solver": "gn"} if sys.argv[2] == "chainwise" else {}
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
tracemalloc.start()
fit = identify(robot, joints, measured, noise, method=sys.argv[2], **kw)
peak = tracemalloc.get_traced_memory()[1]
tracemalloc.stop()
print(json.dumps({"fit_peak_MB": peak / 2**20, "maxrss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "maxrss_before_fit_MB": before / 1024, "success": bool(fit.success)}))
"""


def floor(n: int, k: int, repeat: int) -> float:
    """Best time of one dense J^T J of a (6 n, k) matrix (summed over slices above FLOOR_SLICE poses)."""
    J = np.random.default_rng(0).random((6 * min(n, FLOOR_SLICE), k))
    slices = -(-n // FLOOR_SLICE)
    last = J[: 6 * (n - (slices - 1) * FLOOR_SLICE)]

    def run():
        g = np.zeros((k, k))
        for s in range(slices):
            A = last if s == slices - 1 else J
            g += A.T @ A
        return g

    return best_of(run, repeat)


def baseline(ref: str, sizes, repeat: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        tree = export_revision(ref, Path(tmp))
        out = {}
        for n in sizes:
            r = subprocess.run([sys.executable, "-c", CHILD, str(n), str(repeat), str(HERE)], cwd=tree,
                               env=child_env(tree), capture_output=True, text=True, check=True)
            out[n] = json.loads(r.stdout)
        return out


def memory(n: int, method: str) -> dict:
    root = HERE.parent
    r = subprocess.run([sys.executable, "-c", MEMORY, str(n), method, str(HERE)], cwd=root, env=child_env(root),
                       capture_output=True, text=True, check=True)
    return json.loads(r.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default=",".join(map(str, SIZES)), help="pose counts, comma-separated")
    ap.add_argument("--repeat", type=int, default=3, help="best of this many runs (default 3)")
    ap.add_argument("--generic-max", type=int, default=10_000, help="largest N of the generic scipy fit")
    ap.add_argument("--baseline-ref", default=None, help="also time the engine of this git revision")
    ap.add_argument("--no-memory", action="store_true", help="skip the peak-memory children")
    a = ap.parse_args()
    sizes = [int(s) for s in a.sizes.split(",")]
    robot = default_robot("hexapod")
    k = len(robot.free_default)
    print(f"fit_scale: hexapod, {k} free parameters, best of {a.repeat}; {load()}", flush=True)
    base = baseline(a.baseline_ref, [n for n in sizes if n <= 100_000], a.repeat) if a.baseline_ref else {}
    head = "| poses | forward | chain-wise | J^T J floor | forward / floor | generic scipy fit |"
    if base:
        head += f" forward at {a.baseline_ref} | chain-wise at {a.baseline_ref} |"
    print(head + "\n" + "|---" * (head.count("|") - 1) + "|")
    for n in sizes:
        _, joints, measured = data(robot, n, 0, NOISE)
        t_fwd = best_of(lambda: identify_forward(robot, joints, measured, NOISE), a.repeat)
        t_chain = best_of(lambda: identify_chainwise(robot, joints, measured, NOISE, solver="gn"), a.repeat)
        t_floor = floor(n, k, a.repeat)
        generic = "-"
        if n <= a.generic_max:
            t0 = time.perf_counter()
            sol = generic_forward_fit(robot, joints, measured, NOISE)
            fit = identify_forward(robot, joints, measured, NOISE)
            diff = np.max(np.abs(fit.theta[robot.table.indices(robot.free_default)] - sol.x))
            generic = f"{time.perf_counter() - t0:.3g} s ({sol.nfev} evaluations; answers within {diff:.1g} mm)"
        line = f"| {n:,} | {t_fwd:.3g} s | {t_chain:.3g} s | {t_floor:.3g} s | {t_fwd / t_floor:.1f} | {generic} |"
        if base:
            b = base.get(n)
            line += " - | - |" if b is None else f" {b['forward']:.3g} s | {b['chainwise']:.3g} s |"
        print(line, flush=True)
    if not a.no_memory:
        n = max(sizes)
        whole = 6 * n * k * 8 / 2**20
        print(f"\npeak memory at {n:,} poses (the whole (6 N, {k}) Jacobian would be {whole:,.0f} MB):")
        for method in ("forward", "chainwise"):
            m = memory(n, method)
            print(f"- {method}: the fit's own peak (tracemalloc) {m['fit_peak_MB']:,.0f} MB; process ru_maxrss "
                  f"{m['maxrss_MB']:,.0f} MB ({m['maxrss_before_fit_MB']:,.0f} MB before the fit); "
                  f"converged: {m['success']}")
    print(load())


if __name__ == "__main__":
    main()
