"""``python -m pipeline.convert`` on a large motion-capture export: wall time and peak memory.

    PYTHONPATH=. python benchmarks/convert_scale.py [--rows 10000 100000 300000 1000000] [--out /tmp/convert_scale]

The export, as ``tests/test_convert.py``'s lab style "metres, quaternion scalar last, revolutions"
writes it: ``--rows`` reachable poses of the hexapod (:func:`calib.workspace.reachable_poses`), the
nominal machine's legs for them (:meth:`Robot.inverse_kinematics`), positions in metres and
quaternions (SciPy, scalar last) with 1 um / 1 urad normal noise, legs as motor revolutions
(``(length - zero) / scale``), time in seconds; the TOML map declares it so. The file is written
in blocks (the generator's memory does not grow with the rows).

Each size is converted once by ``python -m pipeline.convert`` in a child process; its wall time,
CPU time and peak resident memory (``ru_maxrss`` of that child alone, :func:`os.wait4`) are
printed, with the size of the export and the command's line saying which rows the map was checked
on. Figures are of one run on a shared machine (noise: the load of the other sessions).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

#: Rows generated and written at a time.
BLOCK_ROWS = 50_000
NOISE_MM, NOISE_RAD = 0.001, 1e-6
MM_PER_M = 1000.0
#: The lab's motor encoding: mm per revolution and the leg's length at 0 revolutions, per leg.
SCALE_MM = 2.0 + 0.05 * np.arange(6)
ZERO_MM = 180.0 + np.arange(6)
HEADER = ["Time", "X", "Y", "Z", "QX", "QY", "QZ", "QW"] + [f"M{i + 1}" for i in range(6)]
MAP = """[robot]
name = "hexapod"
[noise]
position_mm = {noise_mm}
orientation_rad = {noise_rad}
distribution = "normal"
[time]
format = "seconds"
column = "Time"
[position]
columns = ["X", "Y", "Z"]
unit = "m"
[orientation]
kind = "quaternion"
scalar = "last"
columns = ["QX", "QY", "QZ", "QW"]
[joints]
columns = ["M1", "M2", "M3", "M4", "M5", "M6"]
reading = "revolutions"
unit = "mm"
scale = {scale}
zero = {zero}
"""


def write_export(folder: Path, rows: int, seed: int = 0) -> tuple[Path, Path]:
    """Write the export of ``rows`` rows and its map into ``folder``; returns ``(csv, map)``."""
    from scipy.spatial.transform import Rotation

    from calib.robots import default_robot
    from calib.workspace import reachable_poses

    robot = default_robot("hexapod")
    rng = np.random.default_rng(seed)
    csv_path, map_path = folder / f"lab{rows}.csv", folder / "map.toml"
    map_path.write_text(MAP.format(noise_mm=NOISE_MM, noise_rad=NOISE_RAD, scale=SCALE_MM.tolist(),
                                   zero=ZERO_MM.tolist()))
    with open(csv_path, "w") as f:
        f.write(",".join(HEADER) + "\n")
        for start in range(0, rows, BLOCK_ROWS):
            n = min(BLOCK_ROWS, rows - start)
            poses = reachable_poses(robot, n, rng)
            legs = robot.inverse_kinematics(robot.table.nominal, poses)
            seen = poses + np.concatenate([rng.normal(0, NOISE_MM, (n, 3)), rng.normal(0, NOISE_RAD, (n, 3))], axis=1)
            block = np.column_stack([0.01 * np.arange(start, start + n), seen[:, :3] / MM_PER_M,
                                     Rotation.from_euler("xyz", seen[:, 3:]).as_quat(), (legs - ZERO_MM) / SCALE_MM])
            np.savetxt(f, block, fmt="%.17g", delimiter=",")
    return csv_path, map_path


def timed_convert(csv_path: Path, map_path: Path, out: Path) -> dict:
    """Run the command once in a child process, reaped by :func:`os.wait4` for its own resource
    usage: wall s, CPU s, peak resident MB (``ru_maxrss`` is in kB on Linux), its output."""
    cmd = [sys.executable, "-m", "pipeline.convert", str(csv_path), "--map", str(map_path), "--out", str(out),
           "--overwrite"]
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    log = out.with_name(out.name + ".log")
    with open(log, "w+") as stdout, open(log.with_suffix(".err"), "w+") as stderr:
        t = time.perf_counter()
        child = subprocess.Popen(cmd, stdout=stdout, stderr=stderr, env=env)
        _, status, usage = os.wait4(child.pid, 0)
        wall = time.perf_counter() - t
        stdout.seek(0), stderr.seek(0)
        stdout, stderr = stdout.read(), stderr.read()
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"{' '.join(cmd)} failed ({os.waitstatus_to_exitcode(status)}):\n{stderr[-3000:]}")
    return {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime, "peak_mb": usage.ru_maxrss / 1024.0,
            "stdout": stdout, "stderr": stderr}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rows", type=int, nargs="+", default=[10_000, 100_000, 300_000, 1_000_000])
    p.add_argument("--out", type=Path, default=Path("/tmp/convert_scale"))
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"{'rows':>9} {'export MB':>9} {'wall s':>7} {'CPU s':>6} {'peak MB':>8}  checked on")
    for rows in args.rows:
        csv_path, map_path = write_export(args.out, rows)
        r = timed_convert(csv_path, map_path, args.out / f"rec{rows}")
        checked = next((ln.strip() for ln in r["stdout"].splitlines() if "checked" in ln), "")
        print(f"{rows:>9} {csv_path.stat().st_size / 1e6:>9.1f} {r['wall_s']:>7.2f} {r['cpu_s']:>6.2f} "
              f"{r['peak_mb']:>8.0f}  {checked}", flush=True)
        if r["stderr"].strip():
            print(f"          stderr: {r['stderr'].strip()}")
        csv_path.unlink()


if __name__ == "__main__":
    main()
