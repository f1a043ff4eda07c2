"""``pipeline.run --real`` on a large hexapod recording: the file made, each stage timed.

    PYTHONPATH=. python benchmarks/big_recording.py [--rows 100000] [--validation 0] [--out /tmp/big]
                                                    [--discover] [--snapshot]

The recording: ``--rows`` reachable poses of the hexapod's workspace
(:func:`calib.workspace.reachable_poses`), a machine whose geometry departs from nominal by one
draw of the default prior (:meth:`calib.prior.ParameterPrior.default`), the joints its controller
commands for them (:meth:`Robot.inverse_kinematics` of that machine), measured with 1 um / 1 urad
normal noise (kinematic model, no simulator), written with :func:`pipeline.formats.write_recording`.
The last ``--validation`` rows are validation rows (default none: the run cross-validates).

Then ``python -m pipeline.run --real REC.csv`` as a subprocess (one BLAS thread, the commands'
default), its process wall time and the summary's ``wall_time_split_s``; ``--discover`` also
times ``python -m pipeline.discover --real REC.csv --no-resim`` (and prints its verdict); ``--snapshot`` renders the run's ``.rrd``
with ``python -m pipeline.snapshot`` (headless) and prints the ``.rrd``'s size. Figures are of
one run on a shared machine (noise: the load of the other sessions).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

NOISE_MM, NOISE_RAD = 0.001, 1e-6


def make_recording(path: Path, rows: int, validation: int, seed: int = 0) -> Path:
    """Write the benchmark recording (see the module docstring) to ``path``; returns it."""
    from calib.noise import SensorNoise
    from calib.prior import ParameterPrior
    from calib.robots import default_robot
    from calib.workspace import reachable_poses
    from pipeline.formats import Recording, write_recording

    robot = default_robot("hexapod")
    rng = np.random.default_rng(seed)
    prior = ParameterPrior.default(robot)
    theta = robot.table.nominal.copy()
    free = robot.table.indices(robot.free_default)
    theta[free] += rng.normal(size=free.size) * prior.std[free]
    noise = SensorNoise(NOISE_MM, NOISE_RAD, "normal")
    poses = reachable_poses(robot, rows, rng, theta=theta)
    joints = robot.inverse_kinematics(theta, poses)
    measured = poses + noise.sample(rows, rng, robot.pose_units)
    sets = np.array(["calibration"] * (rows - validation) + ["validation"] * validation)
    rec = Recording(robot=robot, noise=noise, t_s=np.arange(rows) * 0.01, joints=joints, measured=measured,
                    sets=sets, meta={"benchmark": "benchmarks/big_recording.py", "seed": seed})
    write_recording(path, rec, overwrite=True)
    return path


def timed(cmd: list[str]) -> tuple[float, subprocess.CompletedProcess]:
    env = dict(os.environ, PYTHONPATH=".")
    t = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr[-3000:]}")
    return wall, done


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rows", type=int, default=100_000)
    p.add_argument("--validation", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("/tmp/big_recording"))
    p.add_argument("--reuse", action="store_true", help="reuse the recording if it exists")
    p.add_argument("--discover", action="store_true")
    p.add_argument("--snapshot", action="store_true")
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rec = args.out / f"rec{args.rows}.csv"
    if not (args.reuse and rec.exists()):
        t = time.perf_counter()
        make_recording(rec, args.rows, args.validation)
        print(f"recording: {rec} ({args.rows} rows, {rec.stat().st_size / 1e6:.1f} MB) made in "
              f"{time.perf_counter() - t:.1f} s")
    summary_path = args.out / "run_summary.json"
    cmd = [sys.executable, "-m", "pipeline.run", "--real", str(rec), "--out", str(args.out), "--name", "run",
           "--overwrite", "--quiet", "--summary-json", str(summary_path)]
    wall, _ = timed(cmd)
    s = json.loads(summary_path.read_text())
    print(f"pipeline.run --real: {wall:.2f} s process wall time (its own wall_time_s {s['wall_time_s']:.2f} s)")
    for k, v in s["wall_time_split_s"].items():
        print(f"  {k:>24}: {v:.3f} s")
    for key in ("crossvalidation", "gross_rows", "outliers", "checks", "diagnosis", "observability_scheme", "rerun"):
        block = s.get(key)
        if isinstance(block, dict):
            print(f"  {key}: " + "; ".join(f"{k}={v}" for k, v in block.items()
                                           if k in ("scheme", "search", "form", "screen", "poses_logged", "excitation", "rows")
                                           and isinstance(v, str)))
    rrd = Path(s["rrd"])
    print(f"  .rrd: {rrd.stat().st_size / 1e6:.2f} MB")
    if args.snapshot:
        png = args.out / "run.png"
        wall, _ = timed([sys.executable, "-m", "pipeline.snapshot", "--out", str(png), str(rrd)])
        print(f"pipeline.snapshot: {wall:.1f} s, {png} {png.stat().st_size / 1e3:.0f} kB")
    if args.discover:
        wall, done = timed([sys.executable, "-m", "pipeline.discover", "--real", str(rec), "--out", str(args.out),
                            "--overwrite", "--no-resim"])
        print(f"pipeline.discover --real --no-resim: {wall:.1f} s process wall time; "
              f"{done.stdout.strip().splitlines()[0] if done.stdout.strip() else '(nothing printed)'}")


if __name__ == "__main__":
    main()
